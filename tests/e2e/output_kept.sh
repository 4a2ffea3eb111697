#!/bin/sh
# output_kept.sh: a finished output is never lost (coordinator/render/output.h; docs/contract.md
# section 2: no error path leaves a corrupted output).
#  1. A new render over a finished one (another size: nothing to resume) renders beside it
#     and replaces it only when complete: on a full disk (a small tmpfs) it fails with a clear
#     error, and the finished render is still there byte for byte, with nothing left beside it.
#  2. With room, the same new render replaces it: the result equals a clean render of the new
#     size, and no temporary file is left.
# Needs root (mounts a tmpfs); exits 77 otherwise.
. "$(dirname "$0")/lib.sh"
e2e_init
[ "$(id -u)" -eq 0 ] || skip "not root: cannot mount a small tmpfs"
mkdir "$T/small"
mount -t tmpfs -o size=1m tmpfs "$T/small" 2>/dev/null || skip "cannot mount a tmpfs here"
trap 'umount "$T/small" 2>/dev/null; e2e_cleanup' EXIT

render -q -j 2 --size 160x90 -o "$T/small/img.exr" || fail "first render: $(cat "$T/last.err")"
sum0=$(cksum <"$T/small/img.exr")
say "a finished 160x90 render in a 1 MiB tmpfs ($(wc -c <"$T/small/img.exr") bytes)"
if "$TF_BIN" render "$SCENE" -j 2 --size 640x360 --tasks rows:2 --listen 127.0.0.1:0 -q \
    -o "$T/small/img.exr" 2>"$T/full.err"; then
    fail "a 640x360 render into the full tmpfs succeeded"
fi
say "stderr: $(cat "$T/full.err")"
grep -q 'No space left on device' "$T/full.err" || fail "the error does not say 'No space left on device'"
grep -q 'finished render' "$T/full.err" || fail "the error does not say the finished render is kept"
[ "$(cksum <"$T/small/img.exr")" = "$sum0" ] || fail "the finished render was changed by the failed render"
[ "$(ls "$T/small" | tr "\n" " ")" = "img.exr img.png " ] || fail "the failed render left files behind: $(ls "$T/small")"
say "the finished render is intact and alone"

cp "$T/small/img.exr" "$T/img.exr"
render -q -j 2 --size 640x360 --tasks rows:2 -o "$T/ref.exr" || fail "reference: $(cat "$T/last.err")"
render -j 2 --size 640x360 --tasks rows:2 -o "$T/img.exr" || fail "render over a finished one: $(cat "$T/last.err")"
grep -q 'replaced only once the new one is complete' "$T/last.err" || fail "no word of rendering beside: $(cat "$T/last.err")"
same "$T/ref.exr" "$T/img.exr" "a new render over a finished one"
[ ! -e "$T/img.exr.rendering.tmp" ] || fail "the temporary file beside the output is left"
echo "output_kept: a failed render leaves the finished output intact; a complete one replaces it"
