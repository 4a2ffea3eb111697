#!/bin/sh
# heightmap_file.sh: generator = file end to end.
#  - terrafarm's own terrain, exported as a float EXR, a Float32 GeoTIFF (georeferenced, UTM)
#    and a 16-bit PNG, renders the same image as the procedural scene it came from:
#    bit-identical pixels from EXR and GeoTIFF, within 16-bit quantisation from PNG (and not
#    within it when the PNG's rows are read the wrong way up: the comparison can fail);
#  - a relative path is relative to the scene file, not the working directory;
#  - --resume refuses when the height map file changed under an unchanged scene text;
#  - missing, empty, not-a-raster, corrupt, truncated, huge-dimension, nodata-only and
#    non-square height maps each fail with one line naming the file;
#  - GDAL is loaded only when a GeoTIFF (or another GDAL format) is read or written: the
#    program does not link it, renders EXR and PNG maps without it, and where it cannot be
#    loaded (TERRAFARM_GDAL names a library that is not there) a GeoTIFF read or write fails
#    with one line naming the library, and writes nothing.
. "$(dirname "$0")/lib.sh"
e2e_init
command -v gdal_create >/dev/null 2>&1 || skip "gdal-bin is not installed (make deps)"
EXRCMP=${TF_BUILD:-$TF_ROOT/build}/tools/exrcmp
[ -x "$EXRCMP" ] || skip "no $EXRCMP (run make test)"
SIZE=200x112
mkdir -p "$T/maps" "$T/elsewhere"

# scene NAME TERRAIN-LINES...: the default scene with its [terrain] block replaced.
scene() {
    sc_out=$T/$1.scene; shift
    { sed -n '1,/^\[terrain\]/p' "$SCENE"; printf '%s\n' "$@"; echo
      sed -n '/^\[materials\]/,$p' "$SCENE"; } >"$sc_out"
}

"$TF_BIN" render "$SCENE" --listen 127.0.0.1:0 -j 2 --size $SIZE -q -o "$T/ref.exr" ||
    fail "procedural reference render failed"
"$TF_BIN" heightfield "$SCENE" -o "$T/maps/hf.exr" >/dev/null || fail "export to EXR failed"
"$TF_BIN" heightfield "$SCENE" -o "$T/maps/hf.tif" --srs EPSG:32632 --origin 400000,5100000 \
    >/dev/null || fail "export to GeoTIFF failed"
"$TF_BIN" heightfield "$SCENE" -o "$T/maps/hf.png" >"$T/png.txt" || fail "export to PNG failed"
lo=$(sed -n 's/^height range: \[\([^,]*\), \([^]]*\)\].*/\1/p' "$T/png.txt")
hi=$(sed -n 's/^height range: \[\([^,]*\), \([^]]*\)\].*/\2/p' "$T/png.txt")
vscale=$(python3 -c "print(($hi - ($lo)) / 65535)")
gdalinfo "$T/maps/hf.tif" | grep -q 'UTM zone 32N' || fail "the GeoTIFF has no CRS"

# render NAME: render $T/NAME.scene from another directory (relative paths: the scene's folder)
render_scene() {
    (cd "$T/elsewhere" && "$TF_BIN" render "../$1.scene" --listen 127.0.0.1:0 -j 2 --size $SIZE \
        -q -o "$T/$1.exr" 2>"$T/$1.err") || fail "$1: render failed: $(cat "$T/$1.err")"
}
scene exr "generator = file" "seed = 1" "path = maps/hf.exr" "first_row = south" "extent = 1000"
scene tif "generator = file" "seed = 1" "path = maps/hf.tif"
scene png "generator = file" "seed = 1" "path = maps/hf.png" "first_row = south" \
    "extent = 1000" "vertical_scale = $vscale" "vertical_offset = $lo"
scene pngflip "generator = file" "seed = 1" "path = maps/hf.png" "first_row = north" \
    "extent = 1000" "vertical_scale = $vscale" "vertical_offset = $lo"
for s in exr tif png pngflip; do render_scene $s; done
"$EXRCMP" "$T/ref.exr" "$T/exr.exr" >"$T/cmp" || fail "EXR height map: pixels differ: $(cat "$T/cmp")"
say "float EXR height map: bit-identical to the procedural render ($(cat "$T/cmp"))"
"$EXRCMP" "$T/ref.exr" "$T/tif.exr" >"$T/cmp" || fail "GeoTIFF height map: pixels differ: $(cat "$T/cmp")"
say "Float32 GeoTIFF (UTM, extent from the georeferencing): bit-identical ($(cat "$T/cmp"))"
# 16-bit codes move heights by up to half a step (~0.002 m here): a few silhouette pixels flip
"$EXRCMP" "$T/ref.exr" "$T/png.exr" --close 0.005 0.0005 >"$T/cmp" ||
    fail "16-bit PNG height map: beyond quantisation: $(cat "$T/cmp")"
say "16-bit PNG height map: within quantisation ($(cat "$T/cmp"))"
if "$EXRCMP" "$T/ref.exr" "$T/pngflip.exr" --close 0.005 0.0005 >"$T/cmp"; then
    fail "a PNG read upside down passed the comparison: $(cat "$T/cmp")"
fi
say "the same PNG read north-first fails the comparison ($(cat "$T/cmp"))"

# --resume refuses a changed height map (same scene text, different file bytes)
cp "$T/tif.exr" "$T/done.exr"
sed 's/^seed *=.*/seed = 2/' "$SCENE" >"$T/seed2.scene"
"$TF_BIN" heightfield "$T/seed2.scene" -o "$T/maps/hf.tif" --srs EPSG:32632 \
    --origin 400000,5100000 >/dev/null || fail "second export failed"
if "$TF_BIN" render "$T/tif.scene" --listen 127.0.0.1:0 -j 2 --size $SIZE -q -o "$T/done.exr" \
    --resume 2>"$T/resume.err"; then
    fail "--resume accepted a changed height map"
fi
grep -q "scene changed" "$T/resume.err" || fail "--resume: unexpected message: $(cat "$T/resume.err")"
say "--resume with a changed height map refused: $(cat "$T/resume.err")"

# bad NAME WORDS FILE-SETUP: a scene whose height map is broken must fail with one line that
# names the file and says WORDS.
bad() {
    name=$1 words=$2 file=$3
    scene "bad_$name" "generator = file" "seed = 1" "path = maps/$file"
    if "$TF_BIN" render "$T/bad_$name.scene" --listen 127.0.0.1:0 -j 1 --size 32x18 -q \
        -o "$T/bad.exr" --overwrite 2>"$T/bad.err"; then
        fail "$name: accepted"
    fi
    [ "$(grep -c . "$T/bad.err")" -eq 1 ] || fail "$name: not one line: $(cat "$T/bad.err")"
    grep -q "maps/$file" "$T/bad.err" || fail "$name: message does not name the file: $(cat "$T/bad.err")"
    grep -qi -e "$words" "$T/bad.err" || fail "$name: message does not say '$words': $(cat "$T/bad.err")"
    say "$name: $(cat "$T/bad.err")"
}
bad missing "cannot open" nothere.tif
: >"$T/maps/empty.tif"; bad empty "empty" empty.tif
# one byte over the 512 MiB a scene's height map may have (sparse: no disk, read once)
truncate -s $(( (512 << 20) + 1 )) "$T/maps/over.tif"; bad over_512mib "too large" over.tif
rm -f "$T/maps/over.tif"
echo "this is not a raster" >"$T/maps/text.tif"; bad not_a_raster "not a raster" text.tif
# A coordinator without local workers (-j 0, a farm's render) decodes the map once before any
# worker joins: a bad one is a bad scene, status 2, which a farm takes as final (no retries).
"$TF_BIN" render "$T/bad_not_a_raster.scene" --listen 127.0.0.1:0 -j 0 --size 32x18 -q \
    -o "$T/bad0.exr" 2>"$T/bad0.err"
rc=$?
[ $rc -eq 2 ] || fail "-j 0 with a map that is no raster: status $rc, not 2: $(cat "$T/bad0.err")"
grep -q "not a raster" "$T/bad0.err" || fail "-j 0: $(cat "$T/bad0.err")"
python3 -c "import os,sys; sys.stdout.buffer.write(b'II*\x00' + os.urandom(4000))" \
    >"$T/maps/garbage.tif"; bad corrupt "not a raster\|corrupt" garbage.tif
head -c 3000 "$T/maps/hf.png" >"$T/maps/cut.png"; bad truncated_png "truncated\|not a readable PNG" cut.png
gdal_translate -q -co COMPRESS=DEFLATE "$T/maps/hf.tif" "$T/maps/whole.tif" || fail "gdal_translate"
head -c $(( $(wc -c <"$T/maps/whole.tif") / 2 )) "$T/maps/whole.tif" >"$T/maps/cut.tif"
bad truncated_tif "corrupt or truncated\|not a raster" cut.tif
head -c 2000 "$T/maps/hf.exr" >"$T/maps/cut.exr"; bad truncated_exr "OpenEXR" cut.exr
# a PNG header declaring 100000 x 100000 16-bit pixels, with a valid CRC
python3 - "$T/maps/huge.png" <<'PY'
import struct, sys, zlib
def chunk(kind, data):
    return struct.pack('>I', len(data)) + kind + data + struct.pack('>I', zlib.crc32(kind + data))
ihdr = struct.pack('>IIBBBBB', 100000, 100000, 16, 0, 0, 0, 0)
open(sys.argv[1], 'wb').write(b'\x89PNG\r\n\x1a\n' + chunk(b'IHDR', ihdr) +
    chunk(b'IDAT', zlib.compress(b'\0' * 1000)) + chunk(b'IEND', b''))
PY
bad huge_png "too large\|exceeds" huge.png
gdal_create -q -of GTiff -outsize 70000 70000 -ot Byte -co SPARSE_OK=TRUE "$T/maps/huge.tif" 2>/dev/null ||
    gdal_create -of GTiff -outsize 70000 70000 -ot Byte -co SPARSE_OK=TRUE "$T/maps/huge.tif" >/dev/null
bad huge_tif "too large" huge.tif
gdal_create -of GTiff -outsize 33 33 -ot Float32 -burn -9999 -a_nodata -9999 \
    "$T/maps/nodata.tif" >/dev/null || fail "gdal_create"
bad nodata_only "no data" nodata.tif
# a coordinator without local workers (-j 0) still decodes the map once: one line, at once
if timeout 20 "$TF_BIN" render "$T/bad_nodata_only.scene" --listen 127.0.0.1:0 -j 0 -q \
    -o "$T/bad.exr" --overwrite 2>"$T/bad.err"; then
    fail "-j 0: a nodata-only height map was accepted"
fi
[ "$(grep -c . "$T/bad.err")" -eq 1 ] && grep -q "maps/nodata.tif: no data" "$T/bad.err" ||
    fail "-j 0: expected one line about maps/nodata.tif: $(cat "$T/bad.err")"
say "-j 0 (networked workers only): $(cat "$T/bad.err")"
gdal_create -of GTiff -outsize 65 33 -ot Float32 -burn 5 "$T/maps/wide.tif" >/dev/null
bad not_square "not a square" wide.tif

# GDAL on demand: not among the program's libraries; without it, EXR still renders, a GeoTIFF
# fails with one line that names the library.
readelf -d "$TF_BIN" | grep NEEDED | grep -q libgdal &&
    fail "bin/terrafarm is linked against libgdal"
export TERRAFARM_GDAL=$T/no-such-libgdal.so
render_scene exr
"$EXRCMP" "$T/ref.exr" "$T/exr.exr" >"$T/cmp" ||
    fail "EXR map without GDAL: pixels differ: $(cat "$T/cmp")"
bad no_gdal "no-such-libgdal.so" whole.tif
grep -q "cannot be loaded" "$T/bad.err" || fail "no GDAL: unexpected message: $(cat "$T/bad.err")"
if "$TF_BIN" heightfield "$SCENE" -o "$T/maps/nogdal.tif" >/dev/null 2>"$T/nogdal.err"; then
    fail "a GeoTIFF export without GDAL succeeded"
fi
[ "$(grep -c . "$T/nogdal.err")" -eq 1 ] &&
    grep -q "nogdal.tif: a GeoTIFF is written by GDAL, and GDAL cannot be loaded" "$T/nogdal.err" || fail "export without GDAL: expected one line: $(cat "$T/nogdal.err")"
[ ! -e "$T/maps/nogdal.tif" ] || fail "export without GDAL left a file behind"
say "without GDAL: EXR maps render, GeoTIFF export fails: $(cat "$T/nogdal.err")"
unset TERRAFARM_GDAL
exit 0
