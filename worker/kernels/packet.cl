/* packet.cl: the types of the packet renderer -- eight samples at a time, one per lane of
 * OpenCL's 8-wide vector types, so the compiler (PoCL on the CPU) runs them in SIMD registers.
 *
 * A work-item of packet_render.cl gathers up to 128 lattice samples (from neighbouring pixels,
 * so their rays are coherent) and hands them to lattice_samples (packet_shade.cl), which
 * shades them eight at a time and walks their rays with walk_stream (packet_trace.cl).  The
 * per-sample math is the C renderer's own source (common/portable.h, render/sample_math.h,
 * render/trace_math.h, terrain/noise_kernel.h), compiled on these types; every packet function
 * NAME8 of the schedules computes, in each active lane, exactly what its C counterpart NAME in
 * common/render (trace.c, shade.c, render.c) computes for that lane's sample: the same
 * operations in the same order, so the OpenCL pixels are the C pixels to the bit
 * (tests/unit/test_opencl.c checks it).
 *
 * Conventions:
 *   - A lane mask is an lv (long8): -1 for active lanes, 0 for idle ones -- what comparisons of
 *     dv (double8) values give.  Use select(a, b, mask) to merge (b where the mask is set).
 *   - Idle lanes still execute (that is what SIMD means) but their results are discarded; every
 *     memory access of an idle lane goes through a clamped index (gather_* below), so an idle
 *     lane never reads outside a buffer.
 *   - Integer per-lane values that index buffers are iv (int8); convert_long8 / convert_int8
 *     move between the two widths. */

#define TF_LANES 8

/* For functions that take or return packets and run often: PoCL leaves such functions as
 * calls with their packets passed through memory unless told to inline them. */
#define TF_INLINE __attribute__((always_inline))

typedef double8 dv; /* a double per lane */
typedef long8 lv;   /* a 64-bit integer or mask per lane */
typedef int8 iv;    /* a 32-bit integer per lane */

typedef struct v3p { dv x, y, z; } v3p; /* a vec3 per lane */

/* A hit per lane (trace.c's tf_hit). */
typedef struct hitp { dv t; v3p p, n; iv ci, cj; } hitp;

v3p v3p_make(dv x, dv y, dv z) { v3p r = {x, y, z}; return r; }
v3p v3p_splat(vec3 a) { v3p r = {(dv)(a.x), (dv)(a.y), (dv)(a.z)}; return r; }
v3p v3p_add(v3p a, v3p b) { return v3p_make(a.x + b.x, a.y + b.y, a.z + b.z); }
v3p v3p_mul(v3p a, v3p b) { return v3p_make(a.x * b.x, a.y * b.y, a.z * b.z); }
v3p v3p_scale(v3p a, dv s) { return v3p_make(a.x * s, a.y * s, a.z * s); }
dv v3p_dot(v3p a, v3p b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
v3p v3p_select(v3p a, v3p b, lv m)
{
    return v3p_make(select(a.x, b.x, m), select(a.y, b.y, m), select(a.z, b.z, m));
}

/* v3_norm per lane: lanes of length 0 (or NaN) keep their vector, as in the scalar code. */
v3p v3p_norm(v3p a)
{
    dv l = sqrt(v3p_dot(a, a));
    return v3p_select(a, v3p_scale(a, 1.0 / l), l > 0.0);
}

/* v3_lerp per lane: a + (b - a) t, each component in the scalar order. */
v3p v3p_lerp(v3p a, v3p b, dv t)
{
    return v3p_make(a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t, a.z + (b.z - a.z) * t);
}

/* v3_lerp between two shared vectors: (b - a) is the scalar difference, then per lane. */
v3p v3p_lerp_ss(vec3 a, vec3 b, dv t)
{
    return v3p_make(a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t, a.z + (b.z - a.z) * t);
}

/* v3_lerp from a packet vector to a shared one. */
v3p v3p_lerp_ps(v3p a, vec3 b, dv t)
{
    return v3p_make(a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t, a.z + (b.z - a.z) * t);
}

/* The lanes of mask m as one byte each of a 64-bit word (lane l: bits 8 l .. 8 l + 7), for a
 * loop over the lanes that cannot be vector selects (lattice_samples' shadow rays): `m[l]` with
 * a variable l made PoCL store the whole vector to the stack at every turn and load the lane
 * back, a 64-byte store the 8-byte load could not be forwarded from. */
ulong lane_bytes(lv m) { return as_ulong(convert_char8(m)); }

/* Is some lane of mask m set?  OpenCL's any() tests every lane's sign bit; PoCL compiles that
 * to a chain of extracts and ORs.  Narrowing the lanes to bytes and testing the 64-bit word is
 * three instructions, and the same answer for masks (every lane 0 or -1). */
int any_lane(lv m) { return lane_bytes(m) != 0; }

/* Loads of p[idx] for the active lanes; idle lanes read p[0] (which every buffer has) and get
 * whatever is there: callers discard them. */
dv gather_f(__global const float *p, lv idx, lv mask)
{
    lv k = select((lv)(0), idx, mask);
    return convert_double8((float8)(p[k.s0], p[k.s1], p[k.s2], p[k.s3], p[k.s4], p[k.s5],
                                     p[k.s6], p[k.s7]));
}

