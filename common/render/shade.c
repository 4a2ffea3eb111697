/* shade.c: materials, lighting, water, sky and mist; see shade.h for the model.
 *
 * Colours are linear RGB in double precision; only the final sample is rounded to float.
 * Constants below set the default look (greens, greys, white snow, blue water); the scene
 * chooses lines, slopes, sun, sky and mist. */
#include "render/shade.h"
#include "render/sun_strips.h"
#include "render/trace_procedural.h"

#include <assert.h>
#include <math.h>
#include <pthread.h>
#include <stddef.h>
#include <string.h>

/* The inline kernels tf_fbm2 is made of (noise_impl.h calls itself private to noise.c and
 * fractal.c): shading reuses an octave plan and lattice lookups across its three bump sums
 * and must give exactly tf_fbm2's bits, which only the same kernels guarantee. */
#include "terrain/noise_impl.h"

/* The formulas of a sample's shading (materials, water surface, sky, mist, normals from
 * heights), shared with the OpenCL kernels; the constants are render/constants.h's.  What is
 * left here is the C schedule around them: the texture octave loops with their lattice
 * lookups, the height-field reads and the shadow rays. */
#include "render/sample_math.h"

tf_vec3 tf_sun_direction(const tf_scene *s)
{
    double az = s->sun.azimuth_deg * TF_DEG2RAD, el = s->sun.elevation_deg * TF_DEG2RAD;
    return v3(sin(az) * cos(el), cos(az) * cos(el), sin(el));
}

/* ---- the slope's blends
 *
 * tf_terrain_albedo reads a hit's slope (tf_slope_deg: an acos) only through two clamped
 * smoothsteps, rock over rock_slope -+ TF_ROCK_BLEND_DEG and the snow's slide over rock_slope ..
 * rock_slope + TF_SNOW_SLIDE_DEG (snow_line_at too, through the latter).  A slope at or below
 * gentle = rock_slope - TF_ROCK_BLEND_DEG gives both their lower ends exactly (no rock, all
 * the snow), one at or above steep = rock_slope + TF_SNOW_SLIDE_DEG (past the rock's blend too)
 * both upper ends; those two values are the smoothsteps' own edges, computed by the same
 * expressions.  So where a normal's z proves its slope beyond one of them, that edge stands in
 * for the acos, and the albedo has the same bits: nz >= cos(gentle) + 1e-9 puts acos(nz) at
 * least 1e-9 below gentle (|acos'| >= 1), orders above the roundings of cos, acos and the
 * degrees (~1e-16); likewise nz <= cos(steep) - 1e-9.  On default.scene two hits in three
 * skip the acos. */
static double slope_gentle(const tf_scene *s)
{
    return s->materials.rock_slope_deg - TF_ROCK_BLEND_DEG;
}

static double slope_steep(const tf_scene *s)
{
    return s->materials.rock_slope_deg + TF_SNOW_SLIDE_DEG;
}

static void blend_normals(tf_shader *sh)
{
    /* (floating constants: not an integer constant expression for _Static_assert) */
    assert(TF_SNOW_SLIDE_DEG >= TF_ROCK_BLEND_DEG && TF_ROCK_BLEND_DEG > 0 &&
           "the steep edge lies past the rock's blend, the gentle one before the snow's");
    const double gentle = slope_gentle(sh->scene), steep = slope_steep(sh->scene);
    sh->nz_gentle = gentle > 0 && gentle < 90 ? cos(gentle * TF_DEG2RAD) + 1e-9 : INFINITY;
    sh->nz_steep = steep > 0 && steep < 180 ? cos(steep * TF_DEG2RAD) - 1e-9 : -INFINITY;
}

/* The slope tf_terrain_albedo is given for a normal's z: tf_slope_deg's, or a blend's edge
 * that gives the same albedo (above). */
static double material_slope(const tf_shader *sh, double nz)
{
    if (nz >= sh->nz_gentle)
        return slope_gentle(sh->scene);
    if (nz <= sh->nz_steep)
        return slope_steep(sh->scene);
    return tf_slope_deg(nz);
}

void tf_shader_init(tf_shader *sh, const tf_scene *s, const tf_heightfield *hf)
{
    *sh = (tf_shader){0};
    sh->scene = s;
    sh->hf = hf;
    sh->textured = s->materials.bump > 0 || s->materials.snow_jitter > 0;
    sh->smooth = s->terrain.smooth;
    if (sh->textured)
        tf_noise_init(&sh->noise, s->terrain.seed ^ 0x7465787475726573ULL); /* "textures" */
    sh->sun_dir = tf_sun_direction(s);
    tf_ray_dir_init(&sh->sun_ray, hf, sh->sun_dir);
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
        sh->pixel_angle = s->camera.fov_deg * TF_DEG2RAD / columns;
    else
        sh->pixel_angle = 2.0 * tan(0.5 * s->camera.fov_deg * TF_DEG2RAD) / columns;
    if (hf->proc)
        sh->view = tf_proc_view_of(hf->proc, s->camera.position, sh->pixel_angle);
    blend_normals(sh);
    if (hf->flow) {
        double sum = 0;
        for (size_t i = 0; i < (size_t)hf->n * (size_t)hf->n; i++)
            sum += hf->flow[i];
        sh->flow_ref = 8.0 * sum / ((double)hf->n * (double)hf->n) + 1e-12;
    }
}

/* ---------------------------------------------------------------- erosion's maps */

/* A map (n x n over the terrain, like the heights) at world (x, y), bilinear. */
static double map_at(const tf_heightfield *hf, const float *map, double x, double y)
{
    double u = fmin(fmax(x / hf->cell, 0.0), hf->n - 1.0);
    double v = fmin(fmax(y / hf->cell, 0.0), hf->n - 1.0);
    int i = (int)u < hf->n - 1 ? (int)u : hf->n - 2, j = (int)v < hf->n - 1 ? (int)v : hf->n - 2;
    double fu = u - i, fv = v - j;
    const float *r0 = map + (size_t)j * (size_t)hf->n + (size_t)i, *r1 = r0 + hf->n;
    return (1 - fv) * ((1 - fu) * r0[0] + fu * r0[1]) + fv * ((1 - fu) * r1[0] + fu * r1[1]);
}

/* What erosion left at p: silt covers the ground with a pale wash, and beds where water runs
 * or stands are darker (wet), fading with the flow through them. */
static tf_vec3 erosion_tint(const tf_shader *sh, tf_vec3 p, tf_vec3 albedo)
{
    const tf_heightfield *hf = sh->hf;
    const tf_vec3 silt_colour = {TF_ALBEDO_SILT};
    double silt = map_at(hf, hf->silt, p.x, p.y), water = map_at(hf, hf->water, p.x, p.y);
    double flow = map_at(hf, hf->flow, p.x, p.y);
    double cover = tf_smoothstep(0.0, TF_SILT_COVER_M, silt);
    double wet = fmax(tf_smoothstep(0.0, 1.0, flow / sh->flow_ref),
                      tf_smoothstep(0.0, 0.2, water));
    tf_vec3 c = v3_lerp(albedo, silt_colour, cover);
    return v3_scale(c, 1.0 - TF_WET_DARKEN * wet);
}

/* ---------------------------------------------------------------- the terrain, either kind */

static int trace_terrain(const tf_shader *sh, tf_vec3 o, tf_vec3 d, double tmax, tf_hit *hit)
{
    if (sh->hf->proc)
        return tf_proc_trace(sh->hf->proc, &sh->view, o, d, 0.0, tmax, hit);
    return tf_trace(sh->hf, o, d, 0.0, tmax, hit);
}

int tf_shadow_strips(const tf_shader *sh, tf_vec3 o, double *tmax)
{
    double t;
    const int said = tf_sun_strips_shadow(sh->sun_strips, o, &t);
    *tmax = said == TF_SUN_CLEAR_AFTER ? t : TF_FAR_AWAY;
    return said == TF_SUN_UNDER;
}

/* Whether the shadow ray from o toward the sun meets the terrain. */
static int terrain_occludes(const tf_shader *sh, tf_vec3 o)
{
    if (sh->hf->proc)
        return tf_proc_occluded(sh->hf->proc, &sh->view, o, sh->sun_dir, 0.0, TF_FAR_AWAY);
    double tmax;
    return tf_shadow_strips(sh, o, &tmax) || tf_occluded(sh->hf, o, sh->sun_dir, 0.0, tmax);
}

/* Shadow rays start this far along the normal from a terrain hit. */
static double shadow_lift_at(const tf_shader *sh, tf_vec3 p)
{
    return sh->hf->proc ? tf_proc_shadow_lift(sh->hf->proc, &sh->view, p) : sh->shadow_lift;
}

/* How many octaves of a texture of first wavelength `scale` a pixel shows at distance dist
 * (tf_visible_octaves, sample_math.h); 0: the texture is invisible there. */
static double visible_octaves(const tf_shader *sh, double scale, double dist, double max_octaves)
{
    return tf_visible_octaves(sh->pixel_angle, scale, dist, max_octaves);
}

/* ---------------------------------------------------------------- surface normals */

static double height_sample(const tf_heightfield *hf, int i, int j)
{
    i = i < 0 ? 0 : i >= hf->n ? hf->n - 1 : i;
    j = j < 0 ? 0 : j >= hf->n ? hf->n - 1 : j;
    return hf->h[(size_t)j * (size_t)hf->n + (size_t)i];
}

/* Vertex normal by central differences (one-sided at the edges, through the clamping).  An
 * interior vertex, nearly every one, reads its four neighbours straight: the same heights and
 * spans (2 cells: the differences of indices are exact) as through the clamping. */
static tf_vec3 vertex_normal(const tf_heightfield *hf, int i, int j)
{
    if ((unsigned)(i - 1) < (unsigned)(hf->n - 2) && (unsigned)(j - 1) < (unsigned)(hf->n - 2)) {
        const ptrdiff_t n = hf->n; /* signed: h[-n] is the row below, not a wrap-around */
        const float *h = hf->h + (ptrdiff_t)j * n + i;
        const double span = 2.0 * hf->cell;
        return tf_vertex_normal_of(h[-1], h[1], h[-n], h[n], span, span);
    }
    double span_x = (double)((i + 1 < hf->n ? i + 1 : i) - (i > 0 ? i - 1 : i)) * hf->cell;
    double span_y = (double)((j + 1 < hf->n ? j + 1 : j) - (j > 0 ? j - 1 : j)) * hf->cell;
    return tf_vertex_normal_of(height_sample(hf, i - 1, j), height_sample(hf, i + 1, j),
                               height_sample(hf, i, j - 1), height_sample(hf, i, j + 1), span_x,
                               span_y);
}

/* The triangle hit in cell (ci, cj) at p: its corner (ci, cj), its side vertex (si, sj) and
 * their normals, p's fractions of the cell.  The cell's diagonal runs from (ci, cj) to
 * (ci+1, cj+1) (heightfield.h), so fx >= fy is the lower-right triangle, whose side vertex is
 * (ci+1, cj); the upper-left one's is (ci, cj+1). */
typedef struct hit_triangle {
    int ci, cj, si, sj;
    tf_vec3 n00, nside, n11;
    double fx, fy;
} hit_triangle;

static void hit_triangle_at(const tf_heightfield *hf, int ci, int cj, tf_vec3 p, hit_triangle *t)
{
    ci = ci < 0 ? 0 : ci >= hf->cells ? hf->cells - 1 : ci;
    cj = cj < 0 ? 0 : cj >= hf->cells ? hf->cells - 1 : cj;
    double fx = p.x / hf->cell - ci, fy = p.y / hf->cell - cj;
    t->fx = tf_clamp01(fx);
    t->fy = tf_clamp01(fy);
    t->ci = ci;
    t->cj = cj;
    t->si = t->fx >= t->fy ? ci + 1 : ci;
    t->sj = t->fx >= t->fy ? cj : cj + 1;
    t->n00 = vertex_normal(hf, ci, cj);
    t->n11 = vertex_normal(hf, ci + 1, cj + 1);
    t->nside = vertex_normal(hf, t->si, t->sj);
}

/* Normal interpolated across the hit triangle with barycentric weights. */
static tf_vec3 smooth_normal(const hit_triangle *t)
{
    return tf_smooth_normal_blend(t->n00, t->nside, t->n11, t->fx, t->fy);
}

/* Sample (i, j) in the world (heightfield.h). */
static tf_vec3 vertex_at(const tf_heightfield *hf, int i, int j)
{
    return v3((double)i * hf->cell, (double)j * hf->cell, height_sample(hf, i, j));
}

/* p lifted onto the smooth surface of its triangle (tf_smooth_shadow_origin, sample_math.h). */
static tf_vec3 smooth_shadow_origin(const tf_heightfield *hf, const hit_triangle *t, tf_vec3 p)
{
    tf_vec3 v00 = vertex_at(hf, t->ci, t->cj), v11 = vertex_at(hf, t->ci + 1, t->cj + 1);
    return tf_smooth_shadow_origin(p, v00, t->n00, vertex_at(hf, t->si, t->sj), t->nside, v11,
                                   t->n11, t->fx, t->fy);
}

/* ---- octave plans without pow() per call
 *
 * tf_octaves_plan(H, lacunarity 2, octaves) gives amp[i] = pow(2^i, -H) (2^i is exact) for
 * i < count, then scales amp[whole] by the fractional remainder: every plan of a given H is a
 * prefix of the 32-octave plan with at most its last weight scaled.  The texture H values
 * (TF_BUMP_H, TF_HALF_H) get their full plan once; texture_plan cuts the prefix.  Made once
 * per process (pthread_once) and checked there against tf_octaves_plan itself on sample octave
 * counts; if noise_impl.h ever plans differently, texture_plan just calls tf_octaves_plan. */
static tf_octaves full_plan_bump, full_plan_half;
static int prefix_plans_exact;
static pthread_once_t full_plans_once = PTHREAD_ONCE_INIT;

static void prefix_plan(tf_octaves *o, const tf_octaves *full, double octaves)
{
    int whole;
    double remainder;
    o->lacunarity = full->lacunarity;
    o->count = tf_octaves_split(octaves, &whole, &remainder);
    memcpy(o->amp, full->amp, (size_t)o->count * sizeof o->amp[0]); /* the rest is never read */
    if (remainder > 0.0)
        o->amp[whole] *= remainder;
}

/* The snow line and the ripples share the H = 0.5 plan. */
#define TF_HALF_H TF_SNOW_H

static void make_full_plans(void)
{
    static const double samples[] = {0.0, 0.4, 1.0, 1.3, 2.0, 2.71, 3.5, 4.0, 5.9, 40.0};
    tf_octaves_plan(&full_plan_bump, TF_BUMP_H, 2.0, TF_MAX_OCTAVES);
    tf_octaves_plan(&full_plan_half, TF_HALF_H, 2.0, TF_MAX_OCTAVES);
    int exact = 1;
    for (size_t i = 0; i < sizeof samples / sizeof samples[0]; i++) {
        for (int which = 0; which < 2; which++) {
            tf_octaves fast, slow;
            const tf_octaves *full = which ? &full_plan_half : &full_plan_bump;
            prefix_plan(&fast, full, samples[i]);
            tf_octaves_plan(&slow, which ? TF_HALF_H : TF_BUMP_H, 2.0, samples[i]);
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
    if (prefix_plans_exact && H == TF_BUMP_H)
        prefix_plan(o, &full_plan_bump, octaves);
    else if (prefix_plans_exact && H == TF_HALF_H)
        prefix_plan(o, &full_plan_half, octaves);
    else
        tf_octaves_plan(o, H, 2.0, octaves);
}

/* fBm value and gradient at (x, y) / scale: tf_fbm2_gradient(nz, q, H, 2.0, octaves) at
 * q = (x / scale + salt, y / scale - salt), bit for bit (the same inline code, noise_impl.h),
 * with the octave plan from texture_plan.  The gradient is exact and per unit of q, so per
 * world unit it is scaled by 1/scale.  `salt` shifts the domain so different textures are
 * uncorrelated. */
static double fbm_with_gradient(const tf_noise *nz, double x, double y, double scale, double H,
                                double octaves, double salt, double *gx, double *gy)
{
    double qx = x / scale + salt, qy = y / scale - salt;
    tf_octaves plan;
    tf_noise_axis axes[TF_MAX_OCTAVES + 1];
    texture_plan(&plan, H, octaves);
    tf_octave_axes(&plan, qy, axes);
    return tf_fbm2_gradient_axes(nz, &plan, qx, axes, gx, gy);
}

/* The snow line's perturbation: fBm with H 0.5, lacunarity 2 and TF_SNOW_OCTAVES octaves, a fixed
 * plan made once (pthread_once: the tables are shared by every renderer and thread).
 * snow_rest_bound[k] is a strict upper bound on |octaves k.. of the snow fBm|: every noise value
 * lies in (-1, 1) (noise.h), so that sum is below the sum of their weights; 1e-9 relative covers
 * the rounding of the sum.  snow_rest_bound[0] bounds the whole fBm
 * (tf_shade_snow_fbm_bound). */
static tf_octaves snow_plan;
static double snow_rest_bound[TF_MAX_OCTAVES + 1];
static pthread_once_t snow_plan_once = PTHREAD_ONCE_INIT;

static void make_snow_plan(void)
{
    tf_octaves_plan(&snow_plan, TF_SNOW_H, 2.0, TF_SNOW_OCTAVES);
    double sum = 0;
    for (int k = snow_plan.count - 1; k >= 0; k--) {
        sum += fabs(snow_plan.amp[k]);
        snow_rest_bound[k] = sum * (1.0 + 1e-9);
    }
}

void tf_shade_octave_weights(double H, double *amp, int n)
{
    tf_octaves plan;
    texture_plan(&plan, H, TF_MAX_OCTAVES);
    memcpy(amp, plan.amp, (size_t)n * sizeof amp[0]);
}

double tf_shade_snow_fbm_bound(void)
{
    pthread_once(&snow_plan_once, make_snow_plan);
    return snow_rest_bound[0];
}

void tf_shade_snow_rest_bounds(double *bound, int n)
{
    pthread_once(&snow_plan_once, make_snow_plan);
    for (int k = 0; k < n; k++)
        bound[k] = k < snow_plan.count ? snow_rest_bound[k] : 0.0;
}

/* ---------------------------------------------------------------- sky and mist */

tf_vec3 tf_sky_color(const tf_shader *sh, tf_vec3 dir)
{
    const tf_scene *s = sh->scene;
    return tf_sky_radiance(s->sky.horizon, s->sky.zenith, sh->sun_dir, sh->sun_light, dir);
}

double tf_mist_depth_exp(double density, double k, double z1, double z2, double len)
{
    return tf_mist_depth_exp_of(density, k, z1, z2, len, 1);
}

tf_vec3 tf_mist_apply(const tf_shader *sh, tf_vec3 c, tf_vec3 origin, tf_vec3 dir, double len)
{
    const tf_scene *s = sh->scene;
    if (!s->mist.enabled || s->mist.density <= 0)
        return c;
    double tau = tf_mist_depth(s->mist.density, sh->mist_k, s->mist.homogeneous, origin.z, dir.z,
                               len);
    return tf_mist_blend(c, tau, s->mist.extinction, s->mist.color);
}

/* ---------------------------------------------------------------- surfaces */

/* The sun is visible from p on a surface of normal ng when the sun is in front of it and a
 * shadow ray from p lifted along ng reaches the sky.  sun_request: 1 if the sun is in front,
 * with the shadow ray's start in *start (the ray goes toward sh->sun_dir); 0 if not (dark,
 * no ray).  Shading is split at the shadow ray (tf_shade_begin / tf_shade_end) so that the
 * renderer can trace a row's shadow rays together (trace_packet.h). */
static int sun_request(const tf_shader *sh, tf_vec3 p, tf_vec3 ng, tf_vec3 *start)
{
    if (v3_dot(ng, sh->sun_dir) <= 0 || sh->sun_dir.z <= -1.0)
        return 0;
    *start = v3_add(p, v3_scale(ng, shadow_lift_at(sh, p)));
    return 1;
}

/* sun_request for a terrain hit with smooth normal n.  Flat (every scene before terrain
 * smooth): the sun must face the hit triangle itself, and the ray starts on it, lifted along
 * its normal -- so near the terminator each triangle is lit or dark on its own.  Smooth: the
 * sun must face n, and the ray starts on the smooth surface (tf_smooth_shadow_origin), lifted
 * along n. */
static int terrain_sun_request(const tf_shader *sh, const tf_hit *hit, const hit_triangle *t,
                               tf_vec3 n, tf_vec3 *start)
{
    if (!sh->smooth || sh->hf->proc) /* procedural: hit->n is n, the surface has no facets */
        return sun_request(sh, hit->p, hit->n, start);
    return sun_request(sh, smooth_shadow_origin(sh->hf, t, hit->p), n, start);
}

/* Whether a pending sample's shadow ray is occluded, traced now (the single-ray path); 0 when
 * it casts none. */
static int resolve_shadow(const tf_shader *sh, const tf_shade_pending *p, uint64_t *shadow_rays)
{
    if (!p->shadow)
        return 0;
    (*shadow_rays)++;
    return terrain_occludes(sh, p->start);
}

/* resolve_shadow on a grid terrain, helped by a neighbour's shadow record (trace.h). */
static int resolve_shadow_coherent(const tf_shader *sh, const tf_shade_pending *p,
                                   const tf_shadow_clear *near, tf_shadow_clear *mine,
                                   uint64_t *shadow_rays)
{
    if (!p->shadow)
        return 0;
    (*shadow_rays)++;
    double tmax;
    if (tf_shadow_strips(sh, p->start, &tmax)) { /* its point named if a neighbour asks */
        if (mine)
            *mine = tf_sun_strips_under_record(sh->sun_strips, p->start);
        return 1;
    }
    tf_shadow_clear named;
    near = tf_sun_strips_named(sh->sun_strips, near, &named);
    return tf_occluded_coherent(&sh->sun_ray, p->start, tmax, near, mine);
}

/* The snow line that tf_terrain_albedo is given at p (z = p.z) on a slope of `slope` degrees:
 * the scene's line moved by snow_jitter times the snow fBm, tf_fbm2(nz, u, v, TF_SNOW_H, 2.0,
 * TF_SNOW_OCTAVES) at the point's snow coordinates -- or any line that gives the same albedo.
 *
 * The albedo depends on the line only through w_snow = smoothstep(line - band, line + band, z)
 * times the slope's weight (sample_math.h), and
 *   S1. where the slope's weight is exactly 0 (snow slid off a steep slope), w_snow is 0 for
 *       every line: the line is left as it is;
 *   S2. where z lies below line - band or above line + band for every line the octaves still to
 *       come can give, smoothstep clamps to exactly 0 or 1 (rounding is monotone) for each of
 *       them: after octave k the sum so far moves the line by jitter * P, and the octaves from
 *       k on by less than jitter * snow_rest_bound[k] (tf_snow_line_matters' test, with its
 *       slack).  The line with the sum so far is one of those lines, so it gives the albedo.
 * Only 6% of default.scene's hits near the snow line need all five octaves; 65% need none (S1).
 * The sum is tf_fbm2_axes' own, term by term, so a line that needs every octave has its bits. */
static double snow_line_at(const tf_shader *sh, tf_vec3 p, double slope)
{
    const tf_scene *s = sh->scene;
    const double line = s->materials.snow_line, jitter = s->materials.snow_jitter;
    if (!(jitter > 0) || tf_snow_slope_weight(s->materials.rock_slope_deg, slope) == 0.0)
        return line;
    pthread_once(&snow_plan_once, make_snow_plan);
    double x = tf_snow_u(p.x, sh->hf->extent), y = tf_snow_v(p.y, sh->hf->extent), sum = 0.0;
    for (int k = 0; k < snow_plan.count; k++) {
        if (!tf_snow_line_matters(line + jitter * sum, jitter, snow_rest_bound[k], sh->band, p.z))
            break;
        tf_noise_axis axis = tf_noise_axis_of(y); /* tf_octave_axes' y halves, one at a time */
        sum += snow_plan.amp[k] * tf_noise2_axis(&sh->noise, x, &axis);
        x *= snow_plan.lacunarity;
        y *= snow_plan.lacunarity;
    }
    return line + jitter * sum;
}

tf_vec3 tf_shade_albedo(const tf_shader *sh, tf_vec3 p, tf_vec3 n, double variation)
{
    const tf_scene *s = sh->scene;
    double slope = material_slope(sh, n.z);
    return tf_terrain_albedo(s->materials.tree_line, s->materials.sea_level,
                             s->materials.rock_slope_deg, sh->band, p.z, slope,
                             snow_line_at(sh, p, slope), variation);
}

/* A terrain hit shaded up to its shadow ray: the albedo, the sky's light and the sun's
 * weight in *p (terrain_end adds the sun's light unless the ray is occluded). */
static void terrain_begin(const tf_shader *sh, const tf_hit *hit, tf_shade_pending *p)
{
    hit_triangle tri = {0};
    tf_vec3 n = hit->n; /* a procedural hit's normal is the surface's own gradient: smooth */
    if (!sh->hf->proc) {
        hit_triangle_at(sh->hf, hit->ci, hit->cj, hit->p, &tri);
        n = smooth_normal(&tri);
    }
    tf_vec3 nb = n;
    double variation = 0;
    double octaves = visible_octaves(sh, sh->bump_scale, hit->t, TF_BUMP_OCTAVES);
    if (sh->textured && sh->scene->materials.bump > 0 && octaves > 0) {
        double gx, gy;
        variation = fbm_with_gradient(&sh->noise, hit->p.x, hit->p.y, sh->bump_scale, TF_BUMP_H,
                                      octaves, 0.0, &gx, &gy);
        nb = tf_bump_normal(n, sh->scene->materials.bump, gx, gy);
    }
    tf_vec3 albedo = tf_shade_albedo(sh, hit->p, n, variation);
    if (sh->hf->silt)
        albedo = erosion_tint(sh, hit->p, albedo);
    p->surface = TF_SURFACE_TERRAIN;
    p->base = albedo;
    p->cos_sun = v3_dot(nb, sh->sun_dir);
    p->light = tf_sky_light_on(sh->sky_light, nb.z);
    p->shadow = p->cos_sun > 0 && terrain_sun_request(sh, hit, &tri, n, &p->start);
}

static tf_vec3 terrain_end(const tf_shader *sh, const tf_shade_pending *p, int occluded)
{
    tf_vec3 light = p->light;
    if (p->shadow && !occluded)
        light = v3_add(light, v3_scale(sh->sun_light, p->cos_sun));
    return v3_mul(p->base, light);
}

tf_vec3 tf_shade_terrain(const tf_shader *sh, const tf_hit *hit, uint64_t *shadow_rays)
{
    tf_shade_pending p = {0};
    terrain_begin(sh, hit, &p);
    return terrain_end(sh, &p, resolve_shadow(sh, &p, shadow_rays));
}

/* The water plane at p seen along dir from dist, up to its shadow ray. */
static void water_begin(const tf_shader *sh, tf_vec3 p, tf_vec3 dir, double dist,
                        tf_shade_pending *pd)
{
    tf_vec3 n = v3(0, 0, 1);
    double octaves = visible_octaves(sh, sh->ripple_scale, dist, TF_RIPPLE_OCTAVES);
    if (sh->textured && sh->scene->materials.bump > 0 && octaves > 0) {
        double gx, gy;
        fbm_with_gradient(&sh->noise, p.x, p.y, sh->ripple_scale, TF_RIPPLE_H, octaves,
                          TF_RIPPLE_SALT, &gx, &gy);
        n = tf_ripple_normal(gx, gy);
    }
    pd->surface = TF_SURFACE_WATER;
    pd->fresnel = tf_water_surface(dir, n, &pd->base); /* base: the reflected direction */
    pd->light = sh->sky_light;
    pd->cos_sun = sh->sun_dir.z;
    pd->shadow = sh->sun_dir.z > 0 && sun_request(sh, p, v3(0, 0, 1), &pd->start);
}

static tf_vec3 water_end(const tf_shader *sh, const tf_shade_pending *p, int occluded)
{
    tf_vec3 light = p->light;
    if (p->shadow && !occluded)
        light = v3_add(light, v3_scale(sh->sun_light, p->cos_sun));
    return tf_water_color(light, tf_sky_color(sh, v3_norm(p->base)), p->fresnel);
}

tf_vec3 tf_shade_water(const tf_shader *sh, tf_vec3 p, tf_vec3 dir, double dist,
                       uint64_t *shadow_rays)
{
    tf_shade_pending pd = {0};
    water_begin(sh, p, dir, dist, &pd);
    return water_end(sh, &pd, resolve_shadow(sh, &pd, shadow_rays));
}

/* ---------------------------------------------------------------- the ray */

double tf_shade_t_water(const tf_shader *sh, tf_vec3 origin, tf_vec3 dir)
{
    double sea = sh->scene->materials.sea_level;
    double t_water = TF_FAR_AWAY;
    if (dir.z < 0 && origin.z > sea)
        t_water = (sea - origin.z) / dir.z;
    return t_water;
}

void tf_shade_begin(const tf_shader *sh, tf_vec3 origin, tf_vec3 dir, double t_water,
                    const tf_hit *hit, tf_shade_pending *p)
{
    *p = (tf_shade_pending){0};
    if (hit) {
        p->dist = hit->t;
        terrain_begin(sh, hit, p);
    } else if (t_water < TF_FAR_AWAY) {
        p->dist = t_water;
        water_begin(sh, v3_add(origin, v3_scale(dir, t_water)), dir, t_water, p);
    } else {
        p->surface = TF_SURFACE_SKY;
    }
}

void tf_shade_end(const tf_shader *sh, tf_vec3 origin, tf_vec3 dir, const tf_shade_pending *p,
                  int occluded, tf_sample *out)
{
    tf_vec3 c;
    if (p->surface == TF_SURFACE_SKY) {
        c = tf_mist_apply(sh, tf_sky_color(sh, dir), origin, dir, INFINITY);
        *out = (tf_sample){(float)c.x, (float)c.y, (float)c.z, 0.0f, TF_SKY_DIST};
        return;
    }
    c = p->surface == TF_SURFACE_TERRAIN ? terrain_end(sh, p, occluded)
                                         : water_end(sh, p, occluded);
    c = tf_mist_apply(sh, c, origin, dir, p->dist);
    *out = (tf_sample){(float)c.x, (float)c.y, (float)c.z, 1.0f, (float)p->dist};
}

void tf_shade_ray_coherent_among(const tf_shader *sh, tf_vec3 origin, tf_vec3 dir,
                                 const tf_ray_clear *const *lowers, int n,
                                 const tf_shadow_clear *near, tf_sample_record *mine,
                                 tf_sample *out, uint64_t *shadow_rays)
{
    if (mine)
        mine->camera.s_free = 0, mine->shadow.t_under = 0;
    if (sh->hf->proc) {
        tf_shade_ray(sh, origin, dir, out, shadow_rays);
        return;
    }
    double t_water = tf_shade_t_water(sh, origin, dir);
    tf_hit hit;
    tf_shade_pending p;
    int found = tf_trace_coherent_among(sh->hf, origin, dir, t_water, lowers, n, &hit,
                                        mine ? &mine->camera : NULL);
    tf_shade_begin(sh, origin, dir, t_water, found ? &hit : NULL, &p);
    tf_shade_end(sh, origin, dir, &p,
                 resolve_shadow_coherent(sh, &p, near, mine ? &mine->shadow : NULL,
                                         shadow_rays),
                 out);
}

void tf_shade_ray_coherent(const tf_shader *sh, tf_vec3 origin, tf_vec3 dir,
                           const tf_sample_record *lower, tf_sample_record *mine, tf_sample *out,
                           uint64_t *shadow_rays)
{
    const tf_ray_clear *camera = lower ? &lower->camera : NULL;
    tf_shade_ray_coherent_among(sh, origin, dir, &camera, camera != NULL,
                                lower ? &lower->shadow : NULL, mine, out, shadow_rays);
}

void tf_shade_ray(const tf_shader *sh, tf_vec3 origin, tf_vec3 dir, tf_sample *out,
                  uint64_t *shadow_rays)
{
    double t_water = tf_shade_t_water(sh, origin, dir);
    tf_hit hit;
    tf_shade_pending p;
    int found = trace_terrain(sh, origin, dir, t_water, &hit);
    tf_shade_begin(sh, origin, dir, t_water, found ? &hit : NULL, &p);
    tf_shade_end(sh, origin, dir, &p, resolve_shadow(sh, &p, shadow_rays), out);
}
