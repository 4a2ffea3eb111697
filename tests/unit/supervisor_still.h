/* supervisor_still.h: the render the supervisor tests (test_supervisor_*.c) drive: a W x H
 * still in two tasks of rows:8, written to a real EXR in the scratch directory by a real row
 * writer; its supervisor config, and the teardown of an output left open.
 * Header-only (static functions; include cmocka.h first): each test program is its own
 * executable. */
#ifndef TF_SUPERVISOR_STILL_H
#define TF_SUPERVISOR_STILL_H

#include "coordinator/render/rowwriter.h"
#include "coordinator/render/supervisor.h"
#include "image/exrfile.h"
#include "linda/tuplespace.h"
#include "scratch_dir.h"

#define W 64
#define H 16 /* two tasks of rows:8 */

static const tf_exr_layout layout = {W, H, 0, 0, 0, TF_PIXEL_HALF};

/* hooks.open: the output (scratch file `still.exr`) and its writer thread. */
static tf_rowwriter *still_open_output(void *ctx, int job, char *err, size_t errlen)
{
    (void)ctx, (void)job;
    tf_exr_meta meta = {.width = W, .height = H, .pixel = TF_PIXEL_HALF};
    tf_exr_writer *w = tf_exr_create(scratch_path("still.exr"), &meta, err, errlen);
    if (!w)
        return NULL;
    tf_rowwriter_config cfg = {8, 1000, NULL, 1000, NULL, 1};
    tf_rowwriter *rw = tf_rowwriter_start(w, &layout, &cfg, err, errlen);
    if (!rw)
        tf_exr_abandon(w);
    return rw;
}

static int still_finish_output(void *ctx, int job, tf_rowwriter *w, char *err, size_t errlen)
{
    (void)ctx, (void)job;
    return tf_rowwriter_finish(w, err, errlen);
}

/* The supervisor's config for the still. */
static tf_supervisor_config still_config(int expected_workers, int max_task_failures)
{
    static const tf_frame_job still = {-1, 0, 0};
    tf_supervisor_config cfg = {
        .width = W, .height = H, .njobs = 1, .jobs = &still,
        .hooks = {NULL, still_open_output, still_finish_output, NULL},
        .layout = layout, .aa_max_depth = 2,
        .spec = {TF_TASKS_ROWS, W, 8}, .watermark = 0, .expected_workers = expected_workers,
        .max_task_failures = max_task_failures,
    };
    return cfg;
}

/* A new space and a supervisor of cfg over it (the test fails if either cannot be made). */
static tf_supervisor *still_supervisor_new(const tf_supervisor_config *cfg, ts_space **space)
{
    char err[256];
    *space = ts_space_new();
    assert_non_null(*space);
    tf_supervisor *sup = tf_supervisor_new(*space, cfg, err, sizeof err);
    if (!sup)
        print_message("tf_supervisor_new: %s\n", err);
    assert_non_null(sup);
    return sup;
}

/* As an interrupted render ends: its open output closed as a partial render. */
static void still_abandon_output(tf_supervisor *sup)
{
    tf_rowwriter *open[1];
    int jobs[1];
    for (int i = tf_supervisor_take_open_writers(sup, open, jobs, 1); i > 0; i--)
        tf_rowwriter_abandon(open[i - 1]);
}

#endif
