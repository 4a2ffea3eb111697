/* farmproto.h: the render farm's conversation, as tuples in the tuple space (tuple.h).  The
 * coordinator's supervisor and every worker (forked or networked) speak only these:
 *
 *   ("scene", text:S, width:I, height:I, hash:S, layout:S)  rd by networked workers (tsnet)
 *   ("heightmap", bytes:I, chunks:I, sha256:S)          generator = file: the height map's
 *   ("heightmap_chunk", index:I, data:B)                bytes, rd by networked workers
 *                                                       (heightmap_tuples.h)
 *   ("next_worker", n:I)                                in + out n+1: a worker takes an id
 *   ("hello", worker:I, kind:S, host:S, pid:I, backend:S)  a worker announces itself
 *   ("task", id:I, frame:I, x:I, y:I, w:I, h:I, excluded:B)  a rectangle of a frame to render;
 *                                                       id < 0 = stop
 *   ("result", id:I, worker:I, primary:I, shadow:I, external:I, busy_ns:I, spp_total:I,
 *              samples:I, hits:I, evictions:I,
 *              index:B, chunks:B, preview:B)                    the task's finished EXR chunks
 *   ("failed", id:I, worker:I, message:S)              a worker could not render a task
 *
 * `frame` is the frame of an [animation] scene whose camera renders the rectangle (0 ..
 * frames-1), or -1 for a still scene; ids run on across the frames of a sequence.
 * `excluded` is a list of little-endian int64 worker ids that must not render this task (it
 * failed on them repeatedly): such a worker puts the tuple back and waits a little.
 * `layout` is the output file's shape (image/exrlayout.h, tf_exr_layout_format): "scanline half",
 * "tiled 64x64 float", ...; workers encode their chunks for exactly that file.
 *
 * THE RESULT FORMAT.  Workers encode; the coordinator moves bytes.  A result carries the
 * task's rectangle as finished OpenEXR chunks, packed (compressed) by the worker with
 * OpenEXRCore's encode pipeline for the output's layout, ready for exr_write_scanline_chunk /
 * exr_write_tile_chunk.  primary, shadow, external are the rays the task cost; busy_ns its
 * render time; spp_total the sum of its pixels' spp channel (for samples_per_pixel_avg: the
 * coordinator never sees a pixel); samples, hits, evictions what it cost the worker's procedural
 * terrain cache (tilecache.h; 0 on a grid), the worker's word only, reported, never trusted.  All integers in the blobs little-endian.
 *   index    n records of TF_CHUNK_RECORD_BYTES (24) bytes, one per chunk, in file order
 *            (increasing y; tiles left to right within a tile row):
 *                int32 cx, int32 cy      scanline: 0 and the chunk's row y;
 *                                        tiled: the tile's indices (x / tile_w, y / tile_h)
 *                int64 packed            bytes of this chunk in `chunks`, 1 .. unpacked
 *                                        (packed == unpacked means stored uncompressed, as
 *                                        OpenEXR does when compression would not help)
 *                int64 unpacked          bytes it decodes to: w * h * (16 half | 24 float)
 *   chunks   the n packed chunks, concatenated in index order (length = sum of packed)
 *   preview  the task's share of the progress preview: the preview pixels whose source pixel
 *            lies in the rectangle (tf_preview_span), row-major, 3 bytes sRGB each
 * A result is structurally valid for task T (tf_result_check, no per-pixel work) when: n and
 * every (cx, cy) are exactly T's chunks in file order (tf_layout_rect_chunks); every unpacked
 * equals what the layout says for that chunk; 1 <= packed <= unpacked; the packed sizes sum to
 * the length of `chunks`; and `preview` has exactly T's preview pixels * 3 bytes.  Anything else
 * is refused: the result is dropped, counted against its worker, and the task dealt again.
 * (Whether the packed bytes decode is checked only with --verify-chunks.)
 * The stop task (id TF_TASK_STOP) is put back by every worker that takes it, so one tuple stops
 * them all. */
#ifndef TF_FARMPROTO_H
#define TF_FARMPROTO_H

#include <stddef.h>
#include <stdint.h>

#include "image/exrlayout.h"
#include "image/pixel.h"
#include "render/counts.h"
#include "linda/tuple.h"

/* The tags (first fields) of the six kinds of tuple, and how many fields each has. */
#define TF_TAG_SCENE "scene"
#define TF_TAG_NEXT_WORKER "next_worker"
#define TF_TAG_HELLO "hello"
#define TF_TAG_TASK "task"
#define TF_TAG_RESULT "result"
#define TF_TAG_FAILED "failed"
#define TF_SCENE_FIELDS 6
#define TF_NEXT_WORKER_FIELDS 2
#define TF_HELLO_FIELDS 6
#define TF_FAILED_FIELDS 4

/* Liveness: a worker that has sent nothing for TF_HEARTBEAT_MS pings its coordinator, busy or
 * idle (linda/tsclient.c), and a coordinator's silence timeout (--lease-timeout) is at least
 * TF_LEASE_MIN_MS, four intervals, so a live worker is never taken for a silent one. */
#define TF_HEARTBEAT_MS 250
#define TF_LEASE_MIN_MS (4 * TF_HEARTBEAT_MS)

#define TF_TASK_STOP (-1)
#define TF_EXCLUDED_MAX 64

/* The scene tuple: strings borrowed from the tuple it was unpacked from. */
typedef struct tf_scene_msg {
    const char *text;
    int64_t width, height;
    const char *hash, *layout;
} tf_scene_msg;

/* A worker's hello: strings borrowed from the tuple. */
typedef struct tf_hello_msg {
    int64_t worker;
    const char *kind, *host;
    int64_t pid;
    const char *backend;
} tf_hello_msg;

/* A worker's report that it could not render a task: message borrowed from the tuple. */
typedef struct tf_failed_msg {
    int64_t id, worker;
    const char *message;
} tf_failed_msg;

typedef struct tf_task_msg {
    int64_t id;
    int frame;          /* -1: a still; else the frame of the scene's animation */
    tf_rect rect;
    int nexcluded;
    int64_t excluded[TF_EXCLUDED_MAX];
} tf_task_msg;

typedef struct tf_result_msg {
    int64_t id, worker;
    tf_render_counts counts; /* primary, shadow, external; pixels = 0 until checked */
    int64_t busy_ns;
    int64_t spp_total;
    const uint8_t *index;    /* borrowed from the tuple: nchunks records */
    size_t nchunks;
    const uint8_t *chunks;
    size_t chunks_len;
    const uint8_t *preview;
    size_t preview_len;
} tf_result_msg;

int tf_scene_tuple_pack(tf_tuple *t, const tf_scene_msg *m);
int tf_scene_tuple_template(tf_tuple *t);
/* Fields and types, and an image size of 1..65536 each way: 0, or -1. */
int tf_scene_tuple_unpack(const tf_tuple *t, tf_scene_msg *m);

/* The worker counter, holding the next free worker id n. */
int tf_next_worker_pack(tf_tuple *t, int64_t n);
int tf_next_worker_template(tf_tuple *t);
int tf_next_worker_unpack(const tf_tuple *t, int64_t *n);

int tf_hello_pack(tf_tuple *t, const tf_hello_msg *m);
int tf_hello_unpack(const tf_tuple *t, tf_hello_msg *m);

int tf_failed_pack(tf_tuple *t, int64_t id, int64_t worker, const char *message);
/* Template for the failure of task id by worker (either < 0: any). */
int tf_failed_template(tf_tuple *t, int64_t id, int64_t worker);
int tf_failed_unpack(const tf_tuple *t, tf_failed_msg *m);

int tf_task_pack(tf_tuple *t, const tf_task_msg *m);
/* Template for any task (id = TF_TASK_ANY) or for one task id. */
#define TF_TASK_ANY INT64_MIN
/* Fields of a task tuple and of a result tuple (the layouts above). */
#define TF_TASK_FIELDS 8
#define TF_RESULT_FIELDS 14
#define TF_RESULT_INDEX_FIELD 11 /* index, chunks, preview: the last three */

int tf_task_template(tf_tuple *t, int64_t id);
/* 0, or -1 if t is not a well-formed task tuple. */
int tf_task_unpack(const tf_tuple *t, tf_task_msg *m);
int tf_task_excludes(const tf_task_msg *m, int64_t worker);

int tf_result_pack(tf_tuple *t, int64_t id, int64_t worker, const tf_render_counts *c,
                   int64_t busy_ns, int64_t spp_total, const tf_chunk_payload *p);
int tf_result_template(tf_tuple *t, int64_t id /* < 0: any */, int64_t worker /* < 0: any */);
/* Fields and types only: 0, or -1 if t is not a well-formed result tuple. */
int tf_result_unpack(const tf_tuple *t, tf_result_msg *m);
/* The structural check described above, of m against the task rectangle r of an output with
 * layout l and preview grid g: 0, or -1 with a one-line reason.  Costs O(chunks), never touches
 * a pixel.  On success m->counts.pixels = r.w * r.h. */
int tf_result_check(tf_result_msg *m, const tf_exr_layout *l, const tf_preview_grid *g,
                    tf_rect r, char *err, size_t errlen);

/* Counts no render of task rectangle r could have reached with antialiasing depth aa_depth
 * (render.c: at most (2^depth + 1)^2 samples per pixel, each with at most one shadow ray; the
 * external samples are among the primary ones): 0, or -1 with a one-line reason.  A result's
 * counts are summed into the statistics, so a lie here would make them overflow. */
int tf_result_counts_check(const tf_result_msg *m, tf_rect r, int aa_depth, char *err,
                           size_t errlen);

/* Largest task a worker accepts, in pixels (a bound on its buffer, whatever a tuple says). */
#define TF_TASK_MAX_PIXELS (64u * 1024u * 1024u)
/* Why a task rectangle cannot be rendered in an image_w x image_h image (0: size unknown, only
 * the rectangle itself is checked), or NULL if it can. */
const char *tf_task_rect_problem(tf_rect r, int image_w, int image_h);
/* Index of the first pixel with a non-finite channel, or -1. */
long tf_first_non_finite(const tf_pixel *px, size_t n);

#endif
