#!/bin/sh
# opencl_cache.sh: the OpenCL program binary cache (worker/opencl_cache.c) through whole renders.
# Two `render --backend opencl` runs of the default scene at 160x90 with TF_OPENCL_CACHE set to
# an empty directory: the first builds from source and stores the entry (its worker logs "cache
# miss" under -v), the second makes its program from it ("cache hit"), and the two images are
# byte-identical.  Then a byte of the entry flipped: refused (one warning), rebuilt, the same
# image, and the rewritten entry hits again.  Then the directory made group-writable: one
# warning per worker, built from source, the same image, nothing stored.  The unit tests
# (tests/unit/test_opencl_cache.c) cover each header field, stale keys and the driver refusing
# a binary.  First of all, PoCL's own cache directory (worker/pocl_cachedir.h): every render here
# uses a private XDG_CACHE_HOME, so PoCL's kernels are compiled there once; the empty
# tempfile_XXXXXX files PoCL 3.1 leaves at every start are swept once older than an hour (three
# planted two hours old: gone after one render; a fresh one and an old file of another name
# stay).  Skipped (77) without an OpenCL platform.  Nothing here depends on timing: the ages
# are set with touch.
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=160x90
CACHE=$T/cache
ENTRY_RE='OpenCL program cache \(hit\|miss\|rebuilt\|off\|refused\)'

say "probe: a tiny OpenCL render, cache off, PoCL's leftovers in its cache directory swept"
export TF_OPENCL_CACHE=off XDG_CACHE_HOME="$T/xdg"
unset POCL_CACHE_DIR
POCL_DIR=$XDG_CACHE_HOME/terrafarm/pocl
mkdir -p "$POCL_DIR" && chmod 700 "$XDG_CACHE_HOME/terrafarm" "$POCL_DIR" || fail "mkdir $POCL_DIR"
for f in tempfile_old001 tempfile_old002 tempfile_old003 tempfile_fresh1 tempfile.notours; do
    : >"$POCL_DIR/$f" || fail "cannot plant $f"
done
touch -d '2 hours ago' "$POCL_DIR"/tempfile_old00? "$POCL_DIR/tempfile.notours"
render -q -j 1 --size 16x9 --backend opencl -o "$T/probe.exr"; rc=$?
if [ $rc -ne 0 ]; then
    grep -q 'no OpenCL platform\|no OpenCL device' "$T/last.err" &&
        skip "no usable OpenCL platform: $(head -1 "$T/last.err")"
    fail "tiny OpenCL render exited $rc: $(cat "$T/last.err")"
fi
for f in tempfile_old001 tempfile_old002 tempfile_old003; do
    [ -e "$POCL_DIR/$f" ] && fail "PoCL's leftover $f (two hours old) was not swept: $(ls "$POCL_DIR" | tr "\n" " ")"
done
for f in tempfile_fresh1 tempfile.notours; do
    [ -e "$POCL_DIR/$f" ] || fail "$f was removed: only tempfile_XXXXXX older than an hour may be"
done
left=$(ls "$POCL_DIR" | grep -c '^tempfile_......$')
[ "$left" -le 2 ] || fail "$left tempfile_XXXXXX in $POCL_DIR after one worker: $(ls "$POCL_DIR" | tr "\n" " ")"
say "PoCL's cache directory: 3 old leftovers swept, $left young tempfile(s) kept"

# cl_render NAME: a 160x90 render by one forked OpenCL worker, -v (the worker says how it made
# its program); stderr in $T/NAME.err.
cl_render() {
    render -v -j 1 --size $SIZE --backend opencl -o "$T/$1.exr" ||
        fail "$1: render failed: $(cat "$T/last.err")"
    cp "$T/last.err" "$T/$1.err"
}

# how NAME: the worker's cache line ("hit", "miss", ...).
how() { sed -n "s/.*$ENTRY_RE: .*/\\1/p" "$T/$1.err" | head -1; }

# expect NAME STATE: the worker of render NAME made its program that way.
expect() {
    got=$(how "$1")
    [ "$got" = "$2" ] || fail "$1: expected a cache $2, the worker logged '${got:-nothing}': $(grep -i 'opencl' "$T/$1.err")"
    say "$1: cache $2"
}

export TF_OPENCL_CACHE="$CACHE"
say "an empty cache directory: built from source and stored"
cl_render first
expect first miss
set -- "$CACHE"/*.bin
[ $# -eq 1 ] && [ -f "$1" ] || fail "expected one entry in $CACHE: $(ls -la "$CACHE")"
ENTRY=$1
[ "$(stat -c %a "$ENTRY")" = 600 ] || fail "entry mode $(stat -c %a "$ENTRY"), expected 600"
[ "$(stat -c %a "$CACHE")" = 700 ] || fail "directory mode $(stat -c %a "$CACHE"), expected 700"

say "the same render again: the program from the stored binary"
cl_render second
expect second hit
same "$T/first.exr" "$T/second.exr" "cache hit"

say "a byte of the stored binary flipped: refused, rebuilt, rewritten"
python3 - "$ENTRY" <<'PY' || fail "cannot flip a byte of $ENTRY"
import sys
p = sys.argv[1]
b = bytearray(open(p, "rb").read())
b[len(b) // 2] ^= 0x10
open(p, "wb").write(b)
PY
cl_render tampered
expect tampered rebuilt
[ "$(grep -c 'refused (the binary.s checksum' "$T/tampered.err")" -eq 1 ] ||
    fail "expected one warning about the checksum: $(cat "$T/tampered.err")"
same "$T/first.exr" "$T/tampered.exr" "after a tampered entry"
cl_render again
expect again hit
same "$T/first.exr" "$T/again.exr" "the rewritten entry"

say "a group-writable cache directory: refused with one warning, built from source"
rm -f "$CACHE"/*.bin
chmod 770 "$CACHE"
cl_render unsafe
expect unsafe refused
[ "$(grep -c 'OpenCL program cache not used: .*writable by its group or others' "$T/unsafe.err")" -eq 1 ] ||
    fail "expected one warning about the directory: $(cat "$T/unsafe.err")"
set -- "$CACHE"/*.bin
[ -e "$1" ] && fail "an entry was stored in a refused directory: $*"
same "$T/first.exr" "$T/unsafe.exr" "refused directory"
echo "opencl_cache: ok"
