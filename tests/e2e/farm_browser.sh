#!/bin/sh
# farm_browser.sh: a real browser (headless Chromium) at a standing farm's web view, driven
# over the DevTools protocol by cdp_farm.py: log in with /login?token= (an admin's), see the
# three jobs with their states (one paused), click "resume" and see that job run to done with
# the others, see a running job's own dashboard link (and that it answers), see the workers
# table; a screenshot is saved ($TF_FARM_SHOT, default in the test's temp dir).  The worker is
# started only once the page has shown the queue and the click has resumed the paused job, and
# born frozen (SIGSTOP): cdp_farm.py lets it run in 20 ms slices, looking at the page only while
# it is frozen, until a running job's dashboard link has been seen and has answered, so no job
# can end while that is checked, however fast the machine; then it runs free.
. "$(dirname "$0")/lib.sh"
e2e_init
CHROMIUM=$(command -v chromium || command -v chromium-browser) || skip "chromium is not installed (make deps)"
(umask 077; head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$T/secret")
"$TF_BIN" farm --state "$T/state" --add-token boss --role admin >"$T/admin" || fail "add-token"
"$TF_BIN" farm --listen 127.0.0.1:0 --state "$T/state" --secret-file "$T/secret" >"$T/farm.log" 2>&1 &
FARM=$!
e2e_track $FARM
i=0
until PORT=$(sed -n 's/.*farm on http:\/\/127.0.0.1:\([0-9]*\):.*/\1/p' "$T/farm.log") && [ -n "$PORT" ]; do
    kill -0 $FARM 2>/dev/null || fail "the farm did not start: $(cat "$T/farm.log")"
    sleep 0.1; i=$((i + 1)); [ $i -lt 600 ] || fail "the farm printed no port"
done
export TERRAFARM_FARM=127.0.0.1:$PORT TERRAFARM_TOKEN_FILE=$T/admin
submit() { "$TF_BIN" submit "$@" 2>>"$T/submit.err" || fail "submit $*: $(cat "$T/submit.err")"; }

say "three jobs, one paused"
first=$(submit "$SCENE" --size 160x90 --name first --priority 5)
paused=$(submit "$SCENE" --size 160x90 --name later --priority 9)
long=$(submit "$TF_ROOT/scenes/alps.scene" --size 1280x720 --name long --priority 1)
"$TF_BIN" pause "$paused" >/dev/null || fail "pause $paused"

say "Chromium at http://127.0.0.1:$PORT/"
shot=${TF_FARM_SHOT:-$T/farm.png}
TMPDIR=$(browser_tmp) python3 "$(dirname "$0")/cdp_farm.py" "$CHROMIUM" "http://127.0.0.1:$PORT" "$(tail -1 "$T/admin")" \
    "$shot" "$T/page-ready" "$paused" "$first" "$long" --worker-pid "$T/worker.pid" --limit 400 \
    >"$T/cdp.out" 2>&1 &
CDP=$!
e2e_track $CDP
i=0
until [ -e "$T/page-ready" ]; do
    kill -0 $CDP 2>/dev/null || break
    sleep 0.1; i=$((i + 1)); [ $i -lt 1200 ] || fail "the page did not list the jobs: $(cat "$T/cdp.out")"
done
if [ -e "$T/page-ready" ]; then
    say "the page listed the queue and resumed the paused job: a staying worker joins, frozen"
    start_stopped "$T/worker.log" "$TF_BIN" worker --connect "http://127.0.0.1:$PORT" \
        --secret-file "$T/secret" --name w1 -j 1
    e2e_track $!
    echo $! >"$T/worker.pid.new" && mv "$T/worker.pid.new" "$T/worker.pid"
fi
wait $CDP
crc=$?
cat "$T/cdp.out"
no_browser_leftovers
[ $crc -eq 77 ] && skip "$(tail -1 "$T/cdp.out")"
[ $crc -eq 0 ] || fail "the farm's page in Chromium: $(grep FAIL "$T/cdp.out" | head -3)"
python3 -c 'import sys; d=open(sys.argv[1],"rb").read(24); sys.exit(0 if d[:8]==b"\x89PNG\r\n\x1a\n" and int.from_bytes(d[16:20],"big")>=640 else 1)' "$shot" \
    || fail "the screenshot is not a PNG of the page"
"$TF_BIN" job "$paused" --json | grep -q '"state": *"done"' || fail "job $paused is not done for the farm"
echo "farm_browser: login, queue, resume by click, dashboard link, workers table all hold; screenshot $shot"
