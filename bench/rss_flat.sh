#!/bin/bash
# rss_flat.sh: the coordinator's peak memory as the image grows (docs/contract.md section 6: "flat
# as the image grows"), for both output kinds, at 1024^2, 2048^2, 4096^2 and 8192^2, each with
# fixed task shapes (tiled stamps:64x64, scanline rows:8: a band of tasks -- the watermark's unit
# -- then grows with the width) and with bands capped as the default stamps are (tiled
# stamps:128xH, 512 K pixels a band; scanline rows:K, 128 K pixels a band).  A real coordinator (-j 0) is served by
# simulated workers (terrafarm worker --simulate ... --payloads) that answer at once with the
# packed chunks of a real render of the same layout, recorded first, so the coordinator
# receives, checks and writes real bytes at full speed without rendering 67 Mpixels here.
# Prints one line per run: kind, size, coordinator_max_rss_kb, output bytes, wall and
# render-path CPU of the coordinator.
#
# usage: bench/rss_flat.sh [--smoke]
#   (env: SIZES="1024 2048 4096 8192" KINDS="tiled tiled-capped scanline scanline-capped"
#    RECORD=1024x256 DIR=/tmp TF=bin/terrafarm)
#   --smoke: one 64^2 run of each fixed-shape kind, payloads from a 128x64 render, 2 simulated
#   workers: for tests/e2e/bench_smoke.sh.
set -eu
cd "$(dirname "$0")/.."
TF=${TF:-bin/terrafarm}
SCENE=scenes/default.scene
SIM_WORKERS=16
if [ "${1:-}" = --smoke ]; then SIZES=64; KINDS="tiled scanline"; RECORD=128x64; SIM_WORKERS=2; fi
SIZES=${SIZES:-"1024 2048 4096 8192"}
KINDS=${KINDS:-"tiled tiled-capped scanline scanline-capped"}
RECORD=${RECORD:-1024x256}
DIR=$(mktemp -d "${DIR:-/tmp}/tf-rss.XXXXXX")
trap 'rm -rf "$DIR"' EXIT
MODEL=bench/default.cost
grep -m1 'model name' /proc/cpuinfo | sed 's/.*: /cpu: /'
echo "load: $(cut -d' ' -f1-3 /proc/loadavg)"

# record TASKS WIDTH: a real render of the layout a run needs (scanline: of its width)
record() {
    case $1 in
    stamps:*) "$TF" render "$SCENE" -j 2 --size "$RECORD" --tasks $1 -o "$DIR/rec.exr" -q --overwrite ;;
    rows:*) "$TF" render "$SCENE" -j 2 --size "$2"x32 --tasks $1 -o "$DIR/rec.exr" -q --overwrite ;;
    esac
}

echo "kind,tasks,size,coordinator_max_rss_kb,out_bytes,wall_s,coordinator_render_cpu_s,cpu_ns_per_pixel"
for kind in $KINDS; do
  for n in $SIZES; do
    cap=$((131072 / n)); [ $cap -gt 128 ] && cap=128
    tcap=$((524288 / n)); [ $tcap -gt 128 ] && tcap=128
    case $kind in
    tiled) tasks=stamps:64x64 ;;
    tiled-capped) tasks=stamps:128x$tcap ;;
    scanline) tasks=rows:8 ;;
    scanline-capped) tasks=rows:$cap ;;
    esac
    record $tasks $n
    rec="$DIR/rec.exr"
    : >"$DIR/coord.err" # there before the render's shell opens it: sed below must find it (set -e)
    "$TF" render "$SCENE" -j 0 --listen 127.0.0.1:0 --size ${n}x$n --tasks $tasks \
      -o "$DIR/out.exr" --overwrite --stats "$DIR/s.json" 2>>"$DIR/coord.err" &
    coord=$!
    port=""
    for i in $(seq 100); do
      port=$(sed -n 's/.*workers may join at [^ ]*:\([0-9][0-9]*\).*/\1/p' "$DIR/coord.err")
      [ -n "$port" ] && break; sleep 0.05
    done
    "$TF" worker --connect 127.0.0.1:$port --simulate "$MODEL" -j "$SIM_WORKERS" --pixel-us 0.001 \
      --payloads "$rec" -q >/dev/null
    wait $coord
    js() { sed -n "s/^ *\"$1\": *\([0-9.]*\).*/\1/p" "$DIR/s.json" | head -1; }
    echo "$kind,$tasks,${n}x$n,$(js coordinator_max_rss_kb),$(wc -c <"$DIR/out.exr"),$(js wall_s),$(js coordinator_render_cpu_s),$(js coordinator_cpu_ns_per_pixel)"
    rm -f "$DIR/out.exr" "$DIR/out.png"
  done
done
