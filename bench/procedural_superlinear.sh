#!/bin/bash
# procedural_superlinear.sh: Musgrave's superlinear speedup (dissertation A.7.2.3), measured.
# A procedural scene ([terrain] procedural = yes) is rendered with 1, 2, 4 and 8 workers (4 and 8
# time-sliced on a 2-core machine) and postage-stamp tasks, with a per-worker terrain cache
# budget (--terrain-cache) that one worker's whole view does not fit.  With horizontal-extent
# affinity each worker renders its own column range, so its share of the terrain may fit its
# cache: the TOTAL terrain samples evaluated over all workers should then fall as workers are
# added, and the speedup over one (thrashing) worker exceed the worker count.
#
# CACHE=6M: one 160x100 worker of closeup.scene thrashes (its view is ~2 M samples, ~12 MB of
# tiles, since the level of detail went one level coarser), a 2-worker share nearly fits
# (bench/README.md section 5 for the first sweep, section 39 for today's: 32M, chosen before
# that change, now holds the whole view and shows nothing).
#
# Three configurations per worker count, alternated in each round (A/B/C, A/B/C, ...) so that a
# change of the machine's load falls on all alike:
#   on    the small budget, --affinity on
#   off   the small budget, --affinity off (FIFO dealing: every worker wanders the whole view)
#   big   a budget the whole view fits (no evictions), --affinity on: the no-thrash baseline
# Each run is `terrafarm bench SCENE -j N --repeat 1 ...` (a real render as a child process);
# wall time is the render's own wall_s.  Speedups are against the 1-worker run of the same
# configuration measured in this run (medians over the rounds), and also against the 1-worker
# no-thrash run.  Every image is checked byte-identical to the first (fixed stamps: one layout).
#
# usage: bench/procedural_superlinear.sh [SCENE]   (default scenes/closeup.scene)
#        bench/procedural_superlinear.sh --smoke   (default.scene procedural, 32x20, workers 1 2,
#                                                  1 round: bench_smoke.sh)
# env:   SIZE=160x100 STAMPS=16x16 CACHE=6M BIG=512M WORKERS="1 2 4 8" ROUNDS=3 TF=bin/terrafarm
set -eu
cd "$(dirname "$0")/.."
TF=${TF:-bin/terrafarm}
SMOKE=0
if [ "${1:-}" = --smoke ]; then
    SMOKE=1; shift
    SIZE=32x20; STAMPS=16x16; CACHE=2M; BIG=64M; WORKERS="1 2"; ROUNDS=1
fi
SCENE=${1:-}
SIZE=${SIZE:-160x100}
STAMPS=${STAMPS:-16x16}
CACHE=${CACHE:-6M}
BIG=${BIG:-512M}
WORKERS=${WORKERS:-1 2 4 8}
ROUNDS=${ROUNDS:-3}
[ -x "$TF" ] || { echo "procedural_superlinear.sh: build first (make)" >&2; exit 1; }
case " $WORKERS " in *" 1 "*) ;; *) echo "procedural_superlinear.sh: WORKERS must include 1" >&2; exit 2 ;; esac
W=$(mktemp -d "${TMPDIR:-/tmp}/tf-superlin.XXXXXX")
trap 'rm -rf "$W"' EXIT
if [ -z "$SCENE" ] && [ "$SMOKE" = 1 ]; then
    # the smoke run only shows the script works (also under AddressSanitizer, ten times slower):
    # default.scene's fBm, procedural, is far cheaper than closeup.scene
    SCENE=$W/smoke.scene
    sed 's/^size_exp .*/procedural   = yes/' scenes/default.scene >"$SCENE"
fi
SCENE=${SCENE:-scenes/closeup.scene}

. bench/lib/cpu.sh
isa=$(bench_isa)
echo "scene $SCENE, $SIZE, stamps:$STAMPS, workers: $WORKERS, $ROUNDS round(s) alternating on/off/big"
echo "terrain cache per worker: $CACHE (on, off), $BIG (big: the no-thrash baseline)"
echo "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), $(nproc) cores," \
     "load: $(cut -d' ' -f1-3 /proc/loadavg)"
echo "vector ISA: ${isa:-none of avx512f/avx2/fma/avx/sse4_2} (the build uses the Makefile's flags, no -march)"

# one CONFIG N ROUND: one render through terrafarm bench, kept in $W/CONFIG-N-ROUND/
one() {
    local cache=$CACHE aff=on
    [ "$1" = big ] && cache=$BIG
    [ "$1" = off ] && aff=off
    "$TF" bench "$SCENE" -q -j "$2" --repeat 1 --size "$SIZE" --tasks "stamps:$STAMPS" \
        --terrain-cache "$cache" --affinity "$aff" --keep "$W/$1-$2-$3" \
        --csv "$W/$1-$2-$3.csv" >"$W/$1-$2-$3.out"
    local img="$W/$1-$2-$3/out-$2-0.exr"
    if [ ! -e "$W/ref.exr" ]; then
        cp "$img" "$W/ref.exr"
    elif ! cmp -s "$W/ref.exr" "$img"; then
        echo "FAIL: $1 with $2 workers (round $3): the image differs from the first" >&2
        exit 1
    fi
    rm -f "$img"
}

for r in $(seq "$ROUNDS"); do
    for n in $WORKERS; do
        for c in on off big; do
            [ "$SMOKE" = 1 ] || echo "round $r: $n worker(s), $c" >&2
            one "$c" "$n" "$r"
        done
    done
done
echo "all $(ls "$W"/*.csv | wc -l) images are byte-identical"

python3 - "$W" "$ROUNDS" "$SIZE" $WORKERS <<'PY'
import csv, json, statistics, sys
w, rounds, counts = sys.argv[1], int(sys.argv[2]), [int(x) for x in sys.argv[4:]]
px = int(sys.argv[3].lower().split("x")[0]) * int(sys.argv[3].lower().split("x")[1])
def runs(c, n):
    out = []
    for r in range(1, rounds + 1):
        row = next(csv.DictReader(open("%s/%s-%d-%d.csv" % (w, c, n, r))))
        st = json.load(open("%s/%s-%d-%d/out-%d-0.json" % (w, c, n, r, n)))
        out.append((float(row["wall_s"]), float(row["samples_evaluated"]),
                    float(row["cache_evictions"]),
                    sum(x["first_choice"] for x in st["workers"]),
                    sum(x["first_choice"] + x["second_choice"] + x["elsewhere"]
                        for x in st["workers"]),
                    st["worker_cpu_ns_per_pixel"] * px / 1e9))
    return out
med = {}
for c in ("on", "off", "big"):
    for n in counts:
        rs = runs(c, n)
        med[c, n] = [statistics.median(x[k] for x in rs) for k in range(6)] + \
                    [[x[0] for x in rs]]
nothrash1 = med["big", 1][0]
print()
print("%-4s %7s %8s %13s %11s %9s %8s %8s %9s %8s %8s %11s  %s"
      % ("cfg", "workers", "wall_s", "samples_total", "per_worker", "evictions", "speedup",
         "spd_min", "vs_big_1w", "cpu_s", "cpu_1/n", "first/takes", "walls"))
for c in ("on", "off", "big"):
    base, cbase, mbase = med[c, 1][0], med[c, 1][5], min(med[c, 1][6])
    for n in counts:
        m = med[c, n]
        print("%-4s %7d %8.3f %13.0f %11.0f %9.0f %8.3f %8.3f %9.3f %8.3f %8.3f %5.0f/%-5.0f  %s"
              % (c, n, m[0], m[1], m[1] / n, m[2], base / m[0], mbase / min(m[6]),
                 nothrash1 / m[0], m[5], cbase / m[5] if m[5] > 0 else 0, m[3], m[4],
                 " ".join("%.2f" % t for t in m[6])))
print("(medians over %d round(s); speedup: wall time of 1 worker of the same cfg / this one;"
      " spd_min: the same with the fastest run of each (the least disturbed by other load);"
      " vs_big_1w: of 1 worker with the big cache / this one; cpu_s: all workers' CPU seconds;"
      " cpu_1/n: 1 worker's CPU / this one's, > 1 when n workers do less work in all)" % rounds)
on = [med["on", n][1] for n in counts]
falls = all(b < a for a, b in zip(on, on[1:]))
print("samples with affinity on: %s (%s)" % (" -> ".join("%.0f" % s for s in on),
      "fall at every step" if falls else "do NOT fall at every step"))
if 2 in counts:
    print("superlinear: 2-worker speedup %.3f (affinity on), %.3f (off); fastest runs %.3f (on);"
          " CPU work 1 worker / 2 workers %.3f (on); against the no-thrash 1-worker run %.3f (on)"
          % (med["on", 1][0] / med["on", 2][0], med["off", 1][0] / med["off", 2][0],
             min(med["on", 1][6]) / min(med["on", 2][6]),
             med["on", 1][5] / med["on", 2][5] if med["on", 2][5] > 0 else 0,
             nothrash1 / med["on", 2][0]))
PY
