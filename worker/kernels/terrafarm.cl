/* terrafarm.cl: the base of the OpenCL kernels -- the renderer's constants, the scalar vec3 and
 * the world (the buffers and height-field shape every kernel reads).  The host
 * (worker/backend_opencl.c) prepends tf_cl_params.h (the P[] / I[] indices) and appends
 * packet.cl, packet_trace.cl, packet_shade.cl and packet_render.cl, which hold the renderer
 * itself: common/render.c, shade.c, camera.c, trace.c and noise.c run eight samples at a time
 * (see worker/kernels/README.md).  The constants below are those files' constants: when one
 * changes there, change it here. */
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

#define TF_AA_MAX_DEPTH 6
#define TF_AA_PROBE_FRACTION 0.1 /* render_internal.h */
#define TF_SKY_DIST 1e30f
#define FAR_AWAY 1e30
#define DEG2RAD (3.14159265358979323846 / 180.0)
#define TF_NOISE_COORD_LIMIT 0x1p52
#define TF_NOISE2_SCALE 1.41421

/* shade.c constants: keep in step with common/shade.c */
#define ROCK_BLEND_DEG 6.0
#define SNOW_SLIDE_DEG 15.0
#define BUMP_OCTAVES 4.0
#define SNOW_OCTAVES 5.0
#define RIPPLE_OCTAVES 3.0
#define RIPPLE_STRENGTH 0.06
#define COLOUR_VARIATION 0.15
#define FRESNEL_R0 0.02

/* ---------------------------------------------------------------- vectors (vec.h) */

typedef struct vec3 { double x, y, z; } vec3;

vec3 v3(double x, double y, double z) { vec3 r = {x, y, z}; return r; }

/* noise_impl.h's gradient table, by its constants: grad_x8 in packet_shade.cl computes the
 * table's entries from them */
#define TF_C1 0.92387953251128674
#define TF_S1 0.38268343236508977
#define TF_H1 0.70710678118654752

/* ---------------------------------------------------------------- the world */

/* Everything a work-item reads, gathered once at kernel entry. */
typedef struct world {
    __global const double *P;
    __global const int *I;
    __global const float *h;      /* n * n heights */
    __global const float2 *mm;    /* (max, min) of every cell of every grid level, levels
                                   * concatenated (level L starts at I[TFI_LEVEL_OFFSET+L]) */
    __global const ushort *perm;  /* texture noise permutation, 512 entries */
    int n, cells, levels;
    double cell;
    /* I[TFI_LEVEL_OFFSET + L] for L < 16 in two vectors: the walk looks a level's offset up with
     * one permute instead of a gather (packet_trace.cl level_offset8) */
    long8 offset_lo, offset_hi;
} world;

vec3 pvec(const world *w, int k) { return v3(w->P[k], w->P[k + 1], w->P[k + 2]); }

world make_world(__global const double *P, __global const int *I, __global const float *h,
                 __global const float2 *mm,
                 __global const ushort *perm)
{
    world w;
    w.P = P;
    w.I = I;
    w.h = h;
    w.mm = mm;
    w.perm = perm;
    w.n = I[TFI_N];
    w.cells = I[TFI_CELLS];
    w.levels = I[TFI_LEVELS];
    w.cell = P[TFP_CELL];
    long off[16];
    for (int L = 0; L < 16; L++)
        off[L] = L < w.levels ? I[TFI_LEVEL_OFFSET + L] : 0;
    w.offset_lo = vload8(0, off);
    w.offset_hi = vload8(1, off);
    return w;
}
