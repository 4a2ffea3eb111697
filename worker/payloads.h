/* payloads.h: recorded results for simulated workers (worker/simulate.h).  A simulated worker
 * must send what a real one sends -- chunks of real pixels, packed as the real encoder packs
 * them, so the coordinator receives, checks and writes bytes of the true size and
 * compressibility -- without the CPU of rendering or encoding on the machine that hosts a
 * thousand of them.  The recording is simply a finished render of a real scene (any
 * `terrafarm render` output): its packed chunks are loaded once, as they are in the file.
 *
 * A task of the simulated render is answered with the recorded chunks at the same relative
 * position in the recorded image (chunk (cx, cy) of a render with NX x NY chunks takes the
 * recorded chunk (cx * RX / NX, cy * RY / NY)), so the horizon's incompressible detail and the
 * sky's flat colour land where they would.  A chunk must find a recorded chunk of the same size:
 * the recording needs the render's layout (scanline of the same width, or the same tile size)
 * and pixel type; edge chunks of another size are refused with a message.  The preview share
 * is sampled from the recording's decoded pixels, kept as 8-bit sRGB. */
#ifndef TF_PAYLOADS_H
#define TF_PAYLOADS_H

#include <stddef.h>
#include <stdint.h>

#include "image/exrlayout.h"

typedef struct tf_payloads tf_payloads;

/* Load every chunk of the finished render at path.  NULL with a message. */
tf_payloads *tf_payloads_load(const char *path, char *err, size_t errlen);
void tf_payloads_free(tf_payloads *p);
/* Does the recording fit renders of layout l?  0, or -1 with a message. */
int tf_payloads_fit(const tf_payloads *p, const tf_exr_layout *l, char *err, size_t errlen);

/* A per-thread builder of payloads (buffers reused from task to task). */
typedef struct tf_payload_buf {
    uint8_t *index, *chunks, *preview;
    size_t index_cap, chunks_cap, preview_cap;
} tf_payload_buf;
/* The payload for task rectangle r of a render of layout l: recorded chunks and a preview
 * share of the right size; *spp_total from the recorded chunks.  0, or -1 with a message. */
int tf_payloads_for(const tf_payloads *p, const tf_exr_layout *l, tf_rect r, tf_payload_buf *b,
                    tf_chunk_payload *out, int64_t *spp_total, char *err, size_t errlen);
void tf_payload_buf_free(tf_payload_buf *b);

#endif
