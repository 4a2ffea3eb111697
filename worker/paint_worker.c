/* paint_worker.c: see paint_worker.h. */
#include "worker/paint_worker.h"

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "clock.h"
#include "log.h"
#include "worker/worker.h"

/* The view this worker renders now: its generation, its scene (a copy of the worker's own with
 * the view's camera, sun and mist) and a renderer over the worker's terrain. */
typedef struct paint_view {
    int64_t gen;
    tf_scene *scene;
    tf_renderer *r;
} paint_view;

static void view_clear(paint_view *v)
{
    tf_renderer_free(v->r);
    tf_scene_free(v->scene);
    *v = (paint_view){0, NULL, NULL};
}

/* Read the scene of view gen and make a renderer of it: 0; 1 when the view is gone (a newer
 * one replaced it after this task was dealt: the task is stale, and skipped); -1 with err.
 * The coordinator puts a view before any of its tasks, and a connection's requests are served
 * in order, so a view missing here can only have been replaced: an rdp, never a blocking rd
 * that would wait for a view that will not come back. */
static int load_view(ts_client *c, const tf_scene *s, const tf_heightfield *hf, int64_t gen,
                     paint_view *v, char *err, size_t errlen)
{
    tf_tuple tmpl, got;
    tf_tuple_init(&tmpl);
    tf_tuple_init(&got);
    const char *text;
    int rc = -1, found = 0;
    if (tf_tuple_pack(&tmpl, "siSS", TF_TAG_PAINT_VIEW, gen) ||
        (found = ts_rdp(c, &tmpl, &got)) < 0 || (found && tf_tuple_get_string(&got, 2, &text))) {
        tf_seterr(err, errlen, "cannot read view %" PRId64 ": %s", gen, ts_client_error(c));
        goto out;
    }
    if (!found) {
        rc = 1;
        goto out;
    }
    char perr[1024];
    tf_scene *vs = tf_scene_parse_text("<paint view>", text, strlen(text), perr, sizeof perr);
    if (!vs) {
        tf_seterr(err, errlen, "view %" PRId64 " does not parse here: %s", gen, perr);
        goto out;
    }
    view_clear(v);
    v->scene = tf_scene_at_frame(s, 0);
    if (v->scene)
        tf_scene_set_view(v->scene, vs);
    tf_scene_free(vs);
    v->r = v->scene ? tf_renderer_new(v->scene, hf, err, errlen) : NULL;
    if (!v->r)
        goto out;
    v->gen = gen;
    rc = 0;
out:
    tf_tuple_clear(&tmpl);
    tf_tuple_clear(&got);
    return rc;
}

/* One SAMPLE node: the corner samples of its lattice, row by row, skipped corners left out. */
static float *sample_node(const tf_renderer *r, const tf_paint_node *n, int w, int h, float *out)
{
    int xs[TF_PAINT_MAX_SIZE + 1], ys[TF_PAINT_MAX_SIZE + 1];
    int ni = tf_paint_axis(n->x, n->s, n->d, w, xs), nj = tf_paint_axis(n->y, n->s, n->d, h, ys);
    for (int j = 0; j < nj; j++)
        for (int i = 0; i < ni; i++)
            if (!tf_paint_point_skipped(n, i, j, ni, nj)) {
                tf_render_corner(r, xs[i], ys[j], out, NULL);
                out += TF_PAINT_SAMPLE_FLOATS;
            }
    return out;
}

/* One EXACT node: the final render's pixels. */
static float *exact_node(const tf_renderer *r, const tf_paint_node *n, int w, int h, float *out)
{
    tf_rect rect = {n->x, n->y, (n->x + n->s < w ? n->x + n->s : w) - n->x,
                    (n->y + n->s < h ? n->y + n->s : h) - n->y};
    tf_pixel *px = (tf_pixel *)out;
    _Static_assert(sizeof(tf_pixel) == TF_PAINT_PIXEL_FLOATS * sizeof(float), "tf_pixel floats");
    tf_render_rect(r, rect, px, NULL);
    return out + (size_t)rect.w * (size_t)rect.h * TF_PAINT_PIXEL_FLOATS;
}

void tf_paint_render_nodes(const tf_renderer *r, const tf_paint_node *nodes, int count, int w,
                           int h, float *out)
{
    for (int k = 0; k < count; k++)
        out = nodes[k].d == 0 ? exact_node(r, &nodes[k], w, h, out)
                              : sample_node(r, &nodes[k], w, h, out);
}

/* Answer one task.  0; 1 (a task or view this worker cannot take: logged); -1 (lost). */
static int answer(ts_client *c, const tf_scene *s, const tf_heightfield *hf, paint_view *v,
                  int64_t worker, const tf_paint_task_msg *m, const tf_tuple *tmpl,
                  tf_tuple *next)
{
    static tf_paint_node nodes[TF_PAINT_MAX_NODES];
    char err[1024];
    const char *why;
    int count = tf_paint_nodes_get(m->nodes, m->nodes_len, s->width, s->height, nodes,
                                   TF_PAINT_MAX_NODES, &why);
    if (count < 0) {
        tf_error("paint task %" PRId64 ": %s", m->id, why);
        return 1;
    }
    int fresh = m->gen == v->gen ? 0 : load_view(c, s, hf, m->gen, v, err, sizeof err);
    if (fresh < 0) {
        tf_error("%s", err);
        return 1;
    }
    if (fresh > 0) /* a task of a view already replaced: nobody wants its answer */
        return ts_in(c, tmpl, next) ? -1 : 0;
    size_t n = tf_paint_task_values(nodes, count, s->width, s->height);
    float *values = malloc(n * sizeof *values + 1);
    if (!values) {
        tf_error("out of memory for paint task %" PRId64, m->id);
        return 1;
    }
    int64_t t0 = tf_now_ns();
    tf_paint_render_nodes(v->r, nodes, count, s->width, s->height, values);
    tf_tuple result;
    int rc = tf_paint_result_pack(&result, m->gen, m->id, worker, tf_now_ns() - t0, values, n) ||
                     ts_out_in(c, &result, tmpl, next)
                 ? -1
                 : 0;
    tf_tuple_clear(&result);
    free(values);
    return rc;
}

/* Take tasks until the stop task (put back for the others).  0, 1, or -1 (lost). */
static int serve(ts_client *c, const tf_scene *s, const tf_heightfield *hf, int64_t worker)
{
    paint_view v = {0, NULL, NULL};
    tf_tuple tmpl, task;
    tf_tuple_init(&tmpl);
    tf_tuple_init(&task);
    int rc = tf_tuple_pack(&tmpl, "sIIB", TF_TAG_PAINT_TASK) || ts_in(c, &tmpl, &task) ? -1 : 0;
    while (rc == 0) {
        tf_paint_task_msg m;
        if (tf_paint_task_unpack(&task, &m) != 0) {
            tf_error("malformed paint task");
            rc = 1;
        } else if (m.gen < 0) {
            rc = ts_out(c, &task) ? -1 : 2;
        } else {
            tf_tuple next;
            tf_tuple_init(&next);
            rc = answer(c, s, hf, &v, worker, &m, &tmpl, &next);
            tf_tuple_clear(&task);
            tf_tuple_move(&task, &next);
        }
    }
    tf_tuple_clear(&tmpl);
    tf_tuple_clear(&task);
    view_clear(&v);
    return rc == 2 ? 0 : rc;
}

int tf_paint_worker_loop(ts_client *c, const tf_scene *s, const tf_heightfield *hf,
                         const char *kind)
{
    ts_client_heartbeat(c, TF_WORKER_HEARTBEAT_MS);
    int64_t id;
    if (tf_worker_join(c, kind, "c", &id)) {
        int refused = strstr(ts_client_error(c), "refused:") != NULL;
        tf_error("cannot join the paint: %s", ts_client_error(c));
        return refused ? 1 : TF_WORKER_EXIT_LOST;
    }
    char tag[40];
    snprintf(tag, sizeof tag, "paint worker %" PRId64, id);
    tf_log_set_tag(tag);
    int rc = serve(c, s, hf, id);
    if (rc < 0)
        tf_warn("lost the paint coordinator: %s", ts_client_error(c));
    tf_log_set_tag(NULL);
    return rc < 0 ? TF_WORKER_EXIT_LOST : rc;
}
