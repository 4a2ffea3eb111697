#!/bin/sh
# heightmap_reimport.sh: what terrafarm heightfield writes comes back with only
# `generator = file` and `path =` in a scene's [terrain] (no `seed`: the file generator does
# not need one): each export (float EXR, 16-bit PNG,
# Float32 GeoTIFF) records its first row's edge, its extent and its vertical scale and offset,
# and the re-imported terrain has the original's heights (bit for bit from EXR and GeoTIFF,
# within half a 16-bit step from PNG) and extent.  Scene keys, when given, win over the file's.
# A file whose terrafarm.* metadata is malformed fails with one line naming file and key.
. "$(dirname "$0")/lib.sh"
e2e_init
HFCMP=${TF_BUILD:-$TF_ROOT/build}/tools/hfcmp
[ -x "$HFCMP" ] || skip "no $HFCMP (run make test)"
mkdir -p "$T/maps"

# scene NAME TERRAIN-LINES...: the default scene with its [terrain] block replaced.
scene() {
    sc_out=$T/$1.scene; shift
    { sed -n '1,/^\[terrain\]/p' "$SCENE"; printf '%s\n' "$@"; echo
      sed -n '/^\[materials\]/,$p' "$SCENE"; } >"$sc_out"
}
# export SCENE FILE: terrafarm heightfield, its report kept in FILE.txt
export_hf() {
    "$TF_BIN" heightfield "$1" -o "$2" >"$2.txt" 2>&1 || fail "export to $2: $(cat "$2.txt")"
}
extent_of() { sed -n 's/^world extent: .*\[0, \(.*\)\]$/\1/p' "$1.txt"; }

for f in exr png tif; do export_hf "$SCENE" "$T/maps/hf.$f"; done
lo=$(sed -n 's/^height range: \[\([^,]*\), \([^]]*\)\].*/\1/p' "$T/maps/hf.png.txt")
hi=$(sed -n 's/^height range: \[\([^,]*\), \([^]]*\)\].*/\2/p' "$T/maps/hf.png.txt")
half_step=$(python3 -c "print(($hi - ($lo)) / 65535 / 2 * 1.001)")

for f in exr tif png; do
    scene re_$f "generator = file" "path = maps/hf.$f"
    export_hf "$T/re_$f.scene" "$T/re_$f.exr"
    [ "$(extent_of "$T/re_$f.exr")" = "$(extent_of "$T/maps/hf.exr")" ] ||
        fail "$f: re-imported extent $(extent_of "$T/re_$f.exr"), not $(extent_of "$T/maps/hf.exr")"
    if [ $f = png ]; then
        "$HFCMP" "$T/maps/hf.exr" "$T/re_$f.exr" --within "$half_step" >"$T/cmp" ||
            fail "$f: re-imported heights differ by more than half a step: $(cat "$T/cmp")"
    else
        "$HFCMP" "$T/maps/hf.exr" "$T/re_$f.exr" >"$T/cmp" ||
            fail "$f: re-imported heights differ: $(cat "$T/cmp")"
    fi
    say "$f: re-imported with only path: the original heights and extent ($(cat "$T/cmp"))"
done

# scene keys win: first_row = north reads the EXR upside down, extent = 500 is the extent
scene keys "generator = file" "seed = 1" "path = maps/hf.exr" "first_row = north" "extent = 500"
export_hf "$T/keys.scene" "$T/keys.exr"
[ "$(extent_of "$T/keys.exr")" = 500 ] || fail "the scene's extent = 500 lost to the file's"
"$HFCMP" "$T/maps/hf.exr" "$T/keys.exr" >"$T/cmp" && fail "the scene's first_row = north lost"
say "the scene's first_row and extent win over the file's"

# malformed metadata: one line naming the file and the key
python3 - "$T/maps/hf.png" "$T/maps/bad.png" <<'PY'
import struct, sys, zlib
d = open(sys.argv[1], 'rb').read()
out, i = d[:8], 8
while i < len(d):
    n, kind = struct.unpack('>I4s', d[i:i + 8])
    chunk = d[i:i + 12 + n]
    if kind == b'tEXt' and d[i + 8:i + 8 + n].startswith(b'terrafarm.extent\0'):
        body = b'tEXt' + b'terrafarm.extent\0-12'
        chunk = struct.pack('>I', len(body) - 4) + body + struct.pack('>I', zlib.crc32(body))
    out += chunk
    i += 12 + n
open(sys.argv[2], 'wb').write(out)
PY
scene bad "generator = file" "seed = 1" "path = maps/bad.png"
"$TF_BIN" heightfield "$T/bad.scene" -o "$T/bad.exr" >"$T/bad.out" 2>&1 &&
    fail "a PNG with terrafarm.extent = -12 was accepted"
grep -q "bad.png: terrafarm.extent: '-12' is not a number" "$T/bad.out" ||
    fail "malformed metadata: not the expected message: $(cat "$T/bad.out")"
[ "$(wc -l <"$T/bad.out")" -eq 1 ] || fail "malformed metadata: more than one line: $(cat "$T/bad.out")"
say "malformed metadata: $(cat "$T/bad.out")"
