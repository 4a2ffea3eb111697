/* counts.h: what a render of a rectangle cost, in rays.  Its own header so that the farm's
 * tuples and the statistics can carry the counts without including the renderer. */
#ifndef TF_RENDER_COUNTS_H
#define TF_RENDER_COUNTS_H

#include <stdint.h>

typedef struct tf_render_counts {
    uint64_t primary_rays;   /* camera rays traced (including external samples) */
    uint64_t shadow_rays;    /* rays towards the sun */
    uint64_t external_rays;  /* camera rays for samples outside the rectangle's own pixels */
    uint64_t pixels;
    /* a procedural terrain's tile cache (terrain/tilecache.h), what this render cost it */
    uint64_t terrain_samples;   /* height samples evaluated */
    uint64_t terrain_hits;      /* tile reads that found their tile */
    uint64_t terrain_evictions; /* tiles dropped for the budget */
} tf_render_counts;

#endif
