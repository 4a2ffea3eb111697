/* test_camera.c: the pinhole and panorama cameras (common/render/camera.c): centre ray along look_at,
 * field-of-view edges, y down, panorama sweep linear in angle, vertical window, bad input. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <cmocka.h>
#include <math.h>
#include <string.h>

#include "render/camera.h"

#define DEG (3.14159265358979323846 / 180.0)

static tf_scene base_scene(enum tf_camera_kind kind, double fov, double vfov)
{
    tf_scene s;
    memset(&s, 0, sizeof s);
    s.width = 200;
    s.height = 100;
    s.camera.kind = kind;
    s.camera.position = v3(10, 20, 30);
    s.camera.look_at = v3(10, 120, 30); /* looking north, level */
    s.camera.up = v3(0, 0, 1);
    s.camera.fov_deg = fov;
    s.camera.vfov_deg = vfov;
    return s;
}

static void assert_vec_near(tf_vec3 a, tf_vec3 b, double tol)
{
    assert_true(fabs(a.x - b.x) < tol);
    assert_true(fabs(a.y - b.y) < tol);
    assert_true(fabs(a.z - b.z) < tol);
}

/* Signed horizontal angle of d from the camera's level forward, positive to the right. */
static double yaw(const tf_camera *c, tf_vec3 d)
{
    return atan2(v3_dot(d, c->pano_right), v3_dot(d, c->pano_forward));
}

static void test_pinhole_centre_ray_is_look_at(void **state)
{
    (void)state;
    tf_scene s = base_scene(TF_CAMERA_PINHOLE, 60, 0);
    s.camera.look_at = v3(40, 70, 5); /* oblique, tilted down */
    tf_camera c;
    char err[128];
    assert_int_equal(tf_camera_init(&c, &s, err, sizeof err), 0);
    tf_vec3 want = v3_norm(v3_sub(s.camera.look_at, s.camera.position));
    assert_vec_near(tf_camera_dir(&c, 100, 50), want, 1e-12);
    assert_true(fabs(v3_len(tf_camera_dir(&c, 3.7, 91.2)) - 1.0) < 1e-12);
}

static void test_pinhole_edges_at_half_fov_and_y_down(void **state)
{
    (void)state;
    tf_scene s = base_scene(TF_CAMERA_PINHOLE, 70, 0);
    tf_camera c;
    char err[128];
    assert_int_equal(tf_camera_init(&c, &s, err, sizeof err), 0);
    tf_vec3 left = tf_camera_dir(&c, 0, 50), right = tf_camera_dir(&c, 200, 50);
    assert_true(fabs(acos(left.y) - 35 * DEG) < 1e-9);  /* forward is +y */
    assert_true(fabs(acos(right.y) - 35 * DEG) < 1e-9);
    assert_true(left.x < 0 && right.x > 0);  /* looking north, east is to the right */
    /* square pixels: vertical half-angle from the aspect; top of the image looks up */
    tf_vec3 top = tf_camera_dir(&c, 100, 0), bottom = tf_camera_dir(&c, 100, 100);
    assert_true(top.z > 0 && bottom.z < 0);
    assert_true(fabs(top.z / top.y - tan(35 * DEG) * 0.5) < 1e-12);
}

static void test_panorama_edges_at_half_sweep(void **state)
{
    (void)state;
    tf_scene s = base_scene(TF_CAMERA_PANORAMA, 240, 60);
    tf_camera c;
    char err[128];
    assert_int_equal(tf_camera_init(&c, &s, err, sizeof err), 0);
    assert_true(fabs(yaw(&c, tf_camera_dir(&c, 0, 50)) + 120 * DEG) < 1e-9);
    assert_true(fabs(yaw(&c, tf_camera_dir(&c, 200, 50)) - 120 * DEG) < 1e-9);
    /* linear in angle across the image: a quarter of the way is a quarter of the sweep */
    assert_true(fabs(yaw(&c, tf_camera_dir(&c, 50, 50)) + 60 * DEG) < 1e-9);
    assert_true(fabs(yaw(&c, tf_camera_dir(&c, 125, 50)) - 30 * DEG) < 1e-9);
    /* centre row is the horizon; top and bottom at +-vfov/2 */
    tf_vec3 top = tf_camera_dir(&c, 30, 0), bottom = tf_camera_dir(&c, 30, 100);
    assert_true(fabs(tf_camera_dir(&c, 77, 50).z) < 1e-12);
    assert_true(fabs(asin(top.z) - 30 * DEG) < 1e-9);
    assert_true(fabs(asin(bottom.z) + 30 * DEG) < 1e-9);
    /* vertical position on the cylinder is linear in y: height at y = 25 is half of the top's */
    tf_vec3 q = tf_camera_dir(&c, 30, 25);
    double h_top = top.z / sqrt(1 - top.z * top.z), h_q = q.z / sqrt(1 - q.z * q.z);
    assert_true(fabs(h_q - 0.5 * h_top) < 1e-12);
}

static void test_panorama_vfov_from_aspect_and_tilt(void **state)
{
    (void)state;
    tf_scene s = base_scene(TF_CAMERA_PANORAMA, 360, 0);
    tf_camera c;
    char err[128];
    assert_int_equal(tf_camera_init(&c, &s, err, sizeof err), 0);
    /* square pixels at the horizon: a pixel is 360/200 degrees wide, so the top sits at
     * height 50 pixels * (2 pi / 200) on the unit cylinder */
    tf_vec3 top = tf_camera_dir(&c, 100, 0);
    double h = top.z / sqrt(1 - top.z * top.z);
    assert_true(fabs(h - 50 * (2 * 3.14159265358979323846 / 200)) < 1e-12);
    /* a tilted look_at stays the centre of the image, and the cylinder stays upright */
    s.camera.look_at = v3(10, 120, 80);
    assert_int_equal(tf_camera_init(&c, &s, err, sizeof err), 0);
    tf_vec3 want = v3_norm(v3_sub(s.camera.look_at, s.camera.position));
    assert_vec_near(tf_camera_dir(&c, 100, 50), want, 1e-12);
    assert_true(fabs(tf_camera_dir(&c, 0, 50).z - tf_camera_dir(&c, 200, 50).z) < 1e-12);
}

static void test_bad_cameras_rejected(void **state)
{
    (void)state;
    tf_camera c;
    char err[128];
    tf_scene s = base_scene(TF_CAMERA_PINHOLE, 180, 0);
    assert_int_equal(tf_camera_init(&c, &s, err, sizeof err), -1);
    assert_non_null(strstr(err, "fov"));
    s = base_scene(TF_CAMERA_PINHOLE, 60, 0);
    s.camera.up = v3(0, 5, 0); /* parallel to the view */
    assert_int_equal(tf_camera_init(&c, &s, err, sizeof err), -1);
    assert_non_null(strstr(err, "up"));
    s = base_scene(TF_CAMERA_PINHOLE, 60, 0);
    s.camera.look_at = s.camera.position;
    assert_int_equal(tf_camera_init(&c, &s, err, sizeof err), -1);
    s = base_scene(TF_CAMERA_PANORAMA, 360, 180);
    assert_int_equal(tf_camera_init(&c, &s, err, sizeof err), -1);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_pinhole_centre_ray_is_look_at),
        cmocka_unit_test(test_pinhole_edges_at_half_fov_and_y_down),
        cmocka_unit_test(test_panorama_edges_at_half_sweep),
        cmocka_unit_test(test_panorama_vfov_from_aspect_and_tilt),
        cmocka_unit_test(test_bad_cameras_rejected),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
