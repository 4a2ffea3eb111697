/* erosion_kernel.h: one time step of the erosion model (erosion.h, E1-E3) over a rectangle, W
 * vertices at a time: the kernels erosion_step.c chooses from, and the code they are made of.
 *
 * The first part declares the kernels.  The rest is a template: erosion_step_<isa>.c defines W,
 * TF_KERNEL (the kernel's name), the vector types vi (W x int32), vf (W x float) and vm (a
 * lane mask), and the lane operations listed below for its ISA, then includes this file
 * (portable: 4 lanes, SSE2 or plain vectors; avx2: 8; avx512: 16 with mask registers).  The
 * arithmetic is GCC's vector operators and those operations: IEEE add, subtract, multiply,
 * compare, min and max as `a < b ? a : b` and `a > b ? a : b` (what minps and maxps compute)
 * and float <-> int truncation, never a fused multiply-add; every operation acts on each lane
 * alone, so every ISA and width computes the same bits (tests/unit/test_erosion.c runs them
 * all and compares).
 *
 * Within the rectangle the rows are updated in place from the bottom up.  Before row j changes:
 * the derived values of row j + 1 (ground a = b + t + d, water surface h = a + w, top-layer
 * softness k) join those of row j in two rolling row buffers (each vertex's are computed once a
 * step); from them the transfers on the edges between rows j and j + 1 and along row j are
 * computed from the old state and kept (the edges between rows j - 1 and j were kept from the
 * previous row), so every transfer sees only the old state (erosion.h, E1) and each edge is
 * computed once. */
#ifndef TF_EROSION_KERNEL_H
#define TF_EROSION_KERNEL_H

#include <stdlib.h>
#include <string.h>

#include "terrain/erosion.h"

/* tf_erosion_step's work, with the step's rain already looked up (0 on dry steps). */
typedef int tf_erosion_kernel(const tf_erosion_model *m, const tf_erosion_view *v,
                              tf_erosion_rect rect, tf_erosion_rect own, float rain_now,
                              tf_erosion_tally *tally);
tf_erosion_kernel tf_erosion_kernel_portable;
#if defined(__x86_64__) && defined(__GNUC__)
#define TF_EROSION_X86 1
tf_erosion_kernel tf_erosion_kernel_avx2, tf_erosion_kernel_avx512;
#endif

#endif

#ifdef TF_KERNEL
/* The lane operations the including file provides (all `static inline`, always inlined):
 *   vm gt_i(vi, vi), eq_i(vi, vi), lt_f(vf, vf)     lane masks of a > b, a == b, a < b
 *   vm m_and(vm, vm), m_or(vm, vm), m_all(int)     and, or; every lane if the int is nonzero
 *   vi sel_i(vm, vi a, vi b), vf sel_f(vm, vf, vf)  a where the mask is set, else b
 *   vi keep_i(vm, vi)                               the lanes the mask sets, 0 elsewhere
 *   vi min_i, max_i (vi, vi), vf min_f, max_f (vf, vf), vf to_f(vi), vi to_i(vf) (truncates)
 *   int any_i(vi)                                   a lane is nonzero
 *   int64_t sum_i(vi)                               the lanes' sum, exact */

/* No fused multiply-add (the build's -ffp-contract=off; clang, which builds the library for the
 * fuzz targets without it, would fuse in the AVX-512 copy, whose target implies FMA). */
#ifdef __clang__
#pragma STDC FP_CONTRACT OFF
#endif

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
INLINE vi splat_i(int32_t x)
{
    vi r;
    for (int l = 0; l < W; l++)
        r[l] = x;
    return r;
}
INLINE vf splat_f(float x)
{
    vf r;
    for (int l = 0; l < W; l++)
        r[l] = x;
    return r;
}
/* global columns c, c + 1, ..., c + W - 1 */
INLINE vi cols(int c)
{
    vi x;
    for (int l = 0; l < W; l++)
        x[l] = c + l;
    return x;
}
INLINE vi pos(vi x) { return max_i(x, splat_i(0)); }
INLINE vi neg(vi x) { return max_i(-x, splat_i(0)); }

/* The model's constants for one call: its scalars (a copy, which no store to the arrays can
 * change, so the compiler keeps them) and, splatted once, the factors the lanes multiply by. */
typedef struct {
    tf_erosion_model s;
    vf v_kc, v_kd, v_ks, v_k_silt, v_k_talus, v_creep, v_evaporation, v_flow_decay;
    vf v_rain_altitude, v_inv_range_units, v_inv_strata_units, v_strata_contrast, v_rain_now;
} consts;

INLINE consts consts_of(const tf_erosion_model *m, float rain_now)
{
    return (consts){*m,
                    splat_f(m->kc),
                    splat_f(m->kd),
                    splat_f(m->ks),
                    splat_f(m->k_silt),
                    splat_f(m->k_talus),
                    splat_f(m->creep),
                    splat_f(m->evaporation),
                    splat_f(m->flow_decay),
                    splat_f(m->rain_altitude),
                    splat_f(m->inv_range_units),
                    splat_f(m->inv_strata_units),
                    splat_f(m->strata_contrast),
                    splat_f(rain_now)};
}

/* The bedrock's strata factor at altitude b: a triangle wave between 1 - contrast and 1. */
INLINE vf strata(const consts *m, vi b)
{
    vf u = to_f(b) * m->v_inv_strata_units;
    vf fl = to_f(to_i(u));
    fl = sel_f(lt_f(u, fl), fl - splat_f(1.0f), fl); /* floor */
    vf f = (u - fl) * splat_f(2.0f) - splat_f(1.0f);
    return splat_f(1.0f) - m->v_strata_contrast * max_f(f, -f);
}

/* What the edges need of a row of vertices beyond w and s: a, h and k, per column. */
typedef struct {
    int32_t *a, *h;
    float *k;
} derived_row;

/* The derived values of window row j, columns [c, c + count), into r from index 0. */
INLINE void derive_row(const consts *m, const tf_erosion_view *v, int j, int c,
                       int count, const derived_row *r)
{
    for (int i = 0; i < count; i += W) {
        size_t at = (size_t)j * v->stride + (size_t)(c + i);
        vi b = ld_i(v->b + at), t = ld_i(v->t + at), d = ld_i(v->d + at);
        vi a = b + t + d;
        st_i(r->a + i, a);
        st_i(r->h + i, a + ld_i(v->w + at));
        vf rock = m->v_ks * ld_f(v->soft + at);
        if (m->s.inv_strata_units > 0.0f)
            rock = rock * strata(m, b);
        vf k = sel_f(gt_i(d, splat_i(0)), m->v_k_silt,
                     sel_f(gt_i(t, splat_i(0)), m->v_k_talus, rock));
        st_f(r->k + i, k);
    }
}

/* W vertices' old state as the edges see it. */
typedef struct {
    vi w, s, a, h;
    vf k;
} vtx;

/* The vertices at window offset `at` (w, s) and derived index i. */
INLINE vtx vtx_at(const tf_erosion_view *v, size_t at, const derived_row *r, int i)
{
    return (vtx){ld_i(v->w + at), ld_i(v->s + at), ld_i(r->a + i), ld_i(r->h + i),
                 ld_f(r->k + i)};
}

/* The transfers on W edges P-Q, positive from P to Q (erosion.h, E1). */
typedef struct {
    vi dw, sus, ero, crp;
} edge;

INLINE edge edge_of(const consts *m, vtx p, vtx q, vm inner)
{
    vm pq = gt_i(p.h, q.h), qp = gt_i(q.h, p.h);
    vi ws = sel_i(pq, p.w, q.w), ss = sel_i(pq, p.s, q.s);
    vi drop = sel_i(pq, p.a - q.a, q.a - p.a);
    vi dh = sel_i(pq, p.h - q.h, q.h - p.h);
    vf k = sel_f(pq, p.k, q.k);
    vi dw = to_i(splat_f(0.25f) * min_f(to_f(ws), splat_f(0.5f) * to_f(dh)));
    vf cap = m->v_kc * to_f(dw);
    vf share = splat_f(0.25f) * to_f(ss);
    vi sus = to_i(min_f(share, cap));
    vf deficit = max_f(cap - share, splat_f(0.0f));
    vf limit = splat_f(0.125f) * max_f(to_f(drop), splat_f(0.0f));
    vi ero = to_i(min_f(k * deficit, limit));
    edge e;
    e.dw = sel_i(qp, -dw, dw);
    e.sus = sel_i(qp, -sus, sus);
    e.ero = sel_i(qp, -ero, ero);
    e.crp = splat_i(0);
    if (m->s.creep != 0.0f) /* else trunc(0 * x) = 0 */
        e.crp = keep_i(inner, to_i(m->v_creep * to_f(p.a - q.a)));
    return e;
}

/* Edge buffers: transfers stored per component, so a row of them is four int32 arrays. */
typedef struct {
    int32_t *dw, *sus, *ero, *crp;
} edge_row;

/* creep: whether c_d is nonzero (else crp is 0 and neither stored nor read) */
INLINE void put_edge(const edge_row *r, int k, edge e, int creep)
{
    st_i(r->dw + k, e.dw);
    st_i(r->sus + k, e.sus);
    st_i(r->ero + k, e.ero);
    if (creep)
        st_i(r->crp + k, e.crp);
}
INLINE edge get_edge(const edge_row *r, int k, int creep)
{
    return (edge){ld_i(r->dw + k), ld_i(r->sus + k), ld_i(r->ero + k),
                  creep ? ld_i(r->crp + k) : splat_i(0)};
}

/* The edges between window rows j (derived p) and j + 1 (derived q) at columns
 * [c0, c0 + count), into r; the derived rows start at column c0 - 1. */
INLINE void vertical_edges(const consts *m, const tf_erosion_view *v, int j, int c0,
                           int count, const derived_row *p, const derived_row *q,
                           const edge_row *r)
{
    int gj = v->gj + j;
    vm row_inner = m_all(gj > 0 && gj + 1 < m->s.n - 1);
    for (int k = 0; k < count; k += W) {
        size_t at = (size_t)j * v->stride + (size_t)(c0 + k);
        vi col = cols(v->gi + c0 + k);
        vm inner = m_and(m_and(gt_i(col, splat_i(0)), gt_i(splat_i(m->s.n - 1), col)), row_inner);
        edge e = edge_of(m, vtx_at(v, at, p, k + 1), vtx_at(v, at + v->stride, q, k + 1), inner);
        put_edge(r, k, e, m->s.creep != 0.0f);
    }
}

/* The edges along window row j (derived p) between columns c-1 and c for c in
 * [c0, c0 + count]: count + 1 edges. */
INLINE void horizontal_edges(const consts *m, const tf_erosion_view *v, int j, int c0,
                             int count, const derived_row *p, const edge_row *r)
{
    int gj = v->gj + j;
    vm row_inner = m_all(gj > 0 && gj < m->s.n - 1);
    for (int k = 0; k <= count; k += W) {
        size_t at = (size_t)j * v->stride + (size_t)(c0 - 1 + k);
        vi col = cols(v->gi + c0 - 1 + k);
        vm inner = m_and(m_and(gt_i(col, splat_i(0)), gt_i(splat_i(m->s.n - 1), col + 1)),
                         row_inner);
        edge e = edge_of(m, vtx_at(v, at, p, k), vtx_at(v, at + 1, p, k + 1), inner);
        put_edge(r, k, e, m->s.creep != 0.0f);
    }
}

/* What flows into a vertex from its four edges (erosion.h, E2): from the left and from below
 * the edge's positive direction is inwards, to the right and above outwards. */
typedef struct {
    vi water, out_water, out_load, in_load, ground_out, creep_in;
} inflow;

INLINE void add_in(inflow *f, edge e, int creep)
{
    f->water += e.dw;
    f->out_water += neg(e.dw);
    f->out_load += neg(e.sus);
    f->in_load += pos(e.sus) + pos(e.ero);
    f->ground_out += neg(e.ero);
    if (creep) {
        f->ground_out += neg(e.crp);
        f->creep_in += pos(e.crp);
    }
}
/* add_in of the reversed edge -e (neg(-x) = max(x, 0) = pos(x), pos(-x) = neg(x), also for
 * INT32_MIN) */
INLINE void add_out(inflow *f, edge e, int creep)
{
    f->water -= e.dw;
    f->out_water += pos(e.dw);
    f->out_load += pos(e.sus);
    f->in_load += neg(e.sus) + neg(e.ero);
    f->ground_out += pos(e.ero);
    if (creep) {
        f->ground_out += pos(e.crp);
        f->creep_in += neg(e.crp);
    }
}

/* Add the lanes of x selected by mask to *sum (most vectors have none nonzero). */
INLINE void tally_add(int64_t *sum, vi x, vm mask)
{
    x = keep_i(mask, x);
    if (any_i(x))
        *sum += sum_i(x);
}

typedef struct {
    const consts *m;
    const tf_erosion_view *v;
    float rain_now;
    int row_ring;       /* this row is the grid's first or last */
    vm own_row;         /* all lanes if the row is owned, none if not */
    int own_c0, own_c1;
    int c1;             /* the rectangle's end column */
    tf_erosion_tally *tally;
} row_ctx;

/* The lanes of window column c that the tally counts. */
INLINE vm owned(const row_ctx *rc, int c)
{
    vi col = cols(c);
    return m_and(rc->own_row,
                 m_and(gt_i(col, splat_i(rc->own_c0 - 1)), gt_i(splat_i(rc->own_c1), col)));
}

/* E3's rain on the vertices of ground a_old (0 on dry steps). */
INLINE vi rain_on(const row_ctx *rc, vi a_old)
{
    const consts *m = rc->m;
    vf lift =
        splat_f(1.0f) + m->v_rain_altitude * to_f(a_old) * m->v_inv_range_units;
    return to_i(m->v_rain_now * max_f(lift, splat_f(0.0f)));
}

/* Whether W vertices from window column c may touch the grid's outer ring. */
INLINE int near_ring(const row_ctx *rc, int c)
{
    int g = rc->v->gi + c;
    return rc->row_ring || g <= 0 || g + W - 1 >= rc->m->s.n - 1;
}

/* E3 after the transfers: rain (on rain steps), evaporation, the outlet; counted. */
INLINE void rain_evaporate_drain(const row_ctx *rc, int c, vi a_old, vi *w, vi *s)
{
    const consts *m = rc->m;
    if (rc->rain_now > 0.0f) { /* else no rain */
        vi rain = rain_on(rc, a_old);
        *w = *w + rain;
        tally_add(&rc->tally->rain, rain, owned(rc, c));
    }
    if (m->s.evaporation != 0.0f) { /* else trunc(0 * w) = 0 */
        vi evap = to_i(m->v_evaporation * to_f(*w));
        *w = *w - evap;
        tally_add(&rc->tally->evaporated, evap, owned(rc, c));
    }
    if (near_ring(rc, c)) {
        vi col = cols(rc->v->gi + c);
        vm ring = m_or(m_all(rc->row_ring),
                       m_or(eq_i(col, splat_i(0)), eq_i(col, splat_i(m->s.n - 1))));
        vi out_w = keep_i(ring, *w), out_s = keep_i(ring, *s);
        *w = *w - out_w;
        *s = *s - out_s;
        tally_add(&rc->tally->out_water, out_w, owned(rc, c));
        tally_add(&rc->tally->out_load, out_s, owned(rc, c));
    }
}

/* E2 and E3 for the W vertices at column c of row j (ground a_old); k indexes the edges.
 * partial: some lanes lie past the rectangle's end and keep their old state (they are
 * rewritten unchanged). */
INLINE void update(const row_ctx *rc, size_t at, int c, const edge_row *hor,
                   const edge_row *down, const edge_row *up, int k, vi a_old, int partial)
{
    const consts *m = rc->m;
    const tf_erosion_view *v = rc->v;
    int creep = m->s.creep != 0.0f;
    inflow f = {0};
    add_in(&f, get_edge(hor, k, creep), creep);
    add_out(&f, get_edge(hor, k + 1, creep), creep);
    add_in(&f, get_edge(down, k, creep), creep);
    add_out(&f, get_edge(up, k, creep), creep);

    vi b0 = ld_i(v->b + at), t0 = ld_i(v->t + at), d0 = ld_i(v->d + at);
    vi w0 = ld_i(v->w + at), s0 = ld_i(v->s + at);
    vi kept = s0 - f.out_load;
    vi dep = to_i(m->v_kd * to_f(kept));
    vi s = kept - dep + f.in_load;
    vi w = w0 + f.water;
    vi take = min_i(d0, f.ground_out);
    vi d = d0 - take;
    vi rest = f.ground_out - take;
    take = min_i(t0, rest);
    vi t = t0 - take;
    vi b = b0 - (rest - take);
    d = d + dep;
    t = t + f.creep_in;
    rain_evaporate_drain(rc, c, a_old, &w, &s);

    vf flow_old = ld_f(v->flow + at);
    vf flow = flow_old * m->v_flow_decay + to_f(f.out_water);
    if (partial) {
        vm live = gt_i(splat_i(rc->c1), cols(c));
        b = sel_i(live, b, b0);
        t = sel_i(live, t, t0);
        d = sel_i(live, d, d0);
        w = sel_i(live, w, w0);
        s = sel_i(live, s, s0);
        flow = sel_f(live, flow, flow_old);
    }
    st_i(v->b + at, b);
    st_i(v->t + at, t);
    st_i(v->d + at, d);
    st_i(v->w + at, w);
    st_i(v->s + at, s);
    st_f(v->flow + at, flow);
}

/* The buffers of one call: two derived rows and three edge rows, `len` elements each, zeroed
 * (lanes past the rectangle's end read what no loop wrote; they are discarded): the view's
 * own (erosion.h, TF_EROSION_ROWS), or allocated for this call (owned set) where it has none. */
typedef struct {
    int32_t *mem;
    int owned;
    derived_row der[2];
    edge_row edges[3];
} step_bufs;

_Static_assert(2 * 3 + 3 * 4 == TF_EROSION_ROW_ARRAYS, "bufs_alloc's arrays");

INLINE int bufs_alloc(step_bufs *sb, const tf_erosion_view *v, int len)
{
    size_t count = TF_EROSION_ROW_ARRAYS * (size_t)len;
    sb->owned = !v->rows || count > TF_EROSION_ROWS(v->nx);
    sb->mem = sb->owned ? calloc(count, sizeof(int32_t)) : v->rows;
    if (!sb->mem)
        return -1;
    if (!sb->owned)
        memset(sb->mem, 0, count * sizeof(int32_t));
    int32_t *p = sb->mem;
    for (int r = 0; r < 2; r++, p += 3 * (size_t)len)
        sb->der[r] = (derived_row){p, p + len, (float *)(p + 2 * (size_t)len)};
    for (int e = 0; e < 3; e++, p += 4 * (size_t)len)
        sb->edges[e] = (edge_row){p, p + len, p + 2 * (size_t)len, p + 3 * (size_t)len};
    return 0;
}

/* Row j: derive row j + 1, compute the edges above and along j, update j. */
INLINE void step_row(row_ctx *rc, tf_erosion_rect rect, tf_erosion_rect own, int j,
                     const derived_row *dj, const derived_row *dj1, const edge_row *down,
                     const edge_row *up, const edge_row *hor)
{
    const consts *m = rc->m;
    const tf_erosion_view *v = rc->v;
    int count = rect.c1 - rect.c0;
    derive_row(m, v, j + 1, rect.c0 - 1, count + 2, dj1);
    vertical_edges(m, v, j, rect.c0, count, dj, dj1, up);
    horizontal_edges(m, v, j, rect.c0, count, dj, hor);
    int gj = v->gj + j;
    rc->row_ring = gj == 0 || gj == m->s.n - 1;
    rc->own_row = m_all(j >= own.r0 && j < own.r1);
    size_t row = (size_t)j * v->stride + (size_t)rect.c0;
    int k = 0;
    for (; k + W <= count; k += W)
        update(rc, row + (size_t)k, rect.c0 + k, hor, down, up, k, ld_i(dj->a + k + 1), 0);
    if (k < count)
        update(rc, row + (size_t)k, rect.c0 + k, hor, down, up, k, ld_i(dj->a + k + 1), 1);
}

int TF_KERNEL(const tf_erosion_model *model, const tf_erosion_view *v, tf_erosion_rect rect,
              tf_erosion_rect own, float rain_now, tf_erosion_tally *tally)
{
    int count = rect.c1 - rect.c0;
    if (count <= 0 || rect.r1 <= rect.r0)
        return 0;
    /* the loops read and rewrite up to W vertices past the row's last needed one: the
     * window's arrays must have them (erosion.h, TF_EROSION_PAD) */
    consts local = consts_of(model, rain_now);
    const consts *m = &local;
    step_bufs sb;
    if (bufs_alloc(&sb, v, (count + 2 + W - 1) / W * W + 2 * W) != 0)
        return -1;
    const derived_row *dj = &sb.der[0], *dj1 = &sb.der[1];
    const edge_row *down = &sb.edges[0], *up = &sb.edges[1], *hor = &sb.edges[2];
    derive_row(m, v, rect.r0 - 1, rect.c0 - 1, count + 2, dj);
    derive_row(m, v, rect.r0, rect.c0 - 1, count + 2, dj1);
    vertical_edges(m, v, rect.r0 - 1, rect.c0, count, dj, dj1, down);
    row_ctx rc = {m, v, rain_now, 0, m_all(0), own.c0, own.c1, rect.c1, tally};
    for (int j = rect.r0; j < rect.r1; j++) {
        const derived_row *swap_d = dj;
        dj = dj1;
        dj1 = swap_d;
        step_row(&rc, rect, own, j, dj, dj1, down, up, hor);
        const edge_row *swap_e = down;
        down = up;
        up = swap_e;
    }
    if (sb.owned)
        free(sb.mem);
    return 0;
}

#undef INLINE
#endif
