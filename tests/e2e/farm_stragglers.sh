#!/bin/sh
# farm_stragglers.sh: stragglers (docs/contract.md section 3): when nothing else is left to deal,
# idle workers may get a duplicate of the oldest outstanding task; the first result wins, later ones
# are dropped.  A worker is frozen (SIGSTOP) while it holds a task, with a lease far longer than the
# render, so only straggler duplication can finish the image; the other worker must get a copy of
# the frozen task, and the image must be identical.  No race with the machine's speed: that worker
# starts stopped and runs 20 ms at a time until the dashboard shows it holding a task; frozen
# then, it cannot finish the task (nor the image) before the second worker joins.
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=320x180
ARGS="--size $SIZE --tasks rows:6"

say "reference render"
render -q -j 1 $ARGS -o "$T/ref.exr" || fail "reference render: $(cat "$T/last.err")"

rm -f "$T/s.exr" "$T/s.json"
"$TF_BIN" render "$SCENE" -j 0 --listen 127.0.0.1:0 --http 127.0.0.1:0 $ARGS --lease-timeout 600000 \
    -o "$T/s.exr" --stats "$T/s.json" -v 2>"$T/s.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/s.err") || fail "the coordinator printed no port: $(cat "$T/s.err")"
addr=$(dashboard_addr "$T/s.err" $coord)
# the first worker starts stopped (its shell stops itself before it execs the worker) and runs
# in slices until the coordinator shows it holding a task
start_stopped "$T/a.err" "$TF_BIN" worker --connect 127.0.0.1:$port -j 1 -q
slow=$!; e2e_track $slow
i=0
until [ -n "$(busy_workers "$addr")" ]; do
    kill -0 $coord 2>/dev/null || fail "the render ended before the first worker was frozen: $(tail -3 "$T/s.err")"
    run_process_slice $slow
    i=$((i + 1)); [ $i -lt 1200 ] || fail "the first worker never held a task: $(cat "$T/a.err")"
done
"$TF_BIN" worker --connect 127.0.0.1:$port -j 1 -q 2>"$T/b.err" &
fast=$!; e2e_track $fast
wait_exit $coord 60
[ $rc -eq 0 ] || fail "render with a frozen worker: exit $rc: $(tail -3 "$T/s.err")"
dup=$(jstat tasks_duplicated "$T/s.json")
kill -CONT $slow
wait_exit $fast 20
wait_exit $slow 20   # it finds its coordinator gone when it wakes: non-zero is expected
[ "$dup" -ge 1 ] || fail "the frozen worker held a task, but tasks_duplicated is $dup"
say "tasks_duplicated = $dup; $(grep -c 'straggler' "$T/s.err") straggler line(s) in the log"
same "$T/ref.exr" "$T/s.exr" "render finished by a duplicate of the frozen worker's task"
echo "farm_stragglers: a frozen worker's task was duplicated and the image is identical"
