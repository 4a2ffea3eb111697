/* packet_render.cl: the two kernels the host runs per rectangle, feeding lattice_samples
 * (packet_shade.cl) batches of up to TF_STREAM samples, traced eight at a time; and, at the
 * end, tf_walk_rays8: walk_stream on rays of the caller's, for the tests.
 *
 *   tf_corners8  work-item g samples the corner columns TF_CL_CORNER_STRIP g .. of the
 *                (w+1) x (h+1) pixel-corner lattice points (external row and column included:
 *                the external-sample rule of render.h), in bands of TF_LOWER_ROWS rows from the
 *                bottom up, a band a batch: each camera ray is helped by the one TF_LOWER_ROWS
 *                rows down in its column (trace.c's coherence), and leaves its own record in
 *                corner_records for the band above and for tf_pixels8.
 *   tf_pixels8   work-item g runs the adaptive subdivision of render.c's render_pixel for
 *                TF_PIX neighbouring pixels at once.  Each pixel is a small state machine over
 *                its own quad stack (render_pixel's, popped in the same order); whenever a
 *                pixel needs a lattice sample it does not have, the sample is queued and the
 *                pixel waits.
 *                The queue (up to TF_STREAM samples) is sampled as one batch, and the pixels
 *                resume.
 *
 * Why the pixels give the C renderer's bits: a pixel takes its quads in render.c's order and
 * sums their samples in render.c's order; only *when* a sample is traced changes, never its
 * value (a sample is a function of its lattice point alone).  A pixel only ever queues samples
 * render.c would trace: the corners of the quad on top of its stack, the probe centre of that
 * quad once its corners show the contrast that asks for it, and -- to keep the batches full --
 * the corners of the quads further down its stack, which render.c reaches and needs whatever
 * happens, and the centres of those of them whose corners ask for a probe (centre_ahead).  So
 * the samples traced, the sample count and the nearest distance are C's too.
 *
 * Sample cache: each pixel owns a slice of (N+1)^2 entries of `cache`, with the samples'
 * display levels (render.c tf_display_level of r, g, b: what the contrast test compares, so
 * each is computed once per sample, not once per quad that looks at it) in `levels`.  Entries
 * are filled from the front in the order samples arrive -- a pixel takes a handful, so its
 * samples share a few cache lines -- and `where` maps a lattice slot to its sample's entry in
 * the whole buffer (the slice's first entry plus its place in it).  The host
 * gives every launch a new epoch, so slices need no clearing between pixels.  The four pixel
 * corners stay where tf_corners8 wrote them.
 *
 * Shared edges (render.c's pixel_edge): a lattice point on a pixel's left edge is the point
 * on its left neighbour's right edge, and one on its lower edge (j == 0) the point on the top
 * edge of the pixel a row down.  Where that neighbour is one of the work-item's pixels, it
 * keeps the point (`keeper`): whichever of the two needs the point first queues it under the
 * keeper's name, and both read it from the keeper's slice, so it is traced once.  A slot's
 * state in `have`, for the pixel that owns the slice:
 *   epoch              the pixel has used the sample (counted in its spp and nearest distance)
 *   epoch | TF_STORED  the sample is in this slice, not yet used by this pixel
 *   epoch | TF_QUEUED  the sample is queued for this slice
 * A pixel that reads a point its neighbour keeps marks its own slot epoch when it first uses
 * it, and copies the keeper's `where` into its own: from then on it reads the sample as one of
 * its own, with no keeper to find.  So each pixel counts exactly the samples it uses, as
 * render.c does. */

#ifndef TF_PIX
#define TF_PIX 64          /* pixels per work-item (the host passes -DTF_PIX) */
#endif
#if TF_PIX > 256
#error "TF_PIX: at most 256 (the queue names pixels with a uchar)"
#endif
#define TF_QUEUE TF_STREAM /* queued samples per work-item: one stream */
#define TF_QUEUED 0x80000000u
#define TF_STORED 0x40000000u /* epochs stay below it (the host's EPOCH_LIMIT) */
#define TF_STACK (3 * TF_AA_MAX_DEPTH + 1)
#if TF_STACK > 32 || TF_AA_MAX_DEPTH > 7
#error "a pixel's stack positions are the bits of a uint (centred), its lattice points uchars"
#endif

__kernel void tf_corners8(__global const double *P, __global const int *I, ulong jitter_key,
                          __global const float *h, __global const float2 *mm,
                          __global const ushort *perm, __global const float *strips,
                          int rx, int ry, int cw, int ch,
                          __global float *out, __global double *out_levels,
                          __global uint *shadow, __global double *out_records)
{
    const int strip = TF_CL_CORNER_STRIP(TF_STREAM), c0 = (int)get_global_id(0) * strip;
    if (c0 >= cw)
        return;
    const int cols = cw - c0 < strip ? cw - c0 : strip;
    world w = make_world(P, I, h, mm, perm, strips);
    const long N = I[TFI_LATTICE];
    /* bands of TF_LOWER_ROWS corner rows, bottom first: each ray is helped by the record of the
     * corner TF_LOWER_ROWS rows down in its column, which the band before left in out_records */
    for (int y1 = ch; y1 > 0; y1 -= TF_LOWER_ROWS) {
        const int y0 = y1 > TF_LOWER_ROWS ? y1 - TF_LOWER_ROWS : 0, n = (y1 - y0) * cols;
        lv X[TF_STREAM_PACKETS], Y[TF_STREAM_PACKETS];
        ray_clears lows, rec;
        long xs[TF_STREAM], ys[TF_STREAM]; /* made packets after (records_gather) */
        int low_at[TF_STREAM];
        for (int e = 0; e < TF_STREAM; e++) {
            const int k = e < n ? e : n - 1;
            const int y = y0 + k / cols, c = c0 + k % cols;
            xs[e] = (long)(rx + c) * N;
            ys[e] = (long)(ry + y) * N;
            low_at[e] = e < n && y + TF_LOWER_ROWS < ch
                            ? ((y + TF_LOWER_ROWS) * cw + c) * TF_CL_RECORD_DOUBLES
                            : -1;
        }
        for (int p = 0; p < TF_STREAM_PACKETS; p++) {
            X[p] = vload8(p, xs);
            Y[p] = vload8(p, ys);
            records_gather(out_records, low_at + p * TF_LANES, p, &lows);
        }
        float8 s[TF_STREAM_PACKETS][5];
        iv rays[TF_STREAM_PACKETS];
        for (int p = 0; p < TF_STREAM_PACKETS; p++)
            rays[p] = (iv)(0);
        lattice_samples(&w, jitter_key, X, Y, n, &lows, NULL, s, rays, &rec);
        dv lvl[TF_STREAM_PACKETS][3];
        for (int p = 0; p * TF_LANES < n; p++)
            for (int chn = 0; chn < 3; chn++)
                lvl[p][chn] = tf_display_level_of(convert_double8(s[p][chn]));
        for (int e = 0; e < n; e++) {
            const int p = e / TF_LANES, l = e % TF_LANES;
            const size_t at = (size_t)(y0 + e / cols) * cw + (size_t)(c0 + e % cols);
            for (int m = 0; m < TF_CL_SAMPLE_FLOATS; m++)
                out[at * TF_CL_SAMPLE_FLOATS + m] = s[p][m][l];
            for (int chn = 0; chn < 3; chn++)
                out_levels[at * 3 + chn] = lvl[p][chn][l];
            shadow[at] = (uint)rays[p][l];
            record_put(out_records + at * TF_CL_RECORD_DOUBLES, &rec, e);
        }
    }
}

/* The records of the corners that help the camera ray of lattice point (px N + i, py N + j),
 * 0 <= i, j <= N (trace.c's coherence), as offsets into the corner records (-1: none): *near,
 * the corner TF_LOWER_ROWS pixel rows below the point's pixel row (or the rectangle's last
 * corner row), in the corner column nearest the point; and *far, the corner TF_LOWER_ROWS_FAR
 * rows below it (or the last), where that is further down, which walk_stream asks where the
 * first cannot vouch.  Any lower ray from the camera may help; these are below by enough to
 * outclimb the terrain's slope across a half pixel's heading.  render.c's ray_below takes the
 * first only: a C ray that walks from the camera costs no lane of a packet, and the far record
 * measured no gain there (bench/README.md section 30). */
void lower_corners(int px, int py, int i, int j, int N, int rx, int ry, int rw, int rh,
                   int *near, int *far)
{
    /* the point's pixel row is py, or py + 1 on the pixel's top edge; its nearest corner
     * column px, or px + 1 in the pixel's right half */
    const int row = py + (j == N);
    int cy = row + TF_LOWER_ROWS - ry, fy = row + TF_LOWER_ROWS_FAR - ry;
    int cx = px + (i + N / 2 >= N) - rx;
    cy = cy < rh ? cy : rh;
    fy = fy < rh ? fy : rh;
    cx = cx < 0 ? 0 : cx > rw ? rw : cx;
    *near = *far = -1;
    if ((long)(cy + ry) * N <= (long)py * N + j) /* no corner row below the point */
        return;
    *near = (cy * (rw + 1) + cx) * TF_CL_RECORD_DOUBLES;
    if (fy > cy)
        *far = (fy * (rw + 1) + cx) * TF_CL_RECORD_DOUBLES;
}

/* The lowest and highest display level of each channel over some samples (render.c's
 * level_span, on the stored levels): a quad's four corners, then its centre too.  Levels lie in
 * [0, 1] and are never NaN (nor -0), so minima and maxima taken in any order are render.c's,
 * and so is display_range; three channels a vector, and the corners' span is kept for the
 * centre.  Taken by comparisons, as render.c takes them: OpenCL's fmin and fmax must also
 * handle NaN, which PoCL does with two more instructions each (perf: they topped `advance`'s
 * own profile). */
typedef struct level_span { double3 lo, hi; } level_span;

double3 min3(double3 a, double3 b) { return select(b, a, a < b); }
double3 max3(double3 a, double3 b) { return select(b, a, a > b); }

level_span span_of_corners(__global const double *const lvl[4])
{
    double3 a = vload3(0, lvl[0]), b = vload3(0, lvl[1]);
    double3 c = vload3(0, lvl[2]), d = vload3(0, lvl[3]);
    level_span sp = {min3(min3(a, b), min3(c, d)), max3(max3(a, b), max3(c, d))};
    return sp;
}

level_span span_with(level_span sp, __global const double *lvl)
{
    double3 v = vload3(0, lvl);
    sp.lo = min3(sp.lo, v);
    sp.hi = max3(sp.hi, v);
    return sp;
}

/* render.c's display_range: the largest channel's range. */
double display_range(level_span sp)
{
    double3 r = sp.hi - sp.lo;
    double m = r.y > r.z ? r.y : r.z;
    return r.x > m ? r.x : m;
}

typedef struct quad { int i, j, size; } quad;

/* One pixel's place in the adaptive subdivision. */
typedef struct pixel_state {
    quad stack[TF_STACK];
    int sp, spp, px, py;
    int left, below;         /* the work-item's pixels that keep this one's left and lower
                                edges (their right and top), or -1 */
    int used;                /* slice entries filled: the camera rays traced for this slice */
    uint entry0;             /* the slice's first entry in cache / levels */
    int asked;               /* stack[0 .. asked-1] have had their corners queued */
    uint centred;            /* bit e: stack[e], below the top, has had its probe decided
                                (centre_ahead) */
    uint rays;
    float zmin;
    double sum_r, sum_g, sum_b, sum_a;
    /* probing: the quad on top of the stack has its corners in hand and their span (in
     * probe_span) passed the probe test; only its centre was missing when advance stopped */
    int probing;
    level_span probe_span;
    __global float *cache;   /* every slice's samples, (N+1)^2 a slice */
    __global double *levels; /* and their display levels, 3 a sample */
    __global uint *have;     /* (N+1)^2 slot states */
    __global uint *where;    /* (N+1)^2 slots: their sample's entry in cache / levels, for a
                                slot used (have == epoch) or kept here (TF_STORED) */
    /* the four corner samples stay where tf_corners8 put them (shared with the neighbours):
     * slots 0, N, N (N+1), N (N+1) + N of the cache are never written */
    __global const float *corner[4];
    __global const double *corner_levels[4];
} pixel_state;

typedef struct sample_queue {
    int n;
    uchar pixel[TF_QUEUE]; /* which of the work-item's pixels asked */
    uchar i[TF_QUEUE], j[TF_QUEUE]; /* the lattice point (slot j * (N+1) + i; N <= 64) */
} sample_queue;

/* The pixel that keeps lattice point (i, j) of pixel p (shared edges, above), and the point
 * in that pixel's slice, (*ki, *kj). */
int keeper(const pixel_state *ps, int p, int side, int i, int j, int *ki, int *kj)
{
    const int N = side - 1;
    if (i == 0 && j > 0 && j < N && ps[p].left >= 0) {
        *ki = N, *kj = j;
        return ps[p].left;
    }
    if (j == 0 && i > 0 && i < N && ps[p].below >= 0) {
        *ki = i, *kj = N;
        return ps[p].below;
    }
    *ki = i, *kj = j;
    return p;
}

/* want's path for a point pixel p has not used yet: if its keeper has the sample, the pixel
 * takes it (its where, its spp and nearest distance) and it is ready; if the keeper neither
 * has it nor waits for it, it is queued for the keeper (room permitting; a pixel that finds
 * the queue full simply asks again in the next round). */
int want_new(pixel_state *ps, int p, int side, int i, int j, uint epoch, sample_queue *q)
{
    pixel_state *me = &ps[p];
    const int mine = j * side + i;
    int ki, kj;
    pixel_state *kp = &ps[keeper(ps, p, side, i, j, &ki, &kj)];
    const int k = kj * side + ki;
    uint st = kp->have[k];
    if (st == epoch || st == (epoch | TF_STORED)) {
        uint entry = kp->where[k];
        me->where[mine] = entry;
        me->have[mine] = epoch;
        me->spp++;
        float z = me->cache[(size_t)entry * TF_CL_SAMPLE_FLOATS + 4];
        if (z < me->zmin)
            me->zmin = z;
        return 1;
    }
    if (st != (epoch | TF_QUEUED) && q->n < TF_QUEUE) {
        kp->have[k] = epoch | TF_QUEUED;
        q->pixel[q->n] = (uchar)(kp - ps);
        q->i[q->n] = (uchar)ki;
        q->j[q->n] = (uchar)kj;
        q->n++;
    }
    return 0;
}

/* Is lattice point (i, j) ready for pixel p (and counted)?  Queues it if need be. */
TF_INLINE int want(pixel_state *ps, int p, int side, int i, int j, uint epoch, sample_queue *q)
{
    return ps[p].have[j * side + i] == epoch || want_new(ps, p, side, i, j, epoch, q);
}

/* The four corners of quad t of pixel p: all ready?  Queues the missing ones either way. */
TF_INLINE int want_corners(pixel_state *ps, int p, quad t, int side, uint epoch, sample_queue *q)
{
    int a = want(ps, p, side, t.i, t.j, epoch, q);
    int b = want(ps, p, side, t.i + t.size, t.j, epoch, q);
    int c = want(ps, p, side, t.i, t.j + t.size, epoch, q);
    int d = want(ps, p, side, t.i + t.size, t.j + t.size, epoch, q);
    return a && b && c && d;
}

/* Which pixel corner lattice point (i, j) is (0..3: (0,0), (N,0), (0,N), (N,N)), or -1. */
int corner_of(int side, int i, int j)
{
    const int N = side - 1;
    return (i == 0 || i == N) && (j == 0 || j == N) ? (j ? 2 : 0) + (i ? 1 : 0) : -1;
}

/* A pixel's sample at lattice point (i, j), which it has used (want), and its display
 * levels: a pixel corner where tf_corners8 left it, else the entry its `where` names. */
__global const float *slot_of(const pixel_state *ps, int side, int i, int j)
{
    int c = corner_of(side, i, j);
    return c >= 0 ? ps->corner[c]
                  : ps->cache + (size_t)ps->where[j * side + i] * TF_CL_SAMPLE_FLOATS;
}

__global const double *levels_of(const pixel_state *ps, int side, int i, int j)
{
    int c = corner_of(side, i, j);
    return c >= 0 ? ps->corner_levels[c] : ps->levels + (size_t)ps->where[j * side + i] * 3;
}

/* Ask ahead for the probe centres of the quads below the top of pixel p's stack: render.c
 * pops every one of them whatever happens above it, and probes it where its corners' span
 * asks for it, so once an entry's corners are in hand its centre is a sample render.c traces,
 * and it is queued now rather than in the round the entry comes to the top (a pixel that
 * splits deep otherwise asks one centre a round).  The decision is advance's own. */
void centre_ahead(pixel_state *all, int p, int side, double threshold, uint epoch,
                  sample_queue *q)
{
    pixel_state *ps = &all[p];
    const int N = side - 1;
    const uint below = ps->sp > 1 ? (1u << (ps->sp - 1)) - 1u : 0u;
    if ((ps->centred & below) == below)
        return; /* every entry below the top decided */
    for (int e = 0; e < ps->sp - 1 && q->n < TF_QUEUE; e++) {
        const quad t = ps->stack[e];
        if ((ps->centred >> e) & 1u)
            continue;
        if (t.size > 1) {
            if (!want_corners(all, p, t, side, epoch, q))
                continue; /* its corners are on their way: decide in a later round */
            __global const double *lvl[4] = {
                levels_of(ps, side, t.i, t.j), levels_of(ps, side, t.i + t.size, t.j),
                levels_of(ps, side, t.i, t.j + t.size),
                levels_of(ps, side, t.i + t.size, t.j + t.size)};
            const double split_threshold = tf_aa_split_threshold(threshold, N, t.size);
            if (display_range(span_of_corners(lvl)) > split_threshold * TF_AA_PROBE_FRACTION)
                want(all, p, side, t.i + t.size / 2, t.j + t.size / 2, epoch, q);
        }
        ps->centred |= 1u << e;
    }
}

/* render_pixel's loop for pixel p, run until its stack is empty or it needs a sample it does
 * not have; then the corners of the quads further down its stack are queued too, and the
 * centres of those whose corners are in hand (centre_ahead). */
void advance(pixel_state *all, int p, int N, double threshold, uint epoch, sample_queue *q)
{
    const int side = N + 1;
    pixel_state *ps = &all[p];
    while (ps->sp > 0) {
        quad t = ps->stack[ps->sp - 1];
        /* a quad stopped at its centre comes back with its corners counted and its span kept:
         * the same decisions, without loading and comparing the corners' levels again */
        if (!ps->probing && !want_corners(all, p, t, side, epoch, q))
            break;
        __global const float *s[5];
        __global const double *lvl[4];
        s[0] = slot_of(ps, side, t.i, t.j);
        s[1] = slot_of(ps, side, t.i + t.size, t.j);
        s[2] = slot_of(ps, side, t.i, t.j + t.size);
        s[3] = slot_of(ps, side, t.i + t.size, t.j + t.size);
        if (t.size > 1) {
            double split_threshold = tf_aa_split_threshold(threshold, N, t.size);
            level_span span;
            if (ps->probing) {
                span = ps->probe_span;
            } else {
                lvl[0] = levels_of(ps, side, t.i, t.j);
                lvl[1] = levels_of(ps, side, t.i + t.size, t.j);
                lvl[2] = levels_of(ps, side, t.i, t.j + t.size);
                lvl[3] = levels_of(ps, side, t.i + t.size, t.j + t.size);
                span = span_of_corners(lvl);
            }
            if (ps->probing || display_range(span) > split_threshold * TF_AA_PROBE_FRACTION) {
                int hs = t.size / 2;
                if (!want(all, p, side, t.i + hs, t.j + hs, epoch, q)) {
                    ps->probing = 1;
                    ps->probe_span = span;
                    break;
                }
                ps->probing = 0;
                s[4] = slot_of(ps, side, t.i + hs, t.j + hs);
                span = span_with(span, levels_of(ps, side, t.i + hs, t.j + hs));
                ps->sp--;
                ps->asked = min(ps->asked, ps->sp);
                if (display_range(span) > split_threshold) {
                    quad *st = ps->stack + ps->sp;
                    ps->centred &= ~(0xfu << ps->sp);
                    st[0].i = t.i + hs, st[0].j = t.j + hs, st[0].size = hs;
                    st[1].i = t.i, st[1].j = t.j + hs, st[1].size = hs;
                    st[2].i = t.i + hs, st[2].j = t.j, st[2].size = hs;
                    st[3].i = t.i, st[3].j = t.j, st[3].size = hs;
                    ps->sp += 4;
                    continue;
                }
                int z = t.size;
                ps->sum_r += tf_aa_probed_leaf(z, s[0][0], s[1][0], s[2][0], s[3][0], s[4][0]);
                ps->sum_g += tf_aa_probed_leaf(z, s[0][1], s[1][1], s[2][1], s[3][1], s[4][1]);
                ps->sum_b += tf_aa_probed_leaf(z, s[0][2], s[1][2], s[2][2], s[3][2], s[4][2]);
                ps->sum_a += tf_aa_probed_leaf(z, s[0][3], s[1][3], s[2][3], s[3][3], s[4][3]);
                continue;
            }
        }
        ps->sp--;
        ps->asked = min(ps->asked, ps->sp);
        ps->sum_r += tf_aa_flat_leaf(t.size, s[0][0], s[1][0], s[2][0], s[3][0]);
        ps->sum_g += tf_aa_flat_leaf(t.size, s[0][1], s[1][1], s[2][1], s[3][1]);
        ps->sum_b += tf_aa_flat_leaf(t.size, s[0][2], s[1][2], s[2][2], s[3][2]);
        ps->sum_a += tf_aa_flat_leaf(t.size, s[0][3], s[1][3], s[2][3], s[3][3]);
    }
    /* an entry below the top changes only by being popped (asked follows every pop down), so
     * each is asked once */
    for (; ps->asked < ps->sp - 1; ps->asked++) {
        int room = TF_QUEUE - q->n;
        if (room < 4)
            break; /* this entry may not fit whole: ask again next round */
        want_corners(all, p, ps->stack[ps->asked], side, epoch, q);
    }
    centre_ahead(all, p, side, threshold, epoch, q);
}

/* The order tf_pixels8 takes a rectangle's pixels in: tiles of TF_TILE x TF_TILE (narrower at
 * the rectangle's right edge, lower at its top), a band of tiles at a time from the bottom,
 * each tile row by row.  A work-item's TF_PIX pixels are then a tile, which shares its inner
 * edges (keeper, above), not a row or two of the rectangle, which shares few of its lower
 * ones.  Pixel t of that order: its column and row in the rw x rh rectangle, and its tile's
 * width. */
#if TF_PIX >= 256
#define TF_TILE 16
#elif TF_PIX >= 64
#define TF_TILE 8
#elif TF_PIX >= 16
#define TF_TILE 4
#elif TF_PIX >= 4
#define TF_TILE 2
#else
#define TF_TILE 1
#endif

void tile_place(int t, int rw, int rh, int *c, int *row, int *tw)
{
    const int band = t / (TF_TILE * rw), th = min(TF_TILE, rh - band * TF_TILE);
    const int in_band = t - band * TF_TILE * rw, tile = in_band / (TF_TILE * th);
    const int in_tile = in_band - tile * TF_TILE * th;
    *tw = min(TF_TILE, rw - tile * TF_TILE);
    *c = tile * TF_TILE + in_tile % *tw;
    *row = band * TF_TILE + in_tile / *tw;
}

/* Pixels first .. first+count-1 of the rw x rh rectangle at (rx, ry), in tile_place's order;
 * pixel first + m uses scratch slice m of cache / levels / have / where ((N+1)^2 entries each)
 * and its results go to out and shadow at its row-major place.  corners,
 * corner_levels: the output of tf_corners8.  epoch: this launch's mark (host: never 0, never
 * with TF_QUEUED set). */
__kernel void tf_pixels8(__global const double *P, __global const int *I, ulong jitter_key,
                         __global const float *h, __global const float2 *mm,
                         __global const ushort *perm, __global const float *strips,
                          int rx, int ry,
                         int rw, int first, int count, __global const float *corners,
                         __global const double *corner_levels, __global float *cache, __global double *levels,
                         __global uint *have, __global uint *where, uint epoch,
                         __global float *out, __global uint *shadow,
                         __global const double *corner_records, int rh)
{
    const int m0 = (int)get_global_id(0) * TF_PIX;
    if (m0 >= count)
        return;
    const int np = count - m0 < TF_PIX ? count - m0 : TF_PIX;
    world w = make_world(P, I, h, mm, perm, strips);
    const int N = I[TFI_LATTICE], side = N + 1, cw = rw + 1;
    const long LN = N;
    const double threshold = P[TFP_THRESHOLD];

    pixel_state ps[TF_PIX];
    for (int p = 0; p < np; p++) {
        pixel_state *s = &ps[p];
        int c, row, tw;
        tile_place(first + m0 + p, rw, rh, &c, &row, &tw);
        s->px = rx + c;
        s->py = ry + row;
        s->cache = cache;
        s->levels = levels;
        s->entry0 = (uint)(m0 + p) * (uint)side * (uint)side;
        s->have = have + (size_t)(m0 + p) * (size_t)side * (size_t)side;
        s->where = where + (size_t)(m0 + p) * (size_t)side * (size_t)side;
        s->used = 0;
        s->left = c % TF_TILE > 0 && p > 0 ? p - 1 : -1;
        s->below = row % TF_TILE > 0 && p >= tw ? p - tw : -1;
        const int slot[4] = {0, N, N * side, N * side + N};
        const size_t from[4] = {(size_t)row * cw + c, (size_t)row * cw + c + 1,
                                (size_t)(row + 1) * cw + c, (size_t)(row + 1) * cw + c + 1};
        s->zmin = TF_SKY_DIST;
        for (int e = 0; e < 4; e++) {
            s->corner[e] = corners + from[e] * TF_CL_SAMPLE_FLOATS;
            s->corner_levels[e] = corner_levels + from[e] * 3;
            s->have[slot[e]] = epoch;
            if (s->corner[e][4] < s->zmin)
                s->zmin = s->corner[e][4];
        }
        s->stack[0].i = 0, s->stack[0].j = 0, s->stack[0].size = N;
        s->sp = 1;
        s->asked = 0;
        s->centred = 0;
        s->probing = 0;
        s->spp = 4;
        s->rays = 0;
        s->sum_r = s->sum_g = s->sum_b = s->sum_a = 0;
    }

    sample_queue q;
    for (;;) {
        q.n = 0;
        int active = 0;
        for (int p = 0; p < np; p++) {
            if (ps[p].sp == 0)
                continue;
            advance(ps, p, N, threshold, epoch, &q);
            active |= ps[p].sp > 0;
        }
        if (!active)
            break;
        /* every pixel still active waits on a queued sample, so q.n > 0 here */
        lv X[TF_STREAM_PACKETS], Y[TF_STREAM_PACKETS];
        ray_clears lows, fars;
        /* the queue's points a sample at a time into arrays, then into packets (a lane put
         * into a vector in place stores and reloads the whole vector) */
        long xs[TF_STREAM], ys[TF_STREAM];
        int near_at[TF_STREAM], far_at[TF_STREAM];
        for (int e = 0; e < q.n; e++) {
            const pixel_state *s = &ps[q.pixel[e]];
            const int i = q.i[e], j = q.j[e];
            xs[e] = (long)s->px * LN + i;
            ys[e] = (long)s->py * LN + j;
            lower_corners(s->px, s->py, i, j, N, rx, ry, rw, rh, &near_at[e], &far_at[e]);
        }
        for (int e = q.n; e < (q.n + TF_LANES - 1) / TF_LANES * TF_LANES; e++) {
            xs[e] = xs[0], ys[e] = ys[0];
            near_at[e] = far_at[e] = -1;
        }
        for (int b = 0; b * TF_LANES < q.n; b++) {
            X[b] = vload8(b, xs);
            Y[b] = vload8(b, ys);
            records_gather(corner_records, near_at + b * TF_LANES, b, &lows);
            records_gather(corner_records, far_at + b * TF_LANES, b, &fars);
        }
        float8 smp[TF_STREAM_PACKETS][5];
        iv rays[TF_STREAM_PACKETS];
        for (int b = 0; b < TF_STREAM_PACKETS; b++)
            rays[b] = (iv)(0);
        lattice_samples(&w, jitter_key, X, Y, q.n, &lows, &fars, smp, rays, NULL);
        for (int b = 0; b * TF_LANES < q.n; b++) {
            dv lvl[3];
            for (int ch = 0; ch < 3; ch++)
                lvl[ch] = tf_display_level_of(convert_double8(smp[b][ch]));
            for (int l = 0; l < TF_LANES && b * TF_LANES + l < q.n; l++) {
                int e = b * TF_LANES + l;
                pixel_state *s = &ps[q.pixel[e]];
                int k = q.j[e] * side + q.i[e];
                uint at = s->entry0 + (uint)s->used++;
                __global float *dst = s->cache + (size_t)at * TF_CL_SAMPLE_FLOATS;
                for (int f = 0; f < TF_CL_SAMPLE_FLOATS; f++)
                    dst[f] = smp[b][f][l];
                for (int ch = 0; ch < 3; ch++)
                    s->levels[(size_t)at * 3 + ch] = lvl[ch][l];
                s->where[k] = at;
                s->have[k] = epoch | TF_STORED;
                s->rays += (uint)rays[b][l];
            }
        }
    }

    const double area = (double)N * (double)N;
    for (int p = 0; p < np; p++) {
        const pixel_state *s = &ps[p];
        int k = (s->py - ry) * rw + (s->px - rx);
        __global float *o = out + (size_t)k * TF_CL_PIXEL_FLOATS;
        o[0] = (float)(s->sum_r / area);
        o[1] = (float)(s->sum_g / area);
        o[2] = (float)(s->sum_b / area);
        o[3] = (float)(s->sum_a / area);
        o[4] = s->zmin;
        o[5] = (float)s->spp;
        o[6] = (float)s->used;
        shadow[k] = s->rays;
    }
}

/* The rays' walk on its own, for the tests and benchmarks (tf_cl_backend_walk): rays
 * TF_STREAM g .. of n through walk_stream.  Ray k: rays[7k ..] = its origin, direction and tmax
 * (tmin 0); with has_lows, the record that helps it at lows[TF_CL_RECORD_DOUBLES k ..] (a record
 * of a ray from its own origin: walk_stream compares none), and with has_fars the one asked
 * where that cannot vouch at fars[TF_CL_RECORD_DOUBLES k ..]; out: t[k], its hit's parameter
 * (INFINITY: none), and its own record at records[TF_CL_RECORD_DOUBLES k ..]. */
__kernel void tf_walk_rays8(__global const double *P, __global const int *I, ulong jitter_key,
                            __global const float *h, __global const float2 *mm,
                            __global const ushort *perm, __global const float *strips, int n,
                            __global const double *rays, __global const double *lows,
                            int has_lows, __global const double *fars, int has_fars,
                            __global double *t, __global double *records)
{
    (void)jitter_key;
    const int base = (int)get_global_id(0) * TF_STREAM;
    if (base >= n)
        return;
    world w = make_world(P, I, h, mm, perm, strips);
    ray_stream in;
    ray_clears low, far, rec;
    in.n = n - base < TF_STREAM ? n - base : TF_STREAM;
    in.one_dir = 1; /* rays of one direction are set up as the shadow rays are */
    for (int e = 0; e < in.n; e++) {
        const int p = e / TF_LANES, l = e % TF_LANES;
        __global const double *r = rays + (size_t)(base + e) * 7;
        in.o[p].x[l] = r[0], in.o[p].y[l] = r[1], in.o[p].z[l] = r[2];
        in.d[p].x[l] = r[3], in.d[p].y[l] = r[4], in.d[p].z[l] = r[5];
        in.tmin[p][l] = 0.0, in.tmax[p][l] = r[6];
        if (has_lows)
            record_get(lows + (size_t)(base + e) * TF_CL_RECORD_DOUBLES, e, &low);
        if (has_fars)
            record_get(fars + (size_t)(base + e) * TF_CL_RECORD_DOUBLES, e, &far);
        in.one_dir &= r[3] == rays[(size_t)base * 7 + 3] && r[4] == rays[(size_t)base * 7 + 4] &&
                      r[5] == rays[(size_t)base * 7 + 5];
    }
    lv found[TF_STREAM_PACKETS];
    hitp hit[TF_STREAM_PACKETS];
    const v3p zero = v3p_splat(v3(0, 0, 0));
    for (int p = 0; p < TF_STREAM_PACKETS; p++) {
        hit[p].t = (dv)(0.0);
        hit[p].p = hit[p].n = zero;
        hit[p].ci = hit[p].cj = (iv)(0);
    }
    walk_stream(&w, &in, has_lows ? &low : NULL, has_fars ? &far : NULL, found, hit, &rec);
    for (int e = 0; e < in.n; e++) {
        const int p = e / TF_LANES, l = e % TF_LANES;
        t[base + e] = found[p][l] ? hit[p].t[l] : INFINITY;
        record_put(records + (size_t)(base + e) * TF_CL_RECORD_DOUBLES, &rec, e);
    }
}
