/* exrlayout.h: the shape of the render's OpenEXR output, as both sides of the farm must agree on
 * it: scanline or tiled, the tile size, the channel types, and from those the chunks a task's
 * rectangle consists of, their coordinates and their decoded ("unpacked") sizes.  No OpenEXR
 * calls here: plain arithmetic that the worker (which encodes its chunks, exrencode.h), the
 * coordinator (which checks a result's chunks against its task with no per-pixel work and writes
 * them raw, exrfile.h) and the farm's tuples (farmproto.h) share.
 *
 * The two kinds of file:
 *   scanline  (--tasks rows:K): ZIPS compression, one scanline per chunk; a chunk is named by
 *             its row y (cx = 0, cy = y).  A task of K rows is K chunks.
 *   tiled     (--tasks stamps:WxH): ZIP compression, one level, tiles of exactly the stamp size
 *             (edge tiles are partial, as OpenEXR defines them); a chunk is named by its tile
 *             indices (cx = x / tile_w, cy = y / tile_h).  A task is one tile.
 * Chunks are written in increasing y (tiles: row by row, left to right), which is OpenEXRCore's
 * chunk index order, so a file killed at any instant holds a valid prefix of chunks.
 *
 * Channels, sorted by name as OpenEXR stores them: A B G R (HALF with --pixel half, FLOAT with
 * --pixel float), Z and spp (always FLOAT).  One pixel unpacks to 16 bytes (half) or 24 (float).
 *
 * The preview grid: the progress preview is the image decimated by an integer factor f so that
 * neither side exceeds TF_PREVIEW_MAX_SIDE; preview pixel (i, j) shows image pixel
 * (min(i*f + f/2, W-1), min(j*f + f/2, H-1)), so every preview pixel belongs to exactly one task,
 * which computes it (tf_preview_span). */
#ifndef TF_EXRLAYOUT_H
#define TF_EXRLAYOUT_H

#include <stddef.h>
#include <stdint.h>

#include "image/pixel.h"

enum { TF_PIXEL_FLOAT = 0, TF_PIXEL_HALF = 1 };

#define TF_PREVIEW_MAX_SIDE 1024
/* Bound on the chunks one task may carry (a rows:K task of K rows is K chunks). */
#define TF_CHUNKS_PER_TASK_MAX 65536

typedef struct tf_exr_layout {
    int width, height;
    int tiled;           /* 0: scanline, 1 row per chunk; 1: tiles of tile_w x tile_h */
    int tile_w, tile_h;  /* tiled only */
    int pixel;           /* TF_PIXEL_HALF or TF_PIXEL_FLOAT: the type of R, G, B, A */
} tf_exr_layout;

/* One chunk of the file: its coordinates (see above), its pixels and decoded size. */
typedef struct tf_chunk_ref {
    int cx, cy;
    tf_rect rect;
    uint64_t unpacked;
} tf_chunk_ref;

/* A rectangle's encoded chunks, as a result tuple carries them (farmproto.h): `index` holds
 * nchunks records of TF_CHUNK_RECORD_BYTES, little-endian
 *     int32 cx, int32 cy, int64 packed bytes, int64 unpacked bytes
 * `chunks` the packed chunks concatenated in index order, `preview` the rectangle's preview
 * pixels (tf_preview_span), 3 bytes sRGB each, row-major. */
#define TF_CHUNK_RECORD_BYTES 24
typedef struct tf_chunk_rec {
    int32_t cx, cy;
    int64_t packed, unpacked;
} tf_chunk_rec;
void tf_chunk_rec_put(uint8_t *rec, const tf_chunk_rec *c);
void tf_chunk_rec_get(const uint8_t *rec, tf_chunk_rec *c);

typedef struct tf_chunk_payload {
    const uint8_t *index;
    size_t nchunks;
    const uint8_t *chunks;
    size_t chunks_len;
    const uint8_t *preview;
    size_t preview_len;
} tf_chunk_payload;

/* 0 if the layout is usable (sizes in range, tile sides >= 1), else -1 with a message. */
int tf_exr_layout_check(const tf_exr_layout *l, char *err, size_t errlen);
/* "half" / "float"; parse returns 0 or -1. */
const char *tf_pixel_type_name(int pixel);
int tf_pixel_type_parse(const char *s, int *pixel);
/* Text form for the scene tuple and messages: "scanline half" or "tiled 64x64 float". */
void tf_exr_layout_format(const tf_exr_layout *l, char *buf, size_t len);
/* Parse that text for an image of width x height; 0 or -1. */
int tf_exr_layout_parse(const char *s, int width, int height, tf_exr_layout *l);

/* Bytes of one decoded pixel: 16 (half) or 24 (float). */
int tf_layout_pixel_bytes(const tf_exr_layout *l);
/* Chunks across and down, and in all. */
int tf_layout_chunks_x(const tf_exr_layout *l);
int tf_layout_chunks_y(const tf_exr_layout *l);
int64_t tf_layout_chunk_count(const tf_exr_layout *l);
/* Chunk number `index` in file order (0 <= index < count). */
tf_chunk_ref tf_layout_chunk(const tf_exr_layout *l, int64_t index);
/* Index in file order of the chunk at (cx, cy), or -1 if there is none. */
int64_t tf_layout_chunk_index(const tf_exr_layout *l, int cx, int cy);
/* Rows entirely covered by the first `chunks` chunks in file order. */
int tf_layout_rows_in_chunks(const tf_exr_layout *l, int64_t chunks);

/* The chunks rectangle r consists of, in file order: their count, and the first one's index.
 * Returns 0, or -1 if r is not a union of whole chunks that follow each other in file order
 * (scanline: full-width rows; tiled: exactly one tile). */
int tf_layout_rect_chunks(const tf_exr_layout *l, tf_rect r, int64_t *first, int *count);

/* The preview grid. */
typedef struct tf_preview_grid {
    int factor;     /* image pixels per preview pixel, per side */
    int pw, ph;     /* preview size */
} tf_preview_grid;
tf_preview_grid tf_preview_grid_for(int width, int height);
/* Preview pixels [*i0, *i1) x [*j0, *j1) are those task rectangle r computes. */
void tf_preview_span(const tf_preview_grid *g, int width, int height, tf_rect r, int *i0,
                     int *i1, int *j0, int *j1);
/* The image pixel preview pixel i (or j) shows, along a side of `size` pixels. */
static inline int tf_preview_source(const tf_preview_grid *g, int i, int size)
{
    int64_t s = (int64_t)i * g->factor + g->factor / 2;
    return s < size ? (int)s : size - 1;
}

#endif
