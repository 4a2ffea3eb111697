/* gridgen.c: the deterministic parallel-for used by the grid generators (see gridgen.h).
 *
 * Threads are started per phase and joined before returning: a phase boundary is a full
 * barrier, which is exactly what level-by-level subdivision and pass-by-pass filtering need.
 * The split into ranges never influences results; see the contract in gridgen.h. */
#include "terrain/gridgen.h"

#include <pthread.h>

typedef struct {
    tf_grid_range_fn fn;
    void *ctx;
    int index, begin, end;
} grid_piece;

static void *grid_piece_run(void *arg)
{
    grid_piece *p = arg;
    p->fn(p->ctx, p->index, p->begin, p->end);
    return NULL;
}

int tf_grid_pieces(int count, int threads, int min_chunk)
{
    if (min_chunk < 1)
        min_chunk = 1;
    if (threads > TF_GRID_MAX_THREADS)
        threads = TF_GRID_MAX_THREADS;
    if (threads > count / min_chunk)
        threads = count / min_chunk;
    return threads < 1 ? 1 : threads;
}

void tf_grid_parallel(int count, int threads, int min_chunk, tf_grid_range_fn fn, void *ctx)
{
    if (count <= 0)
        return;
    threads = tf_grid_pieces(count, threads, min_chunk);
    if (threads == 1) {
        fn(ctx, 0, 0, count);
        return;
    }

    grid_piece piece[TF_GRID_MAX_THREADS];
    pthread_t tid[TF_GRID_MAX_THREADS];
    int started[TF_GRID_MAX_THREADS];
    for (int t = 0; t < threads; t++) {
        piece[t].fn = fn;
        piece[t].ctx = ctx;
        piece[t].index = t;
        piece[t].begin = (int)((long long)count * t / threads);
        piece[t].end = (int)((long long)count * (t + 1) / threads);
    }
    /* Piece 0 runs on the caller's thread; the others on new threads when possible. */
    for (int t = 1; t < threads; t++)
        started[t] = pthread_create(&tid[t], NULL, grid_piece_run, &piece[t]) == 0;
    grid_piece_run(&piece[0]);
    for (int t = 1; t < threads; t++) {
        if (started[t])
            pthread_join(tid[t], NULL);
        else
            grid_piece_run(&piece[t]);
    }
}
