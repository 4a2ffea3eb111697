/* test_pocl_binary.c: PoCL 3.1 binaries rewritten without their LLVM IR (worker/pocl_binary.c).
 *
 *   rewrites_root_and_hash     a built binary of two kernels: the root entry becomes the empty
 *                              placeholder, the build hash one in PoCL's alphabet made from the
 *                              tag (another tag, another hash), the kernels' records the same
 *                              bytes; has_ir says 1 before and 0 after.
 *   leaves_other_binaries      other magic, other versions, a root entry with more than
 *                              program.bc, a kernel with only a specialised function or an empty
 *                              generic one: 0, nothing allocated.
 *   refuses_malformed          every cut of a good binary, a size field past the end, bytes
 *                              after the last kernel: -1 (or 0 when too short to be a poclbin),
 *                              never a read past the end (ASan runs this in make asan).
 *   pocl_runs_it_without_ir    on PoCL: a program built from source gives a binary with IR; the
 *                              rewritten one is created and built in a fresh POCL_CACHE_DIR, its
 *                              kernel runs and writes what it should, and no program.bc appears
 *                              in PoCL's directory for it (so nothing was there to parse).
 * The last test skips without an OpenCL platform, or where the platform writes another format. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <cmocka.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#define CL_TARGET_OPENCL_VERSION 120
#include <CL/cl.h>

#include "le_bytes.h"
#include "scratch_dir.h"
#include "worker/pocl_binary.h"

#define HASH_AT 36
#define HASH_BYTES 41

/* ---------------------------------------------------------------- building binaries */

typedef struct {
    unsigned char b[4096];
    size_t n;
} buf;

static void put(buf *o, const void *p, size_t n)
{
    assert_true(o->n + n <= sizeof o->b);
    memcpy(o->b + o->n, p, n);
    o->n += n;
}

static void put32(buf *o, uint32_t v)
{
    unsigned char t[4];
    tf_le_put32(t, v);
    put(o, t, 4);
}

static void put64(buf *o, uint64_t v)
{
    unsigned char t[8];
    tf_le_put64(t, v);
    put(o, t, 8);
}

static void put_file(buf *o, const char *path, const char *content)
{
    put32(o, (uint32_t)strlen(path));
    put(o, path, strlen(path));
    put32(o, (uint32_t)strlen(content));
    put(o, content, strlen(content));
}

static void put_header(buf *o, uint32_t version, uint32_t kernels)
{
    put(o, "poclbin", 8);
    put64(o, 0x1234567890abcdefull);
    put32(o, version);
    put32(o, kernels);
    put64(o, 4ull << 32);
    put32(o, 1);
    put(o, "BN/GBCGNEJOJFJOLGFCFMJOKOIJPKGCNCLCNACJG", HASH_BYTES);
}

/* A root entry of the given files (path, content, path, content, ..., NULL). */
static void put_root(buf *o, ...)
{
    buf files = {.n = 0};
    va_list ap;
    va_start(ap, o);
    for (const char *p; (p = va_arg(ap, const char *));)
        put_file(&files, p, va_arg(ap, const char *));
    va_end(ap);
    put64(o, files.n);
    put(o, files.b, files.n);
}

/* A kernel record named `name` whose files are one function in the directory `variant`. */
static void put_kernel(buf *o, const char *name, const char *variant, const char *so)
{
    buf files = {.n = 0}, meta = {.n = 0};
    char path[256];
    snprintf(path, sizeof path, "/%s/%s/%s.so", name, variant, name);
    put_file(&files, path, so);
    put32(&meta, (uint32_t)strlen(name));
    put(&meta, name, strlen(name));
    put(&meta, "metadata: args, locals, attributes", 34);
    put64(o, 8 + 8 + 4 + meta.n + files.n);
    put64(o, files.n);
    put32(o, 5);
    put(o, meta.b, meta.n);
    put(o, files.b, files.n);
}

/* What PoCL 3.1 writes for a program of two kernels. */
static buf good_binary(void)
{
    buf o = {.n = 0};
    put_header(&o, TF_POCL_BINARY_VERSION, 2);
    put_root(&o, "/program.bc", "BC\xc0\xde and the rest of the module", (char *)NULL);
    put_kernel(&o, "tf_one", "0-0-0", "\x7f" "ELF one");
    put_kernel(&o, "tf_two", "0-0-0", "\x7f" "ELF two");
    return o;
}

static const unsigned char tag_a[TF_POCL_TAG_BYTES] = {0x12, 0x34, 0x56, 0x78, 0x9a, 0xbc, 0xde};
static const unsigned char tag_b[TF_POCL_TAG_BYTES] = {0x12, 0x34, 0x56, 0x78, 0x9a, 0xbc, 0xdf};

/* Where the kernels' records start in a binary with the given root entry size. */
static size_t kernels_at(const unsigned char *b)
{
    return HASH_AT + HASH_BYTES + 8 + tf_le_get64(b + HASH_AT + HASH_BYTES);
}

/* ---------------------------------------------------------------- tests */

static void rewrites_root_and_hash(void **state)
{
    (void)state;
    buf in = good_binary();
    unsigned char *a = NULL, *b = NULL;
    size_t an = 0, bn = 0;
    assert_int_equal(tf_pocl_binary_has_ir(in.b, in.n), 1);
    assert_int_equal(tf_pocl_binary_without_ir(in.b, in.n, tag_a, &a, &an), 1);
    assert_int_equal(tf_pocl_binary_without_ir(in.b, in.n, tag_b, &b, &bn), 1);
    assert_int_equal(tf_pocl_binary_has_ir(a, an), 0);
    assert_memory_equal(a, in.b, HASH_AT);                     /* magic ... root count */
    assert_memory_equal(a + HASH_AT, "CB/", 3);                /* 0x12: low nibble first */
    for (int i = 3; i < HASH_BYTES - 1; i++)
        assert_true(a[HASH_AT + i] >= 'A' && a[HASH_AT + i] <= 'P');
    assert_int_equal(a[HASH_AT + HASH_BYTES - 1], 0);
    assert_memory_not_equal(a + HASH_AT, b + HASH_AT, HASH_BYTES);
    assert_memory_not_equal(a + HASH_AT, in.b + HASH_AT, HASH_BYTES);
    buf root = {.n = 0};
    put_root(&root, "/terrafarm-no-ir", "", (char *)NULL);
    assert_memory_equal(a + HASH_AT + HASH_BYTES, root.b, root.n);
    size_t ka = kernels_at(a), ki = kernels_at(in.b);
    assert_int_equal(an - ka, in.n - ki);
    assert_memory_equal(a + ka, in.b + ki, in.n - ki);
    free(a);
    free(b);
}

static void expect_left(const buf *in, const char *what)
{
    unsigned char *out = (unsigned char *)1;
    size_t n = 0;
    print_message("%s\n", what);
    assert_int_equal(tf_pocl_binary_without_ir(in->b, in->n, tag_a, &out, &n), 0);
    assert_null(out);
}

static void leaves_other_binaries(void **state)
{
    (void)state;
    buf o = good_binary();
    memcpy(o.b, "BC\xc0\xde", 4);
    expect_left(&o, "LLVM bitcode, not a poclbin");
    for (uint32_t v = 8; v <= 12; v += 3) {
        o = good_binary();
        tf_le_put32(o.b + 16, v);
        expect_left(&o, "another poclbin version");
    }
    o = (buf){.n = 0};
    put_header(&o, TF_POCL_BINARY_VERSION, 1);
    put_root(&o, "/program.bc", "BC\xc0\xde", "/other", "x", (char *)NULL);
    put_kernel(&o, "tf_one", "0-0-0", "\x7f" "ELF");
    expect_left(&o, "a root entry with more than program.bc");
    o = (buf){.n = 0};
    put_header(&o, TF_POCL_BINARY_VERSION, 2);
    put_root(&o, "/program.bc", "BC\xc0\xde", (char *)NULL);
    put_kernel(&o, "tf_one", "0-0-0", "\x7f" "ELF");
    put_kernel(&o, "tf_two", "1-1-1-goffs0-smallgrid", "\x7f" "ELF");
    expect_left(&o, "a kernel with only a specialised function");
    o = (buf){.n = 0};
    put_header(&o, TF_POCL_BINARY_VERSION, 1);
    put_root(&o, "/program.bc", "BC\xc0\xde", (char *)NULL);
    put_kernel(&o, "tf_one", "0-0-0", "");
    expect_left(&o, "an empty generic function");
}

static void expect_refused(const unsigned char *b, size_t n, int allowed_zero)
{
    unsigned char *out = (unsigned char *)1;
    size_t on = 0;
    int r = tf_pocl_binary_without_ir(b, n, tag_a, &out, &on);
    if (r != -1 && !(allowed_zero && r == 0))
        print_message("%zu bytes: %d\n", n, r);
    assert_true(r == -1 || (allowed_zero && r == 0));
    assert_null(out);
}

static void refuses_malformed(void **state)
{
    (void)state;
    buf good = good_binary();
    for (size_t n = 0; n < good.n; n++) { /* each cut on a heap block of its own size */
        unsigned char *cut = malloc(n ? n : 1);
        memcpy(cut, good.b, n);
        expect_refused(cut, n, n < 8);
        free(cut);
    }
    buf o = good_binary();
    tf_le_put64(o.b + HASH_AT + HASH_BYTES, 1u << 20); /* the root entry's size */
    expect_refused(o.b, o.n, 0);
    o = good_binary();
    tf_le_put64(o.b + kernels_at(o.b), 1ull << 62); /* the first kernel's record size */
    expect_refused(o.b, o.n, 0);
    o = good_binary();
    tf_le_put64(o.b + kernels_at(o.b) + 8, 1u << 20); /* its files' size */
    expect_refused(o.b, o.n, 0);
    o = good_binary();
    put(&o, "x", 1);
    expect_refused(o.b, o.n, 0);
}

/* ---------------------------------------------------------------- on PoCL */

static const char *kernel_src =
    "kernel void tf_put(global int *a) { a[get_global_id(0)] = 7 * (int)get_global_id(0) + 1; }\n";

static cl_program built(cl_context ctx, cl_device_id dev, const unsigned char *bin, size_t n)
{
    cl_int rc, status;
    cl_program p = bin ? clCreateProgramWithBinary(ctx, 1, &dev, &n, &bin, &status, &rc)
                       : clCreateProgramWithSource(ctx, 1, &kernel_src, NULL, &rc);
    assert_int_equal(rc, CL_SUCCESS);
    assert_int_equal(clBuildProgram(p, 1, &dev, "", NULL, NULL), CL_SUCCESS);
    return p;
}

static unsigned char *binary_of(cl_program p, size_t *n)
{
    assert_int_equal(clGetProgramInfo(p, CL_PROGRAM_BINARY_SIZES, sizeof *n, n, NULL),
                     CL_SUCCESS);
    unsigned char *b = malloc(*n);
    assert_int_equal(clGetProgramInfo(p, CL_PROGRAM_BINARIES, sizeof b, &b, NULL), CL_SUCCESS);
    return b;
}

/* Run tf_put over 64 work-items, one a group, and check what it wrote. */
static void runs_right(cl_context ctx, cl_device_id dev, cl_program p)
{
    cl_int rc;
    int out[64];
    size_t global = 64, local = 1;
    cl_kernel k = clCreateKernel(p, "tf_put", &rc);
    assert_int_equal(rc, CL_SUCCESS);
    cl_mem m = clCreateBuffer(ctx, CL_MEM_WRITE_ONLY, sizeof out, NULL, &rc);
    cl_command_queue q = clCreateCommandQueue(ctx, dev, 0, &rc);
    assert_int_equal(clSetKernelArg(k, 0, sizeof m, &m), CL_SUCCESS);
    assert_int_equal(clEnqueueNDRangeKernel(q, k, 1, NULL, &global, &local, 0, NULL, NULL),
                     CL_SUCCESS);
    assert_int_equal(clEnqueueReadBuffer(q, m, CL_TRUE, 0, sizeof out, out, 0, NULL, NULL),
                     CL_SUCCESS);
    for (int i = 0; i < 64; i++)
        assert_int_equal(out[i], 7 * i + 1);
    clReleaseCommandQueue(q);
    clReleaseMemObject(m);
    clReleaseKernel(k);
}

static void pocl_runs_it_without_ir(void **state)
{
    (void)state;
    cl_platform_id plat;
    cl_device_id dev;
    cl_uint np = 0;
    if (clGetPlatformIDs(1, &plat, &np) != CL_SUCCESS || np == 0 ||
        clGetDeviceIDs(plat, CL_DEVICE_TYPE_ALL, 1, &dev, NULL) != CL_SUCCESS) {
        print_message("no OpenCL platform: skipping\n");
        skip();
    }
    cl_context ctx = clCreateContext(NULL, 1, &dev, NULL, NULL, NULL);
    assert_non_null(ctx);
    size_t n, slim_n;
    cl_program from_source = built(ctx, dev, NULL, 0);
    unsigned char *bin = binary_of(from_source, &n), *slim = NULL;
    int r = tf_pocl_binary_without_ir(bin, n, tag_a, &slim, &slim_n);
    if (r == 0) {
        print_message("the platform's binary is not PoCL 3.1's: skipping\n");
        skip();
    }
    assert_int_equal(r, 1);
    assert_int_equal(tf_pocl_binary_has_ir(bin, n), 1);
    assert_int_equal(tf_pocl_binary_has_ir(slim, slim_n), 0);
    cl_program p = built(ctx, dev, slim, slim_n);
    runs_right(ctx, dev, p);
    char dir[600];
    struct stat st;
    snprintf(dir, sizeof dir, "%s/%.40s", scratch_path("pocl"), (const char *)slim + HASH_AT);
    assert_int_equal(stat(dir, &st), 0); /* PoCL unpacked the binary there */
    snprintf(dir, sizeof dir, "%s/%.40s/program.bc", scratch_path("pocl"),
             (const char *)slim + HASH_AT);
    assert_int_not_equal(stat(dir, &st), 0);
    clReleaseProgram(p);
    clReleaseProgram(from_source);
    clReleaseContext(ctx);
    free(bin);
    free(slim);
}

/* PoCL reads POCL_CACHE_DIR once, at its first call: a fresh one of the scratch directory's. */
static int setup(void **state)
{
    if (scratch_dir_make(state))
        return -1;
    setenv("POCL_CACHE_DIR", scratch_path("pocl"), 1);
    return mkdir(scratch_path("pocl"), 0700);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(rewrites_root_and_hash),
        cmocka_unit_test(leaves_other_binaries),
        cmocka_unit_test(refuses_malformed),
        cmocka_unit_test(pocl_runs_it_without_ir),
    };
    return cmocka_run_group_tests(tests, setup, scratch_dir_remove);
}
