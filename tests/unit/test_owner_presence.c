/* test_owner_presence.c: is the owner of this machine present? (worker/owner_presence.c).
 * A real child playing the owner (user nobody, busy) is seen present, then away once killed;
 * the CPU arithmetic exactly on a fake /proc (growth, vanished, new and reused pids, real uid,
 * the worker's own tree, malformed and unreadable files, a uid that changes) and the input
 * signal exactly on a fake /dev, both under a fake clock; owner names and bad options. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <fcntl.h>
#include <grp.h>
#include <math.h>
#include <signal.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "clock.h"
#include "scratch_dir.h"
#include "worker/owner_presence.h"

#define OWNER 4242
#define NOBODY 65534
#define SECOND 1000000000LL

/* ---- a fake clock ---- */

static int64_t fake_boot_ns, fake_real_ns;

static int64_t fake_clock(clockid_t id)
{
    return id == CLOCK_REALTIME ? fake_real_ns : fake_boot_ns;
}

/* ---- files ---- */

static void write_file(const char *path, const char *fmt, ...)
{
    FILE *f = fopen(path, "w");
    if (!f)
        fail_msg("can not write %s", path);
    va_list ap;
    va_start(ap, fmt);
    vfprintf(f, fmt, ap);
    va_end(ap);
    fclose(f);
}

static void make_dir(const char *path)
{
    if (mkdir(path, 0755) < 0)
        fail_msg("can not make %s", path);
}

/* ---- a fake /proc ---- */

typedef struct fake_proc {
    int pid, ppid;
    unsigned real_uid, effective_uid;
    unsigned long long start, utime, stime;
    const char *comm; /* NULL: "cmd" */
} fake_proc;

/* root/PID/stat and root/PID/status as the kernel writes them (cutime and cstime are large
 * and grow every sample: a sampler that counted them would be off). */
static void put_proc(const char *root, const fake_proc *f)
{
    static unsigned long long children_ticks;
    char dir[400], path[440];
    snprintf(dir, sizeof dir, "%s/%d", root, f->pid);
    mkdir(dir, 0755);
    children_ticks += 1000;
    snprintf(path, sizeof path, "%s/stat", dir);
    write_file(path, "%d (%s) S %d %d %d 0 -1 4194560 100 0 0 0 %llu %llu %llu %llu 20 0 1 0 "
               "%llu 12345678 300 18446744073709551615 1 1 0 0 0 0 0\n", f->pid,
               f->comm ? f->comm : "cmd", f->ppid, f->pid, f->pid, f->utime, f->stime,
               children_ticks, children_ticks, f->start);
    snprintf(path, sizeof path, "%s/status", dir);
    write_file(path, "Name:\t%s\nUmask:\t0022\nState:\tS (sleeping)\nTgid:\t%d\nPid:\t%d\n"
               "PPid:\t%d\nTracerPid:\t0\nUid:\t%u\t%u\t%u\t%u\nGid:\t0\t0\t0\t0\n",
               f->comm ? f->comm : "cmd", f->pid, f->pid, f->ppid, f->real_uid,
               f->effective_uid, f->effective_uid, f->effective_uid);
}

static void put_procs(const char *root, const fake_proc *v, size_t n)
{
    for (size_t i = 0; i < n; i++)
        put_proc(root, &v[i]);
}

static void remove_proc(const char *root, int pid)
{
    char cmd[400];
    snprintf(cmd, sizeof cmd, "rm -rf '%s/%d'", root, pid);
    assert_int_equal(system(cmd), 0);
}

/* Entries a sampler must skip: not processes, or processes it can not read.  Each is the
 * owner's and burns `ticks`, so a sampler that read one would be off. */
static void put_unreadable(const char *root, unsigned long long ticks)
{
    char path[440];
    for (int pid = 600; pid <= 604; pid++)
        remove_proc(root, pid);
    snprintf(path, sizeof path, "%s/self", root);
    mkdir(path, 0755);
    snprintf(path, sizeof path, "%s/meminfo", root);
    write_file(path, "MemTotal: 1 kB\n");
    put_proc(root, &(fake_proc){600, 1, OWNER, OWNER, 10, ticks, 0, NULL});
    snprintf(path, sizeof path, "%s/600/stat", root); /* vanished between readdir and open */
    unlink(path);
    put_proc(root, &(fake_proc){601, 1, OWNER, OWNER, 10, ticks, 0, NULL});
    snprintf(path, sizeof path, "%s/601/stat", root);
    unlink(path);
    make_dir(path); /* unreadable (EISDIR; root reads any file whatever its mode) */
    put_proc(root, &(fake_proc){602, 1, OWNER, OWNER, 10, ticks, 0, NULL});
    snprintf(path, sizeof path, "%s/602/stat", root);
    write_file(path, "602 (no closing parenthesis S 1 1 1 0 -1 0 0 0 0 0 %llu 0 0 0 20 0 1 0 10\n",
               ticks);
    put_proc(root, &(fake_proc){603, 1, OWNER, OWNER, 10, ticks, 0, NULL});
    snprintf(path, sizeof path, "%s/603/stat", root);
    write_file(path, "603 (short) S 1 1 1 0 -1 0 0 0 0 0 %llu 0\n", ticks);
    put_proc(root, &(fake_proc){604, 1, OWNER, OWNER, 10, ticks, 0, NULL});
    snprintf(path, sizeof path, "%s/604/status", root);
    write_file(path, "Name:\tcmd\nPPid:\t1\n"); /* no Uid: line */
}

/* The first sample, at boot time 1000 s (tick 1000 * hz): processes of every kind. */
static fake_proc first[] = {
    {100, 1, OWNER, OWNER, 1000, 50, 10, NULL},        /* grows by 20 */
    {101, 1, OWNER, OWNER, 2000, 15, 5, "(a) b)"},     /* comm with blanks and ')': +10 */
    {102, 1, OWNER, OWNER, 2500, 5, 0, NULL},          /* vanishes */
    {103, 1, OWNER, OWNER, 3000, 300, 100, NULL},      /* its pid is reused */
    {104, 1, OWNER, OWNER, 3500, 40, 10, NULL},        /* its ticks go back: counts 0 */
    {107, 1, OWNER, 0, 4000, 10, 0, "passwd"},         /* real uid the owner's: +4 */
    {108, 1, 0, OWNER, 4000, 10, 0, NULL},             /* only the effective uid: ignored */
    {200, 1, 0, 0, 100, 1000, 0, "stress-ng"},         /* root's: ignored */
    {500, 1, OWNER, OWNER, 5000, 0, 0, "worker"},      /* self_root */
    {501, 500, 0, 0, 5000, 0, 0, "sudo"},              /* the worker's tree... */
    {502, 501, OWNER, OWNER, 5000, 10, 0, "task"},     /* ...through another user's process */
    {503, 1, OWNER, OWNER, 5000, 5, 0, NULL},          /* not in it: +5 */
    {700, 701, OWNER, OWNER, 6000, 0, 0, NULL},        /* a ppid cycle: +1 */
    {701, 700, OWNER, OWNER, 6000, 0, 0, NULL},        /* +1 */
};

/* The second sample, half a second later (tick 1000 * hz + hz / 2). */
static fake_proc second(long hz, int i)
{
    unsigned long long prev_tick = 1000ULL * (unsigned long long)hz;
    fake_proc v[] = {
        {100, 1, OWNER, OWNER, 1000, 65, 15, NULL},
        {101, 1, OWNER, OWNER, 2000, 22, 8, "(a) b)"},
        {103, 1, OWNER, OWNER, prev_tick + 20, 7, 0, NULL}, /* new, started after: +7 */
        {104, 1, OWNER, OWNER, 3500, 30, 10, NULL},
        {105, 1, OWNER, OWNER, prev_tick, 2, 1, NULL},       /* new, started at: +3 */
        {106, 1, OWNER, OWNER, prev_tick - 10, 500, 0, NULL}, /* new, started before: 0 */
        {107, 1, OWNER, 0, 4000, 14, 0, "passwd"},
        {108, 1, 0, OWNER, 4000, 1010, 0, NULL},
        {200, 1, 0, 0, 100, 5000, 0, "stress-ng"},
        {500, 1, OWNER, OWNER, 5000, 800, 200, "worker"},
        {501, 500, 0, 0, 5000, 0, 0, "sudo"},
        {502, 501, OWNER, OWNER, 5000, 900, 0, "task"},
        {503, 1, OWNER, OWNER, 5000, 10, 0, NULL},
        {700, 701, OWNER, OWNER, 6000, 1, 0, NULL},
        {701, 700, OWNER, OWNER, 6000, 1, 0, NULL},
    };
    return v[i];
}
#define SECOND_COUNT 15

static tf_presence *fake_sampler(const char *proc, const char *dev, double threshold,
                                 double idle_after, pid_t self_root)
{
    char err[256] = "";
    tf_presence_opts o = {.owner = OWNER, .cpu_threshold = threshold, .idle_after_s = idle_after,
                          .self_root = self_root, .proc_root = proc, .dev_root = dev,
                          .clock_ns = fake_clock};
    tf_presence *p = tf_presence_new(&o, err, sizeof err);
    if (!p)
        fail_msg("tf_presence_new: %s", err);
    return p;
}

static void assert_near(double got, double want)
{
    if (fabs(got - want) > 1e-9)
        fail_msg("got %.12g, want %.12g", got, want);
}

static void test_cpu_arithmetic_on_a_fake_proc(void **state)
{
    (void)state;
    long hz = sysconf(_SC_CLK_TCK);
    const char *proc = scratch_path("proc"), *dev = scratch_path("dev-empty");
    make_dir(proc);
    make_dir(dev);
    put_procs(proc, first, sizeof first / sizeof first[0]);
    put_unreadable(proc, 10);
    fake_boot_ns = 1000 * SECOND;
    fake_real_ns = 1700000000 * SECOND;
    tf_presence *p = fake_sampler(proc, dev, 0.5, 0, 500);
    tf_presence *whole = fake_sampler(proc, dev, 0.5, 0, 0); /* no tree excluded */
    assert_near(tf_presence_owner_cpu(p), 0);

    remove_proc(proc, 102);
    remove_proc(proc, 103);
    for (int i = 0; i < SECOND_COUNT; i++) {
        fake_proc f = second(hz, i);
        put_proc(proc, &f);
    }
    put_unreadable(proc, 10000);
    fake_boot_ns += SECOND / 2;
    char why[128];
    assert_int_equal(tf_presence_sample(p, why, sizeof why), 1);
    double ticks = 20 + 10 + 7 + 3 + 4 + 5 + 1 + 1; /* 100 101 103 105 107 503 700 701 */
    assert_near(tf_presence_owner_cpu(p), ticks / (double)hz / 0.5);
    char want[128];
    snprintf(want, sizeof want, "owner CPU %.2f cores > 0.50", ticks / (double)hz / 0.5);
    assert_string_equal(why, want);
    assert_int_equal(tf_presence_sample(whole, why, sizeof why), 1);
    assert_near(tf_presence_owner_cpu(whole), (ticks + 1000 + 890) / (double)hz / 0.5);

    /* a second later: 106, seen last time, counts its growth; everything else is still */
    put_proc(proc, &(fake_proc){106, 1, OWNER, OWNER, 1000ULL * hz - 10, 520, 0, NULL});
    fake_boot_ns += SECOND;
    assert_int_equal(tf_presence_sample(p, why, sizeof why), 0);
    assert_near(tf_presence_owner_cpu(p), 20.0 / (double)hz);
    assert_non_null(strstr(why, "<= 0.50, no terminal input"));

    /* no time passed: no rate */
    assert_int_equal(tf_presence_sample(p, why, sizeof why), 0);
    assert_near(tf_presence_owner_cpu(p), 0);

    /* proc_root gone: an error naming it */
    char cmd[400];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", proc);
    assert_int_equal(system(cmd), 0);
    assert_int_equal(tf_presence_sample(p, why, sizeof why), -1);
    assert_non_null(strstr(why, proc));
    tf_presence_free(p);
    tf_presence_free(whole);
}

/* A process that becomes the owner's (setuid, same pid and start time) is seen as such at the
 * next recheck of every uid, and its CPU counts from the sample after. */
static void test_uid_change_seen_at_recheck(void **state)
{
    (void)state;
    long hz = sysconf(_SC_CLK_TCK);
    const char *proc = scratch_path("proc-recheck"), *dev = scratch_path("dev-recheck");
    make_dir(proc);
    make_dir(dev);
    put_proc(proc, &(fake_proc){800, 1, 0, 0, 10, 0, 0, "login"});
    put_proc(proc, &(fake_proc){801, 1, OWNER, OWNER, 20, 0, 0, NULL}); /* its pid is reused */
    fake_boot_ns = 3000 * SECOND;
    tf_presence *p = fake_sampler(proc, dev, 0.05, 0, 0); /* the first scan, a recheck */
    char why[128];
    for (int scan = 1; scan <= TF_PRESENCE_UID_RECHECK + 1; scan++) {
        put_proc(proc, &(fake_proc){800, 1, OWNER, OWNER, 10, 10ULL * scan, 0, "bash"});
        put_proc(proc, &(fake_proc){801, 1, 0, 0, 3000ULL * hz + 1, 50ULL * scan, 0, "reused"});
        fake_boot_ns += SECOND;
        int want = scan == TF_PRESENCE_UID_RECHECK + 1;
        if (tf_presence_sample(p, why, sizeof why) != want)
            fail_msg("scan %d: %s", scan, why);
        assert_near(tf_presence_owner_cpu(p), want ? 10.0 / (double)hz : 0);
    }
    tf_presence_free(p);
}

/* ---- a fake /dev ---- */

/* dev/name, owned by uid, last read (atime) `ago_ns` before the fake wall clock. */
static void put_terminal(const char *dev, const char *name, uid_t uid, int64_t ago_ns)
{
    char path[440];
    snprintf(path, sizeof path, "%s/%s", dev, name);
    write_file(path, "");
    if (chown(path, uid, 0) < 0)
        fail_msg("chown %s", path);
    int64_t t = fake_real_ns - ago_ns;
    struct timespec times[2] = {{t / SECOND, t % SECOND}, {0, UTIME_OMIT}};
    if (utimensat(AT_FDCWD, path, times, 0) < 0)
        fail_msg("utimensat %s", path);
}

static void test_input_idle_on_a_fake_dev(void **state)
{
    (void)state;
    if (geteuid() != 0)
        skip(); /* terminals of other users: chown */
    const char *proc = scratch_path("proc-empty"), *dev = scratch_path("dev");
    make_dir(proc);
    make_dir(dev);
    make_dir(scratch_path("dev/pts"));
    fake_boot_ns = 2000 * SECOND;
    fake_real_ns = 1700000000 * SECOND + 123456789;
    put_terminal(dev, "pts/0", OWNER, 30 * SECOND);
    put_terminal(dev, "pts/3", OWNER, 3 * SECOND + SECOND / 2); /* the newest */
    put_terminal(dev, "pts/1", OWNER + 1, 1 * SECOND);          /* another user's */
    put_terminal(dev, "pts/ptmx", OWNER, 0);                     /* not a terminal */
    put_terminal(dev, "tty1", OWNER, 100 * SECOND);
    put_terminal(dev, "tty", OWNER, 0);
    put_terminal(dev, "ttyS0", OWNER, 0);
    put_terminal(dev, "console", OWNER, 0);
    put_terminal(dev, "7", OWNER, 0); /* digits, but not in pts/ */

    char why[128];
    tf_presence *p = fake_sampler(proc, dev, 0.5, 5, 0);
    assert_near(tf_presence_input_idle_s(p), 3.5);
    assert_int_equal(tf_presence_sample(p, why, sizeof why), 1);
    assert_string_equal(why, "input 4 s ago");
    tf_presence_free(p);

    p = fake_sampler(proc, dev, 0.5, 3.5, 0); /* not more recent than 3.5 s: away */
    assert_int_equal(tf_presence_sample(p, why, sizeof why), 0);
    assert_string_equal(why, "owner CPU 0.00 cores <= 0.50, input 4 s ago");
    fake_real_ns += 60 * SECOND;
    assert_int_equal(tf_presence_sample(p, why, sizeof why), 0);
    assert_near(tf_presence_input_idle_s(p), 63.5);
    put_terminal(dev, "tty2", OWNER, -10 * SECOND); /* in the future: just now */
    assert_int_equal(tf_presence_sample(p, why, sizeof why), 1);
    assert_near(tf_presence_input_idle_s(p), 0);
    tf_presence_free(p);

    tf_presence_opts none = {.owner = OWNER + 2, .idle_after_s = 1e9, .proc_root = proc,
                             .dev_root = dev, .clock_ns = fake_clock};
    p = tf_presence_new(&none, NULL, 0);
    assert_non_null(p);
    assert_int_equal(tf_presence_sample(p, why, sizeof why), 0);
    assert_true(isinf(tf_presence_input_idle_s(p)));
    assert_string_equal(why, "owner CPU 0.00 cores <= 0.00, no terminal input");
    tf_presence_free(p);
}

/* ---- a real owner: a busy child running as nobody ---- */

static pid_t owner_child = -1;

static int kill_owner_child(void **state)
{
    (void)state;
    if (owner_child > 0) {
        kill(owner_child, SIGKILL);
        waitpid(owner_child, NULL, 0);
        owner_child = -1;
    }
    return 0;
}

/* A child that becomes uid (and gid) and spins.  At nice -10, so that it gets most of a core
 * even beside stress-ng's hogs; it dies with this process or after 60 s, whatever happens. */
static pid_t spawn_busy_child_as(uid_t uid)
{
    pid_t parent = getpid();
    pid_t pid = fork();
    if (pid != 0)
        return pid;
    setpriority(PRIO_PROCESS, 0, -10); /* without CAP_SYS_NICE it spins at nice 0: slower */
    if (setgroups(0, NULL) < 0 || setgid(uid) < 0 || setuid(uid) < 0)
        _exit(2);
    prctl(PR_SET_PDEATHSIG, SIGKILL); /* after setuid, which clears it */
    if (getppid() != parent)
        _exit(3);
    alarm(60);
    for (volatile unsigned long spin = 0;; spin++)
        ;
}

/* Samples every 250 ms until the verdict is `want` or `deadline_s` passed; the last verdict. */
static int sample_until(tf_presence *p, int want, double deadline_s, char *why, size_t whylen)
{
    double end = tf_now_s() + deadline_s;
    int verdict;
    do {
        usleep(250000);
        verdict = tf_presence_sample(p, why, whylen);
    } while (verdict != want && verdict >= 0 && tf_now_s() < end);
    return verdict;
}

static tf_presence *real_sampler(pid_t self_root)
{
    char err[256] = "";
    /* 0.1 cores: more than 2 ticks in 250 ms; input ignored (/dev is the machine's) */
    tf_presence_opts o = {.owner = NOBODY, .cpu_threshold = 0.1, .self_root = self_root};
    tf_presence *p = tf_presence_new(&o, err, sizeof err);
    if (!p)
        fail_msg("tf_presence_new: %s", err);
    return p;
}

static void test_a_busy_nobody_is_present_until_killed(void **state)
{
    (void)state;
    if (geteuid() != 0)
        skip(); /* setuid */
    char why[128];
    tf_presence *p = real_sampler(0), *mine = real_sampler(getpid());
    int before = sample_until(p, 0, 5, why, sizeof why);
    if (before != 0 && tf_presence_owner_cpu(p) > 0.1) {
        print_message("user nobody is busy on this machine already (%s)\n", why);
        tf_presence_free(p);
        tf_presence_free(mine);
        skip();
    }
    assert_int_equal(before, 0);
    owner_child = spawn_busy_child_as(NOBODY);
    assert_true(owner_child > 0);
    int status, seen = sample_until(p, 1, 20, why, sizeof why);
    if (seen != 1 && waitpid(owner_child, &status, WNOHANG) > 0)
        fail_msg("the child playing the owner ended (status 0x%x) before it was seen", status);
    assert_int_equal(seen, 1);
    assert_non_null(strstr(why, "owner CPU"));
    /* the same child seen from a sampler whose own tree holds it: not the owner's */
    assert_int_equal(tf_presence_sample(mine, why, sizeof why), 0);
    kill_owner_child(NULL);
    assert_int_equal(sample_until(p, 0, 20, why, sizeof why), 0);
    tf_presence_free(p);
    tf_presence_free(mine);
}

/* ---- owner names, bad options ---- */

static void test_owner_names(void **state)
{
    (void)state;
    uid_t uid = 7;
    char err[256] = "";
    assert_int_equal(tf_presence_owner_uid("nobody", &uid, err, sizeof err), 0);
    assert_int_equal(uid, NOBODY);
    assert_int_equal(tf_presence_owner_uid("0", &uid, err, sizeof err), 0);
    assert_int_equal(uid, 0);
    assert_int_equal(tf_presence_owner_uid("123456", &uid, err, sizeof err), 0); /* no entry */
    assert_int_equal(uid, 123456);
    assert_int_equal(tf_presence_owner_uid("no_such_user_tf", &uid, err, sizeof err), -1);
    assert_string_equal(err, "owner 'no_such_user_tf': no such user");
    assert_int_equal(tf_presence_owner_uid("4294967295", &uid, err, sizeof err), -1);
    assert_string_equal(err, "owner uid 4294967295 is out of range");
    assert_int_equal(tf_presence_owner_uid("99999999999999999999", &uid, err, sizeof err), -1);
    assert_int_equal(tf_presence_owner_uid("", &uid, err, sizeof err), -1);
    assert_int_equal(uid, 123456); /* untouched */
}

static void test_bad_options(void **state)
{
    (void)state;
    char err[256] = "";
    tf_presence_opts o = {.owner = OWNER, .cpu_threshold = -0.5};
    assert_null(tf_presence_new(&o, err, sizeof err));
    assert_non_null(strstr(err, "CPU threshold -0.5"));
    o = (tf_presence_opts){.owner = OWNER, .idle_after_s = NAN};
    assert_null(tf_presence_new(&o, err, sizeof err));
    assert_non_null(strstr(err, "idle-after"));
    o = (tf_presence_opts){.owner = OWNER, .proc_root = "/nonexistent/proc"};
    assert_null(tf_presence_new(&o, err, sizeof err));
    assert_string_equal(err, "presence: can not read /nonexistent/proc: No such file or directory");
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_cpu_arithmetic_on_a_fake_proc),
        cmocka_unit_test(test_uid_change_seen_at_recheck),
        cmocka_unit_test(test_input_idle_on_a_fake_dev),
        cmocka_unit_test_teardown(test_a_busy_nobody_is_present_until_killed, kill_owner_child),
        cmocka_unit_test(test_owner_names),
        cmocka_unit_test(test_bad_options),
    };
    return cmocka_run_group_tests(tests, scratch_dir_make, scratch_dir_remove);
}
