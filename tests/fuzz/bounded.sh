#!/bin/sh
# tests/fuzz/bounded.sh: runs every libFuzzer target under $BUILD/fuzz/ for RUNS mutations
# after its committed corpus (tests/corpus/<name>/): a count, not a time, with a fixed seed, so
# two runs try the same inputs.  New inputs go to a scratch directory, never into the corpus.
# Every target runs even when one fails; the failures are listed at the end (exit 1).
# Run by `make asan` (the fuzz-runs target).  Usage: tests/fuzz/bounded.sh BUILD RUNS
BUILD=${1:?usage: bounded.sh BUILD RUNS}
RUNS=${2:?usage: bounded.sh BUILD RUNS}
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
SCRATCH=$(mktemp -d "${TMPDIR:-/tmp}/tf-fuzz.XXXXXX") || exit 1
trap 'rm -rf "$SCRATCH"' EXIT
failures=""
for f in "$BUILD"/fuzz/fuzz_*; do
    case "$f" in *.d) continue ;; esac
    [ -x "$f" ] || continue
    name=$(basename "$f")
    mkdir -p "$SCRATCH/$name"
    start=$(date +%s)
    if "$f" -runs="$RUNS" -seed=1 -max_len=4096 -timeout=20 -artifact_prefix="$SCRATCH/$name-" \
        "$SCRATCH/$name" \
        "$ROOT/tests/corpus/${name#fuzz_}" >"$SCRATCH/$name.log" 2>&1; then
        echo "ok   $name ($RUNS runs, $(( $(date +%s) - start ))s)"
    else
        echo "FAIL $name"; grep -v '^#\|^INFO' "$SCRATCH/$name.log" | tail -25 | sed 's/^/    /'
        failures="$failures $name"
    fi
done
[ -z "$failures" ] || { echo "fuzz targets failed:$failures"; exit 1; }
