#!/bin/bash
# affinity_ab.sh: what horizontal-extent affinity (--affinity, coordinator/render/affinity.h) costs or
# saves on a scene, against plain FIFO dealing.  The same render with --affinity on (A) and off
# (B), alternated A/B/A/B... so that a change in the machine's load falls on both alike, each run
# timed by hyperfine (one run per call, after one warm-up of each; without hyperfine, by the
# clock around the process: the same wall time, give or take a fork).  Prints each side's mean and
# median wall time, the ratio on/off of the medians (< 1: affinity is faster), the median of the
# coordinator's CPU while supervising (what the chooser costs), and from the last runs' --stats
# how many takes were first choices and how often a worker left its range.  The two images are
# checked byte-identical.
#
# Terrain here is a height field built once before the fork, so a worker has no terrain cache
# to re-use: on such scenes affinity should cost nothing (ratio ~1); procedural terrain
# evaluated per sample by the worker is where Musgrave expected it to pay.
#
# usage: bench/affinity_ab.sh [SCENE]      (default scenes/default.scene)
#        bench/affinity_ab.sh --smoke      (64x48, 1 round: for tests/e2e/bench_smoke.sh)
# env:   SIZE=640x480 WORKERS=2 ROUNDS=8 TASKS= (default stamps) TF=bin/terrafarm
set -eu
cd "$(dirname "$0")/.."
TF=${TF:-bin/terrafarm}
SMOKE=0
[ "${1:-}" = --smoke ] && { SMOKE=1; shift; SIZE=64x48; ROUNDS=1; TASKS=stamps:16x16; }
SCENE=${1:-scenes/default.scene}
SIZE=${SIZE:-640x480}
WORKERS=${WORKERS:-2}
ROUNDS=${ROUNDS:-8}
TASKS=${TASKS:-}
[ -x "$TF" ] || { echo "affinity_ab.sh: build first (make)" >&2; exit 1; }
W=$(mktemp -d "${TMPDIR:-/tmp}/tf-affbench.XXXXXX")
trap 'rm -rf "$W"' EXIT
tasks_arg=${TASKS:+--tasks $TASKS}

# cmd on|off: the render of one side
cmd() {
    echo "$TF render $SCENE -q -j $WORKERS --wait-workers $WORKERS --size $SIZE $tasks_arg" \
         "--http none --listen 127.0.0.1:0 --overwrite --affinity $1 -o $W/$1.exr" \
         "--stats $W/$1.json"
}
# one on|off: one timed run, its wall time appended to $W/$1.times
one() {
    if [ -n "$HYPERFINE" ]; then
        hyperfine -N --runs 1 --style none --export-json "$W/h.json" "$(cmd "$1")" >/dev/null
        python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["results"][0]["mean"])' \
            "$W/h.json" >>"$W/$1.times"
    else
        local t0 t1
        t0=$(date +%s.%N); $(cmd "$1"); t1=$(date +%s.%N)
        echo "$t1 - $t0" | bc -l >>"$W/$1.times"
    fi
    python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["coordinator_supervise_cpu_s"])' \
        "$W/$1.json" >>"$W/$1.cpu"
}
HYPERFINE=$(command -v hyperfine || true)
echo "scene $SCENE, $SIZE, $WORKERS workers, tasks ${TASKS:-default}, $ROUNDS rounds A/B"
echo "timer: ${HYPERFINE:-date +%s.%N (no hyperfine)}"
echo "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), load: $(cut -d' ' -f1-3 /proc/loadavg)"
[ "$SMOKE" = 1 ] || { $(cmd on) && $(cmd off); }   # warm-up: page cache, first fork
for r in $(seq "$ROUNDS"); do
    one on
    one off
done
cmp -s "$W/on.exr" "$W/off.exr" || { echo "FAIL: the images differ"; exit 1; }
echo "the on and off images are byte-identical"
python3 - "$W" <<'PY'
import json, statistics, sys
w = sys.argv[1]
t = {k: [float(x) for x in open("%s/%s.times" % (w, k))] for k in ("on", "off")}
cpu = {k: [float(x) for x in open("%s/%s.cpu" % (w, k))] for k in ("on", "off")}
for k in ("on", "off"):
    s = json.load(open("%s/%s.json" % (w, k)))
    takes = sum(x["first_choice"] + x["second_choice"] + x["elsewhere"] for x in s["workers"])
    first = sum(x["first_choice"] for x in s["workers"])
    switches = sum(x["range_switches"] for x in s["workers"])
    print("%-3s wall mean %.3f s, median %.3f s (%s); coordinator supervising CPU median "
          "%.3f s; last run: %d tasks, %d of %d takes first choices, %d range switches"
          % (k, statistics.mean(t[k]), statistics.median(t[k]),
             " ".join("%.3f" % x for x in t[k]), statistics.median(cpu[k]), s["tasks_total"],
             first, takes, switches))
print("affinity on/off wall ratio: %.3f (medians), %.3f (means)"
      % (statistics.median(t["on"]) / statistics.median(t["off"]),
         statistics.mean(t["on"]) / statistics.mean(t["off"])))
PY
