#!/bin/sh
# dashboard_controls.sh: the dashboard's controls and --on-done, on real renders.
#  1. POST /api/stop mid-render: exit status 130 as for an interrupt, --on-done sees
#     "interrupted"; --resume finishes it and the image is identical to a clean render.
#  2. POST /api/workers/ID/drop on a busy worker: it is shown as dropped, its task is dealt
#     again (a re-deal in the events and the statistics), and the image is identical.
#  3. POST /api/watermark: the status shows the new watermark; out of range is a 400.
#  4. --on-done on a render that fails: "failed", its exit status and the reason.
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=1280x720
TASKS=stamps:128x120
LEASE="--lease-timeout 120000"   # frozen workers must not be taken for dead
render -q -j 2 --size $SIZE --tasks $TASKS --http none -o "$T/ref.exr" || fail "reference: $(cat "$T/last.err")"
ENVDUMP='env | grep ^TERRAFARM_ | sort > "$0"'

post() { # post URL PATH [JSON]: prints the HTTP status and body
    python3 - "$@" <<'PY'
import sys, urllib.request, urllib.error
url, path = sys.argv[1], sys.argv[2]
body = sys.argv[3].encode() if len(sys.argv) > 3 else b""
r = urllib.request.Request(url.rstrip("/") + path, data=body, method="POST",
                           headers={"X-Terrafarm-Token": "loopback", "Content-Type": "application/json"})
try:
    with urllib.request.urlopen(r, timeout=10) as a:
        print(a.status, a.read().decode())
except urllib.error.HTTPError as e:
    print(e.code, e.read().decode().strip())
PY
}
get() { python3 -c 'import sys,urllib.request; print(urllib.request.urlopen(sys.argv[1].rstrip("/")+sys.argv[2], timeout=10).read().decode())' "$1" "$2"; }
jget() { get "$1" "$2" | python3 -c 'import json,sys; d=json.load(sys.stdin); exec(sys.argv[1])' "$3"; }

say "1. stop from the dashboard, then --resume"
"$TF_BIN" render "$SCENE" --listen 127.0.0.1:0 --http 127.0.0.1:0 -j 1 --size $SIZE --tasks $TASKS \
    -o "$T/stop.exr" --on-done "sh -c '$ENVDUMP' '$T/stop.env'" 2>"$T/stop.err" &
pid=$!; e2e_track $pid
freeze_workers_at_birth $pid 1
url=$(dashboard_url "$T/stop.err" $pid)
# the worker, frozen at birth, runs 20 ms at a time until a row is on disk: the render cannot
# have ended when the stop is posted, however fast this machine
i=0
until jget "$url" /api/status 'sys.exit(0 if d["rows_written"] > 0 else 1)' 2>/dev/null; do
    run_slice $pid
    i=$((i + 1)); [ $i -lt 1200 ] || fail "no row written in time"
done
thaw_workers $pid
out=$(post "$url" /api/stop)
case "$out" in 202*) ;; *) fail "POST /api/stop: $out" ;; esac
wait_exit $pid 60
[ $rc -eq 130 ] || fail "stopped render exited $rc, expected 130: $(tail -3 "$T/stop.err")"
grep -q 'stopped from the dashboard' "$T/stop.err" || fail "no stop message: $(tail -3 "$T/stop.err")"
grep -qx 'TERRAFARM_STATUS=interrupted' "$T/stop.env" || fail "--on-done after a stop: $(cat "$T/stop.env")"
grep -qx 'TERRAFARM_EXIT=130' "$T/stop.env" || fail "--on-done exit after a stop: $(cat "$T/stop.env")"
rows=$(sed -n 's/^TERRAFARM_ROWS=//p' "$T/stop.env")
[ "$rows" -gt 0 ] && [ "$rows" -lt 720 ] || fail "--on-done rows after a stop: $rows"
say "stopped with $rows rows on disk; resuming"
render -q -j 2 --size $SIZE --tasks $TASKS --http none --resume -o "$T/stop.exr" || fail "resume: $(cat "$T/last.err")"
same "$T/ref.exr" "$T/stop.exr" "stopped from the dashboard and resumed"

say "2. drop a busy worker, 3. change the watermark"
"$TF_BIN" render "$SCENE" --listen 127.0.0.1:0 --http 127.0.0.1:0 -j 2 --size $SIZE --tasks $TASKS \
    $LEASE -o "$T/drop.exr" --stats "$T/drop.json" 2>"$T/drop.err" &
pid=$!; e2e_track $pid
freeze_workers_at_birth $pid 2
url=$(dashboard_url "$T/drop.err" $pid)
# the workers, frozen at birth (SIGSTOP), run 20 ms at a time until one is busy; frozen then,
# nothing moves meanwhile
i=0
until jget "$url" /api/workers 'sys.exit(0 if any(w["state"]=="busy" for w in d["workers"]) else 1)'; do
    run_slice $pid
    i=$((i + 1)); [ $i -lt 1200 ] || fail "no worker became busy"
done
sleep 0.6   # a snapshot or two after the freeze
id=$(jget "$url" /api/workers 'b=[w["id"] for w in d["workers"] if w["state"]=="busy"]; print(b[0] if b else "")')
[ -n "$id" ] || fail "no busy worker once frozen"
before=$(jget "$url" /api/status 'print(d["tasks_redealt"])')
out=$(post "$url" /api/workers/$id/drop)
case "$out" in 202*) ;; *) fail "POST drop worker $id: $out" ;; esac
i=0
until jget "$url" /api/workers "sys.exit(0 if [w for w in d['workers'] if w['id']==$id and w['state']=='dropped'] else 1)"; do
    sleep 0.1; i=$((i + 1)); [ $i -lt 100 ] || fail "worker $id is not shown as dropped"
done
redealt=$(jget "$url" /api/status 'print(d["tasks_redealt"])')
[ "$redealt" -gt "$before" ] || fail "dropping busy worker $id re-dealt no task ($before -> $redealt)"
say "dropped busy worker $id: its task was dealt again"
out=$(post "$url" /api/workers/$id/drop)
case "$out" in 404*) ;; *) fail "dropping worker $id twice: $out" ;; esac
out=$(post "$url" /api/watermark '{"watermark": 1}')
case "$out" in 400*) ;; *) fail "watermark 1 (below a band) was not refused: $out" ;; esac
wm=$(jget "$url" /api/status 'print(d["watermark_min"] + 2)')
out=$(post "$url" /api/watermark "{\"watermark\": $wm}")
case "$out" in 202*) ;; *) fail "POST watermark $wm: $out" ;; esac
i=0
until jget "$url" /api/status "sys.exit(0 if d['watermark']==$wm else 1)"; do
    sleep 0.1; i=$((i + 1)); [ $i -lt 100 ] || fail "the watermark did not become $wm"
done
jget "$url" /api/events 'k=[e["text"] for e in d["events"] if e["kind"]=="control"]; print(k); sys.exit(0 if any("dropped" in t for t in k) and any("watermark set" in t for t in k) else 1)' \
    || fail "the controls are not in the event log"
jget "$url" /api/events 'sys.exit(0 if any(e["kind"]=="redeal" for e in d["events"]) else 1)' || fail "no re-deal in the event log"
thaw_workers $pid
wait_exit $pid 120
[ $rc -eq 0 ] || fail "render with a dropped worker exited $rc: $(tail -3 "$T/drop.err")"
[ "$(jstat tasks_redealt "$T/drop.json")" -ge 1 ] || fail "--stats shows no re-dealt task"
same "$T/ref.exr" "$T/drop.exr" "render with dropped workers and a new watermark"

say "4. --on-done on a failed render"
"$TF_BIN" render "$T/no-such.scene" --http none --on-done "sh -c '$ENVDUMP' '$T/fail.env'" 2>"$T/fail.err"
rc=$?
refused $rc || fail "a render of a missing scene exited $rc"
grep -qx 'TERRAFARM_STATUS=failed' "$T/fail.env" || fail "--on-done after a failure: $(cat "$T/fail.env")"
grep -qx "TERRAFARM_EXIT=$rc" "$T/fail.env" || fail "--on-done exit after a failure: $(cat "$T/fail.env")"
grep -q '^TERRAFARM_ERROR=.*no-such.scene' "$T/fail.env" || fail "--on-done has no reason: $(cat "$T/fail.env")"
say "ok"
