/* heightmap_file.h: generator = file: the terrain's heights from a height map raster (PNG,
 * OpenEXR, GeoTIFF or another GDAL format; raster.h), cropped, with nodata filled or made sea,
 * scaled to world heights and resampled onto the (2^k+1)^2 grid the tracer needs.  How, in
 * heightmap_file.c and scenes/README.md. */
#ifndef TF_HEIGHTMAP_FILE_H
#define TF_HEIGHTMAP_FILE_H

#include <stddef.h>
#include "scene.h"

/* The n * n world heights (n = 2^t->size_exp + 1, row-major, row 0 at world y = 0, the south
 * edge) of the height map in t->file_bytes, and in *extent the world size of a side: t->extent
 * if above 0, else from the raster's georeferencing (metres), else one unit per pixel.
 * Returns a malloc'd array, or NULL with one line in err naming the file. */
float *tf_heightmap_heights(const tf_terrain *t, double *extent, char *err, size_t errlen);

#endif
