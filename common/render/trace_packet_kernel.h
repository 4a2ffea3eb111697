/* trace_packet_kernel.h: the packet walk, W rays at a time: the kernels trace_packet.c chooses
 * from, and the code they are made of (the pattern of terrain/erosion_kernel.h).
 *
 * The first part declares the kernels.  The rest is a template: trace_packet_<isa>.c defines W
 * (lanes), TF_KERNEL (the kernel's name), the vector types vd (W doubles) and vl (W int64s,
 * which is also the type of a comparison of vds: a lane mask, all bits set or none), then
 * includes this file (portable: 2 lanes; avx2: 4; avx512: 8 -- one register of doubles each;
 * two registers a vector measured 2-3x slower, bench/README.md), with these lane operations:
 *   unsigned bits_l(vl m)        bit l set where lane l of the mask is set
 *   vd gather_f(const float *base, vl off)   (double) of the float at base + 4 off[l] bytes
 *                                per lane (the walk's max or min of each lane's block; off may
 *                                reach any level's grid, a separate allocation)
 *   vl gather_i(const int64_t *table, vl idx) table[idx[l]] per lane
 *
 * Each lane runs trace.c's walk_hier for its own ray -- its own level, cell, stale axis and
 * event time -- so the lanes need not agree on anything.  A step computes, for all lanes at
 * once, what walk_hier computes at the top of its loop: the block's exit crossings tx, ty, the
 * segment's end t_out, the altitudes z(t_cur), z(t_out) and the cull against the block's max
 * and min (gathered: the loads of W independent rays are in flight together, where the single
 * walk waits on each).  Then, each lane taking the branch walk_hier takes for its ray: a
 * descent (settling one more bit of the stale axis's index, settle_half), or the block step
 * (the next block, the climb), with masks.
 * These are walk_hier's expressions term for term (tf_grid_cross, tf_span_culled in
 * trace_math.h, spelled here on vectors: the one place the walk's arithmetic is written twice
 * in C), on IEEE vector add, subtract, multiply, divide and compare, never a fused
 * multiply-add (-ffp-contract=off; the clang pragma below), so a lane computes walk_hier's
 * bits.  A level-0 cell that is not culled is tested lane by lane by trace.c's own test_cell,
 * and setup and the hit record are trace.c's too (trace_internal.h).  So every lane's hit is
 * tf_trace's to the bit, and its occlusion tf_occluded's (tests/unit/test_trace_packet.c
 * checks it on every ISA).  Two packets are walked side by side (TF_PACKETS), a step of each
 * in turn, so that one packet's gathers are in flight while the other steps.
 *
 * Integers (cells, levels, block indexes) are int64 lanes, the width of a double's mask; they
 * become doubles through the exact 1.5 * 2^52 trick (|x| < 2^51), the value (double)x. */
#ifndef TF_TRACE_PACKET_KERNEL_H
#define TF_TRACE_PACKET_KERNEL_H

#include <assert.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "render/trace_internal.h"

/* Trace rays 0 .. n-1 (o[i] + t d[i], t in (tmin[i], tmax[i])): found[i] = 1 on a hit, and
 * hits[i] filled when hits is not NULL (NULL: occlusion only, as tf_occluded). */
typedef void tf_trace_packet_kernel(const tf_heightfield *hf, int n, const tf_vec3 *o,
                                    const tf_vec3 *d, const double *tmin, const double *tmax,
                                    unsigned char *found, tf_hit *hits);
tf_trace_packet_kernel tf_trace_packet_portable;
#if defined(__x86_64__) && defined(__GNUC__)
#define TF_TRACE_X86 1
tf_trace_packet_kernel tf_trace_packet_avx2, tf_trace_packet_avx512;
#endif

#endif

#ifdef TF_KERNEL

#ifdef __clang__
#pragma STDC FP_CONTRACT OFF
#endif

#define INLINE static inline __attribute__((always_inline))

INLINE vd sel_d(vl m, vd a, vd b) { return (vd)((m & (vl)a) | (~m & (vl)b)); }
INLINE vl sel_l(vl m, vl a, vl b) { return (m & a) | (~m & b); }
INLINE vd splat_d(double x) { return (vd){0} + x; }
INLINE vl splat_l(int64_t x) { return (vl){0} + x; }
INLINE int any_l(vl m) { return bits_l(m) != 0; }
/* The mask whose lane l is set where bit l of b is. */
INLINE vl from_bits(unsigned b)
{
    vl lane_bit;
    for (int l = 0; l < W; l++)
        lane_bit[l] = (int64_t)1 << l;
    return (splat_l((int64_t)b) & lane_bit) != 0;
}
/* (double)x exactly, for |x| < 2^51. */
INLINE vd to_d(vl x)
{
    return (vd)(x + splat_l(0x4338000000000000LL)) - splat_d(6755399441055744.0);
}

/* Where every lane's walk stands: walk_hier's locals, and the ray's constants it reads. */
typedef struct lanes {
    vd ox, oy, oz, dx, dy, dz, t1, inv_dx, inv_dy, margin;
    vl sx, sy, x_ahead, y_ahead;
    vl ci, cj, level, stale;
    vd t_cur, t_event;
    vl active;
} lanes;

/* Rays first .. first+W-1 (those below n) into the lanes; a lane whose ray cannot meet the
 * terrain is left inactive (found = 0). */
INLINE void load_lanes(const tf_heightfield *hf, int first, int n, const tf_vec3 *o,
                       const tf_vec3 *d, const double *tmin, const double *tmax,
                       tf_ray_ctx *ctx, lanes *L)
{
    memset(L, 0, sizeof *L);
    for (int l = 0; l < W && first + l < n; l++) {
        int i = first + l;
        tf_ray_ctx *r = &ctx[l];
        if (!tf_trace_setup(r, hf, o[i], d[i], tmin[i], tmax[i]))
            continue;
        L->ox[l] = r->o[0], L->oy[l] = r->o[1], L->oz[l] = r->o[2];
        L->dx[l] = r->d[0], L->dy[l] = r->d[1], L->dz[l] = r->d[2];
        L->t1[l] = r->t1, L->inv_dx[l] = r->inv_dx, L->inv_dy[l] = r->inv_dy;
        L->margin[l] = r->margin;
        L->sx[l] = r->sx, L->sy[l] = r->sy, L->x_ahead[l] = r->sx > 0, L->y_ahead[l] = r->sy > 0;
        L->ci[l] = r->ci, L->cj[l] = r->cj, L->level[l] = 0; /* walk_hier's start */
        L->stale[l] = TF_STALE_NONE;
        L->t_cur[l] = r->t0, L->t_event[l] = r->t0;
        L->active[l] = -1;
    }
}

/* Every level's max and min grid as addresses relative to level 0's, in floats (the grids are
 * separate allocations, all float-aligned): a lane's block is at max0 + 4 * (max_at[level] +
 * idx) bytes, whatever its level, so one gather (gather_f) loads the lanes' blocks. */
typedef struct grids {
    const float *max0, *min0;
    int64_t max_at[64], min_at[64];
} grids;

static int64_t floats_from(const float *base, const float *p)
{
    return ((int64_t)(intptr_t)p - (int64_t)(intptr_t)base) / (int64_t)sizeof(float);
}

static void grids_of(const tf_heightfield *hf, grids *g)
{
    memset(g, 0, sizeof *g);
    g->max0 = hf->maxgrid[0], g->min0 = hf->mingrid[0];
    for (int L = 0; L < hf->levels && L < 64; L++) {
        g->max_at[L] = floats_from(g->max0, hf->maxgrid[L]);
        g->min_at[L] = floats_from(g->min0, hf->mingrid[L]);
    }
}

/* The step's view of every lane: walk_hier's tx, ty, tc, t_out and the cull. */
typedef struct step {
    vl bi, bj;
    vd tx, ty, tc, t_out;
    vl culled;
} step;

/* The block's max and min per lane (inactive lanes read block 0 of level 0). */
INLINE void load_bounds(const grids *g, vl level, vl idx, vd *hi, vd *lo)
{
    *hi = gather_f(g->max0, gather_i(g->max_at, level) + idx);
    *lo = gather_f(g->min0, gather_i(g->min_at, level) + idx);
}

INLINE void compute_step(const tf_heightfield *hf, const grids *g, const lanes *L, step *s)
{
    const vd cell = splat_d(hf->cell), inf = splat_d(INFINITY);
    const vl level = sel_l(L->active, L->level, splat_l(0));
    s->bi = sel_l(L->active, L->ci >> level, splat_l(0));
    s->bj = sel_l(L->active, L->cj >> level, splat_l(0));
    vd tx = (to_d((s->bi + L->x_ahead) << level) * cell - L->ox) * L->inv_dx;
    vd ty = (to_d((s->bj + L->y_ahead) << level) * cell - L->oy) * L->inv_dy;
    s->tx = sel_d(L->sx != 0, tx, inf);
    s->ty = sel_d(L->sy != 0, ty, inf);
    s->tc = sel_d(s->tx <= s->ty, s->tx, s->ty);
    vd t_out = sel_d(s->tc < L->t1, s->tc, L->t1);
    s->t_out = sel_d(t_out < L->t_cur, L->t_cur, t_out);
    vl idx = s->bj * (splat_l(hf->cells) >> level) + s->bi;
    vd hi, lo;
    load_bounds(g, level, idx, &hi, &lo);
    vd z_in = L->oz + L->t_cur * L->dz, z_out = L->oz + s->t_out * L->dz;
    vl rising = z_in < z_out;
    vd zlo = sel_d(rising, z_in, z_out), zhi = sel_d(rising, z_out, z_in);
    s->culled = (zlo > hi + L->margin) | (zhi < lo - L->margin);
}

/* trace.c's settle_half for the lanes of `fix` (the axis per lane: y where `y`; y crossings
 * strict): the line between the halves of the lane's block, crossed before t_event or not,
 * moves the index to the far half's first one or leaves it.  The crossing is xcross / ycross,
 * term for term. */
INLINE vl settle_half_v(const tf_heightfield *hf, const lanes *L, vl fix, vl y)
{
    const vd cell = splat_d(hf->cell);
    const vl zero = splat_l(0), one = splat_l(1);
    const vl s = sel_l(y, L->sy, L->sx), stale = sel_l(y, L->cj, L->ci), up = s > zero;
    const vd o = sel_d(y, L->oy, L->ox), inv = sel_d(y, L->inv_dy, L->inv_dx);
    const vl level = L->level, below = (level - one) & (level > zero); /* 0 where not descending */
    const vl mid = ((stale >> level) << level) + (one << below);
    vd t = (to_d(mid) * cell - o) * inv;
    vl entered = sel_l(y, t < L->t_event, t <= L->t_event);
    vl beyond = sel_l(up, stale >= mid, stale < mid); /* already in the half it moves into */
    return sel_l(fix & entered & ~beyond, sel_l(up, mid, mid - one), stale);
}

/* In builds with assertions (make asan): every lane's index is right to the next level's
 * block, where trace.c's fix_stale_axis puts it, and still behind (or at) that index. */
static inline int settle_matches(const tf_ray_ctx *ctx, const lanes *L, vl fix, vl y, vl j)
{
    for (int l = 0; l < W; l++) {
        if (!fix[l])
            continue;
        int level = (int)L->level[l], stale = (int)(y[l] ? L->cj[l] : L->ci[l]);
        int exact = tf_trace_fix_stale(&ctx[l], y[l] ? 1 : 0, stale, level, L->t_event[l],
                                       y[l] != 0);
        int s = y[l] ? ctx[l].sy : ctx[l].sx;
        if (j[l] >> (level - 1) != exact >> (level - 1) || (s > 0 ? j[l] > exact : j[l] < exact))
            return 0;
    }
    return 1;
}

/* walk_hier's descent for the lanes of `down` (not culled, above level 0). */
INLINE void descend(const tf_heightfield *hf, const tf_ray_ctx *ctx, lanes *L, vl down)
{
    const vl zero = splat_l(0);
    vl fix_y = down & (L->stale == TF_STALE_Y), fix_x = down & (L->stale == TF_STALE_X);
    (void)ctx;
    if (any_l(fix_y | fix_x)) {
        vl j = settle_half_v(hf, L, fix_y | fix_x, fix_y);
        assert(settle_matches(ctx, L, fix_y | fix_x, fix_y, j) &&
               "the vector settle is trace.c's settle_half");
        L->cj = sel_l(fix_y, j, L->cj);
        L->ci = sel_l(fix_x, j, L->ci);
    }
    L->level = L->level + (down & splat_l(-1));
    L->stale = sel_l(down & (L->level == zero), zero, L->stale); /* every bit settled */
}

/* walk_hier's test of the level-0 cells of the lanes of bits `cells`, by trace.c's own
 * test_cell: the lanes that hit (bits); best holds their hits. */
INLINE unsigned test_cells(const tf_ray_ctx *ctx, const lanes *L, const step *s, unsigned cells,
                           tf_trace_cand *best)
{
    int64_t ci[W], cj[W];
    double tx[W], ty[W];
    unsigned found = 0;
    memcpy(ci, &L->ci, sizeof ci), memcpy(cj, &L->cj, sizeof cj);
    memcpy(tx, &s->tx, sizeof tx), memcpy(ty, &s->ty, sizeof ty);
    for (; cells; cells &= cells - 1) {
        int l = __builtin_ctz(cells);
        if (tf_trace_test_cell(&ctx[l], (int)ci[l], (int)cj[l], tx[l], ty[l], &best[l]))
            found |= 1u << l;
    }
    return found;
}

/* walk_hier's block step for the lanes of adv; returns the lanes whose walk ends (a miss). */
INLINE vl advance(const tf_heightfield *hf, lanes *L, const step *s, vl adv)
{
    const vl zero = splat_l(0), cells = splat_l(hf->cells), top = splat_l(hf->levels - 1);
    vl ends = adv & ~(s->tc < L->t1);
    adv &= ~ends;
    L->t_cur = sel_d(adv, s->t_out, L->t_cur);
    L->t_event = sel_d(adv, s->tc, L->t_event);
    vl x_first = s->tx <= s->ty;
    vl xs = adv & x_first, ys = adv & ~x_first;
    vl bx = s->bi + L->x_ahead, by = s->bj + L->y_ahead;
    L->ci = sel_l(xs, (bx << L->level) + L->x_ahead - 1, L->ci);
    L->cj = sel_l(ys, (by << L->level) + L->y_ahead - 1, L->cj);
    vl out = (xs & ((L->ci < zero) | (L->ci >= cells))) |
             (ys & ((L->cj < zero) | (L->cj >= cells)));
    xs &= ~out;
    ys &= ~out;
    vl deep = L->level > zero;
    L->stale = sel_l(xs, sel_l(deep & (L->sy != zero), splat_l(TF_STALE_Y), zero), L->stale);
    L->stale = sel_l(ys, sel_l(deep & (L->sx != zero), splat_l(TF_STALE_X), zero), L->stale);
    vl boundary = sel_l(xs, bx, by);
    vl climb = (xs | ys) & (L->level < top) & ((boundary & 1) == zero);
    L->level = L->level - climb; /* a mask is -1 where set */
    return ends | out;
}

/* One step of every active lane; the lanes that hit join *hit, the lanes done leave active. */
INLINE void walk_step(const tf_heightfield *hf, const grids *g, const tf_ray_ctx *ctx, lanes *L,
                      tf_trace_cand *best, vl *hit)
{
    step s;
    compute_step(hf, g, L, &s);
    const vl zero = splat_l(0), keep = L->active & ~s.culled;
    const vl at_cell = keep & (L->level == zero), down = keep & (L->level > zero);
    vl found = zero;
    unsigned cells = bits_l(at_cell);
    if (cells)
        found = from_bits(test_cells(ctx, L, &s, cells, best));
    if (any_l(down))
        descend(hf, ctx, L, down);
    vl ends = advance(hf, L, &s, L->active & ~down & ~found);
    *hit |= found;
    L->active &= ~(found | ends);
}

/* Rays first .. first+W-1 (those below n): the packet's rays, its lanes, their hits. */
typedef struct packet {
    int first;
    tf_ray_ctx ctx[W];
    tf_trace_cand best[W];
    lanes L;
    vl hit;
} packet;

INLINE void packet_start(const tf_heightfield *hf, int first, int n, const tf_vec3 *o,
                         const tf_vec3 *d, const double *tmin, const double *tmax, packet *p)
{
    p->first = first;
    p->hit = splat_l(0);
    load_lanes(hf, first, n, o, d, tmin, tmax, p->ctx, &p->L);
    for (int l = 0; l < W; l++)
        p->best[l] = (tf_trace_cand){INFINITY, 0, 0, 0};
}

static inline void packet_answer(const packet *p, int n, unsigned char *found, tf_hit *hits)
{
    for (int l = 0; l < W && p->first + l < n; l++) {
        found[p->first + l] = p->hit[l] != 0;
        if (p->hit[l] && hits)
            tf_trace_finish(&p->ctx[l], &p->best[l], &hits[p->first + l]);
    }
}

/* TF_PACKETS packets walked side by side, a step of each in turn: one packet's gathers are in
 * flight while the others step. */
#ifndef TF_PACKETS
#define TF_PACKETS 2
#endif
void TF_KERNEL(const tf_heightfield *hf, int n, const tf_vec3 *o, const tf_vec3 *d,
               const double *tmin, const double *tmax, unsigned char *found, tf_hit *hits)
{
    grids g;
    packet p[TF_PACKETS];
    grids_of(hf, &g);
    for (int first = 0; first < n; first += TF_PACKETS * W) {
        for (int k = 0; k < TF_PACKETS; k++)
            packet_start(hf, first + k * W, n, o, d, tmin, tmax, &p[k]);
        for (int busy = 1; busy;) {
            busy = 0;
            for (int k = 0; k < TF_PACKETS; k++)
                if (any_l(p[k].L.active)) {
                    walk_step(hf, &g, p[k].ctx, &p[k].L, p[k].best, &p[k].hit);
                    busy = 1;
                }
        }
        for (int k = 0; k < TF_PACKETS; k++)
            packet_answer(&p[k], n, found, hits);
    }
}

#undef INLINE
#endif
