/* farmproto.c: see farmproto.h. */
#include "farmproto.h"

#include <endian.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

int tf_task_pack(tf_tuple *t, const tf_task_msg *m)
{
    uint8_t ex[TF_EXCLUDED_MAX * 8];
    int n = m->nexcluded < 0 ? 0 : m->nexcluded > TF_EXCLUDED_MAX ? TF_EXCLUDED_MAX : m->nexcluded;
    for (int i = 0; i < n; i++) {
        uint64_t le = htole64((uint64_t)m->excluded[i]);
        memcpy(ex + 8 * i, &le, 8);
    }
    tf_tuple_init(t);
    return tf_tuple_pack(t, "siiiiib", "task", m->id, (int64_t)m->rect.x, (int64_t)m->rect.y,
                         (int64_t)m->rect.w, (int64_t)m->rect.h, (const void *)ex, (size_t)(8 * n));
}

int tf_task_template(tf_tuple *t, int64_t id)
{
    tf_tuple_init(t);
    if (tf_tuple_add_string(t, "task"))
        return -1;
    if (id == TF_TASK_ANY ? tf_tuple_add_formal(t, TF_FIELD_INT) : tf_tuple_add_int(t, id))
        return -1;
    return tf_tuple_pack(t, "IIIIB");
}

int tf_task_unpack(const tf_tuple *t, tf_task_msg *m)
{
    const char *name = tf_tuple_name(t);
    int64_t v[5];
    const uint8_t *ex;
    size_t exlen;
    if (!name || strcmp(name, "task") || t->nfields != 7)
        return -1;
    for (int i = 0; i < 5; i++)
        if (tf_tuple_get_int(t, 1 + i, &v[i]))
            return -1;
    if (tf_tuple_get_blob(t, 6, &ex, &exlen) || exlen % 8 || exlen / 8 > TF_EXCLUDED_MAX)
        return -1;
    for (int i = 1; i < 5; i++)
        if (v[i] < 0 || v[i] > 1 << 20)
            return -1;
    m->id = v[0];
    m->rect = (tf_rect){(int)v[1], (int)v[2], (int)v[3], (int)v[4]};
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

static void put_f32(uint8_t *p, float f)
{
    uint32_t u;
    memcpy(&u, &f, 4);
    u = htole32(u);
    memcpy(p, &u, 4);
}

static float get_f32(const uint8_t *p)
{
    uint32_t u;
    memcpy(&u, p, 4);
    u = le32toh(u);
    float f;
    memcpy(&f, &u, 4);
    return f;
}

int tf_result_pack(tf_tuple *t, int64_t id, int64_t worker, const tf_render_counts *c,
                   int64_t busy_ns, const tf_pixel *px, size_t npx)
{
    uint8_t *wire = malloc(npx * TF_PIXEL_WIRE_BYTES + 1);
    if (!wire)
        return -1;
    for (size_t i = 0; i < npx; i++) {
        uint8_t *p = wire + i * TF_PIXEL_WIRE_BYTES;
        put_f32(p, px[i].r);
        put_f32(p + 4, px[i].g);
        put_f32(p + 8, px[i].b);
        put_f32(p + 12, px[i].a);
        put_f32(p + 16, px[i].z);
        put_f32(p + 20, px[i].spp);
    }
    tf_tuple_init(t);
    int rc = tf_tuple_pack(t, "siiiiiib", "result", id, worker, (int64_t)c->primary_rays,
                           (int64_t)c->shadow_rays, (int64_t)c->external_rays, busy_ns,
                           (const void *)wire, npx * TF_PIXEL_WIRE_BYTES);
    free(wire);
    return rc;
}

int tf_result_template(tf_tuple *t, int64_t id, int64_t worker)
{
    tf_tuple_init(t);
    if (tf_tuple_add_string(t, "result"))
        return -1;
    if (id >= 0 ? tf_tuple_add_int(t, id) : tf_tuple_add_formal(t, TF_FIELD_INT))
        return -1;
    if (worker >= 0 ? tf_tuple_add_int(t, worker) : tf_tuple_add_formal(t, TF_FIELD_INT))
        return -1;
    return tf_tuple_pack(t, "IIIIB");
}

int tf_result_unpack(const tf_tuple *t, tf_result_msg *m)
{
    const char *name = tf_tuple_name(t);
    int64_t v[6];
    if (!name || strcmp(name, "result") || t->nfields != 8)
        return -1;
    for (int i = 0; i < 6; i++)
        if (tf_tuple_get_int(t, 1 + i, &v[i]))
            return -1;
    if (tf_tuple_get_blob(t, 7, &m->pixels, &m->pixels_len))
        return -1;
    for (int i = 2; i < 6; i++)
        if (v[i] < 0)
            return -1;
    m->id = v[0];
    m->worker = v[1];
    m->counts.primary_rays = (uint64_t)v[2];
    m->counts.shadow_rays = (uint64_t)v[3];
    m->counts.external_rays = (uint64_t)v[4];
    m->counts.pixels = m->pixels_len / TF_PIXEL_WIRE_BYTES;
    m->busy_ns = v[5];
    return 0;
}

void tf_pixels_decode(const uint8_t *wire, tf_pixel *px, size_t n)
{
    for (size_t i = 0; i < n; i++) {
        const uint8_t *p = wire + i * TF_PIXEL_WIRE_BYTES;
        px[i].r = get_f32(p);
        px[i].g = get_f32(p + 4);
        px[i].b = get_f32(p + 8);
        px[i].a = get_f32(p + 12);
        px[i].z = get_f32(p + 16);
        px[i].spp = get_f32(p + 20);
    }
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
