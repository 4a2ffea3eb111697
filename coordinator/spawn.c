/* spawn.c: see spawn.h. */
#include "coordinator/spawn.h"

#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include "log.h"
#include "worker/worker.h"

/* In the child: keep stdin/stdout/stderr and our socket, close every other inherited fd (the
 * listening socket, other workers' sockets, the output file). */
static void close_inherited_fds(int keep)
{
    if (keep > 3)
        close_range(3, (unsigned)keep - 1, 0);
    close_range((unsigned)keep + 1, ~0U, 0);
}

pid_t tf_spawn_worker(ts_server *srv, const tf_scene *s, const tf_heightfield *hf,
                      const char *backend, int index, char *err, size_t errlen)
{
    int sv[2];
    if (socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, sv)) {
        tf_seterr(err, errlen, "socketpair: %s", strerror(errno));
        return -1;
    }
    pid_t pid = fork();
    if (pid < 0) {
        tf_seterr(err, errlen, "fork: %s", strerror(errno));
        close(sv[0]);
        close(sv[1]);
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
        int status = tf_worker_loop(c, s, hf, "forked", backend);
        ts_client_close(c);
        _exit(status);
    }
    close(sv[1]);
    char peer[32];
    snprintf(peer, sizeof peer, "local worker %d", index);
    if (!ts_server_add_fd(srv, sv[0], peer)) {
        tf_seterr(err, errlen, "cannot serve local worker %d", index);
        kill(pid, SIGKILL);
        return -1;
    }
    return pid;
}
