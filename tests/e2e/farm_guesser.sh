#!/bin/sh
# farm_guesser.sh: a secret guesser does not lock out the honest workers at its address
# (docs/contract.md section 3).  tests/tools/guesser.py hammers a coordinator that requires a
# secret with wrong-secret handshakes from 127.0.0.1, two at a time, without a pause.  Once it
# has seen the throttle in force (a wrong guess answered only after a wait, or -- as before the
# fix -- a connection from its address closed unheard), an honest `terrafarm worker` with the
# right secret joins from the same address.  The render must finish (exit 0) with the image of a
# clean render, the worker must leave with 0, and the guesser must still be hammering at the
# end.  Before the fix the throttle barred the whole address: the honest worker was turned
# away (or gave up on a "wrong secret") and the render waited with no worker, forever.
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=160x90
GUESSER="$TF_ROOT/tests/tools/guesser.py"

render -q -j 1 --size $SIZE --tasks rows:8 -o "$T/ref.exr" || fail "reference render: $(cat "$T/last.err")"
head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$T/farm.key"
head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$T/wrong.key"
chmod 600 "$T/farm.key" "$T/wrong.key"

"$TF_BIN" render "$SCENE" -j 0 --size $SIZE --tasks rows:8 --secret-file "$T/farm.key" \
    --listen 127.0.0.1:0 -o "$T/out.exr" 2>"$T/coord.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/coord.err") || fail "coordinator printed no port: $(cat "$T/coord.err")"

say "the guesser hammers wrong secrets from 127.0.0.1 until the throttle is in force"
python3 "$GUESSER" 127.0.0.1 "$port" "$T/wrong.key" 127.0.0.1 2 "$T/throttled" "$T/stop" \
    >"$T/guesser.out" 2>&1 &
guesser=$!; e2e_track $guesser
i=0
until [ -s "$T/throttled" ]; do
    kill -0 $guesser 2>/dev/null || fail "the guesser ended: $(cat "$T/guesser.out")"
    i=$((i + 1)); [ $i -lt 1200 ] || fail "no throttle seen in 60 s: $(tail -3 "$T/coord.err")"
    sleep 0.05
done
say "throttle seen by the guesser: $(cat "$T/throttled")"

say "an honest worker joins from the same address while the guessing goes on"
"$TF_BIN" worker --connect 127.0.0.1:$port --secret-file "$T/farm.key" -j 1 -q --timeout 30s \
    2>"$T/worker.err" &
worker=$!; e2e_track $worker
# the worker first: turned away, it gives up after its --timeout (the render would wait forever)
wait_exit $worker 90
[ $rc -eq 0 ] || fail "the honest worker exited $rc: $(cat "$T/worker.err"); coordinator: $(tail -3 "$T/coord.err")"
wait_exit $coord 30
[ $rc -eq 0 ] || fail "render with a guesser at the worker's address exited $rc: $(tail -5 "$T/coord.err")"
kill -0 $guesser 2>/dev/null || fail "the guesser stopped before the render ended: $(cat "$T/guesser.out")"
: >"$T/stop"
wait_exit $guesser 60
[ $rc -eq 0 ] || fail "the guesser failed: $(cat "$T/guesser.out")"
say "guesser: $(tail -1 "$T/guesser.out")"
grep -q 'failed handshakes from 127.0.0.1' "$T/coord.err" ||
    fail "the coordinator logged no throttled guesses: $(tail -5 "$T/coord.err")"
same "$T/ref.exr" "$T/out.exr" "render beside a guesser"
echo "farm_guesser: the honest worker rendered while its address kept guessing"
