/* tf_cl_params.h: the parameter block the host (worker/backend_opencl.c) fills and the kernels
 * in worker/kernels read.  Plain C preprocessor only, so the same file is compiled
 * into the host and prepended to the kernel source at run time: the indices can never drift.
 *
 * Two arrays carry everything derived from the scene, the camera and the shader setup (the very
 * values tf_renderer_new computes, copied, never recomputed on the device):
 *   P[] doubles, indexed by TFP_*   (vectors take three consecutive slots x, y, z)
 *   I[] ints,    indexed by TFI_*   (TFI_LEVEL_OFFSET + L: start of mip level L in the
 *                                    concatenated max/min grid buffers) */
#ifndef TF_CL_PARAMS_H
#define TF_CL_PARAMS_H

/* doubles */
#define TFP_CELL          0
#define TFP_EXTENT        1
#define TFP_HMIN          2
#define TFP_HMAX          3
#define TFP_CAM_POS       4   /* 3 */
#define TFP_CAM_FORWARD   7   /* 3 */
#define TFP_CAM_RIGHT    10   /* 3 */
#define TFP_CAM_UP       13   /* 3 */
#define TFP_HALF_W       16
#define TFP_HALF_H       17
#define TFP_PANO_FORWARD 18   /* 3 */
#define TFP_PANO_RIGHT   21   /* 3 */
#define TFP_PANO_UP      24   /* 3 */
#define TFP_SWEEP        27
#define TFP_V_CENTRE     28
#define TFP_V_HALF       29
#define TFP_SUN_DIR      30   /* 3 */
#define TFP_SUN_LIGHT    33   /* 3 */
#define TFP_SKY_LIGHT    36   /* 3 */
#define TFP_MIST_K       39
#define TFP_BAND         40
#define TFP_BUMP_SCALE   41
#define TFP_RIPPLE_SCALE 42
#define TFP_SHADOW_LIFT  43
#define TFP_PIXEL_ANGLE  44
#define TFP_SEA_LEVEL    45
#define TFP_TREE_LINE    46
#define TFP_SNOW_LINE    47
#define TFP_SNOW_JITTER  48
#define TFP_ROCK_SLOPE   49
#define TFP_BUMP         50
#define TFP_MIST_DENSITY 51
#define TFP_MIST_COLOR   52   /* 3 */
#define TFP_MIST_EXT     55   /* 3 */
#define TFP_SKY_HORIZON  58   /* 3 */
#define TFP_SKY_ZENITH   61   /* 3 */
#define TFP_THRESHOLD    64
/* fBm octave weights pow(2^i, -H) for the two H the textures use (lacunarity 2), computed on
 * the host exactly as tf_octaves_plan does: the device's pow was the kernels' hottest call. */
#define TF_CL_AMP_TABLE   8   /* octaves per table (textures use at most 5) */
#define TFP_AMP_H08      65   /* H = 0.8: bump */
#define TFP_AMP_H05      73   /* H = 0.5: snow line, water ripples */
#define TFP_SNOW_REST    81   /* TF_CL_SNOW_TERMS: strict bounds on |octaves k.. of the snow
                                 fBm| (shade.c snow_rest_bound; the first bounds it all) */
#define TF_CL_SNOW_TERMS  5   /* the snow fBm's octaves: TF_SNOW_OCTAVES, whole */
/* The sun's strips (render/sun_math.h's tf_sun_frame, its doubles in its order; the table
 * itself is the kernels' `strips` buffer): a_s, b_s, a_p, b_p, along0, across0, inv_w, inv_ds,
 * ds, climb, t_per_cell, eps, dx, dy, cell */
#define TFP_SUN_FRAME    86   /* 15 */
#define TF_CL_SUN_DOUBLES 15
#define TFP_SLOPE_MAX   101   /* hf->slope_max, NAN where it bounds nothing (coherence) */
#define TFP_COUNT       102

/* ints */
#define TFI_N             0   /* samples per side */
#define TFI_CELLS         1
#define TFI_LEVELS        2
#define TFI_WIDTH         3
#define TFI_HEIGHT        4
#define TFI_CAM_KIND      5   /* 0 pinhole, 1 panorama (enum tf_camera_kind) */
#define TFI_TEXTURED      6
#define TFI_MIST_ENABLED  7
#define TFI_MIST_HOMOG    8
#define TFI_LATTICE       9   /* N = 2^depth */
#define TFI_DEPTH        10
#define TFI_SMOOTH       11   /* terrain.smooth (shade.h) */
#define TFI_SUN_STRIPS   12   /* tf_sun_frame's strips (0: no strips), bins, look and n */
#define TFI_SUN_BINS     13
#define TFI_SUN_LOOK     14
#define TFI_SUN_N        15
#define TFI_LEVEL_OFFSET 16   /* up to TF_CL_MAX_LEVELS entries */
#define TF_CL_MAX_LEVELS 18
#define TFI_COUNT        (TFI_LEVEL_OFFSET + TF_CL_MAX_LEVELS)

/* Floats per stored sample (r, g, b, a, dist) and per output pixel (r, g, b, a, z, spp, and
 * the camera rays traced into the pixel's slice: its spp less its corners and the samples it
 * took from a neighbour, plus the ones a neighbour took from it). */
#define TF_CL_SAMPLE_FLOATS 5
#define TF_CL_RECORD_DOUBLES 5 /* a corner's coherence record: ux, uy, k, s_in, s_free */
/* tf_corners8's corner columns per work-item for batches of `stream` samples: a band of
 * TF_LOWER_ROWS (render/constants.h) rows of them fills a batch */
#define TF_CL_CORNER_STRIP(stream) ((stream) / TF_LOWER_ROWS)
#define TF_CL_PIXEL_FLOATS  7

#endif
