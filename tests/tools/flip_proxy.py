#!/usr/bin/env python3
"""tests/tools/flip_proxy.py: a machine on the path.  A TCP proxy that forwards connections to
HOST:PORT, records every byte the server sends (to CAPTURE), and in the FIRST connection flips
one bit of the client's byte number FLIP_AT (counted from the start of that connection, so
past the handshake when FLIP_AT is large enough).

Usage: flip_proxy.py HOST PORT FLIP_AT CAPTURE
Prints "listening on PORT" once ready; runs until killed."""
import os
import sys
import threading

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from tfwire import serve_proxy, shut_both  # noqa: E402


def pump(src, dst, flip_at, capture, lock):
    seen = 0
    while True:
        try:
            data = src.recv(65536)
        except OSError:
            data = b""
        if not data:
            break
        if flip_at is not None and seen <= flip_at < seen + len(data):
            i = flip_at - seen
            data = data[:i] + bytes([data[i] ^ 0x10]) + data[i + 1:]
            print("flipped client byte %d" % flip_at, flush=True)
        seen += len(data)
        if capture is not None:
            with lock:
                capture.write(data)
                capture.flush()
        try:
            dst.sendall(data)
        except OSError:
            break
    shut_both(src, dst)


def main():
    host, port, flip_at, capture_path = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
    capture = open(capture_path, "wb")
    lock = threading.Lock()
    serve_proxy(host, port, lambda c, s, n: [(pump, (c, s, flip_at if n == 0 else None, None, lock)),
                                             (pump, (s, c, None, capture, lock))])


if __name__ == "__main__":
    main()
