#!/bin/sh
# resume_torn.sh: a torn final chunk (the file cut in the middle of a chunk, as a crash during
# a write or a lost page can leave it) is detected, dropped and rendered again: --resume
# reports only whole chunks as on disk and the result is byte-identical.  Also: the partial
# file is an OpenEXR file whose header tools read (exrheader) and whose whole chunks read back.
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=480x270
ARGS="-j 2 --size $SIZE --tasks rows:2"
PROBE_ARGS="--size $SIZE"
CHUNK=1   # scanlines per OpenEXR chunk (ZIPS compression, common/image/exrwrite.c)

render -q $ARGS -o "$T/ref.exr" || fail "reference render: $(cat "$T/last.err")"
full=$(wc -c <"$T/ref.exr")
make_partial "$T/p.exr" $((full * 6 / 10)) $ARGS
whole=$(rows_on_disk "$T/p.exr")
[ -n "$whole" ] && [ "$whole" -gt $((2 * CHUNK)) ] || fail "partial file: '$whole' rows on disk"
say "interrupted render: $whole of 270 rows in whole chunks, $(wc -c <"$T/p.exr") bytes"
if command -v exrheader >/dev/null 2>&1; then
    exrheader "$T/p.exr" >"$T/hdr.txt" 2>&1 || fail "exrheader cannot read the partial file's header"
    grep -q 'terrafarm' "$T/hdr.txt" || fail "no terrafarm attributes in the partial file's header"
    say "exrheader reads the partial file's header"
fi

# Walk the chunks (header attributes, offset table, then [y, size, data] per chunk) and cut
# the file in the middle of its last whole chunk; whatever the kill left after it goes too.
# Rows per chunk follow from the compression attribute (1 for none/RLE/ZIPS, 16 for ZIP, ...).
python3 - "$T/p.exr" 270 >"$T/cut.txt" <<'PY' || fail "cannot tear the file"
import os, struct, sys
p, height = sys.argv[1], int(sys.argv[2])
data = open(p, "rb").read()
pos, attrs = 8, {}                        # after magic and version
while data[pos] != 0:                     # attributes: name\0 type\0 size value
    end = data.index(b"\0", pos); name = data[pos:end]; pos = end + 1
    pos = data.index(b"\0", pos) + 1
    (n,) = struct.unpack_from("<i", data, pos)
    attrs[name] = data[pos + 4:pos + 4 + n]
    pos += 4 + n
lines = {0: 1, 1: 1, 2: 1, 3: 16, 4: 32, 5: 16, 6: 16, 7: 32, 8: 32, 9: 256}[attrs[b"compression"][0]]
pos += 1 + 8 * ((height + lines - 1) // lines)   # end of header, offset table
chunks = []
while pos + 8 <= len(data):
    y, n = struct.unpack_from("<ii", data, pos)
    if pos + 8 + n > len(data):
        break                             # torn by the kill
    chunks.append((pos, n, y))
    pos += 8 + n
start, n, y = chunks[-1]
with open(p, "r+b") as f:
    f.truncate(start + 8 + n // 2)
print(min(len(chunks) * lines, height), y, lines)
PY
read whole_chunks last_y lines <"$T/cut.txt"
say "the file had $whole_chunks rows in whole chunks of $lines rows; cut in the middle of the chunk at y=$last_y"
[ "$whole_chunks" -eq "$whole" ] || fail "the probe counted $whole rows, the chunk walk $whole_chunks"
torn=$(rows_on_disk "$T/p.exr")
say "after the cut: $torn rows in whole chunks"
[ "$torn" -eq $((whole - CHUNK)) ] || fail "expected the torn chunk dropped ($((whole - CHUNK)) rows), got $torn"

"$TF_BIN" render "$SCENE" $ARGS --resume --listen 127.0.0.1:0 -o "$T/p.exr" --stats "$T/s.json" \
    2>"$T/resume.err" || fail "resume of a torn file failed: $(cat "$T/resume.err")"
say "$(grep -o 'resuming .*' "$T/resume.err")"
[ "$(jstat rows_resumed "$T/s.json")" -eq "$torn" ] || fail "rows_resumed is not $torn"
[ "$(jstat rows_rendered "$T/s.json")" -eq $((270 - torn)) ] || fail "rows_rendered is not $((270 - torn))"
same "$T/ref.exr" "$T/p.exr" "resumed after a torn chunk"

say "a cut inside the header is refused, not trusted"
head -c 40 "$T/ref.exr" >"$T/h.exr"
if "$TF_BIN" render "$SCENE" $ARGS --resume --listen 127.0.0.1:0 -o "$T/h.exr" 2>"$T/h.err"; then
    fail "a file cut inside its header was resumed"
fi
say "$(cat "$T/h.err")"
echo "resume_torn: torn chunk dropped and re-rendered, image identical"
