/* erosion_tuples.c: the plan and the state blocks of an erosion on the farm (erosion_tuples.h). */
#include "erosion_tuples.h"

#include <math.h>
#include <string.h>

#include "log.h"

/* The factor pair px * py = w with px >= py as close to square as w allows. */
static void split(int w, int *px, int *py)
{
    int best = 1;
    for (int d = 1; d * d <= w; d++)
        if (w % d == 0)
            best = d;
    *py = best;
    *px = w / best;
}

int tf_erosion_plan_make(tf_erosion_plan *p, int64_t job, int n, int workers, int halo,
                         int steps)
{
    memset(p, 0, sizeof *p);
    if (workers < 1)
        workers = 1;
    split(workers, &p->px, &p->py);
    int smallest = (n / p->px < n / p->py) ? n / p->px : n / p->py;
    if (smallest < 2)
        return -1;
    p->job = job;
    p->n = n;
    p->halo = halo < 1 ? 1 : halo > smallest ? smallest : halo;
    p->steps = steps;
    return 0;
}

int tf_erosion_plan_rounds(const tf_erosion_plan *p)
{
    return (p->steps + p->halo - 1) / p->halo;
}

void tf_erosion_patch_rect(const tf_erosion_plan *p, int patch, int *i0, int *i1, int *j0,
                           int *j1)
{
    int pi = patch % p->px, pj = patch / p->px;
    *i0 = (int)((int64_t)pi * p->n / p->px);
    *i1 = (int)((int64_t)(pi + 1) * p->n / p->px);
    *j0 = (int)((int64_t)pj * p->n / p->py);
    *j1 = (int)((int64_t)(pj + 1) * p->n / p->py);
}

size_t tf_erosion_block_bytes(int rows, int cols)
{
    return (size_t)TF_EROSION_FIELDS * (size_t)rows * (size_t)cols * 4;
}

/* The six arrays of v, in block order. */
static void fields(const tf_erosion_view *v, void *out[TF_EROSION_FIELDS])
{
    out[0] = v->b;
    out[1] = v->t;
    out[2] = v->d;
    out[3] = v->w;
    out[4] = v->s;
    out[5] = v->flow;
}

void tf_erosion_block_pack(const tf_erosion_view *v, tf_erosion_rect r, uint8_t *data)
{
    void *f[TF_EROSION_FIELDS];
    fields(v, f);
    size_t row = (size_t)(r.c1 - r.c0) * 4;
    for (int k = 0; k < TF_EROSION_FIELDS; k++)
        for (int j = r.r0; j < r.r1; j++, data += row)
            memcpy(data, (uint8_t *)f[k] + ((size_t)j * v->stride + (size_t)r.c0) * 4, row);
}

void tf_erosion_block_unpack(tf_erosion_view *v, tf_erosion_rect r, const uint8_t *data)
{
    void *f[TF_EROSION_FIELDS];
    fields(v, f);
    size_t row = (size_t)(r.c1 - r.c0) * 4;
    for (int k = 0; k < TF_EROSION_FIELDS; k++)
        for (int j = r.r0; j < r.r1; j++, data += row)
            memcpy((uint8_t *)f[k] + ((size_t)j * v->stride + (size_t)r.c0) * 4, data, row);
}

/* Largest altitude a real state holds (erosion.h: 2^25 of range, deposits and water above). */
#define ALT_LIMIT (1 << 28)

int tf_erosion_block_check(const uint8_t *data, size_t len, int rows, int cols,
                           const char *from, char *err, size_t errlen)
{
    static const char *const names[TF_EROSION_FIELDS] = {"bedrock", "talus", "silt", "water",
                                                         "load", "flow"};
    if (len != tf_erosion_block_bytes(rows, cols))
        return tf_seterr(err, errlen, "%s: erosion block of %zu bytes, expected %zu (%dx%d)",
                         from, len, tf_erosion_block_bytes(rows, cols), cols, rows);
    size_t count = (size_t)rows * (size_t)cols;
    for (int k = 0; k < TF_EROSION_FIELDS; k++)
        for (size_t e = 0; e < count; e++) {
            int32_t i;
            float f;
            memcpy(&i, data + (k * count + e) * 4, 4);
            memcpy(&f, &i, 4);
            int bad = k == 0   ? (i <= -ALT_LIMIT || i >= ALT_LIMIT)
                      : k < 5 ? (i < 0 || i >= ALT_LIMIT)
                              : !(f >= 0.0f && f < 1e30f);
            if (bad)
                return tf_seterr(err, errlen, "%s: erosion block holds %s = %d at element %zu, "
                                 "which no erosion produces", from, names[k], (int)i, e);
        }
    return 0;
}

double tf_erosion_plan_edge_bytes(const tf_erosion_plan *p)
{
    double sum = 0;
    for (int id = 0; id < p->px * p->py; id++) {
        int i0, i1, j0, j1, pi = id % p->px, pj = id / p->px;
        tf_erosion_patch_rect(p, id, &i0, &i1, &j0, &j1);
        int rows = (pj > 0) + (pj < p->py - 1), cols = (pi > 0) + (pi < p->px - 1);
        sum += (double)tf_erosion_block_bytes(p->halo, i1 - i0) * rows +
               (double)tf_erosion_block_bytes(j1 - j0, p->halo) * cols;
    }
    return sum;
}
