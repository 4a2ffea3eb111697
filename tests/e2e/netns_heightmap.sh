#!/bin/sh
# netns_heightmap.sh: a networked worker that cannot see the coordinator's files renders a
# generator = file (GeoTIFF) scene: the height map reaches it through the tuple space only.
#
# Two "machines": network namespaces tf-PID-hc (coordinator, 10.78.0.1) and tf-PID-hw (worker,
# 10.78.0.2) joined by a veth cable.  The worker also runs in its own mount namespace with an
# empty tmpfs mounted over the coordinator's directory (the scene and the GeoTIFF): it checks
# that it cannot see them, then joins.  The image must equal (cmp) a local render of the same
# scene, and its pixels the procedural scene the height map was exported from (exrcmp).
# Needs root, `ip netns` and `unshare`; otherwise exits 77 with the reason.
set -u
ROOT=${TF_ROOT:-$(cd "$(dirname "$0")/../.." && pwd)}
TF=${TF_BIN:-$ROOT/bin/terrafarm}
EXRCMP=${TF_BUILD:-$ROOT/build}/tools/exrcmp
SCENE=$ROOT/scenes/default.scene
SIZE=240x135
PORT=7878 # inside a private network namespace: no collision with anything else
LIMIT=60
NS_C=tf-$$-hc
NS_W=tf-$$-hw

skip() { echo "skipped: $*"; exit 77; }
fail() { echo "FAIL: $*"; exit 1; }
note() { echo "netns_heightmap: $*"; }

[ "$(id -u)" -eq 0 ] || skip "needs root to create network and mount namespaces"
command -v ip >/dev/null 2>&1 || skip "ip (iproute2) is not installed"
command -v unshare >/dev/null 2>&1 || skip "unshare (util-linux) is not installed"
[ -x "$TF" ] || fail "$TF is not built (run make)"
[ -x "$EXRCMP" ] || skip "no $EXRCMP (run make test)"

PIDS="" NAMESPACES="" CDIR="" WDIR=""
cleanup() {
    for pid in $PIDS; do kill "$pid" 2>/dev/null; done
    for pid in $PIDS; do wait "$pid" 2>/dev/null; done
    for ns in $NAMESPACES; do ip netns delete "$ns" 2>/dev/null; done
    [ -n "$CDIR" ] && rm -rf "$CDIR"
    [ -n "$WDIR" ] && rm -rf "$WDIR"
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

CDIR=$(mktemp -d "${TMPDIR:-/tmp}/tf-hm-coord.XXXXXX") || fail "mktemp"
WDIR=$(mktemp -d "${TMPDIR:-/tmp}/tf-hm-worker.XXXXXX") || fail "mktemp"
for ns in "$NS_C" "$NS_W"; do
    ip netns add "$ns" 2>"$WDIR/ip.err" || skip "ip netns add failed: $(head -1 "$WDIR/ip.err")"
    NAMESPACES="$NAMESPACES $ns"
    ip -n "$ns" link set lo up || fail "lo in $ns"
done
ip -n "$NS_C" link add eth0 type veth peer name eth0 netns "$NS_W" || fail "veth"
if ! { ip -n "$NS_C" addr add 10.78.0.1/24 dev eth0 && ip -n "$NS_C" link set eth0 up &&
    ip -n "$NS_W" addr add 10.78.0.2/24 dev eth0 && ip -n "$NS_W" link set eth0 up; }; then
    fail "cannot address the cable"
fi

umask 077
head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$CDIR/secret"
cp "$CDIR/secret" "$WDIR/secret"
# the coordinator's scene: default.scene's terrain as a georeferenced GeoTIFF beside it
"$TF" heightfield "$SCENE" -o "$CDIR/dem.tif" --srs EPSG:32632 --origin 400000,5100000 \
    >/dev/null || fail "export"
{ sed -n '1,/^\[terrain\]/p' "$SCENE"; printf 'generator = file\nseed = 1\npath = dem.tif\n\n'
  sed -n '/^\[materials\]/,$p' "$SCENE"; } >"$CDIR/dem.scene"

# --wait-workers 2: the worker's two processes both join before any task is dealt (the first
# could otherwise finish alone, and the second, finding no coordinator, fail the worker)
ip netns exec "$NS_C" timeout $LIMIT "$TF" render "$CDIR/dem.scene" --size $SIZE -j 0 --wait-workers 2 \
    --listen 10.78.0.1:$PORT --secret-file "$CDIR/secret" -o "$CDIR/net.exr" >"$WDIR/coord.log" 2>&1 &
COORD=$!
PIDS="$PIDS $COORD"
i=0
until grep -q "may join at" "$WDIR/coord.log"; do
    kill -0 $COORD 2>/dev/null || { cat "$WDIR/coord.log"; fail "coordinator exited"; }
    i=$((i + 1)); [ $i -le 200 ] || fail "coordinator not listening after 20 s"
    sleep 0.1
done
# the worker: its own mount namespace, the coordinator's directory covered by an empty tmpfs
# shellcheck disable=SC2016 # the inner script expands its own arguments
ip netns exec "$NS_W" unshare --mount --propagation private sh -c '
    mount -t tmpfs none "$1" || exit 90
    if [ -e "$1/dem.tif" ] || [ -e "$1/dem.scene" ]; then exit 91; fi
    cd / && exec timeout "$2" "$3" worker --connect "$5" --secret-file "$4" -j 2
' sh "$CDIR" "$LIMIT" "$TF" "$WDIR/secret" "10.78.0.1:$PORT" >"$WDIR/worker.log" 2>&1
rc=$?
[ $rc -eq 90 ] && skip "cannot mount a tmpfs in a private mount namespace"
[ $rc -eq 91 ] && fail "the worker could still see the coordinator's files"
[ $rc -eq 0 ] || { cat "$WDIR/worker.log"; fail "worker exited with $rc"; }
wait $COORD; crc=$?
PIDS=""
[ $crc -eq 0 ] || { cat "$WDIR/coord.log"; fail "coordinator exited with $crc"; }
grep -q "file terrain" "$WDIR/worker.log" || fail "the worker did not build a file terrain"
note "worker (no access to $CDIR) joined: $(head -1 "$WDIR/worker.log")"

"$TF" render "$CDIR/dem.scene" --size $SIZE -j 2 -q -o "$CDIR/local.exr" || fail "local render"
cmp "$CDIR/local.exr" "$CDIR/net.exr" || fail "the networked DEM render differs from the local one"
note "networked render of the GeoTIFF scene identical to the local render (cmp)"
"$TF" render "$SCENE" --size $SIZE -j 2 -q -o "$CDIR/procedural.exr" || fail "procedural render"
"$EXRCMP" "$CDIR/procedural.exr" "$CDIR/net.exr" >"$WDIR/cmp" ||
    fail "the networked DEM render's pixels differ from the procedural scene's: $(cat "$WDIR/cmp")"
note "and pixel-identical to the procedural scene it was exported from ($(cat "$WDIR/cmp"))"
echo "netns_heightmap: ok"
