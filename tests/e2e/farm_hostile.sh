#!/bin/sh
# farm_hostile.sh: a client holding the secret can only render (coordinator/render/worker_role.h).
# tests/tools/hostile_worker.py joins a render in progress and tries each class of attack: forged,
# duplicate, empty and short results (non-finite values are refused by the worker itself,
# tests/unit/test_worker.c; in encoded chunks only --verify can catch them); forged tasks and stops;
# scene replacement; stealing results; hoarding; exclusions; joining twice.  Each must be refused
# (an ERROR reply for that request), then it hoards tasks on five connections until the end.  A real
# worker renders meanwhile.  The render must exit 0 with an image identical to a clean render, and
# the coordinator's log must name the refused attempts and the peer.
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=320x180
HOSTILE="$TF_ROOT/tests/tools/hostile_worker.py"

render -q -j 1 --size $SIZE --tasks rows:2 -o "$T/ref.exr" || fail "reference render: $(cat "$T/last.err")"
head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$T/farm.key"
chmod 600 "$T/farm.key"

say "coordinator with a secret, no local workers; the hostile client attacks first"
"$TF_BIN" render "$SCENE" -j 0 --size $SIZE --tasks rows:2 --secret-file "$T/farm.key" \
    --listen 127.0.0.1:0 --lease-timeout 5000 -o "$T/hostile.exr" 2>"$T/coord.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/coord.err") || fail "coordinator printed no port: $(cat "$T/coord.err")"
python3 "$HOSTILE" 127.0.0.1 "$port" "$T/farm.key" 320 180 "$T/ready" >"$T/hostile.out" 2>&1 &
hostile=$!; e2e_track $hostile
i=0
while [ ! -e "$T/ready" ]; do
    kill -0 $hostile 2>/dev/null || fail "the hostile client ended early: $(cat "$T/hostile.out")"
    i=$((i + 1)); [ $i -gt 300 ] && fail "the hostile client never finished its attacks: $(cat "$T/hostile.out")"
    sleep 0.1
done
say "$(grep -c '^refused' "$T/hostile.out") attacks refused; $(tail -1 "$T/hostile.out")"
"$TF_BIN" worker --connect 127.0.0.1:$port --secret-file "$T/farm.key" -j 1 -q 2>"$T/worker.err" &
worker=$!; e2e_track $worker
wait_exit $coord 90
[ $rc -eq 0 ] || fail "render under attack exited $rc: $(tail -5 "$T/coord.err")"
wait_exit $worker 20
[ $rc -eq 0 ] || fail "the real worker exited $rc: $(cat "$T/worker.err")"
wait_exit $hostile 30
[ $rc -eq 0 ] || fail "hostile client: $(cat "$T/hostile.out")"
same "$T/ref.exr" "$T/hostile.exr" "render under attack"
for what in 'more than 1 time' 'before joining' 'not allowed to a worker' 'forged stop task' \
    'invented\|failure reported as worker 9999' 'which this connection does not hold' \
    'one at a time' 'actual fields' 'signed as worker' 'result of task [0-9]* ([0-9]*x[0-9]* at' \
    'shifted\|instead of' 'excluding workers'; do
    grep "from 127.0.0.1:[0-9]* (worker) refused: " "$T/coord.err" | grep -q "$what" ||
        fail "the coordinator's log does not name the refused attempt '$what': $(grep refused "$T/coord.err" | head -30)"
done
say "coordinator: $(grep -c ') refused: ' "$T/coord.err") refusals logged, e.g. $(grep ') refused: ' "$T/coord.err" | head -1)"
echo "farm_hostile: every attack refused, hoarded tasks re-dealt, image identical"
