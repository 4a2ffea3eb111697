#!/bin/bash
# paint_progress.sh: how fast Raypaint (terrafarm paint, Musgrave A.7.2.4) comes into focus,
# against the full render of the same scene measured in the same run (alternating render and
# paint, medians over ROUNDS).  For each configuration it starts `terrafarm paint` and watches it
# as a page does (tests/tools/paint_watch: the display messages drawn by the page's own rule),
# and reports:
#   coarse_s   from the start (a paint started --paused, its terrain built and its workers in,
#              resumed by the watcher) to its first complete coarse picture drawn
#   tNN_s      from the start to a picture within NN dB PSNR of the painted one (which
#              is the render's: tests/e2e/paint_browser.sh), also as a fraction of the render's
#              wall time; painted_s, every pixel exact
# Configurations: the granularity (A.7.2.4.2) -- levels a task descends (LEVELS), the side of
# the cells rendered exactly (LEAVES), the stride of their lattice before that (FINES), rays a
# task (RAYS) -- with WORKERS forked workers, and
# with NET networked workers (terrafarm worker --connect, one process each) instead.
# PSNR_CURVE=1 prints the whole curve of the default configuration, then moves the view as the
# page does and times the new view's first pixels and its coarse picture.
#
# usage: bench/paint_progress.sh [SCENE]       (default scenes/default.scene at SIZE=1920x1080)
#        bench/paint_progress.sh --smoke       (160x90, one configuration, 1 round)
# env:   SIZE LEVELS="1 2 3" LEAVES="2 4 8" FINES="2" RAYS="4096" WORKERS="1 2" NET=2 ROUNDS=1
#        TF=bin/terrafarm WATCH=build/tools/paint_watch (a TF copied elsewhere needs
#        TERRAFARM_WEB=path/to/web for the paint's page)
set -euo pipefail
cd "$(dirname "$0")/.."
TF=${TF:-bin/terrafarm}
WATCH=${WATCH:-${TF_BUILD:-build}/tools/paint_watch}
if [ "${1:-}" = --smoke ]; then
    shift
    SIZE=160x90 LEVELS=2 LEAVES=8 RAYS=4096 FINES=2 WORKERS=2 NET=0 ROUNDS=1
fi
SCENE=${1:-scenes/default.scene}
SIZE=${SIZE:-1920x1080}
LEVELS=${LEVELS:-1 2 3}
LEAVES=${LEAVES:-2 4 8}
RAYS=${RAYS:-4096}
FINES=${FINES:-2}
WORKERS=${WORKERS:-1 2}
NET=${NET:-2}
ROUNDS=${ROUNDS:-1}
[ -x "$TF" ] && [ -x "$WATCH" ] || { echo "paint_progress.sh: build first (make test builds $WATCH)" >&2; exit 1; }
W=$(mktemp -d "${TMPDIR:-/tmp}/tf-paintbench.XXXXXX")
PIDS=""
trap 'for p in $PIDS; do kill -9 $p 2>/dev/null; done; rm -rf "$W"' EXIT

. bench/lib/cpu.sh
bench_cpu_line
echo "scene $SCENE at $SIZE; $ROUNDS round(s); render and paint alternate"

median() { sort -g | awk '{v[NR]=$1} END {if (NR) print (NR%2 ? v[(NR+1)/2] : (v[NR/2]+v[NR/2+1])/2); else print -1}'; }
now() { date +%s.%N; }

# render_wall J: wall seconds of a full render with J forked workers.
render_wall() {
    t0=$(now)
    "$TF" render "$SCENE" --size "$SIZE" -j "$1" -q --http none --listen 127.0.0.1:0 -o "$W/r.exr"
    awk -v a="$t0" -v b="$(now)" 'BEGIN {print b - a}'
}

# paint_run J NET LEVELS LEAF RAYS FINE: one paint watched to the end; paint_watch's last line.
paint_run() {
    rm -f "$W/p.err"
    if [ "$2" -gt 0 ]; then
        "$TF" paint "$SCENE" --size "$SIZE" -j 0 --listen 127.0.0.1:0 --http 127.0.0.1:0 \
            --paused --levels "$3" --leaf "$4" --task-rays "$5" --fine "$6" 2>"$W/p.err" &
    else
        "$TF" paint "$SCENE" --size "$SIZE" -j "$1" --http 127.0.0.1:0 --paused \
            --levels "$3" --leaf "$4" --task-rays "$5" --fine "$6" 2>"$W/p.err" &
    fi
    pp=$!; PIDS="$PIDS $pp"
    for _ in $(seq 600); do grep -q 'paint: open' "$W/p.err" 2>/dev/null && break; sleep 0.05; done
    addr=$(sed -n 's/.*paint: open http:\/\/\([^/]*\)\/.*/\1/p' "$W/p.err")
    [ -n "$addr" ] || { echo "paint_progress.sh: terrafarm paint did not start: $(cat "$W/p.err")" >&2; exit 1; }
    if [ "$2" -gt 0 ]; then
        port=$(sed -n 's/.*worker --connect HOST:\([0-9]*\).*/\1/p' "$W/p.err")
        for _ in $(seq "$2"); do "$TF" worker --connect "127.0.0.1:$port" -j 1 -q & PIDS="$PIDS $!"; done
        # the paint counts its workers by their hellos: wait until they are all in
        for _ in $(seq 600); do
            [ "$(python3 -c 'import json,sys,urllib.request
print(json.load(urllib.request.urlopen(sys.argv[1]))["workers"])' "http://$addr/api/paint/status")" = "$2" ] && break
            sleep 0.05
        done
    fi
    "$WATCH" "$addr" 50 --resume ${MOVE:+--then-move} >"$W/watch.out" || { cat "$W/p.err" >&2; exit 1; }
    kill -TERM $pp; wait $pp 2>/dev/null || true
    wait 2>/dev/null || true
    tail -1 "$W/watch.out"
}

field() { sed -n "s/.*$1=\([-0-9.]*\).*/\1/p"; }

# config J NET LEVELS LEAF RAYS FINE: medians of ROUNDS paint runs, each after a render.
config() {
    : >"$W/renders"; : >"$W/paints"
    for _ in $(seq "$ROUNDS"); do
        render_wall "$([ "$2" -gt 0 ] && echo "$2" || echo "$1")" >>"$W/renders"
        paint_run "$@" >>"$W/paints"
    done
    rw=$(median <"$W/renders")
    line="render_s=$rw"
    for f in coarse_s t25_s t30_s t35_s painted_s; do
        line="$line $f=$(field "$f" <"$W/paints" | median)"
    done
    t30=$(echo "$line" | field t30_s)
    frac=$(awk -v a="$t30" -v b="$rw" 'BEGIN {print a / b}')
    printf '%-28s %s t30/render=%.3f\n' "workers=$1 net=$2 levels=$3 leaf=$4 fine=$6 rays=$5" "$line" "$frac"
}

best=""
for j in $WORKERS; do
    for l in $LEVELS; do for f in $LEAVES; do for r in $RAYS; do for q in $FINES; do
        [ "$q" -le "$f" ] && config "$j" 0 "$l" "$f" "$r" "$q" | tee -a "$W/table"
    done; done; done; done
done
if [ "$NET" -gt 0 ]; then
    for l in $LEVELS; do for f in $LEAVES; do for r in $RAYS; do for q in $FINES; do
        [ "$q" -le "$f" ] && config 0 "$NET" "$l" "$f" "$r" "$q" | tee -a "$W/table"
    done; done; done; done
fi
if [ "${PSNR_CURVE:-0}" = 1 ]; then
    echo "PSNR curve, 2 forked workers, default granularity, then a new view (the sun turned):"
    MOVE=1 paint_run 2 0 2 16 16384 2 >/dev/null
    cat "$W/watch.out"
fi
best=$(sort -t= -k9 -g "$W/table" | awk '{print $NF, $0}' | sort -g | head -1 | cut -d' ' -f2-)
echo "fastest to 30 dB: $best"
echo "paint_progress: $(wc -l <"$W/table") configurations measured"
