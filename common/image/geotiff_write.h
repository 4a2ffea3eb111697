/* geotiff_write.h: a terrain's heights as a Float32 GeoTIFF (through GDAL), for terrafarm
 * heightfield -o FILE.tif: the same samples, bit for bit, with georeferencing, so any GIS tool
 * (and terrafarm's own generator = file) reads them in place. */
#ifndef TF_GEOTIFF_WRITE_H
#define TF_GEOTIFF_WRITE_H

#include <stddef.h>

/* Write the n x n heights h (row-major, row 0 = world y = 0, the south edge) north-up: the
 * file's first row is the north edge.  Sample (i, j) is the centre of its pixel, at easting
 * east0 + i * cell and northing north0 + j * cell, so the raster's corner lies half a cell
 * outside.  srs: anything GDAL's OSRSetFromUserInput takes ("EPSG:32632", WKT, PROJ), or NULL
 * for none.  meta: NULL, or dataset metadata items name, value, ..., NULL (GTiff keeps them in
 * its GDAL_METADATA tag).  Returns 0, or -1 with one line in err naming path. */
int tf_geotiff_write_heights(const char *path, int n, const float *h, double cell,
                             double east0, double north0, const char *srs,
                             const char *const *meta, char *err, size_t errlen);

#endif
