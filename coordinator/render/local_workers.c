/* local_workers.c: see local_workers.h. */
#include "coordinator/render/local_workers.h"

#include <errno.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/pidfd.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include "clock.h"
#include "log.h"
#include "worker/backend.h"
#include "worker/worker.h"

/* In the child: keep stdin/stdout/stderr and our socket, close every other inherited fd (the
 * listening socket, other workers' sockets, the output file). */
static void close_inherited_fds(int keep)
{
    if (keep > 3)
        close_range(3, (unsigned)keep - 1, 0);
    close_range((unsigned)keep + 1, ~0U, 0);
}

/* Fork worker number `index` running loop (NULL: tf_worker_loop); the parent's end of the
 * socketpair is added to srv as a trusted connection, whose id goes to *conn.  Returns the
 * child's pid, or -1 with a message in err. */
static pid_t spawn_worker(ts_server *srv, const tf_scene *s, const tf_heightfield *hf,
                          const char *backend, tf_local_worker_fn loop, int index,
                          uint64_t *conn, char *err, size_t errlen)
{
    int sv[2];
    if (socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, sv)) {
        tf_seterr(err, errlen, "socketpair: %s", strerror(errno));
        return -1;
    }
    /* Its results come through shared memory (outbox.h); without one, through the socket. */
    char why[160];
    tf_outbox *outbox = tf_outbox_create(why, sizeof why);
    if (!outbox)
        tf_warn("local worker %d: %s; its results come through its socket", index, why);
    pid_t pid = fork();
    if (pid < 0) {
        tf_seterr(err, errlen, "fork: %s", strerror(errno));
        close(sv[0]);
        close(sv[1]);
        tf_outbox_unref(outbox);
        return -1;
    }
    if (pid == 0) {
        /* A worker must not outlive its coordinator, nor react to its terminal's ^C on its own
         * terms: the coordinator decides (it kills or stops its workers). */
        prctl(PR_SET_PDEATHSIG, SIGKILL);
        signal(SIGINT, SIG_IGN);
        signal(SIGTERM, SIG_DFL);
        signal(SIGPIPE, SIG_IGN);
        close_inherited_fds(sv[1]);
        char tag[32];
        snprintf(tag, sizeof tag, "local worker %d", index);
        tf_log_set_tag(tag);
        ts_client *c = ts_client_from_fd(sv[1]);
        if (!c)
            _exit(1);
        ts_client_adopt_outbox(c, outbox);
        int status = (loop ? loop : tf_worker_loop)(c, s, hf, "forked", backend);
        ts_client_close(c);
        _exit(status);
    }
    close(sv[1]);
    tf_outbox_keep_from_later_forks(outbox);
    char peer[32];
    snprintf(peer, sizeof peer, "local worker %d", index);
    uint64_t id = ts_server_add_fd(srv, sv[0], peer);
    *conn = id;
    if (!id) {
        tf_seterr(err, errlen, "cannot serve local worker %d", index);
        kill(pid, SIGKILL);
        tf_outbox_unref(outbox);
        return -1;
    }
    if (outbox && ts_server_adopt_outbox(srv, id, outbox) != 0)
        tf_outbox_unref(outbox);
    return pid;
}

/* ---- the pool ---- */

#define MAX_RESPAWNS_PER_WORKER 3

/* Fork worker i into its slot, with a pidfd to wait on (none where the kernel has none). */
static int spawn_into(tf_local_workers *lw, int i, char *err, size_t errlen)
{
    pid_t p = spawn_worker(lw->srv, lw->scene, lw->hf, lw->backend, lw->loop, i, &lw->conn[i],
                           err, errlen);
    if (p < 0)
        return -1;
    lw->pid[i] = p;
    lw->pidfd[i] = pidfd_open(p, 0);
    return 0;
}

/* Slot i's worker is gone (reaped or killed). */
static void forget(tf_local_workers *lw, int i)
{
    lw->pid[i] = 0;
    if (lw->pidfd[i] >= 0)
        close(lw->pidfd[i]);
    lw->pidfd[i] = -1;
}

int tf_local_workers_start(tf_local_workers *lw, int n, ts_server *srv, const tf_scene *s,
                           const tf_heightfield *hf, const char *backend, char *err,
                           size_t errlen)
{
    return tf_local_workers_start_loop(lw, n, srv, s, hf, backend, NULL, err, errlen);
}

int tf_local_workers_start_loop(tf_local_workers *lw, int n, ts_server *srv, const tf_scene *s,
                                const tf_heightfield *hf, const char *backend,
                                tf_local_worker_fn loop, char *err, size_t errlen)
{
    memset(lw, 0, sizeof *lw);
    lw->srv = srv;
    lw->scene = s;
    lw->hf = hf;
    lw->backend = backend;
    lw->loop = loop;
    size_t slots = (size_t)(n > 0 ? n : 1);
    lw->pid = calloc(slots, sizeof *lw->pid);
    lw->conn = calloc(slots, sizeof *lw->conn);
    lw->pidfd = malloc(slots * sizeof *lw->pidfd);
    lw->respawns = calloc(slots, sizeof *lw->respawns);
    if (!lw->pid || !lw->conn || !lw->pidfd || !lw->respawns)
        return tf_seterr(err, errlen, "out of memory");
    for (size_t i = 0; i < slots; i++)
        lw->pidfd[i] = -1;
    tf_backend_share_cores(backend, n);
    for (int i = 0; i < n; i++) {
        if (spawn_into(lw, i, err, errlen))
            return -1;
        lw->n = i + 1;
    }
    return 0;
}

/* Has any child of this process exited (not yet waited for)?  One system call, where a waitpid
 * per worker would be one each; the status stays for the waitpid that collects it. */
static int any_child_exited(void)
{
    siginfo_t si;
    si.si_pid = 0;
    return waitid(P_ALL, 0, &si, WEXITED | WNOHANG | WNOWAIT) != 0 || si.si_pid != 0;
}

void tf_local_workers_reap(tf_local_workers *lw, int respawn)
{
    if (!any_child_exited())
        return;
    for (int i = 0; i < lw->n; i++) {
        if (lw->pid[i] <= 0)
            continue;
        int status;
        pid_t r = waitpid(lw->pid[i], &status, WNOHANG);
        if (r != lw->pid[i])
            continue;
        forget(lw, i);
        int clean = WIFEXITED(status) && WEXITSTATUS(status) == 0;
        if (clean || !respawn)
            continue;
        if (WIFEXITED(status) && WEXITSTATUS(status) == TF_WORKER_EXIT_NOSTART) {
            lw->gave_up++; /* it said why; restarting would say it again */
            continue;
        }
        if (WIFSIGNALED(status))
            tf_warn("local worker %d killed by signal %d", i, WTERMSIG(status));
        else
            tf_warn("local worker %d exited with status %d", i, WEXITSTATUS(status));
        if (lw->respawns[i] >= MAX_RESPAWNS_PER_WORKER) {
            lw->gave_up++;
            continue;
        }
        lw->respawns[i]++;
        char err[512];
        if (spawn_into(lw, i, err, sizeof err) == 0) {
            tf_info("restarted local worker %d", i);
        } else {
            tf_warn("cannot restart local worker %d: %s", i, err);
        }
    }
}

int tf_local_workers_alive(const tf_local_workers *lw)
{
    int n = 0;
    for (int i = 0; i < lw->n; i++)
        n += lw->pid[i] > 0;
    return n;
}

static int any_connected(const tf_local_workers *lw)
{
    for (int i = 0; i < lw->n; i++)
        if (lw->pid[i] > 0 && ts_server_peer(lw->srv, lw->conn[i]))
            return 1;
    return 0;
}

/* Wait up to ms for a running worker to exit: on the pidfds, or 1 ms without them. */
static void wait_for_an_exit(const tf_local_workers *lw, int ms)
{
    struct pollfd fds[64];
    nfds_t n = 0;
    int blind = 0;  /* running without a pidfd */
    for (int i = 0; i < lw->n; i++) {
        if (lw->pid[i] <= 0)
            continue;
        if (lw->pidfd[i] < 0 || n == sizeof fds / sizeof fds[0])
            blind = 1;
        else
            fds[n++] = (struct pollfd){.fd = lw->pidfd[i], .events = POLLIN};
    }
    poll(fds, n, blind && ms > 1 ? 1 : ms);
}

void tf_local_workers_drain(tf_local_workers *lw, double grace_s)
{
    double until = tf_now_s() + grace_s;
    for (double now = tf_now_s(); tf_local_workers_alive(lw) && now < until; now = tf_now_s()) {
        int ms = (int)((until - now) * 1000) + 1;
        if (any_connected(lw)) {
            ts_server_run_once(lw->srv, ms < 20 ? ms : 20);
        } else { /* the socket closes before the exit can be reaped: wait for the exit */
            ts_server_run_once(lw->srv, 0);
            wait_for_an_exit(lw, ms < 20 ? ms : 20);
        }
        tf_local_workers_reap(lw, 0);
    }
    for (int i = 0; i < lw->n; i++)
        if (lw->pid[i] > 0) {
            kill(lw->pid[i], SIGKILL);
            waitpid(lw->pid[i], NULL, 0);
            forget(lw, i);
        }
}

void tf_local_workers_free(tf_local_workers *lw)
{
    for (int i = 0; lw->pidfd && i < lw->n; i++)
        if (lw->pidfd[i] >= 0)
            close(lw->pidfd[i]);
    free(lw->pid);
    free(lw->conn);
    free(lw->pidfd);
    free(lw->respawns);
    lw->pid = NULL;
    lw->conn = NULL;
    lw->pidfd = NULL;
    lw->respawns = NULL;
    lw->n = 0;
}
