/* farm_keys.h: the keys and tokens of a standing farm (terrafarm farm), derived where both
 * sides must agree and random where a person is named.
 *
 * Workers hold the farm's secret (--secret-file, linda/auth.h).  From it they derive their
 * bearer token for the farm's API and, for each job they are sent to, that job's tuple-space
 * key (from the job's id and a random nonce the farm chose): the farm secret itself never
 * crosses the network, each job's render has its own key, and an assignment is useless to
 * anyone without the secret.  People (submitters, admins) get random tokens that the farm
 * stores only as hashes (coordinator/farm/farmdb.h, Q3). */
#ifndef TF_FARM_KEYS_H
#define TF_FARM_KEYS_H

#include <stddef.h>
#include <stdint.h>

#define TF_FARM_TOKEN_HEX 65 /* 64 hex digits and a NUL */

/* The workers' bearer token for the farm's API, from the farm secret: 0 or -1. */
int tf_farm_worker_token(const uint8_t key[32], char out[TF_FARM_TOKEN_HEX]);
/* Job id's tuple-space secret from the farm secret and the job's nonce, as the 64 hex digits
 * the farm writes to the job's secret file; both sides turn it into the job's key with
 * tf_secret_from_bytes (linda/auth.h).  0 or -1. */
int tf_farm_job_secret(const uint8_t key[32], int64_t job, const char *nonce,
                       char out[TF_FARM_TOKEN_HEX]);
/* A new random person's token (hex): 0 or -1. */
int tf_farm_token_new(char out[TF_FARM_TOKEN_HEX]);
/* What the farm stores of a token: its SHA-256 (hex).  Tokens are 256 random bits, so a
 * plain hash is as good as a slow one. */
void tf_farm_token_hash(const char *token, char out[TF_FARM_TOKEN_HEX]);
/* What a worker keeps a built terrain under: SHA-256 of the scene's canonical [terrain] and
 * [erosion] text without the height map's path (a job's copy of a map has another path than
 * the submitter's; its bytes' SHA-256 stays in the text).  0 or -1 (out of memory). */
struct tf_scene;
int tf_farm_terrain_key(const struct tf_scene *s, char out[TF_FARM_TOKEN_HEX]);
/* A random nonce of 16 bytes (32 hex digits). */
int tf_farm_nonce_new(char out[33]);

#endif
