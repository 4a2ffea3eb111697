#!/bin/sh
# standing_farm.sh: a standing farm (terrafarm farm, coordinator/farm/) end to end.  Three jobs
# of different priorities, queued before any worker, are served by one staying worker in
# priority order, and each output is pixel for pixel a plain `terrafarm render` of the same
# scene and options; a dependency (--after) is honoured against priority; a paused job waits
# and a resumed one runs; a cancelled job never renders; pools and tags keep jobs from
# workers that may not serve them; and a farm killed (-9) in the middle of the queue and
# started again on the same state folder finishes every job, with the same pixels.
. "$(dirname "$0")/lib.sh"
e2e_init
. "$(dirname "$0")/lib_farm.sh"
farm_init
tf() { "$TF_BIN" "$@"; }
submit() { tf submit "$@" 2>>"$T/submit.err" || fail "submit $*: $(cat "$T/submit.err")"; }
worker() { farm_worker "$@"; }
reference() { # NAME SCENE OPTIONS...: the plain render of a job
    r=$1; s=$2; shift 2
    tf render "$s" --listen 127.0.0.1:0 -j 2 -o "$T/ref/$r.exr" "$@" 2>"$T/ref.err" ||
        fail "reference $r: $(cat "$T/ref.err")"
}
check_output() { # ID NAME
    tf job "$1" --output "$T/got/$2.exr" || fail "job $1's output cannot be downloaded"
    same_pixels "$T/ref/$2.exr" "$T/got/$2.exr" "job $1 ($2)"
}
mkdir -p "$T/ref" "$T/got"
start_farm

say "three jobs of priorities 0, 5, 9, queued before any worker"
low=$(submit "$TF_ROOT/scenes/valley.scene" --size 96x64 --name low --priority 0)
mid=$(submit "$TF_ROOT/scenes/default.scene" --size 80x60 --name mid --priority 5 --tasks rows:8)
high=$(submit "$TF_ROOT/scenes/mesa.scene" --size 64x48 --name high --priority 9)
after=$(submit "$TF_ROOT/scenes/valley.scene" --size 72x40 --name after --priority 20 --after "$low")
paused=$(submit "$TF_ROOT/scenes/default.scene" --size 48x32 --name paused --priority 30)
cancelled=$(submit "$TF_ROOT/scenes/default.scene" --size 48x32 --name cancelled --priority 30)
gpu=$(submit "$TF_ROOT/scenes/default.scene" --size 40x30 --name gpu --pool gpu --priority 50)
big=$(submit "$TF_ROOT/scenes/default.scene" --size 40x30 --name big --tags big --priority 50)
tf pause "$paused" >/dev/null || fail "pause"
tf cancel "$cancelled" >/dev/null || fail "cancel"
[ "$(field "$paused" state)" = paused ] || fail "job $paused is not paused"
[ "$(field "$cancelled" state)" = cancelled ] || fail "job $cancelled is not cancelled"
[ "$(field "$after" state)" = waiting ] || fail "job $after does not say it waits for $low"

say "one staying worker serves them"
worker w1
wait_state "$low" done
wait_state "$mid" done
wait_state "$high" done
wait_state "$after" done
# the order the worker joined them (a render may start ahead of its worker: "started" is not it)
order=$(sed -n 's/.*serving job \([0-9]*\) .*/\1/p' "$T/worker-w1.log" | head -4 | tr '\n' ' ')
[ "$order" = "$high $mid $low $after " ] ||
    fail "served in the order $order, not $high $mid $low $after (priorities 9, 5, 0, then 20 after $low)"
say "served in priority order: 9 before 5 before 0"
python3 -c 'import sys; assert float(sys.argv[1]) >= float(sys.argv[2])' \
    "$(field "$after" started)" "$(field "$low" finished)" ||
    fail "job $after (priority 20) started before job $low it waits for was done"
say "the priority-20 job waited for the job it depends on"
[ "$(field "$paused" state)" = paused ] || fail "the paused job ran"
# (their renders may have been started ahead of a worker: a served job is one a worker joined)
! grep -q "serving job $gpu " "$T/worker-w1.log" || fail "a pool-gpu job was served by a default-pool worker"
! grep -q "serving job $big " "$T/worker-w1.log" || fail "a job needing tag big was served by a worker without it"
[ "$(field "$cancelled" attempts)" = 0 ] || fail "the cancelled job was rendered"
say "paused, cancelled, other-pool and missing-tag jobs were left alone"

say "outputs against plain renders"
reference low "$TF_ROOT/scenes/valley.scene" --size 96x64
reference mid "$TF_ROOT/scenes/default.scene" --size 80x60 --tasks rows:8
reference high "$TF_ROOT/scenes/mesa.scene" --size 64x48
reference after "$TF_ROOT/scenes/valley.scene" --size 72x40
for p in "$low low" "$mid mid" "$high high" "$after after"; do set -- $p; check_output "$1" "$2"; done

say "resume the paused job; workers of pool gpu and with tag big take the others"
tf resume "$paused" >/dev/null || fail "resume"
worker w2 --pool gpu
worker w3 --tags big,fast
wait_state "$paused" done
wait_state "$gpu" done
wait_state "$big" done
grep -q "job $gpu" "$T/worker-w2.log" || fail "the gpu job was not served by the gpu worker"
grep -q "job $big" "$T/worker-w3.log" || fail "the big job was not served by the worker tagged big"

say "a farm killed mid-queue continues where it stopped"
# The workers are frozen (SIGSTOP) before the first job comes and let run 20 ms at a time, the
# farm asked only while they are frozen, until it shows that job running (or done, on a machine
# that renders it in one slice): it cannot end unseen between two looks, whatever the machine's
# speed.  Frozen, the second is queued behind it and the farm is killed: the second is
# unfinished then (no worker could move since it came), and every job running at the kill must
# be started again and resumed.  (A worker's forked processes share its command line: a second
# STOP catches one forked while the first was sent.)
freeze() { workers_signal "$PORT" STOP; workers_signal "$PORT" STOP; }
freeze
long=$(submit "$TF_ROOT/scenes/alps.scene" --size 480x270 --name long --tasks rows:2)
i=0
until case $(field "$long" state) in running | done) true ;; *) false ;; esac; do
    i=$((i + 1)); [ $i -lt 1200 ] || fail "job $long never ran"
    workers_signal "$PORT" CONT; sleep 0.02; freeze; sleep 0.05
done
next=$(submit "$TF_ROOT/scenes/valley.scene" --size 480x270 --name next --tasks rows:2)
at_kill="$long:$(field "$long" state) $next:$(field "$next" state)"
OLDPORT=$PORT
# A render whose results were all in before the freeze can still finish, and the farm record it
# done, between that look and the kill: its log then says "done" before this instant.
kill_at=$(date +%s.%N)
kill -KILL $FARM
wait $FARM 2>/dev/null
workers_signal "$OLDPORT" CONT
say "killed with $at_kill"
case "$at_kill" in *:done) fail "job $next finished with every worker frozen: $at_kill" ;; esac
start_farm "$OLDPORT"
wait_state "$long" done 600
wait_state "$next" done 600
for jr in $at_kill; do
    [ "${jr#*:}" = running ] || continue
    log=$(tf job "${jr%%:*}")
    echo "$log" | grep -q "render started (attempt 2)" && continue
    done_at=$(echo "$log" | sed -n 's/^\([0-9.]*\) done$/\1/p' | head -1)
    if [ -n "$done_at" ] && awk -v d="$done_at" -v k="$kill_at" 'BEGIN {exit !(d <= k)}'; then
        say "job ${jr%%:*} finished between the look and the kill ($done_at <= $kill_at)"
        continue
    fi
    fail "job ${jr%%:*} was running at the kill but was not started again: $log"
done
say "the restarted farm finished the queue: $(grep -ho 'resuming.*disk' "$T"/state/jobs/*/render.log | tail -1)"
reference next "$TF_ROOT/scenes/valley.scene" --size 480x270 --tasks rows:2
check_output "$next" next
reference long "$TF_ROOT/scenes/alps.scene" --size 480x270 --tasks rows:2
check_output "$long" long
say "a sequence job: each frame fetched by --frame; a ?frame= that is not a number is a 400"
seqjob=$(submit "$TF_ROOT/scenes/flyby.scene" --size 48x30 --frames 0-1 --name seq)
wait_state "$seqjob" done 600
for k in 0 1; do
    reference "seq$k" "$TF_ROOT/scenes/flyby.scene" --size 48x30 --frame $k
    tf job "$seqjob" --frame $k --output "$T/got/seq$k.exr" ||
        fail "frame $k of job $seqjob cannot be downloaded"
    same_pixels "$T/ref/seq$k.exr" "$T/got/seq$k.exr" "job $seqjob frame $k"
done
for bad in x -1 1x 99999999999 ''; do
    got=$(python3 -c 'import http.client, sys
c = http.client.HTTPConnection("127.0.0.1", int(sys.argv[1]), timeout=30)
c.request("GET", "/api/jobs/%s/output?frame=%s" % (sys.argv[2], sys.argv[3]),
          headers={"Authorization": "Bearer " + open(sys.argv[4]).read().split()[-1]})
r = c.getresponse()
print(r.status, r.read().decode(errors="replace").replace("\n", " ")[:160])' \
        "$PORT" "$seqjob" "$bad" "$T/alice")
    case "$got" in "400 "*"expected a frame number"*) ;; *) fail "?frame=$bad answered: $got" ;; esac
done
say "?frame= x, -1, 1x, 99999999999 and empty: 400, one line each"
echo "standing_farm: priorities, dependency, pause/resume, cancel, pools, tags and a farm kill all hold"
