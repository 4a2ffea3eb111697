#!/bin/sh
# dashboard_browser.sh: a real browser (headless Chromium, Debian's chromium package) opens the
# dashboard of a running render and the page is checked over the DevTools protocol
# (cdp_dashboard.py): no error shown, the workers table filled, progress rising, finished
# stamps drawn on the image, events listed, the plot drawn, the whole picture once finished (the
# dashboard serves the final state while --on-done runs, here until the check is over); a
# screenshot is saved ($TF_DASHBOARD_SHOT, default in the test's temp dir).  The worker is
# frozen at birth and run in slices until the page has shown the render under way, so the page
# sees it on a machine of any speed.  The image must still be byte-identical to one rendered
# without a dashboard.
. "$(dirname "$0")/lib.sh"
e2e_init
CHROMIUM=$(command -v chromium || command -v chromium-browser) || skip "chromium is not installed (make deps)"
SIZE=960x540
say "reference render without a dashboard"
render -q -j 2 --size $SIZE --tasks stamps:80x60 --http none -o "$T/ref.exr" || fail "reference: $(cat "$T/last.err")"

say "render with the dashboard, watched by Chromium"
# a generous lease: a worker frozen between slices must not be dropped as silent
"$TF_BIN" render "$SCENE" --listen 127.0.0.1:0 --http 127.0.0.1:0 -j 1 --size $SIZE \
    --tasks stamps:80x60 --lease-timeout 10m -o "$T/out.exr" \
    --on-done "i=0; while [ ! -e '$T/checked' ] && [ \$i -lt 1800 ]; do sleep 0.1; i=\$((i + 1)); done" \
    2>"$T/coord.err" &
pid=$!; e2e_track $pid
freeze_workers_at_birth $pid 1
i=0
while ! grep -q 'dashboard at' "$T/coord.err" 2>/dev/null; do
    kill -0 $pid 2>/dev/null || fail "render ended early: $(cat "$T/coord.err")"
    sleep 0.1; i=$((i + 1)); [ $i -lt 600 ] || fail "no dashboard URL logged: $(cat "$T/coord.err")"
done
url=$(sed -n 's/.*dashboard at \(http:[^ ]*\).*/\1/p' "$T/coord.err" | head -1)
say "page at $url"
shot=${TF_DASHBOARD_SHOT:-$T/dashboard.png}
TMPDIR=$(browser_tmp) python3 "$(dirname "$0")/cdp_dashboard.py" "$CHROMIUM" "$url" "$shot" 150 $pid >"$T/cdp.out" 2>&1
crc=$?
thaw_workers $pid
touch "$T/checked"
cat "$T/cdp.out"
no_browser_leftovers
[ $crc -eq 77 ] && skip "$(tail -1 "$T/cdp.out")"
[ $crc -eq 0 ] || fail "the dashboard page in Chromium: $(grep FAIL "$T/cdp.out" | head -3)"
[ -s "$shot" ] || fail "no screenshot saved"
python3 -c 'import sys; d=open(sys.argv[1],"rb").read(24); sys.exit(0 if d[:8]==b"\x89PNG\r\n\x1a\n" and int.from_bytes(d[16:20],"big")>=640 else 1)' "$shot" \
    || fail "the screenshot is not a PNG of the page"
wait_exit $pid 120
[ $rc -eq 0 ] || fail "the watched render exited $rc: $(cat "$T/coord.err")"
same "$T/ref.exr" "$T/out.exr" "render watched by a browser"
say "ok"
