/* farm_keys.c: see farm_keys.h. */
#include "farm_keys.h"

#include <sodium.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "scene.h"

static const char worker_context[] = "terrafarm farm worker token v1";

int tf_farm_worker_token(const uint8_t key[32], char out[TF_FARM_TOKEN_HEX])
{
    uint8_t h[32];
    if (sodium_init() < 0 ||
        crypto_generichash(h, sizeof h, (const unsigned char *)worker_context,
                           sizeof worker_context - 1, key, 32))
        return -1;
    sodium_bin2hex(out, TF_FARM_TOKEN_HEX, h, sizeof h);
    sodium_memzero(h, sizeof h);
    return 0;
}

int tf_farm_job_secret(const uint8_t key[32], int64_t job, const char *nonce,
                       char out[TF_FARM_TOKEN_HEX])
{
    char msg[128];
    uint8_t h[32];
    int n = snprintf(msg, sizeof msg, "terrafarm job key v1 %lld %s", (long long)job, nonce);
    if (n <= 0 || n >= (int)sizeof msg || sodium_init() < 0 ||
        crypto_generichash(h, sizeof h, (const unsigned char *)msg, (size_t)n, key, 32))
        return -1;
    sodium_bin2hex(out, TF_FARM_TOKEN_HEX, h, sizeof h);
    sodium_memzero(h, sizeof h);
    return 0;
}

static int random_hex(char *out, size_t bytes)
{
    uint8_t b[32];
    if (bytes > sizeof b || sodium_init() < 0)
        return -1;
    randombytes_buf(b, bytes);
    sodium_bin2hex(out, 2 * bytes + 1, b, bytes);
    return 0;
}

int tf_farm_token_new(char out[TF_FARM_TOKEN_HEX])
{
    return random_hex(out, 32);
}

int tf_farm_nonce_new(char out[33])
{
    return random_hex(out, 16);
}

void tf_farm_token_hash(const char *token, char out[TF_FARM_TOKEN_HEX])
{
    uint8_t h[32];
    crypto_hash_sha256(h, (const unsigned char *)token, strlen(token));
    sodium_bin2hex(out, TF_FARM_TOKEN_HEX, h, sizeof h);
}

int tf_farm_terrain_key(const tf_scene *s, char out[TF_FARM_TOKEN_HEX])
{
    char *text = tf_scene_canonical_terrain(s);
    if (!text)
        return -1;
    for (char *line = text; line && *line;) { /* drop the "path = ..." line */
        char *nl = strchr(line, '\n');
        if (!strncmp(line, "path = ", 7)) {
            memmove(line, nl ? nl + 1 : line + strlen(line), strlen(nl ? nl + 1 : "") + 1);
            continue;
        }
        line = nl ? nl + 1 : NULL;
    }
    uint8_t h[32];
    crypto_hash_sha256(h, (const unsigned char *)text, strlen(text));
    sodium_bin2hex(out, TF_FARM_TOKEN_HEX, h, sizeof h);
    free(text);
    return 0;
}
