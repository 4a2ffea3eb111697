/* painttree.c: Raypaint's quad-tree and its queue (painttree.h). */
#include "coordinator/paint/painttree.h"

#include <assert.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "coordinator/paint/paint_raster.h"
#include "image/preview.h"

/* A cell waiting: its square, whether its corners are known (roots' are not), its contrast
 * and its key in the queue. */
typedef struct cell {
    int x, y, s, corners_known;
    float contrast;
    double key;
    int fine;      /* a leaf-sized cell whose lattice at the fine stride is known */
} cell;

struct tf_paint_tree {
    int w, h;
    tf_paint_params p;
    tf_rect interest;
    cell *heap;
    size_t n, cap;
    float *level;       /* (w+1) x (h+1) corners: display levels, 3 a corner */
    uint8_t *srgb;      /* the same corners as the page sees them */
    tf_pixel *px;       /* w x h: the exact pixels */
    int64_t exact_pixels, samples, queued_pixels, out_pixels, roots_left;
};

void tf_paint_params_default(tf_paint_params *p)
{
    *p = (tf_paint_params){64, 2, 16, 16384, 2}; /* bench/README.md section 11 */
}

static int pow2(int v) { return v > 0 && (v & (v - 1)) == 0; }

const char *tf_paint_params_problem(const tf_paint_params *p)
{
    if (!pow2(p->root) || p->root > TF_PAINT_MAX_SIZE)
        return "the root side must be a power of two up to 1024";
    if (!pow2(p->leaf) || p->leaf > p->root)
        return "the exact side must be a power of two no larger than the root";
    if (p->levels < 1 || p->levels > 10)
        return "levels per task must be 1 to 10";
    if (p->task_rays < 1 || p->task_rays > 1 << 24)
        return "rays per task must be 1 to 16777216";
    if (!pow2(p->fine) || p->fine > p->leaf)
        return "the fine stride must be a power of two no larger than the exact side";
    return NULL;
}

int tf_paint_bytes_add(tf_paint_bytes *b, const void *data, size_t n)
{
    if (n == 0)
        return 0;
    if (b->len + n > b->cap) {
        size_t cap = b->cap ? b->cap : 4096;
        while (cap < b->len + n)
            cap *= 2;
        uint8_t *p = realloc(b->p, cap);
        if (!p)
            return -1;
        b->p = p;
        b->cap = cap;
    }
    memcpy(b->p + b->len, data, n);
    b->len += n;
    return 0;
}

void tf_paint_bytes_free(tf_paint_bytes *b)
{
    free(b->p);
    *b = (tf_paint_bytes){0};
}

/* ---- the queue: a max-heap of cells on key ---- */

static int64_t cell_pixels(const tf_paint_tree *t, int x, int y, int s)
{
    int64_t pw = (x + s < t->w ? x + s : t->w) - x, ph = (y + s < t->h ? y + s : t->h) - y;
    return pw * ph;
}

static int meets_interest(const tf_paint_tree *t, const cell *c)
{
    const tf_rect *a = &t->interest;
    return a->w > 0 && c->x < a->x + a->w && a->x < c->x + c->s && c->y < a->y + a->h &&
           a->y < c->y + c->s;
}

static tf_paint_node node_of(const tf_paint_tree *t, const cell *c, int64_t *rays);

/* Roots first, then the area of interest, then what a ray buys: contrast times area over the
 * rays the cell's next node costs (painttree.h), so the cheap passes that sharpen the most
 * come before the exact ones that only settle what is already nearly right. */
static double key_of(const tf_paint_tree *t, const cell *c)
{
    double tier = !c->corners_known ? 2 : meets_interest(t, c) ? 1 : 0;
    int64_t rays;
    node_of(t, c, &rays);
    double area = (double)c->s * (double)c->s;
    return tier * 1e13 + ((double)c->contrast + 1.0 / 64) * area / (double)(rays > 0 ? rays : 1);
}

static void sift_up(cell *h, size_t i)
{
    while (i > 0 && h[(i - 1) / 2].key < h[i].key) {
        cell tmp = h[i];
        h[i] = h[(i - 1) / 2];
        h[(i - 1) / 2] = tmp;
        i = (i - 1) / 2;
    }
}

static void sift_down(cell *h, size_t n, size_t i)
{
    for (;;) {
        size_t l = 2 * i + 1, r = l + 1, m = i;
        if (l < n && h[l].key > h[m].key)
            m = l;
        if (r < n && h[r].key > h[m].key)
            m = r;
        if (m == i)
            return;
        cell tmp = h[i];
        h[i] = h[m];
        h[m] = tmp;
        i = m;
    }
}

static int push(tf_paint_tree *t, cell c)
{
    if (t->n == t->cap) {
        size_t cap = t->cap ? 2 * t->cap : 1024;
        cell *h = realloc(t->heap, cap * sizeof *h);
        if (!h)
            return -1;
        t->heap = h;
        t->cap = cap;
    }
    c.key = key_of(t, &c);
    t->heap[t->n] = c;
    sift_up(t->heap, t->n++);
    t->queued_pixels += cell_pixels(t, c.x, c.y, c.s);
    return 0;
}

static cell pop(tf_paint_tree *t)
{
    cell top = t->heap[0];
    t->heap[0] = t->heap[--t->n];
    sift_down(t->heap, t->n, 0);
    t->queued_pixels -= cell_pixels(t, top.x, top.y, top.s);
    return top;
}

static float cell_contrast(const tf_paint_tree *t, int x0, int x1, int y0, int y1);

/* ---- the tree ---- */

tf_paint_tree *tf_paint_tree_new(int w, int h, const tf_paint_params *p)
{
    tf_paint_tree *t = calloc(1, sizeof *t);
    size_t corners = (size_t)(w + 1) * (size_t)(h + 1);
    if (!t)
        return NULL;
    *t = (tf_paint_tree){.w = w, .h = h, .p = *p};
    t->level = malloc(corners * 3 * sizeof *t->level);
    t->srgb = malloc(corners * 3);
    t->px = malloc((size_t)w * (size_t)h * sizeof *t->px);
    if (!t->level || !t->srgb || !t->px) {
        tf_paint_tree_free(t);
        return NULL;
    }
    if (tf_paint_tree_reset(t) != 0) {
        tf_paint_tree_free(t);
        return NULL;
    }
    return t;
}

void tf_paint_tree_free(tf_paint_tree *t)
{
    if (!t)
        return;
    free(t->heap);
    free(t->level);
    free(t->srgb);
    free(t->px);
    free(t);
}

int tf_paint_tree_reset(tf_paint_tree *t)
{
    t->n = 0;
    t->exact_pixels = t->samples = t->queued_pixels = t->out_pixels = t->roots_left = 0;
    for (int y = 0; y < t->h; y += t->p.root)
        for (int x = 0; x < t->w; x += t->p.root) {
            if (push(t, (cell){x, y, t->p.root, 0, 0, 0, 0}) != 0)
                return -1;
            t->roots_left++;
        }
    return 0;
}

void tf_paint_tree_set_interest(tf_paint_tree *t, tf_rect area)
{
    t->interest = area;
    for (size_t i = 0; i < t->n; i++)
        t->heap[i].key = key_of(t, &t->heap[i]);
    for (size_t i = t->n / 2; i-- > 0;)
        sift_down(t->heap, t->n, i);
}

/* Does a cell of side s still want its fine pass (its lattice at the fine stride)? */
static int wants_fine(const tf_paint_tree *t, const cell *c)
{
    return !c->fine && t->p.fine < c->s;
}

/* The node a cell becomes, and about how many rays it costs: a coarse cell (or a root) is
 * refined `levels` levels, down to the exact side; a cell of the exact side gets its fine
 * pass first, then is rendered exactly. */
static tf_paint_node node_of(const tf_paint_tree *t, const cell *c, int64_t *rays)
{
    tf_paint_node n = {c->x, c->y, c->s, 0, c->corners_known ? TF_PAINT_CORNERS_KNOWN : 0};
    if (c->s > t->p.leaf || !c->corners_known || wants_fine(t, c)) {
        int d = c->s >> t->p.levels;
        n.d = c->s > t->p.leaf || !c->corners_known ? (d > t->p.leaf ? d : t->p.leaf)
                                                    : t->p.fine;
        if (n.d > c->s)
            n.d = c->s;
        *rays = (int64_t)(tf_paint_node_values(&n, t->w, t->h) / TF_PAINT_SAMPLE_FLOATS);
    } else {
        int64_t pixels = cell_pixels(t, c->x, c->y, c->s);
        *rays = pixels * 2 + 2 * c->s + 1; /* the corners, and about one more sample a pixel */
    }
    return n;
}

int tf_paint_tree_next(tf_paint_tree *t, tf_paint_node *nodes, int max)
{
    int count = 0;
    int64_t rays = 0;
    while (count < max && t->n > 0 && rays < t->p.task_rays) {
        if (count > 0 && !t->heap[0].corners_known != !(nodes[0].flags & TF_PAINT_CORNERS_KNOWN))
            break; /* roots travel alone: the coarse picture is not held up by finer work */
        cell c = pop(t);
        int64_t r;
        nodes[count++] = node_of(t, &c, &r);
        rays += r;
        t->out_pixels += cell_pixels(t, c.x, c.y, c.s);
    }
    return count;
}

void tf_paint_tree_requeue(tf_paint_tree *t, const tf_paint_node *nodes, int count)
{
    for (int k = 0; k < count; k++) {
        const tf_paint_node *n = &nodes[k];
        t->out_pixels -= cell_pixels(t, n->x, n->y, n->s);
        cell c = {n->x, n->y, n->s, (n->flags & TF_PAINT_CORNERS_KNOWN) != 0, 0, 0, 0};
        c.fine = n->d == 0 && t->p.fine < n->s; /* an exact node had had its fine pass */
        if (c.corners_known)
            c.contrast = cell_contrast(t, n->x, n->x + n->s < t->w ? n->x + n->s : t->w, n->y,
                                       n->y + n->s < t->h ? n->y + n->s : t->h);
        if (push(t, c) != 0)
            abort(); /* the heap held this cell before: its room is there */
    }
}

/* ---- applying results ---- */

static size_t corner_index(const tf_paint_tree *t, int x, int y)
{
    return ((size_t)y * (size_t)(t->w + 1) + (size_t)x) * 3;
}

/* A channel as the eye sees it: the antialiasing's measure (render/sample_math.h), sqrt of the
 * linear value clamped to [0, 1]. */
static float display_level(float v)
{
    return v > 0 ? (v < 1 ? sqrtf(v) : 1.0f) : 0.0f;
}

/* The widest per-channel range of the display levels at a cell's four corners. */
static float cell_contrast(const tf_paint_tree *t, int x0, int x1, int y0, int y1)
{
    const float *c[4] = {&t->level[corner_index(t, x0, y0)], &t->level[corner_index(t, x1, y0)],
                         &t->level[corner_index(t, x0, y1)], &t->level[corner_index(t, x1, y1)]};
    float widest = 0;
    for (int ch = 0; ch < 3; ch++) {
        float lo = c[0][ch], hi = c[0][ch];
        for (int k = 1; k < 4; k++) {
            lo = fminf(lo, c[k][ch]);
            hi = fmaxf(hi, c[k][ch]);
        }
        widest = fmaxf(widest, hi - lo);
    }
    return widest;
}

static int put_header(tf_paint_bytes *out, uint32_t kind, const tf_paint_node *n)
{
    uint32_t v[5] = {kind, (uint32_t)n->x, (uint32_t)n->y, (uint32_t)n->s, (uint32_t)n->d};
    uint8_t b[TF_PAINT_MSG_HEADER];
    for (int f = 0; f < 5; f++)
        for (int k = 0; k < 4; k++)
            b[4 * f + k] = (uint8_t)(v[f] >> (8 * k));
    return tf_paint_bytes_add(out, b, sizeof b);
}

/* After a SAMPLE node: a fine pass queues its node again, to be rendered exactly, with the
 * widest contrast of its fine cells; any other queues its sub-squares as cells. */
static void queue_after_sample(tf_paint_tree *t, const tf_paint_node *n, const int *xs, int ni,
                               const int *ys, int nj, int *rc)
{
    int fine_pass = (n->flags & TF_PAINT_CORNERS_KNOWN) && n->s <= t->p.leaf && n->d < n->s;
    float widest = 0;
    for (int j = 0; j + 1 < nj; j++)
        for (int i = 0; i + 1 < ni; i++) {
            float c = cell_contrast(t, xs[i], xs[i + 1], ys[j], ys[j + 1]);
            if (!fine_pass)
                *rc |= push(t, (cell){xs[i], ys[j], n->d, 1, c, 0, 0});
            widest = fmaxf(widest, c);
        }
    if (fine_pass)
        *rc |= push(t, (cell){n->x, n->y, n->s, 1, widest, 0, 1});
}

/* A SAMPLE node's values into the corners, its lattice to the page, its sub-squares queued. */
static const float *apply_sample(tf_paint_tree *t, const tf_paint_node *n, const float *v,
                                 tf_paint_bytes *out, int *rc)
{
    int xs[TF_PAINT_MAX_SIZE + 1], ys[TF_PAINT_MAX_SIZE + 1];
    int ni = tf_paint_axis(n->x, n->s, n->d, t->w, xs), nj = tf_paint_axis(n->y, n->s, n->d, t->h, ys);
    for (int j = 0; j < nj; j++)
        for (int i = 0; i < ni; i++) {
            if (tf_paint_point_skipped(n, i, j, ni, nj))
                continue;
            size_t k = corner_index(t, xs[i], ys[j]);
            for (int ch = 0; ch < 3; ch++) {
                t->level[k + (size_t)ch] = display_level(v[ch]);
                t->srgb[k + (size_t)ch] = tf_srgb8(v[ch]);
            }
            v += TF_PAINT_SAMPLE_FLOATS;
            t->samples++;
        }
    if (!(n->flags & TF_PAINT_CORNERS_KNOWN))
        t->roots_left--;
    *rc |= put_header(out, TF_PAINT_MSG_LATTICE, n);
    for (int j = 0; j < nj; j++)
        for (int i = 0; i < ni; i++)
            *rc |= tf_paint_bytes_add(out, &t->srgb[corner_index(t, xs[i], ys[j])], 3);
    t->out_pixels -= cell_pixels(t, n->x, n->y, n->s);
    queue_after_sample(t, n, xs, ni, ys, nj, rc);
    return v;
}

/* What the render's PNG preview shows for a channel of an exact pixel: the sRGB of its float
 * value, as the workers make the preview (image/exrencode.h, tf_preview_share). */
static uint8_t shown(float v)
{
    return tf_srgb8(v);
}

static const float *apply_exact(tf_paint_tree *t, const tf_paint_node *n, const float *v,
                                tf_paint_bytes *out, int *rc)
{
    int pw = (n->x + n->s < t->w ? n->x + n->s : t->w) - n->x;
    int ph = (n->y + n->s < t->h ? n->y + n->s : t->h) - n->y;
    *rc |= put_header(out, TF_PAINT_MSG_EXACT, n);
    for (int row = 0; row < ph; row++)
        for (int c = 0; c < pw; c++, v += TF_PAINT_PIXEL_FLOATS) {
            tf_pixel *p = &t->px[(size_t)(n->y + row) * (size_t)t->w + (size_t)(n->x + c)];
            memcpy(p, v, sizeof *p);
            uint8_t rgb[3] = {shown(p->r), shown(p->g), shown(p->b)};
            *rc |= tf_paint_bytes_add(out, rgb, 3);
        }
    t->exact_pixels += (int64_t)pw * ph;
    t->out_pixels -= (int64_t)pw * ph;
    return v;
}

int tf_paint_tree_apply(tf_paint_tree *t, const tf_paint_node *nodes, int count,
                        const float *values, tf_paint_bytes *out)
{
    int rc = 0;
    for (int k = 0; k < count; k++)
        values = nodes[k].d == 0 ? apply_exact(t, &nodes[k], values, out, &rc)
                                 : apply_sample(t, &nodes[k], values, out, &rc);
    return rc ? -1 : 0;
}

void tf_paint_tree_counts(const tf_paint_tree *t, tf_paint_counts *c)
{
    *c = (tf_paint_counts){t->exact_pixels, (int64_t)t->w * t->h, t->samples, (int64_t)t->n,
                           t->roots_left};
}

const tf_pixel *tf_paint_tree_pixels(const tf_paint_tree *t)
{
    return t->exact_pixels == (int64_t)t->w * t->h ? t->px : NULL;
}

int tf_paint_tree_check(const tf_paint_tree *t)
{
    assert(t->queued_pixels + t->out_pixels + t->exact_pixels == (int64_t)t->w * t->h &&
           "P1: queued, out and exact pixels cover the image once");
    for (size_t i = 1; i < t->n; i++)
        assert(t->heap[(i - 1) / 2].key >= t->heap[i].key && "P2: the queue is a max-heap");
    for (size_t i = 0; i < t->n; i++) {
        const cell *c = &t->heap[i];
        assert(pow2(c->s) && c->s <= t->p.root && "P3: a cell's side is a power of two");
        assert(c->x >= 0 && c->y >= 0 && c->x < t->w && c->y < t->h && c->x % c->s == 0 &&
               c->y % c->s == 0 && "P3: a cell is an aligned square in the image");
        (void)c;
    }
    return 1;
}
