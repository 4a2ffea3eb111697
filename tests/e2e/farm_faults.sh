#!/bin/sh
# farm_faults.sh: a task is never lost (docs/contract.md section 3, Faults).
#  1. SIGKILL a forked worker mid-render: its task returns to the space and is dealt again
#     (tasks_redealt >= 1), the coordinator carries on, the image is identical.
#  2. SIGSTOP a networked worker while it holds a task (--lease-timeout 4000): the coordinator
#     drops the silent worker, re-deals its task, and the render completes identically.
# Never a race with the machine's speed: no task is dealt while the workers run free (in part 1
# the forked ones are frozen at the --wait-workers gate, the networked ones start stopped), and
# they run 20 ms at a time until a quarter of the file is written and the dashboard shows the
# victim holding a task; frozen then, the render cannot end, nor the victim put its task down,
# before the kill or the stop lands.
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=480x270

say "reference: -j 2, $SIZE"
render -q -j 2 --size $SIZE --tasks rows:8 -o "$T/ref.exr" || fail "reference render: $(cat "$T/last.err")"
full=$(wc -c <"$T/ref.exr")

say "1. kill -KILL one forked worker mid-render (rows:8, -j 2)"
# --wait-workers 3: the two forked workers join and wait at the gate, nothing dealt, and are
# frozen there; the third, a networked worker started stopped, runs 20 ms at a time until it
# has joined, and stays frozen.  Then the forked ones run in slices.
"$TF_BIN" render "$SCENE" -v -j 2 --wait-workers 3 --size $SIZE --tasks rows:8 --watermark 64 \
    --lease-timeout 120000 --listen 127.0.0.1:0 --http 127.0.0.1:0 -o "$T/kill.exr" \
    --stats "$T/kill.json" 2>"$T/kill.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/kill.err") || fail "coordinator printed no port: $(cat "$T/kill.err")"
addr=$(dashboard_addr "$T/kill.err" $coord)
i=0
while [ "$(grep -c 'worker [0-9]* joined: forked' "$T/kill.err")" -lt 2 ]; do
    kill -0 $coord 2>/dev/null || fail "the coordinator ended: $(tail -3 "$T/kill.err")"
    sleep 0.05; i=$((i + 1)); [ $i -lt 1200 ] || fail "the forked workers did not join: $(cat "$T/kill.err")"
done
freeze_workers $coord
start_stopped "$T/third.err" "$TF_BIN" worker --connect 127.0.0.1:$port -j 1 -q
third=$!; e2e_track $third
i=0
until grep -q 'joined: networked' "$T/kill.err"; do
    kill -CONT $third; sleep 0.02; kill -STOP $third; sleep 0.1
    i=$((i + 1)); [ $i -lt 1200 ] || fail "the third worker did not join: $(cat "$T/third.err")"
done
# Until a forked worker holds a task: frozen, it still holds it when it dies.  Seen in two
# dashboard snapshots a pause apart (each at most 200 ms old), so not a result that was on its
# way when the worker froze.
i=0 victim=""
while [ -z "$victim" ]; do
    kill -0 $coord 2>/dev/null || fail "the render ended before a worker was seen holding a task: $(tail -3 "$T/kill.err")"
    run_slice $coord
    i=$((i + 1)); [ $i -lt 1200 ] || fail "no forked worker was seen holding a task"
    held=$(busy_workers "$addr"); sleep 0.25
    for it in $(busy_workers "$addr"); do
        case " $held " in *" $it "*) ;; *) continue ;; esac
        victim=$(sed -n "s/.*worker ${it%%:*} joined: forked on .*(pid \([0-9]*\),.*/\1/p" "$T/kill.err" | head -1)
        [ -n "$victim" ] && break
    done
done
kill -KILL "$victim"
say "killed forked worker pid $victim, holding a task"
# The coordinator looks at its children every 200 ms; the other worker stays frozen until it has
# seen the death, so the render cannot end first.
i=0
while ! grep -q "killed by signal 9" "$T/kill.err"; do
    kill -0 $coord 2>/dev/null || fail "the render ended before the kill was seen: $(tail -3 "$T/kill.err")"
    sleep 0.05; i=$((i + 1)); [ $i -lt 600 ] || fail "coordinator never noticed a killed worker"
done
thaw_workers $coord
kill -CONT $third
wait_exit $coord 60
[ $rc -eq 0 ] || fail "render with a killed worker exited $rc: $(tail -5 "$T/kill.err")"
wait_exit $third 30
[ $rc -eq 0 ] || fail "the networked worker exited $rc: $(tail -3 "$T/third.err")"
grep -q "killed by signal 9" "$T/kill.err" || fail "coordinator never noticed a killed worker"
grep -q 'left holding task' "$T/kill.err" || fail "the victim held a task, but no 'left holding task' was logged"
say "$(grep 'left holding task' "$T/kill.err" | head -1)"
redealt=$(jstat tasks_redealt "$T/kill.json")
say "tasks_redealt = $redealt"
[ "$redealt" -ge 1 ] || fail "the killed worker held a task but tasks_redealt is $redealt"
same "$T/ref.exr" "$T/kill.exr" "killed forked worker"

say "2. SIGSTOP a networked worker holding a task (--lease-timeout 4000, -j 0)"
# Worker A alone (no forked workers): stopped while it holds a task, nobody else is idle, so no
# straggler copy is dealt: only the lease brings the task back.  A starts stopped (its shell
# stops itself before it execs the worker), then runs 20 ms at a time until it holds a task
# past a quarter of the file (a ping goes out in each slice: far from the 4 s of silence).
"$TF_BIN" render "$SCENE" -v -j 0 --size $SIZE --tasks rows:8 --watermark 64 --lease-timeout 4000 \
    --listen 127.0.0.1:0 --http 127.0.0.1:0 -o "$T/stop.exr" --stats "$T/stop.json" 2>"$T/stop.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/stop.err") || fail "coordinator printed no port: $(cat "$T/stop.err")"
addr=$(dashboard_addr "$T/stop.err" $coord)
start_stopped "$T/workerA.err" "$TF_BIN" worker --connect 127.0.0.1:$port -j 1 -v
wa=$!; e2e_track $wa
i=0
until [ "$(wc -c 2>/dev/null <"$T/stop.exr" || echo 0)" -ge $((full / 4)) ] && [ -n "$(busy_workers "$addr")" ]; do
    kill -0 $coord 2>/dev/null || fail "the render ended before the stop: $(tail -3 "$T/stop.err")"
    run_process_slice $wa
    i=$((i + 1)); [ $i -lt 1200 ] || fail "A never held a task past a quarter of the file: $(cat "$T/workerA.err")"
done
grep -q 'joined: .*networked' "$T/stop.err" || fail "networked worker never joined: $(cat "$T/workerA.err")"
stopped="$wa $(pgrep -P $wa)"
kill -STOP $stopped
say "stopped networked worker A (pids $stopped), holding a task"
i=0; while ! grep -q 'silent for too long' "$T/stop.err" && [ $i -lt 300 ]; do sleep 0.1; i=$((i+1)); done
grep -q 'silent for too long' "$T/stop.err" || fail "silent worker not dropped within 30 s: $(tail -3 "$T/stop.err")"
say "after $((i / 10)).$((i % 10)) s: $(grep 'silent for too long' "$T/stop.err" | head -1)"
i=0; while ! grep -q 'left holding task' "$T/stop.err" && [ $i -lt 50 ]; do sleep 0.1; i=$((i+1)); done
grep -q 'left holding task' "$T/stop.err" || fail "A held a task when stopped, but no 'left holding task' was logged"
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
