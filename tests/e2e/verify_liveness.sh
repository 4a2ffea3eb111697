#!/bin/sh
# verify_liveness.sh: under --verify, a check copy taken by a worker it excludes is dealt again
# (coordinator/render/supervisor.c, invariant S9).  tests/tools/check_copy_thief.py joins as two
# workers: one that takes nothing, and a thief that answers every task, the check copies of its
# own results included (they exclude it).  With --verify 1 and a watermark of 2 nothing else can
# be dealt, so the thief's next task is a copy it already answered only if the coordinator dealt
# it again; before the fix it was dropped and the render hung with the write front at row 0.
# Then the thief leaves, two real workers finish the render (its zero pixels are caught by the
# checks and excluded), and the image must equal a clean render.
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=160x48
TASKS=rows:8
THIEF="$TF_ROOT/tests/tools/check_copy_thief.py"

render -q -j 1 --size $SIZE --tasks $TASKS -o "$T/ref.exr" || fail "reference render: $(cat "$T/last.err")"

"$TF_BIN" render "$SCENE" -j 0 --size $SIZE --tasks $TASKS --verify 1 --watermark 2 \
    --lease-timeout 10m --listen 127.0.0.1:0 -o "$T/out.exr" --stats "$T/out.json" 2>"$T/coord.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/coord.err") || fail "coordinator printed no port: $(cat "$T/coord.err")"
python3 "$THIEF" 127.0.0.1 "$port" >"$T/thief.out" 2>&1
rc=$?
[ $rc -eq 0 ] || fail "the thief's check copy was not dealt again (exit $rc): $(cat "$T/thief.out")"
say "$(tail -1 "$T/thief.out")"

"$TF_BIN" worker --connect 127.0.0.1:$port -j 1 -q 2>"$T/a.err" &
a=$!; e2e_track $a
"$TF_BIN" worker --connect 127.0.0.1:$port -j 1 -q 2>"$T/b.err" &
b=$!; e2e_track $b
wait_exit $coord 120
[ $rc -eq 0 ] || fail "render after the thief exited $rc: $(tail -5 "$T/coord.err")"
wait_exit $a 30
wait_exit $b 30
same "$T/ref.exr" "$T/out.exr" "--verify 1 after a check-copy thief"
[ "$(jstat workers_excluded "$T/out.json")" -ge 1 ] || fail "the thief was not excluded: $(grep -i 'lied\|exclu' "$T/coord.err")"
echo "verify_liveness: stolen check copies dealt again; image identical"
