/* fuzz_render.c: libFuzzer harness for what a worker does with a scene it accepted: build the
 * height field, prepare the renderer and render.  The input bytes are scene text (as
 * fuzz_scene.c); every scene that parses is rendered, so a scene the parser lets through can
 * never crash, hang or poison a render.  Besides "no crash, leak or hang" it checks:
 *   - a refusal (the parser's, the terrain build's or the renderer's) is one non-empty line;
 *   - every pixel of an accepted scene is finite (a worker reports a non-finite pixel as its
 *     task's failure, so a scene that makes one would fail on every worker: the parser must
 *     refuse it instead);
 *   - the image rendered whole and as four rectangles (cut where the input's hash says) has
 *     the same bits: the decomposition invariant of render.h, for any scene.
 * What costs time but not correctness is capped before the build so that a run takes
 * milliseconds: the image is at most 6x4 pixels, the grid at most 17x17 samples, at most 2
 * levels of antialiasing, 4 erosion steps, 4 weathering iterations, 16 fault lines and 2
 * filter passes.  Of an animation, one frame (chosen by the input's hash).  A height map
 * (generator = file) has no bytes here: the build refuses it with its one line.
 * Built by `make build/fuzz/fuzz_render` (clang libFuzzer) and replayed over
 * tests/corpus/render/ by `make test`. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "farmproto.h"
#include "log.h"
#include "render/render.h"
#include "scene.h"
#include "terrain/heightfield.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

#define CAP(field, most)                                                                       \
    do {                                                                                       \
        if ((field) > (most))                                                                  \
            (field) = (most);                                                                  \
    } while (0)

static void check_line(const char *err)
{
    if (err[0] == '\0' || strchr(err, '\n'))
        abort(); /* every refusal is exactly one non-empty line */
}

/* The caps of the header comment. */
static void make_cheap(tf_scene *s)
{
    int w = s->width < 6 ? s->width : 6, h = s->height < 4 ? s->height : 4;
    tf_scene_set_size(s, w, h);
    tf_terrain *t = &s->terrain;
    CAP(t->size_exp, 4);
    CAP(t->erosion.fluvial_steps, 4);
    CAP(t->thermal_iterations, 4);
    CAP(t->faults, 16);
    CAP(t->wind_passes, 2);
    CAP(t->rain_passes, 2);
    CAP(s->antialias.max_depth, 2);
}

/* Render rectangle rect into its place in the image img (w pixels a row). */
static void render_into(const tf_renderer *r, tf_rect rect, int w, tf_pixel *img)
{
    tf_pixel *px = calloc((size_t)rect.w * (size_t)rect.h, sizeof *px);
    if (!px)
        abort();
    tf_render_counts counts;
    memset(&counts, 0, sizeof counts);
    tf_render_rect(r, rect, px, &counts);
    for (int y = 0; y < rect.h; y++)
        memcpy(&img[(size_t)(rect.y + y) * (size_t)w + (size_t)rect.x],
               &px[(size_t)y * (size_t)rect.w], sizeof *px * (size_t)rect.w);
    free(px);
}

/* The image once whole and once as four rectangles cut where `cut` says: every pixel finite,
 * and the same bits both ways (the decomposition invariant, render.h). */
static void render_all(const tf_scene *s, tf_heightfield *hf, uint32_t cut)
{
    char err[512] = "";
    tf_render_prepare(s, hf, 1);
    tf_renderer *r = tf_renderer_new(s, hf, err, sizeof err);
    if (!r) {
        check_line(err);
        return;
    }
    const int w = s->width, h = s->height;
    const size_t n = (size_t)w * (size_t)h;
    tf_pixel *whole = calloc(n, sizeof *whole), *parts = calloc(n, sizeof *parts);
    if (!whole || !parts)
        abort();
    render_into(r, (tf_rect){0, 0, w, h}, w, whole);
    if (tf_first_non_finite(whole, n) >= 0)
        abort(); /* an accepted scene rendered a NaN or an infinity */
    const int cx = w > 1 ? 1 + (int)(cut % (uint32_t)(w - 1)) : w;
    const int cy = h > 1 ? 1 + (int)((cut >> 16) % (uint32_t)(h - 1)) : h;
    const tf_rect quarters[4] = {{0, 0, cx, cy}, {cx, 0, w - cx, cy}, {0, cy, cx, h - cy},
                                 {cx, cy, w - cx, h - cy}};
    for (int q = 0; q < 4; q++)
        if (quarters[q].w > 0 && quarters[q].h > 0)
            render_into(r, quarters[q], w, parts);
    if (memcmp(whole, parts, sizeof *whole * n) != 0)
        abort(); /* a pixel depends on how the image was cut into tasks */
    free(whole);
    free(parts);
    tf_renderer_free(r);
}

/* Where to cut the image: from the input's bytes (FNV-1a), so a replay cuts the same way. */
static uint32_t cut_of(const uint8_t *data, size_t size)
{
    uint32_t hash = 2166136261u;
    for (size_t i = 0; i < size; i++)
        hash = (hash ^ data[i]) * 16777619u;
    return hash;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char err[512] = "";
    tf_log_set_level(TF_LOG_ERROR); /* the erosion's progress lines, not the fuzzer's output */
    tf_scene *s = tf_scene_parse_text("fuzz", (const char *)data, size, err, sizeof err);
    if (!s) {
        check_line(err);
        return 0;
    }
    make_cheap(s);
    const uint32_t cut = cut_of(data, size);
    if (s->animation.frames > 1) /* one frame of the sequence, the same one on every replay */
        tf_scene_apply_frame(s, (int)(cut % (uint32_t)s->animation.frames));
    tf_heightfield *hf = tf_heightfield_build(s, 1, err, sizeof err);
    if (hf)
        render_all(s, hf, cut);
    else
        check_line(err);
    tf_heightfield_free(hf);
    tf_scene_free(s);
    return 0;
}
