# lib_paint.sh: starting `terrafarm paint` in the paint tests (sourced after lib.sh).
#
# render_reference SIZE: the plain render of $SCENE at SIZE, $T/ref.exr with its PNG preview
# $T/ref.png (what a fully painted canvas must equal byte for byte).
render_reference() {
    say "reference render"
    render -q -j 2 --size "$1" --http none -o "$T/ref.exr" || fail "reference: $(cat "$T/last.err")"
    [ -s "$T/ref.png" ] || fail "the reference render wrote no preview PNG"
}
#
# start_paint LOG ARGS...: terrafarm paint $SCENE ARGS in the background, its stderr to LOG;
# waits for its page and sets PAINT_PID and PAINT_URL (http://127.0.0.1:PORT/), and
# PAINT_WORKERS (the networked workers' HOST:PORT) when it listens for them.
start_paint() {
    sp_log=$1; shift
    "$TF_BIN" paint "$SCENE" "$@" 2>"$sp_log" &
    PAINT_PID=$!; e2e_track $PAINT_PID
    i=0
    while ! grep -q 'paint: open http' "$sp_log" 2>/dev/null; do
        kill -0 $PAINT_PID 2>/dev/null || fail "terrafarm paint ended early: $(cat "$sp_log")"
        sleep 0.1; i=$((i + 1)); [ $i -lt 600 ] || fail "terrafarm paint logged no page: $(cat "$sp_log")"
    done
    PAINT_URL=$(sed -n 's/.*paint: open \(http:[^ ]*\).*/\1/p' "$sp_log" | head -1)
    PAINT_WORKERS=$(sed -n 's/.*worker --connect HOST:\([0-9]*\).*/127.0.0.1:\1/p' "$sp_log" | head -1)
}

# paint_status FIELD: one field of the paint's /api/paint/status (a number or a string).
paint_status() {
    python3 -c 'import json,sys,urllib.request
d = json.load(urllib.request.urlopen(sys.argv[1] + "api/paint/status", timeout=10))
for k in sys.argv[2].split("."): d = d[k]
print(d)' "$PAINT_URL" "$1"
}

# wait_painted SECONDS: until the paint's current view is painted.
wait_painted() {
    i=0
    while [ "$(paint_status painted_s | cut -c1)" = "-" ]; do
        kill -0 $PAINT_PID 2>/dev/null || fail "terrafarm paint ended: $(tail -3 "$T/paint.err")"
        sleep 0.1; i=$((i + 1)); [ $i -lt $(($1 * 10)) ] || fail "not painted within $1 s"
    done
}

# paint_http METHOD PATH [BODY] [HEADER]: one request to the paint's page; the body of the
# answer goes to $T/ctl.out and its HTTP status is printed.  BODY "@FILE" sends FILE; HEADER
# is "Name: value" (default "X-Terrafarm-Token: x", which loopback controls need); "Host: ..."
# replaces the Host header.
paint_http() {
    python3 -c 'import http.client, sys, urllib.parse
method, url, body, header, out = sys.argv[1:6]
u = urllib.parse.urlsplit(url)
if body.startswith("@"): body = open(body[1:], "rb").read()
else: body = body.encode()
name, _, value = header.partition(":")
c = http.client.HTTPConnection(u.hostname, u.port, timeout=30)
c.putrequest(method, u.path + ("?" + u.query if u.query else ""), skip_host=name.lower() == "host")
c.putheader(name.strip(), value.strip())
c.putheader("Content-Length", str(len(body)))
c.endheaders()
if body: c.send(body)
r = c.getresponse()
open(out, "wb").write(r.read())
print(r.status)' "$1" "${PAINT_URL%/}$2" "${3:-}" "${4:-X-Terrafarm-Token: x}" "$T/ctl.out"
}

# wait_status FIELD VALUE SECONDS WHAT: until the paint's status FIELD reads VALUE.
wait_status() {
    i=0
    while [ "$(paint_status "$1")" != "$2" ]; do
        kill -0 $PAINT_PID 2>/dev/null || fail "terrafarm paint ended waiting for $4"
        sleep 0.05; i=$((i + 1)); [ $i -lt $(($3 * 20)) ] || fail "$4: not within $3 s"
    done
}
