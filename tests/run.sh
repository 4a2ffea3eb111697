#!/bin/sh
# tests/run.sh: the one test runner.  Runs every unit test program (cmocka) under $BUILD/tests,
# replays every fuzz harness over its committed corpus (tests/corpus/<harness>/), then every
# end-to-end script tests/e2e/*.sh except lib*.sh (exit 0 = pass, 77 = skipped with a reason, else fail).
# Ends with the line "N passed, N failed, N skipped".
# Usage: tests/run.sh [PATTERN]   (only tests whose name contains PATTERN)
BUILD=${BUILD:-build}
BIN=${BIN:-bin}
export TF_BIN="$(cd "$(dirname "$BIN/terrafarm")" && pwd)/terrafarm"
export TF_BUILD="$(cd "$BUILD" && pwd)"
ROOT=$(cd "$(dirname "$0")/.." && pwd)
export TF_ROOT="$ROOT"
PATTERN=${1:-}
passed=0 failed=0 skipped=0
failures=""
LOG=$(mktemp -d "${TMPDIR:-/tmp}/tf-tests.XXXXXX")

for t in "$BUILD"/tests/test_*; do
    [ -x "$t" ] || continue
    case "$t" in *.d) continue ;; esac
    name=$(basename "$t")
    case "$name" in *"$PATTERN"*) ;; *) continue ;; esac
    out="$LOG/$name.out"
    CMOCKA_MESSAGE_OUTPUT=stdout "$t" >"$out" 2>&1
    rc=$?
    p=$(sed -n 's/^\[  PASSED  \] \([0-9]*\) test.*/\1/p' "$out" | tail -1)
    f=$(sed -n 's/^\[  FAILED  \] \([0-9]*\) test.*/\1/p' "$out" | tail -1)
    s=$(sed -n 's/^\[  SKIPPED \] \([0-9]*\) test.*/\1/p' "$out" | tail -1)
    p=${p:-0}; f=${f:-0}; s=${s:-0}
    if [ "$rc" -ne 0 ] && [ "$f" -eq 0 ]; then f=1; fi   # crashed before its summary
    passed=$((passed + p)); failed=$((failed + f)); skipped=$((skipped + s))
    if [ "$f" -ne 0 ]; then
        echo "FAIL $name ($f failed)"; sed 's/^/    /' "$out" | grep -v '^    \[       OK \]' | tail -40
        failures="$failures $name"
    else
        if [ "$s" -ne 0 ]; then echo "ok   $name ($p passed, $s skipped)"; else echo "ok   $name ($p passed)"; fi
    fi
done

for r in "$BUILD"/replay/fuzz_*; do
    [ -x "$r" ] || continue
    name=$(basename "$r")
    case "$name" in *"$PATTERN"*) ;; *) continue ;; esac
    corpus="$ROOT/tests/corpus/${name#fuzz_}"
    if "$r" "$corpus" >"$LOG/$name.out" 2>&1; then
        passed=$((passed + 1)); echo "ok   $name (corpus $(ls "$corpus" | wc -l) inputs)"
    else
        failed=$((failed + 1)); echo "FAIL $name"; tail -20 "$LOG/$name.out" | sed 's/^/    /'
        failures="$failures $name"
    fi
done

for e in "$ROOT"/tests/e2e/*.sh; do
    [ -f "$e" ] || continue
    name=$(basename "$e" .sh)
    case "$name" in lib*) continue ;; esac   # shared helpers, not tests
    case "$name" in *"$PATTERN"*) ;; *) continue ;; esac
    start=$(date +%s)
    sh "$e" >"$LOG/$name.out" 2>&1
    rc=$?
    secs=$(( $(date +%s) - start ))
    if [ $rc -eq 0 ]; then
        passed=$((passed + 1)); echo "ok   e2e/$name (${secs}s)"
    elif [ $rc -eq 77 ]; then
        skipped=$((skipped + 1)); echo "skip e2e/$name: $(tail -1 "$LOG/$name.out")"
    else
        failed=$((failed + 1)); echo "FAIL e2e/$name (exit $rc, ${secs}s)"
        tail -30 "$LOG/$name.out" | sed 's/^/    /'
        failures="$failures e2e/$name"
    fi
done

[ -n "$failures" ] && echo "failed:$failures"
echo "logs in $LOG"
echo "$passed passed, $failed failed, $skipped skipped"
[ "$failed" -eq 0 ]
