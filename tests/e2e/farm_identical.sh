#!/bin/sh
# farm_identical.sh: the decomposition invariant end to end (docs/contract.md section 4).  The same
# scene and size give bit-identical decoded pixels whatever the worker count (1, 2, 4 forked),
# the task shape (rows:1, rows:7 -> a scanline EXR; stamps:16x16, stamps:37x23 with partial
# edge tiles, the default stamps -> a tiled EXR) and the mix of forked and networked workers.
# Files of the same layout are byte-identical (cmp: the workers' chunks do not depend on who
# encoded them); files of different layouts are compared decoded (tests/tools/exrcmp.c).
# Also: both kinds are ordinary OpenEXR files (exrheader and exrinfo read them); a bad
# --wait-workers is one line and exit 2.
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=240x135

say "reference: -j 1, rows:1 (a scanline file), $SIZE"
render -q -j 1 --size $SIZE --tasks rows:1 -o "$T/ref.exr" || fail "reference render: $(cat "$T/last.err")"
[ -s "$T/ref.exr" ] || fail "no reference image"

for j in 2 4; do
    render -q -j $j --size $SIZE --tasks rows:7 -o "$T/rows7_j$j.exr" || fail "-j $j rows:7: $(cat "$T/last.err")"
    same "$T/ref.exr" "$T/rows7_j$j.exr" "scanline, rows:7, -j $j"
done

for tasks in stamps:16x16 stamps:37x23; do
    t=$(echo $tasks | tr ':' '_')
    for j in 1 2 4; do
        render -q -j $j --size $SIZE --tasks $tasks -o "$T/${t}_j$j.exr" || fail "--tasks $tasks -j $j: $(cat "$T/last.err")"
    done
    same_pixels "$T/ref.exr" "$T/${t}_j1.exr" "tiled, $tasks, -j 1 vs the scanline file"
    same "$T/${t}_j1.exr" "$T/${t}_j2.exr" "tiled, $tasks, -j 2 vs -j 1"
    same "$T/${t}_j1.exr" "$T/${t}_j4.exr" "tiled, $tasks, -j 4 vs -j 1"
done
render -q -j 2 --size $SIZE -o "$T/default.exr" || fail "default tasks: $(cat "$T/last.err")"
same_pixels "$T/ref.exr" "$T/default.exr" "default stamps, -j 2"

# mixed TASKS REF: -j 1 forked plus a terrafarm worker --connect -j 1, compared with REF (cmp).
# --wait-workers 2: no task is dealt before both have joined (else the forked worker may render
# everything before the networked one connects, and that one finds no coordinator); a worker
# joins already asking for a task, so the first two tasks go one to each: both render.
mixed() {
    say "forked plus networked, --tasks $1: -j 1 and a terrafarm worker --connect -j 1"
    : >"$T/coord.err"   # empty now: e2e_port must not read the previous call's port
    "$TF_BIN" render "$SCENE" -j 1 --wait-workers 2 --size $SIZE --tasks $1 --listen 127.0.0.1:0 \
        -o "$T/mixed.exr" --overwrite --stats "$T/mixed.json" 2>"$T/coord.err" &
    coord=$!; e2e_track $coord
    port=$(e2e_port "$T/coord.err") || fail "coordinator printed no port: $(cat "$T/coord.err")"
    "$TF_BIN" worker --connect 127.0.0.1:$port -j 1 -q 2>"$T/worker.err" &
    wk=$!; e2e_track $wk
    wait_exit $coord 60
    [ $rc -eq 0 ] || fail "mixed render exited $rc: $(cat "$T/coord.err")"
    wait_exit $wk 20
    [ $rc -eq 0 ] || fail "networked worker exited $rc: $(cat "$T/worker.err")"
    same "$2" "$T/mixed.exr" "forked + networked, $1"
    kinds=$(python3 -c 'import json,sys; print(" ".join(sorted(set(w["kind"] for w in json.load(open(sys.argv[1]))["workers"]))))' "$T/mixed.json")
    say "worker kinds in the statistics: $kinds"
    case "$kinds" in *forked*networked*) ;; *) fail "expected both forked and networked workers, got '$kinds'" ;; esac
    nettasks=$(python3 -c 'import json,sys; print(sum(w["tasks"] for w in json.load(open(sys.argv[1]))["workers"] if w["kind"]=="networked"))' "$T/mixed.json")
    say "tasks rendered by the networked worker: $nettasks"
    [ "$nettasks" -ge 1 ] || fail "the networked worker rendered no task: not a mixed render"
}
mixed rows:1 "$T/ref.exr"
mixed stamps:37x23 "$T/stamps_37x23_j1.exr"
for bad in -1 x2 ''; do
    "$TF_BIN" render "$SCENE" --wait-workers "$bad" -o "$T/bad.exr" 2>"$T/bad.err"; rc=$?
    [ $rc -eq 2 ] && [ "$(wc -l <"$T/bad.err")" -eq 1 ] ||
        fail "--wait-workers '$bad': exit $rc, $(cat "$T/bad.err")"
done
say "a bad --wait-workers: $(cat "$T/bad.err")"

command -v exrheader >/dev/null 2>&1 || skip "exrheader not installed (package openexr)"
for f in ref stamps_37x23_j1; do
    exrheader "$T/$f.exr" >"$T/hdr.txt" 2>&1 || fail "exrheader cannot read $f.exr: $(tail -3 "$T/hdr.txt")"
    # exrinfo 3.1.5 exits with a random status after printing a tiled file (it does so for
    # exrmaketiled's output too): judge it by what it prints
    if command -v exrinfo >/dev/null 2>&1; then
        exrinfo "$T/$f.exr" >"$T/info.txt" 2>&1
        grep -q 'ERROR' "$T/info.txt" && fail "exrinfo cannot read $f.exr: $(cat "$T/info.txt")"
        grep -q "channels: 6 channels" "$T/info.txt" || fail "exrinfo on $f.exr: $(cat "$T/info.txt")"
    fi
done
exrinfo "$T/stamps_37x23_j1.exr" 2>&1 | grep -q 'tiles: size 37 x 23' || fail "exrinfo sees no 37x23 tiles"
exrheader "$T/ref.exr" | grep -q 'dataWindow.*(0 0) - (239 134)' || fail "unexpected data window"
exrheader "$T/stamps_37x23_j1.exr" | grep -q 'tile size 37 by 23 pixels' || fail "the stamps file is not tiled 37x23: $(exrheader "$T/stamps_37x23_j1.exr")"
say "exrheader and exrinfo read the scanline and the tiled file (tiles 37x23)"
echo "farm_identical: all images identical"
