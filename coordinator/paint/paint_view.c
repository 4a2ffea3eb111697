/* paint_view.c: see paint_view.h. */
#include "coordinator/paint/paint_view.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"

void tf_paint_view_values_of(const tf_scene *s, tf_paint_view_values *v)
{
    const tf_vec3 *vec[3] = {&s->camera.position, &s->camera.look_at, &s->camera.up};
    double *out[3] = {v->position, v->look_at, v->up};
    for (int k = 0; k < 3; k++) {
        out[k][0] = vec[k]->x;
        out[k][1] = vec[k]->y;
        out[k][2] = vec[k]->z;
    }
    v->fov = s->camera.fov_deg;
    v->sun_azimuth = s->sun.azimuth_deg;
    v->sun_elevation = s->sun.elevation_deg;
    v->mist_enabled = s->mist.enabled;
    v->mist_density = s->mist.density;
    v->mist_falloff = s->mist.falloff;
}

static json_t *vec_json(const double *d)
{
    return json_pack("[f,f,f]", d[0], d[1], d[2]);
}

json_t *tf_paint_view_json(const tf_paint_view_values *v)
{
    return json_pack("{s:{s:o,s:o,s:o,s:f},s:{s:f,s:f},s:{s:b,s:f,s:f}}", "camera", "position",
                     vec_json(v->position), "look_at", vec_json(v->look_at), "up",
                     vec_json(v->up), "fov", v->fov, "sun", "azimuth", v->sun_azimuth,
                     "elevation", v->sun_elevation, "mist", "enabled", v->mist_enabled,
                     "density", v->mist_density, "falloff", v->mist_falloff);
}

/* A finite number at key of obj into *out (absent: unchanged).  0, or -1 with err. */
static int number(json_t *obj, const char *sect, const char *key, double *out, char *err,
                  size_t errlen)
{
    json_t *j = obj ? json_object_get(obj, key) : NULL;
    if (!j)
        return 0;
    if (!json_is_number(j) || !isfinite(json_number_value(j)))
        return tf_seterr(err, errlen, "%s.%s must be a finite number", sect, key);
    *out = json_number_value(j);
    return 0;
}

static int vec3(json_t *obj, const char *key, tf_vec3 *out, char *err, size_t errlen)
{
    json_t *j = obj ? json_object_get(obj, key) : NULL;
    if (!j)
        return 0;
    double d[3];
    for (size_t k = 0; k < 3; k++) {
        json_t *e = json_is_array(j) && json_array_size(j) == 3 ? json_array_get(j, k) : NULL;
        if (!e || !json_is_number(e) || !isfinite(json_number_value(e)))
            return tf_seterr(err, errlen, "camera.%s must be 3 finite numbers", key);
        d[k] = json_number_value(e);
    }
    *out = (tf_vec3){d[0], d[1], d[2]};
    return 0;
}

static int apply(tf_scene *s, json_t *doc, char *err, size_t errlen)
{
    json_t *cam = json_object_get(doc, "camera"), *sun = json_object_get(doc, "sun");
    json_t *mist = json_object_get(doc, "mist");
    if (!json_is_object(doc) || (cam && !json_is_object(cam)) || (sun && !json_is_object(sun)) ||
        (mist && !json_is_object(mist)))
        return tf_seterr(err, errlen, "a view is an object of camera, sun and mist objects");
    json_t *on = mist ? json_object_get(mist, "enabled") : NULL;
    if (on && !json_is_boolean(on))
        return tf_seterr(err, errlen, "mist.enabled must be true or false");
    if (on)
        s->mist.enabled = json_is_true(on);
    return vec3(cam, "position", &s->camera.position, err, errlen) ||
                   vec3(cam, "look_at", &s->camera.look_at, err, errlen) ||
                   vec3(cam, "up", &s->camera.up, err, errlen) ||
                   number(cam, "camera", "fov", &s->camera.fov_deg, err, errlen) ||
                   number(sun, "sun", "azimuth", &s->sun.azimuth_deg, err, errlen) ||
                   number(sun, "sun", "elevation", &s->sun.elevation_deg, err, errlen) ||
                   number(mist, "mist", "density", &s->mist.density, err, errlen) ||
                   number(mist, "mist", "falloff", &s->mist.falloff, err, errlen)
               ? -1
               : 0;
}

char *tf_paint_view_text(const tf_scene *base, json_t *doc, char *err, size_t errlen)
{
    tf_scene *s = tf_scene_at_frame(base, 0);
    char *text = NULL;
    if (!s) {
        tf_seterr(err, errlen, "out of memory");
        return NULL;
    }
    if (apply(s, doc, err, errlen) == 0 && !(text = tf_scene_canonical(s)))
        tf_seterr(err, errlen, "out of memory");
    tf_scene_free(s);
    char perr[512];
    tf_scene *check = text ? tf_scene_parse_text("view", text, strlen(text), perr, sizeof perr)
                           : NULL;
    if (text && !check) { /* a value out of its key's range: the parser says which */
        tf_seterr(err, errlen, "%s", perr);
        free(text);
        text = NULL;
    }
    tf_scene_free(check);
    return text;
}
