/* simulate.h: synthetic workers, to measure the coordinator beyond the cores at hand
 * (docs/contract.md section 6, "Targets": parallel efficiency modelled at 1024 workers).
 *
 * A simulated worker speaks the real farm protocol (farmproto.h) over its own tuple-space
 * connection, exactly like `terrafarm worker`, but instead of tracing rays it sleeps the
 * *modelled* cost of its task and puts back a result of the right size: with a recording
 * (--payloads, worker/payloads.h) the packed chunks of a real render, sized and compressed as
 * real results are; without one, encoded black pixels.  Many of them are served by one
 * thread (an event loop over their connections, simulate.c), so a 2-core machine can host a
 * farm of 1024 that costs its cores less than the coordinator does.
 *
 * The model (cost_map.c) is a cost map: a coarse grid of relative cost densities over the
 * image, measured once on a real render (tf_cost_map_measure), so the horizon stays as
 * expensive as it is in a real scene while the image is rescaled to any size.  Density is normalised so its
 * area-weighted mean is 1; a task's modelled cost is
 *     pixel_us * (integral of density over the task's rectangle, in pixels)
 * so pixel_us is the cost of an average pixel and pixel_us * w * h that of an average task.
 *
 * File format (text, one header line, then GH lines of GW numbers):
 *     terrafarm-cost-map 1 GW GH MEASURED_W MEASURED_H PIXEL_NS
 *     d(0,0) d(1,0) ... d(GW-1,0)
 *     ...
 * PIXEL_NS records the measured mean CPU time of one pixel (information only).  GW, GH are
 * bounded by TF_COST_MAP_MAX before anything is allocated. */
#ifndef TF_SIMULATE_H
#define TF_SIMULATE_H

#include <stddef.h>
#include <stdint.h>

#include "render/render.h"

#define TF_COST_MAP_MAX 1024

typedef struct tf_cost_map {
    int gw, gh;              /* grid cells across, down */
    int measured_w, measured_h;
    double pixel_ns;         /* measured mean cost of one pixel */
    double *density;         /* gw * gh, row-major, area-weighted mean 1 */
} tf_cost_map;

/* Render the scene at its size one grid cell at a time, timing each cell with the thread's CPU
 * clock (robust on a shared machine).  0, or -1 with a message. */
int tf_cost_map_measure(const tf_scene *s, const tf_heightfield *hf, int gw, int gh,
                        tf_cost_map *m, char *err, size_t errlen);
int tf_cost_map_save(const char *path, const tf_cost_map *m, char *err, size_t errlen);
int tf_cost_map_load(const char *path, tf_cost_map *m, char *err, size_t errlen);
void tf_cost_map_free(tf_cost_map *m);
/* Integral of the density over rect r of an image_w x image_h image (the map is stretched over
 * the whole image): the task's cost in "average pixels".  Equals r.w * r.h for a flat map. */
double tf_cost_map_rect(const tf_cost_map *m, int image_w, int image_h, tf_rect r);

typedef struct tf_sim_config {
    const char *connect;     /* HOST:PORT of the coordinator */
    const uint8_t *key;      /* or NULL */
    int timeout_ms;          /* connect timeout */
    int workers;             /* each with its own connection */
    double pixel_us;         /* modelled cost of an average pixel */
    const tf_cost_map *map;
    int image_w, image_h;    /* the render's size (from the scene tuple) */
    const struct tf_payloads *payloads; /* recorded chunks to send (payloads.h), or NULL */
} tf_sim_config;

typedef struct tf_sim_report {
    int workers;             /* that joined */
    int64_t tasks;           /* results delivered */
    int64_t ops;             /* tuple operations issued after the start line */
    double wall_s;           /* start line (all joined) -> first stop tuple seen */
    double modelled_s;       /* the whole image's modelled cost (useful work, once) */
    double slept_s;          /* modelled cost of every task served, duplicates included */
    double efficiency;       /* (modelled_s / workers) / wall_s */
    double take_mean_ms, take_p50_ms, take_p99_ms, take_max_ms; /* dealing latency: in(task) */
    double slept_over_ms;    /* mean oversleep beyond the modelled cost (timer slack) */
    double bound_s;          /* the schedule bound: these tasks on these workers, in dealing
                              * order, with nothing between tasks (simulate.c) */
    double bound_efficiency; /* (modelled_s / workers) / bound_s: the best this run could be */
} tf_sim_report;

/* Run cfg->workers simulated workers until the coordinator's stop tuple.  0 when every worker
 * finished cleanly; -1 with a message otherwise (the report holds what was measured). */
int tf_simulate_run(const tf_sim_config *cfg, tf_sim_report *rep, char *err, size_t errlen);

#endif
