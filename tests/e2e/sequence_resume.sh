#!/bin/sh
# sequence_resume.sh: resuming a sequence (docs/contract.md section 5, frames_skipped).  The
# coordinator of a `render --frames` run is SIGKILLed in the middle of the sequence, twice; each
# `--resume` skips the frames that are complete and verified (they are not rendered again: the
# statistics list them in frames_skipped and not in frames), continues the frame in progress row by
# row, and renders the rest; every frame is byte-identical to the uninterrupted sequence.  A changed
# animation key is refused with one line.
. "$(dirname "$0")/lib.sh"
e2e_init
# the showpiece's path and sun over a smaller terrain (2049^2 takes a while under ASan)
FLY=$T/flyby.scene
sed 's/^size_exp .*/size_exp = 8/' "$TF_ROOT/scenes/flyby.scene" >"$FLY"
SIZE=192x108
H=108
ARGS="--frames 0-9 -j 2 --size $SIZE --tasks stamps:16x16"
N=10

say "reference: the uninterrupted sequence, 10 frames $SIZE"
"$TF_BIN" render "$FLY" $ARGS --listen 127.0.0.1:0 -q -o "$T/ref/f.####.exr" 2>"$T/ref.err" ||
    fail "reference: $(cat "$T/ref.err")"

# kill_when FILE RUN: SIGKILL run RUN's coordinator once FILE exists (a later frame was opened:
# every frame before the previous one is finished).
kill_when() {
    i=0
    while [ ! -e "$1" ]; do
        kill -0 $coord 2>/dev/null || fail "run $2 ended before $1 appeared: $(cat "$T/run$2.err")"
        sleep 0.005; i=$((i + 1)); [ $i -lt 6000 ] || fail "run $2: $1 never appeared"
    done
    kill -KILL $coord; wait $coord 2>/dev/null
    sleep 0.2   # its forked workers follow it (PR_SET_PDEATHSIG)
}

run=0
for at in 0003 0007; do
    run=$((run + 1))
    "$TF_BIN" render "$FLY" $ARGS --resume --listen 127.0.0.1:0 -o "$T/out/f.####.exr" 2>"$T/run$run.err" &
    coord=$!; e2e_track $coord
    kill_when "$T/out/f.$at.exr" $run
    done_now=$(ls "$T/out" | grep -c 'exr$')
    say "kill $run: SIGKILL once frame $at was opened ($done_now frame files on disk)"
done
grep -q 'resuming the sequence .*: [1-9][0-9]* of 10 frames complete on disk (skipped)' "$T/run2.err" ||
    fail "the second run did not skip the frames the first one finished: $(cat "$T/run2.err")"
say "run 2: $(grep -o 'resuming the sequence.*' "$T/run2.err")"

say "final --resume"
"$TF_BIN" render "$FLY" $ARGS --resume --listen 127.0.0.1:0 -o "$T/out/f.####.exr" \
    --stats "$T/final.json" 2>"$T/final.err" || fail "final resume: $(cat "$T/final.err")"
say "$(grep -o 'resuming the sequence.*' "$T/final.err")"
python3 - "$T/final.json" $N $H <<'PY' || fail "statistics of the final run"
import json, sys
st, n, h = json.load(open(sys.argv[1])), int(sys.argv[2]), int(sys.argv[3])
skipped = st["frames_skipped"]
rendered = [f["frame"] for f in st["frames"]]
assert len(skipped) >= 5, "only %s were complete after the second kill at frame 7" % skipped
assert sorted(skipped + rendered) == list(range(n)), (skipped, rendered)
assert not set(skipped) & set(rendered), "a complete frame was rendered again"
for f in st["frames"]:
    assert f["rows_resumed"] + f["rows_rendered"] == h, f
assert st["rows_rendered"] == sum(f["rows_rendered"] for f in st["frames"])
print("-- complete frames skipped: %s; rendered: %s; rows resumed in frame %d: %d" %
      (skipped, rendered, st["frames"][0]["frame"], st["frames"][0]["rows_resumed"]))
PY
for k in 0 1 2 3 4 5 6 7 8 9; do same "$T/ref/f.000$k.exr" "$T/out/f.000$k.exr" "frame $k after 2 kills"; done
left=$(ls "$T/out" | grep -v '^f\.[0-9]*\.\(exr\|png\)$' || true)
[ -z "$left" ] || fail "stray files beside the frames: $left"

say "a resume of a changed animation is refused"
sed 's/^camera = 30  position 400 250 230/camera = 30  position 400 250 231/' "$FLY" >"$T/changed.scene"
cmp -s "$FLY" "$T/changed.scene" && fail "the test scene was not changed"
rm "$T/out/f.0009.exr"   # one frame to render, so the others are looked at
"$TF_BIN" render "$T/changed.scene" $ARGS --resume --listen 127.0.0.1:0 -o "$T/out/f.####.exr" 2>"$T/changed.err"; rc=$?
refused $rc || fail "a resume of a changed animation exited $rc"
grep -q 'cannot resume: the scene changed' "$T/changed.err" || fail "no clear refusal: $(cat "$T/changed.err")"
[ "$(grep -c . "$T/changed.err")" -eq 1 ] || fail "more than one line: $(cat "$T/changed.err")"
say "$(cat "$T/changed.err")"
same "$T/ref/f.0000.exr" "$T/out/f.0000.exr" "frame 0 after the refused resume"
echo "sequence_resume: 2 kills, complete frames skipped, every frame identical"
