/* portable.h: the bridge that lets one source of per-sample math compile as C (one sample at a
 * time, the C backend) and as OpenCL C (eight samples at a time, one per lane of the packet
 * types of worker/kernels/packet.cl), in the spirit of pbrt-v4's PBRT_CPU_GPU functions.
 *
 * Shared functions are marked TF_SHARED (TF_SHARED_HOT where PoCL must inline them) and are
 * written on these types:
 *
 *                 C                  OpenCL C
 *   tf_lane       double             double8      a value per sample
 *   tf_mask       int (0 / 1)        long8 (0/-1) a condition per sample (a double comparison)
 *   tf_lane3      tf_vec3            v3p          a vector per sample
 *   tf_lane_u64   uint64_t           ulong8       an integer per sample
 *   tf_lane_i64   int64_t            long8
 *   tf_lane_int   int                int8
 *   tf_vec3       tf_vec3            vec3         a vector all samples share (scene constants)
 *
 * with the operators +, -, *, / and the math functions (sqrt, exp, log2, acos, cos, ...), which
 * OpenCL overloads on vectors, and these macros for what the two languages spell differently:
 *
 *   TF_SEL(a, b, m)     b where m, else a        (C: m ? b : a -- only the side taken is
 *   TF_SEL3(a, b, m)    the same on tf_lane3       evaluated; OpenCL: select, both are)
 *   TF_SELM(a, b, m)    the same on tf_masks
 *   TF_ANY(m)           some sample has m        (guards work no sample needs: in C a plain if)
 *   TF_NOT(m)           !m                       (masks combine with & and |, or with
 *   TF_AND(a, b)        a && b                    TF_AND / TF_OR, which short-circuit in C:
 *   TF_OR(a, b)         a || b                    for hot tests that C should branch on)
 *   TF_ISINF(x), TF_ISFINITE(x)   as masks
 *   TF_SELI64, TF_LANE_TO_I64, TF_I64_TO_LANE, TF_I64_TO_INT, TF_I64_AS_U64, TF_U64_TO_LANE:
 *                       selects and C casts on the integer lanes; TF_MASK_ONE(m) is 1 where m
 *   TF_LANE(s)          a tf_lane from a shared double; TF_SPLAT3(v) a tf_lane3 from a tf_vec3
 *
 * A branch of the scalar code is written `if (TF_ANY(m)) x = TF_SEL(x, value, m);`: in C that
 * is the branch itself (the select folds away), in OpenCL the packet runs the branch when some
 * lane takes it and keeps the result in those lanes.  So every sample, in both languages,
 * performs the same floating-point operations in the same order: the bit-identity of the two
 * backends (tests/unit/test_opencl.c) rests on that, and on FMA contraction being off in both
 * (-ffp-contract=off in the Makefile; `#pragma OPENCL FP_CONTRACT OFF` in terrafarm.cl).
 *
 * Included by the shared C headers (terrain/noise_kernel.h, render/sample_math.h,
 * render/trace_math.h), and handed to the OpenCL build by worker/backend_opencl.c right after
 * packet.cl, which defines the packet types. */
#ifndef TF_PORTABLE_H
#define TF_PORTABLE_H

#ifdef __OPENCL_VERSION__

#define TF_SHARED
#define TF_SHARED_HOT __attribute__((always_inline))
typedef dv tf_lane;
typedef lv tf_mask;
typedef v3p tf_lane3;
typedef ulong8 tf_lane_u64;
typedef long8 tf_lane_i64;
typedef int8 tf_lane_int;
typedef ulong tf_u64;
typedef vec3 tf_vec3;
#define TF_SEL(a, b, m) select((tf_lane)(a), (tf_lane)(b), (m))
#define TF_SEL3(a, b, m) v3p_select((a), (b), (m))
#define TF_SELM(a, b, m) select((tf_mask)(a), (tf_mask)(b), (m))
#define TF_ANY(m) any_lane(m)
#define TF_NOT(m) (~(m))
#define TF_AND(a, b) ((a) & (b))
#define TF_OR(a, b) ((a) | (b))
#define TF_ISINF(x) isinf(x)
#define TF_ISFINITE(x) isfinite(x)
#define TF_LANE(s) ((tf_lane)(s))
#define TF_SPLAT3(v) v3p_splat(v)
#define TF_U64_TO_LANE(x) convert_double8(x)
#define TF_I64_TO_LANE(x) convert_double8(x)
#define TF_I64_AS_U64(x) as_ulong8(x)
#define TF_LANE_TO_I64(x) convert_long8(x) /* rounds toward zero, as C's cast */
#define TF_I64_TO_INT(x) convert_int8(x)
#define TF_SELI64(a, b, m) select((tf_lane_i64)(a), (tf_lane_i64)(b), (m))
#define TF_MASK_ONE(m) (-(m)) /* 1 where m, as a tf_lane_i64 */
#define tf_l3(x, y, z) v3p_make((x), (y), (z))
#define tf_l3_add v3p_add
#define tf_l3_mul v3p_mul
#define tf_l3_scale v3p_scale
#define tf_l3_dot v3p_dot
#define tf_l3_norm v3p_norm
#define tf_l3_lerp v3p_lerp
#define tf_l3_lerp_ss v3p_lerp_ss /* from a shared vector to a shared vector */
#define tf_l3_lerp_ps v3p_lerp_ps /* from a per-sample vector to a shared vector */

#else /* C */

#include <math.h>
#include <stdint.h>
#include "vec.h"

#define TF_SHARED static inline
#define TF_SHARED_HOT
typedef double tf_lane;
typedef int tf_mask;
typedef tf_vec3 tf_lane3;
typedef uint64_t tf_lane_u64;
typedef int64_t tf_lane_i64;
typedef int tf_lane_int;
typedef uint64_t tf_u64;
#define TF_SEL(a, b, m) ((m) ? (b) : (a))
#define TF_SEL3(a, b, m) ((m) ? (b) : (a))
#define TF_SELM(a, b, m) ((m) ? (b) : (a))
#define TF_ANY(m) (m)
#define TF_NOT(m) (!(m))
#define TF_AND(a, b) ((a) && (b))
#define TF_OR(a, b) ((a) || (b))
#define TF_ISINF(x) (isinf(x) != 0)
#define TF_ISFINITE(x) (isfinite(x) != 0)
#define TF_LANE(s) ((double)(s))
#define TF_SPLAT3(v) (v)
#define TF_U64_TO_LANE(x) ((double)(x))
#define TF_I64_TO_LANE(x) ((double)(x))
#define TF_I64_AS_U64(x) ((uint64_t)(x))
#define TF_LANE_TO_I64(x) ((int64_t)(x))
#define TF_I64_TO_INT(x) ((int)(x))
#define TF_SELI64(a, b, m) ((m) ? (b) : (a))
#define TF_MASK_ONE(m) (m)
#define tf_l3(x, y, z) v3((x), (y), (z))
#define tf_l3_add v3_add
#define tf_l3_mul v3_mul
#define tf_l3_scale v3_scale
#define tf_l3_dot v3_dot
#define tf_l3_norm v3_norm
#define tf_l3_lerp v3_lerp
#define tf_l3_lerp_ss v3_lerp
#define tf_l3_lerp_ps v3_lerp

#endif

#endif
