#!/bin/sh
# bench_speedup.sh: `terrafarm bench` works end to end on a tiny render: it runs the renders
# (1 and 2 workers), finds the images identical, prints the table (speedup 1 at the smallest
# count, efficiency = speedup / workers) and writes the CSV, with terrain columns (samples
# evaluated, per worker, evictions) on a procedural scene only; bad flags fail with one line.
# Timings are not checked (they belong to bench/README.md, not to `make test`).
. "$(dirname "$0")/lib.sh"
e2e_init

say "bench --workers 1,2 --repeat 2 on a 96x54 render, CSV and kept images"
"$TF_BIN" bench "$SCENE" --workers 1,2 --repeat 2 --size 96x54 --tasks stamps:16x16 \
    --csv "$T/s.csv" --keep "$T/keep" -q >"$T/out" 2>"$T/err" || fail "bench failed: $(cat "$T/err")"
grep -q '^workers .*speedup .*efficiency' "$T/out" || fail "no table header: $(cat "$T/out")"
grep -q 'bit-identical' "$T/out" || fail "no identity line: $(cat "$T/out")"
[ "$(wc -l <"$T/s.csv")" -eq 3 ] || fail "CSV should have a header and 2 rows: $(cat "$T/s.csv")"
python3 - "$T/s.csv" <<'PY' || fail "CSV content"
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
assert [int(r["workers"]) for r in rows] == [1, 2], rows
assert abs(float(rows[0]["speedup"]) - 1) < 1e-9, rows[0]
for r in rows:
    assert float(r["wall_s"]) > 0 and float(r["rays_per_s"]) > 0, r
    assert abs(float(r["efficiency"]) - float(r["speedup"]) / int(r["workers"])) < 1e-3, r
    assert 0 < float(r["busy_fraction"]) <= 1.05, r
    assert 0 < float(r["external_overhead"]) < 1, r
PY
head -1 "$T/s.csv" | grep -q 'external_overhead$' || fail "a grid scene's CSV gained columns: $(head -1 "$T/s.csv")"
grep -q 'samples' "$T/out" && fail "a grid scene's table gained terrain columns: $(cat "$T/out")"

say "a procedural scene: --terrain-cache and --affinity reach the renders, terrain columns"
# default.scene's fBm, procedural: cheap enough under AddressSanitizer too
sed 's/^size_exp .*/procedural   = yes/' "$TF_ROOT/scenes/default.scene" >"$T/proc.scene"
"$TF_BIN" bench "$T/proc.scene" --workers 1,2 --repeat 1 --size 32x20 \
    --tasks stamps:16x16 --terrain-cache 1M --affinity off --csv "$T/p.csv" --keep "$T/pk" -q \
    >"$T/pout" 2>"$T/perr" || fail "procedural bench failed: $(cat "$T/perr")"
grep -q '^workers .*samples .*per_worker .*evictions' "$T/pout" || fail "no terrain columns: $(cat "$T/pout")"
grep -q 'terrain cache 1M per worker; affinity off' "$T/pout" || fail "no terrain line: $(cat "$T/pout")"
python3 - "$T/p.csv" "$T/pk" <<'PY' || fail "procedural CSV content"
import csv, json, sys
rows = list(csv.DictReader(open(sys.argv[1])))
assert [int(r["workers"]) for r in rows] == [1, 2], rows
for r in rows:
    n = int(r["workers"])
    st = json.load(open("%s/out-%d-0.json" % (sys.argv[2], n)))
    assert st["affinity"] is False, st["affinity"]
    assert int(r["samples_evaluated"]) == st["terrain_samples_evaluated"] > 0, (r, st)
    assert abs(float(r["samples_per_worker"]) - int(r["samples_evaluated"]) / n) < 1, r
    assert int(r["cache_evictions"]) == sum(w["cache_evictions"] for w in st["workers"]), r
PY

say "the kept images are the renders the bench compared"
n=$(ls "$T/keep"/out-*.exr | wc -l)
[ "$n" -eq 4 ] || fail "expected 4 kept images, found $n"
for f in "$T/keep"/out-*.exr; do same "$T/keep/out-1-0.exr" "$f" "$(basename "$f")"; done

say "usage errors: one line, exit 2"
"$TF_BIN" bench "$SCENE" --workers 0,2 2>"$T/e1"; rc=$?
[ $rc -eq 2 ] && [ "$(wc -l <"$T/e1")" -eq 1 ] || fail "--workers 0,2: rc $rc: $(cat "$T/e1")"
"$TF_BIN" bench "$SCENE" --tasks bogus 2>"$T/e2"; rc=$?
[ $rc -eq 2 ] && [ "$(wc -l <"$T/e2")" -eq 1 ] || fail "--tasks bogus: rc $rc: $(cat "$T/e2")"
"$TF_BIN" bench "$SCENE" --affinity maybe 2>"$T/e4"; rc=$?
[ $rc -eq 2 ] && [ "$(wc -l <"$T/e4")" -eq 1 ] || fail "--affinity maybe: rc $rc: $(cat "$T/e4")"
"$TF_BIN" bench "$SCENE" --terrain-cache lots 2>"$T/e5"; rc=$?
[ $rc -eq 2 ] && [ "$(wc -l <"$T/e5")" -eq 1 ] || fail "--terrain-cache lots: rc $rc: $(cat "$T/e5")"
say "a render that fails makes the bench fail with a message"
"$TF_BIN" bench "$T/missing.scene" --workers 1 --repeat 1 -q 2>"$T/e3"; rc=$?
refused $rc && grep -q 'render with 1 worker failed' "$T/e3" || fail "missing scene: rc $rc: $(cat "$T/e3")"
echo "ok"
