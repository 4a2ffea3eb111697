/* fuzz_eroded.c: libFuzzer harness for an eroded terrain as a networked worker receives it
 * (terrain/eroded.h; heightmap_tuples.h carries it): a blob whose values the input chooses,
 * framed and checksummed as a hostile sender would (the right magic, grid side and key, its
 * own SHA-256), attached to an [erosion] scene; the height field is built from it and a 4x3
 * image rendered.  Besides "no crash, leak or hang" it checks the promise of eroded.h: a
 * refusal is one non-empty line, and a blob accepted has finite heights and finite water,
 * silt and flow >= 0.  (The pixels of hostile but finite heights are not checked: a worker
 * refuses to send a non-finite one, worker.c.)
 *
 * Input: byte 0 picks the grid (size_exp 1..3: 3, 5 or 9 samples a side), byte 1 what to get
 * wrong (bit 0 the checksum, bit 1 the key, bit 2 the length, bit 3 the grid side); the rest
 * fills the four maps' floats (little-endian, cycled; none: all zero).
 * Built by `make build/fuzz/fuzz_eroded` (clang libFuzzer) and replayed over
 * tests/corpus/eroded/ by `make test`. */
#include <math.h>
#include <sodium.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"
#include "render/render.h"
#include "scene.h"
#include "terrain/eroded.h"
#include "terrain/heightfield.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

enum { MAPS = 4, HEADER = 8 + 32 + 4 + 8 + 4, SUM = 32 };

static tf_scene *eroded_scene(int size_exp)
{
    char text[512], err[256];
    int len = snprintf(text, sizeof text,
                       "[image]\nwidth = 4\nheight = 3\n"
                       "[camera]\nposition = 500 -400 300\nlook_at = 500 500 0\n"
                       "[terrain]\ngenerator = fbm\nseed = 3\nsize_exp = %d\nextent = 1000\n"
                       "[erosion]\nfluvial_steps = 10\n",
                       size_exp);
    tf_scene *s = tf_scene_parse_text("fuzz_eroded", text, (size_t)len, err, sizeof err);
    if (!s)
        abort(); /* the harness's own scene must parse */
    return s;
}

static void put_le32(uint8_t *p, uint32_t v)
{
    for (int i = 0; i < 4; i++)
        p[i] = (uint8_t)(v >> (8 * i));
}

/* The blob eroded.h describes, its maps' bytes from the input, framed for the scene's terrain
 * and spoiled where `wrong` says.  *len its length. */
static uint8_t *hostile_blob(const tf_terrain *t, int n, const uint8_t *fill, size_t nfill,
                             unsigned wrong, size_t *len)
{
    const size_t body = (size_t)MAPS * (size_t)n * (size_t)n * 4;
    *len = HEADER + body + SUM;
    uint8_t *b = calloc(1, *len);
    if (!b)
        abort();
    memcpy(b, "TFERODE1", 8);
    tf_eroded_key(t, b + 8);
    if (wrong & 2)
        b[8] ^= 1;
    put_le32(b + 40, (uint32_t)n + ((wrong & 8) ? 2u : 0u));
    double extent = t->extent;
    memcpy(b + 44, &extent, 8); /* host order = little-endian on every machine this runs on */
    put_le32(b + 52, (uint32_t)t->erosion.fluvial_steps);
    for (size_t i = 0; nfill > 0 && i < body; i++)
        b[HEADER + i] = fill[i % nfill];
    crypto_hash_sha256(b + *len - SUM, b, *len - SUM);
    if (wrong & 1)
        b[*len - 1] ^= 0x80;
    if (wrong & 4)
        (*len)--;
    return b;
}

/* eroded.h's promise for a blob it accepted. */
static void check_accepted(const tf_terrain *t, int n, const uint8_t *blob, size_t len)
{
    float *h = malloc(sizeof *h * (size_t)n * (size_t)n);
    tf_eroded_maps maps = {NULL, NULL, NULL};
    char err[256] = "";
    if (!h)
        abort();
    if (tf_eroded_parse(t, n, blob, len, "fuzz", h, &maps, err, sizeof err) == 0) {
        for (int i = 0; i < n * n; i++)
            if (!isfinite(h[i]) || !(maps.water[i] >= 0) || !isfinite(maps.water[i]) ||
                !(maps.silt[i] >= 0) || !isfinite(maps.silt[i]) || !(maps.flow[i] >= 0) ||
                !isfinite(maps.flow[i]))
                abort(); /* accepted a value no erosion writes */
        tf_eroded_maps_free(&maps);
    } else if (!err[0] || strchr(err, '\n')) {
        abort();
    }
    free(h);
}

/* A worker's use of it: the height field built (the blob checked again there) and rendered. */
static void build_and_render(tf_scene *s)
{
    char err[256] = "";
    tf_heightfield *hf = tf_heightfield_build(s, 1, err, sizeof err);
    if (!hf) {
        if (!err[0] || strchr(err, '\n'))
            abort(); /* every refusal is exactly one non-empty line */
        return;
    }
    tf_render_prepare(s, hf, 1);
    tf_renderer *r = tf_renderer_new(s, hf, err, sizeof err);
    if (r) {
        tf_pixel px[4 * 3];
        tf_render_counts counts;
        memset(&counts, 0, sizeof counts);
        tf_render_rect(r, (tf_rect){0, 0, 4, 3}, px, &counts);
        tf_renderer_free(r);
    }
    tf_heightfield_free(hf);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < 2)
        return 0;
    tf_log_set_level(TF_LOG_ERROR);
    const int size_exp = 1 + data[0] % 3, n = (1 << size_exp) + 1;
    tf_scene *s = eroded_scene(size_exp);
    size_t len;
    uint8_t *blob = hostile_blob(&s->terrain, n, data + 2, size - 2, data[1], &len);
    check_accepted(&s->terrain, n, blob, len);
    if (tf_scene_attach_eroded(s, blob, len, "fuzz") != 0)
        abort(); /* out of memory */
    build_and_render(s);
    tf_scene_free(s);
    return 0;
}
