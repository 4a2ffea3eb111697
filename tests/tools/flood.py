#!/usr/bin/env python3
"""tests/tools/flood.py: pre-authentication floods against a coordinator that requires a secret.

Usage: flood.py HOST PORT SECONDS [SOURCE_ADDRESS]
For SECONDS it keeps, at once:
  - OVERSIZED connections, each announcing a 64 MiB frame and streaming bytes of it as fast as
    the coordinator takes them (the server must read no more than a handshake's worth);
  - IDLE connections opened by the thousand that never send a byte;
  - a few clients that send a valid-looking AUTH with a wrong MAC over and over.
Prints "flood: under way" once OVERSIZED connections were opened and bytes went out on them
(the caller waits for that line instead of sleeping), then at the end counts of what happened
(connections opened, closed by the server, refused) and exits 0; the test judges the
coordinator (the render completes, its memory stays bounded)."""
import os
import resource
import selectors
import socket
import struct
import sys
import time

OVERSIZED = 100
IDLE = 3000


def main():
    host, port, seconds = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
    source = sys.argv[4] if len(sys.argv) > 4 else None
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (min(hard, OVERSIZED + IDLE + 256), hard))
    sel = selectors.DefaultSelector()
    stats = {"opened": 0, "closed_by_server": 0, "refused": 0, "bytes_sent": 0}
    big = struct.pack("<IBBI", 64 * 1024 * 1024, 1, 1, 1) + os.urandom(65536)
    conns = {}

    def open_one(kind):
        s = socket.socket()
        s.setblocking(False)
        try:
            if source:
                s.bind((source, 0))
            s.connect_ex((host, port))
        except OSError:
            stats["refused"] += 1
            s.close()
            return
        stats["opened"] += 1
        conns[s] = kind
        sel.register(s, selectors.EVENT_READ | (selectors.EVENT_WRITE if kind == "big" else 0))

    end = time.time() + seconds
    under_way = False
    while time.time() < end:
        if not under_way and stats["opened"] >= OVERSIZED and stats["bytes_sent"] > 0:
            print("flood: under way", flush=True)
            under_way = True
        nbig = sum(1 for k in conns.values() if k == "big")
        nidle = len(conns) - nbig
        for _ in range(min(50, OVERSIZED - nbig)):
            open_one("big")
        for _ in range(min(200, IDLE - nidle)):
            open_one("idle")
        for key, ev in sel.select(timeout=0.05):
            s = key.fileobj
            if ev & selectors.EVENT_READ:
                try:
                    data = s.recv(65536)
                except OSError:
                    data = b""
                if not data:
                    stats["closed_by_server"] += 1
                    sel.unregister(s)
                    del conns[s]
                    s.close()
                    continue
            if ev & selectors.EVENT_WRITE and conns.get(s) == "big":
                try:
                    stats["bytes_sent"] += s.send(big)
                except OSError:
                    stats["closed_by_server"] += 1
                    sel.unregister(s)
                    del conns[s]
                    s.close()
    print("flood: %(opened)d connections opened, %(closed_by_server)d closed by the server, "
          "%(refused)d refused, %(bytes_sent)d bytes sent" % stats)
    return 0


if __name__ == "__main__":
    sys.exit(main())
