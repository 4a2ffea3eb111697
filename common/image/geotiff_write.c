/* geotiff_write.c: see geotiff_write.h.  GDAL's GTiff driver, deflate-compressed with the
 * floating-point predictor (lossless), one Float32 band. */
#include "image/geotiff_write.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdal_loader.h"
#include "log.h"

/* A new single-band Float32 GTiff at path, deflated with the floating-point predictor. */
static GDALDatasetH create_dataset(const tf_gdal *g, const char *path, int n, char *err,
                                   size_t errlen)
{
    GDALDriverH drv = g->GDALGetDriverByName("GTiff");
    if (!drv) {
        tf_seterr(err, errlen, "%s: this GDAL has no GTiff driver", path);
        return NULL;
    }
    char **opts = NULL;
    opts = g->CSLSetNameValue(opts, "COMPRESS", "DEFLATE");
    opts = g->CSLSetNameValue(opts, "PREDICTOR", "3");
    opts = g->CSLSetNameValue(opts, "TILED", "NO");
    GDALDatasetH ds = g->GDALCreate(drv, path, n, n, 1, GDT_Float32, opts);
    g->CSLDestroy(opts);
    if (!ds)
        tf_seterr(err, errlen, "%s: cannot create: %s", path, g->CPLGetLastErrorMsg());
    return ds;
}

/* The grid's place: the geotransform (sample centres on the cell lattice, north up) and, when
 * srs is given, the coordinate reference system. */
static int set_georeference(const tf_gdal *g, GDALDatasetH ds, const char *path, int n,
                            double cell, double east0, double north0, const char *srs,
                            char *err, size_t errlen)
{
    double gt[6] = {east0 - cell / 2, cell, 0, north0 + (n - 1) * cell + cell / 2, 0, -cell};
    if (g->GDALSetGeoTransform(ds, gt) != CE_None)
        return tf_seterr(err, errlen, "%s: cannot set the geotransform: %s", path,
                         g->CPLGetLastErrorMsg());
    if (!srs)
        return 0;
    int rc = 0;
    OGRSpatialReferenceH ref = g->OSRNewSpatialReference(NULL);
    if (!ref || g->OSRSetFromUserInput(ref, srs) != OGRERR_NONE)
        rc = tf_seterr(err, errlen, "%s: --srs '%s': not a coordinate reference system GDAL "
                       "knows", path, srs);
    else if (g->GDALSetSpatialRef(ds, ref) != CE_None)
        rc = tf_seterr(err, errlen, "%s: cannot set the CRS: %s", path, g->CPLGetLastErrorMsg());
    if (ref)
        g->OSRDestroySpatialReference(ref);
    return rc;
}

/* The metadata items (name, value pairs up to a NULL name) and the heights, north row first. */
static int write_contents(const tf_gdal *g, GDALDatasetH ds, const char *path, int n,
                          const float *h, const char *const *meta, char *err, size_t errlen)
{
    for (int i = 0; meta && meta[i]; i += 2)
        if (g->GDALSetMetadataItem(ds, meta[i], meta[i + 1], NULL) != CE_None)
            return tf_seterr(err, errlen, "%s: cannot set metadata %s: %s", path, meta[i],
                             g->CPLGetLastErrorMsg());
    GDALRasterBandH band = g->GDALGetRasterBand(ds, 1);
    for (int r = 0; r < n; r++) {
        const float *row = h + (size_t)(n - 1 - r) * (size_t)n; /* north first */
        if (g->GDALRasterIO(band, GF_Write, 0, r, n, 1, (void *)row, n, 1, GDT_Float32, 0, 0) !=
            CE_None)
            return tf_seterr(err, errlen, "%s: cannot write: %s", path, g->CPLGetLastErrorMsg());
    }
    return 0;
}

int tf_geotiff_write_heights(const char *path, int n, const float *h, double cell,
                             double east0, double north0, const char *srs,
                             const char *const *meta, char *err, size_t errlen)
{
    char why_not[224];
    const tf_gdal *g = tf_gdal_load(why_not, sizeof why_not);
    if (!g)
        return tf_seterr(err, errlen, "%s: a GeoTIFF is written by GDAL, and %s", path, why_not);
    g->CPLPushErrorHandler(g->CPLQuietErrorHandler);
    g->CPLErrorReset();
    int rc = -1;
    GDALDatasetH ds = create_dataset(g, path, n, err, errlen);
    if (ds && set_georeference(g, ds, path, n, cell, east0, north0, srs, err, errlen) == 0 &&
        write_contents(g, ds, path, n, h, meta, err, errlen) == 0)
        rc = 0;
    if (ds) {
        g->CPLErrorReset();
        g->GDALClose(ds); /* flushes: a full disk shows here */
        if (rc == 0 && g->CPLGetLastErrorType() >= CE_Failure)
            rc = tf_seterr(err, errlen, "%s: cannot finish writing: %s", path,
                           g->CPLGetLastErrorMsg());
    }
    g->CPLPopErrorHandler();
    return rc;
}
