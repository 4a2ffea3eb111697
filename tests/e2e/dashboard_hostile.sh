#!/bin/sh
# dashboard_hostile.sh: the dashboard anywhere but loopback, and hostile HTTP.
#  1. --http 0.0.0.0:0 without a token source is refused before anything is rendered.
#  2. A render whose dashboard listens on 0.0.0.0 (token derived from --secret-file), reached
#     at this machine's non-loopback address: every request without the token (or with a wrong
#     one) gets 401 and nothing else; the token as a bearer header or a cookie opens it;
#     a control with the cookie alone is refused (CSRF); `terrafarm status` needs the token
#     and derives it from --secret-file.  Meanwhile malformed, oversized, slow and hostile
#     requests hit it, with and without the token; the render completes, the dashboard still
#     answers, and the image is byte-identical to a render without a dashboard.
#  3. --http-token-file, on a loopback dashboard: the Host header must be loopback (DNS
#     rebinding), controls need a header, and a stop with the token stops the render (130).
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=1280x720

# a non-loopback address of this machine: the first global IPv4, else a dummy interface
ADDR=$(ip -o -4 addr show scope global 2>/dev/null | awk '{print $4}' | cut -d/ -f1 | head -1)
if [ -z "$ADDR" ]; then
    DUMMY=tfdash$$
    ip link add "$DUMMY" type dummy 2>/dev/null && ip addr add 198.18.$(( $$ % 250 )).1/32 dev "$DUMMY" &&
        ip link set "$DUMMY" up && ADDR=198.18.$(( $$ % 250 )).1
    trap 'ip link del "$DUMMY" 2>/dev/null; e2e_cleanup' EXIT
    [ -n "$ADDR" ] || skip "this machine has no non-loopback address and cannot make one (needs root)"
fi
say "non-loopback address: $ADDR"
head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$T/farm.key"
chmod 600 "$T/farm.key"

say "1. a dashboard off loopback without a token is refused"
"$TF_BIN" render "$SCENE" --listen 127.0.0.1:0 --http 0.0.0.0:0 -j 1 --size 64x32 -o "$T/no.exr" 2>"$T/no.err"
rc=$?
[ $rc -eq 2 ] || fail "--http 0.0.0.0:0 without a token exited $rc: $(cat "$T/no.err")"
grep -q 'needs a token' "$T/no.err" || fail "unclear refusal: $(cat "$T/no.err")"
[ ! -e "$T/no.exr" ] || fail "the refused render created its output"
say "refused: $(cat "$T/no.err")"

say "reference render without a dashboard"
render -q -j 2 --size $SIZE --tasks stamps:64x64 --http none -o "$T/ref.exr" || fail "reference: $(cat "$T/last.err")"

say "2. a dashboard on 0.0.0.0 with the token derived from the farm secret, under attack"
"$TF_BIN" render "$SCENE" --listen 127.0.0.1:0 --secret-file "$T/farm.key" --http 0.0.0.0:0 \
    -j 2 --size $SIZE --tasks stamps:64x64 --lease-timeout 120000 -o "$T/out.exr" 2>"$T/coord.err" &
pid=$!; e2e_track $pid
# the workers are frozen (SIGSTOP) from birth through the attack, so the render outlasts it on a
# machine of any speed; they go on after
freeze_workers_at_birth $pid 2
i=0
while ! grep -q 'dashboard at' "$T/coord.err" 2>/dev/null; do
    kill -0 $pid 2>/dev/null || fail "render ended early: $(cat "$T/coord.err")"
    sleep 0.05; i=$((i + 1)); [ $i -lt 400 ] || fail "no dashboard URL logged: $(cat "$T/coord.err")"
done
grep 'dashboard at' "$T/coord.err" | grep -q 'token required' || fail "the log does not say a token is required"
port=$(sed -n 's/.*dashboard at http:\/\/[^ ]*:\([0-9][0-9]*\)\/.*/\1/p' "$T/coord.err" | head -1)
TOKEN=$("$TF_BIN" status --secret-file "$T/farm.key" --print-token) || fail "status --print-token"
printf '%s\n' "$TOKEN" >"$T/token"
"$TF_BIN" status "$ADDR:$port" >"$T/st_no.out" 2>"$T/st_no.err" && fail "terrafarm status without the token succeeded"
grep -q '401' "$T/st_no.err" || fail "status without the token: $(cat "$T/st_no.err")"
"$TF_BIN" status "$ADDR:$port" --secret-file "$T/farm.key" >"$T/st.out" 2>"$T/st.err" || fail "status with --secret-file: $(cat "$T/st.err")"
"$TF_BIN" status "$ADDR:$port" --token-file "$T/token" --json >"$T/st.json" 2>"$T/st.err" || fail "status with --token-file: $(cat "$T/st.err")"
python3 - "$ADDR" "$port" "$TOKEN" <<'PY' || fail "the dashboard off loopback (above)"
import http.client, json, os, socket, sys, time
addr, port, token = sys.argv[1], int(sys.argv[2]), sys.argv[3]
bad = []
def req(method, path, headers=None, body=None):
    c = http.client.HTTPConnection(addr, port, timeout=10)
    c.request(method, path, body=body, headers=headers or {})
    r = c.getresponse()
    data = r.read()
    c.close()
    return r.status, dict(r.getheaders()), data
def raw(data, read=True, linger=0.0):
    try:
        s = socket.create_connection((addr, port), timeout=1.5)
        for chunk in (data if isinstance(data, list) else [data]):
            s.sendall(chunk)
            if linger:
                time.sleep(linger)
        out = b""
        if read:
            try:
                while True:
                    c = s.recv(65536)
                    if not c:
                        break
                    out += c
            except (socket.timeout, ConnectionError):
                pass
        s.close()
        return out
    except (ConnectionError, BrokenPipeError, socket.timeout) as e:
        return b""
# without the token, or with a wrong one: 401 and nothing else
for method, path, hdr in [("GET", "/", {}), ("GET", "/index.html", {}), ("GET", "/dashboard.js", {}),
                          ("GET", "/api/status", {}), ("GET", "/api/workers", {}),
                          ("GET", "/api/events", {}), ("GET", "/api/events/stream", {}),
                          ("GET", "/api/tasks", {}), ("GET", "/api/history", {}),
                          ("GET", "/api/preview.png", {}), ("GET", "/nothing", {}),
                          ("GET", "/login?token=wrong", {}), ("POST", "/api/stop", {}),
                          ("POST", "/api/stop", {"X-Terrafarm-Token": "wrong"}),
                          ("GET", "/api/status", {"Authorization": "Bearer " + token[:-1]}),
                          ("GET", "/api/status", {"Authorization": "Bearer " + token + "x"}),
                          ("GET", "/api/status", {"Cookie": "tf_token=nope"}),
                          ("DELETE", "/api/status", {})]:
    st, h, body = req(method, path, hdr)
    if st != 401 or body != b"401 unauthorized\n" or "Set-Cookie" in h:
        bad.append("%s %s %s: %d %r" % (method, path, hdr, st, body[:80]))
# with it
st, h, body = req("GET", "/api/status", {"Authorization": "Bearer " + token})
if st != 200 or json.loads(body)["state"] not in ("starting", "rendering"):
    bad.append("bearer token: %d %r" % (st, body[:80]))
st, h, body = req("GET", "/", {"Cookie": "tf_token=" + token})
if st != 200 or b"<title>terrafarm" not in body:
    bad.append("cookie: %d %r" % (st, body[:80]))
st, h, body = req("GET", "/login?token=" + token)
if st != 303 or "tf_token=" + token not in h.get("Set-Cookie", "") or "SameSite=Strict" not in h.get("Set-Cookie", ""):
    bad.append("login: %d %s" % (st, h))
# a control with the cookie alone (what a cross-site form would send) is refused
st, h, body = req("POST", "/api/stop", {"Cookie": "tf_token=" + token})
if st != 403:
    bad.append("stop with the cookie alone: %d %r" % (st, body[:80]))
auth = "Authorization: Bearer %s\r\n" % token
hostile = [
    os.urandom(4096),
    b"GET / HTTP/1.1\r\nHost: x\r\nX-Big: " + b"a" * 200000 + b"\r\n\r\n",
    b"GET /" + b"a" * 1000000 + b" HTTP/1.1\r\nHost: x\r\n\r\n",
    b"GET /api/status HTTP/1.1\r\n" + b"".join(b"X-H%d: v\r\n" % i for i in range(5000)) + b"\r\n",
    b"POST /api/watermark HTTP/1.1\r\nHost: x\r\n" + auth.encode() + b"Content-Length: 100000000\r\n\r\n" + b"{" * 500000,
    b"POST /api/watermark HTTP/1.1\r\nHost: x\r\n" + auth.encode() + b"Transfer-Encoding: chunked\r\n\r\nzzzz\r\nxx\r\n",
    b"POST /api/watermark HTTP/1.1\r\nHost: x\r\n" + auth.encode() + b"Transfer-Encoding: chunked\r\n\r\nffffffffffffffff\r\n" + b"a" * 10000,
    b"GET /../../../../etc/passwd HTTP/1.1\r\nHost: x\r\n" + auth.encode() + b"\r\n",
    b"GET /api/st\x00atus HTTP/1.1\r\nHost: x\r\n" + auth.encode() + b"\r\n",
    b"GET /\r\n\r\n",
    b"GET / HTTP/9.9\r\nHost: x\r\n\r\n",
    b"BREW /pot HTTP/1.1\r\nHost: x\r\n" + auth.encode() + b"\r\n",
    b"GET / HTTP/1.1\r\nno colon here\r\n\r\n",
    b"\r\n\r\n\r\n\r\n",
    b"GET /api/events?after=-1 HTTP/1.1\r\nHost: x\r\n" + auth.encode() + b"\r\n",
    b"GET /api/events?after=99999999999999999999999 HTTP/1.1\r\nHost: x\r\n" + auth.encode() + b"\r\n",
    b"POST /api/workers/99999999999999999999/drop HTTP/1.1\r\nHost: x\r\n" + auth.encode() + b"Content-Length: 0\r\n\r\n",
    b"POST /api/workers/1/drop/../../stop HTTP/1.1\r\nHost: x\r\n" + auth.encode() + b"Content-Length: 0\r\n\r\n",
    b"POST /api/watermark HTTP/1.1\r\nHost: x\r\n" + auth.encode() + b"Content-Length: 20\r\n\r\n{\"watermark\": 1e999}",
    b"POST /api/watermark HTTP/1.1\r\nHost: x\r\n" + auth.encode() + b"Content-Length: 16\r\n\r\n{\"watermark\": 1}",
    b"POST /api/watermark HTTP/1.1\r\nHost: x\r\n" + auth.encode() + b"Content-Length: 9\r\n\r\n\xff\xfe\x00\x01\x02[[[[",
    b"GET /api/status HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer " + b"\xff" * 3000 + b"\r\n\r\n",
    b"GET /api/status HTTP/1.1\r\nHost: x\r\nCookie: " + b"tf_token=a; " * 2000 + b"\r\n\r\n",
]
import threading
for k in range(0, len(hostile), 8):  # eight at a time: the render must still be running
    ts = [threading.Thread(target=raw, args=(h,)) for h in hostile[k:k + 8]]
    for t in ts: t.start()
    for t in ts: t.join()
# byte by byte, slowly, then gone
raw([b"GET /api/st", b"atus HTTP/1.1\r\n", b"Host: x\r\n"], read=False, linger=0.2)
# many idle connections at once (more than the server allows), held, then dropped
idle = []
for i in range(48):
    try:
        idle.append(socket.create_connection((addr, port), timeout=2))
    except OSError:
        break
time.sleep(1.5)
for s in idle:
    s.close()
time.sleep(0.3)
# a control that is fine: refused as out of range, and the dashboard still answers
st, h, body = req("POST", "/api/watermark", {"Authorization": "Bearer " + token}, body=b'{"watermark": 1}')
if st != 400:
    bad.append("watermark 1: %d %r" % (st, body[:80]))
st, h, body = req("GET", "/api/status", {"Authorization": "Bearer " + token})
if st != 200:
    bad.append("the dashboard stopped answering after the hostile requests: %d" % st)
for b in bad:
    print("FAIL:", b)
print("off-loopback checks: %s" % ("ok" if not bad else "%d failed" % len(bad)))
sys.exit(1 if bad else 0)
PY
thaw_workers $pid
wait_exit $pid 120
[ $rc -eq 0 ] || fail "the attacked render exited $rc: $(tail -5 "$T/coord.err")"
same "$T/ref.exr" "$T/out.exr" "render whose dashboard was attacked"
grep -q 'stopping\|dropping' "$T/coord.err" && fail "a hostile request reached a control: $(grep 'dashboard:' "$T/coord.err")"

say "3. --http-token-file on loopback: Host check, controls need a header, stop with the token"
echo "a-dashboard-token-of-mine-0123456789" >"$T/http.token"
"$TF_BIN" render "$SCENE" --listen 127.0.0.1:0 --http 127.0.0.1:0 --http-token-file "$T/http.token" \
    -j 1 --size $SIZE --tasks stamps:64x64 -o "$T/stop.exr" 2>"$T/stop.err" &
pid=$!; e2e_track $pid
i=0
while ! grep -q 'dashboard at' "$T/stop.err" 2>/dev/null; do
    kill -0 $pid 2>/dev/null || fail "render ended early: $(cat "$T/stop.err")"
    sleep 0.05; i=$((i + 1)); [ $i -lt 400 ] || fail "no dashboard URL logged: $(cat "$T/stop.err")"
done
port=$(sed -n 's/.*dashboard at http:\/\/[^ ]*:\([0-9][0-9]*\)\/.*/\1/p' "$T/stop.err" | head -1)
python3 - "$port" "a-dashboard-token-of-mine-0123456789" <<'PY' || fail "loopback dashboard with a token file (above)"
import http.client, sys, time
port, token = int(sys.argv[1]), sys.argv[2]
bad = []
def req(method, path, headers):
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    c.request(method, path, headers=headers)
    r = c.getresponse()
    return r.status, r.read()
st, b = req("GET", "/api/status", {})
if st != 401: bad.append("no token: %d" % st)
st, b = req("GET", "/api/status", {"Authorization": "Bearer " + token, "Host": "evil.example:80"})
if st != 403: bad.append("foreign Host header: %d" % st)
st, b = req("POST", "/api/stop", {"Cookie": "tf_token=" + token})
if st != 403: bad.append("stop with the cookie alone: %d" % st)
time.sleep(0.5)
st, b = req("POST", "/api/stop", {"X-Terrafarm-Token": token})
if st != 202: bad.append("stop with the token: %d %r" % (st, b))
for x in bad: print("FAIL:", x)
sys.exit(1 if bad else 0)
PY
wait_exit $pid 60
[ $rc -eq 130 ] || fail "a render stopped from the dashboard exited $rc, expected 130: $(tail -3 "$T/stop.err")"
grep -q 'stopped from the dashboard' "$T/stop.err" || fail "no stop message: $(tail -3 "$T/stop.err")"
say "stopped: $(grep 'stopped from the dashboard' "$T/stop.err")"
say "ok"
