/* exrinternal.h: what the files behind exrfile.h share and nothing else includes: the header
 * attributes' names and the size limit, the error text (exrerror.c), the writer's hand-over of
 * its file to resume (exrwrite.c), and the reader that verifies chunks (exrread.c) for the
 * streams (exrstream.c) and resume (exrresume.c).  The output stream has its own header,
 * exrsink.h. */
#ifndef TF_EXRINTERNAL_H
#define TF_EXRINTERNAL_H

#include <openexr.h>
#include <stddef.h>
#include <stdint.h>

#include "image/exrfile.h"
#include "image/exrpart.h"

#define TF_EXR_ATTR_HASH "terrafarm.scene_hash"
#define TF_EXR_ATTR_SCENE "terrafarm.scene"
#define TF_EXR_ATTR_SETTINGS "terrafarm.settings"
#define TF_EXR_ATTR_VERSION "terrafarm.version"
#define TF_EXR_MAX_DIM 65536 /* refuse absurd sizes before allocating anything */

static inline int tf_exr_valid_size(int width, int height)
{
    return width > 0 && height > 0 && width <= TF_EXR_MAX_DIM && height <= TF_EXR_MAX_DIM;
}

/* exrerror.c: OpenEXRCore's error callback keeps its last detail per thread; clear it before
 * a step; tf_exr_set_error writes "PATH: what: detail" (detail from rv, if it failed). */
void tf_exr_remember_error(exr_const_context_t ctxt, exr_result_t code, const char *msg);
void tf_exr_clear_error(void);
void tf_exr_set_error(char *err, size_t errlen, const char *path, const char *what,
                      exr_result_t rv);

/* exrwrite.c: the writer's file was renamed to path (malloc'd; the writer takes it). */
void tf_exr_writer_take_path(tf_exr_writer *w, char *path);

/* exrread.c: an output open for reading, checked to be a terrafarm render. */
typedef struct tf_exr_reader {
    exr_context_t ctx;
    const char *path;
    int64_t file_size;
    tf_exr_meta meta;
    tf_exr_layout layout;
    const tf_exr_channel *channels;
    int nchannels;
    int64_t nchunks;
} tf_exr_reader;

/* 1 if path does not exist, 0 when open and checked, -1 with a message otherwise. */
int tf_exr_reader_open(tf_exr_reader *r, const char *path, char *err, size_t errlen);
void tf_exr_reader_close(tf_exr_reader *r);
/* Called for each verified chunk in order with its decoded pixels; nonzero stops the walk. */
typedef int (*tf_exr_visit_fn)(void *user, tf_exr_reader *r, const exr_chunk_info_t *cinfo,
                        const tf_chunk_ref *c, const tf_pixel *px);
/* Verify chunks from the first, at most `limit` of them; returns the number of leading whole,
 * decodable chunks, or -1 if fn failed or memory ran out (message in err). */
int64_t tf_exr_walk_chunks_upto(tf_exr_reader *r, int64_t limit, tf_exr_visit_fn fn,
                                void *user, char *err, size_t errlen);
/* The same walk handing fn each chunk's packed bytes as they are in the file too. */
int64_t tf_exr_walk_packed(tf_exr_reader *r, int64_t limit, tf_exr_packed_fn fn, void *user,
                           char *err, size_t errlen);
int64_t tf_exr_walk_chunks(tf_exr_reader *r, tf_exr_visit_fn fn, void *user, char *err,
                           size_t errlen);

#endif
