#!/bin/sh
# farm_lies.sh: results whose chunks lie are refused (farmproto.h "THE RESULT
# FORMAT").  tests/tools/lying_worker.py joins like any networked worker and answers tasks with
# results that lie: another task's chunk coordinates, unpacked sizes that cannot belong to the
# task, packed sizes that do not add up, a chunk too few, a preview share of the wrong size, and
# a perfect structure over bytes that do not decode, chunks stored raw full of NaN and infinity,
# and a count of 2^62 rays.  No option is needed: a networked worker's pixels are always
# checked (coordinator/render/resultcheck.h).  Each lie is refused with a line naming the peer and
# what is wrong, counted in results_refused, the task is dealt again, and nothing of it reaches
# the file: a real worker then finishes the render, the image is byte-identical to a clean one,
# and the rays in the statistics are the real ones.  Scanline (rows:5 at 960x135) and tiled (stamps:40x27 at 240x135).
. "$(dirname "$0")/lib.sh"
e2e_init
LIAR="$TF_ROOT/tests/tools/lying_worker.py"
LIES=16

# A rows:5 result at 960 wide decodes to 75 KiB and is checked on the checker thread; a
# stamps:40x27 result to 17 KiB, checked on the event loop's thread (resultcheck.c,
# INLINE_CHECK_BYTES): both paths meet the lies.  Each has more tasks than the liar has lies, so
# no task excludes the liar (two failures each) before it has told them all.
for case in rows:5@960x135 stamps:40x27@240x135; do
    tasks=${case%@*}; SIZE=${case#*@}
    t=$(echo $tasks | tr ':' '_')
    render -q -j 1 --size $SIZE --tasks $tasks -o "$T/ref_$t.exr" || fail "reference: $(cat "$T/last.err")"
    say "$tasks: a lying worker first, then a real one"
    "$TF_BIN" render "$SCENE" -j 0 --listen 127.0.0.1:0 --size $SIZE --tasks $tasks \
        -o "$T/$t.exr" --stats "$T/$t.json" 2>"$T/$t.err" &
    coord=$!; e2e_track $coord
    port=$(e2e_port "$T/$t.err") || fail "the coordinator printed no port: $(cat "$T/$t.err")"
    timeout 120 python3 "$LIAR" 127.0.0.1 "$port" $LIES >"$T/liar.out" 2>&1
    [ $? -eq 0 ] || fail "the lying worker failed: $(cat "$T/liar.out")"
    [ "$(grep -c '^lie ' "$T/liar.out")" -eq $LIES ] || fail "the liar told $(grep -c '^lie ' "$T/liar.out") lies: $(cat "$T/liar.out")"
    "$TF_BIN" worker --connect 127.0.0.1:$port -j 1 -q 2>"$T/w.err" &
    worker=$!; e2e_track $worker
    wait_exit $coord 60
    [ $rc -eq 0 ] || fail "$tasks: render with a lying worker exited $rc: $(tail -3 "$T/$t.err")"
    wait_exit $worker 20
    refused=$(jstat results_refused "$T/$t.json")
    [ "$refused" -eq $LIES ] || fail "$tasks: results_refused $refused, the liar told $LIES lies: $(grep refused "$T/$t.err")"
    for why in "is at (" "unpacked bytes" "add up" "chunks, the task has" "preview of" "does not decode" \
               "is not finite at pixel" "primary rays, the task has room for"; do
        grep "refused: " "$T/$t.err" | grep -q "$why" || fail "$tasks: no refusal saying '$why': $(grep refused "$T/$t.err")"
    done
    grep "refused: " "$T/$t.err" | grep -q "from 127.0.0.1:" || fail "$tasks: refusals do not name the peer"
    grep "refused: " "$T/$t.err" | grep "not finite" | grep -q "(127.0.0.1:" || fail "$tasks: pixel refusals do not name the peer"
    rays=$(jstat rays_total "$T/$t.json")
    [ "$rays" -gt 0 ] && [ "$rays" -lt 1000000000 ] || fail "$tasks: rays_total $rays: a lie reached the statistics"
    say "$tasks: $refused results refused, e.g. $(grep -m1 'refused: ' "$T/$t.err")"
    same "$T/ref_$t.exr" "$T/$t.exr" "$tasks after $LIES lies"
done
echo "farm_lies: every lie refused, images identical"
