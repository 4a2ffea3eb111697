/* constants.h: every number the C renderer (common/render) and the
 * OpenCL kernels (worker/kernels) share, defined once (the noise's are in
 * common/terrain/noise_kernel.h).  Plain C preprocessor only: C includes
 * it (render_internal.h, shade.h), and worker/backend_opencl.c hands the same
 * file to the kernel build, right after tf_cl_params.h (see worker/kernels/README.md).  A
 * constant used by only one side lives with that side.
 *
 * Changing a value here changes both backends at once; tests/unit/test_opencl.c still checks
 * that they agree to the bit. */
#ifndef TF_RENDER_CONSTANTS_H
#define TF_RENDER_CONSTANTS_H

/* ---- geometry and units */
#define TF_FAR_AWAY 1e30                            /* "no hit" / "no water" ray length */
#define TF_SKY_DIST 1e30f                           /* a sky sample's distance (tf_sample) */
#define TF_DEG2RAD (3.14159265358979323846 / 180.0)

/* ---- adaptive antialiasing (render.c, packet_render.cl; render_internal.h explains) */
#define TF_AA_MAX_DEPTH 6        /* 64x64 quads, 4225 samples: the most a pixel can take */
/* A quad whose corners' display range exceeds this fraction of its split threshold gets its
 * centre sample (the probe) before the split decision; below it the corners are trusted. */
#define TF_AA_PROBE_FRACTION 0.1
/* Coherence (render/trace.h): in the OpenCL kernels a sample off its pixel's corner columns has
 * its camera ray helped by the ray of the corner this many pixel rows below its pixel row (or
 * the rectangle's last corner row), in the nearest corner column.  Nearer rows are often too
 * close to outclimb the terrain's slope across half a pixel of heading (trace.c's D), farther
 * ones vouch for less; 3, 5 and 8 measured on default.scene, 5 the fastest in C and in OpenCL.
 * The C renderer asks the corner rows 1 to this many below, nearest first, for the first that
 * vouches (render.c's lower_rays): 4.4% fewer instructions than this one alone. */
#define TF_LOWER_ROWS 5
/* In the OpenCL pixel kernel, where that corner's ray cannot vouch (one pixel camera ray in
 * eleven on default.scene at 1920x1080, most with trace.c's D <= 0: its climb does not outpace
 * the slope across the two headings), the corner this many rows down is asked instead: twice
 * the climb for the same offset in heading.  It spares those rays most of a walk from the
 * camera, which held up the other lanes of their packets (a pixel camera ray's steps 7.54 ->
 * 6.29; 8 rows 6.46, 15 rows 6.81).  The C renderer keeps the one record: there such a walk
 * holds up nothing, and the far record measured no gain (bench/README.md section 30); it asks
 * nearer rows first instead (above). */
#define TF_LOWER_ROWS_FAR 10
/* lattice jitter: tf_hash64 of the key, X, and Y times the golden ratio; jy from the hash
 * xored with TF_JITTER_Y_SALT */
#define TF_JITTER_Y_MUL 0x9e3779b97f4a7c15UL
#define TF_JITTER_Y_SALT 0xd1b54a32d192ed03UL

/* The noise constants (coordinate limit, scales, table sizes, gradients) are in
 * common/terrain/noise_kernel.h, which both sides load too. */

/* ---- materials and lighting (shade.c, packet_shade.cl; shared math in shade_math.h) */
#define TF_ROCK_BLEND_DEG 6.0     /* rock fades in over rock_slope_deg +- this */
#define TF_SNOW_SLIDE_DEG 15.0    /* snow thins out this far above the rock slope */
#define TF_BUMP_OCTAVES 4.0
#define TF_BUMP_H 0.8             /* fBm H of the bump and colour variation texture */
#define TF_SNOW_OCTAVES 5.0
#define TF_SNOW_H 0.5             /* fBm H of the snow line perturbation */
#define TF_RIPPLE_OCTAVES 3.0
#define TF_RIPPLE_H 0.5           /* fBm H of the water ripples */
#define TF_RIPPLE_STRENGTH 0.06   /* slope amplitude of the water ripples */
#define TF_RIPPLE_SALT 71.0       /* domain shift of the ripple texture */
#define TF_COLOUR_VARIATION 0.15  /* fractal albedo perturbation (Musgrave 5.6.5) */
#define TF_FRESNEL_R0 0.02        /* water at normal incidence */
/* The snow line texture: noise space is the terrain extent / TF_SNOW_WAVELENGTHS per unit,
 * shifted by (+TF_SNOW_SALT_X, -TF_SNOW_SALT_Y). */
#define TF_SNOW_WAVELENGTHS 12.0
#define TF_SNOW_SALT_X 37.5
#define TF_SNOW_SALT_Y 11.25
/* Albedos (linear RGB), as initialiser lists: {TF_ALBEDO_ROCK}. */
#define TF_ALBEDO_VEGETATION 0.040, 0.075, 0.022
#define TF_ALBEDO_ALPINE 0.120, 0.105, 0.070
#define TF_ALBEDO_ROCK 0.200, 0.180, 0.160
#define TF_ALBEDO_SNOW 0.800, 0.820, 0.860
#define TF_ALBEDO_SAND 0.330, 0.290, 0.200
/* [erosion]: silt deposited by water (a pale dry wash, Musgrave's plates 2.10-2.11), the
 * depth at which it hides what is below, and how much darker the wettest bed is. */
#define TF_ALBEDO_SILT 0.420, 0.380, 0.300
#define TF_SILT_COVER_M 0.5
#define TF_WET_DARKEN 0.55
#define TF_WATER_BODY 0.010, 0.028, 0.040

#endif
