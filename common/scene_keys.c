/* scene_keys.c: the scene file's key table (scene_impl.h): every section and key, its type,
 * the field of tf_scene it fills, its range and its default.  Parsing, the checks, the
 * defaults and the canonical form are all driven by this one table. */
#include "scene_impl.h"

#include <stdlib.h>
#include <string.h>
#include <strings.h>

#define F(field) offsetof(tf_scene, field)

const char *const SCENE_SECTION_NAMES[SEC_COUNT] = {
    "image", "camera", "sun", "sky", "terrain", "materials", "mist", "antialias", "animation",
    "erosion"};

/* Keys that may be given more than once (each adds to a list) and continue on indented lines. */
int scene_is_list_type(int type)
{
    return type == KT_ENVELOPE || type == KT_CAMERA_KEY || type == KT_SUN_KEY;
}

const struct key_def SCENE_KEYS[SCENE_KEY_COUNT] = {
    {SEC_IMAGE, "width", KT_INT, F(width), 1, 65536, 0, 1, {0}},
    {SEC_IMAGE, "height", KT_INT, F(height), 1, 65536, 0, 1, {0}},

    {SEC_CAMERA, "type", KT_CAMERA, F(camera.kind), 0, 0, 0, 0, {TF_CAMERA_PINHOLE}},
    {SEC_CAMERA, "position", KT_VEC3, F(camera.position), -BIG, BIG, 0, 1, {0}},
    {SEC_CAMERA, "look_at", KT_VEC3, F(camera.look_at), -BIG, BIG, 0, 1, {0}},
    {SEC_CAMERA, "up", KT_VEC3, F(camera.up), -BIG, BIG, 0, 0, {0, 0, 1}},
    {SEC_CAMERA, "fov", KT_DOUBLE, F(camera.fov_deg), 0, 360, 1, 0, {60}},
    {SEC_CAMERA, "vfov", KT_DOUBLE, F(camera.vfov_deg), 0, 179, 0, 0, {0}},

    {SEC_SUN, "azimuth", KT_DOUBLE, F(sun.azimuth_deg), -360, 360, 0, 0, {135}},
    {SEC_SUN, "elevation", KT_DOUBLE, F(sun.elevation_deg), -90, 90, 0, 0, {25}},
    {SEC_SUN, "color", KT_VEC3, F(sun.color), 0, 1000, 0, 0, {1.0, 0.95, 0.85}},
    {SEC_SUN, "intensity", KT_DOUBLE, F(sun.intensity), 0, 1000, 0, 0, {1.0}},

    {SEC_SKY, "zenith", KT_VEC3, F(sky.zenith), 0, 1000, 0, 0, {0.25, 0.45, 0.85}},
    {SEC_SKY, "horizon", KT_VEC3, F(sky.horizon), 0, 1000, 0, 0, {0.75, 0.85, 0.95}},
    {SEC_SKY, "intensity", KT_DOUBLE, F(sky.intensity), 0, 1000, 0, 0, {0.3}},

    {SEC_TERRAIN, "generator", KT_GENERATOR, F(terrain.generator), 0, 0, 0, 1, {0}},
    {SEC_TERRAIN, "seed", KT_U64, F(terrain.seed), 0, 0, 0, 1, {0}},
    {SEC_TERRAIN, "size_exp", KT_INT, F(terrain.size_exp), 1, 13, 0, 0, {9}},
    /* extent: above 0; generator = file also takes 0 (the default there): from the raster */
    {SEC_TERRAIN, "extent", KT_DOUBLE, F(terrain.extent), 0, BIG, 0, 0, {1000}},
    {SEC_TERRAIN, "height_scale", KT_DOUBLE, F(terrain.height_scale), 0, BIG, 0, 0, {200}},
    {SEC_TERRAIN, "feature_size", KT_DOUBLE, F(terrain.feature_size), 0, BIG, 1, 0, {400}},
    {SEC_TERRAIN, "octaves", KT_DOUBLE, F(terrain.octaves), 1, 30, 0, 0, {8}},
    {SEC_TERRAIN, "H", KT_DOUBLE, F(terrain.H), 0, 2, 0, 0, {0.8}},
    {SEC_TERRAIN, "lacunarity", KT_DOUBLE, F(terrain.lacunarity), 1.1, 8, 0, 0, {2.0}},
    {SEC_TERRAIN, "offset", KT_DOUBLE, F(terrain.offset), -10, 10, 0, 0, {0.7}},
    {SEC_TERRAIN, "gain", KT_DOUBLE, F(terrain.gain), 0, 10, 0, 0, {2.0}},
    {SEC_TERRAIN, "roughness", KT_DOUBLE, F(terrain.roughness), 0, 2, 0, 0, {0.8}},
    {SEC_TERRAIN, "envelope_n", KT_INT, F(terrain.envelope_n), 0, TF_ENVELOPE_MAX, 0, 0, {0}},
    {SEC_TERRAIN, "envelope", KT_ENVELOPE, F(terrain.envelope), -1000, 1000, 0, 0, {0}},
    {SEC_TERRAIN, "envelope_tolerance", KT_DOUBLE, F(terrain.envelope_tolerance), 0, 1000, 0, 0,
     {0.1}},
    {SEC_TERRAIN, "faults", KT_INT, F(terrain.faults), 0, 100000, 0, 0, {400}},
    {SEC_TERRAIN, "fault_step", KT_DOUBLE, F(terrain.fault_step), 0, 10, 0, 0, {0.05}},
    {SEC_TERRAIN, "wind_passes", KT_INT, F(terrain.wind_passes), 0, 1000, 0, 0, {1}},
    {SEC_TERRAIN, "rain_passes", KT_INT, F(terrain.rain_passes), 0, 1000, 0, 0, {1}},
    {SEC_TERRAIN, "erosion_k", KT_DOUBLE, F(terrain.erosion_k), 0, 1, 0, 0, {0.5}},
    {SEC_TERRAIN, "sub_M", KT_DOUBLE, F(terrain.sub_M), 0, 1000, 0, 0, {1.0}},
    {SEC_TERRAIN, "sub_E", KT_DOUBLE, F(terrain.sub_E), 1, 10, 1, 0, {2.0}},
    {SEC_TERRAIN, "sub_W", KT_DOUBLE, F(terrain.sub_W), -1000, 1000, 0, 0, {0.3}},
    {SEC_TERRAIN, "thermal_iterations", KT_INT, F(terrain.thermal_iterations), 0, 10000, 0, 0,
     {0}},
    {SEC_TERRAIN, "talus", KT_DOUBLE, F(terrain.talus_deg), 0, 90, 0, 0, {35}},
    /* smooth, procedural, detail: added after format 1, written only when set
     * (scene_key_silent) */
    {SEC_TERRAIN, "smooth", KT_BOOL, F(terrain.smooth), 0, 1, 0, 0, {0}},
    {SEC_TERRAIN, "procedural", KT_BOOL, F(terrain.procedural), 0, 1, 0, 0, {0}},
    {SEC_TERRAIN, "detail", KT_DOUBLE, F(terrain.detail), 0, BIG, 0, 0, {0}},
    {SEC_TERRAIN, "path", KT_PATH, F(terrain.file_path), 0, TF_SCENE_PATH_MAX, 0, 0, {0}},
    {SEC_TERRAIN, "sha256", KT_SHA256, F(terrain.file_sha256), 0, 0, 0, 0, {0}},
    {SEC_TERRAIN, "vertical_scale", KT_DOUBLE, F(terrain.vertical_scale), -BIG, BIG, 0, 0, {1}},
    {SEC_TERRAIN, "vertical_offset", KT_DOUBLE, F(terrain.vertical_offset), -BIG, BIG, 0, 0,
     {0}},
    {SEC_TERRAIN, "nodata", KT_NODATA, F(terrain.nodata), 0, 0, 0, 0, {TF_NODATA_FILL}},
    {SEC_TERRAIN, "first_row", KT_FIRST_ROW, F(terrain.first_row), 0, 0, 0, 0,
     {TF_FIRST_ROW_AUTO}},
    {SEC_TERRAIN, "crop_x", KT_INT, F(terrain.crop_x), 0, 1 << 20, 0, 0, {0}},
    {SEC_TERRAIN, "crop_y", KT_INT, F(terrain.crop_y), 0, 1 << 20, 0, 0, {0}},
    {SEC_TERRAIN, "crop_width", KT_INT, F(terrain.crop_width), 0, 1 << 20, 0, 0, {0}},
    {SEC_TERRAIN, "crop_height", KT_INT, F(terrain.crop_height), 0, 1 << 20, 0, 0, {0}},

    {SEC_MATERIALS, "sea_level", KT_DOUBLE, F(materials.sea_level), -BIG, BIG, 0, 0, {0}},
    {SEC_MATERIALS, "tree_line", KT_DOUBLE, F(materials.tree_line), -BIG, BIG, 0, 0, {80}},
    {SEC_MATERIALS, "snow_line", KT_DOUBLE, F(materials.snow_line), -BIG, BIG, 0, 0, {160}},
    {SEC_MATERIALS, "snow_jitter", KT_DOUBLE, F(materials.snow_jitter), 0, BIG, 0, 0, {20}},
    {SEC_MATERIALS, "rock_slope", KT_DOUBLE, F(materials.rock_slope_deg), 0, 90, 0, 0, {40}},
    {SEC_MATERIALS, "bump", KT_DOUBLE, F(materials.bump), 0, 10, 0, 0, {0.5}},

    {SEC_MIST, "enabled", KT_BOOL, F(mist.enabled), 0, 1, 0, 0, {0}},
    {SEC_MIST, "homogeneous", KT_BOOL, F(mist.homogeneous), 0, 1, 0, 0, {0}},
    {SEC_MIST, "density", KT_DOUBLE, F(mist.density), 0, 1000, 0, 0, {0.0005}},
    {SEC_MIST, "falloff", KT_DOUBLE, F(mist.falloff), 0, BIG, 1, 0, {100}},
    {SEC_MIST, "color", KT_VEC3, F(mist.color), 0, 1000, 0, 0, {0.75, 0.8, 0.9}},
    {SEC_MIST, "extinction", KT_VEC3, F(mist.extinction), 0, 1000, 0, 0, {0.6, 0.8, 1.0}},

    {SEC_ANTIALIAS, "threshold", KT_DOUBLE, F(antialias.threshold), 0, 1000, 0, 0, {0.028}},
    {SEC_ANTIALIAS, "max_depth", KT_INT, F(antialias.max_depth), 0, 6, 0, 0, {3}},

    /* frames is required once the section is there (check_animation) */
    {SEC_ANIMATION, "frames", KT_INT, F(animation.frames), 1, TF_ANIM_MAX_FRAMES, 0, 0, {0}},
    {SEC_ANIMATION, "fps", KT_DOUBLE, F(animation.fps), 0, 1000, 1, 0, {24}},
    {SEC_ANIMATION, "camera", KT_CAMERA_KEY, F(animation), -BIG, BIG, 0, 0, {0}},
    {SEC_ANIMATION, "sun", KT_SUN_KEY, F(animation), -360, 360, 0, 0, {0}},
    {SEC_ANIMATION, "erosion_steps", KT_INT, F(animation.erosion_steps), 0, 1000000, 0, 0, {0}},

#define E(field) F(terrain.erosion.field)
    {SEC_EROSION, "fluvial_steps", KT_INT, E(fluvial_steps), 0, 10000000, 0, 0, {0}},
    {SEC_EROSION, "capacity", KT_DOUBLE, E(capacity), 0, 1000, 0, 0, {5.0}},
    {SEC_EROSION, "deposition", KT_DOUBLE, E(deposition), 0, 1, 0, 0, {0.1}},
    {SEC_EROSION, "softness", KT_DOUBLE, E(softness), 0, 1, 0, 0, {0.3}},
    {SEC_EROSION, "silt_softness", KT_DOUBLE, E(silt_softness), 0, 3.3, 0, 0, {3.0}},
    {SEC_EROSION, "talus_softness", KT_DOUBLE, E(talus_softness), 0, 3.3, 0, 0, {2.0}},
    {SEC_EROSION, "rain", KT_DOUBLE, E(rain), 0, 1000, 0, 0, {0.5}},
    {SEC_EROSION, "rain_interval", KT_INT, E(rain_interval), 1, 1000000, 0, 0, {80}},
    {SEC_EROSION, "rain_altitude", KT_DOUBLE, E(rain_altitude), 0, 100, 0, 0, {1.0}},
    {SEC_EROSION, "rain_noise", KT_DOUBLE, E(rain_noise), 0, 1, 0, 0, {0}},
    {SEC_EROSION, "evaporation", KT_DOUBLE, E(evaporation), 0, 1, 0, 0, {0}},
    {SEC_EROSION, "creep", KT_DOUBLE, E(creep), 0, 0.125, 0, 0, {0}},
    {SEC_EROSION, "strata", KT_DOUBLE, E(strata), 0, BIG, 0, 0, {0}},
    {SEC_EROSION, "strata_contrast", KT_DOUBLE, E(strata_contrast), 0, 1, 0, 0, {0.5}},
    {SEC_EROSION, "hardness_noise", KT_DOUBLE, E(hardness_noise), 0, 1, 0, 0, {0}},
#undef E
};
_Static_assert(sizeof SCENE_KEYS / sizeof SCENE_KEYS[0] == SCENE_KEY_COUNT,
               "SCENE_KEY_COUNT counts the table");

const char *const SCENE_GENERATOR_NAMES[SCENE_GENERATOR_COUNT] = {
    "fbm", "hetero", "hybrid", "ridged", "midpoint", "fault", "subdivide", "file"};
const char *const SCENE_CAMERA_NAMES[SCENE_CAMERA_COUNT] = {"pinhole", "panorama"};
const char *const SCENE_NODATA_NAMES[SCENE_NODATA_COUNT] = {"fill", "sea"};
const char *const SCENE_FIRST_ROW_NAMES[SCENE_FIRST_ROW_COUNT] = {"auto", "north", "south"};

const char *tf_generator_name(enum tf_generator g)
{
    if ((int)g < 0 || (int)g >= SCENE_GENERATOR_COUNT)
        return "unknown";
    return SCENE_GENERATOR_NAMES[g];
}

int scene_find_key(enum section sec, const char *name)
{
    for (int i = 0; i < SCENE_KEY_COUNT; i++)
        if (SCENE_KEYS[i].section == sec && strcasecmp(SCENE_KEYS[i].name, name) == 0)
            return i;
    return -1;
}

int scene_key_index(enum section sec, const char *name)
{
    int i = scene_find_key(sec, name);
    if (i < 0)
        abort(); /* a name in this file that is not in SCENE_KEYS: a programming error */
    return i;
}

void *scene_field(tf_scene *s, int key)
{
    return (char *)s + SCENE_KEYS[key].offset;
}

const void *scene_cfield(const tf_scene *s, int key)
{
    return (const char *)s + SCENE_KEYS[key].offset;
}

int scene_key_silent(const tf_scene *s, int key)
{
    const struct key_def *k = &SCENE_KEYS[key];
    int silent = k->section == SEC_TERRAIN
                     ? !strcmp(k->name, "smooth") || !strcmp(k->name, "procedural") ||
                           !strcmp(k->name, "detail")
                     : k->section == SEC_ANIMATION && !strcmp(k->name, "erosion_steps");
    if (!silent)
        return 0;
    if (k->type == KT_DOUBLE)
        return *(const double *)scene_cfield(s, key) == k->def[0];
    return *(const int *)scene_cfield(s, key) == (int)k->def[0];
}

/* Keys that an animated camera or sun replaces: not required, and not allowed, when animated. */
int scene_replaced_by_animation(const tf_scene *s, int key)
{
    const struct key_def *k = &SCENE_KEYS[key];
    if (k->section == SEC_CAMERA && s->animation.ncamera > 0)
        return !strcmp(k->name, "position") || !strcmp(k->name, "look_at");
    if (k->section == SEC_SUN && s->animation.nsun > 0)
        return !strcmp(k->name, "azimuth") || !strcmp(k->name, "elevation");
    return 0;
}

/* Every key at its default: the table's, or zero (calloc'd) for lists and strings. */
void scene_set_defaults(tf_scene *s)
{
    for (int key = 0; key < SCENE_KEY_COUNT; key++) {
        const struct key_def *k = &SCENE_KEYS[key];
        void *dst = scene_field(s, key);
        int i = (int)k->def[0];
        switch (k->type) {
        case KT_INT:
        case KT_BOOL:
            *(int *)dst = i;
            break;
        case KT_U64:
            *(uint64_t *)dst = (uint64_t)k->def[0];
            break;
        case KT_DOUBLE:
            *(double *)dst = k->def[0];
            break;
        case KT_VEC3:
            *(tf_vec3 *)dst = v3(k->def[0], k->def[1], k->def[2]);
            break;
        case KT_GENERATOR:
        case KT_CAMERA:
        case KT_NODATA:
        case KT_FIRST_ROW:
            memcpy(dst, &i, sizeof i);
            break;
        case KT_ENVELOPE:
        case KT_CAMERA_KEY:
        case KT_SUN_KEY:
            break; /* calloc'd: all zero, no keys */
        case KT_PATH:
        case KT_SHA256:
            break; /* calloc'd: all zero, the empty string */
        }
    }
}
