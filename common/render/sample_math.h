/* sample_math.h: the per-sample math of the renderer, written once for the C backend and the
 * OpenCL kernels (common/portable.h says how one source is both): the camera ray through a
 * jittered lattice point, surface normals from height samples, materials, the water surface,
 * the sky and the mist.  camera.c, render.c and shade.c call these for one sample;
 * worker/kernels/packet_shade.cl and packet_render.cl call the very same functions on packets
 * of eight (worker/backend_opencl.c loads this file into the kernel build).
 *
 * What stays per target is what the two backends schedule differently: the grid walk
 * (trace.c / packet_trace.cl), the octave loops of the textures and their lattice lookups
 * (shade.c / packet_shade.cl), the shadow rays (cast at once in C; collected and walked as one
 * stream in OpenCL), and the pixel refinement (render.c / packet_render.cl).
 *
 * Every function takes its scene constants as plain doubles and tf_vec3s (the C callers read
 * them from tf_scene / tf_shader, the kernels from the parameter block P[]) and its per-sample
 * inputs as lanes.  shade.h and camera.h describe the model; each function here says which of
 * their functions it is part of. */
#ifndef TF_SAMPLE_MATH_H
#define TF_SAMPLE_MATH_H

#ifndef __OPENCL_VERSION__
#include "portable.h"
#include "render/camera.h"
#include "render/constants.h"
#include "terrain/noise_kernel.h"
#endif

/* ---------------------------------------------------------------- small helpers */

/* x clamped to [0, 1] (a NaN stays NaN). */
TF_SHARED tf_lane tf_clamp01(tf_lane x)
{
    return TF_SEL(TF_SEL(x, 1.0, x > 1.0), 0.0, x < 0.0);
}

TF_SHARED tf_lane tf_smoothstep(tf_lane e0, tf_lane e1, tf_lane x)
{
    tf_lane t = tf_clamp01((x - e0) / (e1 - e0));
    return t * t * (3.0 - 2.0 * t);
}

/* ---------------------------------------------------------------- the camera sample */

/* tf_camera_dir: unit direction of the primary ray through image point (x, y). */
TF_SHARED tf_lane3 tf_camera_ray(const tf_camera *cam, tf_lane x, tf_lane y)
{
    tf_lane u = x / (double)cam->width - 0.5;  /* -0.5 .. 0.5, left to right */
    tf_lane v = 0.5 - y / (double)cam->height; /* 0.5 .. -0.5, top to bottom */
    if (cam->kind == TF_CAMERA_PANORAMA) {
        tf_lane theta = u * cam->sweep;
        tf_lane3 horizontal = tf_l3_add(tf_l3_scale(TF_SPLAT3(cam->pano_forward), cos(theta)),
                                        tf_l3_scale(TF_SPLAT3(cam->pano_right), sin(theta)));
        tf_lane height = cam->v_centre + 2.0 * v * cam->v_half;
        return tf_l3_norm(tf_l3_add(horizontal, tf_l3_scale(TF_SPLAT3(cam->pano_up), height)));
    }
    tf_lane3 d = tf_l3_add(TF_SPLAT3(cam->forward),
                           tf_l3_scale(TF_SPLAT3(cam->right), 2.0 * u * cam->half_w));
    d = tf_l3_add(d, tf_l3_scale(TF_SPLAT3(cam->up), 2.0 * v * cam->half_h));
    return tf_l3_norm(d);
}

/* The image position of lattice point (X, Y) with N lattice steps per pixel
 * (render_internal.h): (X + jx) / N, (Y + jy) / N, the jitter from jitter_key and (X, Y) only.
 * N is a power of two, so the divisions are exact scalings. */
TF_SHARED void tf_lattice_position(tf_u64 jitter_key, double N, tf_lane_i64 X, tf_lane_i64 Y,
                                   tf_lane *x, tf_lane *y)
{
    tf_lane_u64 h = tf_hash64(jitter_key ^ TF_I64_AS_U64(X));
    h = tf_hash64(h ^ (TF_I64_AS_U64(Y) * TF_JITTER_Y_MUL));
    tf_lane jx = tf_hash_unit(h) - 0.5;
    tf_lane jy = tf_hash_unit(h ^ TF_JITTER_Y_SALT) - 0.5;
    *x = (TF_I64_TO_LANE(X) + jx) / N;
    *y = (TF_I64_TO_LANE(Y) + jy) / N;
}

/* tf_display_level: sqrt of the linear value, clamped to [0, 1]; never NaN.  sqrt is correctly
 * rounded in IEEE C and in OpenCL C, so both backends make the same subdivision decisions. */
TF_SHARED tf_lane tf_display_level_of(tf_lane v)
{
    return TF_SEL(0.0, TF_SEL(1.0, sqrt(v), v < 1.0), v > 0.0);
}

/* ---------------------------------------------------------------- a pixel's refinement
 *
 * render.c's render_pixel and packet_render.cl's pixel state machine run one pixel at a time
 * in both backends, so these take plain doubles and floats. */

/* The split threshold of a quad `size` lattice steps wide in a pixel of N steps: it grows 8x
 * per level (N/size cubed, exact in double): a quad's error weighs in the pixel by its share
 * of the area (4x per level) and its 5-sample estimate is already better than the corners'
 * (another 2x). */
TF_SHARED double tf_aa_split_threshold(double threshold, int N, int size)
{
    double ratio = (double)(N / size);
    return threshold * ratio * ratio * ratio;
}

/* A probed leaf's share of a channel: its area (size^2 lattice cells) times corners/8 +
 * centre/2 (the quincunx estimate). */
TF_SHARED double tf_aa_probed_leaf(int size, float c0, float c1, float c2, float c3, float centre)
{
    double w = 0.125 * (double)size * (double)size;
    return w * ((double)c0 + c1 + c2 + c3 + 4.0 * centre);
}

/* A flat (or smallest) leaf's share: its area times the mean of its corners. */
TF_SHARED double tf_aa_flat_leaf(int size, float c0, float c1, float c2, float c3)
{
    double w = 0.25 * (double)size * (double)size;
    return w * ((double)c0 + c1 + c2 + c3);
}

/* ---------------------------------------------------------------- surfaces */

/* How many octaves of a texture whose first octave has wavelength `scale` a pixel (of angle
 * pixel_angle) can show at distance dist: octave i is kept while it spans at least two pixel
 * footprints (Nyquist), the last fading in fractionally; 0: the texture is invisible. */
TF_SHARED tf_lane tf_visible_octaves(double pixel_angle, double scale, tf_lane dist,
                                     double max_octaves)
{
    tf_lane footprint = 2.0 * dist * pixel_angle;
    tf_mask resolved = footprint > 0.0;
    if (!TF_ANY(resolved))
        return TF_LANE(max_octaves);
    tf_lane octaves = log2(scale / footprint) + 1.0;
    octaves = TF_SEL(TF_SEL(octaves, max_octaves, octaves > max_octaves), 0.0, octaves < 0.0);
    return TF_SEL(max_octaves, octaves, resolved);
}

/* A vertex normal by central differences: the heights one step either side along x (hx0,
 * hx1) and y (hy0, hy1), the steps spanning span_x and span_y world units. */
TF_SHARED tf_lane3 tf_vertex_normal_of(tf_lane hx0, tf_lane hx1, tf_lane hy0, tf_lane hy1,
                                       tf_lane span_x, tf_lane span_y)
{
    tf_lane dzdx = (hx1 - hx0) / span_x;
    tf_lane dzdy = (hy1 - hy0) / span_y;
    return tf_l3_norm(tf_l3(-dzdx, -dzdy, TF_LANE(1.0)));
}

/* The normal interpolated across the hit triangle of a cell from its vertex normals n00, n11
 * and nside (n10 when fx >= fy, the lower-right triangle; else n01), at cell fractions fx, fy
 * (each clamped to [0, 1] by the caller). */
TF_SHARED tf_lane3 tf_smooth_normal_blend(tf_lane3 n00, tf_lane3 nside, tf_lane3 n11, tf_lane fx,
                                          tf_lane fy)
{
    tf_mask lower = fx >= fy;
    tf_lane big = TF_SEL(fy, fx, lower), small = TF_SEL(fx, fy, lower);
    tf_lane3 n = tf_l3_add(tf_l3_add(tf_l3_scale(n00, 1 - big), tf_l3_scale(nside, big - small)),
                           tf_l3_scale(n11, small));
    return tf_l3_norm(n);
}

/* ---- the shadow ray of smooth shading (terrain smooth = yes)
 *
 * Shaded with the interpolated normal, a point near the terminator may face the sun while its
 * flat triangle faces away; a shadow ray from the triangle then enters the triangle's own mesh
 * at once, and every such triangle is dark on its own: the mosaic of the "shadow terminator"
 * problem.  The ray starts instead on the smooth surface the vertex normals describe (Hanika,
 * "Hacking the shadow terminator", Ray Tracing Gems II, 2021): p is lifted onto the tangent
 * plane of each vertex of its triangle (only upwards: a point already above a vertex's plane,
 * as in a concave cell, stays), and the three lifts are blended with p's barycentric weights,
 * those of tf_smooth_normal_blend.  On a convex slope the triangles lie below that surface, so
 * a ray leaving it towards a sun above its tangent plane misses them; in a concave cell the
 * point stays on its triangle, where the curved surface does shade itself.  The lift is zero
 * at the vertices and, along an edge, depends on the edge's two vertices alone, so the start
 * is continuous from triangle to triangle and light ends on the smooth normal's terminator,
 * not on triangle edges.  It is a few hundredths of a cell on real terrain: no light leaks
 * under a ridge taller than that. */

/* How far p lies below the plane through v normal to unit n (0 on or above it). */
TF_SHARED tf_lane tf_depth_below_plane(tf_lane3 p, tf_lane3 v, tf_lane3 n)
{
    tf_lane d = tf_l3_dot(tf_l3(p.x - v.x, p.y - v.y, p.z - v.z), n);
    return TF_SEL(-d, 0.0, d >= 0.0);
}

/* p lifted onto the smooth surface: the hit triangle's vertices v00, vside, v11 with their
 * normals n00, nside, n11 and p's cell fractions fx, fy, as tf_smooth_normal_blend takes them. */
TF_SHARED tf_lane3 tf_smooth_shadow_origin(tf_lane3 p, tf_lane3 v00, tf_lane3 n00, tf_lane3 vside,
                                           tf_lane3 nside, tf_lane3 v11, tf_lane3 n11,
                                           tf_lane fx, tf_lane fy)
{
    tf_mask lower = fx >= fy;
    tf_lane big = TF_SEL(fy, fx, lower), small = TF_SEL(fx, fy, lower);
    tf_lane3 up = tf_l3_scale(n00, (1 - big) * tf_depth_below_plane(p, v00, n00));
    up = tf_l3_add(up, tf_l3_scale(nside, (big - small) * tf_depth_below_plane(p, vside, nside)));
    up = tf_l3_add(up, tf_l3_scale(n11, small * tf_depth_below_plane(p, v11, n11)));
    return tf_l3_add(p, up);
}

/* The bumped normal: n tilted by the bump texture's gradient (gx, gy) times amp -- but never
 * tipped over the horizon (then n itself). */
TF_SHARED tf_lane3 tf_bump_normal(tf_lane3 n, double amp, tf_lane gx, tf_lane gy)
{
    tf_lane3 nb = tf_l3_norm(tf_l3_add(n, tf_l3(-amp * gx, -amp * gy, TF_LANE(0.0))));
    return TF_SEL3(nb, n, nb.z < 0.05);
}

/* The water's normal from the ripple texture's gradient. */
TF_SHARED tf_lane3 tf_ripple_normal(tf_lane gx, tf_lane gy)
{
    return tf_l3_norm(tf_l3(-TF_RIPPLE_STRENGTH * gx, -TF_RIPPLE_STRENGTH * gy, TF_LANE(1.0)));
}

/* Slope of a surface with unit normal z component nz, in degrees. */
TF_SHARED tf_lane tf_slope_deg(tf_lane nz)
{
    return acos(TF_SEL(nz, 1.0, nz > 1.0)) / TF_DEG2RAD;
}

/* Can the snow line's fBm perturbation change the snow weight at altitude z?  The weight is
 * smoothstep(line - band, line + band, z) with line = snow_line + jitter * fBm and |fBm| <
 * fbm_bound; below the lowest possible line - band it is exactly 0, above the highest
 * line + band exactly 1 (smoothstep clamps), whatever the fBm value.  The bounds are widened
 * by a relative 1e-9 so rounding in line +- band cannot cross them.  Skipping the fBm there
 * gives the same bits and saves most snow noise on scenes whose terrain is mostly far from
 * the line.  snow_line may be a lane's own (the line moved by the octaves summed so far). */
TF_SHARED tf_mask tf_snow_line_matters(tf_lane snow_line, double jitter, double fbm_bound,
                                       double band, tf_lane z)
{
    double reach = jitter * fbm_bound + band;
    tf_lane lo = snow_line - reach, hi = snow_line + reach;
    tf_lane slack = 1e-9 * (fabs(lo) + fabs(hi) + reach);
    return (z >= lo - slack) & (z <= hi + slack);
}

/* The snow texture's noise-space coordinates of world (x, y) on a terrain `extent` wide. */
TF_SHARED tf_lane tf_snow_u(tf_lane x, double extent)
{
    return x / (extent / TF_SNOW_WAVELENGTHS) + TF_SNOW_SALT_X;
}

TF_SHARED tf_lane tf_snow_v(tf_lane y, double extent)
{
    return y / (extent / TF_SNOW_WAVELENGTHS) - TF_SNOW_SALT_Y;
}

/* How much snow a slope of `slope` degrees holds: all of it up to the rock slope, none from
 * TF_SNOW_SLIDE_DEG past it (exactly 0 there, which shade.c's snow_line_at relies on). */
TF_SHARED tf_lane tf_snow_slope_weight(double rock_deg, tf_lane slope)
{
    return 1.0 - tf_smoothstep(TF_LANE(rock_deg), TF_LANE(rock_deg + TF_SNOW_SLIDE_DEG), slope);
}

/* Albedo by altitude z and slope (degrees): vegetation below tree_line, alpine ground above,
 * sand just above sea_level, rock on slopes past rock_deg, snow above snow_line (already
 * perturbed by its texture) thinning out on steep slopes; variation in [-1, 1] perturbs all but
 * the snow.  band is the width of the transitions. */
TF_SHARED tf_lane3 tf_terrain_albedo(double tree_line, double sea_level, double rock_deg,
                                     double band, tf_lane z, tf_lane slope, tf_lane snow_line,
                                     tf_lane variation)
{
    const tf_vec3 vegetation = {TF_ALBEDO_VEGETATION}, alpine = {TF_ALBEDO_ALPINE};
    const tf_vec3 rock = {TF_ALBEDO_ROCK}, snow = {TF_ALBEDO_SNOW}, sand = {TF_ALBEDO_SAND};
    tf_lane w_veg = tf_smoothstep(TF_LANE(tree_line + band), TF_LANE(tree_line - band), z);
    tf_lane w_sand = tf_smoothstep(TF_LANE(sea_level + 0.8 * band),
                                   TF_LANE(sea_level + 0.2 * band), z);
    tf_lane w_rock = tf_smoothstep(TF_LANE(rock_deg - TF_ROCK_BLEND_DEG),
                                   TF_LANE(rock_deg + TF_ROCK_BLEND_DEG), slope);
    tf_lane w_snow = tf_smoothstep(snow_line - band, snow_line + band, z) *
                     tf_snow_slope_weight(rock_deg, slope);
    tf_lane3 c = tf_l3_lerp_ss(alpine, vegetation, w_veg);
    c = tf_l3_lerp_ps(c, sand, w_sand);
    c = tf_l3_lerp_ps(c, rock, w_rock);
    c = tf_l3_scale(c, 1.0 + TF_COLOUR_VARIATION * variation);
    return tf_l3_lerp_ps(c, snow, w_snow);
}

/* The sky light a surface with normal z component nz receives (sky_light: on a level one). */
TF_SHARED tf_lane3 tf_sky_light_on(tf_vec3 sky_light, tf_lane nz)
{
    return tf_l3_scale(TF_SPLAT3(sky_light), 0.5 + 0.5 * nz);
}

/* The water surface seen along unit dir with (rippled) normal n: *refl gets the reflected
 * direction (kept above the water), the result is Schlick's Fresnel weight. */
TF_SHARED tf_lane tf_water_surface(tf_lane3 dir, tf_lane3 n, tf_lane3 *refl)
{
    tf_lane cos_i = -tf_l3_dot(dir, n);
    cos_i = TF_SEL(cos_i, 1e-3, cos_i < 1e-3);
    tf_lane3 r = tf_l3_add(dir, tf_l3_scale(n, 2.0 * cos_i));
    r.z = TF_SEL(r.z, -r.z, r.z < 0.0); /* a ripple facing away */
    *refl = r;
    tf_lane m = 1.0 - cos_i, m2 = m * m;
    return TF_FRESNEL_R0 + (1.0 - TF_FRESNEL_R0) * m2 * m2 * m;
}

/* The water's colour: its lit body blended with the reflected sky by the Fresnel weight. */
TF_SHARED tf_lane3 tf_water_color(tf_lane3 light, tf_lane3 reflected_sky, tf_lane fresnel)
{
    const tf_vec3 water_body = {TF_WATER_BODY};
    tf_lane3 body = tf_l3_mul(TF_SPLAT3(water_body), light);
    return tf_l3_lerp(body, reflected_sky, fresnel);
}

/* ---------------------------------------------------------------- sky and mist */

/* tf_sky_color: zenith/horizon gradient plus a glow around the sun, in unit direction dir. */
TF_SHARED tf_lane3 tf_sky_radiance(tf_vec3 horizon, tf_vec3 zenith, tf_vec3 sun_dir,
                                   tf_vec3 sun_light, tf_lane3 dir)
{
    tf_lane up = TF_SEL(0.0, dir.z, dir.z > 0.0);
    tf_lane w = 1.0 - (1.0 - up) * (1.0 - up) * (1.0 - up);
    tf_lane3 c = tf_l3_lerp_ss(horizon, zenith, w);
    tf_lane cg = tf_l3_dot(dir, TF_SPLAT3(sun_dir));
    tf_mask glowing = cg > 0.0;
    if (TF_ANY(glowing)) {
        tf_lane c2 = cg * cg, c4 = c2 * c2, c8 = c4 * c4, c16 = c8 * c8, c32 = c16 * c16;
        tf_lane c64 = c32 * c32, c256 = c64 * c64 * c64 * c64;
        tf_lane glow = 0.03 * c8 + 0.08 * c64 + 0.25 * c256;
        c = TF_SEL3(c, tf_l3_add(c, tf_l3_scale(TF_SPLAT3(sun_light), glow)), glowing);
    }
    return c;
}

/* tf_mist_depth_exp for the samples of `want` (shade.h): optical depth of a path of length len
 * from altitude z1 to z2 through density * exp(-k z), in closed form, or at the mean altitude
 * when the path is (nearly) level. */
TF_SHARED tf_lane tf_mist_depth_exp_of(double density, double k, tf_lane z1, tf_lane z2,
                                       tf_lane len, tf_mask want)
{
    if (k == 0)
        return density * len;
    tf_lane x = k * fabs(z2 - z1);
    tf_mask level = x < 1e-5;
    tf_lane mean_density = TF_LANE(0.0);
    if (TF_ANY(level)) /* (nearly) level: density at the mean altitude, eq. 4.1.7 */
        mean_density = TF_SEL(mean_density, exp(-k * 0.5 * (z1 + z2)), level);
    tf_mask slanted = want & TF_NOT(level);
    if (TF_ANY(slanted)) /* eq. 4.1.5 normalised by the span, from the lower (densest) end */
        mean_density = TF_SEL(mean_density, exp(-k * fmin(z1, z2)) * (-expm1(-x) / x), slanted);
    return density * len * mean_density;
}

/* Optical depth of the mist from altitude oz along a unit ray of vertical component dz over
 * len (INFINITY: to the sky; that converges only while climbing: density e^{-k oz} / (k dz)). */
TF_SHARED tf_lane tf_mist_depth(double density, double k, int homogeneous, tf_lane oz, tf_lane dz,
                                tf_lane len)
{
    tf_mask endless = TF_ISINF(len);
    if (homogeneous || k == 0)
        return TF_SEL(density * len, INFINITY, endless);
    tf_lane tau = TF_LANE(0.0);
    tf_mask finite = TF_NOT(endless);
    if (TF_ANY(finite))
        tau = TF_SEL(tau, tf_mist_depth_exp_of(density, k, oz, oz + dz * len, len, finite),
                     finite);
    if (TF_ANY(endless))
        tau = TF_SEL(tau, TF_SEL(density * exp(-k * oz) / (k * dz), INFINITY, dz <= 1e-12),
                     endless);
    return tau;
}

TF_SHARED tf_lane tf_transparency(tf_lane tau, double extinction)
{
    if (extinction <= 0)
        return TF_LANE(1.0);
    return exp(-tau * extinction); /* tau = INFINITY gives 0 */
}

/* tf_mist_apply's blend: colour c behind optical depth tau, per channel
 * sigma * c + (1 - sigma) * color with sigma = exp(-tau * extinction). */
TF_SHARED tf_lane3 tf_mist_blend(tf_lane3 c, tf_lane tau, tf_vec3 extinction, tf_vec3 color)
{
    tf_lane sr = tf_transparency(tau, extinction.x);
    tf_lane sg = tf_transparency(tau, extinction.y);
    tf_lane sb = tf_transparency(tau, extinction.z);
    return tf_l3(sr * c.x + (1 - sr) * color.x, sg * c.y + (1 - sg) * color.y,
                 sb * c.z + (1 - sb) * color.z);
}

#endif
