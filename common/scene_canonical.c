/* scene_canonical.c: the canonical form of a parsed scene and its SHA-256 (scene.h): every
 * key of the table in its order, in one fixed spelling, so equal scenes hash equal whatever
 * their comments, spacing, key order and defaults spelled out or not. */
#include "scene_impl.h"

#include <inttypes.h>
#include <sodium.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define ENVELOPE_PER_LINE 6 /* envelope numbers per line */

struct strbuf {
    char *data;
    size_t len, cap;
    int oom;
};

static void sb_printf(struct strbuf *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void sb_printf(struct strbuf *b, const char *fmt, ...)
{
    if (b->oom)
        return;
    for (;;) {
        va_list ap;
        va_start(ap, fmt);
        /* an empty buffer is NULL: no offset may be added to it (UB even when zero) */
        char *end = b->data ? b->data + b->len : NULL;
        int n = vsnprintf(end, b->cap - b->len, fmt, ap);
        va_end(ap);
        if (n < 0) {
            b->oom = 1;
            return;
        }
        if ((size_t)n < b->cap - b->len) {
            b->len += (size_t)n;
            return;
        }
        size_t cap = (b->cap + (size_t)n + 1) * 2;
        char *d = realloc(b->data, cap);
        if (!d) {
            b->oom = 1;
            return;
        }
        b->data = d;
        b->cap = cap;
    }
}

/* The envelope in rows of envelope_n numbers, at most ENVELOPE_PER_LINE per line; lines after
 * the first are indented continuation lines (every line stays far below inih's limit). */
static void canonical_envelope(struct strbuf *b, const tf_terrain *t)
{
    int n = t->envelope_n, count = n * n;
    sb_printf(b, "envelope =");
    for (int i = 0, on_line = 0; i < count; i++, on_line++) {
        if (i > 0 && (i % n == 0 || on_line == ENVELOPE_PER_LINE)) {
            sb_printf(b, "\n   ");
            on_line = 0;
        }
        sb_printf(b, " %.17g", t->envelope[i]);
    }
    sb_printf(b, "\n");
}

/* A key whose value is one of count names (an enum stored as int). */
static void canonical_name(struct strbuf *b, const struct key_def *k, const void *src,
                           const char *const *names, int count)
{
    int i;
    memcpy(&i, src, sizeof i);
    sb_printf(b, "%s = %s\n", k->name, (i >= 0 && i < count) ? names[i] : "?");
}

/* The [animation]'s camera keys, one a frame, each on three lines. */
static void canonical_camera_keys(struct strbuf *b, const tf_animation *a)
{
    for (int j = 0; j < a->ncamera; j++) {
        const tf_camera_key *c = &a->camera[j];
        sb_printf(b, "camera = %d position %.17g %.17g %.17g\n", c->frame, c->position.x,
                  c->position.y, c->position.z);
        sb_printf(b, "    look_at %.17g %.17g %.17g\n", c->look_at.x, c->look_at.y, c->look_at.z);
        sb_printf(b, "    up %.17g %.17g %.17g fov %.17g\n", c->up.x, c->up.y, c->up.z,
                  c->fov_deg);
    }
}

/* The [animation]'s sun keys, one line each. */
static void canonical_sun_keys(struct strbuf *b, const tf_animation *a)
{
    for (int j = 0; j < a->nsun; j++)
        sb_printf(b, "sun = %d azimuth %.17g elevation %.17g\n", a->sun[j].frame,
                  a->sun[j].azimuth_deg, a->sun[j].elevation_deg);
}

static void canonical_key(struct strbuf *b, const tf_scene *s, int key)
{
    const struct key_def *k = &SCENE_KEYS[key];
    const void *src = scene_cfield(s, key);
    int i;
    switch (k->type) {
    case KT_INT:
        sb_printf(b, "%s = %d\n", k->name, *(const int *)src);
        break;
    case KT_U64:
        sb_printf(b, "%s = %" PRIu64 "\n", k->name, *(const uint64_t *)src);
        break;
    case KT_DOUBLE:
        if (scene_key_silent(s, key))
            break; /* not written: the key is absent */
        sb_printf(b, "%s = %.17g\n", k->name, *(const double *)src);
        break;
    case KT_VEC3: {
        const tf_vec3 *v = src;
        sb_printf(b, "%s = %.17g %.17g %.17g\n", k->name, v->x, v->y, v->z);
        break;
    }
    case KT_BOOL:
        if (scene_key_silent(s, key))
            break; /* not written: the key is absent */
        sb_printf(b, "%s = %s\n", k->name, *(const int *)src ? "true" : "false");
        break;
    case KT_GENERATOR:
        memcpy(&i, src, sizeof i);
        sb_printf(b, "%s = %s\n", k->name, tf_generator_name((enum tf_generator)i));
        break;
    case KT_CAMERA:
        canonical_name(b, k, src, SCENE_CAMERA_NAMES, SCENE_CAMERA_COUNT);
        break;
    case KT_ENVELOPE:
        if (s->terrain.envelope_n > 0)
            canonical_envelope(b, &s->terrain);
        break;
    case KT_CAMERA_KEY:
        canonical_camera_keys(b, &s->animation);
        break;
    case KT_SUN_KEY:
        canonical_sun_keys(b, &s->animation);
        break;
    case KT_PATH:
    case KT_SHA256:
        if (*(const char *)src) /* an empty value is not written: the key is absent */
            sb_printf(b, "%s = %s\n", k->name, (const char *)src);
        break;
    case KT_NODATA:
        canonical_name(b, k, src, SCENE_NODATA_NAMES, SCENE_NODATA_COUNT);
        break;
    case KT_FIRST_ROW:
        canonical_name(b, k, src, SCENE_FIRST_ROW_NAMES, SCENE_FIRST_ROW_COUNT);
        break;
    }
}

/* The canonical text of the sections in `mask` (bit per enum section). */
static char *canonical_sections(const tf_scene *s, unsigned mask)
{
    struct strbuf b = {0};
    sb_printf(&b, "; terrafarm canonical scene, format 1\n");
    for (int sec = 0; sec < SEC_COUNT; sec++) {
        if (!(mask & (1u << sec)))
            continue;
        if (sec == SEC_ANIMATION && s->animation.frames == 0)
            continue; /* a still: no section, and the hash of every still scene is unchanged */
        if (sec == SEC_EROSION && s->terrain.erosion.fluvial_steps == 0)
            continue; /* no erosion: every other scene's hash is unchanged */
        sb_printf(&b, "[%s]\n", SCENE_SECTION_NAMES[sec]);
        for (int key = 0; key < SCENE_KEY_COUNT; key++)
            if (SCENE_KEYS[key].section == (enum section)sec &&
                !scene_replaced_by_animation(s, key))
                canonical_key(&b, s, key);
    }
    if (b.oom) {
        free(b.data);
        return NULL;
    }
    return b.data;
}

char *tf_scene_canonical(const tf_scene *s) { return canonical_sections(s, ~0u); }

char *tf_scene_canonical_terrain(const tf_scene *s)
{
    return canonical_sections(s, (1u << SEC_TERRAIN) | (1u << SEC_EROSION));
}

void tf_scene_rehash(tf_scene *s)
{
    static const char hex[] = "0123456789abcdef";
    /* sodium_init is idempotent and thread-safe; crypto_hash_sha256 needs no state from it,
     * so a failure (no entropy source) does not matter here */
    if (sodium_init() < 0)
        (void)0;
    char *c = tf_scene_canonical(s);
    if (c) {
        crypto_hash_sha256(s->hash, (const unsigned char *)c, strlen(c));
        free(c);
    } else {
        /* out of memory: an all-zero hash matches nothing real */
        memset(s->hash, 0, sizeof s->hash);
    }
    for (int i = 0; i < 32; i++) {
        s->hash_hex[2 * i] = hex[s->hash[i] >> 4];
        s->hash_hex[2 * i + 1] = hex[s->hash[i] & 15];
    }
    s->hash_hex[64] = '\0';
}
