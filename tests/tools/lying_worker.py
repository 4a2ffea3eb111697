#!/usr/bin/env python3
"""tests/tools/lying_worker.py: a networked worker that answers every task with a result whose
chunks lie (farmproto.h, "THE RESULT FORMAT"), to check that the coordinator refuses them.

Usage: lying_worker.py HOST PORT MAX_LIES
Speaks the tuple-space protocol itself (the helpers of failing_worker.py).  Reads the scene
tuple for the image size and the output layout, then for each task it is not excluded from puts
back a result that lies in one of these ways, in turn:
  coords    chunk coordinates of the next task (right sizes otherwise)
  unpacked  an unpacked size that cannot belong to the task's chunk
  sum       packed sizes that do not add up to the chunks blob
  count     one chunk too few
  preview   a preview share of the wrong size
  garbage   a perfect structure whose packed bytes do not decode
  nonfinite chunks stored raw (packed = unpacked) whose values are NaN and infinity
  rays      a perfect structure claiming 2^62 primary rays (more than the task can hold)
The last three are refused only by what the coordinator checks of a result beyond its
structure: its counts at once, its pixels in the checker thread (coordinator/render/resultcheck.h).
After MAX_LIES results it stops lying and leaves (so a real worker finishes the render); it also
leaves on the stop task.  Prints one line per lie: "lie MODE task ID"."""
import os
import random
import struct
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from failing_worker import Conn, dec, IN, OUT, INT, STRING, BLOB  # noqa: E402

RD = 3  # common/linda/proto.h: TF_OP_RD

MODES = ["coords", "unpacked", "sum", "count", "preview", "garbage", "nonfinite", "rays"]


def layout_of(text):
    parts = text.split()
    if parts[0] == "tiled":
        tw, th = (int(v) for v in parts[1].split("x"))
        return True, tw, th, parts[2]
    return False, 0, 0, parts[1]


def chunks_of(rect, tiled, tw, th, pixel):
    """[(cx, cy, unpacked)] of a task rectangle, in file order (image/exrlayout.c)."""
    x, y, w, h = rect
    bpp = 16 if pixel == "half" else 24
    if tiled:
        return [(x // tw, y // th, w * h * bpp)]
    return [(0, y + i, w * bpp) for i in range(h)]


def preview_len(rect, width, height):
    side = max(width, height)
    f = max(1, (side + 1023) // 1024)
    pw, ph = (width + f - 1) // f, (height + f - 1) // f

    def first(a, size, n):
        if a >= size:
            return n
        num = a - f // 2
        i = 0 if num <= 0 else (num + f - 1) // f
        return min(i, n)
    x, y, w, h = rect
    return (first(x + w, width, pw) - first(x, width, pw)) * \
        (first(y + h, height, ph) - first(y, height, ph)) * 3


def lie(mode, rect, tiled, tw, th, pixel, width, height):
    chunks = chunks_of(rect, tiled, tw, th, pixel)
    recs, data = [], b""
    for cx, cy, unpacked in chunks:
        if mode == "nonfinite":  # halves 0x7c00 (+inf) and 0xffff (NaN), floats 0xffffffff
            recs.append([cx, cy, unpacked, unpacked])
            data += (b"\x00\x7c\xff\xff" * unpacked)[:unpacked]
            continue
        packed = max(1, min(unpacked, 64))
        recs.append([cx, cy, packed, unpacked])
        data += bytes(random.getrandbits(8) for _ in range(packed))
    prev = bytes(preview_len(rect, width, height))
    if mode == "coords":
        recs[0][1] += 1
    elif mode == "unpacked":
        recs[0][3] += 16
    elif mode == "sum":
        data += b"x"
    elif mode == "count":
        if len(recs) > 1:
            data = data[:-recs[-1][2]]
            recs.pop()
        else:
            recs.append([recs[0][0] + 1, recs[0][1], 1, recs[0][3]])
            data += b"y"
    elif mode == "preview":
        prev += b"\0\0\0"
    index = b"".join(struct.pack("<iiqq", *r) for r in recs)
    return index, data, prev


def main():
    host, port, max_lies = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    c = Conn(host, port)
    op, body = c.call(RD, [(STRING, "scene"), (STRING, None), (INT, None), (INT, None),
                           (STRING, None), (STRING, None)])
    scene = dec(body)
    width, height = scene[2], scene[3]
    tiled, tw, th, pixel = layout_of(scene[5].decode())
    op, body = c.call(IN, [(STRING, "next_worker"), (INT, None)])
    me = dec(body)[1]
    # the coordinator binds this id to the connection and restores the counter itself
    c.call(OUT, [(STRING, "hello"), (INT, me), (STRING, "networked"), (STRING, "lying"),
                 (INT, os.getpid()), (STRING, "c")])
    # ("task", id, frame, x, y, w, h, excluded)
    task_tmpl = [(STRING, "task")] + [(INT, None)] * 6 + [(BLOB, None)]
    lies = 0
    while lies < max_lies:
        op, body = c.call(IN, task_tmpl)
        f = dec(body)
        tid, rect, excluded = f[1], tuple(f[3:7]), f[7]
        back = [(STRING, "task")] + [(INT, v) for v in f[1:7]] + [(BLOB, excluded)]
        if tid == -1:
            c.call(OUT, back)
            break
        ex = [struct.unpack_from("<q", excluded, 8 * i)[0] for i in range(len(excluded) // 8)]
        if me in ex:
            c.call(OUT, back)
            time.sleep(0.2)
            continue
        mode = MODES[lies % len(MODES)]
        index, data, prev = lie(mode, rect, tiled, tw, th, pixel, width, height)
        primary = 2 ** 62 if mode == "rays" else 100
        c.call(OUT, [(STRING, "result"), (INT, tid), (INT, me), (INT, primary), (INT, 10), (INT, 1),
                     (INT, 1000000), (INT, rect[2] * rect[3]), (INT, 0), (INT, 0), (INT, 0),
                     (BLOB, index), (BLOB, data), (BLOB, prev)])
        print("lie %s task %d" % (mode, tid), flush=True)
        lies += 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
