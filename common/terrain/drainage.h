/* drainage.h: what erosion did to a height field, measured: the number of pits (interior
 * vertices lower than all 8 neighbours, where water cannot leave) and the share of the area
 * that drains into the largest basin (every vertex follows its steepest downhill neighbour, of
 * 8, until a pit or the grid's edge; a basin is every vertex that ends at one place). */
#ifndef TF_DRAINAGE_H
#define TF_DRAINAGE_H

#include <stdint.h>

typedef struct tf_drainage {
    int64_t pits;
    double largest_basin_share; /* of all n * n vertices */
} tf_drainage;

/* 0, or -1 on out of memory. */
int tf_drainage_measure(const float *h, int n, tf_drainage *out);

#endif
