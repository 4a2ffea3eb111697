/* fuzz_paint.c: libFuzzer harness for Raypaint's wire geometry (common/paintproto.c): the node
 * list a paint worker parses out of a task (tf_paint_nodes_get, from a coordinator it does not
 * have to trust) and the check the paint coordinator runs on a worker's values before it draws
 * anything (tf_paint_values_check, coordinator/paint/paint_role.c).
 *
 * Input: a 7-byte header, then the node blob, then the values:
 *   u16 width-1, u16 height-1 (little-endian, 1..65536), u8 aa_depth (its low 3 bits),
 *   u16 the node blob's length in bytes (cut to what the input holds)
 * Besides "no crash, leak or hang" it checks: a refused node list or set of values gets one
 * non-empty line; accepted nodes are each valid (tf_paint_node_problem), re-encode to the very
 * bytes they came from, and lay out lattices (tf_paint_axis) whose points are in order, start
 * at the node, end at its clipped edge and number what tf_paint_node_values says; accepted
 * values are each in the range paintproto.h promises for their field.  Seeds
 * (tests/corpus/paint/, made by tests/tools/fuzzseeds.c) are answers of the right length for a
 * few node lists, and refused_* ones (a NaN, an alpha of 2, a sample count no render makes, a
 * value short, a node of size 3, an unknown flag). */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "paintproto.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

#define HEADER 7

static int u16(const uint8_t *p) { return p[0] | p[1] << 8; }

/* Only a one-line, non-empty reason may explain a refusal. */
static void check_reason(const char *why)
{
    if (!why || why[0] == '\0' || strchr(why, '\n'))
        abort();
}

/* One axis of node n's lattice: in order, from its start to its clipped end, never past the
 * image; returns the count. */
static int check_axis(int x, int s, int d, int limit)
{
    int pos[TF_PAINT_MAX_SIZE + 2];
    int n = tf_paint_axis(x, s, d, limit, pos);
    int end = x + s < limit ? x + s : limit;
    if (n < 2 || n > s / d + 1 || pos[0] != x || pos[n - 1] != end)
        abort();
    for (int i = 1; i < n; i++)
        if (pos[i] <= pos[i - 1] || pos[i] > limit)
            abort();
    return n;
}

/* An accepted node: valid, and its lattice holds as many values as tf_paint_node_values says. */
static void check_node(const tf_paint_node *n, int w, int h)
{
    if (tf_paint_node_problem(n, w, h))
        abort();
    size_t values = tf_paint_node_values(n, w, h);
    if (n->d == 0) {
        size_t pw = (size_t)((n->x + n->s < w ? n->x + n->s : w) - n->x);
        size_t ph = (size_t)((n->y + n->s < h ? n->y + n->s : h) - n->y);
        if (pw < 1 || ph < 1 || values != pw * ph * TF_PAINT_PIXEL_FLOATS)
            abort();
        return;
    }
    int ni = check_axis(n->x, n->s, n->d, w), nj = check_axis(n->y, n->s, n->d, h);
    size_t points = 0;
    for (int j = 0; j < nj; j++)
        for (int i = 0; i < ni; i++)
            points += !tf_paint_point_skipped(n, i, j, ni, nj);
    if (values != points * TF_PAINT_SAMPLE_FLOATS)
        abort();
}

/* Accepted values: each in its field's range (paintproto.h), checked again here. */
static void check_values(const float *v, const tf_paint_node *nodes, int count, int w, int h,
                         int aa_depth)
{
    const double side = (double)(1 << aa_depth) + 1;
    size_t at = 0;
    for (int k = 0; k < count; k++) {
        const int exact = nodes[k].d == 0;
        const size_t per = exact ? TF_PAINT_PIXEL_FLOATS : TF_PAINT_SAMPLE_FLOATS;
        const size_t n = tf_paint_node_values(&nodes[k], w, h);
        for (size_t i = 0; i < n; i++, at++) {
            const float x = v[at];
            const size_t field = i % per;
            int ok = isfinite(x) && (field >= 3 || (x >= 0 && x <= TF_PAINT_MAX_RADIANCE));
            if (exact && field == 3)
                ok = ok && x >= 0 && x <= 1;
            if (exact && field == 4)
                ok = ok && x > 0;
            if (exact && field == 5)
                ok = ok && x >= 4 && x <= side * side && x == floorf(x);
            if (!ok)
                abort();
        }
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < HEADER)
        return 0;
    const int w = u16(data) + 1, h = u16(data + 2) + 1, aa_depth = data[4] & 7;
    size_t nodes_len = (size_t)u16(data + 5);
    if (nodes_len > size - HEADER)
        nodes_len = size - HEADER;
    const uint8_t *blob = data + HEADER, *values = blob + nodes_len;
    const size_t values_len = size - HEADER - nodes_len;

    static tf_paint_node nodes[TF_PAINT_MAX_NODES];
    const char *why = NULL;
    int count = tf_paint_nodes_get(blob, nodes_len, w, h, nodes, TF_PAINT_MAX_NODES, &why);
    if (count < 0) {
        check_reason(why);
        return 0;
    }
    if ((size_t)count * TF_PAINT_RECORD_BYTES != nodes_len)
        abort();
    uint8_t *again = malloc(nodes_len);
    if (!again)
        return 0;
    tf_paint_nodes_put(again, nodes, count);
    if (memcmp(again, blob, nodes_len) != 0)
        abort(); /* a parsed node list re-encodes to its bytes */
    free(again);
    for (int k = 0; k < count; k++)
        check_node(&nodes[k], w, h);

    /* the values: of the wrong length refused before anything is copied (out may be short) */
    const size_t want = tf_paint_task_values(nodes, count, w, h);
    float *out = malloc(values_len ? values_len : 1);
    if (!out)
        return 0;
    char err[256] = "";
    if (tf_paint_values_check(values, values_len, nodes, count, w, h, aa_depth, out, err,
                              sizeof err)) {
        check_reason(err);
    } else {
        if (values_len != want * sizeof(float))
            abort();
        check_values(out, nodes, count, w, h, aa_depth);
    }
    free(out);
    return 0;
}
