/* opencl_cache.c: the on-disk cache of compiled OpenCL programs (opencl_cache.h), which spares
 * every OpenCL worker process the kernel build from source.  The directory is opened once and
 * checked (owner, mode) through its descriptor; entries are read and written relative to it
 * (openat, renameat), so a directory swapped after the check is never used. */
#include "worker/opencl_cache.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <sodium.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cachefile.h"
#include "le_bytes.h"
#include "log.h"
#include "worker/pocl_binary.h"

#define MAGIC "TFCLPRG\0"        /* 8 bytes */
#define FORMAT 1u                /* the header's layout and the key's recipe */
#define KEY_DOMAIN "terrafarm opencl program cache 2" /* 2: PoCL 3.1 binaries without IR */
#define MAX_BINARY ((size_t)256 << 20) /* a larger entry is not one of ours */
/* header layout: magic[8] format:u32 zero:u32 key[32] length:u64 checksum[32], little-endian */
enum { OFF_FORMAT = 8, OFF_ZERO = 12, OFF_KEY = 16, OFF_LENGTH = 48, OFF_SUM = 56 };

/* ---------------------------------------------------------------- the directory */

/* The cache directory (opencl_cache.h).  0, 1 when TF_OPENCL_CACHE=off, -1 when none is known. */
static int cache_dir(char *dir, size_t len)
{
    const char *env = getenv("TF_OPENCL_CACHE"), *xdg = getenv("XDG_CACHE_HOME");
    const char *home = getenv("HOME");
    int n;
    if (env && *env && strcmp(env, "off") == 0)
        return 1;
    if (env && *env)
        n = snprintf(dir, len, "%s", env);
    else if (xdg && *xdg)
        n = snprintf(dir, len, "%s/terrafarm/opencl", xdg);
    else if (home && *home)
        n = snprintf(dir, len, "%s/.cache/terrafarm/opencl", home);
    else
        return -1;
    return n > 0 && (size_t)n < len ? 0 : -1;
}

/* Create dir if absent and open it; refuse it unless it is a directory (not a symbolic link)
 * owned by this user and writable by nobody else.  The descriptor, or -1 with a message. */
static int open_checked_dir(const char *dir, char *err, size_t errlen)
{
    struct stat st;
    tf_make_private_dirs(dir); /* what it could not do, the checks below name */
    int fd = open(dir, O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
    if (fd < 0)
        return tf_seterr(err, errlen, "cannot open %s: %s", dir,
                         errno == ENOTDIR || errno == ELOOP ? "not a directory, or a symbolic link"
                                                            : strerror(errno));
    if (fstat(fd, &st) != 0 || st.st_uid != geteuid())
        tf_seterr(err, errlen, "%s is not owned by this user (uid %u)", dir, (unsigned)geteuid());
    else if (st.st_mode & (S_IWGRP | S_IWOTH))
        tf_seterr(err, errlen, "%s is writable by its group or others (mode %03o)", dir,
                  (unsigned)(st.st_mode & 0777));
    else
        return fd;
    close(fd);
    return -1;
}

/* ---------------------------------------------------------------- the key */

static uint64_t get_le(const unsigned char *p, int bytes)
{
    uint64_t v = 0;
    for (int i = bytes - 1; i >= 0; i--)
        v = v << 8 | p[i];
    return v;
}

/* A field of the key: its length, then its bytes, so no two field lists hash alike. */
static void hash_field(crypto_generichash_state *st, const void *p, size_t n)
{
    unsigned char len8[8];
    tf_le_put64(len8, n);
    crypto_generichash_update(st, len8, sizeof len8);
    crypto_generichash_update(st, p, n);
}

/* A string property of the platform (plat non-NULL) or of the device, as a field. */
static int hash_cl_text(crypto_generichash_state *st, cl_platform_id plat, cl_device_id dev,
                        cl_uint param)
{
    char text[4096];
    size_t n = 0;
    cl_int rc = plat ? clGetPlatformInfo(plat, param, sizeof text, text, &n)
                     : clGetDeviceInfo(dev, param, sizeof text, text, &n);
    if (rc != CL_SUCCESS || n > sizeof text)
        return -1;
    hash_field(st, text, n);
    return 0;
}

/* c->key and c->name for the program (opencl_cache.h says what the key covers). */
static int compute_key(tf_clcache *c, cl_device_id dev, cl_uint nsrc, const char *const *src,
                       const size_t *len, const char *options)
{
    crypto_generichash_state st;
    cl_platform_id plat = NULL;
    crypto_generichash_init(&st, NULL, 0, sizeof c->key);
    hash_field(&st, KEY_DOMAIN, strlen(KEY_DOMAIN));
    if (clGetDeviceInfo(dev, CL_DEVICE_PLATFORM, sizeof plat, &plat, NULL) != CL_SUCCESS ||
        hash_cl_text(&st, plat, NULL, CL_PLATFORM_NAME) ||
        hash_cl_text(&st, plat, NULL, CL_PLATFORM_VERSION) ||
        hash_cl_text(&st, NULL, dev, CL_DEVICE_NAME) ||
        hash_cl_text(&st, NULL, dev, CL_DEVICE_VERSION) ||
        hash_cl_text(&st, NULL, dev, CL_DRIVER_VERSION))
        return -1;
    hash_field(&st, options, strlen(options));
    for (cl_uint i = 0; i < nsrc; i++)
        hash_field(&st, src[i], len[i]);
    crypto_generichash_final(&st, c->key, sizeof c->key);
    sodium_bin2hex(c->name, sizeof c->name, c->key, sizeof c->key);
    strcat(c->name, ".bin");
    return 0;
}

/* ---------------------------------------------------------------- open and close */

int tf_clcache_open(tf_clcache *c, cl_device_id dev, cl_uint nsrc, const char *const *src,
                    const size_t *len, const char *options, char *err, size_t errlen)
{
    memset(c, 0, sizeof *c);
    c->dirfd = -1;
    c->state = TF_CLCACHE_OFF;
    if (err && errlen)
        err[0] = 0;
    int where = cache_dir(c->dir, sizeof c->dir);
    if (where > 0)
        return -1;
    c->state = TF_CLCACHE_REFUSED;
    if (where < 0)
        return tf_seterr(err, errlen, "no cache directory (set TF_OPENCL_CACHE or HOME)");
    if (sodium_init() < 0 || compute_key(c, dev, nsrc, src, len, options))
        return tf_seterr(err, errlen, "cannot compute the cache key of the program");
    c->dirfd = open_checked_dir(c->dir, err, errlen);
    if (c->dirfd < 0)
        return -1;
    c->state = TF_CLCACHE_MISS;
    return 0;
}

void tf_clcache_close(tf_clcache *c)
{
    if (c->dirfd >= 0)
        close(c->dirfd);
    c->dirfd = -1;
}

const char *tf_clcache_state_name(enum tf_clcache_state s)
{
    static const char *const names[] = {"off", "refused", "hit", "miss", "rebuilt"};
    return (unsigned)s < sizeof names / sizeof names[0] ? names[s] : "?";
}

/* ---------------------------------------------------------------- reading an entry */

/* Read the whole entry into *buf (*size bytes).  1 when there is none, 0 when read, -1 when
 * refused (not a regular file of this user's, writable by others, too short or too long). */
static int read_entry(const tf_clcache *c, unsigned char **buf, size_t *size, char *err,
                      size_t errlen)
{
    struct stat st;
    int fd = openat(c->dirfd, c->name, O_RDONLY | O_NOFOLLOW | O_CLOEXEC);
    if (fd < 0 && errno == ENOENT)
        return 1;
    if (fd < 0 || fstat(fd, &st) != 0 || !S_ISREG(st.st_mode) || st.st_uid != geteuid() ||
        (st.st_mode & (S_IWGRP | S_IWOTH)) || st.st_size < TF_CLCACHE_HEADER_BYTES ||
        (uint64_t)st.st_size > TF_CLCACHE_HEADER_BYTES + (uint64_t)MAX_BINARY) {
        if (fd >= 0)
            close(fd);
        return tf_seterr(err, errlen, "not a plain file of this user's of a plausible size");
    }
    *size = (size_t)st.st_size;
    *buf = malloc(*size);
    ssize_t got = *buf ? pread(fd, *buf, *size, 0) : -1;
    futimens(fd, NULL); /* its last use, for tf_clcache_prune */
    close(fd);
    if (got == (ssize_t)*size)
        return 0;
    free(*buf);
    return tf_seterr(err, errlen, "cannot read it");
}

/* The header of an entry of size bytes against the key and the binary that follows it. */
static int check_entry(const tf_clcache *c, const unsigned char *buf, size_t size, char *err,
                       size_t errlen)
{
    unsigned char sum[crypto_generichash_BYTES];
    size_t n = size - TF_CLCACHE_HEADER_BYTES;
    if (memcmp(buf, MAGIC, 8) != 0)
        return tf_seterr(err, errlen, "its magic is not a terrafarm OpenCL cache entry's");
    if (get_le(buf + OFF_FORMAT, 4) != FORMAT)
        return tf_seterr(err, errlen, "header format %u, expected %u",
                         (unsigned)get_le(buf + OFF_FORMAT, 4), FORMAT);
    if (get_le(buf + OFF_ZERO, 4) != 0)
        return tf_seterr(err, errlen, "the header's reserved word is not zero");
    if (memcmp(buf + OFF_KEY, c->key, sizeof c->key) != 0)
        return tf_seterr(err, errlen, "its key is another program's or device's");
    if (get_le(buf + OFF_LENGTH, 8) != n)
        return tf_seterr(err, errlen, "length %llu in the header, %zu bytes follow it",
                         (unsigned long long)get_le(buf + OFF_LENGTH, 8), n);
    crypto_generichash(sum, sizeof sum, buf + TF_CLCACHE_HEADER_BYTES, n, NULL, 0);
    if (memcmp(buf + OFF_SUM, sum, sizeof sum) != 0)
        return tf_seterr(err, errlen, "the binary's checksum differs from the header's");
    return 0;
}

/* The program from a binary, built for dev.  NULL with a message if the driver refuses it. */
static cl_program program_from_binary(cl_context ctx, cl_device_id dev, const unsigned char *bin,
                                      size_t n, const char *options, char *err, size_t errlen)
{
    cl_int rc, status = CL_SUCCESS;
    cl_program p = clCreateProgramWithBinary(ctx, 1, &dev, &n, &bin, &status, &rc);
    if (rc == CL_SUCCESS && status == CL_SUCCESS)
        rc = clBuildProgram(p, 1, &dev, options, NULL, NULL);
    if (rc == CL_SUCCESS && status == CL_SUCCESS)
        return p;
    if (p)
        clReleaseProgram(p);
    tf_seterr(err, errlen, "the driver rejected the stored binary: error %d, status %d", rc,
              status);
    return NULL;
}

cl_program tf_clcache_load(const tf_clcache *c, cl_context ctx, cl_device_id dev,
                           const char *options, char *err, size_t errlen)
{
    unsigned char *buf = NULL;
    size_t size = 0;
    if (err && errlen)
        err[0] = 0;
    if (c->dirfd < 0 || read_entry(c, &buf, &size, err, errlen) != 0)
        return NULL;
    cl_program p = NULL;
    if (check_entry(c, buf, size, err, errlen) == 0)
        p = program_from_binary(ctx, dev, buf + TF_CLCACHE_HEADER_BYTES,
                                size - TF_CLCACHE_HEADER_BYTES, options, err, errlen);
    free(buf);
    return p;
}

/* ---------------------------------------------------------------- writing an entry */

static int write_all(int fd, const unsigned char *p, size_t n)
{
    while (n > 0) {
        ssize_t w = write(fd, p, n);
        if (w < 0 && errno == EINTR)
            continue;
        if (w <= 0)
            return -1;
        p += w;
        n -= (size_t)w;
    }
    return 0;
}

static void make_header(unsigned char *h, const tf_clcache *c, const unsigned char *bin,
                        size_t len)
{
    memset(h, 0, TF_CLCACHE_HEADER_BYTES);
    memcpy(h, MAGIC, 8);
    tf_le_put32(h + OFF_FORMAT, FORMAT);
    memcpy(h + OFF_KEY, c->key, sizeof c->key);
    tf_le_put64(h + OFF_LENGTH, len);
    crypto_generichash(h + OFF_SUM, crypto_generichash_BYTES, bin, len, NULL, 0);
}

int tf_clcache_write(const tf_clcache *c, const unsigned char *bin, size_t len, char *err,
                     size_t errlen)
{
    unsigned char h[TF_CLCACHE_HEADER_BYTES];
    char tmp[sizeof c->name + 48];
    if (c->dirfd < 0)
        return tf_seterr(err, errlen, "the cache is not open");
    make_header(h, c, bin, len);
    snprintf(tmp, sizeof tmp, ".%.16s.%ld.%08x.tmp", c->name, (long)getpid(),
             (unsigned)randombytes_random());
    int fd = openat(c->dirfd, tmp, O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0600);
    int ok = fd >= 0 && write_all(fd, h, sizeof h) == 0 && write_all(fd, bin, len) == 0;
    ok = fd >= 0 && close(fd) == 0 && ok;
    if (ok && renameat(c->dirfd, tmp, c->dirfd, c->name) == 0)
        return 0;
    int e = errno;
    unlinkat(c->dirfd, tmp, 0);
    return tf_seterr(err, errlen, "cannot write %s/%s: %s", c->dir, c->name, strerror(e));
}

int tf_clcache_store(const tf_clcache *c, cl_program prog, char *err, size_t errlen)
{
    size_t n = 0;
    cl_int rc = clGetProgramInfo(prog, CL_PROGRAM_BINARY_SIZES, sizeof n, &n, NULL);
    if (rc != CL_SUCCESS || n == 0 || n > MAX_BINARY)
        return tf_seterr(err, errlen, "the driver gave no binary to store (error %d, %zu bytes)",
                         rc, n);
    unsigned char *bin = malloc(n);
    if (!bin)
        return tf_seterr(err, errlen, "out of memory for a %zu-byte binary", n);
    rc = clGetProgramInfo(prog, CL_PROGRAM_BINARIES, sizeof bin, &bin, NULL);
    if (rc != CL_SUCCESS) {
        free(bin);
        return tf_seterr(err, errlen, "cannot read the program's binary (error %d)", rc);
    }
    unsigned char *slim = NULL;
    size_t slim_n = 0;
    int r = tf_pocl_binary_without_ir(bin, n, c->key, &slim, &slim_n) == 1
                ? tf_clcache_write(c, slim, slim_n, err, errlen)
                : tf_clcache_write(c, bin, n, err, errlen);
    free(slim);
    free(bin);
    return r;
}

/* ---------------------------------------------------------------- pruning */

/* Are p[0..n) lowercase hex digits (sodium_bin2hex's)? */
static int is_hex(const char *p, size_t n)
{
    for (size_t i = 0; i < n; i++)
        if (!((p[i] >= '0' && p[i] <= '9') || (p[i] >= 'a' && p[i] <= 'f')))
            return 0;
    return 1;
}

/* Is name an entry's (64 lowercase hex digits and ".bin") or a temporary file of
 * tf_clcache_write's ("." 16 of those digits "." pid "." 8 hex digits ".tmp")? */
static int is_cache_name(const char *name)
{
    const size_t n = strlen(name), key = 2 * TF_CLCACHE_KEY_BYTES;
    if (n == key + 4 && is_hex(name, key) && strcmp(name + key, ".bin") == 0)
        return 1;
    const char *pid = name + 18, *dot = n > 30 ? name + n - 13 : NULL;
    if (!dot || name[0] != '.' || !is_hex(name + 1, 16) || name[17] != '.' || *dot != '.' ||
        !is_hex(dot + 1, 8) || strcmp(dot + 9, ".tmp") != 0 || pid == dot)
        return 0;
    for (const char *q = pid; q < dot; q++)
        if (*q < '0' || *q > '9')
            return 0;
    return 1;
}

int tf_clcache_prune(const tf_clcache *c, time_t now, long max_idle_s)
{
    int fd = c->dirfd >= 0 ? openat(c->dirfd, ".", O_RDONLY | O_DIRECTORY | O_CLOEXEC) : -1;
    DIR *d = fd >= 0 ? fdopendir(fd) : NULL;
    if (!d) {
        if (fd >= 0)
            close(fd);
        return -1;
    }
    int removed = 0;
    struct dirent *de;
    while ((de = readdir(d)) != NULL) {
        struct stat st;
        if (!is_cache_name(de->d_name) || strcmp(de->d_name, c->name) == 0 ||
            fstatat(fd, de->d_name, &st, AT_SYMLINK_NOFOLLOW) != 0)
            continue;
        if (S_ISREG(st.st_mode) && st.st_uid == geteuid() && st.st_mtime < now - max_idle_s &&
            unlinkat(fd, de->d_name, 0) == 0)
            removed++;
    }
    closedir(d); /* closes fd */
    return removed;
}
