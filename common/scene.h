/* scene.h: the parsed, validated scene.  A scene file (scenes/NAME.scene, INI syntax read with
 * inih) is the whole description of a render: image, camera, sun, sky, terrain generator,
 * materials, mist and antialiasing.  The coordinator parses it; forked workers inherit the
 * parsed struct; networked workers receive the text through the tuple space and parse it
 * themselves, so tf_scene_parse_text must give the same struct (and hash) for the same text.
 *
 * Units: world coordinates are metres-like scene units, x east, y north, z up.  The terrain
 * covers x, y in [0, terrain.extent]; heights are terrain.height_scale * (generator output).
 * Angles in the file are degrees. */
#ifndef TF_SCENE_H
#define TF_SCENE_H

#include <stddef.h>
#include <stdint.h>
#include "animation.h"
#include "vec.h"

enum tf_camera_kind { TF_CAMERA_PINHOLE, TF_CAMERA_PANORAMA };

enum tf_generator {
    TF_GEN_FBM,       /* homogeneous fBm (Musgrave 2.3.2.1) */
    TF_GEN_HETERO,    /* heterogeneous terrain, "statistics by altitude" (Musgrave 2.3.2) */
    TF_GEN_HYBRID,    /* hybrid multifractal (Musgrave 2.3.2) */
    TF_GEN_RIDGED,    /* ridged multifractal: hybrid with basis 1-|N| */
    TF_GEN_MIDPOINT,  /* diamond-square under Koh & Hearn's control envelope */
    TF_GEN_FAULT,     /* Krten's fault lines + wind / rain erosion filters */
    TF_GEN_SUBDIVIDE, /* Ammeter & Mikhailyuk recursive subdivision (M, E, W) */
};

#define TF_ENVELOPE_MAX 9 /* control grid up to 9x9 points (2^3+1) */

typedef struct tf_terrain {
    enum tf_generator generator;
    uint64_t seed;
    int size_exp;        /* height field has (2^size_exp + 1)^2 samples; 1..13 */
    double extent;       /* world size of the square terrain */
    double height_scale; /* world height of a generator output of 1.0 */

    /* procedural generators (fbm, hetero, hybrid, ridged) */
    double feature_size; /* world size of the lowest-frequency octave */
    double octaves;      /* may be fractional */
    double H;            /* fractal increment (roughness: higher is smoother) */
    double lacunarity;   /* frequency gap between octaves */
    double offset;       /* hetero / hybrid / ridged offset */
    double gain;         /* hybrid / ridged gain */

    /* midpoint displacement + Koh & Hearn envelope */
    double roughness;                 /* H of the displacement (amplitude ratio 2^-H per level) */
    int envelope_n;                   /* control points per side (2..9); 0 = no envelope */
    double envelope[TF_ENVELOPE_MAX * TF_ENVELOPE_MAX]; /* control elevations, row-major, y then x */
    double envelope_tolerance;        /* generated heights stay within control +- tolerance */

    /* Krten fault lines */
    int faults;          /* number of fault lines */
    double fault_step;   /* initial height step of a fault (decays over the faults) */
    int wind_passes;     /* two-pass wind erosion filter, repetitions */
    int rain_passes;     /* four-pass rain erosion filter, repetitions */
    double erosion_k;    /* filter coefficient (0..1) */

    /* Ammeter & Mikhailyuk subdivision */
    double sub_M, sub_E, sub_W;

    /* optional post-processes */
    int thermal_iterations; /* thermal weathering; 0 = off */
    double talus_deg;       /* talus angle for thermal weathering */
} tf_terrain;

typedef struct tf_scene {
    char *path;   /* file name, for messages ("<string>" when parsed from text) */
    char *text;   /* the scene file's full text, NUL-terminated (sent to networked workers) */
    size_t text_len;

    int width, height; /* [image] */

    struct {
        enum tf_camera_kind kind;
        tf_vec3 position, look_at, up;
        double fov_deg;      /* pinhole: horizontal field of view; panorama: horizontal sweep */
        double vfov_deg;     /* panorama: vertical field of view (0 = from aspect) */
    } camera;

    struct {
        double azimuth_deg;   /* compass direction towards the sun, 0 = +y (north), 90 = +x */
        double elevation_deg; /* above the horizon */
        tf_vec3 color;        /* linear RGB */
        double intensity;
    } sun;

    struct {
        tf_vec3 zenith, horizon; /* linear RGB of the sky gradient */
        double intensity;        /* ambient sky light on the terrain */
    } sky;

    tf_terrain terrain;

    struct {
        double sea_level;      /* world z of the water plane */
        double tree_line;      /* vegetation below this altitude */
        double snow_line;      /* snow above this altitude (perturbed by fBm) */
        double snow_jitter;    /* amplitude of the snow line perturbation, world units */
        double rock_slope_deg; /* slopes steeper than this are bare rock */
        double bump;           /* fBm bump-map strength (0 = off) */
    } materials;

    struct {
        int enabled;
        int homogeneous;       /* 1 = constant-density fog instead of exponential mist */
        double density;        /* extinction per unit distance at z = 0 */
        double falloff;        /* density halves every `falloff` world units of altitude (exp. mist) */
        tf_vec3 color;         /* in-scattered colour */
        tf_vec3 extinction;    /* per-channel relative extinction (Rayleigh-like: blue > red) */
    } mist;

    struct {
        double threshold;      /* per-channel contrast that triggers subdivision */
        int max_depth;         /* subdivision levels; 3 -> up to 8x8 subpixels, 81 samples */
    } antialias;

    /* [animation]: frames = 0 for a still.  An animated camera or sun replaces the [camera]
     * position / look_at / up / fov or the [sun] azimuth / elevation frame by frame
     * (tf_scene_apply_frame); after parsing those fields hold frame 0's values. */
    tf_animation animation;

    uint8_t hash[32];          /* SHA-256 of the canonical form (see tf_scene_canonical) */
    char hash_hex[65];
} tf_scene;

/* Parse a scene file.  On error returns NULL and writes one line "FILE:LINE: key: what is wrong"
 * to err (no trailing newline).  The result owns path and text. */
tf_scene *tf_scene_load(const char *path, char *err, size_t errlen);
/* Parse scene text; `name` is used in messages.  Same contract as tf_scene_load. */
tf_scene *tf_scene_parse_text(const char *name, const char *text, size_t len, char *err, size_t errlen);
void tf_scene_free(tf_scene *s);

/* Override the image size (render --size) and recompute the hash. */
void tf_scene_set_size(tf_scene *s, int width, int height);

/* Canonical text of the parsed scene: every field, fixed order, fixed formatting ("%.17g"),
 * independent of comments, spacing, key order and defaults spelled out or not.  The hash is
 * SHA-256 of it.  Returns a malloc'd string. */
char *tf_scene_canonical(const tf_scene *s);
void tf_scene_rehash(tf_scene *s);

const char *tf_generator_name(enum tf_generator g);

#endif
