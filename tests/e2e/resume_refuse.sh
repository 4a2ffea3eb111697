#!/bin/sh
# resume_refuse.sh: what --resume, --overwrite and a plain render do with what is at the output.
#  - a changed scene, size or render setting (renderer version, --pixel) or a --tasks whose file
#    layout differs (tiles asked of a scanline file) is refused with a message naming it,
#    and nothing on disk is modified (checksum before/after);
#  - a plain render (no --resume) on a partial output is refused, telling the user to choose
#    --resume or --overwrite; --overwrite then works;
#  - --resume with nothing to resume starts a fresh render and says so;
#  - --resume of a finished render says it is complete and changes nothing.
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=480x270
ARGS="-j 2 --size $SIZE --tasks rows:2"

cp "$SCENE" "$T/hills.scene"
PARTIAL_SCENE="$T/hills.scene"
"$TF_BIN" render "$T/hills.scene" --listen 127.0.0.1:0 $ARGS -q -o "$T/ref.exr" ||
    fail "reference render failed"
full=$(wc -c <"$T/ref.exr")
make_partial "$T/p.exr" $((full / 2)) $ARGS
sum0=$(cksum <"$T/p.exr")
say "partial render: $(wc -c <"$T/p.exr") of $full bytes"

# refused CASE_NAME EXPECTED_WORDS ARGS...: the render must fail with one line containing the
# expected words and leave p.exr as it was (and no file beside it created or removed).
refused() {
    name=$1 words=$2; shift 2
    : >"$T/refuse.err"; before=$(ls "$T")
    if "$TF_BIN" render "$@" --listen 127.0.0.1:0 -o "$T/p.exr" 2>"$T/refuse.err"; then
        fail "$name: accepted"
    fi
    grep -qi -e "$words" "$T/refuse.err" || fail "$name: message does not say '$words': $(cat "$T/refuse.err")"
    [ "$(grep -c . "$T/refuse.err")" -eq 1 ] || fail "$name: not one line: $(cat "$T/refuse.err")"
    [ "$(cksum <"$T/p.exr")" = "$sum0" ] || fail "$name: the partial file was modified"
    [ "$(ls "$T")" = "$before" ] || fail "$name: files beside the output changed: $(ls "$T" | tr '\n' ' ')"
    say "$name refused, file untouched: $(cat "$T/refuse.err")"
}

sed 's/^seed *=.*/seed = 2/' "$SCENE" >"$T/hills.scene.new"
cp "$T/hills.scene" "$T/hills.scene.orig"
mv "$T/hills.scene.new" "$T/hills.scene"
refused "changed scene (seed)" "scene changed" "$T/hills.scene" $ARGS --resume
mv "$T/hills.scene.orig" "$T/hills.scene"
refused "changed size" "size changed" "$T/hills.scene" -j 2 --size 320x180 --resume

# A file written by another renderer version: same bytes but for the settings attribute.
python3 - "$T/p.exr" "$T/other.exr" <<'PY' || fail "cannot make the other-version file"
import sys
data = open(sys.argv[1], "rb").read()
old = b"renderer=terrafarm-"
i = data.find(old)
if i < 0:
    sys.exit("no settings attribute in the header")
j = i + len(old)
ver = data[j:j + 5]
data = data[:j] + b"9.9.9"[:len(ver)] + data[j + len(ver):]
open(sys.argv[2], "wb").write(data)
PY
cp "$T/p.exr" "$T/keep.exr"; cp "$T/other.exr" "$T/p.exr"; sum_keep=$sum0; sum0=$(cksum <"$T/p.exr")
refused "changed render settings" "settings changed" "$T/hills.scene" $ARGS --resume
cp "$T/keep.exr" "$T/p.exr"; rm "$T/keep.exr" "$T/other.exr"; sum0=$sum_keep
# The channel type is a setting; the file's layout (scanline rows:2 here) must match --tasks.
refused "another pixel type" "settings changed" "$T/hills.scene" $ARGS --pixel float --resume
refused "tiles asked of a scanline file" "the file is 'scanline half'" "$T/hills.scene" -j 2 \
    --size $SIZE --tasks stamps:32x32 --resume

refused "plain render on a partial output" "--resume.*--overwrite" "$T/hills.scene" $ARGS

say "--overwrite replaces the partial render"
"$TF_BIN" render "$T/hills.scene" $ARGS --overwrite --listen 127.0.0.1:0 -o "$T/p.exr" \
    --stats "$T/ow.json" 2>"$T/ow.err" || fail "--overwrite failed: $(cat "$T/ow.err")"
[ "$(jstat rows_resumed "$T/ow.json")" -eq 0 ] || fail "--overwrite resumed rows"
same "$T/ref.exr" "$T/p.exr" "--overwrite"

say "--resume of a finished render"
sum1=$(cksum <"$T/p.exr")
"$TF_BIN" render "$T/hills.scene" $ARGS --resume --listen 127.0.0.1:0 -o "$T/p.exr" 2>"$T/done.err" ||
    fail "--resume of a complete file failed: $(cat "$T/done.err")"
grep -q 'already complete' "$T/done.err" || fail "does not say the render is complete: $(cat "$T/done.err")"
[ "$(cksum <"$T/p.exr")" = "$sum1" ] || fail "a complete file was modified by --resume"
say "$(cat "$T/done.err")"

say "--resume with nothing to resume"
"$TF_BIN" render "$T/hills.scene" $ARGS --resume --listen 127.0.0.1:0 -o "$T/fresh.exr" \
    --stats "$T/fresh.json" 2>"$T/fresh.err" || fail "--resume without a file failed: $(cat "$T/fresh.err")"
grep -q 'nothing to resume, starting a fresh render' "$T/fresh.err" ||
    fail "does not say it starts afresh: $(cat "$T/fresh.err")"
[ "$(jstat rows_resumed "$T/fresh.json")" -eq 0 ] || fail "rows_resumed is not 0"
say "$(grep 'nothing to resume' "$T/fresh.err")"
same "$T/ref.exr" "$T/fresh.exr" "--resume from nothing"
say "a refused setting or a busy port leaves a finished image at the output untouched"
sum2=$(cksum <"$T/fresh.exr")
"$TF_BIN" render "$T/hills.scene" $ARGS --tasks stamps:16x16 --watermark 1 --listen 127.0.0.1:0 -o "$T/fresh.exr" \
    2>"$T/wm.err" && fail "--watermark 1 was accepted"
[ "$(cksum <"$T/fresh.exr")" = "$sum2" ] || fail "a refused --watermark modified the output"
say "$(cat "$T/wm.err")"
python3 -c 'import socket, sys, time
s = socket.socket(); s.bind(("127.0.0.1", 0)); s.listen(); print(s.getsockname()[1], flush=True)
time.sleep(20)' >"$T/busy.port" &
busy=$!; e2e_track $busy
i=0; while [ ! -s "$T/busy.port" ]; do sleep 0.05; i=$((i + 1)); [ $i -lt 100 ] || fail "no busy port"; done
"$TF_BIN" render "$T/hills.scene" $ARGS --listen 127.0.0.1:$(cat "$T/busy.port") -o "$T/fresh.exr" \
    2>"$T/busy.err" && fail "a busy --listen port was accepted"
[ "$(cksum <"$T/fresh.exr")" = "$sum2" ] || fail "a failed listen modified the output"
say "$(grep -v 'will be replaced' "$T/busy.err")"
echo "resume_refuse: every refusal clear and harmless"
