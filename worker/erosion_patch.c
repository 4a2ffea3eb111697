/* erosion_patch.c: a worker's side of an erosion on the farm (erosion_patch.h): take one patch,
 * run it round by round, trading edges with the 8 neighbours through the tuple space, and hand
 * in the final state (common/erosion_tuples.h has the protocol). */
#include "worker/erosion_patch.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"
#include "terrain/terrain_build.h"

typedef struct patch {
    ts_client *c;
    const tf_erosion_plan *plan;
    const tf_erosion_model *m;
    int id, pi, pj;
    int i0, i1, j0, j1; /* owned, global */
    int w, h, k;        /* owned size, halo */
    tf_erosion_window win;
    tf_erosion_tally tally;
    char from[64];
} patch;

/* The window rectangle of side `side`'s edge (erosion_tuples.h), in window coordinates. */
static tf_erosion_rect edge_rect(const patch *p, int side)
{
    int k = p->k;
    switch (side) {
    case 0: return (tf_erosion_rect){k, 2 * k, k, k + p->w};
    case 1: return (tf_erosion_rect){p->h, p->h + k, k, k + p->w};
    case 2: return (tf_erosion_rect){k, k + p->h, k, 2 * k};
    default: return (tf_erosion_rect){k, k + p->h, p->w, p->w + k};
    }
}

/* Whether a neighbour lies beyond side `side` (else nobody reads that edge). */
static int has_neighbour(const patch *p, int side)
{
    return side == 0 ? p->pj > 0 : side == 1 ? p->pj < p->plan->py - 1
                                 : side == 2 ? p->pi > 0 : p->pi < p->plan->px - 1;
}

static int put_edges(patch *p, int round, char *err, size_t errlen)
{
    for (int side = 0; side < 4; side++) {
        if (!has_neighbour(p, side))
            continue;
        tf_erosion_rect r = edge_rect(p, side);
        size_t len = tf_erosion_block_bytes(r.r1 - r.r0, r.c1 - r.c0);
        uint8_t *data = malloc(len);
        tf_tuple t;
        tf_tuple_init(&t);
        int bad = !data;
        if (data) {
            tf_erosion_block_pack(&p->win.v, r, data);
            bad = tf_tuple_pack(&t, "siiiib", "erode_edge", p->plan->job, (int64_t)p->id,
                                (int64_t)round, (int64_t)side, (const void *)data, len) ||
                  ts_out(p->c, &t);
        }
        free(data);
        tf_tuple_clear(&t);
        if (bad)
            return tf_seterr(err, errlen, "patch %d: cannot put its edge: %s", p->id,
                             ts_client_error(p->c));
    }
    return 0;
}

/* Take back this patch's edges of `round` (every neighbour has read them: erosion_tuples.h). */
static void drop_edges(patch *p, int round)
{
    for (int side = 0; side < 4; side++) {
        tf_tuple tmpl, got;
        tf_tuple_init(&tmpl);
        tf_tuple_init(&got);
        if (tf_tuple_pack(&tmpl, "siiiiB", "erode_edge", p->plan->job, (int64_t)p->id,
                          (int64_t)round, (int64_t)side) == 0)
            ts_inp(p->c, &tmpl, &got);
        tf_tuple_clear(&tmpl);
        tf_tuple_clear(&got);
    }
}

/* Which neighbour edge fills the halo block toward (di, dj), and the part of it to take. */
static void halo_source(const patch *p, int di, int dj, int nw, int nh, int *side,
                        tf_erosion_rect *part)
{
    int k = p->k;
    if (dj != 0) {
        *side = dj < 0 ? 1 : 0; /* the neighbour's north edge lies south of us */
        int c0 = di < 0 ? nw - k : 0, c1 = di == 0 ? nw : c0 + k;
        *part = (tf_erosion_rect){0, k, c0, c1};
    } else {
        *side = di < 0 ? 3 : 2;
        *part = (tf_erosion_rect){0, nh, 0, k};
    }
}

/* The window block toward (di, dj). */
static tf_erosion_rect halo_block(const patch *p, int di, int dj)
{
    int k = p->k;
    int c0 = di < 0 ? 0 : di == 0 ? k : k + p->w, c1 = di == 0 ? k + p->w : c0 + k;
    int r0 = dj < 0 ? 0 : dj == 0 ? k : k + p->h, r1 = dj == 0 ? k + p->h : r0 + k;
    return (tf_erosion_rect){r0, r1, c0, c1};
}

/* Copy the rows part of a block (rows x cols) into the window's rectangle dst. */
static void unpack_part(patch *p, const uint8_t *data, int rows, int cols, tf_erosion_rect part,
                        tf_erosion_rect dst)
{
    size_t count = (size_t)rows * (size_t)cols;
    int32_t *f[TF_EROSION_FIELDS] = {p->win.v.b, p->win.v.t, p->win.v.d,
                                     p->win.v.w, p->win.v.s, (int32_t *)p->win.v.flow};
    size_t len = (size_t)(part.c1 - part.c0) * 4;
    for (int k = 0; k < TF_EROSION_FIELDS; k++)
        for (int r = part.r0; r < part.r1; r++) {
            const uint8_t *src = data + (k * count + (size_t)r * cols + (size_t)part.c0) * 4;
            size_t at = (size_t)(dst.r0 + r - part.r0) * p->win.v.stride + (size_t)dst.c0;
            memcpy(f[k] + at, src, len);
        }
}

/* Read neighbour (pi + di, pj + dj)'s edge of `round` into the halo toward it. */
static int fill_from(patch *p, int di, int dj, int round, char *err, size_t errlen)
{
    int nb = (p->pj + dj) * p->plan->px + (p->pi + di);
    int ni0, ni1, nj0, nj1, side;
    tf_erosion_patch_rect(p->plan, nb, &ni0, &ni1, &nj0, &nj1);
    int nw = ni1 - ni0, nh = nj1 - nj0;
    tf_erosion_rect part;
    halo_source(p, di, dj, nw, nh, &side, &part);
    int rows = side < 2 ? p->k : nh, cols = side < 2 ? nw : p->k;
    tf_tuple tmpl, got;
    tf_tuple_init(&tmpl);
    tf_tuple_init(&got);
    const uint8_t *data;
    size_t len;
    char from[160];
    snprintf(from, sizeof from, "%s: patch %d's edge %d of round %d", p->from, nb, side, round);
    int rc = -1;
    if (tf_tuple_pack(&tmpl, "siiiiB", "erode_edge", p->plan->job, (int64_t)nb, (int64_t)round,
                      (int64_t)side) || ts_rd(p->c, &tmpl, &got))
        tf_seterr(err, errlen, "%s: cannot read it: %s", from, ts_client_error(p->c));
    else if (got.nfields != 6 || tf_tuple_get_blob(&got, 5, &data, &len))
        tf_seterr(err, errlen, "%s: malformed", from);
    else if (tf_erosion_block_check(data, len, rows, cols, from, err, errlen) == 0) {
        unpack_part(p, data, rows, cols, part, halo_block(p, di, dj));
        rc = 0;
    }
    tf_tuple_clear(&tmpl);
    tf_tuple_clear(&got);
    return rc;
}

static int fill_halo(patch *p, int round, char *err, size_t errlen)
{
    for (int dj = -1; dj <= 1; dj++)
        for (int di = -1; di <= 1; di++) {
            int qi = p->pi + di, qj = p->pj + dj;
            if ((di || dj) && qi >= 0 && qj >= 0 && qi < p->plan->px && qj < p->plan->py &&
                fill_from(p, di, dj, round, err, errlen) != 0)
                return -1;
        }
    return 0;
}

/* Steps first .. first + k - 1 on the window; the owned part is exact afterwards. */
static int run_round(patch *p, int first, int k, char *err, size_t errlen)
{
    int n = p->m->n;
    tf_erosion_rect own = {p->k, p->k + p->h, p->k, p->k + p->w};
    for (int s = 0; s < k; s++) {
        int g = k - 1 - s;
        tf_erosion_rect r = {own.r0 - g, own.r1 + g, own.c0 - g, own.c1 + g};
        r.r0 = r.r0 + p->win.v.gj < 0 ? -p->win.v.gj : r.r0;
        r.c0 = r.c0 + p->win.v.gi < 0 ? -p->win.v.gi : r.c0;
        r.r1 = r.r1 + p->win.v.gj > n ? n - p->win.v.gj : r.r1;
        r.c1 = r.c1 + p->win.v.gi > n ? n - p->win.v.gi : r.c1;
        if (tf_erosion_step(p->m, &p->win.v, r, own, first + s, &p->tally) != 0)
            return tf_seterr(err, errlen, "patch %d: out of memory", p->id);
    }
    return 0;
}

/* The owned state in bands of rows, then the tally. */
static int hand_in(patch *p, char *err, size_t errlen)
{
    int band = (int)((8u << 20) / tf_erosion_block_bytes(1, p->w));
    band = band < 1 ? 1 : band;
    for (int r = 0; r < p->h; r += band) {
        int rows = p->h - r < band ? p->h - r : band;
        tf_erosion_rect rect = {p->k + r, p->k + r + rows, p->k, p->k + p->w};
        size_t len = tf_erosion_block_bytes(rows, p->w);
        uint8_t *data = malloc(len);
        tf_tuple t;
        tf_tuple_init(&t);
        int bad = !data;
        if (data) {
            tf_erosion_block_pack(&p->win.v, rect, data);
            bad = tf_tuple_pack(&t, "siiiib", "erode_final", p->plan->job, (int64_t)p->id,
                                (int64_t)r, (int64_t)rows, (const void *)data, len) ||
                  ts_out(p->c, &t);
        }
        free(data);
        tf_tuple_clear(&t);
        if (bad)
            return tf_seterr(err, errlen, "patch %d: cannot hand in: %s", p->id,
                             ts_client_error(p->c));
    }
    tf_tuple t;
    tf_tuple_init(&t);
    int bad = tf_tuple_pack(&t, "siiiiii", "erode_tally", p->plan->job, (int64_t)p->id,
                            p->tally.rain, p->tally.evaporated, p->tally.out_water,
                            p->tally.out_load) ||
              ts_out(p->c, &t);
    tf_tuple_clear(&t);
    return bad ? tf_seterr(err, errlen, "patch %d: cannot hand in its tally", p->id) : 0;
}

static int run_patch(patch *p, const tf_erosion_state *init, char *err, size_t errlen)
{
    tf_erosion_patch_rect(p->plan, p->id, &p->i0, &p->i1, &p->j0, &p->j1);
    p->pi = p->id % p->plan->px;
    p->pj = p->id / p->plan->px;
    p->w = p->i1 - p->i0;
    p->h = p->j1 - p->j0;
    p->k = p->plan->halo;
    if (tf_erosion_window_alloc(&p->win, p->w + 2 * p->k, p->h + 2 * p->k) != 0)
        return tf_seterr(err, errlen, "patch %d: out of memory", p->id);
    tf_erosion_window_load(&p->win, init, p->i0 - p->k, p->j0 - p->k);
    int rounds = tf_erosion_plan_rounds(p->plan);
    for (int r = 0; r < rounds; r++) {
        int first = r * p->k;
        int k = p->plan->steps - first < p->k ? p->plan->steps - first : p->k;
        if ((r > 0 && fill_halo(p, r - 1, err, errlen) != 0) ||
            run_round(p, first, k, err, errlen) != 0)
            return -1;
        if (r + 1 < rounds && put_edges(p, r, err, errlen) != 0)
            return -1;
        if (r >= 2)
            drop_edges(p, r - 2);
    }
    return hand_in(p, err, errlen);
}

static void report_failure(ts_client *c, int64_t job, int id, const char *why)
{
    tf_tuple t;
    tf_tuple_init(&t);
    if (tf_tuple_pack(&t, "siis", "erode_failed", job, (int64_t)id, why) == 0)
        ts_out(c, &t);
    tf_tuple_clear(&t);
}

int tf_erosion_patch_serve(ts_client *c, const tf_erosion_plan *plan, const tf_erosion_model *m,
                           const tf_erosion_state *init, const char *from)
{
    tf_tuple tmpl, got;
    tf_tuple_init(&tmpl);
    tf_tuple_init(&got);
    int64_t id;
    if (tf_tuple_pack(&tmpl, "siI", "erode_patch", plan->job) || ts_in(c, &tmpl, &got) ||
        tf_tuple_get_int(&got, 2, &id) || id < 0 || id >= (int64_t)plan->px * plan->py) {
        tf_error("%s: cannot take a patch: %s", from, ts_client_error(c));
        tf_tuple_clear(&tmpl);
        tf_tuple_clear(&got);
        return 1;
    }
    tf_tuple_clear(&tmpl);
    tf_tuple_clear(&got);
    patch p = {.c = c, .plan = plan, .m = m, .id = (int)id};
    snprintf(p.from, sizeof p.from, "%s", from);
    char err[512];
    int rc = run_patch(&p, init, err, sizeof err);
    tf_erosion_window_free(&p.win);
    if (rc != 0) {
        tf_error("%s", err);
        report_failure(c, plan->job, (int)id, err);
        return 1;
    }
    return 0;
}

/* ---- a networked erosion worker ------------------------------------------------------ */

/* The plan in c's space, if it is an erosion's: 1 found, 0 not an erosion, -1 error. */
static int fetch_plan(ts_client *c, tf_erosion_plan *p)
{
    tf_tuple tmpl, got;
    tf_tuple_init(&tmpl);
    tf_tuple_init(&got);
    int64_t v[6];
    int rc = tf_tuple_pack(&tmpl, "sIIIIII", "erode_plan") ? -1 : ts_rdp(c, &tmpl, &got);
    for (int k = 0; rc == 1 && k < 6; k++)
        if (tf_tuple_get_int(&got, 1 + k, &v[k]) || v[k] < 0 || v[k] > (1 << 24))
            rc = -1;
    if (rc == 1)
        *p = (tf_erosion_plan){v[0], (int)v[1], (int)v[2], (int)v[3], (int)v[4], (int)v[5]};
    tf_tuple_clear(&tmpl);
    tf_tuple_clear(&got);
    return rc;
}

/* The plan must be the one this scene makes: else the patches would not fit. */
static int plan_fits(const tf_erosion_plan *p, const tf_scene *s, const char *from, char *err,
                     size_t errlen)
{
    tf_erosion_plan mine;
    int n = (1 << s->terrain.size_exp) + 1;
    if (p->px < 1 || p->py < 1 || p->px > 1024 || p->py > 1024 ||
        tf_erosion_plan_make(&mine, p->job, n, p->px * p->py, p->halo, p->steps) != 0 ||
        mine.px != p->px || mine.py != p->py || mine.halo != p->halo || p->n != n ||
        p->steps != s->terrain.erosion.fluvial_steps)
        return tf_seterr(err, errlen, "%s: an erosion plan (%dx%d patches of a %d grid, halo "
                         "%d, %d steps) that does not fit its scene", from, p->px, p->py, p->n,
                         p->halo, p->steps);
    return 0;
}

int tf_erosion_networked(ts_client *c, const tf_scene *s, const char *from, int heartbeat_ms)
{
    tf_erosion_plan plan;
    char err[1024];
    if (fetch_plan(c, &plan) != 1) {
        tf_error("%s: an erosion without a readable plan: %s", from, ts_client_error(c));
        return 1;
    }
    tf_erosion_model m;
    tf_erosion_state st = {0};
    ts_client_heartbeat(c, heartbeat_ms); /* rounds can outlast the server's silence timeout */
    int rc = plan_fits(&plan, s, from, err, sizeof err) != 0 ||
             tf_terrain_erosion_start(&s->terrain, NULL, &m, &st, err, sizeof err) != 0;
    if (rc)
        tf_error("%s", err);
    else {
        tf_info("joining %s: erosion of a %dx%d grid, %d steps, as one of %d patches", from,
                plan.n, plan.n, plan.steps, plan.px * plan.py);
        rc = tf_erosion_patch_serve(c, &plan, &m, &st, from);
    }
    tf_erosion_state_free(&st);
    return rc;
}
