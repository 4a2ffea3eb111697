#!/bin/sh
# sequence_identical.sh: determinism of sequences (docs/contract.md section 2, --frames).  Frame k
# of one `render --frames` run is byte-identical to `render --frame k` alone (the same task shape,
# so the same file layout) for several k, worker counts and frame steps, with forked and with
# networked workers (a networked worker builds the terrain once for the whole sequence), and holds
# bit-identical decoded pixels with other task shapes (rows:K write scanline files, stamps tiled
# ones).  The frames overlap: frame k+1's first task is dealt before frame k's last row is on disk
# (stats: frames[].start_s / done_s), and each frame's preview is written beside it.
. "$(dirname "$0")/lib.sh"
e2e_init
# the showpiece's path and sun over a smaller terrain (2049^2 takes a while under ASan)
FLY=$T/flyby.scene
sed 's/^size_exp .*/size_exp = 8/' "$TF_ROOT/scenes/flyby.scene" >"$FLY"
SIZE=96x54
seq_render() { "$TF_BIN" render "$FLY" --listen 127.0.0.1:0 --size $SIZE -q "$@" 2>"$T/last.err"; }

say "one run: --frames 0-5, -j 2, stamps:16x16"
seq_render --frames 0-5 -j 2 --tasks stamps:16x16 -o "$T/a/f.####.exr" --stats "$T/a.json" ||
    fail "sequence render: $(cat "$T/last.err")"
for k in 0 1 2 3 4 5; do
    [ -s "$T/a/f.000$k.exr" ] || fail "frame $k: no $T/a/f.000$k.exr"
    [ -s "$T/a/f.000$k.png" ] || fail "frame $k: no preview"
done
cmp -s "$T/a/f.0000.exr" "$T/a/f.0005.exr" && fail "frames 0 and 5 are identical: the camera did not move"
python3 - "$T/a.json" <<'PY' || fail "statistics of the sequence"
import json, sys
st = json.load(open(sys.argv[1]))
fr = st["frames"]
assert [f["frame"] for f in fr] == [0, 1, 2, 3, 4, 5], fr
assert st["frames_skipped"] == [], st["frames_skipped"]
assert all(f["rays_total"] > 0 and f["wall_s"] > 0 and f["rows_rendered"] == 54 for f in fr), fr
assert sum(f["rays_total"] for f in fr) == st["rays_total"], "per-frame rays do not add up"
# under one watermark the next frame is dealt while the previous one is still being finished
early = [k for k in range(5) if fr[k + 1]["start_s"] <= fr[k]["done_s"]]
assert len(early) == 5, "frames that started only after the previous one was done: %s" % fr
print("-- frames overlap: every frame's first task was dealt before the previous frame was on disk")
PY

for spec in "0 -j 1" "3 -j 3 --watermark 7" "5 -j 2"; do
    set -- $spec; k=$1; shift
    seq_render --frame $k "$@" --tasks stamps:16x16 -o "$T/single$k.exr" || fail "--frame $k: $(cat "$T/last.err")"
    same "$T/a/f.000$k.exr" "$T/single$k.exr" "--frame $k alone ($*)"
done
for spec in "2 -j 1 --tasks rows:5" "4 -j 2 --tasks stamps:37x23"; do
    set -- $spec; k=$1; shift
    seq_render --frame $k "$@" -o "$T/other$k.exr" || fail "--frame $k: $(cat "$T/last.err")"
    same_pixels "$T/a/f.000$k.exr" "$T/other$k.exr" "--frame $k alone ($*)"
done

say "a stepped range: --frames 1-5:2 -j 1, and with another task shape"
seq_render --frames 1-5:2 -j 1 --tasks stamps:16x16 -o "$T/b/f.##.exr" || fail "stepped: $(cat "$T/last.err")"
[ ! -e "$T/b/f.02.exr" ] || fail "--frames 1-5:2 rendered frame 2"
for k in 1 3 5; do same "$T/a/f.000$k.exr" "$T/b/f.0$k.exr" "frame $k of --frames 1-5:2"; done
seq_render --frames 1-5:2 -j 2 --tasks rows:7 -o "$T/c/f.##.exr" || fail "stepped rows:7: $(cat "$T/last.err")"
for k in 1 3 5; do same_pixels "$T/a/f.000$k.exr" "$T/c/f.0$k.exr" "frame $k of --frames 1-5:2, rows:7"; done

say "networked workers only: -j 0 and a terrafarm worker --connect -j 2"
# --wait-workers 2: the worker's second process may connect a moment after the first, which
# could otherwise render the whole sequence alone (the second then finds no coordinator).
"$TF_BIN" render "$FLY" --listen 127.0.0.1:0 --size $SIZE --frames 0-5 -j 0 --wait-workers 2 --tasks stamps:16x16 \
    -o "$T/n/f.####.exr" --stats "$T/n.json" 2>"$T/coord.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/coord.err") || fail "coordinator printed no port: $(cat "$T/coord.err")"
"$TF_BIN" worker --connect 127.0.0.1:$port -j 2 2>"$T/worker.err" &
wk=$!; e2e_track $wk
wait_exit $coord 60
[ $rc -eq 0 ] || fail "networked sequence exited $rc: $(cat "$T/coord.err")"
wait_exit $wk 20
[ $rc -eq 0 ] || fail "networked worker exited $rc: $(cat "$T/worker.err")"
builds=$(grep -c 'building the height field' "$T/worker.err")
[ "$builds" -eq 1 ] || fail "the networked worker built the terrain $builds times for one sequence"
say "the networked worker built the terrain once for 6 frames"
for k in 0 1 2 3 4 5; do same "$T/a/f.000$k.exr" "$T/n/f.000$k.exr" "networked frame $k"; done

say "refusals, one line each"
seq_render --frames 0-5 -j 1 -o "$T/nohash.exr"; rc=$?
# exit 2, a refusal: not a crash (139) in the cleanup of outputs never made
[ $rc -eq 2 ] && grep -q "needs a run of '#'" "$T/last.err" || fail "a sequence into one file name: exit $rc: $(cat "$T/last.err")"
"$TF_BIN" render "$SCENE" --frame 2 -j 1 -o "$T/still.exr" 2>"$T/last.err"; rc=$?
refused $rc && grep -q 'no \[animation\] section' "$T/last.err" || fail "--frame on a still: exit $rc: $(cat "$T/last.err")"
seq_render --frames 90-96 -j 1 -o "$T/c/f.####.exr"; rc=$?
refused $rc && grep -q 'has frames 0..95' "$T/last.err" || fail "a frame past the end: exit $rc: $(cat "$T/last.err")"
seq_render --frames 5-2 -j 1 -o "$T/c/f.####.exr"; rc=$?
[ $rc -eq 2 ] && grep -q 'last frame is before the first' "$T/last.err" || fail "--frames 5-2: exit $rc: $(cat "$T/last.err")"
say "a camera path that dips below the terrain is a warning naming the frame and the key's line"
cat >"$T/under.scene" <<'SCENE'
[image]
width = 32
height = 18
[terrain]
generator = fbm
seed = 1
size_exp = 6
height_scale = 150
[animation]
frames = 10
camera = 0 position 500 -100 300 look_at 500 500 0
camera = 9 position 500 500 -200 look_at 500 900 -300
SCENE
"$TF_BIN" render "$T/under.scene" -j 1 --listen 127.0.0.1:0 -o "$T/u/f.####.exr" 2>"$T/under.err" ||
    fail "a camera under the terrain is not an error: $(cat "$T/under.err")"
grep -q "under.scene:11: camera: at frame [0-9]* .*the camera is below the terrain" "$T/under.err" ||
    fail "no warning: $(cat "$T/under.err")"
say "$(grep 'below the terrain' "$T/under.err")"
echo "sequence_identical: every frame identical to its render alone, forked and networked"
