/* test_heightmap_file.c: generator = file's raster-to-terrain steps (common/terrain/
 * heightmap_file.c) on small GeoTIFFs made in memory with GDAL: metres per pixel from a
 * geographic (degree) raster, the square check, north-up rows flipped to terrafarm's south-first
 * order, nodata filled or made sea, all-nodata refused, vertical scale and offset, the crop
 * window, and resampling (exact on a 2^k+1 grid, area-weighted when shrinking); what a file
 * says of itself (terrafarm.* in EXR attributes, PNG text chunks, GeoTIFF metadata) honoured
 * where the scene leaves a key at its default, and refused with one line naming file and key
 * when malformed.  The render comparisons are in tests/e2e/heightmap_file.sh, the round trip
 * through terrafarm heightfield in tests/e2e/heightmap_reimport.sh. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include <gdal.h>
#include <cpl_vsi.h>
#include <ogr_srs_api.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "image/exrfile.h"
#include "image/geotiff_write.h"
#include "image/png_write.h"
#include "terrain/heightmap_file.h"
#include "terrain/raster.h"

/* A w x h Float32 GeoTIFF, first row first, as file bytes (malloc'd, *len). epsg 0: no CRS;
 * gt NULL: no geotransform; has_nodata: that value is the band's nodata. */
static uint8_t *make_tif(int w, int h, const float *v, const double *gt, int epsg,
                         int has_nodata, double nodata, size_t *len)
{
    static int counter;
    char path[64];
    snprintf(path, sizeof path, "/vsimem/test-%d.tif", counter++);
    GDALAllRegister();
    GDALDatasetH ds = GDALCreate(GDALGetDriverByName("GTiff"), path, w, h, 1, GDT_Float32, NULL);
    assert_non_null(ds);
    if (gt)
        GDALSetGeoTransform(ds, (double *)gt);
    if (epsg) {
        OGRSpatialReferenceH srs = OSRNewSpatialReference(NULL);
        assert_int_equal(OSRImportFromEPSG(srs, epsg), OGRERR_NONE);
        GDALSetSpatialRef(ds, srs);
        OSRDestroySpatialReference(srs);
    }
    GDALRasterBandH band = GDALGetRasterBand(ds, 1);
    if (has_nodata)
        GDALSetRasterNoDataValue(band, nodata);
    assert_int_equal(GDALRasterIO(band, GF_Write, 0, 0, w, h, (void *)v, w, h, GDT_Float32, 0, 0),
                     CE_None);
    GDALClose(ds);
    vsi_l_offset n;
    GByte *mem = VSIGetMemFileBuffer(path, &n, FALSE);
    uint8_t *copy = malloc((size_t)n);
    memcpy(copy, mem, (size_t)n);
    VSIUnlink(path);
    *len = (size_t)n;
    return copy;
}

static tf_terrain file_terrain(const uint8_t *bytes, size_t len, int size_exp)
{
    tf_terrain t;
    memset(&t, 0, sizeof t);
    t.generator = TF_GEN_FILE;
    t.size_exp = size_exp;
    t.vertical_scale = 1;
    t.file_bytes = bytes;
    t.file_len = len;
    t.file_name = "mem.tif";
    return t;
}

static void test_geographic_metres(void **state)
{
    (void)state;
    enum { N = 65 };
    float v[N * N];
    for (int i = 0; i < N * N; i++)
        v[i] = 100;
    /* one arc-second of latitude; longitude widened so the window is square in metres at
     * its centre, latitude 45 */
    double dlat = 1.0 / 3600, lat_top = 45 + dlat * N / 2.0;
    double dlon = dlat / cos(45 * M_PI / 180);
    double gt[6] = {7.0, dlon, 0, lat_top, 0, -dlat};
    size_t len;
    uint8_t *bytes = make_tif(N, N, v, gt, 4326, 0, 0, &len);
    tf_terrain t = file_terrain(bytes, len, 6);
    double extent = 0;
    char err[512];
    float *h = tf_heightmap_heights(&t, &extent, err, sizeof err);
    assert_non_null(h);
    double want = (N - 1) * dlat * M_PI / 180 * 6378137.0; /* WGS 84 semi-major axis */
    if (fabs(extent - want) > 1e-6 * want)
        fail_msg("extent %.9g, expected %.9g", extent, want);
    free(h);
    free(bytes);

    /* equal degrees at 45 degrees north: 0.71 as wide as high, refused with a crop hint */
    gt[1] = dlat;
    bytes = make_tif(N, N, v, gt, 4326, 0, 0, &len);
    t = file_terrain(bytes, len, 6);
    assert_null(tf_heightmap_heights(&t, &extent, err, sizeof err));
    assert_non_null(strstr(err, "mem.tif: the window covers"));
    assert_non_null(strstr(err, "crop_height = 46"));
    free(bytes);
}

/* Row r of the file holds value r; north-up, so file row 0 is terrain row n-1. */
static void test_rows_north_up_and_south_first(void **state)
{
    (void)state;
    enum { N = 9 };
    float v[N * N];
    for (int r = 0; r < N; r++)
        for (int c = 0; c < N; c++)
            v[r * N + c] = (float)(r * 10 + c);
    double gt[6] = {1000, 5, 0, 2000, 0, -5};
    size_t len;
    uint8_t *bytes = make_tif(N, N, v, gt, 32632, 0, 0, &len);
    tf_terrain t = file_terrain(bytes, len, 3);
    double extent;
    char err[512];
    float *h = tf_heightmap_heights(&t, &extent, err, sizeof err);
    assert_non_null(h);
    assert_true(extent == 40);
    for (int j = 0; j < N; j++)
        for (int i = 0; i < N; i++)
            assert_true(h[j * N + i] == (float)((N - 1 - j) * 10 + i)); /* exact: on the grid */
    free(h);
    t.first_row = TF_FIRST_ROW_SOUTH;
    h = tf_heightmap_heights(&t, &extent, err, sizeof err);
    assert_non_null(h);
    assert_true(h[0] == 0 && h[N * N - 1] == (float)((N - 1) * 10 + N - 1));
    free(h);
    /* vertical scale and offset; an explicit extent wins over the georeferencing */
    t.vertical_scale = 2;
    t.vertical_offset = -3;
    t.extent = 777;
    h = tf_heightmap_heights(&t, &extent, err, sizeof err);
    assert_non_null(h);
    assert_true(extent == 777 && h[1] == 2 * 1 - 3);
    free(h);
    /* crop: columns 2..6 of rows 1..5 (5x5), shrunk to... no: size_exp 2 is 5x5, exact */
    t = file_terrain(bytes, len, 2);
    t.first_row = TF_FIRST_ROW_SOUTH;
    t.crop_x = 2;
    t.crop_y = 1;
    t.crop_width = 5;
    t.crop_height = 5;
    h = tf_heightmap_heights(&t, &extent, err, sizeof err);
    assert_non_null(h);
    assert_true(h[0] == 12 && h[24] == 56 && extent == 20);
    free(h);
    t.crop_x = 6;
    assert_null(tf_heightmap_heights(&t, &extent, err, sizeof err));
    assert_non_null(strstr(err, "mem.tif: crop window x 6, y 1, 5x5 lies outside the 9x9"));
    free(bytes);
}

static void test_nodata(void **state)
{
    (void)state;
    enum { N = 9 };
    float v[N * N];
    for (int r = 0; r < N; r++)
        for (int c = 0; c < N; c++)
            v[r * N + c] = (float)c;
    v[4 * N + 4] = -9999; /* a one-sample hole: the mean of its neighbours, 4 */
    for (int c = 0; c < 3; c++)
        v[0 * N + c] = -9999; /* a hole on the edge, filled from the data inwards */
    size_t len;
    uint8_t *bytes = make_tif(N, N, v, NULL, 0, 1, -9999, &len);
    tf_terrain t = file_terrain(bytes, len, 3);
    t.first_row = TF_FIRST_ROW_SOUTH;
    double extent;
    char err[512];
    float *h = tf_heightmap_heights(&t, &extent, err, sizeof err);
    assert_non_null(h);
    assert_true(extent == 8); /* no georeferencing: a unit a pixel */
    assert_true(h[4 * N + 4] == 4);
    /* the first layer: each from its known neighbours only (right 3 and below 2 for (2, 0)) */
    assert_true(h[0] == 0 && h[1] == 1 && h[2] == 2.5f);
    free(h);
    t.nodata = TF_NODATA_SEA;
    t.file_sea_level = -50;
    h = tf_heightmap_heights(&t, &extent, err, sizeof err);
    assert_non_null(h);
    assert_true(h[4 * N + 4] == -51 && h[0] == -51 && h[3] == 3);
    free(h);
    free(bytes);
    for (int i = 0; i < N * N; i++)
        v[i] = -9999;
    bytes = make_tif(N, N, v, NULL, 0, 1, -9999, &len);
    t = file_terrain(bytes, len, 3);
    assert_null(tf_heightmap_heights(&t, &extent, err, sizeof err));
    assert_string_equal(err, "mem.tif: no data: all 9x9 samples are nodata");
    free(bytes);
}

/* One known sample in a corner of 1025 x 1025: the fill reaches every sample in breadth-first
 * layers, each sample once (the first version rescanned every pending sample per layer, 2000
 * layers here: minutes; the fuzzer found it as a hang). */
static void test_fill_single_sample(void **state)
{
    (void)state;
    enum { N = 1025 };
    float *v = malloc((size_t)N * N * sizeof *v);
    for (size_t i = 0; i < (size_t)N * N; i++)
        v[i] = -9999;
    v[0] = 42;
    size_t len;
    uint8_t *bytes = make_tif(N, N, v, NULL, 0, 1, -9999, &len);
    free(v);
    tf_terrain t = file_terrain(bytes, len, 10);
    double extent;
    char err[512];
    float *h = tf_heightmap_heights(&t, &extent, err, sizeof err);
    assert_non_null(h);
    for (size_t i = 0; i < (size_t)N * N; i++)
        if (h[i] != 42)
            fail_msg("sample %zu is %g, not 42", i, (double)h[i]);
    free(h);
    free(bytes);
}

/* 17 -> 9 samples: two source pixels a sample; the tent of radius 2 keeps a ramp exact away
 * from the edges and a constant exact everywhere. */
static void test_resample_shrink(void **state)
{
    (void)state;
    enum { N = 17, M = 9 };
    float v[N * N];
    for (int r = 0; r < N; r++)
        for (int c = 0; c < N; c++)
            v[r * N + c] = (float)(3 * c + 7);
    size_t len;
    uint8_t *bytes = make_tif(N, N, v, NULL, 0, 0, 0, &len);
    tf_terrain t = file_terrain(bytes, len, 3);
    double extent;
    char err[512];
    float *h = tf_heightmap_heights(&t, &extent, err, sizeof err);
    assert_non_null(h);
    assert_true(extent == 16);
    for (int j = 0; j < M; j++)
        for (int i = 1; i < M - 1; i++)
            assert_true(fabsf(h[j * M + i] - (float)(3 * 2 * i + 7)) < 1e-4f);
    free(h);
    /* an alternating +-1 pattern (pure aliasing for point sampling every other pixel) averages
     * towards 0 */
    for (int r = 0; r < N; r++)
        for (int c = 0; c < N; c++)
            v[r * N + c] = (float)(((r + c) & 1) ? 1 : -1);
    free(bytes);
    bytes = make_tif(N, N, v, NULL, 0, 0, 0, &len);
    t = file_terrain(bytes, len, 3);
    h = tf_heightmap_heights(&t, &extent, err, sizeof err);
    assert_non_null(h);
    for (int j = 1; j < M - 1; j++)
        for (int i = 1; i < M - 1; i++)
            assert_true(fabsf(h[j * M + i]) < 0.3f);
    free(h);
    free(bytes);
}

/* An n x n file of values v (first row first) as FORMAT ('e' OpenEXR, 'p' 16-bit PNG of the
 * values as codes, 't' GeoTIFF: v south first, written north-up) with the metadata items meta
 * (name, value, ..., NULL), as bytes (malloc'd, *len). */
static uint8_t *make_file(char format, int n, const float *v, const char *const *meta,
                          size_t *len)
{
    char path[] = "/tmp/test_heightmap_file.XXXXXX", err[512];
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    close(fd);
    int rc = -1;
    if (format == 'e')
        rc = tf_exr_write_gray_attrs(path, n, n, v, meta, err, sizeof err);
    if (format == 't')
        rc = tf_geotiff_write_heights(path, n, v, 1.0, 0, 0, NULL, meta, err, sizeof err);
    if (format == 'p') {
        tf_png_writer *w = tf_png_create(path, n, n, 16, 1, err, sizeof err);
        assert_non_null(w);
        for (int i = 0; meta[i]; i += 2)
            assert_int_equal(tf_png_text(w, meta[i], meta[i + 1], err, sizeof err), 0);
        uint16_t row[64];
        for (int r = 0; r < n; r++) {
            for (int c = 0; c < n; c++)
                row[c] = (uint16_t)v[r * n + c];
            assert_int_equal(tf_png_write_row(w, row, err, sizeof err), 0);
        }
        rc = tf_png_finish(w, err, sizeof err);
    }
    assert_int_equal(rc, 0);
    FILE *f = fopen(path, "rb");
    assert_non_null(f);
    uint8_t *bytes = malloc(1 << 20);
    *len = fread(bytes, 1, 1 << 20, f);
    fclose(f);
    unlink(path);
    return bytes;
}

enum { MN = 9 };

static void ramp(float *v)
{
    for (int r = 0; r < MN; r++)
        for (int c = 0; c < MN; c++)
            v[r * MN + c] = (float)(r * 10 + c);
}

static void test_file_says_orientation_extent_vertical(void **state)
{
    (void)state;
    float v[MN * MN];
    ramp(v);
    const char *const exr_meta[] = {TF_RASTER_KEY_FIRST_ROW, "south", TF_RASTER_KEY_EXTENT, "80",
                                    TF_RASTER_KEY_VERTICAL_SCALE, "2",
                                    TF_RASTER_KEY_VERTICAL_OFFSET, "-3", NULL};
    size_t len;
    uint8_t *bytes = make_file('e', MN, v, exr_meta, &len);
    tf_terrain t = file_terrain(bytes, len, 3);
    double extent;
    char err[512];
    float *h = tf_heightmap_heights(&t, &extent, err, sizeof err);
    assert_non_null(h);
    assert_true(extent == 80);
    for (int i = 0; i < MN * MN; i++)
        assert_true(h[i] == 2 * v[i] - 3); /* south first: file row j is terrain row j */
    free(h);
    /* the scene's keys, where given, win: each on its own */
    t.first_row = TF_FIRST_ROW_NORTH;
    t.extent = 500;
    t.vertical_scale = 4;
    h = tf_heightmap_heights(&t, &extent, err, sizeof err);
    assert_non_null(h);
    assert_true(extent == 500);
    assert_true(h[0] == 4 * v[(MN - 1) * MN] - 3 && h[MN * MN - 1] == 4 * v[MN - 1] - 3);
    free(h);
    /* the recorded extent spans the whole raster: a 5x5 crop of the 9x9 covers half of it */
    t = file_terrain(bytes, len, 2);
    t.crop_width = t.crop_height = 5;
    h = tf_heightmap_heights(&t, &extent, err, sizeof err);
    assert_non_null(h);
    assert_true(extent == 40);
    free(h);
    free(bytes);
    const char *const png_meta[] = {TF_RASTER_KEY_FIRST_ROW, "north", TF_RASTER_KEY_EXTENT, "40",
                                    TF_RASTER_KEY_VERTICAL_SCALE, "0.5",
                                    TF_RASTER_KEY_VERTICAL_OFFSET, "1", NULL};
    bytes = make_file('p', MN, v, png_meta, &len);
    t = file_terrain(bytes, len, 3);
    h = tf_heightmap_heights(&t, &extent, err, sizeof err);
    assert_non_null(h);
    assert_true(extent == 40);
    for (int j = 0; j < MN; j++)
        for (int i = 0; i < MN; i++)
            assert_true(h[j * MN + i] == 0.5f * v[(MN - 1 - j) * MN + i] + 1);
    free(h);
    free(bytes);
}

/* The file made with the one item key = value fails with one line naming it and the key. */
static void expect_refused(char format, const char *key, const char *value, const char *what)
{
    float v[MN * MN];
    ramp(v);
    const char *const meta[] = {key, value, NULL};
    size_t len;
    uint8_t *bytes = make_file(format, MN, v, meta, &len);
    tf_terrain t = file_terrain(bytes, len, 3);
    t.file_name = "hostile.map";
    double extent;
    char err[512], want[256];
    assert_null(tf_heightmap_heights(&t, &extent, err, sizeof err));
    snprintf(want, sizeof want, "hostile.map: %s: %s", key, what);
    if (!strstr(err, want))
        fail_msg("%c %s = '%s': got \"%s\", want \"%s\"", format, key, value, err, want);
    assert_null(strchr(err, '\n'));
    free(bytes);
}

static void test_file_says_nonsense(void **state)
{
    (void)state;
    expect_refused('e', TF_RASTER_KEY_EXTENT, "abc", "'abc' is not a number in (0, 1e+09]");
    expect_refused('e', TF_RASTER_KEY_EXTENT, "0", "'0' is not a number in (0, 1e+09]");
    expect_refused('e', TF_RASTER_KEY_EXTENT, "1e10", "'1e10' is not a number");
    expect_refused('e', TF_RASTER_KEY_VERTICAL_OFFSET, "", "'' is not a number");
    expect_refused('p', TF_RASTER_KEY_FIRST_ROW, "sideways", "'sideways' is neither north");
    expect_refused('p', TF_RASTER_KEY_VERTICAL_SCALE, "2\x01x", "'2?x' is not a number");
    expect_refused('t', TF_RASTER_KEY_VERTICAL_SCALE, "nan", "'nan' is not a number");
    expect_refused('t', TF_RASTER_KEY_FIRST_ROW, "North", "'North' is neither north");
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_geographic_metres),
        cmocka_unit_test(test_rows_north_up_and_south_first),
        cmocka_unit_test(test_nodata),
        cmocka_unit_test(test_fill_single_sample),
        cmocka_unit_test(test_resample_shrink),
        cmocka_unit_test(test_file_says_orientation_extent_vertical),
        cmocka_unit_test(test_file_says_nonsense),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
