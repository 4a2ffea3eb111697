/* cost_map.c: the simulated workers' cost model (declared in simulate.h): a coarse grid of
 * relative cost densities over the image, measured once on a real render, saved and loaded as
 * text, and integrated over a task's rectangle. */
#include "worker/simulate.h"
#include "clock.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "log.h"

/* ---- the cost map --------------------------------------------------------------------------- */

/* Cell i of n over a side of `size` pixels covers [cell_edge(i), cell_edge(i + 1)). */
static int cell_edge(int i, int n, int size) { return (int)((int64_t)i * size / n); }

int tf_cost_map_measure(const tf_scene *s, const tf_heightfield *hf, int gw, int gh,
                        tf_cost_map *m, char *err, size_t errlen)
{
    memset(m, 0, sizeof *m);
    if (gw < 1 || gh < 1 || gw > TF_COST_MAP_MAX || gh > TF_COST_MAP_MAX || gw > s->width ||
        gh > s->height) {
        tf_seterr(err, errlen, "cost map grid %dx%d: expected 1..%d cells a side, at most one per "
                 "pixel of the %dx%d image", gw, gh, TF_COST_MAP_MAX, s->width, s->height);
        return -1;
    }
    tf_renderer *r = tf_renderer_new(s, hf, err, errlen);
    if (!r)
        return -1;
    int maxw = cell_edge(1, gw, s->width) + s->width / gw + 1;
    int maxh = cell_edge(1, gh, s->height) + s->height / gh + 1;
    tf_pixel *px = malloc((size_t)maxw * (size_t)maxh * sizeof *px);
    m->density = calloc((size_t)gw * (size_t)gh, sizeof *m->density);
    if (!px || !m->density) {
        tf_seterr(err, errlen, "out of memory measuring the cost map");
        free(px);
        tf_renderer_free(r);
        tf_cost_map_free(m);
        return -1;
    }
    double total_ns = 0;
    for (int j = 0; j < gh; j++)
        for (int i = 0; i < gw; i++) {
            tf_rect c = {cell_edge(i, gw, s->width), cell_edge(j, gh, s->height), 0, 0};
            c.w = cell_edge(i + 1, gw, s->width) - c.x;
            c.h = cell_edge(j + 1, gh, s->height) - c.y;
            int64_t t0 = tf_clock_ns(CLOCK_THREAD_CPUTIME_ID);
            tf_render_rect(r, c, px, NULL);
            double ns = (double)(tf_clock_ns(CLOCK_THREAD_CPUTIME_ID) - t0);
            total_ns += ns;
            m->density[j * gw + i] = ns / ((double)c.w * c.h); /* ns per pixel, for now */
        }
    free(px);
    tf_renderer_free(r);
    m->gw = gw;
    m->gh = gh;
    m->measured_w = s->width;
    m->measured_h = s->height;
    m->pixel_ns = total_ns / ((double)s->width * s->height);
    /* Normalise: density = (ns per pixel in the cell) / (mean ns per pixel), whose
     * area-weighted mean is exactly 1 by construction. */
    for (int k = 0; k < gw * gh; k++)
        m->density[k] = m->pixel_ns > 0 ? m->density[k] / m->pixel_ns : 1.0;
    return 0;
}

int tf_cost_map_save(const char *path, const tf_cost_map *m, char *err, size_t errlen)
{
    FILE *f = fopen(path, "w");
    if (!f) {
        tf_seterr(err, errlen, "%s: cannot write the cost map: %s", path, strerror(errno));
        return -1;
    }
    fprintf(f, "terrafarm-cost-map 1 %d %d %d %d %.1f\n", m->gw, m->gh, m->measured_w,
            m->measured_h, m->pixel_ns);
    for (int j = 0; j < m->gh; j++)
        for (int i = 0; i < m->gw; i++)
            fprintf(f, "%.4f%c", m->density[j * m->gw + i], i + 1 == m->gw ? '\n' : ' ');
    int bad = ferror(f);
    bad |= fclose(f) != 0;
    if (bad) {
        tf_seterr(err, errlen, "%s: cannot write the cost map: %s", path, strerror(errno));
        return -1;
    }
    return 0;
}

int tf_cost_map_load(const char *path, tf_cost_map *m, char *err, size_t errlen)
{
    memset(m, 0, sizeof *m);
    FILE *f = fopen(path, "r");
    if (!f) {
        tf_seterr(err, errlen, "%s: cannot read the cost map: %s", path, strerror(errno));
        return -1;
    }
    int version = 0;
    if (fscanf(f, "terrafarm-cost-map %d %d %d %d %d %lf", &version, &m->gw, &m->gh,
               &m->measured_w, &m->measured_h, &m->pixel_ns) != 6 || version != 1) {
        tf_seterr(err, errlen, "%s: not a terrafarm cost map (expected 'terrafarm-cost-map 1 GW "
                 "GH W H PIXEL_NS' on the first line)", path);
        fclose(f);
        return -1;
    }
    if (m->gw < 1 || m->gh < 1 || m->gw > TF_COST_MAP_MAX || m->gh > TF_COST_MAP_MAX) {
        tf_seterr(err, errlen, "%s: cost map grid %dx%d out of range 1..%d", path, m->gw, m->gh,
                 TF_COST_MAP_MAX);
        fclose(f);
        return -1;
    }
    m->density = malloc((size_t)m->gw * (size_t)m->gh * sizeof *m->density);
    if (!m->density) {
        tf_seterr(err, errlen, "%s: out of memory", path);
        fclose(f);
        return -1;
    }
    for (int k = 0; k < m->gw * m->gh; k++) {
        double d;
        if (fscanf(f, "%lf", &d) != 1 || !isfinite(d) || d < 0) {
            tf_seterr(err, errlen, "%s: cost map cell %d: expected a finite non-negative number",
                     path, k);
            fclose(f);
            tf_cost_map_free(m);
            return -1;
        }
        m->density[k] = d;
    }
    fclose(f);
    return 0;
}

void tf_cost_map_free(tf_cost_map *m)
{
    free(m->density);
    m->density = NULL;
}

/* Overlap of [a0, a1) and [b0, b1), or 0. */
static double overlap(double a0, double a1, double b0, double b1)
{
    double lo = a0 > b0 ? a0 : b0, hi = a1 < b1 ? a1 : b1;
    return hi > lo ? hi - lo : 0.0;
}

double tf_cost_map_rect(const tf_cost_map *m, int image_w, int image_h, tf_rect r)
{
    /* Cell i spans [i * image_w / gw, (i + 1) * image_w / gw) in the target image's pixels:
     * the map is stretched, so its cells need not fall on pixel boundaries. */
    double sx = (double)image_w / m->gw, sy = (double)image_h / m->gh;
    int i0 = (int)(r.x / sx), i1 = (int)ceil((r.x + r.w) / sx);
    int j0 = (int)(r.y / sy), j1 = (int)ceil((r.y + r.h) / sy);
    if (i1 > m->gw)
        i1 = m->gw;
    if (j1 > m->gh)
        j1 = m->gh;
    double sum = 0;
    for (int j = j0 < 0 ? 0 : j0; j < j1; j++) {
        double oy = overlap(r.y, r.y + r.h, j * sy, (j + 1) * sy);
        for (int i = i0 < 0 ? 0 : i0; i < i1; i++)
            sum += m->density[j * m->gw + i] * oy * overlap(r.x, r.x + r.w, i * sx, (i + 1) * sx);
    }
    return sum;
}
