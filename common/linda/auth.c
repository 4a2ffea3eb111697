/* auth.c: secret loading and the mutual HMAC-SHA256 challenge-response (see auth.h), plus the
 * loopback test the coordinator uses to decide whether --listen needs a secret. */
#include "linda/auth.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <sodium.h>
#include <stdio.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

#include "log.h"

static const char CLIENT_LABEL[] = "terrafarm-client";
static const char SERVER_LABEL[] = "terrafarm-server";

int tf_auth_init(void) { return sodium_init() < 0 ? -1 : 0; }

int tf_secret_from_bytes(const void *secret, size_t len, uint8_t key[TF_KEY_BYTES])
{
    if (len == 0 || tf_auth_init() != 0)
        return -1;
    crypto_hash_sha256(key, secret, len);
    return 0;
}

/* Read at most TF_SECRET_FILE_MAX + 1 bytes of fd into buf; returns the count or -1. */
static ssize_t read_bounded(int fd, uint8_t *buf, size_t cap)
{
    size_t got = 0;
    while (got < cap) {
        ssize_t n = read(fd, buf + got, cap - got);
        if (n < 0 && errno == EINTR)
            continue;
        if (n < 0)
            return -1;
        if (n == 0)
            break;
        got += (size_t)n;
    }
    return (ssize_t)got;
}

/* The secret file opened for reading, refused when its group or others may read it; the
 * descriptor, or -1 and a message. */
static int open_private(const char *path, char *err, size_t errlen)
{
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    if (fd < 0)
        return tf_seterr(err, errlen, "cannot read secret file %s: %s", path, strerror(errno));
    struct stat st;
    if (fstat(fd, &st) != 0) {
        int saved = errno;
        close(fd);
        return tf_seterr(err, errlen, "cannot stat secret file %s: %s", path, strerror(saved));
    }
    if (st.st_mode & (S_IRGRP | S_IROTH)) {
        /* Anyone who can read it can join the farm (and, with the frames sealed under keys
         * derived from it, read the scene): refuse rather than warn. */
        close(fd);
        return tf_seterr(err, errlen, "secret file %s is readable by %s (mode %04o): chmod 600 it",
                         path, (st.st_mode & S_IROTH) ? "others" : "its group",
                         (unsigned)(st.st_mode & 07777));
    }
    return fd;
}

/* The file's bytes into buf (TF_SECRET_FILE_MAX + 1), trailing line ends dropped, fd closed:
 * the count, or -1 and a message (a read error, a file too large or too short). */
static ssize_t read_secret(int fd, const char *path, uint8_t *buf, char *err, size_t errlen)
{
    ssize_t n = read_bounded(fd, buf, TF_SECRET_FILE_MAX + 1);
    int saved = errno;
    close(fd);
    if (n < 0)
        return tf_seterr(err, errlen, "cannot read secret file %s: %s", path, strerror(saved));
    if (n > TF_SECRET_FILE_MAX)
        return tf_seterr(err, errlen, "secret file %s is larger than %d bytes", path,
                         TF_SECRET_FILE_MAX);
    while (n > 0 && (buf[n - 1] == '\n' || buf[n - 1] == '\r'))
        n--;
    if (n > 0 && n < TF_SECRET_MIN_BYTES)
        return tf_seterr(err, errlen, "secret file %s holds %zd bytes; at least %d are needed "
                         "(e.g. head -c 32 /dev/urandom | od -An -tx1 >%s)", path, n,
                         TF_SECRET_MIN_BYTES, path);
    return n;
}

int tf_secret_load(const char *path, uint8_t key[TF_KEY_BYTES], char *err, size_t errlen)
{
    int fd = open_private(path, err, errlen);
    if (fd < 0)
        return -1;
    uint8_t buf[TF_SECRET_FILE_MAX + 1];
    ssize_t n = read_secret(fd, path, buf, err, errlen);
    int rc = n < 0 ? -1 : tf_secret_from_bytes(buf, (size_t)n, key);
    sodium_memzero(buf, sizeof buf);
    if (n >= 0 && rc != 0)
        tf_seterr(err, errlen, "secret file %s is empty", path);
    return rc != 0 ? -1 : 0;
}

void tf_auth_nonce(uint8_t nonce[TF_NONCE_BYTES])
{
    if (tf_auth_init() != 0)
        tf_die(70, "libsodium failed to initialise");
    randombytes_buf(nonce, TF_NONCE_BYTES);
}

/* HMAC-SHA256(key, label || ns || nc). */
static void mac_over(const uint8_t key[TF_KEY_BYTES], const char *label,
                     const uint8_t ns[TF_NONCE_BYTES], const uint8_t nc[TF_NONCE_BYTES],
                     uint8_t mac[TF_MAC_BYTES])
{
    crypto_auth_hmacsha256_state st;
    crypto_auth_hmacsha256_init(&st, key, TF_KEY_BYTES);
    crypto_auth_hmacsha256_update(&st, (const unsigned char *)label, strlen(label));
    crypto_auth_hmacsha256_update(&st, ns, TF_NONCE_BYTES);
    crypto_auth_hmacsha256_update(&st, nc, TF_NONCE_BYTES);
    crypto_auth_hmacsha256_final(&st, mac);
    sodium_memzero(&st, sizeof st);
}

void tf_auth_client_mac(const uint8_t key[TF_KEY_BYTES], const uint8_t ns[TF_NONCE_BYTES],
                        const uint8_t nc[TF_NONCE_BYTES], uint8_t mac[TF_MAC_BYTES])
{
    mac_over(key, CLIENT_LABEL, ns, nc, mac);
}

void tf_auth_server_mac(const uint8_t key[TF_KEY_BYTES], const uint8_t ns[TF_NONCE_BYTES],
                        const uint8_t nc[TF_NONCE_BYTES], uint8_t mac[TF_MAC_BYTES])
{
    mac_over(key, SERVER_LABEL, ns, nc, mac);
}

int tf_auth_client_mac_ok(const uint8_t key[TF_KEY_BYTES], const uint8_t ns[TF_NONCE_BYTES],
                          const uint8_t nc[TF_NONCE_BYTES], const uint8_t mac[TF_MAC_BYTES])
{
    uint8_t want[TF_MAC_BYTES];
    tf_auth_client_mac(key, ns, nc, want);
    return crypto_verify_32(want, mac) == 0;
}

int tf_auth_server_mac_ok(const uint8_t key[TF_KEY_BYTES], const uint8_t ns[TF_NONCE_BYTES],
                          const uint8_t nc[TF_NONCE_BYTES], const uint8_t mac[TF_MAC_BYTES])
{
    uint8_t want[TF_MAC_BYTES];
    tf_auth_server_mac(key, ns, nc, want);
    return crypto_verify_32(want, mac) == 0;
}
