/* drainage.c: pits and basins of a height field (drainage.h). */
#include "terrain/drainage.h"

#include <stdlib.h>

static const int DI[8] = {-1, 0, 1, -1, 1, -1, 0, 1};
static const int DJ[8] = {-1, -1, -1, 0, 0, 1, 1, 1};

/* The steepest downhill neighbour of (i, j) (drop per distance), or -1: a pit or an edge. */
static int64_t downhill(const float *h, int n, int i, int j)
{
    if (i == 0 || j == 0 || i == n - 1 || j == n - 1)
        return -1;
    double best = 0.0;
    int64_t to = -1;
    float here = h[(int64_t)j * n + i];
    for (int k = 0; k < 8; k++) {
        int64_t v = (int64_t)(j + DJ[k]) * n + (i + DI[k]);
        double drop = (double)here - h[v];
        if (DI[k] && DJ[k])
            drop *= 0.70710678118654752; /* diagonal: per unit distance */
        if (drop > best) {
            best = drop;
            to = v;
        }
    }
    return to;
}

/* The end of v's path (memoised in end[]; -2 = unknown), iteratively. */
static int64_t path_end(const int64_t *next, int64_t *end, int64_t v, int64_t *stack)
{
    int64_t top = 0;
    while (end[v] == -2 && next[v] >= 0) {
        stack[top++] = v;
        v = next[v];
    }
    int64_t e = end[v] == -2 ? v : end[v];
    end[v] = e;
    while (top > 0)
        end[stack[--top]] = e;
    return e;
}

int tf_drainage_measure(const float *h, int n, tf_drainage *out)
{
    int64_t count = (int64_t)n * n;
    int64_t *next = malloc((size_t)count * sizeof *next);
    int64_t *end = malloc((size_t)count * sizeof *end);
    int64_t *stack = malloc((size_t)count * sizeof *stack);
    int64_t *size = calloc((size_t)count, sizeof *size);
    if (!next || !end || !stack || !size) {
        free(next), free(end), free(stack), free(size);
        return -1;
    }
    out->pits = 0;
    for (int j = 0; j < n; j++)
        for (int i = 0; i < n; i++) {
            int64_t v = (int64_t)j * n + i;
            next[v] = downhill(h, n, i, j);
            end[v] = -2;
            int inner = i > 0 && j > 0 && i < n - 1 && j < n - 1;
            out->pits += inner && next[v] < 0;
        }
    int64_t largest = 0;
    for (int64_t v = 0; v < count; v++) {
        int64_t e = path_end(next, end, v, stack);
        if (++size[e] > largest)
            largest = size[e];
    }
    out->largest_basin_share = (double)largest / (double)count;
    free(next), free(end), free(stack), free(size);
    return 0;
}
