/* erosion_film.h: an erosion film ([animation] erosion_steps = n, Musgrave 2.4.4): a sequence
 * whose frame k shows the terrain after k * n steps of the scene's [erosion], each frame a still
 * rendered by the farm (forked and networked workers, as any render) while a forked eroder
 * works ahead on the next frames' terrain, each continuing from the last (exact, through the
 * erosion cache's checkpoints).  --resume skips complete frames; --movie is not offered. */
#ifndef TF_EROSION_FILM_H
#define TF_EROSION_FILM_H

#include "coordinator/render/coordinator.h"
#include "scene.h"

/* Render the film s (taken over, freed) with options o.  The exit status. */
int tf_erosion_film_run(const tf_render_opts *o, tf_scene *s);

#endif
