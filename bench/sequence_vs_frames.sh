#!/bin/bash
# sequence_vs_frames.sh: what a sequence run saves over a per-frame farm.  A 24-frame sequence at a
# modest size with 2 workers, rendered side by side in one run
#   (a) as one `terrafarm render SCENE --frames 0-23` run: the terrain built once, one pool of
#       workers, the next frame's tasks dealt while the previous frame's last ones are in flight;
#   (b) as 24 separate `terrafarm render SCENE --frame N` runs, the way a per-frame farm
#       (Deadline, OpenCue, Flamenco) runs a sequence: every frame a new job that starts the
#       coordinator, builds the terrain, forks its workers and waits for its last task.
# Prints the ratio (a)/(b) of wall times (target <= 0.75), the same ratio of CPU seconds (user +
# sys of every process: far less sensitive than wall time to other work on a shared machine),
# and where the difference comes from, from the runs' own --stats: time before the first task (scene, terrain, fork), the workers' idle time while
# a frame is rendered (the frame-end tail), and process start/exit outside the coordinator's
# clock.  Every frame of (a) is checked byte-identical to its (b) counterpart.
#
# usage: bench/sequence_vs_frames.sh [SCENE]     (default scenes/flyby.scene)
#        bench/sequence_vs_frames.sh --smoke     (2 frames at 32x18 of flyby.scene with a 129^2,
#                                                3-octave terrain: for tests/e2e/bench_smoke.sh)
# env:   SIZE=320x180 FRAMES=24 WORKERS=2 REPEAT=1 TF=bin/terrafarm
set -eu
cd "$(dirname "$0")/.."
TF=${TF:-bin/terrafarm}
SMOKE=0
[ "${1:-}" = --smoke ] && { SMOKE=1; shift; SIZE=32x18; FRAMES=2; REPEAT=1; }
SCENE=${1:-scenes/flyby.scene}
SIZE=${SIZE:-320x180}
FRAMES=${FRAMES:-24}
WORKERS=${WORKERS:-2}
REPEAT=${REPEAT:-1}
[ -x "$TF" ] || { echo "sequence_vs_frames.sh: build first (make)" >&2; exit 1; }
W=$(mktemp -d "${TMPDIR:-/tmp}/tf-seqbench.XXXXXX")
trap 'rm -rf "$W"' EXIT
if [ "$SMOKE" = 1 ]; then
    sed 's/^size_exp *=.*/size_exp = 7/; s/^octaves *=.*/octaves = 3/' "$SCENE" >"$W/smoke.scene"
    SCENE=$W/smoke.scene
fi
last=$((FRAMES - 1))
now() { date +%s.%N; }
# cpu_of CMD...: run CMD; its children's user + sys seconds in $cpu
TIMEFORMAT='%U %S'
cpu_of() { local t; t=$( { time "$@" >/dev/null 2>&1; } 2>&1 ); cpu=$(echo "$t" | awk '{ print $1 + $2 }'); }

echo "cpu: $(sed -n 's/^model name[^:]*: //p' /proc/cpuinfo | head -1) ($(nproc) cores)"
echo "scene: $SCENE, $FRAMES frames at $SIZE, $WORKERS local workers, default tasks; best of $REPEAT"
echo "load average before: $(cut -d' ' -f1-3 /proc/loadavg)"

best_a= best_b=
for rep in $(seq 1 "$REPEAT"); do
    rm -rf "$W/a" "$W/b"; mkdir -p "$W/a" "$W/b"
    t0=$(now)
    cpu_of "$TF" render "$SCENE" --frames 0-$last --size "$SIZE" -j "$WORKERS" -q --listen 127.0.0.1:0 \
        -o "$W/a/f.####.exr" --stats "$W/a/stats.json"
    cpu_a=$cpu
    t1=$(now)
    cpu_b=0
    for n in $(seq 0 $last); do
        cpu_of "$TF" render "$SCENE" --frame "$n" --size "$SIZE" -j "$WORKERS" -q --listen 127.0.0.1:0 \
            -o "$W/b/f.####.exr" --stats "$W/b/stats.$n.json"
        cpu_b=$(echo "$cpu_b + $cpu" | bc -l)
    done
    t2=$(now)
    a=$(echo "$t1 - $t0" | bc -l); b=$(echo "$t2 - $t1" | bc -l)
    echo "run $rep: (a) $a s wall, $cpu_a CPU-s; (b) $b s wall, $cpu_b CPU-s"
    if [ -z "$best_a" ] || [ "$(echo "$a / $b < $best_a / $best_b" | bc -l)" = 1 ]; then
        best_a=$a; best_b=$b; best_cpu_a=$cpu_a; best_cpu_b=$cpu_b
        rm -rf "$W/best"; mkdir "$W/best"; cp -r "$W/a" "$W/b" "$W/best/"
    fi
done
for n in $(seq 0 $last); do
    f=$(printf 'f.%04d.exr' "$n")
    cmp -s "$W/best/a/$f" "$W/best/b/$f" || { echo "frame $n differs between (a) and (b)" >&2; exit 1; }
done
echo "all $FRAMES frames of (a) are byte-identical to (b)'s"

python3 - "$W/best" "$best_a" "$best_b" "$FRAMES" "$WORKERS" "$best_cpu_a" "$best_cpu_b" <<'PY'
import json, sys, glob
d, wall_a, wall_b, n, workers = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
cpu_a, cpu_b = float(sys.argv[6]), float(sys.argv[7])
a = json.load(open(d + "/a/stats.json"))
bs = [json.load(open(d + "/b/stats.%d.json" % i)) for i in range(n)]

def parts(runs, outer):
    """time before the first task, rendering span, workers idle in it, outside the stats clock"""
    setup = sum(r["frames"][0]["start_s"] for r in runs)
    terrain = sum(r["heightfield_s"] for r in runs)
    span = sum(r["wall_s"] - r["frames"][0]["start_s"] for r in runs)
    busy = sum(w["busy_s"] for r in runs for w in r["workers"])
    idle = span * workers - busy
    return dict(setup=setup, terrain=terrain, span=span, busy=busy, idle=idle,
                outside=outer - sum(r["wall_s"] for r in runs))

pa, pb = parts([a], wall_a), parts(bs, wall_b)
print()
print("                                     (a) one --frames run   (b) %d --frame runs" % n)
print("wall time, s                          %10.2f            %10.2f" % (wall_a, wall_b))
print("CPU time of all processes, s          %10.2f            %10.2f" % (cpu_a, cpu_b))
print("  before the first task (parse, terrain, fork), s %6.2f            %10.2f" % (pa["setup"], pb["setup"]))
print("    of which the height field, s      %10.2f            %10.2f" % (pa["terrain"], pb["terrain"]))
print("  dealing to the end, s               %10.2f            %10.2f" % (pa["span"], pb["span"]))
print("    worker-seconds busy               %10.2f            %10.2f" % (pa["busy"], pb["busy"]))
print("    worker-seconds idle (tails, finish) %8.2f            %10.2f" % (pa["idle"], pb["idle"]))
print("  process start and exit outside the stats clock, s %4.2f        %10.2f" % (pa["outside"], pb["outside"]))
print()
print("ratio (a)/(b) = %.3f   (target <= 0.75: %s); CPU seconds (a)/(b) = %.3f" % (
      wall_a / wall_b, "met" if wall_a / wall_b <= 0.75 else "NOT met", cpu_a / cpu_b))
saved = wall_b - wall_a
if saved > 0:
    print("of the %.2f s saved: %.2f s before the first task (%.2f s of it the height field), "
          "%.2f worker-s of idle (~%.2f s of wall), %.2f s of process start/exit, %.2f s busy time" % (
          saved, pb["setup"] - pa["setup"], pb["terrain"] - pa["terrain"], pb["idle"] - pa["idle"],
          (pb["idle"] - pa["idle"]) / workers, pb["outside"] - pa["outside"], (pb["busy"] - pa["busy"]) / workers))
PY
echo "load average after: $(cut -d' ' -f1-3 /proc/loadavg)"
