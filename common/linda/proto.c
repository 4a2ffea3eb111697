/* proto.c: frame parsing and building for the tuple-space protocol (format in proto.h), the
 * growable byte buffer used for connection input/output, and HOST:PORT splitting.
 * tf_frame_parse is what the server runs on untrusted input: it validates the header from the
 * first 4 bytes on, so an oversized length is refused before a single byte is buffered for it. */
#include "linda/proto.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "le_bytes.h"
#include "log.h"

const char *tf_op_name(int op)
{
    static const char *names[] = {"?",    "OUT",  "IN",   "RD",    "INP",  "RDP",     "TUPLE",
                                  "NONE", "OK",   "PING", "PONG",  "HELLO", "AUTH", "AUTH_OK",
                                  "ERROR", "OUT_SHARED"};
    return op >= 1 && op <= TF_OP_MAX ? names[op] : "?";
}

long tf_frame_parse(const uint8_t *buf, size_t len, tf_frame *out, char *err, size_t errlen)
{
    return tf_frame_parse_max(buf, len, TF_MAX_FRAME, out, err, errlen);
}

long tf_frame_parse_max(const uint8_t *buf, size_t len, uint32_t max_length, tf_frame *out,
                        char *err, size_t errlen)
{
    if (len < 4)
        return 0;
    uint32_t length = tf_le_get32(buf);
    if (max_length > TF_MAX_FRAME)
        max_length = TF_MAX_FRAME;
    if (length < TF_FRAME_MIN_LENGTH || length > max_length) {
        tf_seterr(err, errlen, "frame length %u out of bounds [%u, %u]", length,
                 TF_FRAME_MIN_LENGTH, max_length);
        return -1;
    }
    if (len >= 5 && buf[4] != TF_PROTO_VERSION) {
        tf_seterr(err, errlen, "protocol version %u (expected %u)", buf[4], TF_PROTO_VERSION);
        return -1;
    }
    if (len >= 6 && (buf[5] < 1 || buf[5] > TF_OP_MAX)) {
        tf_seterr(err, errlen, "unknown op %u", buf[5]);
        return -1;
    }
    if (len - 4 < length)
        return 0;
    out->version = buf[4];
    out->op = buf[5];
    out->request_id = tf_le_get32(buf + 6);
    out->body = buf + TF_FRAME_HEADER;
    out->body_len = length - TF_FRAME_MIN_LENGTH;
    return (long)length + 4;
}

size_t tf_frame_rest(const uint8_t *buf, size_t len)
{
    if (len < 4)
        return 0;
    uint64_t whole = 4 + (uint64_t)tf_le_get32(buf);
    return whole > len ? (size_t)(whole - len) : 0;
}

void tf_buf_init(tf_buf *b) { memset(b, 0, sizeof *b); }

void tf_buf_free(tf_buf *b)
{
    free(b->data);
    tf_buf_init(b);
}

static int buf_grow(tf_buf *b, size_t n, int exact)
{
    if (n > SIZE_MAX / 2 - b->len)
        return -1;
    if (b->off > 0 && b->off + b->len + n > b->cap) {
        /* Compact before growing: consumed bytes at the front are dead. */
        memmove(b->data, b->data + b->off, b->len);
        b->off = 0;
    }
    if (b->len + n <= b->cap)
        return 0;
    size_t cap = b->cap ? b->cap : 4096;
    while (cap < b->len + n)
        cap *= 2;
    if (exact)
        cap = b->len + n;
    uint8_t *p = realloc(b->data, cap);
    if (!p)
        return -1;
    b->data = p;
    b->cap = cap;
    return 0;
}

int tf_buf_reserve(tf_buf *b, size_t n) { return buf_grow(b, n, 0); }

int tf_buf_reserve_exact(tf_buf *b, size_t n) { return buf_grow(b, n, 1); }

void tf_buf_trim(tf_buf *b, size_t keep)
{
    if (b->len == 0 && b->cap > keep) {
        free(b->data);
        b->data = NULL;
        b->cap = b->off = 0;
    }
}

int tf_buf_append(tf_buf *b, const void *p, size_t n)
{
    if (tf_buf_reserve(b, n) != 0)
        return -1;
    if (n)
        memcpy(b->data + b->off + b->len, p, n);
    b->len += n;
    return 0;
}

void tf_buf_consume(tf_buf *b, size_t n)
{
    if (n >= b->len) {
        b->off = 0;
        b->len = 0;
        return;
    }
    b->off += n;
    b->len -= n;
}

/* Reserve and write a frame header for a body of body_len bytes; returns where the body goes,
 * or NULL (too large or OOM). */
static uint8_t *begin_frame(tf_buf *b, uint8_t op, uint32_t request_id, size_t body_len)
{
    if (body_len > TF_MAX_FRAME - TF_FRAME_MIN_LENGTH)
        return NULL;
    if (tf_buf_reserve(b, TF_FRAME_HEADER + body_len) != 0)
        return NULL;
    uint8_t *h = b->data + b->off + b->len;
    tf_le_put32(h, (uint32_t)(body_len + TF_FRAME_MIN_LENGTH));
    h[4] = TF_PROTO_VERSION;
    h[5] = op;
    tf_le_put32(h + 6, request_id);
    b->len += TF_FRAME_HEADER + body_len;
    return h + TF_FRAME_HEADER;
}

int tf_frame_append_raw(tf_buf *b, uint8_t op, uint32_t request_id, const void *body,
                        size_t body_len)
{
    uint8_t *p = begin_frame(b, op, request_id, body_len);
    if (!p)
        return -1;
    if (body_len)
        memcpy(p, body, body_len);
    return 0;
}

int tf_frame_append_tuple(tf_buf *b, uint8_t op, uint32_t request_id, const tf_tuple *t)
{
    size_t n = t ? tf_tuple_encoded_size(t) : 0;
    uint8_t *p = begin_frame(b, op, request_id, n);
    if (!p)
        return -1;
    if (t)
        tf_tuple_encode(t, p);
    return 0;
}
