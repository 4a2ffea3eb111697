#!/bin/sh
# simulate_farm.sh: the synthetic-worker path end to end, tiny: `bench --cost-map` writes a
# cost map; a real coordinator (-j 0) finishes a render served only by 8 simulated workers
# (`worker --simulate`), every task accounted for, the workers reported with the "simulated"
# backend; a malformed cost map fails with one line.  No timing is checked.
. "$(dirname "$0")/lib.sh"
e2e_init

say "cost map of a 96x54 render on an 8x6 grid"
"$TF_BIN" bench "$SCENE" --cost-map "$T/m.cost" --grid 8x6 --size 96x54 >"$T/cm.out" 2>"$T/cm.err" ||
    fail "cost map: $(cat "$T/cm.err")"
head -1 "$T/m.cost" | grep -q '^terrafarm-cost-map 1 8 6 96 54 ' || fail "header: $(head -1 "$T/m.cost")"
[ "$(sed 1d "$T/m.cost" | wc -l)" -eq 6 ] || fail "expected 6 rows of cells"
python3 - "$T/m.cost" <<'PY' || fail "densities must average 1 over the image"
import sys
lines = open(sys.argv[1]).read().split("\n")
gw, gh, w, h = (int(v) for v in lines[0].split()[2:6])
d = [[float(v) for v in l.split()] for l in lines[1:1 + gh]]
edge = lambda i, n, size: i * size // n
tot = sum(d[j][i] * (edge(i + 1, gw, w) - edge(i, gw, w)) * (edge(j + 1, gh, h) - edge(j, gh, h))
          for j in range(gh) for i in range(gw))
assert abs(tot / (w * h) - 1) < 1e-3, tot / (w * h)
PY

say "a 64x48 render (48 stamps of 8x8) served by 8 simulated workers"
# --wait-workers 8: all eight join before any task is dealt (the first could otherwise serve
# the tiny render alone before the last connected)
"$TF_BIN" render "$SCENE" -j 0 --wait-workers 8 --listen 127.0.0.1:0 --size 64x48 --tasks stamps:8x8 \
    -o "$T/sim.exr" --stats "$T/sim.json" 2>"$T/coord.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/coord.err") || fail "coordinator printed no port: $(cat "$T/coord.err")"
"$TF_BIN" worker --connect 127.0.0.1:$port --simulate "$T/m.cost" -j 8 --pixel-us 20 -q \
    >"$T/sim.out" 2>"$T/sim.err" || fail "simulated workers: $(cat "$T/sim.err")"
wait_exit $coord 20
[ $rc -eq 0 ] || fail "coordinator exit $rc: $(cat "$T/coord.err")"
grep -q '^simulated workers=8 ' "$T/sim.out" || fail "report: $(cat "$T/sim.out")"
tasks=$(sed -n 's/.* tasks=\([0-9]*\) .*/\1/p' "$T/sim.out")
[ "$tasks" -ge 48 ] || fail "simulated workers delivered $tasks results, expected >= 48"
[ "$(jstat tasks_total "$T/sim.json")" -eq 48 ] || fail "tasks_total"
[ "$(jstat rows_rendered "$T/sim.json")" -eq 48 ] || fail "rows_rendered"
python3 - "$T/sim.json" <<'PY' || fail "worker statistics"
import json, sys
s = json.load(open(sys.argv[1]))
ws = s["workers"]
assert len(ws) == 8 and all(w["backend"] == "simulated" for w in ws), ws
assert sum(w["tasks"] for w in ws) >= 48, ws
assert sum(w["busy_s"] for w in ws) > 0, ws
PY

grep -q 'without --payloads' "$T/sim.err" || fail "no warning about black payloads: $(cat "$T/sim.err")"

say "--payloads: the packed chunks of a real 32x24 render stand in for the simulated results"
render -q -j 1 --size 32x24 --tasks stamps:8x8 -o "$T/rec.exr" || fail "recording: $(cat "$T/last.err")"
"$TF_BIN" render "$SCENE" -j 0 --wait-workers 8 --listen 127.0.0.1:0 --size 64x48 --tasks stamps:8x8 --verify-chunks \
    -o "$T/sim2.exr" --stats "$T/sim2.json" 2>"$T/coord3.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/coord3.err") || fail "coordinator printed no port: $(cat "$T/coord3.err")"
"$TF_BIN" worker --connect 127.0.0.1:$port --simulate "$T/m.cost" -j 8 --pixel-us 20 -q \
    --payloads "$T/rec.exr" >"$T/sim2.out" 2>"$T/sim2.err" || fail "simulated workers: $(cat "$T/sim2.err")"
wait_exit $coord 20
[ $rc -eq 0 ] || fail "coordinator exit $rc: $(cat "$T/coord3.err")"
[ "$(jstat results_refused "$T/sim2.json")" -eq 0 ] || fail "recorded chunks were refused: $(grep refused "$T/coord3.err")"
"$EXRCMP" "$T/sim2.exr" "$T/sim2.exr" >/dev/null || fail "the simulated render does not decode"
rec=$(wc -c <"$T/rec.exr") sim=$(wc -c <"$T/sim2.exr")
[ "$sim" -gt $((3 * rec)) ] || fail "4x the recording's area in $sim bytes, the recording has $rec: not its chunks"
say "recording $rec bytes, the 4x larger simulated render $sim bytes; chunks decode (--verify-chunks)"
"$TF_BIN" render "$SCENE" -j 0 --listen 127.0.0.1:0 --size 64x48 --tasks rows:4 \
    -o "$T/sim3.exr" 2>"$T/coord4.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/coord4.err") || fail "coordinator printed no port"
"$TF_BIN" worker --connect 127.0.0.1:$port --simulate "$T/m.cost" -j 2 --payloads "$T/rec.exr" \
    2>"$T/fit.err"; rc=$?
[ $rc -eq 1 ] && [ "$(wc -l <"$T/fit.err")" -eq 1 ] && grep -q 'cannot stand in' "$T/fit.err" ||
    fail "a recording of tiles for a scanline render: rc $rc: $(cat "$T/fit.err")"
say "refused: $(cat "$T/fit.err")"
kill $coord 2>/dev/null

say "a malformed cost map: one line, exit 1"
printf 'terrafarm-cost-map 1 2 2 4 4 1\n1 1\n1 x\n' >"$T/bad.cost"
"$TF_BIN" render "$SCENE" -j 0 --listen 127.0.0.1:0 --size 16x16 -o "$T/bad.exr" 2>"$T/coord2.err" &
coord2=$!; e2e_track $coord2
port=$(e2e_port "$T/coord2.err") || fail "coordinator printed no port"
"$TF_BIN" worker --connect 127.0.0.1:$port --simulate "$T/bad.cost" -j 2 2>"$T/bad.err"; rc=$?
[ $rc -eq 1 ] && [ "$(wc -l <"$T/bad.err")" -eq 1 ] && grep -q 'cell 3' "$T/bad.err" ||
    fail "bad cost map: rc $rc: $(cat "$T/bad.err")"
echo "ok"
