#!/bin/sh
# jobs_lying_farm.sh: the job commands (jobs, job ID, job ID --output, pause, submit) against a
# farm that lies (tests/tools/lying_farm.py): names, states, reasons and histories with escape
# sequences and newlines, fields missing or of the wrong type, errors that would clear the
# terminal.  Each command must end without crashing, and nothing it prints may carry a control
# byte other than the newline ending each line, nor a line the farm forged.
. "$(dirname "$0")/lib.sh"
e2e_init

python3 "$TF_ROOT/tests/tools/lying_farm.py" "$T/port" &
farm=$!; e2e_track $farm
wait_for_file "$T/port" $farm lying_farm.py
export TERRAFARM_FARM="127.0.0.1:$(cat "$T/port")"
(umask 077; echo "tf_0123456789abcdef" >"$T/token")
export TERRAFARM_TOKEN_FILE="$T/token"

# run WHAT EXPECTED_STATUS ARGS...: the command's status and a clean output
run() {
    what=$1 want=$2; shift 2
    "$TF_BIN" "$@" >"$T/out" 2>&1
    got=$?
    [ $got -eq "$want" ] || fail "$what: exit $got, not $want: $(cat -v "$T/out" | head -5)"
    ! tr -d '\n' <"$T/out" | grep -q '[[:cntrl:]]' ||
        fail "$what printed a control byte: $(cat -v "$T/out" | head -5)"
    ! grep -q '^terrafarm: forged' "$T/out" || fail "$what printed a line the farm forged"
    say "$what: exit $got, $(wc -l <"$T/out") clean lines"
}
run "jobs" 0 jobs
run "job 1 (escapes in its name, reason and history)" 0 job 1
grep -q '^render died' "$T/out" && fail "the reason's newline split the line"
run "job 2 (no name, reason or history)" 0 job 2
run "job 3 (fields of the wrong type)" 0 job 3
run "job 4 (an answer that is no JSON)" 1 job 4
run "job 1 --output (a refusal with escapes)" 1 job 1 --output "$T/x.exr"
[ ! -e "$T/x.exr" ] && [ ! -e "$T/x.exr.download.tmp" ] || fail "a refused download left a file"
run "pause 1 (an answer of the wrong types)" 0 pause 1
run "submit (a refusal with a forged line)" 1 submit "$TF_ROOT/scenes/default.scene"
echo "jobs_lying_farm: the job commands print a lying farm's words harmlessly and never crash"
