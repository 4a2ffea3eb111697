#!/bin/sh
# farm_tamper.sh: frames are sealed after the handshake (common/linda/seal.h).  A networked worker
# reaches the coordinator through tests/tools/flip_proxy.py, a machine on the path that records what
# the coordinator sends and flips one bit of the worker's stream well after the handshake, once.
# The coordinator must close that connection only (one line naming it: the record failed
# authentication); a second networked worker, connected directly, goes on; the tampered-with worker
# reconnects and finishes; the image is identical to a clean render.  And the recorded stream must
# not contain the scene's text, which the worker did receive (a machine on the path cannot read the
# scene).
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=640x360
PROXY="$TF_ROOT/tests/tools/flip_proxy.py"

render -q -j 1 --size $SIZE --tasks rows:2 -o "$T/ref.exr" || fail "reference render: $(cat "$T/last.err")"
head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$T/farm.key"
chmod 600 "$T/farm.key"
# --wait-workers 2: the direct worker cannot finish the render before the proxied one is back
# (the flipped byte falls in its first connection, before it joins; it reconnects and joins).
"$TF_BIN" render "$SCENE" -j 0 --wait-workers 2 --size $SIZE --tasks rows:2 --secret-file "$T/farm.key" \
    --listen 127.0.0.1:0 -o "$T/tamper.exr" -v 2>"$T/coord.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/coord.err") || fail "coordinator printed no port: $(cat "$T/coord.err")"
python3 "$PROXY" 127.0.0.1 "$port" 200 "$T/capture.bin" >"$T/proxy.out" 2>&1 &
proxy=$!; e2e_track $proxy
i=0
until grep -q 'listening on' "$T/proxy.out" 2>/dev/null; do
    i=$((i + 1)); [ $i -gt 100 ] && fail "the proxy did not start: $(cat "$T/proxy.out")"
    sleep 0.1
done
pport=$(sed -n 's/listening on //p' "$T/proxy.out")
"$TF_BIN" worker --connect 127.0.0.1:$pport --secret-file "$T/farm.key" -j 1 2>"$T/worker.err" &
worker=$!; e2e_track $worker
"$TF_BIN" worker --connect 127.0.0.1:$port --secret-file "$T/farm.key" -j 1 2>"$T/direct.err" &
direct=$!; e2e_track $direct
wait_exit $coord 90
[ $rc -eq 0 ] || fail "render with a tampering proxy exited $rc: $(tail -5 "$T/coord.err")"
wait_exit $worker 30
[ $rc -eq 0 ] || fail "the networked worker exited $rc: $(cat "$T/worker.err")"
wait_exit $direct 30
[ $rc -eq 0 ] || fail "the direct worker exited $rc: $(cat "$T/direct.err")"
grep -q 'flipped client byte' "$T/proxy.out" || fail "the proxy never flipped a byte (too few bytes passed?)"
same "$T/ref.exr" "$T/tamper.exr" "render with a tampered frame"
n=$(grep -c 'failed authentication' "$T/coord.err")
[ "$n" -eq 1 ] || fail "expected one connection closed for a failed record, saw $n: $(grep dropping "$T/coord.err")"
say "coordinator: $(grep 'failed authentication' "$T/coord.err")"
drops=$(grep -c 'dropping tuple-space connection' "$T/coord.err")
[ "$drops" -eq 1 ] || fail "other connections were dropped too: $(grep dropping "$T/coord.err")"
grep -q 'reconnecting to' "$T/worker.err" || fail "the networked worker did not reconnect: $(cat "$T/worker.err")"
grep -q 'reconnecting' "$T/direct.err" && fail "the direct worker lost its connection too: $(cat "$T/direct.err")"
# A line of the scene's text, as it travels in the scene tuple, must not be on the wire.
line=$(grep -v '^[#;]' "$SCENE" | grep '=' | head -1)
[ -n "$line" ] || fail "no scene line to look for"
if grep -qaF "$line" "$T/capture.bin"; then
    fail "the scene's text ('$line') crossed the wire in clear"
fi
[ "$(wc -c <"$T/capture.bin")" -gt 1000 ] || fail "the proxy captured almost nothing"
say "scene text ('$line') not in the $(wc -c <"$T/capture.bin") bytes the coordinator sent"
echo "farm_tamper: one tampered connection closed, the worker came back, image identical, scene unreadable on the wire"
