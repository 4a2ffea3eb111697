/* erosion_step.c: one time step of the erosion model (erosion.h, E1-E3) over a rectangle,
 * 8 vertices at a time, compiled twice: for AVX2 and for the baseline ISA (the portable path).
 *
 * The code is written once with GCC's generic vectors (8 x int32, 8 x float); the compiler
 * lowers them to 256-bit AVX2 in the avx2 copy and to pairs of SSE2 operations (or scalars on
 * other machines) in the portable one.  Only IEEE add, subtract, multiply, compare and
 * float <-> int truncation are used, never a fused multiply-add, so both copies compute the
 * same bits; tests/unit/test_erosion.c runs both and compares.
 *
 * Within the rectangle the rows are updated in place from the bottom up: before row j changes,
 * the transfers on the edges between rows j and j+1 and along row j are computed from the old
 * state and kept (the edges between rows j-1 and j were kept from the previous row), so every
 * transfer sees only the old state (erosion.h, E1), and each edge is computed once. */
#include "terrain/erosion.h"

#include <stdlib.h>
#include <string.h>

/* The vector helpers below are always inlined, so no vector crosses a call: GCC's note that
 * passing one would change the ABI between the two copies does not apply. */
#pragma GCC diagnostic ignored "-Wpsabi"

#define LANES 8
typedef int32_t vi __attribute__((vector_size(32)));
typedef float vf __attribute__((vector_size(32)));

#define INLINE static inline __attribute__((always_inline))

INLINE vi ld_i(const int32_t *p)
{
    vi x;
    memcpy(&x, p, sizeof x);
    return x;
}
INLINE vf ld_f(const float *p)
{
    vf x;
    memcpy(&x, p, sizeof x);
    return x;
}
INLINE void st_i(int32_t *p, vi x) { memcpy(p, &x, sizeof x); }
INLINE void st_f(float *p, vf x) { memcpy(p, &x, sizeof x); }
INLINE vi splat_i(int32_t x) { return (vi){x, x, x, x, x, x, x, x}; }
INLINE vf splat_f(float x) { return (vf){x, x, x, x, x, x, x, x}; }
INLINE vi sel_i(vi m, vi a, vi b) { return (a & m) | (b & ~m); }
INLINE vf sel_f(vi m, vf a, vf b) { return (vf)(((vi)a & m) | ((vi)b & ~m)); }
INLINE vi min_i(vi a, vi b) { return sel_i(a < b, a, b); }
INLINE vi max_i(vi a, vi b) { return sel_i(a > b, a, b); }
INLINE vf min_f(vf a, vf b) { return sel_f(a < b, a, b); }
INLINE vf max_f(vf a, vf b) { return sel_f(a > b, a, b); }
INLINE vf to_f(vi x) { return __builtin_convertvector(x, vf); }
INLINE vi to_i(vf x) { return __builtin_convertvector(x, vi); } /* truncates toward zero */
INLINE vi pos(vi x) { return max_i(x, splat_i(0)); }
INLINE vi neg(vi x) { return max_i(-x, splat_i(0)); }

/* Eight vertices' old state, and what the edges need of it. */
typedef struct {
    vi b, t, d, w, s, a, h; /* a = ground, h = water surface */
    vf k;                   /* K_s times the softness of the top layer */
} vtx;

/* The bedrock's strata factor at altitude b: a triangle wave between 1 - contrast and 1. */
INLINE vf strata(const tf_erosion_model *m, vi b)
{
    vf u = to_f(b) * splat_f(m->inv_strata_units);
    vf fl = to_f(to_i(u));
    fl = sel_f(u < fl, fl - splat_f(1.0f), fl); /* floor */
    vf f = (u - fl) * splat_f(2.0f) - splat_f(1.0f);
    return splat_f(1.0f) - splat_f(m->strata_contrast) * max_f(f, -f);
}

INLINE vtx load_vtx(const tf_erosion_model *m, const tf_erosion_view *v, size_t at)
{
    vtx x;
    x.b = ld_i(v->b + at);
    x.t = ld_i(v->t + at);
    x.d = ld_i(v->d + at);
    x.w = ld_i(v->w + at);
    x.s = ld_i(v->s + at);
    x.a = x.b + x.t + x.d;
    x.h = x.a + x.w;
    vf rock = splat_f(m->ks) * ld_f(v->soft + at);
    if (m->inv_strata_units > 0.0f)
        rock = rock * strata(m, x.b);
    x.k = sel_f(x.d > 0, splat_f(m->k_silt), sel_f(x.t > 0, splat_f(m->k_talus), rock));
    return x;
}

/* The transfers on eight edges P-Q, positive from P to Q (erosion.h, E1). */
typedef struct {
    vi dw, sus, ero, crp;
} edge;

INLINE edge edge_of(const tf_erosion_model *m, const vtx *p, const vtx *q, vi inner)
{
    vi pq = p->h > q->h, qp = q->h > p->h;
    vi ws = sel_i(pq, p->w, q->w), ss = sel_i(pq, p->s, q->s);
    vi drop = sel_i(pq, p->a - q->a, q->a - p->a);
    vi dh = sel_i(pq, p->h - q->h, q->h - p->h);
    vf k = sel_f(pq, p->k, q->k);
    vi dw = to_i(splat_f(0.25f) * min_f(to_f(ws), splat_f(0.5f) * to_f(dh)));
    vf cap = splat_f(m->kc) * to_f(dw);
    vf share = splat_f(0.25f) * to_f(ss);
    vi sus = to_i(min_f(share, cap));
    vf deficit = max_f(cap - share, splat_f(0.0f));
    vf limit = splat_f(0.125f) * max_f(to_f(drop), splat_f(0.0f));
    vi ero = to_i(min_f(k * deficit, limit));
    edge e;
    e.dw = sel_i(qp, -dw, dw);
    e.sus = sel_i(qp, -sus, sus);
    e.ero = sel_i(qp, -ero, ero);
    e.crp = to_i(splat_f(m->creep) * to_f(p->a - q->a)) & inner;
    return e;
}

/* Edge buffers: transfers stored per component, so a row of them is four int32 arrays. */
typedef struct {
    int32_t *dw, *sus, *ero, *crp;
} edge_row;

INLINE void put_edge(const edge_row *r, int k, edge e)
{
    st_i(r->dw + k, e.dw);
    st_i(r->sus + k, e.sus);
    st_i(r->ero + k, e.ero);
    st_i(r->crp + k, e.crp);
}
INLINE edge get_edge(const edge_row *r, int k)
{
    return (edge){ld_i(r->dw + k), ld_i(r->sus + k), ld_i(r->ero + k), ld_i(r->crp + k)};
}

/* Lanes of global column gi0 + lane that lie on the grid's outer ring, or all if row is. */
INLINE vi ring_lanes(int n, int gi0, int row_on_ring)
{
    vi col = splat_i(gi0) + (vi){0, 1, 2, 3, 4, 5, 6, 7};
    vi ring = (col == 0) | (col == splat_i(n - 1));
    return row_on_ring ? splat_i(-1) : ring;
}

/* What flows into a vertex from one of its edges, summed over its four (erosion.h, E2). */
typedef struct {
    vi water, out_water, out_load, in_load, ground_out, creep_in;
} inflow;

INLINE void add_inflow(inflow *f, edge e)
{
    f->water += e.dw;
    f->out_water += neg(e.dw);
    f->out_load += neg(e.sus);
    f->in_load += pos(e.sus) + pos(e.ero);
    f->ground_out += neg(e.ero) + neg(e.crp);
    f->creep_in += pos(e.crp);
}
INLINE edge reversed(edge e) { return (edge){-e.dw, -e.sus, -e.ero, -e.crp}; }

/* Add the lanes of x selected by mask to *sum. */
INLINE void tally_add(int64_t *sum, vi x, vi mask)
{
    x &= mask;
    for (int l = 0; l < LANES; l++)
        *sum += x[l];
}

typedef struct {
    const tf_erosion_model *m;
    const tf_erosion_view *v;
    float rain_now;
    int row_ring;       /* this row is the grid's first or last */
    vi own_row;         /* all lanes if the row is owned, none if not */
    int own_c0, own_c1;
    int c1;             /* the rectangle's end column */
    tf_erosion_tally *tally;
} row_ctx;

/* E2 and E3 for the eight vertices at column c of row j; k indexes the edge buffers. */
INLINE void update8(const row_ctx *rc, size_t at, int c, const edge_row *hor, const edge_row *down,
                    const edge_row *up, int k)
{
    const tf_erosion_model *m = rc->m;
    const tf_erosion_view *v = rc->v;
    inflow f = {0};
    add_inflow(&f, get_edge(hor, k));
    add_inflow(&f, reversed(get_edge(hor, k + 1)));
    add_inflow(&f, get_edge(down, k));
    add_inflow(&f, reversed(get_edge(up, k)));

    vi b = ld_i(v->b + at), t = ld_i(v->t + at), d = ld_i(v->d + at);
    vi w = ld_i(v->w + at), s = ld_i(v->s + at);
    vi a_old = b + t + d;
    vi kept = s - f.out_load;
    vi dep = to_i(splat_f(m->kd) * to_f(kept));
    s = kept - dep + f.in_load;
    w = w + f.water;
    vi take = min_i(d, f.ground_out);
    d = d - take;
    vi rest = f.ground_out - take;
    take = min_i(t, rest);
    t = t - take;
    b = b - (rest - take);
    d = d + dep;
    t = t + f.creep_in;

    vi rain = splat_i(0);
    if (rc->rain_now > 0.0f) {
        vf lift = splat_f(1.0f) + splat_f(m->rain_altitude) * to_f(a_old) *
                                      splat_f(m->inv_range_units);
        rain = to_i(splat_f(rc->rain_now) * max_f(lift, splat_f(0.0f)));
        w = w + rain;
    }
    vi evap = to_i(splat_f(m->evaporation) * to_f(w));
    w = w - evap;
    vi ring = ring_lanes(m->n, v->gi + c, rc->row_ring);
    vi out_w = w & ring, out_s = s & ring;
    w = w & ~ring;
    s = s & ~ring;

    vf flow_old = ld_f(v->flow + at);
    vf flow = flow_old * splat_f(m->flow_decay) + to_f(f.out_water);
    /* lanes past the rectangle's end keep their old state (they are rewritten unchanged) */
    vi col = splat_i(c) + (vi){0, 1, 2, 3, 4, 5, 6, 7};
    vi live = col < splat_i(rc->c1);
    st_i(v->b + at, sel_i(live, b, ld_i(v->b + at)));
    st_i(v->t + at, sel_i(live, t, ld_i(v->t + at)));
    st_i(v->d + at, sel_i(live, d, ld_i(v->d + at)));
    st_i(v->w + at, sel_i(live, w, ld_i(v->w + at)));
    st_i(v->s + at, sel_i(live, s, ld_i(v->s + at)));
    st_f(v->flow + at, sel_f(live, flow, flow_old));

    vi own = rc->own_row & (col >= splat_i(rc->own_c0)) & (col < splat_i(rc->own_c1));
    tally_add(&rc->tally->rain, rain, own);
    tally_add(&rc->tally->evaporated, evap, own);
    tally_add(&rc->tally->out_water, out_w, own);
    tally_add(&rc->tally->out_load, out_s, own);
}

/* The edges between rows j and j + 1 (window rows) at columns [c0, c0 + count), into r. */
INLINE void vertical_edges(const tf_erosion_model *m, const tf_erosion_view *v, int j, int c0,
                           int count, const edge_row *r)
{
    int gj = v->gj + j;
    int row_inner = gj > 0 && gj + 1 < m->n - 1;
    for (int k = 0; k < count; k += LANES) {
        size_t at = (size_t)j * v->stride + (size_t)(c0 + k);
        vtx p = load_vtx(m, v, at), q = load_vtx(m, v, at + v->stride);
        vi col = splat_i(v->gi + c0 + k) + (vi){0, 1, 2, 3, 4, 5, 6, 7};
        vi inner = (col > 0) & (col < splat_i(m->n - 1)) & splat_i(row_inner ? -1 : 0);
        put_edge(r, k, edge_of(m, &p, &q, inner));
    }
}

/* The edges along row j between columns c-1 and c for c in [c0, c0 + count]: count + 1 edges. */
INLINE void horizontal_edges(const tf_erosion_model *m, const tf_erosion_view *v, int j, int c0,
                             int count, const edge_row *r)
{
    int gj = v->gj + j;
    int row_inner = gj > 0 && gj < m->n - 1;
    for (int k = 0; k <= count; k += LANES) {
        size_t at = (size_t)j * v->stride + (size_t)(c0 - 1 + k);
        vtx p = load_vtx(m, v, at), q = load_vtx(m, v, at + 1);
        vi col = splat_i(v->gi + c0 - 1 + k) + (vi){0, 1, 2, 3, 4, 5, 6, 7};
        vi inner = (col > 0) & (col + 1 < splat_i(m->n - 1)) & splat_i(row_inner ? -1 : 0);
        put_edge(r, k, edge_of(m, &p, &q, inner));
    }
}

#define STEP_BODY                                                                              \
    {                                                                                          \
        int count = rect.c1 - rect.c0;                                                         \
        if (count <= 0 || rect.r1 <= rect.r0)                                                  \
            return 0;                                                                          \
        /* the loops read and rewrite up to LANES vertices past the row's last needed one:    \
         * the window's arrays must have them (erosion.h, TF_EROSION_PAD) */                   \
        int padded = ((count + LANES) / LANES + 1) * LANES;                                   \
        int32_t *buf = malloc(sizeof(int32_t) * 12 * (size_t)padded);                          \
        if (!buf)                                                                              \
            return -1;                                                                         \
        edge_row rows[3];                                                                      \
        for (int e = 0; e < 3; e++)                                                            \
            rows[e] = (edge_row){buf + (size_t)(4 * e) * padded,                               \
                                 buf + (size_t)(4 * e + 1) * padded,                           \
                                 buf + (size_t)(4 * e + 2) * padded,                           \
                                 buf + (size_t)(4 * e + 3) * padded};                          \
        edge_row *down = &rows[0], *up = &rows[1], *hor = &rows[2];                            \
        vertical_edges(m, v, rect.r0 - 1, rect.c0, count, down);                               \
        row_ctx rc = {m, v, rain_now, 0, splat_i(0), own.c0, own.c1, rect.c1, tally};                   \
        for (int j = rect.r0; j < rect.r1; j++) {                                              \
            vertical_edges(m, v, j, rect.c0, count, up);                                       \
            horizontal_edges(m, v, j, rect.c0, count, hor);                                    \
            int gj = v->gj + j;                                                                \
            rc.row_ring = gj == 0 || gj == m->n - 1;                                           \
            rc.own_row = splat_i(j >= own.r0 && j < own.r1 ? -1 : 0);                          \
            for (int k = 0; k < count; k += LANES)                                             \
                update8(&rc, (size_t)j * v->stride + (size_t)(rect.c0 + k), rect.c0 + k, hor,  \
                        down, up, k);                                                          \
            edge_row *swap = down;                                                             \
            down = up;                                                                         \
            up = swap;                                                                         \
        }                                                                                      \
        free(buf);                                                                             \
        return 0;                                                                              \
    }

typedef int (*step_fn)(const tf_erosion_model *m, const tf_erosion_view *v, tf_erosion_rect rect,
                       tf_erosion_rect own, float rain_now, tf_erosion_tally *tally);

static int step_portable(const tf_erosion_model *m, const tf_erosion_view *v,
                         tf_erosion_rect rect, tf_erosion_rect own, float rain_now,
                         tf_erosion_tally *tally) STEP_BODY

#if defined(__x86_64__) && defined(__GNUC__)
__attribute__((target("avx2"))) static int step_avx2(const tf_erosion_model *m,
                                                     const tf_erosion_view *v,
                                                     tf_erosion_rect rect, tf_erosion_rect own,
                                                     float rain_now,
                                                     tf_erosion_tally *tally) STEP_BODY
#endif

static int forced_portable = -1; /* -1: TF_EROSION_ISA decides */

void tf_erosion_force_portable(int portable) { forced_portable = portable; }

static step_fn chosen_step(void)
{
#if defined(__x86_64__) && defined(__GNUC__)
    int portable = forced_portable;
    if (portable < 0) {
        const char *force = getenv("TF_EROSION_ISA");
        portable = force && !strcmp(force, "portable");
    }
    if (!portable && __builtin_cpu_supports("avx2"))
        return step_avx2;
#endif
    return step_portable;
}

const char *tf_erosion_isa(void)
{
#if defined(__x86_64__) && defined(__GNUC__)
    return chosen_step() == step_avx2 ? "avx2" : "portable";
#else
    return "portable";
#endif
}

int tf_erosion_step(const tf_erosion_model *m, const tf_erosion_view *v, tf_erosion_rect rect,
                    tf_erosion_rect own, int step, tf_erosion_tally *tally)
{
    return chosen_step()(m, v, rect, own, tf_erosion_rain_now(m, step), tally);
}
