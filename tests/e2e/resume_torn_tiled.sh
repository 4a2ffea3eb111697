#!/bin/sh
# resume_torn_tiled.sh: resume_torn.sh for a tiled output.  A render with --tasks stamps:64x48
# (a tiled OpenEXR file, tiles partial at the edges) is killed, its last whole tile is cut in
# the middle, and --resume drops exactly that tile, keeps every tile before it -- including the
# tiles of an incomplete tile row -- and finishes a byte-identical file.  exrheader reads the
# partial tiled file.
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=480x270
TASKS=stamps:64x48
ARGS="-j 2 --size $SIZE --tasks $TASKS"
PROBE_ARGS="--size $SIZE --tasks $TASKS"
TPR=8      # tiles per tile row: ceil(480 / 64)
TH=48

render -q $ARGS -o "$T/ref.exr" || fail "reference render: $(cat "$T/last.err")"
full=$(wc -c <"$T/ref.exr")
make_partial "$T/p.exr" $((full * 6 / 10)) $ARGS
set -- $(tiles_on_disk "$T/p.exr")
rows=$1 tiles=$2
[ -n "$rows" ] && [ "$rows" -gt 0 ] || fail "partial file: '$rows' rows on disk"
have=$((rows / TH * TPR + tiles))
say "interrupted render: $rows rows and $tiles more tiles on disk ($have tiles), $(wc -c <"$T/p.exr") bytes"
exrheader "$T/p.exr" >"$T/hdr.txt" 2>&1 || fail "exrheader cannot read the partial file's header"
grep -q 'tile size 64 by 48' "$T/hdr.txt" || fail "the partial file is not tiled 64x48"

# Walk the tile chunks (header, offset table of 48 tiles, then [tx, ty, lx, ly, size, data]
# each) and cut the file in the middle of its last whole tile.
python3 - "$T/p.exr" 48 >"$T/cut.txt" <<'PY' || fail "cannot tear the file"
import struct, sys
p, ntiles = sys.argv[1], int(sys.argv[2])
data = open(p, "rb").read()
pos = 8
while data[pos] != 0:
    pos = data.index(b"\0", pos) + 1
    pos = data.index(b"\0", pos) + 1
    (n,) = struct.unpack_from("<i", data, pos)
    pos += 4 + n
pos += 1 + 8 * ntiles
chunks = []
while pos + 20 <= len(data):
    tx, ty, lx, ly, n = struct.unpack_from("<iiiii", data, pos)
    if pos + 20 + n > len(data):
        break
    chunks.append((pos, n, tx, ty))
    pos += 20 + n
start, n, tx, ty = chunks[-1]
with open(p, "r+b") as f:
    f.truncate(start + 20 + n // 2)
print(len(chunks), tx, ty)
PY
read whole tx ty <"$T/cut.txt"
say "the file had $whole whole tiles; cut in the middle of tile ($tx, $ty)"
[ "$whole" -eq "$have" ] || fail "the probe counted $have tiles, the chunk walk $whole"
set -- $(tiles_on_disk "$T/p.exr")
left=$(($1 / TH * TPR + $2))
say "after the cut: $1 rows and $2 more tiles ($left tiles)"
[ "$left" -eq $((whole - 1)) ] || fail "expected only the torn tile dropped ($((whole - 1)) tiles), got $left"
[ "$2" -gt 0 ] || say "(the cut tile was the first of its tile row)"

"$TF_BIN" render "$SCENE" $ARGS --resume --listen 127.0.0.1:0 -o "$T/p.exr" --stats "$T/s.json" \
    2>"$T/resume.err" || fail "resume of a torn tiled file failed: $(cat "$T/resume.err")"
say "$(grep -o 'resuming .*' "$T/resume.err")"
[ "$(jstat rows_resumed "$T/s.json")" -eq "$1" ] || fail "rows_resumed is not $1"
tasks=$(jstat tasks_total "$T/s.json")
[ "$tasks" -eq $((TPR * 6 - left)) ] || fail "the resume dealt $tasks tasks, $((TPR * 6 - left)) tiles were missing"
same "$T/ref.exr" "$T/p.exr" "resumed after a torn tile"
echo "resume_torn_tiled: torn tile dropped, the tiles before it kept, image identical"
