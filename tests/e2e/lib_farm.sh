# tests/e2e/lib_farm.sh: helpers of the standing farm's end-to-end scripts (sourced after
# lib.sh and e2e_init): a secret and a token, a farm started (again) on a port, a job's fields,
# waiting for a job's state, staying workers, freezing and thawing them.

# farm_init ROLE: the farm secret in $T/secret and a person's token (alice) in $T/alice.
farm_init() {
    (umask 077; head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$T/secret")
    "$TF_BIN" farm --state "$T/state" --add-token alice --role "${1:-submitter}" >"$T/alice" ||
        fail "add-token"
    chmod 600 "$T/alice"
}

# start_farm [PORT]: a farm on $T/state in the background ($FARM), its port in $PORT, and
# TERRAFARM_FARM / TERRAFARM_TOKEN_FILE set; restarted on the same PORT, its workers find it.
# $FARM_ARGS: more options for the farm.
start_farm() {
    : >"$T/farm.log"
    # shellcheck disable=SC2086
    "$TF_BIN" farm --listen "127.0.0.1:${1:-0}" --state "$T/state" --secret-file "$T/secret" \
        ${FARM_ARGS:-} >>"$T/farm.log" 2>&1 &
    FARM=$!
    e2e_track $FARM
    i=0
    until PORT=$(sed -n 's/.*farm on http:\/\/127.0.0.1:\([0-9]*\):.*/\1/p' "$T/farm.log") &&
          [ -n "$PORT" ]; do
        kill -0 $FARM 2>/dev/null || fail "the farm did not start: $(cat "$T/farm.log")"
        sleep 0.1; i=$((i + 1)); [ $i -lt 600 ] || fail "the farm printed no port"
    done
    export TERRAFARM_FARM=127.0.0.1:$PORT TERRAFARM_TOKEN_FILE=$T/alice
}

# field ID KEY: one field of a job (GET /api/jobs/ID)
field() {
    "$TF_BIN" job "$1" --json | python3 -c 'import json,sys; print(json.load(sys.stdin)[sys.argv[1]])' "$2"
}

# wait_state ID STATE [SECONDS]
wait_state() {
    i=0 lim=$(( ${3:-300} * 5 ))
    while [ "$(field "$1" state 2>/dev/null)" != "$2" ]; do
        i=$((i + 1)); [ $i -lt $lim ] || fail "job $1 is $(field "$1" state), not $2: $(cat "$T/farm.log")"
        sleep 0.2
    done
}

# farm_worker NAME [worker options]: a staying worker in the background, log $T/worker-NAME.log
farm_worker() {
    n=$1; shift
    "$TF_BIN" worker --connect "http://$TERRAFARM_FARM" --secret-file "$T/secret" --name "$n" \
        -j 2 "$@" >"$T/worker-$n.log" 2>&1 &
    e2e_track $!
}

# workers_signal PORT SIG: every worker process of the farm on PORT (STOP freezes, CONT thaws)
workers_signal() { pgrep -f "worker --connect http://127.0.0.1:$1" | xargs -r kill -"$2"; }
