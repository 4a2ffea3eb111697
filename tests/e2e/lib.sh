# tests/e2e/lib.sh: shared helpers of the end-to-end farm and resume scripts (sourced, POSIX sh).
#
# Every script: `. "$(dirname "$0")/lib.sh"`, then e2e_init.  That makes a private temp dir
# $T, and a trap that kills every process the script started (recorded with e2e_track, plus
# their children) and removes $T, whether the script passes, fails or is interrupted.
# tests/run.sh sets TF_BIN (the binary under test: bin/terrafarm or the ASan build) and
# TF_ROOT; run by hand, both default to this checkout.  TF_KEEP_LOGS=1 keeps $T.
#
# Conventions: say() prints what is checked; fail() prints one reason and exits 1; skip()
# exits 77 with the reason as its last line.  Never a fixed port: coordinators listen on
# 127.0.0.1:0 and e2e_port reads the port they print ("workers may join at HOST:PORT").

TF_ROOT=${TF_ROOT:-$(cd "$(dirname "$0")/../.." && pwd)}
TF_BIN=${TF_BIN:-$TF_ROOT/bin/terrafarm}
SCENE=$TF_ROOT/scenes/default.scene
E2E_PIDS=""

say() { echo "-- $*"; }
fail() { echo "FAIL: $*"; exit 1; }
skip() { echo "$*"; exit 77; }
# refused RC: true when exit status RC is a refusal -- non-zero by the program's choice -- and
# not a crash: a process killed by a signal exits 128+N, which `[ $rc -ne 0 ]` would accept
refused() { [ "$1" -ge 1 ] && [ "$1" -lt 128 ]; }

e2e_cleanup() {
    for p in $E2E_PIDS; do
        for c in $(pgrep -P "$p" 2>/dev/null); do kill -KILL "$c" 2>/dev/null; kill -CONT "$c" 2>/dev/null; done
        kill -KILL "$p" 2>/dev/null
        kill -CONT "$p" 2>/dev/null
    done
    for p in $E2E_PIDS; do wait "$p" 2>/dev/null; done
    if [ -n "${TF_KEEP_LOGS:-}" ] && [ -n "${T:-}" ]; then
        echo "logs kept in $T"
    elif [ -n "${T:-}" ]; then
        rm -rf "$T"
    fi
}

e2e_init() {
    [ -x "$TF_BIN" ] || skip "no terrafarm binary at $TF_BIN (run make)"
    command -v python3 >/dev/null 2>&1 || skip "python3 is not installed"
    T=$(mktemp -d "${TMPDIR:-/tmp}/tf-e2e.XXXXXX") || fail "mktemp"
    trap e2e_cleanup EXIT
    trap 'exit 1' INT TERM HUP
}

# Remember a background process so the trap kills it (and its children).
e2e_track() { E2E_PIDS="$E2E_PIDS $1"; }

# render ARGS...: a foreground render of the default scene; stderr to $T/last.err.
render() { "$TF_BIN" render "$SCENE" --listen 127.0.0.1:0 "$@" 2>"$T/last.err"; }

# e2e_port LOGFILE [SECONDS]: wait until a coordinator logging to LOGFILE prints its port.
e2e_port() {
    i=0 lim=$(( ${2:-20} * 10 ))
    while [ $i -lt $lim ]; do
        p=$(sed -n 's/.*workers may join at [^ ]*:\([0-9][0-9]*\).*/\1/p' "$1" 2>/dev/null | head -1)
        [ -n "$p" ] && { echo "$p"; return 0; }
        sleep 0.1; i=$((i + 1))
    done
    return 1
}

# wait_exit PID SECONDS: wait for a tracked background process; its exit status in $rc.
# Fails the test if it does not end in time.
wait_exit() {
    i=0 lim=$(( $2 * 10 ))
    while kill -0 "$1" 2>/dev/null; do
        # a zombie counts as ended: `wait` below reaps it
        [ "$(ps -o stat= -p "$1" 2>/dev/null | cut -c1)" = Z ] && break
        i=$((i + 1)); [ $i -ge $lim ] && fail "process $1 still running after $2 s"
        sleep 0.1
    done
    wait "$1"; rc=$?
}

# jstat KEY FILE.json: one value of the statistics.
jstat() { python3 -c 'import json,sys; print(json.load(open(sys.argv[2]))[sys.argv[1]])' "$1" "$2"; }

# same A B WHAT: the two images must be byte-identical.
same() {
    cmp -s "$1" "$2" || fail "$3: $2 differs from the reference $1"
    say "$3: identical to the reference"
}

# rows_on_disk FILE: rows in whole verified chunks of a (partial) output, read with the
# coordinator's own probe: "resuming ...: N of H rows already on disk" from a --resume that is
# stopped right after it (its stderr is the only thing used; the copy is thrown away).
# Prints N, or nothing if the file is not resumable.
rows_on_disk() {
    mkdir -p "$T/probe" && cp "$1" "$T/probe/p.exr" && : >"$T/probe/out" || return 1
    "$TF_BIN" render "$SCENE" --listen 127.0.0.1:0 -j 0 --resume -o "$T/probe/p.exr" \
        $PROBE_ARGS >"$T/probe/out" 2>&1 &
    pp=$!
    i=0
    while [ $i -lt 100 ] && ! grep -q 'rows already on disk\|nothing to resume\|already complete\|cannot\|error' "$T/probe/out"; do
        sleep 0.05; i=$((i + 1))
    done
    kill -KILL $pp 2>/dev/null; wait $pp 2>/dev/null
    sed -n 's/.*resuming .*: \([0-9][0-9]*\) of [0-9]* rows already on disk.*/\1/p' "$T/probe/out"
    grep -q 'already complete' "$T/probe/out" && echo complete
    [ -n "${PROBE_TILES:-}" ] && { sed -n 's/.*rows already on disk (and \([0-9]*\) tiles.*/\1/p' "$T/probe/out"; echo; } >"$T/probe.tiles"
    rm -rf "$T/probe"
}

# tiles_on_disk FILE: for a tiled output, "ROWS TILES": whole rows on disk, and tiles of the
# next tile row on disk beside them.
tiles_on_disk() {
    td_rows=$(PROBE_TILES=1 rows_on_disk "$1")
    td_tiles=$(head -1 "$T/probe.tiles")
    echo "$td_rows ${td_tiles:-0}"
}

# no_leftovers PIDS...: none of these processes may still exist (zombies excluded).
no_leftovers() {
    for p in "$@"; do
        s=$(ps -o stat= -p "$p" 2>/dev/null | cut -c1)
        [ -n "$s" ] && [ "$s" != Z ] && fail "process $p ($(ps -o args= -p "$p")) outlived its coordinator"
    done
    return 0
}

# browser_tmp: the temporary directory a browser check (cdp_*.py) runs with (TMPDIR=...), where
# cdp_lib.py keeps Chromium's profile and Chromium its own temporary files; no_browser_leftovers:
# after the check, it must be empty (cdp_lib.py closes Chromium and removes the profile once no
# process of Chromium's runs: a helper left running wrote into it after it was gone, and a
# killed browser leaves its org.chromium.Chromium.* directory).
browser_tmp() { mkdir -p "$T/browser-tmp" && echo "$T/browser-tmp"; }
no_browser_leftovers() {
    nbl=$(ls -A "$T/browser-tmp" 2>/dev/null)
    [ -z "$nbl" ] || fail "Chromium's files left behind in the temporary directory: $nbl"
}

# make_partial OUT MINBYTES ARGS...: start a render of $SCENE (or $PARTIAL_SCENE) into OUT and
# SIGKILL it once OUT holds at least MINBYTES: an interrupted render, as a crash leaves it.
make_partial() {
    mp_out=$1 mp_min=$2; shift 2
    "$TF_BIN" render "${PARTIAL_SCENE:-$SCENE}" --listen 127.0.0.1:0 -o "$mp_out" "$@" 2>"$T/partial.err" &
    mp_pid=$!; e2e_track $mp_pid
    i=0
    while [ "$(wc -c 2>/dev/null <"$mp_out" || echo 0)" -lt "$mp_min" ]; do
        kill -0 $mp_pid 2>/dev/null || fail "the render to interrupt ended first: $(cat "$T/partial.err")"
        sleep 0.01; i=$((i + 1)); [ $i -lt 3000 ] || fail "$mp_out never reached $mp_min bytes"
    done
    kill -KILL $mp_pid; wait $mp_pid 2>/dev/null
    sleep 0.1   # its forked workers follow it (PR_SET_PDEATHSIG)
}

# same_pixels A B WHAT: the two renders must hold bit-identical decoded pixels (for files whose
# layout differs -- scanline vs tiled, another tile size -- where cmp cannot apply).
EXRCMP=${TF_BUILD:-$TF_ROOT/build}/tools/exrcmp
same_pixels() {
    [ -x "$EXRCMP" ] || fail "no $EXRCMP (make build/tools/exrcmp)"
    out=$("$EXRCMP" "$1" "$2" 2>&1) || fail "$3: $2 and $1 differ: $out"
    say "$3: $out, as the reference"
}

# dashboard_url LOGFILE PID: wait until a coordinator logging to LOGFILE prints its dashboard
# URL ("dashboard at http://HOST:PORT/"); prints the URL.  Fails if PID ends first.
dashboard_url() {
    i=0
    while ! grep -q 'dashboard at' "$1" 2>/dev/null; do
        kill -0 "$2" 2>/dev/null || fail "render ended before its dashboard was up: $(cat "$1")"
        sleep 0.05; i=$((i + 1)); [ $i -lt 600 ] || fail "no dashboard URL logged: $(cat "$1")"
    done
    sed -n 's/.*dashboard at \(http:[^ ]*\).*/\1/p' "$1" | head -1
}

# wait_for_file FILE PID WHAT: until FILE is not empty (a helper's port file), failing if the
# process PID (WHAT) exits first or a minute passes.
wait_for_file() {
    i=0
    while [ ! -s "$1" ]; do
        kill -0 "$2" 2>/dev/null || fail "$3 exited before writing $(basename "$1")"
        i=$((i + 1)); [ $i -lt 600 ] || fail "$3 did not write $(basename "$1") in a minute"
        sleep 0.1
    done
}

# dashboard_addr LOGFILE PID: dashboard_url's HOST:PORT, as `terrafarm status` takes it.
dashboard_addr() { dashboard_url "$1" "$2" | sed 's#http://\([^/]*\)/#\1#'; }

# busy_workers HOST:PORT: "id:task" of each worker the dashboard there shows holding a task.
busy_workers() {
    "$TF_BIN" status "$1" --json 2>/dev/null |
        python3 -c 'import json,sys; print(*["%d:%d" % (w["id"], w["task"]) for w in json.load(sys.stdin)["workers"] if w["state"] == "busy"])' 2>/dev/null
}

# start_stopped LOGFILE CMD...: CMD in the background, stopped (SIGSTOP) before it runs at all
# (its shell stops itself, then execs CMD under the same pid, $!); its output to LOGFILE.
start_stopped() {
    log=$1; shift
    # shellcheck disable=SC2016
    sh -c 'kill -STOP $$; exec "$@"' sh "$@" >"$log" 2>&1 &
}

# freeze_workers PID / thaw_workers PID: SIGSTOP / SIGCONT the forked workers of coordinator
# PID, so that a render lasts exactly as long as a test needs (the coordinator keeps serving).
freeze_workers() { for c in $(pgrep -P "$1"); do kill -STOP "$c" 2>/dev/null; done; }
thaw_workers() { for c in $(pgrep -P "$1"); do kill -CONT "$c" 2>/dev/null; done; }

# freeze_workers_at_birth PID N: wait (up to 60 s) for coordinator PID's first N forked workers
# and SIGSTOP each the moment it exists, before it can have rendered much: a render started
# just before, however fast this machine, is then still under way.  Fails if PID ends first.
freeze_workers_at_birth() {
    python3 - "$1" "$2" <<'PY' || fail "could not freeze the workers of $1 at birth"
import os, signal, subprocess, sys, time
coordinator, n = sys.argv[1], int(sys.argv[2])
frozen, t_end = set(), time.time() + 60
while len(frozen) < n and time.time() < t_end:
    with open("/proc/%s/stat" % coordinator) as f:  # gone, or a zombie: it ended
        if f.read().rsplit(")", 1)[1].split()[0] == "Z":
            sys.exit(1)
    out = subprocess.run(["pgrep", "-P", coordinator], capture_output=True, text=True).stdout
    for w in map(int, out.split()):
        if w not in frozen:
            os.kill(w, signal.SIGSTOP)
            frozen.add(w)
sys.exit(0 if len(frozen) == n else 1)
PY
}

# run_slice PID: let coordinator PID's frozen workers run 20 ms, freeze them again, and wait
# past the dashboard's next snapshot (every 200 ms).  A loop of these until a poll shows what a
# test waits for never races the machine's speed.  worker_slices.py (beside this file) is the
# same for the scripts' python.
run_slice() { thaw_workers "$1"; sleep 0.02; freeze_workers "$1"; sleep 0.25; }

# run_process_slice PID: the same for one stopped process (e.g. one start_stopped began).
run_process_slice() { kill -CONT "$1"; sleep 0.02; kill -STOP "$1"; sleep 0.25; }
