/* seal.h: authenticated encryption of a tuple-space connection after the handshake (auth.h),
 * with libsodium's XChaCha20-Poly1305 (IETF AEAD).
 *
 * When the server has a key its HELLO says so (TF_HELLO_SEALED, proto.h), and once AUTH_OK has
 * been sent (in clear) every byte in both directions travels in sealed records:
 *   u32 length L (little-endian) = bytes that follow = plaintext length + TF_SEAL_ABYTES,
 *                                  TF_SEAL_ABYTES < L <= TF_SEAL_RECORD_MAX + TF_SEAL_ABYTES
 *   ciphertext and tag of the plaintext, with the 4 length bytes as associated data
 * The plaintext of the records, concatenated, is the ordinary frame stream (proto.h): a record
 * may hold part of a frame or several.  Each direction has its own key,
 *   k_c2s = HMAC-SHA256(K, "terrafarm-c2s" || Ns || Nc),  k_s2c = the same with "terrafarm-s2c"
 * (K the secret's key, Ns and Nc the handshake's nonces, so every connection has fresh keys),
 * and its own record counter n = 0, 1, 2, ...; record n is sealed under the 24-byte nonce
 * LE64(n) || 16 zero bytes.  The counter is never sent: a record that was altered, replayed,
 * reordered, dropped, or moved from another connection or direction fails to open, and the
 * connection is closed.  A machine on the path sees record lengths and timing, nothing else.
 * Loopback without a secret has no key and is not sealed. */
#ifndef TF_SEAL_H
#define TF_SEAL_H

#include <stddef.h>
#include <stdint.h>

#include "linda/auth.h"
#include "linda/proto.h"

#define TF_SEAL_ABYTES 16
#define TF_SEAL_RECORD_MAX 65536 /* plaintext bytes in one record */

typedef struct tf_seal {
    uint8_t key[32];
    uint64_t counter;
} tf_seal;

/* The two directions' states of one side of a connection (is_client: which side). */
void tf_seal_init(const uint8_t key[TF_KEY_BYTES], const uint8_t ns[TF_NONCE_BYTES],
                  const uint8_t nc[TF_NONCE_BYTES], int is_client, tf_seal *tx, tf_seal *rx);
/* Seal len plaintext bytes (any number: split into records) onto out.  0 or -1 (OOM). */
int tf_seal_append(tf_seal *tx, tf_buf *out, const uint8_t *plain, size_t len);
/* Open the first record of buf[0..len) and append its plaintext to plain.  Returns the bytes
 * of buf it used (> 0), 0 when the record is not complete yet, or -1 (a length out of bounds,
 * a record that fails authentication, OOM) with one line in err: close the connection. */
long tf_seal_open(tf_seal *rx, const uint8_t *buf, size_t len, tf_buf *plain, char *err,
                  size_t errlen);

#endif
