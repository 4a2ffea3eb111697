/* noise_row.c: tf_noise_row_blend (noise_row.h), the blend of a row's samples from the lattice
 * columns of one octave, in AVX-512 where the CPU has it (an AVX2 version with gathers was no
 * faster than the scalar loop on AMD Zen 4, and is not kept).
 *
 * Each lane repeats the scalar arithmetic of noise_kernel.h exactly (-ffp-contract=off keeps
 * every multiply and add separate, as in the scalar code):
 *   floor split  i = trunc(x); d = (double)i; below = x < d; fx = x - (d - (below ? 1 : 0))
 *   fade         u = ((fx fx) fx) ((fx ((fx 6) - 15)) + 10)
 *   blend        l = sl fx + il; r = sr (fx - 1) + ir; noise = (l + u (r - l)) 1.41421
 * AVX-512 converts with cvttpd2qq / cvtqq2pd exactly like the scalar casts.  The octave's two
 * other row loops (x times the lacunarity, fBm's sum) are here too, for the same reason. */
#include "terrain/noise_row.h"

#include <stdlib.h>
#include <string.h>

#include "terrain/noise_impl.h"

#if defined(__x86_64__) && defined(__GNUC__)
#define TF_NOISE_X86 1
#include <immintrin.h>
#endif

/* The fade and blend of one vector of samples, on GCC vector types (operators, no FMA). */
#define TF_BLEND(fx, sl, il, sr, ir)                                                          \
    ({                                                                                        \
        __typeof__(fx) u_ = (fx) * (fx) * (fx) * ((fx) * ((fx) * 6.0 - 15.0) + 10.0);         \
        __typeof__(fx) l_ = (sl) * (fx) + (il);                                               \
        __typeof__(fx) r_ = (sr) * ((fx) - 1.0) + (ir);                                       \
        (l_ + u_ * (r_ - l_)) * TF_NOISE2_SCALE;                                              \
    })

#ifdef TF_NOISE_X86
typedef double v8d __attribute__((vector_size(64)));

/* Each lane's left and right columns, `at` = 2 (column index).  Where the eight lanes' columns
 * lie within seven of the lowest (a sample spacing of 6/7 column or less, every octave of a
 * typical terrain), two loads and four permutes pick them; else four gathers (slower on
 * AMD's Zen 4 by half).  The table has 8 columns of slack past its end for the loads. */
__attribute__((target("avx512f,avx512dq"))) static inline void
columns_avx512(const double *col, __m512i at, v8d *sl, v8d *il, v8d *sr, v8d *ir)
{
    int64_t base = _mm512_reduce_min_epi64(at);
    __m512i rel = _mm512_sub_epi64(at, _mm512_set1_epi64(base));
    if (_mm512_cmpgt_epi64_mask(rel, _mm512_set1_epi64(12)) == 0) {
        __m512d lo = _mm512_loadu_pd(col + base), hi = _mm512_loadu_pd(col + base + 8);
        __m512i one = _mm512_set1_epi64(1);
        *sl = (v8d)_mm512_permutex2var_pd(lo, rel, hi);
        rel = _mm512_add_epi64(rel, one);
        *il = (v8d)_mm512_permutex2var_pd(lo, rel, hi);
        rel = _mm512_add_epi64(rel, one);
        *sr = (v8d)_mm512_permutex2var_pd(lo, rel, hi);
        rel = _mm512_add_epi64(rel, one);
        *ir = (v8d)_mm512_permutex2var_pd(lo, rel, hi);
        return;
    }
    *sl = (v8d)_mm512_i64gather_pd(at, col, 8), *il = (v8d)_mm512_i64gather_pd(at, col + 1, 8);
    *sr = (v8d)_mm512_i64gather_pd(at, col + 2, 8), *ir = (v8d)_mm512_i64gather_pd(at, col + 3, 8);
}

__attribute__((target("avx512f,avx512dq"))) static int
blend_avx512(const double *x, int count, int64_t first, const tf_noise_column *columns,
             double *noise)
{
    const double *col = (const double *)columns; /* slope, intercept, slope, ... */
    const __m512i firstv = _mm512_set1_epi64(first), onei = _mm512_set1_epi64(1);
    int k = 0;
    for (; k + 8 <= count; k += 8) {
        __m512d xv = _mm512_loadu_pd(x + k);
        __m512i i = _mm512_cvttpd_epi64(xv);
        __m512d d = _mm512_cvtepi64_pd(i);
        __mmask8 below = _mm512_cmp_pd_mask(xv, d, _CMP_LT_OQ);
        v8d fx = (v8d)xv - ((v8d)d - (v8d)_mm512_maskz_mov_pd(below, _mm512_set1_pd(1.0)));
        __m512i at = _mm512_sub_epi64(_mm512_mask_sub_epi64(i, below, i, onei), firstv);
        v8d sl, il, sr, ir;
        columns_avx512(col, _mm512_slli_epi64(at, 1), &sl, &il, &sr, &ir);
        _mm512_storeu_pd(noise + k, (__m512d)TF_BLEND(fx, sl, il, sr, ir));
    }
    return k;
}

__attribute__((target("avx512f"))) static int scale_avx512(double *x, int count, double by)
{
    const __m512d b = _mm512_set1_pd(by);
    int k = 0;
    for (; k + 8 <= count; k += 8)
        _mm512_storeu_pd(x + k, _mm512_mul_pd(_mm512_loadu_pd(x + k), b));
    return k;
}

__attribute__((target("avx512f"))) static int
accumulate_avx512(double *v, double amp, const double *n, int count)
{
    const __m512d a = _mm512_set1_pd(amp);
    int k = 0;
    for (; k + 8 <= count; k += 8) {
        __m512d term = _mm512_mul_pd(a, _mm512_loadu_pd(n + k));
        _mm512_storeu_pd(v + k, _mm512_add_pd(_mm512_loadu_pd(v + k), term));
    }
    return k;
}
#endif

/* ---- choosing the kernel -------------------------------------------------------------------- */

enum { ISA_UNSET = 0, ISA_AVX512, ISA_PORTABLE };
static const char *const isa_names[] = {"", "avx512", "portable"};
static int isa_chosen = ISA_UNSET; /* read and written with __atomic: any thread may choose */

static int isa_runs(int isa)
{
#ifdef TF_NOISE_X86
    if (isa == ISA_AVX512)
        return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512dq");
#endif
    return isa == ISA_PORTABLE;
}

static int isa_named(const char *name)
{
    for (int i = ISA_AVX512; i <= ISA_PORTABLE; i++)
        if (name && !strcmp(name, isa_names[i]))
            return i;
    return ISA_UNSET;
}

/* The best kernel this CPU runs, no better than TF_NOISE_ISA names. */
static int isa_best(void)
{
    int i = isa_named(getenv("TF_NOISE_ISA"));
    if (i == ISA_UNSET)
        i = ISA_AVX512;
    while (!isa_runs(i))
        i++;
    return i;
}

static int isa_now(void)
{
    int i = __atomic_load_n(&isa_chosen, __ATOMIC_RELAXED);
    if (i == ISA_UNSET) {
        i = isa_best();
        __atomic_store_n(&isa_chosen, i, __ATOMIC_RELAXED);
    }
    return i;
}

const char *tf_noise_row_isa(void) { return isa_names[isa_now()]; }

int tf_noise_row_force_isa(const char *isa)
{
    int i = isa ? isa_named(isa) : isa_best();
    if (i == ISA_UNSET || !isa_runs(i))
        return -1;
    __atomic_store_n(&isa_chosen, i, __ATOMIC_RELAXED);
    return 0;
}

void tf_row_scale(double *x, int count, double by)
{
    int k = 0;
#ifdef TF_NOISE_X86
    if (isa_now() == ISA_AVX512)
        k = scale_avx512(x, count, by);
#endif
    for (; k < count; k++)
        x[k] *= by;
}

void tf_row_accumulate(double *v, double amp, const double *n, int count)
{
    int k = 0;
#ifdef TF_NOISE_X86
    if (isa_now() == ISA_AVX512)
        k = accumulate_avx512(v, amp, n, count);
#endif
    for (; k < count; k++)
        v[k] += amp * n[k];
}

int tf_noise_row_blend(const double *x, int count, int64_t first, const tf_noise_column *columns,
                       double *noise)
{
#ifdef TF_NOISE_X86
    switch (isa_now()) {
    case ISA_AVX512:
        return blend_avx512(x, count, first, columns, noise);
    default:
        break;
    }
#endif
    (void)x, (void)count, (void)first, (void)columns, (void)noise;
    return 0;
}
