#!/bin/sh
# tuplespace_vs_redis.sh: the tuple space as a task queue (one producer, N consumers, out/in over
# loopback) side by side with Redis doing the same work with LPUSH/BRPOP, in one run; prints both
# lines and the throughput ratio.  Starts a private redis-server on a free port in a temp dir
# and stops it afterwards.
# Usage: bench/tuplespace_vs_redis.sh [CONSUMERS] [TASKS]
#        bench/tuplespace_vs_redis.sh --smoke     (2 consumers, 200 tasks: for
#                                                 tests/e2e/bench_smoke.sh; no timing judged)
# Env: TF_BUILD (default build/) holds bench/bench_tuplespace, built here if it is missing.
# Exit status: 0 done, 77 redis-server or redis-cli not installed (make bench-deps), 1 error.
set -e
if [ "${1:-}" = --smoke ]; then N=2; T=200; else N=${1:-4}; T=${2:-20000}; fi
ROOT=$(cd "$(dirname "$0")/.." && pwd)
BUILD=${TF_BUILD:-$ROOT/build}
BENCH="$BUILD/bench/bench_tuplespace"
for peer in redis-server redis-cli; do
    command -v $peer >/dev/null 2>&1 || { echo "tuplespace_vs_redis: $peer not installed (make bench-deps): skipped"; exit 77; }
done
[ -x "$BENCH" ] || (cd "$ROOT" && make -s "build/bench/bench_tuplespace")
DIR=$(mktemp -d "${TMPDIR:-/tmp}/tf-redis.XXXXXX")
PORT=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
redis-server --port "$PORT" --bind 127.0.0.1 --dir "$DIR" --save "" --appendonly no \
    --daemonize yes --pidfile "$DIR/redis.pid" --logfile "$DIR/redis.log"
trap 'kill "$(cat "$DIR/redis.pid")" 2>/dev/null; rm -rf "$DIR"' EXIT
i=0
while ! redis-cli -p "$PORT" ping >/dev/null 2>&1; do
    i=$((i + 1)); [ $i -gt 50 ] && { echo "redis-server did not start" >&2; exit 1; }; sleep 0.1
done
TS=$("$BENCH" -n "$N" -t "$T")
RS=$("$BENCH" -n "$N" -t "$T" --redis "$PORT")
echo "$TS"
echo "$RS"
# ops_per_s of the run's "system=..." line (the program prints a "cpu=..." line before it)
ops() { echo "$1" | sed -n 's/^system=.* ops_per_s=\([0-9.]*\) .*/\1/p'; }
ts_ops=$(ops "$TS")
rs_ops=$(ops "$RS")
[ -n "$ts_ops" ] && [ -n "$rs_ops" ] || { echo "tuplespace_vs_redis: no ops_per_s in the output above" >&2; exit 1; }
python3 -c "print('tuplespace/redis throughput ratio: %.2f' % ($ts_ops / $rs_ops))"
