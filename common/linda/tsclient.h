/* tsclient.h: the blocking tuple-space client a worker uses to talk to the coordinator's
 * tuple-space server (common/linda/tsserver.h) over TCP, a Unix socket, or an inherited
 * socketpair fd (forked workers).  Protocol: proto.h.
 *
 * One request at a time: every call sends one frame and waits for its reply, so a client must
 * not be used by two threads at once -- except for the heartbeat, a background thread that
 * sends a PING (request id 0, no reply) every interval so the server's silence timeout does not
 * drop a worker busy on a long task; socket writes are serialised by a mutex inside the client.
 *
 * Errors: every call returns -1 on failure and leaves one clear line (no "terrafarm:" prefix)
 * in ts_client_error(); after a transport or protocol error (refused, reset, closed, bad frame
 * from the server, authentication failure) the client is dead and every later call fails
 * fast with the same message.  Nothing here exits or crashes the process. */
#ifndef TF_TSCLIENT_H
#define TF_TSCLIENT_H

#include <stddef.h>
#include <stdint.h>

#include "linda/auth.h"
#include "linda/outbox.h"
#include "linda/tuple.h"

typedef struct ts_client ts_client;

/* Connect to "HOST:PORT" ("[::1]:PORT" for IPv6) or "unix:/path/to/socket", waiting at most
 * timeout_ms for the connection and the server's HELLO (<= 0: 10 s).  key is the 32-byte key
 * from tf_secret_load, or NULL.  With a key the client authenticates and also verifies the
 * server's proof; it refuses a server that does not ask for authentication (it could be an
 * impostor).  Without a key, a server that requires authentication is reported as
 * "coordinator requires a secret (--secret-file)".  NULL on failure with the reason in err. */
ts_client *ts_client_connect(const char *hostport, const uint8_t *key, int timeout_ms,
                             char *err, size_t errlen);
/* Wrap an already-connected, trusted fd (a socketpair end given to a forked worker; the server
 * side was added with ts_server_add_fd, which sends no HELLO).  Takes ownership of fd.  NULL
 * only on OOM. */
ts_client *ts_client_from_fd(int fd);
/* Such a client's outbox, shared with the server's end (outbox.h; the server adopted the same
 * one with ts_server_adopt_outbox): from now on a large OUT (TF_OUTBOX_MIN) is encoded in a
 * record of it and sent as OUT_SHARED, or as before when it has no room.  c takes the
 * caller's reference (NULL: none; OUTs travel whole again). */
void ts_client_adopt_outbox(ts_client *c, tf_outbox *ob);
/* Stop the heartbeat, close the socket, free. NULL is fine. */
void ts_client_close(ts_client *c);

/* Put tuple t (no formals) into the space; returns once the server has stored it. 0 or -1. */
int ts_out(ts_client *c, const tf_tuple *t);
/* Blocking: wait for a tuple matching tmpl; in removes it, rd copies it.  The result is decoded
 * into *out (caller-owned: must not hold data; free it with tf_tuple_clear).  0 or -1. */
int ts_in(ts_client *c, const tf_tuple *tmpl, tf_tuple *out);
int ts_rd(ts_client *c, const tf_tuple *tmpl, tf_tuple *out);
/* Non-blocking: 1 found (into *out), 0 no match now, -1 error. */
int ts_inp(ts_client *c, const tf_tuple *tmpl, tf_tuple *out);
int ts_rdp(ts_client *c, const tf_tuple *tmpl, tf_tuple *out);
/* ts_out(t) then ts_in(tmpl, out) in one round trip: both requests leave in one write and
 * their replies are read in order (the server serves a connection's requests in order, so the
 * in is admitted after the out is stored).  A worker returns a result and takes its next task
 * this way: half the wake-ups and system calls per task on both sides.  0 or -1 (after an
 * error nothing says whether the out was stored). */
int ts_out_in(ts_client *c, const tf_tuple *t, const tf_tuple *tmpl, tf_tuple *out);
/* The same exchange for one thread serving many connections (worker/simulate.c), in two
 * halves: ts_out_in_send sends the out (t may be NULL: the in alone) and the in without
 * waiting; then, whenever the connection's fd is readable, ts_out_in_poll reads what it holds,
 * never waiting: 1 with the in's tuple in *out (caller-owned), 0 while replies are still to
 * come, -1 on error.  One exchange in flight at a time; other calls only once it is done. */
int ts_client_fd(const ts_client *c);
int ts_out_in_send(ts_client *c, const tf_tuple *t, const tf_tuple *tmpl);
int ts_out_in_poll(ts_client *c, tf_tuple *out);
/* Round trip a PING/PONG.  0 or -1. */
int ts_ping(ts_client *c);

/* Start (interval_ms > 0) or stop (0) the heartbeat thread.  0 or -1. */
int ts_client_heartbeat(ts_client *c, int interval_ms);

/* The last error, "" if none. */
const char *ts_client_error(const ts_client *c);

#endif
