/* raster_gdal.c: a height map in any self-contained raster format GDAL reads (GeoTIFF above
 * all; also Erdas Imagine, ASCII grids, SRTM .hgt, USGS DEM, netCDF, GeoPackage, JPEG 2000,
 * ...), decoded from memory through GDAL's /vsimem/ file system.  See raster.h.
 *
 * Band 1 is read as Float32 (Float32 rasters bit for bit); the band's nodata value, and NaN,
 * become nodata.  The georeferencing comes along: the geotransform, whether the CRS is
 * geographic (degrees) and the ellipsoid, or the projected CRS's linear unit; so do the
 * metadata items raster.h's TF_RASTER_KEY_* (terrafarm heightfield records them).
 *
 * Only drivers that read a single file are allowed (ALLOWED_DRIVERS): a VRT could make GDAL
 * open other files on this machine, and formats that need sidecar files would decode
 * differently on a networked worker, which has only the bytes. */
#include "terrain/raster.h"

#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "gdal_loader.h"
#include "log.h"

static const char *const ALLOWED_DRIVERS[] = {
    "GTiff", "COG", "HFA", "AAIGrid", "GSAG", "GSBG", "GS7BG", "SRTMHGT", "USGSDEM", "BT",
    "Terragen", "netCDF", "GPKG", "JP2OpenJPEG", "PNG", "GIF", "BMP", "JPEG", "XYZ",
    "NWT_GRD", "PCIDSK", "RMF", "KEA", "HDF5Image", "ERS", NULL};

static pthread_once_t options_once = PTHREAD_ONCE_INIT;

static void set_options(void)
{
    const tf_gdal *g = tf_gdal_load(NULL, 0);
    /* never list a directory or look for sidecars in /vsimem, never touch the network */
    g->CPLSetConfigOption("GDAL_DISABLE_READDIR_ON_OPEN", "EMPTY_DIR");
    g->CPLSetConfigOption("GDAL_HTTP_TIMEOUT", "1");
    g->CPLSetConfigOption("CPL_VSIL_CURL_ALLOWED_EXTENSIONS", "none");
}

/* Georeferencing of ds into r (has_georef stays 0 without a usable geotransform). */
static void read_georef(const tf_gdal *g, GDALDatasetH ds, tf_raster *r)
{
    double gt[6];
    if (g->GDALGetGeoTransform(ds, gt) != CE_None)
        return;
    /* GDAL's default (0, 1, 0, 0, 0, 1) means "no geotransform" */
    if (gt[0] == 0 && gt[1] == 1 && gt[2] == 0 && gt[3] == 0 && gt[4] == 0 && gt[5] == 1)
        return;
    memcpy(r->gt, gt, sizeof gt);
    r->has_georef = 1;
    r->unit_m = 1.0;
    OGRSpatialReferenceH srs = g->GDALGetSpatialRef(ds);
    if (!srs)
        return;
    if (g->OSRIsGeographic(srs)) {
        OGRErr e;
        r->geographic = 1;
        r->semi_major = g->OSRGetSemiMajor(srs, &e);
        if (e != OGRERR_NONE || !(r->semi_major > 0))
            r->semi_major = 6378137.0;
    } else if (g->OSRIsProjected(srs)) {
        double u = g->OSRGetLinearUnits(srs, NULL);
        if (u > 0)
            r->unit_m = u;
    }
}

/* The dataset's metadata items TF_RASTER_KEY_* (the GeoTIFF's GDAL_METADATA tag) into r->meta. */
static int read_meta(const tf_gdal *g, GDALDatasetH ds, const char *name, tf_raster *r,
                     char *err, size_t errlen)
{
    static const char *const keys[] = {TF_RASTER_KEY_FIRST_ROW, TF_RASTER_KEY_EXTENT,
                                       TF_RASTER_KEY_VERTICAL_SCALE,
                                       TF_RASTER_KEY_VERTICAL_OFFSET};
    for (size_t i = 0; i < sizeof keys / sizeof *keys; i++) {
        const char *v = g->GDALGetMetadataItem(ds, keys[i], NULL);
        if (v && tf_raster_meta_item(r, keys[i], v, name, err, errlen) != 0)
            return -1;
    }
    return 0;
}

/* GDAL's last message, on one line and without our /vsimem/ prefix: ": what", or "". */
static void last_gdal_message(const tf_gdal *g, char *out, size_t outlen, const char *vpath)
{
    const char *m = g->CPLGetLastErrorMsg();
    out[0] = '\0';
    if (!m || !*m || outlen < 8)
        return;
    size_t k = snprintf(out, outlen, ": ");
    size_t vlen = strlen(vpath);
    for (const char *c = m; *c && k + 1 < outlen && k < 170; c++) {
        if (strncmp(c, vpath, vlen) == 0) { /* "VPATH: " or "VPATH, ": said already */
            c += vlen - 1; /* the loop's c++ steps past the path */
            if ((c[1] == ':' || c[1] == ',') && c[2] == ' ')
                c += 2;
            continue;
        }
        out[k++] = (*c >= 0x20 && *c < 0x7f) ? *c : ' ';
    }
    out[k] = '\0';
}

/* The file's bytes as a private /vsimem file that keeps its base name (SRTMHGT reads it), its
 * path in vpath.  0, or -1 without memory. */
static int expose_in_memory(const tf_gdal *g, const uint8_t *data, size_t len, const char *name,
                            char *vpath, size_t vlen)
{
    static int counter;
    const char *base = strrchr(name, '/');
    base = base ? base + 1 : name;
    snprintf(vpath, vlen, "/vsimem/terrafarm-%ld-%d/%.120s", (long)getpid(),
             __atomic_add_fetch(&counter, 1, __ATOMIC_RELAXED), base);
    VSILFILE *f = g->VSIFileFromMemBuffer(vpath, (GByte *)data, (vsi_l_offset)len, FALSE);
    if (!f)
        return -1;
    g->VSIFCloseL(f);
    return 0;
}

/* Band 1 of ds as r's values: its nodata value and non-finite samples become NAN.  0, or -1
 * with err. */
static int read_band(const tf_gdal *g, GDALDatasetH ds, const char *name, const char *vpath,
                     tf_raster *r, char *err, size_t errlen)
{
    if (g->GDALGetRasterCount(ds) < 1)
        return tf_seterr(err, errlen, "%s: raster has no bands", name);
    int w = g->GDALGetRasterXSize(ds), h = g->GDALGetRasterYSize(ds);
    if (tf_raster_check_size(w, h, name, err, errlen) != 0)
        return -1;
    GDALRasterBandH band = g->GDALGetRasterBand(ds, 1);
    size_t count = (size_t)w * (size_t)h;
    r->v = malloc(count * sizeof *r->v);
    if (!r->v)
        return tf_seterr(err, errlen, "%s: out of memory for a %dx%d height map", name, w, h);
    if (g->GDALRasterIO(band, GF_Read, 0, 0, w, h, r->v, w, h, GDT_Float32, 0, 0) != CE_None) {
        char why[192];
        last_gdal_message(g, why, sizeof why, vpath);
        return tf_seterr(err, errlen, "%s: pixels do not decode (corrupt or truncated)%s", name,
                         why);
    }
    int has_nodata = 0;
    float nodata = (float)g->GDALGetRasterNoDataValue(band, &has_nodata);
    for (size_t i = 0; i < count; i++)
        if (!isfinite(r->v[i]) || (has_nodata && r->v[i] == nodata))
            r->v[i] = NAN;
    r->width = w;
    r->height = h;
    return 0;
}

int tf_raster_read_gdal(const uint8_t *data, size_t len, const char *name, tf_raster *r,
                        char *err, size_t errlen)
{
    memset(r, 0, sizeof *r);
    char why_not[224], vpath[256], why[192];
    const tf_gdal *g = tf_gdal_load(why_not, sizeof why_not);
    if (!g)
        return tf_seterr(err, errlen, "%s: neither PNG nor OpenEXR, and %s", name, why_not);
    pthread_once(&options_once, set_options);
    if (expose_in_memory(g, data, len, name, vpath, sizeof vpath))
        return tf_seterr(err, errlen, "%s: out of memory", name);
    g->CPLPushErrorHandler(g->CPLQuietErrorHandler);
    g->CPLErrorReset();
    GDALDatasetH ds = g->GDALOpenEx(vpath, GDAL_OF_RASTER | GDAL_OF_READONLY,
                                    (const char *const *)ALLOWED_DRIVERS, NULL, NULL);
    int rc = -1;
    if (!ds) {
        last_gdal_message(g, why, sizeof why, vpath);
        tf_seterr(err, errlen, "%s: not a raster image terrafarm can read (PNG, OpenEXR, or a "
                  "single-file format of GDAL's such as GeoTIFF)%s", name, why);
    } else if (read_band(g, ds, name, vpath, r, err, errlen) == 0) {
        read_georef(g, ds, r);
        rc = read_meta(g, ds, name, r, err, errlen) != 0 ? -1 : 0;
    }
    if (rc != 0) {
        free(r->v);
        r->v = NULL;
    }
    if (ds)
        g->GDALClose(ds);
    g->CPLPopErrorHandler();
    g->VSIUnlink(vpath);
    return rc;
}
