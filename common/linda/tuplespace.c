/* tuplespace.c: the in-process Linda store (see tuplespace.h for the semantics).
 *
 * Data structures
 *   - bucket: one per distinct key, in a chained hash table.  A key is (name, arity) -- the
 *     "primary" key -- or (name, arity, k2) where k2 is an int64 second field -- the
 *     "secondary" key.  A bucket holds the stored tuples with that key in a FIFO list, and a
 *     primary bucket also holds the blocked requests whose template has that (name, arity).
 *     A bucket is freed as soon as it holds neither tuples nor waiters, so per-task secondary
 *     keys do not accumulate over a long render.
 *   - entry: a stored tuple.  It sits on up to three FIFO lists at once: link 0 its primary
 *     bucket, link 1 its secondary bucket (when its second field is an int64), link 2 the list
 *     of every tuple of its arity (only used by templates whose first field is not an actual
 *     string, and by tuples that have no string name).
 *   - waiter: a blocked in/rd.  Waiters with a named template hang on their primary bucket;
 *     others on the "wild" list.  Every waiter is also in an id hash for ts_cancel.  A global
 *     sequence number orders waiters across the two lists (arrival order).
 *
 * INVARIANTS (checked clause by clause in debug builds, `make asan`: L1 by assert_no_match_waits
 * after every out and wait, L2-L3 by assert_space_counts whenever the statistics are read and
 * when the space is freed):
 *   L1. No stored tuple matches a queued in-waiter or rd-waiter: a tuple is stored only after
 *       every waiter that matches it has been served (rd) or it has been taken (in), and a
 *       waiter is queued only after no stored tuple matched it.  (A wake-up that runs out of
 *       memory leaves the waiters it could not serve queued, to be served by a later out; from
 *       then on, short_of_memory set, L1 is not checked.)
 *   L2. The statistics count what is there: st.tuples the stored tuples, st.bytes the sum of
 *       their sizes, st.waiters (and nwaiters) the queued waiters.
 *   L3. Every bucket holds a stored tuple or a queued waiter (an emptied one is freed at once),
 *       and nbuckets counts the buckets. */
#include "linda/tuplespace.h"

#include <assert.h>
#include <stdlib.h>
#include <string.h>

#define LINK_PRIMARY 0
#define LINK_SECONDARY 1
#define LINK_ARITY 2

typedef struct bucket bucket;

typedef struct entry {
    tf_tuple t;
    size_t bytes;
    struct entry *prev[3], *next[3];
    bucket *bucket[2]; /* primary, secondary (either may be NULL) */
} entry;

typedef struct elist {
    entry *head, *tail;
} elist;

typedef struct waiter {
    tf_tuple tmpl;
    int take;
    uint64_t taker;             /* ts_wait_as: who takes, for the chooser (0: nobody named) */
    ts_wait_fn fn;
    void *ctx;
    uint64_t id, seq;
    struct waiter *prev, *next; /* in bucket->waiters or space->wild */
    bucket *bucket;             /* NULL: on the wild list */
    struct waiter *id_next;     /* id hash chain */
} waiter;

typedef struct wlist {
    waiter *head, *tail;
} wlist;

/* A lookup key; name points at the caller's bytes until a bucket copies it. */
typedef struct key {
    const char *name;
    uint32_t name_len;
    int arity;
    int has_k2;
    int64_t k2;
} key;

struct bucket {
    key k; /* k.name owned by the bucket */
    uint64_t hash;
    elist tuples;
    int link; /* which entry link threads `tuples`: LINK_PRIMARY or LINK_SECONDARY */
    wlist waiters;
    bucket *chain;
};

struct ts_space {
    bucket **slots;
    size_t nslots, nbuckets;
    waiter **wslots;
    size_t nwslots, nwaiters;
    wlist wild;
    elist by_arity[TF_TUPLE_MAX_FIELDS + 1];
    uint64_t next_waiter_id, next_seq;
    ts_space_stats st;
    int short_of_memory; /* a wake-up left matching waiters queued (L1) */
    ts_rank_fn rank;     /* the chooser (ts_space_set_chooser), or NULL */
    void *rank_ctx;
};

#ifndef NDEBUG
static int assert_space_counts(const ts_space *s); /* L2, L3 */
#endif

/* ---- lists ---- */
static void elist_push(elist *l, entry *e, int k)
{
    e->next[k] = NULL;
    e->prev[k] = l->tail;
    if (l->tail)
        l->tail->next[k] = e;
    else
        l->head = e;
    l->tail = e;
}

static void elist_remove(elist *l, entry *e, int k)
{
    if (e->prev[k])
        e->prev[k]->next[k] = e->next[k];
    else
        l->head = e->next[k];
    if (e->next[k])
        e->next[k]->prev[k] = e->prev[k];
    else
        l->tail = e->prev[k];
    e->prev[k] = e->next[k] = NULL;
}

static void wlist_push(wlist *l, waiter *w)
{
    w->next = NULL;
    w->prev = l->tail;
    if (l->tail)
        l->tail->next = w;
    else
        l->head = w;
    l->tail = w;
}

static void wlist_remove(wlist *l, waiter *w)
{
    if (w->prev)
        w->prev->next = w->next;
    else
        l->head = w->next;
    if (w->next)
        w->next->prev = w->prev;
    else
        l->tail = w->prev;
    w->prev = w->next = NULL;
}

/* ---- keys and the bucket table ---- */
static uint64_t key_hash(const key *k)
{
    uint64_t h = 1469598103934665603ull; /* FNV-1a */
    for (uint32_t i = 0; i < k->name_len; i++)
        h = (h ^ (uint8_t)k->name[i]) * 1099511628211ull;
    h = (h ^ (uint64_t)k->arity) * 1099511628211ull;
    if (k->has_k2) {
        uint64_t v = (uint64_t)k->k2;
        for (int i = 0; i < 8; i++)
            h = (h ^ ((v >> (8 * i)) & 0xff)) * 1099511628211ull;
        h ^= 0x9e3779b97f4a7c15ull;
    }
    return h ^ (h >> 29);
}

static int key_equal(const key *a, const key *b)
{
    return a->arity == b->arity && a->has_k2 == b->has_k2 && (!a->has_k2 || a->k2 == b->k2) &&
           a->name_len == b->name_len && memcmp(a->name, b->name, a->name_len) == 0;
}

/* The primary key of a tuple or template; 0 if its first field is not an actual string. */
static int primary_key(const tf_tuple *t, key *k)
{
    const char *name = tf_tuple_name(t);
    if (!name)
        return 0;
    k->name = name;
    k->name_len = t->f[0].v.bytes.len;
    k->arity = t->nfields;
    k->has_k2 = 0;
    k->k2 = 0;
    return 1;
}

/* The secondary key: the primary key plus an actual int64 second field; 0 if none. */
static int secondary_key(const tf_tuple *t, key *k)
{
    int64_t v;
    if (!primary_key(t, k) || tf_tuple_get_int(t, 1, &v) != 0)
        return 0;
    k->has_k2 = 1;
    k->k2 = v;
    return 1;
}

static bucket *bucket_find(ts_space *s, const key *k, uint64_t h)
{
    for (bucket *b = s->slots[h & (s->nslots - 1)]; b; b = b->chain)
        if (b->hash == h && key_equal(&b->k, k))
            return b;
    return NULL;
}

static int table_grow(ts_space *s)
{
    size_t n = s->nslots * 2;
    bucket **slots = calloc(n, sizeof *slots);
    if (!slots)
        return -1;
    for (size_t i = 0; i < s->nslots; i++) {
        bucket *b = s->slots[i], *next;
        for (; b; b = next) {
            next = b->chain;
            b->chain = slots[b->hash & (n - 1)];
            slots[b->hash & (n - 1)] = b;
        }
    }
    free(s->slots);
    s->slots = slots;
    s->nslots = n;
    return 0;
}

static bucket *bucket_get(ts_space *s, const key *k, int link)
{
    uint64_t h = key_hash(k);
    bucket *b = bucket_find(s, k, h);
    if (b)
        return b;
    if (s->nbuckets >= s->nslots && table_grow(s) != 0)
        return NULL;
    b = calloc(1, sizeof *b);
    char *name = malloc(k->name_len + 1);
    if (!b || !name) {
        free(b);
        free(name);
        return NULL;
    }
    memcpy(name, k->name, k->name_len);
    name[k->name_len] = 0;
    b->k = *k;
    b->k.name = name;
    b->hash = h;
    b->link = link;
    size_t slot = h & (s->nslots - 1);
    b->chain = s->slots[slot];
    s->slots[slot] = b;
    s->nbuckets++;
    return b;
}

/* Free b if it holds nothing any more. */
static void bucket_release_if_empty(ts_space *s, bucket *b)
{
    if (!b || b->tuples.head || b->waiters.head)
        return;
    bucket **pp = &s->slots[b->hash & (s->nslots - 1)];
    while (*pp != b)
        pp = &(*pp)->chain;
    *pp = b->chain;
    free((char *)b->k.name);
    free(b);
    s->nbuckets--;
}

/* ---- the waiter id table ---- */
static waiter **wslot(ts_space *s, uint64_t id) { return &s->wslots[id & (s->nwslots - 1)]; }

static int wtable_grow(ts_space *s)
{
    size_t n = s->nwslots * 2;
    waiter **slots = calloc(n, sizeof *slots);
    if (!slots)
        return -1;
    for (size_t i = 0; i < s->nwslots; i++) {
        waiter *w = s->wslots[i], *next;
        for (; w; w = next) {
            next = w->id_next;
            w->id_next = slots[w->id & (n - 1)];
            slots[w->id & (n - 1)] = w;
        }
    }
    free(s->wslots);
    s->wslots = slots;
    s->nwslots = n;
    return 0;
}

static void wtable_remove(ts_space *s, waiter *w)
{
    waiter **pp = wslot(s, w->id);
    while (*pp && *pp != w)
        pp = &(*pp)->id_next;
    if (*pp)
        *pp = w->id_next;
    s->nwaiters--;
}

/* ---- creation ---- */
ts_space *ts_space_new(void)
{
    ts_space *s = calloc(1, sizeof *s);
    if (!s)
        return NULL;
    s->nslots = 64;
    s->nwslots = 64;
    s->slots = calloc(s->nslots, sizeof *s->slots);
    s->wslots = calloc(s->nwslots, sizeof *s->wslots);
    if (!s->slots || !s->wslots) {
        free(s->slots);
        free(s->wslots);
        free(s);
        return NULL;
    }
    s->next_waiter_id = 1;
    return s;
}

static void waiter_free(waiter *w)
{
    tf_tuple_clear(&w->tmpl);
    free(w);
}

void ts_space_free(ts_space *s)
{
    if (!s)
        return;
    assert(assert_space_counts(s));
    for (int a = 0; a <= TF_TUPLE_MAX_FIELDS; a++) {
        entry *e = s->by_arity[a].head, *next;
        for (; e; e = next) {
            next = e->next[LINK_ARITY];
            tf_tuple_clear(&e->t);
            free(e);
        }
    }
    for (size_t i = 0; i < s->nwslots; i++) {
        waiter *w = s->wslots[i], *next;
        for (; w; w = next) {
            next = w->id_next;
            waiter_free(w);
        }
    }
    for (size_t i = 0; i < s->nslots; i++) {
        bucket *b = s->slots[i], *next;
        for (; b; b = next) {
            next = b->chain;
            free((char *)b->k.name);
            free(b);
        }
    }
    free(s->slots);
    free(s->wslots);
    free(s);
}

/* ---- stored tuples ---- */
static int entry_insert(ts_space *s, tf_tuple *t)
{
    entry *e = calloc(1, sizeof *e);
    if (!e)
        return -1;
    key pk, sk;
    if (primary_key(t, &pk) && !(e->bucket[0] = bucket_get(s, &pk, LINK_PRIMARY)))
        goto oom;
    if (secondary_key(t, &sk) && !(e->bucket[1] = bucket_get(s, &sk, LINK_SECONDARY))) {
        bucket_release_if_empty(s, e->bucket[0]);
        goto oom;
    }
    tf_tuple_move(&e->t, t);
    e->bytes = tf_tuple_bytes(&e->t);
    for (int k = 0; k < 2; k++)
        if (e->bucket[k])
            elist_push(&e->bucket[k]->tuples, e, k);
    elist_push(&s->by_arity[e->t.nfields], e, LINK_ARITY);
    s->st.tuples++;
    s->st.bytes += e->bytes;
    if (s->st.tuples > s->st.max_tuples)
        s->st.max_tuples = s->st.tuples;
    if (s->st.bytes > s->st.max_bytes)
        s->st.max_bytes = s->st.bytes;
    return 0;
oom:
    free(e);
    return -1;
}

/* Unlink e from every list, move its tuple into *out and free the entry. */
static void entry_take(ts_space *s, entry *e, tf_tuple *out)
{
    for (int k = 0; k < 2; k++) {
        if (e->bucket[k]) {
            elist_remove(&e->bucket[k]->tuples, e, k);
            bucket_release_if_empty(s, e->bucket[k]);
        }
    }
    elist_remove(&s->by_arity[e->t.nfields], e, LINK_ARITY);
    s->st.tuples--;
    s->st.bytes -= e->bytes;
    tf_tuple_move(out, &e->t);
    free(e);
}

/* The list a lookup of tmpl scans (one bucket when tmpl is named) and its link; NULL if none. */
static const elist *candidates(ts_space *s, const tf_tuple *tmpl, int *link)
{
    if (tmpl->nfields < 0 || tmpl->nfields > TF_TUPLE_MAX_FIELDS)
        return NULL;
    key k;
    if (secondary_key(tmpl, &k) || primary_key(tmpl, &k)) {
        bucket *b = bucket_find(s, &k, key_hash(&k));
        *link = b ? b->link : LINK_PRIMARY;
        return b ? &b->tuples : NULL;
    }
    *link = LINK_ARITY;
    return &s->by_arity[tmpl->nfields];
}

/* The chooser's pick for taker among l's tuples matching tmpl: the lowest rank, the oldest
 * among equals; a rank of 0 ends the scan. */
static entry *find_ranked(ts_space *s, const elist *l, int link, const tf_tuple *tmpl,
                          uint64_t taker, uint64_t *comparisons)
{
    entry *best = NULL;
    uint64_t best_rank = UINT64_MAX;
    for (entry *e = l->head; e; e = e->next[link]) {
        if (comparisons)
            (*comparisons)++;
        /* Ranked before it is matched: a tuple that cannot outrank the best match so far is
         * not compared with the template (the same choice, fewer matches). */
        uint64_t r = s->rank(s->rank_ctx, taker, &e->t);
        if ((best && r >= best_rank) || !tf_tuple_match(tmpl, &e->t))
            continue;
        best = e;
        best_rank = r;
        if (r == 0)
            break;
    }
    return best;
}

/* The stored tuple matching tmpl that taker gets (the oldest, unless a chooser ranks them), or
 * NULL.  Each comparison is counted in *comparisons (NULL: not counted). */
static entry *find(ts_space *s, const tf_tuple *tmpl, uint64_t taker, uint64_t *comparisons)
{
    int link;
    const elist *l = candidates(s, tmpl, &link);
    if (!l)
        return NULL;
    if (s->rank && taker)
        return find_ranked(s, l, link, tmpl, taker, comparisons);
    for (entry *e = l->head; e; e = e->next[link]) {
        if (comparisons)
            (*comparisons)++;
        if (tf_tuple_match(tmpl, &e->t))
            return e;
    }
    return NULL;
}

static entry *lookup(ts_space *s, const tf_tuple *tmpl, uint64_t taker)
{
    return find(s, tmpl, taker, &s->st.comparisons);
}

#ifndef NDEBUG
/* L1, one assert (SQLite's assert_pager_state): no queued waiter's lookup finds a tuple.
 * Returns 1, so that a call sits inside assert() and vanishes with NDEBUG. */
static int assert_no_match_waits(ts_space *s)
{
    for (size_t i = 0; i < s->nwslots; i++)
        for (const waiter *w = s->wslots[i]; w; w = w->id_next)
            assert((s->short_of_memory || !find(s, &w->tmpl, 0, NULL)) &&
                   "L1: no stored tuple matches a queued waiter");
    return 1;
}

/* The queued waiters, counted on their lists (the buckets' and the wild one). */
static size_t count_waiters(const ts_space *s, size_t *buckets)
{
    size_t n = 0;
    *buckets = 0;
    for (const waiter *w = s->wild.head; w; w = w->next)
        n++;
    for (size_t i = 0; i < s->nslots; i++)
        for (const bucket *b = s->slots[i]; b; b = b->chain, (*buckets)++) {
            assert((b->tuples.head || b->waiters.head) &&
                   "L3: every bucket holds a stored tuple or a queued waiter");
            for (const waiter *w = b->waiters.head; w; w = w->next)
                n++;
        }
    return n;
}

/* L2 and L3, one assert a clause.  Returns 1, as assert_no_match_waits. */
static int assert_space_counts(const ts_space *s)
{
    size_t tuples = 0, bytes = 0, buckets;
    for (int a = 0; a <= TF_TUPLE_MAX_FIELDS; a++)
        for (const entry *e = s->by_arity[a].head; e; e = e->next[LINK_ARITY]) {
            tuples++;
            bytes += e->bytes;
        }
    size_t waiters = count_waiters(s, &buckets);
    assert(tuples == s->st.tuples && "L2: st.tuples counts the stored tuples");
    assert(bytes == s->st.bytes && "L2: st.bytes is the sum of their sizes");
    assert(waiters == s->st.waiters && waiters == s->nwaiters &&
           "L2: st.waiters and nwaiters count the queued waiters");
    assert(buckets == s->nbuckets && "L3: nbuckets counts the buckets");
    return 1;
}
#endif

/* ---- waiters ---- */
typedef struct delivery {
    waiter *w;
    tf_tuple t;
} delivery;

/* The next waiter in arrival order from the two candidate lists (bucket list and wild list),
 * advancing whichever cursor it came from. */
static waiter *next_candidate(waiter **a, waiter **b)
{
    waiter **from = NULL;
    if (*a && (!*b || (*a)->seq < (*b)->seq))
        from = a;
    else if (*b)
        from = b;
    if (!from)
        return NULL;
    waiter *w = *from;
    *from = w->next;
    return w;
}

static void waiter_unlink(ts_space *s, waiter *w)
{
    if (w->bucket) {
        wlist_remove(&w->bucket->waiters, w);
        bucket_release_if_empty(s, w->bucket);
        w->bucket = NULL;
    } else {
        wlist_remove(&s->wild, w);
    }
    wtable_remove(s, w);
    s->st.waiters--;
}

/* The in waiter the chooser gives t to: the lowest rank, the oldest among equals (a waiter
 * naming no taker ranks 0).  NULL without a chooser: the first matching in waiter takes t. */
static waiter *chosen_taker(ts_space *s, bucket *b, const tf_tuple *t)
{
    if (!s->rank)
        return NULL;
    waiter *ca = b ? b->waiters.head : NULL, *cb = s->wild.head, *w, *best = NULL;
    uint64_t best_rank = UINT64_MAX;
    while ((w = next_candidate(&ca, &cb)) != NULL) {
        s->st.comparisons++;
        if (!w->take || !tf_tuple_match(&w->tmpl, t))
            continue;
        uint64_t r = w->taker ? s->rank(s->rank_ctx, w->taker, t) : 0;
        if (!best || r < best_rank) {
            best = w;
            best_rank = r;
        }
        if (r == 0)
            break;
    }
    return best;
}

/* Collect the waiters t serves, oldest first: every matching rd waiter up to and including the
 * in waiter that takes it (the first matching one, or the chooser's).  Each is unlinked and
 * given its tuple (a copy for rd; t itself for the in waiter, leaving t empty).  Returns the
 * number collected into *out (malloc'd), or -1. */
static long collect_waiters(ts_space *s, tf_tuple *t, delivery **out)
{
    *out = NULL;
    key k;
    bucket *b = primary_key(t, &k) ? bucket_find(s, &k, key_hash(&k)) : NULL;
    waiter *chosen = chosen_taker(s, b, t);
    waiter *ca = b ? b->waiters.head : NULL, *cb = s->wild.head, *w;
    size_t n = 0, cap = 0;
    delivery *d = NULL;
    while ((w = next_candidate(&ca, &cb)) != NULL) {
        s->st.comparisons++;
        if ((chosen && w->take && w != chosen) || !tf_tuple_match(&w->tmpl, t))
            continue;
        if (n == cap) {
            size_t ncap = cap ? cap * 2 : 4;
            delivery *nd = realloc(d, ncap * sizeof *nd);
            if (!nd) {
                s->short_of_memory = 1; /* L1: those not collected stay queued, served later */
                break;
            }
            d = nd;
            cap = ncap;
        }
        if (w->take) {
            tf_tuple_move(&d[n].t, t);
        } else if (tf_tuple_copy(&d[n].t, t) != 0) {
            s->short_of_memory = 1; /* L1: this rd waiter stays queued */
            continue;
        }
        d[n++].w = w;
        /* ca/cb already point past w, so unlinking it (and maybe freeing an emptied bucket:
         * only possible when ca is NULL, as w was its last waiter) is safe. */
        waiter_unlink(s, w);
        if (w->take)
            break;
    }
    *out = d;
    return (long)n;
}

static void deliver(ts_space *s, delivery *d, long n)
{
    for (long i = 0; i < n; i++) {
        waiter *w = d[i].w;
        if (w->take)
            s->st.ins++;
        else
            s->st.rds++;
        w->fn(w->ctx, w->id, &d[i].t);
        tf_tuple_clear(&d[i].t); /* in case the callback left it */
        waiter_free(w);
    }
    free(d);
}

int ts_space_out(ts_space *s, tf_tuple *t)
{
    if (tf_tuple_has_formals(t) || t->nfields < 0 || t->nfields > TF_TUPLE_MAX_FIELDS) {
        tf_tuple_clear(t);
        return -1;
    }
    s->st.outs++;
    delivery *d;
    long n = collect_waiters(s, t, &d);
    if (n < 0)
        n = 0;
    int rc = 0;
    /* An in waiter took it, or it is stored; either way the store is consistent before any
     * callback runs, so callbacks may re-enter. */
    int taken = n > 0 && d[n - 1].w->take;
    if (!taken && entry_insert(s, t) != 0) {
        tf_tuple_clear(t);
        rc = -1;
    }
    assert(assert_no_match_waits(s));
    deliver(s, d, n);
    return rc;
}

int ts_space_inp(ts_space *s, const tf_tuple *tmpl, tf_tuple *out)
{
    return ts_space_inp_as(s, tmpl, 0, out);
}

int ts_space_inp_as(ts_space *s, const tf_tuple *tmpl, uint64_t taker, tf_tuple *out)
{
    entry *e = lookup(s, tmpl, taker);
    if (!e)
        return 0;
    entry_take(s, e, out);
    s->st.ins++;
    return 1;
}

int ts_space_rdp(ts_space *s, const tf_tuple *tmpl, tf_tuple *out)
{
    entry *e = lookup(s, tmpl, 0);
    if (!e)
        return 0;
    if (tf_tuple_copy(out, &e->t) != 0)
        return -1;
    s->st.rds++;
    return 1;
}

/* Queue a copy of tmpl as a new waiter; 0 or -1. */
static int enqueue_waiter(ts_space *s, const tf_tuple *tmpl, int take, uint64_t taker,
                          ts_wait_fn fn, void *ctx, uint64_t *waiter_id)
{
    if (s->nwaiters >= s->nwslots && wtable_grow(s) != 0)
        return -1;
    waiter *w = calloc(1, sizeof *w);
    if (!w)
        return -1;
    if (tf_tuple_copy(&w->tmpl, tmpl) != 0) {
        free(w);
        return -1;
    }
    key k;
    if (primary_key(&w->tmpl, &k)) {
        w->bucket = bucket_get(s, &k, LINK_PRIMARY);
        if (!w->bucket) {
            waiter_free(w);
            return -1;
        }
        wlist_push(&w->bucket->waiters, w);
    } else {
        wlist_push(&s->wild, w);
    }
    w->take = take;
    w->taker = taker;
    w->fn = fn;
    w->ctx = ctx;
    w->id = s->next_waiter_id++;
    w->seq = s->next_seq++;
    w->id_next = *wslot(s, w->id);
    *wslot(s, w->id) = w;
    s->nwaiters++;
    s->st.waiters++;
    if (waiter_id)
        *waiter_id = w->id;
    return 0;
}

int ts_wait(ts_space *s, const tf_tuple *tmpl, int take, ts_wait_fn fn, void *ctx,
            uint64_t *waiter_id)
{
    return ts_wait_as(s, tmpl, take, 0, fn, ctx, waiter_id);
}

int ts_wait_as(ts_space *s, const tf_tuple *tmpl, int take, uint64_t taker, ts_wait_fn fn,
               void *ctx, uint64_t *waiter_id)
{
    if (waiter_id)
        *waiter_id = 0;
    tf_tuple got;
    int found = take ? ts_space_inp_as(s, tmpl, taker, &got) : ts_space_rdp(s, tmpl, &got);
    if (found < 0)
        return -1;
    if (found) {
        fn(ctx, 0, &got);
        tf_tuple_clear(&got);
        return 1;
    }
    int rc = enqueue_waiter(s, tmpl, take, taker, fn, ctx, waiter_id);
    assert(assert_no_match_waits(s));
    return rc;
}

int ts_cancel(ts_space *s, uint64_t waiter_id)
{
    if (waiter_id == 0)
        return 0;
    waiter *w = *wslot(s, waiter_id);
    while (w && w->id != waiter_id)
        w = w->id_next;
    if (!w)
        return 0;
    waiter_unlink(s, w);
    waiter_free(w);
    return 1;
}

void ts_space_set_chooser(ts_space *s, ts_rank_fn fn, void *ctx)
{
    s->rank = fn;
    s->rank_ctx = ctx;
}

void ts_space_get_stats(const ts_space *s, ts_space_stats *out)
{
    assert(assert_space_counts(s));
    *out = s->st;
}

size_t ts_space_count(ts_space *s, const tf_tuple *tmpl)
{
    if (tmpl->nfields < 0 || tmpl->nfields > TF_TUPLE_MAX_FIELDS)
        return 0;
    key k;
    int link = LINK_ARITY;
    const elist *l = &s->by_arity[tmpl->nfields];
    if (secondary_key(tmpl, &k) || primary_key(tmpl, &k)) {
        bucket *b = bucket_find(s, &k, key_hash(&k));
        if (!b)
            return 0;
        l = &b->tuples;
        link = b->link;
    }
    size_t n = 0;
    for (entry *e = l->head; e; e = e->next[link])
        n += (size_t)tf_tuple_match(tmpl, &e->t);
    return n;
}
