#!/bin/sh
# bench/farm_sim.sh: the standing farm under a queue of N jobs served by F staying workers, each
# of them S simulated workers (terrafarm worker --connect http://FARM --simulate MODEL -j S:
# threads that sleep each task's modelled cost from the cost map and answer with a real render's
# recorded chunks, worker/simulate.h), so F*S workers on 2 cores.  Every job is SIZE of
# default.scene in 8x8 stamps whose average costs TASK_MS.  Prints tasks dealt per second over
# the farm, the farm's efficiency (the modelled work of all jobs over F*S workers' wall time:
# 1.0 would be no worker ever idle, between jobs included) and the API's latency (GET /api/jobs
# every 50 ms).
# usage: bench/farm_sim.sh [JOBS] [FARM_WORKERS] [SIM_PER_WORKER] [SIZE] [TASK_MS]
#          (defaults 100 4 16 256x144 10: 64 simulated workers)
#        bench/farm_sim.sh --smoke   (3 jobs, 2 x 2 workers, 64x32, 1 ms)
set -u
ROOT=$(cd "$(dirname "$0")/.." && pwd)
TF=${TF:-$ROOT/bin/terrafarm}
if [ "${1:-}" = --smoke ]; then N=3 F=2 S=2 SIZE=64x32 MS=1
else N=${1:-100} F=${2:-4} S=${3:-16} SIZE=${4:-256x144} MS=${5:-10}; fi
T=$(mktemp -d "${TMPDIR:-/tmp}/tf-farm-sim.XXXXXX")
PIDS=""
cleanup() { for p in $PIDS; do pkill -KILL -P "$p" 2>/dev/null; kill -KILL "$p" 2>/dev/null; done; rm -rf "$T"; }
trap cleanup EXIT
die() { echo "FAIL: $*"; exit 1; }
echo "cpu: $(sed -n 's/^model name[^:]*: //p' /proc/cpuinfo | head -1); $(nproc) cores"
(umask 077; head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$T/secret")
"$TF" render "$ROOT/scenes/default.scene" -j 2 --size "$SIZE" --tasks stamps:8x8 -o "$T/rec.exr" -q ||
    die "recording the payloads"
"$TF" farm --state "$T/state" --add-token bench --role admin >"$T/token" || die token
chmod 600 "$T/token"
"$TF" farm --listen 127.0.0.1:0 --state "$T/state" --secret-file "$T/secret" >"$T/farm.log" 2>&1 &
PIDS="$PIDS $!"
i=0
until PORT=$(sed -n 's/.*farm on http:\/\/127.0.0.1:\([0-9]*\):.*/\1/p' "$T/farm.log") && [ -n "$PORT" ]; do
    sleep 0.05; i=$((i + 1)); [ $i -lt 1200 ] || die "the farm did not start"
done
export TERRAFARM_FARM=127.0.0.1:$PORT TERRAFARM_TOKEN_FILE=$T/token
i=0; while [ $i -lt "$N" ]; do
    i=$((i + 1))
    "$TF" submit "$ROOT/scenes/default.scene" --size "$SIZE" --tasks stamps:8x8 --name "j$i" >/dev/null || die submit
done
python3 - "$TERRAFARM_FARM" "$(cat "$T/token")" "$T/lat" <<'PY' &
import http.client, sys, time
host, port = sys.argv[1].split(":"); tok = sys.argv[2]; out = open(sys.argv[3], "w")
while True:
    t0 = time.perf_counter()
    try:
        c = http.client.HTTPConnection(host, int(port), timeout=10)
        c.request("GET", "/api/jobs", headers={"Authorization": "Bearer " + tok}); c.getresponse().read(); c.close()
    except Exception: break
    out.write("%.3f\n" % ((time.perf_counter() - t0) * 1000)); out.flush()
    time.sleep(0.05)
PY
POLL=$!; PIDS="$PIDS $POLL"
PIXEL_US=$(python3 -c "print(round($MS * 1000 / 64, 4))")
t0=$(date +%s%N)
i=0; while [ $i -lt "$F" ]; do
    i=$((i + 1))
    "$TF" worker --connect "http://$TERRAFARM_FARM" --secret-file "$T/secret" --name "sim$i" -j "$S" \
        --simulate "$ROOT/bench/default.cost" --pixel-us "$PIXEL_US" --payloads "$T/rec.exr" \
        >"$T/sim$i.out" 2>"$T/sim$i.log" &
    PIDS="$PIDS $!"
done
i=0
while :; do
    done_n=$("$TF" jobs --json | python3 -c '
import json, sys
j = json.load(sys.stdin)["jobs"]
bad = [x for x in j if x["state"] in ("failed", "cancelled")]
print(-1 if bad else sum(x["state"] == "done" for x in j))')
    [ "$done_n" = -1 ] && die "a job failed: $("$TF" jobs)"
    [ "$done_n" -ge "$N" ] && break
    sleep 0.2; i=$((i + 1)); [ $i -lt 30000 ] || die "jobs not done"
done
t1=$(date +%s%N)
kill $POLL 2>/dev/null
cat "$T"/sim*.out >"$T/sessions"
python3 - "$T/lat" "$T/sessions" "$N" "$F" "$S" "$SIZE" "$PIXEL_US" "$(( (t1 - t0) / 1000000 ))" <<'PY'
import re, sys
lat = sorted(float(x) for x in open(sys.argv[1]) if x.strip()) or [0.0]
sessions = [dict(kv.split("=") for kv in l.split()[1:]) for l in open(sys.argv[2]) if l.startswith("simulated")]
n, f, s = int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
w, h = map(int, sys.argv[6].split("x")); pixel_us = float(sys.argv[7]); wall = int(sys.argv[8]) / 1000.0
tasks = sum(int(x["tasks"]) for x in sessions)
work = n * w * h * pixel_us / 1e6
p = lambda q: lat[min(len(lat) - 1, int(q * len(lat)))]
print("farm_sim: %d jobs, %d x %d simulated workers, %d sessions: %.0f tasks dealt/s; farm efficiency %.3f "
      "(%.1f s of modelled work over %d workers in %.1f s); GET /api/jobs p50 %.1f ms p99 %.1f ms "
      "(%d requests)" % (n, f, s, len(sessions), tasks / wall, work / (f * s * wall), work, f * s,
                         wall, p(0.5), p(0.99), len(lat)))
PY
