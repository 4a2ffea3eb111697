/* gdal_loader.h: GDAL, loaded the first time a raster needs it.
 *
 * libgdal pulls in about a hundred libraries (PROJ, HDF5, netCDF, poppler, libheif, ...) whose
 * loading and relocation took ~35 ms of every terrafarm process's start, a forked worker's and
 * `terrafarm --version`'s alike, though few runs read or write a GeoTIFF.  So bin/terrafarm is
 * not linked against it: tf_gdal_load() dlopen()s the library the build compiled against (its
 * soname, which the Makefile reads with readelf from the libgdal.so the compiler finds) on
 * first use, and the callers reach every GDAL function through the table it returns, by its
 * own name: g->GDALOpenEx(...).  A machine without GDAL (a networked worker's, say) runs
 * everything but the GDAL formats, which fail with one line naming the library.
 *
 * TERRAFARM_GDAL, if set, names the library to load instead (a path or a soname; it must be
 * the same GDAL ABI the build used): for a GDAL installed elsewhere, and for the test that
 * proves the missing-library error. */
#ifndef TF_GDAL_LOADER_H
#define TF_GDAL_LOADER_H

#include <stddef.h>

#include <gdal.h>
#include <cpl_conv.h>
#include <cpl_error.h>
#include <cpl_string.h>
#include <cpl_vsi.h>
#include <ogr_srs_api.h>

/* Every GDAL function terrafarm calls. */
#define TF_GDAL_FUNCTIONS(X)                                                                     \
    X(GDALAllRegister) X(GDALOpenEx) X(GDALClose) X(GDALCreate) X(GDALGetDriverByName)           \
    X(GDALGetRasterCount) X(GDALGetRasterXSize) X(GDALGetRasterYSize) X(GDALGetRasterBand)       \
    X(GDALRasterIO) X(GDALGetRasterNoDataValue) X(GDALGetGeoTransform) X(GDALSetGeoTransform)    \
    X(GDALGetSpatialRef) X(GDALSetSpatialRef) X(GDALGetMetadataItem) X(GDALSetMetadataItem)      \
    X(OSRNewSpatialReference) X(OSRDestroySpatialReference) X(OSRSetFromUserInput)               \
    X(OSRIsGeographic) X(OSRIsProjected) X(OSRGetSemiMajor) X(OSRGetLinearUnits)                 \
    X(CPLSetConfigOption) X(CPLPushErrorHandler) X(CPLPopErrorHandler) X(CPLQuietErrorHandler)   \
    X(CPLErrorReset) X(CPLGetLastErrorMsg) X(CPLGetLastErrorType) X(CSLSetNameValue)             \
    X(CSLDestroy) X(VSIFileFromMemBuffer) X(VSIFCloseL) X(VSIUnlink)

/* The table: one pointer a function, named as the function is. */
typedef struct tf_gdal {
#define TF_GDAL_MEMBER(name) __typeof__(name) *name;
    TF_GDAL_FUNCTIONS(TF_GDAL_MEMBER)
#undef TF_GDAL_MEMBER
} tf_gdal;

/* GDAL, loaded and its drivers registered on the first call (thread-safe); NULL, with one line
 * in err naming the library and why it did not load, when it cannot be had. */
const tf_gdal *tf_gdal_load(char *err, size_t errlen);

#endif
