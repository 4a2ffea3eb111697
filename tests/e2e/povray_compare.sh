#!/bin/sh
# tests/e2e/povray_compare.sh: the POV-Ray comparison (bench/povray_compare.sh) runs end to end at
# a tiny size: both renderers produce a picture, and the result table has a row per mode with
# its two ratios.  Skips (77) when povray is not installed.  Not a timing test: at this size a
# side's CPU time can round to 0 (10 ms clock ticks), and the script then prints "?" for the
# ratio it cannot form, which is accepted here; a number or "?" must be there.
ROOT=${TF_ROOT:-$(cd "$(dirname "$0")/../.." && pwd)}
command -v povray >/dev/null 2>&1 || { echo "povray not installed: skipped"; exit 77; }
OUT=$(mktemp -d "${TMPDIR:-/tmp}/tf-povcmp.XXXXXX") || exit 1
trap 'rm -rf "$OUT"' EXIT

"$ROOT/bench/povray_compare.sh" --sizes 5 --image 64x36 --runs 1 --modes aa,noaa \
    --keep "$OUT/keep" >"$OUT/table.txt" 2>&1
rc=$?
if [ $rc -ne 0 ]; then
    echo "FAIL: povray_compare.sh exited $rc"; cat "$OUT/table.txt"; exit 1
fi
for mode in aa noaa; do
    # "33     MODE  | ... | CPU_RATIO TRACE_RATIO": 33 = 2^5 + 1 samples a side.
    grep -Eq "^33 +$mode +\|.*\| +([0-9]+\.[0-9]+|\?) +([0-9]+\.[0-9]+|\?)\$" "$OUT/table.txt" ||
        { echo "FAIL: no result row for $mode"; cat "$OUT/table.txt"; exit 1; }
    for who in terrafarm povray; do
        f="$OUT/keep/${who}_33_$mode.png"
        [ -s "$f" ] || { echo "FAIL: missing $f"; exit 1; }
        # a PNG of the requested size: width and height are big-endian at bytes 16..23
        size=$(od -An -tu1 -j16 -N8 "$f" | awk '{ print $3 * 256 + $4 "x" $7 * 256 + $8 }')
        [ "$size" = "64x36" ] || { echo "FAIL: $f is $size, not 64x36"; exit 1; }
    done
done
grep -q 'height_field' "$OUT/keep/hf_5.pov" || { echo "FAIL: no height_field in the .pov"; exit 1; }
echo "ok: povray comparison ran at 33x33 / 64x36"
