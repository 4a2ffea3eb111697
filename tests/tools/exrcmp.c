/* exrcmp.c: do two terrafarm renders hold the same decoded pixels?  The test suite's check of
 * the decomposition invariant across files that differ in layout (scanline vs tiled, tile
 * sizes), where `cmp` cannot apply.  Reads both files with the project's reader (OpenEXRCore
 * decoding, every chunk verified), converts each pixel's six channels to float and compares
 * them bit for bit.  A file must be complete (every chunk present).
 *
 * usage: exrcmp A.exr B.exr   exit 0: identical pixels; 1: they differ (first difference on
 * stdout); 2: a file cannot be read. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "image/exrfile.h"

typedef struct image {
    tf_exr_meta meta;
    tf_pixel *px;
} image;

static int keep_row(void *user, int y, const tf_pixel *row)
{
    image *im = user;
    if (!im->px) {
        im->px = calloc((size_t)im->meta.width * (size_t)im->meta.height, sizeof *im->px);
        if (!im->px)
            return -1;
    }
    memcpy(im->px + (size_t)y * (size_t)im->meta.width, row,
           (size_t)im->meta.width * sizeof *row);
    return 0;
}

static int load(const char *path, image *im)
{
    char err[1024];
    int rows = 0;
    memset(im, 0, sizeof *im);
    if (tf_exr_read_rows(path, &im->meta, &rows, keep_row, im, err, sizeof err)) {
        fprintf(stderr, "exrcmp: %s\n", err);
        return -1;
    }
    if (rows != im->meta.height) {
        fprintf(stderr, "exrcmp: %s: only %d of %d rows\n", path, rows, im->meta.height);
        return -1;
    }
    return 0;
}

int main(int argc, char **argv)
{
    if (argc != 3) {
        fprintf(stderr, "usage: exrcmp A.exr B.exr\n");
        return 2;
    }
    image a, b;
    if (load(argv[1], &a) || load(argv[2], &b))
        return 2;
    if (a.meta.width != b.meta.width || a.meta.height != b.meta.height) {
        printf("sizes differ: %dx%d vs %dx%d\n", a.meta.width, a.meta.height, b.meta.width,
               b.meta.height);
        return 1;
    }
    size_t n = (size_t)a.meta.width * (size_t)a.meta.height;
    for (size_t i = 0; i < n; i++)
        if (memcmp(&a.px[i], &b.px[i], sizeof a.px[i])) {
            printf("pixel (%zu, %zu) differs: %g %g %g %g %g %g vs %g %g %g %g %g %g\n",
                   i % (size_t)a.meta.width, i / (size_t)a.meta.width, a.px[i].r, a.px[i].g,
                   a.px[i].b, a.px[i].a, a.px[i].z, a.px[i].spp, b.px[i].r, b.px[i].g, b.px[i].b,
                   b.px[i].a, b.px[i].z, b.px[i].spp);
            return 1;
        }
    printf("identical pixels (%dx%d)\n", a.meta.width, a.meta.height);
    free(a.px);
    free(b.px);
    return 0;
}
