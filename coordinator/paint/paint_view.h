/* paint_view.h: what the page may change of a scene -- the camera (position, look_at, up,
 * field of view), the sun (azimuth, elevation) and the mist (on, density, falloff) -- as
 * plain values and as JSON, and a view's scene text made from them (checked by parsing it,
 * so a value out of a key's range is refused with the parser's own one-line message). */
#ifndef TF_PAINT_VIEW_H
#define TF_PAINT_VIEW_H

#include <jansson.h>
#include <stddef.h>

#include "coordinator/paint/paint_hub.h"
#include "scene.h"

void tf_paint_view_values_of(const tf_scene *s, tf_paint_view_values *v);
json_t *tf_paint_view_json(const tf_paint_view_values *v);
/* The values in doc (any of "camera": {"position", "look_at", "up", "fov"}, "sun":
 * {"azimuth", "elevation"}, "mist": {"enabled", "density", "falloff"}) over base's: the new
 * view's scene text (malloc'd), or NULL with a one-line reason. */
char *tf_paint_view_text(const tf_scene *base, json_t *doc, char *err, size_t errlen);

#endif
