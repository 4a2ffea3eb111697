/* test_pocl_cachedir.c: PoCL's cache directory as terrafarm chooses and sweeps it
 * (worker/pocl_cachedir.c).  No OpenCL needed: the files PoCL leaves are made here, their ages
 * set with utimensat, and the sweep is given its "now".
 *
 *   sweeps_old_tempfiles     tempfile_XXXXXX files older than the limit are removed, and only
 *                            those: the count returned is theirs.
 *   keeps_young_tempfiles    one a second younger than the limit stays (a PoCL at work).
 *   keeps_other_names        other names, however old: a seventh character, a bare prefix, a
 *                            prefix inside a name, PoCL's program.bc.
 *   keeps_links_and_dirs     a symbolic link of that name (and the old file it points to), a
 *                            directory of that name.
 *   keeps_other_users_files  a file of that name owned by another user (as root only).
 *   refuses_a_linked_dir     the directory given as a symbolic link: -1, nothing removed.
 *   missing_dir              -1 with ENOENT.
 *   chooses_xdg_unless_set   POCL_CACHE_DIR unset: $XDG_CACHE_HOME/terrafarm/pocl, made 0700
 *                            and exported; set by the user: left as it is, no directory named.
 *   prunes_idle_programs     program directories (XX/YYY... as PoCL lays them out, with their
 *                            kernels' files) last used before the limit go, whole; by their
 *                            last_accessed file, else their own time; an emptied XX goes too.
 *   keeps_used_programs      one used at the limit or since, however old its directory; other
 *                            names (not PoCL's hash letters, another length) however old.
 *   prune_follows_no_link    a link named like a program directory or a bucket, to an old
 *                            program elsewhere: the link goes or stays, the program elsewhere
 *                            stays whole; a file named like a program stays.
 *   prune_keeps_other_users  an old program directory of another user's (as root only).
 *   prune_refuses_links_and_missing  the cache given as a link, or missing: -1. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <cmocka.h>
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "worker/pocl_cachedir.h"
#include "scratch_dir.h"

#define NOW ((time_t)2000000000)
#define AGE 3600L

/* A fresh empty directory NAME in the scratch directory; its path. */
static const char *fresh_dir(const char *name)
{
    const char *d = scratch_path(name);
    assert_int_equal(mkdir(d, 0700), 0);
    return d;
}

/* File dir/name, empty, last modified at `when`. */
static void make_file_at(const char *dir, const char *name, time_t when)
{
    char p[512];
    snprintf(p, sizeof p, "%s/%s", dir, name);
    int fd = open(p, O_WRONLY | O_CREAT | O_EXCL, 0600);
    assert_true(fd >= 0);
    close(fd);
    struct timespec ts[2] = {{when, 0}, {when, 0}};
    assert_int_equal(utimensat(AT_FDCWD, p, ts, AT_SYMLINK_NOFOLLOW), 0);
}

/* out = dir/name, which must fit in PATH_BYTES. */
#define PATH_BYTES 512
static void join(char *out, const char *dir, const char *name)
{
    assert_true(snprintf(out, PATH_BYTES, "%s/%s", dir, name) < PATH_BYTES);
}

static int exists(const char *dir, const char *name)
{
    char p[PATH_BYTES];
    struct stat st;
    join(p, dir, name);
    return lstat(p, &st) == 0;
}

static void sweeps_old_tempfiles(void **state)
{
    (void)state;
    const char *d = fresh_dir("old");
    make_file_at(d, "tempfile_AbC123", NOW - AGE - 1);
    make_file_at(d, "tempfile_zzzzzz", NOW - 30 * 86400);
    make_file_at(d, "tempfile_keep01", NOW);
    assert_int_equal(tf_pocl_cache_sweep(d, NOW, AGE), 2);
    assert_false(exists(d, "tempfile_AbC123"));
    assert_false(exists(d, "tempfile_zzzzzz"));
    assert_true(exists(d, "tempfile_keep01"));
    assert_int_equal(tf_pocl_cache_sweep(d, NOW, AGE), 0);
}

static void keeps_young_tempfiles(void **state)
{
    (void)state;
    const char *d = fresh_dir("young");
    make_file_at(d, "tempfile_young1", NOW - AGE + 1);
    make_file_at(d, "tempfile_edge01", NOW - AGE); /* exactly the limit: not older */
    assert_int_equal(tf_pocl_cache_sweep(d, NOW, AGE), 0);
    assert_true(exists(d, "tempfile_young1"));
    assert_true(exists(d, "tempfile_edge01"));
}

static void keeps_other_names(void **state)
{
    (void)state;
    const char *d = fresh_dir("names");
    const char *names[] = {"tempfile_1234567", "tempfile_", "tempfile_12345", "xtempfile_12345",
                           "program.bc", "TEMPFILE_123456"};
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++)
        make_file_at(d, names[i], NOW - 10 * AGE);
    assert_int_equal(tf_pocl_cache_sweep(d, NOW, AGE), 0);
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++)
        assert_true(exists(d, names[i]));
}

static void keeps_links_and_dirs(void **state)
{
    (void)state;
    const char *d = fresh_dir("links");
    const char *elsewhere = fresh_dir("elsewhere");
    make_file_at(elsewhere, "tempfile_target", NOW - 10 * AGE);
    char target[512], link[512], sub[512];
    snprintf(target, sizeof target, "%s/tempfile_target", elsewhere);
    snprintf(link, sizeof link, "%s/tempfile_link01", d);
    assert_int_equal(symlink(target, link), 0);
    struct timespec ts[2] = {{NOW - 10 * AGE, 0}, {NOW - 10 * AGE, 0}};
    assert_int_equal(utimensat(AT_FDCWD, link, ts, AT_SYMLINK_NOFOLLOW), 0);
    snprintf(sub, sizeof sub, "%s/tempfile_dir001", d);
    assert_int_equal(mkdir(sub, 0700), 0);
    assert_int_equal(utimensat(AT_FDCWD, sub, ts, 0), 0);
    assert_int_equal(tf_pocl_cache_sweep(d, NOW, AGE), 0);
    assert_true(exists(d, "tempfile_link01"));
    assert_true(exists(d, "tempfile_dir001"));
    assert_true(exists(elsewhere, "tempfile_target"));
}

static void keeps_other_users_files(void **state)
{
    (void)state;
    if (geteuid() != 0) {
        print_message("not root: cannot make another user's file; skipping\n");
        skip();
    }
    const char *d = fresh_dir("users");
    make_file_at(d, "tempfile_theirs", NOW - 10 * AGE);
    make_file_at(d, "tempfile_mine01", NOW - 10 * AGE);
    char p[512];
    snprintf(p, sizeof p, "%s/tempfile_theirs", d);
    assert_int_equal(lchown(p, 12345, 12345), 0);
    assert_int_equal(tf_pocl_cache_sweep(d, NOW, AGE), 1);
    assert_true(exists(d, "tempfile_theirs"));
    assert_false(exists(d, "tempfile_mine01"));
}

static void refuses_a_linked_dir(void **state)
{
    (void)state;
    const char *real = fresh_dir("real");
    make_file_at(real, "tempfile_old001", NOW - 10 * AGE);
    const char *link = scratch_path("dirlink");
    assert_int_equal(symlink(real, link), 0);
    assert_int_equal(tf_pocl_cache_sweep(link, NOW, AGE), -1);
    assert_true(exists(real, "tempfile_old001"));
}

static void missing_dir(void **state)
{
    (void)state;
    errno = 0;
    assert_int_equal(tf_pocl_cache_sweep(scratch_path("no-such-dir"), NOW, AGE), -1);
    assert_int_equal(errno, ENOENT);
}

static void chooses_xdg_unless_set(void **state)
{
    (void)state;
    const char *xdg = fresh_dir("xdg");
    char want[512], dir[512];
    snprintf(want, sizeof want, "%s/terrafarm/pocl", xdg);
    unsetenv("POCL_CACHE_DIR");
    setenv("XDG_CACHE_HOME", xdg, 1);
    tf_pocl_cache_dir_choose(dir, sizeof dir);
    assert_string_equal(dir, want);
    assert_non_null(getenv("POCL_CACHE_DIR"));
    assert_string_equal(getenv("POCL_CACHE_DIR"), want);
    struct stat st;
    assert_int_equal(stat(want, &st), 0);
    assert_true(S_ISDIR(st.st_mode));
    assert_int_equal(st.st_mode & 0777, 0700);

    setenv("POCL_CACHE_DIR", "/the/users/own", 1);
    tf_pocl_cache_dir_choose(dir, sizeof dir);
    assert_string_equal(dir, "");
    assert_string_equal(getenv("POCL_CACHE_DIR"), "/the/users/own");
}

/* Directory dir/name (any depth of existing parents), last modified at `when`. */
static void make_dir_at(const char *dir, const char *name, time_t when)
{
    char p[PATH_BYTES];
    join(p, dir, name);
    assert_int_equal(mkdir(p, 0700), 0);
    struct timespec ts[2] = {{when, 0}, {when, 0}};
    assert_int_equal(utimensat(AT_FDCWD, p, ts, AT_SYMLINK_NOFOLLOW), 0);
}

/* A program directory dir/bucket/prog as PoCL 3.1 leaves one: its LLVM IR, two kernels with a
 * work-group function each, and last_accessed at `used` (none when used < 0); its directories'
 * own times are `made`. */
static void make_program(const char *dir, const char *bucket, const char *prog, time_t made,
                         time_t used)
{
    char b[PATH_BYTES], p[PATH_BYTES], k[PATH_BYTES], v[PATH_BYTES];
    join(b, dir, bucket);
    struct stat st;
    if (stat(b, &st) != 0)
        make_dir_at(dir, bucket, made);
    make_dir_at(b, prog, made);
    join(p, b, prog);
    make_file_at(p, "program.bc", made);
    for (int i = 0; i < 2; i++) {
        const char *kernel = i ? "tf_kernel1" : "tf_kernel0";
        make_dir_at(p, kernel, made);
        join(k, p, kernel);
        make_dir_at(k, "0-0-0", made);
        join(v, k, "0-0-0");
        make_file_at(v, "tf_kernel.so", made);
    }
    if (used >= 0)
        make_file_at(p, "last_accessed", used);
    struct timespec ts[2] = {{made, 0}, {made, 0}}; /* its files made it younger */
    assert_int_equal(utimensat(AT_FDCWD, p, ts, AT_SYMLINK_NOFOLLOW), 0);
}

static int program_exists(const char *dir, const char *bucket, const char *prog)
{
    char b[PATH_BYTES], p[PATH_BYTES], k[PATH_BYTES];
    join(b, dir, bucket);
    join(p, b, prog);
    join(k, p, "tf_kernel1/0-0-0");
    return exists(k, "tf_kernel.so");
}

static void prunes_idle_programs(void **state)
{
    (void)state;
    const char *d = fresh_dir("prune");
    make_program(d, "GO", "BAAPGDHKHAIKIHJEGHGJNBJOMEPJBGEAMEIFD", NOW, NOW - AGE - 1);
    make_program(d, "GO", "PPPPPPPPPPPPPPPPPPPPPPPPPPPPPPPPPPPPP", NOW, NOW);
    make_program(d, "KK", "AAIJFNLADMIAILBEPNCAEIBNAFKGMIMJAIFIM", NOW - 90 * 86400, -1);
    make_program(d, "NE", "LHIAEDFAKNEOAPKPIDBKLINCKHJANOCLOGMIG", NOW, NOW - 90 * 86400);
    assert_int_equal(tf_pocl_cache_prune(d, NOW, AGE), 3);
    assert_false(exists(d, "GO/BAAPGDHKHAIKIHJEGHGJNBJOMEPJBGEAMEIFD"));
    assert_true(program_exists(d, "GO", "PPPPPPPPPPPPPPPPPPPPPPPPPPPPPPPPPPPPP"));
    assert_false(exists(d, "KK"));
    assert_false(exists(d, "NE"));
    assert_int_equal(tf_pocl_cache_prune(d, NOW, AGE), 0);
}

static void keeps_used_programs(void **state)
{
    (void)state;
    const char *d = fresh_dir("used");
    make_program(d, "AB", "CDEFGHIJKLMNOP", NOW - 90 * 86400, NOW - AGE); /* at the limit */
    make_program(d, "AB", "ABCDEFGHIJKLMNOPABCD", NOW - 90 * 86400, NOW);
    make_program(d, "AB", "PONMLKJIHGFEDCBA", NOW, -1); /* never used, made just now */
    make_program(d, "AQ", "ABCDEFGHIJKLMNOPABCD", NOW - 90 * 86400, -1); /* Q: not PoCL's */
    make_program(d, "ABC", "ABCDEFGHIJKLMNOPABCD", NOW - 90 * 86400, -1);
    make_program(d, "CD", "ABCDEFG", NOW - 90 * 86400, -1);              /* too short */
    make_program(d, "CD", "abcdefghijklmnopabcd", NOW - 90 * 86400, -1); /* lower case */
    assert_int_equal(tf_pocl_cache_prune(d, NOW, AGE), 0);
    assert_true(program_exists(d, "AB", "CDEFGHIJKLMNOP"));
    assert_true(program_exists(d, "AB", "ABCDEFGHIJKLMNOPABCD"));
    assert_true(program_exists(d, "AB", "PONMLKJIHGFEDCBA"));
    assert_true(program_exists(d, "AQ", "ABCDEFGHIJKLMNOPABCD"));
    assert_true(program_exists(d, "ABC", "ABCDEFGHIJKLMNOPABCD"));
    assert_true(program_exists(d, "CD", "ABCDEFG"));
    assert_true(program_exists(d, "CD", "abcdefghijklmnopabcd"));
}

static void prune_follows_no_link(void **state)
{
    (void)state;
    const char *d = fresh_dir("nolink"), *away = fresh_dir("away");
    make_program(away, "EE", "EEEEEEEEEEEEEEEEEEEE", NOW - 90 * 86400, NOW - 90 * 86400);
    char target[PATH_BYTES], link[PATH_BYTES];
    join(target, away, "EE/EEEEEEEEEEEEEEEEEEEE");
    make_dir_at(d, "FF", NOW - 90 * 86400);
    join(link, d, "FF/FFFFFFFFFFFFFFFFFFFF"); /* a program that is a link */
    assert_int_equal(symlink(target, link), 0);
    join(target, away, "EE");
    join(link, d, "EE"); /* a bucket that is a link */
    assert_int_equal(symlink(target, link), 0);
    make_dir_at(d, "GG", NOW - 90 * 86400);
    join(link, d, "GG");
    make_file_at(link, "GGGGGGGGGGGGGGGGGGGG", NOW - 90 * 86400); /* a file, not a program */
    assert_int_equal(tf_pocl_cache_prune(d, NOW, AGE), 0);
    assert_true(program_exists(away, "EE", "EEEEEEEEEEEEEEEEEEEE"));
    assert_true(exists(d, "GG/GGGGGGGGGGGGGGGGGGGG"));
    /* inside a program, a link to a directory elsewhere is removed as a name */
    make_program(d, "HH", "HHHHHHHHHHHHHHHHHHHH", NOW, NOW - 90 * 86400);
    join(target, away, "EE");
    join(link, d, "HH/HHHHHHHHHHHHHHHHHHHH/tf_kernel0/elsewhere");
    assert_int_equal(symlink(target, link), 0);
    assert_int_equal(tf_pocl_cache_prune(d, NOW, AGE), 1);
    assert_false(exists(d, "HH"));
    assert_true(program_exists(away, "EE", "EEEEEEEEEEEEEEEEEEEE"));
}

static void prune_keeps_other_users(void **state)
{
    (void)state;
    if (geteuid() != 0) {
        print_message("not root: cannot make another user's directory; skipping\n");
        skip();
    }
    const char *d = fresh_dir("theirs");
    make_program(d, "II", "IIIIIIIIIIIIIIIIIIII", NOW, NOW - 90 * 86400);
    make_program(d, "II", "JJJJJJJJJJJJJJJJJJJJ", NOW, NOW - 90 * 86400);
    char p[PATH_BYTES];
    join(p, d, "II/IIIIIIIIIIIIIIIIIIII");
    assert_int_equal(lchown(p, 12345, 12345), 0);
    assert_int_equal(tf_pocl_cache_prune(d, NOW, AGE), 1);
    assert_true(program_exists(d, "II", "IIIIIIIIIIIIIIIIIIII"));
    assert_false(exists(d, "II/JJJJJJJJJJJJJJJJJJJJ"));
}

static void prune_refuses_links_and_missing(void **state)
{
    (void)state;
    const char *real = fresh_dir("realprune");
    make_program(real, "KL", "KLKLKLKLKLKLKLKLKLKL", NOW, NOW - 90 * 86400);
    const char *link = scratch_path("prunelink");
    assert_int_equal(symlink(real, link), 0);
    assert_int_equal(tf_pocl_cache_prune(link, NOW, AGE), -1);
    assert_true(program_exists(real, "KL", "KLKLKLKLKLKLKLKLKLKL"));
    errno = 0;
    assert_int_equal(tf_pocl_cache_prune(scratch_path("no-such-cache"), NOW, AGE), -1);
    assert_int_equal(errno, ENOENT);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(sweeps_old_tempfiles),    cmocka_unit_test(keeps_young_tempfiles),
        cmocka_unit_test(keeps_other_names),       cmocka_unit_test(keeps_links_and_dirs),
        cmocka_unit_test(keeps_other_users_files), cmocka_unit_test(refuses_a_linked_dir),
        cmocka_unit_test(missing_dir),             cmocka_unit_test(chooses_xdg_unless_set),
        cmocka_unit_test(prunes_idle_programs),    cmocka_unit_test(keeps_used_programs),
        cmocka_unit_test(prune_follows_no_link),   cmocka_unit_test(prune_keeps_other_users),
        cmocka_unit_test(prune_refuses_links_and_missing),
    };
    return cmocka_run_group_tests(tests, scratch_dir_make, scratch_dir_remove);
}
