#!/usr/bin/env python3
"""tests/tools/flip_proxy.py: a machine on the path.  A TCP proxy that forwards connections to
HOST:PORT, records every byte the server sends (to CAPTURE), and in the FIRST connection flips
one bit of the client's byte number FLIP_AT (counted from the start of that connection, so
past the handshake when FLIP_AT is large enough).

Usage: flip_proxy.py HOST PORT FLIP_AT CAPTURE
Prints "listening on PORT" once ready; runs until killed."""
import select
import socket
import sys
import threading


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
    for s in (src, dst):
        try:
            s.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass


def main():
    host, port, flip_at, capture_path = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
    capture = open(capture_path, "wb")
    lock = threading.Lock()
    ls = socket.socket()
    ls.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    ls.bind(("127.0.0.1", 0))
    ls.listen(64)
    print("listening on %d" % ls.getsockname()[1], flush=True)
    first = True
    while True:
        c, _ = ls.accept()
        try:
            s = socket.create_connection((host, port))
        except OSError:
            c.close()  # the coordinator is gone: so is this connection
            continue
        threading.Thread(target=pump, args=(c, s, flip_at if first else None, None, lock),
                         daemon=True).start()
        threading.Thread(target=pump, args=(s, c, None, capture, lock), daemon=True).start()
        first = False


if __name__ == "__main__":
    main()
