#!/bin/sh
# erosion_farm.sh: fluvial erosion ([erosion], terrain/erosion.h) on the farm and its cache.
#  - `terrafarm heightfield -j N` erodes on N forked workers (patches trading edges through the
#    tuple space): the heights are byte-identical to one process for N = 1, 2, 3, 4 (patch grids
#    1x1, 2x1, 3x1, 2x2) and for other halos; the statistics balance the mass exactly and say
#    erosion removed pits; the EXR holds channels Y, flow, silt and water;
#  - the eroded terrain is cached by the hash of [terrain] and [erosion]: a second run reads
#    it (no erosion), a changed key erodes again, a damaged entry is refused and rebuilt;
#  - a render erodes once (cache beside the output); a networked worker receives the eroded
#    terrain through the tuple space (it erodes nothing) and the image is identical;
#  - --backend opencl is refused for an eroded terrain (its kernels do not read the maps).
. "$(dirname "$0")/lib.sh"
e2e_init
SCENE=$T/e.scene
sed -e 's/^size_exp .*/size_exp = 7/' "$TF_ROOT/scenes/default.scene" >"$SCENE"
cat >>"$SCENE" <<'EOF'

[erosion]
fluvial_steps = 200
rain = 0.3
rain_interval = 20
creep = 0.01
evaporation = 0.002
strata = 5
hardness_noise = 0.3
rain_noise = 0.5
EOF
hf() { "$TF_BIN" heightfield "$SCENE" "$@" 2>"$T/hf.err" >"$T/hf.out"; }

say "one process (no cache): the reference"
TF_EROSION_CACHE=off hf -o "$T/ref.exr" --stats "$T/ref.json" || fail "heightfield: $(cat "$T/hf.err")"
grep -q 'erosion: 200 steps on 129x129' "$T/hf.err" || fail "no erosion logged: $(cat "$T/hf.err")"
for j in 1 2 3 4; do
    TF_EROSION_CACHE=off hf -o "$T/j$j.exr" -j $j --stats "$T/j$j.json" || fail "-j $j: $(cat "$T/hf.err")"
    grep -q "$j workers" "$T/hf.err" || fail "-j $j did not erode on $j workers: $(cat "$T/hf.err")"
    same "$T/ref.exr" "$T/j$j.exr" "heights eroded on $j workers"
done
if command -v exrheader >/dev/null 2>&1; then
    chans=$(exrheader "$T/ref.exr" | sed -n 's/^ *\([A-Za-z]*\), 32-bit floating-point.*/\1/p' | tr '\n' ' ')
    [ "$chans" = "Y flow silt water " ] || fail "the eroded EXR's channels: '$chans'"
    say "the EXR holds the heights and the maps: $chans"
fi
TF_EROSION_CACHE=off hf -o "$T/h3.exr" -j 2 --halo 3 || fail "--halo 3: $(cat "$T/hf.err")"
same "$T/ref.exr" "$T/h3.exr" "2 workers trading edges every 3 steps"

python3 - "$T/ref.json" "$T/j4.json" <<'PY' || fail "statistics"
import json, sys
for path in sys.argv[1:]:
    d = json.load(open(path))
    assert d["mass_balance_quanta"] == 0, (path, d["mass_balance_quanta"])
    assert d["erosion_vertex_steps_per_s"] > 0 and d["erosion_vertex_steps"] == 129 * 129 * 200
    assert d["rain_quanta"] > 0 and d["outflow_water_quanta"] > 0 and d["evaporated_quanta"] > 0
    assert d["pits_after"] < d["pits_before"], (d["pits_before"], d["pits_after"])
    assert d["from_cache"] is False
d = json.load(open(sys.argv[2]))
assert (d["workers"], d["patches_x"], d["patches_y"]) == (4, 2, 2), d
assert d["edge_bytes_per_step"] > 0
print("mass balance 0; pits %d -> %d; largest basin %.3f -> %.3f" % (d["pits_before"],
      d["pits_after"], d["largest_basin_share_before"], d["largest_basin_share_after"]))
PY

say "the cache beside the output"
hf -o "$T/c1.exr" -j 2 || fail "first cached run: $(cat "$T/hf.err")"
ls "$T"/.terrafarm-cache/*.eroded >/dev/null 2>&1 || fail "no cache entry beside the output"
hf -o "$T/c2.exr" --stats "$T/c2.json" || fail "second run: $(cat "$T/hf.err")"
grep -q 'erosion: reused' "$T/hf.err" || fail "the second run eroded again: $(cat "$T/hf.err")"
grep -q 'steps on' "$T/hf.err" && fail "the second run eroded: $(cat "$T/hf.err")"
[ "$(jstat from_cache "$T/c2.json")" = True ] || fail "from_cache is not true"
same "$T/ref.exr" "$T/c2.exr" "heights read from the cache"
sed -i 's/^creep = 0.01/creep = 0.02/' "$SCENE"
hf -o "$T/c3.exr" || fail "changed creep: $(cat "$T/hf.err")"
grep -q 'steps on' "$T/hf.err" || fail "a changed [erosion] key reused the cache: $(cat "$T/hf.err")"
cmp -s "$T/ref.exr" "$T/c3.exr" && fail "another creep gave the same heights"
sed -i 's/^creep = 0.02/creep = 0.01/' "$SCENE"
entry=$(ls "$T"/.terrafarm-cache/*.eroded | head -1)
for e in "$T"/.terrafarm-cache/*.eroded; do
    printf 'X' | dd of="$e" bs=1 seek=5000 conv=notrunc 2>/dev/null
done
hf -o "$T/c4.exr" || fail "damaged cache: $(cat "$T/hf.err")"
grep -q 'checksum does not match; eroding again' "$T/hf.err" ||
    fail "a damaged entry was not refused: $(cat "$T/hf.err")"
same "$T/ref.exr" "$T/c4.exr" "heights after a damaged cache entry"
say "damaged entry: $(grep checksum "$T/hf.err")"
[ -f "$entry" ] || fail "the entry was not rewritten"
# A NaN height, the checksum made to match it (as whoever sends a blob can): refused for its
# value, not trusted for its checksum, and eroded again (it hung the render before).
latest=$(ls -t "$T"/.terrafarm-cache/*.eroded | head -1) # the scene's own, just rewritten
python3 - "$latest" <<'PY' || fail "cannot spoil the cache entry"
import hashlib, struct, sys
b = bytearray(open(sys.argv[1], 'rb').read())
struct.pack_into('<f', b, 8 + 32 + 4 + 8 + 4 + 4 * 7, float('nan'))
b[-32:] = hashlib.sha256(bytes(b[:-32])).digest()
open(sys.argv[1], 'wb').write(b)
PY
hf -o "$T/c5.exr" || fail "an entry holding a NaN: $(cat "$T/hf.err")"
grep -q 'holds a height of nan at vertex (7, 0), which no erosion produces; eroding again' \
    "$T/hf.err" || fail "an entry holding a NaN was not refused: $(cat "$T/hf.err")"
same "$T/ref.exr" "$T/c5.exr" "heights after a cache entry holding a NaN"

say "a render erodes once; a networked worker receives the eroded terrain"
"$TF_BIN" render "$SCENE" -q -j 1 --size 160x90 --listen 127.0.0.1:0 -o "$T/r/forked.exr" \
    2>"$T/r1.err" || fail "render: $(cat "$T/r1.err")"
ls "$T"/r/.terrafarm-cache/*.eroded >/dev/null 2>&1 || fail "the render left no cache entry"
"$TF_BIN" render "$SCENE" -j 0 --wait-workers 1 --size 160x90 --listen 127.0.0.1:0 \
    -o "$T/r/net.exr" 2>"$T/coord.err" &
coord=$!; e2e_track $coord
port=$(e2e_port "$T/coord.err") || fail "coordinator printed no port: $(cat "$T/coord.err")"
"$TF_BIN" worker --connect 127.0.0.1:$port -j 1 2>"$T/worker.err" &
wk=$!; e2e_track $wk
wait_exit $coord 60
[ $rc -eq 0 ] || fail "networked render exited $rc: $(cat "$T/coord.err")"
wait_exit $wk 20
[ $rc -eq 0 ] || fail "networked worker exited $rc: $(cat "$T/worker.err")"
grep -q 'erosion: reused' "$T/coord.err" || fail "the coordinator eroded again: $(cat "$T/coord.err")"
grep -q 'erosion' "$T/worker.err" && fail "the networked worker eroded: $(cat "$T/worker.err")"
same_pixels "$T/r/forked.exr" "$T/r/net.exr" "a networked worker's render of the eroded terrain"

"$TF_BIN" render "$SCENE" -j 1 --backend opencl --size 160x90 --listen 127.0.0.1:0 \
    -o "$T/r/cl.exr" 2>"$T/cl.err"; rc=$?
refused $rc && grep -q 'cannot shade an eroded terrain' "$T/cl.err" ||
    fail "--backend opencl on an eroded terrain: exit $rc, $(cat "$T/cl.err")"
say "refused: $(cat "$T/cl.err")"

say "networked erosion workers: a real one, then a liar"
hf_remote() {
    : >"$T/hfr.err"
    TF_EROSION_CACHE=off "$TF_BIN" heightfield "$SCENE" -o "$1" -j 1 --remote 1 \
        --listen 127.0.0.1:0 2>"$T/hfr.err" >/dev/null &
    hfc=$!; e2e_track $hfc
    i=0
    while ! grep -q 'networked workers expected at port' "$T/hfr.err"; do
        sleep 0.1; i=$((i + 1)); [ $i -lt 200 ] || fail "no port: $(cat "$T/hfr.err")"
    done
    hport=$(sed -n 's/.*expected at port \([0-9]*\).*/\1/p' "$T/hfr.err")
}
hf_remote "$T/net.exr"
"$TF_BIN" worker --connect 127.0.0.1:$hport 2>"$T/ew.err" || fail "erosion worker: $(cat "$T/ew.err")"
wait_exit $hfc 60
[ $rc -eq 0 ] || fail "heightfield with a networked worker exited $rc: $(cat "$T/hfr.err")"
grep -q 'erosion of a 129x129 grid' "$T/ew.err" || fail "the worker did not erode: $(cat "$T/ew.err")"
same "$T/ref.exr" "$T/net.exr" "heights eroded by a forked and a networked worker"
hf_remote "$T/lie.exr"
python3 "$TF_ROOT/tests/tools/erosion_liar.py" 127.0.0.1 "$hport" >"$T/liar.out" 2>&1 ||
    fail "the liar was not refused: $(cat "$T/liar.out")"
wait_exit $hfc 60
refused $rc || fail "an erosion with a lying worker exited $rc"
grep -q "erosion failed on a worker: .*edge .* of round 0: erosion block of" "$T/hfr.err" ||
    fail "the short edge was not refused: $(cat "$T/hfr.err")"
[ -e "$T/lie.exr" ] && fail "a failed erosion wrote its output"
say "liar: $(grep -c '^refused' "$T/liar.out") requests refused; $(grep 'erosion failed' "$T/hfr.err")"
