/* camera.h: primary rays.  Two projections (docs/contract.md section 4):
 *
 *   pinhole   a flat virtual screen perpendicular to the view direction; horizontal field of
 *             view fov_deg, square pixels.
 *   panorama  Musgrave's cylindrical virtual screen (dissertation, Appendix B): the horizontal
 *             angle is linear across the image over fov_deg (any sweep, even > 360 degrees);
 *             the vertical position on the unit cylinder is linear in y over vfov_deg, or, when
 *             vfov_deg = 0, chosen so pixels are square at the image's horizontal centre line.
 *             The window is shifted vertically so the image centre looks at look_at.
 *
 * Image coordinates are continuous: pixel (px, py) covers [px, px+1) x [py, py+1), y grows
 * downwards, so (width/2, height/2) is the image centre.  tf_camera_dir is a pure function of
 * the camera and (x, y): the renderer relies on that for the decomposition invariant. */
#ifndef TF_CAMERA_H
#define TF_CAMERA_H

#include <stddef.h>
#include "scene.h"
#include "vec.h"

typedef struct tf_camera {
    enum tf_camera_kind kind;
    int width, height;
    tf_vec3 position;
    tf_vec3 forward, right, up; /* orthonormal; right = forward x up */
    /* pinhole: half extents of the virtual screen at distance 1 */
    double half_w, half_h;
    /* panorama: horizontal forward (forward with its up component removed), its right, the
     * world up; sweep in radians; vertical window centre and half height on the cylinder */
    tf_vec3 pano_forward, pano_right, pano_up;
    double sweep, v_centre, v_half;
} tf_camera;

/* Build the camera of scene s.  Returns 0, or -1 with one line in err (degenerate basis,
 * field of view out of range, empty image). */
int tf_camera_init(tf_camera *cam, const tf_scene *s, char *err, size_t errlen);

/* Unit direction of the primary ray through image point (x, y). */
tf_vec3 tf_camera_dir(const tf_camera *cam, double x, double y);

#endif
