/* tsserver.h: the tuple-space server, a single-threaded poll() event loop in the coordinator
 * (in the style of Redis's ae.c/anet.c) that serves a ts_space (tuplespace.h) to workers over TCP
 * and over already-connected fds (socketpairs to forked workers).  Protocol: proto.h.
 *
 * The coordinator drives it: ts_server_run_once(srv, timeout) waits at most timeout ms for
 * socket events, serves them, enforces timeouts, and returns, so the coordinator can interleave
 * its own work (the supervisor calls the ts_space directly between iterations, in the same
 * thread; tuples it outs wake network waiters immediately, whose replies go out on the next
 * iteration).
 *
 * With a key, every byte after the handshake travels in sealed records (seal.h), and every
 * request is checked against the connection's role (capability.h) before the space sees it.
 *
 * Connections are non-blocking, with a bounded input buffer (one frame of at most TF_MAX_FRAME)
 * and a bounded output buffer (a client that stops reading its replies is dropped when more
 * than max_output_bytes are queued).  Any malformed, oversized, unknown-op, wrong-version or
 * unauthenticated frame closes that connection only, logging one line that names the peer.
 * A connection that sends nothing (not even a PING) for silence_timeout_ms is closed; so is
 * one that has not finished the authentication handshake within handshake_timeout_ms.  The
 * silence is judged only after what arrived has been read, and never across a stall of the
 * server itself (the process stopped, a VM paused, a long step between iterations): when the
 * clock jumps between two iterations, every silence timer starts again.
 *
 * Bounded resources: before authentication only handshake-sized frames are read (proto.h);
 * unauthenticated connections have their own caps (see the config) and deadline; an address
 * that fails the handshake repeatedly is made to wait, doubling, before it may try again;
 * every repeated warning is rate-limited (log.h).  When a
 * connection closes, its blocked requests are cancelled and on_disconnect runs.
 *
 * Hooks (all optional) let the coordinator lease tasks: on_take runs when a connection removes a
 * tuple with in or inp (immediately or when a blocked in is served later), before the reply is
 * queued; on_out after a connection's tuple has been put in the space (it may already have been
 * handed to a waiter: the hook sees the tuple's value, not a live reference into the store: a
 * view of the request's frame, tuple.h's tf_tuple_view, read-only and valid during the call);
 * on_disconnect when a connection is closed for any reason (including ts_server_close_conn and
 * ts_server_free).  Hooks may call the ts_space and ts_server_close_conn.
 *
 * Every in and inp names its connection id as the taker (ts_wait_as, ts_space_inp_as), so a
 * chooser set on the space (tuplespace.h) can rank the matching tuples per connection. */
#ifndef TF_TSSERVER_H
#define TF_TSSERVER_H

#include <stddef.h>
#include <stdint.h>

#include "linda/auth.h"
#include "linda/capability.h"
#include "linda/outbox.h"
#include "linda/tuple.h"
#include "linda/tuplespace.h"

typedef struct ts_server ts_server;

typedef struct ts_server_hooks {
    void *ctx;
    void (*on_take)(void *ctx, uint64_t conn_id, const tf_tuple *tuple);
    void (*on_out)(void *ctx, uint64_t conn_id, const tf_tuple *tuple);
    void (*on_disconnect)(void *ctx, uint64_t conn_id, const char *peer);
} ts_server_hooks;

typedef struct ts_server_config {
    /* "HOST:PORT" / "[V6]:PORT" to listen on TCP (port 0 = ephemeral, see ts_server_port),
     * "unix:/path" for a Unix socket, or NULL to accept only fds added by ts_server_add_fd.  Any
     * address is accepted here: the caller enforces "non-loopback needs a secret" with
     * tf_addr_is_loopback (auth.h). */
    const char *listen;
    /* 32-byte key (tf_secret_load), or NULL: no authentication on accepted connections.  Fds
     * added with ts_server_add_fd are trusted and never authenticate. The key is copied. */
    const uint8_t *key;
    int silence_timeout_ms;   /* <= 0: no silence timeout */
    int handshake_timeout_ms; /* <= 0: 5000 */
    size_t max_output_bytes;  /* <= 0: 2 * TF_MAX_FRAME + 1 MiB (room for one largest reply) */
    int max_connections;      /* <= 0: 4096; accepted connections beyond it are closed */
    /* The role of every connection, accepted or added by fd (capability.h); NULL: every
     * connection is privileged (the tuple space as plain Linda: tests, benchmarks). */
    const ts_role *role;
    /* With a role: an out is refused once the space would hold more than this many bytes
     * (tf_tuple_bytes); 0: no limit. */
    size_t max_space_bytes;
    /* Connections that have not finished the handshake: at most this many in all and from
     * one address; a new one beyond either cap closes the oldest such connection still waiting
     * for its AUTH (so idle strangers cannot lock real workers out: a worker needs one round
     * trip).  Failed handshakes whose answer is held (a wrong secret from an address that
     * failed before) count too; from one address they are never closed early: a newcomer is
     * refused instead, so the guesses in flight stay bounded.  <= 0: 64, 8. */
    int max_unauthenticated, max_unauthenticated_per_address;
    /* Authenticated (or loopback) connections from one address beyond this are refused.
     * <= 0: 1024. */
    int max_per_address;
} ts_server_config;

/* Create the server over space (not owned: the caller frees it after the server).  cfg and
 * hooks may be NULL (defaults, no hooks).  NULL on failure with the reason in err (e.g.
 * "cannot listen on 0.0.0.0:7000: Address already in use"). */
ts_server *ts_server_new(ts_space *space, const ts_server_config *cfg,
                         const ts_server_hooks *hooks, char *err, size_t errlen);
/* Close every connection (on_disconnect for each), the listener (unlinking a Unix socket
 * path), and free.  NULL is fine. */
void ts_server_free(ts_server *srv);

/* The TCP port actually bound (useful with port 0), or 0 when not listening on TCP. */
int ts_server_port(const ts_server *srv);

/* Serve an already-connected fd (e.g. the coordinator's end of a socketpair to a forked
 * worker): trusted, no HELLO, no authentication.  Takes ownership of fd (made non-blocking).
 * peer labels it in logs and ts_server_peer (e.g. "worker 3"; NULL: "fd N").  Returns the
 * connection id (> 0), or 0 on failure (fd closed). */
uint64_t ts_server_add_fd(ts_server *srv, int fd, const char *peer);
/* Give such a connection the outbox its forked worker shares (outbox.h): from now on it may send
 * OUT_SHARED.  The connection takes the caller's reference and drops it when it is freed (the
 * tuples it stored there hold their own).  0, or -1 (no such live connection; the reference
 * stays the caller's). */
int ts_server_adopt_outbox(ts_server *srv, uint64_t conn_id, tf_outbox *ob);

/* One event-loop iteration: wait up to timeout_ms (0: poll only, < 0: until something
 * happens) for socket events, accept, read, serve, write, enforce timeouts.  Returns the number
 * of sockets that had events, or -1 on a fatal poll error (EINTR counts as 0 events). */
int ts_server_run_once(ts_server *srv, int timeout_ms);


/* Open connections (authenticated or not). */
size_t ts_server_conn_count(const ts_server *srv);
/* A connection's peer ("127.0.0.1:53122", "[::1]:5000", "unix", or the add_fd label); NULL if
 * no such connection.  Valid until the connection closes. */
const char *ts_server_peer(const ts_server *srv, uint64_t conn_id);
/* Close a connection now (on_disconnect runs).  1 if it existed, 0 if not. */
int ts_server_close_conn(ts_server *srv, uint64_t conn_id);
/* 1 if the connection was added by fd (ts_server_add_fd: a child this process forked), 0 if it
 * was accepted from the network or does not exist. */
int ts_server_conn_trusted(const ts_server *srv, uint64_t conn_id);

#endif
