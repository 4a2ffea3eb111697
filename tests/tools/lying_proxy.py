#!/usr/bin/env python3
"""tests/tools/lying_proxy.py: makes a real worker a liar.  A TCP proxy for a coordinator
without a secret (loopback: frames in clear, common/linda/proto.h) that passes everything
through but changes one pixel of every result the worker puts (("result", ...) field 12,
common/farmproto.h): its first chunk is inflated, its ZIP filter undone (image/exrcheck.c),
the lowest bit of its first value flipped, and it is sent back stored raw (packed = unpacked).
The result stays structurally valid, decodes and holds finite values: only its pixels lie,
and only --verify (coordinator/render/verify.h) can tell.

Usage: lying_proxy.py HOST PORT [SOURCE_ADDRESS [HONEST_FIRST]]
It connects to the coordinator from SOURCE_ADDRESS (e.g. 127.0.0.2), as a machine of its own.
With HONEST_FIRST = N it passes the first N results through untouched (a liar that earns trust
by passing its first checks, then lies: "passed a result" lines for those).
Prints "listening on PORT" once ready, then one line per altered result; runs until killed."""
import os
import struct
import sys
import zlib

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from tfwire import enc, frame as make_frame, serve_proxy, shut_both  # noqa: E402

OUT = 1
honest_left = 0


def field_span(body, index):
    """(offset, length) of field `index` of the tuple encoded in body, or None."""
    n, pos = body[0], 1
    for i in range(n):
        tag = body[pos]
        pos += 1
        if tag & 0x80:
            if i == index:
                return None
            continue
        if tag in (1, 2):
            span = (pos, 8)
            pos += 8
        else:
            (ln,) = struct.unpack_from("<I", body, pos)
            span = (pos + 4, ln)
            pos += 4 + ln
        if i == index:
            return span
    return None


def typed_fields(body):
    """[(type, value)] of the tuple encoded in body (all actuals)."""
    n, pos, out = body[0], 1, []
    for _ in range(n):
        tag = body[pos]
        pos += 1
        if tag in (1, 2):
            out.append((tag, struct.unpack_from("<q" if tag == 1 else "<d", body, pos)[0]))
            pos += 8
        else:
            (ln,) = struct.unpack_from("<I", body, pos)
            out.append((tag, bytes(body[pos + 4:pos + 4 + ln])))
            pos += 4 + ln
    return out


def raw_chunk(packed, unpacked):
    """The bytes a reader decodes from an OpenEXR ZIP/ZIPS chunk (stored raw if same size)."""
    if len(packed) == unpacked:
        return bytearray(packed)
    t = bytearray(zlib.decompress(packed))
    for i in range(1, len(t)):
        t[i] = (t[i - 1] + t[i] - 128) & 0xff
    half = (len(t) + 1) // 2
    out = bytearray(len(t))
    out[0::2] = t[:half]
    out[1::2] = t[half:]
    return out


INDEX, CHUNKS = 11, 12  # the result's index and chunks blobs (common/farmproto.h)


def altered_body(body):
    """The result tuple with its first chunk's first value changed in its lowest bit."""
    f = typed_fields(body)
    index, chunks = bytearray(f[INDEX][1]), f[CHUNKS][1]
    cx, cy, packed, unpacked = struct.unpack_from("<iiqq", index, 0)
    raw = raw_chunk(chunks[:packed], unpacked)
    raw[0] ^= 0x01
    struct.pack_into("<iiqq", index, 0, cx, cy, unpacked, unpacked)
    f[INDEX] = (f[INDEX][0], bytes(index))
    f[CHUNKS] = (f[CHUNKS][0], bytes(raw) + chunks[packed:])
    return enc(f)


def lie(frame):
    """frame: one whole frame (length field included).  Returns it, altered if a result."""
    if len(frame) < 11 or frame[5] != OUT:
        return frame
    body = bytearray(frame[10:])
    first = field_span(body, 0)
    if not first or bytes(body[first[0]:first[0] + first[1]]) != b"result":
        return frame
    span = field_span(body, CHUNKS)
    if not span or span[1] == 0:
        return frame
    global honest_left
    if honest_left > 0:
        honest_left -= 1
        print("passed a result", flush=True)
        return frame
    op, req = struct.unpack_from("<BI", frame, 5)
    print("altered a result", flush=True)
    return make_frame(op, req, altered_body(body))


def worker_to_coordinator(src, dst):
    buf = b""
    try:
        while True:
            data = src.recv(65536)
            if not data:
                break
            buf += data
            while len(buf) >= 4:
                (length,) = struct.unpack_from("<I", buf)
                if len(buf) < 4 + length:
                    break
                frame, buf = buf[:4 + length], buf[4 + length:]
                dst.sendall(lie(frame))
    except OSError:
        pass
    shut_both(src, dst)


def coordinator_to_worker(src, dst):
    try:
        while True:
            data = src.recv(65536)
            if not data:
                break
            dst.sendall(data)
    except OSError:
        pass
    shut_both(src, dst)


def main():
    host, port = sys.argv[1], int(sys.argv[2])
    source = (sys.argv[3], 0) if len(sys.argv) > 3 and sys.argv[3] else None
    global honest_left
    honest_left = int(sys.argv[4]) if len(sys.argv) > 4 else 0
    serve_proxy(host, port, lambda c, s, n: [(worker_to_coordinator, (c, s)),
                                             (coordinator_to_worker, (s, c))], source)


if __name__ == "__main__":
    main()
