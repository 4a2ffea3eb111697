/* scene_check.c: the checks once the whole text is read (scene_impl.h): required keys, the
 * envelope against envelope_n, generator = file against extent, the [animation] keys, and a
 * camera that can see. */
#include "scene_impl.h"

#include <assert.h>
#include <math.h>
#include <string.h>

/* Line to blame for a key: where it was set, else its section header, else 0. */
static int blame_line(const struct parser *p, int key)
{
    return p->key_line[key] ? p->key_line[key] : p->section_line[SCENE_KEYS[key].section];
}

/* generator = file makes no terrain from the seed: there it only seeds the jitter and the
 * textures, and may be left out (0), so a height map re-imports with `path =` alone. */
static int seed_of_a_file(const struct parser *p, int key)
{
    return key == scene_key_index(SEC_TERRAIN, "seed") &&
           p->s->terrain.generator == TF_GEN_FILE;
}

static void check_required(struct parser *p)
{
    for (int key = 0; key < SCENE_KEY_COUNT && !p->failed; key++) {
        const struct key_def *k = &SCENE_KEYS[key];
        if (scene_replaced_by_animation(p->s, key)) {
            if (p->key_line[key])
                scene_fail_at(p, p->key_line[key], "%s: the %s is animated by [animation] %s "
                              "keys; give %s in those keys instead", k->name,
                              SCENE_SECTION_NAMES[k->section], SCENE_SECTION_NAMES[k->section],
                              k->name);
            continue;
        }
        if (!k->required || p->key_line[key] || seed_of_a_file(p, key))
            continue;
        if (p->section_line[k->section])
            scene_fail_at(p, p->section_line[k->section], "%s: missing required key in [%s]",
                          k->name, SCENE_SECTION_NAMES[k->section]);
        else
            scene_fail_at(p, 0, "%s: missing required key (no [%s] section)", k->name,
                          SCENE_SECTION_NAMES[k->section]);
    }
}

/* envelope_n and the envelope list must agree; envelope_n may be left out and is then the
 * side of the square list. */
static void check_envelope(struct parser *p)
{
    int kn = scene_key_index(SEC_TERRAIN, "envelope_n");
    int kl = scene_key_index(SEC_TERRAIN, "envelope");
    tf_terrain *t = &p->s->terrain;
    int count = p->envelope_count;
    if (t->envelope_n == 1) {
        scene_fail_at(p, blame_line(p, kn), "envelope_n: must be 0 (no envelope) or 2..%d",
                      TF_ENVELOPE_MAX);
        return;
    }
    if (!p->key_line[kl]) {
        if (t->envelope_n > 0)
            scene_fail_at(p, blame_line(p, kn),
                          "envelope: missing (envelope_n = %d needs %d numbers)",
                          t->envelope_n, t->envelope_n * t->envelope_n);
        return;
    }
    if (!p->key_line[kn]) {
        int side = 2;
        while (side < TF_ENVELOPE_MAX && side * side < count)
            side++;
        if (side * side != count) {
            scene_fail_at(p, p->key_line[kl], "envelope: %d numbers is not a square grid of "
                          "2x2..%dx%d control points", count, TF_ENVELOPE_MAX, TF_ENVELOPE_MAX);
            return;
        }
        t->envelope_n = side;
        return;
    }
    if (count != t->envelope_n * t->envelope_n)
        scene_fail_at(p, p->key_line[kl], "envelope: expected %d numbers (envelope_n = %d), got %d",
                      t->envelope_n * t->envelope_n, t->envelope_n, count);
}

static void check_camera(struct parser *p)
{
    const tf_scene *s = p->s;
    int kpos = scene_key_index(SEC_CAMERA, "position");
    int kup = scene_key_index(SEC_CAMERA, "up");
    int kfov = scene_key_index(SEC_CAMERA, "fov");
    tf_vec3 dir = v3_sub(s->camera.look_at, s->camera.position);
    double dlen = v3_len(dir), ulen = v3_len(s->camera.up);
    if (!(dlen > 0)) {
        scene_fail_at(p, blame_line(p, kpos), "look_at: must differ from position");
        return;
    }
    if (!(ulen > 0) || !(v3_len(v3_cross(dir, s->camera.up)) > 1e-9 * dlen * ulen)) {
        scene_fail_at(p, blame_line(p, kup), "up: must be non-zero and not parallel to the view "
                      "direction (look_at - position)");
        return;
    }
    if (s->camera.kind == TF_CAMERA_PINHOLE && !(s->camera.fov_deg < 180))
        scene_fail_at(p, blame_line(p, kfov), "fov: %.17g is out of range for a pinhole camera "
                      "(above 0, below 180)", s->camera.fov_deg);
}

/* [animation]: frames given, every key complete (fov and up default to [camera]'s), the keys
 * in order and every frame's camera and sun well defined (animation.c); then the [camera] and
 * [sun] fields take frame 0's values. */
static void check_animation(struct parser *p)
{
    tf_scene *s = p->s;
    tf_animation *a = &s->animation;
    int kframes = scene_key_index(SEC_ANIMATION, "frames");
    if (!p->section_line[SEC_ANIMATION])
        return;
    if (!p->key_line[kframes]) {
        scene_fail_at(p, p->section_line[SEC_ANIMATION],
                      "frames: missing required key in [animation]");
        return;
    }
    for (int k = 0; k < a->ncamera; k++) {
        tf_camera_key *key = &a->camera[k];
        if (!p->key_has_pos[k] || !p->key_has_look[k]) {
            scene_fail_at(p, key->line, "camera: the key at frame %d needs %s", key->frame,
                          !p->key_has_pos[k] ? "a position" : "a look_at");
            return;
        }
        if (!p->key_has_fov[k])
            key->fov_deg = s->camera.fov_deg;
        if (!p->key_has_up[k])
            key->up = s->camera.up;
    }
    for (int k = 0; k < a->nsun; k++)
        if (isnan(a->sun[k].azimuth_deg) || isnan(a->sun[k].elevation_deg)) {
            scene_fail_at(p, a->sun[k].line, "sun: the key at frame %d needs %s", a->sun[k].frame,
                          isnan(a->sun[k].azimuth_deg) ? "an azimuth" : "an elevation");
            return;
        }
    int line = 0;
    char what[400];
    if (tf_animation_check(a, s->camera.kind == TF_CAMERA_PINHOLE, &line, what, sizeof what)) {
        scene_fail_at(p, line, "%s", what);
        return;
    }
    tf_scene_apply_frame(s, 0);
}

/* generator = file needs a path, and its extent defaults to 0 (from the raster); every other
 * generator needs an extent above 0. */
static void check_terrain_file(struct parser *p)
{
    tf_terrain *t = &p->s->terrain;
    int kext = scene_key_index(SEC_TERRAIN, "extent");
    int kgen = scene_key_index(SEC_TERRAIN, "generator");
    if (t->generator == TF_GEN_FILE) {
        if (!t->file_path[0])
            scene_fail_at(p, blame_line(p, kgen), "path: missing (generator = file needs the "
                          "height map's file name)");
        else if (!p->key_line[kext])
            t->extent = 0;
        return;
    }
    if (!(t->extent > 0))
        scene_fail_at(p, blame_line(p, kext), "extent: %.17g is out of range above 0..%.17g "
                      "(0, from the raster, is only for generator = file)", t->extent, BIG);
}

/* detail adds to a grid or a height map under procedural = yes; a noise generator has its
 * own octaves for that.  Erosion changes a grid: a procedural noise terrain has none. */
static void check_procedural(struct parser *p)
{
    const tf_terrain *t = &p->s->terrain;
    int noise = t->generator == TF_GEN_FBM || t->generator == TF_GEN_HETERO ||
                t->generator == TF_GEN_HYBRID || t->generator == TF_GEN_RIDGED;
    if (t->detail > 0 && (noise || !t->procedural))
        scene_fail_at(p, blame_line(p, scene_key_index(SEC_TERRAIN, "detail")),
                      "detail: only for a grid generator or generator = file with procedural "
                      "= yes (a noise generator's detail is its octaves)");
    int eroded = t->erosion.fluvial_steps > 0 || p->s->animation.erosion_steps > 0;
    if (!p->failed && eroded && noise && t->procedural)
        scene_fail_at(p, p->section_line[SEC_EROSION] ? p->section_line[SEC_EROSION]
                                                     : p->section_line[SEC_ANIMATION],
                      "erosion: needs a grid; procedural = yes with a noise generator has none "
                      "(set size_exp and drop procedural, or add detail over a grid)");
}

void scene_check_semantics(struct parser *p)
{
    check_required(p);
    if (!p->failed)
        check_envelope(p);
    if (!p->failed)
        check_terrain_file(p);
    if (!p->failed)
        check_procedural(p);
    if (!p->failed)
        check_animation(p);
    if (!p->failed)
        check_camera(p);
}

/* ---------------------------------------------------------------------------------------- */
/* The invariants of scene.c, asserted clause by clause (debug builds)                      */

#ifndef NDEBUG
/* P3 for the keys set so far: each on a line at or after its section's header. */
static int keys_after_headers(const struct parser *p)
{
    for (int key = 0; key < SCENE_KEY_COUNT; key++) {
        int sec_line = p->section_line[SCENE_KEYS[key].section];
        if (p->key_line[key] && (!sec_line || p->key_line[key] < sec_line))
            return 0;
    }
    return 1;
}

int scene_assert_parser(const struct parser *p)
{
    const tf_animation *a = &p->s->animation;
    assert((!p->failed || (p->err_line >= 0 && p->err_line <= p->line)) &&
           "P1: the error names a line already read");
    assert((!p->failed || !p->err || p->errlen < 2 || (p->err[0] && !strchr(p->err, '\n'))) &&
           "P2: an error message is one non-empty line");
    assert(p->section >= -1 && p->section < SEC_COUNT && "P3: the section is -1 or a section");
    assert((p->last_key < 0 || (p->last_key < SCENE_KEY_COUNT &&
                                (int)SCENE_KEYS[p->last_key].section == p->section)) &&
           "P3: the last key is -1 or a key of the current section");
    assert(keys_after_headers(p) && "P3: a key is set at or after its section's header");
    assert(p->envelope_count >= 0 && p->envelope_count <= TF_ENVELOPE_MAX * TF_ENVELOPE_MAX &&
           "P3: the envelope fits its array");
    assert(a->ncamera >= 0 && a->ncamera <= TF_ANIM_MAX_KEYS && a->nsun >= 0 &&
           a->nsun <= TF_ANIM_MAX_KEYS && "P3: the [animation] keys fit their arrays");
    return 1;
}

/* 1 if v is within key's range. */
static int in_range(const struct key_def *k, double v)
{
    return (k->min_exclusive ? v > k->min : v >= k->min) && v <= k->max;
}

/* P4 for one key its text set (numbers and vectors; other types have no range). */
static int value_in_range(const tf_scene *s, int key)
{
    const struct key_def *k = &SCENE_KEYS[key];
    const void *src = scene_cfield(s, key);
    if (k->type == KT_INT)
        return in_range(k, *(const int *)src);
    if (k->type == KT_DOUBLE)
        return in_range(k, *(const double *)src);
    if (k->type == KT_VEC3) {
        const tf_vec3 *v = src;
        return in_range(k, v->x) && in_range(k, v->y) && in_range(k, v->z);
    }
    return 1;
}

int scene_assert_values(const struct parser *p)
{
    for (int key = 0; key < SCENE_KEY_COUNT; key++)
        assert((!p->key_line[key] || value_in_range(p->s, key)) &&
               "P4: every number the text set is in its key's range");
    return 1;
}
#endif
