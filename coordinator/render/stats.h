/* stats.h: the run statistics as JSON (--stats FILE.json, docs/contract.md section 5: keep the names). */
#ifndef TF_STATS_H
#define TF_STATS_H

#include <stddef.h>
#include "coordinator/render/supervisor.h"

typedef struct tf_run_info {
    double wall_s;
    int width, height;
    const char *scene;
    const char *output;
    const char *tasks;       /* e.g. "stamps:64x64" */
    int local_workers;
    double heightfield_s;    /* time to build the height field before forking */
    double setup_cpu_s;      /* the coordinator's CPU time up to the end of the terrain build */
    double supervise_cpu_s;  /* its CPU time in the event loop alone (no start-up, no finish) */
    const char *layout;      /* the output's layout, e.g. "tiled 64x64 half" */
    double start_s;          /* when the run started (tf_now_s), for frames' start_s / done_s */
    int sequence;            /* an [animation] scene: write "frames" and "frames_skipped" */
    const int *frames_skipped; /* frames asked for that were already complete on disk */
    int nskipped;
} tf_run_info;

/* Write atomically (temporary file + rename).  0, or -1 with a message. */
int tf_stats_write(const char *path, const tf_run_info *run, const tf_farm_stats *st, char *err,
                   size_t errlen);

#endif
