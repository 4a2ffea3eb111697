/* shade.c: materials, lighting, water, sky and mist; see shade.h for the model.
 *
 * Colours are linear RGB in double precision; only the final sample is rounded to float.
 * Constants below set the default look (greens, greys, white snow, blue water); the scene
 * chooses lines, slopes, sun, sky and mist. */
#include "render/shade.h"

#include <math.h>
#include <pthread.h>
#include <string.h>

/* The inline kernels tf_fbm2 is made of (noise_impl.h calls itself private to noise.c and
 * fractal.c): shading reuses an octave plan and lattice lookups across its three bump sums
 * and must give exactly tf_fbm2's bits, which only the same kernels guarantee. */
#include "terrain/noise_impl.h"

#define DEG2RAD (3.14159265358979323846 / 180.0)
#define FAR_AWAY 1e30

/* Albedos (linear RGB). */
static const tf_vec3 ALBEDO_VEGETATION = {0.040, 0.075, 0.022};
static const tf_vec3 ALBEDO_ALPINE = {0.120, 0.105, 0.070};
static const tf_vec3 ALBEDO_ROCK = {0.200, 0.180, 0.160};
static const tf_vec3 ALBEDO_SNOW = {0.800, 0.820, 0.860};
static const tf_vec3 ALBEDO_SAND = {0.330, 0.290, 0.200};
static const tf_vec3 WATER_BODY = {0.010, 0.028, 0.040};

#define ROCK_BLEND_DEG 6.0     /* rock fades in over rock_slope_deg +- this */
#define SNOW_SLIDE_DEG 15.0    /* snow thins out this far above the rock slope */
#define BUMP_OCTAVES 4.0
#define BUMP_H 0.8
#define SNOW_OCTAVES 5.0
#define RIPPLE_OCTAVES 3.0
#define RIPPLE_STRENGTH 0.06   /* slope amplitude of the water ripples */
#define COLOUR_VARIATION 0.15  /* fractal albedo perturbation (Musgrave 5.6.5) */
#define FRESNEL_R0 0.02        /* water at normal incidence */

static double smoothstep(double e0, double e1, double x)
{
    double t = (x - e0) / (e1 - e0);
    t = t < 0 ? 0 : t > 1 ? 1 : t;
    return t * t * (3.0 - 2.0 * t);
}

void tf_shader_init(tf_shader *sh, const tf_scene *s, const tf_heightfield *hf)
{
    *sh = (tf_shader){0};
    sh->scene = s;
    sh->hf = hf;
    sh->textured = s->materials.bump > 0 || s->materials.snow_jitter > 0;
    if (sh->textured)
        tf_noise_init(&sh->noise, s->terrain.seed ^ 0x7465787475726573ULL); /* "textures" */
    double az = s->sun.azimuth_deg * DEG2RAD, el = s->sun.elevation_deg * DEG2RAD;
    sh->sun_dir = v3(sin(az) * cos(el), cos(az) * cos(el), sin(el));
    sh->sun_light = v3_scale(s->sun.color, s->sun.intensity);
    sh->sky_light = v3_scale(v3_lerp(s->sky.horizon, s->sky.zenith, 0.5), s->sky.intensity);
    sh->mist_k = s->mist.falloff > 0 ? log(2.0) / s->mist.falloff : 0.0;
    double relief = (double)hf->hmax - (double)hf->hmin;
    sh->band = fmax(2.0 * hf->cell, 0.012 * relief);
    sh->bump_scale = 2.0 * hf->cell;
    sh->ripple_scale = fmax(4.0 * hf->cell, hf->extent / 300.0);
    sh->shadow_lift = 0.01 * hf->cell + 1e-6 * relief;
    double columns = s->width > 0 ? s->width : 1;
    if (s->camera.kind == TF_CAMERA_PANORAMA)
        sh->pixel_angle = s->camera.fov_deg * DEG2RAD / columns;
    else
        sh->pixel_angle = 2.0 * tan(0.5 * s->camera.fov_deg * DEG2RAD) / columns;
}

/* How many octaves of a texture whose first octave has wavelength `scale` a pixel can show at
 * distance dist: octave i (wavelength scale / 2^i) is kept while it spans at least two pixel
 * footprints (Nyquist); the last one fades in fractionally, so the cut moves smoothly with
 * distance.  0 means the texture is invisible there. */
static double visible_octaves(const tf_shader *sh, double scale, double dist, double max_octaves)
{
    double footprint = 2.0 * dist * sh->pixel_angle;
    if (!(footprint > 0))
        return max_octaves;
    double octaves = log2(scale / footprint) + 1.0;
    return octaves < 0 ? 0 : octaves > max_octaves ? max_octaves : octaves;
}

/* ---------------------------------------------------------------- surface normals */

static double height_sample(const tf_heightfield *hf, int i, int j)
{
    i = i < 0 ? 0 : i >= hf->n ? hf->n - 1 : i;
    j = j < 0 ? 0 : j >= hf->n ? hf->n - 1 : j;
    return hf->h[(size_t)j * (size_t)hf->n + (size_t)i];
}

/* Vertex normal by central differences (one-sided at the edges, through the clamping). */
static tf_vec3 vertex_normal(const tf_heightfield *hf, int i, int j)
{
    double span_x = (double)((i + 1 < hf->n ? i + 1 : i) - (i > 0 ? i - 1 : i)) * hf->cell;
    double span_y = (double)((j + 1 < hf->n ? j + 1 : j) - (j > 0 ? j - 1 : j)) * hf->cell;
    double dzdx = (height_sample(hf, i + 1, j) - height_sample(hf, i - 1, j)) / span_x;
    double dzdy = (height_sample(hf, i, j + 1) - height_sample(hf, i, j - 1)) / span_y;
    return v3_norm(v3(-dzdx, -dzdy, 1.0));
}

/* Normal interpolated across the hit triangle with barycentric weights.  The cell's diagonal
 * runs from (ci, cj) to (ci+1, cj+1) (heightfield.h), so fx >= fy is the lower-right triangle. */
static tf_vec3 smooth_normal(const tf_heightfield *hf, int ci, int cj, tf_vec3 p)
{
    ci = ci < 0 ? 0 : ci >= hf->cells ? hf->cells - 1 : ci;
    cj = cj < 0 ? 0 : cj >= hf->cells ? hf->cells - 1 : cj;
    double fx = p.x / hf->cell - ci, fy = p.y / hf->cell - cj;
    fx = fx < 0 ? 0 : fx > 1 ? 1 : fx;
    fy = fy < 0 ? 0 : fy > 1 ? 1 : fy;
    tf_vec3 n00 = vertex_normal(hf, ci, cj), n11 = vertex_normal(hf, ci + 1, cj + 1);
    tf_vec3 n;
    if (fx >= fy) {
        tf_vec3 n10 = vertex_normal(hf, ci + 1, cj);
        n = v3_add(v3_add(v3_scale(n00, 1 - fx), v3_scale(n10, fx - fy)), v3_scale(n11, fy));
    } else {
        tf_vec3 n01 = vertex_normal(hf, ci, cj + 1);
        n = v3_add(v3_add(v3_scale(n00, 1 - fy), v3_scale(n01, fy - fx)), v3_scale(n11, fx));
    }
    return v3_norm(n);
}

/* Noise at x and at x_dx (the same lattice row `ay`), as tf_noise2_axis(nz, x, ay) and
 * tf_noise2_axis(nz, x_dx, ay) compute them, operation for operation; when both lie in the same
 * lattice cell along x (nearly always: x_dx - x is small) the two column lines are looked up
 * once.  *n_dy is tf_noise2_axis(nz, x, ay_dy), which shares x's floor and fraction. */
static void noise_triple(const tf_noise *nz, double x, double x_dx, const tf_noise_axis *ay,
                         const tf_noise_axis *ay_dy, double *n, double *n_dx, double *n_dy)
{
    if (!(fabs(x) < TF_NOISE_COORD_LIMIT) || !(fabs(x_dx) < TF_NOISE_COORD_LIMIT) || !ay->ok ||
        !ay_dy->ok) {
        *n = tf_noise2_axis(nz, x, ay);
        *n_dx = tf_noise2_axis(nz, x_dx, ay);
        *n_dy = tf_noise2_axis(nz, x, ay_dy);
        return;
    }
    double fx, fx_dx;
    int64_t xi = tf_floor_split(x, &fx), xi_dx = tf_floor_split(x_dx, &fx_dx);
    tf_noise_column left = tf_noise_column_at(nz, xi, ay);
    tf_noise_column right = tf_noise_column_at(nz, xi + 1, ay);
    *n = tf_noise_blend(fx, left, right);
    if (xi_dx == xi)
        *n_dx = tf_noise_blend(fx_dx, left, right);
    else
        *n_dx = tf_noise_blend(fx_dx, tf_noise_column_at(nz, xi_dx, ay),
                               tf_noise_column_at(nz, xi_dx + 1, ay));
    *n_dy = tf_noise_blend(fx, tf_noise_column_at(nz, xi, ay_dy),
                           tf_noise_column_at(nz, xi + 1, ay_dy));
}

/* ---- octave plans without pow() per call
 *
 * tf_octaves_plan(H, lacunarity 2, octaves) gives amp[i] = pow(2^i, -H) (2^i is exact) for
 * i < count, then scales amp[whole] by the fractional remainder: every plan of a given H is a
 * prefix of the 32-octave plan with at most its last weight scaled.  The texture H values
 * (BUMP_H, 0.5) get their full plan once; texture_plan cuts the prefix.  Made once per process
 * (pthread_once) and checked there against tf_octaves_plan itself on sample octave counts; if
 * noise_impl.h ever plans differently, texture_plan just calls tf_octaves_plan. */
static tf_octaves full_plan_bump, full_plan_half;
static int prefix_plans_exact;
static pthread_once_t full_plans_once = PTHREAD_ONCE_INIT;

static void prefix_plan(tf_octaves *o, const tf_octaves *full, double octaves)
{
    if (!(octaves >= 1.0))
        octaves = 1.0;
    if (octaves > TF_MAX_OCTAVES)
        octaves = TF_MAX_OCTAVES;
    int whole = (int)octaves;
    double remainder = octaves - whole;
    *o = *full;
    o->count = whole + (remainder > 0.0);
    if (remainder > 0.0)
        o->amp[whole] *= remainder;
}

static void make_full_plans(void)
{
    static const double samples[] = {0.0, 0.4, 1.0, 1.3, 2.0, 2.71, 3.5, 4.0, 5.9, 40.0};
    tf_octaves_plan(&full_plan_bump, BUMP_H, 2.0, TF_MAX_OCTAVES);
    tf_octaves_plan(&full_plan_half, 0.5, 2.0, TF_MAX_OCTAVES);
    int exact = 1;
    for (size_t i = 0; i < sizeof samples / sizeof samples[0]; i++) {
        for (int which = 0; which < 2; which++) {
            tf_octaves fast, slow;
            const tf_octaves *full = which ? &full_plan_half : &full_plan_bump;
            prefix_plan(&fast, full, samples[i]);
            tf_octaves_plan(&slow, which ? 0.5 : BUMP_H, 2.0, samples[i]);
            exact &= fast.count == slow.count && fast.lacunarity == slow.lacunarity &&
                     memcmp(fast.amp, slow.amp, (size_t)slow.count * sizeof slow.amp[0]) == 0;
        }
    }
    prefix_plans_exact = exact;
}

/* The plan of tf_octaves_plan(H, 2.0, octaves), from the table when H is a texture's. */
static void texture_plan(tf_octaves *o, double H, double octaves)
{
    pthread_once(&full_plans_once, make_full_plans);
    if (prefix_plans_exact && H == BUMP_H)
        prefix_plan(o, &full_plan_bump, octaves);
    else if (prefix_plans_exact && H == 0.5)
        prefix_plan(o, &full_plan_half, octaves);
    else
        tf_octaves_plan(o, H, 2.0, octaves);
}

/* fBm value and gradient (per world unit, scaled by 1/scale) at (x, y) / scale, by forward
 * differences.  `salt` shifts the domain so different textures are uncorrelated.
 *
 * The three sums are exactly tf_fbm2(nz, q, H, 2.0, octaves) at q, q + (eps, 0) and
 * q + (0, eps) (tf_fbm2 = plan + y axes + tf_fbm2_axes, noise_impl.h): each is accumulated in
 * the same octave order with the same coordinates, scaled octave by octave exactly as
 * tf_fbm2_axes scales them.  But the octave plan (a pow() per octave) is made once, not three
 * times, the value and x-offset sums share their y axes, and noise_triple shares lattice
 * lookups between them.  Same bits as three tf_fbm2 calls, about half the cost. */
static double fbm_with_gradient(const tf_noise *nz, double x, double y, double scale, double H,
                                double octaves, double salt, double *gx, double *gy)
{
    const double eps = 1e-3;
    double qx = x / scale + salt, qy = y / scale - salt;
    tf_octaves plan;
    tf_noise_axis axes[TF_MAX_OCTAVES + 1], axes_dy[TF_MAX_OCTAVES + 1];
    texture_plan(&plan, H, octaves);
    tf_octave_axes(&plan, qy, axes);
    tf_octave_axes(&plan, qy + eps, axes_dy);
    double f = 0.0, f_dx = 0.0, f_dy = 0.0;
    double xo = qx, xo_dx = qx + eps;
    for (int i = 0; i < plan.count; i++) {
        double n, n_dx, n_dy;
        noise_triple(nz, xo, xo_dx, &axes[i], &axes_dy[i], &n, &n_dx, &n_dy);
        f += plan.amp[i] * n;
        f_dx += plan.amp[i] * n_dx;
        f_dy += plan.amp[i] * n_dy;
        xo *= plan.lacunarity;
        xo_dx *= plan.lacunarity;
    }
    *gx = (f_dx - f) / eps;
    *gy = (f_dy - f) / eps;
    return f;
}

/* The snow line's perturbation: fBm with H 0.5, lacunarity 2 and SNOW_OCTAVES octaves, a fixed
 * plan made once (pthread_once: the tables are shared by every renderer and thread).
 * snow_fbm_bound is a strict upper bound on |snow fBm|: every noise value lies in (-1, 1)
 * (noise.h), so |sum| < sum of the weights; 1e-9 relative covers the rounding of the sum. */
static tf_octaves snow_plan;
static double snow_fbm_bound;
static pthread_once_t snow_plan_once = PTHREAD_ONCE_INIT;

static void make_snow_plan(void)
{
    tf_octaves_plan(&snow_plan, 0.5, 2.0, SNOW_OCTAVES);
    double sum = 0;
    for (int i = 0; i < snow_plan.count; i++)
        sum += fabs(snow_plan.amp[i]);
    snow_fbm_bound = sum * (1.0 + 1e-9);
}

/* Exactly tf_fbm2(nz, x, y, 0.5, 2.0, SNOW_OCTAVES), without re-planning per call. */
static double snow_fbm(const tf_noise *nz, double x, double y)
{
    tf_noise_axis axes[TF_MAX_OCTAVES + 1];
    pthread_once(&snow_plan_once, make_snow_plan);
    tf_octave_axes(&snow_plan, y, axes);
    return tf_fbm2_axes(nz, &snow_plan, x, axes);
}

/* ---------------------------------------------------------------- sky and mist */

tf_vec3 tf_sky_color(const tf_shader *sh, tf_vec3 dir)
{
    const tf_scene *s = sh->scene;
    double up = dir.z > 0 ? dir.z : 0;
    double w = 1.0 - (1.0 - up) * (1.0 - up) * (1.0 - up);
    tf_vec3 c = v3_lerp(s->sky.horizon, s->sky.zenith, w);
    double cg = v3_dot(dir, sh->sun_dir);
    if (cg > 0) {
        double c2 = cg * cg, c4 = c2 * c2, c8 = c4 * c4, c16 = c8 * c8, c32 = c16 * c16;
        double c64 = c32 * c32, c256 = c64 * c64 * c64 * c64;
        double glow = 0.03 * c8 + 0.08 * c64 + 0.25 * c256;
        c = v3_add(c, v3_scale(sh->sun_light, glow));
    }
    return c;
}

double tf_mist_depth_exp(double density, double k, double z1, double z2, double len)
{
    if (k == 0)
        return density * len;
    double x = k * fabs(z2 - z1);
    double mean_density;
    if (x < 1e-5) /* (nearly) level: density at the mean altitude, eq. 4.1.7 */
        mean_density = exp(-k * 0.5 * (z1 + z2));
    else /* eq. 4.1.5 normalised by the span, factored from the lower (densest) end */
        mean_density = exp(-k * fmin(z1, z2)) * (-expm1(-x) / x);
    return density * len * mean_density;
}

/* Optical depth from origin along unit dir over len (INFINITY: to the sky). */
static double mist_depth(const tf_shader *sh, tf_vec3 origin, tf_vec3 dir, double len)
{
    const tf_scene *s = sh->scene;
    if (s->mist.homogeneous || sh->mist_k == 0)
        return isinf(len) ? INFINITY : s->mist.density * len;
    if (!isinf(len))
        return tf_mist_depth_exp(s->mist.density, sh->mist_k, origin.z, origin.z + dir.z * len,
                                 len);
    /* to infinity: converges only while climbing, integral = density e^{-k z1} / (k dz) */
    if (dir.z <= 1e-12)
        return INFINITY;
    return s->mist.density * exp(-sh->mist_k * origin.z) / (sh->mist_k * dir.z);
}

static double transparency(double tau, double extinction)
{
    if (extinction <= 0)
        return 1.0;
    return exp(-tau * extinction); /* tau = INFINITY gives 0 */
}

tf_vec3 tf_mist_apply(const tf_shader *sh, tf_vec3 c, tf_vec3 origin, tf_vec3 dir, double len)
{
    const tf_scene *s = sh->scene;
    if (!s->mist.enabled || s->mist.density <= 0)
        return c;
    double tau = mist_depth(sh, origin, dir, len);
    double sr = transparency(tau, s->mist.extinction.x);
    double sg = transparency(tau, s->mist.extinction.y);
    double sb = transparency(tau, s->mist.extinction.z);
    return v3(sr * c.x + (1 - sr) * s->mist.color.x, sg * c.y + (1 - sg) * s->mist.color.y,
              sb * c.z + (1 - sb) * s->mist.color.z);
}

/* ---------------------------------------------------------------- surfaces */

/* 1 if the sun is visible from p (surface with geometric normal ng). */
static int sunlit(const tf_shader *sh, tf_vec3 p, tf_vec3 ng, uint64_t *shadow_rays)
{
    if (v3_dot(ng, sh->sun_dir) <= 0 || sh->sun_dir.z <= -1.0)
        return 0;
    tf_vec3 start = v3_add(p, v3_scale(ng, sh->shadow_lift));
    (*shadow_rays)++;
    return !tf_occluded(sh->hf, start, sh->sun_dir, 0.0, FAR_AWAY);
}

/* Can the snow line's fBm perturbation change the snow weight at altitude z?  The weight is
 * smoothstep(line - band, line + band, z) with line = snow_line + jitter * fBm, |fBm| <
 * snow_fbm_bound; below the lowest possible line - band it is exactly 0, above the highest
 * line + band exactly 1 (smoothstep clamps), whatever the fBm value.  The bounds are widened by
 * a relative 1e-9 so rounding in line +- band cannot cross them.  Skipping the fBm there gives
 * the same bits and saves most snow noise on scenes whose terrain is mostly far from the line. */
static int snow_line_matters(const tf_shader *sh, double z)
{
    const tf_scene *s = sh->scene;
    pthread_once(&snow_plan_once, make_snow_plan);
    double reach = s->materials.snow_jitter * snow_fbm_bound + sh->band;
    double lo = s->materials.snow_line - reach, hi = s->materials.snow_line + reach;
    double slack = 1e-9 * (fabs(lo) + fabs(hi) + reach);
    return z >= lo - slack && z <= hi + slack;
}

/* Albedo by altitude and slope at p with smooth normal n; variation in [-1, 1] perturbs it. */
static tf_vec3 terrain_albedo(const tf_shader *sh, tf_vec3 p, tf_vec3 n, double variation)
{
    const tf_scene *s = sh->scene;
    double slope = acos(n.z > 1 ? 1 : n.z) / DEG2RAD;
    double rock_deg = s->materials.rock_slope_deg;
    double band = sh->band;

    double w_veg = smoothstep(s->materials.tree_line + band, s->materials.tree_line - band, p.z);
    double w_sand = smoothstep(s->materials.sea_level + 0.8 * band,
                               s->materials.sea_level + 0.2 * band, p.z);
    double w_rock = smoothstep(rock_deg - ROCK_BLEND_DEG, rock_deg + ROCK_BLEND_DEG, slope);
    double snow_line = s->materials.snow_line;
    if (s->materials.snow_jitter > 0 && snow_line_matters(sh, p.z))
        snow_line += s->materials.snow_jitter *
                     snow_fbm(&sh->noise, p.x / (sh->hf->extent / 12.0) + 37.5,
                              p.y / (sh->hf->extent / 12.0) - 11.25);
    double w_snow = smoothstep(snow_line - band, snow_line + band, p.z) *
                    (1.0 - smoothstep(rock_deg, rock_deg + SNOW_SLIDE_DEG, slope));

    tf_vec3 c = v3_lerp(ALBEDO_ALPINE, ALBEDO_VEGETATION, w_veg);
    c = v3_lerp(c, ALBEDO_SAND, w_sand);
    c = v3_lerp(c, ALBEDO_ROCK, w_rock);
    c = v3_scale(c, 1.0 + COLOUR_VARIATION * variation);
    return v3_lerp(c, ALBEDO_SNOW, w_snow);
}

tf_vec3 tf_shade_terrain(const tf_shader *sh, const tf_hit *hit, uint64_t *shadow_rays)
{
    tf_vec3 n = smooth_normal(sh->hf, hit->ci, hit->cj, hit->p);
    tf_vec3 nb = n;
    double variation = 0;
    double octaves = visible_octaves(sh, sh->bump_scale, hit->t, BUMP_OCTAVES);
    if (sh->textured && sh->scene->materials.bump > 0 && octaves > 0) {
        double gx, gy;
        variation = fbm_with_gradient(&sh->noise, hit->p.x, hit->p.y, sh->bump_scale, BUMP_H,
                                      octaves, 0.0, &gx, &gy);
        double amp = sh->scene->materials.bump;
        nb = v3_norm(v3_add(n, v3(-amp * gx, -amp * gy, 0.0)));
        if (nb.z < 0.05) /* never tip a bumped normal over the horizon */
            nb = n;
    }
    tf_vec3 albedo = terrain_albedo(sh, hit->p, n, variation);
    double cos_sun = v3_dot(nb, sh->sun_dir);
    tf_vec3 light = v3_scale(sh->sky_light, 0.5 + 0.5 * nb.z);
    if (cos_sun > 0 && sunlit(sh, hit->p, hit->n, shadow_rays))
        light = v3_add(light, v3_scale(sh->sun_light, cos_sun));
    return v3_mul(albedo, light);
}

tf_vec3 tf_shade_water(const tf_shader *sh, tf_vec3 p, tf_vec3 dir, double dist,
                       uint64_t *shadow_rays)
{
    tf_vec3 n = v3(0, 0, 1);
    double octaves = visible_octaves(sh, sh->ripple_scale, dist, RIPPLE_OCTAVES);
    if (sh->textured && sh->scene->materials.bump > 0 && octaves > 0) {
        double gx, gy;
        fbm_with_gradient(&sh->noise, p.x, p.y, sh->ripple_scale, 0.5, octaves, 71.0, &gx, &gy);
        n = v3_norm(v3(-RIPPLE_STRENGTH * gx, -RIPPLE_STRENGTH * gy, 1.0));
    }
    double cos_i = -v3_dot(dir, n);
    if (cos_i < 1e-3)
        cos_i = 1e-3;
    tf_vec3 refl = v3_add(dir, v3_scale(n, 2.0 * cos_i));
    if (refl.z < 0) /* a ripple facing away: keep the reflection above the water */
        refl.z = -refl.z;
    double m = 1.0 - cos_i, m2 = m * m;
    double fresnel = FRESNEL_R0 + (1.0 - FRESNEL_R0) * m2 * m2 * m;
    tf_vec3 light = sh->sky_light;
    if (sh->sun_dir.z > 0 && sunlit(sh, p, v3(0, 0, 1), shadow_rays))
        light = v3_add(light, v3_scale(sh->sun_light, sh->sun_dir.z));
    tf_vec3 body = v3_mul(WATER_BODY, light);
    return v3_lerp(body, tf_sky_color(sh, v3_norm(refl)), fresnel);
}

/* ---------------------------------------------------------------- the ray */

void tf_shade_ray(const tf_shader *sh, tf_vec3 origin, tf_vec3 dir, tf_sample *out,
                  uint64_t *shadow_rays)
{
    double sea = sh->scene->materials.sea_level;
    double t_water = FAR_AWAY;
    if (dir.z < 0 && origin.z > sea)
        t_water = (sea - origin.z) / dir.z;

    tf_hit hit;
    tf_vec3 c;
    double dist;
    if (tf_trace(sh->hf, origin, dir, 0.0, t_water, &hit)) {
        dist = hit.t;
        c = tf_shade_terrain(sh, &hit, shadow_rays);
    } else if (t_water < FAR_AWAY) {
        dist = t_water;
        c = tf_shade_water(sh, v3_add(origin, v3_scale(dir, t_water)), dir, t_water, shadow_rays);
    } else {
        c = tf_mist_apply(sh, tf_sky_color(sh, dir), origin, dir, INFINITY);
        *out = (tf_sample){(float)c.x, (float)c.y, (float)c.z, 0.0f, TF_SKY_DIST};
        return;
    }
    c = tf_mist_apply(sh, c, origin, dir, dist);
    *out = (tf_sample){(float)c.x, (float)c.y, (float)c.z, 1.0f, (float)dist};
}
