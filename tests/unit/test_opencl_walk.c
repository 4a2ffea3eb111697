/* test_opencl_walk.c: the kernels' ray walk (packet_trace.cl's walk_stream, through
 * tf_cl_backend_walk) against trace.c's, on the adversarial fans of test_fans.h: origins above
 * the hills, outside the square, low and grazing, under the surface; fans drifting sideways
 * past what slope_max allows; water planes.  The rendering tests (test_opencl.c) only meet the
 * rays a camera makes; these attack the coherence the kernels took from trace.c.
 *
 *   walk_matches_trace  every ray's hit parameter is tf_trace's to the bit, and its record
 *                       (heading, climb, the run it is above the surface) tf_trace_coherent's:
 *                       walked alone, helped by the record of the ray below it, and helped by a
 *                       random other ray's of its fan (which vouches for nothing when higher);
 *                       and helped by the rays 5 and 10 rows below it, as the pixel kernel's
 *                       samples are by their near and far corners.
 *   a_far_record_is_asked_where_the_near_one_cannot_vouch   a false far record hides the hit
 *                       after a near one that is missing or cannot vouch, and not after a true
 *                       one; a far one that cannot vouch is not used.
 *   a_false_record_hides_a_hit   a record that claims the ray below stayed clear beyond this
 *                       ray's hit makes the kernel's walk start past it: the records are what
 *                       the walk goes by (so walk_matches_trace can fail).
 *   the_prefix_finds_a_hit_before_the_lower_ray_enters   a ray helped by a lower one's record
 *                       still hits a hill before the lower ray enters the square: the prefix
 *                       walk (trace.c's C3), which no fan happens to need.
 *   parallel_rays_match_trace   rays of one direction (the shadow rays' case: the kernels set
 *                       the direction up once and skip the box's divisions where a ray's
 *                       window stays in the box, window_in_box8), from origins over, under and
 *                       outside the square, with short and endless windows: tf_trace's hits.
 * On PoCL's CPU device the bits are demanded; elsewhere the test says so and asks nothing (a
 * GPU's division may round differently).  Skipped without an OpenCL platform. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <cmocka.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define CL_TARGET_OPENCL_VERSION 120
#include <CL/cl.h>

#include "worker/backend_opencl.h"
#include "render/trace.h"
#include "scene.h"
#include "test_terrains.h"
#include "test_fans.h"

enum { FANS = 400, RAYS = FANS * FAN_ROWS, REC = 5 };

static int have_platform(void)
{
    cl_uint n = 0;
    return clGetPlatformIDs(0, NULL, &n) == CL_SUCCESS && n > 0;
}

/* A field and a backend over it (default.scene's parameters, the field's heights), on PoCL's
 * CPU device: the test is skipped without an OpenCL platform, or on another device (whose
 * bits are not asked). */
typedef struct walk_env {
    tf_heightfield *hf;
    tf_scene *s;
    tf_cl_backend *b;
} walk_env;

static void env_free(walk_env *e)
{
    tf_cl_backend_free(e->b);
    tf_scene_free(e->s);
    tf_heightfield_free(e->hf);
}

static walk_env env_over(height_fn fn, int k, double extent)
{
    if (!have_platform()) {
        print_message("no OpenCL platform: skipping\n");
        skip();
    }
    walk_env e = {make_field(fn, k, extent), NULL, NULL};
    char err[1024], path[4096];
    const char *root = getenv("TF_ROOT");
    snprintf(path, sizeof path, "%s/scenes/default.scene", root ? root : ".");
    e.s = tf_scene_load(path, err, sizeof err);
    assert_non_null(e.s);
    tf_scene_set_size(e.s, 16, 9);
    e.b = tf_cl_backend_new(e.s, e.hf, err, sizeof err);
    if (!e.b)
        fail_msg("OpenCL backend: %s", err);
    if (strncmp(tf_cl_backend_device(e.b), "pthread", 7) != 0) {
        print_message("device %s is not PoCL's CPU: its bits are not asked\n",
                      tf_cl_backend_device(e.b));
        env_free(&e);
        skip();
    }
    return e;
}

static void put_record(double *r, const tf_ray_clear *c)
{
    r[0] = c->ux, r[1] = c->uy, r[2] = c->k, r[3] = c->s_in, r[4] = c->s_free;
}

/* Ray k of the kernel's walk against trace.c: its hit parameter, and (if rec) its record. */
static void check_ray(const tf_heightfield *hf, const ray_fan *f, int row, double t,
                      const double *rec, const char *how)
{
    tf_hit hit;
    tf_ray_clear mine;
    const int found = tf_trace_coherent(hf, f->o, f->d[row], f->tmax, NULL, &hit, &mine);
    const double want = found ? hit.t : INFINITY;
    if (memcmp(&want, &t, sizeof t) != 0)
        fail_msg("%s: o=(%.17g,%.17g,%.17g) d=(%.17g,%.17g,%.17g) t %.17g, C %.17g", how,
                 f->o.x, f->o.y, f->o.z, f->d[row].x, f->d[row].y, f->d[row].z, t, want);
    if (!rec)
        return;
    double c[REC];
    put_record(c, &mine);
    if (memcmp(&c[4], &rec[4], sizeof c[4]) != 0 ||
        (mine.s_free > 0 && memcmp(c, rec, sizeof c) != 0))
        fail_msg("%s: record (%.17g %.17g %.17g %.17g %.17g), C (%.17g %.17g %.17g %.17g %.17g)",
                 how, rec[0], rec[1], rec[2], rec[3], rec[4], c[0], c[1], c[2], c[3], c[4]);
}

static void walk(tf_cl_backend *b, const double *rays, const double *lows, const double *fars,
                 double *t, double *rec)
{
    char err[1024];
    if (tf_cl_backend_walk(b, RAYS, rays, lows, fars, t, rec, err, sizeof err))
        fail_msg("%s", err);
}

/* lows[m] = the record of the ray `back` rows below ray m in its fan (none below the fan). */
static void records_below(const double *rec, int back, double *lows)
{
    for (int m = 0; m < RAYS; m++) {
        const int row = m % FAN_ROWS;
        if (row - back < 0)
            memset(lows + (size_t)m * REC, 0, sizeof(double) * REC);
        else
            memcpy(lows + (size_t)m * REC, rec + (size_t)(m - back) * REC, sizeof(double) * REC);
    }
}

static void fans_over(height_fn fn, int k, double extent, uint64_t seed)
{
    walk_env env = env_over(fn, k, extent);
    const tf_heightfield *hf = env.hf;
    tf_cl_backend *b = env.b;
    ray_fan *fans = malloc(sizeof *fans * FANS);
    double *rays = malloc(sizeof *rays * RAYS * 7), *t = malloc(sizeof *t * RAYS);
    double *rec = malloc(sizeof *rec * RAYS * REC), *lows = malloc(sizeof *lows * RAYS * REC);
    double *rec2 = malloc(sizeof *rec2 * RAYS * REC), *fars = malloc(sizeof *fars * RAYS * REC);
    assert_true(fans && rays && t && rec && lows && rec2 && fars);
    rng r = {seed};
    for (int n = 0; n < FANS; n++) {
        make_fan(hf, &r, n, &fans[n]);
        for (int i = 0; i < FAN_ROWS; i++) {
            double *y = rays + (size_t)(n * FAN_ROWS + i) * 7;
            const tf_vec3 o = fans[n].o, d = fans[n].d[i];
            y[0] = o.x, y[1] = o.y, y[2] = o.z, y[3] = d.x, y[4] = d.y, y[5] = d.z;
            y[6] = fans[n].tmax;
        }
    }
    walk(b, rays, NULL, NULL, t, rec); /* alone: the hits, and the records that help below */
    int hits = 0, vouching = 0;
    for (int m = 0; m < RAYS; m++) {
        check_ray(hf, &fans[m / FAN_ROWS], m % FAN_ROWS, t[m], rec + (size_t)m * REC, "alone");
        hits += t[m] < INFINITY;
        vouching += rec[(size_t)m * REC + 4] > 0;
    }
    records_below(rec, 1, lows); /* the ray below's record */
    walk(b, rays, lows, NULL, t, rec2);
    for (int m = 0; m < RAYS; m++)
        check_ray(hf, &fans[m / FAN_ROWS], m % FAN_ROWS, t[m], NULL, "helped by the ray below");
    for (int m = 0; m < RAYS; m++) { /* a random ray's of its fan */
        const int from = m - m % FAN_ROWS + (int)(uni(&r) * FAN_ROWS) % FAN_ROWS;
        memcpy(lows + (size_t)m * REC, rec + (size_t)from * REC, sizeof(double) * REC);
    }
    walk(b, rays, lows, NULL, t, rec2);
    for (int m = 0; m < RAYS; m++)
        check_ray(hf, &fans[m / FAN_ROWS], m % FAN_ROWS, t[m], NULL, "helped by another ray");
    records_below(rec, 5, lows);
    records_below(rec, 10, fars);
    walk(b, rays, lows, fars, t, rec2);
    for (int m = 0; m < RAYS; m++)
        check_ray(hf, &fans[m / FAN_ROWS], m % FAN_ROWS, t[m], NULL, "helped by rows 5 and 10");
    print_message("%d rays, %d hits, %d records vouching\n", RAYS, hits, vouching);
    assert_true(hits > RAYS / 5);
    assert_true(vouching > RAYS / 5);
    free(fans), free(rays), free(t), free(rec), free(lows), free(rec2), free(fars);
    env_free(&env);
}

static void walk_matches_trace_hills(void **state) { (void)state; fans_over(hills, 7, 1000, 2); }
static void walk_matches_trace_rough(void **state) { (void)state; fans_over(rough, 5, 100, 1); }
static void walk_matches_trace_terraces(void **state)
{
    (void)state;
    fans_over(terraces, 6, 300, 3);
}

/* trace.c's test of the same name, on the kernels: the lying record's ray misses. */
static void a_false_record_hides_a_hit(void **state)
{
    (void)state;
    walk_env env = env_over(hills, 6, 1000);
    const tf_heightfield *hf = env.hf;
    tf_cl_backend *b = env.b;
    const tf_vec3 o = v3(500, 100, hf->hmax + 50), d = v3(0, 1, -0.3);
    tf_hit hit;
    assert_true(tf_trace(hf, o, d, 0.0, INFINITY, &hit));
    const double ray[7] = {o.x, o.y, o.z, d.x, d.y, d.z, INFINITY};
    const double lie[REC] = {0, 1, -0.31, 0, 2 * hit.t}, none[REC] = {0};
    double t, rec[REC];
    char err[1024];
    assert_int_equal(tf_cl_backend_walk(b, 1, ray, none, NULL, &t, rec, err, sizeof err), 0);
    assert_true(t == hit.t);
    assert_int_equal(tf_cl_backend_walk(b, 1, ray, lie, NULL, &t, rec, err, sizeof err), 0);
    assert_true(isinf(t));
    env_free(&env);
}

/* The far record is asked only where the near one cannot vouch.  A false far record (it claims
 * the run past this ray's hit) hides the hit after a missing near record and after one that
 * climbs faster than this ray (so cannot vouch), not after a true one; a far record that climbs
 * faster cannot vouch and is not used, however far it claims. */
static void a_far_record_is_asked_where_the_near_one_cannot_vouch(void **state)
{
    (void)state;
    walk_env env = env_over(hills, 6, 1000);
    const tf_heightfield *hf = env.hf;
    tf_cl_backend *b = env.b;
    const tf_vec3 o = v3(500, 100, hf->hmax + 50), d = v3(0, 1, -0.3), low = v3(0, 1, -0.32);
    tf_hit hit;
    assert_true(tf_trace(hf, o, d, 0.0, INFINITY, &hit));
    double below[REC], t, rec[REC];
    char err[1024];
    const double low_ray[7] = {o.x, o.y, o.z, low.x, low.y, low.z, INFINITY};
    assert_int_equal(tf_cl_backend_walk(b, 1, low_ray, NULL, NULL, &t, below, err, sizeof err), 0);
    assert_true(below[4] > 0);
    const double ray[7] = {o.x, o.y, o.z, d.x, d.y, d.z, INFINITY};
    const double lie[REC] = {0, 1, -0.31, 0, 2 * hit.t}, none[REC] = {0};
    const double climber[REC] = {0, 1, -0.29, 0, 4 * hit.t};
    const double *cases[][2] = {{none, lie}, {climber, lie}, {below, lie}, {none, climber},
                                {below, climber}};
    const int hides[] = {1, 1, 0, 0, 0};
    for (int c = 0; c < 5; c++) {
        assert_int_equal(
            tf_cl_backend_walk(b, 1, ray, cases[c][0], cases[c][1], &t, rec, err, sizeof err), 0);
        if (hides[c] ? !isinf(t) : t != hit.t)
            fail_msg("case %d: t %.17g, tf_trace's %.17g", c, t, hit.t);
    }
    env_free(&env);
}

/* test_trace_coherent's prefix case on the kernels (test_fans.h): the upper ray, helped by the
 * lower one's record, still hits the hill before the lower ray enters the square. */
static void the_prefix_finds_a_hit_before_the_lower_ray_enters(void **state)
{
    (void)state;
    walk_env env = env_over(edge_hill, 7, 1000);
    const tf_heightfield *hf = env.hf;
    tf_cl_backend *b = env.b;
    tf_vec3 o, lower, upper;
    prefix_rays(&o, &lower, &upper);
    tf_hit plain;
    assert_true(tf_trace(hf, o, upper, 0.0, INFINITY, &plain));
    const double rays[14] = {o.x, o.y, o.z, lower.x, lower.y, lower.z, INFINITY,
                             o.x, o.y, o.z, upper.x, upper.y, upper.z, INFINITY};
    double t[2], rec[2 * REC], lows[2 * REC] = {0};
    char err[1024];
    assert_int_equal(tf_cl_backend_walk(b, 1, rays, NULL, NULL, t, rec, err, sizeof err), 0);
    assert_true(rec[4] > rec[3]); /* the lower ray vouches */
    memcpy(lows + REC, rec, sizeof(double) * REC);
    assert_int_equal(tf_cl_backend_walk(b, 2, rays, lows, NULL, t, rec, err, sizeof err), 0);
    assert_true(t[1] == plain.t);
    env_free(&env);
}

/* Streams of parallel rays, as the shadow rays are, which the kernels set up once for the
 * stream (tf_walk_rays8 sees that every ray shares the first's direction): each direction's
 * rays hit where tf_trace says and leave tf_trace_coherent's records.  Most packets start
 * inside the square with windows of a few cells (what the sun's strips give), so the box's
 * shortcut (window_in_box8) is taken for all their lanes; in every other packet one lane
 * starts just outside the square, and every fifth packet's windows never end, so the
 * shortcut is refused and the box clipped.  A shortcut that kept a window it should have cut
 * (one taken whatever the box) fails here. */
static void parallel_rays_match_trace(void **state)
{
    (void)state;
    walk_env env = env_over(hills, 7, 1000);
    const tf_heightfield *hf = env.hf;
    tf_cl_backend *b = env.b;
    const tf_vec3 dirs[] = {v3_norm(v3(-0.9, -0.33, 0.25)), v3_norm(v3(0.4, 0.7, 0.3)),
                            v3_norm(v3(0.5, -0.2, -0.4)), v3_norm(v3(0, 0.8, 0.2)),
                            v3_norm(v3(-0.6, 0.0, 0.5))};
    enum { N = 2048 };
    double *rays = malloc(sizeof *rays * N * 7), *t = malloc(sizeof *t * N);
    double *rec = malloc(sizeof *rec * N * REC);
    assert_true(rays && t && rec);
    rng r = {7};
    int hits = 0, kept = 0;
    for (size_t k = 0; k < sizeof dirs / sizeof dirs[0]; k++) {
        const tf_vec3 d = dirs[k];
        for (int m = 0; m < N; m++) { /* packets of 8 (the kernels' lanes) */
            double *y = rays + (size_t)m * 7;
            const int lane = m % 8, packet = m / 8;
            /* most packets inside the square with short windows, so the shortcut is open to
             * all their lanes but one: the last lane of every other packet starts outside */
            const int outside = lane == 7 && packet % 2 == 0;
            y[0] = range(&r, 0, 1000), y[1] = range(&r, 0, 1000);
            if (outside && uni(&r) < 0.5) /* a few cells out, so that it enters in its window */
                y[0] = uni(&r) < 0.5 ? range(&r, -20, -0.1) : range(&r, 1000.1, 1020);
            else if (outside)
                y[1] = uni(&r) < 0.5 ? range(&r, -20, -0.1) : range(&r, 1000.1, 1020);
            const int endless = packet % 5 == 4;
            y[2] = endless ? range(&r, hf->hmin - 20, hf->hmax + 40)
                           : range(&r, hf->hmin + 30, hf->hmax - 30);
            y[3] = d.x, y[4] = d.y, y[5] = d.z;
            y[6] = endless ? INFINITY : range(&r, 1, 30); /* a few cells, as the strips say */
        }
        char err[1024];
        if (tf_cl_backend_walk(b, N, rays, NULL, NULL, t, rec, err, sizeof err))
            fail_msg("%s", err);
        for (int m = 0; m < N; m++) {
            const double *y = rays + (size_t)m * 7;
            const tf_vec3 o = v3(y[0], y[1], y[2]);
            tf_hit hit;
            tf_ray_clear mine;
            const int found = tf_trace_coherent(hf, o, d, y[6], NULL, &hit, &mine);
            const double want = found ? hit.t : INFINITY;
            if (memcmp(&want, &t[m], sizeof want) != 0)
                fail_msg("direction %zu: o=(%.17g,%.17g,%.17g) tmax %.17g: t %.17g, C %.17g", k,
                         o.x, o.y, o.z, y[6], t[m], want);
            double c[REC];
            put_record(c, &mine);
            const double *got = rec + (size_t)m * REC;
            if (memcmp(&c[4], &got[4], sizeof c[4]) != 0 ||
                (mine.s_free > 0 && memcmp(c, got, sizeof c) != 0))
                fail_msg("direction %zu: o=(%.17g,%.17g,%.17g) tmax %.17g: record s_in %.17g "
                         "s_free %.17g, C %.17g %.17g", k, o.x, o.y, o.z, y[6], got[3], got[4],
                         c[3], c[4]);
            hits += found;
            const double top = (double)hf->cells * hf->cell;
            kept += o.x >= 0 && o.x <= top && o.y >= 0 && o.y <= top && isfinite(y[6]);
        }
    }
    print_message("%d parallel rays, %d hits, %d short windows inside the square\n",
                  (int)(N * (sizeof dirs / sizeof dirs[0])), hits, kept);
    assert_true(hits > N / 2);
    assert_true(kept > N);
    free(rays), free(t), free(rec);
    env_free(&env);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(walk_matches_trace_hills),
        cmocka_unit_test(walk_matches_trace_rough),
        cmocka_unit_test(walk_matches_trace_terraces),
        cmocka_unit_test(a_false_record_hides_a_hit),
        cmocka_unit_test(a_far_record_is_asked_where_the_near_one_cannot_vouch),
        cmocka_unit_test(the_prefix_finds_a_hit_before_the_lower_ray_enters),
        cmocka_unit_test(parallel_rays_match_trace),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
