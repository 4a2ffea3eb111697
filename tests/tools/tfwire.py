"""tests/tools/tfwire.py: the tuple-space wire protocol in Python, for test clients that must
speak it exactly as a worker does (common/linda/proto.h for frames, common/linda/tuple.h for the
tuple encoding, common/linda/auth.h for the handshake).  Imported by hostile_worker.py and the
flood/tamper tools; failing_worker.py predates it and keeps its own copy.

Conn(host, port, secret_path=None) connects, reads the HELLO and, with a secret, runs the
mutual HMAC-SHA256 handshake (key = SHA-256 of the secret file's bytes without trailing
newlines) and then seals every frame (see seal.py's description in common/linda/seal.h).
call(op, fields) sends one request and returns (reply_op, body); join(c, name) joins a render as
a networked worker."""
import hashlib
import hmac
import os
import socket
import struct

OUT, IN, RD, INP, RDP, TUPLE, NONE, OK, PING, PONG, HELLO, AUTH, AUTH_OK, ERROR = range(1, 15)
INT, DOUBLE, STRING, BLOB, FORMAL = 1, 2, 3, 4, 0x80
OP_NAMES = {OUT: "OUT", IN: "IN", RD: "RD", INP: "INP", RDP: "RDP", TUPLE: "TUPLE", NONE: "NONE",
            OK: "OK", PING: "PING", PONG: "PONG", HELLO: "HELLO", AUTH: "AUTH",
            AUTH_OK: "AUTH_OK", ERROR: "ERROR"}


def enc(fields):
    """fields: list of (type, value); value None makes a formal."""
    out = bytes([len(fields)])
    for t, v in fields:
        if v is None:
            out += bytes([t | FORMAL])
        elif t == INT:
            out += bytes([t]) + struct.pack("<q", v)
        elif t == DOUBLE:
            out += bytes([t]) + struct.pack("<d", v)
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
        if t == INT:
            fields.append(struct.unpack_from("<q", body, pos)[0])
            pos += 8
        elif t == DOUBLE:
            fields.append(struct.unpack_from("<d", body, pos)[0])
            pos += 8
        else:
            (ln,) = struct.unpack_from("<I", body, pos)
            fields.append(body[pos + 4:pos + 4 + ln])
            pos += 4 + ln
    return fields


def frame(op, req, body=b""):
    return struct.pack("<IBBI", 6 + len(body), 1, op, req) + body


def load_key(path):
    data = open(path, "rb").read()
    while data and data[-1:] in (b"\n", b"\r"):
        data = data[:-1]
    return hashlib.sha256(data).digest()


class Sealer:
    """Per-frame AEAD after the handshake (common/linda/seal.h), through libsodium by ctypes."""

    def __init__(self, key, ns, nc, client=True):
        import ctypes
        import ctypes.util
        self.ct = ctypes
        self.na = ctypes.CDLL(ctypes.util.find_library("sodium") or "libsodium.so.23")
        if self.na.sodium_init() < 0:
            raise RuntimeError("sodium_init failed")
        c2s = self.derive(key, b"terrafarm-c2s", ns, nc)
        s2c = self.derive(key, b"terrafarm-s2c", ns, nc)
        self.send_key, self.recv_key = (c2s, s2c) if client else (s2c, c2s)
        self.send_n = 0
        self.recv_n = 0

    @staticmethod
    def derive(key, label, ns, nc):
        return hmac.new(key, label + ns + nc, hashlib.sha256).digest()

    @staticmethod
    def nonce(n):
        return struct.pack("<Q", n) + bytes(16)

    def seal(self, plain):
        ct = self.ct
        length = len(plain) + 16
        ad = struct.pack("<I", length)
        out = ct.create_string_buffer(length)
        outlen = ct.c_ulonglong(0)
        self.na.crypto_aead_xchacha20poly1305_ietf_encrypt(
            out, ct.byref(outlen), plain, ct.c_ulonglong(len(plain)), ad, ct.c_ulonglong(4),
            None, self.nonce(self.send_n), self.send_key)
        self.send_n += 1
        return ad + out.raw[:outlen.value]

    def open(self, length, cipher):
        ct = self.ct
        out = ct.create_string_buffer(max(1, len(cipher)))
        outlen = ct.c_ulonglong(0)
        rc = self.na.crypto_aead_xchacha20poly1305_ietf_decrypt(
            out, ct.byref(outlen), None, cipher, ct.c_ulonglong(len(cipher)),
            struct.pack("<I", length), ct.c_ulonglong(4), self.nonce(self.recv_n), self.recv_key)
        if rc != 0:
            raise EOFError("a frame from the server failed authentication")
        self.recv_n += 1
        return out.raw[:outlen.value]


class Conn:
    def __init__(self, host, port, secret_path=None, timeout=30, handshake=True, source=None):
        self.s = socket.create_connection((host, port), timeout=timeout,
                                          source_address=(source, 0) if source else None)
        self.req = 0
        self.sealer = None
        self.raw_in = b""
        self.plain_in = b""
        if not handshake:
            return
        op, body = self.recv()
        if op != HELLO:
            raise SystemExit("expected HELLO, got op %d" % op)
        ns = body[1:33]
        body0 = body[0]
        if body0 & 1:
            if not secret_path:
                raise SystemExit("the coordinator requires a secret")
            key = load_key(secret_path)
            nc = os.urandom(32)
            mac = hmac.new(key, b"terrafarm-client" + ns + nc, hashlib.sha256).digest()
            self.s.sendall(frame(AUTH, 0, nc + mac))
            op, body = self.recv()
            want = hmac.new(key, b"terrafarm-server" + ns + nc, hashlib.sha256).digest()
            if op != AUTH_OK or not hmac.compare_digest(body, want):
                raise SystemExit("handshake failed: op %d" % op)
            if body0 & 2:  # TF_HELLO_SEALED: every frame after AUTH_OK is sealed
                self.sealer = Sealer(key, ns, nc)

    def recv_exact(self, n):
        while len(self.raw_in) < n:
            chunk = self.s.recv(max(65536, n - len(self.raw_in)))
            if not chunk:
                raise EOFError("connection closed")
            self.raw_in += chunk
        data, self.raw_in = self.raw_in[:n], self.raw_in[n:]
        return data

    def recv(self):
        if not self.sealer:
            (length,) = struct.unpack("<I", self.recv_exact(4))
            rest = self.recv_exact(length)
            return rest[1], rest[6:]
        # Sealed: the records' plaintexts form the frame stream (a record may hold part of a
        # frame or several).
        while True:
            if len(self.plain_in) >= 4:
                (length,) = struct.unpack_from("<I", self.plain_in)
                if len(self.plain_in) >= 4 + length:
                    rest = self.plain_in[4:4 + length]
                    self.plain_in = self.plain_in[4 + length:]
                    return rest[1], rest[6:]
            (rlen,) = struct.unpack("<I", self.recv_exact(4))
            self.plain_in += self.sealer.open(rlen, self.recv_exact(rlen))

    def send_frame(self, op, req, body=b""):
        f = frame(op, req, body)
        self.s.sendall(self.sealer.seal(f) if self.sealer else f)

    def call(self, op, fields):
        self.req += 1
        self.send_frame(op, self.req, enc(fields) if fields is not None else b"")
        while True:
            rop, rbody = self.recv()
            if rop == PONG and self.req != 0:
                continue
            return rop, rbody

    def ping(self):
        self.send_frame(PING, 0)

    def close(self):
        self.s.close()


def join(c, name):
    """Join a render on Conn c as a worker does: take a worker id, say hello as a networked
    worker on host `name`; returns the id.  Exits (SystemExit) with a message if refused."""
    op, body = c.call(IN, [(STRING, "next_worker"), (INT, None)])
    if op != TUPLE:
        raise SystemExit("cannot take a worker id: %s" % OP_NAMES.get(op, op))
    me = dec(body)[1]
    op, _ = c.call(OUT, [(STRING, "hello"), (INT, me), (STRING, "networked"), (STRING, name),
                         (INT, os.getpid()), (STRING, "c")])
    if op != OK:
        raise SystemExit("hello refused: %s" % OP_NAMES.get(op, op))
    return me


# ---- proxies (tests/tools/lying_proxy.py, flip_proxy.py): a machine on the path ----

def shut_both(a, b):
    """End a proxied connection in both directions (the other pump then sees EOF)."""
    for s in (a, b):
        try:
            s.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass


def serve_proxy(host, port, start, source=None):
    """Listen on a free loopback port, print "listening on PORT", and for every connection
    accepted open one to HOST:PORT (from SOURCE_ADDRESS if given) and call
    start(client, server, n) with n the connection's number from 0.  Runs until killed."""
    import threading
    ls = socket.socket()
    ls.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    ls.bind(("127.0.0.1", 0))
    ls.listen(64)
    print("listening on %d" % ls.getsockname()[1], flush=True)
    n = 0
    while True:
        c, _ = ls.accept()
        try:
            s = socket.create_connection((host, port), source_address=source)
        except OSError:
            c.close()  # the coordinator is gone: so is this connection
            continue
        for target, args in start(c, s, n):
            threading.Thread(target=target, args=args, daemon=True).start()
        n += 1
