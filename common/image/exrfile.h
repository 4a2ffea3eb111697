/* exrfile.h: the render's output and checkpoint, an OpenEXR file written through OpenEXRCore
 * (openexr.h): a scanline file (one row per chunk) or a tiled one, with the channels and
 * compression of its layout (exrlayout.h, exrpart.h).
 *
 * The coordinator writes chunks that workers packed (tf_exr_write_chunk: OpenEXRCore's raw
 * exr_write_scanline_chunk / exr_write_tile_chunk, no pixel is touched); tf_exr_write_rows
 * encodes rows in-process (tests, the height-field export).
 * Header attributes: terrafarm.scene_hash (SHA-256 hex of the canonical scene,
 * which includes the image size), terrafarm.scene (scene file name), terrafarm.settings
 * (render settings that affect pixels), terrafarm.version.
 *
 * The writer appends whole chunks in file order (increasing y) through a custom write function on our own
 * file descriptor, so tf_exr_sync can fsync and so a killed process leaves a file whose chunks
 * up to the last whole one are valid: OpenEXRCore rebuilds the offset table of such a file from
 * the chunk headers when reading it.  tf_exr_resume reads such a partial file, verifies each
 * chunk (a torn last chunk is dropped, never trusted), copies the good chunks into a new file
 * beside it, makes that durable and renames it over the original: at every instant the output
 * path holds either the old partial file or the new one, never less. */
#ifndef TF_EXRFILE_H
#define TF_EXRFILE_H

#include <stddef.h>
#include <stdint.h>

#include "image/exrlayout.h"
#include "image/pixel.h"

typedef struct tf_exr_meta {
    int width, height;
    int tiled, tile_w, tile_h;  /* the layout (exrlayout.h); zero: scanline */
    int pixel;                  /* TF_PIXEL_FLOAT (0) or TF_PIXEL_HALF */
    char scene_hash[65];  /* hex */
    char scene_name[256];
    char settings[256];
} tf_exr_meta;

typedef struct tf_exr_writer tf_exr_writer;

/* The layout a meta describes. */
tf_exr_layout tf_exr_meta_layout(const tf_exr_meta *m);

/* Rows per chunk of a scanline file (ZIPS: 1). */
int tf_exr_chunk_rows(void);

/* Create (truncate) path and write the header.  The caller decides whether overwriting is
 * allowed (see tf_exr_probe). */
tf_exr_writer *tf_exr_create(const char *path, const tf_exr_meta *meta, char *err, size_t errlen);

/* Append nrows rows starting at tf_exr_next_row(w), encoding them here.  nrows must be a whole
 * number of chunk rows (tiled: of tile rows), or reach the last row of the image.  px holds
 * width * nrows pixels, row-major.  Only at a chunk-row boundary (tf_exr_next_chunk). */
int tf_exr_write_rows(tf_exr_writer *w, int nrows, const tf_pixel *px, char *err, size_t errlen);
/* Rows entirely written, and the index (file order) of the next chunk to write. */
int tf_exr_next_row(const tf_exr_writer *w);
int64_t tf_exr_next_chunk(const tf_exr_writer *w);
/* Write chunk (cx, cy) -- which must be tf_exr_next_chunk in file order -- from its packed
 * bytes, untouched (OpenEXRCore's raw chunk write).  0, or -1 with a message. */
int tf_exr_write_chunk(tf_exr_writer *w, int cx, int cy, const void *packed, size_t len,
                       char *err, size_t errlen);
/* Hand what the write-behind buffer holds to the file (one pwritev, or whole blocks O_DIRECT;
 * no fsync), and let go of every reference to the caller's chunks.  tf_exr_write_chunk buffers:
 * the coordinator flushes when its queue of results runs dry, so results that come together
 * cost one write.  On the direct path the last part block (under 4 KB) reaches the file only
 * with the next tf_exr_sync, tf_exr_finish or tf_exr_abandon (or as part of a later block): a
 * kill between them tears the last chunk, which a resume renders again.  0 or -1. */
int tf_exr_flush(tf_exr_writer *w, char *err, size_t errlen);
/* With hold on, tf_exr_write_chunk keeps a reference to large packed chunks instead of
 * copying them into the buffer, and the caller keeps that memory alive and unchanged until
 * the next tf_exr_flush, tf_exr_sync or tf_exr_finish -- which it must call before freeing it
 * whenever tf_exr_holds_references says so.  Off by default. */
void tf_exr_hold_chunks(tf_exr_writer *w, int on);
int tf_exr_holds_references(const tf_exr_writer *w);
/* Make everything written so far durable (flush and fsync). */
int tf_exr_sync(tf_exr_writer *w, char *err, size_t errlen);
/* All rows written: finish the file (offset table), fsync, close, free. */
int tf_exr_finish(tf_exr_writer *w, char *err, size_t errlen);
/* Close without finishing: the file stays a resumable partial render.  Frees w. */
void tf_exr_abandon(tf_exr_writer *w);

/* What is at path?  Returns 1 if no file exists; 0 if it is a terrafarm EXR (fills meta,
 * *rows_done = rows in whole verified chunks, *complete = 1 if every row is there); -1 if it
 * exists but is not a terrafarm EXR we can resume (message in err).  A file killed after its
 * last chunk but before tf_exr_finish has every row but no offset table: it reports
 * *complete = 0 (and rows_done = height), so it is resumed and finished, not taken as done. */
int tf_exr_probe(const char *path, tf_exr_meta *meta, int *rows_done, int *complete, char *err,
                 size_t errlen);
/* The same, counting whole verified chunks in file order (a tiled file may hold part of a tile
 * row). */
int tf_exr_probe_chunks(const char *path, tf_exr_meta *meta, int64_t *chunks_done,
                        int *complete, char *err, size_t errlen);

/* Continue a partial render.  Fails (and modifies nothing on disk) if the file's meta differs
 * from `expect` (scene, size, settings, layout), naming what differs.  On success *rows_done
 * is the number of whole rows on disk; tf_exr_next_chunk(w) says which chunk comes next. */
tf_exr_writer *tf_exr_resume(const char *path, const tf_exr_meta *expect, int *rows_done,
                             char *err, size_t errlen);
/* The same, keeping at most the first keep_chunks chunks of the file: the chunks after them are
 * dropped as a torn tail would be (the new prefix is made beside and renamed over PATH, so PATH
 * is at every instant the old partial or the shorter one).  --verify uses it to take back
 * chunks a liar wrote (coordinator/render/supervisor_verify.c, rewind_liar). */
tf_exr_writer *tf_exr_resume_prefix(const char *path, const tf_exr_meta *expect,
                                    int64_t keep_chunks, int *rows_done, char *err, size_t errlen);

/* Read back rows [0, *rows_valid) of a (possibly partial) file, chunk row by chunk row, calling
 * fn(user, y, row_pixels) for each row in order.  *meta is filled before the first call, so fn
 * may size its output from it.  A nonzero return from fn stops reading (returns -1).
 * Returns 0 on success. */
typedef int (*tf_exr_row_fn)(void *user, int y, const tf_pixel *row);
int tf_exr_read_rows(const char *path, tf_exr_meta *meta, int *rows_valid, tf_exr_row_fn fn,
                     void *user, char *err, size_t errlen);

/* Read back every verified chunk of a (possibly partial) file in file order, calling
 * fn(user, rect, px) with the chunk's rectangle and its decoded pixels (rect.w * rect.h).  *meta
 * is filled first; *chunks_valid is the verified prefix.  0 or -1. */
typedef int (*tf_exr_chunk_fn)(void *user, tf_rect rect, const tf_pixel *px);
int tf_exr_read_chunks(const char *path, tf_exr_meta *meta, int64_t *chunks_valid,
                       tf_exr_chunk_fn fn, void *user, char *err, size_t errlen);

/* The same walk, also handing over each chunk's packed bytes as they are in the file (for a
 * recording of real chunks: worker/payloads.h). */
typedef int (*tf_exr_packed_fn)(void *user, const tf_chunk_ref *chunk, const uint8_t *packed,
                                size_t len, const tf_pixel *px);
int tf_exr_read_packed_chunks(const char *path, tf_exr_meta *meta, int64_t *chunks_valid,
                              tf_exr_packed_fn fn, void *user, char *err, size_t errlen);

/* Write a single-channel FLOAT image (channel "Y"), e.g. height field export. */
int tf_exr_write_gray(const char *path, int width, int height, const float *data, char *err,
                      size_t errlen);
/* The same with string attributes in its header: attrs is NULL or name, value, ..., NULL. */
int tf_exr_write_gray_attrs(const char *path, int width, int height, const float *data,
                            const char *const *attrs, char *err, size_t errlen);
/* Several FLOAT channels, plane c named names[c] (the names sorted, as OpenEXR lists them),
 * with string attributes as above: a height field with its erosion maps. */
int tf_exr_write_planes(const char *path, int width, int height, const char *const *names,
                        const float *const *planes, int nplanes, const char *const *attrs,
                        char *err, size_t errlen);

#endif
