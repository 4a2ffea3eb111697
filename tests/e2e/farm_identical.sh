#!/bin/sh
# farm_identical.sh: the decomposition invariant end to end (docs/contract.md section 4): the same
# scene and size give a byte-identical EXR whatever the worker count (1, 2, 4 forked), the task
# shape (rows:1, rows:7, stamps:16x16, stamps:37x23) and the mix of forked and networked
# workers.  Also: the finished file is an ordinary OpenEXR file (exrheader reads it).
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=240x135

say "reference: -j 1, default tasks, $SIZE"
render -q -j 1 --size $SIZE -o "$T/ref.exr" || fail "reference render: $(cat "$T/last.err")"
[ -s "$T/ref.exr" ] || fail "no reference image"

for j in 2 4; do
    render -q -j $j --size $SIZE -o "$T/j$j.exr" || fail "-j $j: $(cat "$T/last.err")"
    same "$T/ref.exr" "$T/j$j.exr" "-j $j"
done

for tasks in rows:1 rows:7 stamps:16x16 stamps:37x23; do
    f="$T/$(echo $tasks | tr ':' '_').exr"
    render -q -j 2 --size $SIZE --tasks $tasks -o "$f" || fail "--tasks $tasks: $(cat "$T/last.err")"
    same "$T/ref.exr" "$f" "--tasks $tasks"
done

say "forked plus networked: -j 1 and a terrafarm worker --connect -j 1"
"$TF_BIN" render "$SCENE" -j 1 --size $SIZE --tasks rows:1 --listen 127.0.0.1:0 \
    -o "$T/mixed.exr" --stats "$T/mixed.json" 2>"$T/coord.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/coord.err") || fail "coordinator printed no port: $(cat "$T/coord.err")"
"$TF_BIN" worker --connect 127.0.0.1:$port -j 1 -q 2>"$T/worker.err" &
wk=$!; e2e_track $wk
wait_exit $coord 60
[ $rc -eq 0 ] || fail "mixed render exited $rc: $(cat "$T/coord.err")"
wait_exit $wk 20
[ $rc -eq 0 ] || fail "networked worker exited $rc: $(cat "$T/worker.err")"
same "$T/ref.exr" "$T/mixed.exr" "forked + networked"
kinds=$(python3 -c 'import json,sys; print(" ".join(sorted(set(w["kind"] for w in json.load(open(sys.argv[1]))["workers"]))))' "$T/mixed.json")
say "worker kinds in the statistics: $kinds"
case "$kinds" in *forked*networked*) ;; *) fail "expected both forked and networked workers, got '$kinds'" ;; esac
nettasks=$(python3 -c 'import json,sys; print(sum(w["tasks"] for w in json.load(open(sys.argv[1]))["workers"] if w["kind"]=="networked"))' "$T/mixed.json")
say "tasks rendered by the networked worker: $nettasks"

if command -v exrheader >/dev/null 2>&1; then
    exrheader "$T/ref.exr" >"$T/hdr.txt" 2>&1 || fail "exrheader cannot read the output: $(tail -3 "$T/hdr.txt")"
    grep -q 'dataWindow.*(0 0) - (239 134)' "$T/hdr.txt" || fail "unexpected data window: $(grep dataWindow "$T/hdr.txt")"
    say "exrheader reads the finished file (data window 240x135)"
fi
echo "farm_identical: all images identical"
