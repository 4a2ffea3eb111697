#!/bin/sh
# farm_faults.sh: a task is never lost (docs/contract.md section 3, Faults).
#  1. SIGKILL a forked worker mid-render: its task returns to the space and is dealt again
#     (tasks_redealt >= 1 when it held one), the coordinator carries on, the image is identical.
#  2. SIGSTOP a networked worker while it holds a task (--lease-timeout 2000): the coordinator
#     drops the silent worker, re-deals its task, and the render completes identically.
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=480x270

say "reference: -j 2, $SIZE"
render -q -j 2 --size $SIZE --tasks rows:8 -o "$T/ref.exr" || fail "reference render: $(cat "$T/last.err")"
full=$(wc -c <"$T/ref.exr")


say "1. kill -KILL one forked worker mid-render (rows:8, -j 2)"
# One attempt; returns 2 if the victim happened to be between tasks (it had delivered a result
# and not yet taken the next one): then the re-deal is not exercised, so try again.
kill_attempt() {
    rm -f "$T/kill.exr"
    "$TF_BIN" render "$SCENE" -v -j 2 --size $SIZE --tasks rows:8 --watermark 64 --listen 127.0.0.1:0 \
        -o "$T/kill.exr" --stats "$T/kill.json" 2>"$T/kill.err" &
    coord=$!; e2e_track $coord
    e2e_port "$T/kill.err" >/dev/null || fail "coordinator printed no port: $(cat "$T/kill.err")"
    # Into the terrain rows (a quarter of the file: the sky rows at the top render faster than
    # a round trip, so there a worker is as often between tasks as inside one).
    i=0
    while [ "$(wc -c 2>/dev/null <"$T/kill.exr" || echo 0)" -lt $((full / 4)) ]; do
        kill -0 $coord 2>/dev/null || fail "the render ended before the kill"
        sleep 0.01; i=$((i + 1)); [ $i -lt 3000 ] || fail "the render made no progress"
    done
    victim=$(pgrep -P $coord | head -1)
    [ -n "$victim" ] || fail "no forked worker found under coordinator $coord"
    kill -KILL "$victim"
    say "killed forked worker pid $victim"
    wait_exit $coord 60
    [ $rc -eq 0 ] || fail "render with a killed worker exited $rc: $(tail -5 "$T/kill.err")"
    # It looks at its children every 200 ms: a render that ended sooner never saw the death.
    if ! grep -q "killed by signal 9" "$T/kill.err"; then
        say "the render ended before the coordinator looked at its children: again"
        return 2
    fi
    grep -q 'left holding task' "$T/kill.err" && return 0
    say "the victim held no task at the instant it died: again"
    return 2
}
for attempt in 1 2 3 4; do kill_attempt && break; done
grep -q "killed by signal 9" "$T/kill.err" || fail "coordinator never noticed a killed worker"
grep -q 'left holding task' "$T/kill.err" || fail "never managed to kill a worker while it held a task"
say "$(grep 'left holding task' "$T/kill.err" | head -1)"
redealt=$(jstat tasks_redealt "$T/kill.json")
say "tasks_redealt = $redealt"
[ "$redealt" -ge 1 ] || fail "the killed worker held a task but tasks_redealt is $redealt"
same "$T/ref.exr" "$T/kill.exr" "killed forked worker"

say "2. SIGSTOP a networked worker holding a task (--lease-timeout 2000, -j 0)"
# Worker A alone (no forked workers, plenty of tasks dealt) nearly always holds a task.  Stop
# it; nobody else is idle, so no straggler copy is dealt: only the lease brings the task back.
# One attempt: returns 0 once A was dropped holding a task, 2 if A held none when stopped (a
# worker is between tasks for the instant of a round trip after each result): then again.
stop_attempt() {
    rm -f "$T/stop.exr"
    : >"$T/stop.err"   # empty now: e2e_port must not read the previous attempt's port
    "$TF_BIN" render "$SCENE" -v -j 0 --size $SIZE --tasks rows:8 --watermark 64 \
        --lease-timeout 2000 --listen 127.0.0.1:0 -o "$T/stop.exr" --stats "$T/stop.json" 2>"$T/stop.err" &
    coord=$!; e2e_track $coord
    port=$(e2e_port "$T/stop.err") || fail "coordinator printed no port: $(cat "$T/stop.err")"
    "$TF_BIN" worker --connect 127.0.0.1:$port -j 1 -v 2>"$T/workerA.err" &
    wa=$!; e2e_track $wa
    i=0; while ! grep -q 'joined: .*networked' "$T/stop.err" && [ $i -lt 500 ]; do sleep 0.02; i=$((i+1)); done
    grep -q 'joined: .*networked' "$T/stop.err" || fail "networked worker never joined: $(cat "$T/workerA.err")"
    # into the terrain rows, as above, and far from the end
    i=0
    while [ "$(wc -c 2>/dev/null <"$T/stop.exr" || echo 0)" -lt $((full / 4)) ]; do
        kill -0 $coord 2>/dev/null || fail "the render ended before the stop"
        sleep 0.01; i=$((i + 1)); [ $i -lt 3000 ] || fail "the render made no progress"
    done
    stopped="$wa $(pgrep -P $wa)"
    kill -STOP $stopped
    say "stopped networked worker A (pids $stopped)"
    i=0; while ! grep -q 'silent for too long' "$T/stop.err" && [ $i -lt 100 ]; do sleep 0.1; i=$((i+1)); done
    grep -q 'silent for too long' "$T/stop.err" || fail "silent worker not dropped within 10 s: $(tail -3 "$T/stop.err")"
    say "after $((i / 10)).$((i % 10)) s: $(grep 'silent for too long' "$T/stop.err" | head -1)"
    sleep 0.3
    grep -q 'left holding task' "$T/stop.err" && return 0
    say "A held no task when stopped: again"
    kill -KILL $coord $stopped; kill -CONT $stopped; wait $coord 2>/dev/null
    return 2
}
for attempt in 1 2 3 4; do stop_attempt && break; done
grep -q 'left holding task' "$T/stop.err" || fail "never managed to stop A while it held a task"
say "$(grep 'left holding task' "$T/stop.err" | head -1)"
say "worker B joins and finishes the render"
"$TF_BIN" worker --connect 127.0.0.1:$port -j 1 -q 2>"$T/workerB.err" &
wb=$!; e2e_track $wb
wait_exit $coord 60
[ $rc -eq 0 ] || fail "render with a silent worker exited $rc: $(tail -5 "$T/stop.err")"
redealt=$(jstat tasks_redealt "$T/stop.json")
say "tasks_redealt = $redealt"
[ "$redealt" -ge 1 ] || fail "the silent worker's task was not re-dealt"
same "$T/ref.exr" "$T/stop.exr" "silent networked worker"
kill -KILL $stopped 2>/dev/null; kill -CONT $stopped 2>/dev/null
echo "farm_faults: tasks survive killed and silent workers"
