#!/bin/sh
# farm_openapi.sh: docs/farm-api.yaml against a real standing farm, both ways
# (tests/tools/farm_openapi_check.py): every operation the spec lists is called (as the caller
# its security names, with the login cookie where allowed, without a token, with the wrong kind
# of token, and with the cookie but without X-Terrafarm-Request), and each answer's status must
# be one the spec lists and its JSON must match the spec's schema; every route the spec does
# not list must answer 404.  One job is rendered to done by a staying worker first, so that the
# output route has something to give.
. "$(dirname "$0")/lib.sh"
e2e_init
python3 -c 'import yaml' 2>/dev/null || skip "python3-yaml is not installed"
(umask 077; head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$T/secret")
"$TF_BIN" farm --state "$T/state" --add-token root --role admin >"$T/admin" || fail "add-token"
"$TF_BIN" farm --listen 127.0.0.1:0 --state "$T/state" --secret-file "$T/secret" >"$T/farm.log" 2>&1 &
FARM=$!
e2e_track $FARM
i=0
until PORT=$(sed -n 's/.*farm on http:\/\/127.0.0.1:\([0-9]*\):.*/\1/p' "$T/farm.log") && [ -n "$PORT" ]; do
    kill -0 $FARM 2>/dev/null || fail "the farm did not start: $(cat "$T/farm.log")"
    sleep 0.1; i=$((i + 1)); [ $i -lt 600 ] || fail "the farm printed no port"
done
export TERRAFARM_FARM=127.0.0.1:$PORT TERRAFARM_TOKEN_FILE=$T/admin
# The workers' token, as a worker derives it from the farm secret.
WTOKEN=$(python3 "$TF_ROOT/tests/tools/farm_worker_token.py" "$T/secret") || fail "the workers' token"

say "one job rendered to done, for the output route"
done_job=$("$TF_BIN" submit "$SCENE" --size 32x24 --name first 2>"$T/submit.err") || fail "submit: $(cat "$T/submit.err")"
"$TF_BIN" worker --connect "http://127.0.0.1:$PORT" --secret-file "$T/secret" --name w1 -j 1 >"$T/worker.log" 2>&1 &
e2e_track $!
i=0
until "$TF_BIN" job "$done_job" --json 2>/dev/null | grep -q '"state": *"done"'; do
    i=$((i + 1)); [ $i -lt 1500 ] || fail "job $done_job never finished: $(tail -5 "$T/farm.log")"
    sleep 0.2
done

say "the spec against the farm at 127.0.0.1:$PORT"
python3 "$TF_ROOT/tests/tools/farm_openapi_check.py" "${TF_OPENAPI_SPEC:-$TF_ROOT/docs/farm-api.yaml}" \
    "127.0.0.1:$PORT" "$(tail -1 "$T/admin")" "$WTOKEN" "$SCENE" "$done_job" \
    "$TF_ROOT/coordinator/farm/farmapi.c" >"$T/check.out" 2>&1
crc=$?
cat "$T/check.out"
[ $crc -eq 0 ] || fail "the farm and docs/farm-api.yaml disagree: $(grep FAIL "$T/check.out" | head -3)"
echo "farm_openapi: every route in docs/farm-api.yaml answers as described, and no other route exists"
