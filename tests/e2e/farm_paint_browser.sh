#!/bin/sh
# farm_paint_browser.sh: Raypaint reached from the standing farm's web view in a real browser
# (headless Chromium over the DevTools protocol, cdp_farm_paint.py).  Alice logs in to the
# farm's page, clicks "paint" on her paused still, follows the paint job's "paint view" link,
# and watches the farm's staying worker paint it: painted, the canvas is the render's PNG
# preview byte for byte.  The page's "render on the farm" button queues the view as alice's
# render job, which the farm then lists.  Screenshot: $TF_FARM_PAINT_SHOT (default in the
# test's temp dir).
. "$(dirname "$0")/lib.sh"
e2e_init
. "$(dirname "$0")/lib_farm.sh"
. "$(dirname "$0")/lib_paint.sh"
CHROMIUM=$(command -v chromium || command -v chromium-browser) || skip "chromium is not installed (make deps)"
SIZE=240x136
render_reference $SIZE

say "a farm with alice's paused still and a staying worker"
farm_init
start_farm
still=$("$TF_BIN" submit "$SCENE" --size $SIZE --name still) || fail "submit"
"$TF_BIN" pause "$still" >/dev/null || fail "pause"
farm_worker w1

say "Chromium at http://$TERRAFARM_FARM/"
shot=${TF_FARM_PAINT_SHOT:-$T/farm_paint.png}
TMPDIR=$(browser_tmp) python3 "$(dirname "$0")/cdp_farm_paint.py" "$CHROMIUM" "http://$TERRAFARM_FARM" \
    "$(tail -1 "$T/alice")" "$still" "$T/ref.png" "$shot" >"$T/cdp.out" 2>&1
crc=$?
cat "$T/cdp.out"
no_browser_leftovers
[ $crc -eq 77 ] && skip "$(tail -1 "$T/cdp.out")"
[ $crc -eq 0 ] || fail "Raypaint from the farm's page: $(grep FAIL "$T/cdp.out" | head -3)"
paint=$(sed -n 's/^paint_job=//p' "$T/cdp.out")
job=$(sed -n 's/^submitted_job=//p' "$T/cdp.out")
[ "$(field "$paint" kind)" = paint ] || fail "job $paint is a $(field "$paint" kind)"
[ "$(field "$paint" owner)" = alice ] || fail "the paint job belongs to $(field "$paint" owner)"
[ "$(field "$job" kind)" = render ] && [ "$(field "$job" owner)" = alice ] ||
    fail "the submitted job $job is $(field "$job" owner)'s $(field "$job" kind)"
[ "$(field "$job" width)x$(field "$job" height)" = $SIZE ] ||
    fail "the submitted job is $(field "$job" width)x$(field "$job" height), not $SIZE"
echo "farm_paint_browser: paint button, paint view link, painted canvas and Submit all hold; screenshot $shot"
