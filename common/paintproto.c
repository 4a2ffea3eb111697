/* paintproto.c: Raypaint's tuples and node geometry (paintproto.h). */
#include "paintproto.h"

#include <endian.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "log.h"

int tf_paint_axis(int x, int s, int d, int limit, int *pos)
{
    int end = x + s < limit ? x + s : limit, n = 0;
    for (int p = x; p < end; p += d)
        pos[n++] = p;
    pos[n++] = end;
    return n;
}

static int is_pow2(int v) { return v > 0 && (v & (v - 1)) == 0; }

const char *tf_paint_node_problem(const tf_paint_node *n, int w, int h)
{
    if (!is_pow2(n->s) || n->s > TF_PAINT_MAX_SIZE)
        return "node size is not a power of two up to 1024";
    if (n->x < 0 || n->y < 0 || n->x >= w || n->y >= h || n->x % n->s || n->y % n->s)
        return "node is not an aligned square of the image";
    if (n->d < 0 || (n->d > 0 && (!is_pow2(n->d) || n->d > n->s)))
        return "node stride is not a power of two up to its size";
    if (n->flags & ~TF_PAINT_CORNERS_KNOWN)
        return "node has unknown flags";
    return NULL;
}

static int axis_count(int x, int s, int d, int limit)
{
    int end = x + s < limit ? x + s : limit;
    return (end - x + d - 1) / d + 1;
}

size_t tf_paint_node_values(const tf_paint_node *n, int w, int h)
{
    if (n->d == 0) {
        size_t pw = (size_t)((n->x + n->s < w ? n->x + n->s : w) - n->x);
        size_t ph = (size_t)((n->y + n->s < h ? n->y + n->s : h) - n->y);
        return pw * ph * TF_PAINT_PIXEL_FLOATS;
    }
    size_t ni = (size_t)axis_count(n->x, n->s, n->d, w);
    size_t nj = (size_t)axis_count(n->y, n->s, n->d, h);
    size_t points = ni * nj - ((n->flags & TF_PAINT_CORNERS_KNOWN) ? 4 : 0);
    return points * TF_PAINT_SAMPLE_FLOATS;
}

size_t tf_paint_task_values(const tf_paint_node *nodes, int count, int w, int h)
{
    size_t total = 0;
    for (int k = 0; k < count; k++)
        total += tf_paint_node_values(&nodes[k], w, h);
    return total;
}

int tf_paint_point_skipped(const tf_paint_node *n, int i, int j, int ni, int nj)
{
    return (n->flags & TF_PAINT_CORNERS_KNOWN) && (i == 0 || i == ni - 1) &&
           (j == 0 || j == nj - 1);
}

void tf_paint_nodes_put(uint8_t *out, const tf_paint_node *nodes, int count)
{
    for (int k = 0; k < count; k++) {
        int32_t v[5] = {nodes[k].x, nodes[k].y, nodes[k].s, nodes[k].d, nodes[k].flags};
        for (int f = 0; f < 5; f++) {
            uint32_t le = htole32((uint32_t)v[f]);
            memcpy(out + (size_t)k * TF_PAINT_RECORD_BYTES + 4u * (size_t)f, &le, 4);
        }
    }
}

int tf_paint_nodes_get(const uint8_t *blob, size_t len, int w, int h, tf_paint_node *nodes,
                       int max, const char **why)
{
    if (len == 0 || len % TF_PAINT_RECORD_BYTES || len / TF_PAINT_RECORD_BYTES > (size_t)max) {
        *why = "node list of a wrong length";
        return -1;
    }
    int count = (int)(len / TF_PAINT_RECORD_BYTES);
    for (int k = 0; k < count; k++) {
        int32_t v[5];
        for (int f = 0; f < 5; f++) {
            uint32_t le;
            memcpy(&le, blob + (size_t)k * TF_PAINT_RECORD_BYTES + 4u * (size_t)f, 4);
            v[f] = (int32_t)le32toh(le);
        }
        nodes[k] = (tf_paint_node){v[0], v[1], v[2], v[3], v[4]};
        if ((*why = tf_paint_node_problem(&nodes[k], w, h)) != NULL)
            return -1;
    }
    return count;
}

int tf_paint_view_pack(tf_tuple *t, int64_t gen, const char *text, const char *hash)
{
    tf_tuple_init(t);
    return tf_tuple_pack(t, "siss", TF_TAG_PAINT_VIEW, gen, text, hash);
}

int tf_paint_task_pack(tf_tuple *t, int64_t gen, int64_t id, const tf_paint_node *nodes,
                       int count)
{
    uint8_t blob[TF_PAINT_MAX_NODES * TF_PAINT_RECORD_BYTES];
    if (count < 0 || count > TF_PAINT_MAX_NODES)
        return -1;
    tf_paint_nodes_put(blob, nodes, count);
    tf_tuple_init(t);
    return tf_tuple_pack(t, "siib", TF_TAG_PAINT_TASK, gen, id, blob,
                         (size_t)count * TF_PAINT_RECORD_BYTES);
}

int tf_paint_result_pack(tf_tuple *t, int64_t gen, int64_t id, int64_t worker, int64_t busy_ns,
                         const float *values, size_t nvalues)
{
    /* little-endian on the wire; this is a no-op copy on the hosts we build for */
    _Static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "float32 values go out as they are");
    tf_tuple_init(t);
    return tf_tuple_pack(t, "siiiib", TF_TAG_PAINT_RESULT, gen, id, worker, busy_ns, values,
                         nvalues * sizeof(float));
}

int tf_paint_task_unpack(const tf_tuple *t, tf_paint_task_msg *m)
{
    const char *name = tf_tuple_name(t);
    if (!name || strcmp(name, TF_TAG_PAINT_TASK) || t->nfields != TF_PAINT_TASK_FIELDS ||
        tf_tuple_get_int(t, 1, &m->gen) || tf_tuple_get_int(t, 2, &m->id) ||
        tf_tuple_get_blob(t, 3, &m->nodes, &m->nodes_len))
        return -1;
    return 0;
}

int tf_paint_result_unpack(const tf_tuple *t, tf_paint_result_msg *m)
{
    const char *name = tf_tuple_name(t);
    if (!name || strcmp(name, TF_TAG_PAINT_RESULT) || t->nfields != TF_PAINT_RESULT_FIELDS ||
        tf_tuple_get_int(t, 1, &m->gen) || tf_tuple_get_int(t, 2, &m->id) ||
        tf_tuple_get_int(t, 3, &m->worker) || tf_tuple_get_int(t, 4, &m->busy_ns) ||
        tf_tuple_get_blob(t, 5, &m->values, &m->values_len) || m->busy_ns < 0)
        return -1;
    return 0;
}

/* One value of node k: which of the record's floats, and whether it is in range. */
static const char *value_problem(float v, int field, int exact, int aa_depth)
{
    if (!isfinite(v))
        return "a value that is not finite";
    if (field < 3)
        return v >= 0 && v <= TF_PAINT_MAX_RADIANCE ? NULL : "a colour out of range";
    if (!exact)
        return NULL;
    if (field == 3)
        return v >= 0 && v <= 1 ? NULL : "an alpha outside [0, 1]";
    if (field == 4)
        return v > 0 ? NULL : "a depth that is not positive";
    double side = (double)(1 << aa_depth) + 1;
    return v >= 4 && v <= side * side && v == floorf(v) ? NULL
                                                        : "a sample count no render makes";
}

int tf_paint_values_check(const uint8_t *values, size_t len, const tf_paint_node *nodes,
                          int count, int w, int h, int aa_depth, float *out, char *err,
                          size_t errlen)
{
    size_t want = tf_paint_task_values(nodes, count, w, h);
    if (len != want * sizeof(float))
        return tf_seterr(err, errlen, "%zu bytes of values where its %d nodes take %zu", len,
                         count, want * sizeof(float));
    memcpy(out, values, len);
    size_t at = 0;
    for (int k = 0; k < count; k++) {
        int exact = nodes[k].d == 0, per = exact ? TF_PAINT_PIXEL_FLOATS : TF_PAINT_SAMPLE_FLOATS;
        size_t n = tf_paint_node_values(&nodes[k], w, h);
        for (size_t v = 0; v < n; v++) {
            const char *why = value_problem(out[at + v], (int)(v % (size_t)per), exact, aa_depth);
            if (why)
                return tf_seterr(err, errlen, "%s at node %dx%d+%d+%d", why, nodes[k].s,
                                 nodes[k].s, nodes[k].x, nodes[k].y);
        }
        at += n;
    }
    return 0;
}
