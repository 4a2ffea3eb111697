#!/bin/sh
# erosion_film.sh: an erosion film ([animation] erosion_steps, coordinator/erosion/erosion_film.h).
# Frame k shows the terrain after k * 100 steps: frames differ as the erosion proceeds; the
# eroder continues each frame from the previous one's checkpoint, and that is exact: frame 3
# is pixel for pixel a still of the same scene eroded 300 steps in one go (no cache); a
# --resume of the finished film renders nothing again; a damaged checkpoint is refused (the
# erosion starts over) and the frame is the same.
. "$(dirname "$0")/lib.sh"
e2e_init
SCENE=$T/film.scene
sed -e 's/^size_exp .*/size_exp = 7/' "$TF_ROOT/scenes/default.scene" >"$SCENE"
cat >>"$SCENE" <<'EOF'

[erosion]
fluvial_steps = 1
rain = 0.3
rain_interval = 30
creep = 0.01

[animation]
frames = 4
erosion_steps = 100
EOF
film() { "$TF_BIN" render "$SCENE" --listen 127.0.0.1:0 -j 2 --size 120x68 "$@" 2>"$T/film.err"; }

say "a film of 4 frames, 100 steps apart"
film -o "$T/f/film.####.exr" || fail "film: $(cat "$T/film.err")"
for k in 0 1 2 3; do [ -f "$T/f/film.000$k.exr" ] || fail "no frame $k: $(cat "$T/film.err")"; done
grep -q 'continuing from the checkpoint after 200 steps' "$T/film.err" ||
    fail "the eroder did not continue from a checkpoint: $(cat "$T/film.err")"
n=$(grep -c 'erosion: reused' "$T/film.err")
[ "$n" -eq 3 ] || fail "frames 1-3 should read their terrain from the cache, $n did"
cmp -s "$T/f/film.0001.exr" "$T/f/film.0003.exr" && fail "frames 1 and 3 are the same: no erosion between"
say "frames differ; frames 1-3 read the eroder's terrain"

say "frame 3 against a still eroded 300 steps at once"
sed -e 's/^fluvial_steps = 1/fluvial_steps = 300/' -e '/^\[animation\]/,$d' "$SCENE" >"$T/still.scene"
TF_EROSION_CACHE=off "$TF_BIN" render "$T/still.scene" --listen 127.0.0.1:0 -j 2 --size 120x68 \
    -o "$T/s/still.exr" 2>"$T/still.err" || fail "still: $(cat "$T/still.err")"
same_pixels "$T/s/still.exr" "$T/f/film.0003.exr" "frame 3 (continued from checkpoints)"

say "--resume of the finished film renders nothing again"
film -o "$T/f/film.####.exr" --resume || fail "resume: $(cat "$T/film.err")"
n=$(grep -c 'already complete' "$T/film.err")
[ "$n" -eq 4 ] || fail "--resume: $n of 4 frames found complete: $(cat "$T/film.err")"

say "a damaged checkpoint is not used"
for c in "$T"/f/.terrafarm-cache/*.state; do printf 'X' | dd of="$c" bs=1 seek=100 conv=notrunc 2>/dev/null; done
rm -f "$T"/f/.terrafarm-cache/*.eroded
film -o "$T/f/again.####.exr" --frame 3 || fail "film --frame 3: $(cat "$T/film.err")"
grep -q 'not a checkpoint of this erosion, or damaged; not used' "$T/film.err" ||
    fail "a damaged checkpoint was not refused: $(cat "$T/film.err")"
same_pixels "$T/s/still.exr" "$T/f/again.0003.exr" "frame 3 after damaged checkpoints"

"$TF_BIN" render "$SCENE" -o "$T/f/bad.exr" 2>"$T/bad.err"; rc=$?
[ $rc -eq 2 ] && grep -q "needs a run of '#'" "$T/bad.err" || fail "no frame number: exit $rc, $(cat "$T/bad.err")"
