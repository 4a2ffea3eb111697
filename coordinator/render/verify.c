/* verify.c: see verify.h. */
#include "coordinator/render/verify.h"

#include <sodium.h>

uint64_t tf_verify_seed(void)
{
    uint64_t seed;
    randombytes_buf(&seed, sizeof seed);
    return seed;
}

/* splitmix64: a well-mixed 64-bit value of (seed, id). */
static uint64_t mix(uint64_t x)
{
    x += 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}

int tf_verify_selected(uint64_t seed, double fraction, int64_t id)
{
    if (fraction <= 0)
        return 0;
    if (fraction >= 1)
        return 1;
    double u = (double)(mix(seed ^ mix((uint64_t)id)) >> 11) * (1.0 / 9007199254740992.0);
    return u < fraction;
}

void tf_result_digest(const tf_result_msg *m, uint8_t out[TF_DIGEST_BYTES])
{
    crypto_generichash_state st;
    crypto_generichash_init(&st, NULL, 0, TF_DIGEST_BYTES);
    crypto_generichash_update(&st, m->index, m->nchunks * TF_CHUNK_RECORD_BYTES);
    crypto_generichash_update(&st, m->chunks, m->chunks_len);
    crypto_generichash_update(&st, m->preview, m->preview_len);
    crypto_generichash_final(&st, out, TF_DIGEST_BYTES);
}
