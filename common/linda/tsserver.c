/* tsserver.c: the tuple-space server event loop (see tsserver.h for the contract, proto.h for
 * the wire format).  One thread, epoll, non-blocking sockets, per-connection buffers.
 *
 * Life of a connection: accepted (HELLO queued; if a key is set, state NEED_AUTH until a valid
 * AUTH; a wrong AUTH from an address that failed before is HELD: its answer waits, see
 * note_auth_failure) or added by fd (trusted, READY at once) -> frames are parsed from its
 * input buffer in order -> replies are queued on its output buffer and written before the next poll, like
 * Redis's beforeSleep -> closed on EOF, error, protocol violation or timeout.
 *
 * Ordering invariant: a connection has at most one request in progress.  While its blocked
 * IN/RD waits (c->waiting), later frames stay in its input buffer unparsed -- except heartbeat
 * PINGs with request id 0, which need no reply and so cannot reorder anything -- and input
 * reading stops once TS_MAX_PIPELINE bytes are buffered.  So replies always leave in request
 * order.  When the blocked request is served, the frames behind it are served before the
 * next poll (conn_resume, from flush_dirty).
 *
 * Closing never frees a connection while the loop may still hold a pointer to it: it is marked
 * dead (fd closed, waiter cancelled, on_disconnect run) and freed by the sweep at the end of
 * ts_server_run_once, or at once when the close comes from outside the loop.
 *
 * The dirty list (see conn_touch).  INVARIANTS (checked clause by clause by
 * assert_dirty_list() before every flush, in debug builds, `make asan`):
 *   T1. A connection is on srv->dirty at most once, and exactly when c->dirty is set (a live
 *       connection with c->dirty set is on the list; every entry of the list has it set).
 *   T2. srv->nconns is the length of the live list srv->conns. */
#include "linda/tsserver.h"
#include "clock.h"

#include <assert.h>
#include <errno.h>
#include <fcntl.h>
#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sodium.h>
#include <sys/epoll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#include "le_bytes.h"
#include "log.h"
#include "linda/proto.h"
#include "linda/seal.h"
#include "linda/sock.h"

#define TS_READ_CHUNK 65536
/* The first read into an empty buffer: a request whole, or a result's length field, so that the
 * buffer can grow once to the result's size (tf_frame_rest) with little to copy. */
#define TS_FIRST_READ 4096
#define TS_MAX_PIPELINE 65536 /* input bytes buffered behind a blocked request */
/* An idle connection's input buffer keeps at most this much memory: results of up to this size
 * (most tasks' results) reuse it, larger ones (the default 128 K-pixel bands, ~1 MB) give it
 * back once read, or 1024 workers would hold 1 GB between their results. */
#define TS_BUF_KEEP (256 * 1024)
/* An OUT frame whose body is at least this large is not copied out of the buffer it was read
 * into: the buffer becomes the stored tuple's (detach_frame), for its blobs of at least
 * TS_SHARE_BLOB_MIN bytes (a result's chunks, and its preview share when that is 1 KB or more:
 * a 128x128 stamp's is 3 KB, whose copy was a malloc above glibc's small bins, which
 * consolidates its fast bins each time); smaller fields are copied as usual.  The buffer is
 * kept while the tuple is anyway: its chunks hold it. */
#define TS_SHARE_MIN (32 * 1024)
#define TS_SHARE_BLOB_MIN 1024
/* The most a frame's length field makes the server reserve before its bytes come (a longer
 * frame's buffer grows as they do): a peer's header alone never costs more than a connection
 * may keep anyway. */
#define TS_EXACT_MAX TS_BUF_KEEP
#define TS_POLL_CAP_MS 250    /* longest poll when timeouts must be enforced */
#define TS_STALL_MS 1000      /* a gap this long between iterations is a stall (see enforce_timeouts) */
#define TS_PENALTY_SLOTS 64   /* addresses remembered for failed handshakes */
#define TS_PENALTY_FREE_FAILS 3 /* failures from one address answered at once */
#define TS_PENALTY_BASE_MS 250
#define TS_PENALTY_MAX_MS 30000
#define TS_PENALTY_FORGET_MS 600000 /* an address quiet this long starts afresh */
#define TS_ACCEPT_PAUSE_MS 100 /* out of file descriptors: stop accepting this long */
#define TS_ACCEPT_BATCH 64     /* connections accepted a turn of the event loop */

/* HELD: a failed handshake whose answer waits out its address's penalty (note_auth_failure). */
enum conn_state { NEED_AUTH, HELD, READY };

typedef struct conn {
    uint64_t id;
    int fd;
    char peer[96];
    char addr[96];         /* peer without the port: the unit of per-address caps */
    ts_cap_usage usage;    /* what it has used of its role */
    tf_ratelimit refusals; /* its refused requests' log lines */
    int trusted;
    enum conn_state state;
    int dead;
    uint8_t ns[TF_NONCE_BYTES];
    tf_buf in, out;        /* plaintext frames in and out */
    int sealed;            /* after AUTH_OK with a key: records on the wire (seal.h) */
    tf_seal tx, rx;
    tf_buf raw, wire;      /* sealed: records read but not opened yet, records not yet sent */
    tf_outbox *outbox;     /* a forked worker's shared records for OUT_SHARED (outbox.h) */
    int64_t created_ms, last_rx_ms;
    int64_t verdict_ms;    /* HELD: when "authentication failed" is sent and c closed */
    int waiting;           /* a blocked IN/RD is queued in the space */
    int pending_take;      /* ... and whether it is an IN */
    uint32_t pending_req;  /* ... and its request id */
    uint64_t waiter_id;    /* ... and its waiter id (0 once served) */
    uint32_t ep_events;    /* events registered with the server's epoll set */
    int ep_added;          /* registered at all (EPOLL_CTL_ADD done) */
    int dirty;             /* on the server's dirty list (see conn_touch) */
    struct conn *dirty_next;
    struct ts_server *srv;
    struct conn *next, *prev;
} conn;

/* Failed handshakes from one address (see note_auth_failure). */
typedef struct auth_penalty {
    char addr[96];
    int failures;
    int64_t last_ms;
} auth_penalty;

struct ts_server {
    ts_space *space;
    ts_server_hooks hooks;
    const ts_role *role;
    size_t max_space_bytes;
    int max_unauth, max_unauth_per_addr, max_per_addr;
    auth_penalty penalties[TS_PENALTY_SLOTS];
    int64_t accept_paused_until;
    int has_key;
    uint8_t key[TF_KEY_BYTES];
    int silence_ms, handshake_ms, max_conns;
    size_t max_out;
    int listen_fd;
    int port;
    char unix_path[sizeof(((struct sockaddr_un *)0)->sun_path)];
    conn *conns; /* live connections, newest first */
    conn *dirty; /* connections whose output or epoll interest may have changed */
    int64_t last_timeout_check_ms;
    conn *graveyard;
    size_t nconns;
    uint64_t next_id;
    int in_loop;
    /* epoll, not poll: with a thousand connections poll() spent the coordinator's time
     * re-registering every socket on every iteration (bench/README.md); epoll costs O(ready).
     * A connection's interest set is kept in step lazily (sync_interest); a listener event
     * carries data.ptr == NULL. */
    int epfd;
    int listen_added;
    struct epoll_event *evs;
    size_t evcap;
};

ts_server *ts_server_new(ts_space *space, const ts_server_config *cfg,
                         const ts_server_hooks *hooks, char *err, size_t errlen)
{
    ts_server_config none = {0};
    if (!cfg)
        cfg = &none;
    if (tf_auth_init() != 0) {
        tf_seterr(err, errlen, "libsodium failed to initialise");
        return NULL;
    }
    ts_server *srv = calloc(1, sizeof *srv);
    if (!srv) {
        tf_seterr(err, errlen, "out of memory");
        return NULL;
    }
    srv->space = space;
    if (hooks)
        srv->hooks = *hooks;
    if (cfg->key) {
        srv->has_key = 1;
        memcpy(srv->key, cfg->key, TF_KEY_BYTES);
    }
    srv->silence_ms = cfg->silence_timeout_ms > 0 ? cfg->silence_timeout_ms : 0;
    srv->handshake_ms = cfg->handshake_timeout_ms > 0 ? cfg->handshake_timeout_ms : 5000;
    srv->max_out = cfg->max_output_bytes > 0 ? cfg->max_output_bytes
                                             : 2 * (size_t)TF_MAX_FRAME + (1u << 20);
    srv->max_conns = cfg->max_connections > 0 ? cfg->max_connections : 4096;
    srv->role = cfg->role;
    srv->max_space_bytes = cfg->max_space_bytes;
    srv->max_unauth = cfg->max_unauthenticated > 0 ? cfg->max_unauthenticated : 64;
    srv->max_unauth_per_addr =
        cfg->max_unauthenticated_per_address > 0 ? cfg->max_unauthenticated_per_address : 8;
    srv->max_per_addr = cfg->max_per_address > 0 ? cfg->max_per_address : 1024;
    srv->listen_fd = -1;
    srv->next_id = 1;
    srv->epfd = epoll_create1(EPOLL_CLOEXEC);
    if (srv->epfd < 0) {
        tf_seterr(err, errlen, "epoll_create1: %s", strerror(errno));
        free(srv);
        return NULL;
    }
    if (cfg->listen) {
        srv->listen_fd = tf_sock_listen(cfg->listen, &srv->port, err, errlen);
        if (srv->listen_fd < 0) {
            close(srv->epfd);
            free(srv);
            return NULL;
        }
        if (strncmp(cfg->listen, "unix:", 5) == 0)
            snprintf(srv->unix_path, sizeof srv->unix_path, "%s", cfg->listen + 5);
    }
    return srv;
}

int ts_server_port(const ts_server *srv) { return srv->port; }
/* ---- connections ---- */
static void conn_touch(conn *c);
static void addr_of(const char *peer, char *addr, size_t len);

static conn *find_conn(const ts_server *srv, uint64_t id);

static conn *conn_new(ts_server *srv, int fd, const char *peer, int trusted)
{
    conn *c = calloc(1, sizeof *c);
    if (!c)
        return NULL;
    c->id = srv->next_id++;
    c->fd = fd;
    snprintf(c->peer, sizeof c->peer, "%s", peer);
    addr_of(peer, c->addr, sizeof c->addr);
    c->trusted = trusted;
    c->refusals.burst = 40;
    c->state = trusted || !srv->has_key ? READY : NEED_AUTH;
    c->created_ms = c->last_rx_ms = tf_now_ms();
    c->srv = srv;
    tf_buf_init(&c->in);
    tf_buf_init(&c->out);
    tf_buf_init(&c->raw);
    tf_buf_init(&c->wire);
    c->next = srv->conns;
    if (srv->conns)
        srv->conns->prev = c;
    srv->conns = c;
    srv->nconns++;
    conn_touch(c); /* to be registered with epoll */
    return c;
}

/* Put c on the dirty list: its queued output or its epoll interest may have changed.  Only
 * dirty connections are visited by flush_dirty, so an event-loop iteration costs time in
 * proportion to the connections that did something, not to all of them (1024 workers). */
static void conn_touch(conn *c)
{
    if (c->dirty || c->dead)
        return;
    c->dirty = 1;
    c->dirty_next = c->srv->dirty;
    c->srv->dirty = c;
}

#ifndef NDEBUG
/* 1 if the dirty list ends: a connection on it twice would close it into a cycle (Floyd). */
static int dirty_list_ends(const ts_server *srv)
{
    const conn *slow = srv->dirty, *fast = srv->dirty;
    while (fast && fast->dirty_next) {
        slow = slow->dirty_next;
        fast = fast->dirty_next->dirty_next;
        if (slow == fast)
            return 0;
    }
    return 1;
}

/* T1 and T2, one assert a clause (as SQLite's assert_pager_state).  Returns 1, so that a call
 * sits inside assert() and vanishes with NDEBUG. */
static int assert_dirty_list(const ts_server *srv)
{
    size_t live_listed = 0, live_dirty = 0, live = 0;
    assert(dirty_list_ends(srv) && "T1: no connection is on the dirty list twice");
    for (const conn *c = srv->dirty; c; c = c->dirty_next) {
        assert(c->dirty && "T1: every connection on the dirty list has its dirty flag set");
        live_listed += !c->dead;
    }
    for (const conn *c = srv->conns; c; c = c->next) {
        live++;
        live_dirty += c->dirty && !c->dead;
    }
    assert(live_listed == live_dirty &&
           "T1: every live connection with its dirty flag set is on the dirty list");
    assert(live == srv->nconns && "T2: srv->nconns is the length of the live list");
    return 1;
}
#endif

static void conn_destroy(conn *c)
{
    if (c->dirty) { /* unlink: a dead connection may still sit on the list */
        conn **pp = &c->srv->dirty;
        while (*pp && *pp != c)
            pp = &(*pp)->dirty_next;
        if (*pp)
            *pp = c->dirty_next;
    }
    tf_buf_free(&c->in);
    tf_buf_free(&c->out);
    tf_buf_free(&c->raw);
    tf_buf_free(&c->wire);
    tf_outbox_unref(c->outbox);
    sodium_memzero(&c->tx, sizeof c->tx);
    sodium_memzero(&c->rx, sizeof c->rx);
    free(c);
}

/* Close c now: fd, blocked request, hook.  Freed later by the sweep (or now, outside the loop). */
static void conn_close(conn *c)
{
    if (c->dead)
        return;
    ts_server *srv = c->srv;
    c->dead = 1;
    /* Deregister explicitly: a forked child may briefly hold a copy of this fd, and epoll
     * only forgets a file when every copy is closed. */
    if (c->ep_added)
        epoll_ctl(srv->epfd, EPOLL_CTL_DEL, c->fd, NULL);
    close(c->fd);
    c->fd = -1;
    if (c->waiting && c->waiter_id)
        ts_cancel(srv->space, c->waiter_id);
    c->waiting = 0;
    if (c->prev)
        c->prev->next = c->next;
    else
        srv->conns = c->next;
    if (c->next)
        c->next->prev = c->prev;
    srv->nconns--;
    c->next = srv->graveyard;
    srv->graveyard = c;
    if (srv->hooks.on_disconnect)
        srv->hooks.on_disconnect(srv->hooks.ctx, c->id, c->peer);
    if (!srv->in_loop) {
        while (srv->graveyard) {
            conn *g = srv->graveyard;
            srv->graveyard = g->next;
            conn_destroy(g);
        }
    }
}

/* Log why and close: the one line naming the peer. */
static void conn_drop(conn *c, const char *why)
{
    static tf_ratelimit rl;
    tf_warn_limited(&rl, "dropping tuple-space connection from %s: %s", c->peer, why);
    conn_close(c);
}

/* Write as much queued output as the socket takes.  -1 if the connection broke.  A sealed
 * connection's plaintext is sealed into records first. */
static int conn_flush(conn *c)
{
    tf_buf *q = &c->out;
    if (c->sealed) {
        if (c->out.len > 0) {
            if (tf_seal_append(&c->tx, &c->wire, tf_buf_head(&c->out), c->out.len) != 0) {
                errno = ENOMEM;
                return -1;
            }
            tf_buf_consume(&c->out, c->out.len);
        }
        q = &c->wire;
    }
    while (q->len > 0) {
        ssize_t n = send(c->fd, tf_buf_head(q), q->len, MSG_NOSIGNAL);
        if (n > 0) {
            tf_buf_consume(q, (size_t)n);
            continue;
        }
        if (n < 0 && errno == EINTR)
            continue;
        if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK))
            return 0;
        return -1;
    }
    return 0;
}

/* Check the output bound after queuing; drop a client that does not read its replies. */
static int conn_check_out(conn *c, int append_rc)
{
    if (append_rc != 0) {
        conn_drop(c, "out of memory queuing a reply");
        return -1;
    }
    if (c->out.len + c->wire.len > c->srv->max_out) {
        conn_drop(c, "too many unread replies (client not reading)");
        return -1;
    }
    conn_touch(c);
    return 0;
}

static int reply_tuple(conn *c, uint8_t op, uint32_t req, const tf_tuple *t)
{
    return conn_check_out(c, tf_frame_append_tuple(&c->out, op, req, t));
}

/* Best effort: send ERROR with msg, then close. */
static void conn_refuse(conn *c, const char *msg)
{
    tf_frame_append_raw(&c->out, TF_OP_ERROR, 0, msg, strlen(msg));
    conn_flush(c);
    conn_close(c);
}

static void send_hello(conn *c)
{
    uint8_t body[1 + TF_NONCE_BYTES];
    tf_auth_nonce(c->ns);
    body[0] = c->srv->has_key ? TF_HELLO_AUTH_REQUIRED | TF_HELLO_SEALED : 0;
    memcpy(body + 1, c->ns, TF_NONCE_BYTES);
    conn_check_out(c, tf_frame_append_raw(&c->out, TF_OP_HELLO, 0, body, sizeof body));
}

uint64_t ts_server_add_fd(ts_server *srv, int fd, const char *peer)
{
    char label[32];
    if (!peer) {
        snprintf(label, sizeof label, "fd %d", fd);
        peer = label;
    }
    conn *c = NULL;
    if (tf_sock_set_nonblocking(fd) != 0 || !(c = conn_new(srv, fd, peer, 1))) {
        close(fd);
        return 0;
    }
    return c->id;
}

int ts_server_adopt_outbox(ts_server *srv, uint64_t conn_id, tf_outbox *ob)
{
    conn *c = find_conn(srv, conn_id);
    if (!c)
        return -1;
    tf_outbox_unref(c->outbox);
    c->outbox = ob;
    return 0;
}

/* ---- admission: caps per address and for strangers, failed-handshake penalties ---- */

/* "1.2.3.4:5678" -> "1.2.3.4", "[::1]:5" -> "[::1]"; labels without a port stay whole. */
static void addr_of(const char *peer, char *addr, size_t len)
{
    snprintf(addr, len, "%s", peer);
    char *colon = strrchr(addr, ':');
    if (colon && (addr[0] != '[' || colon[-1] == ']'))
        *colon = '\0';
}

static auth_penalty *penalty_for(ts_server *srv, const char *addr, int create)
{
    auth_penalty *oldest = &srv->penalties[0];
    for (int i = 0; i < TS_PENALTY_SLOTS; i++) {
        auth_penalty *p = &srv->penalties[i];
        if (p->addr[0] && !strcmp(p->addr, addr))
            return p;
        if (p->last_ms < oldest->last_ms)
            oldest = p;
    }
    if (!create)
        return NULL;
    memset(oldest, 0, sizeof *oldest);
    snprintf(oldest->addr, sizeof oldest->addr, "%s", addr);
    return oldest;
}

/* Count a failed handshake from addr; returns how long its answer must wait.  The first
 * TS_PENALTY_FREE_FAILS failures are answered at once, then 250 ms, 500 ms, 1 s ... up to 30 s:
 * guessing a secret online becomes hopeless.  Only wrong guesses wait: a right one from the same
 * address is admitted at once, so a guesser cannot lock out the workers sharing its address. */
static int64_t note_auth_failure(ts_server *srv, const char *addr)
{
    auth_penalty *p = penalty_for(srv, addr, 1);
    int64_t now = tf_now_ms();
    if (p->failures > 0 && now - p->last_ms > TS_PENALTY_FORGET_MS)
        p->failures = 0;
    p->failures++;
    p->last_ms = now;
    if (p->failures <= TS_PENALTY_FREE_FAILS)
        return 0;
    int shift = p->failures - TS_PENALTY_FREE_FAILS - 1;
    int64_t wait = shift > 16 ? TS_PENALTY_MAX_MS : (int64_t)TS_PENALTY_BASE_MS << shift;
    return wait > TS_PENALTY_MAX_MS ? TS_PENALTY_MAX_MS : wait;
}

/* The oldest connection still in the handshake (from addr, or from anywhere if NULL), among
 * those waiting for their AUTH (held = 0) or those holding a failed one's answer (held = 1);
 * *count (if given): how many of that kind there are. */
static conn *oldest_unauthenticated(ts_server *srv, const char *addr, int held, size_t *count)
{
    conn *oldest = NULL;
    size_t n = 0;
    enum conn_state want = held ? HELD : NEED_AUTH;
    for (conn *c = srv->conns; c; c = c->next) {
        if (c->state != want || (addr && strcmp(c->addr, addr)))
            continue;
        n++;
        if (!oldest || c->created_ms <= oldest->created_ms)
            oldest = c;
    }
    if (count)
        *count = n;
    return oldest;
}

static void evict(conn *c, const char *why)
{
    static tf_ratelimit rl;
    tf_warn_limited(&rl, "closing unauthenticated tuple-space connection from %s: %s", c->peer,
                    why);
    conn_close(c);
}

static void pause_accepting(ts_server *srv)
{
    srv->accept_paused_until = tf_now_ms() + TS_ACCEPT_PAUSE_MS;
    if (srv->listen_added && epoll_ctl(srv->epfd, EPOLL_CTL_DEL, srv->listen_fd, NULL) == 0)
        srv->listen_added = 0;
}

/* Make room for one more unfinished handshake from addr: at a cap, close the oldest one still
 * waiting for its AUTH (it learns nothing).  Failed handshakes whose answer is held count too,
 * but are not closed early for a newcomer from their own address (that would answer a guess
 * sooner): then the newcomer is refused, -1 (logged).  So one address has at most
 * max_unauth_per_addr guesses in flight. */
static int room_for_handshake(ts_server *srv, const char *peer, const char *addr)
{
    static tf_ratelimit rl;
    size_t waiting, held, all_waiting, all_held;
    conn *old_here = oldest_unauthenticated(srv, addr, 0, &waiting);
    oldest_unauthenticated(srv, addr, 1, &held);
    conn *old_all = oldest_unauthenticated(srv, NULL, 0, &all_waiting);
    conn *old_held = oldest_unauthenticated(srv, NULL, 1, &all_held);
    if (waiting + held >= (size_t)srv->max_unauth_per_addr) {
        if (!old_here) {
            tf_warn_limited(&rl, "refusing tuple-space connection from %s: %zu failed "
                            "handshakes from %s await their answer", peer, held, addr);
            return -1;
        }
        evict(old_here, "too many unfinished handshakes from this address");
    } else if (all_waiting + all_held >= (size_t)srv->max_unauth) {
        evict(old_all ? old_all : old_held, "too many unfinished handshakes");
    }
    return 0;
}

/* Decide whether a new connection from peer may stay; may close older strangers to make room.
 * 0: keep it; -1: refuse it (logged).  Failed handshakes do not bar an address: they only slow
 * its wrong guesses (note_auth_failure). */
static int admit(ts_server *srv, const char *peer)
{
    static tf_ratelimit rl_cap;
    char addr[96];
    addr_of(peer, addr, sizeof addr);
    if (srv->has_key && room_for_handshake(srv, peer, addr) != 0)
        return -1;
    size_t same = 0;
    for (conn *c = srv->conns; c; c = c->next)
        same += c->state == READY && !strcmp(c->addr, addr);
    if (same >= (size_t)srv->max_per_addr) {
        tf_warn_limited(&rl_cap, "refusing tuple-space connection from %s: %zu connections "
                        "from %s already", peer, same, addr);
        return -1;
    }
    if (srv->nconns >= (size_t)srv->max_conns) {
        conn *old = oldest_unauthenticated(srv, NULL, 0, NULL);
        if (!old) {
            tf_warn_limited(&rl_cap, "refusing tuple-space connection from %s: %d connections "
                            "open", peer, srv->max_conns);
            return -1;
        }
        evict(old, "connection limit reached");
    }
    return 0;
}

/* At most TS_ACCEPT_BATCH connections a turn of the loop: a connection evicted to make room
 * is freed by the sweep at the end of the turn, so an accept loop that ran as long as a flood
 * kept the backlog full held every evicted stranger until it stopped (300 MB, seen in
 * farm_flood); the listener stays readable and is served again next turn. */
static void accept_all(ts_server *srv)
{
    static tf_ratelimit rl;
    for (int accepted = 0; accepted < TS_ACCEPT_BATCH; accepted++) {
        char peer[96];
        int fd = tf_sock_accept(srv->listen_fd, peer, sizeof peer);
        if (fd < 0) {
            if (errno == EMFILE || errno == ENFILE || errno == ENOBUFS || errno == ENOMEM) {
                /* Out of descriptors: free one held by a stranger, else stop accepting for a
                 * moment (the listener would otherwise stay readable and spin the loop). */
                conn *old = oldest_unauthenticated(srv, NULL, 0, NULL);
                if (old) {
                    evict(old, "out of file descriptors");
                    continue;
                }
                tf_warn_limited(&rl, "tuple-space accept failed: %s; pausing new connections",
                                strerror(errno));
                pause_accepting(srv);
            } else if (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR &&
                       errno != ECONNABORTED) {
                tf_warn_limited(&rl, "tuple-space accept failed: %s", strerror(errno));
            }
            return;
        }
        if (admit(srv, peer) != 0) {
            close(fd);
            continue;
        }
        conn *c = conn_new(srv, fd, peer, 0);
        if (!c) {
            close(fd);
            continue;
        }
        send_hello(c);
    }
}

/* ---- serving requests ---- */

/* The space delivers a blocked IN/RD's tuple (or an immediate one). */
static void on_waiter_served(void *ctx, uint64_t waiter_id, tf_tuple *t)
{
    (void)waiter_id;
    conn *c = ctx;
    c->waiting = 0;
    c->waiter_id = 0;
    if (c->dead)
        return;
    conn_touch(c); /* readable again, and a reply is coming */
    ts_server *srv = c->srv;
    if (c->pending_take && srv->hooks.on_take)
        srv->hooks.on_take(srv->hooks.ctx, c->id, t);
    if (!c->dead)
        reply_tuple(c, TF_OP_TUPLE, c->pending_req, t);
}

/* A request its role does not allow: an ERROR reply for that request (the connection stays),
 * and one rate-limited line naming the peer. */
static void refuse_request(conn *c, const tf_frame *f, const tf_tuple *t, const char *why)
{
    /* Per connection (a peer's first refusals are all named), and in all (many peers). */
    static tf_ratelimit all = {.burst = 200};
    if (tf_ratelimit_take(&all, (long long)tf_now_ms(), NULL)) {
        char shown[160];
        tf_tuple_format(t, shown, sizeof shown);
        tf_warn_limited(&c->refusals, "%s %s from %s (%s) refused: %s", tf_op_name(f->op), shown,
                        c->peer, c->srv->role ? c->srv->role->name : "?", why);
    }
    char msg[TF_PROTO_ERROR_MAX];
    snprintf(msg, sizeof msg, "refused: %s", why);
    conn_check_out(c, tf_frame_append_raw(&c->out, TF_OP_ERROR, f->request_id, msg, strlen(msg)));
}

/* OUT: decode (blobs left in `shared` when the frame was detached), check against the role and
 * the space's cap, store, and show the hook. */
static int handle_out(conn *c, const tf_frame *f, tf_shared_bytes *shared, char *err,
                      size_t errlen)
{
    tf_tuple t, seen;
    int bad = shared ? tf_tuple_decode_shared(f->body, f->body_len, shared, TS_SHARE_BLOB_MIN, &t,
                                              err, errlen)
                     : tf_tuple_decode(f->body, f->body_len, &t, 0, err, errlen);
    if (bad)
        return -1;
    ts_server *srv = c->srv;
    if (srv->role) {
        char why[TF_PROTO_ERROR_MAX - 16];
        ts_cap_verdict v = ts_cap_check(srv->role, &c->usage, c->id, TS_CAP_OUT, 0, &t, why,
                                        sizeof why);
        if (v == TS_CAP_ALLOW && srv->max_space_bytes) {
            ts_space_stats st;
            ts_space_get_stats(srv->space, &st);
            if (st.bytes + tf_tuple_bytes(&t) > srv->max_space_bytes) {
                snprintf(why, sizeof why, "the tuple space is full (%zu of %zu bytes)", st.bytes,
                         srv->max_space_bytes);
                v = TS_CAP_REFUSE;
            }
        }
        if (v != TS_CAP_ALLOW) {
            if (v == TS_CAP_REFUSE && !c->dead)
                refuse_request(c, f, &t, why);
            else if (!c->dead)
                reply_tuple(c, TF_OP_OK, f->request_id, NULL); /* discarded: not stored */
            tf_tuple_clear(&t);
            return 0;
        }
    }
    /* The hook sees the tuple's value, not the stored tuple, which it (or a waiter) may take
     * meanwhile: a view of the frame, which stays in c->in until this request is served (a
     * closed connection's buffers outlive the loop's turn), or in `shared`, of which the
     * caller holds a reference until then; so a result's blobs are not copied once more. */
    int want_view = srv->hooks.on_out != NULL;
    if (want_view && tf_tuple_view(f->body, f->body_len, &seen, err, errlen) != 0) {
        tf_tuple_clear(&t);
        return -1;
    }
    uint64_t id = c->id;
    if (ts_space_out(srv->space, &t) != 0) {
        if (want_view)
            tf_tuple_view_clear(&seen);
        tf_seterr(err, errlen, "out of memory storing a tuple");
        return -1;
    }
    if (want_view) {
        srv->hooks.on_out(srv->hooks.ctx, id, &seen);
        tf_tuple_view_clear(&seen);
    }
    if (!c->dead)
        reply_tuple(c, TF_OP_OK, f->request_id, NULL);
    return 0;
}

static int handle_take_or_read(conn *c, const tf_frame *f, char *err, size_t errlen)
{
    tf_tuple tmpl;
    if (tf_tuple_decode(f->body, f->body_len, &tmpl, 1, err, errlen) != 0)
        return -1;
    ts_server *srv = c->srv;
    int take = f->op == TF_OP_IN || f->op == TF_OP_INP;
    int rc = 0;
    if (srv->role) {
        char why[TF_PROTO_ERROR_MAX - 16];
        int blocking = f->op == TF_OP_IN || f->op == TF_OP_RD;
        ts_cap_verdict v = ts_cap_check(srv->role, &c->usage, c->id, take ? TS_CAP_IN : TS_CAP_RD,
                                        blocking, &tmpl, why, sizeof why);
        if (v != TS_CAP_ALLOW) {
            if (!c->dead)
                refuse_request(c, f, &tmpl, v == TS_CAP_REFUSE ? why : "not served");
            tf_tuple_clear(&tmpl);
            return 0;
        }
    }
    if (f->op == TF_OP_IN || f->op == TF_OP_RD) {
        c->waiting = 1;
        c->pending_take = take;
        c->pending_req = f->request_id;
        if (ts_wait_as(srv->space, &tmpl, take, c->id, on_waiter_served, c, &c->waiter_id) <
            0) {
            c->waiting = 0;
            tf_seterr(err, errlen, "out of memory queuing a request");
            rc = -1;
        }
    } else {
        tf_tuple got;
        int found = take ? ts_space_inp_as(srv->space, &tmpl, c->id, &got)
                         : ts_space_rdp(srv->space, &tmpl, &got);
        if (found > 0) {
            if (take && srv->hooks.on_take)
                srv->hooks.on_take(srv->hooks.ctx, c->id, &got);
            if (!c->dead)
                reply_tuple(c, TF_OP_TUPLE, f->request_id, &got);
            tf_tuple_clear(&got);
        } else if (found == 0) {
            reply_tuple(c, TF_OP_NONE, f->request_id, NULL);
        } else {
            tf_seterr(err, errlen, "out of memory copying a tuple");
            rc = -1;
        }
    }
    tf_tuple_clear(&tmpl);
    return rc;
}

/* A wrong MAC: answered at once, or held (state HELD, input ignored) until the address's
 * penalty is served, then answered and closed by enforce_timeouts. */
static void auth_failed(conn *c)
{
    static tf_ratelimit rl;
    int64_t wait = note_auth_failure(c->srv, c->addr);
    auth_penalty *p = penalty_for(c->srv, c->addr, 0);
    tf_warn_limited(&rl, "authentication failed from %s (%d failed handshakes from %s; "
                    "answered in %lld ms)", c->peer, p ? p->failures : 0, c->addr,
                    (long long)wait);
    if (wait == 0) {
        conn_refuse(c, "authentication failed");
        return;
    }
    c->state = HELD;
    c->verdict_ms = tf_now_ms() + wait;
}

static int handle_auth(conn *c, const tf_frame *f, char *err, size_t errlen)
{
    if (c->state != NEED_AUTH) {
        tf_seterr(err, errlen, "unexpected AUTH");
        return -1;
    }
    if (f->body_len != TF_NONCE_BYTES + TF_MAC_BYTES) {
        tf_seterr(err, errlen, "AUTH body of %u bytes", f->body_len);
        return -1;
    }
    const uint8_t *nc = f->body, *mac = f->body + TF_NONCE_BYTES;
    if (!tf_auth_client_mac_ok(c->srv->key, c->ns, nc, mac)) {
        auth_failed(c);
        return 0;
    }
    uint8_t proof[TF_MAC_BYTES];
    tf_auth_server_mac(c->srv->key, c->ns, nc, proof);
    c->state = READY;
    if (conn_check_out(c, tf_frame_append_raw(&c->out, TF_OP_AUTH_OK, f->request_id, proof,
                                              sizeof proof)) != 0)
        return 0;
    /* AUTH_OK goes out in clear; every byte after it, both ways, is sealed (seal.h). */
    if (tf_buf_append(&c->wire, tf_buf_head(&c->out), c->out.len) != 0) {
        tf_seterr(err, errlen, "out of memory");
        return -1;
    }
    tf_buf_consume(&c->out, c->out.len);
    tf_seal_init(c->srv->key, c->ns, nc, 0, &c->tx, &c->rx);
    c->sealed = 1;
    if (c->in.len > (size_t)f->body_len + TF_FRAME_HEADER) {
        /* Bytes after AUTH in the same read are already sealed records: back to raw. */
        size_t extra = c->in.len - ((size_t)f->body_len + TF_FRAME_HEADER);
        if (tf_buf_append(&c->raw, tf_buf_head(&c->in) + f->body_len + TF_FRAME_HEADER,
                          extra) != 0) {
            tf_seterr(err, errlen, "out of memory");
            return -1;
        }
        c->in.len -= extra;
    }
    return 0;
}

static uint32_t conn_max_frame(const conn *c);

/* OUT_SHARED: the tuple's encoding is the payload of a record of c's outbox, decoded where it
 * lies; the stored tuple's large blobs keep the record (tf_outbox_lend) until they are freed. */
static int handle_out_shared(conn *c, const tf_frame *f, char *err, size_t errlen)
{
    if (!c->outbox)
        return tf_seterr(err, errlen, "OUT_SHARED on a connection without an outbox");
    if (f->body_len != 8)
        return tf_seterr(err, errlen, "OUT_SHARED body of %u bytes", f->body_len);
    uint64_t off = tf_le_get32(f->body), len = tf_le_get32(f->body + 4);
    if (tf_outbox_payload_ok(c->outbox, off, len, err, errlen) != 0)
        return -1;
    if (len > conn_max_frame(c) - TF_FRAME_MIN_LENGTH)
        return tf_seterr(err, errlen, "OUT_SHARED of %llu bytes, more than a frame holds",
                         (unsigned long long)len);
    tf_shared_bytes *shared = tf_outbox_lend(c->outbox, off);
    if (!shared)
        return tf_seterr(err, errlen, "out of memory");
    tf_frame out = {f->version, TF_OP_OUT, f->request_id, tf_outbox_base(c->outbox) + off,
                    (uint32_t)len};
    int rc = handle_out(c, &out, shared, err, errlen);
    tf_shared_bytes_release(shared); /* the stored tuple's blobs keep theirs */
    return rc;
}

/* Serve one frame.  0 ok (c may have been closed), -1 protocol violation (err set). */
static int handle_frame(conn *c, const tf_frame *f, tf_shared_bytes *shared, char *err,
                        size_t errlen)
{
    if (c->state == NEED_AUTH && f->op != TF_OP_AUTH) {
        static tf_ratelimit rl;
        tf_warn_limited(&rl, "unauthenticated %s from %s refused", tf_op_name(f->op), c->peer);
        conn_refuse(c, "authentication required");
        return 0;
    }
    switch (f->op) {
    case TF_OP_OUT: return handle_out(c, f, shared, err, errlen);
    case TF_OP_OUT_SHARED: return handle_out_shared(c, f, err, errlen);
    case TF_OP_IN:
    case TF_OP_RD:
    case TF_OP_INP:
    case TF_OP_RDP: return handle_take_or_read(c, f, err, errlen);
    case TF_OP_PING:
        if (f->body_len != 0) {
            tf_seterr(err, errlen, "PING with a body");
            return -1;
        }
        if (f->request_id != 0)
            reply_tuple(c, TF_OP_PONG, f->request_id, NULL);
        return 0;
    case TF_OP_AUTH: return handle_auth(c, f, err, errlen);
    default:
        tf_seterr(err, errlen, "client sent server-only op %s", tf_op_name(f->op));
        return -1;
    }
}

/* The largest length field c may send now: a handshake before authentication, then the
 * largest tuple its role allows (plus the frame header), then TF_MAX_FRAME. */
static uint32_t conn_max_frame(const conn *c)
{
    if (c->state != READY)
        return TF_HANDSHAKE_FRAME_MAX;
    const ts_role *role = c->srv->role;
    if (role && role->max_tuple_bytes && role->max_tuple_bytes < TF_MAX_FRAME - 64)
        return (uint32_t)role->max_tuple_bytes + 64;
    return TF_MAX_FRAME;
}

/* The frame f (n bytes at the head of c->in) leaves c->in without a copy: c->in's memory becomes
 * shared bytes (one reference, the caller's) for the tuple's blobs, and c->in starts afresh
 * with the bytes that followed the frame.  NULL, with nothing changed, without memory. */
static tf_shared_bytes *detach_frame(conn *c, size_t n)
{
    tf_buf fresh;
    tf_buf_init(&fresh);
    size_t after = c->in.len - n;
    if (after > 0 && tf_buf_append(&fresh, tf_buf_head(&c->in) + n, after) != 0)
        return NULL;
    tf_shared_bytes *shared = tf_shared_bytes_adopt(c->in.data);
    if (!shared) {
        tf_buf_free(&fresh);
        return NULL;
    }
    c->in = fresh;
    return shared;
}

/* Parse and serve the complete frames in c's input buffer (see the ordering invariant). */
static void conn_process_input(conn *c)
{
    char err[160];
    if (c->state == HELD) { /* nothing it says counts until its answer is sent */
        tf_buf_consume(&c->in, c->in.len);
        return;
    }
    while (!c->dead && c->in.len > 0) {
        tf_frame f;
        long n = tf_frame_parse_max(tf_buf_head(&c->in), c->in.len, conn_max_frame(c), &f, err,
                                    sizeof err);
        if (n < 0) {
            conn_drop(c, err);
            return;
        }
        if (n == 0)
            return;
        if (c->waiting) {
            if (f.op != TF_OP_PING || f.request_id != 0 || f.body_len != 0)
                return; /* wait until the blocked request is served */
            tf_buf_consume(&c->in, (size_t)n);
            continue;
        }
        tf_shared_bytes *shared = NULL;
        if (f.op == TF_OP_OUT && f.body_len >= TS_SHARE_MIN && c->state == READY)
            shared = detach_frame(c, (size_t)n);
        int rc = handle_frame(c, &f, shared, err, sizeof err);
        tf_shared_bytes_release(shared); /* the stored tuple's blobs keep theirs */
        if (c->dead)
            return;
        if (!shared)
            tf_buf_consume(&c->in, (size_t)n);
        if (rc != 0) {
            conn_drop(c, err);
            return;
        }
    }
}

/* A sealed connection: open the complete records read so far into c->in, serving frames as
 * they become whole, while c->in has room (at most one maximal frame plus one record: a
 * partial frame can always take one more record, and a buffer that full holds a whole frame).
 * -1 once the connection was dropped. */
static int unseal_and_serve(conn *c)
{
    size_t limit = (size_t)conn_max_frame(c) + 4;
    for (;;) {
        if (c->waiting && c->in.len >= TS_MAX_PIPELINE)
            return 0;
        if (c->in.len >= limit || c->raw.len == 0)
            return 0;
        char err[160];
        /* a frame whose length is in: its buffer grown once to its size (detach_frame) */
        size_t rest = tf_frame_rest(tf_buf_head(&c->in), c->in.len);
        if (rest > 0 && rest <= TS_EXACT_MAX && rest <= limit - c->in.len &&
            tf_buf_reserve_exact(&c->in, rest) != 0) {
            conn_drop(c, "out of memory buffering input");
            return -1;
        }
        long n = tf_seal_open(&c->rx, tf_buf_head(&c->raw), c->raw.len, &c->in, err, sizeof err);
        if (n < 0) {
            conn_drop(c, err);
            return -1;
        }
        if (n == 0)
            return 0;
        tf_buf_consume(&c->raw, (size_t)n);
        conn_process_input(c);
        if (c->dead)
            return -1;
    }
}

/* Drained: an idle connection keeps no large-result-sized buffer. */
static void trim_idle(conn *c)
{
    tf_buf_trim(&c->in, TS_BUF_KEEP);
    tf_buf_trim(&c->raw, TS_BUF_KEEP);
}

/* How much to read next into *dst, never more than one maximal frame buffered: the parser
 * refuses longer lengths, so a buffer this full always holds a complete frame to consume first
 * (sealed: one record at a time, opened as room allows).  The rest of a frame whose length is in
 * (and passed the parser) is read to its end into a buffer grown once to its size (*exact),
 * which detach_frame can then hand over as it is.  0: nothing may be read now. */
static size_t next_read(conn *c, tf_buf **dst, int *exact)
{
    if (c->waiting && c->in.len >= TS_MAX_PIPELINE)
        return 0;
    *dst = c->sealed ? &c->raw : &c->in;
    size_t len = (*dst)->len;
    size_t limit = c->sealed ? (size_t)TF_SEAL_RECORD_MAX + TF_SEAL_ABYTES + 4
                             : (size_t)conn_max_frame(c) + 4;
    size_t room = len < limit ? limit - len : 0;
    size_t chunk = len == 0 && !c->sealed ? TS_FIRST_READ : TS_READ_CHUNK;
    size_t rest = c->sealed || c->waiting ? 0 : tf_frame_rest(tf_buf_head(*dst), len);
    *exact = rest > 0 && rest <= TS_EXACT_MAX && rest <= room;
    return *exact ? rest : room < chunk ? room : chunk;
}

/* n bytes just received: served.  1 to read on, 0 to stop (the connection died, or a short
 * read took all the socket had: stop rather than pay a recv that says EAGAIN -- epoll is
 * level-triggered and reports anything that comes next). */
static int serve_received(conn *c, size_t n, size_t want)
{
    c->last_rx_ms = tf_now_ms();
    if (c->sealed) {
        if (unseal_and_serve(c) != 0)
            return 0;
    } else {
        int was_sealed = c->sealed;
        conn_process_input(c);
        if (c->dead)
            return 0;
        if (!was_sealed && c->sealed && unseal_and_serve(c) != 0)
            return 0; /* records that came with the AUTH */
    }
    if (c->dead)
        return 0;
    if (n < want) {
        trim_idle(c);
        return 0;
    }
    return 1;
}

/* recv gave n <= 0: 1 to try again (EINTR), 0 when the socket is drained, -1 when the
 * connection is over (closed by the peer, or an error). */
static int receive_failed(conn *c, ssize_t n)
{
    if (n < 0 && errno == EINTR)
        return 1;
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) {
        trim_idle(c);
        return 0;
    }
    if (n == 0 && (c->in.len > 0 || c->raw.len > 0))
        conn_drop(c, "closed in the middle of a frame");
    else if (n == 0)
        conn_close(c);
    else
        conn_drop(c, strerror(errno));
    return -1;
}

/* Read what is available (bounded), then serve it. */
static void conn_readable(conn *c)
{
    conn_touch(c); /* input, replies and interest may all change */
    if (c->sealed && unseal_and_serve(c) != 0)
        return;
    for (;;) {
        tf_buf *dst = NULL;
        int exact = 0;
        size_t want = next_read(c, &dst, &exact);
        if (want == 0)
            return;
        if ((exact ? tf_buf_reserve_exact(dst, want) : tf_buf_reserve(dst, want)) != 0) {
            conn_drop(c, "out of memory buffering input");
            return;
        }
        ssize_t n = recv(c->fd, dst->data + dst->off + dst->len, want, 0);
        if (n > 0) {
            dst->len += (size_t)n;
            if (!serve_received(c, (size_t)n, want))
                return;
        } else if (receive_failed(c, n) != 1) {
            return;
        }
    }
}

/* Keep c's epoll interest in line with what it wants now: readable unless its pipeline is full
 * behind a blocked request, writable while replies are queued.  A syscall only on a change. */
static void sync_conn_interest(conn *c)
{
    uint32_t want = 0;
    if (!(c->waiting && c->in.len >= TS_MAX_PIPELINE))
        want |= EPOLLIN;
    if (c->out.len > 0 || c->wire.len > 0)
        want |= EPOLLOUT;
    if (c->ep_added && want == c->ep_events)
        return;
    struct epoll_event ev = {.events = want, .data.ptr = c};
    if (epoll_ctl(c->srv->epfd, c->ep_added ? EPOLL_CTL_MOD : EPOLL_CTL_ADD, c->fd, &ev) == 0) {
        c->ep_added = 1;
        c->ep_events = want;
    } else {
        conn_drop(c, strerror(errno));
    }
}

/* Serve the frames that waited behind c's blocked request, once it is served (on_waiter_served
 * touched c): they are in its buffers already, and nothing need come on the socket to wake it
 * (a client may write a blocking take and more requests behind it in one go). */
static void conn_resume(conn *c)
{
    if (c->waiting || c->state == HELD || (c->in.len == 0 && c->raw.len == 0))
        return;
    conn_process_input(c);
    if (!c->dead && c->sealed)
        unseal_and_serve(c);
}

/* Serve what waited behind a served request, send what the dirty connections have queued and
 * bring their interest up to date.  Serving or dropping a connection may run hooks that touch
 * others: they join the list and are served here too. */
static void flush_dirty(ts_server *srv)
{
    assert(assert_dirty_list(srv));
    while (srv->dirty) {
        conn *c = srv->dirty;
        srv->dirty = c->dirty_next;
        c->dirty = 0;
        if (!c->dead)
            conn_resume(c);
        if (c->dead)
            continue;
        if ((c->out.len > 0 || c->wire.len > 0) && conn_flush(c) != 0) {
            conn_drop(c, strerror(errno));
            continue;
        }
        sync_conn_interest(c);
    }
}

static void enforce_timeouts(ts_server *srv)
{
    int64_t now = tf_now_ms();
    int64_t gap = now - srv->last_timeout_check_ms;
    if (gap < 100) /* timeouts are seconds: check 10 times a second */
        return;
    if (srv->last_timeout_check_ms > 0 && gap > TS_STALL_MS) {
        /* The server itself did not run for a while (SIGSTOP, a paused VM, a long step): what
         * peers sent meanwhile has just been read, and silence during the stall is ours, not
         * theirs.  Every silence timer starts again. */
        static tf_ratelimit rl;
        if (srv->silence_ms > 0 && gap > srv->silence_ms / 2)
            tf_warn_limited(&rl, "the tuple-space server did not run for %.1f s (paused?); "
                            "restarting every connection's silence timer", (double)gap / 1000);
        for (conn *c = srv->conns; c; c = c->next)
            c->last_rx_ms = now;
    }
    srv->last_timeout_check_ms = now;
    for (conn *c = srv->conns, *next; c; c = next) {
        next = c->next;
        if (c->state == HELD && now >= c->verdict_ms)
            conn_refuse(c, "authentication failed");
        else if (c->state == HELD)
            continue;
        else if (c->state == NEED_AUTH && now - c->created_ms > srv->handshake_ms)
            conn_drop(c, "authentication handshake timed out");
        else if (srv->silence_ms > 0 && now - c->last_rx_ms > srv->silence_ms)
            conn_drop(c, "silent for too long (no frame or heartbeat)");
    }
}

/* Bring the epoll interest set in line with what each connection wants now: readable unless
 * its pipeline is full behind a blocked request, writable while replies are queued.  Costs a
 * syscall only for connections whose interest changed.  Returns the capacity needed for
 * epoll_wait's event array, or 0 if it cannot be allocated. */
static size_t sync_interest(ts_server *srv)
{
    if (srv->listen_fd >= 0 && !srv->listen_added && tf_now_ms() >= srv->accept_paused_until) {
        struct epoll_event ev = {.events = EPOLLIN, .data.ptr = NULL};
        if (epoll_ctl(srv->epfd, EPOLL_CTL_ADD, srv->listen_fd, &ev) == 0)
            srv->listen_added = 1;
    }
    flush_dirty(srv); /* per-connection interest */
    size_t need = srv->nconns + 1;
    if (need > srv->evcap) {
        struct epoll_event *e = realloc(srv->evs, 2 * need * sizeof *e);
        if (!e)
            return 0;
        srv->evs = e;
        srv->evcap = 2 * need;
    }
    return srv->evcap;
}

int ts_server_run_once(ts_server *srv, int timeout_ms)
{
    srv->in_loop = 1;
    flush_dirty(srv); /* replies produced by in-process outs since the last iteration */
    int needs_timer = srv->silence_ms > 0 || srv->has_key;
    if (needs_timer && (timeout_ms < 0 || timeout_ms > TS_POLL_CAP_MS))
        timeout_ms = TS_POLL_CAP_MS;
    size_t n = sync_interest(srv);
    if (n == 0) {
        srv->in_loop = 0;
        errno = ENOMEM;
        return -1;
    }
    int ready = epoll_wait(srv->epfd, srv->evs, (int)(n < 65536 ? n : 65536), timeout_ms);
    if (ready < 0 && errno != EINTR) {
        srv->in_loop = 0;
        return -1;
    }
    /* Connections closed while serving this batch stay in the graveyard (not freed) until the
     * batch is done, so a later event's data.ptr is never dangling. */
    for (int i = 0; i < ready; i++) {
        uint32_t re = srv->evs[i].events;
        conn *c = srv->evs[i].data.ptr;
        if (!c) {
            accept_all(srv);
            continue;
        }
        if (c->dead)
            continue;
        if (re & (EPOLLIN | EPOLLHUP | EPOLLERR))
            conn_readable(c);
        if (!c->dead && (re & EPOLLOUT)) {
            if (conn_flush(c) != 0)
                conn_drop(c, strerror(errno));
            else
                conn_touch(c); /* maybe no longer wants EPOLLOUT */
        }
    }
    flush_dirty(srv);
    enforce_timeouts(srv);
    while (srv->graveyard) {
        conn *g = srv->graveyard;
        srv->graveyard = g->next;
        conn_destroy(g);
    }
    srv->in_loop = 0;
    return ready < 0 ? 0 : ready;
}

size_t ts_server_conn_count(const ts_server *srv) { return srv->nconns; }

static conn *find_conn(const ts_server *srv, uint64_t id)
{
    for (conn *c = srv->conns; c; c = c->next)
        if (c->id == id)
            return c;
    return NULL;
}

const char *ts_server_peer(const ts_server *srv, uint64_t conn_id)
{
    conn *c = find_conn(srv, conn_id);
    return c ? c->peer : NULL;
}

int ts_server_conn_trusted(const ts_server *srv, uint64_t conn_id)
{
    const conn *c = find_conn(srv, conn_id);
    return c && c->trusted;
}

int ts_server_close_conn(ts_server *srv, uint64_t conn_id)
{
    conn *c = find_conn(srv, conn_id);
    if (!c)
        return 0;
    conn_close(c);
    return 1;
}

void ts_server_free(ts_server *srv)
{
    if (!srv)
        return;
    srv->in_loop = 0;
    while (srv->conns)
        conn_close(srv->conns);
    if (srv->listen_fd >= 0)
        close(srv->listen_fd);
    if (srv->unix_path[0])
        unlink(srv->unix_path);
    close(srv->epfd);
    free(srv->evs);
    free(srv);
}
