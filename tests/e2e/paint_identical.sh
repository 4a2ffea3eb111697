#!/bin/sh
# paint_identical.sh: a fully painted view is `terrafarm render` of its scene, pixel for pixel
# (decoded EXR, every channel), whoever paints it and however the quad-tree is cut: forked
# workers with the default granularity; networked workers only, with another root, depth, leaf
# and task size; and a procedural terrain (levels of detail follow the view) after a camera
# move from the API, forked and networked workers together, against a render of the scene the
# paint saved.
. "$(dirname "$0")/lib.sh"
. "$(dirname "$0")/lib_paint.sh"
e2e_init
SIZE=200x120
say "reference render"
render -q -j 2 --size $SIZE --http none -o "$T/ref.exr" || fail "reference: $(cat "$T/last.err")"

say "painted by forked workers"
"$TF_BIN" paint "$SCENE" --size $SIZE -j 2 -o "$T/forked.exr" --until-painted 2>"$T/forked.err" \
    || fail "paint: $(cat "$T/forked.err")"
same_pixels "$T/ref.exr" "$T/forked.exr" "forked, default granularity"

say "painted by networked workers only, another cut of the tree"
# --wait-workers 2: nothing is dealt before both have joined, so the first cannot paint it all
# and leave the second refused at a closed port (a busy machine starts the second late)
start_paint "$T/paint.err" --size $SIZE -j 0 --listen 127.0.0.1:0 --http 127.0.0.1:0 \
    --root 32 --levels 1 --leaf 4 --task-rays 700 -o "$T/networked.exr" --until-painted \
    --wait-workers 2
"$TF_BIN" worker --connect "$PAINT_WORKERS" -j 1 2>"$T/worker1.err" &
w1=$!; e2e_track $w1
wait_status workers 1 60 "the first worker's hello"
sleep 0.5 # a broken gate would deal to it meanwhile
[ "$(paint_status counts.exact_pixels)" = 0 ] || fail "--wait-workers 2 dealt to one worker: $(paint_status counts.exact_pixels) exact pixels"
"$TF_BIN" worker --connect "$PAINT_WORKERS" -j 1 2>"$T/worker2.err" &
w2=$!; e2e_track $w2
wait_exit $PAINT_PID 120
[ $rc -eq 0 ] || fail "paint with networked workers exited $rc: $(tail -3 "$T/paint.err")"
for k in 1 2; do
    eval "wait_exit \$w$k 30"
    [ $rc -eq 0 ] || fail "networked paint worker $k exited $rc: $(tail -3 "$T/worker$k.err")"
done
same_pixels "$T/ref.exr" "$T/networked.exr" "networked, root 32, 1 level, leaf 4, 700 rays"

say "a procedural terrain, the camera moved through the API"
SCENE=$TF_ROOT/scenes/closeup.scene
start_paint "$T/proc.err" --size 120x80 -j 1 --listen 127.0.0.1:0 --http 127.0.0.1:0 \
    -o "$T/proc.exr" --save "$T/proc.scene"
"$TF_BIN" worker --connect "$PAINT_WORKERS" -j 1 2>"$T/worker3.err" &
w3=$!; e2e_track $w3
wait_painted 120
python3 -c 'import json,sys,urllib.request
u = sys.argv[1]
v = json.load(urllib.request.urlopen(u + "api/paint/status"))["view"]
for k in ("position", "look_at"): v["camera"][k][0] += 25
v["camera"]["fov"] = 48
r = urllib.request.Request(u + "api/paint/view", json.dumps(v).encode(), method="POST",
                           headers={"X-Terrafarm-Token": "x"})
sys.exit(0 if urllib.request.urlopen(r).status == 202 else 1)' "$PAINT_URL" || fail "the new view was refused"
wait_status gen 2 60 "view 2"
wait_painted 120
wait_status output_written True 60 "the painted view 2 written"
[ "$(paint_http POST /api/paint/save)" = 200 ] || fail "save failed: $(cat "$T/ctl.out")"
kill -TERM $PAINT_PID; wait_exit $PAINT_PID 30
[ $rc -eq 0 ] || fail "paint exited $rc: $(tail -3 "$T/proc.err")"
wait_exit $w3 30
grep -q 'fov *= *48' "$T/proc.scene" || fail "the saved scene lacks the new view: $(grep fov "$T/proc.scene")"
"$TF_BIN" render "$T/proc.scene" --listen 127.0.0.1:0 -q -j 2 --http none -o "$T/proc_ref.exr" \
    2>"$T/last.err" || fail "render of the saved view: $(cat "$T/last.err")"
same_pixels "$T/proc_ref.exr" "$T/proc.exr" "procedural, view 2, forked and networked"
say "ok"
