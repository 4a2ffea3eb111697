/* auth.h: the shared secret and the mutual HMAC challenge-response of the tuple-space protocol
 * (see proto.h for the HELLO / AUTH / AUTH_OK frames), with libsodium.
 *
 * The secret file holds any non-empty bytes (a trailing newline is ignored); the key used on
 * the wire is SHA-256 of those bytes, so every secret length gives a 32-byte HMAC key.  The key
 * itself never crosses the wire: the server sends a fresh random nonce Ns, the client answers
 * with its own fresh nonce Nc and HMAC(key, "terrafarm-client" || Ns || Nc); the server checks
 * it in constant time and answers HMAC(key, "terrafarm-server" || Ns || Nc), which the client
 * checks in turn, so a worker cannot be fooled by an impostor coordinator.  The distinct labels
 * stop a reflection of one side's MAC from passing as the other's. */
#ifndef TF_AUTH_H
#define TF_AUTH_H

#include <stddef.h>
#include <stdint.h>

#define TF_KEY_BYTES 32
#define TF_NONCE_BYTES 32
#define TF_MAC_BYTES 32
/* Largest secret file accepted. */
#define TF_SECRET_FILE_MAX 4096
/* Shortest secret accepted from a file (a 1-byte secret was guessed in 121 tries). */
#define TF_SECRET_MIN_BYTES 16

/* Initialise libsodium (idempotent, thread-safe).  0 or -1. */
int tf_auth_init(void);

/* Load the secret file and derive the key.  0, or -1 with a reason in err: unreadable, empty,
 * shorter than TF_SECRET_MIN_BYTES, larger than TF_SECRET_FILE_MAX, or readable by its group
 * or by others (chmod 600 it). */
int tf_secret_load(const char *path, uint8_t key[TF_KEY_BYTES], char *err, size_t errlen);
/* Derive the key from secret bytes held in memory (tests, embedding).  0 or -1 (empty). */
int tf_secret_from_bytes(const void *secret, size_t len, uint8_t key[TF_KEY_BYTES]);

/* A fresh random nonce (randombytes_buf). */
void tf_auth_nonce(uint8_t nonce[TF_NONCE_BYTES]);

/* The client's and the server's proofs over (Ns, Nc). */
void tf_auth_client_mac(const uint8_t key[TF_KEY_BYTES], const uint8_t ns[TF_NONCE_BYTES],
                        const uint8_t nc[TF_NONCE_BYTES], uint8_t mac[TF_MAC_BYTES]);
void tf_auth_server_mac(const uint8_t key[TF_KEY_BYTES], const uint8_t ns[TF_NONCE_BYTES],
                        const uint8_t nc[TF_NONCE_BYTES], uint8_t mac[TF_MAC_BYTES]);
/* Constant-time checks of a received proof: 1 valid, 0 not. */
int tf_auth_client_mac_ok(const uint8_t key[TF_KEY_BYTES], const uint8_t ns[TF_NONCE_BYTES],
                          const uint8_t nc[TF_NONCE_BYTES], const uint8_t mac[TF_MAC_BYTES]);
int tf_auth_server_mac_ok(const uint8_t key[TF_KEY_BYTES], const uint8_t ns[TF_NONCE_BYTES],
                          const uint8_t nc[TF_NONCE_BYTES], const uint8_t mac[TF_MAC_BYTES]);

#endif
