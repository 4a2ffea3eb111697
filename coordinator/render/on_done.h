/* on_done.h: --on-done CMD, run once when a render ends (finished, failed or interrupted), by
 * /bin/sh -c CMD, with the outcome in its environment:
 *   TERRAFARM_STATUS   ok | failed | interrupted
 *   TERRAFARM_EXIT     the coordinator's exit status (0, 1, 130, ...)
 *   TERRAFARM_OUTPUT   the output EXR;  TERRAFARM_PREVIEW  the PNG beside it
 *   TERRAFARM_SCENE    the scene file;  TERRAFARM_SIZE      WxH
 *   TERRAFARM_WALL_S   seconds since the render started
 *   TERRAFARM_ROWS     rows on disk;    TERRAFARM_ROWS_TOTAL  rows of the image
 *   TERRAFARM_STATS    the --stats file (empty if none)
 *   TERRAFARM_ERROR    the reason a failed render stopped (empty otherwise)
 *   TERRAFARM_DASHBOARD  the dashboard's URL, still serving the final state (empty if none)
 * The coordinator waits for it (its output goes to the coordinator's stdout/stderr), serving
 * the dashboard's final state meanwhile; its exit status is logged, never changes the
 * render's. */
#ifndef TF_ON_DONE_H
#define TF_ON_DONE_H

typedef struct tf_outcome {
    const char *status;      /* ok | failed | interrupted */
    int exit_status;
    const char *output, *preview, *scene, *stats, *error, *dashboard;
    int width, height, rows;
    double wall_s;
} tf_outcome;

/* Run cmd; returns its exit status (-1 if it could not run, with a warning logged). */
int tf_on_done_run(const char *cmd, const tf_outcome *out);

#endif
