/* geotiff_write.c: see geotiff_write.h.  GDAL's GTiff driver, deflate-compressed with the
 * floating-point predictor (lossless), one Float32 band. */
#include "image/geotiff_write.h"

#include <gdal.h>
#include <cpl_conv.h>
#include <cpl_error.h>
#include <cpl_string.h>
#include <ogr_srs_api.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"

int tf_geotiff_write_heights(const char *path, int n, const float *h, double cell,
                             double east0, double north0, const char *srs,
                             const char *const *meta, char *err, size_t errlen)
{
    GDALAllRegister();
    GDALDriverH drv = GDALGetDriverByName("GTiff");
    if (!drv)
        return tf_seterr(err, errlen, "%s: this GDAL has no GTiff driver", path);
    CPLPushErrorHandler(CPLQuietErrorHandler);
    CPLErrorReset();
    char **opts = NULL;
    opts = CSLSetNameValue(opts, "COMPRESS", "DEFLATE");
    opts = CSLSetNameValue(opts, "PREDICTOR", "3");
    opts = CSLSetNameValue(opts, "TILED", "NO");
    GDALDatasetH ds = GDALCreate(drv, path, n, n, 1, GDT_Float32, opts);
    CSLDestroy(opts);
    int rc = -1;
    OGRSpatialReferenceH ref = NULL;
    if (!ds) {
        tf_seterr(err, errlen, "%s: cannot create: %s", path, CPLGetLastErrorMsg());
        goto out;
    }
    double gt[6] = {east0 - cell / 2, cell, 0, north0 + (n - 1) * cell + cell / 2, 0, -cell};
    if (GDALSetGeoTransform(ds, gt) != CE_None) {
        tf_seterr(err, errlen, "%s: cannot set the geotransform: %s", path, CPLGetLastErrorMsg());
        goto out;
    }
    if (srs) {
        ref = OSRNewSpatialReference(NULL);
        if (!ref || OSRSetFromUserInput(ref, srs) != OGRERR_NONE) {
            tf_seterr(err, errlen, "%s: --srs '%s': not a coordinate reference system GDAL "
                      "knows", path, srs);
            goto out;
        }
        if (GDALSetSpatialRef(ds, ref) != CE_None) {
            tf_seterr(err, errlen, "%s: cannot set the CRS: %s", path, CPLGetLastErrorMsg());
            goto out;
        }
    }
    for (int i = 0; meta && meta[i]; i += 2)
        if (GDALSetMetadataItem(ds, meta[i], meta[i + 1], NULL) != CE_None) {
            tf_seterr(err, errlen, "%s: cannot set metadata %s: %s", path, meta[i],
                      CPLGetLastErrorMsg());
            goto out;
        }
    GDALRasterBandH band = GDALGetRasterBand(ds, 1);
    for (int r = 0; r < n; r++) {
        const float *row = h + (size_t)(n - 1 - r) * (size_t)n; /* north first */
        if (GDALRasterIO(band, GF_Write, 0, r, n, 1, (void *)row, n, 1, GDT_Float32, 0, 0) !=
            CE_None) {
            tf_seterr(err, errlen, "%s: cannot write: %s", path, CPLGetLastErrorMsg());
            goto out;
        }
    }
    rc = 0;
out:
    if (ds) {
        CPLErrorReset();
        GDALClose(ds); /* flushes: a full disk shows here */
        if (rc == 0 && CPLGetLastErrorType() >= CE_Failure)
            rc = tf_seterr(err, errlen, "%s: cannot finish writing: %s", path,
                           CPLGetLastErrorMsg());
    }
    if (ref)
        OSRDestroySpatialReference(ref);
    CPLPopErrorHandler();
    return rc;
}
