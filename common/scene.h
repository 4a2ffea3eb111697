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
    TF_GEN_FILE,      /* a height map read from a raster file (terrain/heightmap_file.c) */
};

/* generator = file: what a nodata sample becomes */
enum tf_nodata { TF_NODATA_FILL, TF_NODATA_SEA };
/* generator = file: which edge the raster's first row is (auto: north unless the
 * georeferencing says the rows run south to north) */
enum tf_first_row { TF_FIRST_ROW_AUTO, TF_FIRST_ROW_NORTH, TF_FIRST_ROW_SOUTH };

#define TF_SCENE_PATH_MAX 192 /* a path value fits on one scene line (inih: 200 bytes a line) */

#define TF_ENVELOPE_MAX 9 /* control grid up to 9x9 points (2^3+1) */

/* [erosion]: Musgrave's fluvial erosion (2.4.1), dry creep (2.4.3) and layers (2.4.4), run on
 * the grid after the generator and thermal weathering (terrain/erosion.h; scenes/README.md). */
typedef struct tf_erosion_keys {
    int fluvial_steps;      /* time steps; 0 = no erosion */
    double capacity;        /* K_c: sediment a unit of moving water can carry */
    double deposition;      /* K_d: fraction of the suspended sediment settling each step */
    double softness;        /* K_s: fraction of a capacity deficit taken from the bedrock */
    double silt_softness;   /* softness of deposited silt, relative to the bedrock's */
    double talus_softness;  /* softness of talus (crept material), relative to the bedrock's */
    double rain;            /* metres of rain per vertex per rain event */
    int rain_interval;      /* steps between rain events */
    double rain_altitude;   /* rain multiplier grows linearly: 1 + rain_altitude at the top */
    double rain_noise;      /* 0: steady; > 0: 1/f-distributed storm sizes of this spread */
    double evaporation;     /* fraction of each vertex's water evaporating per step */
    double creep;           /* c_d: diffusive creep coefficient per step (0..0.125) */
    double strata;          /* bedrock strata thickness in metres; 0 = uniform */
    double strata_contrast; /* 0..1: softness of the hardest stratum is 1 - contrast */
    double hardness_noise;  /* 0..1: a fractal field of bedrock hardness of this amplitude */
} tf_erosion_keys;

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

    /* procedural = yes: a point generator evaluated where rays need it, at the level of detail
     * of the pixel footprint, with no grid and no size cap (terrain/procedural.h) */
    int procedural;
    double detail;          /* procedural over a grid or height map: metres of the first
                             * detail octave (wavelength two cells; terrain/procedural.h) */

    /* shading of the grid's triangles (render/shade.h): 0 = flat-lit triangles near the
     * terminator (the sun test and the shadow ray's start by the triangle's own normal, the
     * look of every scene before the key), 1 = smooth: both by the interpolated normal, as
     * POV-Ray's height_field { smooth } */
    int smooth;

    tf_erosion_keys erosion;

    /* generator = file (terrain/heightmap_file.c; scenes/README.md) */
    char file_path[TF_SCENE_PATH_MAX]; /* as written; relative to the scene file's folder */
    char file_sha256[65];   /* hex SHA-256 of the file: pinned by the scene, or set on load */
    double vertical_scale;  /* world height = raster value * vertical_scale + vertical_offset */
    double vertical_offset;
    int nodata;             /* enum tf_nodata */
    int first_row;          /* enum tf_first_row */
    int crop_x, crop_y;     /* crop window in raster pixels; width/height 0 = to the edge */
    int crop_width, crop_height;
    /* Not part of the file format: the height map's bytes, borrowed from the tf_scene that
     * owns them (tf_scene_load reads them; a networked worker receives them, see
     * heightmap_tuples.h), its name for messages, and the sea level for nodata = sea. */
    const uint8_t *file_bytes;
    size_t file_len;
    const char *file_name;
    double file_sea_level;
    /* Not part of the file format: the eroded terrain's blob (terrain/eroded.h), borrowed from
     * the tf_scene that owns it, when the coordinator has it: then nothing is generated or
     * eroded here, the blob is checked and used. */
    const uint8_t *eroded_bytes;
    size_t eroded_len;
    const char *eroded_from;
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
    /* generator = file: the height map's bytes (terrain.file_bytes borrows them) and where
     * they came from (the path resolved against the scene's folder, or the coordinator). */
    uint8_t *heightmap;
    size_t heightmap_len;
    char *heightmap_name;
    /* [erosion]: the eroded terrain's blob (terrain.eroded_bytes borrows it), see
     * tf_scene_attach_eroded */
    uint8_t *eroded;
    size_t eroded_len;
    char *eroded_from;

    uint8_t hash[32];          /* SHA-256 of the canonical form (see tf_scene_canonical) */
    char hash_hex[65];
} tf_scene;

/* Parse a scene file.  On error returns NULL and writes one line "FILE:LINE: key: what is wrong"
 * to err (no trailing newline).  The result owns path and text. */
tf_scene *tf_scene_load(const char *path, char *err, size_t errlen);
/* Largest height map file tf_scene_load reads (generator = file). */
#define TF_HEIGHTMAP_MAX_BYTES ((size_t)512 << 20)

/* Parse scene text; `name` is used in messages.  Same contract as tf_scene_load, except that a
 * generator = file scene gets no height map bytes: tf_scene_load reads them from the file, a
 * networked worker receives them and calls tf_scene_attach_heightmap. */
tf_scene *tf_scene_parse_text(const char *name, const char *text, size_t len, char *err, size_t errlen);
void tf_scene_free(tf_scene *s);

/* Give a generator = file scene its height map: takes ownership of bytes (malloc'd, len
 * bytes), named `name` in messages.  Their SHA-256 becomes terrain.file_sha256 and enters the
 * scene hash; if the scene pins a sha256 that differs, fails with one line in err (bytes are
 * freed either way on failure).  Returns 0 or -1. */
int tf_scene_attach_heightmap(tf_scene *s, uint8_t *bytes, size_t len, const char *name,
                              char *err, size_t errlen);

/* Give an [erosion] scene its eroded terrain's blob (terrain/eroded.h): takes ownership of
 * bytes (malloc'd); `from` names it in messages.  It is checked against the scene when the
 * terrain is built.  Returns 0, or -1 on out of memory (bytes freed). */
int tf_scene_attach_eroded(tf_scene *s, uint8_t *bytes, size_t len, const char *from);

/* Override the image size (render --size) and recompute the hash. */
void tf_scene_set_size(tf_scene *s, int width, int height);

/* Canonical text of the parsed scene: every field, fixed order, fixed formatting ("%.17g"),
 * independent of comments, spacing, key order and defaults spelled out or not.  The hash is
 * SHA-256 of it.  Returns a malloc'd string. */
char *tf_scene_canonical(const tf_scene *s);
void tf_scene_rehash(tf_scene *s);
/* The canonical text of the [terrain] and [erosion] sections only: what determines the
 * terrain's heights (terrain/eroded.h keys its cache with it). */
char *tf_scene_canonical_terrain(const tf_scene *s);

const char *tf_generator_name(enum tf_generator g);

/* Set s's camera and sun to those of frame f (whatever is animated; the rest unchanged).  The
 * scene hash is not changed: a frame belongs to its sequence's scene. */
void tf_scene_apply_frame(tf_scene *s, int f);
/* A copy of s (own path and text; a generator = file height map stays s's, borrowed, so s must
 * outlive the copy) with frame f's camera and sun, for a renderer of that frame.  NULL on out
 * of memory.  Free with tf_scene_free. */
tf_scene *tf_scene_at_frame(const tf_scene *s, int f);
/* Raypaint's view: set s's camera, sun and mist to view's (everything a paint view may edit;
 * the terrain, materials and image stay s's).  The hash is not changed (tf_scene_rehash). */
void tf_scene_set_view(tf_scene *s, const tf_scene *view);

#endif
