/* test_render_option.c: unit tests for coordinator/render/render_option.c, the one parser of
 * render's option values that the command line and the farm's submissions share, and for
 * frames.c's check of a range against a scene's frames. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include <string.h>

#include "coordinator/render/frames.h"
#include "coordinator/render/render_option.h"
#include "image/exrlayout.h"

static int set(tf_render_opts *o, const char *flag, const char *value, char *err, size_t n)
{
    err[0] = '\0';
    return tf_render_option_set(o, flag, value, err, n);
}

static void test_values_taken(void **state)
{
    (void)state;
    char err[512];
    tf_render_opts o;
    tf_render_opts_init(&o);
    assert_int_equal(set(&o, "--size", "64x36", err, sizeof err), 0);
    assert_int_equal(o.width, 64);
    assert_int_equal(o.height, 36);
    assert_int_equal(set(&o, "--lease-timeout", "1500ms", err, sizeof err), 0);
    assert_int_equal(o.lease_timeout_ms, 1500);
    assert_int_equal(set(&o, "--affinity", "off", err, sizeof err), 0);
    assert_int_equal(o.affinity, 0);
    assert_int_equal(set(&o, "--backend", "opencl", err, sizeof err), 0);
    assert_string_equal(o.backend, "opencl");
    assert_int_equal(set(&o, "--pixel", "float", err, sizeof err), 0);
    assert_int_equal(o.pixel, TF_PIXEL_FLOAT);
    assert_int_equal(o.pixel_given, 1);
    assert_int_equal(set(&o, "--verify", "0.25", err, sizeof err), 0);
    assert_true(o.verify_fraction == 0.25);
    assert_int_equal(set(&o, "--tasks", "rows:8", err, sizeof err), 0);
    assert_int_equal(o.tasks_given, 1);
    assert_int_equal(set(&o, "--watermark", "12", err, sizeof err), 0);
    assert_int_equal(o.watermark, 12);
    assert_int_equal(set(&o, "--frames", "2-8:3", err, sizeof err), 0);
    assert_int_equal(o.frames_given, 1);
    assert_int_equal(o.frame_first, 2);
    assert_int_equal(o.frame_last, 8);
    assert_int_equal(o.frame_step, 3);
    /* not a value this parser knows: left to its caller, err untouched */
    assert_int_equal(set(&o, "--output", "x.exr", err, sizeof err), 1);
    assert_string_equal(err, "");
}

static void test_values_refused(void **state)
{
    (void)state;
    static const struct {
        const char *flag, *value, *says;
    } bad[] = {
        {"--size", "0x36", "--size '0x36': expected WxH with sides from 1 to 65536"},
        {"--size", "64x65537", "--size '64x65537': expected WxH"},
        {"--lease-timeout", "999ms", "--lease-timeout '999ms': expected a duration from 1s"},
        {"--lease-timeout", "25h", "--lease-timeout '25h': expected a duration"},
        {"--affinity", "yes", "--affinity 'yes': expected on or off"},
        {"--backend", "cuda", "--backend 'cuda': expected c, opencl or auto"},
        {"--pixel", "8", "--pixel '8': expected half or float"},
        {"--verify", "1.5", "--verify '1.5': expected a fraction from 0 to 1"},
        {"--verify", "nan", "--verify 'nan': expected a fraction"},
        {"--tasks", "stamps:0x4", "--tasks 'stamps:0x4'"},
        {"--watermark", "0", "--watermark '0': expected an integer from 1 to"},
        {"--workers", "-1", "--workers '-1': expected an integer from 0 to 4096"},
        {"--wait-workers", "3x", "--wait-workers '3x': expected an integer"},
        {"--preview-interval", "99", "--preview-interval '99': expected an integer from 100"},
        {"--frame", "1-4", "--frame '1-4': expected one frame number"},
        {"--frames", "4-1", "--frames '4-1': the last frame is before the first"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        char err[512];
        tf_render_opts o;
        tf_render_opts_init(&o);
        if (set(&o, bad[i].flag, bad[i].value, err, sizeof err) != -1)
            fail_msg("%s %s accepted", bad[i].flag, bad[i].value);
        if (!strstr(err, bad[i].says))
            fail_msg("%s %s: \"%s\" does not say \"%s\"", bad[i].flag, bad[i].value, err,
                     bad[i].says);
        assert_null(strchr(err, '\n'));
    }
}

static void test_frames_once(void **state)
{
    (void)state;
    char err[512];
    tf_render_opts o;
    tf_render_opts_init(&o);
    assert_int_equal(set(&o, "--frame", "3", err, sizeof err), 0);
    assert_int_equal(set(&o, "--frames", "0-5", err, sizeof err), -1);
    assert_string_equal(err, "render: give --frames or --frame once");
    assert_int_equal(o.frame_first, 3); /* the first one stands */
}

static void test_range_fits_scene(void **state)
{
    (void)state;
    char err[512];
    tf_frame_range r = {0, 95, 1};
    assert_int_equal(tf_frame_range_fits(&r, 96, "flyby", err, sizeof err), 0);
    r.last = 96;
    assert_int_equal(tf_frame_range_fits(&r, 96, "flyby", err, sizeof err), -1);
    assert_string_equal(err, "--frame/--frames: flyby has frames 0..95; frame 96 is not one of "
                             "them");
    r = (tf_frame_range){0, 0, 1};
    assert_int_equal(tf_frame_range_fits(&r, 0, "default", err, sizeof err), -1);
    assert_non_null(strstr(err, "default has no [animation] section"));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_values_taken),
        cmocka_unit_test(test_values_refused),
        cmocka_unit_test(test_frames_once),
        cmocka_unit_test(test_range_fits_scene),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
