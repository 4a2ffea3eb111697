/* png_write.c: see png_write.h.  libpng reports errors by longjmp; every libpng call here sits
 * behind the setjmp in the function that makes it.  The bytes go out through a tf_directfile
 * (directfile.h): the preview the coordinator rewrites every few seconds bypasses the page
 * cache, whose fresh pages cost more than the copy on a virtual machine. */
#include "image/png_write.h"

#include <png.h>
#include <errno.h>
#include <setjmp.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "directfile.h"
#include "log.h"

struct tf_png_writer {
    tf_directfile file; /* fd -1 when not open */
    png_structp png;
    png_infop info;
    int width, height, depth, channels, rows;
    uint8_t *swap;      /* row in network byte order for 16-bit */
    char *path, *tmp;
};

static void free_writer(tf_png_writer *w, int remove_tmp)
{
    if (!w)
        return;
    if (w->png)
        png_destroy_write_struct(&w->png, &w->info);
    tf_directfile_discard(&w->file);
    if (remove_tmp && w->tmp)
        remove(w->tmp);
    free(w->swap);
    free(w->path);
    free(w->tmp);
    free(w);
}

/* libpng's own handlers print to stderr; ours stay quiet (the caller reports one line) and
 * return through the setjmp, as libpng requires of an error handler. */
static void quiet_png_error(png_structp png, png_const_charp msg)
{
    (void)msg;
    png_longjmp(png, 1);
}

static void quiet_png_warning(png_structp png, png_const_charp msg)
{
    (void)png;
    (void)msg;
}

/* libpng's output: the direct file (its first errno is kept for the caller's message). */
static void write_bytes(png_structp png, png_bytep data, size_t n)
{
    tf_png_writer *w = png_get_io_ptr(png);
    if (tf_directfile_write(&w->file, data, n) != 0)
        png_longjmp(png, 1);
}

static void flush_nothing(png_structp png) { (void)png; }

/* One line for a failed libpng call: the file's errno when a write failed under it, else what
 * libpng was doing. */
static void png_failure(const tf_png_writer *w, const char *what, char *err, size_t errlen)
{
    if (w->file.err)
        tf_seterr(err, errlen, "%s: write failed: %s", w->tmp, strerror(w->file.err));
    else
        tf_seterr(err, errlen, "%s: %s", w->path, what);
}

/* A writer with its buffers and PATH.tmp created, libpng not started; NULL and a message. */
static tf_png_writer *new_writer(const char *path, int width, int height, int bit_depth,
                                 int channels, char *err, size_t errlen)
{
    tf_png_writer *w = calloc(1, sizeof *w);
    if (!w) {
        tf_seterr(err, errlen, "%s: out of memory", path);
        return NULL;
    }
    w->file.fd = -1;
    w->width = width;
    w->height = height;
    w->depth = bit_depth;
    w->channels = channels;
    w->path = strdup(path);
    w->tmp = malloc(strlen(path) + 5);
    w->swap = malloc((size_t)width * (size_t)channels * 2);
    if (!w->path || !w->tmp || !w->swap) {
        tf_seterr(err, errlen, "%s: out of memory", path);
        free_writer(w, 0);
        return NULL;
    }
    sprintf(w->tmp, "%s.tmp", path);
    if (tf_directfile_create(&w->file, w->tmp) != 0) {
        tf_seterr(err, errlen, "%s: cannot create: %s", w->tmp, strerror(errno));
        free_writer(w, 0);
        return NULL;
    }
    return w;
}

/* libpng started on w's file and the header written (IHDR, sRGB for 8-bit colour).  0, or -1
 * with a message (the caller frees w, its temporary file removed). */
static int start_png(tf_png_writer *w, char *err, size_t errlen)
{
    w->png =
        png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, quiet_png_error, quiet_png_warning);
    w->info = w->png ? png_create_info_struct(w->png) : NULL;
    if (!w->info)
        return tf_seterr(err, errlen, "%s: libpng initialisation failed", w->path);
    if (setjmp(png_jmpbuf(w->png)))
        return tf_seterr(err, errlen, "%s: libpng error writing header", w->path);
    png_set_write_fn(w->png, w, write_bytes, flush_nothing);
    /* zlib level 3: the coordinator streams the preview of every render it writes; level 6
     * (the default) costs it about twice the CPU for a file a few percent smaller. */
    png_set_compression_level(w->png, 3);
    png_set_IHDR(w->png, w->info, (png_uint_32)w->width, (png_uint_32)w->height, w->depth,
                 w->channels == 1 ? PNG_COLOR_TYPE_GRAY : PNG_COLOR_TYPE_RGB,
                 PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    if (w->channels == 3 && w->depth == 8)
        png_set_sRGB(w->png, w->info, PNG_sRGB_INTENT_PERCEPTUAL);
    png_write_info(w->png, w->info);
    return 0;
}

tf_png_writer *tf_png_create(const char *path, int width, int height, int bit_depth, int channels,
                             char *err, size_t errlen)
{
    if ((bit_depth != 8 && bit_depth != 16) || (channels != 1 && channels != 3) || width <= 0 ||
        height <= 0) {
        tf_seterr(err, errlen, "%s: unsupported PNG format %dx%d depth %d channels %d", path, width,
                 height, bit_depth, channels);
        return NULL;
    }
    tf_png_writer *w = new_writer(path, width, height, bit_depth, channels, err, errlen);
    if (w && start_png(w, err, errlen) != 0) {
        free_writer(w, 1);
        return NULL;
    }
    return w;
}

void tf_png_fast(tf_png_writer *w, int level)
{
    if (setjmp(png_jmpbuf(w->png)))
        return;
    png_set_compression_level(w->png, level);
    png_set_filter(w->png, PNG_FILTER_TYPE_BASE, PNG_FILTER_NONE);
}

int tf_png_text(tf_png_writer *w, const char *key, const char *value, char *err,
                size_t errlen)
{
    png_text t = {.compression = PNG_TEXT_COMPRESSION_NONE, .key = (char *)key,
                  .text = (char *)value, .text_length = strlen(value)};
    if (setjmp(png_jmpbuf(w->png)))
        return tf_seterr(err, errlen, "%s: libpng refuses the text chunk %s", w->path, key);
    png_set_text(w->png, w->info, &t, 1);
    return 0;
}

/* The setjmp lives here, apart from the caller's locals, so nothing live across it changes. */
static int write_raw_row(tf_png_writer *w, png_const_bytep src)
{
    if (setjmp(png_jmpbuf(w->png)))
        return -1;
    png_write_row(w->png, src);
    return 0;
}

int tf_png_write_row(tf_png_writer *w, const void *row, char *err, size_t errlen)
{
    if (w->rows >= w->height) {
        tf_seterr(err, errlen, "%s: more rows than the image height %d", w->path, w->height);
        return -1;
    }
    const uint8_t *src = row;
    if (w->depth == 16) {
        const uint16_t *s16 = row;
        size_t count = (size_t)w->width * (size_t)w->channels;
        for (size_t i = 0; i < count; i++) {
            w->swap[2 * i] = (uint8_t)(s16[i] >> 8);
            w->swap[2 * i + 1] = (uint8_t)(s16[i] & 0xff);
        }
        src = w->swap;
    }
    if (write_raw_row(w, src) != 0) {
        char what[64];
        snprintf(what, sizeof what, "libpng error writing row %d", w->rows);
        png_failure(w, what, err, errlen);
        return -1;
    }
    w->rows++;
    return 0;
}

int tf_png_finish(tf_png_writer *w, char *err, size_t errlen)
{
    if (w->rows != w->height) {
        tf_seterr(err, errlen, "%s: only %d of %d rows written", w->path, w->rows, w->height);
        free_writer(w, 1);
        return -1;
    }
    if (setjmp(png_jmpbuf(w->png))) {
        png_failure(w, "libpng error finishing the file", err, errlen);
        free_writer(w, 1);
        return -1;
    }
    png_write_end(w->png, w->info);
    png_destroy_write_struct(&w->png, &w->info);
    w->png = NULL;
    int bad = tf_directfile_close(&w->file) != 0;
    if (bad) {
        tf_seterr(err, errlen, "%s: write failed: %s", w->tmp, strerror(errno));
        free_writer(w, 1);
        return -1;
    }
    if (rename(w->tmp, w->path) != 0) {
        tf_seterr(err, errlen, "%s: cannot rename into place: %s", w->path, strerror(errno));
        free_writer(w, 1);
        return -1;
    }
    free_writer(w, 0);
    return 0;
}

void tf_png_abort(tf_png_writer *w) { free_writer(w, 1); }
