/* on_done.c: see on_done.h. */
#include "coordinator/on_done.h"

#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "log.h"

static void put(const char *name, const char *value) { setenv(name, value ? value : "", 1); }

static void put_int(const char *name, long v)
{
    char buf[32];
    snprintf(buf, sizeof buf, "%ld", v);
    setenv(name, buf, 1);
}

int tf_on_done_run(const char *cmd, const tf_outcome *o)
{
    pid_t pid = fork();
    if (pid < 0) {
        tf_warn("--on-done: cannot fork: %s", strerror(errno));
        return -1;
    }
    if (pid == 0) {
        signal(SIGPIPE, SIG_DFL);
        signal(SIGINT, SIG_DFL);
        signal(SIGTERM, SIG_DFL);
        char buf[64];
        put("TERRAFARM_STATUS", o->status);
        put_int("TERRAFARM_EXIT", o->exit_status);
        put("TERRAFARM_OUTPUT", o->output);
        put("TERRAFARM_PREVIEW", o->preview);
        put("TERRAFARM_SCENE", o->scene);
        put("TERRAFARM_STATS", o->stats);
        put("TERRAFARM_ERROR", o->error);
        put("TERRAFARM_DASHBOARD", o->dashboard);
        snprintf(buf, sizeof buf, "%dx%d", o->width, o->height);
        put("TERRAFARM_SIZE", buf);
        snprintf(buf, sizeof buf, "%.3f", o->wall_s);
        put("TERRAFARM_WALL_S", buf);
        put_int("TERRAFARM_ROWS", o->rows);
        put_int("TERRAFARM_ROWS_TOTAL", o->height);
        execl("/bin/sh", "sh", "-c", cmd, (char *)NULL);
        _exit(127);
    }
    int status;
    while (waitpid(pid, &status, 0) < 0)
        if (errno != EINTR) {
            tf_warn("--on-done: %s", strerror(errno));
            return -1;
        }
    int rc = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    if (rc)
        tf_warn("--on-done command exited with status %d", rc);
    return rc;
}
