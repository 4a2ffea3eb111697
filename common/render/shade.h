/* shade.h: what a camera ray sees: terrain materials and lighting, the water plane, the sky and
 * the atmosphere between the eye and whatever the ray ends on (docs/contract.md section 4; Musgrave
 * chapters 4.1 and 5).
 *
 *   materials   by altitude and slope: vegetation below the tree line, alpine ground above
 *               it, bare rock on slopes steeper than rock_slope_deg, snow above a snow line
 *               perturbed by fBm (snow_jitter); all transitions are smooth blends.  Normals are
 *               interpolated across each triangle from vertex normals (no faceting), then
 *               perturbed by fBm bump mapping (materials.bump) whose octaves start where the
 *               height field's resolution stops ("leave the highest frequencies to the
 *               texture", Musgrave 5).  Texture octaves finer than the pixel's footprint
 *               at the hit are faded out (band-limited textures: less aliasing, and the
 *               adaptive antialiasing is not sent chasing sub-pixel noise).
 *   light       sun (direct, shadowed through tf_occluded) plus sky light weighted by how
 *               much sky the normal sees.  Whether the sun shines on a terrain point is
 *               decided, by default, by its flat triangle: the sun must face the triangle, and
 *               the shadow ray starts on it, lifted along its normal, so near the terminator
 *               each triangle is lit or dark on its own.  terrain.smooth decides it by the
 *               interpolated normal instead, the shadow ray starting on the smooth surface the
 *               vertex normals describe (tf_smooth_shadow_origin, sample_math.h): light then
 *               ends on a smooth terminator.
 *   water       an infinite plane at sea_level, flat with fBm ripples in its normal; reflects
 *               the sky with Schlick's Fresnel term over a dark, lit water body.
 *   sky         zenith/horizon gradient plus a soft glow around the sun.
 *   mist        exponential in altitude, optical depth in closed form (Musgrave 4.1.5, with the
 *               near-horizontal fallback), per-channel extinction (4.1.7); or homogeneous fog.
 *
 * Everything here is a pure function of the scene, the height field and the ray, so shading is
 * deterministic and thread-safe. */
#ifndef TF_SHADE_H
#define TF_SHADE_H

#include <stdint.h>
#include "terrain/heightfield.h"
#include "terrain/noise.h"
#include "scene.h"
#include "render/constants.h"
#include "render/trace.h"
#include "terrain/procedural.h"
#include "vec.h"

typedef struct tf_shader {
    const tf_scene *scene;
    const tf_heightfield *hf;
    tf_noise noise;          /* texture noise (initialised only when textures need it) */
    int textured;            /* bump > 0 or snow_jitter > 0 */
    int smooth;              /* terrain.smooth: the sun test and the shadow ray by the
                              * interpolated normal (tf_shade_terrain) */
    tf_vec3 sun_dir;         /* unit vector towards the sun */
    tf_ray_dir sun_ray;      /* sun_dir's part of a shadow ray's setup, made once (trace.h) */
    tf_vec3 sun_light;       /* sun colour * intensity */
    tf_vec3 sky_light;       /* ambient sky radiance on an upward-facing surface */
    double mist_k;           /* exponential mist: density(z) = density * exp(-mist_k * z) */
    double band;             /* width of material transitions, world units */
    double bump_scale;       /* world wavelength of the first bump octave */
    double ripple_scale;     /* world wavelength of the first water ripple octave */
    double shadow_lift;      /* shadow ray start offset along the normal */
    double pixel_angle;      /* angle one pixel subtends at the image centre, radians */
    tf_proc_view view;       /* a procedural terrain's levels of detail for this camera */
    double flow_ref;         /* [erosion]: flow at which a bed looks fully wet (mean * 8) */
    /* a normal's z at or above nz_gentle is a slope below both materials' blends, at or below
     * nz_steep one past them (tf_shade_albedo: no acos needed there) */
    double nz_gentle, nz_steep;
    /* NULL, or the sun's strips (sun_strips.h: the renderer's, or kept with the height
     * field): where a shadow ray's walk may end, the same answer from a shorter walk */
    const struct tf_sun_strips *sun_strips;
} tf_shader;

/* One camera sample: linear RGB, alpha (1 = terrain or water), distance to the hit (or
 * TF_SKY_DIST for sky). */
typedef struct tf_sample {
    float r, g, b, a;
    float dist;
} tf_sample;

/* TF_SKY_DIST: render/constants.h */

/* What the sun's strips (sun_strips.h) prove of the shadow ray from o toward sh->sun_dir: 1,
 * it is occluded; else 0, and *tmax is where tf_occluded may stop and still give the whole
 * ray's answer (TF_FAR_AWAY where nothing is proved, or there are no strips; TF_FAR_AWAY too
 * where the ray is occluded). */
int tf_shadow_strips(const tf_shader *sh, tf_vec3 o, double *tmax);

void tf_shader_init(tf_shader *sh, const tf_scene *s, const tf_heightfield *hf);
/* The unit vector toward the scene's sun (tf_shader_init's sun_dir, the same bits). */
tf_vec3 tf_sun_direction(const tf_scene *s);

/* Trace and shade one camera ray (dir unit).  Adds the shadow rays it casts to *shadow_rays. */
void tf_shade_ray(const tf_shader *sh, tf_vec3 origin, tf_vec3 dir, tf_sample *out,
                  uint64_t *shadow_rays);

/* What a sample's rays vouch for about a neighbour's (render/trace.h's coherence): its camera
 * ray's record and its shadow ray's. */
typedef struct tf_sample_record {
    tf_ray_clear camera;
    tf_shadow_clear shadow;
} tf_sample_record;

/* tf_shade_ray, its camera ray traced with tf_trace_coherent and its shadow ray with
 * tf_occluded_coherent: the same bits, helped by `lower` (NULL or another sample's record);
 * *mine, unless NULL, gets this sample's (one that vouches for nothing on a procedural
 * terrain). */
void tf_shade_ray_coherent(const tf_shader *sh, tf_vec3 origin, tf_vec3 dir,
                           const tf_sample_record *lower, tf_sample_record *mine, tf_sample *out,
                           uint64_t *shadow_rays);
/* tf_shade_ray_coherent with its camera ray helped by whichever of lowers[0 .. n) vouches for
 * most (tf_trace_coherent_among) and its shadow ray by `near` (NULL: none). */
void tf_shade_ray_coherent_among(const tf_shader *sh, tf_vec3 origin, tf_vec3 dir,
                                 const tf_ray_clear *const *lowers, int n,
                                 const tf_shadow_clear *near, tf_sample_record *mine,
                                 tf_sample *out, uint64_t *shadow_rays);

/* tf_shade_ray in three steps, split at the shadow ray, so that a caller can trace many
 * samples' rays together (render.c's corner rows, trace_packet.h) with the same bits:
 *   t_water = tf_shade_t_water(sh, o, d);
 *   hit = tf_trace(sh->hf, o, d, 0.0, t_water, &h) ? &h : NULL;   (grid terrains)
 *   tf_shade_begin(sh, o, d, t_water, hit, &p);
 *   occluded = p.shadow && tf_occluded(sh->hf, p.start, sh->sun_dir, 0.0, TF_FAR_AWAY);
 *   tf_shade_end(sh, o, d, &p, occluded, &sample);       (p.shadow: one shadow ray cast) */
enum { TF_SURFACE_SKY, TF_SURFACE_TERRAIN, TF_SURFACE_WATER };
typedef struct tf_shade_pending {
    int surface;     /* TF_SURFACE_* */
    int shadow;      /* 1: the sun is in front; a shadow ray from start toward sh->sun_dir */
    tf_vec3 start;
    tf_vec3 base;    /* terrain: the albedo; water: the reflected direction */
    tf_vec3 light;   /* the light before the sun's */
    double cos_sun;  /* the sun's weight where the shadow ray escapes */
    double fresnel;  /* water */
    double dist;     /* distance to the surface */
} tf_shade_pending;
double tf_shade_t_water(const tf_shader *sh, tf_vec3 origin, tf_vec3 dir);
void tf_shade_begin(const tf_shader *sh, tf_vec3 origin, tf_vec3 dir, double t_water,
                    const tf_hit *hit, tf_shade_pending *p);
void tf_shade_end(const tf_shader *sh, tf_vec3 origin, tf_vec3 dir, const tf_shade_pending *p,
                  int occluded, tf_sample *out);

/* The two surfaces, before mist (tf_shade_ray calls them; tests call them directly).
 * tf_shade_terrain: colour at a terrain hit; tf_shade_water: colour of the water plane at p
 * seen along unit dir from distance dist.  Both cast one shadow ray when the sun is in front of the surface. */
tf_vec3 tf_shade_terrain(const tf_shader *sh, const tf_hit *hit, uint64_t *shadow_rays);
tf_vec3 tf_shade_water(const tf_shader *sh, tf_vec3 p, tf_vec3 dir, double dist,
                       uint64_t *shadow_rays);

/* The albedo of terrain point p with smooth normal n (tf_terrain_albedo), the snow line moved
 * by its fBm wherever that can change the albedo; variation in [-1, 1] perturbs it. */
tf_vec3 tf_shade_albedo(const tf_shader *sh, tf_vec3 p, tf_vec3 n, double variation);

/* For the OpenCL host, which uploads what the shader uses instead of deriving it again:
 * tf_shade_octave_weights puts in amp[0 .. n-1] (n <= 32) the full-weight octave weights of
 * the texture fBm plan of exponent H (TF_BUMP_H, or TF_SNOW_H = TF_RIPPLE_H), lacunarity 2;
 * tf_shade_snow_fbm_bound is the strict bound on |snow line fBm| that snow shading tests
 * against (tf_snow_line_matters), and tf_shade_snow_rest_bounds puts in bound[k] (k < n) the
 * bound on its octaves from k on (0 past its last octave). */
void tf_shade_octave_weights(double H, double *amp, int n);
double tf_shade_snow_fbm_bound(void);
void tf_shade_snow_rest_bounds(double *bound, int n);

/* Sky radiance in direction dir (unit), before mist. */
tf_vec3 tf_sky_color(const tf_shader *sh, tf_vec3 dir);

/* Exponential mist: optical depth of a straight path of length `len` from altitude z1 to
 * altitude z2 through density(z) = density * exp(-k z), in closed form.  When the path is
 * (nearly) level, uses the density at the mean altitude (Musgrave eq. 4.1.7), which agrees
 * with the closed form to ~1e-12 relative at the switch-over.  len must be finite (a ray to
 * the sky is handled by tf_mist_apply). */
double tf_mist_depth_exp(double density, double k, double z1, double z2, double len);

/* Apply the scene's mist to colour c seen at distance len along the unit ray origin + t dir
 * (len = INFINITY for the sky): I = sigma * c + (1 - sigma) * mist.color per channel, with
 * sigma = exp(-tau * extinction[channel]). */
tf_vec3 tf_mist_apply(const tf_shader *sh, tf_vec3 c, tf_vec3 origin, tf_vec3 dir, double len);

#endif
