/* terrafarm.cl: the base of the OpenCL kernels -- the scalar vec3, the camera and the world
 * (the buffers and height-field shape every kernel reads).  The host (worker/backend_opencl.c)
 * builds one program from, in this order: tf_cl_params.h (the P[] / I[] indices),
 * common/render/constants.h (the numbers the C renderer and the kernels share), this file,
 * packet.cl (the packet types), common/portable.h, common/terrain/noise_kernel.h and
 * common/render/sample_math.h (the per-sample math, the C renderer's own source), then
 * packet_trace.cl, packet_shade.cl and packet_render.cl, which schedule that math eight samples
 * at a time (see worker/kernels/README.md). */
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

/* ---------------------------------------------------------------- vectors (vec.h) */

typedef struct vec3 { double x, y, z; } vec3;

vec3 v3(double x, double y, double z) { vec3 r = {x, y, z}; return r; }

/* ---------------------------------------------------------------- the camera (camera.h)
 *
 * camera.h's tf_camera with the fields sample_math.h's tf_camera_ray reads, under the same
 * names; make_world fills it from the values the host copied out of the C camera. */
#define TF_CAMERA_PANORAMA 1 /* enum tf_camera_kind; I[TFI_CAM_KIND] is 1 for a panorama */

typedef struct tf_camera {
    int kind, width, height;
    vec3 forward, right, up;
    double half_w, half_h;
    vec3 pano_forward, pano_right, pano_up;
    double sweep, v_centre, v_half;
} tf_camera;

/* ---------------------------------------------------------------- the world */

/* Everything a work-item reads, gathered once at kernel entry. */
typedef struct world {
    __global const double *P;
    __global const int *I;
    __global const float *h;      /* n * n heights */
    __global const float2 *mm;    /* (max, min) of every cell of every grid level, levels
                                   * concatenated (level L starts at I[TFI_LEVEL_OFFSET+L]) */
    __global const ushort *perm;  /* texture noise permutation, 512 entries */
    __global const float *strips; /* the sun's strips' table (render/sun_math.h;
                                   * I[TFI_SUN_STRIPS] 0: none, two unread floats) */
    int n, cells, levels;
    int cell_shift;               /* cells == 1 << cell_shift (heightfield.c: n = 2^k + 1), so
                                   * a row's offset is a shift, not a 64-bit vector multiply
                                   * (vpmullq: three uops, 15 cycles, on a walk step's path) */
    double cell;
    tf_camera cam;
} world;

vec3 pvec(const world *w, int k) { return v3(w->P[k], w->P[k + 1], w->P[k + 2]); }

world make_world(__global const double *P, __global const int *I, __global const float *h,
                 __global const float2 *mm, __global const ushort *perm,
                 __global const float *strips)
{
    world w;
    w.P = P;
    w.I = I;
    w.h = h;
    w.mm = mm;
    w.perm = perm;
    w.strips = strips;
    w.n = I[TFI_N];
    w.cells = I[TFI_CELLS];
    w.levels = I[TFI_LEVELS];
    w.cell_shift = 31 - clz(w.cells);
    w.cell = P[TFP_CELL];
    w.cam.kind = I[TFI_CAM_KIND];
    w.cam.width = I[TFI_WIDTH];
    w.cam.height = I[TFI_HEIGHT];
    w.cam.forward = pvec(&w, TFP_CAM_FORWARD);
    w.cam.right = pvec(&w, TFP_CAM_RIGHT);
    w.cam.up = pvec(&w, TFP_CAM_UP);
    w.cam.half_w = P[TFP_HALF_W];
    w.cam.half_h = P[TFP_HALF_H];
    w.cam.pano_forward = pvec(&w, TFP_PANO_FORWARD);
    w.cam.pano_right = pvec(&w, TFP_PANO_RIGHT);
    w.cam.pano_up = pvec(&w, TFP_PANO_UP);
    w.cam.sweep = P[TFP_SWEEP];
    w.cam.v_centre = P[TFP_V_CENTRE];
    w.cam.v_half = P[TFP_V_HALF];
    return w;
}
