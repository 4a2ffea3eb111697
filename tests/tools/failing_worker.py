#!/usr/bin/env python3
"""tests/tools/failing_worker.py: a networked worker that fails every task it takes.

Usage: failing_worker.py HOST PORT
Speaks the tuple-space protocol (common/linda/proto.h, tuple encoding in common/linda/tuple.h) and the
farm's tuples (common/farmproto.h) directly: takes a worker id, says hello, then for every task
it is not excluded from puts ("failed", id, worker, FAILURE) back; a task that lists
it as excluded goes back into the space untouched.  Leaves on the stop task (id -1), which it
also puts back, or when the coordinator goes away.  Exit 0 on a stop task, 1 otherwise.

Its words are hostile too: its host name carries an escape sequence and its failure message a
newline and a forged line of the coordinator's ("terrafarm: wrote ..."), which the coordinator's
log must show as one line with the control bytes made harmless (common/log.c)."""
import os
import socket
import struct
import sys
import time

OUT, IN, TUPLE, OK, HELLO = 1, 2, 6, 8, 11
FAILURE = "injected failure\nterrafarm: wrote /tmp/forged.exr (240x135) \x1b[2J"
HOST = "failing\x1b]0;owned\x07"
INT, DOUBLE, STRING, BLOB, FORMAL = 1, 2, 3, 4, 0x80


def enc(fields):
    """fields: list of (type, value); value None makes a formal."""
    out = bytes([len(fields)])
    for t, v in fields:
        if v is None:
            out += bytes([t | FORMAL])
        elif t == INT:
            out += bytes([t]) + struct.pack("<q", v)
        elif t in (STRING, BLOB):
            b = v.encode() if isinstance(v, str) else v
            out += bytes([t]) + struct.pack("<I", len(b)) + b
        else:
            raise ValueError(t)
    return out


def dec(body):
    n, pos, fields = body[0], 1, []
    for _ in range(n):
        t = body[pos]
        pos += 1
        if t in (INT, DOUBLE):
            fields.append(struct.unpack_from("<q" if t == INT else "<d", body, pos)[0])
            pos += 8
        else:
            (ln,) = struct.unpack_from("<I", body, pos)
            fields.append(body[pos + 4:pos + 4 + ln])
            pos += 4 + ln
    return fields


class Conn:
    def __init__(self, host, port):
        self.s = socket.create_connection((host, port), timeout=30)
        self.req = 0
        op, _ = self.recv()
        if op != HELLO:
            raise SystemExit("expected HELLO, got op %d" % op)

    def recv_exact(self, n):
        data = b""
        while len(data) < n:
            chunk = self.s.recv(n - len(data))
            if not chunk:
                raise EOFError
            data += chunk
        return data

    def recv(self):
        (length,) = struct.unpack("<I", self.recv_exact(4))
        rest = self.recv_exact(length)
        return rest[1], rest[6:]

    def call(self, op, fields):
        self.req += 1
        body = enc(fields)
        self.s.sendall(struct.pack("<IBBI", 6 + len(body), 1, op, self.req) + body)
        rop, rbody = self.recv()
        return rop, rbody


def main():
    c = Conn(sys.argv[1], int(sys.argv[2]))
    op, body = c.call(IN, [(STRING, "next_worker"), (INT, None)])
    me = dec(body)[1]  # the coordinator binds this id to the connection and restores the counter
    c.call(OUT, [(STRING, "hello"), (INT, me), (STRING, "networked"), (STRING, HOST),
                 (INT, os.getpid()), (STRING, "c")])
    # ("task", id, frame, x, y, w, h, excluded)
    task_tmpl = [(STRING, "task")] + [(INT, None)] * 6 + [(BLOB, None)]
    failures = 0
    while True:
        try:
            op, body = c.call(IN, task_tmpl)
        except (EOFError, OSError):
            print("failing worker %d: coordinator gone after %d failures" % (me, failures))
            return 1
        f = dec(body)
        tid, excluded = f[1], f[7]
        back = [(STRING, "task")] + [(INT, v) for v in f[1:7]] + [(BLOB, excluded)]
        if tid == -1:
            c.call(OUT, back)
            print("failing worker %d: stop after %d failures" % (me, failures))
            return 0
        ex = [struct.unpack_from("<q", excluded, 8 * i)[0] for i in range(len(excluded) // 8)]
        if me in ex:
            c.call(OUT, back)
            time.sleep(0.2)
            continue
        c.call(OUT, [(STRING, "failed"), (INT, tid), (INT, me), (STRING, FAILURE)])
        failures += 1


if __name__ == "__main__":
    sys.exit(main())
