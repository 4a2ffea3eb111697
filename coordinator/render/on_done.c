/* on_done.c: see on_done.h. */
#include "coordinator/render/on_done.h"

#include <errno.h>
#include <stdarg.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "log.h"

extern char **environ;

/* The child's environment: ours plus the outcome, built before the fork so the child only
 * calls async-signal-safe functions (the HTTP threads may hold the allocator's lock). */
typedef struct envp {
    char **v;
    size_t n, cap;
} envp;

/* Take ownership of "NAME=VALUE" s. */
static int env_put(envp *e, char *s)
{
    if (!s)
        return -1;
    if (e->n + 2 > e->cap) {
        size_t cap = e->cap ? 2 * e->cap : 64;
        char **v = realloc(e->v, cap * sizeof *v);
        if (!v) {
            free(s);
            return -1;
        }
        e->v = v;
        e->cap = cap;
    }
    e->v[e->n++] = s;
    e->v[e->n] = NULL;
    return 0;
}

static int env_add(envp *e, const char *name, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
static int env_add(envp *e, const char *name, const char *fmt, ...)
{
    char value[4096];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(value, sizeof value, fmt, ap);
    va_end(ap);
    char *s = NULL;
    if (asprintf(&s, "%s=%s", name, value) < 0)
        return -1;
    return env_put(e, s);
}

static void env_free(envp *e)
{
    for (size_t i = 0; i < e->n; i++)
        free(e->v[i]);
    free(e->v);
}

/* The command's environment: this process's without any TERRAFARM_ variable, then the
 * outcome's.  0, or -1 when out of memory. */
static int outcome_env(envp *e, const tf_outcome *o)
{
    int bad = 0;
    for (char **p = environ; p && *p; p++)
        if (strncmp(*p, "TERRAFARM_", 10)) /* ours replace any inherited ones */
            bad |= env_put(e, strdup(*p));
    bad |= env_add(e, "TERRAFARM_STATUS", "%s", o->status ? o->status : "");
    bad |= env_add(e, "TERRAFARM_EXIT", "%d", o->exit_status);
    bad |= env_add(e, "TERRAFARM_OUTPUT", "%s", o->output ? o->output : "");
    bad |= env_add(e, "TERRAFARM_PREVIEW", "%s", o->preview ? o->preview : "");
    bad |= env_add(e, "TERRAFARM_SCENE", "%s", o->scene ? o->scene : "");
    bad |= env_add(e, "TERRAFARM_STATS", "%s", o->stats ? o->stats : "");
    bad |= env_add(e, "TERRAFARM_ERROR", "%s", o->error ? o->error : "");
    bad |= env_add(e, "TERRAFARM_DASHBOARD", "%s", o->dashboard ? o->dashboard : "");
    bad |= env_add(e, "TERRAFARM_SIZE", "%dx%d", o->width, o->height);
    bad |= env_add(e, "TERRAFARM_WALL_S", "%.3f", o->wall_s);
    bad |= env_add(e, "TERRAFARM_ROWS", "%d", o->rows);
    bad |= env_add(e, "TERRAFARM_ROWS_TOTAL", "%d", o->height);
    return bad ? -1 : 0;
}

/* The child: `sh -c cmd` with env, the signals as a fresh process has them.  Only
 * async-signal-safe calls (the parent has threads). */
static void exec_command(const char *cmd, char *const *env)
{
    char *const argv[] = {"sh", "-c", (char *)cmd, NULL};
    signal(SIGPIPE, SIG_DFL);
    signal(SIGINT, SIG_DFL);
    signal(SIGTERM, SIG_DFL);
    sigset_t none;
    sigemptyset(&none);
    sigprocmask(SIG_SETMASK, &none, NULL);
    execve("/bin/sh", argv, env);
    _exit(127);
}

/* Wait for the command: its exit status (128 + the signal that killed it), or -1. */
static int command_status(pid_t pid)
{
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

int tf_on_done_run(const char *cmd, const tf_outcome *o)
{
    envp e = {NULL, 0, 0};
    if (outcome_env(&e, o)) {
        env_free(&e);
        tf_warn("--on-done: out of memory");
        return -1;
    }
    pid_t pid = fork();
    if (pid == 0)
        exec_command(cmd, e.v);
    if (pid < 0)
        tf_warn("--on-done: cannot fork: %s", strerror(errno));
    env_free(&e);
    return pid < 0 ? -1 : command_status(pid);
}
