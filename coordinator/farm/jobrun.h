/* jobrun.h: one job's render as a child process of the standing farm.  The job's folder
 * STATE/jobs/ID holds what the render reads and writes: the scene as the farm rewrote it
 * (its canonical form, naming the job's own copy of the height map), the height map, the job's
 * secret, the output (the checkpoint), the statistics and the render's log.  The render is
 * `terrafarm render SCENE -o OUTPUT -j 0 --listen fd:N --secret-file SECRET --resume ...`: it
 * serves only networked workers, on a socket the farm bound (so its port is known before the
 * render starts and nobody can take it in between), shows its dashboard on a second such
 * socket (the farm reads the job's progress there; its token derives from the job's key), and
 * continues whatever is on disk.  A lock
 * on the folder, held by the render process for its whole life, keeps a second render of the
 * same job (after a farm restart, while the old one is still dying) from touching the output
 * until the first is gone.
 *
 * A paint job (kind "paint", farm_paint.c) runs `terrafarm paint job.scene -j 0 --listen fd:N
 * --secret-file secret --http fd:M -o painted.exr --save edited.scene --farm FARM
 * --farm-token-file farm-token` in its folder instead: its page is the job's dashboard, its
 * Save writes edited.scene there and its Submit queues the view on this farm. */
#ifndef TF_JOBRUN_H
#define TF_JOBRUN_H

#include <stddef.h>
#include <stdint.h>
#include <sys/types.h>

#include "coordinator/farm/farmdb.h"

/* STATE/jobs/ID (+ "/" name when name is not NULL) into out. */
int tf_job_path(const char *state_dir, int64_t id, const char *name, char *out, size_t n);

/* Write the job's folder from its content: the scene, the height map, the secret (from the
 * farm key), and for a paint job the token its Submit gives the farm (submit_token; NULL:
 * none).  Idempotent: files are replaced atomically.  0, or -1 with one line. */
int tf_jobrun_prepare(const char *state_dir, const tf_job *j, const tf_job_content *c,
                      const uint8_t farm_key[32], const char *submit_token, char *err,
                      size_t errlen);

/* Where a job's process listens and finds the farm. */
typedef struct tf_jobrun_where {
    const char *host; /* the farm's host: the job listens there, on ephemeral ports */
    int api_port;     /* the farm's API (a paint job's Submit goes there) */
    int port;         /* out: the workers' port */
    int http_port;    /* out: the dashboard's (or paint page's) port */
} tf_jobrun_where;

/* Start the render (or paint) of job j listening at *at: the child's pid, or -1 with one
 * line.  exe: this program (/proc/self/exe).  options: the job's render options (a JSON array
 * of strings, checked at submission).  The child dies with the farm (PR_SET_PDEATHSIG). */
pid_t tf_jobrun_start(const char *exe, const char *state_dir, const tf_job *j,
                      const char *options, tf_jobrun_where *at, char *err, size_t errlen);

/* The last line the render wrote to its log (its one-line error, with the job's folder left
 * out: a submitter sees file names, not the farm's paths), or "" into out. */
void tf_jobrun_last_error(const char *state_dir, int64_t id, char *out, size_t n);

#endif
