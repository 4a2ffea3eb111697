/* tuplespace.h: the Linda tuple store, in-process.  The coordinator's tuple-space server
 * (tsserver.h) serves network clients from it, and the supervisor calls it directly from the
 * server's thread (it is "an in-process client").  Not thread-safe: one thread owns a space.
 *
 * Indexing: tuples live in a hash table keyed by (name, arity) -- name being the first field when
 * it is a string -- each bucket a FIFO list in arrival order, and additionally, when the second
 * field is an int64, in a bucket keyed by (name, arity, that int64).  A template whose name is an
 * actual string looks in one bucket only (the (name, arity, int) bucket when its second field is
 * an int64 actual), scanning within it for the other actuals; so 100k tuples of other names cost
 * nothing.  Only a template whose FIRST field is a formal (not used by the farm) scans every tuple
 * of its arity.  Among matching tuples the oldest is returned (FIFO).
 *
 * Blocked requests (ts_wait) are served in arrival order: when a tuple is put in, the waiting
 * requests it matches are visited oldest first; each rd waiter gets a copy and stays satisfied,
 * and the first in waiter takes the tuple (later waiters do not see it); if no in waiter matched,
 * the tuple is stored.  Waiters are indexed by (name, arity) the same way.
 *
 * A chooser (ts_space_set_chooser) may rank the tuples that match a take by the taker named in
 * ts_space_inp_as / ts_wait_as: such a take gets the lowest-ranked match (the oldest among
 * equals; a rank of 0 ends the scan at once), and a tuple put in goes to the matching in waiter
 * with the lowest rank for it (the oldest among equals; rd waiters queued before that one get
 * their copies as above).  Takes naming taker 0, and every take while no chooser is set, are
 * the plain FIFO ones.  The space knows nothing of what the ranks mean (the farm's supervisor
 * uses them for horizontal-extent affinity, coordinator/render/affinity.h).
 *
 * Callbacks run after the store is consistent, so a callback may call any function here
 * (ts_space_out, ts_wait, ts_cancel, ...) on the same space.
 *
 * Accounting: "bytes" of a tuple is tf_tuple_bytes() (its encoded size); the space tracks the
 * current and the highest tuple count and bytes held (docs/contract.md: max_tuple_bytes). */
#ifndef TF_TUPLESPACE_H
#define TF_TUPLESPACE_H

#include <stddef.h>
#include <stdint.h>

#include "linda/tuple.h"

typedef struct ts_space ts_space;

/* A waiter's callback.  tuple is handed over: the callee owns its contents (for an in waiter,
 * the tuple removed from the space; for a rd waiter, a copy) and must tf_tuple_clear or
 * tf_tuple_move it.  waiter_id is the id ts_wait reported (0 when served immediately). */
typedef void (*ts_wait_fn)(void *ctx, uint64_t waiter_id, tf_tuple *tuple);

typedef struct ts_space_stats {
    size_t tuples;          /* tuples held now */
    size_t bytes;           /* sum of tf_tuple_bytes of those */
    size_t max_tuples;      /* high-water marks since creation */
    size_t max_bytes;
    size_t waiters;         /* blocked requests now */
    uint64_t outs, ins, rds;/* completed operations (in/inp, rd/rdp counted when they deliver) */
    uint64_t comparisons;   /* tf_tuple_match calls made by lookups and wake-ups (the index test
                               asserts on this, not on time) */
} ts_space_stats;

ts_space *ts_space_new(void);
/* Frees every tuple and waiter (callbacks are not called). NULL is fine. */
void ts_space_free(ts_space *s);

/* out: put tuple t (no formals) in.  Takes its contents (t is left empty) whatever the result.
 * Serves matching waiters first (see top).  0, or -1 if t has formals (t is then cleared) or
 * memory ran out. */
int ts_space_out(ts_space *s, tf_tuple *t);
/* inp / rdp: 1 and *out filled (caller owns it; must not hold data) when a tuple matches tmpl;
 * 0 when none does; -1 on OOM (rdp's copy). */
int ts_space_inp(ts_space *s, const tf_tuple *tmpl, tf_tuple *out);
int ts_space_rdp(ts_space *s, const tf_tuple *tmpl, tf_tuple *out);

/* The blocking forms as callbacks: if a tuple matches tmpl now, fn is called before ts_wait
 * returns (waiter id 0) and the result is 1; else the request is queued behind earlier ones,
 * *waiter_id (may be NULL) receives its id (> 0) and the result is 0; -1 on OOM.  take = 1 for
 * in, 0 for rd.  tmpl is copied. */
int ts_wait(ts_space *s, const tf_tuple *tmpl, int take, ts_wait_fn fn, void *ctx,
            uint64_t *waiter_id);
/* Drop a queued request; 1 if it was queued, 0 if unknown or already served. */
int ts_cancel(ts_space *s, uint64_t waiter_id);

/* A take's preference among the tuples matching it: lower is better, 0 is the best there is.
 * Called with the taker named by the take; must not call into the space.  It may be called on
 * a stored tuple the take's template does not match (a take ranks a tuple before matching it,
 * and matches it only if it could win): its rank then counts for nothing. */
typedef uint64_t (*ts_rank_fn)(void *ctx, uint64_t taker, const tf_tuple *t);
/* Rank the matches of takes that name a taker with fn from now on (NULL: plain FIFO again). */
void ts_space_set_chooser(ts_space *s, ts_rank_fn fn, void *ctx);
/* ts_space_inp and ts_wait for a named taker (> 0; 0 is the plain forms): see the top. */
int ts_space_inp_as(ts_space *s, const tf_tuple *tmpl, uint64_t taker, tf_tuple *out);
int ts_wait_as(ts_space *s, const tf_tuple *tmpl, int take, uint64_t taker, ts_wait_fn fn,
               void *ctx, uint64_t *waiter_id);

void ts_space_get_stats(const ts_space *s, ts_space_stats *out);
/* Number of tuples held that match tmpl (a scan of tmpl's bucket; for tests and statistics). */
size_t ts_space_count(ts_space *s, const tf_tuple *tmpl);

#endif
