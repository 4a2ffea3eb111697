#!/bin/bash
# backend_ab.sh: issue 23's measure of the OpenCL backend, whole renders `--backend opencl`
# against `--backend c` (target: OpenCL 1.3x faster at 480x270 and at 1920x1080).  Each pair is
# the same render by both backends, their order swapped from one pair to the next (C first, then
# OpenCL first, ...) so that a change in the machine's load falls on both alike; a render's
# figures are its wall time and its CPU (the coordinator's and its workers', user + system).
# Prints every pair, each size's medians, the median of the pairs' C / OpenCL ratios (> 1:
# OpenCL faster) with their spread and in how many pairs OpenCL was faster, checks that the two
# backends' images hold the same pixels (on PoCL they are bit-identical), and the CPU with its
# vector ISA and the load.  This VM's renders move by 10-30% from one run to the next: trust
# the medians of 8 pairs or more.  Exits 77 (skipped) where no OpenCL device works.
#
# usage: bench/backend_ab.sh [SCENE]   (default scenes/default.scene)
#        bench/backend_ab.sh --smoke   (64x36, one pair: for tests/e2e/bench_smoke.sh)
# env:   SIZES="480x270 1920x1080" PAIRS=8 WORKERS=2 TF=bin/terrafarm
#        EXRCMP=build/tools/exrcmp
set -eu
cd "$(dirname "$0")/.."
if [ "${1:-}" = --smoke ]; then
    shift
    SIZES=64x36 PAIRS=1
fi
SCENE=${1:-scenes/default.scene}
SIZES=${SIZES:-480x270 1920x1080}
PAIRS=${PAIRS:-8}
WORKERS=${WORKERS:-2}
TF=${TF:-bin/terrafarm}
EXRCMP=${EXRCMP:-${TF_BUILD:-build}/tools/exrcmp}
for bin in "$TF" "$EXRCMP"; do
    [ -x "$bin" ] || { echo "backend_ab.sh: no executable $bin (make; make test builds exrcmp)" >&2; exit 1; }
done
W=$(mktemp -d "${TMPDIR:-/tmp}/tf-backendab.XXXXXX")
trap 'rm -rf "$W"' EXIT

# A tiny OpenCL render first: without a device this is a missing peer, not a slow backend.
if ! "$TF" render "$SCENE" -q -j 1 --size 16x9 --backend opencl --http none -o "$W/probe.exr" \
    2>"$W/probe.err"; then
    echo "backend_ab.sh: no working OpenCL device: $(grep -m1 -i opencl "$W/probe.err" ||
        head -1 "$W/probe.err")"
    exit 77
fi

# run BACKEND SIZE: one whole render; appends "wall_s cpu_s" to $W/BACKEND.SIZE
run() {
    python3 - "$TF" "$SCENE" "$2" "$WORKERS" "$1" "$W/$1.exr" >>"$W/$1.$2" <<'EOF'
import os, resource, subprocess, sys, time
tf, scene, size, workers, backend, out = sys.argv[1:]
before = resource.getrusage(resource.RUSAGE_CHILDREN)
t0 = time.perf_counter()
subprocess.run([tf, "render", scene, "-q", "-j", workers, "--size", size, "--backend", backend,
                "--http", "none", "--overwrite", "-o", out], check=True)
wall = time.perf_counter() - t0
after = resource.getrusage(resource.RUSAGE_CHILDREN)
cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
print("%.4f %.4f" % (wall, cpu))
EOF
}

. bench/lib/cpu.sh
bench_cpu_line
echo "scene $SCENE, sizes $SIZES, -j $WORKERS, $PAIRS pairs C/OpenCL, binary $TF"
echo "load before: $(cut -d' ' -f1-3 /proc/loadavg)"
summary=""
for size in $SIZES; do
    echo "$size: pair  C wall  OpenCL wall  C cpu  OpenCL cpu"
    for i in $(seq "$PAIRS"); do
        if [ $((i % 2)) -eq 1 ]; then run c "$size"; run opencl "$size"
        else run opencl "$size"; run c "$size"; fi
        paste -d' ' <(sed -n "${i}p" "$W/c.$size") <(sed -n "${i}p" "$W/opencl.$size") |
            awk -v i="$i" '{ printf "%10d  %6.3f  %11.3f  %5.3f  %10.3f\n", i, $1, $3, $2, $4 }'
    done
    "$EXRCMP" "$W/c.exr" "$W/opencl.exr" >/dev/null ||
        { echo "backend_ab.sh: the two backends' images differ at $size" >&2; exit 1; }
    paste -d' ' "$W/c.$size" "$W/opencl.$size" | python3 -c '
import statistics, sys
rows = [list(map(float, line.split())) for line in sys.stdin]
c = [q[0] for q in rows]; o = [q[2] for q in rows]
r = [x / y for x, y in zip(c, o)]
print("%s: median wall C %.3f s, OpenCL %.3f s; C/OpenCL wall median %.3f (%.3f-%.3f), OpenCL "
      "faster in %d of %d pairs; median CPU C %.3f s, OpenCL %.3f s; images identical" %
      (sys.argv[1], statistics.median(c), statistics.median(o), statistics.median(r), min(r),
       max(r), sum(x > y for x, y in zip(c, o)), len(rows),
       statistics.median(q[1] for q in rows), statistics.median(q[3] for q in rows)))
open(sys.argv[2], "w").write("%.3f" % statistics.median(r))' "$size" "$W/ratio"
    summary="$summary $size $(cat "$W/ratio")"
done
echo "load after: $(cut -d' ' -f1-3 /proc/loadavg)"
echo "C/OpenCL wall ratio (> 1: OpenCL faster; issue 23 asks >= 1.3):$summary"
