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
 *                            and exported; set by the user: left as it is, no directory named. */
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

static int exists(const char *dir, const char *name)
{
    char p[512];
    struct stat st;
    snprintf(p, sizeof p, "%s/%s", dir, name);
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

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(sweeps_old_tempfiles),    cmocka_unit_test(keeps_young_tempfiles),
        cmocka_unit_test(keeps_other_names),       cmocka_unit_test(keeps_links_and_dirs),
        cmocka_unit_test(keeps_other_users_files), cmocka_unit_test(refuses_a_linked_dir),
        cmocka_unit_test(missing_dir),             cmocka_unit_test(chooses_xdg_unless_set),
    };
    return cmocka_run_group_tests(tests, scratch_dir_make, scratch_dir_remove);
}
