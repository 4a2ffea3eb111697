/* resultcheck.c: see resultcheck.h.  Two lists under one mutex: `todo` (FIFO, the threads take
 * from its head) and `done` (FIFO, the supervisor takes from its head).  A result is in exactly
 * one of todo, a thread's hands, or done, until tf_resultcheck_next returns it.  A small result
 * skips todo: it is checked on the caller's thread and goes straight to done. */
#include "coordinator/render/resultcheck.h"

#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "clock.h"
#include "farmproto.h"
#include "image/exrcheck.h"
#include "log.h"

#define MAX_THREADS 16

/* A result whose chunks decode to at most this many bytes (a 64x64 tile of half RGBA, or 8x8
 * stamps by the dozen) is checked on the caller's thread: inflating it costs a few microseconds,
 * less than handing it to a thread and back (two futex wake-ups, two reads of the thread's CPU
 * clock, which on a VM are system calls, and an event loop polling every millisecond while a
 * verdict is pending).  Measured with 1024 simulated workers on 8x8 stamps: bench/README.md. */
#define INLINE_CHECK_BYTES (64 * 1024)

typedef struct item {
    struct item *next;
    tf_tuple result;
    int refused;
    char why[192];
} item;

typedef struct list {
    item *head, *tail;
} list;

struct tf_resultcheck {
    tf_exr_layout layout;
    pthread_mutex_t mu;
    pthread_cond_t work;
    list todo, done;
    size_t pending;       /* in todo, in a thread's hands, or in done */
    int stop;
    int nthreads;          /* started: none until the first result (see tf_resultcheck_new) */
    int wanted;            /* how many to start then */
    pthread_t threads[MAX_THREADS];
    double cpu_s;
    uint64_t pixels;
    uint8_t *inline_scratch;  /* the caller's thread's inflate buffer for small results */
    size_t inline_cap;
};

static void push(list *l, item *it)
{
    it->next = NULL;
    if (l->tail)
        l->tail->next = it;
    else
        l->head = it;
    l->tail = it;
}

static item *pop(list *l)
{
    item *it = l->head;
    if (it) {
        l->head = it->next;
        if (!l->head)
            l->tail = NULL;
    }
    return it;
}

static double thread_cpu_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

/* Every chunk of the result, against the task rectangle its id names.  0, or -1 with why. */
static int check_result(const tf_exr_layout *l, const tf_tuple *t, uint8_t **scratch,
                        size_t *cap, uint64_t *pixels, char *why, size_t len)
{
    tf_result_msg m;
    if (tf_result_unpack(t, &m))
        return tf_seterr(why, len, "malformed result tuple");
    size_t off = 0;
    for (size_t i = 0; i < m.nchunks; i++) {
        tf_chunk_rec rec;
        tf_chunk_rec_get(m.index + i * TF_CHUNK_RECORD_BYTES, &rec);
        int64_t index = tf_layout_chunk_index(l, rec.cx, rec.cy);
        tf_chunk_ref c = tf_layout_chunk(l, index < 0 ? 0 : index);
        if (index < 0 || rec.packed < 1 || (uint64_t)rec.unpacked != c.unpacked ||
            (uint64_t)rec.packed > m.chunks_len - off)
            return tf_seterr(why, len, "chunk (%d, %d) is not one of the output's", rec.cx,
                             rec.cy);
        if (tf_exr_chunk_check(l, &c, m.chunks + off, (size_t)rec.packed, scratch, cap, why,
                               len))
            return -1;
        off += (size_t)rec.packed;
        *pixels += (uint64_t)c.rect.w * (uint64_t)c.rect.h;
    }
    return 0;
}

static void *checker(void *arg)
{
    tf_resultcheck *rc = arg;
    uint8_t *scratch = NULL;
    size_t cap = 0;
    pthread_mutex_lock(&rc->mu);
    for (;;) {
        while (!rc->stop && !rc->todo.head)
            pthread_cond_wait(&rc->work, &rc->mu);
        if (rc->stop)
            break;
        item *it = pop(&rc->todo);
        pthread_mutex_unlock(&rc->mu);
        double t0 = thread_cpu_s();
        uint64_t px = 0;
        it->refused = check_result(&rc->layout, &it->result, &scratch, &cap, &px, it->why,
                                   sizeof it->why) != 0;
        double spent = thread_cpu_s() - t0;
        pthread_mutex_lock(&rc->mu);
        rc->cpu_s += spent;
        rc->pixels += px;
        push(&rc->done, it);
    }
    pthread_mutex_unlock(&rc->mu);
    free(scratch);
    return NULL;
}

tf_resultcheck *tf_resultcheck_new(const tf_exr_layout *l, int threads, char *err,
                                   size_t errlen)
{
    tf_resultcheck *rc = calloc(1, sizeof *rc);
    if (!rc) {
        tf_seterr(err, errlen, "out of memory for the result checker");
        return NULL;
    }
    rc->layout = *l;
    pthread_mutex_init(&rc->mu, NULL);
    pthread_cond_init(&rc->work, NULL);
    rc->wanted = threads < 1 ? 1 : threads > MAX_THREADS ? MAX_THREADS : threads;
    return rc;
}

/* The threads start with the first result, not with the checker: the coordinator forks its
 * local workers after making the supervisor, and a child forked while another thread is
 * inside the allocator may inherit its lock held for good (AddressSanitizer's was seen to hang
 * a worker at its first allocation of that size).  0, or -1 if none could start. */
static int start_threads(tf_resultcheck *rc)
{
    for (; rc->nthreads < rc->wanted; rc->nthreads++)
        if (pthread_create(&rc->threads[rc->nthreads], NULL, checker, rc))
            break;
    return rc->nthreads > 0 ? 0 : -1;
}

static void drop_all(list *l)
{
    item *it;
    while ((it = pop(l))) {
        tf_tuple_clear(&it->result);
        free(it);
    }
}

void tf_resultcheck_free(tf_resultcheck *rc)
{
    if (!rc)
        return;
    pthread_mutex_lock(&rc->mu);
    rc->stop = 1;
    pthread_cond_broadcast(&rc->work);
    pthread_mutex_unlock(&rc->mu);
    for (int i = 0; i < rc->nthreads; i++)
        pthread_join(rc->threads[i], NULL);
    drop_all(&rc->todo);
    drop_all(&rc->done);
    pthread_cond_destroy(&rc->work);
    pthread_mutex_destroy(&rc->mu);
    free(rc->inline_scratch);
    free(rc);
}

/* The bytes the result's chunks decode to, by their records; SIZE_MAX if it is malformed (the
 * check proper says how). */
static size_t unpacked_bytes(const tf_tuple *t)
{
    tf_result_msg m;
    if (tf_result_unpack(t, &m))
        return SIZE_MAX;
    size_t sum = 0;
    for (size_t i = 0; i < m.nchunks; i++) {
        tf_chunk_rec rec;
        tf_chunk_rec_get(m.index + i * TF_CHUNK_RECORD_BYTES, &rec);
        if (rec.unpacked < 0 || (uint64_t)rec.unpacked > SIZE_MAX - sum)
            return SIZE_MAX;
        sum += (size_t)rec.unpacked;
    }
    return sum;
}

/* Check it here and now.  Its time is the wall time of the check, which for a few microseconds
 * of arithmetic is its CPU time: reading this thread's CPU clock would cost as much again. */
static void check_inline(tf_resultcheck *rc, item *it)
{
    int64_t t0 = tf_now_ns();
    uint64_t px = 0;
    it->refused = check_result(&rc->layout, &it->result, &rc->inline_scratch, &rc->inline_cap,
                               &px, it->why, sizeof it->why) != 0;
    double spent = (double)(tf_now_ns() - t0) * 1e-9;
    pthread_mutex_lock(&rc->mu);
    rc->cpu_s += spent;
    rc->pixels += px;
    push(&rc->done, it);
    rc->pending++;
    pthread_mutex_unlock(&rc->mu);
}

/* Does the tuple reference bytes that another process lends it (a forked worker's outbox)?
 * A networked worker's blobs lie in the receive buffer the server adopted: ours alone. */
static int holds_lent(const tf_tuple *t)
{
    for (int i = 0; i < t->nfields; i++)
        if (t->f[i].type == TF_FIELD_BLOB && !t->f[i].formal && t->f[i].v.bytes.shared &&
            !tf_shared_bytes_adopted(t->f[i].v.bytes.shared))
            return 1;
    return 0;
}

/* Move result into the item, its lent bytes copied: they may lie in a forked worker's outbox,
 * which that process can still write, and the verdict must be about the very bytes the writer
 * will write.  A networked worker's bytes move with the tuple, uncopied: nothing writes the
 * buffer they were received into.  0, or -1 without memory (result left as it was). */
static int take_own_copy(item *it, tf_tuple *result)
{
    if (!holds_lent(result)) {
        tf_tuple_move(&it->result, result);
        return 0;
    }
    if (tf_tuple_copy(&it->result, result))
        return -1;
    tf_tuple_clear(result);
    return 0;
}

int tf_resultcheck_submit(tf_resultcheck *rc, tf_tuple *result)
{
    int small = unpacked_bytes(result) <= INLINE_CHECK_BYTES;
    if (!small && start_threads(rc))
        return -1;
    item *it = calloc(1, sizeof *it);
    if (!it || take_own_copy(it, result)) {
        free(it);
        return -1;
    }
    if (small) {
        check_inline(rc, it);
        return 0;
    }
    pthread_mutex_lock(&rc->mu);
    push(&rc->todo, it);
    rc->pending++;
    pthread_cond_signal(&rc->work);
    pthread_mutex_unlock(&rc->mu);
    return 0;
}

int tf_resultcheck_next(tf_resultcheck *rc, tf_tuple *result, char *why, size_t len)
{
    pthread_mutex_lock(&rc->mu);
    item *it = pop(&rc->done);
    if (it)
        rc->pending--;
    pthread_mutex_unlock(&rc->mu);
    if (!it)
        return -1;
    tf_tuple_move(result, &it->result);
    snprintf(why, len, "%s", it->why);
    int refused = it->refused;
    free(it);
    return refused;
}

size_t tf_resultcheck_pending(tf_resultcheck *rc)
{
    pthread_mutex_lock(&rc->mu);
    size_t n = rc->pending;
    pthread_mutex_unlock(&rc->mu);
    return n;
}

void tf_resultcheck_totals(tf_resultcheck *rc, double *cpu_s, uint64_t *pixels)
{
    pthread_mutex_lock(&rc->mu);
    *cpu_s = rc->cpu_s;
    *pixels = rc->pixels;
    pthread_mutex_unlock(&rc->mu);
}
