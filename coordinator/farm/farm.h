/* farm.h: `terrafarm farm`, the standing farm: one long-lived process with a durable job queue
 * (farmdb.h), an HTTP JSON API for people and workers (farmapi.c, docs/farm-api.yaml), and one
 * render process per running job (jobrun.h) that its workers join.  Workers that stay
 * (`terrafarm worker --connect http://FARM`, worker/farm_worker.h) ask the farm which job to
 * serve (scheduler.h), serve it until it ends or the farm tells them to leave, and ask again.
 *
 * A kill -9 of the farm loses nothing: the queue is in the database, each job's output is its
 * checkpoint, the renders die with the farm, and the next farm on the same state folder starts
 * every unfinished job again where its output stopped. */
#ifndef TF_FARM_H
#define TF_FARM_H

typedef struct tf_farm_opts {
    const char *listen;      /* HOST:PORT of the API; the jobs' renders listen on HOST too */
    const char *state_dir;   /* farm.db and jobs/ */
    const char *secret_file; /* the farm secret the workers hold (required) */
    int worker_timeout_ms;   /* a worker silent this long no longer counts (default 15 s) */
    int max_failures;        /* failed sessions of a worker on a job before it is barred (3) */
    int forgive_ms;          /* how long a bar lasts (default 10 min) */
    int max_render_attempts; /* renders of a job that fail before the job fails (3) */
    int paint_idle_ms;       /* a paint job whose page nobody reads this long is closed (10 min) */
} tf_farm_opts;

/* Run the farm until SIGINT or SIGTERM.  Returns the exit status (0, or 1 after one line). */
int tf_farm_run(const tf_farm_opts *o);

/* Add a person's token to the farm at state_dir (a farm may be running) and print it: 0 or 1.
 * role: "submitter" or "admin". */
int tf_farm_add_token(const char *state_dir, const char *name, const char *role);

#endif
