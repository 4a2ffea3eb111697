/* test_shade.c: shading (common/render/shade.c).  Mist: the closed form equals numerical integration,
 * the near-level fallback is continuous with it, extinction is per channel, homogeneous fog,
 * sky rays.  Sky gradient and sun glow.  Materials by altitude and slope, water Fresnel, and
 * (with the real tracer) sun shadows.  Height fields for the material tests are filled in by
 * hand: the shader reads only h, n, cells, cell, extent, hmin, hmax. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <cmocka.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "render/shade.h"
#include "render/trace.h"
#include "terrain/noise.h"
#include "render/sample_math.h" /* the albedo's definition, to check tf_shade_albedo by */

/* Simpson's rule for the optical depth of a straight path (unit speed in t). */
static double numeric_depth(double density, double k, double z1, double z2, double len)
{
    const int n = 20000; /* even */
    double h = len / n, sum = 0;
    for (int i = 0; i <= n; i++) {
        double z = z1 + (z2 - z1) * ((double)i / n);
        double w = (i == 0 || i == n) ? 1 : (i % 2 ? 4 : 2);
        sum += w * density * exp(-k * z);
    }
    return sum * h / 3.0;
}

static void test_mist_closed_form_matches_integration(void **state)
{
    (void)state;
    const double k = log(2.0) / 300.0, density = 0.002;
    const double rays[][3] = {
        {0, 500, 2000}, {800, 10, 5000}, {-50, 1200, 1300}, {300, 300.5, 4000}, {20, 19, 90},
    };
    for (size_t i = 0; i < sizeof rays / sizeof rays[0]; i++) {
        double closed = tf_mist_depth_exp(density, k, rays[i][0], rays[i][1], rays[i][2]);
        double numeric = numeric_depth(density, k, rays[i][0], rays[i][1], rays[i][2]);
        assert_true(fabs(closed - numeric) <= 1e-9 * numeric);
    }
}

static void test_mist_level_fallback_is_continuous(void **state)
{
    (void)state;
    const double k = log(2.0) / 300.0, density = 0.002, z1 = 140, len = 3000;
    double dz_switch = 1e-5 / k; /* where the closed form hands over to the fallback */
    double below = tf_mist_depth_exp(density, k, z1, z1 + dz_switch * (1 - 1e-9), len);
    double above = tf_mist_depth_exp(density, k, z1, z1 + dz_switch * (1 + 1e-9), len);
    assert_true(fabs(above - below) <= 1e-11 * above);
    /* and the fallback itself is right: level ray at z1, and a tiny climb */
    double level = tf_mist_depth_exp(density, k, z1, z1, len);
    assert_true(fabs(level - density * len * exp(-k * z1)) <= 1e-14 * level);
    double tiny = tf_mist_depth_exp(density, k, z1, z1 + 0.5 * dz_switch, len);
    assert_true(fabs(tiny - numeric_depth(density, k, z1, z1 + 0.5 * dz_switch, len)) <=
                1e-11 * tiny);
    /* going down gives the same depth as going up the same span */
    assert_true(tf_mist_depth_exp(density, k, 500, 100, len) ==
                tf_mist_depth_exp(density, k, 100, 500, len));
}

/* A scene and a flat 3x3 height field (k = 1) for shader tests. */
typedef struct fixture {
    tf_scene scene;
    tf_heightfield hf;
    float h[9 * 9];
    tf_shader sh;
} fixture;

static void fill_scene(tf_scene *s)
{
    memset(s, 0, sizeof *s);
    s->width = 64;
    s->height = 64;
    s->sun.azimuth_deg = 180;
    s->sun.elevation_deg = -10; /* below the horizon: no shadow rays, sky light only */
    s->sun.color = v3(1, 0.95, 0.9);
    s->sun.intensity = 3;
    s->sky.zenith = v3(0.1, 0.2, 0.5);
    s->sky.horizon = v3(0.5, 0.6, 0.7);
    s->sky.intensity = 1;
    s->materials.sea_level = -1000;
    s->materials.tree_line = 300;
    s->materials.snow_line = 700;
    s->materials.rock_slope_deg = 40;
    s->mist.density = 0.001;
    s->mist.falloff = 200;
    s->mist.color = v3(1, 1, 1);
    s->mist.extinction = v3(1, 3, 20);
}

/* Heights: a plane z = base + slope_x * x over a 2x2-cell field of extent 100 (k = 1, n = 3). */
static void fill_plane(fixture *f, double base, double slope_x)
{
    f->hf = (tf_heightfield){.k = 1, .n = 3, .cells = 2, .extent = 100, .cell = 50, .h = f->h};
    f->hf.hmin = 1e30f;
    f->hf.hmax = -1e30f;
    for (int j = 0; j < 3; j++)
        for (int i = 0; i < 3; i++) {
            float z = (float)(base + slope_x * 50.0 * i);
            f->h[j * 3 + i] = z;
            f->hf.hmin = fminf(f->hf.hmin, z);
            f->hf.hmax = fmaxf(f->hf.hmax, z);
        }
}

/* Albedo seen at the centre of a plane (sky light only). */
static tf_vec3 shade_plane_centre(fixture *f, double base, double slope_x)
{
    fill_plane(f, base, slope_x);
    tf_shader_init(&f->sh, &f->scene, &f->hf);
    tf_hit hit = {.t = 10, .p = v3(50, 50, base + slope_x * 50), .ci = 1, .cj = 1};
    hit.n = v3_norm(v3(-slope_x, 0, 1));
    uint64_t shadow = 0;
    tf_vec3 c = tf_shade_terrain(&f->sh, &hit, &shadow);
    assert_true(shadow == 0); /* sun below the horizon */
    /* divide out the (blue) sky light on the plane's normal: what is left is the albedo */
    tf_vec3 light = v3_scale(f->sh.sky_light, 0.5 + 0.5 * hit.n.z);
    return v3(c.x / light.x, c.y / light.y, c.z / light.z);
}

static void test_mist_extinction_is_per_channel(void **state)
{
    (void)state;
    fixture *f = calloc(1, sizeof *f);
    fill_scene(&f->scene);
    f->scene.mist.enabled = 1;
    fill_plane(f, 0, 0);
    tf_shader_init(&f->sh, &f->scene, &f->hf);
    /* level ray at z = 0: tau = density * len */
    double len = 400, tau = 0.001 * 400;
    tf_vec3 c = tf_mist_apply(&f->sh, v3(0, 0, 0), v3(0, 0, 0), v3(1, 0, 0), len);
    assert_true(fabs(c.x - (1 - exp(-tau))) < 1e-12);
    assert_true(fabs(c.y - (1 - exp(-3 * tau))) < 1e-12);
    assert_true(fabs(c.z - (1 - exp(-20 * tau))) < 1e-12);
    assert_true(c.z > c.y && c.y > c.x); /* distant dark ridges turn blue */
    /* a channel without extinction passes the surface colour unchanged */
    f->scene.mist.extinction = v3(0, 1, 1);
    c = tf_mist_apply(&f->sh, v3(0.25, 0, 0), v3(0, 0, 0), v3(1, 0, 0), len);
    assert_true(c.x == 0.25);
    /* homogeneous fog ignores altitude */
    f->scene.mist.homogeneous = 1;
    f->scene.mist.extinction = v3(1, 1, 1);
    c = tf_mist_apply(&f->sh, v3(0, 0, 0), v3(0, 0, 900), v3(1, 0, 0), len);
    assert_true(fabs(c.x - (1 - exp(-tau))) < 1e-12);
    /* disabled: nothing happens */
    f->scene.mist.enabled = 0;
    c = tf_mist_apply(&f->sh, v3(0.3, 0.2, 0.1), v3(0, 0, 0), v3(1, 0, 0), len);
    assert_true(c.x == 0.3 && c.y == 0.2 && c.z == 0.1);
    free(f);
}

static void test_sky_rays_through_mist(void **state)
{
    (void)state;
    fixture *f = calloc(1, sizeof *f);
    fill_scene(&f->scene);
    f->scene.mist.enabled = 1;
    fill_plane(f, 0, 0);
    tf_shader_init(&f->sh, &f->scene, &f->hf);
    /* climbing ray: the integral to infinity converges to density e^{-k z} / (k dz) */
    tf_vec3 dir = v3(0.6, 0, 0.8), o = v3(0, 0, 50);
    double k = log(2.0) / 200;
    double tau = 0.001 * exp(-k * 50) / (k * 0.8);
    assert_true(fabs(tau - numeric_depth(0.001, k, 50, 50 + 0.8 * 20000, 20000)) < 1e-9 * tau);
    tf_vec3 c = tf_mist_apply(&f->sh, v3(0, 0, 0), o, dir, INFINITY);
    assert_true(fabs(c.x - (1 - exp(-tau))) < 1e-12);
    assert_true(fabs(c.z - (1 - exp(-20 * tau))) < 1e-12);
    /* a level ray never leaves the mist: pure mist colour */
    c = tf_mist_apply(&f->sh, v3(0.2, 0.2, 0.2), o, v3(1, 0, 0), INFINITY);
    assert_true(c.x == 1 && c.y == 1 && c.z == 1);
    free(f);
}

static void test_sky_gradient_and_sun_glow(void **state)
{
    (void)state;
    fixture *f = calloc(1, sizeof *f);
    fill_scene(&f->scene);
    f->scene.sun.elevation_deg = 5;
    fill_plane(f, 0, 0);
    tf_shader_init(&f->sh, &f->scene, &f->hf);
    tf_vec3 zen = tf_sky_color(&f->sh, v3(0, 0, 1));
    assert_true(fabs(zen.z - 0.5) < 1e-6 && fabs(zen.x - 0.1) < 1e-6);
    tf_vec3 away = tf_sky_color(&f->sh, v3(0, 1, 0)); /* north; the sun is south */
    assert_true(away.x == 0.5 && away.y == 0.6 && away.z == 0.7);
    tf_vec3 toward = tf_sky_color(&f->sh, f->sh.sun_dir);
    assert_true(toward.x > away.x + 0.5);
    tf_vec3 below = tf_sky_color(&f->sh, v3(0, 0.6, -0.8));
    assert_true(below.x == away.x && below.z == away.z);
    free(f);
}

static void test_materials_by_altitude_and_slope(void **state)
{
    (void)state;
    fixture *f = calloc(1, sizeof *f);
    fill_scene(&f->scene);
    tf_vec3 low = shade_plane_centre(f, 100, 0);    /* below the tree line, flat */
    tf_vec3 snow = shade_plane_centre(f, 900, 0);   /* above the snow line, flat */
    tf_vec3 mid = shade_plane_centre(f, 500, 0);    /* alpine ground */
    tf_vec3 cliff = shade_plane_centre(f, 100, 2.0); /* 63 degrees: rock even low down */
    assert_true(low.y > low.x && low.y > low.z);    /* green */
    assert_true(snow.x > 5 * low.y && snow.z > 5 * low.y); /* white and bright */
    assert_true(fabs(snow.x - snow.z) < 0.1 * snow.x);
    assert_true(mid.x > mid.z && !(mid.y > mid.x)); /* brownish, not green */
    assert_true(cliff.x >= cliff.y && cliff.y >= cliff.z); /* grey rock, no green */
    assert_true(cliff.z > 0.6 * cliff.x);
    /* transitions are smooth: halfway across the tree line band is between both sides */
    tf_vec3 at_line = shade_plane_centre(f, 300, 0);
    assert_true(at_line.y < low.y || at_line.x > low.x);
    assert_true(at_line.x < mid.x + 1e-9 && at_line.x > low.x - 1e-9);
    free(f);
}

/* The snow line moved by its full five-octave fBm at p, and the albedo with it: the definition
 * that tf_shade_albedo may shorten (shade.c's snow_line_at) but must match bit for bit. */
static double snow_line_by_definition(const tf_shader *sh, tf_vec3 p)
{
    double fbm = tf_fbm2(&sh->noise, tf_snow_u(p.x, sh->hf->extent),
                         tf_snow_v(p.y, sh->hf->extent), TF_SNOW_H, 2.0, TF_SNOW_OCTAVES);
    return sh->scene->materials.snow_line + sh->scene->materials.snow_jitter * fbm;
}

static tf_vec3 albedo_by_definition(const tf_shader *sh, tf_vec3 p, tf_vec3 n, double variation)
{
    const tf_scene *s = sh->scene;
    return tf_terrain_albedo(s->materials.tree_line, s->materials.sea_level,
                             s->materials.rock_slope_deg, sh->band, p.z, tf_slope_deg(n.z),
                             snow_line_by_definition(sh, p), variation);
}

static double uniform(double lo, double hi) { return lo + (hi - lo) * rand() / RAND_MAX; }

/* default.scene's materials over a level plane at the snow line (700), its line moved by up to
 * 40 times the snow fBm, the shader set up. */
static fixture *snowy_plane(void)
{
    fixture *f = calloc(1, sizeof *f);
    fill_scene(&f->scene);
    f->scene.materials.snow_jitter = 40;
    fill_plane(f, 700, 0);
    tf_shader_init(&f->sh, &f->scene, &f->hf);
    return f;
}

/* Points all through the snow line's reach (jitter times the fBm's bound, plus the band), and
 * just inside the band around the line itself, where a shortcut that under-bounds the octaves
 * it skips gives a clamped weight for a partial one; slopes all through the snow's slide,
 * half of them within a degree of where the snow slides off. */
static void test_snow_line_shortcuts_keep_the_albedo(void **state)
{
    (void)state;
    fixture *f = snowy_plane();
    const double band = f->sh.band, reach = 40 * tf_shade_snow_fbm_bound() + band;
    const double slide = f->scene.materials.rock_slope_deg + TF_SNOW_SLIDE_DEG;
    srand(7);
    int differ = 0, snowy = 0, bare = 0;
    for (int i = 0; i < 300000; i++) {
        tf_vec3 p = v3(uniform(0, 100), uniform(0, 100), 0);
        double line = snow_line_by_definition(&f->sh, p);
        p.z = i % 3 == 0 ? uniform(700 - 1.2 * reach, 700 + 1.2 * reach)
                         : line + (i % 3 == 1 ? 0.999 : -0.999) * band;
        double slope = i % 2 ? uniform(slide - 1, slide + 1) : uniform(0, 90);
        tf_vec3 n = v3(sin(slope * TF_DEG2RAD), 0, cos(slope * TF_DEG2RAD));
        tf_vec3 got = tf_shade_albedo(&f->sh, p, n, 0.25);
        tf_vec3 want = albedo_by_definition(&f->sh, p, n, 0.25);
        differ += memcmp(&got, &want, sizeof got) != 0;
        snowy += got.z > 0.6, bare += got.z < 0.4;
    }
    assert_int_equal(differ, 0);
    assert_true(snowy > 10000 && bare > 10000); /* both sides of the line were met */
    free(f);
}

/* Normals whose slope lies on either side of the blends' edges (shade.c's material_slope), by a
 * few ulps of their z and by up to a degree: the albedo has the definition's bits, with the
 * acos or without it. */
static void test_slope_shortcuts_keep_the_albedo(void **state)
{
    (void)state;
    fixture *f = snowy_plane();
    const double edges[2] = {f->sh.nz_gentle, f->sh.nz_steep};
    assert_true(edges[0] < 1 && edges[1] > 0); /* default.scene's rock slope has both */
    srand(11);
    int differ = 0, checked = 0;
    for (int e = 0; e < 2; e++) {
        double nz = edges[e];
        for (int k = 0; k < 40; k++)
            nz = nextafter(nz, -2);
        for (int i = 0; i < 20000; i++) {
            double z = i < 80 ? nz : edges[e] + uniform(-0.02, 0.02);
            if (i < 80)
                nz = nextafter(nz, 2);
            tf_vec3 n = v3(sqrt(1 - z * z), 0, z);
            tf_vec3 p = v3(uniform(0, 100), uniform(0, 100), uniform(650, 750));
            tf_vec3 got = tf_shade_albedo(&f->sh, p, n, -0.5);
            tf_vec3 want = albedo_by_definition(&f->sh, p, n, -0.5);
            differ += memcmp(&got, &want, sizeof got) != 0;
            checked++;
        }
    }
    assert_int_equal(differ, 0);
    assert_int_equal(checked, 40000);
    free(f);
}

static void test_water_reflects_sky_with_fresnel(void **state)
{
    (void)state;
    fixture *f = calloc(1, sizeof *f);
    fill_scene(&f->scene);
    fill_plane(f, -50, 0);
    f->scene.materials.sea_level = 0;
    tf_shader_init(&f->sh, &f->scene, &f->hf);
    uint64_t shadow = 0;
    tf_vec3 steep = tf_shade_water(&f->sh, v3(50, 50, 0), v3_norm(v3(0, 0.2, -1)), 100, &shadow);
    tf_vec3 grazing = tf_shade_water(&f->sh, v3(50, 50, 0), v3_norm(v3(0, 1, -0.02)), 100, &shadow);
    assert_true(steep.z > steep.x);              /* blue */
    assert_true(grazing.z > 4 * steep.z);        /* Fresnel: bright at grazing angles */
    tf_vec3 horizon = f->scene.sky.horizon;      /* ... approaching the sky it mirrors */
    assert_true(grazing.z > 0.7 * horizon.z && grazing.z <= horizon.z * 1.001);
    free(f);
}

/* Needs the real tracer: a wall between the sun and the ground casts a shadow. */
static void test_sun_shadow_through_tracer(void **state)
{
    (void)state;
    fixture *f = calloc(1, sizeof *f);
    fill_scene(&f->scene);
    f->scene.sun.azimuth_deg = 270; /* west, 45 degrees up: the wall's shadow reaches x = 600 */
    f->scene.sun.elevation_deg = 45;
    /* 9x9 samples (k = 3), flat at 0 with a tall north-south wall at i = 2 */
    float h[81];
    for (int j = 0; j < 9; j++)
        for (int i = 0; i < 9; i++)
            h[j * 9 + i] = i == 2 ? 400.0f : 0.0f;
    tf_heightfield *hf = tf_heightfield_from_heights(h, 3, 800, 1);
    assert_non_null(hf);
    tf_shader_init(&f->sh, &f->scene, hf);
    uint64_t shadow = 0;
    tf_hit shaded = {.t = 1, .p = v3(450, 400, 0), .n = v3(0, 0, 1), .ci = 4, .cj = 4};
    tf_hit open = {.t = 1, .p = v3(750, 400, 0), .n = v3(0, 0, 1), .ci = 7, .cj = 4};
    tf_vec3 in_shadow = tf_shade_terrain(&f->sh, &shaded, &shadow);
    tf_vec3 in_sun = tf_shade_terrain(&f->sh, &open, &shadow);
    assert_true(shadow == 2);
    assert_true(in_sun.y > 2 * in_shadow.y);
    tf_heightfield_free(hf);
    free(f);
}

/* A convex ridge sloping away from a low western sun, faceted by its 10 m cells: z = 300 -
 * 0.02 (x - 40)^2, level along y; 17 x 17 samples (k = 4).  The slope steepens by 0.4 per
 * cell: cell x in [40, 50] (chord slope 0.2) faces the sun (tan 27 deg = 0.51), cell [50, 60]
 * (chord 0.6) faces away, though its interpolated normal faces the sun up to x = 52.7. */
static tf_heightfield *convex_ridge(void)
{
    float h[17 * 17];
    for (int j = 0; j < 17; j++)
        for (int i = 0; i < 17; i++)
            h[j * 17 + i] = (float)(300.0 - 0.02 * (10.0 * i - 40.0) * (10.0 * i - 40.0));
    return tf_heightfield_from_heights(h, 4, 160, 1);
}

/* The colour of the terrain straight below (x, y), through the real tracer's hit. */
static tf_vec3 shade_below(const tf_shader *sh, double x, double y)
{
    tf_hit hit;
    assert_true(tf_trace(sh->hf, v3(x, y, 1000), v3(0, 0, -1), 0, 1e9, &hit));
    uint64_t shadow = 0;
    return tf_shade_terrain(sh, &hit, &shadow);
}

/* Along the ridge's slope from x = 40 to 70 (0.25 apart, off the vertices): the largest step of
 * the green channel between neighbours, and the step across the edge x = 50 (1e-4 either side). */
static void slope_steps(const tf_shader *sh, double *largest, double *at_edge)
{
    *largest = 0;
    for (double x = 40.125; x < 70; x += 0.25) {
        double step = fabs(shade_below(sh, x + 0.25, 80.3).y - shade_below(sh, x, 80.3).y);
        *largest = fmax(*largest, step);
    }
    *at_edge = fabs(shade_below(sh, 50.0001, 80.3).y - shade_below(sh, 49.9999, 80.3).y);
}

/* terrain.smooth: near the terminator the flat look jumps at the triangle's edge (the cell that
 * faces away is dark whole, its smooth normal notwithstanding); the smooth look varies
 * continuously, lit where the interpolated normal faces the sun, its shadow ray not caught by
 * its own triangles. */
static void test_smooth_terminator_is_continuous(void **state)
{
    (void)state;
    fixture *f = calloc(1, sizeof *f);
    fill_scene(&f->scene);
    f->scene.sun.azimuth_deg = 270;
    f->scene.sun.elevation_deg = 27;
    tf_heightfield *hf = convex_ridge();
    assert_non_null(hf);
    double flat_largest, flat_edge, smooth_largest, smooth_edge;
    tf_shader_init(&f->sh, &f->scene, hf);
    tf_vec3 flat_inside = shade_below(&f->sh, 51, 80.3);
    slope_steps(&f->sh, &flat_largest, &flat_edge);
    f->scene.terrain.smooth = 1;
    tf_shader_init(&f->sh, &f->scene, hf);
    tf_vec3 smooth_inside = shade_below(&f->sh, 51, 80.3);
    slope_steps(&f->sh, &smooth_largest, &smooth_edge);
    print_message("flat: edge step %.4f, largest %.4f; smooth: edge step %.6f, largest %.4f; "
                  "x = 51: %.4f flat, %.4f smooth\n", flat_edge, flat_largest, smooth_edge,
                  smooth_largest, flat_inside.y, smooth_inside.y);
    double lit = shade_below(&f->sh, 49.9999, 80.3).y; /* the uphill side of the edge */
    assert_true(flat_edge > 0.3 * lit);             /* the facet's edge shows */
    assert_true(smooth_edge < 1e-3 * lit);          /* no edge: the step of a 2e-4 move */
    assert_true(smooth_largest < 0.25 * flat_edge); /* and nowhere a jump like it */
    assert_true(smooth_inside.y > flat_inside.y + 0.5 * flat_edge); /* lit past the edge */
    tf_heightfield_free(hf);
    free(f);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_mist_closed_form_matches_integration),
        cmocka_unit_test(test_mist_level_fallback_is_continuous),
        cmocka_unit_test(test_mist_extinction_is_per_channel),
        cmocka_unit_test(test_sky_rays_through_mist),
        cmocka_unit_test(test_sky_gradient_and_sun_glow),
        cmocka_unit_test(test_materials_by_altitude_and_slope),
        cmocka_unit_test(test_snow_line_shortcuts_keep_the_albedo),
        cmocka_unit_test(test_slope_shortcuts_keep_the_albedo),
        cmocka_unit_test(test_water_reflects_sky_with_fresnel),
        cmocka_unit_test(test_sun_shadow_through_tracer),
        cmocka_unit_test(test_smooth_terminator_is_continuous),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
