#!/bin/sh
# farm_paint_idle.sh: a standing farm closes a paint job whose page nobody reads (it holds its
# pool's workers).  A paint whose page a client is reading (an updates long poll in flight)
# says so in its status (watchers >= 1 and unwatched_s 0, in one answer; before, 0 and more
# than 0); on a farm with --paint-idle 2s a paint job nobody opens is cancelled by the farm
# with the reason.
. "$(dirname "$0")/lib.sh"
e2e_init
. "$(dirname "$0")/lib_farm.sh"
say "a watched paint (terrafarm paint, paused: no message is coming)"
. "$(dirname "$0")/lib_paint.sh"
start_paint "$T/paint.err" --size 96x64 -j 1 --paused --http 127.0.0.1:0
python3 -c 'import json, sys, threading, time, urllib.request
page = sys.argv[1].rstrip("/")
def get(path):
    with urllib.request.urlopen(page + path, timeout=60) as a:
        return a.read()
s = json.loads(get("/api/paint/status"))
if s["watchers"] != 0 or s["unwatched_s"] <= 0:
    sys.exit("nobody reads yet, but watchers=%s unwatched_s=%s" % (s["watchers"], s["unwatched_s"]))
def watch():  # a page: long polls for the next messages, back to back
    while True:
        get("/api/paint/updates?gen=%d&from=%d&wait=2000" % (s["gen"], s["log_bytes"]))
threading.Thread(target=watch, daemon=True).start()
end = time.time() + 60
while time.time() < end:
    s = json.loads(get("/api/paint/status"))
    if s["watchers"] >= 1:
        sys.exit(0 if s["unwatched_s"] == 0 else "watched, yet unwatched_s is %s" % s["unwatched_s"])
    time.sleep(0.05)
sys.exit("the long poll never showed as a watcher")' "$PAINT_URL" || fail "a watched page"
say "its status counts the reader and says it is watched"
kill -TERM $PAINT_PID; wait_exit $PAINT_PID 30

say "a paint job nobody opens, on a farm with --paint-idle 2s"
farm_init
FARM_ARGS="--paint-idle 2s" start_farm
still=$("$TF_BIN" submit "$SCENE" --size 96x64 --name still) || fail "submit"
"$TF_BIN" pause "$still" >/dev/null || fail "pause"
lonely=$("$TF_BIN" job "$still" --paint) || fail "open a second paint job"
wait_state "$lonely" cancelled 120
reason=$(field "$lonely" reason)
case "$reason" in "closed: nobody watched its page for "*) ;; *) fail "closed for '$reason'" ;; esac
grep -q "job $lonely (still-paint): closed: nobody watched" "$T/farm.log" || fail "the farm did not log it"
echo "farm_paint_idle: a watched page is counted; an unwatched paint job is closed ($reason)"
