/* test_farmdb.c: the standing farm's durable queue (coordinator/farm/farmdb.c) on a database in
 * a temporary folder: jobs inserted with their content (a height map with NUL bytes comes back
 * byte for byte), loaded in id order, updated with their history; tokens added and found, a
 * duplicate name or token and an unknown role refused with a clear message; everything still
 * there after close and reopen; the schema's CHECK refusing a state outside TF_JOB_STATES
 * (through SQLite itself, and through tf_farmdb_update in a child, where a build with asserts
 * on stops at the Q1 assert instead: both are refusals); a job's kind stored and loaded, and
 * an older database without kinds gaining the column.  And the worker's terrain shelf
 * (worker/terrain_shelf.c) with fake height fields: least recently used out under a byte
 * budget, the newest kept even alone over it, at most 16 held, keys most recent first, a key
 * put again replaced. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <signal.h>
#include <sqlite3.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "coordinator/farm/farmdb.h"
#include "render/sun_strips.h"
#include "scratch_dir.h"
#include "worker/terrain_shelf.h"

static const char H1[] = "1111111111111111111111111111111111111111111111111111111111111111";
static const char H2[] = "2222222222222222222222222222222222222222222222222222222222222222";
static const char H3[] = "3333333333333333333333333333333333333333333333333333333333333333";

static tf_farmdb *open_db(const char *name)
{
    char err[512] = "";
    tf_farmdb *db = tf_farmdb_open(scratch_path(name), err, sizeof err);
    if (!db)
        fail_msg("open %s: %s", name, err);
    return db;
}

static tf_job make_job(const char *name, int priority)
{
    tf_job j;
    memset(&j, 0, sizeof j);
    snprintf(j.name, sizeof j.name, "%s", name);
    snprintf(j.owner, sizeof j.owner, "alice");
    snprintf(j.pool, sizeof j.pool, "default");
    snprintf(j.tags, sizeof j.tags, "gpu,big");
    j.priority = priority;
    snprintf(j.state, sizeof j.state, "queued");
    snprintf(j.scene_hash, sizeof j.scene_hash, "%s", H1);
    snprintf(j.terrain, sizeof j.terrain, "%s", H2);
    snprintf(j.nonce, sizeof j.nonce, "0123456789abcdef0123456789abcdef");
    snprintf(j.output, sizeof j.output, "out.exr");
    j.width = 64;
    j.height = 48;
    j.created = 1700000000.25;
    return j;
}

static const uint8_t hm_bytes[] = {0, 1, 0, 0, 255, 0, 'P', 'N', 'G', 0, '\n', 0};

static void insert(tf_farmdb *db, tf_job *j, int with_heightmap)
{
    char scene[] = "[terrain]\ngenerator = file\n";
    char opts[] = "[\"--size\",\"64x48\"]";
    tf_job_content c = {.scene = scene, .scene_len = strlen(scene),
                        .heightmap = with_heightmap ? (uint8_t *)hm_bytes : NULL,
                        .heightmap_len = with_heightmap ? sizeof hm_bytes : 0,
                        .heightmap_name = with_heightmap ? "dem.png" : NULL, .options = opts};
    char err[512] = "";
    if (tf_farmdb_insert(db, j, &c, err, sizeof err))
        fail_msg("insert %s: %s", j->name, err);
}

static void insert_load_content(void **state)
{
    (void)state;
    tf_farmdb *db = open_db("jobs.db");
    tf_job a = make_job("a", 5), b = make_job("b", 1), c = make_job("c", 9);
    insert(db, &a, 1);
    insert(db, &b, 0);
    insert(db, &c, 1);
    assert_true(a.id > 0);
    assert_true(b.id > a.id);
    assert_true(c.id > b.id);

    tf_job *jobs;
    int n;
    char err[512] = "";
    assert_int_equal(tf_farmdb_load(db, &jobs, &n, err, sizeof err), 0);
    assert_int_equal(n, 3);
    assert_int_equal(jobs[0].id, a.id);
    assert_int_equal(jobs[1].id, b.id);
    assert_int_equal(jobs[2].id, c.id);
    assert_string_equal(jobs[0].name, "a");
    assert_string_equal(jobs[2].name, "c");
    assert_int_equal(jobs[2].priority, 9);
    assert_string_equal(jobs[0].owner, "alice");
    assert_string_equal(jobs[0].tags, "gpu,big");
    assert_string_equal(jobs[0].state, "queued");
    assert_string_equal(jobs[0].terrain, H2);
    assert_string_equal(jobs[0].nonce, "0123456789abcdef0123456789abcdef");
    assert_int_equal(jobs[0].width, 64);
    assert_int_equal(jobs[0].attempts, 0);
    assert_true(jobs[0].created == 1700000000.25);
    assert_true(jobs[0].started == 0 && jobs[0].finished == 0);
    free(jobs);

    tf_job_content got;
    assert_int_equal(tf_farmdb_content(db, a.id, &got, err, sizeof err), 0);
    assert_string_equal(got.scene, "[terrain]\ngenerator = file\n");
    assert_int_equal(got.scene_len, strlen(got.scene));
    assert_non_null(got.heightmap);
    assert_int_equal(got.heightmap_len, sizeof hm_bytes);
    assert_memory_equal(got.heightmap, hm_bytes, sizeof hm_bytes);
    assert_string_equal(got.heightmap_name, "dem.png");
    assert_string_equal(got.options, "[\"--size\",\"64x48\"]");
    tf_job_content_free(&got);
    assert_null(got.heightmap);

    assert_int_equal(tf_farmdb_content(db, b.id, &got, err, sizeof err), 0);
    assert_null(got.heightmap);
    assert_int_equal(got.heightmap_len, 0);
    assert_null(got.heightmap_name);
    tf_job_content_free(&got);

    err[0] = 0;
    assert_int_not_equal(tf_farmdb_content(db, 999, &got, err, sizeof err), 0);
    assert_non_null(strstr(err, "job 999 has no content"));
    assert_null(strchr(err, '\n'));
    tf_farmdb_close(db);
}

static void update_and_history(void **state)
{
    (void)state;
    tf_farmdb *db = open_db("update.db");
    tf_job j = make_job("u", 0);
    insert(db, &j, 0);
    char err[512] = "";
    snprintf(j.state, sizeof j.state, "paused");
    j.priority = 7;
    j.attempts = 2;
    j.started = 1700000100.5;
    assert_int_equal(tf_farmdb_update(db, &j, "paused", err, sizeof err), 0);
    /* no event: the row changes, the history does not */
    snprintf(j.state, sizeof j.state, "failed");
    snprintf(j.reason, sizeof j.reason, "the render failed 3 times");
    j.finished = 1700000200.75;
    assert_int_equal(tf_farmdb_update(db, &j, NULL, err, sizeof err), 0);

    tf_job *jobs;
    int n;
    assert_int_equal(tf_farmdb_load(db, &jobs, &n, err, sizeof err), 0);
    assert_int_equal(n, 1);
    assert_string_equal(jobs[0].state, "failed");
    assert_string_equal(jobs[0].reason, "the render failed 3 times");
    assert_int_equal(jobs[0].priority, 7);
    assert_int_equal(jobs[0].attempts, 2);
    assert_true(jobs[0].started == 1700000100.5);
    assert_true(jobs[0].finished == 1700000200.75);
    /* fields that do not change stay as inserted */
    assert_string_equal(jobs[0].name, "u");
    assert_string_equal(jobs[0].terrain, H2);
    free(jobs);

    char *h = tf_farmdb_history(db, j.id);
    assert_non_null(h);
    double t1, t2;
    char e1[32], e2[32];
    assert_int_equal(sscanf(h, "%lf %31s\n%lf %31s", &t1, e1, &t2, e2), 4);
    assert_string_equal(e1, "submitted");
    assert_string_equal(e2, "paused");
    assert_true(t1 > 1e9 && t2 >= t1);
    int lines = 0;
    for (const char *p = h; *p; p++)
        lines += *p == '\n';
    assert_int_equal(lines, 2);
    free(h);
    h = tf_farmdb_history(db, 4242); /* no such job: an empty history */
    assert_true(!h || !*h);
    free(h);
    tf_farmdb_close(db);
}

static void tokens(void **state)
{
    (void)state;
    tf_farmdb *db = open_db("tokens.db");
    char err[512] = "", name[64], role[16];
    assert_int_equal(tf_farmdb_token_add(db, "alice", "submitter", H1, err, sizeof err), 0);
    assert_int_equal(tf_farmdb_token_add(db, "root", "admin", H2, err, sizeof err), 0);
    assert_int_equal(tf_farmdb_token_find(db, H1, name, sizeof name, role, sizeof role), 1);
    assert_string_equal(name, "alice");
    assert_string_equal(role, "submitter");
    assert_int_equal(tf_farmdb_token_find(db, H2, name, sizeof name, role, sizeof role), 1);
    assert_string_equal(name, "root");
    assert_string_equal(role, "admin");
    assert_int_equal(tf_farmdb_token_find(db, H3, name, sizeof name, role, sizeof role), 0);

    /* a second token named alice */
    err[0] = 0;
    assert_int_equal(tf_farmdb_token_add(db, "alice", "admin", H3, err, sizeof err), -1);
    assert_non_null(strstr(err, "a token named 'alice' exists already"));
    assert_null(strchr(err, '\n'));
    assert_int_equal(tf_farmdb_token_find(db, H3, name, sizeof name, role, sizeof role), 0);
    /* the same token under another name: refused, and not blamed on the name */
    err[0] = 0;
    assert_int_equal(tf_farmdb_token_add(db, "carol", "submitter", H1, err, sizeof err), -1);
    assert_non_null(strstr(err, "this token exists already"));
    assert_null(strstr(err, "named 'carol'"));
    assert_int_equal(tf_farmdb_token_find(db, H1, name, sizeof name, role, sizeof role), 1);
    assert_string_equal(name, "alice");
    /* a role that is not submitter or admin (a worker is never a stored token) */
    const char *bad_roles[] = {"worker", "wizard", ""};
    for (size_t i = 0; i < sizeof bad_roles / sizeof *bad_roles; i++) {
        err[0] = 0;
        assert_int_equal(tf_farmdb_token_add(db, "dave", bad_roles[i], H3, err, sizeof err), -1);
        assert_non_null(strstr(err, "role"));
        assert_null(strstr(err, "exists already"));
        assert_int_equal(tf_farmdb_token_find(db, H3, name, sizeof name, role, sizeof role), 0);
    }
    tf_farmdb_close(db);
}

static void reopen_keeps_everything(void **state)
{
    (void)state;
    tf_farmdb *db = open_db("durable.db");
    tf_job a = make_job("first", 3), b = make_job("second", 4);
    insert(db, &a, 1);
    insert(db, &b, 0);
    char err[512] = "";
    snprintf(b.state, sizeof b.state, "done");
    b.finished = 1700000300.0;
    assert_int_equal(tf_farmdb_update(db, &b, "done", err, sizeof err), 0);
    assert_int_equal(tf_farmdb_token_add(db, "bob", "submitter", H3, err, sizeof err), 0);
    tf_farmdb_close(db);

    db = open_db("durable.db");
    tf_job *jobs;
    int n;
    assert_int_equal(tf_farmdb_load(db, &jobs, &n, err, sizeof err), 0);
    assert_int_equal(n, 2);
    assert_int_equal(jobs[0].id, a.id);
    assert_string_equal(jobs[0].name, "first");
    assert_string_equal(jobs[0].state, "queued");
    assert_int_equal(jobs[1].id, b.id);
    assert_string_equal(jobs[1].state, "done");
    assert_true(jobs[1].finished == 1700000300.0);
    free(jobs);
    tf_job_content got;
    assert_int_equal(tf_farmdb_content(db, a.id, &got, err, sizeof err), 0);
    assert_int_equal(got.heightmap_len, sizeof hm_bytes);
    assert_memory_equal(got.heightmap, hm_bytes, sizeof hm_bytes);
    tf_job_content_free(&got);
    char *h = tf_farmdb_history(db, b.id);
    assert_non_null(h);
    assert_non_null(strstr(h, " submitted\n"));
    assert_non_null(strstr(h, " done\n"));
    free(h);
    char name[64], role[16];
    assert_int_equal(tf_farmdb_token_find(db, H3, name, sizeof name, role, sizeof role), 1);
    assert_string_equal(name, "bob");

    /* Q2: an id is never reused, even after the newest job's row is gone */
    sqlite3 *raw;
    assert_int_equal(sqlite3_open(scratch_path("durable.db"), &raw), SQLITE_OK);
    char sql[128];
    snprintf(sql, sizeof sql, "DELETE FROM history WHERE job=%lld; DELETE FROM content WHERE "
             "job=%lld; DELETE FROM jobs WHERE id=%lld;", (long long)b.id, (long long)b.id,
             (long long)b.id);
    assert_int_equal(sqlite3_exec(raw, sql, NULL, NULL, NULL), SQLITE_OK);
    sqlite3_close(raw);
    tf_job c = make_job("third", 0);
    insert(db, &c, 0);
    assert_true(c.id > b.id);
    tf_farmdb_close(db);

    err[0] = 0;
    assert_null(tf_farmdb_open(scratch_path("no/such/folder/farm.db"), err, sizeof err));
    assert_non_null(strstr(err, "cannot open the farm database"));
}

/* The CHECK on state, through SQLite itself: valid with or without asserts. */
static void check_refuses_bad_state_sql(void **state)
{
    (void)state;
    tf_farmdb *db = open_db("check.db");
    tf_job j = make_job("checked", 0);
    insert(db, &j, 0);
    tf_farmdb_close(db);

    sqlite3 *raw;
    assert_int_equal(sqlite3_open(scratch_path("check.db"), &raw), SQLITE_OK);
    char sql[512];
    snprintf(sql, sizeof sql, "UPDATE jobs SET state='running' WHERE id=%lld", (long long)j.id);
    assert_int_equal(sqlite3_exec(raw, sql, NULL, NULL, NULL), SQLITE_CONSTRAINT);
    assert_non_null(strstr(sqlite3_errmsg(raw), "CHECK"));
    assert_int_equal(sqlite3_exec(raw, "INSERT INTO jobs(name,owner,pool,tags,priority,after,"
                                  "state,reason,scene_hash,terrain,nonce,output,frames,width,"
                                  "height,attempts,created,started,finished) VALUES('x','a','d',"
                                  "'',0,0,'sleeping','','','','','',0,1,1,0,0,0,0)",
                                  NULL, NULL, NULL),
                     SQLITE_CONSTRAINT);
    /* a good state is accepted by the same statement */
    snprintf(sql, sizeof sql, "UPDATE jobs SET state='cancelled' WHERE id=%lld",
             (long long)j.id);
    assert_int_equal(sqlite3_exec(raw, sql, NULL, NULL, NULL), SQLITE_OK);
    sqlite3_close(raw);
}

/* A job's kind: paint and render come back as stored ("" is stored as render); the schema
 * refuses any other. */
static void kinds_round_trip(void **state)
{
    (void)state;
    tf_farmdb *db = open_db("kinds.db");
    tf_job a = make_job("painted", 1), b = make_job("plain", 0);
    snprintf(a.kind, sizeof a.kind, "paint");
    insert(db, &a, 0);
    insert(db, &b, 0);
    tf_job *jobs = NULL;
    int n = 0;
    char err[512] = "";
    assert_int_equal(tf_farmdb_load(db, &jobs, &n, err, sizeof err), 0);
    assert_int_equal(n, 2);
    assert_string_equal(jobs[0].kind, "paint");
    assert_string_equal(jobs[1].kind, "render");
    free(jobs);
    tf_farmdb_close(db);
    sqlite3 *raw;
    assert_int_equal(sqlite3_open(scratch_path("kinds.db"), &raw), SQLITE_OK);
    assert_int_equal(sqlite3_exec(raw, "UPDATE jobs SET kind='bake'", NULL, NULL, NULL),
                     SQLITE_CONSTRAINT);
    sqlite3_close(raw);
}

/* A database written before jobs had a kind (the jobs table without the column) opens, gains
 * the column, and its jobs load as renders. */
static void old_database_gains_kind(void **state)
{
    (void)state;
    sqlite3 *raw;
    assert_int_equal(sqlite3_open(scratch_path("old.db"), &raw), SQLITE_OK);
    assert_int_equal(sqlite3_exec(raw,
        "CREATE TABLE jobs(id INTEGER PRIMARY KEY AUTOINCREMENT, name TEXT NOT NULL,"
        " owner TEXT NOT NULL, pool TEXT NOT NULL, tags TEXT NOT NULL, priority INTEGER NOT NULL,"
        " after INTEGER NOT NULL, state TEXT NOT NULL, reason TEXT NOT NULL,"
        " scene_hash TEXT NOT NULL, terrain TEXT NOT NULL, nonce TEXT NOT NULL,"
        " output TEXT NOT NULL, frames INTEGER NOT NULL, width INTEGER NOT NULL,"
        " height INTEGER NOT NULL, attempts INTEGER NOT NULL, created REAL NOT NULL,"
        " started REAL NOT NULL, finished REAL NOT NULL);"
        "INSERT INTO jobs(name,owner,pool,tags,priority,after,state,reason,scene_hash,terrain,"
        "nonce,output,frames,width,height,attempts,created,started,finished) VALUES('old','a',"
        "'default','',0,0,'queued','','','','n','out.exr',0,8,8,0,1,0,0)", NULL, NULL, NULL),
        SQLITE_OK);
    sqlite3_close(raw);
    tf_farmdb *db = open_db("old.db");
    tf_job *jobs = NULL;
    int n = 0;
    char err[512] = "";
    assert_int_equal(tf_farmdb_load(db, &jobs, &n, err, sizeof err), 0);
    assert_int_equal(n, 1);
    assert_string_equal(jobs[0].name, "old");
    assert_string_equal(jobs[0].kind, "render");
    free(jobs);
    tf_farmdb_close(db);
}

/* tf_farmdb_update with a bad state, in a child: refused either by the Q1 assert (asserts on:
 * the child aborts) or by the CHECK (NDEBUG: it returns -1 with a message); never stored. */
static void check_refuses_bad_state_api(void **state)
{
    (void)state;
    tf_farmdb *db = open_db("check2.db");
    tf_job j = make_job("checked", 0);
    insert(db, &j, 0);
    tf_farmdb_close(db);

    fflush(NULL);
    pid_t pid = fork();
    assert_true(pid >= 0);
    if (pid == 0) {
        char err[512] = "";
        tf_farmdb *cdb = tf_farmdb_open(scratch_path("check2.db"), err, sizeof err);
        if (!cdb)
            _exit(3);
        tf_job bad = j;
        snprintf(bad.state, sizeof bad.state, "running");
        int rc = tf_farmdb_update(cdb, &bad, "bad", err, sizeof err);
        if (rc == 0)
            _exit(1); /* stored */
        if (!strstr(err, "CHECK") || strchr(err, '\n'))
            _exit(2); /* refused without saying why */
        tf_farmdb_close(cdb);
        _exit(0);
    }
    int st;
    assert_int_equal(waitpid(pid, &st, 0), pid);
    assert_true((WIFEXITED(st) && WEXITSTATUS(st) == 0) ||
                (WIFSIGNALED(st) && WTERMSIG(st) == SIGABRT));

    db = open_db("check2.db");
    tf_job *jobs;
    int n;
    char err[512];
    assert_int_equal(tf_farmdb_load(db, &jobs, &n, err, sizeof err), 0);
    assert_int_equal(n, 1);
    assert_string_equal(jobs[0].state, "queued");
    free(jobs);
    char *h = tf_farmdb_history(db, j.id);
    assert_null(strstr(h ? h : "", " bad"));
    free(h);
    tf_farmdb_close(db);
}

/* ---- the terrain shelf ---- */

/* A fake height field of n*n samples that tf_heightfield_free frees. */
static tf_heightfield *fake_hf(int n, float fill)
{
    tf_heightfield *hf = calloc(1, sizeof *hf);
    assert_non_null(hf);
    hf->n = n;
    hf->cells = n - 1;
    hf->h = malloc((size_t)n * (size_t)n * sizeof(float));
    assert_non_null(hf->h);
    for (int i = 0; i < n * n; i++)
        hf->h[i] = fill;
    return hf;
}

static void shelf_bytes(void **state)
{
    (void)state;
    tf_heightfield *hf = fake_hf(33, 0);
    assert_int_equal(tf_heightfield_bytes(hf), sizeof *hf + 33 * 33 * sizeof(float));
    hf->water = malloc(4);
    hf->silt = malloc(4);
    assert_int_equal(tf_heightfield_bytes(hf), sizeof *hf + 3 * 33 * 33 * sizeof(float));
    tf_heightfield_free(hf);
    /* the sun's strips kept with a terrain (render/sun_strips.h) count too */
    float h[33 * 33];
    for (int i = 0; i < 33 * 33; i++)
        h[i] = (float)(i % 7);
    tf_heightfield *real = tf_heightfield_from_heights(h, 5, 100.0, 1);
    assert_non_null(real);
    const size_t bare = tf_heightfield_bytes(real);
    assert_int_equal(tf_sun_strips_keep(real, v3(0.5, 0.5, 0.7), 1), 0);
    assert_true(tf_sun_strips_kept_bytes(real) > 0);
    assert_int_equal(tf_heightfield_bytes(real), bare + tf_sun_strips_kept_bytes(real));
    tf_heightfield_free(real);
}

static void keys_are(tf_terrain_shelf *sh, const char *const *want, int n)
{
    const char *keys[20];
    int got = tf_terrain_shelf_keys(sh, keys, 20);
    assert_int_equal(got, n);
    for (int i = 0; i < n; i++)
        assert_string_equal(keys[i], want[i]);
}

static void shelf_lru(void **state)
{
    (void)state;
    tf_heightfield *a = fake_hf(65, 1);
    size_t one = tf_heightfield_bytes(a);
    tf_terrain_shelf *sh = tf_terrain_shelf_new(3 * one);
    assert_non_null(sh);
    assert_null(tf_terrain_shelf_get(sh, "A"));
    keys_are(sh, NULL, 0);
    tf_terrain_shelf_put(sh, "A", a);
    tf_terrain_shelf_put(sh, "B", fake_hf(65, 2));
    tf_terrain_shelf_put(sh, "C", fake_hf(65, 3));
    keys_are(sh, (const char *[]){"C", "B", "A"}, 3);
    /* using A makes it the most recent; B is now the least */
    const tf_heightfield *got = tf_terrain_shelf_get(sh, "A");
    assert_ptr_equal(got, a);
    assert_true(got->h[0] == 1);
    keys_are(sh, (const char *[]){"A", "C", "B"}, 3);
    tf_terrain_shelf_put(sh, "D", fake_hf(65, 4));
    keys_are(sh, (const char *[]){"D", "A", "C"}, 3);
    assert_null(tf_terrain_shelf_get(sh, "B"));
    assert_true(tf_terrain_shelf_get(sh, "C")->h[0] == 3);
    keys_are(sh, (const char *[]){"C", "D", "A"}, 3);
    /* a bigger one takes the room of two */
    tf_terrain_shelf_put(sh, "E", fake_hf(91, 5)); /* about twice the bytes */
    assert_true(tf_heightfield_bytes(tf_terrain_shelf_get(sh, "E")) > one * 3 / 2);
    keys_are(sh, (const char *[]){"E", "C"}, 2);
    /* max of keys asked for */
    const char *k1[1];
    assert_int_equal(tf_terrain_shelf_keys(sh, k1, 1), 1);
    assert_string_equal(k1[0], "E");
    /* one over the whole budget stays alone: the newest is always kept */
    tf_terrain_shelf_put(sh, "huge", fake_hf(200, 6));
    keys_are(sh, (const char *[]){"huge"}, 1);
    assert_true(tf_terrain_shelf_get(sh, "huge")->h[0] == 6);
    /* and goes at the next put */
    tf_terrain_shelf_put(sh, "F", fake_hf(65, 7));
    keys_are(sh, (const char *[]){"F"}, 1);
    tf_terrain_shelf_free(sh);
    tf_terrain_shelf_free(NULL);
}

static void shelf_at_most_sixteen(void **state)
{
    (void)state;
    tf_terrain_shelf *sh = tf_terrain_shelf_new((size_t)1 << 40);
    char key[20][8];
    for (int i = 0; i < 20; i++) {
        snprintf(key[i], sizeof key[i], "k%d", i);
        tf_terrain_shelf_put(sh, key[i], fake_hf(3, (float)i));
    }
    const char *keys[20];
    assert_int_equal(tf_terrain_shelf_keys(sh, keys, 20), 16);
    for (int i = 0; i < 16; i++)
        assert_string_equal(keys[i], key[19 - i]);
    for (int i = 0; i < 4; i++)
        assert_null(tf_terrain_shelf_get(sh, key[i]));
    tf_terrain_shelf_free(sh);
}

static void shelf_put_again_replaces(void **state)
{
    (void)state;
    tf_heightfield *a = fake_hf(65, 1);
    size_t one = tf_heightfield_bytes(a);
    tf_terrain_shelf *sh = tf_terrain_shelf_new(10 * one);
    tf_terrain_shelf_put(sh, "A", a);
    tf_terrain_shelf_put(sh, "B", fake_hf(65, 2));
    tf_heightfield *a2 = fake_hf(65, 9);
    tf_terrain_shelf_put(sh, "A", a2);
    /* A once, the new one (the old one freed: make asan would see a leak), B still held */
    keys_are(sh, (const char *[]){"A", "B"}, 2);
    assert_ptr_equal(tf_terrain_shelf_get(sh, "A"), a2);
    assert_true(tf_terrain_shelf_get(sh, "B")->h[0] == 2);
    /* the bytes of one A counted, not two: eight more fill the budget of ten exactly */
    for (int i = 0; i < 8; i++) {
        char k[8];
        snprintf(k, sizeof k, "f%d", i);
        tf_terrain_shelf_put(sh, k, fake_hf(65, 0));
    }
    assert_non_null(tf_terrain_shelf_get(sh, "B"));
    assert_ptr_equal(tf_terrain_shelf_get(sh, "A"), a2);
    tf_terrain_shelf_free(sh);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(insert_load_content),
        cmocka_unit_test(update_and_history),
        cmocka_unit_test(tokens),
        cmocka_unit_test(reopen_keeps_everything),
        cmocka_unit_test(check_refuses_bad_state_sql),
        cmocka_unit_test(check_refuses_bad_state_api),
        cmocka_unit_test(kinds_round_trip),
        cmocka_unit_test(old_database_gains_kind),
        cmocka_unit_test(shelf_bytes),
        cmocka_unit_test(shelf_lru),
        cmocka_unit_test(shelf_at_most_sixteen),
        cmocka_unit_test(shelf_put_again_replaces),
    };
    return cmocka_run_group_tests(tests, scratch_dir_make, scratch_dir_remove);
}
