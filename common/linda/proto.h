/* proto.h: the tuple-space wire protocol: framing, op codes, the frame decoder the server runs
 * on every connection's input buffer, and a small growable byte buffer for building frames.
 *
 * FRAME FORMAT (version 1; every integer little-endian)
 *   offset  size  field
 *   0       4     u32 length  = number of bytes that follow this field (6 + body length);
 *                 6 <= length <= TF_MAX_FRAME, checked as soon as these 4 bytes arrive and
 *                 before anything is allocated
 *   4       1     u8  version = TF_PROTO_VERSION (1)
 *   5       1     u8  op      (enum tf_op below)
 *   6       4     u32 request id: chosen by the client, echoed in the reply; 0 in unsolicited
 *                 server frames and in PINGs that want no PONG
 *   10      ...   body, length - 6 bytes, whose layout depends on op:
 *
 *   op            dir   body
 *   OUT      1    c->s  tuple (tuple.h encoding, no formals)          reply OK
 *   IN       2    c->s  template (formals allowed)    blocks;         reply TUPLE
 *   RD       3    c->s  template                      blocks;         reply TUPLE
 *   INP      4    c->s  template                      non-blocking;   reply TUPLE or NONE
 *   RDP      5    c->s  template                      non-blocking;   reply TUPLE or NONE
 *   TUPLE    6    s->c  tuple
 *   NONE     7    s->c  empty (inp/rdp found nothing)
 *   OK       8    s->c  empty (out stored)
 *   PING     9    c->s  empty; a PONG comes back only if the request id is non-zero
 *   PONG    10    s->c  empty
 *   HELLO   11    s->c  u8 flags (bit 0: authentication required; bit 1: frames sealed after
 *                       AUTH_OK, linda/seal.h), then 32-byte server nonce Ns.
 *                       Sent first, unsolicited, on every connection accepted from the
 *                       listening socket (never on fds added with ts_server_add_fd).
 *   AUTH    12    c->s  32-byte client nonce Nc, then 32-byte
 *                       HMAC-SHA256(key, "terrafarm-client" || Ns || Nc)
 *   AUTH_OK 13    s->c  32-byte HMAC-SHA256(key, "terrafarm-server" || Ns || Nc): proves the
 *                       server knows the key too (mutual authentication)
 *   ERROR   14    s->c  UTF-8 message, at most 256 bytes.  With request id 0 the server closes
 *                       after sending it; with the id of a request, that one request was
 *                       refused by the connection's role (capability.h), nothing changed in
 *                       the space, and the connection stays open.
 *   OUT_SHARED 15 c->s  u32 offset, u32 length L: an OUT whose tuple encoding (L bytes, as an OUT
 *                       body) is the payload at that offset of a record of the connection's
 *                       outbox, memory shared with the forked worker at its other end
 *                       (outbox.h).  The stored tuple keeps its large blobs there until they
 *                       are freed.  On a connection without an outbox, or with a payload no
 *                       record could hold, or larger than a frame may be, it closes the
 *                       connection.                                             reply OK
 *
 * When the HELLO says authentication is required, any frame but AUTH (even a PING) before a
 * successful AUTH closes the connection.  A wrong MAC gets an ERROR and a close, and the server
 * logs "authentication failed from PEER".  The key is never sent (see auth.h).
 * Before authentication the length field may not exceed TF_HANDSHAKE_FRAME_MAX (so a stranger
 * cannot make the server buffer more than a handshake); after it, not more than the largest
 * tuple the connection's role may send.
 * An unknown op, a wrong version, a length out of bounds, a body that does not decode, or a
 * frame in the wrong direction closes that one connection. */
#ifndef TF_PROTO_H
#define TF_PROTO_H

#include <stddef.h>
#include <stdint.h>

#include "linda/tuple.h"

#define TF_PROTO_VERSION 1
/* Largest value of the length field: bounds every allocation driven by the peer. */
#define TF_MAX_FRAME (64u * 1024u * 1024u)
/* Bytes before the body: length, version, op, request id. */
#define TF_FRAME_HEADER 10
/* Smallest legal length field (version + op + request id). */
#define TF_FRAME_MIN_LENGTH 6
#define TF_PROTO_ERROR_MAX 256

enum tf_op {
    TF_OP_OUT = 1,
    TF_OP_IN = 2,
    TF_OP_RD = 3,
    TF_OP_INP = 4,
    TF_OP_RDP = 5,
    TF_OP_TUPLE = 6,
    TF_OP_NONE = 7,
    TF_OP_OK = 8,
    TF_OP_PING = 9,
    TF_OP_PONG = 10,
    TF_OP_HELLO = 11,
    TF_OP_AUTH = 12,
    TF_OP_AUTH_OK = 13,
    TF_OP_ERROR = 14,
    TF_OP_OUT_SHARED = 15
};
#define TF_OP_MAX TF_OP_OUT_SHARED

#define TF_HELLO_AUTH_REQUIRED 0x01
#define TF_HELLO_SEALED 0x02 /* after AUTH_OK every byte is in sealed records (seal.h) */

/* A decoded frame header; body points into the caller's buffer (not a copy). */
typedef struct tf_frame {
    uint8_t version;
    uint8_t op;
    uint32_t request_id;
    const uint8_t *body;
    uint32_t body_len;
} tf_frame;

/* Name of an op for logs ("OUT", ...; "op 77" style text for unknown ones is not produced:
 * returns "?" for those). */
const char *tf_op_name(int op);

/* Parse the first frame of buf[0..len).  Returns:
 *   > 0  a complete valid frame occupies that many bytes; *out describes it
 *     0  not enough bytes yet (and nothing seen so far is invalid)
 *    -1  malformed: length out of [TF_FRAME_MIN_LENGTH, TF_MAX_FRAME], bad version or unknown
 *        op; a one-line reason is written to err.  The connection must be closed.
 * Only the header is validated here; the body is decoded by tf_tuple_decode (or by the auth
 * code) according to op.  This is the function the server runs on each connection's input. */
long tf_frame_parse(const uint8_t *buf, size_t len, tf_frame *out, char *err, size_t errlen);
/* The same with a smaller bound on the length field (the server reads only handshake-sized
 * frames before authentication, and at most its role's largest tuple after). */
long tf_frame_parse_max(const uint8_t *buf, size_t len, uint32_t max_length, tf_frame *out,
                        char *err, size_t errlen);
/* Bytes still missing from the frame that starts buf[0..len): 0 while its length field is
 * incomplete or once the frame is whole.  Only for sizing a buffer: the length is not checked
 * here (tf_frame_parse_max checks it, and must have seen these bytes first). */
size_t tf_frame_rest(const uint8_t *buf, size_t len);
/* Largest length field accepted before authentication: an AUTH frame. */
#define TF_HANDSHAKE_FRAME_MAX (TF_FRAME_MIN_LENGTH + 128)

/* ---- growable byte buffer ------------------------------------------------------------------ */
typedef struct tf_buf {
    uint8_t *data;
    size_t len; /* bytes in use, starting at data + off */
    size_t off; /* bytes already consumed at the front */
    size_t cap;
} tf_buf;

void tf_buf_init(tf_buf *b);
void tf_buf_free(tf_buf *b);
/* Make room for n more bytes; 0 or -1 (OOM or size overflow). */
int tf_buf_reserve(tf_buf *b, size_t n);
/* The same, growing to exactly that room when it must grow (not to a power of two): for a frame
 * whose length is known, whose buffer may then be kept as it is (tsserver.c detach_frame). */
int tf_buf_reserve_exact(tf_buf *b, size_t n);
int tf_buf_append(tf_buf *b, const void *p, size_t n);
/* Drop n bytes from the front (compacts lazily). */
void tf_buf_consume(tf_buf *b, size_t n);
/* An empty buffer that grew beyond `keep` bytes gives its memory back (a server holds one per
 * connection: a thousand workers that each sent one large result must not keep a thousand
 * result-sized buffers while they render). */
void tf_buf_trim(tf_buf *b, size_t keep);
/* First unconsumed byte. */
static inline uint8_t *tf_buf_head(const tf_buf *b) { return b->data + b->off; }

/* Append one frame whose body is the given bytes.  0 or -1 (OOM or body too large). */
int tf_frame_append_raw(tf_buf *b, uint8_t op, uint32_t request_id, const void *body,
                        size_t body_len);
/* Append one frame whose body is the encoding of tuple t (NULL: empty body). */
int tf_frame_append_tuple(tf_buf *b, uint8_t op, uint32_t request_id, const tf_tuple *t);

#endif
