/* exrpart.h: the one definition of the render output's OpenEXR part (channels and their types,
 * compression and its zlib level, line order, tiles) for a tf_exr_layout.  The coordinator's
 * file writer (exrwrite.c) and every worker's chunk encoder (exrencode.c) build their contexts
 * with it, so a chunk a worker packs is exactly the chunk the file's header describes. */
#ifndef TF_EXRPART_H
#define TF_EXRPART_H

#include <openexr.h>
#include <stddef.h>

#include "image/exrlayout.h"

/* Deflate level 1 (libdeflate's, exrzip.h; zlib's before), not the default 6: on float pixels
 * zlib's level 6 bought 1.4% of file size for 13% more CPU (alps.scene 1920x640).  Any level
 * reads back the same; a resumed file may mix levels. */
#define TF_EXR_ZIP_LEVEL 1

/* How one channel of the part maps onto a caller's pixel struct. */
typedef struct tf_exr_channel {
    const char *name;
    size_t offset;        /* byte offset of the float inside one caller pixel */
    exr_pixel_type_t type;
} tf_exr_channel;

/* The six channels of a terrafarm render for this pixel type, sorted by name (A B G R Z spp),
 * as offsets into a tf_pixel.  *n = 6. */
const tf_exr_channel *tf_exr_render_channels(int pixel, int *n);
/* The channel called name in map, or NULL. */
const tf_exr_channel *tf_exr_find_channel(const tf_exr_channel *map, int n, const char *name);
/* Compression of a layout's part: ZIPS (one scanline per chunk) or ZIP (tiles). */
exr_compression_t tf_exr_layout_compression(const tf_exr_layout *l);

/* Add part 0 to a fresh write context: storage, data window, compression and level, line
 * order, tile description and the channels.  Returns OpenEXRCore's result. */
exr_result_t tf_exr_define_part(exr_context_t ctx, const tf_exr_layout *l,
                                const tf_exr_channel *channels, int nchannels);

/* Start encoding chunk c of part 0: its chunk info, the encode pipeline initialised, each
 * channel pointed at its float in the caller's pixels (origin: the chunk's top-left pixel;
 * pixels pixel_bytes and rows line_bytes apart), the default routines chosen.  Returns
 * OpenEXRCore's result; enc is to be destroyed (exr_encoding_destroy) either way. */
exr_result_t tf_exr_begin_chunk(exr_context_t ctx, const tf_exr_layout *l,
                                const tf_chunk_ref *c, const tf_exr_channel *channels,
                                int nchannels, const uint8_t *origin, size_t pixel_bytes,
                                size_t line_bytes, exr_encode_pipeline_t *enc);

#endif
