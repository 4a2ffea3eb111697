/* finisher.c: see finisher.h.  A list of jobs, each a thread running tf_rowwriter_finish; a
 * job is removed (joined) once its `done` flag is set. */
#include "coordinator/render/finisher.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"

typedef struct finish_job {
    struct finish_job *next;
    pthread_t thread;
    tf_rowwriter *w;
    char what[256];
    atomic_int done;
    int failed;
    char err[1024];
} finish_job;

struct tf_finisher {
    finish_job *jobs;
    int failed;
    char err[1024];  /* the first failure */
};

static void *finish_thread(void *arg)
{
    finish_job *j = arg;
    j->failed = tf_rowwriter_finish(j->w, j->err, sizeof j->err) != 0;
    atomic_store(&j->done, 1);
    return NULL;
}

tf_finisher *tf_finisher_new(void) { return calloc(1, sizeof(tf_finisher)); }

static void note(tf_finisher *f, finish_job *j)
{
    if (j->failed && !f->failed) {
        f->failed = 1;
        snprintf(f->err, sizeof f->err, "%s", j->err);
    } else if (!j->failed) {
        tf_debug("finished %s", j->what);
    }
}

int tf_finisher_add(tf_finisher *f, tf_rowwriter *w, const char *what, char *err, size_t errlen)
{
    finish_job *j = calloc(1, sizeof *j);
    if (j) {
        j->w = w;
        snprintf(j->what, sizeof j->what, "%s", what);
        if (pthread_create(&j->thread, NULL, finish_thread, j) == 0) {
            j->next = f->jobs;
            f->jobs = j;
            return 0;
        }
        free(j);
    }
    /* no thread: finish here, in the caller's thread */
    return tf_rowwriter_finish(w, err, errlen) ? -1 : 0;
}

static int collect(tf_finisher *f, int wait, char *err, size_t errlen)
{
    for (finish_job **p = &f->jobs; *p;) {
        finish_job *j = *p;
        if (!wait && !atomic_load(&j->done)) {
            p = &j->next;
            continue;
        }
        pthread_join(j->thread, NULL);
        note(f, j);
        *p = j->next;
        free(j);
    }
    if (f->failed)
        return tf_seterr(err, errlen, "%s", f->err);
    return 0;
}

int tf_finisher_reap(tf_finisher *f, char *err, size_t errlen) { return collect(f, 0, err, errlen); }

int tf_finisher_wait(tf_finisher *f, char *err, size_t errlen) { return collect(f, 1, err, errlen); }

void tf_finisher_free(tf_finisher *f)
{
    if (!f)
        return;
    char err[64];
    collect(f, 1, err, sizeof err);
    free(f);
}
