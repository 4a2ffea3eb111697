#!/bin/sh
# tests/e2e/netns_farm.sh: a render across "machines" that share nothing but a network.
#
# Builds a small LAN out of Linux network namespaces: a switch (a bridge in its own namespace,
# tf-PID-lan) and three hosts plugged into it with veth cables: the coordinator (tf-PID-coord,
# 10.77.0.1) and two workers (tf-PID-w1, tf-PID-w2, 10.77.0.2 and .3).  Each host sees only its
# own loopback and its cable, so the workers reach the coordinator over the "network" alone,
# authenticated by a shared secret file, exactly as on separate machines.
#
#   1. A wrong secret is refused with one clear line.
#   2. Coordinator (-j 0, networked workers only) + two workers (-j 1 each) render
#      scenes/default.scene at 240x135; both workers take tasks; the image is bit-identical
#      (cmp) to a local render of the same scene and size.
#   3. The same at a larger size with --tasks rows:4, --lease-timeout 2000 and a watermark that
#      lets every task be dealt (see below why); both workers join and are frozen before the
#      first task is dealt (a third, tests/tools/gate_worker.py, opens the --wait-workers gate
#      and takes nothing), so the render advances only while the test lets it; once the
#      coordinator's dashboard shows worker 2 holding a task (the worker frozen meanwhile), its
#      cable is pulled at the switch (ip link set down).  The coordinator hears nothing more
#      from it, drops it after the lease timeout and deals its task again (tasks_redealt >= 1
#      in --stats); worker 1 finishes the render and the image still equals the local render.
#   4. A partition: every worker's cable is pulled for longer than the lease (2.5 leases), then
#      plugged back (pulled after both joined and before the first task is dealt: the gate
#      worker, on the coordinator's host, opens the gate once they are cut off).  The coordinator drops both as silent and deals their tasks again; the
#      workers notice the broken connections once the network is back, reconnect with backoff
#      within --timeout, authenticate and join again, and finish the render: exit 0 for all,
#      no manual restart, the image identical to the local render.
#
# Needs root and `ip netns`; otherwise exits 77 (skipped) with the reason on its last line.
# Every namespace and process it makes is removed on exit, even on failure or interrupt.
# Usage: sh tests/e2e/netns_farm.sh   (or tests/run.sh netns; TF_BIN / TF_ROOT as run.sh sets;
#        TF_KEEP_LOGS=1 keeps the logs, images and stats of the run)
set -u

ROOT=${TF_ROOT:-$(cd "$(dirname "$0")/../.." && pwd)}
TF=${TF_BIN:-$ROOT/bin/terrafarm}
SCENE=$ROOT/scenes/default.scene
PORT=7878
HTTP_PORT=7879            # the coordinator's dashboard, read to see which task worker 2 holds
COORD_IP=10.77.0.1
SMALL=240x135
LARGE=2048x1152        # ~7 s of one core here: after the cut, worker 1 alone still needs well
                       # over the 2 s lease, so the lease expires (a re-deal) before the
                       # straggler policy could cover the lost task with a duplicate
LIMIT=45               # seconds any one process may run before `timeout` stops it

NS_LAN=tf-$$-lan
NS_COORD=tf-$$-coord
NS_W1=tf-$$-w1
NS_W2=tf-$$-w2

skip() { echo "skipped: $*"; exit 77; }
fail() { echo "FAIL: $*"; exit 1; }
note() { echo "netns_farm: $*"; }

# ---- preconditions: skip (77) with a reason, never fail, when the host cannot do this ----
[ "$(id -u)" -eq 0 ] || skip "needs root to create network namespaces"
command -v ip >/dev/null 2>&1 || skip "ip (iproute2) is not installed"
command -v timeout >/dev/null 2>&1 || skip "timeout (coreutils) is not installed"
[ -x "$TF" ] || fail "$TF is not built (run make)"
# Under AddressSanitizer (make asan) everything runs several times slower.
if ldd "$TF" 2>/dev/null | grep -q libasan; then LIMIT=150; fi

# ---- cleanup: every process we started (by pid), then every namespace, then the temp dir ----
PIDS=""
NAMESPACES=""
TMP=""
STOPPED=""             # workers paused by cut_while_holding, continued before anything else
cleanup() {
    for pid in $STOPPED; do kill -CONT "$pid" 2>/dev/null; done
    for pid in $PIDS; do
        kill "$pid" 2>/dev/null
    done
    for pid in $PIDS; do
        wait "$pid" 2>/dev/null
    done
    for ns in $NAMESPACES; do
        ip netns delete "$ns" 2>/dev/null
    done
    if [ -n "${TF_KEEP_LOGS:-}" ]; then
        echo "netns_farm: logs kept in $TMP"
    elif [ -n "$TMP" ]; then
        rm -rf "$TMP"
    fi
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

TMP=$(mktemp -d "${TMPDIR:-/tmp}/tf-netns.XXXXXX") || fail "mktemp failed"

# ---- the network ----
make_ns() {
    ip netns add "$1" 2>"$TMP/ip.err" || skip "ip netns add $1 failed: $(head -1 "$TMP/ip.err")"
    NAMESPACES="$NAMESPACES $1"
    ip -n "$1" link set lo up || fail "cannot bring up lo in $1"
}

# plug HOST_NS ADDRESS: a veth cable from the switch port p-HOST to eth0 in HOST_NS.
plug() {
    port=p-${1##*-}
    if ! { ip -n "$NS_LAN" link add "$port" type veth peer name eth0 netns "$1" &&
        ip -n "$NS_LAN" link set "$port" master br0 &&
        ip -n "$NS_LAN" link set "$port" up &&
        ip -n "$1" addr add "$2/24" dev eth0 &&
        ip -n "$1" link set eth0 up; }; then
        fail "cannot plug $1 into the switch"
    fi
}

make_ns "$NS_LAN"
make_ns "$NS_COORD"
make_ns "$NS_W1"
make_ns "$NS_W2"
if ! { ip -n "$NS_LAN" link add br0 type bridge && ip -n "$NS_LAN" link set br0 up; }; then
    skip "cannot create a bridge in a network namespace"
fi
plug "$NS_COORD" "$COORD_IP"
plug "$NS_W1" 10.77.0.2
plug "$NS_W2" 10.77.0.3
note "LAN up: $NS_COORD=$COORD_IP, $NS_W1=10.77.0.2, $NS_W2=10.77.0.3 on a bridge in $NS_LAN"

# The shared secret, readable by its owner only (the farm warns about looser modes).
umask 077
head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$TMP/secret"
head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$TMP/wrong-secret"

# ---- helpers ----
# start NS LOG CMD...: run CMD in namespace NS in the background, bounded by $LIMIT seconds;
# the pid (of `timeout`, which passes signals on) is in $LAST and is killed on exit.
start() {
    ns=$1 log=$2
    shift 2
    ip netns exec "$ns" timeout "$LIMIT" "$@" >"$log" 2>&1 &
    LAST=$!
    PIDS="$PIDS $LAST"
}

# wait_for_line FILE TEXT SECONDS PID: until FILE contains TEXT; fails if PID dies first.
wait_for_line() {
    i=0
    while ! grep -q "$2" "$1" 2>/dev/null; do
        kill -0 "$4" 2>/dev/null || { cat "$1"; fail "process exited before '$2' appeared in $1"; }
        i=$((i + 1))
        [ "$i" -le $(($3 * 10)) ] || { cat "$1"; fail "no '$2' in $1 after $3 s"; }
        sleep 0.1
    done
}

# count_lines FILE TEXT: how many lines of FILE contain TEXT (0 when none).
count_lines() {
    grep -c "$2" "$1" 2>/dev/null || true
}

# json_int FILE KEY: the integer value of the first "KEY": N in a stats file.
json_int() {
    sed -n "s/.*\"$2\": *\\([0-9][0-9]*\\).*/\\1/p" "$1" | head -1
}

# start_coordinator TAG SIZE EXTRA...: the coordinator of a networked-only render into
# $TMP/TAG.exr; returns once it is listening.  Its pid is $COORD, its log $TMP/TAG.coord.log.
start_coordinator() {
    tag=$1 size=$2
    shift 2
    start "$NS_COORD" "$TMP/$tag.coord.log" "$TF" render "$SCENE" --size "$size" -j 0 \
        --listen "$COORD_IP:$PORT" --secret-file "$TMP/secret" -o "$TMP/$tag.exr" \
        --stats "$TMP/$tag.json" -v "$@"
    COORD=$LAST
    wait_for_line "$TMP/$tag.coord.log" "may join at $COORD_IP:$PORT" 20 "$COORD"
}

# forget PID: it has been reaped, so cleanup must not signal it (the number may be reused).
forget() {
    kept=""
    for pid in $PIDS; do
        [ "$pid" = "$1" ] || kept="$kept $pid"
    done
    PIDS=$kept
}

# finish PID WHAT: wait for PID and fail unless it exited 0.
finish() {
    wait "$1"
    rc=$?
    forget "$1"
    [ "$rc" -eq 0 ] || fail "$2 exited with status $rc"
}

# local_reference SIZE [ARGS]: a plain local render of the same scene and size, in the root
# namespace (ARGS: the --tasks of the render it is compared with, so the layout is the same).
local_reference() {
    lr_size=$1; shift
    "$TF" render "$SCENE" --size "$lr_size" -j 2 -q -o "$TMP/local-$lr_size.exr" "$@" ||
        fail "local reference render at $1 failed"
}

# child_of PID: the first child of PID (`timeout` runs the farm command as its child).
child_of() {
    first=""
    read -r first _ <"/proc/$1/task/$1/children" 2>/dev/null # no newline: read says 1 at EOF
    echo "$first"
}

# worker_task ID: the task the coordinator has dealt to worker ID and not yet had back (its
# dashboard's /api/workers "task"), or "none"; read over the coordinator's own namespace.
worker_task() {
    ip netns exec "$NS_COORD" "$TF" status "$COORD_IP:$HTTP_PORT" --secret-file "$TMP/secret" \
        --json 2>/dev/null | python3 -c '
import json, sys
try:
    w = [w for w in json.load(sys.stdin)["workers"] if w["id"] == int(sys.argv[1])]
    print(w[0]["task"] if w and w[0]["task"] is not None else "none")
except Exception:
    print("none")' "$1"
}

# cut_while_holding PID PORT OTHER: pull the cable at switch port PORT while the worker under PID
# (a `timeout` started by start; worker id 2 at the coordinator) holds a task it has not
# returned, so there is a lease to expire.  A worker between tasks holds none: the coordinator
# may already have its result and the `in` for the next task be lost with the cable, and then
# nothing is there to re-deal.  Timing cannot tell the two apart (a fast machine returns a task
# in a few milliseconds), so ask the coordinator: freeze the worker (SIGSTOP: it can send
# nothing more), give the coordinator 0.5 s to take in whatever was already on the wire, and
# read worker 2's task from the dashboard.  If it holds one, cut the cable before it runs again;
# if not, let it run a moment and look again.  The freeze is well inside the 2 s lease, so the
# cut, not the pause, is what silences it.  The other worker (under OTHER) is frozen while we
# look too: the render advances only between looks, so it cannot end during a run of misses
# however slow the look (a loaded machine) or fast the workers.
cut_while_holding() {
    wpid=$(child_of "$1") opid=$(child_of "$3")
    if [ -z "$wpid" ] || [ -z "$opid" ]; then
        fail "cannot find the worker processes under pids $1 $3"
    fi
    tries=0
    while :; do
        # a zombie takes the signal too: ask ps whether it is still there and not one
        kill -STOP "$wpid" "$opid" 2>/dev/null
        st=$(ps -o stat= -p "$wpid" | cut -c1)
        if [ -z "$st" ] || [ "$st" = Z ]; then
            tail -3 "$TMP/cut.coord.log" "$TMP/cut.w1.log" "$TMP/cut.w2.log"
            fail "worker 2 exited before the cut"
        fi
        STOPPED="$wpid $opid"
        sleep 0.5
        held=$(worker_task 2)
        [ "$held" != none ] && break
        kill -CONT "$wpid" "$opid"
        STOPPED=""
        tries=$((tries + 1))
        [ "$tries" -le 20 ] || fail "worker 2 was never seen holding a task"
        sleep 0.05
    done
    ip -n "$NS_LAN" link set "$2" down
    rc=$?
    kill -CONT "$wpid" "$opid"
    STOPPED=""
    [ "$rc" -eq 0 ] || fail "cannot cut the cable at $2"
    note "worker 2 frozen holding task $held (after $tries miss(es)); cable cut"
}

# ---- 1. the secret is checked across the network ----
start_coordinator small "$SMALL" --wait-workers 2
if ip netns exec "$NS_W1" timeout 20 "$TF" worker --connect "$COORD_IP:$PORT" \
    --secret-file "$TMP/wrong-secret" -j 1 --timeout 5000 >"$TMP/wrong.log" 2>&1; then
    fail "a worker with the wrong secret was accepted"
fi
[ "$(wc -l <"$TMP/wrong.log")" -eq 1 ] || { cat "$TMP/wrong.log"; fail "refusal is not one line"; }
note "wrong secret refused: $(cat "$TMP/wrong.log")"

# ---- 2. a render across the two worker hosts equals a local render ----
# (the coordinator runs with --wait-workers in every part: nothing is dealt before both hosts
# have joined, so neither can finish a render alone before the other is in, and the first two
# tasks go one to each: both render, whichever is faster; parts 3 and 4 wait for a third, the
# gate worker, started once the test has the two where it wants them)
start "$NS_W1" "$TMP/small.w1.log" "$TF" worker --connect "$COORD_IP:$PORT" \
    --secret-file "$TMP/secret" -j 1
W1=$LAST
start "$NS_W2" "$TMP/small.w2.log" "$TF" worker --connect "$COORD_IP:$PORT" \
    --secret-file "$TMP/secret" -j 1
W2=$LAST
finish "$COORD" "coordinator (small render)"
finish "$W1" "worker 1 (small render)"
finish "$W2" "worker 2 (small render)"

local_reference "$SMALL"
cmp "$TMP/local-$SMALL.exr" "$TMP/small.exr" ||
    fail "the networked render differs from the local render at $SMALL"
workers=$(count_lines "$TMP/small.json" '"kind": "networked"')
[ "$workers" -eq 2 ] || { cat "$TMP/small.json"; fail "expected 2 networked workers, stats list $workers"; }
idle=$(count_lines "$TMP/small.json" '"kind": "networked".*"tasks": 0,')
[ "$idle" -eq 0 ] || { cat "$TMP/small.json"; fail "a worker host rendered no task"; }
note "$SMALL across 2 hosts: identical to the local render; tasks per worker:" \
    "$(sed -n 's/.*"kind": "networked".*"tasks": \([0-9]*\),.*/\1/p' "$TMP/small.json" | tr '\n' ' ')"

# ---- 3. cut worker 2's cable mid-render: its task is dealt again ----
# --watermark above the task count: with the default watermark, worker 1 would soon reach the
# watermark behind the lost task and sit idle, and the straggler policy would deal it a duplicate
# of that task well before the lease expires (the render recovers, tasks_duplicated counts it,
# but nothing is re-dealt).  Here worker 1 keeps rendering fresh tasks, so it is the lease that
# notices the silent worker and deals its task again.
start_coordinator cut "$LARGE" --wait-workers 3 --tasks rows:4 --lease-timeout 2000 --watermark 1000 \
    --http "$COORD_IP:$HTTP_PORT"
# One after the other, so that worker 2 is the second to join: id 2 at the coordinator (the
# coordinator logs each join at -v).
wait_joined() {
    i=0
    while [ "$(count_lines "$TMP/cut.coord.log" 'joined: networked')" -lt "$1" ]; do
        kill -0 "$COORD" 2>/dev/null || { cat "$TMP/cut.coord.log"; fail "coordinator exited early"; }
        i=$((i + 1))
        [ "$i" -le 200 ] || { cat "$TMP/cut.coord.log"; fail "worker $1 did not join"; }
        sleep 0.1
    done
}
start "$NS_W1" "$TMP/cut.w1.log" "$TF" worker --connect "$COORD_IP:$PORT" \
    --secret-file "$TMP/secret" -j 1
W1=$LAST
wait_joined 1
start "$NS_W2" "$TMP/cut.w2.log" "$TF" worker --connect "$COORD_IP:$PORT" \
    --secret-file "$TMP/secret" -j 1
W2=$LAST
wait_joined 2
# Both frozen before any task is dealt, then the gate opened by a worker that takes none: from
# here the render advances only in cut_while_holding's short runs, whatever the machine's speed.
w2pid=$(child_of "$W2") w1pid=$(child_of "$W1")
if [ -z "$w2pid" ] || [ -z "$w1pid" ]; then
    fail "cannot find the worker processes under $W2 $W1"
fi
kill -STOP "$w2pid" "$w1pid"
STOPPED="$w2pid $w1pid"
start "$NS_W1" "$TMP/cut.gate.log" python3 "$ROOT/tests/tools/gate_worker.py" "$COORD_IP" \
    "$PORT" "$TMP/secret" # ends with the render; cleanup kills it otherwise
wait_joined 3
cut_while_holding "$W2" p-w2 "$W1"
cut_at=$(date +%s)
note "cut worker 2's cable (p-w2 down) mid-render"
finish "$COORD" "coordinator (render with a cut cable)"
after=$(($(date +%s) - cut_at))
finish "$W1" "worker 1 (render with a cut cable)"

# The lost task is dealt again either way: by the lease (re-dealt, logged) when worker 1 still
# has fresh tasks 2 s after the cut, which is the case here (it needs ~7 s alone), or, on a
# machine fast enough to finish the rest sooner, as a straggler's second copy to the idle
# worker 1 (duplicated).  Both are a recovery; which one comes first is the machine's speed.
redealt=$(json_int "$TMP/cut.json" tasks_redealt)
duplicated=$(json_int "$TMP/cut.json" tasks_duplicated)
if [ "${redealt:-0}" -lt 1 ] && [ "${duplicated:-0}" -lt 1 ]; then
    cat "$TMP/cut.json"
    fail "tasks_redealt is ${redealt:-missing} and tasks_duplicated ${duplicated:-missing}" \
        "${after} s after the cut: the lost task was never dealt again"
fi
if [ "${redealt:-0}" -ge 1 ]; then
    grep -q "re-dealing task" "$TMP/cut.coord.log" || fail "the coordinator did not log a re-deal"
fi
local_reference "$LARGE" --tasks rows:4
cmp "$TMP/local-$LARGE.exr" "$TMP/cut.exr" ||
    fail "the render with a cut cable differs from the local render at $LARGE"
note "$LARGE with worker 2 cut off: tasks_redealt=$redealt tasks_duplicated=$duplicated," \
    "identical to the local render"
[ "${redealt:-0}" -lt 1 ] || note "$(grep -m1 're-dealing task' "$TMP/cut.coord.log")"

# ---- 4. pull every cable for longer than the lease: the farm heals by itself ----
# Worker 2 of part 3 is still cut off (and would come back to this render): end it, replug.
kill "$W2" 2>/dev/null
wait "$W2" 2>/dev/null
forget "$W2"
ip -n "$NS_LAN" link set p-w2 up || fail "cannot plug worker 2 back in"
LIMIT=$((LIMIT + 55)) # the partition and the reconnections come on top of the render
start_coordinator part "$LARGE" --wait-workers 3 --tasks rows:4 --lease-timeout 2000
start "$NS_W1" "$TMP/part.w1.log" "$TF" worker --connect "$COORD_IP:$PORT" \
    --secret-file "$TMP/secret" -j 1 --timeout 30000
W1=$LAST
start "$NS_W2" "$TMP/part.w2.log" "$TF" worker --connect "$COORD_IP:$PORT" \
    --secret-file "$TMP/secret" -j 1 --timeout 30000
W2=$LAST
i=0
while [ "$(count_lines "$TMP/part.coord.log" 'joined: networked')" -lt 2 ]; do
    kill -0 "$COORD" 2>/dev/null || { cat "$TMP/part.coord.log"; fail "coordinator exited early"; }
    i=$((i + 1))
    [ "$i" -le 200 ] || { cat "$TMP/part.coord.log"; fail "the two workers did not join"; }
    sleep 0.1
done
if ! { ip -n "$NS_LAN" link set p-w1 down && ip -n "$NS_LAN" link set p-w2 down; }; then
    fail "cannot pull the cables"
fi
start "$NS_COORD" "$TMP/part.gate.log" python3 "$ROOT/tests/tools/gate_worker.py" "$COORD_IP" \
    "$PORT" "$TMP/secret"
wait_for_line "$TMP/part.coord.log" "3 workers joined: dealing tasks" 20 "$COORD"
note "both workers' cables pulled for 5 s (2.5 leases), then the gate opened"
sleep 5
if ! { ip -n "$NS_LAN" link set p-w1 up && ip -n "$NS_LAN" link set p-w2 up; }; then
    fail "cannot plug the cables back"
fi
finish "$COORD" "coordinator (render across a partition)"
finish "$W1" "worker 1 (render across a partition)"
finish "$W2" "worker 2 (render across a partition)"
dropped=$(count_lines "$TMP/part.coord.log" 'silent for too long')
[ "$dropped" -ge 2 ] || { cat "$TMP/part.coord.log"; fail "expected both workers dropped as silent, saw $dropped"; }
back=$(cat "$TMP/part.w1.log" "$TMP/part.w2.log" | grep -c 'reconnecting to')
[ "$back" -ge 2 ] || { cat "$TMP/part.w1.log" "$TMP/part.w2.log"; fail "the workers did not reconnect"; }
cmp "$TMP/local-$LARGE.exr" "$TMP/part.exr" ||
    fail "the render across a partition differs from the local render at $LARGE"
note "partition healed: $dropped silent workers dropped, $back reconnections, identical image"
echo "netns_farm: ok"
