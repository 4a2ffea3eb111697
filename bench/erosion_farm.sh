#!/bin/sh
# bench/erosion_farm.sh: fluvial erosion on the farm (docs/erosion.md) -- parallel efficiency of
# `terrafarm heightfield -j N` against one worker, and of networked workers across network
# namespaces, with the bytes of edges traded per step, on one grid.
#
# Alternates the configurations (1, 2, 4 forked workers, then 1 forked + 1 networked), REPS
# rounds, and prints each run's erosion seconds (the `erosion_seconds` statistic: from the moment
# every patch has a worker to the last band in, so it leaves out the terrain synthesis), the
# best of each, and efficiency = T1 / (min(N, cores) * TN): with more workers than cores (4 on
# 2) the workers are time-sliced and the best possible is the core count.  The networked run
# (root and `ip netns` needed, else skipped) puts the worker in its own namespace behind a
# veth cable, with a shared secret: the edges cross a real (virtual) network.  Every run's heights
# must equal the 1-worker run's (cmp), or the script fails.
#
# usage: bench/erosion_farm.sh [SIZE_EXP] [STEPS] [REPS]     (defaults 12 1000 2: 4097^2 x 1000)
#        bench/erosion_farm.sh --smoke                        (65^2 x 40, one round)
set -u
ROOT=$(cd "$(dirname "$0")/.." && pwd)
TF=${TF:-$ROOT/bin/terrafarm}
if [ "${1:-}" = --smoke ]; then E=6 STEPS=40 REPS=1; else E=${1:-12} STEPS=${2:-1000} REPS=${3:-2}; fi
CORES=$(nproc)
T=$(mktemp -d "${TMPDIR:-/tmp}/tf-erosion-bench.XXXXXX")
NS=tf-eb-$$
hf=""
# a networked run's coordinator (hf) waits for its worker for good: it goes with the script
cleanup() {
    [ -n "$hf" ] && kill "$hf" 2>/dev/null
    ip netns delete "$NS" 2>/dev/null; ip link delete "tfeb$$" 2>/dev/null; rm -rf "$T"
}
trap cleanup EXIT
# killed, the namespace and the cable must go too: a cable left holding 10.78.0.1 sends every
# later run's networked worker nowhere (netns_farm.sh does the same)
trap 'exit 130' INT
trap 'exit 143' TERM
export TF_EROSION_CACHE=off

sed -e "s/^size_exp .*/size_exp = $E/" "$ROOT/scenes/default.scene" >"$T/s.scene"
cat >>"$T/s.scene" <<EOF

[erosion]
fluvial_steps = $STEPS
rain = 0.02
rain_interval = 10
evaporation = 0.002
EOF

# the kernel's ISA, from a one-step erosion of a 65^2 grid (the measured grid would take a whole
# erosion's time just to say it)
sed -e "s/^size_exp .*/size_exp = 6/" -e "s/^fluvial_steps .*/fluvial_steps = 1/" "$T/s.scene" \
    >"$T/isa.scene"
echo "cpu: $(sed -n 's/^model name[^:]*: //p' /proc/cpuinfo | head -1); $CORES cores;" \
     "$("$TF" heightfield "$T/isa.scene" -o "$T/isa.exr" --stats "$T/isa.json" >/dev/null 2>&1 &&
        python3 -c 'import json,sys; print("erosion kernel:", json.load(open(sys.argv[1]))["isa"])' "$T/isa.json")"
echo "grid $(( (1 << E) + 1 ))^2, $STEPS steps, the default halo"

secs() { python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["erosion_seconds"])' "$1"; }
edge() { python3 -c 'import json,sys; print(int(json.load(open(sys.argv[1]))["edge_bytes_per_step"]))' "$1"; }

forked() { # N TAG
    "$TF" heightfield "$T/s.scene" -o "$T/$2.exr" -j "$1" --stats "$T/$2.json" >/dev/null 2>"$T/$2.err" ||
        { echo "FAIL: -j $1: $(tail -1 "$T/$2.err")"; exit 1; }
}

# networked TAG: one forked worker here, one networked worker in a namespace of its own.
NET=""
if [ "$(id -u)" -eq 0 ] && command -v ip >/dev/null 2>&1 && ip netns add "$NS" 2>/dev/null; then
    if ip link add "tfeb$$" type veth peer name eth0 netns "$NS" &&
        ip addr add 10.78.0.1/24 dev "tfeb$$" && ip link set "tfeb$$" up &&
        ip -n "$NS" addr add 10.78.0.2/24 dev eth0 && ip -n "$NS" link set eth0 up &&
        ip -n "$NS" link set lo up; then
        NET=yes
        head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$T/key"; chmod 600 "$T/key"
    fi
fi
networked() {
    port=$((20000 + $$ % 20000))
    "$TF" heightfield "$T/s.scene" -o "$T/$1.exr" -j 1 --remote 1 --listen 10.78.0.1:$port \
        --secret-file "$T/key" --stats "$T/$1.json" >/dev/null 2>"$T/$1.err" &
    hf=$!
    i=0; until grep -q 'expected at port' "$T/$1.err"; do
        i=$((i + 1)); [ $i -lt 600 ] || { echo "FAIL: networked: $(cat "$T/$1.err")"; exit 1; }; sleep 0.1
    done
    ip netns exec "$NS" "$TF" worker --connect 10.78.0.1:$port --secret-file "$T/key" 2>"$T/$1.w.err" ||
        { echo "FAIL: networked worker: $(tail -1 "$T/$1.w.err")"; exit 1; }
    wait $hf || { echo "FAIL: networked: $(tail -1 "$T/$1.err")"; exit 1; }
    hf=""
}

best1="" best2="" best4="" bestn=""
min() { python3 -c 'import sys; v=[float(x) for x in sys.argv[1:] if x]; print(min(v))' "$@"; }
rep=1
while [ $rep -le "$REPS" ]; do
    forked 1 w1; a=$(secs "$T/w1.json")
    forked 2 w2; b=$(secs "$T/w2.json")
    forked 4 w4; c=$(secs "$T/w4.json")
    for x in w2 w4; do cmp -s "$T/w1.exr" "$T/$x.exr" || { echo "FAIL: $x heights differ from 1 worker"; exit 1; }; done
    line="round $rep: 1 worker ${a}s, 2 workers ${b}s, 4 workers ${c}s"
    best1=$(min $a $best1) best2=$(min $b $best2) best4=$(min $c $best4)
    if [ -n "$NET" ]; then
        networked wn; d=$(secs "$T/wn.json")
        cmp -s "$T/w1.exr" "$T/wn.exr" || { echo "FAIL: networked heights differ"; exit 1; }
        line="$line, 1 forked + 1 networked ${d}s"
        bestn=$(min $d $bestn)
    fi
    echo "$line"
    rep=$((rep + 1))
done
vs=$(python3 -c "print('%.3f' % ($(( (1 << E) + 1 ))**2 * $STEPS / $best1 / 1e9))")
echo "1 worker: $vs G vertex-steps/s; edges traded: $(edge "$T/w2.json") bytes/step at 2 workers (2x1 patches), $(edge "$T/w4.json") at 4 (2x2)"
eff() { python3 -c "import sys; t1,tn,n,c=map(float,sys.argv[1:]); print('%.3f' % (t1/(min(n,c)*tn)))" "$best1" "$1" "$2" "$CORES"; }
echo "efficiency (best of $REPS): 2 forked $(eff "$best2" 2), 4 forked time-sliced on $CORES cores $(eff "$best4" 4)"
[ -n "$NET" ] && echo "efficiency: 1 forked + 1 networked (netns, sealed) $(eff "$bestn" 2)" ||
    echo "networked: skipped (needs root and ip netns)"
echo "erosion farm: every run's heights equal the 1-worker run's"
