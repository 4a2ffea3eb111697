#!/bin/bash
# startup_ab.sh: what starting the program costs, one binary against another (issue 23, "no
# start-up tax").  Every forked worker's parent, every networked worker, every `terrafarm jobs`
# or `status` call and every test pays it.  Alternating A/B/A/B so that a change in the
# machine's load falls on both alike, it measures:
#   version  wall of `BIN --version` (the process start alone: loading and relocating its
#            libraries), RUNS times each;
#   render   wall of a small whole render, default.scene at SIZE with `-j 2` and no dashboard
#            (the start plus a render a user waits for), RENDERS times each;
#   rss      the coordinator's peak RSS in that render (`--stats coordinator_max_rss_kb`).
# Prints each side's medians, the ratios B/A and, last, one summary line.  Also prints the CPU
# and its vector ISA, and the number of shared libraries each binary maps.
#
# usage: bench/startup_ab.sh A_BIN B_BIN      env: RUNS=40 RENDERS=8 SIZE=480x270 BACKEND=c
#        bench/startup_ab.sh --smoke          bin/terrafarm against itself, 3 runs, 1 render
#                                             at 64x36 (for tests/e2e/bench_smoke.sh)
set -eu
cd "$(dirname "$0")/.."
if [ "${1:-}" = --smoke ]; then
    A=${TF:-bin/terrafarm} B=${TF:-bin/terrafarm} RUNS=3 RENDERS=1 SIZE=64x36
else
    [ $# -eq 2 ] || { sed -n '14,16p' "$0" >&2; exit 2; }
    A=$1 B=$2
fi
RUNS=${RUNS:-40}
RENDERS=${RENDERS:-8}
SIZE=${SIZE:-480x270}
BACKEND=${BACKEND:-c}
for bin in "$A" "$B"; do
    [ -x "$bin" ] || { echo "startup_ab.sh: no executable $bin (make)" >&2; exit 1; }
done
W=$(mktemp -d "${TMPDIR:-/tmp}/tf-startup.XXXXXX")
trap 'rm -rf "$W"' EXIT

# now_ns: the monotonic-enough wall clock in nanoseconds
now_ns() { date +%s%N; }

# time_ms SIDE-FILE CMD...: run CMD (output discarded), append its wall in ms to SIDE-FILE
time_ms() {
    local out=$1 t0 t1
    shift
    t0=$(now_ns)
    "$@" >/dev/null 2>&1
    t1=$(now_ns)
    echo "$(( (t1 - t0) / 1000 ))" | awk '{printf "%.3f\n", $1 / 1000}' >>"$out"
}

render() { # render SIDE BIN
    "$2" render scenes/default.scene -q -j 2 --size "$SIZE" --backend "$BACKEND" --http none \
        --overwrite -o "$W/$1.exr" --stats "$W/$1.json"
}

. bench/lib/cpu.sh
bench_cpu_line
echo "A: $A ($(ldd "$A" | grep -c '=>') shared libraries)"
echo "B: $B ($(ldd "$B" | grep -c '=>') shared libraries)"
echo "load before: $(cut -d' ' -f1-3 /proc/loadavg)"

for i in $(seq "$RUNS"); do
    time_ms "$W/version.a" "$A" --version
    time_ms "$W/version.b" "$B" --version
done
for i in $(seq "$RENDERS"); do
    time_ms "$W/render.a" render a "$A"
    python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["coordinator_max_rss_kb"] / 1024)' \
        "$W/a.json" >>"$W/rss.a"
    time_ms "$W/render.b" render b "$B"
    python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["coordinator_max_rss_kb"] / 1024)' \
        "$W/b.json" >>"$W/rss.b"
done
echo "load after: $(cut -d' ' -f1-3 /proc/loadavg)"

python3 - "$W" "$RUNS" "$RENDERS" "$SIZE" "$BACKEND" <<'EOF'
import statistics, sys
w, runs, renders, size, backend = sys.argv[1:]
def side(name, s):
    return [float(x) for x in open(f"{w}/{name}.{s}").read().split()]
ratios = {}
for name, what, unit in (("version", f"--version, {runs} runs", "ms"),
                         ("render", f"render default.scene {size} -j 2 --backend {backend}, {renders} runs", "ms"),
                         ("rss", "coordinator peak RSS in that render", "MB")):
    a, b = side(name, "a"), side(name, "b")
    ma, mb = statistics.median(a), statistics.median(b)
    ratios[name] = mb / ma if ma > 0 else float("nan")
    print(f"{what}: A median {ma:.1f} {unit} ({min(a):.1f}-{max(a):.1f}), "
          f"B median {mb:.1f} {unit} ({min(b):.1f}-{max(b):.1f}), B/A {ratios[name]:.3f}")
print("startup B/A: version %.3f, render %.3f, rss %.3f" %
      (ratios["version"], ratios["render"], ratios["rss"]))
EOF
