/* isa.h: which build of a SIMD kernel this CPU runs.  A kernel family (the packet tracer, the
 * erosion step) is a table of builds, best first, each entry beginning with its instruction
 * set's name: "avx512" (F, BW, VL, DQ), "avx2", and last "portable", which every CPU runs.  The
 * family's kernel is the best build the CPU runs, no better than a cap: a name from the
 * environment (TF_TRACE_ISA, TF_EROSION_ISA) or one a test forces. */
#ifndef TF_ISA_H
#define TF_ISA_H

#include <stddef.h>

/* Does this CPU run code built for the named instruction set?  An unknown name: no. */
int tf_isa_runs(const char *name);
/* In a table of n entries of `size` bytes, each beginning with a `const char *` name: the index
 * of the entry named `name`, or n. */
int tf_isa_find(const void *table, size_t size, int n, const char *name);
/* The index of the best entry this CPU runs, no better than the one named cap (NULL, or a name
 * not in the table: no cap).  The table's last entry must be one every CPU runs. */
int tf_isa_choose(const void *table, size_t size, int n, const char *cap);

#endif
