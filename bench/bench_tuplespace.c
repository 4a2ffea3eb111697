/* bench_tuplespace.c: task-queue throughput and latency of the tuple space over loopback TCP,
 * and (with --redis PORT) of the same work done with Redis LPUSH/BRPOP over plain RESP, so
 * bench/tuplespace_vs_redis.sh can print the two side by side.
 *
 * One producer thread puts T tasks ("task", i, t_sent_ns); N consumer threads take them with
 * in("task", ?int, ?int) (or BRPOP) until a poison task (i = -1).  Reported: tasks per second
 * (each task is one out round trip + one in round trip) and the out->in latency per task
 * (median, p99), measured with CLOCK_MONOTONIC in one process.
 * With --sealed the same run is done twice, in clear and then with a secret (the HMAC handshake
 * and sealed records of linda/seal.h on every connection), and a third line gives the ratio:
 * the cost of encryption in tasks/s, measured against the clear baseline of the same run.
 * Usage: bench_tuplespace [-n CONSUMERS] [-t TASKS] [--redis PORT | --sealed] [--smoke]
 * (--smoke: 2 consumers, 200 tasks, for tests/e2e/bench_smoke.sh; -n and -t after it win.)
 * Output: one line "system=... consumers=N tasks=T ops_per_s=X median_us=Y p99_us=Z" per run. */
#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "bench/bench_cpu.h"
#include "linda/tsserver.h"
#include "log.h"
#include "linda/tsclient.h"

static int consumers = 4, tasks = 20000, redis_port = 0, sealed_compare = 0;
static const uint8_t *client_key; /* NULL: in clear */
static char ts_addr[64];
static double *latency_us; /* one per task, written by the consumer that took it */

static int64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

/* ---- tuple space ---- */
static volatile int server_stop;
static void *server_main(void *arg)
{
    while (!server_stop)
        ts_server_run_once(arg, 50);
    return NULL;
}

static ts_client *ts_connect(void)
{
    char err[256];
    ts_client *c = ts_client_connect(ts_addr, client_key, 5000, err, sizeof err);
    if (!c)
        tf_die(1, "%s", err);
    return c;
}

static void ts_put(ts_client *c, int64_t i)
{
    tf_tuple t;
    tf_tuple_init(&t);
    tf_tuple_pack(&t, "sii", "task", i, (int64_t)now_ns());
    if (ts_out(c, &t) != 0)
        tf_die(1, "out: %s", ts_client_error(c));
    tf_tuple_clear(&t);
}

static void *ts_consumer(void *arg)
{
    (void)arg;
    ts_client *c = ts_connect();
    tf_tuple m, got;
    tf_tuple_init(&m);
    tf_tuple_pack(&m, "sII", "task");
    for (;;) {
        if (ts_in(c, &m, &got) != 0)
            tf_die(1, "in: %s", ts_client_error(c));
        int64_t i, sent;
        tf_tuple_get_int(&got, 1, &i);
        tf_tuple_get_int(&got, 2, &sent);
        tf_tuple_clear(&got);
        if (i < 0)
            break;
        latency_us[i] = (double)(now_ns() - sent) / 1000.0;
    }
    tf_tuple_clear(&m);
    ts_client_close(c);
    return NULL;
}

static void *ts_producer(void *arg)
{
    (void)arg;
    ts_client *c = ts_connect();
    for (int i = 0; i < tasks; i++)
        ts_put(c, i);
    for (int i = 0; i < consumers; i++)
        ts_put(c, -1);
    ts_client_close(c);
    return NULL;
}

/* ---- Redis over RESP ---- */
typedef struct resp {
    int fd;
    char buf[4096];
    size_t len;
} resp;

static resp *resp_connect(void)
{
    resp *r = calloc(1, sizeof *r);
    r->fd = socket(AF_INET, SOCK_STREAM, 0);
    struct sockaddr_in sa = {.sin_family = AF_INET, .sin_port = htons((uint16_t)redis_port)};
    sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (connect(r->fd, (struct sockaddr *)&sa, sizeof sa) != 0)
        tf_die(1, "cannot connect to redis on port %d", redis_port);
    int one = 1;
    setsockopt(r->fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    return r;
}

static void resp_send(resp *r, int argc, const char **argv)
{
    char out[512];
    int n = snprintf(out, sizeof out, "*%d\r\n", argc);
    for (int i = 0; i < argc; i++)
        n += snprintf(out + n, sizeof out - (size_t)n, "$%zu\r\n%s\r\n", strlen(argv[i]), argv[i]);
    if (write(r->fd, out, (size_t)n) != n)
        tf_die(1, "redis write failed");
}

/* Read one reply; for BRPOP's array reply, returns the last bulk string in val. */
static void resp_read(resp *r, char *val, size_t vlen)
{
    /* Replies here are small (":N", or a 2-element array of short bulks): read until the
     * expected number of lines is complete. */
    for (;;) {
        int lines = 0;
        for (size_t i = 0; i + 1 < r->len; i++)
            if (r->buf[i] == '\r' && r->buf[i + 1] == '\n')
                lines++;
        int need = r->len && r->buf[0] == '*' ? 5 : 1;
        if (lines >= need) {
            if (need == 5 && val) {
                char *p = r->buf;
                for (int k = 0; k < 4; k++)
                    p = strstr(p, "\r\n") + 2;
                char *e = strstr(p, "\r\n");
                snprintf(val, vlen, "%.*s", (int)(e - p), p);
            }
            char *p = r->buf;
            for (int k = 0; k < need; k++)
                p = strstr(p, "\r\n") + 2;
            r->len -= (size_t)(p - r->buf);
            memmove(r->buf, p, r->len);
            return;
        }
        ssize_t n = read(r->fd, r->buf + r->len, sizeof r->buf - r->len);
        if (n <= 0)
            tf_die(1, "redis read failed");
        r->len += (size_t)n;
    }
}

static void *redis_consumer(void *arg)
{
    (void)arg;
    resp *r = resp_connect();
    const char *argv[] = {"BRPOP", "tfq", "0"};
    for (;;) {
        char val[64];
        resp_send(r, 3, argv);
        resp_read(r, val, sizeof val);
        long long i, sent;
        if (sscanf(val, "%lld:%lld", &i, &sent) != 2)
            tf_die(1, "bad redis value %s", val);
        if (i < 0)
            break;
        latency_us[i] = (double)(now_ns() - sent) / 1000.0;
    }
    close(r->fd);
    free(r);
    return NULL;
}

static void redis_put(resp *r, long long i)
{
    char val[64];
    snprintf(val, sizeof val, "%lld:%lld", i, (long long)now_ns());
    const char *argv[] = {"LPUSH", "tfq", val};
    resp_send(r, 3, argv);
    resp_read(r, NULL, 0);
}

static void *redis_producer(void *arg)
{
    (void)arg;
    resp *r = resp_connect();
    for (int i = 0; i < tasks; i++)
        redis_put(r, i);
    for (int i = 0; i < consumers; i++)
        redis_put(r, -1);
    close(r->fd);
    free(r);
    return NULL;
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

typedef struct run_result {
    double ops_per_s, median_us, p99_us;
} run_result;

/* One run of the producer and consumers; key: the server's secret key, or NULL. */
static run_result run(const uint8_t *key)
{
    ts_space *space = NULL;
    ts_server *srv = NULL;
    pthread_t server_thread;
    client_key = key;
    if (!redis_port) {
        char err[256];
        space = ts_space_new();
        ts_server_config cfg = {.listen = "127.0.0.1:0", .key = key};
        srv = ts_server_new(space, &cfg, NULL, err, sizeof err);
        if (!srv)
            tf_die(1, "%s", err);
        snprintf(ts_addr, sizeof ts_addr, "127.0.0.1:%d", ts_server_port(srv));
        pthread_create(&server_thread, NULL, server_main, srv);
    }
    pthread_t th[257];
    memset(latency_us, 0, (size_t)tasks * sizeof *latency_us);
    int64_t t0 = now_ns();
    for (int i = 0; i < consumers; i++)
        pthread_create(&th[i], NULL, redis_port ? redis_consumer : ts_consumer, NULL);
    pthread_create(&th[consumers], NULL, redis_port ? redis_producer : ts_producer, NULL);
    for (int i = 0; i <= consumers; i++)
        pthread_join(th[i], NULL);
    double secs = (double)(now_ns() - t0) / 1e9;
    qsort(latency_us, (size_t)tasks, sizeof *latency_us, cmp_double);
    run_result r = {tasks / secs, latency_us[tasks / 2], latency_us[(size_t)(tasks * 0.99)]};
    printf("system=%s consumers=%d tasks=%d ops_per_s=%.0f median_us=%.1f p99_us=%.1f\n",
           redis_port ? "redis" : key ? "tuplespace-sealed" : "tuplespace", consumers, tasks,
           r.ops_per_s, r.median_us, r.p99_us);
    if (srv) {
        server_stop = 1;
        pthread_join(server_thread, NULL);
        server_stop = 0;
        ts_server_free(srv);
        ts_space_free(space);
    }
    return r;
}

int main(int argc, char **argv)
{
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "-n") && i + 1 < argc)
            consumers = atoi(argv[++i]);
        else if (!strcmp(argv[i], "-t") && i + 1 < argc)
            tasks = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--redis") && i + 1 < argc)
            redis_port = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--smoke")) {
            consumers = 2;
            tasks = 200;
        } else if (!strcmp(argv[i], "--sealed"))
            sealed_compare = 1;
        else
            tf_die(2, "usage: bench_tuplespace [-n CONSUMERS] [-t TASKS] [--redis PORT | --sealed] [--smoke]");
    }
    if (consumers < 1 || consumers > 256 || tasks < 1 || tasks > 10000000)
        tf_die(2, "bad -n or -t");
    latency_us = calloc((size_t)tasks, sizeof *latency_us);
    char cpu[256];
    tf_bench_cpu_model(cpu, sizeof cpu);
    printf("cpu=%s\n", cpu);
    run_result clear = run(NULL);
    if (sealed_compare) {
        uint8_t key[TF_KEY_BYTES];
        tf_secret_from_bytes("bench_tuplespace secret, 32 bytes", 33, key);
        run_result sealed = run(key);
        printf("sealed/clear: ops_per_s %.3f, median latency %.3f, p99 latency %.3f\n",
               sealed.ops_per_s / clear.ops_per_s, sealed.median_us / clear.median_us,
               sealed.p99_us / clear.p99_us);
    }
    free(latency_us);
    return 0;
}
