/* sun_strips.h: the terrain seen along the sun's heading, so that a shadow ray stops its walk
 * where it is proved above the surface for good (render/sun_math.h explains the bound and the
 * query; issue 23).
 *
 * A lit shadow ray used to walk the max/min hierarchy all the way out of the terrain's box,
 * climbing a level at a time: 18 steps and 220 ns on default.scene.  All shadow rays go one
 * way, so one table answers for all of them: per strip along the sun's heading and per bin of
 * it, how high the surface reaches from there on, less what a ray climbs meanwhile.  A shadow
 * ray reads a few entries ahead of its start and then walks only up to the first bin it is
 * proved to clear, with tf_occluded's tmax moved in: the same answer from a short walk (a
 * lit ray: 220 -> ~135 ns).  Each bin also keeps the most a ray may start at and still be
 * under the surface in some bin further on: one comparison proves a ray occluded, no walk at
 * all, whether the occluder is in the next bin or hundreds of cells off (two thirds of the
 * occluded rays on default.scene). */
#ifndef TF_SUN_STRIPS_H
#define TF_SUN_STRIPS_H

#include "render/sun_math.h"
#include "render/trace.h" /* tf_shadow_clear */
#include "terrain/heightfield.h"
#include "vec.h"

typedef struct tf_sun_strips {
    tf_sun_frame frame;
    float *table;    /* frame.strips * frame.bins bins of TF_SUN_BIN floats (reach, sink) */
    const float *h;  /* the height field's heights (the under proof's start) */
    tf_vec3 sun;     /* the shadow rays' direction */
} tf_sun_strips;

/* The strips of height field hf for shadow rays of direction sun (the shader's sun_dir), or
 * NULL where none help: a procedural terrain, a sun at or below the horizon or overhead, no
 * memory. */
tf_sun_strips *tf_sun_strips_build(const tf_heightfield *hf, tf_vec3 sun);
/* The same table built on `threads` threads (0: all online CPUs), each a range of strips. */
tf_sun_strips *tf_sun_strips_build_threads(const tf_heightfield *hf, tf_vec3 sun, int threads);
void tf_sun_strips_free(tf_sun_strips *s);

/* Strips kept with the terrain.  A process that builds a height field and then forks the
 * renderers (a render's coordinator, `terrafarm worker -j N`) builds them once, on all its
 * cores, before the fork: tf_sun_strips_keep puts them in hf->derived (freed with hf); 0, or
 * -1 where none help or hf keeps something already.  tf_sun_strips_kept gives them to a
 * renderer of hf whose sun is exactly `sun`, else NULL (it builds its own). */
int tf_sun_strips_keep(tf_heightfield *hf, tf_vec3 sun, int threads);
const tf_sun_strips *tf_sun_strips_kept(const tf_heightfield *hf, tf_vec3 sun);
/* Bytes of the strips kept with hf, whatever their sun (0: none). */
size_t tf_sun_strips_kept_bytes(const tf_heightfield *hf);

/* tf_sun_strips_say for a shadow ray of the strips' sun from o (TF_SUN_UNKNOWN where s is
 * NULL): TF_SUN_CLEAR_AFTER, *t a tmax for tf_occluded that gives its answer over
 * (0, TF_FAR_AWAY); TF_SUN_UNDER, the ray is occluded (*t 0: no point named). */
int tf_sun_strips_shadow(const tf_sun_strips *s, tf_vec3 o, double *t);

/* The record (trace.h's coherence) of the shadow ray from o that the strips proved under: its
 * point under the surface is named only when a neighbour's ray asks (tf_sun_strips_named),
 * which is rare -- the neighbours of an occluded ray are nearly all proved occluded too
 * (default.scene: 3 345 of 206 779), and naming is a search along the strip. */
tf_shadow_clear tf_sun_strips_under_record(const tf_sun_strips *s, tf_vec3 o);

/* near itself, or where it is a tf_sun_strips_under_record, *named: a copy with the point
 * named (t_under 0 where the strips no longer prove it: another sun's record), for
 * tf_occluded_coherent. */
const tf_shadow_clear *tf_sun_strips_named(const tf_sun_strips *s, const tf_shadow_clear *near,
                                           tf_shadow_clear *named);

/* Bytes of the table (what the OpenCL kernels get), and all bytes held (the memory
 * comparisons). */
size_t tf_sun_strips_table_bytes(const tf_sun_strips *s);
size_t tf_sun_strips_bytes(const tf_sun_strips *s);

#endif
