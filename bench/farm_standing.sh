#!/bin/sh
# bench/farm_standing.sh: the standing farm (terrafarm farm, coordinator/farm/) measured.
#  1. switching: one staying worker serves four jobs on two terrains (A, B, A, B, by priority);
#     prints the time from the end of one job's session to the next one's processes, with the
#     terrain built and with it kept (worker/terrain_shelf.h);
#  2. kill storm: K kill -9 of the farm at random moments while J jobs are in flight, each
#     followed by a restart on the same state folder and port; then every job must be done and
#     pixel for pixel a plain `terrafarm render` of it (jobs lost and images wrong must be 0);
#  3. load: N tiny jobs queued at once for W staying workers while a client polls GET /api/jobs
#     every 50 ms: jobs per second, assignments per second and the API's p50/p99 latency.
# usage: bench/farm_standing.sh [KILLS] [JOBS] [LOAD_JOBS] [LOAD_WORKERS] [STORM_SIZE]
#          (defaults 20 6 100 16 1920x1080; the storm's jobs must outlast the kills)
#        bench/farm_standing.sh --smoke          (2 kills, 2 jobs of 320x180, 4 tiny jobs, 2 workers)
set -u
ROOT=$(cd "$(dirname "$0")/.." && pwd)
TF=${TF:-$ROOT/bin/terrafarm}
EXRCMP=${TF_BUILD:-$ROOT/build}/tools/exrcmp
if [ "${1:-}" = --smoke ]; then K=2 J=2 LN=4 LW=2 SZ=320x180
else K=${1:-20} J=${2:-6} LN=${3:-100} LW=${4:-16} SZ=${5:-1920x1080}; fi
T=$(mktemp -d "${TMPDIR:-/tmp}/tf-farm-bench.XXXXXX")
export TERRAFARM_WEB=${TERRAFARM_WEB:-$ROOT/web}
PIDS=""
cleanup() { for p in $PIDS; do pkill -KILL -P "$p" 2>/dev/null; kill -KILL "$p" 2>/dev/null; done; rm -rf "$T"; }
trap cleanup EXIT
die() { echo "FAIL: $*"; exit 1; }
echo "cpu: $(sed -n 's/^model name[^:]*: //p' /proc/cpuinfo | head -1); $(nproc) cores"
(umask 077; head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$T/secret")

start_farm() { # STATE [PORT]
    : >"$T/farm.log"
    "$TF" farm --listen "127.0.0.1:${2:-0}" --state "$1" --secret-file "$T/secret" >>"$T/farm.log" 2>&1 &
    FARM=$!; PIDS="$PIDS $FARM"
    i=0
    until PORT=$(sed -n 's/.*farm on http:\/\/127.0.0.1:\([0-9]*\):.*/\1/p' "$T/farm.log") && [ -n "$PORT" ]; do
        sleep 0.05; i=$((i + 1)); [ $i -lt 1200 ] || die "the farm did not start: $(cat "$T/farm.log")"
    done
    export TERRAFARM_FARM=127.0.0.1:$PORT
}
new_farm() { # NAME: a fresh state folder with a token
    S=$T/$1; "$TF" farm --state "$S" --add-token bench --role admin >"$T/$1.token" || die token
    chmod 600 "$T/$1.token"; export TERRAFARM_TOKEN_FILE=$T/$1.token
    start_farm "$S"
}
worker() { # LOG [options]
    l=$1; shift
    "$TF" worker --connect "http://$TERRAFARM_FARM" --secret-file "$T/secret" -j 1 "$@" >"$l" 2>&1 &
    PIDS="$PIDS $!"
}
all_done() { # N: wait until N jobs are done (or fail on a failed one)
    "$TF" jobs --json | python3 -c '
import json, sys
jobs = json.load(sys.stdin)["jobs"]
bad = [j for j in jobs if j["state"] in ("failed", "cancelled")]
if bad: print("FAILED", bad[0]["id"], bad[0]["reason"]); sys.exit(2)
sys.exit(0 if sum(j["state"] == "done" for j in jobs) >= int(sys.argv[1]) else 1)' "$1"
}
wait_done() { i=0; while :; do all_done "$1"; r=$?; [ $r = 0 ] && return; [ $r = 2 ] && die "a job failed"; sleep 0.2; i=$((i+1)); [ $i -lt 9000 ] || die "jobs not done"; done; }

# ---- 1. switching between jobs with kept terrains ----
new_farm switch
S1=$(printf 'alps %s\nvalley %s\nalps %s\nvalley %s\n' 40 30 20 10)
echo "$S1" | while read -r sc pr; do
    "$TF" submit "$ROOT/scenes/$sc.scene" --size 96x54 --priority "$pr" --name "$sc$pr" >/dev/null || die submit
done
worker "$T/switch.log" --name switcher
wait_done 4
grep 'serving job' "$T/switch.log" | sed 's/.*(\(.*\))$/\1/' >"$T/switch.gaps"
python3 - "$T/switch.gaps" <<'PY'
import re, sys
built, kept = [], []
for line in open(sys.argv[1]):
    m = re.search(r"since the last job", line)
    g = re.search(r"(\d+) ms since", line)
    if not g: continue
    (kept if "terrain kept" in line else built).append(int(g.group(1)))
b = re.findall(r"built in ([0-9.]+) s", open(sys.argv[1]).read())
print("switch: job to job with the terrain built: %s ms (build %s s); with it kept: %s ms" % (
    "/".join(map(str, built)) or "-", "/".join(b), "/".join(map(str, kept)) or "-"))
PY
kill -TERM $FARM; wait $FARM 2>/dev/null

# ---- 2. kill storm ----
new_farm storm
SCENES="alps valley mesa default highlands valley"
n=0
for sc in $SCENES; do
    [ $n -lt "$J" ] || break
    n=$((n + 1))
    "$TF" submit "$ROOT/scenes/$sc.scene" --size "$SZ" --tasks rows:4 --name "s$n" >/dev/null || die "submit $sc"
    echo "$n $sc" >>"$T/storm.jobs"
done
worker "$T/storm-w1.log"; worker "$T/storm-w2.log"
kills=0
while [ $kills -lt "$K" ]; do
    sleep "$(python3 -c 'import random; print(round(random.uniform(0.3, 1.5), 2))')"
    all_done "$J" && break
    kill -KILL $FARM; wait $FARM 2>/dev/null
    kills=$((kills + 1))
    start_farm "$T/storm" "$PORT"
done
wait_done "$J"
identical=0 resumed=0 attempts=0
while read -r id sc; do
    "$TF" render "$ROOT/scenes/$sc.scene" --size "$SZ" --tasks rows:4 --listen 127.0.0.1:0 -j 2 -q \
        -o "$T/ref$id.exr" || die "reference $sc"
    "$TF" job "$id" --output "$T/got$id.exr" || die "download $id"
    "$EXRCMP" "$T/ref$id.exr" "$T/got$id.exr" >/dev/null 2>&1 && identical=$((identical + 1))
    a=$("$TF" job "$id" --json | python3 -c 'import json,sys; print(json.load(sys.stdin)["attempts"])')
    attempts=$((attempts + a))
    r=$(grep -c 'rows already on disk' "$T/storm/jobs/$id/render.log")
    resumed=$((resumed + r))
done <"$T/storm.jobs"
total=$("$TF" jobs --json | python3 -c 'import json,sys; print(len(json.load(sys.stdin)["jobs"]))')
echo "killstorm: kills=$kills jobs=$J in_queue=$total done=$J lost=$((J - total)) identical=$identical/$J renders=$attempts resumed_from_rows=$resumed"
[ "$identical" = "$J" ] && [ "$total" = "$J" ] || die "a job was lost or its image differs"
kill -TERM $FARM; wait $FARM 2>/dev/null

# ---- 3. load ----
new_farm load
sed -e 's/^size_exp .*/size_exp = 7/' "$ROOT/scenes/default.scene" >"$T/tiny.scene"
i=0; while [ $i -lt "$LN" ]; do
    i=$((i + 1)); "$TF" submit "$T/tiny.scene" --size 32x24 --name "t$i" --priority $((i % 3)) >/dev/null || die submit
done
python3 - "$TERRAFARM_FARM" "$(cat "$T/load.token")" "$T/lat" <<'PY' &
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
t0=$(date +%s%N)
i=0; while [ $i -lt "$LW" ]; do i=$((i + 1)); worker "$T/load-w$i.log" --name "w$i"; done
wait_done "$LN"
t1=$(date +%s%N)
kill $POLL 2>/dev/null
assign=$(python3 -c '
import json, sys, urllib.request
r = urllib.request.Request("http://%s/api/workers" % sys.argv[1], headers={"Authorization": "Bearer " + sys.argv[2]})
print(json.load(urllib.request.urlopen(r))["assignments"])' "$TERRAFARM_FARM" "$(cat "$T/load.token")")
python3 - "$T/lat" "$LN" "$LW" "$(( (t1 - t0) / 1000000 ))" "$assign" <<'PY'
import sys
lat = sorted(float(x) for x in open(sys.argv[1]) if x.strip()) or [0.0]
n, w, ms, assign = int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
p = lambda q: lat[min(len(lat) - 1, int(q * len(lat)))]
print("load: %d jobs, %d workers: %.2f jobs/s, %.2f assignments/s; GET /api/jobs p50 %.1f ms, p99 %.1f ms (%d requests)"
      % (n, w, n / (ms / 1000.0), assign / (ms / 1000.0), p(0.5), p(0.99), len(lat)))
PY
echo "farm_standing: done"
