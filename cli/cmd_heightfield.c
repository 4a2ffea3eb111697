/* cmd_heightfield.c: `terrafarm heightfield SCENE -o FILE.png|.exr|.tif`: export the scene's
 * terrain heights, the same samples the renderer traces (tf_terrain_heights, the first half of
 * tf_heightfield_build; the max/min grids are not needed here, which saves their memory).
 *
 * PNG: 16-bit grayscale, [hmin, hmax] mapped linearly to 0..65535.  EXR: one FLOAT channel "Y"
 * of world heights.  GeoTIFF (geotiff_write.h): Float32 world heights, north-up with a
 * geotransform (and a CRS with --srs), the way GIS tools and real DEMs have them.  Row order in
 * PNG and EXR: image row r holds terrain row j = r, i.e. world
 * y = r * cell, so row 0 is the NEAR (south, y = 0) edge and the last row the far edge; image
 * column c is world x = c * cell.  That order is chosen for POV-Ray: its height_field puts the
 * image's last row at local z = 0 and splits each cell along the (x+1, z)-(x, z+1) diagonal;
 * mirrored in z by the printed transform, that split becomes terrafarm's own (ci, cj)-(ci+1,
 * cj+1) diagonal, so POV-Ray traces exactly the triangles the terrafarm tracer does.
 *
 * Every format also records what generator = file needs to read it back as this terrain
 * (terrain/raster.h's TF_RASTER_KEY_*: which edge the first row is, the extent, how values
 * become heights) in the file itself: EXR string attributes, PNG text chunks, GeoTIFF
 * metadata.  A scene with only `generator = file` and `path` re-imports the same heights. */
#include <getopt.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include <jansson.h>

#include "cli/commands.h"
#include "coordinator/erosion/erosion_farm.h"
#include "linda/auth.h"
#include "linda/sock.h"
#include "terrain/drainage.h"
#include "terrain/eroded.h"
#include "image/exrfile.h"
#include "image/geotiff_write.h"
#include "log.h"
#include "image/png_write.h"
#include "scene.h"
#include "terrain/raster.h"
#include "terrain/terrain_build.h"

static const char usage[] =
    "usage: terrafarm heightfield SCENE -o FILE.png|FILE.exr|FILE.tif [-j N] [--size-exp K]\n"
    "                             [--srs SRS] [--origin EAST,NORTH] [--stats FILE.json]\n"
    "                             [--maps PREFIX] [--halo K]\n"
    "\n"
    "Export the terrain of SCENE as a height field image.\n"
    "\n"
    "  -o, --output FILE     FILE.png: 16-bit grayscale, the height range [hmin, hmax]\n"
    "                        mapped to 0..65535 (readable by POV-Ray's height_field);\n"
    "                        FILE.exr: one float channel Y of world heights (with\n"
    "                        [erosion] also water, silt and flow, world metres);\n"
    "                        FILE.tif: a Float32 GeoTIFF of world heights, north-up (its\n"
    "                        first row is the far edge), georeferenced\n"
    "      --srs SRS         GeoTIFF: its CRS, e.g. EPSG:32632 (default: none, only the\n"
    "                        geotransform); world units are then the CRS's metres\n"
    "      --origin E,N      GeoTIFF: easting and northing of sample (0, 0) (default 0,0)\n"
    "  -j, --workers N       threads for the terrain synthesis; with [erosion], the erosion\n"
    "                        runs on N forked workers, one patch each, exchanging their\n"
    "                        edges through the tuple space (default: in this process, on\n"
    "                        every core)\n"
    "      --threads N       threads for the terrain synthesis; [erosion] in this process\n"
    "      --halo K          erosion: steps between edge exchanges, K rows each (default 12)\n"
    "      --remote M        erosion: M more patches for networked workers (terrafarm worker\n"
    "                        --connect HOST:PORT), who read the scene and derive the start\n"
    "      --listen ADDR     where they connect (default 127.0.0.1:7879; port 0: any)\n"
    "      --secret-file F   their shared secret (needed off loopback)\n"
    "      --stats FILE      write JSON: erosion_vertex_steps_per_s, seconds, the mass\n"
    "                        balance, pits and the largest basin before and after\n"
    "      --maps PREFIX     erosion: also write PREFIX-water.exr, PREFIX-silt.exr and\n"
    "                        PREFIX-flow.exr (world metres, rows as the heights)\n"
    "  -k, --size-exp K      override the scene's size_exp: (2^K + 1)^2 samples, K in 1..13\n"
    "  -h, --help            this text\n"
    "\n"
    "Orientation: image column c is world x = c * cell; image row r is world y = r * cell, so\n"
    "row 0 (the top of the image) is the NEAR edge y = 0 and the last row the far edge\n"
    "y = extent (north is at the bottom).  Printed after writing: the world extent, the height\n"
    "range, and the POV-Ray transform that places the PNG exactly on the terrain (POV-Ray's y\n"
    "is up and its z is terrafarm's y; the negative z scale undoes POV-Ray's bottom-row-first\n"
    "reading and makes its triangle split equal terrafarm's).\n"
    "\n"
    "An eroded terrain is cached under .terrafarm-cache/ beside FILE, by the hash of the\n"
    "scene's [terrain] and [erosion] (TF_EROSION_CACHE=DIR or off overrides): a second run,\n"
    "or a render of the same terrain, does no erosion.\n"
    "\n"
    "The file records its first row's edge, its extent and how its values become heights\n"
    "(terrafarm.* attributes, text chunks or metadata), so a scene's [terrain] with only\n"
    "generator = file and path = FILE reads these heights back.\n";

struct hf_options {
    const char *scene_path;
    const char *output;
    int threads;
    int size_exp; /* 0 = the scene's */
    const char *srs;
    double east0, north0;
    int workers; /* -j given: erosion on this many forked workers */
    int halo;
    const char *stats, *maps;
    int remote;  /* --remote: this many networked erosion workers */
    const char *listen, *secret_file;
};

static int ends_with(const char *s, const char *suffix)
{
    size_t ls = strlen(s), lf = strlen(suffix);
    return ls >= lf && strcasecmp(s + ls - lf, suffix) == 0;
}

/* Parse a whole decimal integer in [lo, hi]; 0 on success. */
static int parse_int(const char *text, int lo, int hi, int *out)
{
    char *end;
    long v = strtol(text, &end, 10);
    if (end == text || *end != '\0' || v < lo || v > hi)
        return -1;
    *out = (int)v;
    return 0;
}

static const struct option longopts[] = {
    {"output", required_argument, NULL, 'o'},   {"threads", required_argument, NULL, 't'},
    {"size-exp", required_argument, NULL, 'k'}, {"help", no_argument, NULL, 'h'},
    {"srs", required_argument, NULL, 's'},      {"origin", required_argument, NULL, 'O'},
    {"workers", required_argument, NULL, 'j'},  {"halo", required_argument, NULL, 'H'},
    {"stats", required_argument, NULL, 'S'},    {"maps", required_argument, NULL, 'M'},
    {"remote", required_argument, NULL, 'R'},   {"listen", required_argument, NULL, 'L'},
    {"secret-file", required_argument, NULL, 'F'},
    {NULL, 0, NULL, 0},
};

/* An integer option from lo to hi into *out: 0, or -1 after saying what it wants. */
static int int_option(const char *flag, const char *arg, int lo, int hi, int *out)
{
    if (parse_int(arg, lo, hi, out) == 0)
        return 0;
    tf_error("heightfield: %s wants an integer %d..%d, not '%s'", flag, lo, hi, arg);
    return -1;
}

/* --origin EAST,NORTH: two finite numbers.  0, or -1 after saying so. */
static int origin_option(const char *arg, struct hf_options *o)
{
    char *end;
    o->east0 = strtod(arg, &end);
    if (end != arg && *end == ',' && (o->north0 = strtod(end + 1, &end), *end == '\0') &&
        isfinite(o->east0) && isfinite(o->north0))
        return 0;
    tf_error("heightfield: --origin wants EAST,NORTH (two numbers), not '%s'", arg);
    return -1;
}

/* One option into o: 0, or -1 after saying why not. */
static int hf_option(struct hf_options *o, int c, const char *arg)
{
    switch (c) {
    case 'o': o->output = arg; return 0;
    case 's': o->srs = arg; return 0;
    case 'S': o->stats = arg; return 0;
    case 'L': o->listen = arg; return 0;
    case 'F': o->secret_file = arg; return 0;
    case 'M': o->maps = arg; return 0;
    case 'O': return origin_option(arg, o);
    case 'H': return int_option("--halo", arg, 1, 1024, &o->halo);
    case 'R': return int_option("--remote", arg, 1, 1024, &o->remote);
    case 'k': return int_option("--size-exp", arg, 1, TF_TERRAIN_MAX_SIZE_EXP, &o->size_exp);
    default: /* 't', 'j' */
        if (int_option("-j", arg, 0, 1024, &o->threads))
            return -1;
        o->workers = c == 'j' ? o->threads : 0;
        return 0;
    }
}

/* What the options say together: one SCENE, -o with a known extension, --remote's needs. */
static int check_options(struct hf_options *o)
{
    if (o->remote > 0 && !o->listen)
        o->listen = "127.0.0.1:7879";
    if (o->remote > 0 && o->size_exp) {
        tf_error("heightfield: --remote with --size-exp: networked workers erode the scene's "
                 "own size_exp; set it in the scene");
        return -1;
    }
    if (!o->output) {
        tf_error("heightfield: -o FILE.png, -o FILE.exr or -o FILE.tif is required");
        return -1;
    }
    if (!ends_with(o->output, ".png") && !ends_with(o->output, ".exr") &&
        !ends_with(o->output, ".tif") && !ends_with(o->output, ".tiff")) {
        tf_error("heightfield: output '%s' must end in .png, .exr or .tif", o->output);
        return -1;
    }
    return 0;
}

/* Returns -1 to continue, else the exit status (help, usage error). */
static int parse_options(int argc, char **argv, struct hf_options *o)
{
    memset(o, 0, sizeof *o);
    opterr = 0;
    optind = 1;
    int c;
    while ((c = getopt_long(argc, argv, ":o:t:j:k:h", longopts, NULL)) != -1) {
        if (c == 'h') {
            fputs(usage, stdout);
            return TF_EXIT_OK;
        }
        if (c == ':' || c == '?') {
            tf_error(c == ':' ? "heightfield: option '%s' needs a value"
                              : "heightfield: unknown option '%s' (try 'terrafarm heightfield "
                                "--help')",
                     argv[optind - 1]);
            return TF_EXIT_USAGE;
        }
        if (hf_option(o, c, optarg))
            return TF_EXIT_USAGE;
    }
    if (optind != argc - 1) {
        tf_error("heightfield: expected exactly one SCENE argument (try 'terrafarm heightfield "
                 "--help')");
        return TF_EXIT_USAGE;
    }
    o->scene_path = argv[optind];
    return check_options(o) ? TF_EXIT_USAGE : -1;
}

/* What a file says of itself, as name, value pairs for the writers. */
typedef struct hf_meta {
    char extent[32], scale[32], offset[32];
    const char *items[9];
} hf_meta;

static const char *const *describe(hf_meta *m, const char *first_row, double extent,
                                   double scale, double offset)
{
    snprintf(m->extent, sizeof m->extent, "%.17g", extent);
    snprintf(m->scale, sizeof m->scale, "%.17g", scale);
    snprintf(m->offset, sizeof m->offset, "%.17g", offset);
    const char *items[9] = {TF_RASTER_KEY_FIRST_ROW, first_row, TF_RASTER_KEY_EXTENT,
                            m->extent, TF_RASTER_KEY_VERTICAL_SCALE, m->scale,
                            TF_RASTER_KEY_VERTICAL_OFFSET, m->offset, NULL};
    memcpy(m->items, items, sizeof items);
    return m->items;
}

static void height_range(const float *h, size_t count, float *lo, float *hi)
{
    *lo = *hi = h[0];
    for (size_t i = 1; i < count; i++) {
        if (h[i] < *lo) *lo = h[i];
        if (h[i] > *hi) *hi = h[i];
    }
}

/* Its text chunks meta (name, value, ..., NULL) to w; 0 or -1. */
static int png_texts(tf_png_writer *w, const char *const *meta, char *err, size_t errlen)
{
    for (int i = 0; meta[i]; i += 2)
        if (tf_png_text(w, meta[i], meta[i + 1], err, errlen) != 0)
            return -1;
    return 0;
}

/* 16-bit PNG, row r = terrain row r, with its text chunks meta.  0 on success. */
static int write_png(const char *path, const float *h, int n, float lo, float hi,
                     const char *const *meta, char *err, size_t errlen)
{
    uint16_t *row = malloc((size_t)n * sizeof *row);
    if (!row) {
        tf_seterr(err, errlen, "out of memory for a PNG row");
        return -1;
    }
    tf_png_writer *w = tf_png_create(path, n, n, 16, 1, err, errlen);
    if (w && png_texts(w, meta, err, errlen) != 0) {
        tf_png_abort(w);
        w = NULL;
    }
    if (!w) {
        free(row);
        return -1;
    }
    /* A flat terrain maps every sample to 0. */
    double range = (double)hi - (double)lo;
    double to_code = range > 0.0 ? 65535.0 / range : 0.0;
    for (int j = 0; j < n; j++) {
        const float *src = h + (size_t)j * (size_t)n;
        for (int i = 0; i < n; i++) {
            double code = ((double)src[i] - (double)lo) * to_code + 0.5;
            row[i] = (uint16_t)(code < 0.0 ? 0.0 : code > 65535.0 ? 65535.0 : code);
        }
        if (tf_png_write_row(w, row, err, errlen) != 0) {
            tf_png_abort(w);
            free(row);
            return -1;
        }
    }
    free(row);
    return tf_png_finish(w, err, errlen);
}

static void print_placement(const char *path, int n, double extent, float lo, float hi, int png,
                            int tif)
{
    double range = (double)hi - (double)lo;
    printf("wrote %s: %dx%d samples, cell %.9g\n", path, n, n, extent / (n - 1));
    printf("world extent: x, y in [0, %.9g]\n", extent);
    printf("height range: [%.9g, %.9g] (hmin, hmax)\n", (double)lo, (double)hi);
    if (tif) {
        printf("GeoTIFF band 1 holds world heights, north-up (first row = far edge y = %.9g)\n",
               extent);
        return;
    }
    if (!png) {
        printf("EXR channel Y holds world heights; row r is world y = r * cell (row 0 = y 0)\n");
        return;
    }
    printf("PNG code v in 0..65535 is height hmin + v / 65535 * (hmax - hmin); row r is world "
           "y = r * cell (row 0 = y 0)\n");
    /* POV-Ray reads a 16-bit value v as local height v / 65536, so the y scale that lands
     * v = 65535 exactly on hmax is range * 65536 / 65535. */
    printf("POV-Ray (y up, z = terrafarm y; sample (i, j) lands at <i*cell, h, j*cell>):\n");
    printf("  height_field { png \"%s\"\n", path);
    printf("    scale <%.9g, %.9g, %.9g>\n", extent, range * 65536.0 / 65535.0, -extent);
    printf("    translate <0, %.9g, %.9g> }\n", (double)lo, extent);
}

/* ---- erosion: where it runs, its cache, its maps and its figures ---------------------- */

typedef struct erosion_run {
    tf_eroded_maps maps;
    tf_erosion_report rep;
    tf_erosion_farm_report farm;
} erosion_run;

/* The networked workers' key: a secret file, or none on a loopback address. */
static int erosion_key(const struct hf_options *o, uint8_t *key, const uint8_t **out, char *err,
                       size_t errlen)
{
    *out = NULL;
    if (o->secret_file) {
        if (tf_auth_init() || tf_secret_load(o->secret_file, key, err, errlen))
            return -1;
        *out = key;
    } else if (!tf_listen_is_loopback(o->listen)) {
        return tf_seterr(err, errlen, "--listen %s is not a loopback address: networked "
                         "workers there need --secret-file FILE", o->listen);
    }
    return 0;
}

/* The heights: with -j (or --remote) and [erosion], eroded on the farm; else in this
 * process.  s's terrain is t (its size_exp may be overridden: then no networked worker). */
static float *heights(const struct hf_options *o, const tf_scene *s, const tf_terrain *t,
                      double *extent, erosion_run *er, char *err, size_t errlen)
{
    if (t->erosion.fluvial_steps <= 0 || (o->workers <= 0 && o->remote <= 0))
        return tf_terrain_heights_maps(t, o->threads, extent, &er->maps, &er->rep, err, errlen);
    uint8_t key[32];
    tf_erosion_farm_opts fo = {o->workers, o->remote, o->halo, o->listen, NULL};
    if (o->remote > 0 && erosion_key(o, key, &fo.key, err, errlen) != 0)
        return NULL;
    uint8_t *blob;
    size_t len;
    if (tf_erosion_farm(s, &fo, &blob, &len, &er->rep, &er->farm, err, errlen) != 0)
        return NULL;
    tf_terrain with = *t;
    with.eroded_bytes = blob;
    with.eroded_len = len;
    with.eroded_from = "the erosion farm";
    float *h = tf_terrain_heights_maps(&with, o->threads, extent, &er->maps, NULL, err, errlen);
    free(blob);
    return h;
}

static int write_maps(const char *prefix, int n, const tf_eroded_maps *m, char *err,
                      size_t errlen)
{
    const char *names[3] = {"water", "silt", "flow"};
    const float *maps[3] = {m->water, m->silt, m->flow};
    for (int k = 0; k < 3; k++) {
        char path[600];
        snprintf(path, sizeof path, "%s-%s.exr", prefix, names[k]);
        if (!maps[k] || tf_exr_write_gray_attrs(path, n, n, maps[k], NULL, err, errlen) != 0)
            return maps[k] ? -1 : tf_seterr(err, errlen, "no %s map", names[k]);
        printf("wrote %s\n", path);
    }
    return 0;
}

/* Pits and the largest basin of t's heights before erosion and of h after. */
static int drainage(const tf_terrain *t, int n, const float *after, tf_drainage *before,
                    tf_drainage *now, char *err, size_t errlen)
{
    tf_terrain raw = *t;
    raw.erosion.fluvial_steps = 0;
    float *h = tf_terrain_heights(&raw, 0, NULL, err, errlen);
    if (!h)
        return -1;
    int rc = tf_drainage_measure(h, n, before) | tf_drainage_measure(after, n, now);
    free(h);
    return rc ? tf_seterr(err, errlen, "out of memory measuring drainage") : 0;
}

static int write_stats(const char *path, const tf_terrain *t, int n, const erosion_run *er,
                       const tf_drainage *before, const tf_drainage *after, char *err,
                       size_t errlen)
{
    const tf_erosion_report *r = &er->rep;
    double rate = r->seconds > 0 ? r->vertex_steps / r->seconds : 0;
    int64_t balance = r->solid_after + r->tally.out_load - r->solid_before;
    json_t *doc = json_pack(
        "{s:i, s:i, s:b, s:s, s:f, s:f, s:f, s:i, s:i, s:i, s:i, s:f, s:I, s:I, s:I, s:I, s:I,"
        " s:I, s:f, s:I, s:I, s:f, s:f}",
        "n", n, "fluvial_steps", t->erosion.fluvial_steps, "from_cache", r->from_cache,
        "isa", r->isa ? r->isa : "", "erosion_seconds", r->seconds,
        "erosion_vertex_steps_per_s", rate, "erosion_vertex_steps", r->vertex_steps,
        "workers", er->farm.workers, "patches_x", er->farm.px, "patches_y", er->farm.py,
        "halo", er->farm.halo, "edge_bytes_per_step", er->farm.edge_bytes_per_step,
        "rain_quanta", (json_int_t)r->tally.rain, "evaporated_quanta",
        (json_int_t)r->tally.evaporated, "outflow_water_quanta", (json_int_t)r->tally.out_water,
        "outflow_load_quanta", (json_int_t)r->tally.out_load, "solid_before_quanta",
        (json_int_t)r->solid_before, "mass_balance_quanta", (json_int_t)balance,
        "quantum_m", r->quantum, "pits_before", (json_int_t)before->pits, "pits_after",
        (json_int_t)after->pits, "largest_basin_share_before", before->largest_basin_share,
        "largest_basin_share_after", after->largest_basin_share);
    int rc = doc && json_dump_file(doc, path, JSON_INDENT(2)) == 0 ? 0 : -1;
    json_decref(doc);
    return rc ? tf_seterr(err, errlen, "%s: cannot write the statistics", path) : 0;
}

/* EXR: channel Y, and with erosion's maps also flow, silt and water (world metres). */
static int write_exr(const char *path, int n, const float *h, const tf_eroded_maps *m,
                     const char *const *meta, char *err, size_t errlen)
{
    if (!m->water)
        return tf_exr_write_gray_attrs(path, n, n, h, meta, err, errlen);
    const char *names[4] = {"Y", "flow", "silt", "water"}; /* sorted, as OpenEXR lists them */
    const float *planes[4] = {h, m->flow, m->silt, m->water};
    return tf_exr_write_planes(path, n, n, names, planes, 4, meta, err, errlen);
}

/* The maps and the statistics of the eroded heights h. */
static int erosion_outputs(const struct hf_options *o, const tf_terrain *t, int n,
                           const float *h, const erosion_run *er, char *err, size_t errlen)
{
    if (o->maps && write_maps(o->maps, n, &er->maps, err, errlen) != 0)
        return -1;
    if (!o->stats)
        return 0;
    tf_drainage before, after;
    if (drainage(t, n, h, &before, &after, err, errlen) != 0)
        return -1;
    return write_stats(o->stats, t, n, er, &before, &after, err, errlen);
}

int cmd_heightfield(int argc, char **argv)
{
    struct hf_options o;
    int status = parse_options(argc, argv, &o);
    if (status >= 0)
        return status;

    char err[512];
    tf_scene *scene = tf_scene_load(o.scene_path, err, sizeof err);
    if (!scene) {
        tf_error("%s", err);
        return TF_EXIT_FAIL;
    }
    if (o.size_exp) /* the farm erodes the scene's terrain: the same size */
        scene->terrain.size_exp = o.size_exp;
    tf_terrain terrain = scene->terrain;
    int n = (1 << terrain.size_exp) + 1;

    double extent;
    tf_eroded_cache_beside(o.output);
    erosion_run er = {0};
    float *h = heights(&o, scene, &terrain, &extent, &er, err, sizeof err);
    if (!h) {
        tf_error("%s", err);
        tf_scene_free(scene);
        return TF_EXIT_FAIL;
    }
    float lo, hi;
    height_range(h, (size_t)n * (size_t)n, &lo, &hi);
    int png = ends_with(o.output, ".png");
    int tif = ends_with(o.output, ".tif") || ends_with(o.output, ".tiff");
    hf_meta m;
    double range = (double)hi - (double)lo;
    const char *const *meta = png ? describe(&m, "south", extent, range / 65535.0, lo)
                                  : describe(&m, tif ? "north" : "south", extent, 1, 0);
    int rc = png ? write_png(o.output, h, n, lo, hi, meta, err, sizeof err)
             : tif ? tf_geotiff_write_heights(o.output, n, h, extent / (n - 1), o.east0, o.north0,
                                              o.srs, meta, err, sizeof err)
                   : write_exr(o.output, n, h, &er.maps, meta, err, sizeof err);
    if (rc == 0)
        print_placement(o.output, n, extent, lo, hi, png, tif);
    if (rc == 0 && terrain.erosion.fluvial_steps > 0)
        rc = erosion_outputs(&o, &terrain, n, h, &er, err, sizeof err);
    free(h);
    tf_eroded_maps_free(&er.maps);
    tf_scene_free(scene);
    if (rc != 0) {
        tf_error("%s", err);
        return TF_EXIT_FAIL;
    }
    return TF_EXIT_OK;
}
