#!/bin/sh
# farm_security.sh: docs/contract.md section 3, Security.
#  1. With --secret-file, a worker with the right secret renders while one with a wrong secret
#     is refused: it exits non-zero with a clear message; the coordinator logs "authentication
#     failed from ..."; the render completes, identical to the reference.
#  2. Garbage and oversized frames (tests/tools/garbage.py: random bytes, a 0xffffffff length,
#     an unknown op, a half frame then close, ...) sent to the port of a render in progress,
#     with and without a secret, each close only their own connection; the render completes
#     and its image is identical.
#  3. Secret files: one shorter than 16 bytes, and one readable by others, are refused by
#     both `render` and `worker` with one line naming the file, before anything starts.
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=480x270
GARBAGE="$TF_ROOT/tests/tools/garbage.py"

render -q -j 2 --size $SIZE --tasks rows:4 -o "$T/ref.exr" || fail "reference render: $(cat "$T/last.err")"
head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$T/good.key"
head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$T/bad.key"
chmod 600 "$T/good.key" "$T/bad.key"

say "1. --secret-file: a right and a wrong worker, plus garbage before authentication"
"$TF_BIN" render "$SCENE" -j 0 --size $SIZE --tasks rows:4 --secret-file "$T/good.key" \
    --listen 127.0.0.1:0 -o "$T/auth.exr" 2>"$T/auth.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/auth.err") || fail "coordinator printed no port: $(cat "$T/auth.err")"
grep -q 'secret required' "$T/auth.err" || fail "coordinator does not say a secret is required"
"$TF_BIN" worker --connect 127.0.0.1:$port --secret-file "$T/bad.key" -j 1 2>"$T/bad.err" &
bad=$!; e2e_track $bad
wait_exit $bad 20
refused $rc || fail "the worker with a wrong secret exited $rc"
say "wrong-secret worker exited $rc: $(tail -1 "$T/bad.err")"
grep -qi 'authentication failed\|secret' "$T/bad.err" || fail "unclear refusal: $(cat "$T/bad.err")"
python3 "$GARBAGE" 127.0.0.1 $port || fail "garbage before authentication was not dropped"
"$TF_BIN" worker --connect 127.0.0.1:$port --secret-file "$T/good.key" -j 1 -q 2>"$T/good.err" &
good=$!; e2e_track $good
wait_exit $coord 60
[ $rc -eq 0 ] || fail "render with a secret exited $rc: $(tail -5 "$T/auth.err")"
wait_exit $good 20
[ $rc -eq 0 ] || fail "right-secret worker exited $rc: $(cat "$T/good.err")"
grep -q 'authentication failed from ' "$T/auth.err" || fail "coordinator did not log the failed authentication"
say "coordinator: $(grep 'authentication failed from ' "$T/auth.err" | head -1)"
same "$T/ref.exr" "$T/auth.exr" "render with a refused worker and garbage"

say "2. garbage frames during a render (no secret: frames reach the decoder)"
# No forked worker: the render cannot end before the garbage is sent, however fast the machine;
# a networked worker joins after it and renders the image.
"$TF_BIN" render "$SCENE" -j 0 --size $SIZE --tasks rows:1 --listen 127.0.0.1:0 \
    -o "$T/garbage.exr" 2>"$T/garbage.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/garbage.err") || fail "coordinator printed no port: $(cat "$T/garbage.err")"
python3 "$GARBAGE" 127.0.0.1 $port || fail "some garbage connection was not dropped"
kill -0 $coord 2>/dev/null || fail "the render ended while the garbage was sent: $(tail -3 "$T/garbage.err")"
say "render still in progress after the garbage"
"$TF_BIN" worker --connect 127.0.0.1:$port -j 1 -q 2>"$T/gworker.err" &
gworker=$!; e2e_track $gworker
wait_exit $coord 60
[ $rc -eq 0 ] || fail "render under garbage exited $rc: $(tail -5 "$T/garbage.err")"
n=$(grep -c 'dropping tuple-space connection' "$T/garbage.err")
say "coordinator dropped $n bad connections"
[ "$n" -ge 6 ] || fail "expected at least 6 dropped connections: $(cat "$T/garbage.err")"
wait_exit $gworker 20
[ $rc -eq 0 ] || fail "the worker of the render under garbage exited $rc: $(cat "$T/gworker.err")"
same "$T/ref.exr" "$T/garbage.exr" "render under garbage"
say "3. weak secret files are refused"
printf 'short secret\n' >"$T/short.key"; chmod 600 "$T/short.key"
cp "$T/good.key" "$T/open.key"; chmod 644 "$T/open.key"
for k in short open; do
    for cmd in render worker; do
        if [ $cmd = render ]; then
            "$TF_BIN" render "$SCENE" -j 0 --size 32x18 --secret-file "$T/$k.key" \
                --listen 127.0.0.1:0 -o "$T/weak.exr" 2>"$T/weak.err" </dev/null
        else
            "$TF_BIN" worker --connect 127.0.0.1:9 --secret-file "$T/$k.key" -j 1 2>"$T/weak.err"
        fi
        rc=$?
        refused $rc || fail "$cmd accepted the $k secret file (exit $rc)"
        [ "$(wc -l <"$T/weak.err")" -eq 1 ] || fail "$cmd: refusal of the $k secret is not one line: $(cat "$T/weak.err")"
        grep -q "$T/$k.key" "$T/weak.err" || fail "$cmd: refusal does not name the file: $(cat "$T/weak.err")"
        say "$cmd, $k secret: $(cat "$T/weak.err")"
    done
done
[ ! -e "$T/weak.exr" ] || fail "a refused secret left an output file"
echo "farm_security: wrong secret refused, garbage dropped, weak secrets refused, renders intact"
