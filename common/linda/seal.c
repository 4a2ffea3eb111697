/* seal.c: sealed records of a connection (see seal.h). */
#include "linda/seal.h"

#include <sodium.h>
#include <string.h>

#include "le_bytes.h"
#include "log.h"

static void derive(const uint8_t key[TF_KEY_BYTES], const char *label,
                   const uint8_t ns[TF_NONCE_BYTES], const uint8_t nc[TF_NONCE_BYTES],
                   uint8_t out[32])
{
    crypto_auth_hmacsha256_state st;
    crypto_auth_hmacsha256_init(&st, key, TF_KEY_BYTES);
    crypto_auth_hmacsha256_update(&st, (const unsigned char *)label, strlen(label));
    crypto_auth_hmacsha256_update(&st, ns, TF_NONCE_BYTES);
    crypto_auth_hmacsha256_update(&st, nc, TF_NONCE_BYTES);
    crypto_auth_hmacsha256_final(&st, out);
    sodium_memzero(&st, sizeof st);
}

void tf_seal_init(const uint8_t key[TF_KEY_BYTES], const uint8_t ns[TF_NONCE_BYTES],
                  const uint8_t nc[TF_NONCE_BYTES], int is_client, tf_seal *tx, tf_seal *rx)
{
    tf_seal c2s = {{0}, 0}, s2c = {{0}, 0};
    derive(key, "terrafarm-c2s", ns, nc, c2s.key);
    derive(key, "terrafarm-s2c", ns, nc, s2c.key);
    *tx = is_client ? c2s : s2c;
    *rx = is_client ? s2c : c2s;
    sodium_memzero(&c2s, sizeof c2s);
    sodium_memzero(&s2c, sizeof s2c);
}

static void nonce_of(uint64_t n, uint8_t nonce[crypto_aead_xchacha20poly1305_ietf_NPUBBYTES])
{
    memset(nonce, 0, crypto_aead_xchacha20poly1305_ietf_NPUBBYTES);
    for (int i = 0; i < 8; i++)
        nonce[i] = (uint8_t)(n >> (8 * i));
}

int tf_seal_append(tf_seal *tx, tf_buf *out, const uint8_t *plain, size_t len)
{
    while (len > 0) {
        size_t n = len < TF_SEAL_RECORD_MAX ? len : TF_SEAL_RECORD_MAX;
        if (tf_buf_reserve(out, 4 + n + TF_SEAL_ABYTES) != 0)
            return -1;
        uint8_t *p = out->data + out->off + out->len;
        tf_le_put32(p, (uint32_t)(n + TF_SEAL_ABYTES));
        uint8_t nonce[crypto_aead_xchacha20poly1305_ietf_NPUBBYTES];
        nonce_of(tx->counter++, nonce);
        unsigned long long clen = 0;
        crypto_aead_xchacha20poly1305_ietf_encrypt(p + 4, &clen, plain, n, p, 4, NULL, nonce,
                                                   tx->key);
        out->len += 4 + (size_t)clen;
        plain += n;
        len -= n;
    }
    return 0;
}

long tf_seal_open(tf_seal *rx, const uint8_t *buf, size_t len, tf_buf *plain, char *err,
                  size_t errlen)
{
    if (len < 4)
        return 0;
    uint32_t L = (uint32_t)buf[0] | (uint32_t)buf[1] << 8 | (uint32_t)buf[2] << 16 |
                 (uint32_t)buf[3] << 24;
    if (L <= TF_SEAL_ABYTES || L > TF_SEAL_RECORD_MAX + TF_SEAL_ABYTES)
        return tf_seterr(err, errlen, "sealed record length %u out of bounds", L);
    if (len - 4 < L)
        return 0;
    if (tf_buf_reserve(plain, L - TF_SEAL_ABYTES) != 0)
        return tf_seterr(err, errlen, "out of memory opening a record");
    uint8_t nonce[crypto_aead_xchacha20poly1305_ietf_NPUBBYTES];
    nonce_of(rx->counter, nonce);
    unsigned long long mlen = 0;
    if (crypto_aead_xchacha20poly1305_ietf_decrypt(plain->data + plain->off + plain->len, &mlen,
                                                   NULL, buf + 4, L, buf, 4, nonce,
                                                   rx->key) != 0)
        return tf_seterr(err, errlen, "sealed record %llu failed authentication (altered, "
                         "replayed or reordered on the way)", (unsigned long long)rx->counter);
    rx->counter++;
    plain->len += (size_t)mlen;
    return (long)L + 4;
}
