#!/bin/sh
# procedural_identical.sh: procedural terrain ([terrain] procedural = yes) on the farm.  The level
# of detail depends on the camera only, so the decoded pixels are bit-identical whatever the task
# shape (rows:1 scanline, stamps:16x16 and stamps:37x23 tiled), the worker count (-j 1, 2, 4), a
# mix of forked and networked workers, the per-worker tile cache budget (--terrain-cache 1M, which
# thrashes, to 512M), corner rows in packets or one ray at a time (TF_TRACE_PACKETS=0), and a
# coordinator SIGKILLed mid-render then resumed (with another budget).
# The statistics: per worker samples_evaluated / cache_hits / cache_evictions, their sum is
# terrain_samples_evaluated; a tiny cache evicts and evaluates more.  Refusals, each exit 2 and
# one line: --backend opencl, --terrain-cache 12Q, detail = METRES on a noise generator.
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=160x100   # the view needs more tiles than the 1M budget holds
H=100
SCENE=$T/proc.scene   # render() and make_partial() use $SCENE
# the default scene, evaluated procedurally, the camera tilted down so that terrain fills the
# frame (rows that show terrain reach the disk early: a partial file holds some)
sed -e 's/^size_exp .*/procedural   = yes/' -e 's/^look_at .*/look_at  = 500, 400, -150/' \
    "$TF_ROOT/scenes/default.scene" >"$SCENE"
grep -q '^procedural *= *yes' "$SCENE" || fail "could not make a procedural scene"
TINY=1M BIG=512M   # 1M: 145 tiles (the floor is 128, tilecache.h)

# stats FILE.json [big|tiny|any]: the procedural statistics are sane; sets st_samples (the total)
# and st_evictions (summed over the workers).
# Every worker with a task evaluated samples and found tiles in its cache, the per-worker sum is
# the total; big (the default): no worker evicted a tile; tiny: tiles were evicted (used with one
# worker, -j 1: what it renders, and so what it evicts, does not depend on dealing).
stats() {
    python3 - "$@" >"$T/stats.out" 2>"$T/stats.err" <<'PY' || fail "statistics $1: $(cat "$T/stats.err")"
import json, sys
d = json.load(open(sys.argv[1])); mode = sys.argv[2] if len(sys.argv) > 2 else "big"
tot = d["terrain_samples_evaluated"]
ws = d["workers"]
def bad(m):
    print(m, file=sys.stderr); sys.exit(1)
if not ws: bad("no workers")
for w in ws:
    for k in ("samples_evaluated", "cache_hits", "cache_evictions"):
        if not isinstance(w.get(k), int) or w[k] < 0: bad("worker %s: %s = %r" % (w["id"], k, w.get(k)))
    if w["tasks"] > 0 and (w["samples_evaluated"] <= 0 or w["cache_hits"] <= 0):
        bad("worker %s rendered %d tasks but evaluated %d samples, %d hits" % (w["id"], w["tasks"], w["samples_evaluated"], w["cache_hits"]))
    if mode == "big" and w["cache_evictions"] != 0: bad("worker %s: %d evictions with a large cache" % (w["id"], w["cache_evictions"]))
s = sum(w["samples_evaluated"] for w in ws)
if not isinstance(tot, int) or tot <= 0 or s != tot:
    bad("terrain_samples_evaluated %r, but the workers' sum is %d" % (tot, s))
ev = sum(w["cache_evictions"] for w in ws)
if mode == "tiny" and ev <= 0: bad("no eviction with a tiny cache")
print(tot, ev)
PY
    read st_samples st_evictions <"$T/stats.out"
}

say "reference: procedural default scene, $SIZE, -j 1, rows:1, --terrain-cache $BIG"
render -q -j 1 --size $SIZE --tasks rows:1 --terrain-cache $BIG -o "$T/ref.exr" --stats "$T/ref.json" ||
    fail "reference render: $(cat "$T/last.err")"
stats "$T/ref.json"; ref_samples=$st_samples
say "reference: $ref_samples samples evaluated, no eviction"

for j in 2 4; do
    render -q -j $j --size $SIZE --tasks rows:1 --terrain-cache $BIG -o "$T/rows_j$j.exr" --stats "$T/rows_j$j.json" ||
        fail "-j $j: $(cat "$T/last.err")"
    stats "$T/rows_j$j.json"
    same "$T/ref.exr" "$T/rows_j$j.exr" "rows:1, -j $j"
done
for tasks in stamps:16x16 stamps:37x23; do
    t=$(echo $tasks | tr ':' '_')
    for j in 1 2 4; do
        render -q -j $j --size $SIZE --tasks $tasks --terrain-cache $BIG -o "$T/${t}_j$j.exr" --stats "$T/$t.json" ||
            fail "--tasks $tasks -j $j: $(cat "$T/last.err")"
        stats "$T/$t.json"
        same_pixels "$T/ref.exr" "$T/${t}_j$j.exr" "$tasks, -j $j"
    done
done

say "tiny cache: --terrain-cache $TINY"
render -q -j 1 --size $SIZE --tasks rows:1 --terrain-cache $TINY -o "$T/tiny.exr" --stats "$T/tiny.json" ||
    fail "tiny cache: $(cat "$T/last.err")"
stats "$T/tiny.json" tiny; tiny_samples=$st_samples tiny_ev=$st_evictions
same "$T/ref.exr" "$T/tiny.exr" "rows:1, -j 1, --terrain-cache $TINY"
[ "$tiny_samples" -gt "$ref_samples" ] ||
    fail "--terrain-cache $TINY evaluated $tiny_samples samples, not more than $ref_samples with $BIG"
say "tiny cache: $tiny_ev evictions, $tiny_samples samples evaluated (vs $ref_samples)"
render -q -j 2 --size $SIZE --tasks stamps:37x23 --terrain-cache $TINY -o "$T/tiny_st.exr" --stats "$T/tiny_st.json" ||
    fail "tiny cache, stamps: $(cat "$T/last.err")"
stats "$T/tiny_st.json" any   # evictions here depend on what each worker is dealt
same "$T/stamps_37x23_j2.exr" "$T/tiny_st.exr" "stamps:37x23, -j 2, --terrain-cache $TINY vs $BIG"

# corner rows go through the quad-tree in packets unless TF_TRACE_PACKETS=0: the same bits
say "packets off: TF_TRACE_PACKETS=0"
(export TF_TRACE_PACKETS=0; render -q -j 1 --size $SIZE --tasks stamps:37x23 --terrain-cache $BIG \
    -o "$T/single.exr") || fail "packets off: $(cat "$T/last.err")"
same_pixels "$T/ref.exr" "$T/single.exr" "TF_TRACE_PACKETS=0"

# forked (tiny cache) plus networked (large cache); --wait-workers 2 so both render
say "forked plus networked: -j 1 --terrain-cache $TINY and a terrafarm worker -j 1 --terrain-cache $BIG"
: >"$T/coord.err"
"$TF_BIN" render "$SCENE" -j 1 --wait-workers 2 --size $SIZE --tasks rows:1 --terrain-cache $TINY \
    --listen 127.0.0.1:0 -o "$T/mixed.exr" --stats "$T/mixed.json" 2>"$T/coord.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/coord.err") || fail "coordinator printed no port: $(cat "$T/coord.err")"
"$TF_BIN" worker --connect 127.0.0.1:$port -j 1 -q --terrain-cache $BIG 2>"$T/worker.err" &
wk=$!; e2e_track $wk
wait_exit $coord 120
[ $rc -eq 0 ] || fail "mixed render exited $rc: $(cat "$T/coord.err")"
wait_exit $wk 20
[ $rc -eq 0 ] || fail "networked worker exited $rc: $(cat "$T/worker.err")"
same "$T/ref.exr" "$T/mixed.exr" "forked + networked"
python3 - "$T/mixed.json" 2>"$T/stats.err" <<'PY' || fail "mixed statistics: $(cat "$T/stats.err")"
import json, sys
d = json.load(open(sys.argv[1]))
ws = {w["kind"]: w for w in d["workers"]}
f, n = ws.get("forked"), ws.get("networked")
if not f or not n or len(d["workers"]) != 2: sys.exit("want one forked and one networked worker: %r" % d["workers"])
for w in (f, n):
    if w["tasks"] < 1 or w["samples_evaluated"] <= 0: sys.exit("%s worker: %d tasks, %d samples" % (w["kind"], w["tasks"], w["samples_evaluated"]))
if n["cache_evictions"] != 0: sys.exit("the networked worker (512M) evicted %d tiles" % n["cache_evictions"])
if f["samples_evaluated"] + n["samples_evaluated"] != d["terrain_samples_evaluated"]: sys.exit("sum != terrain_samples_evaluated")
PY
say "both workers rendered tasks and evaluated samples; none evicted with $BIG"

# SIGKILL mid-render, then --resume.  At 320x200 one worker takes seconds, a row at a time;
# once a few rows are on disk its worker is frozen, so the render cannot end before the kill
# however loaded the machine.  The resume uses another budget.
KSIZE=320x200 H=200
say "SIGKILL the coordinator mid-render ($KSIZE, --terrain-cache $TINY), --resume with $BIG"
render -q -j 2 --size $KSIZE --tasks rows:1 --terrain-cache $BIG -o "$T/kref.exr" ||
    fail "reference at $KSIZE: $(cat "$T/last.err")"
mkdir "$T/out"; OUT=$T/out/img.exr
full=$(wc -c <"$T/kref.exr")
"$TF_BIN" render "$SCENE" --listen 127.0.0.1:0 -j 1 --size $KSIZE --tasks rows:1 --terrain-cache $TINY -o "$OUT" 2>"$T/partial.err" &
pk=$!; e2e_track $pk
i=0
while [ "$(wc -c 2>/dev/null <"$OUT" || echo 0)" -lt $((full / 30)) ]; do
    kill -0 $pk 2>/dev/null || fail "the render to interrupt ended first: $(cat "$T/partial.err")"
    sleep 0.01; i=$((i + 1)); [ $i -lt 12000 ] || fail "$OUT never reached $((full / 30)) bytes"
done
freeze_workers $pk
kill -KILL $pk; wait $pk 2>/dev/null
PROBE_ARGS="--size $KSIZE --tasks rows:1"
on_disk=$(rows_on_disk "$OUT")
case "$on_disk" in ''|complete|0) fail "after the kill: '$on_disk' rows on disk, want a partial file" ;; esac
[ "$on_disk" -lt $H ] || fail "after the kill: $on_disk rows on disk"
"$TF_BIN" render "$SCENE" --listen 127.0.0.1:0 -j 2 --size $KSIZE --tasks rows:1 --terrain-cache $BIG --resume \
    -o "$OUT" --stats "$T/resume.json" 2>"$T/resume.err" || fail "--resume: $(cat "$T/resume.err")"
resumed=$(jstat rows_resumed "$T/resume.json")
[ "$resumed" -eq "$on_disk" ] || fail "rows_resumed $resumed, but $on_disk rows were on disk"
stats "$T/resume.json"
same "$T/kref.exr" "$OUT" "killed with $on_disk of $H rows on disk, resumed"

say "refusals"
"$TF_BIN" render "$SCENE" --backend opencl --size 8x8 --http none --listen 127.0.0.1:0 -o "$T/cl.exr" 2>"$T/cl.err"; rc=$?
[ $rc -eq 2 ] && [ "$(wc -l <"$T/cl.err")" -eq 1 ] && grep -q 'OpenCL.*procedural' "$T/cl.err" ||
    fail "--backend opencl on a procedural scene: exit $rc, $(cat "$T/cl.err")"
[ ! -e "$T/cl.exr" ] || fail "--backend opencl refused, yet wrote $T/cl.exr"
say "$(cat "$T/cl.err")"
"$TF_BIN" render "$SCENE" --terrain-cache 12Q --size 8x8 --http none --listen 127.0.0.1:0 -o "$T/q.exr" 2>"$T/q.err"; rc=$?
[ $rc -eq 2 ] && [ "$(wc -l <"$T/q.err")" -eq 1 ] && grep -q "terrain-cache '12Q'" "$T/q.err" ||
    fail "--terrain-cache 12Q: exit $rc, $(cat "$T/q.err")"
"$TF_BIN" worker --terrain-cache 12Q --connect 127.0.0.1:1 2>"$T/q.err"; rc=$?
[ $rc -eq 2 ] && [ "$(wc -l <"$T/q.err")" -eq 1 ] && grep -q "terrain-cache '12Q'" "$T/q.err" ||
    fail "worker --terrain-cache 12Q: exit $rc, $(cat "$T/q.err")"
say "$(cat "$T/q.err")"
sed 's/^procedural .*/&\ndetail = 3/' "$SCENE" >"$T/det.scene"
line=$(grep -n '^detail' "$T/det.scene" | cut -d: -f1)
"$TF_BIN" render "$T/det.scene" --size 8x8 --http none --listen 127.0.0.1:0 -o "$T/det.exr" 2>"$T/det.err"; rc=$?
[ $rc -eq 2 ] && [ "$(wc -l <"$T/det.err")" -eq 1 ] && grep -q "det.scene:$line: detail" "$T/det.err" ||
    fail "detail = 3 on fbm: exit $rc, $(cat "$T/det.err") (want det.scene:$line)"
say "$(cat "$T/det.err")"
echo "procedural_identical: all images identical; cache statistics sane; refusals one line"
