#!/bin/sh
# bench_plot.sh: `terrafarm bench --plot` refuses clearly, before rendering, when gnuplot is
# absent or the extension is unknown, and draws an SVG and a PNG when gnuplot is present
# (skipped, 77, without gnuplot).
. "$(dirname "$0")/lib.sh"
e2e_init

say "no gnuplot on PATH: a clear one-line error, nothing rendered"
PATH=/nonexistent "$TF_BIN" bench "$SCENE" --workers 1 --repeat 1 --size 32x18 \
    --plot "$T/p.svg" 2>"$T/e1"; rc=$?
refused $rc && grep -q 'needs gnuplot' "$T/e1" && [ "$(wc -l <"$T/e1")" -eq 1 ] ||
    fail "without gnuplot: rc $rc: $(cat "$T/e1")"
"$TF_BIN" bench "$SCENE" --plot "$T/p.pdf" 2>"$T/e2"; rc=$?
[ $rc -eq 2 ] && grep -q 'svg or .png' "$T/e2" || fail "--plot p.pdf: rc $rc: $(cat "$T/e2")"

command -v gnuplot >/dev/null 2>&1 || skip "gnuplot is not installed (apt-get install gnuplot-nox)"
for ext in svg png; do
    say "--plot p.$ext"
    "$TF_BIN" bench "$SCENE" --workers 1,2 --repeat 1 --size 48x27 --plot "$T/p.$ext" -q \
        >"$T/out" 2>"$T/err" || fail "bench --plot p.$ext: $(cat "$T/err")"
    [ -s "$T/p.$ext" ] || fail "no plot p.$ext"
done
grep -q '<svg' "$T/p.svg" || fail "p.svg is not SVG"
head -c 8 "$T/p.png" | od -An -c | grep -q 'P   N   G' || fail "p.png is not a PNG"
echo "ok"
