/* coordinator.h: `terrafarm render`, the coordinator (docs/contract.md sections 2, 3, 5).
 *
 * One process, one thread, one event loop (tsserver.h).  In order:
 *   1. load the scene, check the output (resume or refuse to clobber a partial render);
 *   2. build the height field, then fork the local workers so they share it copy-on-write
 *      (Musgrave's fork model); networked workers join over TCP and build their own (tsnet);
 *   3. supervise (supervisor.h): deal task tuples up to the watermark, lease them, collect
 *      results in order, write finished rows to the OpenEXR checkpoint, re-deal what is lost;
 *   4. finish the file, write the PNG preview and the statistics.
 * Workers encode their rectangles into the file's OpenEXR chunks themselves; the coordinator only
 * checks and moves those bytes (supervisor.h, rowwriter.h).
 *
 * Sequences.  For an [animation] scene the render covers frames (all of them, or --frames /
 * --frame), each into its own output named by a #### pattern (frames.h).  One terrain, one
 * tuple space and one pool of workers serve the whole sequence: the supervisor deals the
 * frames' tasks as one run of ids, and each frame's file is finished (finisher.h) as soon as
 * its last task is written; like a still's, it is a resumable checkpoint at every instant.  With --resume, frames already complete are skipped, frames
 * in progress continue row by row, and the rest render; --movie assembles the previews. */
#ifndef TF_COORDINATOR_H
#define TF_COORDINATOR_H

#include "coordinator/render/tasks.h"

typedef struct tf_render_opts {
    const char *scene_path;
    struct tf_scene *scene;    /* given: render this scene (taken over and freed) instead of
                                * loading scene_path, which still names it (an erosion film's
                                * frame: erosion_film.h) */
    const char *output;        /* NULL: out/<scene>.exr, or out/<scene>.####.exr for a sequence */
    int frames_given;          /* --frames / --frame: render frames first..last by step */
    int frame_first, frame_last, frame_step;
    const char *movie;         /* --movie FILE.mp4|webm: assemble the previews (needs ffmpeg) */
    int workers;               /* forked local workers; -1 = online CPUs */
    int tasks_given;           /* 1 if --tasks was given */
    tf_task_spec tasks;
    int watermark;             /* 0 = default */
    int width, height;         /* --size, 0 = scene's */
    const char *backend;       /* "c" | "opencl" */
    const char *listen;        /* NULL = 127.0.0.1:7878 (falls back to ephemeral if busy) */
    const char *secret_file;
    int resume;
    int overwrite;             /* --overwrite: discard a partial render at the output */
    const char *stats_path;
    int wait_workers;          /* --wait-workers N: deal no task before N workers joined */
    int affinity;              /* --affinity on|off: column-range affinity (default on) */
    int lease_timeout_ms;      /* a silent worker is dropped after this (default 15000) */
    size_t terrain_cache;      /* --terrain-cache: procedural terrain per local worker; 0 = default */
    int max_task_failures;     /* distinct workers a task may fail on before the render stops */
    int fsync_interval_ms;     /* at most this long between durable checkpoints */
    int pixel;                 /* --pixel: TF_PIXEL_HALF | TF_PIXEL_FLOAT (image/exrlayout.h) */
    int pixel_given;           /* 1 if --pixel was given (a resume otherwise keeps the file's) */
    int verify_chunks;         /* --verify-chunks: decode every result's chunks before accepting */
    double verify_fraction;    /* --verify: fraction of tasks rendered twice (supervisor.h) */
    int preview_interval_ms;   /* rewrite the progress preview this often (default 5000) */
    const char *http;          /* --http HOST:PORT | none; NULL = 127.0.0.1:7880 (ephemeral if busy) */
    const char *http_token_file; /* the dashboard's token (else derived from the secret) */
    const char *on_done;       /* --on-done CMD (on_done.h) */
    int quiet, verbose;
} tf_render_opts;

void tf_render_opts_init(tf_render_opts *o);
/* Run a render. Returns the process exit status; every failure has printed one line. */
int tf_coordinator_run(const tf_render_opts *o);

#endif
