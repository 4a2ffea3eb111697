/* erosion_state.c: the erosion's grid state and windows onto it (erosion_state.h). */
#include "terrain/erosion_state.h"

#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>

#define ARRAYS 7 /* b, t, d, w, s, flow, soft: all 4 bytes an element */
#define HUGE_PAGE ((size_t)2 << 20)

/* `bytes` zeroed bytes that free() releases.  A big grid's arrays lie in 2 MiB pages where the
 * operating system offers them (transparent huge pages): a round copies every row of a tile
 * and its halo out of 7 arrays and every row of the tile into 6, and with 4 KiB pages each of
 * those rows was a TLB miss (a costly one under a hypervisor) and each page's first touch a
 * fault. */
static void *zeroed(size_t bytes)
{
    if (bytes < 2 * HUGE_PAGE)
        return calloc(bytes, 1);
    size_t whole = (bytes + HUGE_PAGE - 1) / HUGE_PAGE * HUGE_PAGE;
    void *p;
    if (posix_memalign(&p, HUGE_PAGE, whole) != 0)
        return NULL;
#ifdef MADV_HUGEPAGE
    madvise(p, whole, MADV_HUGEPAGE);
#endif
    memset(p, 0, bytes);
    return p;
}

int tf_erosion_state_alloc(tf_erosion_state *st, int n)
{
    memset(st, 0, sizeof *st);
    size_t count = (size_t)n * (size_t)n;
    void *p[ARRAYS];
    for (int a = 0; a < ARRAYS; a++) {
        p[a] = zeroed(count * 4);
        if (!p[a]) {
            while (a-- > 0)
                free(p[a]);
            return -1;
        }
    }
    *st = (tf_erosion_state){n, p[0], p[1], p[2], p[3], p[4], p[5], p[6]};
    return 0;
}

void tf_erosion_state_free(tf_erosion_state *st)
{
    void *p[ARRAYS] = {st->b, st->t, st->d, st->w, st->s, st->flow, st->soft};
    for (int a = 0; a < ARRAYS; a++)
        free(p[a]);
    memset(st, 0, sizeof *st);
}

int tf_erosion_window_alloc(tf_erosion_window *win, int nx, int ny)
{
    size_t stride = (size_t)nx + TF_EROSION_PAD;
    size_t each = stride * ((size_t)ny + 1); /* the spare row: room after the last */
    memset(win, 0, sizeof *win);
    win->mem = calloc(each * ARRAYS, 4);
    /* the kernel's rows, once for all the window's steps (erosion.h, TF_EROSION_ROWS) */
    void *rows = NULL;
    if (!win->mem || posix_memalign(&rows, 4096, TF_EROSION_ROWS(nx) * sizeof(int32_t)) != 0) {
        free(win->mem);
        win->mem = NULL;
        return -1;
    }
    int32_t *i32 = win->mem;
    tf_erosion_view *v = &win->v;
    v->b = i32;
    v->t = i32 + each;
    v->d = i32 + 2 * each;
    v->w = i32 + 3 * each;
    v->s = i32 + 4 * each;
    v->flow = (float *)(i32 + 5 * each);
    v->soft = (float *)(i32 + 6 * each);
    v->stride = stride;
    v->nx = nx;
    v->ny = ny;
    v->rows = rows;
    return 0;
}

void tf_erosion_window_free(tf_erosion_window *win)
{
    free(win->mem);
    free(win->v.rows);
    memset(win, 0, sizeof *win);
}

static void ghost(tf_erosion_view *v, size_t at)
{
    v->b[at] = TF_EROSION_GHOST_ALT;
    v->t[at] = v->d[at] = v->w[at] = v->s[at] = 0;
    v->flow[at] = 0.0f;
    v->soft[at] = 1.0f;
}

/* One window row from grid row gj, columns gi .. gi + nx - 1, ghosts off the grid. */
static void load_row(tf_erosion_view *v, const tf_erosion_state *st, int r, int gi, int gj)
{
    size_t row = (size_t)r * v->stride;
    int c0 = gi < 0 ? -gi : 0;                          /* first column on the grid */
    int c1 = gi + v->nx > st->n ? st->n - gi : v->nx;   /* one past the last */
    if (gj < 0 || gj >= st->n || c1 <= c0) {
        for (int c = 0; c < v->nx; c++)
            ghost(v, row + (size_t)c);
        return;
    }
    for (int c = 0; c < c0; c++)
        ghost(v, row + (size_t)c);
    for (int c = c1; c < v->nx; c++)
        ghost(v, row + (size_t)c);
    size_t at = row + (size_t)c0, len = (size_t)(c1 - c0) * 4;
    size_t g = (size_t)gj * (size_t)st->n + (size_t)(gi + c0);
    memcpy(v->b + at, st->b + g, len);
    memcpy(v->t + at, st->t + g, len);
    memcpy(v->d + at, st->d + g, len);
    memcpy(v->w + at, st->w + g, len);
    memcpy(v->s + at, st->s + g, len);
    memcpy(v->flow + at, st->flow + g, len);
    memcpy(v->soft + at, st->soft + g, len);
}

void tf_erosion_window_load(tf_erosion_window *win, const tf_erosion_state *st, int gi, int gj)
{
    win->v.gi = gi;
    win->v.gj = gj;
    for (int r = 0; r < win->v.ny; r++)
        load_row(&win->v, st, r, gi, gj + r);
}

void tf_erosion_window_store(const tf_erosion_window *win, tf_erosion_state *st,
                             tf_erosion_rect r)
{
    const tf_erosion_view *v = &win->v;
    size_t len = (size_t)(r.c1 - r.c0);
    for (int j = r.r0; j < r.r1; j++) {
        size_t at = (size_t)j * v->stride + (size_t)r.c0;
        size_t g = (size_t)(v->gj + j) * (size_t)st->n + (size_t)(v->gi + r.c0);
        memcpy(st->b + g, v->b + at, len * 4);
        memcpy(st->t + g, v->t + at, len * 4);
        memcpy(st->d + g, v->d + at, len * 4);
        memcpy(st->w + g, v->w + at, len * 4);
        memcpy(st->s + g, v->s + at, len * 4);
        memcpy(st->flow + g, v->flow + at, len * 4);
    }
}
