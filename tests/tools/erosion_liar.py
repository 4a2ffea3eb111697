#!/usr/bin/env python3
"""tests/tools/erosion_liar.py: a networked erosion worker that lies (common/erosion_tuples.h,
coordinator/erosion/erosion_role.h).

Usage: erosion_liar.py HOST PORT
Reads the plan, takes one patch as a real worker would, then:
  1. puts an edge, a final band and a tally for a patch it does not hold: each must be refused
     (ERROR reply; the role's ownership guard);
  2. takes a second patch: refused (one patch per connection);
  3. puts its own edges of round 0 (allowed: they are its to put) one element short, so the
     real worker next to it must refuse them when it reads them and fail the erosion, naming
     the patch and what is wrong; the coordinator then exits non-zero and writes nothing.
Prints one line per step; exits 1 if a refusal did not come, 0 when the coordinator hangs up
(which it may do while the short edges are still being put)."""
import os
import struct
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from tfwire import BLOB, ERROR, IN, INT, OK, OP_NAMES, OUT, RDP, STRING, TUPLE, Conn, dec  # noqa: E402

FIELDS = 6  # bedrock, talus, silt, water, load, flow: 4 bytes each


def main():
    host, port = sys.argv[1], int(sys.argv[2])
    c = Conn(host, port)
    op, body = c.call(RDP, [(STRING, "erode_plan")] + [(INT, None)] * 6)
    if op != TUPLE:
        sys.exit("no erosion plan: %s" % OP_NAMES.get(op, op))
    _, job, n, px, py, halo, steps = dec(body)
    op, body = c.call(IN, [(STRING, "erode_patch"), (INT, job), (INT, None)])
    if op != TUPLE:
        sys.exit("no patch: %s" % OP_NAMES.get(op, op))
    mine = dec(body)[2]
    other = (mine + 1) % (px * py)
    print("holding patch %d of %dx%d (grid %d, halo %d)" % (mine, px, py, n, halo))
    bad = []

    def refused(what, op, fields):
        rop, rbody = c.call(op, fields)
        if rop == ERROR:
            print("refused: %s: %s" % (what, rbody.decode(errors="replace")))
        else:
            bad.append(what)
            print("NOT REFUSED: %s: %s" % (what, OP_NAMES.get(rop, rop)))

    blob = bytes(FIELDS * 4 * halo * 8)
    refused("an edge of patch %d" % other, OUT,
            [(STRING, "erode_edge"), (INT, job), (INT, other), (INT, 0), (INT, 0), (BLOB, blob)])
    refused("a final band of patch %d" % other, OUT,
            [(STRING, "erode_final"), (INT, job), (INT, other), (INT, 0), (INT, 1), (BLOB, blob)])
    refused("a tally of patch %d" % other, OUT,
            [(STRING, "erode_tally"), (INT, job), (INT, other)] + [(INT, 0)] * 4)
    refused("a second patch", IN, [(STRING, "erode_patch"), (INT, job), (INT, None)])
    if bad:
        sys.exit(1)
    # its own edges, one element short: its neighbour must refuse them.  The coordinator may
    # fail the erosion and hang up as soon as the first one it needs is read, even before this
    # client has read the reply: a closed connection from here on is the expected end.
    n_cols = n // px + 2
    short = bytes(FIELDS * 4 * halo * n_cols - 4)
    c.s.settimeout(120)
    try:
        for side in range(4):
            op, _ = c.call(OUT, [(STRING, "erode_edge"), (INT, job), (INT, mine), (INT, 0),
                                 (INT, side), (BLOB, short)])
            if op != OK:
                sys.exit("own edge %d not stored: %s" % (side, OP_NAMES.get(op, op)))
        print("put its own edges of round 0, short")
        c.recv()  # hold the patch until the coordinator gives up and hangs up
    except (EOFError, OSError):
        pass
    print("the coordinator hung up")


if __name__ == "__main__":
    main()
