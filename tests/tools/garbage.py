#!/usr/bin/env python3
"""tests/tools/garbage.py: throw malformed traffic at a terrafarm tuple-space port.

Usage: garbage.py HOST PORT
Opens one connection per kind of bad traffic -- random bytes, a length field of 0xffffffff,
a length just over the 64 MiB frame limit, an unknown op, a wrong protocol version, a length
below the minimum, half a frame then close, and a connection that closes at once -- and
reports, for each, whether the server closed it (it must: one bad connection is dropped, the
render carries on).  Exit 0 if every connection was closed by the server within 5 s."""
import os
import socket
import struct
import sys
import time


def frame(op, body=b"", version=1, request_id=7, length=None):
    if length is None:
        length = 6 + len(body)
    return struct.pack("<IBBI", length, version, op, request_id) + body


CASES = [
    ("random bytes", os.urandom(4096)),
    ("length 0xffffffff", struct.pack("<I", 0xFFFFFFFF) + b"\x01\x01" + b"\0" * 64),
    ("length over TF_MAX_FRAME", struct.pack("<I", 64 * 1024 * 1024 + 1) + b"\x01\x01" + b"\0" * 64),
    ("unknown op 200", frame(200)),
    ("wrong version 9", frame(9, version=9)),
    ("length below minimum", struct.pack("<I", 3) + b"\x01\x09\x00"),
    ("server-only op TUPLE from a client", frame(6, b"\x00" * 16)),
    ("half a frame then close", frame(1, b"x" * 100)[:40]),
    ("connect and close", b""),
]


def closed_by_server(sock, deadline):
    """Read until EOF or a reset (the server dropped us) or the deadline."""
    sock.settimeout(0.2)
    while time.time() < deadline:
        try:
            data = sock.recv(65536)
        except socket.timeout:
            continue
        except (ConnectionResetError, BrokenPipeError):
            return True
        if not data:
            return True
    return False


def main():
    host, port = sys.argv[1], int(sys.argv[2])
    ok = True
    for name, payload in CASES:
        s = socket.create_connection((host, port), timeout=5)
        try:
            if payload:
                s.sendall(payload)
            if name.startswith("half a frame") or name == "connect and close":
                s.close()
                print("-- sent %s" % name)
                continue
            dropped = closed_by_server(s, time.time() + 5)
        except (ConnectionResetError, BrokenPipeError):
            dropped = True
        finally:
            s.close()
        print("-- sent %s: %s" % (name, "server closed the connection" if dropped else "NOT CLOSED"))
        ok &= dropped
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
