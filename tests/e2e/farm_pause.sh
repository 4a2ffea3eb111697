#!/bin/sh
# farm_pause.sh: a coordinator paused for longer than the lease heals by itself (leases,
# docs/contract.md section 3).
# A render with one forked and two networked workers, --lease-timeout 1500, --wait-workers 3.
# The forked worker and the first networked one join and wait idle (nothing is dealt before the
# third) for three lease periods: their heartbeats alone must keep them (workers pinged every
# 2 s and were dropped here).  Then the coordinator is SIGSTOPped for three lease periods (as a VM migration or a
# closed laptop lid would) while their heartbeats pile up unread, and the second networked
# worker connects into its listen queue meanwhile; then it is continued.  On waking it must
# read what arrived before it judges anyone silent: no worker is dropped, the third joins, the
# render completes, exit 0, identical to a clean render, and both networked workers end
# normally (exit 0) without a restart.  Nothing here races: the render cannot start before the
# pause (the third worker is started only once the coordinator is stopped).  On main every
# worker was dropped as silent on waking and the networked one exited.
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=960x540
LEASE=1500

render -q -j 2 --size $SIZE --tasks rows:2 -o "$T/ref.exr" || fail "reference render: $(cat "$T/last.err")"
"$TF_BIN" render "$SCENE" -j 1 --wait-workers 3 --size $SIZE --tasks rows:2 --listen 127.0.0.1:0 \
    --lease-timeout $LEASE -o "$T/pause.exr" -v 2>"$T/coord.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/coord.err") || fail "coordinator printed no port: $(cat "$T/coord.err")"
"$TF_BIN" worker --connect 127.0.0.1:$port -j 1 2>"$T/worker.err" &
worker=$!; e2e_track $worker
i=0
while [ "$(grep -c 'worker [0-9]* joined: ' "$T/coord.err")" -lt 2 ]; do
    kill -0 $coord 2>/dev/null || fail "the coordinator ended: $(cat "$T/coord.err")"
    i=$((i + 1)); [ $i -gt 600 ] && fail "the first two workers did not join: $(cat "$T/coord.err")"
    sleep 0.1
done
say "the two wait idle at the gate for three lease periods: their heartbeats keep them"
sleep $((3 * LEASE / 1000)).$((3 * LEASE % 1000))
say "SIGSTOP the coordinator for $((3 * LEASE)) ms; the third worker connects meanwhile"
kill -STOP $coord
"$TF_BIN" worker --connect 127.0.0.1:$port -j 1 --timeout 120s 2>"$T/worker2.err" &
worker2=$!; e2e_track $worker2
sleep $((3 * LEASE / 1000)).$((3 * LEASE % 1000))
kill -CONT $coord
wait_exit $coord 120
[ $rc -eq 0 ] || fail "render after a pause exited $rc: $(tail -5 "$T/coord.err")"
wait_exit $worker 30
[ $rc -eq 0 ] || fail "the networked worker exited $rc after the pause: $(tail -3 "$T/worker.err")"
wait_exit $worker2 30
[ $rc -eq 0 ] || fail "the worker that connected during the pause exited $rc: $(tail -3 "$T/worker2.err")"
same "$T/ref.exr" "$T/pause.exr" "render paused for three lease periods"
grep -q 'did not run for' "$T/coord.err" || fail "the coordinator did not notice its stall: $(tail -5 "$T/coord.err")"
if grep -q 'silent for too long' "$T/coord.err"; then
    fail "a worker was dropped as silent after the pause: $(grep 'silent for too long' "$T/coord.err")"
fi
[ "$(grep -c 'worker [0-9]* joined: ' "$T/coord.err")" -eq 3 ] || fail "expected 3 joins: $(grep 'joined: ' "$T/coord.err")"
say "$(grep -m1 'did not run for' "$T/coord.err")"
echo "farm_pause: coordinator stopped for 3 leases, no worker dropped, image identical"
