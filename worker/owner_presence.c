/* owner_presence.c: see owner_presence.h. */
#include "worker/owner_presence.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <math.h>
#include <pwd.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "clock.h"
#include "log.h"

/* One process as a sample sees it. */
typedef struct proc_entry {
    pid_t pid, ppid;
    uint64_t start_ticks; /* since boot; with the pid, names the process across samples */
    uint64_t cpu_ticks;   /* utime + stime */
    uid_t uid;            /* real; NO_UID until read, or if unreadable */
} proc_entry;

#define NO_UID ((uid_t)-1)

/* Processes sorted by pid. */
typedef struct proc_table {
    proc_entry *v;
    size_t n, cap;
} proc_table;

struct tf_presence {
    tf_presence_opts o; /* proc_root and dev_root point at the copies below */
    char proc_root[PATH_MAX], dev_root[PATH_MAX];
    double ticks_per_s;
    proc_table all;   /* scratch: every process of the current scan */
    proc_table known; /* every process of the previous scan, with the uids it read */
    uint64_t scans;   /* every TF_PRESENCE_UID_RECHECK-th reads every uid afresh */
    proc_table owner; /* scratch: the owner's processes of the current scan */
    proc_table prev;  /* the owner's processes at the last sample */
    int64_t prev_boot_ns;
    double owner_cpu, input_idle_s;
};

int tf_presence_owner_uid(const char *name_or_number, uid_t *uid, char *err, size_t errlen)
{
    const char *s = name_or_number;
    if (!s || !*s)
        return tf_seterr(err, errlen, "no owner given (a user name or a uid)");
    if (s[strspn(s, "0123456789")] == '\0') {
        errno = 0;
        unsigned long long v = strtoull(s, NULL, 10);
        if (errno || v >= (uid_t)-1)
            return tf_seterr(err, errlen, "owner uid %s is out of range", s);
        *uid = (uid_t)v;
        return 0;
    }
    struct passwd *pw = getpwnam(s);
    if (!pw)
        return tf_seterr(err, errlen, "owner '%s': no such user", s);
    *uid = pw->pw_uid;
    return 0;
}

static int check_opts(const tf_presence_opts *o, char *err, size_t errlen)
{
    if (!(o->cpu_threshold >= 0 && isfinite(o->cpu_threshold)))
        return tf_seterr(err, errlen, "presence: CPU threshold %g is not a number of cores >= 0",
                         o->cpu_threshold);
    if (!(o->idle_after_s >= 0 && isfinite(o->idle_after_s)))
        return tf_seterr(err, errlen, "presence: idle-after %g is not a number of seconds >= 0",
                         o->idle_after_s);
    if (o->self_root < 0)
        return tf_seterr(err, errlen, "presence: self root pid %d is negative", (int)o->self_root);
    if (o->owner == (uid_t)-1)
        return tf_seterr(err, errlen, "presence: owner uid -1 is no user");
    return 0;
}

/* name, relative to the open directory dirfd, read as a string into buf (one read: a /proc
 * file is made whole on its first read); its length, or -1 if it can not be read. */
static ssize_t read_text(int dirfd, const char *name, char *buf, size_t size)
{
    int fd = openat(dirfd, name, O_RDONLY | O_CLOEXEC);
    if (fd < 0)
        return -1;
    ssize_t n = read(fd, buf, size - 1);
    close(fd);
    if (n < 0)
        return -1;
    buf[n] = '\0';
    return n;
}

/* The fields of a /proc/PID/stat line a sample needs.  comm (field 2) may hold blanks and
 * parentheses, "(a) b)": the fields resume after the last ')'.  0, or -1 if malformed. */
static int parse_stat(const char *line, proc_entry *e)
{
    const char *after_comm = strrchr(line, ')');
    char state;
    int ppid;
    unsigned long long utime, stime, start;
    /* state ppid pgrp session tty_nr tpgid flags minflt cminflt majflt cmajflt utime stime
     * cutime cstime priority nice num_threads itrealvalue starttime */
    if (!after_comm || sscanf(after_comm + 1, " %c %d %*d %*d %*d %*d %*u %*u %*u %*u %*u %llu "
                              "%llu %*d %*d %*d %*d %*d %*d %llu", &state, &ppid, &utime,
                              &stime, &start) != 5)
        return -1;
    *e = (proc_entry){.ppid = ppid, .start_ticks = start, .cpu_ticks = utime + stime,
                      .uid = NO_UID};
    return 0;
}

/* The real uid, the first number of the Uid: line of a /proc/PID/status.  0, or -1. */
static int parse_real_uid(const char *status, uid_t *uid)
{
    const char *line = strncmp(status, "Uid:", 4) == 0 ? status : strstr(status, "\nUid:");
    unsigned long v;
    if (!line || sscanf(strchr(line, ':') + 1, "%lu", &v) != 1)
        return -1;
    *uid = (uid_t)v;
    return 0;
}

/* A directory entry's name as a pid: 0 unless it is all digits (self, meminfo, ...). */
static pid_t pid_of_name(const char *name)
{
    if (!*name || name[strspn(name, "0123456789")] != '\0')
        return 0;
    long v = strtol(name, NULL, 10);
    return v > 0 && v <= INT_MAX ? (pid_t)v : 0;
}

static proc_entry *table_add(proc_table *t)
{
    if (t->n == t->cap) {
        size_t cap = t->cap ? 2 * t->cap : 256;
        proc_entry *v = realloc(t->v, cap * sizeof *v);
        if (!v)
            return NULL;
        t->v = v;
        t->cap = cap;
    }
    return &t->v[t->n++];
}

static int by_pid(const void *a, const void *b)
{
    pid_t x = ((const proc_entry *)a)->pid, y = ((const proc_entry *)b)->pid;
    return (x > y) - (x < y);
}

static const proc_entry *table_find(const proc_table *t, pid_t pid)
{
    proc_entry key = {.pid = pid};
    return t->n ? bsearch(&key, t->v, t->n, sizeof key, by_pid) : NULL;
}

/* Adds process pid (its stat under procfd) to t.  A process that vanished, or whose stat is
 * unreadable or malformed, is left out (0); -1 only when out of memory. */
static int add_process(proc_table *t, int procfd, pid_t pid)
{
    char path[32], line[1024];
    proc_entry e;
    if (pid == 0)
        return 0;
    snprintf(path, sizeof path, "%d/stat", (int)pid);
    if (read_text(procfd, path, line, sizeof line) < 0 || parse_stat(line, &e) < 0)
        return 0;
    e.pid = pid;
    proc_entry *slot = table_add(t);
    if (!slot)
        return -1;
    *slot = e;
    return 0;
}

/* Every process under procfd into p->all, sorted by pid.  0, or -1 when out of memory. */
static int scan_processes(tf_presence *p, DIR *proc)
{
    struct dirent *de;
    p->all.n = 0;
    while ((de = readdir(proc)))
        if (add_process(&p->all, dirfd(proc), pid_of_name(de->d_name)) < 0)
            return -1;
    if (p->all.n > 1) /* an empty table has no array: qsort(NULL, 0) is undefined */
        qsort(p->all.v, p->all.n, sizeof *p->all.v, by_pid);
    return 0;
}

/* 1 if pid is root or descends from it by the ppids in t.  A chain is at most as long as t,
 * so a cycle (a fake /proc, or pids reused mid-scan) ends. */
static int in_tree(const proc_table *t, pid_t pid, pid_t root)
{
    for (size_t steps = 0; root > 0 && pid > 0 && steps <= t->n; steps++) {
        if (pid == root)
            return 1;
        const proc_entry *e = table_find(t, pid);
        if (!e)
            return 0;
        pid = e->ppid;
    }
    return 0;
}

static uid_t read_real_uid(int procfd, pid_t pid)
{
    char path[32], status[2048];
    uid_t uid;
    snprintf(path, sizeof path, "%d/status", (int)pid);
    if (read_text(procfd, path, status, sizeof status) < 0 || parse_real_uid(status, &uid) < 0)
        return NO_UID;
    return uid;
}

/* e's real uid: the previous scan's if it saw the same process (pid and start time) and no
 * recheck is due, else read from its status (the costlier file: see owner_presence.h). */
static uid_t real_uid_of(const tf_presence *p, int procfd, const proc_entry *e, int recheck)
{
    const proc_entry *seen = table_find(&p->known, e->pid);
    if (!recheck && seen && seen->start_ticks == e->start_ticks && seen->uid != NO_UID)
        return seen->uid;
    return read_real_uid(procfd, e->pid);
}

/* p->all's processes of the owner, outside the worker's tree, into p->owner (sorted); the
 * uids read are kept in p->all. */
static int keep_owner_processes(tf_presence *p, int procfd)
{
    int recheck = p->scans % TF_PRESENCE_UID_RECHECK == 0;
    p->owner.n = 0;
    for (size_t i = 0; i < p->all.n; i++) {
        proc_entry *e = &p->all.v[i];
        if (in_tree(&p->all, e->pid, p->o.self_root))
            continue;
        e->uid = real_uid_of(p, procfd, e, recheck);
        if (e->uid != p->o.owner)
            continue;
        proc_entry *slot = table_add(&p->owner);
        if (!slot)
            return -1;
        *slot = *e;
    }
    return 0;
}

/* The owner's processes now, into p->owner.  0, or -1 and the error in err. */
static int sample_owner_processes(tf_presence *p, char *err, size_t errlen)
{
    DIR *proc = opendir(p->proc_root);
    if (!proc)
        return tf_seterr(err, errlen, "presence: can not read %s: %s", p->proc_root,
                         strerror(errno));
    int rc = scan_processes(p, proc) < 0 ? -1 : keep_owner_processes(p, dirfd(proc));
    closedir(proc);
    if (rc < 0)
        return tf_seterr(err, errlen, "presence: out of memory");
    proc_table t = p->known; /* this scan's uids serve the next */
    p->known = p->all;
    p->all = t;
    p->scans++;
    return 0;
}

/* The ticks process e spent since the previous sample (the rules are in owner_presence.h). */
static uint64_t ticks_in_interval(const tf_presence *p, const proc_entry *e, uint64_t prev_tick)
{
    const proc_entry *was = table_find(&p->prev, e->pid);
    if (was && was->start_ticks == e->start_ticks)
        return e->cpu_ticks > was->cpu_ticks ? e->cpu_ticks - was->cpu_ticks : 0;
    return e->start_ticks >= prev_tick ? e->cpu_ticks : 0;
}

/* Cores the owner used from the previous sample to now_boot_ns (p->owner against p->prev). */
static double owner_cpu_since_prev(const tf_presence *p, int64_t now_boot_ns)
{
    double elapsed_s = (double)(now_boot_ns - p->prev_boot_ns) * 1e-9;
    if (elapsed_s <= 0)
        return 0;
    double prev_boot_s = p->prev_boot_ns > 0 ? (double)p->prev_boot_ns * 1e-9 : 0;
    uint64_t prev_tick = (uint64_t)floor(prev_boot_s * p->ticks_per_s);
    uint64_t ticks = 0;
    for (size_t i = 0; i < p->owner.n; i++)
        ticks += ticks_in_interval(p, &p->owner.v[i], prev_tick);
    return (double)ticks / p->ticks_per_s / elapsed_s;
}

/* The current scan becomes the previous sample, taken at boot_ns. */
static void keep_as_previous(tf_presence *p, int64_t boot_ns)
{
    proc_table t = p->prev;
    p->prev = p->owner;
    p->owner = t;
    p->prev_boot_ns = boot_ns;
}

/* 1 if name is prefix followed by digits only ("tty7" for "tty", "3" for ""). */
static int is_numbered(const char *name, const char *prefix)
{
    size_t n = strlen(prefix);
    if (strncmp(name, prefix, n) != 0 || !name[n])
        return 0;
    return name[n + strspn(name + n, "0123456789")] == '\0';
}

/* Raises *newest_ns to the newest atime of the owner's terminals dev_root/subdir/<prefix>N.
 * A directory that is missing or unreadable has none. */
static void newest_terminal_input(const tf_presence *p, const char *subdir, const char *prefix,
                                  int64_t *newest_ns)
{
    char path[PATH_MAX + 16];
    snprintf(path, sizeof path, "%s/%s", p->dev_root, subdir);
    DIR *d = opendir(path);
    struct dirent *de;
    struct stat st;
    while (d && (de = readdir(d)))
        if (is_numbered(de->d_name, prefix) &&
            fstatat(dirfd(d), de->d_name, &st, AT_SYMLINK_NOFOLLOW) == 0 &&
            st.st_uid == p->o.owner) {
            int64_t atime_ns = (int64_t)st.st_atim.tv_sec * 1000000000 + st.st_atim.tv_nsec;
            if (atime_ns > *newest_ns)
                *newest_ns = atime_ns;
        }
    if (d)
        closedir(d);
}

/* Seconds from the owner's last terminal input to now_real_ns; INFINITY with no terminal. */
static double input_idle_seconds(const tf_presence *p, int64_t now_real_ns)
{
    int64_t newest_ns = INT64_MIN;
    newest_terminal_input(p, "pts", "", &newest_ns);
    newest_terminal_input(p, "", "tty", &newest_ns);
    if (newest_ns == INT64_MIN)
        return INFINITY;
    return newest_ns >= now_real_ns ? 0 : (double)(now_real_ns - newest_ns) * 1e-9;
}

/* 1 (present) or 0 (away) from the last sample's signals, and why. */
static int verdict(const tf_presence *p, char *why, size_t whylen)
{
    char input[48];
    if (p->owner_cpu > p->o.cpu_threshold) {
        snprintf(why, why ? whylen : 0, "owner CPU %.2f cores > %.2f", p->owner_cpu,
                 p->o.cpu_threshold);
        return 1;
    }
    if (p->input_idle_s < p->o.idle_after_s) {
        snprintf(why, why ? whylen : 0, "input %.0f s ago", p->input_idle_s);
        return 1;
    }
    if (isinf(p->input_idle_s))
        snprintf(input, sizeof input, "no terminal input");
    else
        snprintf(input, sizeof input, "input %.0f s ago", p->input_idle_s);
    snprintf(why, why ? whylen : 0, "owner CPU %.2f cores <= %.2f, %s", p->owner_cpu,
             p->o.cpu_threshold, input);
    return 0;
}

int tf_presence_sample(tf_presence *p, char *why, size_t whylen)
{
    int64_t now_boot_ns = p->o.clock_ns(CLOCK_BOOTTIME);
    if (sample_owner_processes(p, why, whylen) < 0)
        return -1;
    p->owner_cpu = owner_cpu_since_prev(p, now_boot_ns);
    keep_as_previous(p, now_boot_ns);
    p->input_idle_s = input_idle_seconds(p, p->o.clock_ns(CLOCK_REALTIME));
    return verdict(p, why, whylen);
}

/* The options copied into p, with the defaults filled in.  0, or -1 and the error. */
static int adopt_opts(tf_presence *p, const tf_presence_opts *o, char *err, size_t errlen)
{
    const char *proc_root = o->proc_root ? o->proc_root : "/proc";
    const char *dev_root = o->dev_root ? o->dev_root : "/dev";
    if (strlen(proc_root) >= sizeof p->proc_root || strlen(dev_root) >= sizeof p->dev_root)
        return tf_seterr(err, errlen, "presence: a root path is too long");
    p->o = *o;
    p->o.proc_root = strcpy(p->proc_root, proc_root);
    p->o.dev_root = strcpy(p->dev_root, dev_root);
    if (!p->o.clock_ns)
        p->o.clock_ns = tf_clock_ns;
    long hz = sysconf(_SC_CLK_TCK);
    p->ticks_per_s = hz > 0 ? (double)hz : 100;
    return 0;
}

tf_presence *tf_presence_new(const tf_presence_opts *o, char *err, size_t errlen)
{
    tf_presence *p = calloc(1, sizeof *p);
    if (!p) {
        tf_seterr(err, errlen, "presence: out of memory");
        return NULL;
    }
    if (check_opts(o, err, errlen) < 0 || adopt_opts(p, o, err, errlen) < 0) {
        tf_presence_free(p);
        return NULL;
    }
    int64_t now_boot_ns = p->o.clock_ns(CLOCK_BOOTTIME);
    if (sample_owner_processes(p, err, errlen) < 0) {
        tf_presence_free(p);
        return NULL;
    }
    keep_as_previous(p, now_boot_ns);
    p->input_idle_s = input_idle_seconds(p, p->o.clock_ns(CLOCK_REALTIME));
    return p;
}

double tf_presence_owner_cpu(const tf_presence *p) { return p->owner_cpu; }
double tf_presence_input_idle_s(const tf_presence *p) { return p->input_idle_s; }

void tf_presence_free(tf_presence *p)
{
    if (!p)
        return;
    free(p->all.v);
    free(p->known.v);
    free(p->owner.v);
    free(p->prev.v);
    free(p);
}
