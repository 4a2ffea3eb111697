#!/bin/sh
# farm_stragglers.sh: stragglers (docs/contract.md section 3): when nothing else is left to deal,
# idle workers may get a duplicate of the oldest outstanding task; the first result wins, later ones
# are dropped.  A worker is frozen (SIGSTOP) while it holds a task, with a lease far longer than the
# render, so only straggler duplication can finish the image; the other worker must get a copy of
# the frozen task, and the image must be identical.
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=320x180
ARGS="--size $SIZE --tasks rows:6"

say "reference render"
render -q -j 1 $ARGS -o "$T/ref.exr" || fail "reference render: $(cat "$T/last.err")"

attempt=0
while :; do
    attempt=$((attempt + 1))
    [ $attempt -le 4 ] || fail "the frozen worker never held a task in 4 attempts"
    rm -f "$T/s.exr" "$T/s.json"
    "$TF_BIN" render "$SCENE" -j 0 --listen 127.0.0.1:0 $ARGS --lease-timeout 600000 \
        -o "$T/s.exr" --stats "$T/s.json" -v 2>"$T/s.err" &
    coord=$!; e2e_track $coord
    port=$(e2e_port "$T/s.err") || fail "the coordinator printed no port: $(cat "$T/s.err")"
    "$TF_BIN" worker --connect 127.0.0.1:$port -j 1 -q 2>"$T/a.err" &
    slow=$!; e2e_track $slow
    # freeze it in the middle of a task: it renders most of the time, so wait until its
    # first task is dealt, then catch it outside a socket wait
    i=0
    while ! grep -q 'worker 1 joined' "$T/s.err"; do
        sleep 0.02; i=$((i + 1)); [ $i -lt 500 ] || fail "the first worker never joined"
    done
    sleep 0.05
    i=0
    while grep -q 'sock\|poll\|recv\|epoll' "/proc/$slow/wchan" 2>/dev/null && [ $i -lt 200 ]; do
        sleep 0.001; i=$((i + 1))
    done
    kill -STOP $slow
    "$TF_BIN" worker --connect 127.0.0.1:$port -j 1 -q 2>"$T/b.err" &
    fast=$!; e2e_track $fast
    wait_exit $coord 60
    [ $rc -eq 0 ] || fail "render with a frozen worker: exit $rc: $(tail -3 "$T/s.err")"
    dup=$(jstat tasks_duplicated "$T/s.json")
    kill -CONT $slow
    wait_exit $fast 20
    wait_exit $slow 20   # it finds its coordinator gone when it wakes: non-zero is expected
    if [ "$dup" -ge 1 ]; then
        break
    fi
    say "attempt $attempt: the frozen worker held no task (no duplicate was needed); again"
done
say "tasks_duplicated = $dup; $(grep -c 'straggler' "$T/s.err") straggler line(s) in the log"
same "$T/ref.exr" "$T/s.exr" "render finished by a duplicate of the frozen worker's task"
echo "farm_stragglers: a frozen worker's task was duplicated and the image is identical"
