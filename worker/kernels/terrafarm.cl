/* terrafarm.cl: the C renderer (common/render.c, shade.c, camera.c, trace.c, noise.c) as
 * OpenCL C 1.2 kernels, in double precision (cl_khr_fp64), for worker/backend_opencl.c.
 *
 * The host prepends tf_cl_params.h (the P[] / I[] indices) to this file before building it.
 * Every function below is a line-by-line port of its C twin, same operations in the same order,
 * with FP contraction off, so a sample differs from the C backend's only where the device's
 * libm (exp, log, pow, acos, tan, sin, cos) rounds differently from glibc's -- a few ulps, which
 * rarely moves a subdivision decision (see tests/unit/test_opencl.c for the measured match).
 * When the C renderer changes, change the function of the same name here.
 *
 * This file is the scalar renderer: one sample at a time.  The host builds it followed by
 * packet.cl, packet_trace.cl, packet_shade.cl and packet_render.cl, which run it eight samples
 * at a time and hold the kernels the host launches (see packet_render.cl). */
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

#define TF_AA_MAX_DEPTH 6
#define TF_AA_PROBE_FRACTION 0.1 /* render_internal.h */
#define TF_SKY_DIST 1e30f
#define FAR_AWAY 1e30
#define DEG2RAD (3.14159265358979323846 / 180.0)
#define TF_NOISE_COORD_LIMIT 0x1p52
#define TF_NOISE2_SCALE 1.41421
#define TF_MAX_OCTAVES 32

/* shade.c constants: keep in step with common/shade.c */
#define ROCK_BLEND_DEG 6.0
#define SNOW_SLIDE_DEG 15.0
#define BUMP_OCTAVES 4.0
#define BUMP_H 0.8        /* host side: TFP_AMP_H08 */
#define SNOW_OCTAVES 5.0
#define RIPPLE_OCTAVES 3.0
#define RIPPLE_STRENGTH 0.06
#define COLOUR_VARIATION 0.15
#define FRESNEL_R0 0.02

/* ---------------------------------------------------------------- vectors (vec.h) */

typedef struct vec3 { double x, y, z; } vec3;

vec3 v3(double x, double y, double z) { vec3 r = {x, y, z}; return r; }
vec3 v3_add(vec3 a, vec3 b) { return v3(a.x + b.x, a.y + b.y, a.z + b.z); }
vec3 v3_sub(vec3 a, vec3 b) { return v3(a.x - b.x, a.y - b.y, a.z - b.z); }
vec3 v3_mul(vec3 a, vec3 b) { return v3(a.x * b.x, a.y * b.y, a.z * b.z); }
vec3 v3_scale(vec3 a, double s) { return v3(a.x * s, a.y * s, a.z * s); }
double v3_dot(vec3 a, vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
double v3_len(vec3 a) { return sqrt(v3_dot(a, a)); }
vec3 v3_norm(vec3 a)
{
    double l = v3_len(a);
    return l > 0 ? v3_scale(a, 1.0 / l) : a;
}
vec3 v3_lerp(vec3 a, vec3 b, double t)
{
    return v3(a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t, a.z + (b.z - a.z) * t);
}

/* ---------------------------------------------------------------- the world */

/* Everything a work-item reads, gathered once at kernel entry. */
typedef struct world {
    __global const double *P;
    __global const int *I;
    __global const float *h;      /* n * n heights */
    __global const float2 *mm;    /* (max, min) of every cell of every grid level, levels
                                   * concatenated (level L starts at I[TFI_LEVEL_OFFSET+L]) */
    __global const ushort *perm;  /* texture noise permutation, 512 entries */
    int n, cells, levels;
    double cell;
} world;

vec3 pvec(const world *w, int k) { return v3(w->P[k], w->P[k + 1], w->P[k + 2]); }

/* ---------------------------------------------------------------- hashing (noise.h) */

ulong tf_hash64(ulong x)
{
    x += 0x9e3779b97f4a7c15UL;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9UL;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebUL;
    return x ^ (x >> 31);
}
double tf_hash_unit(ulong x) { return (double)(tf_hash64(x) >> 11) * 0x1.0p-53; }

/* ---------------------------------------------------------------- noise (noise_impl.h) */

#define TF_C1 0.92387953251128674
#define TF_S1 0.38268343236508977
#define TF_H1 0.70710678118654752
__constant double tf_grad2[16][2] = {
    {1, 0},       {TF_C1, TF_S1},   {TF_H1, TF_H1},   {TF_S1, TF_C1},
    {0, 1},       {-TF_S1, TF_C1},  {-TF_H1, TF_H1},  {-TF_C1, TF_S1},
    {-1, 0},      {-TF_C1, -TF_S1}, {-TF_H1, -TF_H1}, {-TF_S1, -TF_C1},
    {0, -1},      {TF_S1, -TF_C1},  {TF_H1, -TF_H1},  {TF_C1, -TF_S1},
};

double tf_fade(double t) { return t * t * t * (t * (t * 6.0 - 15.0) + 10.0); }

long tf_floor_split(double x, double *fraction)
{
    long i = (long)x;
    double d = (double)i;
    int below = x < d;
    *fraction = x - (d - (below ? 1.0 : 0.0));
    return i - below;
}

typedef struct noise_axis { int lattice, ok; double f0, f1, fade; } noise_axis;

noise_axis noise_axis_set(double y)
{
    noise_axis a;
    double unused;
    a.ok = fabs(y) < TF_NOISE_COORD_LIMIT;
    long yi = a.ok ? tf_floor_split(y, &unused) : 0;
    a.lattice = (int)(yi & 255);
    a.f0 = a.ok ? y - (double)yi : 0.0;
    a.f1 = a.f0 - 1.0;
    a.fade = tf_fade(a.f0);
    return a;
}

/* column line slope * (x - X) + intercept (tf_noise_column_at) */
void noise_column(__global const ushort *p, long xi, const noise_axis *ay, double *slope,
                  double *intercept)
{
    int a = p[xi & 255] + ay->lattice;
    __constant const double *g0 = tf_grad2[p[a] & 15], *g1 = tf_grad2[p[a + 1] & 15];
    double e0 = g0[1] * ay->f0, e1 = g1[1] * ay->f1;
    *slope = g0[0] + ay->fade * (g1[0] - g0[0]);
    *intercept = e0 + ay->fade * (e1 - e0);
}

double noise2_axis(__global const ushort *p, double x, const noise_axis *ay)
{
    if (!(fabs(x) < TF_NOISE_COORD_LIMIT) || !ay->ok)
        return 0.0;
    double fx, ls, li, rs, ri;
    long xi = tf_floor_split(x, &fx);
    noise_column(p, xi, ay, &ls, &li);
    noise_column(p, xi + 1, ay, &rs, &ri);
    double u = tf_fade(fx);
    double l = ls * fx + li;
    double r = rs * (fx - 1.0) + ri;
    return (l + u * (r - l)) * TF_NOISE2_SCALE;
}

/* tf_fbm2 with lacunarity 2 (the only one the textures use): the octave plan
 * (tf_octaves_plan), the y axes (tf_octave_axes) and the sum (tf_fbm2_axes) fused into one
 * loop; the same values meet in the same operations.  amp[] is the host's table of
 * pow(2^i, -H) (TFP_AMP_*), so no pow runs on the device. */
double tf_fbm2(__global const ushort *p, __global const double *amp, double x, double y,
               double octaves)
{
    if (!(octaves >= 1.0))
        octaves = 1.0;
    if (octaves > TF_CL_AMP_TABLE - 1)
        octaves = TF_CL_AMP_TABLE - 1;
    int whole = (int)octaves;
    double remainder = octaves - whole;
    int count = whole + (remainder > 0.0);
    double result = 0.0;
    for (int i = 0; i < count; i++) {
        double a = amp[i];
        if (remainder > 0.0 && i == whole)
            a *= remainder;
        noise_axis ay = noise_axis_set(y);
        result += a * noise2_axis(p, x, &ay);
        x *= 2.0;
        y *= 2.0;
    }
    return result;
}

/* ---------------------------------------------------------------- camera (camera.c) */

vec3 camera_dir(const world *w, double x, double y)
{
    double u = x / (double)w->I[TFI_WIDTH] - 0.5;
    double v = 0.5 - y / (double)w->I[TFI_HEIGHT];
    if (w->I[TFI_CAM_KIND] == 1) {
        double theta = u * w->P[TFP_SWEEP];
        vec3 horizontal = v3_add(v3_scale(pvec(w, TFP_PANO_FORWARD), cos(theta)),
                                 v3_scale(pvec(w, TFP_PANO_RIGHT), sin(theta)));
        double height = w->P[TFP_V_CENTRE] + 2.0 * v * w->P[TFP_V_HALF];
        return v3_norm(v3_add(horizontal, v3_scale(pvec(w, TFP_PANO_UP), height)));
    }
    vec3 d = v3_add(pvec(w, TFP_CAM_FORWARD),
                    v3_scale(pvec(w, TFP_CAM_RIGHT), 2.0 * u * w->P[TFP_HALF_W]));
    d = v3_add(d, v3_scale(pvec(w, TFP_CAM_UP), 2.0 * v * w->P[TFP_HALF_H]));
    return v3_norm(d);
}

/* ---------------------------------------------------------------- tracing (trace.c) */

typedef struct candidate { double t; int ci, cj, tri; } candidate;
typedef struct sheared { double x, y, z; } sheared;

typedef struct ray_ctx {
    double o[3], d[3];
    double inv_dx, inv_dy;
    int sx, sy;
    double tmin, tmax, t0, t1, margin, tie_tol;
    int ci, cj, kx, ky, kz;
    double shx, shy, shz;
} ray_ctx;

typedef struct hit_t { double t; vec3 p, n; int ci, cj; } hit_t;

double xcross(const world *w, const ray_ctx *r, int X)
{
    return ((double)X * w->cell - r->o[0]) * r->inv_dx;
}
double ycross(const world *w, const ray_ctx *r, int Y)
{
    return ((double)Y * w->cell - r->o[1]) * r->inv_dy;
}

sheared shear_vertex(const world *w, const ray_ctx *r, int i, int j)
{
    double a[3] = {(double)i * w->cell - r->o[0], (double)j * w->cell - r->o[1],
                   (double)w->h[(size_t)j * (size_t)w->n + (size_t)i] - r->o[2]};
    sheared s = {a[r->kx] - r->shx * a[r->kz], a[r->ky] - r->shy * a[r->kz], r->shz * a[r->kz]};
    return s;
}

double edge_fn(sheared p, sheared q)
{
    double a = p.x * q.y, b = p.y * q.x, e = a - b;
    if (fabs(e) <= 8 * DBL_EPSILON * (fabs(a) + fabs(b)))
        return 0;
    return e;
}

void try_triangle(const ray_ctx *r, double u, double v, double w, double za, double zb,
                  double zc, int ci, int cj, int tri, candidate *best)
{
    if ((u < 0 || v < 0 || w < 0) && (u > 0 || v > 0 || w > 0))
        return;
    double det = u + v + w;
    if (det == 0)
        return;
    double t = (u * za + v * zb + w * zc) / det;
    if (t > r->tmin && t < r->tmax && t < best->t) {
        best->t = t;
        best->ci = ci;
        best->cj = cj;
        best->tri = tri;
    }
}

void test_triangles(const world *w, const ray_ctx *r, int ci, int cj, candidate *best)
{
    sheared a = shear_vertex(w, r, ci, cj), b = shear_vertex(w, r, ci + 1, cj);
    sheared c = shear_vertex(w, r, ci + 1, cj + 1), d = shear_vertex(w, r, ci, cj + 1);
    double e_ab = edge_fn(a, b), e_bc = edge_fn(b, c), e_ca = edge_fn(c, a);
    double e_cd = edge_fn(c, d), e_da = edge_fn(d, a);
    try_triangle(r, e_bc, e_ca, e_ab, a.z, b.z, c.z, ci, cj, 0, best);
    try_triangle(r, e_cd, e_da, -e_ca, a.z, c.z, d.z, ci, cj, 1, best);
}

void test_if_inside(const world *w, const ray_ctx *r, int ci, int cj, candidate *best)
{
    if ((uint)ci < (uint)w->cells && (uint)cj < (uint)w->cells)
        test_triangles(w, r, ci, cj, best);
}

int test_cell(const world *w, const ray_ctx *r, int ci, int cj, double tx, double ty,
              candidate *best)
{
    test_triangles(w, r, ci, cj, best);
    if (r->sx && r->sy) {
        if (fabs(tx - ty) <= r->tie_tol) {
            test_if_inside(w, r, ci + r->sx, cj, best);
            test_if_inside(w, r, ci, cj + r->sy, best);
        }
        double tx_in = xcross(w, r, ci + (r->sx < 0)), ty_in = ycross(w, r, cj + (r->sy < 0));
        if (fabs(tx_in - ty_in) <= r->tie_tol) {
            test_if_inside(w, r, ci - r->sx, cj, best);
            test_if_inside(w, r, ci, cj - r->sy, best);
        }
    }
    return best->t < INFINITY;
}

int cell_of(const world *w, double v)
{
    double g = v / w->cell;
    int i = g > 0 ? (g < w->cells ? (int)g : w->cells - 1) : 0;
    while (i > 0 && (double)i * w->cell > v)
        i--;
    while (i < w->cells - 1 && (double)(i + 1) * w->cell <= v)
        i++;
    return i;
}

int clip_slab(double o, double d, double lo, double hi, double *t0, double *t1)
{
    if (d == 0)
        return o >= lo && o <= hi;
    double ta = (lo - o) / d, tb = (hi - o) / d;
    if (ta > tb) {
        double s = ta;
        ta = tb;
        tb = s;
    }
    if (ta > *t0)
        *t0 = ta;
    if (tb < *t1)
        *t1 = tb;
    return *t0 <= *t1;
}

double safe_inverse(double v)
{
    double inv = 1.0 / v;
    return isinf(inv) ? copysign(DBL_MAX, v) : inv;
}

int setup_ray(ray_ctx *r, const world *w, vec3 o, vec3 d, double tmin, double tmax)
{
    if (!isfinite(o.x) || !isfinite(o.y) || !isfinite(o.z) || !isfinite(d.x) ||
        !isfinite(d.y) || !isfinite(d.z) || (d.x == 0 && d.y == 0 && d.z == 0) || !(tmin < tmax))
        return 0;
    r->o[0] = o.x, r->o[1] = o.y, r->o[2] = o.z;
    r->d[0] = d.x, r->d[1] = d.y, r->d[2] = d.z;
    r->tmin = tmin;
    r->tmax = tmax;

    const double top = (double)w->cells * w->cell;
    const double hmin = w->P[TFP_HMIN], hmax = w->P[TFP_HMAX];
    const double zpad = 1e-9 * (fabs(hmin) + fabs(hmax) + fabs(o.z) + (hmax - hmin)) + DBL_MIN;
    double t0 = tmin, t1 = tmax;
    if (!clip_slab(o.x, d.x, 0, top, &t0, &t1) || !clip_slab(o.y, d.y, 0, top, &t0, &t1) ||
        !clip_slab(o.z, d.z, hmin - zpad, hmax + zpad, &t0, &t1) || !isfinite(t0) ||
        !isfinite(t1))
        return 0;
    r->t0 = t0;
    r->t1 = t1;

    r->sx = d.x > 0 ? 1 : d.x < 0 ? -1 : 0;
    r->sy = d.y > 0 ? 1 : d.y < 0 ? -1 : 0;
    r->inv_dx = r->sx ? safe_inverse(d.x) : 0;
    r->inv_dy = r->sy ? safe_inverse(d.y) : 0;
    r->ci = cell_of(w, o.x + t0 * d.x);
    r->cj = cell_of(w, o.y + t0 * d.y);

    double tie = 0;
    if (r->sx)
        tie += (top + fabs(o.x)) * fabs(r->inv_dx);
    if (r->sy)
        tie += (top + fabs(o.y)) * fabs(r->inv_dy);
    tie *= 1e-12;
    double tabs = fabs(t0) > fabs(t1) ? fabs(t0) : fabs(t1);
    double hscale = fabs(hmin) > fabs(hmax) ? fabs(hmin) : fabs(hmax);
    double slope = (hmax - hmin) / w->cell;
    double margin = 1e-9 * (fabs(o.z) + fabs(d.z) * tabs + hscale + (hmax - hmin)) +
                    2 * tie * (fabs(d.z) + 2 * slope * (fabs(d.x) + fabs(d.y)));
    r->tie_tol = isfinite(tie) ? tie : INFINITY;
    r->margin = isfinite(margin) ? margin : INFINITY;

    double ax = fabs(d.x), ay = fabs(d.y), az = fabs(d.z);
    r->kz = ax >= ay ? (ax >= az ? 0 : 2) : (ay >= az ? 1 : 2);
    r->kx = (r->kz + 1) % 3;
    r->ky = (r->kx + 1) % 3;
    r->shx = r->d[r->kx] / r->d[r->kz];
    r->shy = r->d[r->ky] / r->d[r->kz];
    r->shz = 1.0 / r->d[r->kz];
    return 1;
}

int culled(double z_in, double z_out, float hi, float lo, double margin)
{
    double zlo = z_in < z_out ? z_in : z_out;
    if (zlo > hi + margin)
        return 1;
    double zhi = z_in < z_out ? z_out : z_in;
    return zhi < lo - margin;
}

void finish_hit(const world *w, const ray_ctx *r, const candidate *c, hit_t *hit)
{
    __global const float *h = w->h + (size_t)c->cj * (size_t)w->n + (size_t)c->ci;
    double ha = h[0], hb = h[1], hd = h[w->n], hc = h[w->n + 1];
    vec3 n = c->tri == 0 ? v3(-(hb - ha), -(hc - hb), w->cell) : v3(-(hc - hd), -(hd - ha), w->cell);
    hit->t = c->t;
    hit->p = v3(r->o[0] + c->t * r->d[0], r->o[1] + c->t * r->d[1], r->o[2] + c->t * r->d[2]);
    hit->n = v3_norm(n);
    hit->ci = c->ci;
    hit->cj = c->cj;
}

double entry_t(const world *w, const ray_ctx *r, int axis, int s, int j)
{
    return axis == 0 ? xcross(w, r, j + (s < 0)) : ycross(w, r, j + (s < 0));
}

int entered(const world *w, const ray_ctx *r, int axis, int s, int j, double t_event, int strict)
{
    double t = entry_t(w, r, axis, s, j);
    return strict ? t < t_event : t <= t_event;
}

int fix_stale_axis(const world *w, const ray_ctx *r, int axis, int stale, int level,
                   double t_event, int strict)
{
    const int s = axis == 0 ? r->sx : r->sy;
    const int lo = (stale >> level) << level, hi = lo + (1 << level) - 1;
    const double o = r->o[axis], dd = r->d[axis];
    double g = (o + t_event * dd) / w->cell;
    int j = g > lo ? (g < hi ? (int)g : hi) : lo;
    if (s > 0) {
        if (j < stale)
            j = stale;
        while (j > stale && !entered(w, r, axis, s, j, t_event, strict))
            j--;
        while (j < hi && entered(w, r, axis, s, j + 1, t_event, strict))
            j++;
    } else {
        if (j > stale)
            j = stale;
        while (j < stale && !entered(w, r, axis, s, j, t_event, strict))
            j++;
        while (j > lo && entered(w, r, axis, s, j - 1, t_event, strict))
            j--;
    }
    return j;
}

#define STALE_NONE 0
#define STALE_X 1
#define STALE_Y 2

int walk_hier(const world *w, const ray_ctx *r, candidate *best)
{
    const int cells = w->cells, top = w->levels - 1;
    const double oz = r->o[2], dz = r->d[2], t1 = r->t1;
    int ci = r->ci, cj = r->cj;
    int stale = STALE_NONE;
    double t_cur = r->t0, t_event = r->t0;
    /* trace.c (b19dfb3): a ray starting at or under the surface of its level-1 block (shadow
     * rays, valley cameras) starts at level 0; same hits, fewer steps. */
    int level = top;
    if (top > 0) {
        const double z0 = oz + t_cur * dz;
        const size_t i1 = (size_t)w->I[TFI_LEVEL_OFFSET + 1] +
                          (size_t)(cj >> 1) * (size_t)(cells >> 1) + (size_t)(ci >> 1);
        if (z0 <= w->mm[i1].x + r->margin && z0 >= w->mm[i1].y - r->margin)
            level = 0;
    }
    for (;;) {
        const int bi = ci >> level, bj = cj >> level;
        double tx = r->sx ? xcross(w, r, (bi + (r->sx > 0)) << level) : INFINITY;
        double ty = r->sy ? ycross(w, r, (bj + (r->sy > 0)) << level) : INFINITY;
        double tc = tx <= ty ? tx : ty;
        double t_out = tc < t1 ? tc : t1;
        if (t_out < t_cur)
            t_out = t_cur;
        size_t idx = (size_t)w->I[TFI_LEVEL_OFFSET + level] +
                     (size_t)bj * (size_t)(cells >> level) + (size_t)bi;
        if (!culled(oz + t_cur * dz, oz + t_out * dz, w->mm[idx].x, w->mm[idx].y, r->margin)) {
            if (level == 0) {
                if (test_cell(w, r, ci, cj, tx, ty, best))
                    return 1;
            } else {
                if (stale == STALE_Y)
                    cj = fix_stale_axis(w, r, 1, cj, level, t_event, 1);
                else if (stale == STALE_X)
                    ci = fix_stale_axis(w, r, 0, ci, level, t_event, 0);
                stale = STALE_NONE;
                level--;
                continue;
            }
        }
        if (!(tc < t1))
            return 0;
        t_cur = t_out;
        t_event = tc;
        int boundary;
        if (tx <= ty) {
            boundary = bi + (r->sx > 0);
            ci = r->sx > 0 ? boundary << level : (boundary << level) - 1;
            if ((uint)ci >= (uint)cells)
                return 0;
            stale = level > 0 && r->sy ? STALE_Y : STALE_NONE;
        } else {
            boundary = bj + (r->sy > 0);
            cj = r->sy > 0 ? boundary << level : (boundary << level) - 1;
            if ((uint)cj >= (uint)cells)
                return 0;
            stale = level > 0 && r->sx ? STALE_X : STALE_NONE;
        }
        /* climb one level per step, as trace.c does (db8307b) */
        if (level < top && !(boundary & 1))
            level++;
    }
}

int trace(const world *w, vec3 origin, vec3 dir, double tmin, double tmax, hit_t *hit)
{
    ray_ctx r;
    candidate best = {INFINITY, 0, 0, 0};
    if (!setup_ray(&r, w, origin, dir, tmin, tmax) || !walk_hier(w, &r, &best))
        return 0;
    finish_hit(w, &r, &best, hit);
    return 1;
}

int occluded(const world *w, vec3 origin, vec3 dir, double tmin, double tmax)
{
    ray_ctx r;
    candidate best = {INFINITY, 0, 0, 0};
    return setup_ray(&r, w, origin, dir, tmin, tmax) && walk_hier(w, &r, &best);
}

/* ---------------------------------------------------------------- shading (shade.c) */

double smoothstep_(double e0, double e1, double x)
{
    double t = (x - e0) / (e1 - e0);
    t = t < 0 ? 0 : t > 1 ? 1 : t;
    return t * t * (3.0 - 2.0 * t);
}

double visible_octaves(const world *w, double scale, double dist, double max_octaves)
{
    double footprint = 2.0 * dist * w->P[TFP_PIXEL_ANGLE];
    if (!(footprint > 0))
        return max_octaves;
    double octaves = log2(scale / footprint) + 1.0;
    return octaves < 0 ? 0 : octaves > max_octaves ? max_octaves : octaves;
}

double height_sample(const world *w, int i, int j)
{
    i = i < 0 ? 0 : i >= w->n ? w->n - 1 : i;
    j = j < 0 ? 0 : j >= w->n ? w->n - 1 : j;
    return w->h[(size_t)j * (size_t)w->n + (size_t)i];
}

vec3 vertex_normal(const world *w, int i, int j)
{
    double span_x = (double)((i + 1 < w->n ? i + 1 : i) - (i > 0 ? i - 1 : i)) * w->cell;
    double span_y = (double)((j + 1 < w->n ? j + 1 : j) - (j > 0 ? j - 1 : j)) * w->cell;
    double dzdx = (height_sample(w, i + 1, j) - height_sample(w, i - 1, j)) / span_x;
    double dzdy = (height_sample(w, i, j + 1) - height_sample(w, i, j - 1)) / span_y;
    return v3_norm(v3(-dzdx, -dzdy, 1.0));
}

vec3 smooth_normal(const world *w, int ci, int cj, vec3 p)
{
    ci = ci < 0 ? 0 : ci >= w->cells ? w->cells - 1 : ci;
    cj = cj < 0 ? 0 : cj >= w->cells ? w->cells - 1 : cj;
    double fx = p.x / w->cell - ci, fy = p.y / w->cell - cj;
    fx = fx < 0 ? 0 : fx > 1 ? 1 : fx;
    fy = fy < 0 ? 0 : fy > 1 ? 1 : fy;
    vec3 n00 = vertex_normal(w, ci, cj), n11 = vertex_normal(w, ci + 1, cj + 1);
    vec3 n;
    if (fx >= fy) {
        vec3 n10 = vertex_normal(w, ci + 1, cj);
        n = v3_add(v3_add(v3_scale(n00, 1 - fx), v3_scale(n10, fx - fy)), v3_scale(n11, fy));
    } else {
        vec3 n01 = vertex_normal(w, ci, cj + 1);
        n = v3_add(v3_add(v3_scale(n00, 1 - fy), v3_scale(n01, fy - fx)), v3_scale(n11, fx));
    }
    return v3_norm(n);
}

/* shade.c's fbm_with_gradient: the value and the x-offset sum share their y axes (computed
 * once per octave here), the y-offset sum has its own; each sum accumulates in the C order, so
 * the bits are tf_fbm2's.  amp_table: TFP_AMP_H08 or TFP_AMP_H05, the H of the C call. */
double fbm_with_gradient(const world *w, double x, double y, double scale, int amp_table,
                         double octaves, double salt, double *gx, double *gy)
{
    const double eps = 1e-3;
    __global const double *amp = w->P + amp_table;
    double qx = x / scale + salt, qy = y / scale - salt;
    if (!(octaves >= 1.0))
        octaves = 1.0;
    if (octaves > TF_CL_AMP_TABLE - 1)
        octaves = TF_CL_AMP_TABLE - 1;
    int whole = (int)octaves;
    double remainder = octaves - whole;
    int count = whole + (remainder > 0.0);
    double f = 0.0, fx = 0.0, fy = 0.0;
    double x0 = qx, x1 = qx + eps, y0 = qy, y1 = qy + eps;
    for (int i = 0; i < count; i++) {
        double a = amp[i];
        if (remainder > 0.0 && i == whole)
            a *= remainder;
        noise_axis ay = noise_axis_set(y0), ay1 = noise_axis_set(y1);
        f += a * noise2_axis(w->perm, x0, &ay);
        fx += a * noise2_axis(w->perm, x1, &ay);
        fy += a * noise2_axis(w->perm, x0, &ay1);
        x0 *= 2.0;
        x1 *= 2.0;
        y0 *= 2.0;
        y1 *= 2.0;
    }
    *gx = (fx - f) / eps;
    *gy = (fy - f) / eps;
    return f;
}

/* shade.c's snow_line_matters: outside [line - reach, line + reach] the snow weight is 0 or 1
 * whatever the fBm, so the fBm is skipped (same bits).  TFP_SNOW_BOUND: the host's bound. */
int snow_line_matters(const world *w, double z)
{
    double reach = w->P[TFP_SNOW_JITTER] * w->P[TFP_SNOW_BOUND] + w->P[TFP_BAND];
    double lo = w->P[TFP_SNOW_LINE] - reach, hi = w->P[TFP_SNOW_LINE] + reach;
    double slack = 1e-9 * (fabs(lo) + fabs(hi) + reach);
    return z >= lo - slack && z <= hi + slack;
}

vec3 sky_color(const world *w, vec3 dir)
{
    double up = dir.z > 0 ? dir.z : 0;
    double wt = 1.0 - (1.0 - up) * (1.0 - up) * (1.0 - up);
    vec3 c = v3_lerp(pvec(w, TFP_SKY_HORIZON), pvec(w, TFP_SKY_ZENITH), wt);
    double cg = v3_dot(dir, pvec(w, TFP_SUN_DIR));
    if (cg > 0) {
        double c2 = cg * cg, c4 = c2 * c2, c8 = c4 * c4, c16 = c8 * c8, c32 = c16 * c16;
        double c64 = c32 * c32, c256 = c64 * c64 * c64 * c64;
        double glow = 0.03 * c8 + 0.08 * c64 + 0.25 * c256;
        c = v3_add(c, v3_scale(pvec(w, TFP_SUN_LIGHT), glow));
    }
    return c;
}

double mist_depth_exp(double density, double k, double z1, double z2, double len)
{
    if (k == 0)
        return density * len;
    double x = k * fabs(z2 - z1);
    double mean_density;
    if (x < 1e-5)
        mean_density = exp(-k * 0.5 * (z1 + z2));
    else
        mean_density = exp(-k * fmin(z1, z2)) * (-expm1(-x) / x);
    return density * len * mean_density;
}

double mist_depth(const world *w, vec3 origin, vec3 dir, double len)
{
    double density = w->P[TFP_MIST_DENSITY], k = w->P[TFP_MIST_K];
    if (w->I[TFI_MIST_HOMOG] || k == 0)
        return isinf(len) ? INFINITY : density * len;
    if (!isinf(len))
        return mist_depth_exp(density, k, origin.z, origin.z + dir.z * len, len);
    if (dir.z <= 1e-12)
        return INFINITY;
    return density * exp(-k * origin.z) / (k * dir.z);
}

double transparency(double tau, double extinction)
{
    if (extinction <= 0)
        return 1.0;
    return exp(-tau * extinction);
}

vec3 mist_apply(const world *w, vec3 c, vec3 origin, vec3 dir, double len)
{
    if (!w->I[TFI_MIST_ENABLED] || w->P[TFP_MIST_DENSITY] <= 0)
        return c;
    double tau = mist_depth(w, origin, dir, len);
    vec3 ext = pvec(w, TFP_MIST_EXT), mc = pvec(w, TFP_MIST_COLOR);
    double sr = transparency(tau, ext.x);
    double sg = transparency(tau, ext.y);
    double sb = transparency(tau, ext.z);
    return v3(sr * c.x + (1 - sr) * mc.x, sg * c.y + (1 - sg) * mc.y, sb * c.z + (1 - sb) * mc.z);
}

int sunlit(const world *w, vec3 p, vec3 ng, uint *shadow_rays)
{
    vec3 sun = pvec(w, TFP_SUN_DIR);
    if (v3_dot(ng, sun) <= 0 || sun.z <= -1.0)
        return 0;
    vec3 start = v3_add(p, v3_scale(ng, w->P[TFP_SHADOW_LIFT]));
    (*shadow_rays)++;
    return !occluded(w, start, sun, 0.0, FAR_AWAY);
}

vec3 terrain_albedo(const world *w, vec3 p, vec3 n, double variation)
{
    const vec3 ALBEDO_VEGETATION = {0.040, 0.075, 0.022};
    const vec3 ALBEDO_ALPINE = {0.120, 0.105, 0.070};
    const vec3 ALBEDO_ROCK = {0.200, 0.180, 0.160};
    const vec3 ALBEDO_SNOW = {0.800, 0.820, 0.860};
    const vec3 ALBEDO_SAND = {0.330, 0.290, 0.200};
    double slope = acos(n.z > 1 ? 1 : n.z) / DEG2RAD;
    double rock_deg = w->P[TFP_ROCK_SLOPE];
    double band = w->P[TFP_BAND];
    double tree_line = w->P[TFP_TREE_LINE], sea_level = w->P[TFP_SEA_LEVEL];
    double extent = w->P[TFP_EXTENT];

    double w_veg = smoothstep_(tree_line + band, tree_line - band, p.z);
    double w_sand = smoothstep_(sea_level + 0.8 * band, sea_level + 0.2 * band, p.z);
    double w_rock = smoothstep_(rock_deg - ROCK_BLEND_DEG, rock_deg + ROCK_BLEND_DEG, slope);
    double snow_line = w->P[TFP_SNOW_LINE];
    if (w->P[TFP_SNOW_JITTER] > 0 && snow_line_matters(w, p.z))
        snow_line += w->P[TFP_SNOW_JITTER] *
                     tf_fbm2(w->perm, w->P + TFP_AMP_H05, p.x / (extent / 12.0) + 37.5,
                             p.y / (extent / 12.0) - 11.25, SNOW_OCTAVES);
    double w_snow = smoothstep_(snow_line - band, snow_line + band, p.z) *
                    (1.0 - smoothstep_(rock_deg, rock_deg + SNOW_SLIDE_DEG, slope));

    vec3 c = v3_lerp(ALBEDO_ALPINE, ALBEDO_VEGETATION, w_veg);
    c = v3_lerp(c, ALBEDO_SAND, w_sand);
    c = v3_lerp(c, ALBEDO_ROCK, w_rock);
    c = v3_scale(c, 1.0 + COLOUR_VARIATION * variation);
    return v3_lerp(c, ALBEDO_SNOW, w_snow);
}

vec3 shade_terrain(const world *w, const hit_t *hit, uint *shadow_rays)
{
    vec3 n = smooth_normal(w, hit->ci, hit->cj, hit->p);
    vec3 nb = n;
    double variation = 0;
    double octaves = visible_octaves(w, w->P[TFP_BUMP_SCALE], hit->t, BUMP_OCTAVES);
    if (w->I[TFI_TEXTURED] && w->P[TFP_BUMP] > 0 && octaves > 0) {
        double gx, gy;
        variation = fbm_with_gradient(w, hit->p.x, hit->p.y, w->P[TFP_BUMP_SCALE], TFP_AMP_H08,
                                      octaves, 0.0, &gx, &gy);
        double amp = w->P[TFP_BUMP];
        nb = v3_norm(v3_add(n, v3(-amp * gx, -amp * gy, 0.0)));
        if (nb.z < 0.05)
            nb = n;
    }
    vec3 albedo = terrain_albedo(w, hit->p, n, variation);
    double cos_sun = v3_dot(nb, pvec(w, TFP_SUN_DIR));
    vec3 light = v3_scale(pvec(w, TFP_SKY_LIGHT), 0.5 + 0.5 * nb.z);
    if (cos_sun > 0 && sunlit(w, hit->p, hit->n, shadow_rays))
        light = v3_add(light, v3_scale(pvec(w, TFP_SUN_LIGHT), cos_sun));
    return v3_mul(albedo, light);
}

vec3 shade_water(const world *w, vec3 p, vec3 dir, double dist, uint *shadow_rays)
{
    const vec3 WATER_BODY = {0.010, 0.028, 0.040};
    vec3 n = v3(0, 0, 1);
    double octaves = visible_octaves(w, w->P[TFP_RIPPLE_SCALE], dist, RIPPLE_OCTAVES);
    if (w->I[TFI_TEXTURED] && w->P[TFP_BUMP] > 0 && octaves > 0) {
        double gx, gy;
        fbm_with_gradient(w, p.x, p.y, w->P[TFP_RIPPLE_SCALE], TFP_AMP_H05, octaves, 71.0, &gx, &gy);
        n = v3_norm(v3(-RIPPLE_STRENGTH * gx, -RIPPLE_STRENGTH * gy, 1.0));
    }
    double cos_i = -v3_dot(dir, n);
    if (cos_i < 1e-3)
        cos_i = 1e-3;
    vec3 refl = v3_add(dir, v3_scale(n, 2.0 * cos_i));
    if (refl.z < 0)
        refl.z = -refl.z;
    double m = 1.0 - cos_i, m2 = m * m;
    double fresnel = FRESNEL_R0 + (1.0 - FRESNEL_R0) * m2 * m2 * m;
    vec3 light = pvec(w, TFP_SKY_LIGHT);
    vec3 sun = pvec(w, TFP_SUN_DIR);
    if (sun.z > 0 && sunlit(w, p, v3(0, 0, 1), shadow_rays))
        light = v3_add(light, v3_scale(pvec(w, TFP_SUN_LIGHT), sun.z));
    vec3 body = v3_mul(WATER_BODY, light);
    return v3_lerp(body, sky_color(w, v3_norm(refl)), fresnel);
}

/* tf_shade_ray: writes r, g, b, a, dist to out[0..4]. */
void shade_ray(const world *w, vec3 origin, vec3 dir, float *out, uint *shadow_rays)
{
    double sea = w->P[TFP_SEA_LEVEL];
    double t_water = FAR_AWAY;
    if (dir.z < 0 && origin.z > sea)
        t_water = (sea - origin.z) / dir.z;

    hit_t hit;
    vec3 c;
    double dist;
    if (trace(w, origin, dir, 0.0, t_water, &hit)) {
        dist = hit.t;
        c = shade_terrain(w, &hit, shadow_rays);
    } else if (t_water < FAR_AWAY) {
        dist = t_water;
        c = shade_water(w, v3_add(origin, v3_scale(dir, t_water)), dir, t_water, shadow_rays);
    } else {
        c = mist_apply(w, sky_color(w, dir), origin, dir, INFINITY);
        out[0] = (float)c.x, out[1] = (float)c.y, out[2] = (float)c.z, out[3] = 0.0f;
        out[4] = TF_SKY_DIST;
        return;
    }
    c = mist_apply(w, c, origin, dir, dist);
    out[0] = (float)c.x, out[1] = (float)c.y, out[2] = (float)c.z, out[3] = 1.0f;
    out[4] = (float)dist;
}

/* ---------------------------------------------------------------- the lattice (render.c) */

void lattice_sample(const world *w, ulong jitter_key, long X, long Y, float *out,
                    uint *shadow_rays)
{
    ulong h = tf_hash64(jitter_key ^ (ulong)X);
    h = tf_hash64(h ^ ((ulong)Y * 0x9e3779b97f4a7c15UL));
    double jx = tf_hash_unit(h) - 0.5;
    double jy = tf_hash_unit(h ^ 0xd1b54a32d192ed03UL) - 0.5;
    double N = (double)w->I[TFI_LATTICE];
    double x = ((double)X + jx) / N;
    double y = ((double)Y + jy) / N;
    vec3 dir = camera_dir(w, x, y);
    shade_ray(w, pvec(w, TFP_CAM_POS), dir, out, shadow_rays);
}

world make_world(__global const double *P, __global const int *I, __global const float *h,
                 __global const float2 *mm,
                 __global const ushort *perm)
{
    world w;
    w.P = P;
    w.I = I;
    w.h = h;
    w.mm = mm;
    w.perm = perm;
    w.n = I[TFI_N];
    w.cells = I[TFI_CELLS];
    w.levels = I[TFI_LEVELS];
    w.cell = P[TFP_CELL];
    return w;
}
