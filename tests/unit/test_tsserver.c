/* test_tsserver.c: the tuple-space server and client end to end (common/linda/tsserver.c,
 * common/linda/tsclient.c): over a socketpair and loopback TCP; a blocked in woken by another
 * client's out, and the requests pipelined behind a blocked in; ts_out_in in two halves; hooks
 * (on_take, on_out, on_disconnect); a large OUT stored in the buffer it arrived in; garbage,
 * oversized, unknown-op and half frames each dropping only their own connection;
 * authentication with the right and the wrong secret and an op before the handshake; wrong
 * secrets slowed per address without barring the right one from that address.  The server
 * loop runs in a background thread; the hooks record what they saw under a mutex. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include "clock.h"
#include "linda/tsserver.h"
#include "linda/proto.h"
#include "linda/tsclient.h"

typedef struct fixture {
    ts_space *space;
    ts_server *srv;
    pthread_t thread;
    volatile int stop;
    pthread_mutex_t lock;
    int takes, outs, disconnects;
    uint64_t blob_sum; /* of every blob byte on_out saw: it reads what it is shown */
    char addr[64];
    /* on_out takes a ("grab", ?I, ?B) out of the space and frees it before it reads the view,
     * as the supervisor does with a result (server thread only) */
    int grabbed, grabbed_shared;
} fixture;

/* Take the tuple just stored out of the space, note whether its blob stayed in the buffer it
 * was received into (shared), and free it. */
static void grab_stored(fixture *fx)
{
    tf_tuple tmpl, got;
    tf_tuple_init(&tmpl);
    tf_tuple_init(&got);
    tf_tuple_pack(&tmpl, "sIB", "grab");
    if (ts_space_inp(fx->space, &tmpl, &got) == 1) {
        pthread_mutex_lock(&fx->lock);
        fx->grabbed++;
        fx->grabbed_shared += got.f[2].v.bytes.shared != NULL;
        pthread_mutex_unlock(&fx->lock);
    }
    tf_tuple_clear(&got);
    tf_tuple_clear(&tmpl);
}

static void on_take(void *ctx, uint64_t id, const tf_tuple *t)
{
    (void)id;
    (void)t;
    fixture *fx = ctx;
    pthread_mutex_lock(&fx->lock);
    fx->takes++;
    pthread_mutex_unlock(&fx->lock);
}

static void on_out(void *ctx, uint64_t id, const tf_tuple *t)
{
    (void)id;
    fixture *fx = ctx;
    const char *name = tf_tuple_name(t);
    if (name && !strcmp(name, "grab"))
        grab_stored(fx); /* the view below must outlive the stored tuple */
    uint64_t sum = 0;
    for (int i = 0; i < t->nfields; i++)
        if (t->f[i].type == TF_FIELD_BLOB)
            for (uint32_t k = 0; k < t->f[i].v.bytes.len; k++)
                sum += t->f[i].v.bytes.ptr[k];
    pthread_mutex_lock(&fx->lock);
    fx->outs++;
    fx->blob_sum += sum;
    pthread_mutex_unlock(&fx->lock);
}

static void on_disconnect(void *ctx, uint64_t id, const char *peer)
{
    (void)id;
    (void)peer;
    fixture *fx = ctx;
    pthread_mutex_lock(&fx->lock);
    fx->disconnects++;
    pthread_mutex_unlock(&fx->lock);
}

static int counter(fixture *fx, int *which)
{
    pthread_mutex_lock(&fx->lock);
    int v = *which;
    pthread_mutex_unlock(&fx->lock);
    return v;
}

/* Wait up to 2 s for *which to reach want. */
static int wait_counter(fixture *fx, int *which, int want)
{
    for (int i = 0; i < 200; i++) {
        if (counter(fx, which) >= want)
            return 1;
        usleep(10000);
    }
    return 0;
}

static void *server_main(void *arg)
{
    fixture *fx = arg;
    while (!fx->stop)
        ts_server_run_once(fx->srv, 10);
    return NULL;
}

/* A server on 127.0.0.1 (with key, or none), not yet running: connections may be added by fd. */
static fixture *setup(const uint8_t *key)
{
    fixture *fx = calloc(1, sizeof *fx);
    pthread_mutex_init(&fx->lock, NULL);
    fx->space = ts_space_new();
    ts_server_config cfg = {.listen = "127.0.0.1:0", .key = key, .silence_timeout_ms = 5000};
    ts_server_hooks hooks = {fx, on_take, on_out, on_disconnect};
    char err[256];
    fx->srv = ts_server_new(fx->space, &cfg, &hooks, err, sizeof err);
    assert_non_null(fx->srv);
    assert_true(ts_server_port(fx->srv) > 0);
    snprintf(fx->addr, sizeof fx->addr, "127.0.0.1:%d", ts_server_port(fx->srv));
    return fx;
}

/* Run its loop in a background thread. */
static void launch(fixture *fx) { pthread_create(&fx->thread, NULL, server_main, fx); }

/* setup, the socketpair end extra_fd (if >= 0) added as a forked worker's, and launch. */
static fixture *start(const uint8_t *key, int extra_fd)
{
    fixture *fx = setup(key);
    if (extra_fd >= 0)
        assert_true(ts_server_add_fd(fx->srv, extra_fd, "worker 1") > 0);
    launch(fx);
    return fx;
}

static void stop(fixture *fx)
{
    fx->stop = 1;
    pthread_join(fx->thread, NULL);
    ts_server_free(fx->srv);
    ts_space_free(fx->space);
    free(fx);
}

static void tup(tf_tuple *t, const char *fmt, const char *name, int64_t v)
{
    tf_tuple_init(t);
    assert_int_equal(tf_tuple_pack(t, fmt, name, v), 0);
}

/* out, rdp, inp, rd, in and the empty answers over one client. */
static void exercise(ts_client *c)
{
    tf_tuple t, m, got;
    tup(&t, "si", "task", 5);
    assert_int_equal(ts_out(c, &t), 0);
    tf_tuple_clear(&t);
    tup(&m, "sI", "task", 0);
    assert_int_equal(ts_rdp(c, &m, &got), 1);
    tf_tuple_clear(&got);
    assert_int_equal(ts_rd(c, &m, &got), 0);
    tf_tuple_clear(&got);
    assert_int_equal(ts_in(c, &m, &got), 0);
    int64_t v;
    assert_int_equal(tf_tuple_get_int(&got, 1, &v), 0);
    assert_int_equal(v, 5);
    tf_tuple_clear(&got);
    assert_int_equal(ts_inp(c, &m, &got), 0);
    assert_int_equal(ts_rdp(c, &m, &got), 0);
    tf_tuple_clear(&m);
    assert_int_equal(ts_ping(c), 0);
}

static void test_socketpair_client(void **state)
{
    (void)state;
    int sv[2];
    assert_int_equal(socketpair(AF_UNIX, SOCK_STREAM, 0, sv), 0);
    fixture *fx = start(NULL, sv[0]);
    ts_client *c = ts_client_from_fd(sv[1]);
    exercise(c);
    assert_int_equal(counter(fx, &fx->takes), 1);
    assert_int_equal(counter(fx, &fx->outs), 1);
    ts_client_close(c);
    assert_true(wait_counter(fx, &fx->disconnects, 1));
    stop(fx);
}

/* ts_out_in of ("out_name", out_v) with the template (tmpl_name, ?int): the tuple it takes
 * must carry `want`. */
static void expect_out_in(ts_client *c, const char *out_name, int64_t out_v,
                          const char *tmpl_name, int64_t want)
{
    tf_tuple t, m, got;
    int64_t v;
    tup(&t, "si", out_name, out_v);
    tup(&m, "sI", tmpl_name, 0);
    assert_int_equal(ts_out_in(c, &t, &m, &got), 0);
    assert_int_equal(tf_tuple_get_int(&got, 1, &v), 0);
    assert_int_equal(v, want);
    tf_tuple_clear(&got);
    tf_tuple_clear(&t);
    tf_tuple_clear(&m);
}

/* ts_out_in: the out is stored before the in is served (the in can take the very tuple just
 * put), both replies are read in order, and a blocking in is woken by a later out; the
 * connection carries on normally afterwards. */
static void test_out_in_one_round_trip(void **state)
{
    (void)state;
    int sv[2];
    assert_int_equal(socketpair(AF_UNIX, SOCK_STREAM, 0, sv), 0);
    fixture *fx = start(NULL, sv[0]);
    ts_client *c = ts_client_from_fd(sv[1]);
    tf_tuple t, m, got;
    int64_t v;
    expect_out_in(c, "result", 7, "result", 7); /* takes back what it put */
    tup(&t, "si", "task", 1);
    assert_int_equal(ts_out(c, &t), 0);
    tf_tuple_clear(&t);
    expect_out_in(c, "result", 8, "task", 1); /* a result for a task */
    tup(&m, "sI", "result", 0);
    assert_int_equal(ts_inp(c, &m, &got), 1); /* the out of the pair was stored */
    assert_int_equal(tf_tuple_get_int(&got, 1, &v), 0);
    assert_int_equal(v, 8);
    tf_tuple_clear(&got);
    tf_tuple_clear(&m);
    exercise(c); /* and the stream is still in step */
    ts_client_close(c);
    assert_true(wait_counter(fx, &fx->disconnects, 1));
    stop(fx);
}

/* Read one frame from fd into *f (its body in buf), waiting at most 10 s: 0, or -1. */
static int read_raw_frame(int fd, uint8_t *buf, size_t cap, size_t *have, tf_frame *f)
{
    for (int64_t until = tf_now_ms() + 10000; tf_now_ms() < until;) {
        char err[160];
        long n = tf_frame_parse(buf, *have, f, err, sizeof err);
        if (n < 0)
            return -1;
        if (n > 0) /* the caller reads f before the next call consumes it */
            return (int)n;
        struct pollfd p = {.fd = fd, .events = POLLIN};
        if (poll(&p, 1, 100) > 0) {
            ssize_t r = recv(fd, buf + *have, cap - *have, 0);
            if (r <= 0)
                return -1;
            *have += (size_t)r;
        }
    }
    return -1;
}

/* Requests pipelined behind a blocked in (one write: IN, then RDP and PING) are served once
 * another client's out serves the in, with nothing more coming from their client: before
 * conn_resume they waited for the next frame on the socket (a heartbeat, 2 s later, or never). */
static void test_pipelined_behind_blocked_in(void **state)
{
    (void)state;
    int sv[2];
    assert_int_equal(socketpair(AF_UNIX, SOCK_STREAM, 0, sv), 0);
    fixture *fx = start(NULL, sv[0]);
    tf_tuple m;
    tup(&m, "sI", "wake", 0);
    tf_buf b;
    tf_buf_init(&b);
    assert_int_equal(tf_frame_append_tuple(&b, TF_OP_IN, 1, &m), 0);
    assert_int_equal(tf_frame_append_tuple(&b, TF_OP_RDP, 2, &m), 0);
    assert_int_equal(tf_frame_append_raw(&b, TF_OP_PING, 3, NULL, 0), 0);
    assert_int_equal(send(sv[1], tf_buf_head(&b), b.len, MSG_NOSIGNAL), (ssize_t)b.len);
    tf_buf_free(&b);
    tf_tuple_clear(&m);
    char err[256];
    ts_client *other = ts_client_connect(fx->addr, NULL, 2000, err, sizeof err);
    assert_non_null(other);
    tf_tuple t;
    tup(&t, "si", "wake", 42);
    assert_int_equal(ts_out(other, &t), 0);
    tf_tuple_clear(&t);
    static uint8_t buf[4096];
    size_t have = 0;
    uint8_t want_op[3] = {TF_OP_TUPLE, TF_OP_NONE, TF_OP_PONG}; /* the rdp finds nothing left */
    for (uint32_t req = 1; req <= 3; req++) {
        tf_frame f;
        int n = read_raw_frame(sv[1], buf, sizeof buf, &have, &f);
        assert_true(n > 0);
        assert_int_equal(f.request_id, req);
        assert_int_equal(f.op, want_op[req - 1]);
        memmove(buf, buf + n, have - (size_t)n);
        have -= (size_t)n;
    }
    ts_client_close(other);
    close(sv[1]);
    stop(fx);
}

/* ts_out_in in two halves (one thread, many connections: worker/simulate.c), plain and sealed:
 * the send does not wait, a poll before the replies come says 0, the replies are collected as
 * the socket has them; the exchange takes back what it put; a blocked in is served by another
 * client's out; a second send while one is in flight, or a poll with none, is an error. */
static int poll_exchange(ts_client *c, tf_tuple *got)
{
    for (int i = 0; i < 1000; i++) { /* a failure, never a hang: at most 10 s */
        int rc = ts_out_in_poll(c, got);
        if (rc != 0)
            return rc;
        struct pollfd p = {.fd = ts_client_fd(c), .events = POLLIN};
        poll(&p, 1, 10);
    }
    return 0;
}

static void exchange_in_halves(const uint8_t *key)
{
    int sv[2];
    assert_int_equal(socketpair(AF_UNIX, SOCK_STREAM, 0, sv), 0);
    fixture *fx = start(key, key ? -1 : sv[0]);
    char err[256];
    ts_client *c = key ? ts_client_connect(fx->addr, key, 2000, err, sizeof err)
                       : ts_client_from_fd(sv[1]);
    assert_non_null(c);
    tf_tuple t, m, got;
    int64_t v;
    tup(&t, "si", "result", 7);
    tup(&m, "sI", "result", 0);
    assert_int_equal(ts_out_in_poll(c, &got), -1); /* nothing in flight */
    assert_int_equal(ts_out_in_send(c, &t, &m), 0);
    assert_int_equal(ts_out_in_send(c, &t, &m), -1); /* one at a time */
    assert_int_equal(poll_exchange(c, &got), 1);
    assert_int_equal(tf_tuple_get_int(&got, 1, &v), 0);
    assert_int_equal(v, 7); /* took back what it put */
    tf_tuple_clear(&got);
    tf_tuple_clear(&m);
    tup(&m, "sI", "wake", 0);
    assert_int_equal(ts_out_in_send(c, NULL, &m), 0); /* the in alone: it blocks */
    assert_int_equal(ts_out_in_poll(c, &got), 0);    /* nothing yet */
    ts_client *other = ts_client_connect(fx->addr, key, 2000, err, sizeof err);
    assert_non_null(other);
    tf_tuple_clear(&t);
    tup(&t, "si", "wake", 9);
    assert_int_equal(ts_out(other, &t), 0);
    assert_int_equal(poll_exchange(c, &got), 1);
    assert_int_equal(tf_tuple_get_int(&got, 1, &v), 0);
    assert_int_equal(v, 9);
    tf_tuple_clear(&got);
    tf_tuple_clear(&t);
    tf_tuple_clear(&m);
    exercise(c); /* and the blocking calls carry on in step */
    ts_client_close(other);
    ts_client_close(c);
    if (key) {
        close(sv[0]);
        close(sv[1]);
    }
    stop(fx);
}

static void test_exchange_in_halves(void **state)
{
    (void)state;
    uint8_t key[TF_KEY_BYTES];
    tf_secret_from_bytes("correct horse", 13, key);
    exchange_in_halves(NULL); /* a plain socketpair */
    exchange_in_halves(key);  /* sealed records over TCP */
}

typedef struct blocked {
    const char *addr;
    int rc;
    int64_t value;
} blocked;

static void *blocked_in(void *arg)
{
    blocked *b = arg;
    char err[256];
    ts_client *c = ts_client_connect(b->addr, NULL, 2000, err, sizeof err);
    if (!c)
        return NULL;
    tf_tuple m, got;
    tf_tuple_init(&m);
    tf_tuple_pack(&m, "sI", "wake");
    b->rc = ts_in(c, &m, &got);
    tf_tuple_get_int(&got, 1, &b->value);
    tf_tuple_clear(&got);
    tf_tuple_clear(&m);
    ts_client_close(c);
    return NULL;
}

static void test_tcp_blocked_in_woken_by_other_client(void **state)
{
    (void)state;
    fixture *fx = start(NULL, -1);
    char err[256];
    ts_client *c = ts_client_connect(fx->addr, NULL, 2000, err, sizeof err);
    assert_non_null(c);
    exercise(c);

    blocked b = {fx->addr, -1, 0};
    pthread_t th;
    pthread_create(&th, NULL, blocked_in, &b);
    usleep(100000); /* let the in block */
    int takes = counter(fx, &fx->takes);
    tf_tuple t;
    tup(&t, "si", "wake", 42);
    assert_int_equal(ts_out(c, &t), 0);
    tf_tuple_clear(&t);
    pthread_join(th, NULL);
    assert_int_equal(b.rc, 0);
    assert_int_equal(b.value, 42);
    assert_int_equal(counter(fx, &fx->takes), takes + 1);
    assert_true(wait_counter(fx, &fx->disconnects, 1)); /* the thread's client closed */
    ts_client_close(c);
    assert_true(wait_counter(fx, &fx->disconnects, 2));
    stop(fx);
}

static int raw_connect(fixture *fx)
{
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    struct sockaddr_in sa = {.sin_family = AF_INET, .sin_port = htons((uint16_t)ts_server_port(fx->srv))};
    sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    assert_int_equal(connect(fd, (struct sockaddr *)&sa, sizeof sa), 0);
    return fd;
}

/* 1 if the server closed fd within 2 s (reads until EOF, skipping HELLO/ERROR bytes). */
static int closed_by_server(int fd)
{
    char buf[4096];
    for (int i = 0; i < 200; i++) {
        struct pollfd p = {.fd = fd, .events = POLLIN};
        if (poll(&p, 1, 10) > 0) {
            ssize_t n = recv(fd, buf, sizeof buf, 0);
            if (n <= 0)
                return 1;
        }
    }
    return 0;
}

/* ("big", id, blob) of n bytes, byte k = k * 31 + id. */
static void big_tuple(tf_tuple *t, int64_t id, size_t n)
{
    uint8_t *blob = malloc(n);
    for (size_t k = 0; k < n; k++)
        blob[k] = (uint8_t)(k * 31 + (size_t)id);
    tf_tuple_init(t);
    assert_int_equal(tf_tuple_pack(t, "sib", "big", id, blob, n), 0);
    free(blob);
}

static uint64_t blob_sum(const tf_tuple *t)
{
    uint64_t sum = 0;
    for (uint32_t k = 0; k < t->f[2].v.bytes.len; k++)
        sum += t->f[2].v.bytes.ptr[k];
    return sum;
}

typedef struct big_waiter {
    const char *addr;
    const uint8_t *key;
    tf_tuple got;
    int rc;
} big_waiter;

static void *take_big(void *arg)
{
    big_waiter *w = arg;
    char err[256];
    ts_client *c = ts_client_connect(w->addr, w->key, 5000, err, sizeof err);
    w->rc = -1;
    if (!c)
        return NULL;
    tf_tuple m;
    tf_tuple_init(&m);
    tf_tuple_pack(&m, "sIB", "big");
    w->rc = ts_in(c, &m, &w->got);
    tf_tuple_clear(&m);
    ts_client_close(c);
    return NULL;
}

/* Large OUTs arrive whole and equal, over a plain and a sealed connection: one of 3 MB handed
 * straight to a waiting taker (the stored tuple is freed at once, while on_out still reads the
 * frame's view), one stored and taken later, one followed in the same write by an IN (the
 * connection's buffer holds the end of one frame and the start of the next), and one smaller
 * than the buffer a connection keeps between frames (256 KB). */
static void check_large_outs(fixture *fx, ts_client *c, const uint8_t *key)
{
    big_waiter w = {.addr = fx->addr, .key = key};
    pthread_t th;
    pthread_create(&th, NULL, take_big, &w);
    ts_space_stats st;
    for (int i = 0; i < 3000; i++) { /* the waiter is blocked in the space before the out */
        ts_space_get_stats(fx->space, &st);
        if (st.waiters == 1)
            break;
        usleep(10000);
    }
    assert_int_equal(st.waiters, 1);
    tf_tuple t1, t2, t3, t4, m, got;
    big_tuple(&t1, 1, 3u << 20);
    big_tuple(&t2, 2, 256 * 1024 + 1);
    big_tuple(&t3, 3, 700 * 1024);
    big_tuple(&t4, 4, 200 * 1024);
    int outs = counter(fx, &fx->outs);
    pthread_mutex_lock(&fx->lock);
    uint64_t sum0 = fx->blob_sum;
    pthread_mutex_unlock(&fx->lock);
    assert_int_equal(ts_out(c, &t1), 0);
    pthread_join(th, NULL);
    assert_int_equal(w.rc, 0);
    assert_true(tf_tuple_equal(&t1, &w.got));
    assert_int_equal(ts_out(c, &t2), 0);
    tf_tuple_init(&m);
    tf_tuple_pack(&m, "siB", "big", (int64_t)3);
    assert_int_equal(ts_out_in(c, &t3, &m, &got), 0); /* a large out, then an in, one write */
    assert_true(tf_tuple_equal(&t3, &got));
    tf_tuple_clear(&got);
    tf_tuple_clear(&m);
    tf_tuple_init(&m);
    tf_tuple_pack(&m, "sIB", "big");
    assert_int_equal(ts_inp(c, &m, &got), 1);
    assert_true(tf_tuple_equal(&t2, &got));
    tf_tuple_clear(&got);
    assert_int_equal(ts_out(c, &t4), 0);
    assert_int_equal(ts_inp(c, &m, &got), 1);
    assert_true(tf_tuple_equal(&t4, &got));
    tf_tuple_clear(&got);
    tf_tuple_clear(&m);
    assert_int_equal(counter(fx, &fx->outs), outs + 4);
    pthread_mutex_lock(&fx->lock);
    assert_true(fx->blob_sum - sum0 ==
                blob_sum(&t1) + blob_sum(&t2) + blob_sum(&t3) + blob_sum(&t4));
    pthread_mutex_unlock(&fx->lock);
    exercise(c); /* the stream is still in step */
    tf_tuple_clear(&w.got);
    tf_tuple_clear(&t1);
    tf_tuple_clear(&t2);
    tf_tuple_clear(&t3);
    tf_tuple_clear(&t4);
}

static void test_large_outs(void **state)
{
    (void)state;
    int sv[2];
    assert_int_equal(socketpair(AF_UNIX, SOCK_STREAM, 0, sv), 0);
    fixture *fx = start(NULL, sv[0]);
    ts_client *c = ts_client_from_fd(sv[1]);
    check_large_outs(fx, c, NULL);
    ts_client_close(c);
    stop(fx);

    uint8_t key[TF_KEY_BYTES];
    tf_secret_from_bytes("large and sealed", 16, key);
    fx = start(key, -1);
    char err[256];
    c = ts_client_connect(fx->addr, key, 2000, err, sizeof err);
    assert_non_null(c);
    check_large_outs(fx, c, key);
    ts_client_close(c);
    stop(fx);
}

/* A result-sized OUT is stored without a copy: its blob stays in the buffer the server read it
 * into (tf_tuple_decode_shared), and the hook's view of it stays valid after the hook took the
 * stored tuple out and freed it (make asan: no use after free).  A small one is copied. */
static void test_large_out_stored_in_its_receive_buffer(void **state)
{
    (void)state;
    int sv[2];
    assert_int_equal(socketpair(AF_UNIX, SOCK_STREAM, 0, sv), 0);
    fixture *fx = start(NULL, sv[0]);
    ts_client *c = ts_client_from_fd(sv[1]);
    tf_tuple big, small;
    uint8_t *blob = malloc(300 * 1024);
    for (size_t k = 0; k < 300 * 1024; k++)
        blob[k] = (uint8_t)(k * 7 + 1);
    tf_tuple_init(&big);
    tf_tuple_init(&small);
    assert_int_equal(tf_tuple_pack(&big, "sib", "grab", (int64_t)1, blob, (size_t)300 * 1024), 0);
    assert_int_equal(tf_tuple_pack(&small, "sib", "grab", (int64_t)2, blob, (size_t)100), 0);
    free(blob);
    pthread_mutex_lock(&fx->lock);
    uint64_t sum0 = fx->blob_sum;
    pthread_mutex_unlock(&fx->lock);
    assert_int_equal(ts_out(c, &big), 0); /* the OK comes after the hook ran */
    assert_int_equal(ts_out(c, &small), 0);
    pthread_mutex_lock(&fx->lock);
    uint64_t seen = fx->blob_sum - sum0;
    pthread_mutex_unlock(&fx->lock);
    uint64_t want = 0;
    for (uint32_t k = 0; k < big.f[2].v.bytes.len; k++)
        want += big.f[2].v.bytes.ptr[k];
    for (uint32_t k = 0; k < small.f[2].v.bytes.len; k++)
        want += small.f[2].v.bytes.ptr[k];
    assert_true(seen == want);
    pthread_mutex_lock(&fx->lock);
    assert_int_equal(fx->grabbed, 2);
    assert_int_equal(fx->grabbed_shared, 1);
    pthread_mutex_unlock(&fx->lock);
    exercise(c); /* the stream is still in step */
    ts_client_close(c);
    stop(fx);
    tf_tuple_clear(&big);
    tf_tuple_clear(&small);
}

/* A forked worker's connection: a socketpair whose server end (added to fx, not yet launched)
 * has an outbox when with_outbox; *ob gets it (the server's reference), or NULL.  Returns the
 * worker's end. */
static int worker_conn(fixture *fx, int with_outbox, tf_outbox **ob)
{
    int sv[2];
    assert_int_equal(socketpair(AF_UNIX, SOCK_STREAM, 0, sv), 0);
    uint64_t id = ts_server_add_fd(fx->srv, sv[0], "worker");
    assert_true(id > 0);
    *ob = NULL;
    if (with_outbox) {
        char err[160];
        *ob = tf_outbox_create(err, sizeof err);
        assert_non_null(*ob);
        assert_int_equal(ts_server_adopt_outbox(fx->srv, id, *ob), 0);
    }
    return sv[1];
}

/* The state word of the outbox's first record: 1 while the coordinator holds it, 0 once free. */
static uint32_t first_record_state(const tf_outbox *ob)
{
    return __atomic_load_n((const uint32_t *)(const void *)tf_outbox_base(ob), __ATOMIC_ACQUIRE);
}

/* The forked worker of test_results_kept_in_the_outbox: two large outs, then (once told) a
 * third; its exit status says whether each was answered. */
static int outbox_child(int fd, tf_outbox *ob)
{
    ts_client *c = ts_client_from_fd(fd);
    ts_client_adopt_outbox(c, ob);
    tf_tuple t, m, got;
    int bad = 0;
    for (int64_t id = 1; id <= 2; id++) {
        big_tuple(&t, id, 100 * 1024);
        bad |= ts_out(c, &t) != 0;
        tf_tuple_clear(&t);
    }
    tf_tuple_init(&m);
    tf_tuple_pack(&m, "s", "go");
    bad |= ts_in(c, &m, &got) != 0;
    tf_tuple_clear(&got);
    tf_tuple_clear(&m);
    big_tuple(&t, 3, 50 * 1024);
    bad |= ts_out(c, &t) != 0;
    tf_tuple_clear(&t);
    ts_client_close(c);
    return bad;
}

/* Take ("big", id, ?B) over c: it must equal big_tuple(id, n). */
static void take_big_equal(ts_client *c, int64_t id, size_t n)
{
    tf_tuple want, m, got;
    big_tuple(&want, id, n);
    tf_tuple_init(&m);
    tf_tuple_pack(&m, "siB", "big", id);
    assert_int_equal(ts_inp(c, &m, &got), 1);
    assert_true(tf_tuple_equal(&want, &got));
    tf_tuple_clear(&got);
    tf_tuple_clear(&m);
    tf_tuple_clear(&want);
}

/* A real forked worker's large outs are stored where it encoded them, in its outbox: the first
 * record stays held while its tuple is stored and is freed once the tuple is taken; with both
 * taken, the worker's next out reuses the ring's start; every tuple arrives equal. */
static void test_results_kept_in_the_outbox(void **state)
{
    (void)state;
    fixture *fx = setup(NULL);
    tf_outbox *ob;
    int fd = worker_conn(fx, 1, &ob);
    pid_t pid = fork(); /* before the server thread starts: the child runs one thread */
    assert_true(pid >= 0);
    if (pid == 0) {
        prctl(PR_SET_PDEATHSIG, SIGKILL); /* a failed test must not leave it waiting */
        _exit(outbox_child(fd, ob));
    }
    close(fd);
    launch(fx);
    char err[256];
    ts_client *c = ts_client_connect(fx->addr, NULL, 2000, err, sizeof err);
    assert_non_null(c);
    tf_tuple m, got; /* the worker's outs are answered in order: with the second, both are in */
    tf_tuple_init(&m);
    tf_tuple_pack(&m, "siB", "big", (int64_t)2);
    assert_int_equal(ts_rd(c, &m, &got), 0);
    tf_tuple_clear(&got);
    tf_tuple_clear(&m);
    assert_int_equal(first_record_state(ob), 1);
    take_big_equal(c, 1, 100 * 1024);
    assert_int_equal(first_record_state(ob), 0);
    take_big_equal(c, 2, 100 * 1024);
    tf_tuple go;
    tup(&go, "s", "go", 0);
    assert_int_equal(ts_out(c, &go), 0);
    tf_tuple_clear(&go);
    int status;
    assert_int_equal(waitpid(pid, &status, 0), pid);
    assert_true(WIFEXITED(status) && WEXITSTATUS(status) == 0);
    tf_tuple third;
    big_tuple(&third, 3, 50 * 1024);
    size_t n = tf_tuple_encoded_size(&third);
    uint8_t *enc = malloc(n);
    tf_tuple_encode(&third, enc);
    assert_memory_equal(tf_outbox_base(ob) + TF_OUTBOX_HEADER, enc, n); /* the ring's start */
    assert_int_equal(first_record_state(ob), 1);
    free(enc);
    tf_tuple_clear(&third);
    take_big_equal(c, 3, 50 * 1024);
    exercise(c);
    ts_client_close(c);
    stop(fx);
}

/* An OUT_SHARED frame (request 1) naming a payload at off of len bytes; only `body` bytes of
 * its 8-byte body are sent. */
static void send_out_shared(int fd, uint32_t off, uint32_t len, int body)
{
    uint8_t f[TF_FRAME_HEADER + 8] = {(uint8_t)(TF_FRAME_MIN_LENGTH + body), 0, 0, 0,
                                      TF_PROTO_VERSION, TF_OP_OUT_SHARED, 1, 0, 0, 0};
    for (int i = 0; i < 4; i++) {
        f[TF_FRAME_HEADER + i] = (uint8_t)(off >> (8 * i));
        f[TF_FRAME_HEADER + 4 + i] = (uint8_t)(len >> (8 * i));
    }
    size_t n = TF_FRAME_HEADER + (size_t)body;
    assert_int_equal(send(fd, f, n, MSG_NOSIGNAL), (ssize_t)n);
}

/* Workers that speak OUT_SHARED and lie: each lie drops its own connection, and only that one;
 * the same frame telling the truth is stored (the control). */
static void test_out_shared_lies_drop_only_their_connection(void **state)
{
    (void)state;
    enum { TRUTH, SHORT_BODY, PAST_END, EMPTY, ON_HEADER, UNALIGNED, GARBAGE, FORMAL,
           NO_OUTBOX, NCASES };
    fixture *fx = setup(NULL);
    int fd[NCASES];
    tf_outbox *ob[NCASES];
    for (int i = 0; i < NCASES; i++)
        fd[i] = worker_conn(fx, i != NO_OUTBOX, &ob[i]);
    launch(fx);
    char err[256];
    ts_client *good = ts_client_connect(fx->addr, NULL, 2000, err, sizeof err);
    assert_non_null(good);
    tf_tuple t, formal;
    big_tuple(&t, 5, 40 * 1024);
    tf_tuple_init(&formal);
    assert_int_equal(tf_tuple_pack(&formal, "sI", "big"), 0);
    uint32_t at = TF_OUTBOX_HEADER, n = (uint32_t)tf_tuple_encoded_size(&t);
    uint32_t size = (uint32_t)TF_OUTBOX_BYTES;
    for (int i = 0; i < NCASES; i++) {
        uint8_t *base = ob[i] ? tf_outbox_base(ob[i]) : NULL;
        if (base)
            tf_tuple_encode(&t, base + at);
        int before = counter(fx, &fx->disconnects);
        switch (i) {
        case TRUTH: send_out_shared(fd[i], at, n, 8); break;
        case SHORT_BODY: send_out_shared(fd[i], at, n, 7); break;
        case PAST_END: send_out_shared(fd[i], at, size - at + 1, 8); break;
        case EMPTY: send_out_shared(fd[i], at, 0, 8); break;
        case ON_HEADER: send_out_shared(fd[i], 0, n, 8); break;
        case UNALIGNED: send_out_shared(fd[i], at + 1, n, 8); break;
        case GARBAGE:
            memset(base + at, 0xff, 64);
            send_out_shared(fd[i], at, 64, 8);
            break;
        case FORMAL:
            tf_tuple_encode(&formal, base + at);
            send_out_shared(fd[i], at, (uint32_t)tf_tuple_encoded_size(&formal), 8);
            break;
        case NO_OUTBOX: send_out_shared(fd[i], at, n, 8); break;
        }
        if (i == TRUTH) {
            uint8_t buf[256];
            size_t have = 0;
            tf_frame f;
            assert_true(read_raw_frame(fd[i], buf, sizeof buf, &have, &f) > 0);
            assert_int_equal(f.op, TF_OP_OK);
            take_big_equal(good, 5, 40 * 1024);
        } else {
            assert_true(closed_by_server(fd[i]));
            assert_true(wait_counter(fx, &fx->disconnects, before + 1));
        }
        exercise(good); /* the other client is undisturbed */
    }
    assert_int_equal(counter(fx, &fx->disconnects), NCASES - 1);
    for (int i = 0; i < NCASES; i++)
        close(fd[i]);
    tf_tuple_clear(&t);
    tf_tuple_clear(&formal);
    ts_client_close(good);
    stop(fx);
}

static void test_bad_traffic_drops_only_that_connection(void **state)
{
    (void)state;
    fixture *fx = start(NULL, -1);
    char err[256];
    ts_client *good = ts_client_connect(fx->addr, NULL, 2000, err, sizeof err);
    assert_non_null(good);
    const uint8_t garbage[] = "GET / HTTP/1.0\r\n\r\n";
    const uint8_t oversized[] = {0xff, 0xff, 0xff, 0x7f, 1, 1};
    const uint8_t unknown_op[] = {6, 0, 0, 0, 1, 200, 1, 0, 0, 0};
    const uint8_t half[] = {20, 0, 0, 0, 1, TF_OP_OUT, 1, 0, 0, 0, 1};
    const uint8_t bad_body[] = {8, 0, 0, 0, 1, TF_OP_OUT, 1, 0, 0, 0, 5, 1};
    struct { const uint8_t *p; size_t n; int then_close; } cases[] = {
        {garbage, sizeof garbage, 0}, {oversized, sizeof oversized, 0},
        {unknown_op, sizeof unknown_op, 0}, {half, sizeof half, 1},
        {bad_body, sizeof bad_body, 0},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        int before = counter(fx, &fx->disconnects);
        int fd = raw_connect(fx);
        assert_int_equal(send(fd, cases[i].p, cases[i].n, MSG_NOSIGNAL), (ssize_t)cases[i].n);
        if (cases[i].then_close)
            close(fd);
        else {
            assert_true(closed_by_server(fd));
            close(fd);
        }
        assert_true(wait_counter(fx, &fx->disconnects, before + 1));
        exercise(good); /* the other client is undisturbed */
    }
    ts_client_close(good);
    stop(fx);
}

static void test_auth(void **state)
{
    (void)state;
    uint8_t key[TF_KEY_BYTES], wrong[TF_KEY_BYTES];
    tf_secret_from_bytes("correct horse", 13, key);
    tf_secret_from_bytes("battery staple", 14, wrong);
    fixture *fx = start(key, -1);
    char err[256];
    ts_client *good = ts_client_connect(fx->addr, key, 2000, err, sizeof err);
    assert_non_null(good);
    exercise(good);

    /* capture stderr to check the log line */
    char path[] = "/tmp/tf-auth-log.XXXXXX";
    int logfd = mkstemp(path);
    int saved = dup(2);
    dup2(logfd, 2);
    ts_client *bad = ts_client_connect(fx->addr, wrong, 2000, err, sizeof err);
    ts_client *none = ts_client_connect(fx->addr, NULL, 2000, err + 128, sizeof err - 128);
    int fd = raw_connect(fx); /* an op before the handshake */
    tf_buf b;
    tf_buf_init(&b);
    tf_frame_append_tuple(&b, TF_OP_OUT, 1, NULL);
    send(fd, tf_buf_head(&b), b.len, MSG_NOSIGNAL);
    tf_buf_free(&b);
    int was_closed = closed_by_server(fd);
    close(fd);
    usleep(50000);
    dup2(saved, 2);
    close(saved);
    assert_null(bad);
    assert_non_null(strstr(err, "authentication failed"));
    assert_null(none);
    assert_non_null(strstr(err + 128, "requires a secret"));
    assert_true(was_closed);
    char log[4096] = {0};
    pread(logfd, log, sizeof log - 1, 0);
    close(logfd);
    unlink(path);
    assert_non_null(strstr(log, "authentication failed from 127.0.0.1:"));
    assert_non_null(strstr(log, "unauthenticated OUT"));

    exercise(good); /* undisturbed */
    ts_client_close(good);

    /* a client with a key refuses a server that does not authenticate */
    fixture *open_fx = start(NULL, -1);
    assert_null(ts_client_connect(open_fx->addr, key, 2000, err, sizeof err));
    assert_non_null(strstr(err, "does not authenticate"));
    stop(open_fx);
    stop(fx);
}

/* A wrong-secret handshake: how long its answer took (ms); it must be "authentication failed". */
static int64_t wrong_guess_ms(fixture *fx, const uint8_t *wrong)
{
    char err[256];
    int64_t t0 = tf_now_ms();
    ts_client *bad = ts_client_connect(fx->addr, wrong, 5000, err, sizeof err);
    assert_null(bad);
    assert_non_null(strstr(err, "authentication failed"));
    return tf_now_ms() - t0;
}

/* Failed handshakes from 127.0.0.1: the first three answered at once, the next ones held
 * (250 ms, 500 ms ...); meanwhile the right secret from the same address is admitted at once. */
static void test_guesses_slowed_right_secret_admitted(void **state)
{
    (void)state;
    uint8_t key[TF_KEY_BYTES], wrong[TF_KEY_BYTES];
    tf_secret_from_bytes("correct horse", 13, key);
    tf_secret_from_bytes("battery staple", 14, wrong);
    fixture *fx = start(key, -1);
    int saved = dup(2), devnull = open("/dev/null", O_WRONLY);
    dup2(devnull, 2); /* the warnings */
    for (int i = 0; i < 3; i++)
        wrong_guess_ms(fx, wrong);
    int64_t held = wrong_guess_ms(fx, wrong);
    char err[256];
    ts_client *good = ts_client_connect(fx->addr, key, 2000, err, sizeof err);
    int64_t held2 = wrong_guess_ms(fx, wrong);
    dup2(saved, 2);
    close(saved);
    close(devnull);
    assert_true(held >= 200);
    assert_true(held2 >= 400);
    assert_non_null(good);
    exercise(good);
    ts_client_close(good);
    stop(fx);
}

static void test_silence_timeout_and_heartbeat(void **state)
{
    (void)state;
    fixture *fx = calloc(1, sizeof *fx);
    pthread_mutex_init(&fx->lock, NULL);
    fx->space = ts_space_new();
    ts_server_config cfg = {.listen = "127.0.0.1:0", .silence_timeout_ms = 300};
    ts_server_hooks hooks = {fx, on_take, on_out, on_disconnect};
    char err[256];
    fx->srv = ts_server_new(fx->space, &cfg, &hooks, err, sizeof err);
    snprintf(fx->addr, sizeof fx->addr, "127.0.0.1:%d", ts_server_port(fx->srv));
    pthread_create(&fx->thread, NULL, server_main, fx);
    ts_client *beating = ts_client_connect(fx->addr, NULL, 2000, err, sizeof err);
    ts_client *silent = ts_client_connect(fx->addr, NULL, 2000, err, sizeof err);
    assert_non_null(beating);
    assert_non_null(silent);
    assert_int_equal(ts_client_heartbeat(beating, 50), 0);
    int saved = dup(2), devnull = open("/dev/null", O_WRONLY);
    dup2(devnull, 2);
    usleep(700000);
    dup2(saved, 2);
    close(saved);
    close(devnull);
    assert_int_equal(counter(fx, &fx->disconnects), 1); /* only the silent one */
    assert_int_equal(ts_ping(beating), 0);
    assert_int_equal(ts_ping(silent), -1);
    assert_true(strlen(ts_client_error(silent)) > 0);
    ts_client_close(beating);
    ts_client_close(silent);
    stop(fx);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_socketpair_client),
        cmocka_unit_test(test_out_in_one_round_trip),
        cmocka_unit_test(test_pipelined_behind_blocked_in),
        cmocka_unit_test(test_exchange_in_halves),
        cmocka_unit_test(test_large_outs),
        cmocka_unit_test(test_large_out_stored_in_its_receive_buffer),
        cmocka_unit_test(test_results_kept_in_the_outbox),
        cmocka_unit_test(test_out_shared_lies_drop_only_their_connection),
        cmocka_unit_test(test_tcp_blocked_in_woken_by_other_client),
        cmocka_unit_test(test_bad_traffic_drops_only_that_connection),
        cmocka_unit_test(test_auth),
        cmocka_unit_test(test_guesses_slowed_right_secret_admitted),
        cmocka_unit_test(test_silence_timeout_and_heartbeat),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
