/* fuzz_heightmap.c: libFuzzer harness for the height map decoders (common/terrain/
 * heightmap_file.c, raster_png.c, raster_exr.c, raster_gdal.c).  The input bytes are a height
 * map file, as tf_scene_load or a networked worker would hand it over; the first byte picks a
 * grid size and nodata mode so both paths are reached.  Besides "no crash, leak or hang" it
 * checks the error contract: a refused input yields one non-empty line naming the file, and an
 * accepted one gives only finite heights and a positive extent.
 * Built by `make build/fuzz/fuzz_heightmap` (clang libFuzzer) and replayed over
 * tests/corpus/heightmap/ by `make test`. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "terrain/heightmap_file.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
const char *__asan_default_options(void);

/* A hostile GeoTIFF can make GDAL ask for a block of any size (the corpus has one of 35.6 GB);
 * GDAL copes when malloc says no, and the refusal is checked below like any other.  Under ASan
 * its allocator says no too, instead of stopping the run. */
const char *__asan_default_options(void) { return "allocator_may_return_null=1"; }

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < 1)
        return 0;
    tf_terrain t;
    memset(&t, 0, sizeof t);
    t.generator = TF_GEN_FILE;
    t.size_exp = 2 + (data[0] & 3);            /* 5..33 samples a side */
    t.nodata = (data[0] >> 2) & 1 ? TF_NODATA_SEA : TF_NODATA_FILL;
    t.first_row = (data[0] >> 3) % 3;
    t.vertical_scale = 1;
    t.file_bytes = data + 1;
    t.file_len = size - 1;
    t.file_name = "fuzz.map";
    char err[512] = "";
    double extent = 0;
    float *h = tf_heightmap_heights(&t, &extent, err, sizeof err);
    if (!h) {
        if (strncmp(err, "fuzz.map: ", 10) != 0 || strchr(err, '\n'))
            abort();
        return 0;
    }
    int n = (1 << t.size_exp) + 1;
    for (int i = 0; i < n * n; i++)
        if (!isfinite(h[i]))
            abort();
    if (!(extent > 0) || !isfinite(extent))
        abort();
    free(h);
    return 0;
}
