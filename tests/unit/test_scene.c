/* test_scene.c: unit tests for the scene parser (common/scene*.c): the exact one-line error for
 * every kind of bad input, defaults, vector syntax, the canonical form and hash (unchanged by
 * comments, spacing, key order and spelled-out defaults; changed by any field and by
 * tf_scene_set_size), tf_scene_parse_text == tf_scene_load, and every scenes/NAME.scene parsing. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include <dirent.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "scene.h"

/* A minimal valid scene: only the required keys. */
#define MINIMAL                                                                                    \
    "[image]\n"            /* 1 */                                                                 \
    "width = 64\n"         /* 2 */                                                                 \
    "height = 32\n"        /* 3 */                                                                 \
    "[camera]\n"           /* 4 */                                                                 \
    "position = 0 0 10\n"  /* 5 */                                                                 \
    "look_at = 100 100 0\n" /* 6 */                                                                \
    "[terrain]\n"          /* 7 */                                                                 \
    "generator = fbm\n"    /* 8 */                                                                 \
    "seed = 5\n"           /* 9 */

static tf_scene *parse(const char *text, char *err, size_t errlen)
{
    return tf_scene_parse_text("t.scene", text, strlen(text), err, errlen);
}

/* Parse text that must fail, and check the message starts with `prefix` and is one line. */
static void expect_error(const char *text, size_t len, const char *prefix)
{
    char err[512] = "";
    tf_scene *s = tf_scene_parse_text("t.scene", text, len, err, sizeof err);
    if (s)
        fail_msg("parsed, expected error \"%s\"", prefix);
    if (strncmp(err, prefix, strlen(prefix)) != 0)
        fail_msg("got error \"%s\"\nexpected prefix \"%s\"", err, prefix);
    assert_null(strchr(err, '\n'));
}

static void expect_error_text(const char *text, const char *prefix)
{
    expect_error(text, strlen(text), prefix);
}

static void test_error_unknown_section(void **state)
{
    (void)state;
    expect_error_text(MINIMAL "[weather]\n", "t.scene:10: [weather]: unknown section");
    expect_error_text(MINIMAL "[image\n", "t.scene:10: syntax: section header without");
    expect_error_text(MINIMAL "[sun] x\n", "t.scene:10: syntax: unexpected \"x\" after");
    expect_error_text(MINIMAL "[image]\n", "t.scene:10: [image]: duplicate section (first on line 1)");
}

static void test_error_unknown_key(void **state)
{
    (void)state;
    expect_error_text(MINIMAL "colour = 1\n", "t.scene:10: colour: unknown key in [terrain]");
    expect_error_text("width = 3\n" MINIMAL, "t.scene:1: width: key outside of any section");
}

static void test_error_duplicate_key(void **state)
{
    (void)state;
    expect_error_text(MINIMAL "seed = 6\n", "t.scene:10: seed: duplicate key (first set on line 9)");
    /* keys are case-insensitive, so different spellings are still duplicates */
    expect_error_text(MINIMAL "h = 0.5\nH = 0.5\n", "t.scene:11: H: duplicate key");
}

static void test_error_missing_required(void **state)
{
    (void)state;
    /* section present: blame its header line */
    expect_error_text("[image]\nwidth = 4\n[camera]\n", "t.scene:1: height: missing required key in [image]");
    /* section absent: line 0 */
    expect_error_text("[image]\nwidth = 4\nheight = 4\n",
                      "t.scene:0: position: missing required key (no [camera] section)");
    expect_error_text("", "t.scene:0: width: missing required key (no [image] section)");
    expect_error_text("[image]\nwidth=1\nheight=1\n[camera]\nposition=0 0 1\nlook_at=1 0 0\n"
                      "[terrain]\ngenerator = ridged\n",
                      "t.scene:7: seed: missing required key in [terrain]");
}

static void test_error_wrong_type(void **state)
{
    (void)state;
    expect_error_text(MINIMAL "size_exp = 9.5\n", "t.scene:10: size_exp: expected an integer, got \"9.5\"");
    expect_error_text(MINIMAL "extent = big\n", "t.scene:10: extent: expected a number, got \"big\"");
    expect_error_text(MINIMAL "H =\n", "t.scene:10: H: missing value");
    expect_error_text(MINIMAL "[mist]\nenabled = maybe\n", "t.scene:11: enabled: unknown value \"maybe\"");
    /* [erosion]: its keys' ranges, and a grid to erode */
    expect_error_text(MINIMAL "[erosion]\nfluvial_steps = -1\n", "t.scene:11: fluvial_steps: ");
    expect_error_text(MINIMAL "[erosion]\ncreep = 0.2\n", "t.scene:11: creep: ");
    expect_error_text(MINIMAL "procedural = yes\n[erosion]\nfluvial_steps = 5\n",
                      "t.scene:11: erosion: needs a grid; procedural = yes with a noise generator");
    expect_error_text(MINIMAL "[animation]\nframes = 2\nerosion_steps = -3\n",
                      "t.scene:12: erosion_steps: -3 is out of range 0..1000000");
    const char *bad_gen = "[terrain]\ngenerator = perlin\n";
    expect_error_text(bad_gen, "t.scene:2: generator: unknown value \"perlin\" (expected "
                               "fbm|hetero|hybrid|ridged|midpoint|fault|subdivide|file)");
    expect_error_text(MINIMAL "[antialias]\nmax_depth = 0x3\n", "t.scene:11: max_depth: trailing junk \"x3\"");
    expect_error_text(MINIMAL "seed_x = 1\n", "t.scene:10: seed_x: unknown key");
}

static void test_error_trailing_junk(void **state)
{
    (void)state;
    expect_error_text(MINIMAL "extent = 12abc\n", "t.scene:10: extent: trailing junk \"abc\" after the number");
    expect_error_text(MINIMAL "octaves = 4 5\n", "t.scene:10: octaves: trailing junk \"5\"");
    expect_error_text(MINIMAL "extent = 100 # metres\n", "t.scene:10: extent: trailing junk \"# metres\"");
    /* an inline comment after " ;" is fine */
    char err[256];
    tf_scene *s = parse(MINIMAL "extent = 100 ; metres\n", err, sizeof err);
    assert_non_null(s);
    assert_true(s->terrain.extent == 100);
    tf_scene_free(s);
}

static void test_error_out_of_range(void **state)
{
    (void)state;
    expect_error_text(MINIMAL "size_exp = 14\n", "t.scene:10: size_exp: 14 is out of range 1..13");
    expect_error_text(MINIMAL "size_exp = 0\n", "t.scene:10: size_exp: 0 is out of range 1..13");
    expect_error_text("[image]\nwidth = 65537\n", "t.scene:2: width: 65537 is out of range 1..65536");
    expect_error_text("[image]\nwidth = 0\n", "t.scene:2: width: 0 is out of range 1..65536");
    expect_error_text(MINIMAL "[antialias]\nmax_depth = 7\n", "t.scene:11: max_depth: 7 is out of range 0..6");
    expect_error_text(MINIMAL "extent = 0\n", "t.scene:10: extent: 0 is out of range above 0..");
    expect_error_text("[terrain]\nseed = -1\n", "t.scene:2: seed: expected an integer 0..18446744073709551615");
    expect_error_text("[terrain]\nseed = 18446744073709551616\n", "t.scene:2: seed: 18446744073709551616 is out of range");
    expect_error_text("[image]\nwidth = 99999999999999999999\n", "t.scene:2: width: 99999999999999999999 is out of range");
    expect_error_text(MINIMAL "[sun]\ncolor = 1 -0.5 1\n", "t.scene:11: color: -0.5 is out of range 0..1000");
    expect_error_text(MINIMAL "envelope_n = 1\n", "t.scene:10: envelope_n: must be 0 (no envelope) or 2..9");
}

static void test_error_nan_inf(void **state)
{
    (void)state;
    expect_error_text(MINIMAL "H = nan\n", "t.scene:10: H: NaN and infinity are not allowed");
    expect_error_text(MINIMAL "H = -Inf\n", "t.scene:10: H: NaN and infinity are not allowed");
    expect_error_text(MINIMAL "extent = 1e999\n", "t.scene:10: extent: \"1e999\" is not a finite number");
    expect_error_text("[camera]\nposition = 0 infinity 0\n", "t.scene:2: position: NaN and infinity are not allowed");
}

static void test_error_vectors(void **state)
{
    (void)state;
    expect_error_text("[camera]\nposition = 1 2\n", "t.scene:2: position: expected 3 numbers \"x y z\", got 2");
    expect_error_text("[camera]\nposition = 1 2 3 4\n", "t.scene:2: position: expected 3 numbers \"x y z\", got more");
    expect_error_text("[camera]\nposition = 1,,2,3\n", "t.scene:2: position: expected a number, got \",2,3\"");
    expect_error_text("[camera]\nposition = 1;2;3\n", "t.scene:2: position: trailing junk \";2;3\"");
    const char *same = "[image]\nwidth=1\nheight=1\n[camera]\nposition = 1 2 3\nlook_at = 1 2 3\n"
                       "[terrain]\ngenerator=fbm\nseed=1\n";
    expect_error_text(same, "t.scene:5: look_at: must differ from position");
    const char *parallel = "[image]\nwidth=1\nheight=1\n[camera]\nposition = 0 0 5\nlook_at = 0 0 0\n"
                           "[terrain]\ngenerator=fbm\nseed=1\n";
    expect_error_text(parallel, "t.scene:4: up: must be non-zero and not parallel");
}

static void test_error_line_level(void **state)
{
    (void)state;
    expect_error_text(MINIMAL "just words\n", "t.scene:10: syntax: expected \"key = value\", \"[section]\" or a comment, got \"just words\"");
    expect_error_text(MINIMAL "= 5\n", "t.scene:10: syntax: missing key name");
    expect_error_text(MINIMAL "  octaves = 3\n", "t.scene:10: seed: indented line would continue its value");
    expect_error_text(MINIMAL " [sun]\n", "t.scene:10: syntax: a section header must start at the beginning");
    /* a NUL byte, with text after it so the length matters */
    static const char nul[] = MINIMAL "[sun]\nazimuth = 1\0 2\n";
    expect_error(nul, sizeof nul - 1, "t.scene:11: line: contains a NUL byte");
    /* inih's buffer holds 198 characters: longer lines are an error, not silently split */
    char text[1024];
    snprintf(text, sizeof text, "%s; %0199d\n", MINIMAL, 0);
    expect_error_text(text, "t.scene:10: line: too long (201 characters, at most 198)");
    snprintf(text, sizeof text, "%s; %0196d\n", MINIMAL, 0); /* exactly 198: fine */
    char err[256];
    tf_scene *s = parse(text, err, sizeof err);
    assert_non_null(s);
    tf_scene_free(s);
    /* a syntax error before a later semantic error is the one reported */
    expect_error_text("[image]\nwidth = 1\noops\nheight = 0\n", "t.scene:3: syntax: expected");
}

static void test_error_file(void **state)
{
    (void)state;
    char err[512];
    assert_null(tf_scene_load("/nonexistent/dir/x.scene", err, sizeof err));
    assert_string_equal(err, "/nonexistent/dir/x.scene: cannot open: No such file or directory");
    assert_null(tf_scene_load("/", err, sizeof err));
    assert_string_equal(err, "/: cannot read: Is a directory");

    char path[] = "/tmp/test_scene_XXXXXX";
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    FILE *f = fdopen(fd, "w");
    for (int i = 0; i < 1024 * 1024 / 8 + 1; i++)
        fputs(";       ", f);
    fclose(f);
    assert_null(tf_scene_load(path, err, sizeof err));
    char want[600];
    snprintf(want, sizeof want, "%s: too large (more than 1048576 bytes)", path);
    assert_string_equal(err, want);
    unlink(path);

    size_t big = 1024 * 1024 + 1;
    char *text = calloc(big, 1);
    assert_null(tf_scene_parse_text("big", text, big, err, sizeof err));
    assert_string_equal(err, "big: too large (1048577 bytes, at most 1048576)");
    free(text);
}

static void test_defaults(void **state)
{
    (void)state;
    char err[256];
    tf_scene *s = parse(MINIMAL, err, sizeof err);
    assert_non_null(s);
    assert_int_equal(s->width, 64);
    assert_int_equal(s->height, 32);
    assert_int_equal(s->camera.kind, TF_CAMERA_PINHOLE);
    assert_true(s->camera.up.x == 0 && s->camera.up.y == 0 && s->camera.up.z == 1);
    assert_true(s->camera.fov_deg == 60 && s->camera.vfov_deg == 0);
    assert_int_equal(s->terrain.generator, TF_GEN_FBM);
    assert_true(s->terrain.seed == 5);
    assert_int_equal(s->terrain.size_exp, 9);
    assert_true(s->terrain.extent == 1000 && s->terrain.height_scale == 200);
    assert_true(s->terrain.lacunarity == 2.0 && s->terrain.octaves == 8);
    assert_int_equal(s->terrain.envelope_n, 0);
    assert_int_equal(s->terrain.thermal_iterations, 0);
    assert_int_equal(s->mist.enabled, 0);
    assert_int_equal(s->antialias.max_depth, 3);
    assert_true(s->antialias.threshold == 0.028);
    assert_true(s->sun.elevation_deg == 25 && s->sun.azimuth_deg == 135);
    assert_string_equal(s->path, "t.scene");
    assert_int_equal(s->text_len, strlen(MINIMAL));
    assert_string_equal(s->text, MINIMAL);
    tf_scene_free(s);
}

static void test_vector_syntax(void **state)
{
    (void)state;
    static const char *const forms[] = {"1 -2 3.5", "1,-2,3.5", "1, -2 ,3.5", "  +1e0\t-2, 35e-1",
                                        "1.0,-2.000,3.50"};
    for (size_t i = 0; i < sizeof forms / sizeof forms[0]; i++) {
        char text[512], err[256];
        snprintf(text, sizeof text, "[image]\nwidth=1\nheight=1\n[camera]\nposition = %s\n"
                 "look_at = 9 9 9\n[terrain]\ngenerator=fbm\nseed=1\n", forms[i]);
        tf_scene *s = parse(text, err, sizeof err);
        if (!s)
            fail_msg("\"%s\": %s", forms[i], err);
        assert_true(s->camera.position.x == 1 && s->camera.position.y == -2 &&
                    s->camera.position.z == 3.5);
        tf_scene_free(s);
    }
}

static void test_envelope_list(void **state)
{
    (void)state;
    char err[256];
    /* envelope_n inferred from a square count; continuation lines and comments inside */
    tf_scene *s = parse(MINIMAL "envelope = 0.1 0.2 ; row 0\n"
                      "   ; a comment line inside the list\n"
                      "   0.3, 0.4\n", err, sizeof err);
    if (!s)
        fail_msg("%s", err);
    assert_int_equal(s->terrain.envelope_n, 2);
    assert_true(s->terrain.envelope[0] == 0.1 && s->terrain.envelope[3] == 0.4);
    tf_scene_free(s);
    expect_error_text(MINIMAL "envelope = 1 2 3\n", "t.scene:10: envelope: 3 numbers is not a square grid");
    expect_error_text(MINIMAL "envelope_n = 3\nenvelope = 1 2 3 4\n",
                      "t.scene:11: envelope: expected 9 numbers (envelope_n = 3), got 4");
    expect_error_text(MINIMAL "envelope_n = 2\n", "t.scene:10: envelope: missing (envelope_n = 2 needs 4 numbers)");
    expect_error_text(MINIMAL "envelope = 1 2\n  3 x\n", "t.scene:11: envelope: expected a number, got \"x\"");
    char text[4096];
    int n = snprintf(text, sizeof text, "%senvelope = 0\n", MINIMAL);
    for (int i = 0; i < 10; i++)
        n += snprintf(text + n, sizeof text - (size_t)n, "  1 2 3 4 5 6 7 8 9\n");
    expect_error_text(text, "t.scene:19: envelope: more than 81 numbers");
}

/* Same scene, written differently: comments, spacing, order, defaults spelled out. */
static const char *const SAME_SCENE[] = {
    MINIMAL,
    "; a comment\n# another\n\n[terrain]\nseed=5\n  ; indented comment\ngenerator=FBM\n"
    "[camera]\nlook_at = 100, 100, 0\nposition=0,0,10 ; eye\n[image]\nheight = 32\nwidth=64\n",
    MINIMAL "size_exp = 9\nextent = 1000.0\nH = 8e-1\nlacunarity = 2\n",
    "\xEF\xBB\xBF[image]\r\nwidth = 64\r\nheight = 32\r\n[camera]\r\nposition = 0 0 10\r\n"
    "look_at = 100 100 0\r\nup = 0 0 1\r\ntype = pinhole\r\n[terrain]\r\ngenerator = fbm\r\n"
    "seed = 5\r\n[mist]\r\nenabled = no\r\n[antialias]\r\nmax_depth = 3\r\n",
};

static void test_canonical_invariance(void **state)
{
    (void)state;
    char err[256];
    tf_scene *ref = NULL;
    char *ref_canon = NULL;
    for (size_t i = 0; i < sizeof SAME_SCENE / sizeof SAME_SCENE[0]; i++) {
        tf_scene *s = parse(SAME_SCENE[i], err, sizeof err);
        if (!s)
            fail_msg("form %zu: %s", i, err);
        char *canon = tf_scene_canonical(s);
        if (!ref) {
            ref = s;
            ref_canon = canon;
            continue;
        }
        assert_string_equal(canon, ref_canon);
        assert_memory_equal(s->hash, ref->hash, 32);
        assert_string_equal(s->hash_hex, ref->hash_hex);
        free(canon);
        tf_scene_free(s);
    }
    /* the hash does not depend on the name the text came from */
    tf_scene *named = tf_scene_parse_text("elsewhere/other.scene", MINIMAL, strlen(MINIMAL), err,
                                          sizeof err);
    assert_string_equal(named->hash_hex, ref->hash_hex);
    assert_null(strstr(ref_canon, "t.scene"));
    tf_scene_free(named);
    free(ref_canon);
    tf_scene_free(ref);
}

/* Changing any one field changes the hash. */
struct change {
    const char *section, *key, *value;
};

/* The text of the minimal scene with one key set: every section is written, the required keys
 * of the minimal scene come first unless the change sets the same key. */
static void scene_with(char *text, size_t size, const struct change *c)
{
    static const struct change base[] = {
        {"image", "width", "64"},          {"image", "height", "32"},
        {"camera", "position", "0 0 10"},  {"camera", "look_at", "100 100 0"},
        {"terrain", "generator", "fbm"},   {"terrain", "seed", "5"},
    };
    static const char *const sections[] = {"image", "camera", "sun", "sky", "terrain",
                                           "materials", "mist", "antialias"};
    size_t n = 0;
    for (size_t si = 0; si < 8; si++) {
        n += (size_t)snprintf(text + n, size - n, "[%s]\n", sections[si]);
        for (size_t b = 0; b < sizeof base / sizeof base[0]; b++)
            if (strcmp(base[b].section, sections[si]) == 0 &&
                !(c && strcmp(c->key, base[b].key) == 0 && strcmp(c->section, sections[si]) == 0))
                n += (size_t)snprintf(text + n, size - n, "%s = %s\n", base[b].key, base[b].value);
        if (c && strcmp(c->section, sections[si]) == 0)
            n += (size_t)snprintf(text + n, size - n, "%s = %s\n", c->key, c->value);
    }
    assert_true(n < size);
}

static void test_hash_changes_with_each_field(void **state)
{
    (void)state;
    static const struct change changes[] = {
        {"image", "width", "65"}, {"image", "height", "33"},
        {"camera", "type", "panorama"}, {"camera", "position", "0 0 11"},
        {"camera", "look_at", "100 101 0"}, {"camera", "up", "0 0.1 1"},
        {"camera", "fov", "61"}, {"camera", "vfov", "1"},
        {"sun", "azimuth", "1"}, {"sun", "elevation", "1"}, {"sun", "color", "1 1 1"},
        {"sun", "intensity", "2"}, {"sky", "zenith", "0 0 0"}, {"sky", "horizon", "0 0 0"},
        {"sky", "intensity", "0"}, {"terrain", "generator", "hetero"}, {"terrain", "seed", "6"},
        {"terrain", "size_exp", "8"}, {"terrain", "extent", "999"},
        {"terrain", "height_scale", "1"}, {"terrain", "feature_size", "1"},
        {"terrain", "octaves", "8.5"}, {"terrain", "H", "0.5"}, {"terrain", "lacunarity", "2.1"},
        {"terrain", "offset", "1"}, {"terrain", "gain", "1"}, {"terrain", "roughness", "0.5"},
        {"terrain", "envelope", "0 0 0 0"}, {"terrain", "envelope", "0 0 0 1"},
        {"terrain", "envelope", "0 0 0 0 0 0 0 0 0"},
        {"terrain", "envelope_tolerance", "0.2"}, {"terrain", "faults", "1"},
        {"terrain", "fault_step", "1"}, {"terrain", "wind_passes", "0"},
        {"terrain", "rain_passes", "0"}, {"terrain", "erosion_k", "0.25"},
        {"terrain", "sub_M", "2"}, {"terrain", "sub_E", "3"}, {"terrain", "sub_W", "0"},
        {"terrain", "thermal_iterations", "1"}, {"terrain", "talus", "30"},
        {"terrain", "smooth", "yes"},
        {"materials", "sea_level", "1"}, {"materials", "tree_line", "1"},
        {"materials", "snow_line", "1"}, {"materials", "snow_jitter", "1"},
        {"materials", "rock_slope", "1"}, {"materials", "bump", "1"},
        {"mist", "enabled", "yes"}, {"mist", "homogeneous", "1"}, {"mist", "density", "1"},
        {"mist", "falloff", "1"}, {"mist", "color", "0 0 0"}, {"mist", "extinction", "1 1 1"},
        {"antialias", "threshold", "1"}, {"antialias", "max_depth", "4"},
    };
    size_t count = sizeof changes / sizeof changes[0];
    char (*hashes)[65] = calloc(count + 1, 65);
    char err[256], text[2048];
    for (size_t i = 0; i <= count; i++) {
        scene_with(text, sizeof text, i < count ? &changes[i] : NULL);
        tf_scene *s = parse(text, err, sizeof err);
        if (!s)
            fail_msg("change %zu: %s", i, err);
        memcpy(hashes[i], s->hash_hex, 65);
        tf_scene_free(s);
        for (size_t j = 0; j < i; j++)
            if (strcmp(hashes[i], hashes[j]) == 0)
                fail_msg("changes %zu and %zu give the same hash", j, i);
    }
    free(hashes);
}

static void test_set_size_rehashes(void **state)
{
    (void)state;
    char err[256];
    tf_scene *s = parse(MINIMAL, err, sizeof err);
    char before[65];
    memcpy(before, s->hash_hex, 65);
    tf_scene_set_size(s, 640, 480);
    assert_int_equal(s->width, 640);
    assert_int_equal(s->height, 480);
    assert_string_not_equal(s->hash_hex, before);
    char *canon = tf_scene_canonical(s);
    assert_non_null(strstr(canon, "width = 640\nheight = 480\n"));
    free(canon);
    /* the same as a file that says 640x480 */
    tf_scene *t = parse("[image]\nwidth = 640\nheight = 480\n[camera]\nposition = 0 0 10\n"
                        "look_at = 100 100 0\n[terrain]\ngenerator = fbm\nseed = 5\n", err, sizeof err);
    assert_string_equal(s->hash_hex, t->hash_hex);
    tf_scene_set_size(s, 64, 32);
    assert_string_equal(s->hash_hex, before);
    tf_scene_free(t);
    tf_scene_free(s);
}

static void test_hash_hex_matches_bytes(void **state)
{
    (void)state;
    char err[256], hex[65];
    tf_scene *s = parse(MINIMAL, err, sizeof err);
    for (int i = 0; i < 32; i++)
        snprintf(hex + 2 * i, 3, "%02x", s->hash[i]);
    assert_string_equal(hex, s->hash_hex);
    tf_scene_free(s);
}

static void test_parse_text_equals_load(void **state)
{
    (void)state;
    char path[] = "/tmp/test_scene_XXXXXX";
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    const char *text = MINIMAL "envelope = 1 2\n   3 4\n[mist]\nenabled = on\n";
    assert_int_equal(write(fd, text, strlen(text)), (ssize_t)strlen(text));
    close(fd);
    char err[256];
    tf_scene *a = tf_scene_load(path, err, sizeof err);
    tf_scene *b = tf_scene_parse_text("<string>", text, strlen(text), err, sizeof err);
    unlink(path);
    assert_non_null(a);
    assert_non_null(b);
    assert_string_equal(a->path, path);
    assert_int_equal(a->text_len, b->text_len);
    assert_string_equal(a->text, b->text);
    assert_string_equal(a->hash_hex, b->hash_hex);
    /* every field equal: compare the structs past the two pointers that differ */
    size_t from = offsetof(tf_scene, width);
    assert_memory_equal((char *)a + from, (char *)b + from, sizeof *a - from);
    tf_scene_free(a);
    tf_scene_free(b);
}

/* parse(canonical(s)) gives the same canonical form: the hash is a function of the struct. */
static void test_canonical_roundtrip(void **state)
{
    (void)state;
    char err[256];
    tf_scene *s = parse(MINIMAL "envelope = 0.1 0.2 0.3 0.4 0.5 0.6 0.7 0.8 0.9 1 1.1 1.2 1.3 1.4 "
                        "1.5 1.6\nH = -0\n[mist]\nenabled = yes\n", err, sizeof err);
    assert_non_null(s);
    char *c1 = tf_scene_canonical(s);
    tf_scene *t = tf_scene_parse_text("canon", c1, strlen(c1), err, sizeof err);
    if (!t)
        fail_msg("%s\n%s", err, c1);
    char *c2 = tf_scene_canonical(t);
    assert_string_equal(c1, c2);
    assert_string_equal(s->hash_hex, t->hash_hex);
    assert_non_null(strstr(c1, "\nH = 0\n")); /* -0 is spelled 0 */
    assert_non_null(strstr(c1, "\noffset = 0.69999999999999996\n")); /* %.17g */
    free(c1);
    free(c2);
    tf_scene_free(s);
    tf_scene_free(t);
}

static void test_every_example_scene_parses(void **state)
{
    (void)state;
    const char *root = getenv("TF_ROOT") ? getenv("TF_ROOT") : ".";
    char dir[1024];
    snprintf(dir, sizeof dir, "%s/scenes", root);
    DIR *d = opendir(dir);
    assert_non_null(d);
    int count = 0, has_default = 0;
    struct dirent *e;
    while ((e = readdir(d)) != NULL) {
        size_t n = strlen(e->d_name);
        if (n < 7 || strcmp(e->d_name + n - 6, ".scene") != 0)
            continue;
        char path[2048], err[512];
        snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
        tf_scene *s = tf_scene_load(path, err, sizeof err);
        if (!s)
            fail_msg("%s", err);
        if (strcmp(e->d_name, "default.scene") == 0) {
            has_default = 1;
            assert_true(s->width * s->height <= 640 * 360); /* stays small and fast */
            assert_true(s->terrain.size_exp <= 9);
        }
        tf_scene_free(s);
        count++;
    }
    closedir(d);
    assert_true(has_default);
    assert_true(count >= 4);
}

static void test_generator_names(void **state)
{
    (void)state;
    assert_string_equal(tf_generator_name(TF_GEN_FBM), "fbm");
    assert_string_equal(tf_generator_name(TF_GEN_RIDGED), "ridged");
    assert_string_equal(tf_generator_name(TF_GEN_SUBDIVIDE), "subdivide");
    assert_string_equal(tf_generator_name((enum tf_generator)99), "unknown");
}

/* terrain smooth: a bool, off by default; the canonical form names it only when on, so a scene
 * that leaves it out (or says no) keeps the hash it had before the key existed, and networked
 * workers, which parse the canonical text, get it when on. */
static void test_smooth_key(void **state)
{
    (void)state;
    char err[512];
    tf_scene *plain = parse(MINIMAL, err, sizeof err), *no = parse(MINIMAL "smooth = no\n", err,
                                                                   sizeof err);
    tf_scene *yes = parse(MINIMAL "smooth = yes\n", err, sizeof err);
    assert_non_null(plain);
    assert_non_null(no);
    assert_non_null(yes);
    assert_int_equal(plain->terrain.smooth, 0);
    assert_int_equal(yes->terrain.smooth, 1);
    char *c_plain = tf_scene_canonical(plain), *c_yes = tf_scene_canonical(yes);
    assert_null(strstr(c_plain, "smooth"));
    assert_non_null(strstr(c_yes, "\nsmooth = true\n"));
    assert_string_equal(no->hash_hex, plain->hash_hex);
    assert_string_not_equal(yes->hash_hex, plain->hash_hex);
    tf_scene *again = parse(c_yes, err, sizeof err);
    assert_non_null(again);
    assert_int_equal(again->terrain.smooth, 1);
    assert_string_equal(again->hash_hex, yes->hash_hex);
    free(c_plain);
    free(c_yes);
    tf_scene_free(again);
    tf_scene_free(plain);
    tf_scene_free(no);
    tf_scene_free(yes);
    expect_error_text(MINIMAL "smooth = maybe\n", "t.scene:10: smooth: unknown value \"maybe\"");
    expect_error_text(MINIMAL "[materials]\nsmooth = yes\n",
                      "t.scene:11: smooth: unknown key in [materials]");
}

/* generator = file: path required, extent 0 (from the raster) unless set, the canonical form
 * keeps the file keys and is itself a valid scene; a procedural scene may not take extent 0. */
#define FILE_SCENE                                                                                 \
    "[image]\nwidth = 64\nheight = 32\n[camera]\nposition = 0 0 10\nlook_at = 100 100 0\n"         \
    "[terrain]\ngenerator = file\nseed = 5\n"

static void test_file_generator_keys(void **state)
{
    (void)state;
    char err[512];
    expect_error_text(FILE_SCENE, "t.scene:8: path: missing (generator = file needs");
    tf_scene *s = parse(FILE_SCENE "path = dem/alps.tif\nnodata = sea\nfirst_row = south\n"
                        "crop_x = 3\ncrop_width = 100\nvertical_scale = 0.5\n"
                        "vertical_offset = -20\n", err, sizeof err);
    assert_non_null(s);
    assert_true(s->terrain.generator == TF_GEN_FILE);
    assert_string_equal(s->terrain.file_path, "dem/alps.tif");
    assert_true(s->terrain.extent == 0);
    assert_true(s->terrain.nodata == TF_NODATA_SEA && s->terrain.first_row == TF_FIRST_ROW_SOUTH);
    assert_true(s->terrain.crop_x == 3 && s->terrain.crop_width == 100);
    assert_true(s->terrain.vertical_scale == 0.5 && s->terrain.vertical_offset == -20);
    assert_null(s->heightmap); /* parse_text never reads files */
    char *c = tf_scene_canonical(s);
    assert_non_null(strstr(c, "\npath = dem/alps.tif\n"));
    assert_non_null(strstr(c, "\nextent = 0\n"));
    assert_null(strstr(c, "sha256")); /* no file attached, none pinned: the key is absent */
    tf_scene *again = parse(c, err, sizeof err);
    assert_non_null(again);
    assert_string_equal(s->hash_hex, again->hash_hex);
    free(c);
    tf_scene_free(again);
    tf_scene_free(s);
    expect_error_text(MINIMAL "extent = 0\n", "t.scene:10: extent: 0 is out of range above 0..");
    expect_error_text(FILE_SCENE "path = a.tif\nsha256 = 12ab\n",
                      "t.scene:11: sha256: expected 64 hexadecimal digits");
    expect_error_text(FILE_SCENE "path = a.tif\nnodata = zero\n",
                      "t.scene:11: nodata: unknown value \"zero\" (expected fill|sea)");
}

/* The height map's SHA-256 enters the scene hash; a pinned sha256 must match. */
static void test_file_hash_follows_bytes(void **state)
{
    (void)state;
    char err[512];
    tf_scene *a = parse(FILE_SCENE "path = m.png\n", err, sizeof err);
    tf_scene *b = parse(FILE_SCENE "path = m.png\n", err, sizeof err);
    assert_non_null(a);
    assert_non_null(b);
    char before[65];
    memcpy(before, a->hash_hex, sizeof before);
    assert_int_equal(tf_scene_attach_heightmap(a, (uint8_t *)strdup("abc"), 3, "m.png", err,
                                               sizeof err), 0);
    assert_int_equal(tf_scene_attach_heightmap(b, (uint8_t *)strdup("abd"), 3, "m.png", err,
                                               sizeof err), 0);
    assert_string_not_equal(a->hash_hex, before);
    assert_string_not_equal(a->hash_hex, b->hash_hex);
    /* SHA-256("abc") */
    assert_string_equal(a->terrain.file_sha256,
                        "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
    assert_true(a->terrain.file_bytes == a->heightmap && a->terrain.file_len == 3);
    /* the canonical form pins the hash: parsed again, the other bytes are refused */
    char *c = tf_scene_canonical(a);
    tf_scene *pinned = parse(c, err, sizeof err);
    free(c);
    assert_non_null(pinned);
    assert_string_equal(pinned->hash_hex, a->hash_hex);
    assert_int_equal(tf_scene_attach_heightmap(pinned, (uint8_t *)strdup("abd"), 3, "m.png", err,
                                               sizeof err), -1);
    assert_non_null(strstr(err, "pins sha256"));
    assert_int_equal(tf_scene_attach_heightmap(pinned, (uint8_t *)strdup("abc"), 3, "m.png", err,
                                               sizeof err), 0);
    assert_string_equal(pinned->hash_hex, a->hash_hex);
    tf_scene_free(pinned);
    tf_scene_free(a);
    tf_scene_free(b);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_error_unknown_section),
        cmocka_unit_test(test_error_unknown_key),
        cmocka_unit_test(test_error_duplicate_key),
        cmocka_unit_test(test_error_missing_required),
        cmocka_unit_test(test_error_wrong_type),
        cmocka_unit_test(test_error_trailing_junk),
        cmocka_unit_test(test_error_out_of_range),
        cmocka_unit_test(test_error_nan_inf),
        cmocka_unit_test(test_error_vectors),
        cmocka_unit_test(test_error_line_level),
        cmocka_unit_test(test_error_file),
        cmocka_unit_test(test_defaults),
        cmocka_unit_test(test_vector_syntax),
        cmocka_unit_test(test_envelope_list),
        cmocka_unit_test(test_canonical_invariance),
        cmocka_unit_test(test_hash_changes_with_each_field),
        cmocka_unit_test(test_set_size_rehashes),
        cmocka_unit_test(test_hash_hex_matches_bytes),
        cmocka_unit_test(test_parse_text_equals_load),
        cmocka_unit_test(test_canonical_roundtrip),
        cmocka_unit_test(test_every_example_scene_parses),
        cmocka_unit_test(test_generator_names),
        cmocka_unit_test(test_file_generator_keys),
        cmocka_unit_test(test_smooth_key),
        cmocka_unit_test(test_file_hash_follows_bytes),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
