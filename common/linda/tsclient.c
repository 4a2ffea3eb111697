/* tsclient.c: the blocking tuple-space client (see tsclient.h; wire format in proto.h).
 *
 * Each call writes one request frame (under send_lock, shared with the heartbeat thread) and
 * then reads frames until the reply with the same request id arrives.  Reads go through an
 * input buffer so a reply split across several recv() calls, or two frames in one, are both
 * fine.  Every frame from the server passes tf_frame_parse's bounds checks before its body is
 * buffered, and tuple bodies pass tf_tuple_decode, so a broken server cannot make the client
 * allocate more than TF_MAX_FRAME or crash. */
#include "linda/tsclient.h"
#include "clock.h"

#include <errno.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>
#include <sodium.h>

#include "le_bytes.h"
#include "linda/outbox.h"
#include "linda/proto.h"
#include "linda/seal.h"
#include "linda/sock.h"
#include "log.h"

struct ts_client {
    int fd;
    int dead;
    uint32_t next_req;
    tf_buf in, out;
    int sealed;            /* records on the wire after AUTH_OK (seal.h) */
    tf_outbox *outbox;     /* a forked worker's: large OUTs go as OUT_SHARED (outbox.h) */
    tf_seal tx, rx;        /* tx under send_lock */
    tf_buf raw, wire;      /* records read but not opened; records being sent */
    char err[256];
    pthread_mutex_t send_lock;
    _Atomic int64_t last_tx_ms; /* when a frame last left (tf_now_ms): a ping is due after it */
    /* heartbeat */
    pthread_t hb_thread;
    int hb_running, hb_stop, hb_interval_ms;
    pthread_mutex_t hb_lock;
    pthread_cond_t hb_cond;
    /* ts_out_in_send's exchange in flight: the reply awaited next (the out's, then the in's) */
    int async_pending;     /* replies still to come: 0, 1 (the in's) or 2 (the out's first) */
    uint32_t async_out, async_in;
};

/* Record the first fatal error; the client is dead afterwards. */
static int fail(ts_client *c, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static int fail(ts_client *c, const char *fmt, ...)
{
    if (!c->dead) {
        va_list ap;
        va_start(ap, fmt);
        tf_vseterr(c->err, sizeof c->err, fmt, ap);
        va_end(ap);
        c->dead = 1;
    }
    return -1;
}

static ts_client *client_new(int fd)
{
    ts_client *c = calloc(1, sizeof *c);
    if (!c)
        return NULL;
    c->fd = fd;
    c->next_req = 1;
    tf_buf_init(&c->in);
    tf_buf_init(&c->out);
    tf_buf_init(&c->raw);
    tf_buf_init(&c->wire);
    pthread_mutex_init(&c->send_lock, NULL);
    pthread_mutex_init(&c->hb_lock, NULL);
    pthread_cond_init(&c->hb_cond, NULL);
    return c;
}

ts_client *ts_client_from_fd(int fd)
{
    ts_client *c = client_new(fd);
    if (!c)
        close(fd);
    return c;
}

void ts_client_adopt_outbox(ts_client *c, tf_outbox *ob)
{
    tf_outbox_unref(c->outbox);
    c->outbox = ob;
}

/* Send every byte of buf; the caller holds send_lock.  0 or -1 with errno. */
static int send_all(int fd, const uint8_t *buf, size_t len);

/* Send plaintext bytes (whole frames), sealed when the connection is; call under send_lock. */
static int send_plain(ts_client *c, const uint8_t *buf, size_t len)
{
    atomic_store(&c->last_tx_ms, tf_now_ms());
    if (!c->sealed)
        return send_all(c->fd, buf, len);
    c->wire.len = c->wire.off = 0;
    if (tf_seal_append(&c->tx, &c->wire, buf, len) != 0) {
        errno = ENOMEM;
        return -1;
    }
    return send_all(c->fd, tf_buf_head(&c->wire), c->wire.len);
}

static int send_all(int fd, const uint8_t *buf, size_t len)
{
    while (len > 0) {
        ssize_t n = send(fd, buf, len, MSG_NOSIGNAL);
        if (n < 0 && errno == EINTR)
            continue;
        if (n < 0)
            return -1;
        buf += n;
        len -= (size_t)n;
    }
    return 0;
}

/* One frame to send: its op, request id, and body (a tuple, or raw bytes). */
typedef struct frame_spec {
    uint8_t op;
    uint32_t req;
    const tf_tuple *t;
    const void *raw;
    size_t rawlen;
} frame_spec;

/* A large OUT as OUT_SHARED, its tuple encoded in a record of the outbox: 0 done, 1 not this
 * way (no outbox, a small or oversized tuple, or no room now), -1 out of memory. */
static int append_shared_out(ts_client *c, const frame_spec *f)
{
    size_t size = f->t && f->op == TF_OP_OUT ? tf_tuple_encoded_size(f->t) : 0;
    if (!c->outbox || size < TF_OUTBOX_MIN || size > TF_MAX_FRAME - TF_FRAME_MIN_LENGTH)
        return 1;
    int64_t off = tf_outbox_reserve(c->outbox, size);
    if (off < 0)
        return 1;
    tf_tuple_encode(f->t, tf_outbox_base(c->outbox) + off);
    uint8_t body[8];
    tf_le_put32(body, (uint64_t)off);
    tf_le_put32(body + 4, size);
    return tf_frame_append_raw(&c->out, TF_OP_OUT_SHARED, f->req, body, sizeof body);
}

/* Append frame f to c->out (a large OUT through the outbox when it can).  0 or -1. */
static int append_frame(ts_client *c, const frame_spec *f)
{
    int rc = append_shared_out(c, f);
    if (rc <= 0)
        return rc;
    return f->t ? tf_frame_append_tuple(&c->out, f->op, f->req, f->t)
                : tf_frame_append_raw(&c->out, f->op, f->req, f->raw, f->rawlen);
}

/* Send n frames in one write (under send_lock, so a heartbeat cannot come between them). */
static int send_frames(ts_client *c, int n, const frame_spec *f)
{
    if (c->dead)
        return -1;
    pthread_mutex_lock(&c->send_lock);
    c->out.len = c->out.off = 0;
    int rc = 0;
    for (int i = 0; i < n && rc == 0; i++)
        rc = append_frame(c, &f[i]);
    if (rc != 0) {
        pthread_mutex_unlock(&c->send_lock);
        return fail(c, "request too large for one frame (%u bytes at most)", TF_MAX_FRAME);
    }
    rc = send_plain(c, tf_buf_head(&c->out), c->out.len);
    int saved = errno;
    pthread_mutex_unlock(&c->send_lock);
    if (rc != 0)
        return fail(c, "lost the coordinator connection: %s", strerror(saved));
    return 0;
}

/* Send one frame (body: raw bytes or a tuple). */
static int send_frame(ts_client *c, uint8_t op, uint32_t req, const tf_tuple *t,
                      const void *raw, size_t rawlen)
{
    frame_spec f = {op, req, t, raw, rawlen};
    return send_frames(c, 1, &f);
}

/* The next whole frame among the bytes read so far (sealed records opened first), without
 * reading more: its length (> 0) with *f (body in c->in), 0 if none is whole yet, or -1. */
static long buffered_frame(ts_client *c, tf_frame *f)
{
    char err[160];
    while (c->sealed && c->raw.len > 0) {
        long k = tf_seal_open(&c->rx, tf_buf_head(&c->raw), c->raw.len, &c->in, err,
                              sizeof err);
        if (k < 0)
            return fail(c, "bad record from the coordinator: %s", err);
        if (k == 0)
            break;
        tf_buf_consume(&c->raw, (size_t)k);
    }
    long n = tf_frame_parse(tf_buf_head(&c->in), c->in.len, f, err, sizeof err);
    return n < 0 ? fail(c, "bad frame from the coordinator: %s", err) : n;
}

/* Read one frame into *f (body points into c->in, valid until the next read), waiting until
 * deadline (ms since boot; < 0: forever).  The caller consumes it with tf_buf_consume. */
static long read_frame(ts_client *c, tf_frame *f, int64_t deadline)
{
    for (;;) {
        long n = buffered_frame(c, f);
        if (n != 0)
            return n;
        int wait = -1;
        if (deadline >= 0) {
            int64_t left = deadline - tf_now_ms();
            if (left <= 0)
                return fail(c, "timed out waiting for the coordinator");
            wait = left > 1000000 ? 1000000 : (int)left;
        }
        struct pollfd p = {.fd = c->fd, .events = POLLIN};
        int pr = poll(&p, 1, wait);
        if (pr < 0 && errno == EINTR)
            continue;
        if (pr < 0)
            return fail(c, "poll: %s", strerror(errno));
        if (pr == 0)
            continue;
        tf_buf *dst = c->sealed ? &c->raw : &c->in;
        if (tf_buf_reserve(dst, 65536) != 0)
            return fail(c, "out of memory reading a reply");
        ssize_t r = recv(c->fd, dst->data + dst->off + dst->len, 65536, 0);
        if (r < 0 && (errno == EINTR || errno == EAGAIN))
            continue;
        if (r < 0)
            return fail(c, "lost the coordinator connection: %s", strerror(errno));
        if (r == 0)
            return fail(c, "the coordinator closed the connection");
        dst->len += (size_t)r;
    }
}

/* Turn an ERROR frame into the client's error. */
static int fail_with_server_error(ts_client *c, const tf_frame *f)
{
    size_t n = f->body_len < TF_PROTO_ERROR_MAX ? f->body_len : TF_PROTO_ERROR_MAX;
    return fail(c, "coordinator refused: %.*s", (int)n, (const char *)f->body);
}

/* A request's reply is awaited for as long as it takes (a blocking in may wait for hours); only
 * the connection and its handshake have a deadline. */
#define NO_DEADLINE (-1)

/* read_frame, with a server's ERROR frame turned into the client's error. */
static long read_reply(ts_client *c, tf_frame *f, int64_t deadline)
{
    long n = read_frame(c, f, deadline);
    if (n >= 0 && f->op == TF_OP_ERROR)
        return fail_with_server_error(c, f);
    return n;
}

static uint32_t next_request_id(ts_client *c)
{
    uint32_t req = c->next_req++;
    if (c->next_req == 0)
        c->next_req = 1; /* 0 is reserved for unsolicited frames */
    return req;
}

static int await_reply(ts_client *c, uint32_t req, tf_tuple *out, int64_t deadline);

/* Send op with body t and wait for its reply.  Returns the reply op (>0) with the decoded
 * tuple in *out for TUPLE, or -1. */
static int request(ts_client *c, uint8_t op, const tf_tuple *t, tf_tuple *out)
{
    if (c->dead)
        return -1;
    uint32_t req = next_request_id(c);
    if (send_frame(c, op, req, t, NULL, 0) != 0)
        return -1;
    return await_reply(c, req, out, NO_DEADLINE);
}

/* Frame f (n bytes) as the reply to request req: its op (> 0), with a TUPLE's body decoded
 * into *out; consumed.  -1 if it is not that reply. */
static int accept_reply(ts_client *c, const tf_frame *f, long n, uint32_t req, tf_tuple *out)
{
    if (f->request_id != req || (f->op != TF_OP_TUPLE && f->op != TF_OP_NONE &&
                                 f->op != TF_OP_OK && f->op != TF_OP_PONG))
        return fail(c, "unexpected %s (request %u) from the coordinator", tf_op_name(f->op),
                    f->request_id);
    int rop = f->op;
    if (rop == TF_OP_TUPLE) {
        char err[160];
        if (tf_tuple_decode(f->body, f->body_len, out, 0, err, sizeof err) != 0)
            return fail(c, "bad tuple from the coordinator: %s", err);
    }
    tf_buf_consume(&c->in, (size_t)n);
    return rop;
}

/* Read the reply to request req (replies come in request order). */
static int await_reply(ts_client *c, uint32_t req, tf_tuple *out, int64_t deadline)
{
    tf_frame f;
    long n = read_reply(c, &f, deadline);
    return n < 0 ? -1 : accept_reply(c, &f, n, req, out);
}

/* The expected reply op for each request. */
static int expect(ts_client *c, int got, int want1, int want2)
{
    if (got < 0)
        return -1;
    if (got != want1 && got != want2)
        return fail(c, "coordinator answered %s where %s was expected", tf_op_name(got),
                    tf_op_name(want1));
    return 0;
}

int ts_out_in(ts_client *c, const tf_tuple *t, const tf_tuple *tmpl, tf_tuple *out)
{
    tf_tuple_init(out);
    if (tf_tuple_has_formals(t)) {
        snprintf(c->err, sizeof c->err, "ts_out: a tuple may not contain formals");
        return -1;
    }
    uint32_t put = next_request_id(c), take = next_request_id(c);
    frame_spec f[2] = {{TF_OP_OUT, put, t, NULL, 0}, {TF_OP_IN, take, tmpl, NULL, 0}};
    if (send_frames(c, 2, f) != 0)
        return -1;
    if (expect(c, await_reply(c, put, NULL, NO_DEADLINE), TF_OP_OK, TF_OP_OK) != 0)
        return -1;
    return expect(c, await_reply(c, take, out, NO_DEADLINE), TF_OP_TUPLE, TF_OP_TUPLE);
}

int ts_out(ts_client *c, const tf_tuple *t)
{
    if (tf_tuple_has_formals(t)) {
        snprintf(c->err, sizeof c->err, "ts_out: a tuple may not contain formals");
        return -1;
    }
    return expect(c, request(c, TF_OP_OUT, t, NULL), TF_OP_OK, TF_OP_OK);
}

static int blocking(ts_client *c, uint8_t op, const tf_tuple *tmpl, tf_tuple *out)
{
    tf_tuple_init(out);
    return expect(c, request(c, op, tmpl, out), TF_OP_TUPLE, TF_OP_TUPLE);
}

static int probing(ts_client *c, uint8_t op, const tf_tuple *tmpl, tf_tuple *out)
{
    tf_tuple_init(out);
    int rop = request(c, op, tmpl, out);
    if (expect(c, rop, TF_OP_TUPLE, TF_OP_NONE) != 0) {
        tf_tuple_clear(out);
        return -1;
    }
    return rop == TF_OP_TUPLE;
}

int ts_in(ts_client *c, const tf_tuple *tmpl, tf_tuple *out) { return blocking(c, TF_OP_IN, tmpl, out); }
int ts_rd(ts_client *c, const tf_tuple *tmpl, tf_tuple *out) { return blocking(c, TF_OP_RD, tmpl, out); }
int ts_inp(ts_client *c, const tf_tuple *tmpl, tf_tuple *out) { return probing(c, TF_OP_INP, tmpl, out); }
int ts_rdp(ts_client *c, const tf_tuple *tmpl, tf_tuple *out) { return probing(c, TF_OP_RDP, tmpl, out); }

int ts_ping(ts_client *c) { return expect(c, request(c, TF_OP_PING, NULL, NULL), TF_OP_PONG, TF_OP_PONG); }

const char *ts_client_error(const ts_client *c) { return c->err; }

/* ---- one thread, many connections: ts_out_in without waiting ---- */

int ts_client_fd(const ts_client *c) { return c->fd; }

int ts_out_in_send(ts_client *c, const tf_tuple *t, const tf_tuple *tmpl)
{
    if (c->async_pending) {
        snprintf(c->err, sizeof c->err, "ts_out_in_send: an exchange is already in flight");
        return -1;
    }
    if (t && tf_tuple_has_formals(t)) {
        snprintf(c->err, sizeof c->err, "ts_out: a tuple may not contain formals");
        return -1;
    }
    frame_spec f[2];
    int n = 0;
    if (t) {
        c->async_out = next_request_id(c);
        f[n++] = (frame_spec){TF_OP_OUT, c->async_out, t, NULL, 0};
    }
    c->async_in = next_request_id(c);
    f[n++] = (frame_spec){TF_OP_IN, c->async_in, tmpl, NULL, 0};
    if (send_frames(c, n, f) != 0)
        return -1;
    c->async_pending = n;
    return 0;
}

/* One recv of what the socket holds now, never waiting.  0 (perhaps nothing came) or -1. */
static int read_available(ts_client *c)
{
    tf_buf *dst = c->sealed ? &c->raw : &c->in;
    if (tf_buf_reserve(dst, 65536) != 0)
        return fail(c, "out of memory reading a reply");
    ssize_t r = recv(c->fd, dst->data + dst->off + dst->len, 65536, MSG_DONTWAIT);
    if (r < 0 && (errno == EINTR || errno == EAGAIN || errno == EWOULDBLOCK))
        return 0;
    if (r < 0)
        return fail(c, "lost the coordinator connection: %s", strerror(errno));
    if (r == 0)
        return fail(c, "the coordinator closed the connection");
    dst->len += (size_t)r;
    return 0;
}

int ts_out_in_poll(ts_client *c, tf_tuple *out)
{
    tf_tuple_init(out);
    if (c->dead)
        return -1;
    if (!c->async_pending) {
        snprintf(c->err, sizeof c->err, "ts_out_in_poll: no exchange in flight");
        return -1;
    }
    if (read_available(c))
        return -1;
    for (;;) {
        tf_frame f;
        long n = buffered_frame(c, &f);
        if (n <= 0)
            return (int)n;
        if (f.op == TF_OP_ERROR)
            return fail_with_server_error(c, &f);
        int last = c->async_pending == 1;
        int rop = accept_reply(c, &f, n, last ? c->async_in : c->async_out, out);
        if (expect(c, rop, last ? TF_OP_TUPLE : TF_OP_OK, last ? TF_OP_TUPLE : TF_OP_OK) != 0) {
            tf_tuple_clear(out);
            return -1;
        }
        if (--c->async_pending == 0)
            return 1;
    }
}

/* ---- heartbeat ---- */
/* A ping goes out once nothing else has for an interval: a worker sending results keeps its
 * connection alive by them, and pings only while it renders a long task or waits idle. */
static void *heartbeat_main(void *arg)
{
    ts_client *c = arg;
    pthread_mutex_lock(&c->hb_lock);
    while (!c->hb_stop) {
        int64_t wait = atomic_load(&c->last_tx_ms) + c->hb_interval_ms - tf_now_ms();
        struct timespec ts = tf_realtime_in(wait > 0 ? (double)wait : 0.0);
        pthread_cond_timedwait(&c->hb_cond, &c->hb_lock, &ts);
        if (c->hb_stop)
            break;
        if (tf_now_ms() - atomic_load(&c->last_tx_ms) < c->hb_interval_ms)
            continue; /* a frame left meanwhile */
        /* A PING with request id 0 wants no reply; send errors surface on the main thread. */
        uint8_t frame[TF_FRAME_HEADER] = {TF_FRAME_MIN_LENGTH, 0, 0, 0, TF_PROTO_VERSION,
                                          TF_OP_PING, 0, 0, 0, 0};
        pthread_mutex_lock(&c->send_lock);
        int rc = send_plain(c, frame, sizeof frame);
        pthread_mutex_unlock(&c->send_lock);
        if (rc != 0)
            break;
    }
    pthread_mutex_unlock(&c->hb_lock);
    return NULL;
}

static void heartbeat_stop(ts_client *c)
{
    if (!c->hb_running)
        return;
    pthread_mutex_lock(&c->hb_lock);
    c->hb_stop = 1;
    pthread_cond_signal(&c->hb_cond);
    pthread_mutex_unlock(&c->hb_lock);
    pthread_join(c->hb_thread, NULL);
    c->hb_running = 0;
}

int ts_client_heartbeat(ts_client *c, int interval_ms)
{
    heartbeat_stop(c);
    if (interval_ms <= 0)
        return 0;
    c->hb_stop = 0;
    c->hb_interval_ms = interval_ms;
    if (pthread_create(&c->hb_thread, NULL, heartbeat_main, c) != 0) {
        snprintf(c->err, sizeof c->err, "cannot start the heartbeat thread");
        return -1;
    }
    c->hb_running = 1;
    return 0;
}

void ts_client_close(ts_client *c)
{
    if (!c)
        return;
    heartbeat_stop(c);
    if (c->fd >= 0)
        close(c->fd);
    tf_buf_free(&c->in);
    tf_buf_free(&c->out);
    tf_buf_free(&c->raw);
    tf_buf_free(&c->wire);
    tf_outbox_unref(c->outbox);
    sodium_memzero(&c->tx, sizeof c->tx);
    sodium_memzero(&c->rx, sizeof c->rx);
    pthread_mutex_destroy(&c->send_lock);
    pthread_mutex_destroy(&c->hb_lock);
    pthread_cond_destroy(&c->hb_cond);
    free(c);
}

/* ---- connecting ---- */

/* Read the HELLO and, with a key, run the mutual handshake.  0 or -1 (c->err set). */
static int handshake(ts_client *c, const uint8_t *key, int64_t deadline)
{
    tf_frame f;
    long n = read_reply(c, &f, deadline);
    if (n < 0)
        return -1;
    if (f.op != TF_OP_HELLO || f.body_len != 1 + TF_NONCE_BYTES)
        return fail(c, "not a terrafarm coordinator (no HELLO)");
    int required = f.body[0] & TF_HELLO_AUTH_REQUIRED;
    int sealed = f.body[0] & TF_HELLO_SEALED;
    uint8_t ns[TF_NONCE_BYTES];
    memcpy(ns, f.body + 1, TF_NONCE_BYTES);
    tf_buf_consume(&c->in, (size_t)n);
    if (!key && required)
        return fail(c, "coordinator requires a secret (--secret-file)");
    if (!key)
        return 0;
    if (!required)
        return fail(c, "coordinator does not authenticate, but a secret was given: refusing it");
    uint8_t body[TF_NONCE_BYTES + TF_MAC_BYTES], nc[TF_NONCE_BYTES];
    tf_auth_nonce(nc);
    memcpy(body, nc, TF_NONCE_BYTES);
    tf_auth_client_mac(key, ns, nc, body + TF_NONCE_BYTES);
    if (send_frame(c, TF_OP_AUTH, 0, NULL, body, sizeof body) != 0)
        return -1;
    /* A wrong secret gets an explicit ERROR ("authentication failed"); a close without one
     * (a handshake evicted to make room, a coordinator going away) may be retried. */
    n = read_frame(c, &f, deadline);
    if (n < 0) {
        if (strstr(c->err, "closed"))
            snprintf(c->err, sizeof c->err, "the coordinator closed the connection during the "
                     "handshake");
        return -1;
    }
    if (f.op == TF_OP_ERROR)
        return fail_with_server_error(c, &f);
    if (f.op != TF_OP_AUTH_OK || f.body_len != TF_MAC_BYTES ||
        !tf_auth_server_mac_ok(key, ns, nc, f.body))
        return fail(c, "the coordinator failed to prove it knows the secret");
    tf_buf_consume(&c->in, (size_t)n);
    if (!sealed)
        return fail(c, "the coordinator does not seal its frames (an older terrafarm?): "
                    "refusing to send the render in clear");
    /* Everything after AUTH_OK is sealed: bytes already read past it are records. */
    if (c->in.len > 0) {
        if (tf_buf_append(&c->raw, tf_buf_head(&c->in), c->in.len) != 0)
            return fail(c, "out of memory");
        tf_buf_consume(&c->in, c->in.len);
    }
    tf_seal_init(key, ns, nc, 1, &c->tx, &c->rx);
    c->sealed = 1;
    return 0;
}

ts_client *ts_client_connect(const char *hostport, const uint8_t *key, int timeout_ms,
                             char *err, size_t errlen)
{
    if (tf_auth_init() != 0) {
        tf_seterr(err, errlen, "libsodium failed to initialise");
        return NULL;
    }
    int64_t deadline = tf_now_ms() + (timeout_ms > 0 ? timeout_ms : 10000);
    int fd = tf_sock_connect(hostport, deadline, err, errlen);
    if (fd < 0)
        return NULL;
    ts_client *c = client_new(fd);
    if (!c) {
        close(fd);
        tf_seterr(err, errlen, "out of memory");
        return NULL;
    }
    if (handshake(c, key, deadline) != 0) {
        tf_seterr(err, errlen, "%s: %s", hostport, c->err);
        ts_client_close(c);
        return NULL;
    }
    return c;
}
