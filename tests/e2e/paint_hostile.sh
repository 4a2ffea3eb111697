#!/bin/sh
# paint_hostile.sh: Raypaint against lies.  A paint worker that speaks the protocol and lies
# (tests/tools/paint_liar.py: forged, short, NaN, stale and oversized results) gets every lie
# refused or discarded, and the page's API refuses bad controls with one line (bad JSON, a value
# out of its key's range, a control without its header, a foreign Host, a huge body).  Then an
# honest networked worker paints the view to the end, and the image written is the render's of
# the view's scene: nothing a liar sent was drawn.
. "$(dirname "$0")/lib.sh"
. "$(dirname "$0")/lib_paint.sh"
e2e_init
SIZE=160x90
start_paint "$T/paint.err" --size $SIZE -j 0 --listen 127.0.0.1:0 --paused --http 127.0.0.1:0 \
    -o "$T/painted.exr" --save "$T/view.scene"
[ -n "$PAINT_WORKERS" ] || fail "no networked workers' port logged: $(cat "$T/paint.err")"

say "a lying paint worker"
python3 "$TF_ROOT/tests/tools/paint_liar.py" "$PAINT_WORKERS" "$PAINT_URL" >"$T/liar.out" 2>&1 \
    || fail "$(grep FAIL "$T/liar.out" || tail -3 "$T/liar.out")"
cat "$T/liar.out"

say "bad controls"
control() { paint_http POST "/api/paint/$1" "$2" "${3:-}"; }
expect() { [ "$1" = "$2" ] || fail "$3: HTTP $1, expected $2 ($(cat "$T/ctl.out"))"; say "$3: $1"; }
expect "$(control view '{"camera": ')" 400 "a view that is not JSON"
expect "$(control view '{"camera": {"fov": 400}}')" 400 "a field of view out of range"
grep -q fov "$T/ctl.out" || fail "the range error does not name the key: $(cat "$T/ctl.out")"
expect "$(control view '{"camera": {"position": [1, "a", 3]}}')" 400 "a position that is not numbers"
expect "$(control interest '{"x": -1, "y": 0, "w": 5, "h": 5}')" 400 "a negative area"
expect "$(control view '{}' 'X-Other: 1')" 403 "a control without the token header"
expect "$(control nonsense '{}')" 404 "an unknown control"
head -c 10000 /dev/zero | tr '\0' 'a' >"$T/big"
expect "$(control view @"$T/big")" 413 "a body over 4 KiB"
expect "$(paint_http GET /api/paint/status '' 'Host: evil.example')" 403 "a foreign Host header"
expect "$(paint_http GET '/api/paint/updates?gen=x')" 400 "updates of a view that is not a number"

say "an honest networked worker paints the view to the end"
"$TF_BIN" worker --connect "$PAINT_WORKERS" -j 1 2>"$T/worker.err" &
wpid=$!; e2e_track $wpid
wait_painted 120
wait_status output_written True 60 "the painted view written"
[ "$(paint_http POST /api/paint/save)" = 200 ] || fail "save failed: $(cat "$T/ctl.out")"
kill -TERM $PAINT_PID; wait_exit $PAINT_PID 30
[ $rc -eq 0 ] || fail "terrafarm paint exited $rc: $(tail -3 "$T/paint.err")"
wait_exit $wpid 30
[ $rc -eq 0 ] || fail "the honest worker exited $rc: $(tail -3 "$T/worker.err")"
"$TF_BIN" render "$T/view.scene" --listen 127.0.0.1:0 -q -j 2 --http none -o "$T/ref.exr" \
    2>"$T/last.err" || fail "render of the view: $(cat "$T/last.err")"
same_pixels "$T/ref.exr" "$T/painted.exr" "the painted view after the lies"
say "ok"
