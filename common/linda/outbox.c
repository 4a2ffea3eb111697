/* outbox.c: the ring of records a forked worker shares with its coordinator (see outbox.h). */
#include "linda/outbox.h"

#include <assert.h>
#include <errno.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>

#include "log.h"

/* A record's state, the first word of its header.  Fresh pages read as free. */
enum { RECORD_FREE = 0, RECORD_HELD = 1 };
/* Records the worker may have outstanding; with more, tuples travel through the socket. */
#define OUTBOX_RECORDS 1024

struct tf_outbox {
    uint8_t *base;
    size_t size;
    atomic_int refs;
    /* The worker's records, oldest first (its own copy of this struct, after the fork). */
    uint32_t rec_off[OUTBOX_RECORDS], rec_len[OUTBOX_RECORDS];
    int first, count;
};

/* A record lent to the stored tuple: released, the record is free again. */
typedef struct loan {
    tf_outbox *ob;
    uint64_t record;
} loan;

static _Atomic uint32_t *state_of(const tf_outbox *ob, uint64_t record)
{
    return (_Atomic uint32_t *)(void *)(ob->base + record);
}

tf_outbox *tf_outbox_create(char *err, size_t errlen)
{
    tf_outbox *ob = calloc(1, sizeof *ob);
    if (!ob) {
        tf_seterr(err, errlen, "out of memory");
        return NULL;
    }
    void *p = mmap(NULL, TF_OUTBOX_BYTES, PROT_READ | PROT_WRITE,
                   MAP_SHARED | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
    if (p == MAP_FAILED) {
        tf_seterr(err, errlen, "mapping a worker's outbox: %s", strerror(errno));
        free(ob);
        return NULL;
    }
    ob->base = p;
    ob->size = TF_OUTBOX_BYTES;
    atomic_init(&ob->refs, 1);
    return ob;
}

void tf_outbox_keep_from_later_forks(const tf_outbox *ob)
{
    if (ob)
        madvise(ob->base, ob->size, MADV_DONTFORK);
}

void tf_outbox_unref(tf_outbox *ob)
{
    if (ob && atomic_fetch_sub_explicit(&ob->refs, 1, memory_order_acq_rel) == 1) {
        munmap(ob->base, ob->size);
        free(ob);
    }
}

uint8_t *tf_outbox_base(const tf_outbox *ob) { return ob->base; }
size_t tf_outbox_size(const tf_outbox *ob) { return ob->size; }

/* ---- the worker's side ---- */

int tf_outbox_check(const tf_outbox *ob)
{
#ifndef NDEBUG
    int wraps = 0;
    for (int k = 0; k < ob->count; k++) {
        int i = (ob->first + k) % OUTBOX_RECORDS;
        uint64_t off = ob->rec_off[i], len = ob->rec_len[i];
        assert(off % TF_OUTBOX_HEADER == 0 && len % TF_OUTBOX_HEADER == 0 &&
               "O1: records are 64-byte aligned");
        assert(len > TF_OUTBOX_HEADER && off + len <= ob->size &&
               "O1: a record is a header and a payload, inside the outbox");
        if (k > 0) {
            int j = (i + OUTBOX_RECORDS - 1) % OUTBOX_RECORDS;
            uint64_t end = (uint64_t)ob->rec_off[j] + ob->rec_len[j];
            assert((off == end || off == 0) && "O2: each record follows the one before it");
            wraps += off == 0 && end != 0;
        }
    }
    assert(wraps <= 1 && "O2: at most one wrap between the oldest and the newest");
    if (ob->count > 1) {
        int last = (ob->first + ob->count - 1) % OUTBOX_RECORDS;
        uint64_t end = (uint64_t)ob->rec_off[last] + ob->rec_len[last];
        assert((!wraps || end <= ob->rec_off[ob->first]) &&
               "O3: the newest record does not reach into the oldest");
    }
#else
    (void)ob;
#endif
    return 1;
}

/* Forget the oldest records while the coordinator has released them. */
static void reclaim(tf_outbox *ob)
{
    while (ob->count > 0 &&
           atomic_load_explicit(state_of(ob, ob->rec_off[ob->first]), memory_order_acquire) ==
               RECORD_FREE) {
        ob->first = (ob->first + 1) % OUTBOX_RECORDS;
        ob->count--;
    }
}

/* Where a record of `need` bytes fits after the newest one (or at 0, wrapping), before the
 * oldest; -1 if nowhere. */
static int64_t place(const tf_outbox *ob, uint64_t need)
{
    if (ob->count == 0)
        return 0;
    int last = (ob->first + ob->count - 1) % OUTBOX_RECORDS;
    uint64_t oldest = ob->rec_off[ob->first], newest = ob->rec_off[last];
    uint64_t head = newest + ob->rec_len[last];
    if (newest >= oldest) { /* not wrapped: room after the newest, else before the oldest */
        if (head + need <= ob->size)
            return (int64_t)head;
        return need <= oldest ? 0 : -1;
    }
    return head + need <= oldest ? (int64_t)head : -1;
}

int64_t tf_outbox_reserve(tf_outbox *ob, size_t n)
{
    uint64_t need = TF_OUTBOX_HEADER + ((uint64_t)n + TF_OUTBOX_HEADER - 1) / TF_OUTBOX_HEADER *
                                           TF_OUTBOX_HEADER;
    if (n == 0 || need > ob->size)
        return -1;
    reclaim(ob);
    int64_t at = ob->count < OUTBOX_RECORDS ? place(ob, need) : -1;
    if (at < 0)
        return -1;
    atomic_store_explicit(state_of(ob, (uint64_t)at), RECORD_HELD, memory_order_relaxed);
    int i = (ob->first + ob->count) % OUTBOX_RECORDS;
    ob->rec_off[i] = (uint32_t)at;
    ob->rec_len[i] = (uint32_t)need;
    ob->count++;
    assert(tf_outbox_check(ob));
    return at + TF_OUTBOX_HEADER;
}

/* ---- the coordinator's side ---- */

int tf_outbox_payload_ok(const tf_outbox *ob, uint64_t off, uint64_t len, char *err,
                         size_t errlen)
{
    if (off < TF_OUTBOX_HEADER || off % TF_OUTBOX_HEADER != 0 || off > ob->size ||
        len == 0 || len > ob->size - off)
        return tf_seterr(err, errlen, "no record of the outbox holds %llu bytes at %llu",
                         (unsigned long long)len, (unsigned long long)off);
    return 0;
}

static void return_loan(void *ctx)
{
    loan *l = ctx;
    atomic_store_explicit(state_of(l->ob, l->record), RECORD_FREE, memory_order_release);
    tf_outbox_unref(l->ob);
    free(l);
}

tf_shared_bytes *tf_outbox_lend(tf_outbox *ob, uint64_t off)
{
    loan *l = malloc(sizeof *l);
    if (!l)
        return NULL;
    l->ob = ob;
    l->record = off - TF_OUTBOX_HEADER;
    tf_shared_bytes *s = tf_shared_bytes_wrap(return_loan, l);
    if (!s) {
        free(l);
        return NULL;
    }
    atomic_fetch_add_explicit(&ob->refs, 1, memory_order_relaxed);
    return s;
}
