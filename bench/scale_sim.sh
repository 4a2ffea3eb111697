#!/bin/bash
# scale_sim.sh: the coordinator with 16..1024 simulated workers (docs/contract.md section 6).
#
# For each worker count W, modelled task cost and watermark it starts a real coordinator
# (`terrafarm render -j 0`, networked workers only, output in /dev/shm) and one process of W
# simulated workers (`terrafarm worker --simulate MODEL -j W`), each a thread with its own
# connection that sleeps its task's modelled cost (from the cost map MODEL) and puts back a
# result of real content: the packed OpenEXR chunks of a real render (--payloads), recorded once
# at the start (RECORD_SIZE of SCENE with 8x8 stamps, -j 2), so the coordinator receives, checks
# and writes what a real farm sends.  The coordinator's CPU (render path) and the simulator's
# CPU are reported apart.  Tasks are 8x8-pixel stamps; the image is sized so every worker gets
# exactly TPW tasks (as near 16:9 as the divisors of W * TPW allow), and --pixel-us is chosen so
# the average task costs TASK_MS.  MODEL "flat" gives every task the same cost (exactly
# TASK_MS); a measured map (the default) gives the scene's spread: default.cost's sky rows cost
# 0.04 of the average, so at "100 ms" a third of the tasks take 4 ms.
# Watermark = F * W + one band of tasks, for each F; F "auto" leaves it to the coordinator (its
# auto watermark, with --wait-workers W so that it counts every worker from the start), and the
# CSV gets the watermark it chose.
#
# Prints one CSV line per run (and writes them to $OUT/scale_sim.csv), then plots modelled
# efficiency against workers for each task size (best watermark) to $OUT/scale_sim.svg.
#
# usage: bench/scale_sim.sh [MODEL|flat]   (default: bench/default.cost)
#        bench/scale_sim.sh --smoke [MODEL|flat]   (2 workers, 2 tasks each of 1 ms, payloads of
#        a 64x32 render, CSV and plot in a temp directory: for tests/e2e/bench_smoke.sh)
# env:   WORKERS="16 64 256 1024" TASK_MS="1 10 30 100" WM="1 2 4" (or auto) TPW=16 OUT=bench/results PIN=0
#        RENDER_ARGS="--affinity off" (more options for the coordinator)
set -eu
cd "$(dirname "$0")/.."
TF=${TF:-bin/terrafarm}
SMOKE_OUT=
if [ "${1:-}" = --smoke ]; then
  shift
  SMOKE_OUT=$(mktemp -d "${TMPDIR:-/tmp}/tf-scale-smoke.XXXXXX")
  WORKERS=2 TASK_MS=1 WM=1 TPW=2 RECORD_SIZE=64x32 OUT=$SMOKE_OUT
fi
MODEL=${1:-bench/default.cost}
WORKERS=${WORKERS:-"16 64 256 1024"}
TASK_MS=${TASK_MS:-"1 10 30 100"}
WM=${WM:-"1 2 4"}
TPW=${TPW:-16}
OUT=${OUT:-bench/results}
# PIN=1: the coordinator on CPU 0 and the simulator on CPU 1 (taskset), so the simulator's
# thousand threads cannot delay the coordinator on a 2-core machine
if [ "${PIN:-0}" = 1 ]; then COORD_PIN="taskset -c 0"; SIM_PIN="taskset -c 1"; else COORD_PIN=""; SIM_PIN=""; fi
SCENE=${SCENE:-scenes/default.scene}
RECORD_SIZE=${RECORD_SIZE:-960x544}
mkdir -p "$OUT"
CSV="$OUT/scale_sim.csv"
EXR=/dev/shm/terrafarm-scale-sim-$$.exr
LOG=$(mktemp)
REC=/dev/shm/terrafarm-scale-payloads-$$.exr
FLAT_MODEL=
trap 'rm -f ${FLAT_MODEL:+"$FLAT_MODEL"} "$EXR" "${EXR%.exr}.png" "$LOG" "$LOG.stats" "$LOG.time" "$LOG.coord" "$LOG.dat" "$REC" "${REC%.exr}.png"; rm -rf ${SMOKE_OUT:+"$SMOKE_OUT"}' EXIT

[ -x "$TF" ] || { echo "scale_sim.sh: build first (make)" >&2; exit 1; }
if [ "$MODEL" = flat ]; then
  MODEL=$(mktemp --suffix=.cost)
  FLAT_MODEL=$MODEL
  printf 'terrafarm-cost-map 1 1 1 1 1 1000.0\n1.0000\n' >"$MODEL"
fi
[ -r "$MODEL" ] || { echo "scale_sim.sh: no cost map $MODEL (terrafarm bench SCENE --cost-map $MODEL)" >&2; exit 1; }

echo "recording the payloads: $SCENE at $RECORD_SIZE, stamps:8x8" >&2
"$TF" render "$SCENE" -j 2 --size "$RECORD_SIZE" --tasks stamps:8x8 -o "$REC" --overwrite -q
echo "recorded $(wc -c <"$REC") bytes for $RECORD_SIZE pixels" >&2
grep -m1 'model name' /proc/cpuinfo | sed 's/.*: /cpu: /' >&2
echo "load before: $(cut -d' ' -f1-3 /proc/loadavg)" >&2

echo "workers,task_ms,watermark,tasks,width,height,wall_s,modelled_s,efficiency,ops_per_s,take_mean_ms,take_p50_ms,take_p99_ms,redealt,duplicated,coord_wall_s,coord_render_cpu_s,sim_cpu_s,out_bytes,load1,bound_efficiency,cost_map" >"$CSV"
for ms in $TASK_MS; do
  for w in $WORKERS; do
    n=$((w * TPW))
    # columns: the divisor of n nearest a 16:9 image, so that there are exactly n tasks (a
    # partial last band would add a wave of a few tasks that the workers finish alone)
    cols=$(awk -v n="$n" 'BEGIN { t = sqrt(n * 16 / 9); b = 1
                                   for (c = 1; c <= n; c++) if (n % c == 0 && (c - t) ^ 2 < (b - t) ^ 2) b = c
                                   print b }')
    bands=$((n / cols))
    width=$((cols * 8)); height=$((bands * 8))
    pixel_us=$(awk -v ms="$ms" 'BEGIN { printf "%.4f", ms * 1000 / 64 }')
    for f in $WM; do
      if [ "$f" = auto ]; then wm=auto wm_args="--wait-workers $w"
      else wm=$((f * w + cols)) wm_args="--watermark $wm"; fi
      # port 0: the system's choice, which no other process holds (a port picked here could be
      # some connection's local port); the coordinator names it once it listens
      $COORD_PIN "$TF" render "$SCENE" -j 0 --listen 127.0.0.1:0 --http 127.0.0.1:0 \
        --size ${width}x$height --tasks stamps:8x8 $wm_args -o "$EXR" --overwrite \
        --lease-timeout 600000 --stats "$LOG.stats" ${RENDER_ARGS:-} 2>"$LOG.coord" &
      coord=$!
      # wait until it listens (a refused connect is not retried by the client), however long
      # a busy machine takes: its log's first line names the port, or it has exited
      PORT=
      until PORT=$(sed -n 's/.*workers may join at 127\.0\.0\.1:\([0-9]*\).*/\1/p' "$LOG.coord") &&
            [ -n "$PORT" ]; do
        kill -0 $coord 2>/dev/null ||
          { cat "$LOG.coord" >&2; echo "scale_sim.sh: the coordinator did not start" >&2; exit 1; }
        sleep 0.05
      done
      /usr/bin/time -f '%U %S' -o "$LOG.time" \
        $SIM_PIN "$TF" worker --connect 127.0.0.1:$PORT --simulate "$MODEL" -j $w --pixel-us "$pixel_us" \
        --payloads "$REC" -q --timeout 30000 >"$LOG"
      wait $coord || { cat "$LOG.coord" >&2; echo "scale_sim.sh: the coordinator failed" >&2; exit 1; }
      sim_cpu=$(awk '{ printf "%.2f", $1 + $2 }' "$LOG.time")
      line=$(cat "$LOG")
      get() { echo "$line" | tr ' ' '\n' | sed -n "s/^$1=//p"; }
      js() { sed -n "s/^ *\"$1\": *\([0-9.]*\).*/\1/p" "$LOG.stats" | head -1; }
      [ "$wm" != auto ] || wm=$(js watermark)
      row="$w,$ms,$wm,$(get tasks),$width,$height,$(get wall_s),$(get modelled_s),$(get efficiency),$(get ops_per_s),$(get take_mean_ms),$(get take_p50_ms),$(get take_p99_ms),$(js tasks_redealt),$(js tasks_duplicated),$(js wall_s),$(js coordinator_render_cpu_s),$sim_cpu,$(wc -c <"$EXR"),$(cut -d' ' -f1 /proc/loadavg),$(get bound_efficiency),${FLAT_MODEL:+flat}${FLAT_MODEL:-$(basename "$MODEL")}"
      echo "$row" | tee -a "$CSV"
    done
  done
done

if command -v gnuplot >/dev/null 2>&1; then
  # best watermark per (task size, workers): the plot's data, a temporary file beside the log
  awk -F, 'NR > 1 { k = $2 " " $1; if (!(k in best) || $9 > best[k]) best[k] = $9 }
           END { for (k in best) print k, best[k] }' "$CSV" | sort -n -k1,1 -k2,2 >"$LOG.dat"
  plot=""
  for ms in $TASK_MS; do
    plot="$plot${plot:+, }'$LOG.dat' using (\$1 == $ms ? \$2 : 1/0):3 with linespoints lw 2 title '$ms ms tasks'"
  done
  gnuplot <<EOF
set terminal svg size 800,500 dynamic
set output '$OUT/scale_sim.svg'
set title 'terrafarm coordinator: modelled efficiency with simulated workers (best watermark)'
set xlabel 'simulated workers'
set ylabel 'modelled parallel efficiency'
set logscale x 2
set yrange [0:1.05]
set key right bottom
set grid
plot 0.95 title '95% target' with lines dt 2 lc rgb 'gray', $plot
EOF
  echo "plot: $OUT/scale_sim.svg"
fi
