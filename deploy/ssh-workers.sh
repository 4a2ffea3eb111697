#!/bin/sh
# deploy/ssh-workers.sh: start terrafarm workers on a list of machines over ssh.
#
# Start the coordinator first, listening on an address the worker machines can reach, with a
# secret file (required on any non-loopback address), and --wait-workers with the number of
# worker processes the hosts file starts (plus -j, the coordinator's own), so that no task is
# dealt before every machine has joined (a small render is otherwise over before the last
# machine connects, and that machine's workers fail to find the coordinator):
#     terrafarm render scenes/alps.scene -o alps.exr --listen 0.0.0.0:7878 --secret-file secret \
#         -j 0 --wait-workers 16
# then, from any machine that can ssh to the workers:
#     deploy/ssh-workers.sh --connect coord.example.org:7878 --push-secret secret hosts.txt
#
# HOSTS is a file with one worker machine a line: "[user@]host [N]", N (optional) the worker
# processes for that machine (else -j, else the machine's CPU count); '#' starts a comment.
# Each worker machine needs terrafarm installed (make install, or --bin PATH) and the secret at
# --secret-file (relative paths are relative to the remote home); --push-secret copies it there
# first (mode 600, through ssh's stdin: it never appears on a command line).
#
# By default the workers run in the foreground, one ssh per host in parallel, their output
# prefixed with the host; the script ends when they all have (workers leave when the render is
# finished) and fails if any failed.  --detach starts them under nohup and returns at once
# (output in ~/terrafarm-worker.log on each host).  --dry-run prints the exact commands, one a
# line, ready to paste into a shell, and runs nothing.
set -u

usage() {
    cat <<'EOF'
usage: deploy/ssh-workers.sh --connect HOST:PORT [options] HOSTS
  --connect HOST:PORT   the coordinator, as the worker machines see it (required)
  --secret-file PATH    the secret on the worker machines (default .config/terrafarm/secret)
  --push-secret FILE    first copy this local secret file to --secret-file on each machine
  -j N                  worker processes per machine (default: the hosts file, else all CPUs)
  --backend c|opencl    worker backend (default c)
  --bin PATH            terrafarm on the worker machines (default: terrafarm on their PATH)
  --ssh "CMD"           the ssh command (default "ssh -o BatchMode=yes")
  --detach              start the workers under nohup and return
  --dry-run             print the commands that would run, run nothing
  -h, --help            this help
EOF
}

die() {
    echo "ssh-workers: $*" >&2
    exit 2
}

# quote WORD: WORD as one shell word (unchanged when it needs no quoting).
quote() {
    case "$1" in
    "" | *[!A-Za-z0-9_@%+=:,./-]*)
        printf "'%s'" "$(printf '%s' "$1" | sed "s/'/'\\\\''/g")"
        ;;
    *) printf '%s' "$1" ;;
    esac
}

# quote_all WORD...: the words quoted and joined by spaces, as a shell would need them.
quote_all() {
    sep=""
    for w in "$@"; do
        printf '%s%s' "$sep" "$(quote "$w")"
        sep=" "
    done
}

is_count() {
    case "$1" in
    "" | *[!0-9]* | 0*) return 1 ;;
    *) [ "$1" -le 4096 ] ;;
    esac
}

CONNECT="" SECRET=.config/terrafarm/secret PUSH="" JOBS="" BACKEND=c TFBIN=terrafarm
SSH="ssh -o BatchMode=yes" DETACH=0 DRY=0 HOSTS=""
while [ $# -gt 0 ]; do
    case "$1" in
    --connect) [ $# -ge 2 ] || die "--connect needs HOST:PORT"; CONNECT=$2; shift 2 ;;
    --secret-file) [ $# -ge 2 ] || die "--secret-file needs a path"; SECRET=$2; shift 2 ;;
    --push-secret) [ $# -ge 2 ] || die "--push-secret needs a file"; PUSH=$2; shift 2 ;;
    -j | --workers) [ $# -ge 2 ] || die "-j needs a number"; JOBS=$2; shift 2 ;;
    --backend) [ $# -ge 2 ] || die "--backend needs c or opencl"; BACKEND=$2; shift 2 ;;
    --bin) [ $# -ge 2 ] || die "--bin needs a path"; TFBIN=$2; shift 2 ;;
    --ssh) [ $# -ge 2 ] || die "--ssh needs a command"; SSH=$2; shift 2 ;;
    --detach) DETACH=1; shift ;;
    --dry-run) DRY=1; shift ;;
    -h | --help) usage; exit 0 ;;
    -*) die "unknown option '$1' (see --help)" ;;
    *) [ -z "$HOSTS" ] || die "one hosts file only (got '$HOSTS' and '$1')"; HOSTS=$1; shift ;;
    esac
done
[ -n "$CONNECT" ] || die "--connect HOST:PORT is required (see --help)"
case "$CONNECT" in *:[0-9]*) ;; *) die "--connect '$CONNECT': expected HOST:PORT" ;; esac
[ -n "$HOSTS" ] || die "a hosts file is required (see --help)"
[ -r "$HOSTS" ] || die "cannot read hosts file '$HOSTS'"
[ -z "$JOBS" ] || is_count "$JOBS" || die "-j '$JOBS': expected an integer from 1 to 4096"
case "$BACKEND" in c | opencl) ;; *) die "--backend '$BACKEND': expected c or opencl" ;; esac
[ -z "$PUSH" ] || [ -r "$PUSH" ] || die "cannot read secret file '$PUSH'"

# worker_command JOBS: the command line run on a worker machine (one string for ssh).
worker_command() {
    cmd=$(quote_all "$TFBIN" worker --connect "$CONNECT" --secret-file "$SECRET" --backend "$BACKEND")
    [ -z "$1" ] || cmd="$cmd -j $1"
    if [ "$DETACH" -eq 1 ]; then
        echo "nohup $cmd >terrafarm-worker.log 2>&1 </dev/null & echo \"started worker pid \$!\""
    else
        echo "exec $cmd"
    fi
}

# push_command: the remote command that stores the secret read from stdin, owner-only.
push_command() {
    case "$SECRET" in
    */*) echo "umask 077 && mkdir -p $(quote "${SECRET%/*}") && cat >$(quote "$SECRET")" ;;
    *) echo "umask 077 && cat >$(quote "$SECRET")" ;;
    esac
}

# Read the hosts file into "host jobs" lines (validated) before running anything.
TARGETS=$(
    sed -e 's/#.*//' "$HOSTS" | while read -r host njobs extra; do
        [ -n "$host" ] || continue
        case "$host" in -*) echo "!bad host '$host'"; continue ;; esac
        [ -z "$extra" ] || { echo "!line for '$host' has extra fields: '$extra'"; continue; }
        [ -z "$njobs" ] || is_count "$njobs" || { echo "!bad worker count '$njobs' for $host"; continue; }
        echo "$host ${njobs:-$JOBS}"
    done
)
bad=$(printf '%s\n' "$TARGETS" | sed -n 's/^!//p' | head -1)
[ -z "$bad" ] || die "$HOSTS: $bad"
[ -n "$TARGETS" ] || die "$HOSTS lists no hosts"

# print_or_run HOST REMOTE INPUT: print (--dry-run) or run `ssh HOST REMOTE`, with stdin from
# the file INPUT when not empty (else /dev/null, so ssh never eats the caller's stdin).
SSH_WORDS=$SSH
print_or_run() {
    host=$1 remote=$2 input=$3
    # shellcheck disable=SC2086 # --ssh is a command line: split into words on purpose
    if [ "$DRY" -eq 1 ]; then
        line="$(quote_all $SSH_WORDS "$host" "$remote")"
        [ -z "$input" ] || line="$line <$(quote "$input")"
        echo "$line"
    elif [ -n "$input" ]; then
        $SSH_WORDS "$host" "$remote" <"$input"
    else
        $SSH_WORDS "$host" "$remote" </dev/null
    fi
}

if [ -n "$PUSH" ]; then
    printf '%s\n' "$TARGETS" | while read -r host _; do
        print_or_run "$host" "$(push_command)" "$PUSH" ||
            { echo "ssh-workers: $host: cannot store the secret" >&2; exit 1; }
    done || exit 1
fi

if [ "$DRY" -eq 1 ] || [ "$DETACH" -eq 1 ]; then
    status=0
    while read -r host njobs; do
        print_or_run "$host" "$(worker_command "$njobs")" "" || {
            echo "ssh-workers: $host: could not start the worker" >&2
            status=1
        }
    done <<EOF
$TARGETS
EOF
    exit $status
fi

# Foreground: every host at once, output prefixed with the host, then every exit status.
RC=$(mktemp -d "${TMPDIR:-/tmp}/ssh-workers.XXXXXX") || die "mktemp failed"
trap 'rm -rf "$RC"' EXIT
i=0
while read -r host njobs; do
    i=$((i + 1))
    {
        print_or_run "$host" "$(worker_command "$njobs")" "" 2>&1
        echo $? >"$RC/$i"
    } | sed "s|^|$host: |" &
done <<EOF
$TARGETS
EOF
wait
status=0 i=0
while read -r host _; do
    i=$((i + 1))
    rc=$(cat "$RC/$i" 2>/dev/null || echo "?")
    if [ "$rc" != 0 ]; then
        echo "ssh-workers: $host: worker exited with status $rc" >&2
        status=1
    fi
done <<EOF
$TARGETS
EOF
[ $status -eq 0 ] && echo "ssh-workers: all $i worker hosts finished"
exit $status
