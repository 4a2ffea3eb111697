/* fuzz_seal.c: libFuzzer harness for the sealed record layer (common/linda/seal.c).  Each input
 * is used twice:
 *   - as the bytes a peer sent after AUTH_OK: opened record after record with the receiving
 *     state of a fixed key and handshake, as tsserver.c's unseal_and_serve does.  Checks the
 *     contract of tf_seal_open: a record it opens used exactly its 4 length bytes plus L and
 *     gave L - TF_SEAL_ABYTES bytes of plaintext; "not complete" (0) only when the bytes are
 *     short of the record; a refusal is one non-empty line and leaves the plaintext alone;
 *   - as plaintext: sealed in pieces the input's own bytes choose, then opened from a wire
 *     handed over in pieces, which must give back exactly the input; then one byte of that
 *     wire altered (where the input says) must never open to the whole input.
 * The committed seeds (tests/corpus/seal/, made by tests/tools/fuzzseeds.c) are records
 * sealed under this harness's key, so the replay opens records, and refused_* ones (cut
 * short, altered, replayed, a length out of bounds) for the refusals. */
#include <sodium.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "linda/seal.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* The fixed key and handshake nonces the seeds are sealed under (fuzzseeds.c uses these). */
static void seal_pair(tf_seal *client_tx, tf_seal *server_rx)
{
    uint8_t key[TF_KEY_BYTES], ns[TF_NONCE_BYTES], nc[TF_NONCE_BYTES];
    tf_seal server_tx, client_rx;
    memset(key, 0x4b, sizeof key);
    memset(ns, 0x53, sizeof ns);
    memset(nc, 0x43, sizeof nc);
    tf_seal_init(key, ns, nc, 1, client_tx, &client_rx);
    tf_seal_init(key, ns, nc, 0, &server_tx, server_rx);
}

static uint32_t le32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

/* One tf_seal_open of buf[0..len) checked against its contract; its return value. */
static long open_checked(tf_seal *rx, const uint8_t *buf, size_t len, tf_buf *plain)
{
    char err[160] = "";
    size_t before = plain->len;
    uint64_t counter = rx->counter;
    long n = tf_seal_open(rx, buf, len, plain, err, sizeof err);
    if (n < 0 && (err[0] == '\0' || strchr(err, '\n') || plain->len != before))
        abort();
    if (n == 0 && (plain->len != before || (len >= 4 && len - 4 >= le32(buf))))
        abort(); /* "not complete" for a record that is complete */
    if (n > 0 && ((size_t)n > len || (size_t)n != 4 + (size_t)le32(buf) ||
                  plain->len - before != (size_t)n - 4 - TF_SEAL_ABYTES ||
                  rx->counter != counter + 1))
        abort();
    return n;
}

/* The input as wire bytes: open records until one is refused or incomplete. */
static void open_wire(const uint8_t *data, size_t size)
{
    tf_seal tx, rx;
    tf_buf plain;
    seal_pair(&tx, &rx);
    tf_buf_init(&plain);
    size_t off = 0;
    long n;
    while ((n = open_checked(&rx, data + off, size - off, &plain)) > 0)
        off += (size_t)n;
    tf_buf_free(&plain);
}

/* Seal data in pieces of 1..64 bytes (the input's bytes choose) onto wire. */
static void seal_pieces(tf_seal *tx, const uint8_t *data, size_t size, tf_buf *wire)
{
    size_t off = 0;
    for (size_t k = 0; off < size; k++) {
        size_t piece = 1 + data[k % size] % 64;
        if (piece > size - off)
            piece = size - off;
        if (tf_seal_append(tx, wire, data + off, piece) != 0)
            abort();
        off += piece;
    }
}

/* Open wire as a reader would, the bytes arriving `step` at a time; the plaintext in *plain.
 * Returns 1 if every byte of wire was opened, 0 if a record was refused or left incomplete. */
static int open_arriving(tf_seal *rx, const uint8_t *wire, size_t len, size_t step,
                         tf_buf *plain)
{
    size_t used = 0, arrived = 0;
    while (arrived < len) {
        arrived = len - arrived < step ? len : arrived + step;
        long n;
        while ((n = open_checked(rx, wire + used, arrived - used, plain)) > 0)
            used += (size_t)n;
        if (n < 0)
            return 0;
    }
    return used == len;
}

/* Flip one bit of the sealed wire (where the input says): it must never open whole. */
static void check_tamper(const uint8_t *data, size_t size, tf_buf *wire, size_t step)
{
    tf_seal tx, rx;
    tf_buf plain;
    tf_buf_init(&plain);
    seal_pair(&tx, &rx);
    uint8_t *w = tf_buf_head(wire);
    w[data[size - 1] * 131u % wire->len] ^= (uint8_t)(1u << (data[0] % 8));
    if (open_arriving(&rx, w, wire->len, step, &plain))
        abort(); /* an altered record was accepted */
    tf_buf_free(&plain);
}

/* Seal, open, compare; then the same wire altered. */
static void roundtrip(const uint8_t *data, size_t size)
{
    tf_seal tx, rx;
    tf_buf wire, plain;
    tf_buf_init(&wire);
    tf_buf_init(&plain);
    seal_pair(&tx, &rx);
    seal_pieces(&tx, data, size, &wire);
    size_t step = 1 + data[0] % 97;
    if (!open_arriving(&rx, tf_buf_head(&wire), wire.len, step, &plain) ||
        plain.len != size || memcmp(tf_buf_head(&plain), data, size) != 0)
        abort(); /* what was sealed must open to itself */
    check_tamper(data, size, &wire, step);
    tf_buf_free(&wire);
    tf_buf_free(&plain);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (sodium_init() < 0)
        abort();
    open_wire(data, size);
    if (size > 0)
        roundtrip(data, size);
    return 0;
}
