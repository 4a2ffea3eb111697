#!/bin/sh
# sequence_movie.sh: output a person can watch (docs/contract.md section 2, --movie): `render
# --frames ... --movie FILE.mp4|webm` writes a PNG preview per frame and assembles them with ffmpeg
# into a video at the scene's frame rate (ffprobe reads its frame count, rate and size back); a
# second run with every frame complete renders nothing and still makes the movie; a bad movie name
# is refused.
. "$(dirname "$0")/lib.sh"
e2e_init
command -v ffmpeg >/dev/null 2>&1 || skip "ffmpeg is not installed (make deps installs it)"
command -v ffprobe >/dev/null 2>&1 || skip "ffprobe is not installed (it comes with ffmpeg)"
# the showpiece's path and sun over a smaller terrain (2049^2 takes a while under ASan)
FLY=$T/flyby.scene
sed 's/^size_exp .*/size_exp = 8/' "$TF_ROOT/scenes/flyby.scene" >"$FLY"
ARGS="--frames 0-11 -j 2 --size 96x54 --listen 127.0.0.1:0"

# probe FILE: "frames rate width height" of the first video stream
probe() {
    ffprobe -v error -select_streams v:0 -count_frames \
        -show_entries stream=nb_read_frames,r_frame_rate,width,height -of csv=p=0 "$1" |
        awk -F, '{ print $4, $3, $1, $2 }'
}

say "12 frames and an MP4 of their previews"
"$TF_BIN" render "$FLY" $ARGS -o "$T/f.####.exr" --movie "$T/fly.mp4" 2>"$T/a.err" ||
    fail "render --movie: $(cat "$T/a.err")"
[ -s "$T/fly.mp4" ] || fail "no movie"
got=$(probe "$T/fly.mp4")
say "fly.mp4: frames, rate, width, height = $got"
[ "$got" = "12 24/1 96 54" ] || fail "fly.mp4 is '$got', expected 12 frames at 24/1, 96x54"
[ ! -e "$T/fly.mp4.tmp.mp4" ] || fail "the temporary movie was left behind"

say "every frame complete: nothing rendered, the movie (webm) made from the previews"
"$TF_BIN" render "$FLY" $ARGS --resume -o "$T/f.####.exr" --movie "$T/fly.webm" 2>"$T/b.err" ||
    fail "render --resume --movie: $(cat "$T/b.err")"
grep -q 'already complete: nothing to render' "$T/b.err" || fail "frames rendered again: $(cat "$T/b.err")"
got=$(probe "$T/fly.webm")
say "fly.webm: $got"
case "$got" in "12 24/1 96 54") ;; *) fail "fly.webm is '$got'" ;; esac

"$TF_BIN" render "$FLY" $ARGS -o "$T/g.####.exr" --movie "$T/fly.gif" 2>"$T/c.err"; rc=$?
[ $rc -eq 2 ] && grep -q 'expected a .mp4 or .webm' "$T/c.err" || fail "--movie fly.gif: exit $rc: $(cat "$T/c.err")"
[ ! -e "$T/g.0000.exr" ] || fail "a refused --movie still rendered"
"$TF_BIN" render "$SCENE" -j 1 --size 32x18 -o "$T/s.exr" --movie "$T/s.mp4" 2>"$T/d.err"; rc=$?
refused $rc && grep -q 'is a still' "$T/d.err" || fail "--movie of a still: exit $rc: $(cat "$T/d.err")"
echo "sequence_movie: previews assembled at the scene's frame rate"
