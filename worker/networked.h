/* networked.h: the life of a networked worker (the tsnet model), `terrafarm worker`.
 *
 * Connect to the coordinator (waiting for it while it is not yet listening, up to a timeout),
 * read the scene from its tuple space, build the terrain once, then run N worker processes
 * that share it copy-on-write, each with its own connection and the worker loop of worker.h,
 * until the render is finished.  With a simulation model it joins as N synthetic workers
 * instead (simulate.h). */
#ifndef TF_NETWORKED_H
#define TF_NETWORKED_H

#include <stdint.h>
#include <stddef.h>

typedef struct tf_networked_opts {
    const char *connect;        /* HOST:PORT of the coordinator */
    const char *secret_file;    /* or NULL */
    int timeout_ms;             /* keep trying to reach the coordinator this long */
    int processes;              /* worker processes; 0 = online CPUs (16 threads simulated) */
    const char *backend;        /* "c" | "opencl" | "auto" */
    const char *simulate_model; /* cost map path: simulated workers; NULL: real ones */
    double pixel_us;            /* simulated cost of an average pixel */
    const char *payloads;       /* simulated workers send this recording's chunks (payloads.h) */
    size_t terrain_cache;       /* procedural terrain cache per process, bytes; 0 = default */
} tf_networked_opts;

/* Connect to a coordinator, retrying with backoff (250 ms doubling to 4 s) for at most
 * timeout_ms while it cannot be reached; a final refusal (a wrong secret, not a coordinator)
 * ends at once.  NULL with one line in err. */
struct ts_client;
struct ts_client *tf_networked_connect(const char *hostport, const uint8_t *key, int timeout_ms,
                                       char *err, size_t errlen);

/* Run until the render is finished.  Returns the process exit status (0, or 1 after one
 * line on stderr). */
int tf_networked_worker_run(const tf_networked_opts *o);

#endif
