#!/usr/bin/env python3
"""tests/tools/check_copy_thief.py: a worker that takes --verify check copies it is excluded
from and answers them (coordinator/render/supervisor_verify.c,
spot checks; invariant S9 in supervisor.c).

Usage: check_copy_thief.py HOST PORT
Joins twice (from 127.0.0.2, a machine of its own), in this order, on two connections:
  sitter  joins and announces itself, then takes nothing: a second live worker, so the
          coordinator deals check copies, but never one that could take them;
  thief   joins and answers every task it takes with a result that is valid (chunks stored raw,
          all zero: they decode and are finite), also the check copies of its own results,
          which exclude it.
A check copy answered by a worker it excludes is no check: the coordinator must deal it again.
The thief stops once it has taken the same check copy twice (proof that it was dealt again)
and prints "copy of task N dealt again"; if its next task never comes (the copy was dropped:
the render would hang), it says so and exits 1.  Run against a render with --verify 1 and a
watermark that leaves nothing else to deal (the sitter holds no task, so nothing is written)."""
import os
import socket
import struct
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from tfwire import Conn, dec, join, IN, OUT, RD, INT, STRING, BLOB, OK  # noqa: E402
from lying_worker import layout_of, chunks_of, preview_len  # noqa: E402

TASK = [(STRING, "task")] + [(INT, None)] * 6 + [(BLOB, None)]


def zero_result(tid, me, rect, scene):
    width, height, (tiled, tw, th, pixel) = scene
    recs, data = b"", b""
    for cx, cy, unpacked in chunks_of(rect, tiled, tw, th, pixel):
        recs += struct.pack("<iiqq", cx, cy, unpacked, unpacked)
        data += bytes(unpacked)
    prev = bytes(preview_len(rect, width, height))
    return [(STRING, "result"), (INT, tid), (INT, me), (INT, 1), (INT, 0), (INT, 0), (INT, 1000),
            (INT, 0), (INT, 0), (INT, 0), (INT, 0), (BLOB, recs), (BLOB, data), (BLOB, prev)]


def main():
    host, port = sys.argv[1], int(sys.argv[2])
    sitter = Conn(host, port, source="127.0.0.2")
    op, body = sitter.call(RD, [(STRING, "scene"), (STRING, None), (INT, None), (INT, None),
                                (STRING, None), (STRING, None)])
    f = dec(body)
    scene = (f[2], f[3], layout_of(f[5].decode()))
    join(sitter, "sitter")
    thief = Conn(host, port, source="127.0.0.2")
    me = join(thief, "thief")
    stolen = set()
    while True:
        try:
            op, body = thief.call(IN, TASK)
        except socket.timeout:
            print("no task came after the thief answered check copies %s: a copy was dropped"
                  % sorted(stolen), flush=True)
            return 1
        f = dec(body)
        tid, rect, excluded = f[1], tuple(f[3:7]), f[7]
        ex = [struct.unpack_from("<q", excluded, 8 * i)[0] for i in range(len(excluded) // 8)]
        if me in ex and tid in stolen:
            print("copy of task %d dealt again" % tid, flush=True)
            return 0
        op, body = thief.call(OUT, zero_result(tid, me, rect, scene))
        if me in ex:
            stolen.add(tid)
            print("answered the check copy of task %d (reply %s)" % (tid, "OK" if op == OK else op),
                  flush=True)


if __name__ == "__main__":
    sys.exit(main())
