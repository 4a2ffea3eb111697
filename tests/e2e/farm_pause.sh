#!/bin/sh
# farm_pause.sh: a coordinator paused for longer than the lease heals by itself (leases,
# docs/contract.md section 3).
# A render with one forked and one networked worker, --lease-timeout 1500; once both render,
# the coordinator is SIGSTOPped for three lease periods (as a VM migration or a closed laptop
# lid would), then continued.  On waking it must read what arrived before it judges anyone
# silent: no worker is dropped, the render completes, exit 0, identical to a clean render, and
# the networked worker ends normally (exit 0) without a restart.  On main every worker was
# dropped as silent on waking and the networked one exited.
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=960x540
LEASE=1500

render -q -j 2 --size $SIZE --tasks rows:2 -o "$T/ref.exr" || fail "reference render: $(cat "$T/last.err")"
# --wait-workers 2: the forked worker cannot render anything before the networked one has
# joined (it could otherwise be done before that one connected).
"$TF_BIN" render "$SCENE" -j 1 --wait-workers 2 --size $SIZE --tasks rows:2 --listen 127.0.0.1:0 \
    --lease-timeout $LEASE -o "$T/pause.exr" -v 2>"$T/coord.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/coord.err") || fail "coordinator printed no port: $(cat "$T/coord.err")"
"$TF_BIN" worker --connect 127.0.0.1:$port -j 1 2>"$T/worker.err" &
worker=$!; e2e_track $worker
i=0
while [ "$(grep -c 'joined: ' "$T/coord.err")" -lt 2 ]; do
    i=$((i + 1)); [ $i -gt 200 ] && fail "the two workers did not join: $(cat "$T/coord.err")"
    sleep 0.1
done
kill -0 $coord 2>/dev/null || fail "the render ended before the pause (make SIZE bigger)"
say "SIGSTOP the coordinator for $((3 * LEASE)) ms"
kill -STOP $coord
sleep $((3 * LEASE / 1000)).$((3 * LEASE % 1000))
kill -CONT $coord
wait_exit $coord 120
[ $rc -eq 0 ] || fail "render after a pause exited $rc: $(tail -5 "$T/coord.err")"
wait_exit $worker 30
[ $rc -eq 0 ] || fail "the networked worker exited $rc after the pause: $(tail -3 "$T/worker.err")"
same "$T/ref.exr" "$T/pause.exr" "render paused for three lease periods"
grep -q 'did not run for' "$T/coord.err" || fail "the coordinator did not notice its stall: $(tail -5 "$T/coord.err")"
if grep -q 'silent for too long' "$T/coord.err"; then
    fail "a worker was dropped as silent after the pause: $(grep 'silent for too long' "$T/coord.err")"
fi
say "$(grep -m1 'did not run for' "$T/coord.err")"
echo "farm_pause: coordinator stopped for 3 leases, no worker dropped, image identical"
