"""tests/tools/guesser.py: a secret guesser for tests/e2e/farm_guesser.sh.  Hammers the
coordinator at HOST PORT with wrong-secret handshakes (the key in WRONG_KEY), from SOURCE, on
THREADS connections one after the other each, until the file STOP exists.

As soon as it sees the coordinator throttle it -- a connection closed before the HELLO (the
address barred), or a wrong guess answered only after 200 ms or more (the answer held) -- it
writes one line to the file THROTTLED, so the test can start the honest worker knowing the
throttle is in force.  At the end it prints one line: attempts, answered, barred, slow.

Usage: guesser.py HOST PORT WRONG_KEY SOURCE THREADS THROTTLED STOP"""
import hashlib
import hmac
import os
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import tfwire  # noqa: E402

host, port, key_path, source = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
threads, throttled, stop = int(sys.argv[5]), sys.argv[6], sys.argv[7]
counts = {"attempts": 0, "answered": 0, "barred": 0, "slow": 0}
lock = threading.Lock()


def note(what, why=None):
    with lock:
        counts[what] += 1
        if why and not os.path.exists(throttled):
            with open(throttled + ".tmp", "w") as f:
                f.write(why + "\n")
            os.rename(throttled + ".tmp", throttled)


def guess(key):
    """One wrong-secret handshake; classifies how the coordinator answered."""
    t0 = time.time()
    try:
        c = tfwire.Conn(host, port, timeout=60, handshake=False, source=source)
        op, body = c.recv()
    except (EOFError, OSError):
        note("barred", "a connection closed before its HELLO")
        return
    try:
        if op != tfwire.HELLO:
            raise SystemExit("expected HELLO, got op %d" % op)
        nc = os.urandom(32)
        mac = hmac.new(key, b"terrafarm-client" + body[1:33] + nc, hashlib.sha256).digest()
        c.send_frame(tfwire.AUTH, 0, nc + mac)
        op, body = c.recv()
    except (EOFError, OSError):
        note("barred", "a connection closed before its handshake was answered")
        return
    finally:
        c.close()
    if op == tfwire.AUTH_OK:
        raise SystemExit("a wrong secret was accepted")
    dt = time.time() - t0
    if dt >= 0.2:
        note("slow", "a wrong guess answered after %.0f ms" % (dt * 1000))
    else:
        note("answered")


def hammer():
    key = tfwire.load_key(key_path)
    while not os.path.exists(stop):
        with lock:
            counts["attempts"] += 1
        guess(key)


workers = [threading.Thread(target=hammer, daemon=True) for _ in range(threads)]
for w in workers:
    w.start()
for w in workers:
    w.join()
print("attempts=%(attempts)d answered=%(answered)d barred=%(barred)d slow=%(slow)d" % counts)
