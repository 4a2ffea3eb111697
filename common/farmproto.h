/* farmproto.h: the render farm's conversation, as tuples in the tuple space (tuple.h).  The
 * coordinator's supervisor and every worker (forked or networked) speak only these:
 *
 *   ("scene", text:S, width:I, height:I, hash:S)        rd by networked workers (tsnet model)
 *   ("next_worker", n:I)                                in + out n+1: a worker takes an id
 *   ("hello", worker:I, kind:S, host:S, pid:I, backend:S)  a worker announces itself
 *   ("task", id:I, x:I, y:I, w:I, h:I, excluded:B)     a rectangle to render; id < 0 = stop
 *   ("result", id:I, worker:I, primary:I, shadow:I, external:I, busy_ns:I, pixels:B)
 *   ("failed", id:I, worker:I, message:S)              a worker could not render a task
 *
 * `excluded` is a list of little-endian int64 worker ids that must not render this task (it
 * failed on them repeatedly): such a worker puts the tuple back and waits a little.
 * `pixels` is w*h tf_pixels, row-major, each 6 little-endian IEEE floats (r g b a z spp).
 * The stop task (id TF_TASK_STOP) is put back by every worker that takes it, so one tuple stops
 * them all. */
#ifndef TF_FARMPROTO_H
#define TF_FARMPROTO_H

#include <stddef.h>
#include <stdint.h>

#include "image/pixel.h"
#include "render/counts.h"
#include "linda/tuple.h"

#define TF_TASK_STOP (-1)
#define TF_EXCLUDED_MAX 64
#define TF_PIXEL_WIRE_BYTES 24

typedef struct tf_task_msg {
    int64_t id;
    tf_rect rect;
    int nexcluded;
    int64_t excluded[TF_EXCLUDED_MAX];
} tf_task_msg;

typedef struct tf_result_msg {
    int64_t id, worker;
    tf_render_counts counts; /* primary, shadow, external (pixels = w*h) */
    int64_t busy_ns;
    const uint8_t *pixels;   /* borrowed from the tuple */
    size_t pixels_len;
} tf_result_msg;

int tf_task_pack(tf_tuple *t, const tf_task_msg *m);
/* Template for any task (id = TF_TASK_ANY) or for one task id. */
#define TF_TASK_ANY INT64_MIN
int tf_task_template(tf_tuple *t, int64_t id);
/* 0, or -1 if t is not a well-formed task tuple. */
int tf_task_unpack(const tf_tuple *t, tf_task_msg *m);
int tf_task_excludes(const tf_task_msg *m, int64_t worker);

/* Packs w*h pixels into a result tuple. */
int tf_result_pack(tf_tuple *t, int64_t id, int64_t worker, const tf_render_counts *c,
                   int64_t busy_ns, const tf_pixel *px, size_t npx);
int tf_result_template(tf_tuple *t, int64_t id /* < 0: any */, int64_t worker /* < 0: any */);
int tf_result_unpack(const tf_tuple *t, tf_result_msg *m);
/* Decode n pixels from the wire form. */
void tf_pixels_decode(const uint8_t *wire, tf_pixel *px, size_t n);

/* Largest task a worker accepts, in pixels (a bound on its buffer, whatever a tuple says). */
#define TF_TASK_MAX_PIXELS (64u * 1024u * 1024u)
/* Why a task rectangle cannot be rendered in an image_w x image_h image (0: size unknown, only
 * the rectangle itself is checked), or NULL if it can. */
const char *tf_task_rect_problem(tf_rect r, int image_w, int image_h);
/* Index of the first pixel with a non-finite channel, or -1. */
long tf_first_non_finite(const tf_pixel *px, size_t n);

#endif
