/* farmdb.h: the standing farm's durable queue, an SQLite database in WAL mode
 * (STATE_DIR/farm.db): the jobs with their content (scene text, height map bytes, render
 * options), kind, state, priority, pool, tags and dependency; their history; and the people's
 * tokens, stored as hashes.  Every change is one transaction with synchronous=FULL, so what
 * an API call answered survives a kill -9 (or a power loss) of the farm.
 *
 * Invariants (asserted in make asan):
 *   Q1 a job's state is one of TF_JOB_STATES, and "running" is never stored: whether a job's
 *      render is running is the farm's knowledge of its processes, not the database's, so a
 *      farm restarted after a crash finds every unfinished job queued or paused;
 *   Q2 a job's id is positive and never reused (AUTOINCREMENT);
 *   Q3 a token is stored only as its hash. */
#ifndef TF_FARMDB_H
#define TF_FARMDB_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>

typedef struct tf_farmdb tf_farmdb;

#define TF_JOB_STATES "queued paused done failed cancelled"

typedef struct tf_job {
    int64_t id;
    char name[128];
    char owner[64];     /* the submitter's token name */
    char pool[64];
    char tags[256];     /* comma list a worker must all have */
    int priority;       /* higher first */
    int64_t after;      /* a job that must be done first; 0: none */
    char kind[8];       /* render | paint (Raypaint: runs until closed); "" is stored as render */
    char state[16];     /* queued | paused | done | failed | cancelled */
    char reason[256];   /* why failed or cancelled */
    char scene_hash[65];
    char terrain[65];   /* SHA-256 of the scene's terrain (what a worker keeps) */
    char nonce[33];     /* makes the job's own tuple-space key */
    char output[64];    /* file name of the output inside the job's folder */
    int frames;         /* frames of a sequence; 0: a still */
    int width, height;
    int attempts;       /* renders started */
    double created, started, finished; /* Unix seconds; 0: not yet */
} tf_job;

/* 1 when j is a paint job (Raypaint: its process is terrafarm paint, farm_paint.c). */
static inline int tf_job_is_paint(const tf_job *j)
{
    return !strcmp(j->kind, "paint");
}

/* A job's content, as submitted (all malloc'd; heightmap may be NULL). */
typedef struct tf_job_content {
    char *scene;
    size_t scene_len;
    uint8_t *heightmap;
    size_t heightmap_len;
    char *heightmap_name;
    char *options;  /* JSON array of render options */
} tf_job_content;

tf_farmdb *tf_farmdb_open(const char *path, char *err, size_t errlen);
void tf_farmdb_close(tf_farmdb *db);

/* Insert j (its id is set) with its content. */
int tf_farmdb_insert(tf_farmdb *db, tf_job *j, const tf_job_content *c, char *err, size_t errlen);
/* Every job, oldest first: *out malloc'd, *n entries. */
int tf_farmdb_load(tf_farmdb *db, tf_job **out, int *n, char *err, size_t errlen);
int tf_farmdb_content(tf_farmdb *db, int64_t id, tf_job_content *c, char *err, size_t errlen);
void tf_job_content_free(tf_job_content *c);

/* Store j's mutable fields (state, reason, priority, attempts, started, finished) and append
 * `event` to its history (NULL: none). */
int tf_farmdb_update(tf_farmdb *db, const tf_job *j, const char *event, char *err,
                     size_t errlen);
/* A job's history, oldest first, as "UNIX_SECONDS EVENT" lines (malloc'd). */
char *tf_farmdb_history(tf_farmdb *db, int64_t id);

/* People's tokens: hash_hex is the token's keyed hash (farm/farmauth.h). */
int tf_farmdb_token_add(tf_farmdb *db, const char *name, const char *role, const char *hash_hex,
                        char *err, size_t errlen);
/* 1 and name/role when hash_hex is a known token, 0 when not, -1 on error. */
int tf_farmdb_token_find(tf_farmdb *db, const char *hash_hex, char *name, size_t namelen,
                         char *role, size_t rolelen);

#endif
