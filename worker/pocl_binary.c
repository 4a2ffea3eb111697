/* pocl_binary.c: see pocl_binary.h.  The layout read here is PoCL 3.1's (lib/CL/pocl_binary.c),
 * all integers little-endian:
 *
 *   header    "poclbin\0", device id u64, version u32, kernels u32, flags u64,
 *             root entries u32, build hash char[41] ("XY/" and 37 letters A-P, NUL)
 *   root      per entry: its size in bytes u64, then files
 *   kernel    per kernel: record size u64, files' size u64, arginfo size u32, name (u32 length,
 *             bytes), metadata; the record's last `files' size` bytes are its files
 *   file      path (u32 length, bytes, relative to the program's directory), content (u32
 *             length, bytes)
 *
 * Every size is checked against the bytes there are before it is used. */
#include "worker/pocl_binary.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "le_bytes.h"

#define MAGIC "poclbin" /* with its NUL, 8 bytes */
#define HASH_BYTES 41   /* SHA1_digest_t: 40 letters and a NUL */
enum { OFF_VERSION = 16, OFF_KERNELS = 20, OFF_ROOTS = 32, OFF_HASH = 36 };
#define HEADER_BYTES (OFF_HASH + HASH_BYTES)
#define PLACEHOLDER "/terrafarm-no-ir" /* the root entry's one file once program.bc is gone */
#define PROGRAM_BC "/program.bc"

/* A window on the binary; every take fails once past `end`. */
typedef struct {
    const unsigned char *p, *end;
} reader;

static int take(reader *r, size_t n, const unsigned char **at)
{
    if ((size_t)(r->end - r->p) < n)
        return -1;
    if (at)
        *at = r->p;
    r->p += n;
    return 0;
}

static int take_u32(reader *r, uint32_t *v)
{
    const unsigned char *at;
    if (take(r, 4, &at))
        return -1;
    *v = tf_le_get32(at);
    return 0;
}

static int take_u64(reader *r, uint64_t *v)
{
    const unsigned char *at;
    if (take(r, 8, &at))
        return -1;
    *v = tf_le_get64(at);
    return 0;
}

/* A length-prefixed string: its bytes at *s, its length in *len. */
static int take_str(reader *r, const unsigned char **s, uint32_t *len)
{
    return take_u32(r, len) || take(r, *len, s) ? -1 : 0;
}

/* A window of n bytes taken from r. */
static int sub(reader *r, uint64_t n, reader *w)
{
    if ((uint64_t)(r->end - r->p) < n)
        return -1;
    w->p = r->p;
    w->end = r->p + n;
    r->p += n;
    return 0;
}

typedef struct {
    const unsigned char *path, *content;
    uint32_t path_len, content_len;
} pfile;

static int take_file(reader *r, pfile *f)
{
    return take_str(r, &f->path, &f->path_len) || take_str(r, &f->content, &f->content_len);
}

static int path_is(const pfile *f, const char *s)
{
    return f->path_len == strlen(s) && memcmp(f->path, s, f->path_len) == 0;
}

/* ---------------------------------------------------------------- the parts */

/* The header: 1 when it is a poclbin of our version with one root entry, 0 when not (another
 * format, version or layout), -1 when a poclbin's header is cut short. */
static int read_header(reader *r, uint32_t *kernels)
{
    const unsigned char *h;
    if ((size_t)(r->end - r->p) < sizeof MAGIC || memcmp(r->p, MAGIC, sizeof MAGIC) != 0)
        return 0;
    if (take(r, HEADER_BYTES, &h))
        return -1;
    if (tf_le_get32(h + OFF_VERSION) != TF_POCL_BINARY_VERSION)
        return 0;
    *kernels = tf_le_get32(h + OFF_KERNELS);
    return tf_le_get32(h + OFF_ROOTS) == 1 ? 1 : 0;
}

/* The root entry: 1 when it is program.bc alone, 0 when it holds anything else, -1 when
 * malformed.  *bitcode tells whether a file of it starts with LLVM bitcode's magic. */
static int read_root(reader *r, int *bitcode)
{
    uint64_t bytes;
    reader w;
    pfile f;
    int only_program = 1, files = 0;
    *bitcode = 0;
    if (take_u64(r, &bytes) || sub(r, bytes, &w))
        return -1;
    for (; w.p < w.end; files++) {
        if (take_file(&w, &f))
            return -1;
        only_program &= path_is(&f, PROGRAM_BC);
        *bitcode |= f.content_len >= 4 && memcmp(f.content, "BC\xc0\xde", 4) == 0;
    }
    return only_program && files == 1;
}

/* One kernel's record: 1 when its files include a generic work-group function
 * (/NAME/0-0-0/NAME.so, not empty), 0 when not, -1 when malformed. */
static int read_kernel(reader *r)
{
    uint64_t size, files_size;
    uint32_t arginfo, name_len;
    const unsigned char *name;
    char want[600];
    reader rec, files;
    pfile f;
    int generic = 0;
    if (take_u64(r, &size) || size < 20 || sub(r, size - 8, &rec) ||
        take_u64(&rec, &files_size) || take_u32(&rec, &arginfo) ||
        take_str(&rec, &name, &name_len) || files_size > (uint64_t)(rec.end - rec.p))
        return -1;
    if (name_len == 0 || name_len > 256 || memchr(name, '/', name_len) || memchr(name, 0, name_len))
        return 0;
    snprintf(want, sizeof want, "/%.*s/0-0-0/%.*s.so", (int)name_len, (const char *)name,
             (int)name_len, (const char *)name);
    files.p = rec.end - files_size;
    files.end = rec.end;
    while (files.p < files.end) {
        if (take_file(&files, &f))
            return -1;
        generic |= path_is(&f, want) && f.content_len > 0;
    }
    return generic;
}

/* The whole binary read: 1 when the rewrite applies, 0 when not, -1 when malformed.  *kernels_at
 * is where the kernels' records begin; *bitcode as read_root gives it. */
static int read_binary(const unsigned char *bin, size_t n, const unsigned char **kernels_at,
                       int *bitcode)
{
    reader r = {bin, bin + n};
    uint32_t kernels;
    int ok = read_header(&r, &kernels);
    if (ok <= 0)
        return ok;
    ok = read_root(&r, bitcode);
    *kernels_at = r.p;
    for (uint32_t k = 0; ok >= 0 && k < kernels; k++) {
        int generic = read_kernel(&r);
        ok = generic < 0 ? -1 : ok && generic;
    }
    return ok >= 0 && r.p != r.end ? -1 : ok;
}

/* ---------------------------------------------------------------- the rewrite */

/* PoCL's build hash alphabet: a byte as two letters A-P, low nibble first; "XY/" in front. */
static void build_hash_from(const unsigned char tag[TF_POCL_TAG_BYTES], unsigned char *hash)
{
    for (int i = 0; i < TF_POCL_TAG_BYTES; i++) {
        hash[2 * i] = (unsigned char)('A' + (tag[i] & 0x0f));
        hash[2 * i + 1] = (unsigned char)('A' + (tag[i] >> 4));
    }
    hash[2] = '/';
    hash[HASH_BYTES - 1] = 0;
}

int tf_pocl_binary_without_ir(const unsigned char *bin, size_t n,
                              const unsigned char tag[TF_POCL_TAG_BYTES], unsigned char **out,
                              size_t *outn)
{
    const unsigned char *kernels_at = NULL;
    int bitcode, ok = read_binary(bin, n, &kernels_at, &bitcode);
    *out = NULL;
    if (ok <= 0) /* kernels_at may be unset: nothing below may use it */
        return ok;
    size_t placeholder = strlen(PLACEHOLDER), root = 4 + placeholder + 4;
    size_t tail = (size_t)(bin + n - kernels_at);
    unsigned char *o = malloc(HEADER_BYTES + 8 + root + tail);
    if (!o)
        return -1;
    memcpy(o, bin, HEADER_BYTES);
    build_hash_from(tag, o + OFF_HASH);
    unsigned char *p = o + HEADER_BYTES;
    tf_le_put64(p, root);
    tf_le_put32(p + 8, (uint32_t)placeholder);
    memcpy(p + 12, PLACEHOLDER, placeholder);
    tf_le_put32(p + 12 + placeholder, 0);
    memcpy(p + 8 + root, kernels_at, tail);
    *out = o;
    *outn = HEADER_BYTES + 8 + root + tail;
    return 1;
}

int tf_pocl_binary_has_ir(const unsigned char *bin, size_t n)
{
    reader r = {bin, bin + n};
    uint32_t kernels;
    int bitcode;
    if (read_header(&r, &kernels) != 1 || read_root(&r, &bitcode) < 0)
        return -1;
    return bitcode;
}
