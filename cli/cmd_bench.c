/* cmd_bench.c: `terrafarm bench SCENE --workers 1,2,4`: speedup against worker count
 * (docs/contract.md section 6, "Targets").
 *
 * Each measurement is a real `terrafarm render` run as a child process (fork + exec of
 * /proc/self/exe) with --stats to a temporary directory, so the bench measures exactly what
 * users run, start-up included.  Every output image is compared with the first one (the
 * decomposition invariant: byte for byte when the layouts agree, else decoded pixel by pixel --
 * the default stamps, and so the tiles, follow the worker count).  For each worker
 * count the run with the median wall time of --repeat runs stands for it; the table gives
 * speedup and parallel efficiency against the smallest count, rays per second, the workers'
 * mean busy fraction, tasks re-dealt, and the external-sample overhead (camera rays traced
 * outside the tasks' own pixels / rays inside, Musgrave's "a few percent").
 *
 * On a procedural scene ([terrain] procedural = yes) the table has three more columns, from the
 * same median run's statistics: the terrain samples evaluated by all workers together, their
 * mean per worker, and the tile-cache evictions of all workers.  --terrain-cache and --affinity
 * are passed to every render, so a budget that one worker's view does not fit shows whether
 * adding workers makes the total fall (Musgrave A.7.2.3: a superlinear speedup).
 *
 * `terrafarm bench SCENE --cost-map OUT` instead measures the per-region cost of the scene
 * in-process and writes the cost map that simulated workers read (worker/simulate.h). */
#include <errno.h>
#include <jansson.h>
#include <getopt.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "cli/commands.h"
#include "terrain/heightfield.h"
#include "log.h"
#include "scene.h"
#include "worker/simulate.h"
#include "coordinator/render/tasks.h"
#include "image/exrfile.h"

#define MAX_COUNTS 64
#define MAX_REPEAT 100

static const char usage[] =
    "usage: terrafarm bench SCENE --workers 1,2,4 [options]\n"
    "       terrafarm bench SCENE --cost-map OUT [--grid GWxGH] [--size WxH]\n"
    "\n"
    "Render SCENE with each worker count (terrafarm render as a child process), check that\n"
    "every image is bit-identical, and print speedup, parallel efficiency, rays/s, the\n"
    "workers' mean busy fraction, tasks re-dealt and the external-sample overhead; on a\n"
    "procedural scene also the terrain samples evaluated (all workers, mean per worker) and\n"
    "the tile-cache evictions.\n"
    "\n"
    "  -j, -w, --workers LIST    comma-separated worker counts (default 1,2)\n"
    "  -r, --repeat R            runs per worker count; the median wall time counts (default 3)\n"
    "      --tasks SPEC          rows:K or stamps:WxH, passed to render\n"
    "      --watermark N         passed to render\n"
    "      --size WxH            override the scene's image size\n"
    "      --terrain-cache SIZE  passed to render: each worker's budget for procedural terrain\n"
    "      --affinity on|off     passed to render (default: render's, on)\n"
    "      --csv FILE            write the table as CSV\n"
    "      --plot FILE.svg|png   plot speedup and efficiency against workers (needs gnuplot)\n"
    "      --keep DIR            keep the images and statistics in DIR (default: a temporary\n"
    "                            directory, removed afterwards)\n"
    "      --cost-map OUT        measure the scene's cost per region instead and write the cost\n"
    "                            map for terrafarm worker --simulate\n"
    "      --grid GWxGH          cost map cells (default 48x27)\n"
    "  -q, --quiet               only the table\n"
    "  -h, --help                this help\n";

typedef struct bench_opts {
    const char *scene, *tasks, *watermark, *size, *csv, *plot, *keep, *cost_map;
    const char *terrain_cache, *affinity;
    int counts[MAX_COUNTS], ncounts;
    int repeat, grid_w, grid_h, quiet;
    int procedural; /* the scene's [terrain] procedural: the terrain columns are shown */
} bench_opts;

/* One render's figures, from its --stats JSON. */
typedef struct run_stats {
    double wall_s, rays, primary, external, redealt, busy_sum;
    double samples, evictions; /* procedural terrain, all workers */
    int nworkers;
} run_stats;

/* The figures of one worker count (its median run). */
typedef struct row {
    int workers;
    run_stats st;
    double speedup, efficiency, busy_fraction, rays_per_s, external_overhead;
} row;

/* ---- parsing ------------------------------------------------------------------------------- */

static int parse_counts(const char *text, bench_opts *o)
{
    const char *p = text;
    o->ncounts = 0;
    for (;;) {
        char *end;
        long v = strtol(p, &end, 10);
        if (end == p || v < 1 || v > 4096 || o->ncounts == MAX_COUNTS ||
            (*end && *end != ',')) {
            tf_error("--workers '%s': expected up to %d comma-separated counts from 1 to 4096",
                     text, MAX_COUNTS);
            return -1;
        }
        o->counts[o->ncounts++] = (int)v;
        if (!*end)
            return 0;
        p = end + 1;
    }
}

static int parse_wxh(const char *flag, const char *text, int lo, int hi, int *w, int *h)
{
    char *end;
    long a = strtol(text, &end, 10);
    if (end != text && (*end == 'x' || *end == 'X')) {
        const char *q = end + 1;
        long b = strtol(q, &end, 10);
        if (end != q && !*end && a >= lo && b >= lo && a <= hi && b <= hi) {
            *w = (int)a;
            *h = (int)b;
            return 0;
        }
    }
    tf_error("%s '%s': expected WxH with sides from %d to %d", flag, text, lo, hi);
    return -1;
}

enum { O_TASKS = 256, O_WATERMARK, O_SIZE, O_CSV, O_PLOT, O_KEEP, O_COST, O_GRID,
       O_TERRAIN_CACHE, O_AFFINITY };

static const struct option longopts[] = {
    {"workers", required_argument, NULL, 'w'}, {"repeat", required_argument, NULL, 'r'},
    {"tasks", required_argument, NULL, O_TASKS},
    {"watermark", required_argument, NULL, O_WATERMARK},
    {"size", required_argument, NULL, O_SIZE}, {"csv", required_argument, NULL, O_CSV},
    {"plot", required_argument, NULL, O_PLOT}, {"keep", required_argument, NULL, O_KEEP},
    {"cost-map", required_argument, NULL, O_COST}, {"grid", required_argument, NULL, O_GRID},
    {"terrain-cache", required_argument, NULL, O_TERRAIN_CACHE},
    {"affinity", required_argument, NULL, O_AFFINITY},
    {"quiet", no_argument, NULL, 'q'}, {"help", no_argument, NULL, 'h'},
    {NULL, 0, NULL, 0},
};

/* The options passed on to each render, checked here so that a bad one stops the bench before
 * its first render: 0, or -1 after saying why. */
static int render_option(bench_opts *o, int c, const char *arg)
{
    char err[256];
    tf_task_spec spec;
    size_t bytes;
    int w, h;
    switch (c) {
    case O_TASKS:
        if (tf_task_spec_parse(arg, &spec, err, sizeof err)) {
            tf_error("%s", err);
            return -1;
        }
        o->tasks = arg;
        return 0;
    case O_SIZE:
        o->size = arg;
        return parse_wxh("--size", arg, 1, 65536, &w, &h);
    case O_TERRAIN_CACHE:
        o->terrain_cache = arg;
        return tf_parse_byte_size("--terrain-cache", arg, &bytes) ? -1 : 0;
    case O_AFFINITY:
        if (strcmp(arg, "on") && strcmp(arg, "off")) {
            tf_error("--affinity '%s': expected on or off", arg);
            return -1;
        }
        o->affinity = arg;
        return 0;
    default: /* O_WATERMARK: render checks it */
        o->watermark = arg;
        return 0;
    }
}

/* One option into o: 0, or -1 after saying why not. */
static int bench_option(bench_opts *o, int c, const char *arg)
{
    char *end;
    switch (c) {
    case 'w':
    case 'j': /* -j as in render, worker and heightfield */
        return parse_counts(arg, o);
    case 'r':
        o->repeat = (int)strtol(arg, &end, 10);
        if (end == arg || *end || o->repeat < 1 || o->repeat > MAX_REPEAT) {
            tf_error("--repeat '%s': expected an integer from 1 to %d", arg, MAX_REPEAT);
            return -1;
        }
        return 0;
    case O_CSV: o->csv = arg; return 0;
    case O_PLOT: o->plot = arg; return 0;
    case O_KEEP: o->keep = arg; return 0;
    case O_COST: o->cost_map = arg; return 0;
    case O_GRID: return parse_wxh("--grid", arg, 1, TF_COST_MAP_MAX, &o->grid_w, &o->grid_h);
    case 'q': o->quiet = 1; return 0;
    default: return render_option(o, c, arg);
    }
}

/* 0 to run, 1 to exit successfully (--help), -1 on a usage error (already reported). */
static int parse_args(int argc, char **argv, bench_opts *o)
{
    *o = (bench_opts){.repeat = 3, .grid_w = 48, .grid_h = 27, .counts = {1, 2}, .ncounts = 2};
    int c;
    optind = 1;
    opterr = 0;
    while ((c = getopt_long(argc, argv, ":w:j:r:qh", longopts, NULL)) != -1) {
        if (c == 'h') {
            fputs(usage, stdout);
            return 1;
        }
        if (c == ':' || c == '?') {
            tf_error(c == ':' ? "bench: option '%s' needs a value (see terrafarm bench --help)"
                              : "bench: unknown option '%s' (see terrafarm bench --help)",
                     argv[optind - 1]);
            return -1;
        }
        if (bench_option(o, c, optarg))
            return -1;
    }
    if (optind != argc - 1) {
        tf_error(optind >= argc ? "bench: missing SCENE (see terrafarm bench --help)"
                                : "bench: expected one SCENE, got extra arguments");
        return -1;
    }
    o->scene = argv[optind];
    return 0;
}

/* ---- the cost map -------------------------------------------------------------------------- */

static int run_cost_map(const bench_opts *o)
{
    char err[1024];
    tf_scene *s = tf_scene_load(o->scene, err, sizeof err);
    if (!s) {
        tf_error("%s", err);
        return TF_EXIT_USAGE;
    }
    int w, h;
    if (o->size && parse_wxh("--size", o->size, 1, 65536, &w, &h) == 0)
        tf_scene_set_size(s, w, h);
    tf_heightfield *hf = tf_heightfield_build(s, 0, err, sizeof err);
    tf_cost_map m;
    int rc = TF_EXIT_FAIL;
    if (!hf || tf_cost_map_measure(s, hf, o->grid_w, o->grid_h, &m, err, sizeof err)) {
        tf_error("%s", err);
        goto out;
    }
    if (tf_cost_map_save(o->cost_map, &m, err, sizeof err) == 0) {
        double lo = m.density[0], hi = m.density[0];
        for (int k = 1; k < m.gw * m.gh; k++) {
            lo = m.density[k] < lo ? m.density[k] : lo;
            hi = m.density[k] > hi ? m.density[k] : hi;
        }
        printf("cost map %s: %dx%d cells of a %dx%d render, %.0f ns per average pixel, cell "
               "cost from %.2f to %.2f times the mean\n",
               o->cost_map, m.gw, m.gh, m.measured_w, m.measured_h, m.pixel_ns, lo, hi);
        rc = TF_EXIT_OK;
    } else {
        tf_error("%s", err);
    }
    tf_cost_map_free(&m);
out:
    tf_heightfield_free(hf);
    tf_scene_free(s);
    return rc;
}

/* ---- running renders ------------------------------------------------------------------------ */

/* Run `terrafarm render` with n workers into dir/out-n-r.{exr,json}.  0 or -1 (reported). */
static int run_render(const bench_opts *o, const char *dir, int n, int r, char *exr,
                      size_t exrlen, char *json, size_t jsonlen)
{
    char jobs[16];
    snprintf(jobs, sizeof jobs, "%d", n);
    snprintf(exr, exrlen, "%s/out-%d-%d.exr", dir, n, r);
    snprintf(json, jsonlen, "%s/out-%d-%d.json", dir, n, r);
    const char *args[28];
    int k = 0;
    args[k++] = "terrafarm";
    args[k++] = "render";
    args[k++] = o->scene;
    args[k++] = "-j";
    args[k++] = jobs;
    args[k++] = "-o";
    args[k++] = exr;
    args[k++] = "--stats";
    args[k++] = json;
    args[k++] = "--overwrite";
    args[k++] = "-q";
    args[k++] = "--http"; /* a measurement opens no dashboard */
    args[k++] = "none";
    if (o->tasks) {
        args[k++] = "--tasks";
        args[k++] = o->tasks;
    }
    if (o->watermark) {
        args[k++] = "--watermark";
        args[k++] = o->watermark;
    }
    if (o->size) {
        args[k++] = "--size";
        args[k++] = o->size;
    }
    if (o->terrain_cache) {
        args[k++] = "--terrain-cache";
        args[k++] = o->terrain_cache;
    }
    if (o->affinity) {
        args[k++] = "--affinity";
        args[k++] = o->affinity;
    }
    args[k] = NULL;
    fflush(NULL);
    pid_t pid = fork();
    if (pid < 0) {
        tf_error("bench: cannot fork a render: %s", strerror(errno));
        return -1;
    }
    if (pid == 0) {
        execv("/proc/self/exe", (char *const *)args);
        fprintf(stderr, "terrafarm: bench: cannot run /proc/self/exe: %s\n", strerror(errno));
        _exit(127);
    }
    int status;
    while (waitpid(pid, &status, 0) < 0)
        if (errno != EINTR) {
            tf_error("bench: waitpid: %s", strerror(errno));
            return -1;
        }
    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
        tf_error("bench: the render with %d worker%s failed (see the message above)", n,
                 n == 1 ? "" : "s");
        return -1;
    }
    return 0;
}

/* One number of the statistics; 0, or -1 if it is missing or not a number. */
static int stat_number(json_t *doc, const char *key, double *out)
{
    json_t *v = json_object_get(doc, key);
    if (!json_is_number(v))
        return -1;
    *out = json_number_value(v);
    return 0;
}

static int read_stats(const char *path, int procedural, run_stats *st)
{
    memset(st, 0, sizeof *st);
    json_error_t jerr;
    json_t *doc = json_load_file(path, JSON_REJECT_DUPLICATES, &jerr);
    if (!doc) {
        tf_error("bench: cannot read the statistics %s: line %d: %s", path, jerr.line, jerr.text);
        return -1;
    }
    int bad = !json_is_object(doc) || stat_number(doc, "wall_s", &st->wall_s) ||
              stat_number(doc, "rays_total", &st->rays) ||
              stat_number(doc, "primary_rays", &st->primary) ||
              stat_number(doc, "external_rays", &st->external) ||
              stat_number(doc, "tasks_redealt", &st->redealt) ||
              (procedural && stat_number(doc, "terrain_samples_evaluated", &st->samples));
    json_t *workers = json_object_get(doc, "workers");
    size_t i;
    json_t *w;
    bad |= !json_is_array(workers);
    json_array_foreach(workers, i, w) {
        double busy;
        if (stat_number(w, "busy_s", &busy)) {
            bad = 1;
            break;
        }
        st->busy_sum += busy;
        st->nworkers++;
        double evictions;
        if (procedural) {
            if (stat_number(w, "cache_evictions", &evictions)) {
                bad = 1;
                break;
            }
            st->evictions += evictions;
        }
    }
    json_decref(doc);
    if (bad || st->wall_s <= 0) {
        tf_error("bench: %s lacks the statistics the bench needs (wall_s, rays_total, ...)",
                 path);
        return -1;
    }
    return 0;
}

/* 1 identical, 0 different, -1 unreadable. */
static int same_bytes(const char *a, const char *b)
{
    FILE *fa = fopen(a, "rb"), *fb = fopen(b, "rb");
    int same = fa && fb ? 1 : -1;
    static char ba[1 << 16], bb[1 << 16];
    while (same == 1) {
        size_t na = fread(ba, 1, sizeof ba, fa), nb = fread(bb, 1, sizeof bb, fb);
        if (na != nb || memcmp(ba, bb, na))
            same = 0;
        else if (na == 0)
            break;
    }
    if (fa)
        fclose(fa);
    if (fb)
        fclose(fb);
    return same;
}

/* Decoded pixels, for images whose layouts differ (the default stamps, hence the tile size,
 * follow the worker count).  Image a is held whole; b is streamed against it. */
typedef struct pixel_cmp {
    tf_exr_meta meta;
    tf_pixel *px;
    int differ;
} pixel_cmp;

static int keep_row(void *user, int y, const tf_pixel *row)
{
    pixel_cmp *c = user;
    if (!c->px && !(c->px = calloc((size_t)c->meta.width * (size_t)c->meta.height, sizeof *row)))
        return -1;
    memcpy(c->px + (size_t)y * (size_t)c->meta.width, row, (size_t)c->meta.width * sizeof *row);
    return 0;
}

static int check_row(void *user, int y, const tf_pixel *row)
{
    pixel_cmp *c = user;
    if (memcmp(c->px + (size_t)y * (size_t)c->meta.width, row,
               (size_t)c->meta.width * sizeof *row))
        c->differ = 1;
    return c->differ;
}

/* 1 identical pixels, 0 different, -1 unreadable. */
static int same_pixels(const char *a, const char *b)
{
    pixel_cmp c;
    memset(&c, 0, sizeof c);
    tf_exr_meta mb;
    int rows_a = 0, rows_b = 0;
    char err[512];
    int rc = -1;
    if (tf_exr_read_rows(a, &c.meta, &rows_a, keep_row, &c, err, sizeof err) == 0 &&
        rows_a == c.meta.height) {
        int r = tf_exr_read_rows(b, &mb, &rows_b, check_row, &c, err, sizeof err);
        if (c.differ || (r == 0 && (mb.width != c.meta.width || mb.height != c.meta.height)))
            rc = 0;
        else if (r == 0 && rows_b == mb.height)
            rc = 1;
    }
    free(c.px);
    return rc;
}

/* Bit-identical files, else bit-identical decoded pixels: 1, 0 or -1. */
static int same_image(const char *a, const char *b)
{
    int same = same_bytes(a, b);
    return same == 1 ? 1 : same_pixels(a, b);
}

static int cmp_double(const void *a, const void *b)
{
    double x = ((const run_stats *)a)->wall_s, y = ((const run_stats *)b)->wall_s;
    return (x > y) - (x < y);
}

/* Remove dir/out-* files and dir itself (the temporary directory only). */
static void remove_tree(const char *dir, const bench_opts *o)
{
    char path[4200];
    for (int i = 0; i < o->ncounts; i++)
        for (int r = 0; r < o->repeat; r++) {
            static const char *const ext[] = {"exr", "json", "png"};
            for (int e = 0; e < 3; e++) {
                snprintf(path, sizeof path, "%s/out-%d-%d.%s", dir, o->counts[i], r, ext[e]);
                unlink(path);
            }
        }
    static const char *const plot_files[] = {"plot.dat", "plot.gp"};
    for (int i = 0; i < 2; i++) {
        snprintf(path, sizeof path, "%s/%s", dir, plot_files[i]);
        unlink(path);
    }
    rmdir(dir);
}

/* Render every count R times; fill rows.  0, or -1 (reported). */
static int measure(const bench_opts *o, const char *dir, row *rows)
{
    char ref[4200] = "", exr[4200], json[4200];
    run_stats *runs = calloc((size_t)o->repeat, sizeof *runs);
    if (!runs) {
        tf_error("out of memory");
        return -1;
    }
    for (int i = 0; i < o->ncounts; i++) {
        int n = o->counts[i];
        for (int r = 0; r < o->repeat; r++) {
            if (!o->quiet)
                fprintf(stderr, "bench: %d worker%s, run %d of %d\n", n, n == 1 ? "" : "s",
                        r + 1, o->repeat);
            if (run_render(o, dir, n, r, exr, sizeof exr, json, sizeof json) ||
                read_stats(json, o->procedural, &runs[r]))
                goto fail;
            if (!ref[0]) {
                snprintf(ref, sizeof ref, "%s", exr);
            } else {
                int same = same_image(ref, exr);
                if (same != 1) {
                    tf_error("bench: %s and %s %s: the decomposition invariant is broken", ref,
                             exr, same == 0 ? "differ" : "cannot be compared");
                    goto fail;
                }
                if (!o->keep)
                    unlink(exr);
            }
        }
        qsort(runs, (size_t)o->repeat, sizeof *runs, cmp_double);
        rows[i].workers = n;
        rows[i].st = runs[o->repeat / 2];
    }
    free(runs);
    return 0;
fail:
    free(runs);
    return -1;
}

static void derive(const bench_opts *o, row *rows)
{
    /* Speedup against the smallest count, assumed to scale perfectly down to one worker. */
    int base = 0;
    for (int i = 1; i < o->ncounts; i++)
        if (rows[i].workers < rows[base].workers)
            base = i;
    double one_worker_s = rows[base].st.wall_s * rows[base].workers;
    for (int i = 0; i < o->ncounts; i++) {
        row *r = &rows[i];
        r->speedup = one_worker_s / r->st.wall_s;
        r->efficiency = r->speedup / r->workers;
        r->rays_per_s = r->st.rays / r->st.wall_s;
        r->busy_fraction = r->st.nworkers ? r->st.busy_sum / r->st.nworkers / r->st.wall_s : 0;
        double inside = r->st.primary - r->st.external;
        r->external_overhead = inside > 0 ? r->st.external / inside : 0;
    }
}

/* ---- output ------------------------------------------------------------------------------- */

static void print_table(const bench_opts *o, const row *rows)
{
    printf("%-8s %9s %8s %10s %10s %6s %8s %9s", "workers", "wall_s", "speedup", "efficiency",
           "Mrays/s", "busy", "redealt", "external");
    if (o->procedural)
        printf(" %12s %12s %10s", "samples", "per_worker", "evictions");
    printf("\n");
    for (int i = 0; i < o->ncounts; i++) {
        const row *r = &rows[i];
        printf("%-8d %9.3f %8.3f %10.3f %10.3f %6.3f %8.0f %8.2f%%", r->workers, r->st.wall_s,
               r->speedup, r->efficiency, r->rays_per_s / 1e6, r->busy_fraction, r->st.redealt,
               100.0 * r->external_overhead);
        if (o->procedural)
            printf(" %12.0f %12.0f %10.0f", r->st.samples,
                   r->st.nworkers ? r->st.samples / r->st.nworkers : 0.0, r->st.evictions);
        printf("\n");
    }
    printf("images: %d render%s bit-identical (decoded); median of %d run%s; tasks %s\n",
           o->ncounts * o->repeat, o->ncounts * o->repeat == 1 ? "" : "s", o->repeat,
           o->repeat == 1 ? "" : "s", o->tasks ? o->tasks : "default");
    if (o->procedural)
        printf("procedural terrain: samples evaluated by all workers (of the median run); "
               "terrain cache %s per worker; affinity %s\n",
               o->terrain_cache ? o->terrain_cache : "default",
               o->affinity ? o->affinity : "on (default)");
}

static int write_csv(const char *path, const bench_opts *o, const row *rows)
{
    FILE *f = fopen(path, "w");
    if (!f) {
        tf_error("%s: cannot write the CSV: %s", path, strerror(errno));
        return -1;
    }
    fprintf(f, "workers,wall_s,speedup,efficiency,rays_per_s,busy_fraction,tasks_redealt,"
               "external_overhead%s\n",
            o->procedural ? ",samples_evaluated,samples_per_worker,cache_evictions" : "");
    for (int i = 0; i < o->ncounts; i++) {
        const row *r = &rows[i];
        fprintf(f, "%d,%.4f,%.4f,%.4f,%.0f,%.4f,%.0f,%.5f", r->workers, r->st.wall_s,
                r->speedup, r->efficiency, r->rays_per_s, r->busy_fraction, r->st.redealt,
                r->external_overhead);
        if (o->procedural)
            fprintf(f, ",%.0f,%.1f,%.0f", r->st.samples,
                    r->st.nworkers ? r->st.samples / r->st.nworkers : 0.0, r->st.evictions);
        fprintf(f, "\n");
    }
    if (fclose(f) != 0) {
        tf_error("%s: cannot write the CSV: %s", path, strerror(errno));
        return -1;
    }
    return 0;
}

/* gnuplot on PATH? */
static int have_gnuplot(void)
{
    const char *path = getenv("PATH");
    if (!path)
        return 0;
    char dir[4096];
    while (*path) {
        size_t n = strcspn(path, ":");
        snprintf(dir, sizeof dir, "%.*s/gnuplot", (int)(n < 4000 ? n : 4000), n ? path : ".");
        if (access(dir, X_OK) == 0)
            return 1;
        path += n + (path[n] == ':');
    }
    return 0;
}

static const char *plot_terminal(const char *path)
{
    size_t n = strlen(path);
    if (n > 4 && !strcasecmp(path + n - 4, ".svg"))
        return "svg size 800,500 dynamic";
    if (n > 4 && !strcasecmp(path + n - 4, ".png"))
        return "pngcairo size 800,500";
    return NULL;
}

/* Speedup (left axis) and efficiency (right axis) against workers, with the ideal line. */
static int write_plot(const char *path, const char *dir, const bench_opts *o, const row *rows)
{
    char data[4200], script[4200];
    snprintf(data, sizeof data, "%s/plot.dat", dir);
    snprintf(script, sizeof script, "%s/plot.gp", dir);
    FILE *d = fopen(data, "w"), *g = fopen(script, "w");
    if (!d || !g) {
        tf_error("bench: cannot write the plot files in %s: %s", dir, strerror(errno));
        if (d)
            fclose(d);
        if (g)
            fclose(g);
        return -1;
    }
    int maxw = 1;
    for (int i = 0; i < o->ncounts; i++) {
        fprintf(d, "%d %.5f %.5f\n", rows[i].workers, rows[i].speedup, rows[i].efficiency);
        maxw = rows[i].workers > maxw ? rows[i].workers : maxw;
    }
    fprintf(g,
            "set terminal %s\nset output '%s'\nset title 'terrafarm: %s'\n"
            "set xlabel 'workers'\nset ylabel 'speedup'\nset y2label 'parallel efficiency'\n"
            "set xrange [0:%d]\nset yrange [0:%d]\nset y2range [0:1.1]\nset ytics nomirror\n"
            "set y2tics\nset key left top\nset grid\n"
            "plot x title 'ideal speedup' with lines dt 2 lc rgb 'gray', "
            "'%s' using 1:2 title 'speedup' with linespoints lw 2 pt 7, "
            "'%s' using 1:3 axes x1y2 title 'efficiency' with linespoints lw 2 pt 5\n",
            plot_terminal(path), path, o->scene, maxw + 1, maxw + 1, data, data);
    fclose(d);
    if (fclose(g) != 0) {
        tf_error("bench: cannot write %s", script);
        return -1;
    }
    fflush(NULL);
    pid_t pid = fork();
    if (pid == 0) {
        execlp("gnuplot", "gnuplot", script, (char *)NULL);
        _exit(127);
    }
    int status = 0;
    if (pid < 0 || waitpid(pid, &status, 0) != pid || !WIFEXITED(status) ||
        WEXITSTATUS(status) != 0) {
        tf_error("bench: gnuplot could not draw %s", path);
        return -1;
    }
    unlink(data);
    unlink(script);
    return 0;
}

int cmd_bench(int argc, char **argv)
{
    bench_opts o;
    int pr = parse_args(argc, argv, &o);
    if (pr)
        return pr > 0 ? TF_EXIT_OK : TF_EXIT_USAGE;
    if (o.quiet)
        tf_log_set_level(TF_LOG_WARN);
    if (o.cost_map)
        return run_cost_map(&o);
    if (o.plot && !plot_terminal(o.plot)) {
        tf_error("--plot '%s': expected a .svg or .png file", o.plot);
        return TF_EXIT_USAGE;
    }
    if (o.plot && !have_gnuplot()) {
        tf_error("--plot needs gnuplot, which is not installed (Debian: apt-get install "
                 "gnuplot-nox)");
        return TF_EXIT_FAIL;
    }
    /* A scene that does not load is left to the first render to report (as before). */
    {
        char err[1024];
        tf_scene *s = tf_scene_load(o.scene, err, sizeof err);
        if (s) {
            o.procedural = s->terrain.procedural;
            tf_scene_free(s);
        }
    }
    char tmpl[] = "/tmp/terrafarm-bench-XXXXXX";
    const char *dir = o.keep;
    if (dir) {
        if (mkdir(dir, 0777) && errno != EEXIST) {
            tf_error("--keep %s: cannot create the directory: %s", dir, strerror(errno));
            return TF_EXIT_FAIL;
        }
    } else if (!(dir = mkdtemp(tmpl))) {
        tf_error("bench: cannot create a temporary directory: %s", strerror(errno));
        return TF_EXIT_FAIL;
    }
    row rows[MAX_COUNTS];
    memset(rows, 0, sizeof rows);
    int rc = TF_EXIT_FAIL;
    if (measure(&o, dir, rows) == 0) {
        derive(&o, rows);
        print_table(&o, rows);
        if ((!o.csv || write_csv(o.csv, &o, rows) == 0) &&
            (!o.plot || write_plot(o.plot, dir, &o, rows) == 0))
            rc = TF_EXIT_OK;
    }
    if (!o.keep)
        remove_tree(dir, &o);
    return rc;
}
