#!/usr/bin/env python3
"""tests/tools/gate_worker.py: a networked worker that joins a render and takes nothing.

Usage: gate_worker.py HOST PORT SECRET_FILE
Connects with the secret, takes a worker id and says hello (so it counts toward the
coordinator's --wait-workers), then holds the connection, with heartbeats, without asking for a
task until the coordinator closes it.  A test whose real workers are frozen at a --wait-workers gate starts it
to open the gate: dealing begins, yet no task is rendered until the test lets a worker run.
Exit 0 when the coordinator closes (or resets) the connection, 1 if it cannot join."""
import os
import select
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from tfwire import Conn, join  # noqa: E402


def main():
    if len(sys.argv) != 4:
        raise SystemExit("usage: gate_worker.py HOST PORT SECRET_FILE")
    c = Conn(sys.argv[1], int(sys.argv[2]), sys.argv[3])
    me = join(c, "gate")
    print("gate_worker: joined as worker %d" % me, flush=True)
    # A heartbeat twice a second (the coordinator drops a connection silent for a lease), the
    # replies read and dropped, until the coordinator closes or resets the connection.
    try:
        while True:
            c.ping()
            ready, _, _ = select.select([c.s], [], [], 0.5)
            if ready and not c.s.recv(65536):
                break
    except OSError:
        pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
