/* hfcmp.c: compare the samples of two height map files (PNG, OpenEXR, GeoTIFF: whatever
 * generator = file decodes, through terrain/raster.h), as stored, ignoring what the files say
 * of themselves.
 *
 *   hfcmp A B            exit 0 if both have the same size and every sample the same bits
 *   hfcmp A B --within D exit 0 if both have the same size and no two samples differ by more
 *                        than D
 * Prints one line: samples, identical, max_abs.  Built by `make test` into
 * $(BUILD)/tools/hfcmp; used by tests/e2e/heightmap_reimport.sh. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "terrain/raster.h"

/* The raster in path, or exit 2 with a message. */
static void load(const char *path, tf_raster *r)
{
    FILE *f = fopen(path, "rb");
    uint8_t *bytes = NULL;
    long len = -1;
    if (f && fseek(f, 0, SEEK_END) == 0 && (len = ftell(f)) >= 0 && fseek(f, 0, SEEK_SET) == 0)
        bytes = malloc((size_t)len + 1);
    if (!bytes || fread(bytes, 1, (size_t)len, f) != (size_t)len) {
        fprintf(stderr, "hfcmp: cannot read %s\n", path);
        exit(2);
    }
    fclose(f);
    char err[512];
    if (tf_raster_decode(bytes, (size_t)len, path, r, err, sizeof err) != 0) {
        fprintf(stderr, "hfcmp: %s\n", err);
        exit(2);
    }
    free(bytes);
}

int main(int argc, char **argv)
{
    if (argc != 3 && !(argc == 5 && strcmp(argv[3], "--within") == 0)) {
        fprintf(stderr, "usage: hfcmp A B [--within D]\n");
        return 2;
    }
    double within = argc == 5 ? atof(argv[4]) : -1;
    tf_raster a, b;
    load(argv[1], &a);
    load(argv[2], &b);
    if (a.width != b.width || a.height != b.height) {
        printf("sizes differ: %dx%d and %dx%d\n", a.width, a.height, b.width, b.height);
        return 1;
    }
    size_t n = (size_t)a.width * (size_t)a.height, same = 0;
    double max_abs = 0;
    for (size_t i = 0; i < n; i++) {
        same += memcmp(&a.v[i], &b.v[i], sizeof(float)) == 0;
        double d = fabs((double)a.v[i] - (double)b.v[i]);
        max_abs = isnan(d) || d > max_abs ? (isnan(d) ? INFINITY : d) : max_abs;
    }
    printf("samples %zu, identical %zu, max_abs %.9g\n", n, same, max_abs);
    tf_raster_free(&a);
    tf_raster_free(&b);
    return within < 0 ? same != n : !(max_abs <= within);
}
