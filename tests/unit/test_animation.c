/* test_animation.c: unit tests for the [animation] section (common/animation.c and its keys in
 * common/scene_*.c): the camera and the sun pass through every key at its frame; the camera's
 * velocity is continuous across keys (one-sided difference quotients agree) and it never runs
 * backwards along its path; repeated key points are well defined; every bad key gives its
 * one-line "FILE:LINE: key: what is wrong"; the keys enter the canonical form and the hash
 * (and a still scene's canonical form has no [animation]); tf_scene_at_frame. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "scene.h"

#define STILL                                                                                      \
    "[image]\n"            /* 1 */                                                                 \
    "width = 64\n"         /* 2 */                                                                 \
    "height = 32\n"        /* 3 */                                                                 \
    "[terrain]\n"          /* 4 */                                                                 \
    "generator = fbm\n"    /* 5 */                                                                 \
    "seed = 5\n"           /* 6 */

/* A camera path with uneven spacing in space and in time, a turn, a climb and a fov change. */
#define ANIMATED                                                                                   \
    STILL                                                                                          \
    "[animation]\n"                                                        /* 7 */                 \
    "frames = 50\n"                                                        /* 8 */                 \
    "fps = 25\n"                                                           /* 9 */                 \
    "camera = 0 position 0 0 100 look_at 500 500 0\n"                      /* 10 */                \
    "camera = 7 position 40 10 110 look_at 520 560 5 fov 40\n"             /* 11 */                \
    "camera = 30 position 400 60 200 look_at 300 700 10 up 0.1 0 1\n"      /* 12 */                \
    "camera = 49 position 420 700 150 look_at 0 900 20\n"                  /* 13 */                \
    "sun = 0 azimuth 100 elevation 10\n"                                   /* 14 */                \
    "sun = 20 azimuth 140 elevation 40\n"                                  /* 15 */                \
    "sun = 49 azimuth 200 elevation 5\n"                                   /* 16 */

static tf_scene *parse(const char *text)
{
    char err[512] = "";
    tf_scene *s = tf_scene_parse_text("t.scene", text, strlen(text), err, sizeof err);
    if (!s)
        fail_msg("parse failed: %s", err);
    return s;
}

static void expect_error(const char *text, const char *prefix)
{
    char err[512] = "";
    tf_scene *s = tf_scene_parse_text("t.scene", text, strlen(text), err, sizeof err);
    if (s)
        fail_msg("parsed, expected error \"%s\"", prefix);
    if (strncmp(err, prefix, strlen(prefix)) != 0)
        fail_msg("got error \"%s\"\nexpected prefix \"%s\"", err, prefix);
    assert_null(strchr(err, '\n'));
}

static void assert_vec_near(tf_vec3 a, tf_vec3 b, double tol)
{
    if (fabs(a.x - b.x) > tol || fabs(a.y - b.y) > tol || fabs(a.z - b.z) > tol)
        fail_msg("(%.17g %.17g %.17g) != (%.17g %.17g %.17g)", a.x, a.y, a.z, b.x, b.y, b.z);
}

static void test_parses_and_resolves_defaults(void **state)
{
    (void)state;
    tf_scene *s = parse(ANIMATED);
    const tf_animation *a = &s->animation;
    assert_int_equal(a->frames, 50);
    assert_true(a->fps == 25);
    assert_int_equal(a->ncamera, 4);
    assert_int_equal(a->nsun, 3);
    assert_int_equal(a->camera[1].line, 11);
    /* fov and up not given in a key: [camera]'s (here its defaults, 60 and 0 0 1) */
    assert_true(a->camera[0].fov_deg == 60);
    assert_true(a->camera[1].fov_deg == 40);
    assert_vec_near(a->camera[2].up, v3(0.1, 0, 1), 0);
    assert_vec_near(a->camera[3].up, v3(0, 0, 1), 0);
    /* after parsing, the [camera] fields hold frame 0 */
    assert_vec_near(s->camera.position, v3(0, 0, 100), 1e-12);
    assert_true(s->sun.azimuth_deg == 100);
    tf_scene_free(s);
}

static void test_passes_through_every_key(void **state)
{
    (void)state;
    tf_scene *s = parse(ANIMATED);
    const tf_animation *a = &s->animation;
    for (int k = 0; k < a->ncamera; k++) {
        tf_vec3 pos, look, up;
        double fov;
        tf_animation_camera_at(a, a->camera[k].frame, &pos, &look, &up, &fov);
        assert_vec_near(pos, a->camera[k].position, 1e-9);
        assert_vec_near(look, a->camera[k].look_at, 1e-9);
        assert_vec_near(up, a->camera[k].up, 1e-12);
        assert_true(fabs(fov - a->camera[k].fov_deg) < 1e-12);
    }
    for (int k = 0; k < a->nsun; k++) {
        double az, el;
        tf_animation_sun_at(a, a->sun[k].frame, &az, &el);
        assert_true(fabs(az - a->sun[k].azimuth_deg) < 1e-12);
        assert_true(fabs(el - a->sun[k].elevation_deg) < 1e-12);
    }
    tf_scene_free(s);
}

static tf_vec3 position_at(const tf_animation *a, double f)
{
    tf_vec3 pos, look, up;
    double fov;
    tf_animation_camera_at(a, f, &pos, &look, &up, &fov);
    return pos;
}

static tf_vec3 look_at_at(const tf_animation *a, double f)
{
    tf_vec3 pos, look, up;
    double fov;
    tf_animation_camera_at(a, f, &pos, &look, &up, &fov);
    return look;
}

/* Velocity from the left and from the right of every interior key agree (to O(h)), and agree
 * with the velocity just inside each segment: no kink anywhere a key joins two segments. */
static void check_velocity_continuous(const tf_animation *a, tf_vec3 (*at)(const tf_animation *,
                                                                             double))
{
    const double h = 1e-5;
    for (int k = 1; k + 1 < a->ncamera; k++) {
        double f = a->camera[k].frame;
        tf_vec3 p = at(a, f);
        tf_vec3 left = v3_scale(v3_sub(p, at(a, f - h)), 1 / h);
        tf_vec3 right = v3_scale(v3_sub(at(a, f + h), p), 1 / h);
        double speed = v3_len(left) > v3_len(right) ? v3_len(left) : v3_len(right);
        double jump = v3_len(v3_sub(left, right));
        if (!(jump <= 1e-3 * (1 + speed)))
            fail_msg("key %d (frame %g): velocity jumps from (%g %g %g) to (%g %g %g)", k, f,
                     left.x, left.y, left.z, right.x, right.y, right.z);
    }
}

static void test_velocity_continuous(void **state)
{
    (void)state;
    tf_scene *s = parse(ANIMATED);
    check_velocity_continuous(&s->animation, position_at);
    check_velocity_continuous(&s->animation, look_at_at);
    tf_scene_free(s);
}

/* The camera never turns back along its path: between keys k and k+1 its distance along the
 * chord grows (a straight path with very uneven timing is the hard case for the timing map). */
static void test_never_runs_backwards(void **state)
{
    (void)state;
    tf_scene *s = parse(STILL "[animation]\nframes = 40\n"
                              "camera = 0 position 0 0 100 look_at 0 1000 0\n"
                              "camera = 2 position 0 300 100 look_at 0 1300 0\n"
                              "camera = 38 position 0 310 100 look_at 0 1310 0\n"
                              "camera = 39 position 0 900 100 look_at 0 1900 0\n");
    double last = -1e300;
    for (double f = 0; f <= 39; f += 0.125) {
        double y = position_at(&s->animation, f).y;
        if (!(y >= last))
            fail_msg("frame %g: y %.17g after %.17g", f, y, last);
        last = y;
    }
    tf_scene_free(s);
}

/* Keys at one point (a hovering camera that turns) stay finite and exact. */
static void test_repeated_points(void **state)
{
    (void)state;
    tf_scene *s = parse(STILL "[animation]\nframes = 10\n"
                              "camera = 0 position 5 5 50 look_at 100 0 0\n"
                              "camera = 4 position 5 5 50 look_at 0 100 0\n"
                              "camera = 9 position 5 5 50 look_at -100 0 0\n");
    for (double f = 0; f <= 9; f += 0.5) {
        tf_vec3 p = position_at(&s->animation, f);
        assert_vec_near(p, v3(5, 5, 50), 0);
        tf_vec3 l = look_at_at(&s->animation, f);
        assert_true(isfinite(l.x) && isfinite(l.y) && isfinite(l.z));
    }
    tf_scene_free(s);
}

static void test_continuation_lines_and_canonical(void **state)
{
    (void)state;
    tf_scene *a = parse(STILL "[animation]\nframes = 3\n"
                              "camera = 0 position 0 0 100\n"
                              "    look_at 500, 500, 0 ; a comment\n"
                              "camera = 2 position 10 0 100 look_at 510 500 0\n");
    tf_scene *b = parse(STILL "[animation]\nframes = 3\nfps = 24\n"
                              "camera = 0 position 0 0 100 look_at 500 500 0 fov 60 up 0 0 1\n"
                              "camera = 2 position 10 0 100 look_at 510 500 0\n");
    assert_string_equal(a->hash_hex, b->hash_hex);
    char *c = tf_scene_canonical(a);
    assert_non_null(strstr(c, "[animation]"));
    assert_null(strstr(c, "position = ")); /* the animated camera has no [camera] position */
    tf_scene *r = parse(c);
    assert_string_equal(r->hash_hex, a->hash_hex);
    free(c);
    /* any key's change changes the hash */
    tf_scene *d = parse(STILL "[animation]\nframes = 3\n"
                              "camera = 0 position 0 0 100 look_at 500 500 0\n"
                              "camera = 2 position 10 0 100.5 look_at 510 500 0\n");
    assert_string_not_equal(d->hash_hex, a->hash_hex);
    tf_scene *e = parse(STILL "[animation]\nframes = 3\nfps = 30\n"
                              "camera = 0 position 0 0 100 look_at 500 500 0\n"
                              "camera = 2 position 10 0 100 look_at 510 500 0\n");
    assert_string_not_equal(e->hash_hex, a->hash_hex);
    tf_scene_free(a);
    tf_scene_free(b);
    tf_scene_free(r);
    tf_scene_free(d);
    tf_scene_free(e);
    /* a still scene's canonical form has no [animation] (so its hash is what it always was) */
    tf_scene *still = parse(STILL "[camera]\nposition = 0 0 10\nlook_at = 1 1 0\n");
    c = tf_scene_canonical(still);
    assert_null(strstr(c, "[animation]"));
    free(c);
    tf_scene_free(still);
}

static void test_scene_at_frame(void **state)
{
    (void)state;
    tf_scene *s = parse(ANIMATED);
    tf_scene *f = tf_scene_at_frame(s, 30);
    assert_non_null(f);
    assert_vec_near(f->camera.position, v3(400, 60, 200), 1e-9);
    assert_string_equal(f->hash_hex, s->hash_hex); /* a frame belongs to its sequence */
    assert_vec_near(s->camera.position, v3(0, 0, 100), 1e-12); /* s itself unchanged */
    double az, el;
    tf_animation_sun_at(&s->animation, 30, &az, &el);
    assert_true(f->sun.azimuth_deg == az && f->sun.elevation_deg == el);
    tf_scene_free(f);
    tf_scene_free(s);
}

#define CAM0 "camera = 0 position 0 0 100 look_at 500 500 0\n"

static void test_bad_keys(void **state)
{
    (void)state;
    expect_error(STILL "[animation]\n" CAM0, "t.scene:7: frames: missing required key in [animation]");
    expect_error(STILL "[animation]\nframes = 0\n", "t.scene:8: frames: 0 is out of range");
    expect_error(STILL "[animation]\nframes = 5\n" CAM0,
                 "t.scene:9: camera: only one key; a path needs at least 2 keys");
    expect_error(STILL "[animation]\nframes = 5\n" CAM0
                 "camera = 4 position 1 0 100 look_at 5 5 0\n"
                 "camera = 3 position 2 0 100 look_at 5 5 0\n",
                 "t.scene:11: camera: key at frame 3 is not after the previous key's frame 4 "
                 "(line 10): keys must be in increasing frame order");
    expect_error(STILL "[animation]\nframes = 5\n"
                 "camera = 1 position 1 0 100 look_at 5 5 0\n"
                 "camera = 4 position 2 0 100 look_at 5 5 0\n",
                 "t.scene:9: camera: the first key is at frame 1; it must be at frame 0");
    expect_error(STILL "[animation]\nframes = 5\n" CAM0
                 "camera = 3 position 2 0 100 look_at 5 5 0\n",
                 "t.scene:10: camera: the last key is at frame 3, before the last frame 4 "
                 "(frames = 5)");
    expect_error(STILL "[animation]\nframes = 5\ncamera = 0 position 0 0 100\n",
                 "t.scene:9: camera: the key at frame 0 needs a look_at");
    expect_error(STILL "[animation]\nframes = 5\ncamera = 0 look_at 0 0 100\n",
                 "t.scene:9: camera: the key at frame 0 needs a position");
    expect_error(STILL "[animation]\nframes = 5\ncamera = 0 position 0 0 100 position 1 1 1\n",
                 "t.scene:9: camera: position given twice in the key at frame 0");
    expect_error(STILL "[animation]\nframes = 5\ncamera = 0 pos 0 0 100\n",
                 "t.scene:9: camera: expected position, look_at, fov or up in the key at frame "
                 "0, got \"pos\"");
    expect_error(STILL "[animation]\nframes = 5\ncamera = 0 position 0 0\n",
                 "t.scene:9: camera: position needs 3 numbers \"x y z\" in the key at frame 0");
    expect_error(STILL "[animation]\nframes = 5\ncamera = 0.5 position 0 0 1\n",
                 "t.scene:9: camera: a key starts with its frame number (an integer), got \"0.5\"");
    expect_error(STILL "[animation]\nframes = 5\ncamera = position 0 0 1\n",
                 "t.scene:9: camera: a key starts with its frame number");
    expect_error(STILL "[animation]\nframes = 5\ncamera = 0 position 0 0 1 fov 0\n",
                 "t.scene:9: camera: fov 0 is out of range above 0..360 in the key at frame 0");
    expect_error(STILL "[animation]\nframes = 5\ncamera = 0 position 0 0 nan\n",
                 "t.scene:9: camera: NaN and infinity are not allowed");
    expect_error(STILL "[animation]\nframes = 5\ncamera =\n", "t.scene:9: camera: missing value");
    /* a static [camera] position beside camera keys */
    expect_error(STILL "[camera]\nposition = 0 0 10\n[animation]\nframes = 2\n" CAM0
                 "camera = 1 position 1 0 100 look_at 5 5 0\n",
                 "t.scene:8: position: the camera is animated by [animation] camera keys; give "
                 "position in those keys instead");
    /* paths that pass through each other, a camera looking along up, an interpolated fov */
    expect_error(STILL "[animation]\nframes = 3\n"
                 "camera = 0 position 0 0 100 look_at 100 0 100\n"
                 "camera = 2 position 100 0 100 look_at 0 0 100\n",
                 "t.scene:9: camera: at frame 1 look_at meets position");
    expect_error(STILL "[animation]\nframes = 3\n" CAM0
                 "camera = 2 position 0 0 100 look_at 0 0 0\n",
                 "t.scene:10: camera: at frame 2 up is zero or parallel to the view direction");
    expect_error(STILL "[animation]\nframes = 30\n"
                 "camera = 0 position 0 0 100 look_at 500 500 0 fov 10\n"
                 "camera = 10 position 1 0 100 look_at 500 500 0 fov 179\n"
                 "camera = 20 position 2 0 100 look_at 500 500 0 fov 179\n"
                 "camera = 29 position 3 0 100 look_at 500 500 0 fov 10\n",
                 "t.scene:10: camera: at frame 11 the interpolated fov");
    /* sun keys */
    expect_error(STILL "[camera]\nposition = 0 0 10\nlook_at = 1 1 0\n[animation]\nframes = 5\n"
                 "sun = 0 azimuth 10\nsun = 4 azimuth 10 elevation 5\n",
                 "t.scene:12: sun: the key at frame 0 needs an elevation");
    expect_error(STILL "[camera]\nposition = 0 0 10\nlook_at = 1 1 0\n[animation]\nframes = 5\n"
                 "sun = 0 azimuth 10 elevation 91\n",
                 "t.scene:12: sun: elevation 91 is out of range -90..90 in the key at frame 0");
    expect_error(STILL "[camera]\nposition = 0 0 10\nlook_at = 1 1 0\n[sun]\nelevation = 3\n"
                 "[animation]\nframes = 5\n"
                 "sun = 0 azimuth 10 elevation 5\nsun = 4 azimuth 10 elevation 5\n",
                 "t.scene:11: elevation: the sun is animated by [animation] sun keys");
    expect_error(STILL "[camera]\nposition = 0 0 10\nlook_at = 1 1 0\n[animation]\nframes = 41\n"
                 "sun = 0 azimuth 0 elevation 0\nsun = 20 azimuth 0 elevation 89\n"
                 "sun = 40 azimuth 0 elevation 89\n",
                 "t.scene:13: sun: at frame 21 the interpolated elevation");
    /* without camera keys the [camera] is still required */
    expect_error(STILL "[animation]\nframes = 5\n",
                 "t.scene:0: position: missing required key (no [camera] section)");
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_parses_and_resolves_defaults),
        cmocka_unit_test(test_passes_through_every_key),
        cmocka_unit_test(test_velocity_continuous),
        cmocka_unit_test(test_never_runs_backwards),
        cmocka_unit_test(test_repeated_points),
        cmocka_unit_test(test_continuation_lines_and_canonical),
        cmocka_unit_test(test_scene_at_frame),
        cmocka_unit_test(test_bad_keys),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
