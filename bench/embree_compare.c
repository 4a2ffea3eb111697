/* embree_compare.c: terrafarm's height-field tracer (render/trace.h) against Embree 3 on the
 * same surface and the same rays (issue 23; bench/README.md section 9 has the figures).
 *
 * The scene's terrain at (2^k+1)^2 samples goes to Embree as the very triangles tf_trace tests
 * (cell split along (ci, cj)-(ci+1, cj+1), render/trace.c), or with --grid as a grid whose
 * columns are mirrored (Embree splits grid quads along the other diagonal).  The rays: the
 * scene camera's primary rays, one per pixel, and from each hit facing the sun a shadow ray as
 * shade.c starts it.  Rounds alternate the tracers (terrafarm as the renderer traces camera
 * rays, bottom row first and each ray helped by the one below it; terrafarm one ray at a time;
 * Embree single rays, packets of
 * 8, of 16 with AVX-512); rates per CPU-second of the tracing thread, medians.  Also printed:
 * build times, memory, and the rays on which the two disagree, sorted.
 *
 * usage: embree_compare [-k K] [-s WxH] [-r ROUNDS] [-j THREADS] [--grid | --grid-unmirrored]
 *                       [--robust] [--list] [SCENE]   (k 11, 1920x1080, 7, all CPUs, default.scene;
 *        --grid-unmirrored: the control, Embree's diagonal; --list: each disagreeing ray)
 *        embree_compare --smoke [SCENE]   (k = 6, 32x18 rays, one round: bench_smoke.sh) */
#include <math.h>
#include <stdatomic.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <embree3/rtcore.h>

#include "bench/bench_cpu.h"
#include "bench/bench_stats.h"
#include "log.h"
#include "render/camera.h"
#include "render/constants.h"
#include "render/shade.h"
#include "render/sun_strips.h"
#include "render/trace.h"
#include "terrain/heightfield.h"
#include "terrain/terrain_build.h"

#define T_TOL 1e-4          /* hit distances this far apart, relative, disagree */
#define GRAZING_COS 0.05    /* |cos| between a ray and the surface under this: grazing */
#define EDGE_TOL 1e-3       /* hit this close (in cells) to a cell's edge or diagonal */
#define NEAR_CELLS 2.0      /* a shadow ray stopped within this many cells of its start */
#define MAX_ROUNDS 64

typedef struct opts {
    const char *scene;
    int k, w, h, rounds, threads, robust, list;
    int grid; /* 0: triangles; 1: a grid, mirrored; 2: a grid in natural order (a control) */
} opts;

/* One set of rays for both tracers: terrafarm's in double, Embree's the same in float. */
typedef struct rays {
    int count;
    tf_vec3 *o, *d;
    float *f;  /* 6 a ray: origin, direction */
    int *src;  /* shadow rays: the primary ray whose hit they start from */
} rays;

/* What one tracer found: per ray the hit distance (INFINITY: none; a shadow ray: 0 when
 * occluded) and, for primary rays, the normal of the triangle hit (3 floats, not unit). */
typedef struct found {
    float *t, *n;
} found;

/* Embree's device and scene, and what they cost. */
typedef struct embree {
    RTCDevice dev;
    RTCScene scene;
    atomic_llong bytes, peak; /* the memory monitor's count, and its high-water mark */
    long long buffer_bytes, bvh_bytes, build_peak;
    char err[200];            /* the device's last error */
} embree;

/* The tracers: terrafarm, then Embree with this many rays a call. */
/* terrafarm as the renderer traces (camera rays bottom row first, each helped by the ray
 * below it: tf_trace_coherent; shadow rays each helped by the one before it:
 * tf_occluded_coherent) and one ray at a time (tf_trace, tf_occluded). */
enum { M_TF, M_TF1, M_E1, M_E8, M_E16, M_COUNT };
static const int mode_width[M_COUNT] = {0, 0, 1, 8, 16};
static const char *const mode_name[M_COUNT] = {"terrafarm coherent", "terrafarm ray by ray",
                                               "embree single ray", "embree packets of 8",
                                               "embree packets of 16"};

typedef struct bench {
    tf_heightfield *hf;
    embree e;
    rays prim, shad;
    tf_hit *ref;     /* terrafarm's primary hits (untimed pass) */
    char *ref_hit;
    found prim_found[M_COUNT], shad_found[M_COUNT];
    int modes;       /* M_E16 + 1 with AVX-512, else M_E8 + 1 */
    int build_rounds;
    int prim_height; /* rows of primary rays */
    int list;        /* --list: print every disagreeing primary ray */
    double tf_build_s, e_build_s; /* medians */
    tf_sun_strips *strips;        /* the coherent mode's shadow rays end where these prove */
    tf_ray_dir sun_ray;           /* and share their direction's setup (as shade.c's do) */
    double strips_build_s;
} bench;

static double clock_s(clockid_t id)
{
    struct timespec ts;
    clock_gettime(id, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* ---- terrafarm's side ------------------------------------------------------------------- */

/* The scene with its terrain at 2^k + 1 samples a side and its image at w x h. */
static tf_scene *load_scene(const opts *o, char *err, size_t errlen)
{
    tf_scene *s = tf_scene_load(o->scene, err, errlen);
    if (!s)
        return NULL;
    if (s->terrain.procedural) {
        tf_scene_free(s);
        tf_seterr(err, errlen, "%s: a procedural terrain has no grid to compare", o->scene);
        return NULL;
    }
    s->terrain.size_exp = o->k;
    tf_scene_set_size(s, o->w, o->h);
    return s;
}

/* A malloc'd copy of n floats (the heights tf_heightfield_wrap takes over), or NULL. */
static float *copy_heights(const float *h, size_t n)
{
    float *c = malloc(n * sizeof *c);
    if (c)
        memcpy(c, h, n * sizeof *c);
    return c;
}

/* Bytes of terrafarm's height field: the samples and every level of the max and min grids. */
static size_t tf_bytes(const tf_heightfield *hf, size_t *grids)
{
    *grids = 0;
    for (int l = 0; l < hf->levels; l++) {
        size_t side = (size_t)hf->cells >> l;
        *grids += 2 * side * side * sizeof(float);
    }
    return (size_t)hf->n * hf->n * sizeof(float) + *grids;
}

/* ---- Embree's side ---------------------------------------------------------------------- */

static void on_embree_error(void *user, enum RTCError code, const char *str)
{
    embree *e = user;
    snprintf(e->err, sizeof e->err, "Embree error %d: %s", (int)code, str ? str : "?");
}

/* Embree's memory monitor: every byte its device allocates or frees, and the high mark. */
static bool on_embree_memory(void *user, ssize_t bytes, bool post)
{
    embree *e = user;
    (void)post;
    long long now = atomic_fetch_add(&e->bytes, (long long)bytes) + bytes;
    long long peak = atomic_load(&e->peak);
    while (now > peak && !atomic_compare_exchange_weak(&e->peak, &peak, now))
        ;
    return true;
}

static int embree_open(embree *e, int threads, char *err, size_t errlen)
{
    char config[64];
    snprintf(config, sizeof config, "threads=%d", tf_thread_count(threads));
    e->dev = rtcNewDevice(config);
    if (!e->dev)
        return tf_seterr(err, errlen, "rtcNewDevice(\"%s\") failed (error %d)", config,
                         (int)rtcGetDeviceError(NULL));
    rtcSetDeviceErrorFunction(e->dev, on_embree_error, e);
    rtcSetDeviceMemoryMonitorFunction(e->dev, on_embree_memory, e);
    return 0;
}

/* The height field's samples as Embree vertices; columns east to west when `mirror`. */
static void fill_vertices(float *v, const tf_heightfield *hf, int mirror)
{
    const int n = hf->n;
    for (int j = 0; j < n; j++)
        for (int i = 0; i < n; i++) {
            int col = mirror ? n - 1 - i : i;
            float *p = v + 3 * ((size_t)j * n + i);
            p[0] = (float)((double)col * hf->cell);
            p[1] = (float)((double)j * hf->cell);
            p[2] = hf->h[(size_t)j * n + col];
        }
}

/* Cell (ci, cj)'s two triangles as trace.c has them: (A, B, C) and (A, C, D). */
static void fill_indices(unsigned *idx, const tf_heightfield *hf)
{
    const unsigned n = (unsigned)hf->n, cells = (unsigned)hf->cells;
    for (unsigned cj = 0; cj < cells; cj++)
        for (unsigned ci = 0; ci < cells; ci++) {
            unsigned a = cj * n + ci, b = a + 1, c = a + n + 1, d = a + n;
            unsigned *t = idx + 6 * ((size_t)cj * cells + ci);
            t[0] = a, t[1] = b, t[2] = c;
            t[3] = a, t[4] = c, t[5] = d;
        }
}

/* One geometry holding the height field: a triangle mesh, or a mirrored grid. */
static RTCGeometry new_geometry(const embree *e, const tf_heightfield *hf, int grid)
{
    size_t n = (size_t)hf->n, cells = (size_t)hf->cells;
    RTCGeometry g = rtcNewGeometry(e->dev, grid ? RTC_GEOMETRY_TYPE_GRID : RTC_GEOMETRY_TYPE_TRIANGLE);
    float *v = g ? rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                           3 * sizeof(float), n * n) : NULL;
    if (!v)
        return g;
    fill_vertices(v, hf, grid == 1);
    if (grid) {
        struct RTCGrid *gr = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_GRID, 0, RTC_FORMAT_GRID,
                                              sizeof(struct RTCGrid), 1);
        if (gr)
            *gr = (struct RTCGrid){0, (unsigned)n, (unsigned short)n, (unsigned short)n};
    } else {
        unsigned *idx = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                3 * sizeof(unsigned), 2 * cells * cells);
        if (idx)
            fill_indices(idx, hf);
    }
    return g;
}

/* Embree's scene of one geometry, the height field (not yet committed); the bytes of its
 * buffers into e.  0, or -1 with one line in err. */
static int embree_scene(embree *e, const tf_heightfield *hf, const opts *o, char *err,
                        size_t errlen)
{
    long long before = atomic_load(&e->bytes);
    e->scene = rtcNewScene(e->dev);
    RTCGeometry g = e->scene ? new_geometry(e, hf, o->grid) : NULL;
    if (g && !e->err[0]) {
        rtcSetSceneFlags(e->scene, o->robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
        rtcCommitGeometry(g);
        rtcAttachGeometry(e->scene, g);
    }
    if (g)
        rtcReleaseGeometry(g);
    if (!g || e->err[0])
        return tf_seterr(err, errlen, "%s", e->err[0] ? e->err : "rtcNewGeometry failed");
    e->buffer_bytes = atomic_load(&e->bytes) - before;
    return 0;
}

/* Build Embree's scene and its BVH; the BVH's bytes (the monitor's count over the commit) and
 * the high mark into e.  Returns the seconds of rtcCommitScene, or -1 with one line in err. */
static double embree_build(embree *e, const tf_heightfield *hf, const opts *o, char *err,
                           size_t errlen)
{
    if (embree_scene(e, hf, o, err, errlen) != 0)
        return -1;
    long long before = atomic_load(&e->bytes);
    atomic_store(&e->peak, before);
    double t0 = clock_s(CLOCK_MONOTONIC);
    rtcCommitScene(e->scene);
    double secs = clock_s(CLOCK_MONOTONIC) - t0;
    if (e->err[0])
        return tf_seterr(err, errlen, "%s", e->err);
    e->bvh_bytes = atomic_load(&e->bytes) - before;
    e->build_peak = atomic_load(&e->peak) - before + e->buffer_bytes;
    return secs;
}

static void embree_drop_scene(embree *e)
{
    if (e->scene)
        rtcReleaseScene(e->scene);
    e->scene = NULL;
}

/* ---- the builds, alternating ---------------------------------------------------------- */

/* terrafarm's build: the max/min grids over a fresh copy of h (what tf_heightfield_build
 * does once the heights exist); its wall seconds into *secs.  0, or -1 when out of memory. */
static int tf_build(bench *b, const float *h, size_t nn, double extent, const opts *o,
                    double *secs)
{
    if (b->hf)
        tf_heightfield_free(b->hf);
    float *mine = copy_heights(h, nn * nn);
    double t0 = clock_s(CLOCK_MONOTONIC);
    b->hf = mine ? tf_heightfield_wrap(mine, o->k, extent, o->threads) : NULL;
    *secs = clock_s(CLOCK_MONOTONIC) - t0;
    return b->hf ? 0 : -1;
}

/* Build both up to 3 times, terrafarm's grids then Embree's BVH; keep the last of each and
 * the medians of their times.  Frees h.  0, or -1 with one line in err. */
static int build_both(bench *b, float *h, double extent, const opts *o, char *err, size_t errlen)
{
    const size_t nn = ((size_t)1 << o->k) + 1;
    int rounds = o->rounds < 3 ? o->rounds : 3, r;
    double tf_s[MAX_ROUNDS], e_s[MAX_ROUNDS];
    for (r = 0; r < rounds; r++) {
        if (tf_build(b, h, nn, extent, o, &tf_s[r]) != 0) {
            tf_seterr(err, errlen, "out of memory: a %zux%zu height field", nn, nn);
            break;
        }
        embree_drop_scene(&b->e);
        if ((e_s[r] = embree_build(&b->e, b->hf, o, err, errlen)) < 0)
            break;
    }
    free(h);
    b->build_rounds = rounds;
    b->tf_build_s = r == rounds ? tf_bench_median(tf_s, rounds) : 0;
    b->e_build_s = r == rounds ? tf_bench_median(e_s, rounds) : 0;
    return r == rounds ? 0 : -1;
}

static void print_builds(const bench *b, const opts *o)
{
    size_t grids, all = tf_bytes(b->hf, &grids);
    printf("build on %d threads, median of %d: terrafarm max/min grids %.3f s; Embree BVH (rtcCommitScene) %.3f s\n",
           tf_thread_count(o->threads), b->build_rounds, b->tf_build_s, b->e_build_s);
    printf("memory: terrafarm %.1f MB (heights %.1f + max/min grids %.1f); Embree %.1f MB (buffers %.1f + BVH %.1f; %.1f at the build's peak)\n",
           all / 1e6, (all - grids) / 1e6, grids / 1e6, (b->e.buffer_bytes + b->e.bvh_bytes) / 1e6,
           b->e.buffer_bytes / 1e6, b->e.bvh_bytes / 1e6, b->e.build_peak / 1e6);
}

/* ---- the rays --------------------------------------------------------------------------- */

static int rays_alloc(rays *r, int count)
{
    r->count = count;
    r->o = malloc(sizeof *r->o * (size_t)(count + 1));
    r->d = malloc(sizeof *r->d * (size_t)(count + 1));
    r->f = malloc(6 * sizeof *r->f * (size_t)(count + 1));
    r->src = malloc(sizeof *r->src * (size_t)(count + 1));
    return r->o && r->d && r->f && r->src ? 0 : -1;
}

static void rays_free(rays *r)
{
    free(r->o);
    free(r->d);
    free(r->f);
    free(r->src);
}

static void set_ray(rays *r, int i, tf_vec3 o, tf_vec3 d, int src)
{
    float *f = r->f + 6 * (size_t)i;
    r->o[i] = o;
    r->d[i] = d;
    r->src[i] = src;
    f[0] = (float)o.x, f[1] = (float)o.y, f[2] = (float)o.z;
    f[3] = (float)d.x, f[4] = (float)d.y, f[5] = (float)d.z;
}

/* One ray through the centre of every pixel, as the renderer's camera makes them. */
static int primary_rays(rays *r, const tf_scene *s, char *err, size_t errlen)
{
    tf_camera cam;
    if (tf_camera_init(&cam, s, err, errlen) != 0)
        return -1;
    if (rays_alloc(r, s->width * s->height) != 0)
        return tf_seterr(err, errlen, "out of memory: %dx%d rays", s->width, s->height);
    for (int y = 0; y < s->height; y++)
        for (int x = 0; x < s->width; x++)
            set_ray(r, y * s->width + x, cam.position, tf_camera_dir(&cam, x + 0.5, y + 0.5),
                    y * s->width + x);
    return 0;
}

/* terrafarm's hits of the primary rays (untimed: the reference, and the shadow rays' starts),
 * then a shadow ray from every hit whose triangle faces the sun, lifted as shade.c lifts it. */
static int shadow_rays(bench *b, const tf_scene *s, char *err, size_t errlen)
{
    tf_shader sh;
    tf_shader_init(&sh, s, b->hf);
    int n = 0;
    for (int i = 0; i < b->prim.count; i++) {
        b->ref_hit[i] = (char)tf_trace(b->hf, b->prim.o[i], b->prim.d[i], 0.0, TF_FAR_AWAY, &b->ref[i]);
        n += b->ref_hit[i] && v3_dot(b->ref[i].n, sh.sun_dir) > 0;
    }
    if (rays_alloc(&b->shad, n) != 0)
        return tf_seterr(err, errlen, "out of memory: %d shadow rays", n);
    for (int i = 0, k = 0; i < b->prim.count; i++)
        if (b->ref_hit[i] && v3_dot(b->ref[i].n, sh.sun_dir) > 0)
            set_ray(&b->shad, k++, v3_add(b->ref[i].p, v3_scale(b->ref[i].n, sh.shadow_lift)),
                    sh.sun_dir, i);
    /* the sun's strips, as tf_renderer_new builds them (one thread) */
    double t0 = clock_s(CLOCK_MONOTONIC);
    b->strips = tf_sun_strips_build(b->hf, sh.sun_dir);
    tf_ray_dir_init(&b->sun_ray, b->hf, sh.sun_dir);
    b->strips_build_s = clock_s(CLOCK_MONOTONIC) - t0;
    return 0;
}

/* ---- tracing: terrafarm, Embree single rays, Embree packets ------------------------------- */

static void note_hit(found *out, int i, int h, const tf_hit *hit)
{
    out->t[i] = h ? (float)hit->t : INFINITY;
    float *n = out->n + 3 * (size_t)i;
    if (h)
        n[0] = (float)hit->n.x, n[1] = (float)hit->n.y, n[2] = (float)hit->n.z;
    else
        n[0] = n[1] = n[2] = 0;
}

static void tf_primary(const bench *b, found *out)
{
    for (int i = 0; i < b->prim.count; i++) {
        tf_hit hit;
        note_hit(out, i, tf_trace(b->hf, b->prim.o[i], b->prim.d[i], 0.0, TF_FAR_AWAY, &hit), &hit);
    }
}

/* The rows bottom to top, each ray helped by the record of the one below it (the records'
 * array is part of the timed work). */
static void tf_primary_coherent(const bench *b, found *out)
{
    const int w = b->prim.count / b->prim_height;
    tf_ray_clear *below = calloc((size_t)w, sizeof *below);
    if (!below)
        tf_die(71, "embree_compare: out of memory for a row of ray records");
    for (int y = b->prim_height - 1; y >= 0; y--)
        for (int x = 0; x < w; x++) {
            const int i = y * w + x;
            tf_hit hit;
            tf_ray_clear mine;
            int h = tf_trace_coherent(b->hf, b->prim.o[i], b->prim.d[i], TF_FAR_AWAY, &below[x],
                                      &hit, &mine);
            below[x] = mine;
            note_hit(out, i, h, &hit);
        }
    free(below);
}

static void tf_shadow(const bench *b, found *out)
{
    for (int i = 0; i < b->shad.count; i++)
        out->t[i] = tf_occluded(b->hf, b->shad.o[i], b->shad.d[i], 0.0, TF_FAR_AWAY) ? 0 : INFINITY;
}

/* In the list's order (the image's, row by row), as shade.c's resolve_shadow_coherent traces
 * them: what the sun's strips prove first (occluded, or clear past some point, where the walk
 * then ends), then each with the record of the one before. */
static void tf_shadow_coherent(const bench *b, found *out)
{
    tf_shadow_clear prev = {{0}, 0, {0}}, named;
    for (int i = 0; i < b->shad.count; i++) {
        double t;
        const int said = tf_sun_strips_shadow(b->strips, b->shad.o[i], &t);
        if (said == TF_SUN_UNDER) {
            prev = tf_sun_strips_under_record(b->strips, b->shad.o[i]);
            out->t[i] = 0;
            continue;
        }
        const double tmax = said == TF_SUN_CLEAR_AFTER ? t : TF_FAR_AWAY;
        const tf_shadow_clear *near = tf_sun_strips_named(b->strips, &prev, &named);
        out->t[i] = tf_occluded_coherent(&b->sun_ray, b->shad.o[i], tmax, near, &prev)
                        ? 0
                        : INFINITY;
    }
}

static void ray1(struct RTCRay *ray, const float *f)
{
    ray->org_x = f[0], ray->org_y = f[1], ray->org_z = f[2], ray->tnear = 0;
    ray->dir_x = f[3], ray->dir_y = f[4], ray->dir_z = f[5], ray->time = 0;
    ray->tfar = INFINITY, ray->mask = ~0u, ray->id = 0, ray->flags = 0;
}

static void embree_primary1(const bench *b, found *out)
{
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    for (int i = 0; i < b->prim.count; i++) {
        struct RTCRayHit rh;
        ray1(&rh.ray, b->prim.f + 6 * (size_t)i);
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(b->e.scene, &ctx, &rh);
        out->t[i] = rh.hit.geomID != RTC_INVALID_GEOMETRY_ID ? rh.ray.tfar : INFINITY;
        float *n = out->n + 3 * (size_t)i;
        n[0] = rh.hit.Ng_x, n[1] = rh.hit.Ng_y, n[2] = rh.hit.Ng_z;
    }
}

static void embree_shadow1(const bench *b, found *out)
{
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    for (int i = 0; i < b->shad.count; i++) {
        struct RTCRay ray;
        ray1(&ray, b->shad.f + 6 * (size_t)i);
        rtcOccluded1(b->e.scene, &ctx, &ray);
        out->t[i] = ray.tfar == -INFINITY ? 0 : INFINITY;
    }
}

/* Packets: Embree's RTCRayHitN layout is one array of w lanes per field, in this order. */
enum { F_ORG = 0, F_TNEAR = 3, F_DIR = 4, F_TIME = 7, F_TFAR = 8, F_MASK = 9, F_ID = 10,
       F_FLAGS = 11, F_NG = 12, F_GEOM = 18 };
_Static_assert(offsetof(struct RTCRayHit8, hit.geomID) == F_GEOM * 8 * sizeof(float), "RTCRayHit8 layout");
_Static_assert(offsetof(struct RTCRayHit16, hit.geomID) == F_GEOM * 16 * sizeof(float), "RTCRayHit16 layout");
_Static_assert(offsetof(struct RTCRayHit16, hit.Ng_x) == F_NG * 16 * sizeof(float), "RTCRayHit16 layout");

static float *lane(void *pk, int w, int field, int i) { return (float *)pk + field * w + i; }
static unsigned *ulane(void *pk, int w, int field, int i) { return (unsigned *)pk + field * w + i; }

/* Rays first.. of r into a w-wide packet (lanes past the end invalid); returns how many. */
static int fill_packet(void *pk, int w, const rays *r, int first, int *valid, int with_hit)
{
    int m = r->count - first < w ? r->count - first : w;
    for (int i = 0; i < w; i++) {
        const float *f = r->f + 6 * (size_t)(first + (i < m ? i : 0));
        for (int c = 0; c < 3; c++)
            *lane(pk, w, F_ORG + c, i) = f[c], *lane(pk, w, F_DIR + c, i) = f[3 + c];
        *lane(pk, w, F_TNEAR, i) = 0, *lane(pk, w, F_TIME, i) = 0, *lane(pk, w, F_TFAR, i) = INFINITY;
        *ulane(pk, w, F_MASK, i) = ~0u, *ulane(pk, w, F_ID, i) = (unsigned)i, *ulane(pk, w, F_FLAGS, i) = 0;
        if (with_hit)
            *ulane(pk, w, F_GEOM, i) = RTC_INVALID_GEOMETRY_ID;
        valid[i] = i < m ? -1 : 0;
    }
    return m;
}

static void embree_primaryN(const bench *b, int w, found *out)
{
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    struct RTCRayHit16 pk; /* 64-byte aligned; the 8-wide packets use its first part */
    _Alignas(64) int valid[16]; /* Embree reads the mask with aligned vector loads */
    for (int first = 0; first < b->prim.count; first += w) {
        int m = fill_packet(&pk, w, &b->prim, first, valid, 1);
        if (w == 8)
            rtcIntersect8(valid, b->e.scene, &ctx, (struct RTCRayHit8 *)&pk);
        else
            rtcIntersect16(valid, b->e.scene, &ctx, &pk);
        for (int i = 0; i < m; i++) {
            int hit = *ulane(&pk, w, F_GEOM, i) != RTC_INVALID_GEOMETRY_ID;
            out->t[first + i] = hit ? *lane(&pk, w, F_TFAR, i) : INFINITY;
            for (int c = 0; c < 3; c++)
                out->n[3 * (size_t)(first + i) + c] = *lane(&pk, w, F_NG + c, i);
        }
    }
}

static void embree_shadowN(const bench *b, int w, found *out)
{
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    struct RTCRay16 pk;
    _Alignas(64) int valid[16]; /* Embree reads the mask with aligned vector loads */
    for (int first = 0; first < b->shad.count; first += w) {
        int m = fill_packet(&pk, w, &b->shad, first, valid, 0);
        if (w == 8)
            rtcOccluded8(valid, b->e.scene, &ctx, (struct RTCRay8 *)&pk);
        else
            rtcOccluded16(valid, b->e.scene, &ctx, &pk);
        for (int i = 0; i < m; i++)
            out->t[first + i] = *lane(&pk, w, F_TFAR, i) == -INFINITY ? 0 : INFINITY;
    }
}

/* Trace all primary (or shadow) rays with tracer m; returns the thread's CPU seconds. */
static double trace_all(const bench *b, int m, int shadow, found *out)
{
    double t0 = clock_s(CLOCK_THREAD_CPUTIME_ID);
    if (m == M_TF)
        shadow ? tf_shadow_coherent(b, out) : tf_primary_coherent(b, out);
    else if (m == M_TF1)
        shadow ? tf_shadow(b, out) : tf_primary(b, out);
    else if (m == M_E1)
        shadow ? embree_shadow1(b, out) : embree_primary1(b, out);
    else
        shadow ? embree_shadowN(b, mode_width[m], out) : embree_primaryN(b, mode_width[m], out);
    return clock_s(CLOCK_THREAD_CPUTIME_ID) - t0;
}

/* ---- disagreements ---------------------------------------------------------------------- */

typedef struct tally {
    long total, tf_only, embree_only, distance; /* disagreeing rays, by kind */
    long grazing, edge, near;                    /* ... and what they are */
} tally;

/* Distance, in cells, from world (x, y) to the nearest edge or the diagonal of its cell. */
static double edge_distance(const tf_heightfield *hf, double x, double y)
{
    double gx = x / hf->cell, gy = y / hf->cell;
    double fx = gx - floor(gx), fy = gy - floor(gy);
    double d = fmin(fmin(fx, 1 - fx), fmin(fy, 1 - fy));
    return fmin(d, fabs(fx - fy) / sqrt(2.0));
}

/* Sort a disagreeing primary ray i: at the hit one tracer found, is it grazing, near an edge? */
static void classify_primary(const bench *b, const found *e, int i, tally *t)
{
    tf_vec3 d = b->prim.d[i], p, n;
    if (b->ref_hit[i]) {
        p = b->ref[i].p, n = b->ref[i].n;
    } else {
        const float *en = e->n + 3 * (size_t)i;
        p = v3_add(b->prim.o[i], v3_scale(d, e->t[i]));
        n = v3_norm(v3(en[0], en[1], en[2]));
    }
    t->grazing += fabs(v3_dot(d, n)) < GRAZING_COS;
    t->edge += edge_distance(b->hf, p.x, p.y) < EDGE_TOL;
}

/* One disagreeing primary ray, for --list: its pixel, both distances, the cosine with the
 * surface and the distance to a cell edge where one tracer hit. */
static void list_primary(const bench *b, const found *e, int i)
{
    int w = b->prim.count / b->prim_height;
    double tt = b->ref_hit[i] ? b->ref[i].t : INFINITY;
    tally one = {0};
    classify_primary(b, e, i, &one);
    tf_vec3 p = b->ref_hit[i] ? b->ref[i].p : v3_add(b->prim.o[i], v3_scale(b->prim.d[i], e->t[i]));
    printf("    pixel %d,%d: terrafarm t %.6g, Embree t %.6g; grazing %ld; %.2g cells from an edge\n",
           i % w, i / w, tt, e->t[i], one.grazing, edge_distance(b->hf, p.x, p.y));
}

static tally primary_disagreements(const bench *b, const found *e, int list)
{
    tally t = {0};
    for (int i = 0; i < b->prim.count; i++) {
        double tt = b->ref_hit[i] ? b->ref[i].t : INFINITY, et = e->t[i];
        int tf_only = isfinite(tt) && !isfinite(et), e_only = !isfinite(tt) && isfinite(et);
        int dist = isfinite(tt) && isfinite(et) && fabs(et - tt) > T_TOL * tt;
        if (!(tf_only || e_only || dist))
            continue;
        t.total++, t.tf_only += tf_only, t.embree_only += e_only, t.distance += dist;
        classify_primary(b, e, i, &t);
        if (list)
            list_primary(b, e, i);
    }
    return t;
}

/* Sort a disagreeing shadow ray i: the sun grazing its start's triangle, or terrafarm's
 * occluder within NEAR_CELLS of the start. */
static void classify_shadow(const bench *b, int i, tally *t)
{
    const tf_hit *from = &b->ref[b->shad.src[i]];
    tf_hit occ;
    t->grazing += v3_dot(from->n, b->shad.d[i]) < GRAZING_COS;
    if (tf_trace(b->hf, b->shad.o[i], b->shad.d[i], 0.0, TF_FAR_AWAY, &occ)) {
        t->near += occ.t < NEAR_CELLS * b->hf->cell;
        t->edge += edge_distance(b->hf, occ.p.x, occ.p.y) < EDGE_TOL;
    }
}

static tally shadow_disagreements(const bench *b, const found *tf, const found *e)
{
    tally t = {0};
    for (int i = 0; i < b->shad.count; i++) {
        int tf_occ = tf->t[i] == 0, e_occ = e->t[i] == 0;
        if (tf_occ == e_occ)
            continue;
        t.total++, t.tf_only += tf_occ, t.embree_only += e_occ;
        classify_shadow(b, i, &t);
    }
    return t;
}

static void print_disagreements(const bench *b, int m)
{
    tally p = primary_disagreements(b, &b->prim_found[m], b->list && m == M_E1);
    tally s = shadow_disagreements(b, &b->shad_found[M_TF], &b->shad_found[m]);
    printf("  %-22s primary %ld of %d (terrafarm hit only %ld, Embree hit only %ld, distance %ld;"
           " grazing %ld, at a cell edge %ld)\n", mode_name[m], p.total, b->prim.count,
           p.tf_only, p.embree_only, p.distance, p.grazing, p.edge);
    printf("  %-22s shadow %ld of %d (terrafarm occluded only %ld, Embree occluded only %ld;"
           " sun grazing the start %ld, occluder within %.0f cells %ld, at a cell edge %ld)\n", "",
           s.total, b->shad.count, s.tf_only, s.embree_only, s.grazing, NEAR_CELLS, s.near, s.edge);
}

/* ---- the rounds ------------------------------------------------------------------------- */

static int found_alloc(found *f, int count)
{
    f->t = malloc(sizeof *f->t * (size_t)(count + 1));
    f->n = malloc(3 * sizeof *f->n * (size_t)(count + 1));
    return f->t && f->n ? 0 : -1;
}

/* Every tracer on every ray, round after round; rates[m][shadow][round] in rays per second. */
static void run_rounds(bench *b, int rounds, double rates[M_COUNT][2][MAX_ROUNDS])
{
    for (int r = 0; r < rounds; r++)
        for (int shadow = 0; shadow < 2; shadow++)
            for (int m = 0; m < b->modes; m++) {
                found *f = shadow ? &b->shad_found[m] : &b->prim_found[m];
                double secs = trace_all(b, m, shadow, f);
                int count = shadow ? b->shad.count : b->prim.count;
                rates[m][shadow][r] = secs > 0 ? count / secs : 0;
            }
}

/* The median of each round's ratio tracer a / tracer m. */
static double median_ratio(double rates[M_COUNT][2][MAX_ROUNDS], int a, int m, int shadow,
                           int rounds)
{
    double q[MAX_ROUNDS];
    for (int r = 0; r < rounds; r++)
        q[r] = rates[m][shadow][r] > 0 ? rates[a][shadow][r] / rates[m][shadow][r] : 0;
    return tf_bench_median(q, rounds);
}

static void report(const bench *b, double rates[M_COUNT][2][MAX_ROUNDS], int rounds)
{
    printf("Mrays/s per core (CPU time of the tracing thread), median of %d rounds:\n", rounds);
    printf("  %-22s %10s %10s\n", "", "primary", "shadow");
    for (int m = 0; m < b->modes; m++)
        printf("  %-22s %10.3f %10.3f\n", mode_name[m], tf_bench_median(rates[m][0], rounds) / 1e6,
               tf_bench_median(rates[m][1], rounds) / 1e6);
    printf("disagreements with terrafarm (hit vs miss, or distances %g apart relative):\n", T_TOL);
    for (int m = M_E1; m < b->modes; m++)
        print_disagreements(b, m);
    const found *c = &b->prim_found[M_TF], *one = &b->prim_found[M_TF1];
    long differ = 0;
    for (int i = 0; i < b->prim.count; i++)
        differ += memcmp(&c->t[i], &one->t[i], sizeof *c->t) != 0 ||
                  memcmp(&c->n[3 * (size_t)i], &one->n[3 * (size_t)i], 3 * sizeof *c->n) != 0;
    long shadow_differ = 0;
    for (int i = 0; i < b->shad.count; i++)
        shadow_differ += b->shad_found[M_TF].t[i] != b->shad_found[M_TF1].t[i];
    printf("terrafarm coherent vs ray by ray: %ld of %d primary hits and %ld of %d shadow rays "
           "differ\n", differ, b->prim.count, shadow_differ, b->shad.count);
    for (int m = b->modes - 1; m >= M_E8; m--)
        printf("terrafarm/embree%d ratio: primary %.3f shadow %.3f; ray by ray: primary %.3f "
               "shadow %.3f (medians of the rounds' ratios)\n", mode_width[m],
               median_ratio(rates, M_TF, m, 0, rounds), median_ratio(rates, M_TF, m, 1, rounds),
               median_ratio(rates, M_TF1, m, 0, rounds), median_ratio(rates, M_TF1, m, 1, rounds));
}

/* ---- setup and main --------------------------------------------------------------------- */

static void print_header(const bench *b, const opts *o, const tf_scene *s)
{
    char cpu[256];
    tf_bench_cpu_model(cpu, sizeof cpu);
    printf("cpu: %s; vector ISA: %s; Embree %ld (native packets: 8 %s, 16 %s)\n", cpu,
           tf_bench_vector_isa(), (long)rtcGetDeviceProperty(b->e.dev, RTC_DEVICE_PROPERTY_VERSION),
           rtcGetDeviceProperty(b->e.dev, RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED) ? "yes" : "no",
           rtcGetDeviceProperty(b->e.dev, RTC_DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED) ? "yes" : "no");
    printf("field: %s's terrain at %dx%d samples (cell %.4g), as Embree %s%s\n", o->scene, b->hf->n,
           b->hf->n, b->hf->cell, o->grid ? o->grid == 1 ? "grid, columns mirrored" : "grid, unmirrored (the other diagonal)" : "triangle mesh, 2 a cell",
           o->robust ? " (robust)" : "");
    print_builds(b, o);
    int hits = 0;
    for (int i = 0; i < b->prim.count; i++)
        hits += b->ref_hit[i];
    printf("rays: %dx%d primary (%d hit the terrain), %d shadow toward the sun (from the hits facing it)\n",
           s->width, s->height, hits, b->shad.count);
    size_t grids, all = tf_bytes(b->hf, &grids), strips = tf_sun_strips_bytes(b->strips);
    printf("terrafarm's sun strips (the coherent mode's shadow rays): build %.3f s on one thread, "
           "%.1f MB; with them terrafarm holds %.1f MB (%.3f of Embree's)\n",
           b->strips_build_s, strips / 1e6, (all + strips) / 1e6,
           (double)(all + strips) / (double)(b->e.buffer_bytes + b->e.bvh_bytes));
}

/* Terrain, builds, rays and result arrays.  0, or -1 with one line in err. */
static int setup(bench *b, const tf_scene *s, const opts *o, char *err, size_t errlen)
{
    double extent;
    if (embree_open(&b->e, o->threads, err, errlen) != 0)
        return -1;
    float *h = tf_terrain_heights(&s->terrain, o->threads, &extent, err, errlen);
    if (!h || build_both(b, h, extent, o, err, errlen) != 0)
        return -1;
    if (primary_rays(&b->prim, s, err, errlen) != 0)
        return -1;
    b->ref = malloc(sizeof *b->ref * (size_t)b->prim.count);
    b->ref_hit = malloc((size_t)b->prim.count);
    if (!b->ref || !b->ref_hit)
        return tf_seterr(err, errlen, "out of memory: %d hits", b->prim.count);
    if (shadow_rays(b, s, err, errlen) != 0)
        return -1;
    b->prim_height = s->height;
    b->list = o->list;
    b->modes = strcmp(tf_bench_vector_isa(), "avx512") ? M_E8 + 1 : M_E16 + 1;
    for (int m = 0; m < b->modes; m++)
        if (found_alloc(&b->prim_found[m], b->prim.count) || found_alloc(&b->shad_found[m], b->shad.count))
            return tf_seterr(err, errlen, "out of memory: results of %d rays", b->prim.count);
    return 0;
}

static void teardown(bench *b)
{
    for (int m = 0; m < M_COUNT; m++) {
        free(b->prim_found[m].t), free(b->prim_found[m].n);
        free(b->shad_found[m].t), free(b->shad_found[m].n);
    }
    rays_free(&b->prim);
    rays_free(&b->shad);
    free(b->ref);
    free(b->ref_hit);
    embree_drop_scene(&b->e);
    if (b->e.dev)
        rtcReleaseDevice(b->e.dev);
    tf_sun_strips_free(b->strips);
    if (b->hf)
        tf_heightfield_free(b->hf);
}

static int usage(void)
{
    fprintf(stderr, "usage: embree_compare [-k K] [-s WxH] [-r ROUNDS] [-j THREADS] [--grid | --grid-unmirrored] [--robust] [--list] [SCENE]\n"
                    "       embree_compare --smoke [SCENE]\n");
    return 2;
}

/* The value of option argv[*a] as an int in [lo, hi], or -1. */
static int int_arg(int argc, char **argv, int *a, int lo, int hi)
{
    char *end;
    if (*a + 1 >= argc)
        return -1;
    long v = strtol(argv[++*a], &end, 10);
    return *end || v < lo || v > hi ? -1 : (int)v;
}

static int parse_opts(opts *o, int argc, char **argv)
{
    *o = (opts){"scenes/default.scene", 11, 1920, 1080, 7, 0, 0, 0, 0};
    for (int a = 1; a < argc; a++) {
        const char *s = argv[a];
        if (!strcmp(s, "--smoke"))
            o->k = 6, o->w = 32, o->h = 18, o->rounds = 1;
        else if (!strcmp(s, "--grid") || !strcmp(s, "--robust"))
            *(s[2] == 'g' ? &o->grid : &o->robust) = 1;
        else if (!strcmp(s, "--grid-unmirrored"))
            o->grid = 2;
        else if (!strcmp(s, "--list"))
            o->list = 1;
        else if (!strcmp(s, "-s") && a + 1 < argc) {
            if (sscanf(argv[++a], "%dx%d", &o->w, &o->h) != 2 || o->w < 1 || o->h < 1 || o->w > 8192 || o->h > 8192)
                return -1;
        } else if (!strcmp(s, "-k")) {
            if ((o->k = int_arg(argc, argv, &a, 1, TF_TERRAIN_MAX_SIZE_EXP)) < 0)
                return -1;
        } else if (!strcmp(s, "-r")) {
            if ((o->rounds = int_arg(argc, argv, &a, 1, MAX_ROUNDS)) < 0)
                return -1;
        } else if (!strcmp(s, "-j")) {
            if ((o->threads = int_arg(argc, argv, &a, 0, 1024)) < 0)
                return -1;
        } else if (s[0] != '-')
            o->scene = s;
        else
            return -1;
    }
    return 0;
}

int main(int argc, char **argv)
{
    opts o;
    if (parse_opts(&o, argc, argv) != 0)
        return usage();
    char err[512] = "";
    tf_scene *s = load_scene(&o, err, sizeof err);
    static bench b;
    int rc = !s || setup(&b, s, &o, err, sizeof err) != 0;
    if (!rc) {
        static double rates[M_COUNT][2][MAX_ROUNDS];
        print_header(&b, &o, s);
        run_rounds(&b, o.rounds, rates);
        report(&b, rates, o.rounds);
    } else
        fprintf(stderr, "embree_compare: %s\n", err);
    teardown(&b);
    if (s)
        tf_scene_free(s);
    return rc;
}
