/* camera.c: pinhole and cylindrical panorama cameras; see camera.h. */
#include "render/camera.h"

#include <math.h>
#include <stdio.h>
#include "log.h"
#include "render/sample_math.h"

/* forward, right, up from position, look_at and the scene's up hint. */
static int build_basis(tf_camera *cam, const tf_scene *s, char *err, size_t errlen)
{
    tf_vec3 view = v3_sub(s->camera.look_at, s->camera.position);
    if (v3_len(view) <= 0) {
        tf_seterr(err, errlen, "camera: look_at equals position");
        return -1;
    }
    cam->forward = v3_norm(view);
    tf_vec3 right = v3_cross(cam->forward, s->camera.up);
    if (v3_len(right) < 1e-9 * v3_len(s->camera.up) || v3_len(s->camera.up) <= 0) {
        tf_seterr(err, errlen, "camera: up is zero or parallel to the view direction");
        return -1;
    }
    cam->right = v3_norm(right);
    cam->up = v3_cross(cam->right, cam->forward);
    return 0;
}

static int init_pinhole(tf_camera *cam, const tf_scene *s, char *err, size_t errlen)
{
    double fov = s->camera.fov_deg;
    if (!(fov > 0 && fov < 180)) {
        tf_seterr(err, errlen, "camera: pinhole fov_deg must be in (0, 180), got %g", fov);
        return -1;
    }
    cam->half_w = tan(0.5 * fov * TF_DEG2RAD);
    cam->half_h = cam->half_w * (double)cam->height / (double)cam->width;
    return 0;
}

/* The cylinder's axis is the scene's up hint (normalised), not the tilted camera up, so
 * vertical lines of the world stay vertical in the panorama (Musgrave rotates about "up"). */
static int init_panorama(tf_camera *cam, const tf_scene *s, char *err, size_t errlen)
{
    double sweep = s->camera.fov_deg, vfov = s->camera.vfov_deg;
    if (!(sweep > 0 && sweep <= 3600)) {
        tf_seterr(err, errlen, "camera: panorama fov_deg must be in (0, 3600], got %g", sweep);
        return -1;
    }
    if (!(vfov >= 0 && vfov < 180)) {
        tf_seterr(err, errlen, "camera: panorama vfov_deg must be in [0, 180), got %g", vfov);
        return -1;
    }
    cam->pano_up = v3_norm(s->camera.up);
    double rise = v3_dot(cam->forward, cam->pano_up);
    tf_vec3 level = v3_sub(cam->forward, v3_scale(cam->pano_up, rise));
    cam->pano_forward = v3_norm(level);
    cam->pano_right = v3_cross(cam->pano_forward, cam->pano_up);
    cam->sweep = sweep * TF_DEG2RAD;
    /* look_at direction on the unit cylinder: height = tan(elevation) = rise / |level| */
    cam->v_centre = rise / v3_len(level);
    if (vfov > 0)
        cam->v_half = tan(0.5 * vfov * TF_DEG2RAD);
    else /* square pixels at the centre line: one pixel is sweep/width radians = arc length */
        cam->v_half = 0.5 * cam->sweep * (double)cam->height / (double)cam->width;
    return 0;
}

int tf_camera_init(tf_camera *cam, const tf_scene *s, char *err, size_t errlen)
{
    *cam = (tf_camera){0};
    cam->kind = s->camera.kind;
    cam->width = s->width;
    cam->height = s->height;
    cam->position = s->camera.position;
    if (s->width <= 0 || s->height <= 0) {
        tf_seterr(err, errlen, "camera: image size %dx%d is empty", s->width, s->height);
        return -1;
    }
    if (build_basis(cam, s, err, errlen) != 0)
        return -1;
    if (cam->kind == TF_CAMERA_PANORAMA)
        return init_panorama(cam, s, err, errlen);
    return init_pinhole(cam, s, err, errlen);
}

/* The ray itself is sample_math.h's tf_camera_ray, which the OpenCL kernels share. */
tf_vec3 tf_camera_dir(const tf_camera *cam, double x, double y)
{
    return tf_camera_ray(cam, x, y);
}
