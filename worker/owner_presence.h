/* owner_presence.h: is the owner of this machine present?  The building block of a "Piranha"
 * worker (Musgrave): a worker on someone's workstation that takes tasks only while the owner
 * is away and retreats within 250 ms when the owner comes back.
 *
 * The owner is a user (uid).  Two signals, read from /proc and /dev (both roots injectable):
 *
 * 1. CPU, the fast one: the CPU time (utime + stime, in clock ticks, from /proc/PID/stat) of
 *    every process whose real uid (the Uid: line of /proc/PID/status) is the owner's, except
 *    the worker's own tree (self_root and its descendants, by PPid chains, through processes
 *    of any user).  The owner of /proc/PID itself is not used: it is root for a process that
 *    changed its credentials (not dumpable), e.g. anything started through su or setuid().
 *    Between two samples, CPU cores in use = ticks spent in the interval / ticks per second
 *    / elapsed seconds (CLOCK_BOOTTIME, the clock of a process's start time), where a process
 *      - seen (same pid, same start time) in both samples counts its ticks' growth;
 *      - not in the previous sample counts all of its ticks if it started at or after the
 *        previous sample (they were all spent in the interval), none if it started before
 *        (it was not the owner's then, or was in the worker's tree, or readdir missed it; how
 *        much of its time fell in the interval is unknown: it counts from the next interval);
 *      - that vanished counts nothing (its last ticks are lost: at most one interval's).
 *    A process that starts and ends between two samples is not seen, so the interval should
 *    be short (50 ms).  Resolution: one tick per interval, 0.2 cores at 50 ms and 100 ticks/s.
 *    Cost: reading a status costs about as much as a stat (the kernel makes each file whole on
 *    every open), so a process's uid is read when the sampler first sees it (pid and start
 *    time) and again every TF_PRESENCE_UID_RECHECK-th sample: a process that changes its uid
 *    (setuid, then exec or not) is seen as the owner's within that many samples.  One sample
 *    of 210 processes took 2.4 ms of CPU on a quiet 2-core machine (4.8 ms reading every
 *    status): 5% of a core at 50 ms.
 *
 * 2. Input, the slow one: the newest atime of the owner's terminals (dev_root/pts/N and
 *    dev_root/ttyN whose st_uid is the owner), as seconds since the last input.  The kernel
 *    updates a tty's times only when they change by 8 s or more (a timing leak otherwise),
 *    so this signal serves idle_after_s (minutes), not the 250 ms retreat.  Input to a
 *    graphical session (X11, Wayland) is not a terminal's: it shows as the owner's CPU.
 *
 * Not thread-safe: one sampler per thread. */
#ifndef TF_OWNER_PRESENCE_H
#define TF_OWNER_PRESENCE_H

#include <stddef.h>
#include <sys/types.h>
#include <stdint.h>
#include <time.h>

/* Every this many samples, the uid of every process is read afresh (1 s at 50 ms). */
#define TF_PRESENCE_UID_RECHECK 20

typedef struct tf_presence_opts {
    uid_t owner;
    double cpu_threshold; /* cores: present while the owner uses more than this */
    double idle_after_s;  /* present while the last input is more recent; 0: input ignored */
    pid_t self_root;      /* the worker's own tree, never the owner's; 0: none */
    const char *proc_root; /* NULL: "/proc" */
    const char *dev_root;  /* NULL: "/dev" */
    /* NULL: tf_clock_ns.  Asked for CLOCK_BOOTTIME (intervals, process start times) and
     * CLOCK_REALTIME (terminal times); tests pass a fake clock. */
    int64_t (*clock_ns)(clockid_t id);
} tf_presence_opts;

typedef struct tf_presence tf_presence; /* the sampler: its options and the last sample */

/* An owner given by name ("alice") or number ("1000", taken as is, with or without a passwd
 * entry).  Returns 0 and *uid, or -1 and one line in err naming what was given. */
int tf_presence_owner_uid(const char *name_or_number, uid_t *uid, char *err, size_t errlen);

/* A sampler; takes the first sample, so the first tf_presence_sample measures the CPU over
 * the time since.  NULL and one line in err if the options are invalid or proc_root can not
 * be read. */
tf_presence *tf_presence_new(const tf_presence_opts *o, char *err, size_t errlen);

/* Samples now.  Returns 1 when the owner is present (CPU above cpu_threshold over the interval
 * since the last sample, or input more recent than idle_after_s), 0 when away, -1 on error
 * (the previous sample is kept, so the next one measures over the longer interval).  why
 * receives a short reason ("owner CPU 0.93 cores > 0.25", "input 3 s ago") or the error. */
int tf_presence_sample(tf_presence *p, char *why, size_t whylen);

/* The last sample's owner CPU in cores (0 before the first tf_presence_sample), and the
 * seconds since the owner's last terminal input (INFINITY: no terminal of the owner). */
double tf_presence_owner_cpu(const tf_presence *p);
double tf_presence_input_idle_s(const tf_presence *p);

void tf_presence_free(tf_presence *p);

#endif
