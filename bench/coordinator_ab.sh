#!/bin/bash
# coordinator_ab.sh: the coordinator's CPU per pixel, one binary against another (issue 23's "a
# coordinator that keeps up": `coordinator_render_cpu_s` per pixel of alps.scene at 3840x1280 with
# two forked workers).  The same render by binary A and by binary B, alternated A/B/A/B so that a
# change in the machine's load falls on both alike.  Each run's --stats gives the coordinator's CPU
# after the terrain build (`coordinator_render_cpu_s`: event loop, writer, checker) and the event
# loop's alone (`coordinator_supervise_cpu_s`).  Prints every pair, each side's median, the median
# of the pairs' ratios B/A (< 1: B spends less), in how many pairs B was lower, the CPU with its
# vector ISA and the load, and checks that the two binaries' images hold the same decoded pixels.
# This VM's figures move by 20-50% from one run to the next: trust the medians of 6 pairs or more.
#
# usage: bench/coordinator_ab.sh A_BIN B_BIN [SCENE]   (default scenes/alps.scene)
#        bench/coordinator_ab.sh --smoke               (bin/terrafarm against itself, 256x96, one
#                                                       pair: for tests/e2e/bench_smoke.sh)
# env:   SIZE=3840x1280 WORKERS=2 PAIRS=6 TASKS= (the default stamps; e.g. stamps:512x128)
#        EXRCMP=build/tools/exrcmp  TERRAFARM_WEB (for binaries copied out of the tree)
set -eu
cd "$(dirname "$0")/.."
if [ "${1:-}" = --smoke ]; then
    shift
    A=${TF:-bin/terrafarm} B=${TF:-bin/terrafarm} SIZE=256x96 PAIRS=1
else
    [ $# -ge 2 ] || { sed -n '12,16p' "$0" >&2; exit 2; }
    A=$1 B=$2
    shift 2
fi
SCENE=${1:-scenes/alps.scene}
SIZE=${SIZE:-3840x1280}
WORKERS=${WORKERS:-2}
PAIRS=${PAIRS:-6}
TASKS=${TASKS:-}
EXRCMP=${EXRCMP:-${TF_BUILD:-build}/tools/exrcmp}
for bin in "$A" "$B" "$EXRCMP"; do
    [ -x "$bin" ] || { echo "coordinator_ab.sh: no executable $bin (make; make test builds exrcmp)" >&2; exit 1; }
done
W=$(mktemp -d "${TMPDIR:-/tmp}/tf-coordab.XXXXXX")
trap 'rm -rf "$W"' EXIT
pixels=$(( ${SIZE%x*} * ${SIZE#*x} ))

# run SIDE BIN: one render; appends "render_cpu_s supervise_cpu_s" to $W/SIDE
run() {
    "$2" render "$SCENE" -q -j "$WORKERS" --size "$SIZE" ${TASKS:+--tasks "$TASKS"} --http none \
        --overwrite -o "$W/$1.exr" --stats "$W/$1.json"
    python3 -c 'import json, sys
d = json.load(open(sys.argv[1]))
print(d["coordinator_render_cpu_s"], d["coordinator_supervise_cpu_s"])' "$W/$1.json" >>"$W/$1"
}

. bench/lib/cpu.sh
bench_cpu_line
echo "scene $SCENE, $SIZE ($pixels pixels), -j $WORKERS, tasks ${TASKS:-default}, $PAIRS pairs A/B"
echo "A: $A"
echo "B: $B"
echo "load before: $(cut -d' ' -f1-3 /proc/loadavg)"
echo "pair  A render_cpu_s  B render_cpu_s  A ns/px  B ns/px  A loop_cpu_s  B loop_cpu_s"
for i in $(seq "$PAIRS"); do
    run a "$A"
    run b "$B"
    paste -d' ' <(sed -n "${i}p" "$W/a") <(sed -n "${i}p" "$W/b") |
        awk -v i="$i" -v px="$pixels" '{ printf "%4d  %13.3f  %13.3f  %7.1f  %7.1f  %11.3f  %11.3f\n",
                                               i, $1, $3, $1 * 1e9 / px, $3 * 1e9 / px, $2, $4 }'
done
"$EXRCMP" "$W/a.exr" "$W/b.exr" >/dev/null ||
    { echo "coordinator_ab.sh: A's and B's images differ" >&2; exit 1; }
echo "load after: $(cut -d' ' -f1-3 /proc/loadavg)"
paste -d' ' "$W/a" "$W/b" | python3 -c '
import statistics, sys
rows = [list(map(float, line.split())) for line in sys.stdin]
a = [r[0] for r in rows]; b = [r[2] for r in rows]
px = float(sys.argv[1])
print("median render_cpu_s: A %.3f (%.1f ns/px), B %.3f (%.1f ns/px)" %
      (statistics.median(a), statistics.median(a) * 1e9 / px,
       statistics.median(b), statistics.median(b) * 1e9 / px))
print("B/A render_cpu_s: median of the pairs %.3f, B lower in %d of %d pairs; images identical" %
      (statistics.median(y / x for x, y in zip(a, b)), sum(y < x for x, y in zip(a, b)), len(rows)))
' "$pixels"
