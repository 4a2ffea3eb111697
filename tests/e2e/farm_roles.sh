#!/bin/sh
# farm_roles.sh: who may do what on a standing farm (terrafarm farm), and what it refuses.
# A real farm with tokens for alice and bob (submitters) and root (admin); tests/tools/
# farm_liar.py then checks over HTTP, each with its status and a one-line error: no or a wrong
# token (401); bob neither sees (404, as for no job), controls nor downloads alice's job;
# people cannot act as workers (403) and the workers' token (derived from the secret as
# common/farm_keys.c does) cannot submit or list; the admin sees and controls all; the
# content rules (height map only with a file scene and always with one; render options from
# the allowed list, values not starting with '-'); absurd bodies and paths (a 100 MiB body is
# 413) get a 4xx and the farm keeps serving; a lying worker is answered 4xx or sensibly and
# counted on no job.  After all that a real worker serves alice's job, whose output
# (terrafarm job ID --output) is pixel for pixel a plain render, and a height-map scene
# (scenes/dem.scene, generator = file) submitted with terrafarm submit completes and matches
# a plain terrafarm render of it.
. "$(dirname "$0")/lib.sh"
e2e_init
(umask 077; head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$T/secret")
for who in alice:submitter bob:submitter root:admin; do
    n=${who%%:*}
    "$TF_BIN" farm --state "$T/state" --add-token "$n" --role "${who#*:}" >"$T/$n" 2>"$T/tok.err" ||
        fail "add-token $n: $(cat "$T/tok.err")"
    chmod 600 "$T/$n"
done
"$TF_BIN" farm --state "$T/state" --add-token alice --role admin >/dev/null 2>"$T/tok.err" &&
    fail "a second token named alice was created"
grep -q "exists already" "$T/tok.err" || fail "a second alice was refused without saying why: $(cat "$T/tok.err")"
[ "$(wc -l <"$T/tok.err")" -eq 1 ] || fail "the refusal is not one line: $(cat "$T/tok.err")"

. "$(dirname "$0")/lib_farm.sh"   # start_farm, field (wait_state is this script's own)
start_farm
tf() { "$TF_BIN" "$@"; }
wait_state() { # ID STATE [SECONDS]
    i=0 lim=$(( ${3:-300} * 5 ))
    while s=$(field "$1" state 2>/dev/null); [ "$s" != "$2" ]; do
        case "$2:$s" in done:failed|done:cancelled|failed:done|failed:cancelled)
            fail "job $1 is $s ($(field "$1" reason)), not $2" ;;
        esac
        kill -0 $FARM 2>/dev/null || fail "the farm died: $(tail -20 "$T/farm.log")"
        i=$((i + 1)); [ $i -lt $lim ] || fail "job $1 is $(field "$1" state), not $2: $(tail -20 "$T/farm.log")"
        sleep 0.2
    done
}

say "roles, content rules, absurd requests and a lying worker (tests/tools/farm_liar.py)"
python3 "$TF_ROOT/tests/tools/farm_liar.py" "127.0.0.1:$PORT" "$T/alice" "$T/bob" "$T/root" \
    "$T/secret" "$TF_ROOT/scenes/default.scene" "$TF_ROOT/scenes/dem.scene" "$T/job_a" ||
    fail "farm_liar.py (farm log: $(tail -5 "$T/farm.log"))"
kill -0 $FARM 2>/dev/null || fail "the farm died: $(tail -20 "$T/farm.log")"
read -r A G <"$T/job_a"

say "the command line says the same: bob cannot see or download alice's job $A"
TERRAFARM_TOKEN_FILE=$T/bob tf job "$A" >/dev/null 2>"$T/bob.err" && fail "bob saw job $A"
TERRAFARM_TOKEN_FILE=$T/bob tf cancel "$A" >/dev/null 2>>"$T/bob.err" && fail "bob cancelled job $A"
grep -q "no job $A of yours" "$T/bob.err" || fail "bob was not told 'no job $A of yours': $(cat "$T/bob.err")"
[ "$(field "$A" state)" = queued ] || fail "job $A is $(field "$A" state), not queued"

say "the height-map scene submitted with terrafarm submit (its file's bytes travel with it)"
D=$(tf submit "$TF_ROOT/scenes/dem.scene" --size 64x36 --name dem 2>"$T/submit.err") ||
    fail "submit dem.scene: $(cat "$T/submit.err")"

say "a real worker serves both"
"$TF_BIN" worker --connect "http://127.0.0.1:$PORT" --secret-file "$T/secret" --name real -j 2 \
    >"$T/worker.log" 2>&1 &
e2e_track $!
wait_state "$A" done
wait_state "$D" done
if [ "$G" != 0 ]; then
    wait_state "$G" failed
    say "job $G (a height map that is no raster) failed: $(field "$G" reason)"
    [ -n "$(field "$G" reason)" ] || fail "job $G failed without a reason"
fi
mkdir -p "$T/got" "$T/ref"
tf job "$A" --output "$T/got/a.exr" || fail "alice cannot download job $A's output"
TERRAFARM_TOKEN_FILE=$T/bob tf job "$A" --output "$T/got/bob.exr" 2>/dev/null &&
    fail "bob downloaded alice's finished job"
[ -e "$T/got/bob.exr" ] && [ -s "$T/got/bob.exr" ] && fail "bob got alice's pixels"
TERRAFARM_TOKEN_FILE=$T/root tf job "$D" --output "$T/got/dem.exr" ||
    fail "the admin cannot download job $D's output"
tf render "$TF_ROOT/scenes/default.scene" --listen 127.0.0.1:0 -j 2 --size 48x32 \
    -o "$T/ref/a.exr" 2>"$T/ref.err" || fail "reference render: $(cat "$T/ref.err")"
tf render "$TF_ROOT/scenes/dem.scene" --listen 127.0.0.1:0 -j 2 --size 64x36 \
    -o "$T/ref/dem.exr" 2>"$T/ref.err" || fail "reference dem render: $(cat "$T/ref.err")"
same_pixels "$T/ref/a.exr" "$T/got/a.exr" "alice's job $A after the attacks"
same_pixels "$T/ref/dem.exr" "$T/got/dem.exr" "the height-map job $D"
[ "$(field "$A" attempts)" = 1 ] || fail "job $A took $(field "$A" attempts) renders, not 1"
kill -0 $FARM 2>/dev/null || fail "the farm died: $(tail -20 "$T/farm.log")"
if grep -E "AddressSanitizer|runtime error|Assertion" "$T/farm.log"; then fail "the farm log shows a bug"; fi
echo "farm_roles: tokens and roles, content rules, absurd requests and a lying worker hold; real jobs still complete"
