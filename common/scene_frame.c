/* scene_frame.c: the scene of one frame of an [animation] (scene.h): its camera and sun from
 * the splines of animation.c.  It sits on the scene's side, so the dependency runs one way:
 * the scene uses the animation, never the reverse. */
#include "scene.h"

#include <stdlib.h>
#include <string.h>

void tf_scene_apply_frame(tf_scene *s, int f)
{
    const tf_animation *a = &s->animation;
    if (a->ncamera >= 2)
        tf_animation_camera_at(a, f, &s->camera.position, &s->camera.look_at, &s->camera.up,
                               &s->camera.fov_deg);
    if (a->nsun >= 2)
        tf_animation_sun_at(a, f, &s->sun.azimuth_deg, &s->sun.elevation_deg);
}

tf_scene *tf_scene_at_frame(const tf_scene *s, int f)
{
    tf_scene *c = malloc(sizeof *c);
    if (!c)
        return NULL;
    memcpy(c, s, sizeof *c);
    /* A height map (generator = file) stays s's: the copy borrows it through terrain.file_bytes
     * and never frees it, so s must outlive the copy (a frame's renderer needs only the
     * terrain already built from it). */
    c->heightmap = NULL;
    c->heightmap_len = 0;
    c->heightmap_name = NULL;
    c->eroded = NULL; /* borrowed the same way (terrain.eroded_bytes) */
    c->eroded_len = 0;
    c->eroded_from = NULL;
    c->path = strdup(s->path ? s->path : "<string>");
    c->text = malloc(s->text_len + 1);
    if (!c->path || !c->text) {
        free(c->path);
        free(c->text);
        free(c);
        return NULL;
    }
    memcpy(c->text, s->text, s->text_len);
    c->text[s->text_len] = '\0';
    tf_scene_apply_frame(c, f);
    return c;
}

void tf_scene_set_view(tf_scene *s, const tf_scene *view)
{
    s->camera = view->camera;
    s->sun = view->sun;
    s->mist = view->mist;
}
