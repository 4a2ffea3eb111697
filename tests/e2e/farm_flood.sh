#!/bin/sh
# farm_flood.sh: bounded resources before authentication (docs/contract.md section 3).  While one
# real worker renders against a coordinator that requires a secret, tests/tools/flood.py keeps 100
# connections streaming a 64 MiB frame and thousands of idle connections open, and the test sends
# wrong-MAC handshakes from the same address.  The render must complete, identical to a clean one;
# the coordinator's peak RSS (--stats coordinator_max_rss_kb) must stay under 64 MB (1 GB under
# ASan) (on main it buffered every 64 MiB frame: 100 connections took it to gigabytes); the log
# stays short (rate-limited warnings); and repeated failed handshakes from one address are slowed
# down (fewer than 20 wrong tries get an answer in 4 s).
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=320x180
FLOOD="$TF_ROOT/tests/tools/flood.py"
RSS_LIMIT_KB=65536
# Under AddressSanitizer the freed-memory quarantine (256 MB) and shadow dominate the RSS: the
# bound is then 1 GB, still far below what unbounded pre-auth buffering takes (100 x 64 MiB).
if ldd "$TF_BIN" 2>/dev/null | grep -q libasan; then RSS_LIMIT_KB=1048576; fi

render -q -j 1 --size $SIZE --tasks rows:2 -o "$T/ref.exr" || fail "reference render: $(cat "$T/last.err")"
head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$T/farm.key"
head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$T/wrong.key"
chmod 600 "$T/farm.key" "$T/wrong.key"

"$TF_BIN" render "$SCENE" -j 0 --size $SIZE --tasks rows:2 --secret-file "$T/farm.key" \
    --listen 127.0.0.1:0 -o "$T/flood.exr" --stats "$T/flood.json" 2>"$T/coord.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/coord.err") || fail "coordinator printed no port: $(cat "$T/coord.err")"
# The attackers come from other loopback addresses than the real worker (127.0.0.1), as they
# would from other machines: per-address caps keep them from evicting its handshake.
python3 "$FLOOD" 127.0.0.1 "$port" 12 127.0.0.2 >"$T/flood.out" 2>&1 &
flood=$!; e2e_track $flood
i=0 # the flood announces itself once its oversized connections stream (no fixed sleep)
until grep -q "under way" "$T/flood.out" 2>/dev/null; do
    kill -0 $flood 2>/dev/null || fail "the flood ended before it began: $(cat "$T/flood.out")"
    i=$((i + 1))
    [ $i -le 600 ] || fail "the flood did not get under way in 60 s: $(cat "$T/flood.out")"
    sleep 0.1
done
say "wrong-secret handshakes, one after the other, for 4 s"
TF_ROOT="$TF_ROOT" python3 - "$port" "$T/wrong.key" >"$T/guess.out" 2>&1 <<'PY' || fail "guessing client: $(cat "$T/guess.out")"
import os, sys, time
sys.path.insert(0, os.path.join(os.environ["TF_ROOT"], "tests", "tools"))
import tfwire
answered = 0
end = time.time() + 4
while time.time() < end:
    try:
        tfwire.Conn("127.0.0.1", int(sys.argv[1]), sys.argv[2], timeout=2, source="127.0.0.3")
    except SystemExit:
        answered += 1      # got an answer: the handshake was judged
    except (EOFError, OSError):
        time.sleep(0.01)   # closed before any handshake: the address must wait
print(answered)
PY
tries=$(tail -1 "$T/guess.out")
say "$tries wrong handshakes were answered in 4 s"
[ "$tries" -lt 20 ] || fail "failed handshakes are not slowed down: $tries answered in 4 s"
say "the real worker joins while the flood goes on"
"$TF_BIN" worker --connect 127.0.0.1:$port --secret-file "$T/farm.key" -j 1 -q --timeout 60000 2>"$T/worker.err" &
worker=$!; e2e_track $worker
wait_exit $coord 90
[ $rc -eq 0 ] || fail "render under flood exited $rc: $(tail -5 "$T/coord.err")"
wait_exit $worker 20
[ $rc -eq 0 ] || fail "the real worker exited $rc: $(cat "$T/worker.err")"
wait_exit $flood 30
say "$(cat "$T/flood.out")"
same "$T/ref.exr" "$T/flood.exr" "render under flood"
rss=$(jstat coordinator_max_rss_kb "$T/flood.json")
say "coordinator peak RSS $rss kB (limit $RSS_LIMIT_KB kB)"
[ "$rss" -lt $RSS_LIMIT_KB ] || fail "coordinator memory not bounded: $rss kB"
lines=$(wc -l <"$T/coord.err")
say "coordinator log: $lines lines"
[ "$lines" -lt 400 ] || fail "the log is flooded: $lines lines; $(sort "$T/coord.err" | uniq -c | sort -rn | head -5)"
echo "farm_flood: render intact under pre-auth floods, RSS $rss kB, $lines log lines, $tries guesses answered"
