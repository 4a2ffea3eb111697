#!/bin/sh
# deploy_slurm_real.sh: deploy/slurm/terrafarm.sbatch submitted with sbatch to a real Slurm.
#
# A private one-node cluster on this machine: munged (its own key and socket), slurmctld and
# slurmd (Debian's slurm-wlm) with a slurm.conf, state and spool in the test's temp dir, on free
# ports; nothing under /etc is read or written (SLURM_CONF points every command at ours).
#   1. sbatch -N 1 terrafarm.sbatch SCENE OUT.exr: the job completes and its image is
#      byte-identical to a local render.
#   2. A bigger job is requeued by Slurm mid-render (scontrol requeue): the script's --resume
#      makes the second run continue the partial image instead of refusing it ("resuming ..."
#      in the job's output), and the final image is byte-identical to a local render.
# This cluster has one node, so the script's srun workers (used from two nodes up) are not
# exercised here; they are checked against stand-ins in deploy_slurm.sh.  Skips (77) with the
# reason where the daemons are not installed or cannot start.
set -u
ROOT=${TF_ROOT:-$(cd "$(dirname "$0")/../.." && pwd)}
TF=${TF_BIN:-$ROOT/bin/terrafarm}
SCENE=$ROOT/scenes/default.scene
SBATCH_SCRIPT=$ROOT/deploy/slurm/terrafarm.sbatch

skip() { echo "skipped: $*"; exit 77; }
fail() { echo "FAIL: $*"; exit 1; }
note() { echo "deploy_slurm_real: $*"; }

[ "$(id -u)" -eq 0 ] || skip "needs root (slurmd runs jobs as their user)"
for p in munged slurmctld slurmd sbatch scontrol; do
    command -v "$p" >/dev/null 2>&1 || [ -x "/usr/sbin/$p" ] ||
        skip "$p is not installed (make deps: slurm-wlm, munge)"
done
PATH=$PATH:/usr/sbin
[ -x "$TF" ] || fail "$TF is not built (run make)"

T=$(mktemp -d "${TMPDIR:-/tmp}/tf-slurm.XXXXXX") || fail "mktemp"
chmod 755 "$T"
export SLURM_CONF="$T/slurm.conf"
# The daemons run in the foreground as children of this script, so it can stop and reap them.
DAEMONS=""
cleanup() {
    scancel --full --quiet --user="$(id -un)" 2>/dev/null
    for pid in $DAEMONS; do kill "$pid" 2>/dev/null; done
    for pid in $DAEMONS; do wait "$pid" 2>/dev/null; done
    rm -rf "$T"
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

# ---- munge ----
mkdir -m 755 "$T/munge"
dd if=/dev/urandom of="$T/munge.key" bs=1024 count=1 2>/dev/null
chmod 600 "$T/munge.key"
munged --foreground --force --key-file="$T/munge.key" --socket="$T/munge/sock" \
    --pid-file="$T/munge/pid" --log-file="$T/munge/log" --seed-file="$T/munge/seed" \
    2>"$T/munged.err" &
DAEMONS="$DAEMONS $!"
i=0
until [ -S "$T/munge/sock" ]; do
    kill -0 $! 2>/dev/null || skip "munged cannot start here: $(head -1 "$T/munged.err")"
    i=$((i + 1)); [ $i -le 100 ] || skip "munged made no socket in 10 s"
    sleep 0.1
done

# ---- slurm ----
HOST=$(hostname -s)
CPUS=$(nproc)
# shellcheck disable=SC2046 # three port numbers, split on purpose
set -- $(python3 -c '
import socket
s = [socket.socket() for _ in range(3)]
for x in s: x.bind(("127.0.0.1", 0))
print(" ".join(str(x.getsockname()[1]) for x in s))')
CTLD_PORT=$1 SLURMD_PORT=$2 TF_PORT=$3
mkdir -p "$T/state" "$T/spool" "$T/log" "$T/job"
cat >"$SLURM_CONF" <<CONF
ClusterName=tftest$$
SlurmctldHost=$HOST(127.0.0.1)
SlurmctldPort=$CTLD_PORT
SlurmdPort=$SLURMD_PORT
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$T/munge/sock
CredType=cred/munge
StateSaveLocation=$T/state
SlurmdSpoolDir=$T/spool
SlurmctldPidFile=$T/slurmctld.pid
SlurmdPidFile=$T/slurmd.pid
SlurmctldLogFile=$T/log/slurmctld.log
SlurmdLogFile=$T/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
MpiDefault=none
SwitchType=switch/none
ReturnToService=2
PlugStackConfig=/dev/null
JobRequeue=1
NodeName=$HOST NodeAddr=127.0.0.1 CPUs=$CPUS State=UNKNOWN
PartitionName=tf Nodes=$HOST Default=YES MaxTime=10 State=UP
CONF
slurmctld -D -i -f "$SLURM_CONF" 2>"$T/ctld.err" &
CTLD=$!
DAEMONS="$DAEMONS $CTLD"
slurmd -D -f "$SLURM_CONF" 2>"$T/slurmd.err" &
SLURMD=$!
DAEMONS="$DAEMONS $SLURMD"
i=0
until sinfo -h -o %t 2>/dev/null | grep -q idle; do
    kill -0 $CTLD 2>/dev/null || skip "slurmctld cannot start here: $(tail -1 "$T/log/slurmctld.log" 2>/dev/null)"
    kill -0 $SLURMD 2>/dev/null || skip "slurmd cannot start here: $(tail -1 "$T/log/slurmd.log" 2>/dev/null)"
    i=$((i + 1))
    [ $i -le 100 ] || skip "the Slurm node never became idle: $(tail -2 "$T/log/slurmd.log" | tr '\n' ' ')"
    sleep 0.1
done
note "slurmctld + slurmd + munged up: $(sinfo -h -o '%P %D node(s) %t %c CPUs')"

# job_state ID: Slurm's state of the job
job_state() { scontrol show job "$1" 2>/dev/null | sed -n 's/.*JobState=\([A-Z_]*\).*/\1/p'; }

# submit OUT SIZE: sbatch the deploy script; the job id in JOB
submit() {
    JOB=$(sbatch --parsable -N 1 --chdir="$T/job" --output="$T/job/slurm-%j.out" --open-mode=append \
        --export=ALL,TF_BIN="$TF",TF_PORT="$TF_PORT",TF_LISTEN_HOST=127.0.0.1,TF_LOCAL_WORKERS=2 \
        "$SBATCH_SCRIPT" "$SCENE" "$1" --size "$2" 2>"$T/sbatch.err") ||
        fail "sbatch refused the job: $(cat "$T/sbatch.err")"
}

# wait_done ID SECONDS
wait_done() {
    i=0
    while :; do
        st=$(job_state "$1")
        case "$st" in COMPLETED) return 0 ;; FAILED | CANCELLED | TIMEOUT | NODE_FAIL | OUT_OF_MEMORY)
            cat "$T"/job/slurm-"$1".out 2>/dev/null; fail "job $1 ended $st" ;;
        esac
        i=$((i + 1))
        [ $i -le $(($2 * 10)) ] || { cat "$T"/job/slurm-"$1".out 2>/dev/null; fail "job $1 still $st after $2 s"; }
        sleep 0.1
    done
}

# ---- 1. a job renders what a local render does ----
SMALL=240x135
submit "$T/job/small.exr" $SMALL
wait_done "$JOB" 60
"$TF" render "$SCENE" --size $SMALL -j 2 -q -o "$T/local-small.exr" || fail "local render"
cmp "$T/local-small.exr" "$T/job/small.exr" || fail "the Slurm job's image differs from a local render"
note "job $JOB (sbatch terrafarm.sbatch) COMPLETED; image identical to a local render"

# ---- 2. requeued mid-render: the second run resumes ----
BIG=1280x720
submit "$T/job/big.exr" $BIG
i=0
until grep -q "rendering .* workers may join" "$T/job/slurm-$JOB.out" 2>/dev/null &&
    [ "$(stat -c %s "$T/job/big.exr" 2>/dev/null || echo 0)" -gt 200000 ]; do
    [ "$(job_state "$JOB")" = RUNNING ] || [ "$(job_state "$JOB")" = PENDING ] ||
        { cat "$T/job/slurm-$JOB.out"; fail "job $JOB ended before it could be requeued"; }
    i=$((i + 1)); [ $i -le 600 ] || fail "job $JOB wrote no rows in 60 s"
    sleep 0.1
done
[ "$(job_state "$JOB")" = RUNNING ] || fail "job $JOB finished before the requeue (raise BIG)"
scontrol requeue "$JOB" || fail "scontrol requeue $JOB"
# Slurm holds a requeued job back for a while (its begin time moves ~2 min ahead): start it now
i=0
until [ "$(job_state "$JOB")" = PENDING ]; do
    i=$((i + 1)); [ $i -le 300 ] || fail "job $JOB is $(job_state "$JOB"), not pending, after the requeue"
    sleep 0.1
done
scontrol update JobId="$JOB" StartTime=now || fail "cannot release the requeued job $JOB"
note "job $JOB requeued mid-render ($(stat -c %s "$T/job/big.exr") bytes on disk)"
wait_done "$JOB" 120
grep -q "resuming" "$T/job/slurm-$JOB.out" ||
    { cat "$T/job/slurm-$JOB.out"; fail "the requeued job did not resume the partial image"; }
"$TF" render "$SCENE" --size $BIG -j 2 -q -o "$T/local-big.exr" || fail "local render"
cmp "$T/local-big.exr" "$T/job/big.exr" || fail "the requeued job's image differs from a local render"
note "requeued job resumed: $(grep -m1 resuming "$T/job/slurm-$JOB.out")"
note "ok"
