/* trace_procedural.c: the quad-tree tracer of the procedural terrain (trace_procedural.h).
 *
 * Node (q, i, j) is the square [i, i + 1] x [j, j + 1] times extent / 2^q.  A node is a leaf
 * when it is at most two cells of the finest level used over it wide (q >= hi + 4, the cells
 * of level L being extent / 2^(L + 5)) and spans few levels; then each level used there covers
 * it with one cell, or two a side for the finest: LEAF_SAMPLES samples, all in one tile. */
#include "render/trace_procedural.h"

#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#define MAX_LEAF_LEVELS 6
#define LEAF_SAMPLES 9
#define MARCH_STEPS 256
#define HIT_TOLERANCE 1e-3 /* of the leaf's finest spacing */
#define SHADOW_LIFT 2e-2   /* of the finest spacing at the hit */

typedef struct pray {
    const tf_procedural *p;
    const tf_proc_view *v;
    tf_vec3 o, d;
    double dxy;     /* |d| across the ground */
    int max_q;
    double t;       /* the hit */
    tf_vec3 n;      /* its normal */
    int want_normal;
    struct node_memo *memo; /* this thread's, or NULL */
} pray;

/* One level's samples over a leaf: n x n cells from cell (ci, cj), spacing s. */
typedef struct leaf_level {
    double s;
    int64_t ci, cj;
    int n;
    float v[LEAF_SAMPLES];
} leaf_level;

typedef struct leaf {
    int lo, hi;
    leaf_level lev[MAX_LEAF_LEVELS];
    double zlo, zhi; /* the range of every sample: the surface lies within */
    double slope;    /* Lipschitz bound of the surface over the leaf */
    double eps;
} leaf;

static double z_at(const pray *r, double t) { return r->o.z + t * r->d.z; }

/* fmax and fmin as glibc computes them on x86-64 (maxsd, minsd: a tie, +0 against -0 included,
 * gives y; a quiet NaN gives the other operand), inline: a call each was 5% of a procedural
 * render, and the tie no longer depends on the machine's libm. */
static inline double larger(double x, double y) { return x > y || y != y ? x : y; }
static inline double smaller(double x, double y) { return x < y || y != y ? x : y; }


/* ------------------------------------------------------------------------------ leaves */

static void read_level(const pray *r, int q, int64_t i, int64_t j, int level, leaf_level *l)
{
    l->s = tf_proc_spacing(r->p, level);
    int shift = q - level - 5; /* >= -1 in a leaf */
    l->n = shift >= 0 ? 1 : 2;
    l->ci = shift >= 0 ? i >> shift : i << 1;
    l->cj = shift >= 0 ? j >> shift : j << 1;
    tf_proc_samples(r->p, level, l->ci, l->cj, l->n + 1, l->n + 1, l->v);
}

/* Steepest slope of level l's bilinear patches, and the range of its samples. */
static double level_slope(const leaf_level *l, double *lo, double *hi)
{
    int m = l->n + 1;
    double gx = 0, gy = 0;
    for (int b = 0; b < m; b++)
        for (int a = 0; a < m; a++) {
            double v = l->v[b * m + a];
            *lo = smaller(*lo, v);
            *hi = larger(*hi, v);
            if (a + 1 < m)
                gx = larger(gx, fabs(l->v[b * m + a + 1] - v));
            if (b + 1 < m)
                gy = larger(gy, fabs(l->v[(b + 1) * m + a] - v));
        }
    return hypot(gx, gy) / l->s;
}

static void load_leaf(const pray *r, int q, int64_t i, int64_t j, int lo, int hi, double *box,
                      leaf *f)
{
    f->lo = lo;
    f->hi = hi;
    f->zlo = INFINITY;
    f->zhi = -INFINITY;
    double steepest = 0;
    for (int level = lo; level <= hi; level++) {
        read_level(r, q, i, j, level, &f->lev[level - lo]);
        steepest = larger(steepest, level_slope(&f->lev[level - lo], &f->zlo, &f->zhi));
    }
    f->slope = steepest + (f->zhi - f->zlo) * tf_proc_lambda_slope(r->p, r->v, box[0], box[1],
                                                                   box[2], box[3]);
    f->eps = HIT_TOLERANCE * tf_proc_spacing(r->p, hi);
}

/* Level l's bilinear height at (x, y), and its gradient if g is not NULL. */
static double level_height(const leaf_level *l, double x, double y, double *g)
{
    double gx = x / l->s - (double)l->ci, gy = y / l->s - (double)l->cj;
    int a = gx < 1 || l->n == 1 ? 0 : 1, b = gy < 1 || l->n == 1 ? 0 : 1;
    double fx = smaller(larger(gx - a, 0.0), 1.0), fy = smaller(larger(gy - b, 0.0), 1.0);
    int m = l->n + 1;
    const float *c = l->v + b * m + a;
    double c00 = c[0], c10 = c[1], c01 = c[m], c11 = c[m + 1];
    if (g) {
        g[0] = ((1 - fy) * (c10 - c00) + fy * (c11 - c01)) / l->s;
        g[1] = ((1 - fx) * (c01 - c00) + fx * (c11 - c10)) / l->s;
    }
    return (1 - fy) * ((1 - fx) * c00 + fx * c10) + fy * ((1 - fx) * c01 + fx * c11);
}

/* The surface h (procedural.h) at (x, y) from the leaf's samples; its gradient into g if
 * g is not NULL. */
static double leaf_height(const pray *r, const leaf *f, double x, double y, double *g)
{
    double dx = x - r->v->eye.x, dy = y - r->v->eye.y, d2 = dx * dx + dy * dy;
    double lambda = tf_proc_lambda(r->p, r->v, d2);
    int level = (int)lambda;
    level = level < f->lo ? f->lo : level > f->hi ? f->hi : level;
    double w = smaller(larger(lambda - level, 0.0), 1.0);
    double g0[2], g1[2];
    double h = level_height(&f->lev[level - f->lo], x, y, g ? g0 : NULL);
    if (!(w > 0) || level >= f->hi) {
        if (g)
            g[0] = g0[0], g[1] = g0[1];
        return h;
    }
    double h1 = level_height(&f->lev[level + 1 - f->lo], x, y, g ? g1 : NULL);
    if (g) { /* d lambda / dx = -(x - ex) / (ln 2 (d2 + dz^2)) while lambda is not clamped */
        double d2z = d2 + r->v->dz * r->v->dz;
        double k = lambda > 0 && lambda < r->p->max_level && d2z > 0 ? -1.0 / (M_LN2 * d2z) : 0;
        for (int a = 0; a < 2; a++)
            g[a] = g0[a] + w * (g1[a] - g0[a]) + (h1 - h) * k * (a == 0 ? dx : dy);
    }
    return h + w * (h1 - h);
}

static void hit_normal(pray *r, const leaf *f, double x, double y)
{
    double g[2];
    leaf_height(r, f, x, y, g);
    r->n = v3_norm(v3(-g[0], -g[1], 1.0));
}

/* March the leaf's surface from t0 to t1 with steps the slope bound makes safe. */
static int march(pray *r, const leaf *f, double t0, double t1)
{
    if (smaller(z_at(r, t0), z_at(r, t1)) > f->zhi)
        return 0;
    double climb = f->slope * r->dxy - r->d.z; /* how fast the gap can close, at most */
    double t = t0;
    for (int step = 0; step < MARCH_STEPS; step++) {
        double x = r->o.x + t * r->d.x, y = r->o.y + t * r->d.y;
        double gap = z_at(r, t) - leaf_height(r, f, x, y, NULL);
        if (gap <= f->eps)
            break;
        if (!(climb > 0))
            return 0;
        t += gap / climb;
        if (t > t1)
            return 0;
    }
    r->t = t;
    if (r->want_normal)
        hit_normal(r, f, r->o.x + t * r->d.x, r->o.y + t * r->d.y);
    return 1;
}

/* ------------------------------------------------------------------------------ the tree */

static void node_box(const pray *r, int q, int64_t i, int64_t j, double *box)
{
    double size = tf_proc_halved(r->p->extent, q);
    box[0] = (double)i * size, box[1] = (double)(i + 1) * size;
    box[2] = (double)j * size, box[3] = (double)(j + 1) * size;
}

/* t where the ray crosses coordinate c along axis a (x: 0, y: 1), or INFINITY. */
static double cross_at(const pray *r, int a, double c)
{
    double o = a == 0 ? r->o.x : r->o.y, d = a == 0 ? r->d.x : r->d.y;
    return d != 0 ? (c - o) / d : INFINITY;
}

static int visit(pray *r, int q, int64_t i, int64_t j, double t0, double t1, int plo, int phi);

/* A thread's memory of nodes, so that the rays after the first through a node skip what it
 * costs to describe: a direct-mapped table of node bounds (an interval sum over the octaves,
 * a function of the terrain, the node and its levels: it serves every view), and one of node
 * facts (node_facts: a function of the terrain, the node and the view; a node's parent is
 * unique, so the levels it inherits from above are too).  A hit returns exactly what the
 * computation would. */
#define BOUND_TABLE_BITS 16
#define FACT_TABLE_BITS 17 /* 4 MiB: a ray visits ~160 nodes, and 2^15 entries missed */
typedef struct bound_entry {
    uint64_t proc;
    int64_t i, j;
    int q, lo, hi;
    tf_interval b;
} bound_entry;

/* What a ray asks of a node: the levels used over it and the top of the surface there. */
typedef struct node_facts {
    int lo, hi;
    double top;
} node_facts;

/* Facts of the memo's terrain and view: those of its generation.  32 bytes, and a node's four
 * siblings side by side (facts_of), so that a ray's next node is often in a line just read. */
typedef struct fact_entry {
    uint64_t qi; /* q << 58 | i (i < 2^(q + 1) and q < 58) */
    int64_t j;
    uint32_t gen;
    int16_t lo, hi;
    double top;
} fact_entry;

typedef struct node_memo {
    bound_entry bounds[1 << BOUND_TABLE_BITS];
    uint64_t proc, view; /* whose facts the table holds */
    uint32_t gen;        /* theirs; entries of other generations are empty */
    fact_entry facts[1 << FACT_TABLE_BITS];
} node_memo;

static __thread node_memo *thread_memo; /* NULL: none yet, or no memory for one */
static pthread_key_t memo_key;
static pthread_once_t memo_key_once = PTHREAD_ONCE_INIT;

static void make_memo_key(void) { pthread_key_create(&memo_key, free); }

/* This thread's memo, or NULL when there is no memory for it (then everything is computed). */
static node_memo *memo(void)
{
    if (!thread_memo) {
        pthread_once(&memo_key_once, make_memo_key);
        thread_memo = calloc(1, sizeof *thread_memo);
        if (thread_memo)
            pthread_setspecific(memo_key, thread_memo);
    }
    return thread_memo;
}

static uint64_t node_hash(int q, int64_t i, int64_t j, int lo, int hi)
{
    return tf_hash64((uint64_t)i * 0x9e3779b97f4a7c15ULL ^ (uint64_t)j ^ ((uint64_t)q << 56) ^
                     ((uint64_t)lo << 48) ^ ((uint64_t)hi << 40));
}

static tf_interval node_bound(const pray *r, int q, int64_t i, int64_t j, const double *box,
                              int lo, int hi)
{
    node_memo *m = r->memo;
    if (!m)
        return tf_proc_bound_levels(r->p, box[0], box[1], box[2], box[3], lo, hi);
    bound_entry *e = &m->bounds[node_hash(q, i, j, lo, hi) >> (64 - BOUND_TABLE_BITS)];
    if (e->proc == r->p->id && e->i == i && e->j == j && e->q == q && e->lo == lo &&
        e->hi == hi)
        return e->b;
    tf_interval b = tf_proc_bound_levels(r->p, box[0], box[1], box[2], box[3], lo, hi);
    *e = (bound_entry){r->p->id, i, j, q, lo, hi, b};
    return b;
}

/* Where the ray crosses the node's midlines xm and ym within [t0, t1], in its order: cut[0]
 * = t0, cut[3] = t1 (a crossing outside is t1). */
static void cuts(const pray *r, double xm, double ym, double t0, double t1, double *cut)
{
    cut[0] = t0, cut[1] = cross_at(r, 0, xm), cut[2] = cross_at(r, 1, ym), cut[3] = t1;
    for (int a = 1; a < 3; a++)
        cut[a] = cut[a] > t0 && cut[a] < t1 ? cut[a] : t1;
    if (cut[1] > cut[2]) {
        double s = cut[1];
        cut[1] = cut[2], cut[2] = s;
    }
}

/* The child (cx + 2 cy) the ray is in over [cut[k], cut[k + 1]], or -1 if that is empty. */
static int child_over(const pray *r, double xm, double ym, const double *cut, int k)
{
    if (!(cut[k + 1] > cut[k]))
        return -1;
    double tm = 0.5 * (cut[k] + cut[k + 1]);
    return (r->o.x + tm * r->d.x >= xm) + 2 * (r->o.y + tm * r->d.y >= ym);
}

/* The four children in the order the ray meets them over [t0, t1].  Inlined by force, as is
 * facts_of: as calls of their own (the packets are their second callers) single rays cost 5%
 * more. */
static inline __attribute__((always_inline)) int visit_children(pray *r, int q, int64_t i,
                                                                 int64_t j, const double *box,
                                                                 double t0, double t1, int lo,
                                                                 int hi)
{
    double xm = 0.5 * (box[0] + box[1]), ym = 0.5 * (box[2] + box[3]), cut[4];
    cuts(r, xm, ym, t0, t1, cut);
    for (int k = 0; k < 3; k++) {
        int c = child_over(r, xm, ym, cut, k);
        if (c >= 0 && visit(r, q + 1, 2 * i + (c & 1), 2 * j + (c >> 1), cut[k], cut[k + 1], lo, hi))
            return 1;
    }
    return 0;
}

/* Once a node lies within one tile of every level used over it (q >= hi), its bound is exact:
 * the range of the samples each level has over it (a block of the tile's pyramid; a node
 * smaller than two cells takes the two-cell block around it).  h mixes those samples only. */
static tf_interval sample_bound(const pray *r, int q, int64_t i, int64_t j, int lo, int hi)
{
    tf_interval b = {INFINITY, -INFINITY};
    for (int level = lo; level <= hi; level++) {
        int cells_log2 = level + 5 - q; /* the node's side in cells of this level, log 2 */
        int k = cells_log2 < 1 ? 1 : cells_log2;
        int64_t ci = cells_log2 >= 0 ? i << cells_log2 : i >> -cells_log2;
        int64_t cj = cells_log2 >= 0 ? j << cells_log2 : j >> -cells_log2;
        float a, c;
        tf_proc_range(r->p, level, k, ci, cj, &a, &c);
        b.lo = a < b.lo ? a : b.lo;
        b.hi = c > b.hi ? c : b.hi;
    }
    return b;
}

/* Node (q, i, j)'s facts, computed; plo, phi: its parent's levels (a child's lie within them,
 * so a parent with one level pair passes it down without computing). */
static node_facts compute_facts(const pray *r, int q, int64_t i, int64_t j, const double *box,
                                int plo, int phi)
{
    node_facts f = {plo, phi, 0};
    if (phi - plo > 1 || (phi == r->p->max_level && plo == phi)) /* may narrow */
        tf_proc_box_levels(r->p, r->v, box[0], box[1], box[2], box[3], &f.lo, &f.hi);
    f.top = q >= f.hi ? sample_bound(r, q, i, j, f.lo, f.hi).hi
                      : node_bound(r, q, i, j, box, f.lo, f.hi).hi;
    return f;
}

/* The same, remembered for the view (node_memo). */
static inline __attribute__((always_inline)) node_facts facts_of(const pray *r, int q,
                                                                 int64_t i, int64_t j,
                                                                 const double *box, int plo,
                                                                 int phi)
{
    node_memo *m = r->memo;
    if (!m)
        return compute_facts(r, q, i, j, box, plo, phi);
    uint64_t family = node_hash(q, i >> 1, j >> 1, 0, 0) >> (64 - FACT_TABLE_BITS + 2);
    fact_entry *e = &m->facts[family << 2 | (uint64_t)(i & 1) | (uint64_t)(j & 1) << 1];
    const uint64_t qi = (uint64_t)q << 58 | (uint64_t)i;
    if (e->gen == m->gen && e->qi == qi && e->j == j)
        return (node_facts){e->lo, e->hi, e->top};
    node_facts f = compute_facts(r, q, i, j, box, plo, phi);
    *e = (fact_entry){qi, j, m->gen, (int16_t)f.lo, (int16_t)f.hi, f.top};
    return f;
}

/* This thread's memo, its facts those of terrain p and view v (a new generation if they were
 * another's), or NULL. */
static node_memo *memo_for(const tf_procedural *p, const tf_proc_view *v)
{
    node_memo *m = memo();
    if (m && (m->proc != p->id || m->view != v->id)) {
        if (++m->gen == 0) { /* after 2^32 views: old entries could pass for new */
            memset(m->facts, 0, sizeof m->facts);
            m->gen = 1;
        }
        m->proc = p->id, m->view = v->id;
    }
    return m;
}

/* Whether the ray passes above a node whose facts are f over [t0, t1]. */
static int passes_above(const pray *r, const node_facts *f, double t0, double t1)
{
    return smaller(z_at(r, t0), z_at(r, t1)) > f->top;
}

/* Whether node (q, .) with facts f is a leaf. */
static int is_leaf(const pray *r, int q, const node_facts *f)
{
    return (q >= f->hi + 4 && f->hi - f->lo < MAX_LEAF_LEVELS) || q >= r->max_q;
}

/* Leaf node (q, i, j)'s samples into l. */
static void leaf_of(const pray *r, int q, int64_t i, int64_t j, const node_facts *f,
                    double *box, leaf *l)
{
    int lo = f->lo, hi = f->hi;
    if (hi - lo >= MAX_LEAF_LEVELS)
        lo = hi - MAX_LEAF_LEVELS + 1; /* q >= max_q: unreachable for any real view */
    load_leaf(r, q, i, j, lo, hi, box, l);
}

/* Node (q, i, j) over [t0, t1] of the ray; plo, phi: its parent's levels. */
static int visit(pray *r, int q, int64_t i, int64_t j, double t0, double t1, int plo, int phi)
{
    double box[4];
    node_box(r, q, i, j, box);
    node_facts f = facts_of(r, q, i, j, box, plo, phi);
    if (passes_above(r, &f, t0, t1))
        return 0;
    if (is_leaf(r, q, &f)) {
        leaf l;
        leaf_of(r, q, i, j, &f, box, &l);
        return march(r, &l, t0, t1);
    }
    return visit_children(r, q, i, j, box, t0, t1, f.lo, f.hi);
}

/* Clip [*t0, *t1] to the ray's stretch over the square [0, extent]^2; 0 if none. */
static int clip_to_square(const pray *r, double *t0, double *t1)
{
    for (int a = 0; a < 2; a++) {
        double o = a == 0 ? r->o.x : r->o.y, d = a == 0 ? r->d.x : r->d.y;
        if (d == 0) {
            if (!(o >= 0 && o <= r->p->extent))
                return 0;
            continue;
        }
        double ta = (0 - o) / d, tb = (r->p->extent - o) / d;
        *t0 = larger(*t0, smaller(ta, tb));
        *t1 = smaller(*t1, larger(ta, tb));
    }
    return *t1 > *t0;
}

/* Ready ray r (its p, v, o, d and want_normal set) for [tmin, tmax]: its stretch over the
 * terrain's square into *t0, *t1; 0 if it has none. */
static int start_ray(pray *r, double tmin, double tmax, double *t0, double *t1)
{
    r->dxy = hypot(r->d.x, r->d.y);
    r->max_q = r->p->max_level + 4 + 2 * MAX_LEAF_LEVELS; /* < 64: tf_proc_halved */
    r->memo = memo_for(r->p, r->v);
    *t0 = tmin, *t1 = tmax;
    return clip_to_square(r, t0, t1);
}

static int trace(pray *r, double tmin, double tmax)
{
    double t0, t1;
    if (!start_ray(r, tmin, tmax, &t0, &t1))
        return 0;
    return visit(r, 0, 0, 0, t0, t1, 0, r->p->max_level);
}

/* The hit ray r found. */
static tf_hit hit_of(const pray *r)
{
    return (tf_hit){r->t, v3_add(r->o, v3_scale(r->d, r->t)), r->n, 0, 0};
}

int tf_proc_trace(const tf_procedural *p, const tf_proc_view *v, tf_vec3 origin, tf_vec3 dir,
                  double tmin, double tmax, tf_hit *hit)
{
    pray r = {.p = p, .v = v, .o = origin, .d = dir, .want_normal = 1};
    if (!trace(&r, tmin, tmax))
        return 0;
    *hit = hit_of(&r);
    return 1;
}

int tf_proc_occluded(const tf_procedural *p, const tf_proc_view *v, tf_vec3 origin, tf_vec3 dir,
                     double tmin, double tmax)
{
    pray r = {.p = p, .v = v, .o = origin, .d = dir, .want_normal = 0};
    return trace(&r, tmin, tmax);
}

/* ------------------------------------------------------------------------------ packets */

/* Rays traced together through the tree: each node's facts are asked once for all the rays in
 * it, each leaf loaded once for all the rays that reach it.  A ray's arithmetic is visit's, so
 * its hit is the same bits.  The rays of a packet head the same way across the ground (d.x >=
 * 0 alike and d.y >= 0 alike): then every ray meets a node's children in a subsequence of one
 * order, children_order's, and the packet visits them in it; a ray whose crossings say
 * otherwise (rounding near a corner) goes on from that node alone, through visit. */
#define PACKET_RAYS 16

typedef struct packet {
    pray r[PACKET_RAYS];
    unsigned char hit[PACKET_RAYS]; /* its first hit found */
    int heading;                    /* (d.x >= 0) + 2 (d.y >= 0), every ray's */
} packet;

/* The rays of a packet in a node: which, and over what stretch of each. */
typedef struct packet_part {
    int n;
    int id[PACKET_RAYS];
    double t0[PACKET_RAYS], t1[PACKET_RAYS];
} packet_part;

static int heading_of(tf_vec3 d) { return (d.x >= 0) + 2 * (d.y >= 0); }

/* The children (cx + 2 cy) in the order a ray of the heading meets them: the nearest corner
 * first, the farthest last. */
static void children_order(int heading, int order[4])
{
    int fx = heading & 1 ? 0 : 1, fy = heading & 2 ? 0 : 2;
    order[0] = fx + fy, order[1] = (fx ^ 1) + fy, order[2] = fx + (fy ^ 2),
    order[3] = (fx ^ 1) + (fy ^ 2);
}

static void visit_packet(packet *pk, int q, int64_t i, int64_t j, node_facts f,
                         const packet_part *in);

/* Leaf node (q, i, j): loaded once, marched by each ray in it. */
static void march_packet(packet *pk, int q, int64_t i, int64_t j, const node_facts *f,
                         double *box, const packet_part *in)
{
    leaf l;
    leaf_of(&pk->r[in->id[0]], q, i, j, f, box, &l);
    for (int s = 0; s < in->n; s++)
        pk->hit[in->id[s]] = (unsigned char)march(&pk->r[in->id[s]], &l, in->t0[s], in->t1[s]);
}

/* Ray s of `in`'s stretches in each child (by children_order's position) into part[]; 0 if
 * its crossings do not follow that order. */
static int split_ray(const packet *pk, const double *box, const packet_part *in, int s,
                     const int pos[4], packet_part part[4])
{
    const pray *r = &pk->r[in->id[s]];
    double xm = 0.5 * (box[0] + box[1]), ym = 0.5 * (box[2] + box[3]), cut[4];
    cuts(r, xm, ym, in->t0[s], in->t1[s], cut);
    int c[3], last = -1;
    for (int k = 0; k < 3; k++) {
        c[k] = child_over(r, xm, ym, cut, k);
        if (c[k] >= 0 && pos[c[k]] <= last)
            return 0;
        last = c[k] >= 0 ? pos[c[k]] : last;
    }
    for (int k = 0; k < 3; k++)
        if (c[k] >= 0) {
            packet_part *p = &part[pos[c[k]]];
            p->id[p->n] = in->id[s], p->t0[p->n] = cut[k], p->t1[p->n] = cut[k + 1];
            p->n++;
        }
    return 1;
}

/* The rays of `in` through node (q, i, j)'s children, in the packet's order; a ray that
 * found its hit in one goes no further. */
static void children_packet(packet *pk, int q, int64_t i, int64_t j, const node_facts *f,
                            const double *box, const packet_part *in)
{
    int order[4], pos[4];
    children_order(pk->heading, order);
    for (int k = 0; k < 4; k++)
        pos[order[k]] = k;
    packet_part part[4]; /* only the counts need a start */
    for (int k = 0; k < 4; k++)
        part[k].n = 0;
    for (int s = 0; s < in->n; s++) {
        pray *r = &pk->r[in->id[s]];
        if (!split_ray(pk, box, in, s, pos, part)) /* on alone, as visit would */
            pk->hit[in->id[s]] = (unsigned char)visit_children(r, q, i, j, box, in->t0[s],
                                                               in->t1[s], f->lo, f->hi);
    }
    for (int k = 0; k < 4; k++) {
        packet_part *p = &part[k];
        int live = 0; /* those that found no hit in an earlier child */
        for (int s = 0; s < p->n; s++)
            if (!pk->hit[p->id[s]])
                p->id[live] = p->id[s], p->t0[live] = p->t0[s], p->t1[live++] = p->t1[s];
        p->n = live;
        if (!live)
            continue;
        int64_t ci = 2 * i + (order[k] & 1), cj = 2 * j + (order[k] >> 1);
        double cbox[4];
        node_box(&pk->r[p->id[0]], q + 1, ci, cj, cbox);
        visit_packet(pk, q + 1, ci, cj, facts_of(&pk->r[p->id[0]], q + 1, ci, cj, cbox, f->lo,
                                                 f->hi), p);
    }
}

/* Node (q, i, j), facts f, for the rays of `in` over their stretches. */
static void visit_packet(packet *pk, int q, int64_t i, int64_t j, node_facts f,
                         const packet_part *in)
{
    packet_part below;
    below.n = 0;
    for (int s = 0; s < in->n; s++)
        if (!passes_above(&pk->r[in->id[s]], &f, in->t0[s], in->t1[s])) {
            below.id[below.n] = in->id[s], below.t0[below.n] = in->t0[s];
            below.t1[below.n++] = in->t1[s];
        }
    if (!below.n)
        return;
    const pray *r = &pk->r[below.id[0]];
    double box[4];
    node_box(r, q, i, j, box);
    if (is_leaf(r, q, &f))
        march_packet(pk, q, i, j, &f, box, &below);
    else
        children_packet(pk, q, i, j, &f, box, &below);
}

/* Trace rays ids[0..n) (n <= PACKET_RAYS, one heading) of o, d, tmin, tmax as a packet; each
 * one's hit (and normal, with want_normal) in pk->r, found in pk->hit. */
static void trace_packet(packet *pk, const tf_procedural *p, const tf_proc_view *v, int n,
                         const int *ids, const tf_vec3 *o, const tf_vec3 *d, const double *tmin,
                         const double *tmax, int want_normal)
{
    packet_part root;
    root.n = 0;
    for (int s = 0; s < n; s++) {
        pray *r = &pk->r[s];
        *r = (pray){.p = p, .v = v, .o = o[ids[s]], .d = d[ids[s]], .want_normal = want_normal};
        pk->hit[s] = 0;
        double t0, t1;
        if (start_ray(r, tmin[ids[s]], tmax[ids[s]], &t0, &t1))
            root.id[root.n] = s, root.t0[root.n] = t0, root.t1[root.n++] = t1;
    }
    if (!root.n)
        return;
    double box[4];
    node_box(&pk->r[0], 0, 0, 0, box);
    visit_packet(pk, 0, 0, 0, facts_of(&pk->r[0], 0, 0, 0, box, 0, p->max_level), &root);
}

/* The rays in packets of one heading and at most PACKET_RAYS; want_normal: hits into hits[]
 * (camera rays), else occlusion only. */
static void trace_packets(const tf_procedural *p, const tf_proc_view *v, int n, const tf_vec3 *o,
                          const tf_vec3 *d, const double *tmin, const double *tmax,
                          unsigned char *found, tf_hit *hits)
{
    packet pk;
    int ids[PACKET_RAYS];
    for (int heading = 0; heading < 4; heading++) {
        pk.heading = heading;
        for (int k = 0, m = 0; k < n; k++) {
            if (heading_of(d[k]) == heading)
                ids[m++] = k;
            if (m < PACKET_RAYS && !(k == n - 1 && m > 0))
                continue;
            trace_packet(&pk, p, v, m, ids, o, d, tmin, tmax, hits != NULL);
            for (int s = 0; s < m; s++) {
                found[ids[s]] = pk.hit[s];
                if (hits && pk.hit[s])
                    hits[ids[s]] = hit_of(&pk.r[s]);
            }
            m = 0;
        }
    }
}

void tf_proc_trace_packet(const tf_procedural *p, const tf_proc_view *v, int n, const tf_vec3 *o,
                          const tf_vec3 *d, const double *tmin, const double *tmax,
                          unsigned char *found, tf_hit *hits)
{
    trace_packets(p, v, n, o, d, tmin, tmax, found, hits);
}

void tf_proc_occluded_packet(const tf_procedural *p, const tf_proc_view *v, int n,
                             const tf_vec3 *o, const tf_vec3 *d, const double *tmin,
                             const double *tmax, unsigned char *occluded)
{
    trace_packets(p, v, n, o, d, tmin, tmax, occluded, NULL);
}

double tf_proc_shadow_lift(const tf_procedural *p, const tf_proc_view *v, tf_vec3 p_hit)
{
    double dx = p_hit.x - v->eye.x, dy = p_hit.y - v->eye.y;
    int level = (int)tf_proc_lambda(p, v, dx * dx + dy * dy) + 1;
    return SHADOW_LIFT * tf_proc_spacing(p, level > p->max_level ? p->max_level : level);
}

