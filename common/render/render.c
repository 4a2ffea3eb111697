/* render.c: tf_render_rect, adaptive antialiasing over a rectangle of the image.
 *
 * A rectangle walks its pixel rows bottom to top, keeping two rows of pixel-corner samples (the
 * row above and the row below the current pixel row, w+1 samples each).  The last corner row
 * and column lie outside the rectangle ("external samples", counted in external_rays): they are
 * computed here rather than borrowed from a neighbour, so tasks never wait on each other.
 *
 * Bottom to top for coherence (trace.h): a camera ray climbs above the ray below it, so traced
 * after it, it starts its walk where that one hit (tf_trace_coherent), if the terrain's slope
 * allows; and its shadow ray is first looked for under the surface where that one's went under
 * (tf_occluded_coherent).  Each corner sample's record is kept beside it (a sample inside a
 * pixel helps no other ray, and keeps none).  A corner row's ray is helped
 * by the highest ray traced below it in its lattice column (each column's highest record is
 * handed up to the next pixel row); a sample inside a pixel by the nearest of the corner rays
 * up to TF_LOWER_ROWS corner rows down that vouches for part of its walk (lower_rays), the
 * corner rows' records being kept that long (rect_state's ring).
 *
 * Each pixel then refines itself (render_pixel): starting from its 4 corners it pops quads off a
 * small explicit stack.  A quad's contrast is the widest per-channel range of its samples'
 * display levels (sqrt of the linear value, clamped to [0, 1]: close to the sRGB curve a viewer
 * sees).  A quad of size S lattice steps has split threshold T * (N/S)^3 (T =
 * antialias.threshold); if its corners' range passes TF_AA_PROBE_FRACTION (1/10) of that, its
 * centre is traced
 * (the probe), and if the range of all five passes the threshold it splits into four, down to
 * quads of one lattice step.  A probed leaf is worth corners/8 + centre/2 (the quincunx
 * estimate, much closer to the pixel's area average than the corners' mean); a flat leaf is
 * worth its corners' mean.  Samples inside the pixel
 * are cached on the pixel's (N+1)^2 lattice so shared quad corners are traced once, and those
 * on the edges it shares with the pixels before it in the rectangle (left, and below) are
 * taken from them (pixel_edge) rather than traced again.  Because
 * every sample is a function of its lattice point only (render_internal.h) and the pixel's
 * refinement looks at nothing but its own samples, a pixel's bits do not depend on the
 * rectangle: THE DECOMPOSITION INVARIANT.  No recursion and no function pointers, so the same
 * loop ports to OpenCL C.
 *
 * A corner row's samples are coherent camera rays: on a grid terrain with coherence off
 * (tf_render_coherence_force, TF_COHERENCE=0) they are traced together in SIMD packets
 * (trace_packet.h), on a procedural terrain in packets through its quad-tree
 * (tf_proc_trace_packet), then shaded up to their shadow rays, which are traced together too,
 * then finished (tf_shade_begin / tf_shade_end): the same bits as one tf_shade_ray a sample.
 * Whether packets are used is row_packets' choice (TF_TRACE_PACKETS; unset, a grid's with the
 * AVX-512 kernel only, a procedural terrain's always).  A pixel's inner samples are traced one
 * at a time. */
#include "render/render.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "log.h"
#include "render/render_internal.h"
#include "render/sample_math.h"
#include "render/sun_strips.h"
#include "render/trace_packet.h"
#include "render/trace_procedural.h"
#include "terrain/tilecache.h"

/* Are the sun's strips worth their build (about 5 ns a cell) for this image?  A render casts
 * some 3.5 shadow rays a pixel, and each lit one is ~70 ns shorter with them: from about a
 * pixel per 64 cells (at 480x270 over 2049^2 samples, one per 32, the render proper with them,
 * build included, measured 0.986x of one without).  Only the time depends on it. */
static int sun_strips_pay(const tf_scene *s, const tf_heightfield *hf)
{
    const double cells = (double)hf->cells * (double)hf->cells;
    return !hf->proc && (double)s->width * (double)s->height * 64.0 >= cells;
}

tf_renderer *tf_renderer_new(const tf_scene *s, const tf_heightfield *hf, char *err, size_t errlen)
{
    if (!s || !hf) {
        tf_seterr(err, errlen, "renderer: no scene or no height field");
        return NULL;
    }
    if (s->antialias.max_depth < 0 || s->antialias.max_depth > TF_AA_MAX_DEPTH) {
        tf_seterr(err, errlen, "renderer: antialias max_depth %d outside 0..%d",
                 s->antialias.max_depth, TF_AA_MAX_DEPTH);
        return NULL;
    }
    if (!(s->antialias.threshold >= 0)) {
        tf_seterr(err, errlen, "renderer: antialias threshold must be >= 0");
        return NULL;
    }
    /* lattice coordinates must fit comfortably in int64 and in a double's integers */
    if (s->width > (1 << 24) || s->height > (1 << 24)) {
        tf_seterr(err, errlen, "renderer: image %dx%d too large", s->width, s->height);
        return NULL;
    }
    tf_renderer *r = calloc(1, sizeof *r);
    if (!r) {
        tf_seterr(err, errlen, "renderer: out of memory");
        return NULL;
    }
    if (tf_camera_init(&r->camera, s, err, errlen) != 0) {
        free(r);
        return NULL;
    }
    r->scene = s;
    r->hf = hf;
    tf_shader_init(&r->shader, s, hf);
    r->depth = s->antialias.max_depth;
    r->lattice = 1 << r->depth;
    r->threshold = s->antialias.threshold;
    r->jitter_key = tf_hash64(s->terrain.seed ^ 0x6a69747465724b59ULL);
    if (sun_strips_pay(s, hf)) {
        const tf_sun_strips *kept = tf_sun_strips_kept(hf, r->shader.sun_dir);
        r->shader.sun_strips =
            kept ? kept : (r->sun_strips = tf_sun_strips_build(hf, r->shader.sun_dir));
    }
    return r;
}

void tf_renderer_free(tf_renderer *r)
{
    if (r)
        tf_sun_strips_free(r->sun_strips);
    free(r);
}

void tf_render_prepare(const tf_scene *s, tf_heightfield *hf, int threads)
{
    if (s && hf && sun_strips_pay(s, hf))
        tf_sun_strips_keep(hf, tf_sun_direction(s), threads);
}

static int coherence_forced = -1;

void tf_render_coherence_force(int on) { coherence_forced = on < 0 ? -1 : on != 0; }

/* Samples helped by the ones below them (trace.h's coherence, the top of this file): on a grid
 * terrain, unless forced off or TF_COHERENCE=0.  Never changes a bit, only the time. */
static int coherence_on(const tf_renderer *r)
{
    if (r->hf->proc)
        return 0;
    if (coherence_forced >= 0)
        return coherence_forced;
    const char *v = getenv("TF_COHERENCE");
    return !(v && !strcmp(v, "0"));
}

/* tf_render_lattice_sample with its rays traced coherently (tf_shade_ray_coherent). */
static void lattice_sample_coherent(const tf_renderer *r, int64_t X, int64_t Y,
                                    const tf_sample_record *lower, tf_sample_record *mine,
                                    tf_sample *out, uint64_t *shadow_rays)
{
    double x, y;
    tf_lattice_position(r->jitter_key, (double)r->lattice, X, Y, &x, &y);
    tf_shade_ray_coherent(&r->shader, r->camera.position, tf_camera_dir(&r->camera, x, y), lower,
                          mine, out, shadow_rays);
}

void tf_render_point(const tf_renderer *r, double x, double y, tf_sample *out,
                     uint64_t *shadow_rays)
{
    tf_vec3 dir = tf_camera_dir(&r->camera, x, y);
    tf_shade_ray(&r->shader, r->camera.position, dir, out, shadow_rays);
}

void tf_render_lattice_sample(const tf_renderer *r, int64_t X, int64_t Y, tf_sample *out,
                              uint64_t *shadow_rays)
{
    double x, y;
    tf_lattice_position(r->jitter_key, (double)r->lattice, X, Y, &x, &y);
    tf_render_point(r, x, y, out, shadow_rays);
}

void tf_render_corner(const tf_renderer *r, int cx, int cy, float rgb[3], tf_render_counts *counts)
{
    tf_sample s;
    uint64_t shadow = 0;
    tf_render_lattice_sample(r, (int64_t)cx * r->lattice, (int64_t)cy * r->lattice, &s, &shadow);
    rgb[0] = (float)s.r;
    rgb[1] = (float)s.g;
    rgb[2] = (float)s.b;
    if (counts) {
        counts->primary_rays++;
        counts->shadow_rays += shadow;
    }
}

/* A sample channel as the eye sees it: the square root of the linear value (close to the sRGB
 * curve the preview and the benchmark's PSNR use), clamped to the displayable [0, 1] since
 * differences above white or below black never show.  sqrt is correctly rounded in IEEE and in
 * OpenCL C, so the kernel makes the same decisions bit for bit. */
double tf_display_level(double v) { return tf_display_level_of(v); }

/* A channel value clamped to [0, 1] as tf_display_level clamps it (NaN: 0): its level is the
 * square root of this, bit for bit (sqrt(0) = 0, sqrt(1) = 1). */
static inline double level_argument(double v)
{
    return v > 0.0 ? (v < 1.0 ? v : 1.0) : 0.0;
}

/* The lowest and highest clamped value (level_argument) of each channel over some samples:
 * a quad's four corners, then its centre too. */
typedef struct level_span {
    double lo[3], hi[3];
} level_span;

static inline void span_add(level_span *sp, const tf_sample *s)
{
    const double v[3] = {level_argument(s->r), level_argument(s->g), level_argument(s->b)};
    for (int ch = 0; ch < 3; ch++) {
        sp->lo[ch] = v[ch] < sp->lo[ch] ? v[ch] : sp->lo[ch];
        sp->hi[ch] = v[ch] > sp->hi[ch] ? v[ch] : sp->hi[ch];
    }
}

static inline level_span span_of_corners(const tf_sample *const s[4])
{
    level_span sp = {{1, 1, 1}, {0, 0, 0}};
    for (int k = 0; k < 4; k++)
        span_add(&sp, s[k]);
    return sp;
}

/* The largest per-channel range of display levels over a span's samples.  A correctly
 * rounded sqrt is monotone, so a channel's lowest and highest levels are the levels of its
 * lowest and highest clamped values: two square roots a channel, not one a sample (the
 * square roots were 5% of a render's CPU).  The same differences as packet_render.cl's
 * display_range over its stored levels, so both backends split the same quads. */
static double display_range(const level_span *sp)
{
    double widest = 0;
    for (int ch = 0; ch < 3; ch++) {
        double range = sqrt(sp->hi[ch]) - sqrt(sp->lo[ch]);
        if (range > widest)
            widest = range;
    }
    return widest;
}

/* Per-pixel sample cache on the pixel's (N+1) x (N+1) lattice.  With coherence, `column`: the
 * rectangle's record for each of the pixel's two corner columns of the highest ray traced in
 * it below this pixel row (NULL: no coherence), and `rows`.  have[k] says what the pixel holds
 * at point k: 0 nothing, 1 a sample it has used, 2 a sample a neighbour took on their shared
 * edge (pixel_edge), not used yet.  `used` lists the points used beyond the four corners (most
 * pixels use none): what the pixel's end reads and clears instead of the whole lattice. */
typedef struct pixel_cache {
    int side;           /* N + 1 */
    tf_sample *sample;  /* side * side */
    unsigned char *have; /* side * side, all 0 between pixels */
    int *used, nused;   /* side * side */
    int took;           /* an edge handed the pixel samples (take_edge) */
    tf_sample_record *column;
    /* rows[m]: the records of the pixel's two corner columns m + 1 corner rows below its top
     * corner row (rows[m][0] left, rows[m][1] right), m < nrows <= TF_LOWER_ROWS */
    const tf_sample_record *rows[TF_LOWER_ROWS];
    int nrows;
} pixel_cache;

/* The records of rays traced below local lattice point (i, j) of the pixel, j < N, that may
 * vouch for part of its camera ray (trace.h's coherence: any lower ray from the camera may;
 * trace.c's D decides how much), in the order worth asking: the corner rows below, nearest
 * first (a higher ray hits further on, so vouches for more), in the nearest corner column,
 * and from the third row down the other column too.  Nearer rows and the other column are
 * often too close in climb to outclimb the terrain's slope across the two rays' offset in
 * heading; then a row further down vouches (default.scene at 480x270 over 2049^2 samples,
 * aa-eq: of the inner samples the first row vouches for 14%, the second for 27%, the third
 * for 43% (its other column for 16 of them), the fourth for 15%, none for 0.4%; 4.4% fewer
 * instructions in the render than the fifth row's corner alone).  Returns how many. */
static int lower_rays(const pixel_cache *pc, int i, const tf_ray_clear *out[2 * TF_LOWER_ROWS])
{
    const int near = 2 * i >= pc->side - 1;
    int n = 0;
    for (int m = 0; m < pc->nrows; m++) {
        out[n++] = &pc->rows[m][near].camera;
        if (m >= 2)
            out[n++] = &pc->rows[m][!near].camera;
    }
    return n;
}

/* A pixel's corners: samples c[0..3] (top left, top right, bottom left, bottom right) and,
 * with coherence, their rays' records k[0..3]. */
typedef struct corners {
    const tf_sample *c[4];
    const tf_sample_record *k[4];
} corners;

/* After a pixel: each of its corner columns' highest ray, its top corner's, is the one the
 * corner row above wants below it (corner_row_coherent).  Only corner rays keep their
 * records: a sample inside a pixel helps no other ray. */
static void note_columns(const pixel_cache *pc, const corners *cs)
{
    pc->column[0] = *cs->k[0];
    pc->column[1] = *cs->k[1];
}

/* The nearest distance among the samples the pixel used (its corners and pc->used). */
static float nearest_dist(const pixel_cache *pc, const size_t at[4])
{
    float zmin = TF_SKY_DIST;
    for (int q = 0; q < 4; q++)
        zmin = pc->sample[at[q]].dist < zmin ? pc->sample[at[q]].dist : zmin;
    for (int t = 0; t < pc->nused; t++)
        zmin = pc->sample[pc->used[t]].dist < zmin ? pc->sample[pc->used[t]].dist : zmin;
    return zmin;
}

/* The samples on one lattice line between two pixels of a row or column, its N - 1 inner
 * points (the ends are corners): what the pixel on one side took there, for the pixel on the
 * other.  Pixels go left to right along a row and rows bottom to top, so a pixel hands its
 * right edge to the next pixel and its top edge to the pixel above; it takes its left edge and
 * its bottom edge from them.  A sample is a function of its lattice point only
 * (render_internal.h), so a pixel that takes one holds what tracing it would have given: the
 * same bits, one ray fewer.  On default.scene 480x270 one inner sample in six lies on an edge
 * already traced. */
typedef struct pixel_edge {
    unsigned char *have;      /* 1: sample[m] holds inner point m's (only while *held) */
    tf_sample *sample;
    unsigned char *held;      /* 0: the edge holds nothing (most pixels use no inner point:
                               * their edges are neither scanned nor cleared) */
} pixel_edge;

/* Take an edge's samples into the pixel's lattice points k0, k0 + step, ...  as not used yet. */
static void take_edge(pixel_cache *pc, const pixel_edge *e, size_t k0, size_t step)
{
    if (!*e->held)
        return;
    pc->took = 1;
    for (int m = 0; m < pc->side - 2; m++)
        if (e->have[m]) {
            size_t k = k0 + (size_t)m * step;
            pc->have[k] = 2;
            pc->sample[k] = e->sample[m];
        }
}

/* Hand the samples the pixel used at lattice points k0, k0 + step, ... to an edge. */
static void hand_edge(const pixel_cache *pc, pixel_edge *e, size_t k0, size_t step)
{
    *e->held = 0;
    if (pc->nused == 0) /* only its corners */
        return;
    for (int m = 0; m < pc->side - 2; m++) {
        size_t k = k0 + (size_t)m * step;
        e->have[m] = pc->have[k] == 1;
        if (e->have[m])
            e->sample[m] = pc->sample[k], *e->held = 1;
    }
}

/* Clear what the pixel held (have[] all 0 again), given its corners. */
static void clear_pixel(pixel_cache *pc, const size_t at[4])
{
    const size_t side = (size_t)pc->side, N = side - 1;
    for (int q = 0; q < 4; q++)
        pc->have[at[q]] = 0;
    for (int t = 0; t < pc->nused; t++)
        pc->have[pc->used[t]] = 0;
    if (pc->took) /* taken, never used */
        for (size_t m = 1; m < N; m++)
            pc->have[m * side] = pc->have[N * side + m] = 0;
    pc->took = 0;
}

typedef struct quad { int i, j, size; } quad;

/* The sample at local lattice point (i, j) of the pixel, (X, Y) on the image's lattice, j < N,
 * its rays traced coherently: the camera ray helped by lower_rays, the shadow ray by the corner
 * nearest below (the nearest hit of a parallel ray). */
static void inner_sample_coherent(const tf_renderer *r, const pixel_cache *pc, int64_t X,
                                  int64_t Y, int i, tf_sample *out, uint64_t *shadow_rays)
{
    const tf_ray_clear *lowers[2 * TF_LOWER_ROWS];
    const int n = lower_rays(pc, i, lowers);
    double x, y;
    tf_lattice_position(r->jitter_key, (double)r->lattice, X, Y, &x, &y);
    tf_shade_ray_coherent_among(&r->shader, r->camera.position, tf_camera_dir(&r->camera, x, y),
                                lowers, n, &pc->rows[0][2 * i >= pc->side - 1].shadow, NULL,
                                out, shadow_rays);
}

/* cached_sample's first use of point k: trace it unless a neighbour handed it over, and note
 * it used. */
static __attribute__((noinline)) void first_use(const tf_renderer *r, pixel_cache *pc, int px,
                                                int py, int i, int j, size_t k, int *spp,
                                                tf_render_counts *tally)
{
    if (!pc->have[k]) {
        int64_t X = (int64_t)px * r->lattice + i, Y = (int64_t)py * r->lattice + j;
        if (pc->column)
            inner_sample_coherent(r, pc, X, Y, i, &pc->sample[k], &tally->shadow_rays);
        else
            tf_render_lattice_sample(r, X, Y, &pc->sample[k], &tally->shadow_rays);
        tally->primary_rays++;
    }
    pc->have[k] = 1;
    pc->used[pc->nused++] = (int)k;
    (*spp)++;
}

/* Sample at local lattice point (i, j) of pixel (px, py), tracing it on first use unless a
 * neighbour handed it over; *spp counts the samples the pixel uses, however they came.  The
 * pixel's quads ask for most of their corners again (a point already used: a load and a
 * compare here, the call only on a first use). */
static inline const tf_sample *cached_sample(const tf_renderer *r, pixel_cache *pc, int px,
                                             int py, int i, int j, int *spp,
                                             tf_render_counts *tally)
{
    const size_t k = (size_t)j * (size_t)pc->side + (size_t)i;
    if (pc->have[k] != 1)
        first_use(r, pc, px, py, i, j, k, spp, tally);
    return &pc->sample[k];
}

/* Refine pixel (px, py) whose four corner samples are given; write its value to *out.  `left`
 * holds the samples on its left edge and `below` those on its bottom edge (pixel_edge); they
 * get its right and its top edge's. */
static void render_pixel(const tf_renderer *r, pixel_cache *pc, int px, int py,
                         const corners *cs, pixel_edge *left, pixel_edge *below, tf_pixel *out,
                         tf_render_counts *tally)
{
    const int N = r->lattice;
    const size_t side = (size_t)pc->side;
    const size_t at[4] = {0, (size_t)N, (size_t)N * side, (size_t)N * side + (size_t)N};
    pc->nused = 0;
    take_edge(pc, left, side, side);
    take_edge(pc, below, (size_t)N * side + 1, 1);
    for (int q = 0; q < 4; q++)
        pc->sample[at[q]] = *cs->c[q];
    pc->have[0] = pc->have[N] = 1;
    pc->have[(size_t)N * (size_t)pc->side] = pc->have[(size_t)N * (size_t)pc->side + (size_t)N] = 1;
    int spp = 4;

    /* Depth-first: each split pops one quad and pushes four, so the stack never holds more than
     * 3 per level plus one. */
    quad stack[3 * TF_AA_MAX_DEPTH + 1];
    int sp = 0;
    stack[sp++] = (quad){0, 0, N};
    double sum_r = 0, sum_g = 0, sum_b = 0, sum_a = 0;
    while (sp > 0) {
        quad q = stack[--sp];
        const tf_sample *s[5];
        s[0] = cached_sample(r, pc, px, py, q.i, q.j, &spp, tally);
        s[1] = cached_sample(r, pc, px, py, q.i + q.size, q.j, &spp, tally);
        s[2] = cached_sample(r, pc, px, py, q.i, q.j + q.size, &spp, tally);
        s[3] = cached_sample(r, pc, px, py, q.i + q.size, q.j + q.size, &spp, tally);
        if (q.size > 1) {
            double split_threshold = tf_aa_split_threshold(r->threshold, N, q.size);
            level_span span = span_of_corners(s);
            if (display_range(&span) > split_threshold * TF_AA_PROBE_FRACTION) {
                int h = q.size / 2;
                s[4] = cached_sample(r, pc, px, py, q.i + h, q.j + h, &spp, tally);
                span_add(&span, s[4]);
                if (display_range(&span) > split_threshold) {
                    stack[sp++] = (quad){q.i + h, q.j + h, h};
                    stack[sp++] = (quad){q.i, q.j + h, h};
                    stack[sp++] = (quad){q.i + h, q.j, h};
                    stack[sp++] = (quad){q.i, q.j, h};
                    continue;
                }
                int z = q.size;
                sum_r += tf_aa_probed_leaf(z, s[0]->r, s[1]->r, s[2]->r, s[3]->r, s[4]->r);
                sum_g += tf_aa_probed_leaf(z, s[0]->g, s[1]->g, s[2]->g, s[3]->g, s[4]->g);
                sum_b += tf_aa_probed_leaf(z, s[0]->b, s[1]->b, s[2]->b, s[3]->b, s[4]->b);
                sum_a += tf_aa_probed_leaf(z, s[0]->a, s[1]->a, s[2]->a, s[3]->a, s[4]->a);
                continue;
            }
        }
        sum_r += tf_aa_flat_leaf(q.size, s[0]->r, s[1]->r, s[2]->r, s[3]->r);
        sum_g += tf_aa_flat_leaf(q.size, s[0]->g, s[1]->g, s[2]->g, s[3]->g);
        sum_b += tf_aa_flat_leaf(q.size, s[0]->b, s[1]->b, s[2]->b, s[3]->b);
        sum_a += tf_aa_flat_leaf(q.size, s[0]->a, s[1]->a, s[2]->a, s[3]->a);
    }

    double area = (double)N * (double)N;
    *out = (tf_pixel){(float)(sum_r / area), (float)(sum_g / area), (float)(sum_b / area),
                      (float)(sum_a / area), nearest_dist(pc, at), (float)spp};
    if (pc->column)
        note_columns(pc, cs);
    hand_edge(pc, left, side + (size_t)N, side);
    hand_edge(pc, below, 1, 1);
    clear_pixel(pc, at);
}

/* Corner sample c's lattice point on corner row cy. */
static void corner_point(const tf_renderer *r, tf_rect rect, int cy, int c, int64_t *X,
                         int64_t *Y)
{
    *X = (int64_t)(rect.x + c) * r->lattice;
    *Y = (int64_t)cy * r->lattice;
}

/* Corner samples of one corner row (image row of corners cy) for columns rect.x .. rect.x+w,
 * one ray at a time. */
static void corner_row_single(const tf_renderer *r, tf_rect rect, int cy, tf_sample *row,
                              tf_render_counts *tally)
{
    for (int c = 0; c <= rect.w; c++) {
        int64_t X, Y;
        corner_point(r, rect, cy, c, &X, &Y);
        tf_render_lattice_sample(r, X, Y, &row[c], &tally->shadow_rays);
    }
}

/* A corner row's rays for the packet tracer, w + 1 of each (allocated once a rectangle). */
typedef struct row_rays {
    tf_vec3 *o, *d, *so, *sd;
    double *tmin, *tmax, *stmin, *stmax;
    unsigned char *found, *occluded;
    tf_hit *hits;
    tf_shade_pending *pending;
} row_rays;

static int row_rays_alloc(row_rays *q, size_t n)
{
    q->o = malloc(n * sizeof *q->o), q->d = malloc(n * sizeof *q->d);
    q->so = malloc(n * sizeof *q->so), q->sd = malloc(n * sizeof *q->sd);
    q->tmin = malloc(n * sizeof *q->tmin), q->tmax = malloc(n * sizeof *q->tmax);
    q->stmin = malloc(n * sizeof *q->stmin), q->stmax = malloc(n * sizeof *q->stmax);
    q->found = malloc(n), q->occluded = malloc(n);
    q->hits = malloc(n * sizeof *q->hits), q->pending = malloc(n * sizeof *q->pending);
    return q->o && q->d && q->so && q->sd && q->tmin && q->tmax && q->stmin && q->stmax &&
           q->found && q->occluded && q->hits && q->pending;
}

static void row_rays_free(row_rays *q)
{
    free(q->o), free(q->d), free(q->so), free(q->sd), free(q->tmin), free(q->tmax);
    free(q->stmin), free(q->stmax), free(q->found), free(q->occluded), free(q->hits);
    free(q->pending);
}

/* The camera rays of corner row cy, as tf_render_lattice_sample makes them, with their
 * interval (0, t_water) (tf_shade_ray's). */
static void camera_rays(const tf_renderer *r, tf_rect rect, int cy, row_rays *q)
{
    for (int c = 0; c <= rect.w; c++) {
        int64_t X, Y;
        double x, y;
        corner_point(r, rect, cy, c, &X, &Y);
        tf_lattice_position(r->jitter_key, (double)r->lattice, X, Y, &x, &y);
        q->o[c] = r->camera.position;
        q->d[c] = tf_camera_dir(&r->camera, x, y);
        q->tmin[c] = 0.0;
        q->tmax[c] = tf_shade_t_water(&r->shader, q->o[c], q->d[c]);
    }
}

/* Shade the row's hits up to their shadow rays; returns how many shadow rays they cast. */
static int shade_begin_row(const tf_renderer *r, int n, row_rays *q)
{
    int k = 0;
    for (int c = 0; c < n; c++) {
        tf_shade_pending *p = &q->pending[c];
        tf_shade_begin(&r->shader, q->o[c], q->d[c], q->tmax[c], q->found[c] ? &q->hits[c] : NULL,
                       p);
        if (!p->shadow)
            continue;
        q->so[k] = p->start, q->sd[k] = r->shader.sun_dir;
        q->stmin[k] = 0.0;
        /* proved under: the packet finds it */
        tf_shadow_strips(&r->shader, p->start, &q->stmax[k]);
        k++;
    }
    return k;
}

/* The same samples as corner_row_single, their rays traced in packets. */
static void corner_row_packets(const tf_renderer *r, tf_rect rect, int cy, row_rays *q,
                               tf_sample *row, tf_render_counts *tally)
{
    const int n = rect.w + 1;
    camera_rays(r, rect, cy, q);
    const tf_procedural *proc = r->hf->proc;
    if (proc)
        tf_proc_trace_packet(proc, &r->shader.view, n, q->o, q->d, q->tmin, q->tmax, q->found,
                             q->hits);
    else
        tf_trace_packets(r->hf, n, q->o, q->d, q->tmin, q->tmax, q->found, q->hits);
    int shadows = shade_begin_row(r, n, q);
    if (proc)
        tf_proc_occluded_packet(proc, &r->shader.view, shadows, q->so, q->sd, q->stmin,
                                q->stmax, q->occluded);
    else
        tf_occluded_packets(r->hf, shadows, q->so, q->sd, q->stmin, q->stmax, q->occluded);
    for (int c = 0, k = 0; c < n; c++) {
        int occluded = q->pending[c].shadow ? q->occluded[k++] : 0;
        tf_shade_end(&r->shader, q->o[c], q->d[c], &q->pending[c], occluded, &row[c]);
    }
    tally->shadow_rays += (uint64_t)shadows;
}

/* The same samples as corner_row_single, each camera ray helped by the one traced below it in
 * its corner column (column[c], NULL-free: a record that vouches for nothing at first);
 * the samples' records go to records[]. */
static void corner_row_coherent(const tf_renderer *r, tf_rect rect, int cy,
                                const tf_sample_record *column, tf_sample *row,
                                tf_sample_record *records, tf_render_counts *tally)
{
    for (int c = 0; c <= rect.w; c++) {
        int64_t X, Y;
        corner_point(r, rect, cy, c, &X, &Y);
        lattice_sample_coherent(r, X, Y, &column[c], &records[c], &row[c], &tally->shadow_rays);
    }
}

/* How a rectangle traces its corner rows: coherent rays (column not NULL: the rectangle's
 * records, one a corner column), packets (q not NULL), or one ray at a time. */
typedef struct row_tracer {
    row_rays *q;
    tf_sample_record *column;
} row_tracer;

/* Corner samples of one corner row (their records to records[] when coherent). */
static void corner_row(const tf_renderer *r, tf_rect rect, int cy, int external_row,
                       const row_tracer *how, tf_sample *row, tf_sample_record *records,
                       tf_render_counts *tally)
{
    if (how->column)
        corner_row_coherent(r, rect, cy, how->column, row, records, tally);
    else if (how->q)
        corner_row_packets(r, rect, cy, how->q, row, tally);
    else
        corner_row_single(r, rect, cy, row, tally);
    tally->primary_rays += (uint64_t)rect.w + 1;
    tally->external_rays += external_row ? (uint64_t)rect.w + 1 : 1;
}

/* A rectangle's buffers: two corner rows of samples (and of ray records), the pixel cache,
 * and how corner rows are traced. */
typedef struct rect_state {
    tf_sample *above, *below;
    tf_sample_record *ring; /* the records of the last TF_CORNER_RING corner rows traced */
    pixel_cache pc;
    pixel_edge left;  /* the current pixel's left edge */
    pixel_edge tops;  /* each pixel column's edge between this pixel row and the one below */
    row_rays rays;
    row_tracer how;
} rect_state;

#define TF_CORNER_RING (TF_LOWER_ROWS + 1) /* a pixel row's lower corner row and those above */

/* The records of the rectangle's corner row y (0 at its top; y > 0 rows kept only while they
 * are among the TF_CORNER_RING lowest not yet left behind); NULL when its rays are not traced
 * coherently, which keeps no records. */
static tf_sample_record *corner_records(const rect_state *st, tf_rect rect, int y)
{
    if (!st->ring)
        return NULL;
    return st->ring + (size_t)(y % TF_CORNER_RING) * ((size_t)rect.w + 1);
}

/* Edges of `count` pixels' worth of inner points (n each; at least one, so no allocation is
 * empty), all holding nothing; 0 if out of memory. */
static int pixel_edges_alloc(pixel_edge *e, size_t count, size_t n)
{
    const size_t points = count * (n > 0 ? n : 1);
    e->have = calloc(points, 1);
    e->sample = malloc(sizeof *e->sample * points);
    e->held = calloc(count, 1);
    return e->have && e->sample && e->held;
}

static void pixel_edges_free(pixel_edge *e)
{
    free(e->have), free(e->sample), free(e->held);
}

/* Pixel column c's slice of a row of edges (n inner points each). */
static pixel_edge edge_slice(const pixel_edge *e, int c, size_t n)
{
    const size_t at = (size_t)c * n;
    return (pixel_edge){e->have + at, e->sample + at, e->held + c};
}

static void rect_state_free(rect_state *st)
{
    free(st->above), free(st->below), free(st->ring);
    free(st->pc.sample), free(st->pc.have), free(st->pc.used);
    pixel_edges_free(&st->left), pixel_edges_free(&st->tops);
    free(st->how.column);
    if (st->how.q)
        row_rays_free(st->how.q);
}

/* Whether corner rows go in packets: a grid's where tf_trace_packets_enabled says (the SIMD
 * walks pay on AVX-512 only); a procedural terrain's unless TF_TRACE_PACKETS=0 (they share the
 * quad-tree's nodes and leaves, tf_proc_trace_packet, on any ISA; as fast as single rays). */
static int row_packets(const tf_renderer *r)
{
    return r->hf->proc ? tf_trace_packets_wanted(1) : tf_trace_packets_enabled();
}

static void rect_state_alloc(const tf_renderer *r, tf_rect rect, rect_state *st)
{
    const size_t w1 = (size_t)rect.w + 1, side = (size_t)r->lattice + 1;
    *st = (rect_state){0};
    st->above = malloc(sizeof *st->above * w1);
    st->below = malloc(sizeof *st->below * w1);
    st->pc = (pixel_cache){(int)side, malloc(sizeof(tf_sample) * side * side),
                           calloc(side * side, 1), malloc(sizeof(int) * side * side), 0, 0,
                           NULL, {NULL}, 0};
    int ok = st->above && st->below && st->pc.sample && st->pc.have && st->pc.used;
    if (coherence_on(r)) {
        /* calloc: records that vouch for nothing until a ray below is traced */
        st->how.column = calloc(w1, sizeof *st->how.column);
        st->ring = calloc(w1 * TF_CORNER_RING, sizeof *st->ring);
        ok = ok && st->how.column && st->ring;
    } else if (row_packets(r)) {
        st->how.q = &st->rays;
        ok = ok && row_rays_alloc(&st->rays, w1);
    }
    ok = pixel_edges_alloc(&st->left, 1, side - 2) && ok;
    ok = pixel_edges_alloc(&st->tops, (size_t)rect.w, side - 2) && ok;
    if (!ok)
        tf_die(71, "tf_render_rect: out of memory for a %d-pixel row", rect.w);
}

/* Swap the corner rows: the row just rendered above becomes the next one's below. */
static void rect_state_step(rect_state *st)
{
    tf_sample *t = st->above;
    st->above = st->below, st->below = t;
}

/* The pixel row `row` of the rectangle, its corner rows traced (st->above, st->below). */
static void render_pixel_row(const tf_renderer *r, tf_rect rect, int row, rect_state *st,
                             tf_pixel *out, tf_render_counts *tally)
{
    const int down = row + TF_LOWER_ROWS < rect.h ? row + TF_LOWER_ROWS : rect.h;
    const tf_sample_record *above = corner_records(st, rect, row),
                           *below = corner_records(st, rect, row + 1), *rows[TF_LOWER_ROWS];
    for (int m = 0; m < down - row; m++)
        rows[m] = corner_records(st, rect, row + 1 + m);
    const size_t inner = (size_t)r->lattice - 1;
    *st->left.held = 0; /* the row's first pixel has no left neighbour here */
    for (int c = 0; c < rect.w; c++) {
        pixel_edge top = edge_slice(&st->tops, c, inner);
        corners cs = {{&st->above[c], &st->above[c + 1], &st->below[c], &st->below[c + 1]},
                      {NULL, NULL, NULL, NULL}};
        if (st->how.column) {
            cs.k[0] = &above[c], cs.k[1] = &above[c + 1];
            cs.k[2] = &below[c], cs.k[3] = &below[c + 1];
            st->pc.column = &st->how.column[c];
            st->pc.nrows = down - row;
            for (int m = 0; m < st->pc.nrows; m++)
                st->pc.rows[m] = &rows[m][c];
        }
        render_pixel(r, &st->pc, rect.x + c, rect.y + row, &cs, &st->left, &top,
                     &out[(size_t)row * (size_t)rect.w + (size_t)c], tally);
    }
}

/* Pixel rows go bottom to top, so that each camera ray has the ray below it traced already
 * (coherence); a pixel's bits do not depend on the order. */
void tf_render_rect(const tf_renderer *r, tf_rect rect, tf_pixel *out, tf_render_counts *counts)
{
    const tf_scene *s = r->scene;
    if (rect.w <= 0 || rect.h <= 0 || rect.x < 0 || rect.y < 0 || rect.x > s->width - rect.w ||
        rect.y > s->height - rect.h)
        tf_die(70, "tf_render_rect: rectangle %dx%d+%d+%d outside the %dx%d image", rect.w,
               rect.h, rect.x, rect.y, s->width, s->height);

    rect_state st;
    rect_state_alloc(r, rect, &st);
    tf_render_counts tally = {0};
    tf_tile_counts cache_before = tf_tilecache_thread_counts();
    corner_row(r, rect, rect.y + rect.h, 1, &st.how, st.below,
               corner_records(&st, rect, rect.h), &tally);
    for (int row = rect.h - 1; row >= 0; row--) {
        corner_row(r, rect, rect.y + row, 0, &st.how, st.above,
                   corner_records(&st, rect, row), &tally);
        render_pixel_row(r, rect, row, &st, out, &tally);
        rect_state_step(&st);
    }
    tally.pixels = (uint64_t)rect.w * (uint64_t)rect.h;
    tf_tile_counts cache_after = tf_tilecache_thread_counts(); /* this thread's: exact */
    tally.terrain_samples = cache_after.samples_evaluated - cache_before.samples_evaluated;
    tally.terrain_hits = cache_after.hits - cache_before.hits;
    tally.terrain_evictions = cache_after.evictions - cache_before.evictions;
    rect_state_free(&st);
    if (counts) {
        counts->primary_rays += tally.primary_rays;
        counts->shadow_rays += tally.shadow_rays;
        counts->external_rays += tally.external_rays;
        counts->pixels += tally.pixels;
        counts->terrain_samples += tally.terrain_samples;
        counts->terrain_hits += tally.terrain_hits;
        counts->terrain_evictions += tally.terrain_evictions;
    }
}

void tf_render_pixel_uniform(const tf_renderer *r, int px, int py, int n, tf_pixel *out,
                             tf_render_counts *counts)
{
    uint64_t shadow = 0;
    double sum_r = 0, sum_g = 0, sum_b = 0, sum_a = 0;
    float zmin = TF_SKY_DIST;
    uint64_t pixel_key = tf_hash64(r->jitter_key ^ 0x756e69666f726d00ULL ^ (uint64_t)px);
    pixel_key = tf_hash64(pixel_key ^ ((uint64_t)py * 0x9e3779b97f4a7c15ULL));
    for (int b = 0; b < n; b++)
        for (int a = 0; a < n; a++) {
            uint64_t h = tf_hash64(pixel_key ^ (uint64_t)(b * n + a));
            double x = px + (a + tf_hash_unit(h)) / n;
            double y = py + (b + tf_hash_unit(h ^ 0xd1b54a32d192ed03ULL)) / n;
            tf_sample s;
            tf_render_point(r, x, y, &s, &shadow);
            sum_r += s.r;
            sum_g += s.g;
            sum_b += s.b;
            sum_a += s.a;
            if (s.dist < zmin)
                zmin = s.dist;
        }
    double count = (double)n * (double)n;
    *out = (tf_pixel){(float)(sum_r / count), (float)(sum_g / count), (float)(sum_b / count),
                      (float)(sum_a / count), zmin, (float)count};
    if (counts) {
        counts->primary_rays += (uint64_t)n * (uint64_t)n;
        counts->shadow_rays += shadow;
        counts->pixels++;
    }
}
