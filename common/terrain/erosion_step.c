/* erosion_step.c: one time step of the erosion model (erosion.h, E1-E3) over a rectangle: the
 * step's rain, then the kernel for the best ISA the CPU has (erosion_kernel.h: AVX-512, AVX2,
 * or the portable one).  Every kernel computes the same bits; TF_EROSION_ISA=portable (or
 * avx2) forces a slower one. */
#include "terrain/erosion.h"

#include <stdlib.h>
#include <string.h>

#include "isa.h"
#include "terrain/erosion_kernel.h"

static const struct {
    const char *name; /* first: a kernel table of isa.h */
    tf_erosion_kernel *fn;
} kernels[] = {
#ifdef TF_EROSION_X86
    {"avx512", tf_erosion_kernel_avx512},
    {"avx2", tf_erosion_kernel_avx2},
#endif
    {"portable", tf_erosion_kernel_portable},
};
enum { KERNELS = sizeof kernels / sizeof kernels[0] };

static const char *forced = NULL; /* NULL: TF_EROSION_ISA decides */
static int forced_set = 0;

/* The best kernel this CPU runs, no better than the one forced (isa.h). */
static int chosen(void)
{
    const char *cap = forced_set ? forced : getenv("TF_EROSION_ISA");
    return tf_isa_choose(kernels, sizeof kernels[0], KERNELS, cap);
}

int tf_erosion_force_isa(const char *isa)
{
    if (isa && (tf_isa_find(kernels, sizeof kernels[0], KERNELS, isa) == KERNELS ||
                !tf_isa_runs(isa)))
        return -1;
    forced = isa;
    forced_set = isa != NULL;
    return 0;
}

void tf_erosion_force_portable(int portable)
{
    forced = portable > 0 ? "portable" : NULL;
    forced_set = portable >= 0;
}

const char *tf_erosion_isa(void) { return kernels[chosen()].name; }

int tf_erosion_step(const tf_erosion_model *m, const tf_erosion_view *v, tf_erosion_rect rect,
                    tf_erosion_rect own, int step, tf_erosion_tally *tally)
{
    return kernels[chosen()].fn(m, v, rect, own, tf_erosion_rain_now(m, step), tally);
}
