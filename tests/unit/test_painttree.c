/* test_painttree.c: Raypaint's quad-tree (coordinator/paint/painttree.c) and its drawing
 * (paint_raster.c) with a made-up renderer: every corner sample and pixel a function of its
 * coordinates.  Checked: any image size and parameters paint every pixel exactly once, through
 * nodes the wire accepts, and the picture drawn from the display messages ends as the exact
 * pixels' sRGB; the roots go first (a complete coarse picture before any finer node); an area of
 * interest is finished before the rest gets exact pixels; a lost task's cells come back; a new
 * view starts over; P1-P3 hold after every step; the drawing of a lattice is the bilinear rule
 * on a hand-made example, and malformed messages are refused. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "coordinator/paint/paint_raster.h"
#include "coordinator/paint/painttree.h"
#include "image/preview.h"

/* The made-up renderer: a corner sample, and a pixel's six floats. */
static float corner(int x, int y, int ch) { return (float)(((x * 7 + y * 13 + ch * 5) % 37) / 40.0); }

static void fake_values(const tf_paint_node *n, int count, int w, int h, float *out)
{
    int xs[TF_PAINT_MAX_SIZE + 1], ys[TF_PAINT_MAX_SIZE + 1];
    for (int k = 0; k < count; k++, n++) {
        if (n->d == 0) {
            for (int y = n->y; y < (n->y + n->s < h ? n->y + n->s : h); y++)
                for (int x = n->x; x < (n->x + n->s < w ? n->x + n->s : w); x++) {
                    float px[6] = {corner(x, y, 0), corner(x, y, 1), corner(x, y, 2), 1, 10, 4};
                    memcpy(out, px, sizeof px);
                    out += 6;
                }
            continue;
        }
        int ni = tf_paint_axis(n->x, n->s, n->d, w, xs), nj = tf_paint_axis(n->y, n->s, n->d, h, ys);
        for (int j = 0; j < nj; j++)
            for (int i = 0; i < ni; i++)
                if (!tf_paint_point_skipped(n, i, j, ni, nj))
                    for (int ch = 0; ch < 3; ch++)
                        *out++ = corner(xs[i], ys[j], ch);
    }
}

typedef struct run {
    int w, h;
    tf_paint_tree *t;
    tf_paint_bytes msgs;
    uint8_t *canvas, *exact;  /* the picture; which pixels are exact */
    int tasks, exact_nodes_before_coarse;
} run;

static void mark_exact(run *r, const tf_paint_node *n)
{
    for (int y = n->y; y < n->y + n->s && y < r->h; y++)
        for (int x = n->x; x < n->x + n->s && x < r->w; x++) {
            assert_int_equal(r->exact[y * r->w + x], 0); /* painted exactly once */
            r->exact[y * r->w + x] = 1;
        }
}

/* One task: taken, answered with the made-up values, applied, drawn.  0 when none waits. */
static int step(run *r)
{
    static tf_paint_node nodes[TF_PAINT_MAX_NODES];
    static float values[1 << 22];
    int count = tf_paint_tree_next(r->t, nodes, TF_PAINT_MAX_NODES);
    if (count == 0)
        return 0;
    for (int k = 0; k < count; k++) {
        assert_null(tf_paint_node_problem(&nodes[k], r->w, r->h));
        tf_paint_counts c;
        tf_paint_tree_counts(r->t, &c);
        if (nodes[k].d == 0 && c.roots_left > 0)
            r->exact_nodes_before_coarse++;
        if (nodes[k].d == 0)
            mark_exact(r, &nodes[k]);
    }
    size_t n = tf_paint_task_values(nodes, count, r->w, r->h);
    assert_true(n <= sizeof values / sizeof values[0]);
    fake_values(nodes, count, r->w, r->h, values);
    r->msgs.len = 0;
    assert_int_equal(tf_paint_tree_apply(r->t, nodes, count, values, &r->msgs), 0);
    assert_int_equal(tf_paint_raster_apply(r->canvas, r->w, r->h, r->msgs.p, r->msgs.len), 0);
    assert_true(tf_paint_tree_check(r->t));
    r->tasks++;
    return 1;
}

static void run_init(run *r, int w, int h, const tf_paint_params *p)
{
    memset(r, 0, sizeof *r);
    r->w = w;
    r->h = h;
    r->t = tf_paint_tree_new(w, h, p);
    r->canvas = calloc((size_t)w * (size_t)h, 3);
    r->exact = calloc((size_t)w * (size_t)h, 1);
    assert_non_null(r->t);
}

static void run_free(run *r)
{
    tf_paint_tree_free(r->t);
    tf_paint_bytes_free(&r->msgs);
    free(r->canvas);
    free(r->exact);
}

/* Painted to the end: every pixel exact, the canvas their sRGB. */
static void assert_painted(run *r)
{
    const tf_pixel *px = tf_paint_tree_pixels(r->t);
    assert_non_null(px);
    for (int y = 0; y < r->h; y++)
        for (int x = 0; x < r->w; x++)
            for (int ch = 0; ch < 3; ch++) {
                float v = corner(x, y, ch);
                assert_true((&px[y * r->w + x].r)[ch] == v);
                assert_int_equal(r->canvas[(y * r->w + x) * 3 + ch], tf_srgb8(v));
            }
    assert_int_equal(r->exact_nodes_before_coarse, 0);
}

static void every_size_and_parameter(void **state)
{
    (void)state;
    static const int sizes[][2] = {{1, 1}, {7, 3}, {64, 64}, {65, 33}, {200, 113}, {320, 180}};
    static const tf_paint_params params[] = {
        {64, 2, 8, 4096, 2}, {64, 1, 1, 100, 1}, {16, 3, 4, 1, 1}, {128, 4, 16, 20000, 4},
        {1, 1, 1, 50, 1},     {64, 2, 8, 4096, 8}, {32, 1, 16, 700, 1}};
    for (size_t s = 0; s < sizeof sizes / sizeof sizes[0]; s++)
        for (size_t p = 0; p < sizeof params / sizeof params[0]; p++) {
            run r;
            assert_null(tf_paint_params_problem(&params[p]));
            run_init(&r, sizes[s][0], sizes[s][1], &params[p]);
            while (step(&r))
                ;
            assert_painted(&r);
            run_free(&r);
        }
}

/* Exact pixels inside area a and outside it. */
static void exact_shares(const run *r, tf_rect a, int *inside, int *outside)
{
    *inside = *outside = 0;
    for (int y = 0; y < r->h; y++)
        for (int x = 0; x < r->w; x++) {
            int in = x >= a.x && x < a.x + a.w && y >= a.y && y < a.y + a.h;
            *(in ? inside : outside) += r->exact[y * r->w + x];
        }
}

static void interest_first(void **state)
{
    (void)state;
    tf_paint_params p = {64, 2, 8, 512, 2};
    run r;
    run_init(&r, 320, 180, &p);
    step(&r); /* the roots */
    tf_rect area = {200, 40, 40, 30};
    tf_paint_tree_set_interest(r.t, area);
    int inside = 0, outside = 0;
    while (inside < area.w * area.h && step(&r))
        exact_shares(&r, area, &inside, &outside);
    assert_int_equal(inside, area.w * area.h);
    /* by then the rest of the picture (56,400 pixels) has fewer exact pixels than the area */
    assert_true(outside < area.w * area.h);
    while (step(&r))
        ;
    assert_painted(&r);
    run_free(&r);
}

static void lost_task_comes_back(void **state)
{
    (void)state;
    tf_paint_params p = {32, 2, 4, 300, 2};
    run r;
    run_init(&r, 100, 70, &p);
    tf_paint_node lost[TF_PAINT_MAX_NODES];
    step(&r);
    step(&r);
    int count = tf_paint_tree_next(r.t, lost, TF_PAINT_MAX_NODES);
    assert_true(count > 0);
    assert_true(tf_paint_tree_check(r.t));
    tf_paint_tree_requeue(r.t, lost, count);
    assert_true(tf_paint_tree_check(r.t));
    while (step(&r))
        ;
    assert_painted(&r);
    run_free(&r);
}

static void new_view_starts_over(void **state)
{
    (void)state;
    tf_paint_params p = {64, 2, 8, 2000, 2};
    run r;
    run_init(&r, 150, 100, &p);
    for (int k = 0; k < 5; k++)
        step(&r);
    tf_paint_node out[TF_PAINT_MAX_NODES];
    assert_true(tf_paint_tree_next(r.t, out, TF_PAINT_MAX_NODES) > 0); /* dealt, never answered */
    assert_int_equal(tf_paint_tree_reset(r.t), 0);
    tf_paint_counts c;
    tf_paint_tree_counts(r.t, &c);
    assert_int_equal(c.exact_pixels, 0);
    assert_int_equal(c.samples, 0);
    assert_int_equal(c.roots_left, 3 * 2);
    assert_true(tf_paint_tree_check(r.t));
    memset(r.canvas, 0, 150 * 100 * 3);
    memset(r.exact, 0, 150 * 100);
    while (step(&r))
        ;
    assert_painted(&r);
    run_free(&r);
}

/* A 2x2 lattice of one cell [0, 2] x [0, 2]: pixel (0, 0) weighs the corners 9:3:3:1 / 16. */
static void bilinear_rule(void **state)
{
    (void)state;
    uint8_t msg[TF_PAINT_MSG_HEADER + 12] = {TF_PAINT_MSG_LATTICE, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
                                             2, 0, 0, 0, 2, 0, 0, 0};
    const uint8_t corners[12] = {0, 0, 0, 160, 160, 160, 16, 16, 16, 255, 255, 255};
    memcpy(msg + TF_PAINT_MSG_HEADER, corners, 12);
    uint8_t canvas[2 * 2 * 3] = {0};
    assert_int_equal(tf_paint_raster_apply(canvas, 2, 2, msg, sizeof msg), 0);
    /* (0*9 + 160*3 + 16*3 + 255*1 + 8) / 16 = 49 */
    assert_int_equal(canvas[0], (0 * 9 + 160 * 3 + 16 * 3 + 255 + 8) / 16);
    assert_int_equal(canvas[3 * 3], (0 * 1 + 160 * 3 + 16 * 3 + 255 * 9 + 8) / 16);
    /* malformed: an unknown kind, a short body, a node outside the picture */
    msg[0] = 9;
    assert_int_equal(tf_paint_raster_apply(canvas, 2, 2, msg, sizeof msg), -1);
    msg[0] = TF_PAINT_MSG_LATTICE;
    assert_int_equal(tf_paint_raster_apply(canvas, 2, 2, msg, sizeof msg - 1), -1);
    msg[4] = 4;
    assert_int_equal(tf_paint_raster_apply(canvas, 2, 2, msg, sizeof msg), -1);
}

static void wire_checks(void **state)
{
    (void)state;
    tf_paint_node n = {64, 0, 64, 16, 0}, got[2];
    uint8_t blob[2 * TF_PAINT_RECORD_BYTES];
    const char *why = NULL;
    tf_paint_nodes_put(blob, &n, 1);
    assert_int_equal(tf_paint_nodes_get(blob, TF_PAINT_RECORD_BYTES, 100, 50, got, 2, &why), 1);
    assert_memory_equal(&got[0], &n, sizeof n);
    tf_paint_node bad[] = {{0, 0, 48, 16, 0}, {10, 0, 16, 4, 0}, {0, 0, 16, 32, 0},
                           {0, 0, 16, 3, 0}, {0, 0, 16, 4, 8}, {128, 0, 16, 4, 0}};
    for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
        tf_paint_nodes_put(blob, &bad[k], 1);
        assert_int_equal(tf_paint_nodes_get(blob, TF_PAINT_RECORD_BYTES, 100, 50, got, 2, &why), -1);
        assert_non_null(why);
    }
    assert_int_equal(tf_paint_nodes_get(blob, 7, 100, 50, got, 2, &why), -1);
    /* values: right length and finite only */
    tf_paint_node s = {0, 0, 4, 2, 0};
    size_t nv = tf_paint_node_values(&s, 100, 50);
    assert_int_equal(nv, 9 * 3);
    float v[27], out[27];
    for (int k = 0; k < 27; k++)
        v[k] = 0.5f;
    char err[256];
    assert_int_equal(tf_paint_values_check((uint8_t *)v, sizeof v, &s, 1, 100, 50, 3, out, err,
                                           sizeof err), 0);
    assert_int_equal(tf_paint_values_check((uint8_t *)v, sizeof v - 4, &s, 1, 100, 50, 3, out,
                                           err, sizeof err), -1);
    v[5] = NAN;
    assert_int_equal(tf_paint_values_check((uint8_t *)v, sizeof v, &s, 1, 100, 50, 3, out, err,
                                           sizeof err), -1);
    v[5] = -1;
    assert_int_equal(tf_paint_values_check((uint8_t *)v, sizeof v, &s, 1, 100, 50, 3, out, err,
                                           sizeof err), -1);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(every_size_and_parameter), cmocka_unit_test(interest_first),
        cmocka_unit_test(lost_task_comes_back),      cmocka_unit_test(new_view_starts_over),
        cmocka_unit_test(bilinear_rule),             cmocka_unit_test(wire_checks),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
