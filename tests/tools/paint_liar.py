#!/usr/bin/env python3
"""paint_liar.py: a paint worker that speaks the protocol and lies (coordinator/paint/
paint_role.h), for tests/e2e/paint_hostile.sh.  Against a `terrafarm paint -j 0 --listen`
that no honest worker has joined yet, each lie on a fresh connection, it checks:

  - a result for a task never dealt is refused (ERROR), and so is one for a task another
    connection holds;
  - putting back a paint task that is not the stop task is refused;
  - a result of the wrong length for a task it holds, and one of the right length holding a
    NaN, are refused after admission: the connection is closed and the status counts them;
  - a result of a task taken in view 1 and sent after the page moved to view 2 is discarded
    (answered OK, counted stale, never drawn);
  - a tuple over the role's size bound closes the connection.
Each refusal must leave the paint serving: the status answers after each.

Usage: paint_liar.py HOST:PORT PAGE_URL
Prints what it checks; on the first failure prints "FAIL: ..." and exits 1."""
import json
import os
import struct
import sys
import time
import urllib.request

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import tfwire as w

host, port = sys.argv[1].rsplit(":", 1)
page = sys.argv[2].rstrip("/") + "/"


def fail(msg):
    print("FAIL: " + msg)
    sys.exit(1)


def status():
    with urllib.request.urlopen(page + "api/paint/status", timeout=10) as r:
        return json.loads(r.read())


def post(path, body):
    req = urllib.request.Request(page + path, data=json.dumps(body).encode(), method="POST",
                                 headers={"X-Terrafarm-Token": "loopback",
                                          "Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=10) as r:
        return r.status


def join():
    c = w.Conn(host, int(port))
    op, body = c.call(w.IN, [(w.STRING, "next_worker"), (w.INT, None)])
    if op != w.TUPLE:
        fail("cannot take a worker id: op %d" % op)
    wid = w.dec(body)[1]
    op, _ = c.call(w.OUT, [(w.STRING, "hello"), (w.INT, wid), (w.STRING, "networked"),
                           (w.STRING, "liar"), (w.INT, os.getpid()), (w.STRING, "c")])
    if op != w.OK:
        fail("hello refused: op %d" % op)
    return c, wid


def take(c):
    op, body = c.call(w.IN, [(w.STRING, "paint_task"), (w.INT, None), (w.INT, None),
                             (w.BLOB, None)])
    if op != w.TUPLE:
        fail("cannot take a paint task: op %d" % op)
    _, gen, tid, nodes = w.dec(body)
    return gen, tid, nodes


def node_values(nodes, width, height):
    """Floats the answer to a task's nodes takes (common/paintproto.c)."""
    total = 0
    for k in range(len(nodes) // 20):
        x, y, s, d, flags = struct.unpack_from("<5i", nodes, 20 * k)
        ex, ey = min(x + s, width), min(y + s, height)
        if d == 0:
            total += (ex - x) * (ey - y) * 6
        else:
            ni, nj = (ex - x + d - 1) // d + 1, (ey - y + d - 1) // d + 1
            total += (ni * nj - (4 if flags & 1 else 0)) * 3
    return total


def result(c, gen, tid, wid, values):
    return c.call(w.OUT, [(w.STRING, "paint_result"), (w.INT, gen), (w.INT, tid), (w.INT, wid),
                          (w.INT, 1000), (w.BLOB, values)])[0]


def closed(c, seconds=60):
    """Whether the paint closes this connection: it does so from its loop, after taking the
    result from the space, so ask until it has (or until a generous bound has passed)."""
    end = time.time() + seconds
    while time.time() < end:
        try:
            c.call(w.RDP, [(w.STRING, "scene"), (w.STRING, None), (w.INT, None),
                           (w.INT, None), (w.STRING, None), (w.STRING, None)])
        except (EOFError, OSError):
            return True
        time.sleep(0.02)
    return False


def wait_status(key, want, seconds=60):
    """The status's key reaches want (the loop publishes it once an iteration)."""
    end = time.time() + seconds
    while time.time() < end:
        if status()[key] >= want:
            return True
        time.sleep(0.02)
    return False


s0 = status()
W, H = s0["width"], s0["height"]
if post("api/paint/resume", {}) != 202:
    fail("resume refused")

c, wid = join()
if result(c, 1, 999999, wid, b"\0" * 12) != w.ERROR:
    fail("a result for a task never dealt was accepted")
print("a result for a task never dealt: refused")
gen, tid, nodes = take(c)
c2, wid2 = join()
if result(c2, gen, tid, wid2, b"\0" * 4 * node_values(nodes, W, H)) != w.ERROR:
    fail("a result for another connection's task was accepted")
print("a result for another connection's task: refused")
if c2.call(w.OUT, [(w.STRING, "paint_task"), (w.INT, gen), (w.INT, 12345),
                   (w.BLOB, nodes)])[0] != w.ERROR:
    fail("a made-up paint task was put into the space")
print("a paint task put back that is not the stop task: refused")

refused0 = status()["refused"]
if result(c, gen, tid, wid, b"\0" * (4 * node_values(nodes, W, H) - 4)) != w.OK:
    fail("a short result was not even admitted")
if not closed(c):
    fail("the connection that sent a short result is still open")
print("a result of the wrong length: refused, connection closed")

c, wid = join()
gen, tid, nodes = take(c)
vals = [0.5] * node_values(nodes, W, H)
vals[len(vals) // 2] = float("nan")
result(c, gen, tid, wid, struct.pack("<%df" % len(vals), *vals))
if not closed(c):
    fail("the connection that sent a NaN is still open")
if not wait_status("refused", refused0 + 2):
    fail("the status counts %d refused results, expected %d" % (status()["refused"], refused0 + 2))
print("a result holding a NaN: refused, connection closed")

c, wid = join()
gen, tid, nodes = take(c)
stale0 = status()["stale"]
v = status()["view"]
v["sun"]["azimuth"] = (v["sun"]["azimuth"] + 40) % 360
if post("api/paint/view", v) != 202:
    fail("the page's new view was refused")
if not wait_status("gen", gen + 1):
    fail("the paint never moved to the new view")
if result(c, gen, tid, wid, struct.pack("<%df" % node_values(nodes, W, H),
                                        *([0.25] * node_values(nodes, W, H)))) != w.OK:
    fail("a result of the view left behind was not quietly discarded")
if not wait_status("stale", stale0 + 1) or status()["stale"] != stale0 + 1:
    fail("the stale result was not counted (stale %d, was %d)" % (status()["stale"], stale0))
print("a result of the view left behind: discarded, counted stale")

big = b"\0" * (64 << 20)
try:
    c.call(w.OUT, [(w.STRING, "paint_result"), (w.INT, gen + 1), (w.INT, 1), (w.INT, wid),
                   (w.INT, 0), (w.BLOB, big)])
except (EOFError, OSError):
    pass
if not closed(c):
    fail("a 64 MiB tuple did not close the connection")
print("a tuple over the size bound: connection closed")
status()
print("the paint still serves")
