/* farmdb.c: see farmdb.h. */
#include "coordinator/farm/farmdb.h"

#include <assert.h>
#include <sqlite3.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "log.h"

struct tf_farmdb {
    sqlite3 *db;
};

static const char schema[] =
    "PRAGMA journal_mode=WAL;"
    "PRAGMA synchronous=FULL;"
    "PRAGMA foreign_keys=ON;"
    "CREATE TABLE IF NOT EXISTS jobs("
    " id INTEGER PRIMARY KEY AUTOINCREMENT,"
    " name TEXT NOT NULL, owner TEXT NOT NULL, pool TEXT NOT NULL, tags TEXT NOT NULL,"
    " priority INTEGER NOT NULL, after INTEGER NOT NULL,"
    " state TEXT NOT NULL CHECK(state IN ('queued','paused','done','failed','cancelled')),"
    " reason TEXT NOT NULL, scene_hash TEXT NOT NULL, terrain TEXT NOT NULL,"
    " nonce TEXT NOT NULL, output TEXT NOT NULL, frames INTEGER NOT NULL,"
    " width INTEGER NOT NULL, height INTEGER NOT NULL, attempts INTEGER NOT NULL,"
    " created REAL NOT NULL, started REAL NOT NULL, finished REAL NOT NULL,"
    " kind TEXT NOT NULL DEFAULT 'render' CHECK(kind IN ('render','paint')));"
    "CREATE TABLE IF NOT EXISTS content("
    " job INTEGER PRIMARY KEY REFERENCES jobs(id), scene BLOB NOT NULL, heightmap BLOB,"
    " heightmap_name TEXT, options TEXT NOT NULL);"
    "CREATE TABLE IF NOT EXISTS history("
    " job INTEGER NOT NULL REFERENCES jobs(id), t REAL NOT NULL, event TEXT NOT NULL);"
    "CREATE INDEX IF NOT EXISTS history_job ON history(job);"
    "CREATE TABLE IF NOT EXISTS tokens("
    " hash TEXT PRIMARY KEY, name TEXT NOT NULL UNIQUE,"
    " role TEXT NOT NULL CHECK(role IN ('submitter','admin')), created REAL NOT NULL);";

/* A database written before jobs had a kind: its jobs are renders. */
static const char add_kind[] =
    "ALTER TABLE jobs ADD COLUMN kind TEXT NOT NULL DEFAULT 'render' "
    "CHECK(kind IN ('render','paint'));";

static int has_kind(sqlite3 *db)
{
    sqlite3_stmt *st;
    int ok = sqlite3_prepare_v2(db, "SELECT kind FROM jobs LIMIT 0", -1, &st, NULL) == SQLITE_OK;
    sqlite3_finalize(st);
    return ok;
}

static double unix_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (double)ts.tv_sec + ts.tv_nsec / 1e9;
}

static int db_fail(tf_farmdb *db, const char *what, char *err, size_t errlen)
{
    return tf_seterr(err, errlen, "farm database: %s: %s", what, sqlite3_errmsg(db->db));
}

tf_farmdb *tf_farmdb_open(const char *path, char *err, size_t errlen)
{
    tf_farmdb *db = calloc(1, sizeof *db);
    if (!db) {
        tf_seterr(err, errlen, "out of memory");
        return NULL;
    }
    int rc = sqlite3_open_v2(path, &db->db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE |
                                                SQLITE_OPEN_FULLMUTEX, NULL);
    if (rc == SQLITE_OK)
        sqlite3_busy_timeout(db->db, 5000);
    char *msg = NULL;
    if (rc != SQLITE_OK || sqlite3_exec(db->db, schema, NULL, NULL, &msg) != SQLITE_OK ||
        (!has_kind(db->db) && sqlite3_exec(db->db, add_kind, NULL, NULL, &msg) != SQLITE_OK)) {
        tf_seterr(err, errlen, "%s: cannot open the farm database: %s", path,
                  msg ? msg : db->db ? sqlite3_errmsg(db->db) : "out of memory");
        sqlite3_free(msg);
        tf_farmdb_close(db);
        return NULL;
    }
    return db;
}

void tf_farmdb_close(tf_farmdb *db)
{
    if (!db)
        return;
    sqlite3_close(db->db);
    free(db);
}

static int exec(tf_farmdb *db, const char *sql, char *err, size_t errlen)
{
    char *msg = NULL;
    if (sqlite3_exec(db->db, sql, NULL, NULL, &msg) == SQLITE_OK)
        return 0;
    tf_seterr(err, errlen, "farm database: %s", msg ? msg : sqlite3_errmsg(db->db));
    sqlite3_free(msg);
    return -1;
}

__attribute__((unused)) static int state_ok(const char *s)
{
    static const char *states[] = {"queued", "paused", "done", "failed", "cancelled"};
    for (size_t i = 0; i < sizeof states / sizeof *states; i++)
        if (!strcmp(s, states[i]))
            return 1;
    return 0;
}

static int insert_job_row(tf_farmdb *db, tf_job *j, char *err, size_t errlen)
{
    sqlite3_stmt *st;
    const char *sql = "INSERT INTO jobs(name,owner,pool,tags,priority,after,state,reason,"
                      "scene_hash,terrain,nonce,output,frames,width,height,attempts,created,"
                      "started,finished,kind) VALUES(?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,0,?,0,0,?)";
    if (sqlite3_prepare_v2(db->db, sql, -1, &st, NULL) != SQLITE_OK)
        return db_fail(db, "insert", err, errlen);
    const char *text[] = {j->name, j->owner, j->pool, j->tags};
    for (int i = 0; i < 4; i++)
        sqlite3_bind_text(st, i + 1, text[i], -1, SQLITE_STATIC);
    sqlite3_bind_int(st, 5, j->priority);
    sqlite3_bind_int64(st, 6, j->after);
    const char *text2[] = {j->state, j->reason, j->scene_hash, j->terrain, j->nonce, j->output};
    for (int i = 0; i < 6; i++)
        sqlite3_bind_text(st, i + 7, text2[i], -1, SQLITE_STATIC);
    sqlite3_bind_int(st, 13, j->frames);
    sqlite3_bind_int(st, 14, j->width);
    sqlite3_bind_int(st, 15, j->height);
    sqlite3_bind_double(st, 16, j->created);
    sqlite3_bind_text(st, 17, j->kind[0] ? j->kind : "render", -1, SQLITE_STATIC);
    int rc = sqlite3_step(st);
    sqlite3_finalize(st);
    if (rc != SQLITE_DONE)
        return db_fail(db, "insert", err, errlen);
    j->id = sqlite3_last_insert_rowid(db->db);
    return 0;
}

static int insert_content(tf_farmdb *db, int64_t id, const tf_job_content *c, char *err,
                          size_t errlen)
{
    sqlite3_stmt *st;
    if (sqlite3_prepare_v2(db->db, "INSERT INTO content(job,scene,heightmap,heightmap_name,"
                           "options) VALUES(?,?,?,?,?)", -1, &st, NULL) != SQLITE_OK)
        return db_fail(db, "insert content", err, errlen);
    sqlite3_bind_int64(st, 1, id);
    sqlite3_bind_blob64(st, 2, c->scene, c->scene_len, SQLITE_STATIC);
    if (c->heightmap)
        sqlite3_bind_blob64(st, 3, c->heightmap, c->heightmap_len, SQLITE_STATIC);
    if (c->heightmap_name)
        sqlite3_bind_text(st, 4, c->heightmap_name, -1, SQLITE_STATIC);
    sqlite3_bind_text(st, 5, c->options, -1, SQLITE_STATIC);
    int rc = sqlite3_step(st);
    sqlite3_finalize(st);
    return rc == SQLITE_DONE ? 0 : db_fail(db, "insert content", err, errlen);
}

static int add_history(tf_farmdb *db, int64_t id, const char *event, char *err, size_t errlen)
{
    sqlite3_stmt *st;
    if (sqlite3_prepare_v2(db->db, "INSERT INTO history(job,t,event) VALUES(?,?,?)", -1, &st,
                           NULL) != SQLITE_OK)
        return db_fail(db, "history", err, errlen);
    sqlite3_bind_int64(st, 1, id);
    sqlite3_bind_double(st, 2, unix_now());
    sqlite3_bind_text(st, 3, event, -1, SQLITE_STATIC);
    int rc = sqlite3_step(st);
    sqlite3_finalize(st);
    return rc == SQLITE_DONE ? 0 : db_fail(db, "history", err, errlen);
}

int tf_farmdb_insert(tf_farmdb *db, tf_job *j, const tf_job_content *c, char *err, size_t errlen)
{
    assert(state_ok(j->state) && "Q1: a stored state is one of TF_JOB_STATES");
    if (exec(db, "BEGIN IMMEDIATE", err, errlen))
        return -1;
    if (insert_job_row(db, j, err, errlen) || insert_content(db, j->id, c, err, errlen) ||
        add_history(db, j->id, "submitted", err, errlen)) {
        exec(db, "ROLLBACK", NULL, 0);
        return -1;
    }
    assert(j->id > 0 && "Q2: a job's id is positive");
    return exec(db, "COMMIT", err, errlen);
}

static void copy_col(sqlite3_stmt *st, int col, char *dst, size_t n)
{
    const unsigned char *t = sqlite3_column_text(st, col);
    snprintf(dst, n, "%s", t ? (const char *)t : "");
}

static void read_job(sqlite3_stmt *st, tf_job *j)
{
    memset(j, 0, sizeof *j);
    j->id = sqlite3_column_int64(st, 0);
    copy_col(st, 1, j->name, sizeof j->name);
    copy_col(st, 2, j->owner, sizeof j->owner);
    copy_col(st, 3, j->pool, sizeof j->pool);
    copy_col(st, 4, j->tags, sizeof j->tags);
    j->priority = sqlite3_column_int(st, 5);
    j->after = sqlite3_column_int64(st, 6);
    copy_col(st, 7, j->state, sizeof j->state);
    copy_col(st, 8, j->reason, sizeof j->reason);
    copy_col(st, 9, j->scene_hash, sizeof j->scene_hash);
    copy_col(st, 10, j->terrain, sizeof j->terrain);
    copy_col(st, 11, j->nonce, sizeof j->nonce);
    copy_col(st, 12, j->output, sizeof j->output);
    j->frames = sqlite3_column_int(st, 13);
    j->width = sqlite3_column_int(st, 14);
    j->height = sqlite3_column_int(st, 15);
    j->attempts = sqlite3_column_int(st, 16);
    j->created = sqlite3_column_double(st, 17);
    j->started = sqlite3_column_double(st, 18);
    j->finished = sqlite3_column_double(st, 19);
    copy_col(st, 20, j->kind, sizeof j->kind);
}

int tf_farmdb_load(tf_farmdb *db, tf_job **out, int *n, char *err, size_t errlen)
{
    sqlite3_stmt *st;
    *out = NULL;
    *n = 0;
    if (sqlite3_prepare_v2(db->db, "SELECT id,name,owner,pool,tags,priority,after,state,reason,"
                           "scene_hash,terrain,nonce,output,frames,width,height,attempts,"
                           "created,started,finished,kind FROM jobs ORDER BY id", -1, &st,
                           NULL) != SQLITE_OK)
        return db_fail(db, "load", err, errlen);
    int cap = 0, rc;
    while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
        if (*n == cap) {
            cap = cap ? 2 * cap : 64;
            tf_job *nj = realloc(*out, (size_t)cap * sizeof **out);
            if (!nj)
                break;
            *out = nj;
        }
        read_job(st, &(*out)[(*n)++]);
        assert(state_ok((*out)[*n - 1].state) && "Q1: a stored state is one of TF_JOB_STATES");
    }
    sqlite3_finalize(st);
    if (rc != SQLITE_DONE) {
        free(*out);
        *out = NULL;
        *n = 0;
        return tf_seterr(err, errlen, "farm database: cannot load the jobs (%s)",
                         rc == SQLITE_ROW ? "out of memory" : sqlite3_errmsg(db->db));
    }
    return 0;
}

static void *dup_blob(sqlite3_stmt *st, int col, size_t *len, int nul)
{
    const void *b = sqlite3_column_blob(st, col);
    *len = (size_t)sqlite3_column_bytes(st, col);
    if (!b && !nul)
        return NULL;
    char *out = malloc(*len + 1);
    if (out) {
        if (*len)
            memcpy(out, b, *len);
        out[*len] = 0;
    }
    return out;
}

int tf_farmdb_content(tf_farmdb *db, int64_t id, tf_job_content *c, char *err, size_t errlen)
{
    sqlite3_stmt *st;
    memset(c, 0, sizeof *c);
    if (sqlite3_prepare_v2(db->db, "SELECT scene,heightmap,heightmap_name,options FROM content "
                           "WHERE job=?", -1, &st, NULL) != SQLITE_OK)
        return db_fail(db, "content", err, errlen);
    sqlite3_bind_int64(st, 1, id);
    int rc = -1;
    if (sqlite3_step(st) == SQLITE_ROW) {
        size_t n;
        c->scene = dup_blob(st, 0, &c->scene_len, 1);
        c->heightmap = dup_blob(st, 1, &c->heightmap_len, 0);
        c->heightmap_name = dup_blob(st, 2, &n, 0);
        c->options = dup_blob(st, 3, &n, 1);
        rc = c->scene && c->options ? 0 : -1;
    }
    sqlite3_finalize(st);
    if (rc)
        tf_job_content_free(c);
    return rc ? tf_seterr(err, errlen, "farm database: job %lld has no content",
                          (long long)id)
              : 0;
}

void tf_job_content_free(tf_job_content *c)
{
    free(c->scene);
    free(c->heightmap);
    free(c->heightmap_name);
    free(c->options);
    memset(c, 0, sizeof *c);
}

static int update_row(tf_farmdb *db, const tf_job *j, char *err, size_t errlen)
{
    sqlite3_stmt *st;
    if (sqlite3_prepare_v2(db->db, "UPDATE jobs SET state=?,reason=?,priority=?,attempts=?,"
                           "started=?,finished=? WHERE id=?", -1, &st, NULL) != SQLITE_OK)
        return db_fail(db, "update", err, errlen);
    sqlite3_bind_text(st, 1, j->state, -1, SQLITE_STATIC);
    sqlite3_bind_text(st, 2, j->reason, -1, SQLITE_STATIC);
    sqlite3_bind_int(st, 3, j->priority);
    sqlite3_bind_int(st, 4, j->attempts);
    sqlite3_bind_double(st, 5, j->started);
    sqlite3_bind_double(st, 6, j->finished);
    sqlite3_bind_int64(st, 7, j->id);
    int rc = sqlite3_step(st);
    sqlite3_finalize(st);
    return rc == SQLITE_DONE ? 0 : db_fail(db, "update", err, errlen);
}

int tf_farmdb_update(tf_farmdb *db, const tf_job *j, const char *event, char *err,
                     size_t errlen)
{
    assert(state_ok(j->state) && "Q1: a stored state is one of TF_JOB_STATES");
    if (exec(db, "BEGIN IMMEDIATE", err, errlen))
        return -1;
    if (update_row(db, j, err, errlen) || (event && add_history(db, j->id, event, err, errlen))) {
        exec(db, "ROLLBACK", NULL, 0);
        return -1;
    }
    return exec(db, "COMMIT", err, errlen);
}

char *tf_farmdb_history(tf_farmdb *db, int64_t id)
{
    sqlite3_stmt *st;
    if (sqlite3_prepare_v2(db->db, "SELECT t,event FROM history WHERE job=? ORDER BY rowid", -1,
                           &st, NULL) != SQLITE_OK)
        return NULL;
    sqlite3_bind_int64(st, 1, id);
    char *buf = NULL;
    size_t len = 0;
    FILE *f = open_memstream(&buf, &len);
    while (f && sqlite3_step(st) == SQLITE_ROW)
        fprintf(f, "%.3f %s\n", sqlite3_column_double(st, 0),
                (const char *)sqlite3_column_text(st, 1));
    sqlite3_finalize(st);
    if (f)
        fclose(f);
    return buf;
}

int tf_farmdb_token_add(tf_farmdb *db, const char *name, const char *role, const char *hash_hex,
                        char *err, size_t errlen)
{
    assert(strlen(hash_hex) == 64 && "Q3: a token is stored only as its hash");
    sqlite3_stmt *st;
    if (sqlite3_prepare_v2(db->db, "INSERT INTO tokens(hash,name,role,created) VALUES(?,?,?,?)",
                           -1, &st, NULL) != SQLITE_OK)
        return db_fail(db, "token", err, errlen);
    sqlite3_bind_text(st, 1, hash_hex, -1, SQLITE_STATIC);
    sqlite3_bind_text(st, 2, name, -1, SQLITE_STATIC);
    sqlite3_bind_text(st, 3, role, -1, SQLITE_STATIC);
    sqlite3_bind_double(st, 4, unix_now());
    int rc = sqlite3_step(st), ext = sqlite3_extended_errcode(db->db);
    sqlite3_finalize(st);
    /* Which constraint refused it: the name (UNIQUE), the token itself (its hash is the
     * PRIMARY KEY) or the role (CHECK); each says so, not all "the name exists". */
    if (rc == SQLITE_CONSTRAINT && ext == SQLITE_CONSTRAINT_UNIQUE)
        return tf_seterr(err, errlen, "farm database: a token named '%s' exists already", name);
    if (rc == SQLITE_CONSTRAINT && ext == SQLITE_CONSTRAINT_PRIMARYKEY)
        return tf_seterr(err, errlen, "farm database: this token exists already (under "
                         "another name)");
    if (rc == SQLITE_CONSTRAINT && ext == SQLITE_CONSTRAINT_CHECK)
        return tf_seterr(err, errlen, "farm database: role '%s': a token's role is submitter "
                         "or admin", role);
    return rc == SQLITE_DONE ? 0 : db_fail(db, "token", err, errlen);
}

int tf_farmdb_token_find(tf_farmdb *db, const char *hash_hex, char *name, size_t namelen,
                         char *role, size_t rolelen)
{
    sqlite3_stmt *st;
    if (sqlite3_prepare_v2(db->db, "SELECT name,role FROM tokens WHERE hash=?", -1, &st,
                           NULL) != SQLITE_OK)
        return -1;
    sqlite3_bind_text(st, 1, hash_hex, -1, SQLITE_STATIC);
    int rc = sqlite3_step(st), found = rc == SQLITE_ROW;
    if (found) {
        copy_col(st, 0, name, namelen);
        copy_col(st, 1, role, rolelen);
    }
    sqlite3_finalize(st);
    return found ? 1 : rc == SQLITE_DONE ? 0 : -1;
}
