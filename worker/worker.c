/* worker.c: see worker.h. */
#include "worker/worker.h"
#include "clock.h"

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "worker/backend.h"
#include "farmproto.h"
#include "image/exrencode.h"
#include "erosion_tuples.h"
#include "paintproto.h"
#include "heightmap_tuples.h"
#include "log.h"

/* Linda's counter idiom, half of it: in ("next_worker", ?n).  The coordinator binds id n to
 * this connection and puts the counter back itself (coordinator/render/worker_role.h): a worker that
 * could hold the counter could stop every other worker from joining. */
static int take_worker_id(ts_client *c, int64_t *id)
{
    tf_tuple tmpl, got;
    tf_tuple_init(&got);
    int rc = tf_next_worker_template(&tmpl) || ts_in(c, &tmpl, &got) ||
                     tf_next_worker_unpack(&got, id)
                 ? -1
                 : 0;
    tf_tuple_clear(&tmpl);
    tf_tuple_clear(&got);
    return rc;
}

int tf_worker_join(ts_client *c, const char *kind, const char *backend, int64_t *id)
{
    return tf_worker_join_take(c, kind, backend, id, NULL);
}

int tf_worker_join_take(ts_client *c, const char *kind, const char *backend, int64_t *id,
                        tf_tuple *first)
{
    if (take_worker_id(c, id))
        return -1;
    char host[64] = "";
    gethostname(host, sizeof host - 1);
    tf_hello_msg m = {*id, kind, host, (int64_t)getpid(), backend};
    tf_tuple t, tmpl;
    tf_task_template(&tmpl, TF_TASK_ANY);
    int rc = tf_hello_pack(&t, &m);
    if (rc == 0)
        rc = first ? ts_out_in(c, &t, &tmpl, first) : ts_out(c, &t);
    tf_tuple_clear(&t);
    tf_tuple_clear(&tmpl);
    return rc ? -1 : 0;
}

static int put_back(ts_client *c, tf_tuple *task)
{
    int rc = ts_out(c, task);
    tf_tuple_clear(task);
    return rc;
}

static int report_failure(ts_client *c, int64_t task, int64_t worker, const char *msg)
{
    tf_tuple t;
    int rc = tf_failed_pack(&t, task, worker, msg) || ts_out(c, &t) ? -1 : 0;
    tf_tuple_clear(&t);
    return rc;
}

int tf_worker_serve(ts_client *c, int64_t id, const tf_exr_layout *layout,
                    const tf_worker_step *step)
{
    return tf_worker_serve_from(c, id, layout, step, NULL);
}

/* ---- the serving loop: a task taken, rendered, encoded and returned, until the stop ---- */

/* What the loop carries from one task to the next. */
typedef struct serve_state {
    ts_client *c;
    int64_t id; /* this worker's */
    const tf_worker_step *step;
    tf_exr_encoder *enc;
    tf_tuple tmpl;  /* any task */
    tf_tuple next;  /* the next task, taken with the last result (ts_out_in) */
    int have_next;
    tf_pixel *px;   /* the task's pixels: px_cap of them */
    size_t px_cap;
    unsigned seed;  /* the random pauses after an excluded task */
    int bounces;    /* excluded tasks taken in a row */
    char err[1024];
} serve_state;

/* A task's turn ends with SERVE_GO_ON (take the next one) or with a TF_SERVE_* status. */
#define SERVE_GO_ON (-1)

static int serve_begin(serve_state *st, ts_client *c, int64_t id, const tf_exr_layout *layout,
                       const tf_worker_step *step, tf_tuple *first)
{
    memset(st, 0, sizeof *st);
    st->c = c;
    st->id = id;
    st->step = step;
    if (!(st->enc = tf_exr_encoder_new(layout, st->err, sizeof st->err))) {
        tf_error("%s", st->err);
        return -1;
    }
    tf_task_template(&st->tmpl, TF_TASK_ANY);
    tf_tuple_init(&st->next);
    st->seed = (unsigned)getpid() ^ (unsigned)tf_now_ns() ^ (unsigned)id * 2654435761u;
    if (first) { /* taken when joining (tf_worker_join_take) */
        st->next = *first;
        tf_tuple_init(first);
        st->have_next = 1;
    }
    return 0;
}

static void serve_end(serve_state *st)
{
    tf_tuple_clear(&st->next);
    tf_tuple_clear(&st->tmpl);
    free(st->px);
    tf_exr_encoder_free(st->enc);
}

/* The next task into *task: the one taken with the last result, or one waited for.  0, or -1
 * when the coordinator is lost. */
static int take_task(serve_state *st, tf_tuple *task)
{
    tf_tuple_init(task);
    if (!st->have_next)
        return ts_in(st->c, &st->tmpl, task) ? -1 : 0;
    *task = st->next; /* moved */
    tf_tuple_init(&st->next);
    st->have_next = 0;
    return 0;
}

/* A task this worker may not render: put it back for a worker that may, after a pause.  The
 * pause is random: two workers each holding the other's task and pausing alike would otherwise
 * take the same tuples back in the same order forever (a livelock seen with --verify check
 * copies). */
static void pass_on(serve_state *st, tf_tuple *task, int64_t task_id)
{
    tf_debug("task %" PRId64 " excludes this worker: put back", task_id);
    put_back(st->c, task);
    if (st->bounces < 4)
        st->bounces++;
    usleep((useconds_t)(30 + rand_r(&st->seed) % (60u << st->bounces)) * 1000u);
}

/* Task `task` answered with a failure instead of pixels: `logged` to the log (NULL: nothing),
 * `reported` to the coordinator, which deals the task again.  SERVE_GO_ON, or
 * TF_SERVE_UNDELIVERED when the report cannot go. */
static int fail_task(serve_state *st, int64_t task, const char *logged, const char *reported)
{
    if (logged)
        tf_warn("%s", logged);
    return report_failure(st->c, task, st->id, reported) ? TF_SERVE_UNDELIVERED : SERVE_GO_ON;
}

/* The same for a step's failure in st->err, logged with the task's number before it. */
static int fail_step(serve_state *st, int64_t task)
{
    char line[sizeof st->err + 32];
    snprintf(line, sizeof line, "task %" PRId64 ": %s", task, st->err);
    return fail_task(st, task, line, st->err);
}

/* Room for n pixels in st->px.  0, or -1 without memory. */
static int ensure_pixels(serve_state *st, size_t n)
{
    if (n <= st->px_cap)
        return 0;
    tf_pixel *np = realloc(st->px, n * sizeof *np);
    if (!np)
        return -1;
    st->px = np;
    st->px_cap = n;
    return 0;
}

/* The encoded pixels back with the request for the next task: one round trip per task. */
static int deliver(serve_state *st, int64_t task, const tf_render_counts *counts, int64_t busy,
                   size_t n, const tf_chunk_payload *pay)
{
    double spp = 0; /* integer-valued floats: exact in a double */
    for (size_t i = 0; i < n; i++)
        spp += st->px[i].spp;
    tf_tuple result;
    int rc = tf_result_pack(&result, task, st->id, counts, busy, (int64_t)spp, pay) ||
             ts_out_in(st->c, &result, &st->tmpl, &st->next);
    tf_tuple_clear(&result);
    if (rc) {
        tf_tuple_clear(&st->next);
        return TF_SERVE_UNDELIVERED;
    }
    st->have_next = 1;
    return SERVE_GO_ON;
}

/* Render, check and encode task m, and deliver it.  Whatever a task tuple says, it can only
 * become a reported failure here, never a crash or an exit: no size, a size no image has, or a
 * rectangle outside the image. */
static int answer_task(serve_state *st, const tf_task_msg *m)
{
    const char *bad = tf_task_rect_problem(m->rect, st->step->image_w, st->step->image_h);
    if (bad) {
        snprintf(st->err, sizeof st->err, "task %" PRId64 " (%dx%d at %d,%d): %s", m->id,
                 m->rect.w, m->rect.h, m->rect.x, m->rect.y, bad);
        return fail_task(st, m->id, st->err, st->err);
    }
    size_t n = (size_t)m->rect.w * (size_t)m->rect.h;
    if (ensure_pixels(st, n))
        return fail_task(st, m->id, NULL, "out of memory");
    tf_render_counts counts = {0};
    int64_t busy = 0;
    if (st->step->render(st->step->ctx, m->frame, m->rect, st->px, &counts, &busy, st->err,
                         sizeof st->err))
        return fail_step(st, m->id);
    long nf = tf_first_non_finite(st->px, n);
    if (nf >= 0) { /* never emit a NaN or an infinity: the file would carry it forever */
        snprintf(st->err, sizeof st->err, "task %" PRId64 ": the renderer produced a "
                 "non-finite value at pixel (%ld,%ld); not sending it", m->id,
                 m->rect.x + nf % m->rect.w, m->rect.y + nf / m->rect.w);
        return fail_task(st, m->id, st->err, st->err);
    }
    tf_chunk_payload pay;
    if (tf_exr_encode_rect(st->enc, m->rect, st->px, &pay, st->err, sizeof st->err))
        return fail_step(st, m->id);
    return deliver(st, m->id, &counts, busy, n, &pay);
}

/* One turn of the loop: a task taken and answered, passed on, or the stop. */
static int serve_one(serve_state *st)
{
    tf_tuple task;
    tf_task_msg m;
    if (take_task(st, &task))
        return TF_SERVE_LOST;
    if (tf_task_unpack(&task, &m)) {
        static tf_ratelimit rl;
        tf_warn_limited(&rl, "ignoring a malformed task tuple");
        tf_tuple_clear(&task);
        return SERVE_GO_ON;
    }
    if (m.id == TF_TASK_STOP) {
        put_back(st->c, &task); /* so every other worker sees it too */
        return TF_SERVE_STOPPED;
    }
    if (tf_task_excludes(&m, st->id)) {
        pass_on(st, &task, m.id);
        return SERVE_GO_ON;
    }
    st->bounces = 0;
    tf_tuple_clear(&task);
    return answer_task(st, &m);
}

int tf_worker_serve_from(ts_client *c, int64_t id, const tf_exr_layout *layout,
                         const tf_worker_step *step, tf_tuple *first)
{
    serve_state st;
    if (serve_begin(&st, c, id, layout, step, first))
        return TF_SERVE_LOST;
    int status = SERVE_GO_ON;
    while (status == SERVE_GO_ON)
        status = serve_one(&st);
    serve_end(&st);
    return status;
}

/* ---- the real worker: a backend renders the rectangle ---- */

/* A sequence's frames differ only in camera and sun: the worker keeps its terrain and its one
 * backend for the whole sequence, and when a task is of another frame than the last one it
 * points the backend at a copy of the scene with that frame's camera and sun
 * (tf_scene_at_frame, tf_backend_set_scene: a new camera setup, and for OpenCL an upload of a
 * few hundred bytes of parameters).  Tasks come in frame order, the next frame's first ones
 * mixed with the last of the frame before, so the two latest frames' scene copies are kept. */
#define FRAME_CACHE 2

typedef struct frame_scene {
    int frame;
    tf_scene *scene;     /* owned; NULL: empty */
    uint64_t used;       /* for least-recently-used replacement */
} frame_scene;

typedef struct backend_ctx {
    tf_backend *b;
    const tf_scene *s;   /* the scene as parsed (a still's, or frame 0's camera) */
    int frame;           /* the frame b renders now: -1 = s itself */
    frame_scene frames[FRAME_CACHE];
    uint64_t uses;
} backend_ctx;

/* The scene of `frame`, from the cache or made (replacing the least recently used copy, never
 * the one the backend renders now). */
static const tf_scene *scene_of_frame(backend_ctx *bc, int frame)
{
    frame_scene *victim = NULL;
    for (int i = 0; i < FRAME_CACHE; i++) {
        frame_scene *f = &bc->frames[i];
        if (f->scene && f->frame == frame) {
            f->used = ++bc->uses;
            return f->scene;
        }
        if (f->scene && f->frame == bc->frame)
            continue;
        if (!victim || !f->scene || (victim->scene && f->used < victim->used))
            victim = f;
    }
    tf_scene *copy = victim ? tf_scene_at_frame(bc->s, frame) : NULL;
    if (!copy)
        return NULL;
    tf_scene_free(victim->scene);
    *victim = (frame_scene){frame, copy, ++bc->uses};
    return copy;
}

/* Point the backend at `frame` (-1: a still's task). */
static int backend_to_frame(backend_ctx *bc, int frame, char *err, size_t errlen)
{
    const tf_animation *a = &bc->s->animation;
    if (a->frames == 0 && frame != -1)
        return tf_seterr(err, errlen, "task for frame %d of a still scene", frame);
    if (a->frames > 0 && (frame < 0 || frame >= a->frames))
        return tf_seterr(err, errlen, "task for frame %d of a %d-frame animation", frame,
                         a->frames);
    if (frame == bc->frame)
        return 0;
    const tf_scene *fs = scene_of_frame(bc, frame);
    if (!fs)
        return tf_seterr(err, errlen, "out of memory");
    if (tf_backend_set_scene(bc->b, fs, err, errlen))
        return -1;
    bc->frame = frame;
    return 0;
}

static void backend_ctx_free(backend_ctx *bc)
{
    for (int i = 0; i < FRAME_CACHE; i++)
        tf_scene_free(bc->frames[i].scene);
}

static int backend_render(void *ctx, int frame, tf_rect rect, tf_pixel *px,
                          tf_render_counts *counts, int64_t *busy_ns, char *err, size_t errlen)
{
    backend_ctx *bc = ctx;
    if (rect.x + rect.w > bc->s->width || rect.y + rect.h > bc->s->height)
        return tf_seterr(err, errlen, "task rectangle outside the image");
    int64_t t0 = tf_now_ns();
    int rc = backend_to_frame(bc, frame, err, errlen) ? -1
             : tf_backend_render(bc->b, rect, px, counts, err, errlen);
    *busy_ns = tf_now_ns() - t0;
    return rc;
}

int tf_worker_loop(ts_client *c, const tf_scene *s, const tf_heightfield *hf, const char *kind,
                   const char *backend_name)
{
    char err[1024];
    ts_client_heartbeat(c, TF_WORKER_HEARTBEAT_MS);
    tf_backend *b = tf_backend_new(backend_name, s, hf, err, sizeof err);
    if (!b) {
        tf_error("%s", err);
        return TF_WORKER_EXIT_NOSTART;
    }
    tf_exr_layout layout;
    if (tf_worker_fetch_layout(c, &layout, err, sizeof err)) {
        tf_error("%s", err);
        tf_backend_free(b);
        return 1;
    }
    /* The hello and the first take leave together: when the coordinator counts this worker
     * as joined (--wait-workers), it is already waiting for a task. */
    int64_t id;
    tf_tuple first;
    tf_tuple_init(&first);
    if (tf_worker_join_take(c, kind, tf_backend_name(b), &id, &first)) {
        /* A refusal (this address is excluded) is final; a lost connection is not. */
        int refused = strstr(ts_client_error(c), "refused:") != NULL;
        if (refused)
            tf_error("cannot join the render: %s", ts_client_error(c));
        else
            tf_warn("cannot join the render: %s", ts_client_error(c));
        tf_tuple_clear(&first);
        tf_backend_free(b);
        return refused ? 1 : TF_WORKER_EXIT_LOST;
    }
    char tag[32];
    snprintf(tag, sizeof tag, "worker %" PRId64, id);
    tf_log_set_tag(tag);
    backend_ctx bc = {b, s, -1, {{0}}, 0};
    tf_worker_step step = {&bc, backend_render, s->width, s->height};
    int rc = tf_worker_serve_from(c, id, &layout, &step, &first);
    backend_ctx_free(&bc);
    if (rc == TF_SERVE_LOST)
        tf_warn("lost the coordinator: %s", ts_client_error(c));
    else if (rc == TF_SERVE_UNDELIVERED)
        tf_warn("cannot deliver a result (the coordinator deals that task again): %s",
                ts_client_error(c));
    tf_backend_free(b);
    tf_log_set_tag(NULL);
    return rc == TF_SERVE_STOPPED ? 0 : TF_WORKER_EXIT_LOST;
}

int tf_worker_fetch_layout(ts_client *c, tf_exr_layout *l, char *err, size_t errlen)
{
    tf_tuple tmpl, got;
    tf_tuple_init(&got);
    tf_scene_msg m;
    int rc = -1;
    if (tf_scene_tuple_template(&tmpl) || ts_rd(c, &tmpl, &got))
        tf_seterr(err, errlen, "cannot read the scene tuple: %s", ts_client_error(c));
    else if (tf_scene_tuple_unpack(&got, &m) ||
             tf_exr_layout_parse(m.layout, (int)m.width, (int)m.height, l))
        tf_seterr(err, errlen, "malformed output layout in the scene tuple");
    else
        rc = 0;
    tf_tuple_clear(&tmpl);
    tf_tuple_clear(&got);
    return rc;
}

tf_scene *tf_worker_fetch_scene(ts_client *c, const char *coordinator, char *err, size_t errlen)
{
    return tf_worker_fetch_scene_ex(c, coordinator, NULL, err, errlen);
}

tf_scene *tf_worker_fetch_scene_ex(ts_client *c, const char *coordinator, int *kind,
                                   char *err, size_t errlen)
{
    tf_tuple tmpl, got;
    tf_tuple_init(&got);
    tf_scene_msg m;
    if (tf_scene_tuple_template(&tmpl) || ts_rd(c, &tmpl, &got)) {
        tf_seterr(err, errlen, "%s: cannot read the scene: %s", coordinator, ts_client_error(c));
        goto fail;
    }
    if (tf_scene_tuple_unpack(&got, &m)) {
        tf_seterr(err, errlen, "%s: malformed scene tuple", coordinator);
        goto fail;
    }
    char perr[1024];
    tf_scene *s = tf_scene_parse_text("<coordinator scene>", m.text, strlen(m.text), perr,
                                      sizeof perr);
    if (!s) {
        tf_seterr(err, errlen, "%s: scene does not parse here: %s", coordinator, perr);
        goto fail;
    }
    tf_scene_set_size(s, (int)m.width, (int)m.height);
    /* an erosion's space (common/erosion_tuples.h) is computing the eroded terrain */
    int eroding = !strcmp(m.layout, TF_EROSION_LAYOUT);
    if (kind)
        *kind = eroding                               ? TF_SPACE_EROSION
                : !strcmp(m.layout, TF_PAINT_LAYOUT) ? TF_SPACE_PAINT
                                                      : TF_SPACE_RENDER;
    if (tf_heightmap_fetch(c, s, coordinator, err, errlen) ||
        (!eroding && tf_eroded_fetch(c, s, coordinator, err, errlen))) {
        tf_scene_free(s);
        goto fail;
    }
    if (strcmp(s->hash_hex, m.hash)) {
        snprintf(err, errlen,
                 "%s: the scene hashes differently here (%.12s vs %.12s): mismatched terrafarm "
                 "versions?",
                 coordinator, s->hash_hex, m.hash);
        tf_scene_free(s);
        goto fail;
    }
    tf_tuple_clear(&tmpl);
    tf_tuple_clear(&got);
    return s;
fail:
    tf_tuple_clear(&tmpl);
    tf_tuple_clear(&got);
    return NULL;
}
