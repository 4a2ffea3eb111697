/* httpauth.h: the dashboard's token.  On loopback the dashboard needs none; anywhere else every
 * request must carry one (Authorization: Bearer TOKEN, or the tf_token cookie for a browser),
 * and every control (POST) must carry it in a header.  The token is the text of
 * --http-token-file, or else derived from the farm secret (--secret-file) with a keyed BLAKE2b
 * hash, so that a farm with a secret needs no second file; `terrafarm status --secret-file`
 * derives the same token.  Used by the coordinator and by the status command. */
#ifndef TF_HTTPAUTH_H
#define TF_HTTPAUTH_H

#include <stddef.h>
#include <stdint.h>

#define TF_HTTP_TOKEN_MAX 256

/* 64 hex digits from the 32-byte farm key (linda/auth.h tf_secret_load).  0 or -1. */
int tf_http_token_derive(const uint8_t *key, char *out, size_t outlen);
/* The token in a file: its first line without surrounding white space, 16 to
 * TF_HTTP_TOKEN_MAX printable characters without spaces, quotes, ';' or ','.  0, or -1 with a
 * message naming the file. */
int tf_http_token_load(const char *path, char *out, size_t outlen, char *err, size_t errlen);
/* 1 if the n bytes at given equal the token, compared in constant time. */
int tf_http_token_matches(const char *token, const char *given, size_t n);

#endif
