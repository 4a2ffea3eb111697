/* tuple.h: Linda tuples and templates, matching, and their binary encoding.
 *
 * A tuple is an ordered list of at most TF_TUPLE_MAX_FIELDS typed fields (int64, double,
 * string, blob).  By convention the first field is a string naming the tuple ("task",
 * "result", "scene", ...): the tuple space indexes on (name, arity) and, when the second field
 * is an int64, on (name, arity, second field).  A template is the same structure in which some
 * fields are *formals*: a formal has a type but no value and matches any value of that type.
 * An *actual* in a template matches only an equal value of the same type (doubles compare by
 * bit pattern, so -0.0 and 0.0 differ and a NaN matches itself: matching must be exact and
 * deterministic, never "close enough").
 *
 * Ownership: a tf_tuple owns the bytes of its string and blob fields (each a separate heap
 * copy, always NUL-terminated so strings can be used as C strings; the length excludes the NUL).
 * tf_tuple_clear() frees them; tf_tuple_move() transfers them.  A zero-initialised tf_tuple
 * (or one after tf_tuple_init) is a valid empty tuple.  The one exception: a large blob that
 * tf_tuple_decode_shared left where it arrived holds a reference to that memory instead (a
 * tf_shared_bytes, freed with the last reference, from any thread), and is not NUL-terminated;
 * tf_tuple_clear() drops the reference, tf_tuple_copy() makes a copy of its own as usual.
 *
 * Encoding (used inside protocol frames, see proto.h; all integers little-endian):
 *   u8  field count N (0..TF_TUPLE_MAX_FIELDS)
 *   N times:
 *     u8 tag   = type (1 int64, 2 double, 3 string, 4 blob) | 0x80 if the field is a formal
 *     actual int64:   8 bytes, two's complement
 *     actual double:  8 bytes, IEEE-754 binary64 bit pattern
 *     actual string:  u32 length L, then L bytes (no NUL on the wire; may contain any byte but
 *                     NUL, so the in-memory copy stays a valid C string)
 *     actual blob:    u32 length L, then L bytes
 *     formal:         nothing more
 * The decoder checks every length against the bytes that remain BEFORE allocating, and the
 * encoding must fill the given buffer exactly (trailing bytes are an error). */
#ifndef TF_TUPLE_H
#define TF_TUPLE_H

#include <stddef.h>
#include <stdint.h>

#define TF_TUPLE_MAX_FIELDS 16

enum tf_field_type {
    TF_FIELD_INT = 1,    /* int64_t */
    TF_FIELD_DOUBLE = 2, /* double */
    TF_FIELD_STRING = 3, /* NUL-free bytes, stored NUL-terminated */
    TF_FIELD_BLOB = 4    /* arbitrary bytes */
};

/* Memory holding the bytes of blob fields, shared by reference (tf_tuple_decode_shared). */
typedef struct tf_shared_bytes tf_shared_bytes;

typedef struct tf_field {
    uint8_t type;   /* enum tf_field_type */
    uint8_t formal; /* 1: template formal (no value); 0: actual */
    union {
        int64_t i;
        double d;
        struct {
            uint8_t *ptr; /* string/blob bytes + a NUL; NULL only when len == 0 for a blob */
            uint32_t len; /* bytes, excluding the trailing NUL */
            tf_shared_bytes *shared; /* non-NULL: ptr lies in this memory (a blob, no NUL) */
        } bytes;
    } v;
} tf_field;

typedef struct tf_tuple {
    int nfields;
    tf_field f[TF_TUPLE_MAX_FIELDS];
} tf_tuple;

/* ---- building ----------------------------------------------------------------------------
 * The add functions return 0, or -1 when the tuple is full, a string contains a NUL, or memory
 * runs out (the tuple is unchanged on failure). */
void tf_tuple_init(tf_tuple *t);
int tf_tuple_add_int(tf_tuple *t, int64_t v);
int tf_tuple_add_double(tf_tuple *t, double v);
int tf_tuple_add_string(tf_tuple *t, const char *s);
int tf_tuple_add_stringn(tf_tuple *t, const char *s, size_t len);
int tf_tuple_add_blob(tf_tuple *t, const void *p, size_t len);
int tf_tuple_add_formal(tf_tuple *t, enum tf_field_type type);

/* Build from a format string, appending to t (call tf_tuple_init first):
 *   's' const char *          'i' int64_t             'd' double
 *   'b' const void *, size_t  (a blob)
 *   'S' 'I' 'D' 'B'           formals of those types (no argument)
 * Example: tf_tuple_pack(&tmpl, "siI", "result", (int64_t)7, ...) is ("result", 7, ?int).
 * Note the int64_t: pass (int64_t) casts for integer literals.  Returns 0 or -1 (t is then
 * cleared). */
int tf_tuple_pack(tf_tuple *t, const char *fmt, ...);

/* Free the string/blob bytes and reset t to an empty tuple. */
void tf_tuple_clear(tf_tuple *t);
/* Deep copy src into dst (dst must not hold data: it is overwritten).  0 or -1 (OOM; dst is
 * then empty). */
int tf_tuple_copy(tf_tuple *dst, const tf_tuple *src);
/* Move src's contents into dst (dst must not hold data) and leave src empty. */
void tf_tuple_move(tf_tuple *dst, tf_tuple *src);

/* ---- reading ------------------------------------------------------------------------------ */
/* The name: the first field when it is an actual string, else NULL. */
const char *tf_tuple_name(const tf_tuple *t);
/* 1 if any field is a formal. */
int tf_tuple_has_formals(const tf_tuple *t);
/* Typed accessors: 0 and *out set when field i exists, is an actual and has that type; -1
 * otherwise.  Strings/blobs are borrowed pointers valid while t is unchanged. */
int tf_tuple_get_int(const tf_tuple *t, int i, int64_t *out);
int tf_tuple_get_double(const tf_tuple *t, int i, double *out);
int tf_tuple_get_string(const tf_tuple *t, int i, const char **out);
int tf_tuple_get_blob(const tf_tuple *t, int i, const uint8_t **out, size_t *len);

/* ---- matching ----------------------------------------------------------------------------- */
/* 1 if tuple t (which must have no formals) matches template tmpl: same arity, and field by
 * field the same type and, for actuals in tmpl, an equal value (bytes and length for
 * strings/blobs, bit pattern for doubles). */
int tf_tuple_match(const tf_tuple *tmpl, const tf_tuple *t);
/* 1 if a and b are equal field by field (types, formal flags, values). */
int tf_tuple_equal(const tf_tuple *a, const tf_tuple *b);

/* ---- encoding ----------------------------------------------------------------------------- */
/* Exact number of bytes tf_tuple_encode writes. */
size_t tf_tuple_encoded_size(const tf_tuple *t);
/* Write the encoding into buf (at least tf_tuple_encoded_size bytes); returns bytes written. */
size_t tf_tuple_encode(const tf_tuple *t, uint8_t *buf);
/* Decode exactly len bytes into out (which must not hold data).  allow_formals = 0 rejects
 * formals (a tuple to out), 1 accepts them (a template).  0 on success; -1 with a one-line
 * reason in err (out is then empty).  Never reads past buf + len; allocates only lengths that
 * fit in the remaining bytes. */
int tf_tuple_decode(const uint8_t *buf, size_t len, tf_tuple *out, int allow_formals,
                    char *err, size_t errlen);
/* Wrap mem (from malloc) for sharing: one reference, the caller's.  NULL without memory (mem
 * is then still the caller's to free). */
tf_shared_bytes *tf_shared_bytes_adopt(void *mem);
/* The same for memory owned elsewhere: release(ctx) runs with the last reference (on whichever
 * thread drops it).  NULL without memory (release is then not called). */
tf_shared_bytes *tf_shared_bytes_wrap(void (*release)(void *ctx), void *ctx);
/* Drop one reference; the last frees the memory.  Thread-safe; NULL does nothing. */
void tf_shared_bytes_release(tf_shared_bytes *s);
/* 1 for memory tf_shared_bytes_adopt wrapped (this process's own, which nothing else writes
 * once adopted), 0 for memory owned elsewhere (tf_shared_bytes_wrap: e.g. a forked worker's
 * outbox, which that process can still write). */
int tf_shared_bytes_adopted(const tf_shared_bytes *s);
/* Decode as tf_tuple_decode (no formals), except that every blob of at least min_shared bytes
 * stays where it is in buf, which must lie in owner's memory: the field takes a reference to
 * owner instead of a copy (a result's chunks are not copied out of the buffer they were received
 * into).  The caller keeps its own reference, and drops it when it likes. */
int tf_tuple_decode_shared(const uint8_t *buf, size_t len, tf_shared_bytes *owner,
                           size_t min_shared, tf_tuple *out, char *err, size_t errlen);
/* A view of a tuple's encoding (no formals), checked as tf_tuple_decode checks it, whose blob
 * fields borrow their bytes from buf instead of copying them (not NUL-terminated: only their
 * length bounds them); its strings are copies as usual.  For a look at a large tuple that
 * another copy of it keeps: valid while buf is, read-only, and released with
 * tf_tuple_view_clear (never tf_tuple_clear, tf_tuple_move or a store).  0, or -1 as decode. */
int tf_tuple_view(const uint8_t *buf, size_t len, tf_tuple *out, char *err, size_t errlen);
void tf_tuple_view_clear(tf_tuple *view);

/* Bytes this tuple is accounted for in the tuple space (its encoded size). */
size_t tf_tuple_bytes(const tf_tuple *t);

/* Human-readable form for logs, e.g. ("task", 12, 3.5, blob[640], ?int); truncated to fit
 * buflen (which must be > 0).  Returns buf. */
char *tf_tuple_format(const tf_tuple *t, char *buf, size_t buflen);

#endif
