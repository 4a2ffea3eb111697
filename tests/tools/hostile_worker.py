#!/usr/bin/env python3
"""tests/tools/hostile_worker.py: a client holding the secret that tries, against a render in
progress, every attack that the worker role (coordinator/render/worker_role.h) must refuse,
then hoards tasks on several connections until the coordinator goes away.

Usage: hostile_worker.py HOST PORT SECRET_FILE WIDTH HEIGHT READY_FILE
Each attack is one request; the expected answer is an ERROR reply for that request (refused,
the connection stays open) or, where noted, an OK that stores nothing.  Prints one line per
attack ("refused: <what>: <coordinator's reason>") and exits 1 at once if any attack is not
answered as expected.  When the attacks are done it writes READY_FILE (the test then starts
the real worker) and holds: its main connection and HOARDERS more each keep one task, sending
heartbeats, so the render can finish only if held tasks are dealt again.  Exits 0 when the
coordinator closes the connections."""
import os
import struct
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from tfwire import (BLOB, DOUBLE, ERROR, IN, INP, INT, OK, OP_NAMES, OUT, RD, RDP, STRING,  # noqa: E402
                    TUPLE, Conn, dec, join)

HOARDERS = 4
# ("task", id, frame, x, y, w, h, excluded)
TASK_TMPL = [(STRING, "task")] + [(INT, None)] * 6 + [(BLOB, None)]
failures = []


def expect(c, what, op, fields, want=ERROR):
    rop, body = c.call(op, fields)
    if rop != want:
        failures.append(what)
        print("NOT REFUSED: %s: got %s" % (what, OP_NAMES.get(rop, rop)))
        return rop, body
    if rop == ERROR:
        print("refused: %s: %s" % (what, body.decode(errors="replace")))
    else:
        print("answered %s as expected: %s" % (OP_NAMES[rop], what))
    return rop, body


def take(c):
    op, body = c.call(IN, TASK_TMPL)
    if op != TUPLE:
        raise SystemExit("cannot take a task: %s" % OP_NAMES.get(op, op))
    f = dec(body)
    return f[1], f[3:7], f[7]


def task_fields(tid, rect, excluded=b"", frame=-1):
    return ([(STRING, "task"), (INT, tid), (INT, frame)] + [(INT, v) for v in rect] +
            [(BLOB, excluded)])


def result_fields(tid, worker, index=b"", chunks=b"", preview=b""):
    """A result tuple (common/farmproto.h, THE RESULT FORMAT) with the given blobs."""
    return [(STRING, "result"), (INT, tid), (INT, worker), (INT, 1), (INT, 0), (INT, 0),
            (INT, 1000), (INT, 4), (INT, 0), (INT, 0), (INT, 0), (BLOB, index), (BLOB, chunks),
            (BLOB, preview)]


def chunk_rec(cx, cy, packed, unpacked):
    return struct.pack("<iiqq", cx, cy, packed, unpacked)


def main():
    host, port, secret, width, height, ready = sys.argv[1], int(sys.argv[2]), sys.argv[3], \
        int(sys.argv[4]), int(sys.argv[5]), sys.argv[6]
    c = Conn(host, port, secret)
    expect(c, "a task taken before joining", IN, TASK_TMPL)
    me = join(c, "hostile")
    print("hostile worker joined as %d" % me)
    expect(c, "joining twice (taking the worker counter again)", IN,
           [(STRING, "next_worker"), (INT, None)])
    expect(c, "putting a worker counter", OUT, [(STRING, "next_worker"), (INT, 1)])
    expect(c, "a second hello", OUT, [(STRING, "hello"), (INT, me), (STRING, "networked"),
                                      (STRING, "x"), (INT, 1), (STRING, "c")])
    expect(c, "taking the scene tuple", IN,
           [(STRING, "scene"), (STRING, None), (INT, None), (INT, None), (STRING, None),
            (STRING, None)])
    expect(c, "replacing the scene", OUT,
           [(STRING, "scene"), (STRING, "[image]\nwidth = 16\n"), (INT, width), (INT, height),
            (STRING, "0" * 64), (STRING, "scanline half")])
    expect(c, "stealing a result", INP, [(STRING, "result")] + [(INT, None)] * 9 + [(BLOB, None)])
    expect(c, "reading a result", RDP, [(STRING, "result")] + [(INT, None)] * 9 + [(BLOB, None)])
    expect(c, "reading a task without taking it", RD, TASK_TMPL)
    expect(c, "a forged stop task", OUT, task_fields(-1, [0, 0, 0, 0]))
    expect(c, "a forged task with a zero-size rectangle", OUT, task_fields(3, [0, 0, 0, 0]))
    expect(c, "a forged task excluding every worker", OUT,
           task_fields(2, [0, 2, width, 2], b"".join(struct.pack("<q", i) for i in range(64))))
    expect(c, "a failure under an invented worker id", OUT,
           [(STRING, "failed"), (INT, 0), (INT, 9999), (STRING, "forged")])
    expect(c, "a failure of a task it does not hold", OUT,
           [(STRING, "failed"), (INT, 0), (INT, me), (STRING, "forged")])
    expect(c, "a result for a task it does not hold (a duplicate)", OUT,
           result_fields(0, me, chunk_rec(0, 0, 4, 4), b"abcd"))
    expect(c, "an unknown tuple", OUT, [(STRING, "x"), (INT, 1)])
    expect(c, "a template without a name", INP, [(STRING, None), (INT, None)])

    tid, rect, excl = take(c)
    print("holding task %d (%dx%d at %d,%d)" % (tid, rect[2], rect[3], rect[0], rect[1]))
    expect(c, "a second task while holding one (hoarding)", IN, TASK_TMPL)
    expect(c, "a task chosen by id", INP, [(STRING, "task"), (INT, tid + 1)] + [(INT, None)] * 5 +
           [(BLOB, None)])
    expect(c, "a result signed with another worker's id", OUT, result_fields(tid, me + 1))
    expect(c, "a result for another task", OUT, result_fields(tid + 1, me))
    expect(c, "a result with empty blobs (no chunk at all)", OUT, result_fields(tid, me))

    tid, rect, excl = take(c)
    npx = rect[2] * rect[3]
    expect(c, "a short result (a chunk of one byte for the whole task)", OUT,
           result_fields(tid, me, chunk_rec(0, rect[1], 1, 1), b"x"))
    tid, rect, excl = take(c)
    npx = rect[2] * rect[3]
    expect(c, "a result whose chunk sizes do not add up", OUT,
           result_fields(tid, me, chunk_rec(0, rect[1], 64, npx * 24), b"y" * 10))
    tid, rect, excl = take(c)
    expect(c, "a task put back with a shifted rectangle", OUT,
           task_fields(tid, [rect[0], rect[1] + 1, rect[2], rect[3]], excl))
    tid, rect, excl = take(c)
    expect(c, "a task put back excluding every worker", OUT,
           task_fields(tid, rect, b"".join(struct.pack("<q", i) for i in range(1, 65))))
    tid, rect, excl = take(c)
    expect(c, "a task put back as it was (re-dealt by the supervisor)", OUT,
           task_fields(tid, rect, excl), want=OK)
    if failures:
        print("hostile worker: %d attacks were not refused: %s" % (len(failures), failures))
        return 1

    # Hoard: this connection and HOARDERS more each hold one task and never answer.
    tid, rect, excl = take(c)
    hoard = [c]
    for _ in range(HOARDERS):
        h = Conn(host, port, secret)
        join(h, "hostile")
        take(h)
        hoard.append(h)
    print("hostile worker: every attack refused; hoarding %d tasks" % len(hoard))
    sys.stdout.flush()
    open(ready, "w").close()
    deadline = time.time() + 120
    while hoard and time.time() < deadline:
        for h in list(hoard):
            try:
                h.ping()
            except OSError:
                hoard.remove(h)
        time.sleep(1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
