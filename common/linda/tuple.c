/* tuple.c: tuples, templates, matching and the tuple encoding.  See tuple.h for the format and
 * the ownership rules; the decoder is fed untrusted bytes straight from the network. */
#include "linda/tuple.h"

#include <inttypes.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "le_bytes.h"
#include "log.h"

#define TAG_FORMAL 0x80

/* ---- shared bytes ---- */
struct tf_shared_bytes {
    atomic_int refs;
    void (*release)(void *ctx);
    void *ctx;
    int adopted; /* our own malloc'd memory (tf_shared_bytes_adopt) */
};

tf_shared_bytes *tf_shared_bytes_wrap(void (*release)(void *ctx), void *ctx)
{
    tf_shared_bytes *s = malloc(sizeof *s);
    if (!s)
        return NULL;
    atomic_init(&s->refs, 1);
    s->release = release;
    s->ctx = ctx;
    s->adopted = 0;
    return s;
}

tf_shared_bytes *tf_shared_bytes_adopt(void *mem)
{
    tf_shared_bytes *s = tf_shared_bytes_wrap(free, mem);
    if (s)
        s->adopted = 1;
    return s;
}

int tf_shared_bytes_adopted(const tf_shared_bytes *s) { return s->adopted; }

void tf_shared_bytes_release(tf_shared_bytes *s)
{
    if (s && atomic_fetch_sub_explicit(&s->refs, 1, memory_order_acq_rel) == 1) {
        s->release(s->ctx);
        free(s);
    }
}

static void shared_bytes_retain(tf_shared_bytes *s)
{
    atomic_fetch_add_explicit(&s->refs, 1, memory_order_relaxed);
}

static int is_bytes_type(int type) { return type == TF_FIELD_STRING || type == TF_FIELD_BLOB; }
static int is_valid_type(int type) { return type >= TF_FIELD_INT && type <= TF_FIELD_BLOB; }

void tf_tuple_init(tf_tuple *t) { memset(t, 0, sizeof *t); }

/* Reserve the next field slot, or NULL when full. */
static tf_field *next_field(tf_tuple *t)
{
    if (t->nfields < 0 || t->nfields >= TF_TUPLE_MAX_FIELDS)
        return NULL;
    tf_field *f = &t->f[t->nfields];
    memset(f, 0, sizeof *f);
    return f;
}

int tf_tuple_add_int(tf_tuple *t, int64_t v)
{
    tf_field *f = next_field(t);
    if (!f)
        return -1;
    f->type = TF_FIELD_INT;
    f->v.i = v;
    t->nfields++;
    return 0;
}

int tf_tuple_add_double(tf_tuple *t, double v)
{
    tf_field *f = next_field(t);
    if (!f)
        return -1;
    f->type = TF_FIELD_DOUBLE;
    f->v.d = v;
    t->nfields++;
    return 0;
}

/* Copy len bytes plus a NUL into a new field of the given type. */
static int add_bytes(tf_tuple *t, int type, const void *p, size_t len)
{
    tf_field *f = next_field(t);
    if (!f || len > UINT32_MAX - 1 || (len > 0 && !p))
        return -1;
    uint8_t *copy = malloc(len + 1);
    if (!copy)
        return -1;
    if (len)
        memcpy(copy, p, len);
    copy[len] = 0;
    f->type = (uint8_t)type;
    f->v.bytes.ptr = copy;
    f->v.bytes.len = (uint32_t)len;
    t->nfields++;
    return 0;
}

int tf_tuple_add_stringn(tf_tuple *t, const char *s, size_t len)
{
    if (!s || memchr(s, 0, len))
        return -1;
    return add_bytes(t, TF_FIELD_STRING, s, len);
}

int tf_tuple_add_string(tf_tuple *t, const char *s)
{
    return s ? add_bytes(t, TF_FIELD_STRING, s, strlen(s)) : -1;
}

int tf_tuple_add_blob(tf_tuple *t, const void *p, size_t len)
{
    return add_bytes(t, TF_FIELD_BLOB, p, len);
}

int tf_tuple_add_formal(tf_tuple *t, enum tf_field_type type)
{
    tf_field *f = next_field(t);
    if (!f || !is_valid_type(type))
        return -1;
    f->type = (uint8_t)type;
    f->formal = 1;
    t->nfields++;
    return 0;
}

/* One format character of tf_tuple_pack; -1 on an unknown character or a failed add. */
static int pack_one(tf_tuple *t, char c, va_list *ap)
{
    switch (c) {
    case 's': return tf_tuple_add_string(t, va_arg(*ap, const char *));
    case 'i': return tf_tuple_add_int(t, va_arg(*ap, int64_t));
    case 'd': return tf_tuple_add_double(t, va_arg(*ap, double));
    case 'b': {
        const void *p = va_arg(*ap, const void *);
        size_t n = va_arg(*ap, size_t);
        return tf_tuple_add_blob(t, p, n);
    }
    case 'S': return tf_tuple_add_formal(t, TF_FIELD_STRING);
    case 'I': return tf_tuple_add_formal(t, TF_FIELD_INT);
    case 'D': return tf_tuple_add_formal(t, TF_FIELD_DOUBLE);
    case 'B': return tf_tuple_add_formal(t, TF_FIELD_BLOB);
    default: return -1;
    }
}

int tf_tuple_pack(tf_tuple *t, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    int rc = 0;
    for (const char *c = fmt; *c && rc == 0; c++)
        rc = pack_one(t, *c, &ap);
    va_end(ap);
    if (rc != 0)
        tf_tuple_clear(t);
    return rc;
}

void tf_tuple_clear(tf_tuple *t)
{
    for (int i = 0; i < t->nfields && i < TF_TUPLE_MAX_FIELDS; i++) {
        const tf_field *f = &t->f[i];
        if (!is_bytes_type(f->type) || f->formal)
            continue;
        if (f->v.bytes.shared)
            tf_shared_bytes_release(f->v.bytes.shared);
        else
            free(f->v.bytes.ptr);
    }
    tf_tuple_init(t);
}

int tf_tuple_copy(tf_tuple *dst, const tf_tuple *src)
{
    tf_tuple_init(dst);
    for (int i = 0; i < src->nfields; i++) {
        const tf_field *f = &src->f[i];
        int rc;
        if (f->formal)
            rc = tf_tuple_add_formal(dst, f->type);
        else if (is_bytes_type(f->type))
            rc = add_bytes(dst, f->type, f->v.bytes.ptr, f->v.bytes.len);
        else {
            rc = 0;
            dst->f[dst->nfields++] = *f;
        }
        if (rc != 0) {
            tf_tuple_clear(dst);
            return -1;
        }
    }
    return 0;
}

void tf_tuple_move(tf_tuple *dst, tf_tuple *src)
{
    *dst = *src;
    tf_tuple_init(src);
}

const char *tf_tuple_name(const tf_tuple *t)
{
    if (t->nfields < 1 || t->f[0].type != TF_FIELD_STRING || t->f[0].formal)
        return NULL;
    return (const char *)t->f[0].v.bytes.ptr;
}

int tf_tuple_has_formals(const tf_tuple *t)
{
    for (int i = 0; i < t->nfields; i++)
        if (t->f[i].formal)
            return 1;
    return 0;
}

/* Field i if it exists and is an actual of the given type, else NULL. */
static const tf_field *actual(const tf_tuple *t, int i, int type)
{
    if (i < 0 || i >= t->nfields || t->f[i].formal || t->f[i].type != type)
        return NULL;
    return &t->f[i];
}

int tf_tuple_get_int(const tf_tuple *t, int i, int64_t *out)
{
    const tf_field *f = actual(t, i, TF_FIELD_INT);
    if (!f)
        return -1;
    *out = f->v.i;
    return 0;
}

int tf_tuple_get_double(const tf_tuple *t, int i, double *out)
{
    const tf_field *f = actual(t, i, TF_FIELD_DOUBLE);
    if (!f)
        return -1;
    *out = f->v.d;
    return 0;
}

int tf_tuple_get_string(const tf_tuple *t, int i, const char **out)
{
    const tf_field *f = actual(t, i, TF_FIELD_STRING);
    if (!f)
        return -1;
    *out = (const char *)f->v.bytes.ptr;
    return 0;
}

int tf_tuple_get_blob(const tf_tuple *t, int i, const uint8_t **out, size_t *len)
{
    const tf_field *f = actual(t, i, TF_FIELD_BLOB);
    if (!f)
        return -1;
    *out = f->v.bytes.ptr;
    *len = f->v.bytes.len;
    return 0;
}

/* Equal values of two actual fields already known to share a type.  Doubles compare by bit
 * pattern: exact and deterministic (NaN == NaN, -0.0 != 0.0). */
static int values_equal(const tf_field *a, const tf_field *b)
{
    switch (a->type) {
    case TF_FIELD_INT: return a->v.i == b->v.i;
    case TF_FIELD_DOUBLE: return memcmp(&a->v.d, &b->v.d, sizeof(double)) == 0;
    default:
        return a->v.bytes.len == b->v.bytes.len &&
               (a->v.bytes.len == 0 ||
                memcmp(a->v.bytes.ptr, b->v.bytes.ptr, a->v.bytes.len) == 0);
    }
}

int tf_tuple_match(const tf_tuple *tmpl, const tf_tuple *t)
{
    if (tmpl->nfields != t->nfields)
        return 0;
    for (int i = 0; i < t->nfields; i++) {
        const tf_field *p = &tmpl->f[i], *f = &t->f[i];
        if (p->type != f->type || f->formal)
            return 0;
        if (!p->formal && !values_equal(p, f))
            return 0;
    }
    return 1;
}

int tf_tuple_equal(const tf_tuple *a, const tf_tuple *b)
{
    if (a->nfields != b->nfields)
        return 0;
    for (int i = 0; i < a->nfields; i++) {
        const tf_field *x = &a->f[i], *y = &b->f[i];
        if (x->type != y->type || x->formal != y->formal)
            return 0;
        if (!x->formal && !values_equal(x, y))
            return 0;
    }
    return 1;
}

size_t tf_tuple_encoded_size(const tf_tuple *t)
{
    size_t n = 1;
    for (int i = 0; i < t->nfields; i++) {
        const tf_field *f = &t->f[i];
        n += 1;
        if (f->formal)
            continue;
        n += is_bytes_type(f->type) ? 4 + (size_t)f->v.bytes.len : 8;
    }
    return n;
}

size_t tf_tuple_encode(const tf_tuple *t, uint8_t *buf)
{
    uint8_t *p = buf;
    *p++ = (uint8_t)t->nfields;
    for (int i = 0; i < t->nfields; i++) {
        const tf_field *f = &t->f[i];
        *p++ = (uint8_t)(f->type | (f->formal ? TAG_FORMAL : 0));
        if (f->formal)
            continue;
        if (f->type == TF_FIELD_INT) {
            tf_le_put64(p, (uint64_t)f->v.i);
            p += 8;
        } else if (f->type == TF_FIELD_DOUBLE) {
            uint64_t bits;
            memcpy(&bits, &f->v.d, 8);
            tf_le_put64(p, bits);
            p += 8;
        } else {
            tf_le_put32(p, f->v.bytes.len);
            p += 4;
            if (f->v.bytes.len)
                memcpy(p, f->v.bytes.ptr, f->v.bytes.len);
            p += f->v.bytes.len;
        }
    }
    return (size_t)(p - buf);
}

/* Where decode keeps a blob: a copy (the default), borrowed from buf (a view), or, from
 * min_shared bytes on, left in buf with a reference to its owner. */
typedef struct blob_rule {
    int borrow;
    tf_shared_bytes *owner;
    size_t min_shared;
} blob_rule;

/* A blob field whose bytes stay where they are: borrowed (tf_tuple_view) or, with owner, a
 * reference to owner's memory (tf_tuple_decode_shared). */
static int add_in_place(tf_tuple *t, const uint8_t *p, size_t len, tf_shared_bytes *owner)
{
    tf_field *f = next_field(t);
    if (!f || len > UINT32_MAX - 1)
        return -1;
    f->type = TF_FIELD_BLOB;
    f->v.bytes.ptr = (uint8_t *)p;
    f->v.bytes.len = (uint32_t)len;
    f->v.bytes.shared = owner;
    if (owner)
        shared_bytes_retain(owner);
    t->nfields++;
    return 0;
}

static int add_blob_by_rule(tf_tuple *t, const uint8_t *p, size_t n, const blob_rule *rule)
{
    if (rule->borrow)
        return add_in_place(t, p, n, NULL);
    if (rule->owner && n >= rule->min_shared)
        return add_in_place(t, p, n, rule->owner);
    return add_bytes(t, TF_FIELD_BLOB, p, n);
}

/* Decode one actual value of `type` at buf[*pos..len) into tuple t, a blob kept by `rule`.
 * 0 or -1 with err set. */
static int decode_value(const uint8_t *buf, size_t len, size_t *pos, int type,
                        const blob_rule *rule, tf_tuple *t, char *err, size_t errlen)
{
    size_t rest = len - *pos;
    if (type == TF_FIELD_INT || type == TF_FIELD_DOUBLE) {
        if (rest < 8) {
            tf_seterr(err, errlen, "tuple truncated in a field of type %s",
                     type == TF_FIELD_INT ? "int" : "double");
            return -1;
        }
        uint64_t bits = tf_le_get64(buf + *pos);
        *pos += 8;
        if (type == TF_FIELD_INT)
            return tf_tuple_add_int(t, (int64_t)bits);
        double d;
        memcpy(&d, &bits, 8);
        return tf_tuple_add_double(t, d);
    }
    if (rest < 4) {
        tf_seterr(err, errlen, "tuple truncated in a length");
        return -1;
    }
    uint32_t n = tf_le_get32(buf + *pos);
    *pos += 4;
    /* The length is checked against the bytes that remain before anything is allocated. */
    if (n > len - *pos) {
        tf_seterr(err, errlen, "field length %" PRIu32 " exceeds the %zu bytes left", n,
                 len - *pos);
        return -1;
    }
    const uint8_t *p = buf + *pos;
    *pos += n;
    if (type == TF_FIELD_STRING && memchr(p, 0, n)) {
        tf_seterr(err, errlen, "string field contains a NUL byte");
        return -1;
    }
    if ((type == TF_FIELD_BLOB ? add_blob_by_rule(t, p, n, rule) : add_bytes(t, type, p, n))) {
        tf_seterr(err, errlen, "out of memory decoding a %" PRIu32 "-byte field", n);
        return -1;
    }
    return 0;
}

void tf_tuple_view_clear(tf_tuple *view)
{
    for (int i = 0; i < view->nfields && i < TF_TUPLE_MAX_FIELDS; i++)
        if (view->f[i].type == TF_FIELD_STRING && !view->f[i].formal)
            free(view->f[i].v.bytes.ptr);
    tf_tuple_init(view);
}

/* tf_tuple_decode, tf_tuple_view (rule->borrow) or tf_tuple_decode_shared (rule->owner);
 * formals only for the first. */
static int decode(const uint8_t *buf, size_t len, tf_tuple *out, int allow_formals,
                  const blob_rule *rule, char *err, size_t errlen)
{
    tf_tuple_init(out);
    if (len < 1) {
        tf_seterr(err, errlen, "empty tuple encoding");
        return -1;
    }
    size_t nfields = buf[0], pos = 1;
    if (nfields > TF_TUPLE_MAX_FIELDS) {
        tf_seterr(err, errlen, "tuple has %zu fields (at most %d)", nfields, TF_TUPLE_MAX_FIELDS);
        return -1;
    }
    for (size_t i = 0; i < nfields; i++) {
        if (pos >= len) {
            tf_seterr(err, errlen, "tuple truncated after %zu of %zu fields", i, nfields);
            goto fail;
        }
        int tag = buf[pos++];
        int type = tag & ~TAG_FORMAL;
        if (!is_valid_type(type)) {
            tf_seterr(err, errlen, "unknown field type %d", type);
            goto fail;
        }
        if (tag & TAG_FORMAL) {
            if (!allow_formals) {
                tf_seterr(err, errlen, "a tuple to store may not contain formals");
                goto fail;
            }
            tf_tuple_add_formal(out, (enum tf_field_type)type);
        } else if (decode_value(buf, len, &pos, type, rule, out, err, errlen) != 0) {
            goto fail;
        }
    }
    if (pos != len) {
        tf_seterr(err, errlen, "%zu trailing bytes after the tuple", len - pos);
        goto fail;
    }
    return 0;
fail:
    if (rule->borrow)
        tf_tuple_view_clear(out);
    else
        tf_tuple_clear(out);
    return -1;
}

int tf_tuple_decode(const uint8_t *buf, size_t len, tf_tuple *out, int allow_formals,
                    char *err, size_t errlen)
{
    const blob_rule copy = {0, NULL, 0};
    return decode(buf, len, out, allow_formals, &copy, err, errlen);
}

int tf_tuple_decode_shared(const uint8_t *buf, size_t len, tf_shared_bytes *owner,
                           size_t min_shared, tf_tuple *out, char *err, size_t errlen)
{
    const blob_rule share = {0, owner, min_shared};
    return decode(buf, len, out, 0, &share, err, errlen);
}

int tf_tuple_view(const uint8_t *buf, size_t len, tf_tuple *out, char *err, size_t errlen)
{
    const blob_rule borrow = {1, NULL, 0};
    return decode(buf, len, out, 0, &borrow, err, errlen);
}

size_t tf_tuple_bytes(const tf_tuple *t) { return tf_tuple_encoded_size(t); }

/* Append formatted text at *used, never overflowing buflen (which is > 0). */
static void appendf(char *buf, size_t buflen, size_t *used, const char *fmt, ...)
{
    if (*used >= buflen - 1)
        return;
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(buf + *used, buflen - *used, fmt, ap);
    va_end(ap);
    if (n > 0)
        *used += (size_t)n < buflen - *used ? (size_t)n : buflen - 1 - *used;
}

char *tf_tuple_format(const tf_tuple *t, char *buf, size_t buflen)
{
    static const char *type_names[] = {"?", "int", "double", "string", "blob"};
    size_t used = 0;
    buf[0] = 0;
    appendf(buf, buflen, &used, "(");
    for (int i = 0; i < t->nfields; i++) {
        const tf_field *f = &t->f[i];
        const char *sep = i ? ", " : "";
        if (f->formal)
            appendf(buf, buflen, &used, "%s?%s", sep, type_names[f->type <= 4 ? f->type : 0]);
        else if (f->type == TF_FIELD_INT)
            appendf(buf, buflen, &used, "%s%" PRId64, sep, f->v.i);
        else if (f->type == TF_FIELD_DOUBLE)
            appendf(buf, buflen, &used, "%s%.17g", sep, f->v.d);
        else if (f->type == TF_FIELD_STRING) {
            /* Peer-supplied text goes into log lines: control bytes and quotes are escaped so a
             * tuple cannot forge a line of its own. */
            char shown[64 * 4 + 4];
            size_t k = 0;
            for (uint32_t j = 0; j < f->v.bytes.len && j < 64; j++) {
                unsigned char ch = f->v.bytes.ptr[j];
                if (ch < 0x20 || ch >= 0x7f || ch == '"' || ch == '\\')
                    k += (size_t)snprintf(shown + k, sizeof shown - k, "\\x%02x", ch);
                else
                    shown[k++] = (char)ch;
            }
            shown[k] = '\0';
            appendf(buf, buflen, &used, "%s\"%s%s\"", sep, shown,
                    f->v.bytes.len > 64 ? "..." : "");
        }
        else
            appendf(buf, buflen, &used, "%sblob[%" PRIu32 "]", sep, f->v.bytes.len);
    }
    appendf(buf, buflen, &used, ")");
    return buf;
}
