/* test_opencl_cache.c: the binary cache of compiled OpenCL programs (worker/opencl_cache.c) and
 * the OpenCL backend's use of it, on PoCL.  Each backend renders scenes/default.scene at 48x27,
 * and its pixels must be memcmp-identical to those of a backend built from source with the
 * cache off, whatever the cache did.
 *
 *   off_builds_from_source   TF_OPENCL_CACHE=off: "off", nothing written.
 *   miss_then_hit            an empty directory: the first backend builds and stores (a 0600
 *                            entry in a 0700 directory it created, on PoCL 3.1 without the
 *                            program's LLVM IR), the second is a hit.
 *   stale_keys_differ        the key covers the source and the options: another source or
 *                            options give another entry, and an entry renamed to another key's
 *                            name is refused (its header holds its own key).
 *   changed_source_misses    the kernels with one comment added (TERRAFARM_KERNELS) do not
 *                            use the checkout's entry: a miss, and a second entry.
 *   tampered_binary          a byte of the stored binary flipped: refused by its checksum,
 *                            rebuilt, and the rewritten entry is a hit again.
 *   tampered_header          the same for a byte of the magic, format, reserved word, key,
 *                            length and checksum, and for a file cut short.
 *   driver_rejects_binary    a well-formed entry whose binary is not one: the driver refuses
 *                            it, the program is rebuilt and the entry rewritten.
 *   unsafe_directory         a group- or world-writable directory, one not owned by this user
 *                            (as root), a symbolic link: "refused", built from source, nothing
 *                            written; made private again, it is used.
 *   prunes_idle_entries      tf_clcache_prune (no device needed): entries and temporary files
 *                            unused past the limit go, and only those: not the cache's own
 *                            entry, not a younger one, not other names, links, directories or
 *                            (as root) other users' files.
 *   hit_marks_use_store_prunes  a hit marks the entry used (its time is now); the next store
 *                            removes an entry idle past TF_CLCACHE_MAX_IDLE_S and keeps a
 *                            recent one.
 * Every test skips (cmocka skip()) with a message when no OpenCL platform exists.  Nothing
 * depends on timing: hits and misses are read from tf_cl_backend_cache. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <cmocka.h>
#include <dirent.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "worker/opencl_cache.h"
#include "worker/pocl_binary.h"
#include "installed_kernels.h"
#include "worker/backend_opencl.h"
#include "terrain/heightfield.h"
#include "render/render.h"
#include "scene.h"
#include "scratch_dir.h"

#define W 48
#define H 27

static tf_scene *scene;
static tf_heightfield *hf;
static tf_pixel ref[W * H]; /* built from source, cache off */

static int have_platform(void)
{
    cl_uint n = 0;
    return clGetPlatformIDs(0, NULL, &n) == CL_SUCCESS && n > 0;
}

static void skip_without_opencl(void)
{
    if (!have_platform()) {
        print_message("no OpenCL platform: skipping the OpenCL cache tests\n");
        skip();
    }
}

/* A new backend renders the whole image into img; returns its cache state ("hit", ...). */
static const char *render_new(tf_pixel *img)
{
    static char state[16];
    char err[1024] = "";
    tf_cl_backend *b = tf_cl_backend_new(scene, hf, err, sizeof err);
    if (!b)
        print_message("OpenCL backend: %s\n", err);
    assert_non_null(b);
    assert_int_equal(tf_cl_backend_render(b, (tf_rect){0, 0, W, H}, img, NULL, err, sizeof err),
                     0);
    snprintf(state, sizeof state, "%s", tf_cl_backend_cache(b));
    tf_cl_backend_free(b);
    return state;
}

/* A new backend with the cache in dir: its state must be `want` and its pixels the reference. */
static void expect(const char *dir, const char *want)
{
    static tf_pixel img[W * H];
    setenv("TF_OPENCL_CACHE", dir, 1);
    const char *got = render_new(img);
    if (strcmp(got, want) != 0)
        print_message("cache in %s: expected %s, got %s\n", dir, want, got);
    assert_string_equal(got, want);
    assert_memory_equal(img, ref, sizeof ref);
}

static int setup(void **state)
{
    char err[1024], path[4096];
    const char *root = getenv("TF_ROOT");
    if (scratch_dir_make(state))
        return -1;
    snprintf(path, sizeof path, "%s/scenes/default.scene", root ? root : ".");
    scene = tf_scene_load(path, err, sizeof err);
    if (scene) {
        tf_scene_set_size(scene, W, H);
        hf = tf_heightfield_build(scene, 0, err, sizeof err);
    }
    if (!hf) {
        fprintf(stderr, "%s\n", err);
        return -1;
    }
    if (have_platform()) {
        setenv("TF_OPENCL_CACHE", "off", 1);
        render_new(ref);
    }
    return 0;
}

static int teardown(void **state)
{
    tf_heightfield_free(hf);
    tf_scene_free(scene);
    return scratch_dir_remove(state);
}

/* ---------------------------------------------------------------- files */

/* The number of entries (*.bin) in dir, and the path of the last one seen in *path. */
static int entries(const char *dir, char *path, size_t len)
{
    DIR *d = opendir(dir);
    int n = 0;
    struct dirent *e;
    while (d && (e = readdir(d))) {
        size_t l = strlen(e->d_name);
        if (l > 4 && strcmp(e->d_name + l - 4, ".bin") == 0 && ++n && path)
            snprintf(path, len, "%s/%s", dir, e->d_name);
    }
    if (d)
        closedir(d);
    return n;
}

static void flip_byte(const char *path, long offset)
{
    FILE *f = fopen(path, "r+b");
    assert_non_null(f);
    if (offset < 0) {
        assert_int_equal(fseek(f, offset, SEEK_END), 0);
        offset = ftell(f);
    }
    assert_int_equal(fseek(f, offset, SEEK_SET), 0);
    int c = fgetc(f);
    assert_int_not_equal(c, EOF);
    assert_int_equal(fseek(f, offset, SEEK_SET), 0);
    fputc(c ^ 0x40, f);
    assert_int_equal(fclose(f), 0);
}

/* A directory holding one good entry (a miss, then a hit); its path in entry. */
static const char *primed(const char *name, char *entry, size_t len)
{
    const char *dir = scratch_path(name);
    expect(dir, "miss");
    expect(dir, "hit");
    assert_int_equal(entries(dir, entry, len), 1);
    return dir;
}

/* ---------------------------------------------------------------- tests */

static void off_builds_from_source(void **state)
{
    (void)state;
    skip_without_opencl();
    expect("off", "off");
}

/* A PoCL 3.1 binary is stored without its LLVM IR (worker/pocl_binary.h); another driver's
 * binary, which pocl_binary.c does not read, is stored as it is. */
static void stored_without_ir(const char *entry)
{
    FILE *f = fopen(entry, "rb");
    static unsigned char bin[8 << 20];
    assert_non_null(f);
    size_t n = fread(bin, 1, sizeof bin, f);
    fclose(f);
    assert_true(n > TF_CLCACHE_HEADER_BYTES && n < sizeof bin);
    int ir = tf_pocl_binary_has_ir(bin + TF_CLCACHE_HEADER_BYTES, n - TF_CLCACHE_HEADER_BYTES);
    print_message("stored binary: %s\n", ir < 0 ? "not PoCL 3.1's" : ir ? "with IR" : "no IR");
    assert_int_not_equal(ir, 1);
}

static void miss_then_hit(void **state)
{
    (void)state;
    skip_without_opencl();
    char dir[400], entry[800];
    struct stat st;
    snprintf(dir, sizeof dir, "%s", scratch_path("fresh/opencl"));
    expect(dir, "miss");
    assert_int_equal(entries(dir, entry, sizeof entry), 1);
    assert_int_equal(stat(entry, &st), 0);
    assert_int_equal(st.st_mode & 0777, 0600);
    assert_int_equal(stat(dir, &st), 0);
    assert_int_equal(st.st_mode & 0777, 0700);
    expect(dir, "hit");
    expect(dir, "hit");
    assert_int_equal(entries(dir, NULL, 0), 1);
    stored_without_ir(entry);
}

/* The first device of the first platform, and a cache for a program of one source. */
static void open_for(tf_clcache *c, const char *src, const char *options)
{
    cl_platform_id plat;
    cl_device_id dev;
    size_t len = strlen(src);
    char err[1024];
    assert_int_equal(clGetPlatformIDs(1, &plat, NULL), CL_SUCCESS);
    assert_int_equal(clGetDeviceIDs(plat, CL_DEVICE_TYPE_ALL, 1, &dev, NULL), CL_SUCCESS);
    assert_int_equal(tf_clcache_open(c, dev, 1, &src, &len, options, err, sizeof err), 0);
}

/* An entry stored for `from` and renamed to `to`'s name is refused by its key. */
static void refused_under(const tf_clcache *from, const tf_clcache *to)
{
    static const unsigned char bytes[64] = {1, 2, 3};
    char err[1024] = "";
    cl_platform_id plat;
    cl_device_id dev;
    assert_int_equal(tf_clcache_write(from, bytes, sizeof bytes, err, sizeof err), 0);
    assert_int_equal(renameat(from->dirfd, from->name, to->dirfd, to->name), 0);
    clGetPlatformIDs(1, &plat, NULL);
    clGetDeviceIDs(plat, CL_DEVICE_TYPE_ALL, 1, &dev, NULL);
    cl_context ctx = clCreateContext(NULL, 1, &dev, NULL, NULL, NULL);
    assert_non_null(ctx);
    assert_null(tf_clcache_load(to, ctx, dev, "", err, sizeof err));
    print_message("renamed entry: %s\n", err);
    assert_non_null(strstr(err, "its key is another"));
    clReleaseContext(ctx);
}

static void stale_keys_differ(void **state)
{
    (void)state;
    skip_without_opencl();
    tf_clcache a, opts, src;
    setenv("TF_OPENCL_CACHE", scratch_path("keys"), 1);
    open_for(&a, "kernel void k(void) {}", "-DX=1");
    open_for(&opts, "kernel void k(void) {}", "-DX=2");
    open_for(&src, "kernel void k(void) {} ", "-DX=1");
    assert_string_not_equal(a.name, opts.name);
    assert_string_not_equal(a.name, src.name);
    assert_string_not_equal(opts.name, src.name);
    refused_under(&a, &opts);
    refused_under(&a, &src);
    tf_clcache_close(&a);
    tf_clcache_close(&opts);
    tf_clcache_close(&src);
}


static void copy_kernels(const char *dir)
{
    const char *root = getenv("TF_ROOT");
    char cmd[8192];
    int n = snprintf(cmd, sizeof cmd, "mkdir -p '%s' && cd '%s' && cp", dir, root ? root : ".");
    for (size_t i = 0; i < INSTALLED_KERNEL_FILES; i++)
        n += snprintf(cmd + n, sizeof cmd - (size_t)n, " %s", installed_kernel_files[i]);
    snprintf(cmd + n, sizeof cmd - (size_t)n, " '%s'/ && echo '/* changed */' >>'%s/terrafarm.cl'",
             dir, dir);
    assert_int_equal(system(cmd), 0);
}

static void changed_source_misses(void **state)
{
    (void)state;
    skip_without_opencl();
    char entry[800];
    const char *dir = primed("changed", entry, sizeof entry);
    copy_kernels(scratch_path("kernels"));
    setenv("TERRAFARM_KERNELS", scratch_path("kernels"), 1);
    expect(dir, "miss");
    expect(dir, "hit");
    unsetenv("TERRAFARM_KERNELS");
    assert_int_equal(entries(dir, NULL, 0), 2);
    expect(dir, "hit");
}

static void tampered_binary(void **state)
{
    (void)state;
    skip_without_opencl();
    char entry[800];
    const char *dir = primed("binary", entry, sizeof entry);
    flip_byte(entry, -1);
    expect(dir, "rebuilt");
    expect(dir, "hit");
    flip_byte(entry, TF_CLCACHE_HEADER_BYTES + 100);
    expect(dir, "rebuilt");
    expect(dir, "hit");
}

static void tampered_header(void **state)
{
    (void)state;
    skip_without_opencl();
    /* magic, format, the reserved word, key, length, checksum */
    static const long offsets[] = {0, 8, 12, 16 + 5, 48, 48 + 7, 56, 87};
    char entry[800];
    const char *dir = primed("header", entry, sizeof entry);
    for (size_t i = 0; i < sizeof offsets / sizeof offsets[0]; i++) {
        print_message("flip byte %ld of the header\n", offsets[i]);
        flip_byte(entry, offsets[i]);
        expect(dir, "rebuilt");
        expect(dir, "hit");
    }
    assert_int_equal(truncate(entry, TF_CLCACHE_HEADER_BYTES - 1), 0);
    expect(dir, "rebuilt");
    assert_int_equal(truncate(entry, TF_CLCACHE_HEADER_BYTES + 10), 0);
    expect(dir, "rebuilt");
    expect(dir, "hit");
}

static void driver_rejects_binary(void **state)
{
    (void)state;
    skip_without_opencl();
    char entry[800], err[1024];
    unsigned char garbage[4096];
    const char *dir = primed("garbage", entry, sizeof entry);
    tf_clcache c = {.dirfd = open(dir, O_RDONLY | O_DIRECTORY)};
    assert_true(c.dirfd >= 0);
    snprintf(c.name, sizeof c.name, "%s", strrchr(entry, '/') + 1);
    FILE *f = fopen(entry, "rb"); /* the key from the good entry's header */
    assert_non_null(f);
    assert_int_equal(fseek(f, 16, SEEK_SET), 0);
    assert_int_equal(fread(c.key, 1, sizeof c.key, f), sizeof c.key);
    fclose(f);
    for (size_t i = 0; i < sizeof garbage; i++)
        garbage[i] = (unsigned char)(i * 131 + 7);
    assert_int_equal(tf_clcache_write(&c, garbage, sizeof garbage, err, sizeof err), 0);
    tf_clcache_close(&c);
    expect(dir, "rebuilt");
    expect(dir, "hit");
}

static void refused_with_mode(const char *dir, mode_t mode)
{
    print_message("directory mode %03o\n", (unsigned)mode);
    assert_int_equal(chmod(dir, mode), 0);
    expect(dir, "refused");
    assert_int_equal(entries(dir, NULL, 0), 0);
}

static void unsafe_directory(void **state)
{
    (void)state;
    skip_without_opencl();
    const char *dir = scratch_path("unsafe");
    char link[400];
    assert_int_equal(mkdir(dir, 0700), 0);
    refused_with_mode(dir, 0770);
    refused_with_mode(dir, 0720);
    refused_with_mode(dir, 0702);
    refused_with_mode(dir, 01777); /* /tmp's mode */
    assert_int_equal(chmod(dir, 0700), 0);
    if (geteuid() == 0) { /* root can give it away: owned by nobody, it is not ours */
        assert_int_equal(chown(dir, 65534, 65534), 0);
        expect(dir, "refused");
        assert_int_equal(chown(dir, 0, 0), 0);
    }
    snprintf(link, sizeof link, "%s", scratch_path("link"));
    assert_int_equal(symlink(dir, link), 0);
    expect(link, "refused");
    assert_int_equal(entries(dir, NULL, 0), 0);
    expect(dir, "miss");
    expect(dir, "hit");
}

/* File dir/name holding a few bytes, its times `when`. */
static void file_at(const char *dir, const char *name, time_t when)
{
    char p[800];
    assert_true(snprintf(p, sizeof p, "%s/%s", dir, name) < (int)sizeof p);
    FILE *f = fopen(p, "wb");
    assert_non_null(f);
    fputs("not a program", f);
    assert_int_equal(fclose(f), 0);
    struct timespec ts[2] = {{when, 0}, {when, 0}};
    assert_int_equal(utimensat(AT_FDCWD, p, ts, AT_SYMLINK_NOFOLLOW), 0);
}

static int present(const char *dir, const char *name)
{
    char p[800];
    struct stat st;
    assert_true(snprintf(p, sizeof p, "%s/%s", dir, name) < (int)sizeof p);
    return lstat(p, &st) == 0;
}

#define KEY_A "aaaa000000000000000000000000000000000000000000000000000000000001" /* no real key */
#define KEY_B "bbbb000000000000000000000000000000000000000000000000000000000002"
#define KEY_C "cccc000000000000000000000000000000000000000000000000000000000003"
#define KEY_LINK "dddd000000000000000000000000000000000000000000000000000000000004"
#define KEY_DIR "eeee000000000000000000000000000000000000000000000000000000000005"
#define KEY_THEIRS "ffff000000000000000000000000000000000000000000000000000000000006"

static void prunes_idle_entries(void **state)
{
    (void)state;
    const time_t now = 2000000000, old = now - TF_CLCACHE_MAX_IDLE_S - 1;
    const char *dir = scratch_path("prune");
    assert_int_equal(mkdir(dir, 0700), 0);
    tf_clcache c = {.dirfd = open(dir, O_RDONLY | O_DIRECTORY), .state = TF_CLCACHE_MISS};
    assert_true(c.dirfd >= 0);
    snprintf(c.name, sizeof c.name, "%s.bin", KEY_A);
    const char *gone[] = {KEY_B ".bin", ".aaaa000000000000.4242.0badf00d.tmp"};
    const char *kept[] = {KEY_A ".bin", /* the cache's own */
                          "AAAA000000000000000000000000000000000000000000000000000000000001.bin",
                          KEY_B ".bin.bak", KEY_B, "notes.txt", ".aaaa000000000000..0badf00d.tmp",
                          ".aaaa000000000000.42x.0badf00d.tmp", "." KEY_B ".tmp"};
    for (size_t i = 0; i < sizeof gone / sizeof gone[0]; i++)
        file_at(dir, gone[i], old);
    for (size_t i = 0; i < sizeof kept / sizeof kept[0]; i++)
        file_at(dir, kept[i], old);
    file_at(dir, KEY_C ".bin", now - TF_CLCACHE_MAX_IDLE_S); /* at the limit: not idle past it */
    char p[800], away[800];
    snprintf(away, sizeof away, "%s", scratch_path("prune-away"));
    assert_int_equal(mkdir(away, 0700), 0);
    file_at(away, "target", old);
    snprintf(p, sizeof p, "%s/" KEY_LINK ".bin", dir);
    assert_int_equal(symlink(away, p), 0); /* a link with an entry's name: left */
    snprintf(p, sizeof p, "%s/" KEY_DIR ".bin", dir);
    assert_int_equal(mkdir(p, 0700), 0);
    int theirs = geteuid() == 0;
    if (theirs) {
        file_at(dir, KEY_THEIRS ".bin", old);
        snprintf(p, sizeof p, "%s/" KEY_THEIRS ".bin", dir);
        assert_int_equal(lchown(p, 12345, 12345), 0);
    }
    assert_int_equal(tf_clcache_prune(&c, now, TF_CLCACHE_MAX_IDLE_S), 2);
    for (size_t i = 0; i < sizeof gone / sizeof gone[0]; i++)
        assert_false(present(dir, gone[i]));
    for (size_t i = 0; i < sizeof kept / sizeof kept[0]; i++)
        assert_true(present(dir, kept[i]));
    assert_true(present(dir, KEY_C ".bin"));
    assert_true(present(away, "target"));
    assert_true(present(dir, KEY_LINK ".bin") && present(dir, KEY_DIR ".bin"));
    if (theirs)
        assert_true(present(dir, KEY_THEIRS ".bin"));
    assert_int_equal(tf_clcache_prune(&c, now, TF_CLCACHE_MAX_IDLE_S), 0);
    tf_clcache_close(&c);
}

static void hit_marks_use_store_prunes(void **state)
{
    (void)state;
    skip_without_opencl();
    char entry[800];
    struct stat st;
    const char *dir = primed("marks", entry, sizeof entry);
    const time_t now = time(NULL), old = now - TF_CLCACHE_MAX_IDLE_S - 86400;
    struct timespec ts[2] = {{old, 0}, {old, 0}};
    assert_int_equal(utimensat(AT_FDCWD, entry, ts, 0), 0);
    expect(dir, "hit");
    assert_int_equal(stat(entry, &st), 0);
    assert_true(st.st_mtime >= now - 600); /* used just now, whatever the clock's steps */
    file_at(dir, KEY_B ".bin", old);
    file_at(dir, KEY_C ".bin", now);
    expect(dir, "hit"); /* a hit stores nothing, so it prunes nothing */
    assert_true(present(dir, KEY_B ".bin"));
    assert_int_equal(unlink(entry), 0);
    expect(dir, "miss"); /* stored again, and the idle entry is gone */
    assert_false(present(dir, KEY_B ".bin"));
    assert_true(present(dir, KEY_C ".bin"));
    assert_int_equal(entries(dir, NULL, 0), 2);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(off_builds_from_source), cmocka_unit_test(miss_then_hit),
        cmocka_unit_test(stale_keys_differ),      cmocka_unit_test(changed_source_misses),
        cmocka_unit_test(tampered_binary),        cmocka_unit_test(tampered_header),
        cmocka_unit_test(driver_rejects_binary),  cmocka_unit_test(unsafe_directory),
        cmocka_unit_test(prunes_idle_entries),    cmocka_unit_test(hit_marks_use_store_prunes),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
