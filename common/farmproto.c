/* farmproto.c: see farmproto.h. */
#include "farmproto.h"
#include "log.h"

#include <endian.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* 1 if t is a tuple of the kind named tag with nfields fields. */
static int is_kind(const tf_tuple *t, const char *tag, int nfields)
{
    const char *name = tf_tuple_name(t);
    return name && !strcmp(name, tag) && t->nfields == nfields;
}

/* (tag, id, worker, rest...): id and worker each an actual, or a formal when < 0; rest the
 * formals of tf_tuple_pack's format. */
static int id_worker_template(tf_tuple *t, const char *tag, int64_t id, int64_t worker,
                              const char *rest)
{
    tf_tuple_init(t);
    if (tf_tuple_add_string(t, tag))
        return -1;
    if (id >= 0 ? tf_tuple_add_int(t, id) : tf_tuple_add_formal(t, TF_FIELD_INT))
        return -1;
    if (worker >= 0 ? tf_tuple_add_int(t, worker) : tf_tuple_add_formal(t, TF_FIELD_INT))
        return -1;
    return tf_tuple_pack(t, rest);
}

#define IMAGE_SIDE_MAX 65536 /* the scene tuple's largest width or height */

int tf_scene_tuple_pack(tf_tuple *t, const tf_scene_msg *m)
{
    tf_tuple_init(t);
    return tf_tuple_pack(t, "ssiiss", TF_TAG_SCENE, m->text, m->width, m->height, m->hash,
                         m->layout);
}

int tf_scene_tuple_template(tf_tuple *t)
{
    tf_tuple_init(t);
    return tf_tuple_pack(t, "sSIISS", TF_TAG_SCENE);
}

int tf_scene_tuple_unpack(const tf_tuple *t, tf_scene_msg *m)
{
    if (!is_kind(t, TF_TAG_SCENE, TF_SCENE_FIELDS) || tf_tuple_get_string(t, 1, &m->text) ||
        tf_tuple_get_int(t, 2, &m->width) || tf_tuple_get_int(t, 3, &m->height) ||
        tf_tuple_get_string(t, 4, &m->hash) || tf_tuple_get_string(t, 5, &m->layout))
        return -1;
    if (m->width < 1 || m->height < 1 || m->width > IMAGE_SIDE_MAX || m->height > IMAGE_SIDE_MAX)
        return -1;
    return 0;
}

int tf_next_worker_pack(tf_tuple *t, int64_t n)
{
    tf_tuple_init(t);
    return tf_tuple_pack(t, "si", TF_TAG_NEXT_WORKER, n);
}

int tf_next_worker_template(tf_tuple *t)
{
    tf_tuple_init(t);
    return tf_tuple_pack(t, "sI", TF_TAG_NEXT_WORKER);
}

int tf_next_worker_unpack(const tf_tuple *t, int64_t *n)
{
    return is_kind(t, TF_TAG_NEXT_WORKER, TF_NEXT_WORKER_FIELDS) ? tf_tuple_get_int(t, 1, n) : -1;
}

int tf_hello_pack(tf_tuple *t, const tf_hello_msg *m)
{
    tf_tuple_init(t);
    return tf_tuple_pack(t, "sissis", TF_TAG_HELLO, m->worker, m->kind, m->host, m->pid,
                         m->backend);
}

int tf_hello_unpack(const tf_tuple *t, tf_hello_msg *m)
{
    if (!is_kind(t, TF_TAG_HELLO, TF_HELLO_FIELDS) || tf_tuple_get_int(t, 1, &m->worker) ||
        tf_tuple_get_string(t, 2, &m->kind) || tf_tuple_get_string(t, 3, &m->host) ||
        tf_tuple_get_int(t, 4, &m->pid) || tf_tuple_get_string(t, 5, &m->backend))
        return -1;
    return 0;
}

int tf_failed_pack(tf_tuple *t, int64_t id, int64_t worker, const char *message)
{
    tf_tuple_init(t);
    return tf_tuple_pack(t, "siis", TF_TAG_FAILED, id, worker, message);
}

int tf_failed_template(tf_tuple *t, int64_t id, int64_t worker)
{
    return id_worker_template(t, TF_TAG_FAILED, id, worker, "S");
}

int tf_failed_unpack(const tf_tuple *t, tf_failed_msg *m)
{
    if (!is_kind(t, TF_TAG_FAILED, TF_FAILED_FIELDS) || tf_tuple_get_int(t, 1, &m->id) ||
        tf_tuple_get_int(t, 2, &m->worker) || tf_tuple_get_string(t, 3, &m->message))
        return -1;
    return 0;
}

int tf_task_pack(tf_tuple *t, const tf_task_msg *m)
{
    uint8_t ex[TF_EXCLUDED_MAX * 8];
    int n = m->nexcluded < 0 ? 0 : m->nexcluded > TF_EXCLUDED_MAX ? TF_EXCLUDED_MAX : m->nexcluded;
    for (int i = 0; i < n; i++) {
        uint64_t le = htole64((uint64_t)m->excluded[i]);
        memcpy(ex + 8 * i, &le, 8);
    }
    tf_tuple_init(t);
    return tf_tuple_pack(t, "siiiiiib", TF_TAG_TASK, m->id, (int64_t)m->frame, (int64_t)m->rect.x,
                         (int64_t)m->rect.y,
                         (int64_t)m->rect.w, (int64_t)m->rect.h, (const void *)ex, (size_t)(8 * n));
}

int tf_task_template(tf_tuple *t, int64_t id)
{
    tf_tuple_init(t);
    if (tf_tuple_add_string(t, TF_TAG_TASK))
        return -1;
    if (id == TF_TASK_ANY ? tf_tuple_add_formal(t, TF_FIELD_INT) : tf_tuple_add_int(t, id))
        return -1;
    return tf_tuple_pack(t, "IIIIIB");
}

int tf_task_unpack(const tf_tuple *t, tf_task_msg *m)
{
    int64_t v[6];
    const uint8_t *ex;
    size_t exlen;
    if (!is_kind(t, TF_TAG_TASK, TF_TASK_FIELDS))
        return -1;
    for (int i = 0; i < 6; i++)
        if (tf_tuple_get_int(t, 1 + i, &v[i]))
            return -1;
    if (tf_tuple_get_blob(t, 7, &ex, &exlen) || exlen % 8 || exlen / 8 > TF_EXCLUDED_MAX)
        return -1;
    if (v[1] < -1 || v[1] >= 1 << 30)
        return -1;
    for (int i = 2; i < 6; i++)
        if (v[i] < 0 || v[i] > 1 << 20)
            return -1;
    m->id = v[0];
    m->frame = (int)v[1];
    m->rect = (tf_rect){(int)v[2], (int)v[3], (int)v[4], (int)v[5]};
    m->nexcluded = (int)(exlen / 8);
    for (int i = 0; i < m->nexcluded; i++) {
        uint64_t le;
        memcpy(&le, ex + 8 * i, 8);
        m->excluded[i] = (int64_t)le64toh(le);
    }
    return 0;
}

int tf_task_excludes(const tf_task_msg *m, int64_t worker)
{
    for (int i = 0; i < m->nexcluded; i++)
        if (m->excluded[i] == worker)
            return 1;
    return 0;
}

int tf_result_pack(tf_tuple *t, int64_t id, int64_t worker, const tf_render_counts *c,
                   int64_t busy_ns, int64_t spp_total, const tf_chunk_payload *p)
{
    tf_tuple_init(t);
    return tf_tuple_pack(t, "siiiiiiiiiibbb", TF_TAG_RESULT, id, worker,
                         (int64_t)c->primary_rays, (int64_t)c->shadow_rays,
                         (int64_t)c->external_rays, busy_ns, spp_total,
                         (int64_t)c->terrain_samples, (int64_t)c->terrain_hits,
                         (int64_t)c->terrain_evictions, (const void *)p->index, p->nchunks * TF_CHUNK_RECORD_BYTES,
                         (const void *)p->chunks, p->chunks_len, (const void *)p->preview,
                         p->preview_len);
}

int tf_result_template(tf_tuple *t, int64_t id, int64_t worker)
{
    return id_worker_template(t, TF_TAG_RESULT, id, worker, "IIIIIIIIBBB");
}

int tf_result_unpack(const tf_tuple *t, tf_result_msg *m)
{
    int64_t v[10];
    size_t index_len;
    if (!is_kind(t, TF_TAG_RESULT, TF_RESULT_FIELDS))
        return -1;
    for (int i = 0; i < 10; i++)
        if (tf_tuple_get_int(t, 1 + i, &v[i]))
            return -1;
    if (tf_tuple_get_blob(t, TF_RESULT_INDEX_FIELD, &m->index, &index_len) ||
        tf_tuple_get_blob(t, TF_RESULT_INDEX_FIELD + 1, &m->chunks, &m->chunks_len) ||
        tf_tuple_get_blob(t, TF_RESULT_INDEX_FIELD + 2, &m->preview, &m->preview_len) ||
        index_len % TF_CHUNK_RECORD_BYTES)
        return -1;
    for (int i = 2; i < 10; i++)
        if (v[i] < 0)
            return -1;
    m->id = v[0];
    m->worker = v[1];
    m->counts.primary_rays = (uint64_t)v[2];
    m->counts.shadow_rays = (uint64_t)v[3];
    m->counts.external_rays = (uint64_t)v[4];
    m->counts.pixels = 0;
    m->busy_ns = v[5];
    m->spp_total = v[6];
    m->counts.terrain_samples = (uint64_t)v[7];
    m->counts.terrain_hits = (uint64_t)v[8];
    m->counts.terrain_evictions = (uint64_t)v[9];
    m->nchunks = index_len / TF_CHUNK_RECORD_BYTES;
    return 0;
}

int tf_result_check(tf_result_msg *m, const tf_exr_layout *l, const tf_preview_grid *g,
                    tf_rect r, char *err, size_t errlen)
{
    int64_t first;
    int count;
    if (tf_layout_rect_chunks(l, r, &first, &count))
        return tf_seterr(err, errlen, "the task's rectangle is not whole chunks of the output");
    if (m->nchunks != (size_t)count)
        return tf_seterr(err, errlen, "%zu chunks, the task has %d", m->nchunks, count);
    uint64_t sum = 0;
    for (int i = 0; i < count; i++) {
        tf_chunk_rec c;
        tf_chunk_rec_get(m->index + (size_t)i * TF_CHUNK_RECORD_BYTES, &c);
        tf_chunk_ref want = tf_layout_chunk(l, first + i);
        if (c.cx != want.cx || c.cy != want.cy)
            return tf_seterr(err, errlen, "chunk %d is at (%d, %d), the task's is at (%d, %d)",
                             i, c.cx, c.cy, want.cx, want.cy);
        if (c.unpacked < 0 || (uint64_t)c.unpacked != want.unpacked)
            return tf_seterr(err, errlen, "chunk (%d, %d) claims %lld unpacked bytes, not %llu",
                             c.cx, c.cy, (long long)c.unpacked,
                             (unsigned long long)want.unpacked);
        if (c.packed < 1 || c.packed > c.unpacked)
            return tf_seterr(err, errlen, "chunk (%d, %d) has %lld packed bytes (1..%lld)", c.cx,
                             c.cy, (long long)c.packed, (long long)c.unpacked);
        sum += (uint64_t)c.packed;
    }
    if (sum != m->chunks_len)
        return tf_seterr(err, errlen, "the chunks add up to %llu bytes, the blob has %zu",
                         (unsigned long long)sum, m->chunks_len);
    int i0, i1, j0, j1;
    tf_preview_span(g, l->width, l->height, r, &i0, &i1, &j0, &j1);
    size_t want_preview = (size_t)(i1 - i0) * (size_t)(j1 - j0) * 3;
    if (m->preview_len != want_preview)
        return tf_seterr(err, errlen, "preview of %zu bytes, the task's is %zu", m->preview_len,
                         want_preview);
    m->counts.pixels = (uint64_t)r.w * (uint64_t)r.h;
    return 0;
}

#define TF_TERRAIN_COUNT_MAX (1ull << 40)

int tf_result_counts_check(const tf_result_msg *m, tf_rect r, int aa_depth, char *err,
                           size_t errlen)
{
    uint64_t side = (1ull << (aa_depth < 0 ? 0 : aa_depth > 8 ? 8 : aa_depth)) + 1;
    uint64_t pixels = (uint64_t)r.w * (uint64_t)r.h;
    uint64_t max_spp = pixels * side * side;
    uint64_t max_primary = max_spp + ((uint64_t)r.w + 1) * ((uint64_t)r.h + 1);
    const tf_render_counts *c = &m->counts;
    if (c->primary_rays > max_primary)
        return tf_seterr(err, errlen, "claims %llu primary rays, the task has room for %llu",
                         (unsigned long long)c->primary_rays, (unsigned long long)max_primary);
    if (c->shadow_rays > c->primary_rays || c->external_rays > c->primary_rays)
        return tf_seterr(err, errlen, "claims more shadow or external rays than primary ones");
    /* the terrain counts are the worker's word, summed into the stats: bounded so no liar can
     * overflow a sum (2^40 samples is days of one worker's evaluation) */
    if (c->terrain_samples > TF_TERRAIN_COUNT_MAX || c->terrain_hits > TF_TERRAIN_COUNT_MAX ||
        c->terrain_evictions > TF_TERRAIN_COUNT_MAX)
        return tf_seterr(err, errlen, "claims a terrain count above 2^40");
    if (m->spp_total < 0 || (uint64_t)m->spp_total > max_spp)
        return tf_seterr(err, errlen, "claims %lld samples, the task has room for %llu",
                         (long long)m->spp_total, (unsigned long long)max_spp);
    return 0;
}

const char *tf_task_rect_problem(tf_rect r, int image_w, int image_h)
{
    if (r.w < 1 || r.h < 1)
        return "empty rectangle";
    if ((uint64_t)r.w * (uint64_t)r.h > TF_TASK_MAX_PIXELS)
        return "rectangle larger than any task";
    if (r.x < 0 || r.y < 0)
        return "rectangle outside the image";
    if (image_w > 0 && image_h > 0 &&
        ((int64_t)r.x + r.w > image_w || (int64_t)r.y + r.h > image_h))
        return "rectangle outside the image";
    return NULL;
}

long tf_first_non_finite(const tf_pixel *px, size_t n)
{
    for (size_t i = 0; i < n; i++)
        if (!isfinite(px[i].r) || !isfinite(px[i].g) || !isfinite(px[i].b) ||
            !isfinite(px[i].a) || !isfinite(px[i].z) || !isfinite(px[i].spp))
            return (long)i;
    return -1;
}
