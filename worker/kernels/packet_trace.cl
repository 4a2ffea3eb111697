/* packet_trace.cl: trace.c's hierarchical grid walk (tf_trace / tf_occluded with walk_hier,
 * setup_ray, test_cell, settle_half) for eight rays at a time, one per lane, and
 * walk_stream, which deals a batch of rays to the eight lanes.  The arithmetic -- box clipping,
 * tolerances, crossings, culling, the triangle test, the hit normal -- is trace.c's own, from
 * common/render/trace_math.h; what is here is the walk's schedule.
 *
 * Each lane runs its own walk (its own level, cell, stale axis and event time), so the lanes
 * need not agree on anything: a step is computed for all lanes, and each lane takes the branch
 * trace.c would take for its ray, merged with select.  The costly branches -- the triangle
 * tests of a level-0 cell, the stale index's settling at a descent (settle8) -- run only when
 * some lane takes them.  Every lane performs trace.c's operations in trace.c's order, so a
 * lane's hit is the C hit to the bit (ties between triangles of neighbouring cells included:
 * the cells are tested in the C order).
 *
 * Integers that index buffers or are shifted by the level are lv (long8): the same width as
 * the masks double8 comparisons produce, so no mask ever needs widening. */

#define STALE_NONE8 0
#define STALE_X8 1
#define STALE_Y8 2

/* Per-lane setup_ray: everything the walk reads about each lane's ray. */
typedef struct rayp {
    v3p o, d;
    dv inv_dx, inv_dy, tmin, tmax, t0, t1, margin, tie_tol;
    dv t_square;        /* where the ray enters the terrain's square (x and y only) */
    lv sx, sy, ci, cj;
    lv kx, ky, kz;      /* the watertight test's axis permutation */
    dv shx, shy, shz;
} rayp;

typedef struct candp { dv t; lv ci, cj, tri; } candp;

/* Vertex (i, j)'s index in the heights, j n + i: n = cells + 1 = 2^cell_shift + 1. */
lv vertex_index8(const world *w, lv i, lv j) { return (j << w->cell_shift) + j + i; }

/* The (max, min) pairs of grid cells idx per lane, as loaded: one 64-bit load a lane, one cache
 * line; minmax_split8 makes doubles of them.  The grids are read-only, so reading the float pairs
 * as 64-bit words aliases nothing that changes.  The loads are volatile so that LLVM keeps them
 * eight scalar loads instead of one vpgatherqq: on Zen 4 (PoCL 3.1) perf put 18% of walk_stream's
 * samples on the gather's wait, and with scalar loads a default.scene 1920x1080 -j 2 render
 * takes 2.5% less CPU (8 alternating pairs, 3.93 against 4.04 s; pixels identical). */
ulong8 gather_minmax(__global const float2 *p, lv idx, lv mask)
{
    __global const volatile ulong *q = (__global const volatile ulong *)p;
    lv k = select((lv)(0), idx, mask);
    return (ulong8)(q[k.s0], q[k.s1], q[k.s2], q[k.s3], q[k.s4], q[k.s5], q[k.s6], q[k.s7]);
}

void minmax_split8(ulong8 v, dv *hi, dv *lo)
{
    float16 f = as_float16(v);
    *hi = convert_double8(f.even);
    *lo = convert_double8(f.odd);
}

/* I[TFI_LEVEL_OFFSET + level] per lane, from its closed form.  The levels are concatenated and
 * level l holds 4^(k-l) cells (cells = 2^k: heightfield.c), so level L starts at
 * 4^k + 4^(k-1) + ... + 4^(k-L+1) = ((4^L - 1) / 3) 4^(k-L+1), and (4^L - 1) / 3 is L ones at
 * the even bit positions: four integer operations.  PoCL compiled the permute of the offsets
 * this replaced (shuffle2 with a variable mask) into eight lanes picked one at a time through
 * the stack, ~60 instructions on every walk step (bench/README.md section 42). */
TF_INLINE lv level_offset8(const world *w, lv level)
{
    const ulong8 twice = as_ulong8(level + level);
    const ulong8 ones = (ulong8)(0x5555555555555555UL) & (((ulong8)(1) << twice) - 1);
    return as_long8(ones << ((ulong8)(2 * w->cell_shift + 2) - twice));
}

dv to_d(lv v) { return convert_double8(v); }

/* Component k (0, 1, 2 per lane) of (a0, a1, a2). */
dv pick3(dv a0, dv a1, dv a2, lv k) { return select(select(a0, a1, k == 1), a2, k == 2); }

dv xcross8(const world *w, const rayp *r, lv X)
{
    return tf_grid_cross(to_d(X), w->cell, r->o.x, r->inv_dx);
}

dv ycross8(const world *w, const rayp *r, lv Y)
{
    return tf_grid_cross(to_d(Y), w->cell, r->o.y, r->inv_dy);
}

/* cell_of per lane; the two correction loops run while some lane still moves. */
lv cell_of8(const world *w, dv v)
{
    dv g = v * (1.0 / w->cell); /* a first guess only, as in trace.c's cell_of */
    lv i = select(select((lv)(w->cells - 1), convert_long8_rtz(g), g < (dv)(w->cells)), (lv)(0),
                  !(g > 0));
    lv m = (i > 0) & (to_d(i) * w->cell > v);
    while (any_lane(m)) {
        i = select(i, i - 1, m);
        m &= (i > 0) & (to_d(i) * w->cell > v);
    }
    m = (i < w->cells - 1) & (to_d(i + 1) * w->cell <= v);
    while (any_lane(m)) {
        i = select(i, i + 1, m);
        m &= (i < w->cells - 1) & (to_d(i + 1) * w->cell <= v);
    }
    return i;
}

/* setup_ray's fields that depend on the direction alone (every lane's own): the steps, the
 * inverses and the watertight test's axes and shear.  (kz + 1) mod 3 by a select: a vector
 * `%` is a division. */
TF_INLINE void setup_dir8(rayp *r, v3p d)
{
    r->d = d;
    r->sx = select(select((lv)(0), (lv)(-1), d.x < 0), (lv)(1), d.x > 0);
    r->sy = select(select((lv)(0), (lv)(-1), d.y < 0), (lv)(1), d.y > 0);
    r->inv_dx = select((dv)(0), tf_safe_inverse(d.x), r->sx != 0);
    r->inv_dy = select((dv)(0), tf_safe_inverse(d.y), r->sy != 0);
    dv ax = fabs(d.x), ay = fabs(d.y), az = fabs(d.z);
    r->kz = select(select((lv)(2), (lv)(1), ay >= az), select((lv)(2), (lv)(0), ax >= az),
                   ax >= ay);
    r->kx = select(r->kz + 1, (lv)(0), r->kz == 2);
    r->ky = select(r->kx + 1, (lv)(0), r->kx == 2);
    dv dkz = pick3(d.x, d.y, d.z, r->kz);
    r->shx = pick3(d.x, d.y, d.z, r->kx) / dkz;
    r->shy = pick3(d.x, d.y, d.z, r->ky) / dkz;
    r->shz = 1.0 / dkz;
}

/* The rest of setup_ray, for the lanes of `mask`, r's direction set (setup_dir8): the lanes
 * whose ray can meet the height field.  The lanes of `window` are known to keep their window
 * (tmin, tmax) through the box's three slabs (window_in_box8); when every lane is, the slabs'
 * six divisions are skipped (the clip would give the same t0, t1 and t_square). */
TF_INLINE lv setup_from8(rayp *r, const world *w, v3p o, dv tmin, dv tmax, lv mask, lv window)
{
    const v3p d = r->d;
    mask &= isfinite(o.x) & isfinite(o.y) & isfinite(o.z) & isfinite(d.x) & isfinite(d.y) &
            isfinite(d.z) & ~((d.x == 0) & (d.y == 0) & (d.z == 0)) & (tmin < tmax);
    r->o = o;
    r->tmin = tmin;
    r->tmax = tmax;

    const double top = (double)w->cells * w->cell;
    const double hmin = w->P[TFP_HMIN], hmax = w->P[TFP_HMAX];
    dv t0 = tmin, t1 = tmax;
    if (any_lane(mask & ~window)) {
        const dv zpad = tf_box_zpad(hmin, hmax, o.z);
        mask &= tf_clip_slab(o.x, d.x, (dv)(0), (dv)(top), &t0, &t1);
        mask &= tf_clip_slab(o.y, d.y, (dv)(0), (dv)(top), &t0, &t1);
        r->t_square = t0;
        mask &= tf_clip_slab(o.z, d.z, hmin - zpad, hmax + zpad, &t0, &t1);
    } else {
        r->t_square = t0;
    }
    mask &= isfinite(t0) & isfinite(t1);
    r->t0 = t0;
    r->t1 = t1;

    /* idle lanes get harmless positions so the correction loops stay short */
    r->ci = cell_of8(w, select((dv)(0), o.x + t0 * d.x, mask));
    r->cj = cell_of8(w, select((dv)(0), o.y + t0 * d.y, mask));

    tf_walk_tolerances(top, w->cell, hmin, hmax, o, d, r->sx != 0, r->sy != 0, r->inv_dx,
                       r->inv_dy, t0, t1, &r->tie_tol, &r->margin);
    return mask;
}

/* setup_ray per lane: the lanes of `mask` whose ray can meet the height field.  Inlined into
 * its one caller: called, its ten vectors went over the stack as 32-byte halves that its 64-byte
 * loads could not be forwarded from (perf: the hottest instruction of setup_ray8 was its first
 * load of an argument). */
TF_INLINE lv setup_ray8(rayp *r, const world *w, v3p o, v3p d, dv tmin, dv tmax, lv mask)
{
    setup_dir8(r, d);
    return setup_from8(r, w, o, tmin, tmax, mask, (lv)(0));
}

/* A direction every ray of a stream shares (the shadow rays toward the sun): its setup_dir8,
 * made once for the stream, and what trace.c's window_in_box asks of it. */
typedef struct one_dir8 {
    rayp r;                       /* setup_dir8's fields */
    int moves_all;                /* no component 0 */
    double top;                   /* the square's side */
    double exit_x, exit_y;        /* the square's sides the ray leaves by on x and y */
    double exit_inv[3];           /* tf_exit_inverse of each component */
} one_dir8;

void one_dir8_make(one_dir8 *k, const world *w, vec3 d)
{
    setup_dir8(&k->r, v3p_splat(d));
    k->top = (double)w->cells * w->cell;
    k->moves_all = d.x != 0 && d.y != 0 && d.z != 0;
    k->exit_x = d.x > 0 ? k->top : 0;
    k->exit_y = d.y > 0 ? k->top : 0;
    k->exit_inv[0] = tf_exit_inverse(d.x);
    k->exit_inv[1] = tf_exit_inverse(d.y);
    k->exit_inv[2] = tf_exit_inverse(d.z);
}

/* trace.c's window_in_box per lane: would each of the box's three slabs leave the window
 * (tmin, tmax) of a ray of direction k from o as it is?  The same comparisons of the same
 * values (trace.c argues them); a shadow ray the sun's strips end nearly always passes. */
lv window_in_box8(const world *w, const one_dir8 *k, v3p o, dv tmin, dv tmax)
{
    if (!k->moves_all)
        return (lv)(0);
    const double top = k->top;
    const double hmin = w->P[TFP_HMIN], hmax = w->P[TFP_HMAX];
    const dv beyond = tmax * (1 + 1e-12);
    lv in = (tmin >= 0) & (tmax >= DBL_MIN);
    in &= (o.x >= 0) & (o.x <= top) & ((k->exit_x - o.x) * k->exit_inv[0] > beyond);
    in &= (o.y >= 0) & (o.y <= top) & ((k->exit_y - o.y) * k->exit_inv[1] > beyond);
    const dv zpad = tf_box_zpad(hmin, hmax, o.z);
    const dv zlo = hmin - zpad, zhi = hmax + zpad;
    const dv exit_z = k->r.d.z.s0 > 0 ? zhi : zlo;
    return in & (o.z >= zlo) & (o.z <= zhi) & ((exit_z - o.z) * k->exit_inv[2] > beyond);
}

typedef tf_sheared shearedp;

/* Vertex (i, j) per lane, its offsets from the origin permuted to each lane's ray space. */
shearedp shear_vertex8(const world *w, const rayp *r, lv i, lv j, lv mask)
{
    dv hz = gather_f(w->h, vertex_index8(w, i, j), mask);
    dv a0 = to_d(i) * w->cell - r->o.x, a1 = to_d(j) * w->cell - r->o.y, a2 = hz - r->o.z;
    return tf_shear(pick3(a0, a1, a2, r->kx), pick3(a0, a1, a2, r->ky), pick3(a0, a1, a2, r->kz),
                    r->shx, r->shy, r->shz);
}

void try_triangle8(const rayp *r, dv u, dv v, dv w, dv za, dv zb, dv zc, lv ci, lv cj, int tri,
                   lv mask, candp *best)
{
    dv t = best->t;
    lv take = mask & tf_triangle_hit(u, v, w, za, zb, zc, r->tmin, r->tmax, best->t, &t);
    best->t = select(best->t, t, take);
    best->ci = select(best->ci, ci, take);
    best->cj = select(best->cj, cj, take);
    best->tri = select(best->tri, (lv)(tri), take);
}

void test_triangles8(const world *w, const rayp *r, lv ci, lv cj, lv mask, candp *best)
{
    shearedp a = shear_vertex8(w, r, ci, cj, mask), b = shear_vertex8(w, r, ci + 1, cj, mask);
    shearedp c = shear_vertex8(w, r, ci + 1, cj + 1, mask), d = shear_vertex8(w, r, ci, cj + 1, mask);
    dv e_ab = tf_edge_fn(a, b), e_bc = tf_edge_fn(b, c), e_ca = tf_edge_fn(c, a);
    dv e_cd = tf_edge_fn(c, d), e_da = tf_edge_fn(d, a);
    try_triangle8(r, e_bc, e_ca, e_ab, a.z, b.z, c.z, ci, cj, 0, mask, best);
    try_triangle8(r, e_cd, e_da, -e_ca, a.z, c.z, d.z, ci, cj, 1, mask, best);
}

void test_if_inside8(const world *w, const rayp *r, lv ci, lv cj, lv mask, candp *best)
{
    mask &= (ci >= 0) & (ci < w->cells) & (cj >= 0) & (cj < w->cells);
    if (any_lane(mask))
        test_triangles8(w, r, ci, cj, mask, best);
}

/* test_cell for the lanes of mask: the lanes that found a hit (best holds it). */
lv test_cell8(const world *w, const rayp *r, lv ci, lv cj, dv tx, dv ty, lv mask, candp *best)
{
    test_triangles8(w, r, ci, cj, mask, best);
    lv diag = mask & (r->sx != 0) & (r->sy != 0);
    if (any_lane(diag)) {
        lv tie_out = diag & (fabs(tx - ty) <= r->tie_tol);
        if (any_lane(tie_out)) {
            test_if_inside8(w, r, ci + r->sx, cj, tie_out, best);
            test_if_inside8(w, r, ci, cj + r->sy, tie_out, best);
        }
        dv tx_in = xcross8(w, r, ci + select((lv)(0), (lv)(1), r->sx < 0));
        dv ty_in = ycross8(w, r, cj + select((lv)(0), (lv)(1), r->sy < 0));
        lv tie_in = diag & (fabs(tx_in - ty_in) <= r->tie_tol);
        if (any_lane(tie_in)) {
            test_if_inside8(w, r, ci - r->sx, cj, tie_in, best);
            test_if_inside8(w, r, ci, cj - r->sy, tie_in, best);
        }
    }
    return mask & (best->t < INFINITY);
}

/* settle_half (trace.c) for the lanes of mask; axis per lane (0 x, 1 y), strict as the walk
 * asks: the line between the halves of the lane's block, crossed before t_event or not, moves
 * the index to the far half's first one or leaves it. */
lv settle8(const world *w, const rayp *r, lv axis, lv stale, lv level, dv t_event, lv strict,
           lv mask)
{
    lv y = axis == 1;
    lv s = select(r->sx, r->sy, y), up = s > 0;
    dv o = select(r->o.x, r->o.y, y), inv = select(r->inv_dx, r->inv_dy, y);
    lv below = (level - 1) & (level > 0); /* 0 where not descending */
    lv mid = ((stale >> level) << level) + ((lv)(1) << below);
    dv t = tf_grid_cross(to_d(mid), w->cell, o, inv);
    lv entered = select(t <= t_event, t < t_event, strict);
    lv beyond = select(stale < mid, stale >= mid, up); /* already in the half it moves into */
    return select(stale, select(mid - 1, mid, up), mask & entered & ~beyond);
}

lv one_if(lv m) { return -m; } /* a vector comparison's -1 as C's 1 */

/* Where each lane's walk stands (walk_hier's locals). */
typedef struct walkp {
    lv ci, cj, level, stale;
    dv t_cur, t_event;
} walkp;

/* walk_hier's start, for the lanes of mask (the other lanes of *s are kept): level 0, as in
 * trace.c ("Where to start"; the hit is the same from any start level).  Both walks searched
 * for a higher one until session 44: the highest level whose block around the start does not
 * hold z(t0), found a level at a time, in lanes a gather a level (~2.9 a packet at
 * default.scene's nine levels), each waited on before the next; a walk from level 0 climbs as
 * it goes, and the kernels took 4.8% less CPU at 1920x1080 without the search, 3.3% at 480x270
 * (bench/README.md section 42). */
TF_INLINE void walk_start8(const rayp *r, lv mask, walkp *s)
{
    s->ci = select(s->ci, r->ci, mask);
    s->cj = select(s->cj, r->cj, mask);
    s->level = select(s->level, (lv)(0), mask);
    s->stale = select(s->stale, (lv)(STALE_NONE8), mask);
    s->t_cur = select(s->t_cur, r->t0, mask);
    s->t_event = select(s->t_event, r->t0, mask);
}

/* ---------------------------------------------------------------- coherence (trace.c)
 *
 * A camera ray helped by a lower ray's record: trace.c's walk_coherent per lane.  Where the
 * record vouches (tf_vouched, trace_math.h), the lane first walks the prefix (its t1 moved in to
 * t_pre), then, if that found nothing, starts again at t_skip with the cell indices the flat
 * walk holds there; trace.c's comment proves the hit is tf_trace's, bit for bit. */

/* The exit crossing of index c on the axis whose origin, inverse direction and step are o,
 * inv, s (s != 0). */
dv exit_cross8(const world *w, lv c, lv s, dv o, dv inv)
{
    return tf_grid_cross(to_d(c + one_if(s > 0)), w->cell, o, inv);
}

/* trace.c's index_at per lane of m, on axis 0 (x) or 1 (y): the index the flat walk holds at
 * t, its first index c0 moved over every exit crossing before t; -1 where it leaves the grid
 * first.  Lanes outside m keep c0. */
lv index_at8(const world *w, const rayp *r, int axis, lv c0, dv t, lv m)
{
    const lv s = axis ? r->sy : r->sx;
    const dv o = axis ? r->o.y : r->o.x, dd = axis ? r->d.y : r->d.x;
    const dv inv = axis ? r->inv_dy : r->inv_dx;
    m &= s != 0;
    lv c = cell_of8(w, select((dv)(0), o + t * dd, m)); /* a guess */
    c = select(c, c0, ~m | select(c > c0, c < c0, s > 0));
    lv back = m & (c != c0) & ~(exit_cross8(w, c - s, s, o, inv) < t);
    while (any_lane(back)) {
        c = select(c, c - s, back);
        back &= (c != c0) & ~(exit_cross8(w, c - s, s, o, inv) < t);
    }
    lv fwd = m & (exit_cross8(w, c, s, o, inv) < t), out = (lv)(0);
    while (any_lane(fwd)) {
        c = select(c, c + s, fwd);
        lv left = fwd & ((c < 0) | (c >= w->cells));
        out |= left;
        fwd &= ~left & (exit_cross8(w, c, s, o, inv) < t);
    }
    return select(c, (lv)(-1), out);
}

/* trace.c's skip_to for the lanes of m: their walks start at t instead; returns the lanes whose
 * walks have not ended by then. */
lv skip8(const world *w, rayp *r, lv m, dv t)
{
    m &= t < r->t1;
    lv ci = index_at8(w, r, 0, r->ci, t, m), cj = index_at8(w, r, 1, r->cj, t, m);
    m &= (ci >= 0) & (cj >= 0);
    r->t0 = select(r->t0, t, m);
    r->ci = select(r->ci, ci, m);
    r->cj = select(r->cj, cj, m);
    return m;
}

/* The first half of a walk_hier step: where each lane's block ends (tx, ty) and the block's
 * max and min, loaded.  Split from the second half so that a caller with two packets can
 * start both packets' loads before it waits on either. */
typedef struct fetchp {
    dv tx, ty;
    ulong8 minmax; /* not yet converted: nothing in the fetch waits for the loads */
} fetchp;

TF_INLINE void walk_fetch8(const world *w, const rayp *r, const walkp *s, lv active, fetchp *f)
{
    const int cells = w->cells;
    const lv step_x = one_if(r->sx > 0), step_y = one_if(r->sy > 0);
    const lv level = s->level, bi = s->ci >> level, bj = s->cj >> level;
    f->tx = select((dv)(INFINITY), xcross8(w, r, (bi + step_x) << level), r->sx != 0);
    f->ty = select((dv)(INFINITY), ycross8(w, r, (bj + step_y) << level), r->sy != 0);
    lv idx = level_offset8(w, level) + (bj << ((lv)(w->cell_shift) - level)) + bi;
    f->minmax = gather_minmax(w->mm, idx, active);
}

/* The second half of the step, for the lanes of `active`: *hit gets the lanes that found
 * their hit (best holds it), *missed the lanes whose ray left the grid or its interval. */
TF_INLINE void walk_step8(const world *w, const rayp *r, walkp *s, lv active, const fetchp *f,
                          candp *best, lv *hit, lv *missed)
{
    const int cells = w->cells, top = w->levels - 1;
    const dv oz = r->o.z, dz = r->d.z, t1 = r->t1;
    const lv step_x = one_if(r->sx > 0), step_y = one_if(r->sy > 0);
    lv ci = s->ci, cj = s->cj, level = s->level, stale = s->stale;
    const lv bi = ci >> level, bj = cj >> level;
    const dv tx = f->tx, ty = f->ty;
    dv hi, lo;
    minmax_split8(f->minmax, &hi, &lo);
    lv x_first = tx <= ty;
    dv tc = select(ty, tx, x_first);
    dv t_out = select(t1, tc, tc < t1);
    t_out = select(t_out, s->t_cur, t_out < s->t_cur);
    dv z_in = oz + s->t_cur * dz, z_out = oz + t_out * dz;
    lv culled = tf_span_culled(z_in, z_out, hi, lo, r->margin);
    lv keep = active & ~culled;

    *hit = (lv)(0);
    lv at_cell = keep & (level == 0);
    if (any_lane(at_cell)) {
        *hit = test_cell8(w, r, ci, cj, tx, ty, at_cell, best);
        active &= ~*hit;
    }
    lv down = keep & (level > 0);
    lv fix_y = down & (stale == STALE_Y8), fix_x = down & (stale == STALE_X8);
    if (any_lane(fix_y | fix_x)) {
        lv j = settle8(w, r, one_if(fix_y), select(ci, cj, fix_y), level, s->t_event, fix_y,
                       fix_y | fix_x);
        cj = select(cj, j, fix_y);
        ci = select(ci, j, fix_x);
    }
    level = select(level, level - 1, down);
    stale = select(stale, (lv)(STALE_NONE8), down & (level == 0)); /* every bit settled */

    lv adv = active & ~down;
    lv ends = adv & ~(tc < t1);
    adv &= ~ends;
    s->t_cur = select(s->t_cur, t_out, adv);
    s->t_event = select(s->t_event, tc, adv);
    lv xs = adv & x_first, ys = adv & ~x_first;
    lv bx = bi + step_x, by = bj + step_y;
    ci = select(ci, select((bx << level) - 1, bx << level, r->sx > 0), xs);
    cj = select(cj, select((by << level) - 1, by << level, r->sy > 0), ys);
    lv out = (xs & ((ci < 0) | (ci >= cells))) | (ys & ((cj < 0) | (cj >= cells)));
    xs &= ~out;
    ys &= ~out;
    stale = select(stale, select((lv)(STALE_NONE8), (lv)(STALE_Y8), (level > 0) & (r->sy != 0)),
                   xs);
    stale = select(stale, select((lv)(STALE_NONE8), (lv)(STALE_X8), (level > 0) & (r->sx != 0)),
                   ys);
    lv boundary = select(by, bx, xs);
    level = select(level, level + 1, (xs | ys) & (level < top) & ((boundary & 1) == 0));
    *missed = ends | out;
    s->ci = ci;
    s->cj = cj;
    s->level = level;
    s->stale = stale;
}

/* The heights at the four corners of cell (ci, cj) per lane of mask: a at (ci, cj), b at
 * (ci + 1, cj), c at (ci + 1, cj + 1), d at (ci, cj + 1) (trace.c's order for a hit's cell). */
typedef struct corners8 { dv a, b, c, d; } corners8;

TF_INLINE corners8 cell_corners8(const world *w, lv ci, lv cj, lv mask)
{
    const lv base = vertex_index8(w, ci, cj);
    corners8 h = {gather_f(w->h, base, mask), gather_f(w->h, base + 1, mask),
                  gather_f(w->h, base + w->n + 1, mask), gather_f(w->h, base + w->n, mask)};
    return h;
}

void finish_hit8(const world *w, const rayp *r, const candp *c, lv mask, hitp *hit)
{
    const corners8 h = cell_corners8(w, c->ci, c->cj, mask);
    hit->t = c->t;
    hit->p = v3p_make(r->o.x + c->t * r->d.x, r->o.y + c->t * r->d.y, r->o.z + c->t * r->d.z);
    hit->n = tf_hit_normal(h.a, h.b, h.c, h.d, w->cell, c->tri == 0);
    hit->ci = convert_int8(c->ci);
    hit->cj = convert_int8(c->cj);
}

/* ---------------------------------------------------------------- streams of rays
 *
 * Eight rays taken as they come make ragged packets: a packet of eight samples' shadow rays is
 * often half empty (only lit lanes cast one).  walk_stream takes all the rays of a batch (up
 * to TF_STREAM: the camera rays of a pixel round, or all their shadow rays) and deals them to
 * the lanes eight at a time, so every packet is full but the last.  A packet gets new rays
 * once all its lanes are done: handing a lane its next ray as soon as it finished measured
 * 3-10% slower on default.scene (a ray's setup costs more than the idle steps it saves). */

#ifndef TF_STREAM
#define TF_STREAM 128 /* rays per stream (the host passes -DTF_STREAM) */
#endif
#define TF_STREAM_PACKETS (TF_STREAM / TF_LANES)
#if TF_STREAM > 256 || TF_STREAM % TF_LANES
#error "TF_STREAM: a multiple of TF_LANES, at most 256 (streams index rays with a uchar)"
#endif

/* Up to TF_STREAM rays; ray k is lane k % 8 of packet k / 8.  one_dir: every ray's direction
 * is the first's (the shadow rays toward the sun), set up once for the stream. */
typedef struct ray_stream {
    int n, one_dir;
    v3p o[TF_STREAM_PACKETS], d[TF_STREAM_PACKETS];
    dv tmin[TF_STREAM_PACKETS], tmax[TF_STREAM_PACKETS];
} ray_stream;

/* Rays' coherence records (trace.h's tf_ray_clear, the origin left out): ray k's is lane k % 8
 * of packet k / 8.  s_free 0: the record vouches for nothing. */
typedef struct ray_clears {
    dv ux[TF_STREAM_PACKETS], uy[TF_STREAM_PACKETS], k[TF_STREAM_PACKETS];
    dv s_in[TF_STREAM_PACKETS], s_free[TF_STREAM_PACKETS];
} ray_clears;

/* Record k of *c from / to its TF_CL_RECORD_DOUBLES doubles in a buffer (ux, uy, k, s_in,
 * s_free; tf_cl_params.h). */
void record_get(__global const double *from, int k, ray_clears *c)
{
    const int p = k / TF_LANES, l = k % TF_LANES;
    c->ux[p][l] = from[0], c->uy[p][l] = from[1], c->k[p][l] = from[2];
    c->s_in[p][l] = from[3], c->s_free[p][l] = from[4];
}

void record_put(__global double *to, const ray_clears *c, int k)
{
    const int p = k / TF_LANES, l = k % TF_LANES;
    to[0] = c->ux[p][l], to[1] = c->uy[p][l], to[2] = c->k[p][l];
    to[3] = c->s_in[p][l], to[4] = c->s_free[p][l];
}

/* Packet p of *to: lane l the record at offset at[l] of records (-1: none,
 * s_free 0), gathered a field at a time (a record put in lane by lane stored and reloaded the
 * packet's vectors for every lane). */
void records_gather(__global const double *records, const int at[TF_LANES], int p,
                    ray_clears *to)
{
    const lv has = convert_long8(vload8(0, at) >= 0);
    const lv k = select((lv)(0), convert_long8(vload8(0, at)), has);
#define TF_GATHER_FIELD(f)                                                                     \
    (dv)(records[k.s0 + (f)], records[k.s1 + (f)], records[k.s2 + (f)], records[k.s3 + (f)],  \
         records[k.s4 + (f)], records[k.s5 + (f)], records[k.s6 + (f)], records[k.s7 + (f)])
    to->ux[p] = TF_GATHER_FIELD(0);
    to->uy[p] = TF_GATHER_FIELD(1);
    to->k[p] = TF_GATHER_FIELD(2);
    to->s_in[p] = TF_GATHER_FIELD(3);
    to->s_free[p] = select((dv)(0), TF_GATHER_FIELD(4), has);
#undef TF_GATHER_FIELD
}

/* One packet walking a stream: its rays (rayp), where their walks stand, their best hits, the
 * lanes at work and which packet of the stream they hold (lane l: its lane l). */
typedef struct walker {
    rayp r;
    walkp s;
    candp best;
    lv active;
    int packet;         /* the stream's packet dealt to the lanes (walker_deal: whole packets) */
    lv prefix;          /* lanes walking the prefix of a vouched-for ray (t1 moved in) */
    dv t_skip, t1_full; /* their restart, and their own t1 */
    lv above;           /* lanes whose ray starts above its cell's maximum (for records) */
    int one_dir_set;    /* r holds the stream's one direction (walker_deal) */
} walker;

#ifndef TF_WALKERS
#define TF_WALKERS 2 /* packets walked side by side */
#endif

void walker_init(walker *k)
{
    walkp s = {(lv)(0), (lv)(0), (lv)(0), (lv)(0), (dv)(0), (dv)(0)};
    candp best = {(dv)(INFINITY), (lv)(0), (lv)(0), (lv)(0)};
    k->s = s;
    k->best = best;
    k->active = k->prefix = k->above = (lv)(0);
    k->packet = 0;
    k->t_skip = k->t1_full = (dv)(0);
    k->one_dir_set = 0;
}

/* One lower record in each lane: heading ux, uy, climb k, the run [s_in, s_free) it is above
 * the surface over (s_free 0: none). */
typedef struct low8 {
    dv ux, uy, k, s_in, s_free;
} low8;

/* walk_coherent's start (trace.c) for the lanes of the walker just dealt, by the first of
 * their lower records that vouches for part of the ray: `near`, or where that one cannot, `far`
 * (the C renderer asks one record only).  A lane with a prefix gets its t1 moved in; one
 * without starts at t_skip at once (or is done, if its walk has ended by then). */
TF_INLINE void vouch8(const world *w, walker *k, const low8 *near, const low8 *far)
{
    rayp *r = &k->r;
    dv run, ux, uy, kk, t_pre = (dv)(0), t_skip = (dv)(0);
    const lv heads = k->active & tf_heading(r->d.x, r->d.y, r->d.z, &run, &ux, &uy, &kk);
    if (!any_lane(heads & ((near->s_free > 0) | (far->s_free > 0))))
        return;
    const dv eps = tf_clearance_eps(w->P[TFP_EXTENT], w->P[TFP_HMIN], w->P[TFP_HMAX], r->o.x,
                                    r->o.y, r->o.z);
    lv v = heads & (near->s_free > 0);
    if (any_lane(v))
        v &= tf_vouched(ux, uy, kk, run, r->t_square, r->t0, near->ux, near->uy, near->k,
                        near->s_in, near->s_free, w->P[TFP_SLOPE_MAX], eps, &t_pre, &t_skip);
    const lv again = heads & ~v & (far->s_free > 0);
    if (any_lane(again)) {
        dv t_pre2, t_skip2;
        const lv v2 = again & tf_vouched(ux, uy, kk, run, r->t_square, r->t0, far->ux, far->uy,
                                         far->k, far->s_in, far->s_free, w->P[TFP_SLOPE_MAX],
                                         eps, &t_pre2, &t_skip2);
        t_pre = select(t_pre, t_pre2, v2);
        t_skip = select(t_skip, t_skip2, v2);
        v |= v2;
    }
    if (!any_lane(v))
        return;
    const lv pre = v & (t_pre > r->t0), now = v & ~pre;
    k->prefix = pre;
    k->t_skip = t_skip;
    k->t1_full = r->t1;
    r->t1 = select(r->t1, select(r->t1, t_pre, t_pre < r->t1), pre);
    if (any_lane(now))
        k->active &= ~(now & ~skip8(w, r, now, t_skip));
}

/* The lanes of `missed` that were walking a prefix start again at their t_skip (trace.c's
 * walk_coherent after a prefix that found nothing); returns the lanes done for good. */
TF_INLINE lv resume8(const world *w, walker *k, lv missed)
{
    const lv again = missed & k->prefix;
    k->prefix &= ~missed;
    if (!any_lane(again))
        return missed;
    k->r.t1 = select(k->r.t1, k->t1_full, again);
    const lv go = skip8(w, &k->r, again, k->t_skip);
    walk_start8(&k->r, go, &k->s);
    return missed & ~go;
}

/* trace.c's starts_above per lane: z(t0) above the maximum of the ray's start cell (level 0,
 * which begins the concatenated grids). */
lv starts_above8(const world *w, const rayp *r, lv mask)
{
    lv idx = (r->cj << w->cell_shift) + r->ci;
    dv hi, lo;
    minmax_split8(gather_minmax(w->mm, idx, mask), &hi, &lo);
    return mask & (r->o.z + r->t0 * r->d.z > hi + r->margin);
}

/* trace.c's note_clear for the lanes of `ended` (hit: the ones that hit, best holding it):
 * their records go to the same lanes of packet k->packet of *out. */
void note_clears8(const world *w, const walker *k, lv ended, lv hit, ray_clears *out)
{
    const rayp *r = &k->r;
    dv run, ux, uy, kk;
    lv ok = ended & tf_heading(r->d.x, r->d.y, r->d.z, &run, &ux, &uy, &kk);
    const corners8 h = cell_corners8(w, k->best.ci, k->best.cj, hit & ok);
    lv free = select(k->above,
                     tf_hit_from_above(h.a, h.b, h.c, h.d, w->cell, k->best.tri == 0, r->d), hit);
    dv s_free = select((dv)(0), select(r->t1, k->best.t, hit) * run, ok & free);
    const int p = k->packet;
    out->ux[p] = select(out->ux[p], ux, ok);
    out->uy[p] = select(out->uy[p], uy, ok);
    out->k[p] = select(out->k[p], kk, ok);
    out->s_in[p] = select(out->s_in[p], r->t_square * run, ok);
    out->s_free[p] = select(out->s_free[p], s_free, ok);
}

/* Packet p of a stream's records, in the lanes of m (none: s_free 0). */
TF_INLINE low8 low_packet(const ray_clears *from, int p, lv m)
{
    const dv zero = (dv)(0);
    low8 to = {select(zero, from->ux[p], m), select(zero, from->uy[p], m),
               select(zero, from->k[p], m), select(zero, from->s_in[p], m),
               select(zero, from->s_free[p], m)};
    return to;
}

/* Once all the walker's lanes are done, deal it rays *next, *next + 1, ... of the stream (up
 * to eight), with their lower records lows and fars (either NULL: none).  k->r is read only
 * after a deal has set it.  Deals are whole packets: *next starts at 0, and a deal takes eight
 * rays, or the rest of the stream when fewer are left, so it always starts a packet and the
 * rays go to their lanes as vectors (lane by lane, PoCL kept every vector on the stack). */
TF_INLINE void walker_deal(const world *w, const ray_stream *in, const one_dir8 *one,
                           const ray_clears *lows, const ray_clears *fars, int out_records,
                           int *next, walker *k)
{
    if (*next >= in->n || any_lane(k->active))
        return;
    const int p = *next / TF_LANES, count = min(TF_LANES, in->n - *next);
    const lv lane = (lv)(0, 1, 2, 3, 4, 5, 6, 7);
    const lv fresh = lane < (lv)(count);
    k->packet = p;
    *next += count;
    const v3p zero = v3p_splat(v3(0, 0, 0));
    v3p o = v3p_select(zero, in->o[p], fresh), d = v3p_select(zero, in->d[p], fresh);
    dv tmin = select((dv)(0), in->tmin[p], fresh), tmax = select((dv)(0), in->tmax[p], fresh);
    low8 near = {(dv)(0), (dv)(0), (dv)(0), (dv)(0), (dv)(0)}, far = near;
    if (lows)
        near = low_packet(lows, p, fresh);
    if (fars)
        far = low_packet(fars, p, fresh);
    if (one) { /* the stream's one direction, set up once; no later deal or step changes it */
        if (!k->one_dir_set)
            k->r = one->r;
        k->one_dir_set = 1;
        k->active = setup_from8(&k->r, w, o, tmin, tmax, fresh,
                                window_in_box8(w, one, o, tmin, tmax));
    } else {
        k->active = setup_ray8(&k->r, w, o, d, tmin, tmax, fresh);
    }
    k->above = out_records ? starts_above8(w, &k->r, k->active) : (lv)(0);
    k->prefix = (lv)(0);
    if (lows || fars)
        vouch8(w, k, &near, &far);
    walk_start8(&k->r, k->active, &k->s);
    k->best.t = (dv)(INFINITY);
}

/* One step of the walker's lanes, its fetch done; the rays that end are reported in found /
 * hits. */
TF_INLINE void walker_step(const world *w, walker *k, const fetchp *f, lv found[], hitp *hits,
                          ray_clears *records)
{
    lv hit, missed;
    walk_step8(w, &k->r, &k->s, k->active, f, &k->best, &hit, &missed);
    k->prefix &= ~hit;
    if (any_lane(missed & k->prefix))
        missed = resume8(w, k, missed);
    if (records && any_lane(hit | missed))
        note_clears8(w, k, hit | missed, hit, records);
    if (any_lane(hit)) {
        hitp h;
        if (hits)
            finish_hit8(w, &k->r, &k->best, hit, &h);
        const int p = k->packet;
        found[p] |= hit;
        if (hits) {
            const iv hit_i = convert_int8(hit);
            hits[p].t = select(hits[p].t, h.t, hit);
            hits[p].p = v3p_select(hits[p].p, h.p, hit);
            hits[p].n = v3p_select(hits[p].n, h.n, hit);
            hits[p].ci = select(hits[p].ci, h.ci, hit_i);
            hits[p].cj = select(hits[p].cj, h.cj, hit_i);
        }
    }
    k->active &= ~(hit | missed);
}

/* Walk every ray of the stream: found[k / 8] lane k % 8 says whether ray k hit; if hits is
 * not NULL, hits[k / 8] lane k % 8 holds that hit (finish_hit8's record).  If lows is not
 * NULL, ray k is helped by record k of it, or where that one cannot vouch by record k of fars
 * (if not NULL; the coherence section above: every ray of the stream starts at the origin the
 * records' rays started at); if records is not NULL, ray k's own record
 * goes to record k of it (trace.c's note_clear).  TF_WALKERS packets
 * walk side by side: a step waits on its grid loads (a gather the next step depends on), so
 * every packet's loads are started (walk_fetch8) before any packet's step goes on with them. */
void walk_stream(const world *w, const ray_stream *in, const ray_clears *lows,
                 const ray_clears *fars, lv found[], hitp *hits, ray_clears *records)
{
    for (int p = 0; p < TF_STREAM_PACKETS; p++) {
        found[p] = (lv)(0);
        if (records) /* a ray that never starts a walk vouches for nothing */
            records->s_free[p] = (dv)(0);
    }
    walker k[TF_WALKERS];
    for (int g = 0; g < TF_WALKERS; g++)
        walker_init(&k[g]);
    one_dir8 one;
    if (in->one_dir)
        one_dir8_make(&one, w, v3(in->d[0].x.s0, in->d[0].y.s0, in->d[0].z.s0));
    int next = 0;
    for (;;) {
        int busy = 0;
        for (int g = 0; g < TF_WALKERS; g++) {
            walker_deal(w, in, in->one_dir ? &one : NULL, lows, fars, records != NULL, &next,
                        &k[g]);
            busy |= any_lane(k[g].active);
        }
        if (!busy) {
            if (next >= in->n)
                break;
            continue;
        }
        fetchp f[TF_WALKERS];
        for (int g = 0; g < TF_WALKERS; g++)
            if (any_lane(k[g].active))
                walk_fetch8(w, &k[g].r, &k[g].s, k[g].active, &f[g]);
        for (int g = 0; g < TF_WALKERS; g++)
            if (any_lane(k[g].active))
                walker_step(w, &k[g], &f[g], found, hits, records);
    }
}
