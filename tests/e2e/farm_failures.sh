#!/bin/sh
# farm_failures.sh: docs/contract.md section 3, "The tuple space and the farm": a task that fails
# repeatedly on one worker is not dealt to it again; a task that fails everywhere stops the render
# with a clear error, and the rows written so far remain valid for --resume; and many failing
# connections of one client beside a real worker cannot stop a render.  The failing workers are
# tests/tools/failing_worker.py, which joins like any networked worker and answers every task with
# ("failed", ...).
. "$(dirname "$0")/lib.sh"
e2e_init
FAILER="$TF_ROOT/tests/tools/failing_worker.py"
SIZE=240x135
ARGS="--size $SIZE --tasks rows:9"

say "reference render"
render -q -j 1 $ARGS -o "$T/ref.exr" || fail "reference render: $(cat "$T/last.err")"

say "one worker fails everything: after two failures a task is not dealt to it again"
"$TF_BIN" render "$SCENE" -j 0 --listen 127.0.0.1:0 $ARGS -o "$T/a.exr" --stats "$T/a.json" \
    2>"$T/a.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/a.err") || fail "the coordinator printed no port: $(cat "$T/a.err")"
python3 "$FAILER" 127.0.0.1 "$port" >"$T/failer.out" 2>&1 &
failer=$!; e2e_track $failer
i=0   # wait until the failing worker has been excluded from the first task
while ! grep -q 'failed task 0' "$T/a.err"; do
    sleep 0.05; i=$((i + 1)); [ $i -lt 200 ] || fail "no failure reported: $(cat "$T/a.err")"
done
sleep 0.5
kill -0 $coord 2>/dev/null || fail "the coordinator gave up with one worker failing: $(cat "$T/a.err")"
# the failing worker said hello with an escape sequence in its host name: `terrafarm status`
# lists it (it has joined, the render waits for a worker that has not failed) and must print it
# harmlessly
"$TF_BIN" status "$(dashboard_addr "$T/a.err" $coord)" >"$T/status.out" 2>&1 ||
    fail "terrafarm status: $(cat "$T/status.out")"
grep -q 'failing?]0;owned' "$T/status.out" || fail "status does not list the failing worker: $(cat -v "$T/status.out")"
! tr -d '\n' <"$T/status.out" | grep -q '[[:cntrl:]]' ||
    fail "status printed a worker's control bytes: $(cat -v "$T/status.out")"
"$TF_BIN" worker --connect 127.0.0.1:$port -j 1 -q 2>"$T/w.err" &
worker=$!; e2e_track $worker
wait_exit $coord 60
[ $rc -eq 0 ] || fail "render with a failing worker: exit $rc: $(tail -3 "$T/a.err")"
wait_exit $worker 20
[ $rc -eq 0 ] || fail "the good worker exited $rc: $(cat "$T/w.err")"
wait_exit $failer 20
fails=$(jstat task_failures "$T/a.json")
[ "$fails" -ge 2 ] || fail "task_failures is $fails, expected at least 2"
say "$fails failures reported, $(grep -c 'failed task' "$T/a.err") warnings; the good worker did the rest"
same "$T/ref.exr" "$T/a.exr" "render with a failing worker"
# its failure message carries a newline, a forged line and an escape sequence
! grep -q '^terrafarm: wrote /tmp/forged' "$T/a.err" ||
    fail "a worker's failure message forged a line of the coordinator's log: $(grep -n forged "$T/a.err" | head -2)"
! grep -q "$(printf '\033')" "$T/a.err" || fail "a worker's escape sequence reached the coordinator's log"
grep -q 'injected failure?terrafarm: wrote /tmp/forged' "$T/a.err" ||
    fail "the failure message is not shown on its one line: $(grep -m1 'failed task' "$T/a.err")"

say "three workers fail everything: the render stops with one clear line"
"$TF_BIN" render "$SCENE" -j 0 --listen 127.0.0.1:0 $ARGS -o "$T/b.exr" 2>"$T/b.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/b.err") || fail "the coordinator printed no port: $(cat "$T/b.err")"
for n in 1 2 3; do
    python3 "$FAILER" 127.0.0.1 "$port" >"$T/failer$n.out" 2>&1 &
    p=$!; e2e_track $p
done
wait_exit $coord 30
refused $rc || fail "a render whose tasks fail everywhere exited $rc"
grep -q 'failed on 3 different workers' "$T/b.err" || fail "no clear error: $(tail -3 "$T/b.err")"
say "$(grep 'failed on 3 different workers' "$T/b.err")"

say "one real worker and four failing connections of one client: the render still completes"
# Each connection joins as a worker of its own and fails every task it takes; a task has not
# failed everywhere while a connected worker that has not failed it (the real one) is left.
# --wait-workers 5: nothing is dealt before all five have joined, so the real worker is there
# before the first failure (else three failing connections that joined first could fail a task
# before it arrived, and the render would rightly stop).
"$TF_BIN" render "$SCENE" -j 0 --wait-workers 5 --listen 127.0.0.1:0 $ARGS -o "$T/c.exr" 2>"$T/c.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/c.err") || fail "the coordinator printed no port: $(cat "$T/c.err")"
"$TF_BIN" worker --connect 127.0.0.1:$port -j 1 -q 2>"$T/cw.err" &
worker=$!; e2e_track $worker
for n in 1 2 3 4; do
    python3 "$FAILER" 127.0.0.1 "$port" >"$T/sybil$n.out" 2>&1 &
    p=$!; e2e_track $p
done
wait_exit $coord 60
[ $rc -eq 0 ] || fail "four failing connections stopped the render: exit $rc: $(grep -v 'rows ' "$T/c.err" | tail -3)"
same "$T/ref.exr" "$T/c.exr" "render with four failing connections beside a real worker"
say "$(grep -c 'failed task' "$T/c.err") failures reported by the failing connections"

say "the rows written so far remain valid: --resume with real workers completes the image"
render -q -j 2 $ARGS --resume -o "$T/b.exr" || fail "resume after the failure: $(cat "$T/last.err")"
same "$T/ref.exr" "$T/b.exr" "resumed after a task failed everywhere"
echo "farm_failures: repeated failures excluded, failing everywhere stops cleanly, resumable"
