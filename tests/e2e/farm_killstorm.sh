#!/bin/sh
# farm_killstorm.sh: a kill storm on a standing farm.  Four jobs are queued for two staying
# workers; five times, while a job is running, the workers are frozen (SIGSTOP, so the job
# cannot finish whatever the machine's speed), the farm is killed with SIGKILL and started
# again on the same state folder and port, and the workers are thawed.  Then every job must be
# done (none lost from the queue), each running job must have been started again and resumed
# from its output, and every output must be pixel for pixel a plain `terrafarm render`.
. "$(dirname "$0")/lib.sh"
e2e_init
. "$(dirname "$0")/lib_farm.sh"
farm_init
start_farm
KILLS=5
ARGS="--size 960x540 --tasks rows:2"
for sc in alps valley mesa default; do
    "$TF_BIN" submit "$TF_ROOT/scenes/$sc.scene" $ARGS --name "$sc" >>"$T/ids" || fail "submit $sc"
done
farm_worker w1 -j 1
farm_worker w2 -j 1

# running_job: the id of a running job; "none" once every job is done; nothing otherwise
running_job() {
    "$TF_BIN" jobs --json | python3 -c '
import json, sys
jobs = json.load(sys.stdin)["jobs"]
r = [j["id"] for j in jobs if j["state"] == "running"]
print(r[0] if r else "none" if all(j["state"] == "done" for j in jobs) else "")'
}
# Each round: a job runs, the workers are frozen at once (so the job cannot finish while the
# farm is killed), the farm is killed and restarted, the workers thawed.  The rounds end after
# KILLS kills or when every job is done.
kills=0
while [ $kills -lt $KILLS ]; do
    i=0
    until j=$(running_job) && [ -n "$j" ]; do
        i=$((i + 1)); [ $i -lt 3000 ] || fail "no job ran (kill $kills): $(cat "$T/farm.log")"
        sleep 0.05
    done
    [ "$j" = none ] && break
    workers_signal "$PORT" STOP
    if [ "$(field "$j" state)" != running ]; then # it finished just before the freeze
        workers_signal "$PORT" CONT
        continue
    fi
    kill -KILL $FARM; wait $FARM 2>/dev/null
    kills=$((kills + 1))
    workers_signal "$PORT" CONT
    start_farm "$PORT"
done
say "$kills kills of the farm with a job running"
[ $kills -ge 3 ] || fail "the jobs finished before three kills could land"
for id in $(cat "$T/ids"); do wait_state "$id" done 600; done
total=$("$TF_BIN" jobs --json | python3 -c 'import json,sys; print(len(json.load(sys.stdin)["jobs"]))')
[ "$total" = 4 ] || fail "the queue holds $total jobs, not 4"
renders=$("$TF_BIN" jobs --json | python3 -c 'import json,sys; print(sum(j["attempts"] for j in json.load(sys.stdin)["jobs"]))')
resumed=$(cat "$T"/state/jobs/*/render.log | grep -c 'rows already on disk')
say "4 of 4 jobs done in $renders renders; $resumed of them resumed rows on disk"
[ "$renders" -ge $((4 + kills)) ] || fail "$kills kills of a running job but only $renders renders"
n=0
for sc in alps valley mesa default; do
    n=$((n + 1))
    "$TF_BIN" render "$TF_ROOT/scenes/$sc.scene" $ARGS --listen 127.0.0.1:0 -j 2 -o "$T/ref$n.exr" \
        2>"$T/ref.err" || fail "reference $sc: $(cat "$T/ref.err")"
    "$TF_BIN" job "$n" --output "$T/got$n.exr" || fail "download job $n"
    same_pixels "$T/ref$n.exr" "$T/got$n.exr" "job $n ($sc) after the storm"
done
echo "farm_killstorm: $kills kills, no job lost, every output the plain render's"
