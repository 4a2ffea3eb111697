#!/bin/sh
# farm_piranha.sh: a Piranha worker (terrafarm worker --idle-only, Musgrave A.7.2.3.3) on a
# standing farm.  A process running as user nobody plays the machine's owner (a busy loop).
# While the owner is busy the worker takes no job; once the owner has been away for
# --idle-after it serves; when the owner comes back mid-job it retreats (its processes are
# killed) and says how fast, and the job stays running; when the owner leaves again it returns
# and the job completes, pixel for pixel a plain render.  Prints the retreat latency (owner
# started -> worker's processes gone, as seen from here).
# The job is submitted with --wait-workers 2 and the worker runs one process: its first
# session cannot finish the job (the render deals nothing before a second process says hello),
# so the owner's return falls in the middle of the job however fast this machine renders.  The
# owner comes back only once that process has said hello (the render's workers_joined), so the
# process of the second session is certainly the second hello: the job then completes.
. "$(dirname "$0")/lib.sh"
e2e_init
command -v setpriv >/dev/null 2>&1 || skip "setpriv (util-linux) is not installed"
[ "$(id -u)" = 0 ] || skip "playing another user's owner needs root"
. "$(dirname "$0")/lib_farm.sh"
farm_init
start_farm
owner_start() { setpriv --reuid=65534 --regid=65534 --clear-groups sh -c 'while :; do :; done' & OWNER=$!; e2e_track $OWNER; }
owner_stop() { kill -KILL $OWNER; wait $OWNER 2>/dev/null; }
wait_log() { # PATTERN [SECONDS]
    i=0 lim=$(( ${2:-120} * 20 ))
    until grep -q "$1" "$T/worker.log"; do
        i=$((i + 1)); [ $i -lt $lim ] || fail "the worker never logged '$1': $(cat "$T/worker.log")"
        sleep 0.05
    done
}
ARGS="--size 480x270 --tasks rows:2"
joined() { # the job's render: how many worker processes have said hello (its /api/status)
    python3 - "$(field "$job" dashboard)" <<'PY'
import json, sys, urllib.parse, urllib.request
u = urllib.parse.urlparse(sys.argv[1])
token = urllib.parse.parse_qs(u.query)["token"][0]
req = urllib.request.Request("%s://%s/api/status" % (u.scheme, u.netloc),
                             headers={"Authorization": "Bearer " + token})
print(json.load(urllib.request.urlopen(req, timeout=10))["workers_joined"])
PY
}

say "the owner is busy: the worker takes nothing"
owner_start
job=$("$TF_BIN" submit "$TF_ROOT/scenes/alps.scene" $ARGS --wait-workers 2 --name piranha) ||
    fail "submit"
"$TF_BIN" worker --connect "http://$TERRAFARM_FARM" --secret-file "$T/secret" -j 1 --idle-only \
    --owner nobody --idle-after 2s --name piranha >"$T/worker.log" 2>&1 &
e2e_track $!
wait_log "owner present"
[ "$(field "$job" attempts)" = 0 ] || fail "the job started while the owner was present"

say "the owner leaves: the worker serves"
owner_stop
wait_log "serving job $job"
i=0
until [ "$(joined)" = 1 ]; do
    i=$((i + 1)); [ $i -lt 600 ] || fail "the worker's process never said hello: $(cat "$T/worker.log")"
    sleep 0.2
done
say "the owner comes back in the middle of the job"
owner_start
t0=$(date +%s%N)
wait_log "retreated from job"
t1=$(date +%s%N)
state=$(field "$job" state)
[ "$state" = running ] || fail "after the retreat the job is $state, not running"
latency=$(( (t1 - t0) / 1000000 ))
say "retreat seen $latency ms after the owner started ($(sed -n 's/.*\(retreated from job .*\)/\1/p' "$T/worker.log"))"

say "the owner leaves again: the worker returns and the job completes"
owner_stop
i=0
until [ "$(field "$job" state)" = done ]; do
    i=$((i + 1)); [ $i -lt 3000 ] || fail "job $job never completed: $(cat "$T/worker.log")"; sleep 0.2
done
[ "$(grep -c "serving job $job " "$T/worker.log")" = 2 ] ||
    fail "the worker did not serve the job twice: $(cat "$T/worker.log")"
"$TF_BIN" render "$TF_ROOT/scenes/alps.scene" $ARGS --listen 127.0.0.1:0 -j 2 -o "$T/ref.exr" \
    2>"$T/ref.err" || fail "reference: $(cat "$T/ref.err")"
"$TF_BIN" job "$job" --output "$T/got.exr" || fail "download"
same_pixels "$T/ref.exr" "$T/got.exr" "the job a Piranha worker retreated from"
echo "-- piranha: retreat latency $latency ms (from here)"
echo "farm_piranha: the idle-only worker waits for the owner to leave, retreats, returns"
