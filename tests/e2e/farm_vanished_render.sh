#!/bin/sh
# farm_vanished_render.sh: a farm worker sent to a job whose render has gone (it died between
# the farm's assignment and the worker's connect) reports the session "lost", not "failed":
# a refused connection is the render's absence, not the worker's fault, and a "failed" counts
# toward barring the worker from the job.  When that happened three times before the job's
# render had failed its own three attempts, the only worker was barred from a job that could
# then never end (tests/e2e/farm_roles.sh hung on it under load).  tests/tools/vanishing_farm.py
# is the farm: it assigns a job at a port where nothing listens and records the outcome the
# worker reports with its next request.  No timing: the refusal is immediate and certain.
. "$(dirname "$0")/lib.sh"
e2e_init

(umask 077; head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$T/secret")
python3 "$TF_ROOT/tests/tools/vanishing_farm.py" "$T/port" "$T/outcome" &
farm=$!; e2e_track $farm
wait_for_file "$T/port" $farm vanishing_farm.py
PORT=$(cat "$T/port")

say "a worker sent to job 7, whose render refuses the connection"
"$TF_BIN" worker --connect "http://127.0.0.1:$PORT" --secret-file "$T/secret" --name w -j 1 \
    >"$T/worker.log" 2>&1 &
W=$!
e2e_track $W
i=0
while [ ! -s "$T/outcome" ]; do
    kill -0 $W 2>/dev/null || fail "the worker left: $(tail -5 "$T/worker.log")"
    i=$((i + 1)); [ $i -lt 1200 ] || fail "no outcome reported in 120 s: $(tail -5 "$T/worker.log")"
    sleep 0.1
done
read -r job outcome <"$T/outcome"
[ "$job" = 7 ] || fail "the outcome is for job $job, not 7"
[ "$outcome" = lost ] || fail "the session ended '$outcome', not 'lost' (worker log: $(tail -3 "$T/worker.log"))"
grep -q "refused" "$T/worker.log" || fail "the worker did not say the connection was refused: $(cat "$T/worker.log")"
say "reported: job $job $outcome"
echo "PASS"
