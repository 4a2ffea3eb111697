/* fuzz_frame.c: libFuzzer harness for the tuple-space frame decoder.  Feeds the input to
 * tf_frame_parse exactly as the server does with a connection's input buffer (frame after
 * frame, stopping at "need more" or "malformed"), decodes each frame body with tf_tuple_decode
 * as both a tuple and a template, and checks that a decoded tuple re-encodes to the same bytes.
 * The same input is also decoded directly as a tuple encoding.  Corpus: tests/corpus/frame/. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "linda/proto.h"
#include "linda/tuple.h"

static void check_tuple_bytes(const uint8_t *p, size_t n)
{
    char err[160];
    for (int formals = 0; formals <= 1; formals++) {
        tf_tuple t;
        if (tf_tuple_decode(p, n, &t, formals, err, sizeof err) != 0) {
            if (t.nfields != 0)
                abort(); /* a failed decode leaves the tuple empty */
            continue;
        }
        size_t size = tf_tuple_encoded_size(&t);
        uint8_t *re = malloc(size ? size : 1);
        if (!re)
            abort();
        if (tf_tuple_encode(&t, re) != size || size != n || memcmp(re, p, n) != 0)
            abort(); /* the encoding is canonical: decode then encode is the identity */
        char text[256];
        tf_tuple_format(&t, text, sizeof text);
        tf_tuple_match(&t, &t);
        free(re);
        tf_tuple_clear(&t);
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    size_t off = 0;
    char err[160];
    for (;;) {
        tf_frame f;
        long n = tf_frame_parse(data + off, size - off, &f, err, sizeof err);
        if (n <= 0)
            break;
        if ((size_t)n > size - off || f.body + f.body_len != data + off + n)
            abort();
        check_tuple_bytes(f.body, f.body_len);
        off += (size_t)n;
    }
    check_tuple_bytes(data, size);
    return 0;
}
