#!/bin/bash
# paint_farm.sh: Raypaint opened on a standing farm (docs/paint.md, "On a standing farm"), as a
# person does from the farm's web view: a farm with one staying worker (-j WORKERS), a still of
# SCENE at SIZE queued and paused, then ROUNDS times: POST /api/jobs/ID/paint, and from that
# moment, timed by one client process (no process started while timing):
#   page_s     until GET /api/jobs/PAINT names its page (the paint process has started)
#   coarse_s   until the page's status says the first complete coarse picture is there
#   painted_s  until every pixel is exact
# and the paint's own clock for its coarse picture (own_coarse_s: from its start).  The paint
# job is closed (cancel) between rounds; the worker keeps the terrain from the first round.
#
# usage: bench/paint_farm.sh [SCENE]     (default scenes/default.scene at SIZE=1920x1080)
#        bench/paint_farm.sh --smoke     (160x90, one round)
# env:   SIZE ROUNDS=3 WORKERS=2 TF=bin/terrafarm
set -euo pipefail
cd "$(dirname "$0")/.."
TF=${TF:-bin/terrafarm}
if [ "${1:-}" = --smoke ]; then
    shift
    SIZE=160x90 ROUNDS=1
fi
SCENE=${1:-scenes/default.scene}
SIZE=${SIZE:-1920x1080} ROUNDS=${ROUNDS:-3} WORKERS=${WORKERS:-2}
[ -x "$TF" ] || { echo "paint_farm.sh: build first (make)" >&2; exit 1; }
T=$(mktemp -d "${TMPDIR:-/tmp}/tf-paint-farm.XXXXXX")
trap 'kill $(jobs -p) 2>/dev/null; wait 2>/dev/null; [ -n "${KEEP:-}" ] || rm -rf "$T"' EXIT
(umask 077; head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$T/secret")
"$TF" farm --state "$T/state" --add-token bench --role submitter >"$T/token"
: >"$T/farm.log" # there before the farm's shell opens it: sed below must find it (set -e)
"$TF" farm --listen 127.0.0.1:0 --state "$T/state" --secret-file "$T/secret" >>"$T/farm.log" 2>&1 &
for _ in $(seq 600); do
    PORT=$(sed -n 's/.*farm on http:\/\/127.0.0.1:\([0-9]*\):.*/\1/p' "$T/farm.log")
    [ -n "$PORT" ] && break
    sleep 0.1
done
[ -n "$PORT" ] || { echo "paint_farm.sh: the farm did not start: $(cat "$T/farm.log")" >&2; exit 1; }
export TERRAFARM_FARM=127.0.0.1:$PORT TERRAFARM_TOKEN_FILE=$T/token
"$TF" worker --connect "http://127.0.0.1:$PORT" --secret-file "$T/secret" --name bench \
    -j "$WORKERS" >"$T/worker.log" 2>&1 &
still=$("$TF" submit "$SCENE" --size "$SIZE" --name still)
"$TF" pause "$still" >/dev/null
echo "paint_farm: $SCENE $SIZE, one staying worker -j $WORKERS, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), $(nproc) cores"
python3 - "$PORT" "$(tail -1 "$T/token")" "$still" "$ROUNDS" <<'EOF'
import json, sys, time, urllib.parse, urllib.request

port, token, still, rounds = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
farm = "http://127.0.0.1:%s" % port


def call(url, tok, method="GET", body=None):
    data = json.dumps(body).encode() if body is not None else None
    req = urllib.request.Request(url, data, method=method, headers={
        "Authorization": "Bearer " + tok, "Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=30) as r:
        return json.loads(r.read())


def until(cond, limit=600):
    end = time.time() + limit
    while time.time() < end:
        v = cond()
        if v:
            return v
        time.sleep(0.005)
    sys.exit("paint_farm: timed out")


for k in range(rounds):
    t0 = time.time()
    paint = call(farm + "/api/jobs/%s/paint" % still, token, "POST", {})["id"]
    url = until(lambda: call(farm + "/api/jobs/%d" % paint, token).get("dashboard"))
    t_page = time.time() - t0
    page, ptok = url.split("/login?token=")
    status = lambda: call(page + "/api/paint/status", ptok)
    s = until(lambda: (lambda s: s if s["coarse_s"] >= 0 else None)(status()))
    t_coarse = time.time() - t0
    s = until(lambda: (lambda s: s if s["painted_s"] >= 0 else None)(status()))
    t_painted = time.time() - t0
    print("round=%d page_s=%.3f coarse_s=%.3f painted_s=%.3f own_coarse_s=%.3f own_painted_s=%.2f"
          % (k + 1, t_page, t_coarse, t_painted, s["coarse_s"], s["painted_s"]))
    call(farm + "/api/jobs/%d/cancel" % paint, token, "POST", {})
    until(lambda: call(farm + "/api/jobs/%d" % paint, token)["state"] == "cancelled")
print("paint_farm: %d rounds measured" % rounds)
EOF
