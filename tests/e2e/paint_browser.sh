#!/bin/sh
# paint_browser.sh: Raypaint in a real browser (headless Chromium over the DevTools protocol,
# cdp_paint.py).  A --paused `terrafarm paint` is opened, an area clicked, and the painting run
# in steps: the clicked area comes first, the picture sharpens, and once painted the canvas is
# the render's PNG preview byte for byte.  A step is one deal of tasks, not what the workers
# finish while the checker looks: paint's forked workers are frozen (SIGSTOP) while it resumes
# and deals, and thawed, paused, only to answer that deal, so the steps are the same on a
# machine of any speed.  Then the page's camera control makes a new view:
# painted, its canvas equals the render of the scene the page's Save wrote.  Screenshot:
# $TF_PAINT_SHOT (default in the test's temp dir).
. "$(dirname "$0")/lib.sh"
. "$(dirname "$0")/lib_paint.sh"
e2e_init
CHROMIUM=$(command -v chromium || command -v chromium-browser) || skip "chromium is not installed (make deps)"
SIZE=320x180
render_reference $SIZE

say "terrafarm paint, paused, watched by Chromium"
# tasks of ~1000 rays: a 320x180 picture in dozens of tasks, so the order of dealing shows
start_paint "$T/paint.err" --size $SIZE -j 2 --paused --http 127.0.0.1:0 --save "$T/saved.scene" \
    --task-rays 1000
TMPDIR=$(browser_tmp) python3 "$(dirname "$0")/cdp_paint.py" "$CHROMIUM" "$PAINT_URL" "$T/ref.png" "$T" "$PAINT_PID" \
    >"$T/cdp.out" 2>&1
crc=$?
cat "$T/cdp.out"
no_browser_leftovers
[ $crc -eq 77 ] && skip "$(tail -1 "$T/cdp.out")"
[ $crc -eq 0 ] || fail "Raypaint in Chromium: $(grep FAIL "$T/cdp.out" | head -3)"
[ -n "${TF_PAINT_SHOT:-}" ] && cp "$T/paint.png" "$TF_PAINT_SHOT"
kill -TERM $PAINT_PID
wait_exit $PAINT_PID 30
[ $rc -eq 0 ] || fail "terrafarm paint exited $rc on SIGTERM: $(tail -3 "$T/paint.err")"

say "the second view equals a render of the scene the page saved"
[ -s "$T/saved.scene" ] || fail "the page's Save wrote no scene"
cmp -s "$T/saved.scene" "$SCENE" && fail "the saved scene is the original: the camera move was lost"
"$TF_BIN" render "$T/saved.scene" --listen 127.0.0.1:0 -q -j 2 --http none -o "$T/ref2.exr" \
    2>"$T/last.err" || fail "render of the saved scene: $(cat "$T/last.err")"
python3 -c 'import sys
sys.path.insert(0, sys.argv[1])
from cdp_lib import read_png_rgb
w, h, ref = read_png_rgb(sys.argv[2])
got = open(sys.argv[3], "rb").read()
sys.exit(0 if got == ref else 1)' "$(dirname "$0")" "$T/ref2.png" "$T/canvas2.rgb" \
    || fail "the painted second view differs from the render of the saved scene"
say "ok"
