#!/bin/sh
# opencl_farm.sh: --backend opencl end to end (worker/backend_opencl.c).  The default scene at
# 160x90 rendered by forked OpenCL workers, and by a farm mixing a C and an OpenCL worker
# (both must take tasks), against the C backend's image.  The contract is a tolerance (PSNR
# >= 45 dB, sample counts equal for nearly all pixels: tests/unit/test_opencl.c measures it per
# pixel); here the images are compared byte for byte, which PoCL's CPU device must give (its bits
# are the C backend's), and on another device by the statistics' ray and sample counts within 1%;
# the networked OpenCL worker
# (one process) starts its device on a thread while it builds the terrain.  A scene with [terrain]
# smooth = yes, rendered by a networked OpenCL worker (which parses the scene's text and checks
# its hash, that of the canonical form, which names the key when on), against the C
# backend's smooth image, which must differ from the flat one.  Frames of a sequence whose sun
# moves, rendered by one OpenCL process, byte for byte the C backend's.  A bad --cl-device gives a
# one-line error from the worker.  Skipped (77) without an OpenCL platform.
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=160x90

say "probe: a tiny OpenCL render"
render -v -j 1 --size 16x9 --backend opencl -o "$T/probe.exr"; rc=$?
if [ $rc -ne 0 ]; then
    grep -q 'no OpenCL platform\|no OpenCL device' "$T/last.err" &&
        skip "no usable OpenCL platform: $(head -1 "$T/last.err")"
    fail "tiny OpenCL render exited $rc: $(cat "$T/last.err")"
fi
grep -q 'OpenCL device: ' "$T/last.err" || fail "-v names no OpenCL device: $(cat "$T/last.err")"
POCL_CPU=0   # PoCL's CPU device (pthread-...) gives the C backend's bits: nothing less is accepted
grep -q 'OpenCL device: pthread' "$T/last.err" && POCL_CPU=1

say "reference: C backend, -j 1, $SIZE"
render -q -j 1 --size $SIZE -o "$T/ref.exr" --stats "$T/ref.json" ||
    fail "C render: $(cat "$T/last.err")"

# close A.json B.exr WHAT B.json [A.exr]: B.exr identical to A.exr (default ref.exr), or rays
# and samples within 1%.
close() {
    ref=${5:-$T/ref.exr}
    if cmp -s "$ref" "$2"; then
        say "$3: byte-identical to the C backend's image"
        return 0
    fi
    if "$EXRCMP" "$ref" "$2" >/dev/null 2>&1; then   # another layout (rows:1: scanline)
        say "$3: pixels identical to the C backend's image"
        return 0
    fi
    [ $POCL_CPU = 0 ] || fail "$3: on PoCL's CPU device the image must be the C backend's, bit for bit"
    python3 - "$1" "$4" "$3" <<'PY' || fail "$3: statistics differ from the C backend's by more than 1%"
import json, sys
a, b = json.load(open(sys.argv[1])), json.load(open(sys.argv[2]))
for k in ("rays_total", "samples_per_pixel_avg"):
    if abs(a[k] - b[k]) > 0.01 * abs(a[k]):
        print("%s: %s %s vs C %s" % (sys.argv[3], k, b[k], a[k])); sys.exit(1)
print("-- %s: not byte-identical; rays and samples within 1%% of the C backend" % sys.argv[3])
PY
}

say "forked OpenCL workers: -j 2 --backend opencl"
render -q -j 2 --size $SIZE --backend opencl -o "$T/cl.exr" --stats "$T/cl.json" ||
    fail "OpenCL render: $(cat "$T/last.err")"
close "$T/ref.json" "$T/cl.exr" "-j 2 --backend opencl" "$T/cl.json"

say "mixed backends: a networked OpenCL worker and a networked C worker, one task per row"
# --wait-workers 2: nothing is dealt before both have joined, and a worker joins already asking
# for a task, so the first two tasks go one to each backend whoever is faster.
"$TF_BIN" render "$SCENE" -j 0 --wait-workers 2 --size $SIZE --tasks rows:1 --listen 127.0.0.1:0 -v \
    -o "$T/mixed.exr" --stats "$T/mixed.json" 2>"$T/coord.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/coord.err") || fail "coordinator printed no port: $(cat "$T/coord.err")"
"$TF_BIN" worker --connect 127.0.0.1:$port -j 1 --backend opencl -v 2>"$T/worker.err" &
wk=$!; e2e_track $wk
"$TF_BIN" worker --connect 127.0.0.1:$port -j 1 --backend c -q 2>"$T/cworker.err" &
cwk=$!; e2e_track $cwk
wait_exit $coord 120
[ $rc -eq 0 ] || fail "mixed render exited $rc: $(cat "$T/coord.err")"
wait_exit $wk 30
[ $rc -eq 0 ] || fail "OpenCL worker exited $rc: $(cat "$T/worker.err")"
wait_exit $cwk 30
[ $rc -eq 0 ] || fail "C worker exited $rc: $(cat "$T/cworker.err")"
close "$T/ref.json" "$T/mixed.exr" "C + OpenCL workers" "$T/mixed.json"
# one process: its device was started on a thread while it built the terrain, and rendered
grep -q 'starting the device while the terrain is built' "$T/worker.err" &&
    grep -q 'the device started while the terrain was built' "$T/worker.err" ||
    fail "the networked OpenCL worker did not start its device during the terrain build: $(grep -i opencl "$T/worker.err" | head -3)"
by=$(python3 -c 'import json,sys; w=json.load(open(sys.argv[1]))["workers"]; print(" ".join("%s:%d" % (b, sum(x["tasks"] for x in w if x["backend"]==b)) for b in ("c","opencl")))' "$T/mixed.json")
say "tasks by backend: $by"
case "$by" in *"c:0"*|*"opencl:0"*) fail "one backend rendered no task ($by): not a mixed render" ;; esac

say "[terrain] smooth = yes: a networked OpenCL worker, which parses the scene's text and checks its hash"
sed 's/^\[terrain\]/[terrain]\nsmooth = yes/' "$SCENE" >"$T/smooth.scene"
"$TF_BIN" render "$T/smooth.scene" -q -j 1 --size $SIZE --listen 127.0.0.1:0 -o "$T/smooth_c.exr" \
    --stats "$T/smooth_c.json" 2>"$T/smooth_c.err" || fail "smooth C render: $(cat "$T/smooth_c.err")"
"$EXRCMP" "$T/ref.exr" "$T/smooth_c.exr" >/dev/null 2>&1 && fail "smooth = yes rendered the flat image"
"$TF_BIN" render "$T/smooth.scene" -j 0 --wait-workers 1 --size $SIZE --listen 127.0.0.1:0 -v \
    -o "$T/smooth_cl.exr" --stats "$T/smooth_cl.json" 2>"$T/coord3.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/coord3.err") || fail "coordinator printed no port: $(cat "$T/coord3.err")"
"$TF_BIN" worker --connect 127.0.0.1:$port -j 1 --backend opencl -q 2>"$T/worker3.err" &
wk=$!; e2e_track $wk
wait_exit $coord 120
[ $rc -eq 0 ] || fail "smooth OpenCL render exited $rc: $(cat "$T/coord3.err")"
wait_exit $wk 30
[ $rc -eq 0 ] || fail "OpenCL worker exited $rc: $(cat "$T/worker3.err")"
close "$T/smooth_c.json" "$T/smooth_cl.exr" "smooth, networked OpenCL worker" "$T/smooth_cl.json" \
    "$T/smooth_c.exr"

say "a sequence whose sun moves: one OpenCL process renders frames 0, 45 and 90 of flyby.scene"
# One backend for the whole sequence (tf_cl_backend_set_scene per frame): the sun's strips
# (render/sun_strips.h) must follow the sun (230 deg at 24 deg high, then 258 at 9), or the kernels'
# shadow proofs use the first frame's table and the later frames differ from the C backend's.
sed 's/^size_exp .*/size_exp = 8/' "$TF_ROOT/scenes/flyby.scene" >"$T/fly.scene"
for backend in c opencl; do
    "$TF_BIN" render "$T/fly.scene" -q -j 1 --size 192x108 --frames 0-95:45 --backend $backend \
        --listen 127.0.0.1:0 -o "$T/fly_$backend/f.####.exr" --stats "$T/fly_$backend.json" \
        2>"$T/fly.err" || fail "flyby frames, --backend $backend: $(cat "$T/fly.err")"
done
# byte for byte: a stale table moves only ~1% of the rays, too few for close()'s tolerance
for k in 0000 0045 0090; do
    same "$T/fly_c/f.$k.exr" "$T/fly_opencl/f.$k.exr" "flyby frame $k, OpenCL against C"
done

say "a bad --cl-device: the worker refuses with one line"
"$TF_BIN" render "$SCENE" -j 0 --size $SIZE --listen 127.0.0.1:0 -o "$T/bad.exr" 2>"$T/coord2.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/coord2.err") || fail "coordinator printed no port: $(cat "$T/coord2.err")"
"$TF_BIN" worker --connect 127.0.0.1:$port -j 1 --backend opencl --cl-device no-such-gpu-xyzzy \
    2>"$T/bad.err"; rc=$?
refused $rc || fail "a worker with --cl-device no-such-gpu-xyzzy exited $rc"
grep -q 'no-such-gpu-xyzzy matches no OpenCL device' "$T/bad.err" ||
    fail "unexpected error: $(cat "$T/bad.err")"
say "worker error: $(grep xyzzy "$T/bad.err" | head -1)"

say "--backend auto without a usable device: a warning, the C backend, the same image"
TERRAFARM_CL_DEVICE=no-such-gpu-xyzzy "$TF_BIN" render "$SCENE" -j 1 --size $SIZE \
    --listen 127.0.0.1:0 --backend auto -o "$T/auto.exr" --stats "$T/auto.json" 2>"$T/auto.err" ||
    fail "--backend auto did not fall back: $(cat "$T/auto.err")"
grep -q 'OpenCL unavailable.*uses the C backend' "$T/auto.err" ||
    fail "no fallback warning: $(cat "$T/auto.err")"
"$TF_BIN" render "$SCENE" -j 1 --size $SIZE --listen 127.0.0.1:0 -o "$T/c.exr" 2>/dev/null ||
    fail "C render failed"
cmp -s "$T/c.exr" "$T/auto.exr" || fail "the fallback image differs from the C backend's"
say "$(grep 'OpenCL unavailable' "$T/auto.err")"
echo "opencl_farm: ok"
