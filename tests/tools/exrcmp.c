/* exrcmp.c: compare the pixels of two terrafarm renders (OpenEXR), ignoring their headers
 * (scene hash and name differ between a procedural scene and the height map exported from it).
 *
 *   exrcmp A.exr B.exr                 exit 0 if every channel of every pixel is bit-identical
 *   exrcmp A.exr B.exr --close F M     exit 0 if at most a fraction F of the pixels differ by
 *                                      more than 2/255 in R, G or B and the mean absolute RGB
 *                                      difference is at most M
 * Prints one line: pixels, identical, mean_abs_rgb, far (> 2/255), max_abs_rgb.
 * Built by `make test` into $(BUILD)/tools/exrcmp; used by tests/e2e/heightmap_file.sh and, to
 * compare renders whose file layouts differ (scanline vs tiled, tile sizes), by same_pixels in
 * tests/e2e/lib.sh. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "image/exrfile.h"

typedef struct image {
    int w, h;
    tf_pixel *px;
} image;

static int take_row(void *user, int y, const tf_pixel *row)
{
    image *im = user;
    if (!im->px) {
        im->px = calloc((size_t)im->w * (size_t)im->h, sizeof *im->px);
        if (!im->px)
            return -1;
    }
    memcpy(im->px + (size_t)y * (size_t)im->w, row, (size_t)im->w * sizeof *row);
    return 0;
}

static int load(const char *path, image *im)
{
    tf_exr_meta meta;
    int rows;
    char err[512];
    im->px = NULL;
    /* the meta is filled before the first row: size the image then */
    if (tf_exr_probe(path, &meta, &rows, &(int){0}, err, sizeof err) != 0) {
        fprintf(stderr, "exrcmp: %s: %s\n", path, err);
        return -1;
    }
    im->w = meta.width;
    im->h = meta.height;
    if (tf_exr_read_rows(path, &meta, &rows, take_row, im, err, sizeof err) != 0 ||
        rows != im->h) {
        fprintf(stderr, "exrcmp: %s: %s\n", path, rows != im->h ? "incomplete" : err);
        return -1;
    }
    return 0;
}

int main(int argc, char **argv)
{
    if (argc != 3 && !(argc == 6 && strcmp(argv[3], "--close") == 0)) {
        fprintf(stderr, "usage: exrcmp A.exr B.exr [--close FRACTION MEAN]\n");
        return 2;
    }
    image a, b;
    if (load(argv[1], &a) || load(argv[2], &b))
        return 2;
    if (a.w != b.w || a.h != b.h) {
        printf("sizes differ: %dx%d vs %dx%d\n", a.w, a.h, b.w, b.h);
        free(a.px);
        free(b.px);
        return 1;
    }
    size_t n = (size_t)a.w * (size_t)a.h, same = 0, far = 0;
    double sum = 0, max = 0;
    for (size_t i = 0; i < n; i++) {
        same += memcmp(&a.px[i], &b.px[i], sizeof a.px[i]) == 0;
        double d[3] = {fabs(a.px[i].r - b.px[i].r), fabs(a.px[i].g - b.px[i].g),
                       fabs(a.px[i].b - b.px[i].b)};
        double m = fmax(d[0], fmax(d[1], d[2]));
        sum += (d[0] + d[1] + d[2]) / 3;
        far += m > 2.0 / 255;
        if (m > max)
            max = m;
    }
    printf("pixels=%zu identical=%zu mean_abs_rgb=%.6g far=%zu max_abs_rgb=%.6g\n", n, same,
           sum / n, far, max);
    free(a.px);
    free(b.px);
    if (argc == 3)
        return same == n ? 0 : 1;
    return (double)far <= atof(argv[4]) * n && sum / n <= atof(argv[5]) ? 0 : 1;
}
