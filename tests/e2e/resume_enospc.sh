#!/bin/sh
# resume_enospc.sh: a full disk stops the render with one clear "No space left on device" line
# and a non-zero exit, and leaves a partial file that can be resumed: moved to a roomy
# directory, --resume completes it byte-identical to an uninterrupted render.
# Needs root (mounts a 300 KiB tmpfs); exits 77 otherwise.
. "$(dirname "$0")/lib.sh"
e2e_init
[ "$(id -u)" -eq 0 ] || skip "not root: cannot mount a small tmpfs"
SIZE=480x270
ARGS="-j 2 --size $SIZE --tasks rows:2"
PROBE_ARGS="--size $SIZE"
mkdir "$T/small"
mount -t tmpfs -o size=300k tmpfs "$T/small" 2>/dev/null || skip "cannot mount a tmpfs here"
trap 'umount "$T/small" 2>/dev/null; e2e_cleanup' EXIT

render -q $ARGS -o "$T/ref.exr" || fail "reference render: $(cat "$T/last.err")"
say "reference: $(wc -c <"$T/ref.exr") bytes; rendering into a 300 KiB tmpfs"
if "$TF_BIN" render "$SCENE" $ARGS --listen 127.0.0.1:0 -q -o "$T/small/img.exr" 2>"$T/full.err"; then
    fail "a render into a full disk succeeded"
fi
say "exit status non-zero; stderr: $(cat "$T/full.err")"
[ "$(grep -c . "$T/full.err")" -eq 1 ] || fail "expected exactly one error line: $(cat "$T/full.err")"
grep -q 'No space left on device' "$T/full.err" || fail "the error does not say 'No space left on device'"
[ -e "$T/small/img.exr" ] || fail "no partial file left"

say "--resume in place, on the still-full disk: refused, the partial file untouched"
sum0=$(cksum <"$T/small/img.exr")
rm -f "$T/small/img.png"   # the progress preview the first run kept up while it rendered
if "$TF_BIN" render "$SCENE" $ARGS --resume --listen 127.0.0.1:0 -q -o "$T/small/img.exr" 2>"$T/again.err"; then
    fail "a resume on a full disk succeeded"
fi
say "stderr: $(cat "$T/again.err")"
[ "$(grep -c . "$T/again.err")" -eq 1 ] || fail "expected exactly one error line: $(cat "$T/again.err")"
[ "$(cksum <"$T/small/img.exr")" = "$sum0" ] || fail "the failed resume modified the partial file"
[ "$(ls "$T/small")" = img.exr ] || fail "the failed resume left files behind: $(ls "$T/small")"

mv "$T/small/img.exr" "$T/img.exr"
rows=$(rows_on_disk "$T/img.exr")
[ -n "$rows" ] && [ "$rows" -gt 0 ] || fail "the partial file is not resumable ('$rows' rows)"
say "the partial file holds $rows of 270 rows in whole chunks"
"$TF_BIN" render "$SCENE" $ARGS --resume --listen 127.0.0.1:0 -o "$T/img.exr" --stats "$T/s.json" \
    2>"$T/resume.err" || fail "resume after the full disk failed: $(cat "$T/resume.err")"
say "$(grep -o 'resuming .*' "$T/resume.err")"
[ "$(jstat rows_resumed "$T/s.json")" -eq "$rows" ] || fail "rows_resumed is not $rows"
same "$T/ref.exr" "$T/img.exr" "resumed after a full disk"
echo "resume_enospc: clear error, resumable file, identical image"
