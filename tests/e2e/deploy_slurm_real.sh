#!/bin/sh
# deploy_slurm_real.sh: deploy/slurm/terrafarm.sbatch submitted with sbatch to a real Slurm.
#
# A private two-node cluster on this machine, built from network namespaces on a bridge (as
# tests/e2e/netns_farm.sh does): slurmctld on "ctl" (10.79.0.1), slurmd on "node1" (.2) and
# "node2" (.3), each slurmd in its own network and UTS namespace (its own address and host
# name; nsenter keeps the host's /sys/fs/cgroup, which slurmd wants), one munged (its own key
# and socket) for all.  slurm.conf, state, spool and logs live in the test's temp dir; nothing
# under /etc is read or written (SLURM_CONF points every command at ours).
#   1. sbatch -N 2 terrafarm.sbatch SCENE OUT.exr: the coordinator runs on node1, `srun`
#      starts a networked worker on node2; the job completes, node2's worker rendered tasks,
#      and the image is byte-identical to a local render.
#   2. A bigger job is requeued by Slurm mid-render (scontrol requeue, its workers frozen first
#      so that it cannot finish before): the script's --resume
#      makes the second run continue the partial image instead of refusing it ("resuming ..."
#      in the job's output), and the final image is byte-identical to a local render.
# Skips (77) with the reason where the daemons are not installed or cannot start, or network
# namespaces cannot be made.
set -u
ROOT=${TF_ROOT:-$(cd "$(dirname "$0")/../.." && pwd)}
TF=${TF_BIN:-$ROOT/bin/terrafarm}
SCENE=$ROOT/scenes/default.scene
SBATCH_SCRIPT=$ROOT/deploy/slurm/terrafarm.sbatch

skip() { echo "skipped: $*"; exit 77; }
fail() { echo "FAIL: $*"; exit 1; }
note() { echo "deploy_slurm_real: $*"; }

[ "$(id -u)" -eq 0 ] || skip "needs root (slurmd runs jobs as their user; network namespaces)"
for p in munged slurmctld slurmd sbatch scontrol ip nsenter unshare; do
    command -v "$p" >/dev/null 2>&1 || [ -x "/usr/sbin/$p" ] ||
        skip "$p is not installed (make deps: slurm-wlm, munge)"
done
PATH=$PATH:/usr/sbin
[ -x "$TF" ] || fail "$TF is not built (run make)"

T=$(mktemp -d "${TMPDIR:-/tmp}/tf-slurm.XXXXXX") || fail "mktemp"
chmod 755 "$T"
export SLURM_CONF="$T/slurm.conf"
# The daemons run in the foreground as children of this script, so it can stop and reap them.
DAEMONS="" NAMESPACES=""
NS=tf-$$-slurm
cleanup() {
    [ -n "$NAMESPACES" ] && ip netns exec "$NS-ctl" scancel --full --quiet --user="$(id -un)" 2>/dev/null
    for pid in $DAEMONS; do kill "$pid" 2>/dev/null; done
    for pid in $DAEMONS; do wait "$pid" 2>/dev/null; done
    for ns in $NAMESPACES; do ip netns delete "$ns" 2>/dev/null; done
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

# ---- the network: a bridge and three hosts ----
for n in lan ctl node1 node2; do
    ip netns add "$NS-$n" 2>"$T/ip.err" || skip "ip netns add failed: $(head -1 "$T/ip.err")"
    NAMESPACES="$NAMESPACES $NS-$n"
    ip -n "$NS-$n" link set lo up || fail "lo in $NS-$n"
done
if ! { ip -n "$NS-lan" link add br0 type bridge && ip -n "$NS-lan" link set br0 up; }; then
    skip "cannot create a bridge in a network namespace"
fi
i=1
for n in ctl node1 node2; do
    if ! { ip -n "$NS-lan" link add "p-$n" type veth peer name eth0 netns "$NS-$n" &&
        ip -n "$NS-lan" link set "p-$n" master br0 && ip -n "$NS-lan" link set "p-$n" up &&
        ip -n "$NS-$n" addr add "10.79.0.$i/24" dev eth0 && ip -n "$NS-$n" link set eth0 up; }; then
        fail "cannot plug $n into the bridge"
    fi
    i=$((i + 1))
done
# on_ctl CMD...: a Slurm client command, run on the controller's host
on_ctl() { ip netns exec "$NS-ctl" "$@"; }

# ---- slurm ----
CPUS=$(nproc)
mkdir -p "$T/state" "$T/spool/node1" "$T/spool/node2" "$T/log" "$T/job"
cat >"$SLURM_CONF" <<CONF
ClusterName=tftest
SlurmctldHost=ctl(10.79.0.1)
SlurmctldPort=6817
SlurmdPort=6818
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
# cred_expire: how long a requeued job is held back (and its old credential stays revoked on
# the nodes); the default is 120 s.  Forcing an earlier start made slurmd refuse the launch
# ("Job credential revoked") whenever it came too soon after the kill.
AuthInfo=socket=$T/munge/sock,cred_expire=10
CredType=cred/munge
StateSaveLocation=$T/state
SlurmdSpoolDir=$T/spool/%n
SlurmctldPidFile=$T/slurmctld.pid
SlurmdPidFile=$T/slurmd-%n.pid
SlurmctldLogFile=$T/log/slurmctld.log
SlurmdLogFile=$T/log/slurmd-%n.log
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
NodeName=node1 NodeAddr=10.79.0.2 CPUs=$CPUS State=UNKNOWN
NodeName=node2 NodeAddr=10.79.0.3 CPUs=$CPUS State=UNKNOWN
PartitionName=tf Nodes=node1,node2 Default=YES MaxTime=10 State=UP
CONF
# Each daemon as its host: its network namespace and its own host name (slurmd takes its node
# name from it).  nsenter, unshare and sh all exec, so $! is the daemon itself.
# shellcheck disable=SC2016 # expanded by the inner sh, from its own arguments
AS_HOST='hostname "$0" && exec "$@"'
nsenter --net="/run/netns/$NS-ctl" unshare --uts sh -c "$AS_HOST" ctl \
    slurmctld -D -i -f "$SLURM_CONF" 2>"$T/ctld.err" &
CTLD=$!
DAEMONS="$DAEMONS $CTLD"
nsenter --net="/run/netns/$NS-node1" unshare --uts sh -c "$AS_HOST" node1 \
    slurmd -D -f "$SLURM_CONF" 2>"$T/slurmd1.err" &
D1=$!
DAEMONS="$DAEMONS $D1"
nsenter --net="/run/netns/$NS-node2" unshare --uts sh -c "$AS_HOST" node2 \
    slurmd -D -f "$SLURM_CONF" 2>"$T/slurmd2.err" &
D2=$!
DAEMONS="$DAEMONS $D2"
i=0
until [ "$(on_ctl sinfo -h -N -o %t 2>/dev/null | grep -c idle)" -eq 2 ]; do
    kill -0 $CTLD 2>/dev/null || skip "slurmctld cannot start here: $(tail -1 "$T/log/slurmctld.log" 2>/dev/null)"
    kill -0 $D1 2>/dev/null || skip "slurmd cannot start here: $(tail -1 "$T/slurmd1.err" 2>/dev/null)"
    kill -0 $D2 2>/dev/null || skip "slurmd cannot start here: $(tail -1 "$T/slurmd2.err" 2>/dev/null)"
    i=$((i + 1))
    [ $i -le 150 ] || skip "the Slurm nodes never became idle: $(tail -2 "$T/slurmd1.err" | tr '\n' ' ')"
    sleep 0.1
done
note "slurmctld + 2 slurmd (network namespaces) + munged up: $(on_ctl sinfo -h -o '%P %D nodes %t %c CPUs each')"

# job_state ID: Slurm's state of the job
job_state() { on_ctl scontrol show job "$1" 2>/dev/null | sed -n 's/.*JobState=\([A-Z_]*\).*/\1/p'; }

# submit OUT SIZE [ARGS]: sbatch -N 2 the deploy script; the job id in JOB.  The coordinator
# finds node1's address itself (hostname -I in node1's namespace); it forks one local worker.
submit() {
    out=$1 size=$2; shift 2
    JOB=$(on_ctl sbatch --parsable -N 2 --chdir="$T/job" --output="$T/job/slurm-%j.out" \
        --open-mode=append --export=ALL,TF_BIN="$TF",TF_LOCAL_WORKERS=1 \
        "$SBATCH_SCRIPT" "$SCENE" "$out" --size "$size" "$@" 2>"$T/sbatch.err") ||
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

# ---- 1. a two-node job renders what a local render does ----
SMALL=720x405
submit "$T/job/small.exr" $SMALL --stats "$T/job/small.json"
wait_done "$JOB" 90
grep -q "coordinator on node1 (10.79.0.2:[0-9]*), 1 worker node(s)" "$T/job/slurm-$JOB.out" ||
    { cat "$T/job/slurm-$JOB.out"; fail "the job did not put its coordinator on node1"; }
srun_tasks=$(sed -n 's/.*"kind": "networked".*"tasks": \([0-9]*\),.*/\1/p' "$T/job/small.json" |
    awk '{ s += $1 } END { print s + 0 }')
[ "$srun_tasks" -gt 0 ] || { cat "$T/job/slurm-$JOB.out"; fail "node2's srun worker rendered no task"; }
"$TF" render "$SCENE" --size $SMALL -j 2 -q -o "$T/local-small.exr" || fail "local render"
cmp "$T/local-small.exr" "$T/job/small.exr" || fail "the Slurm job's image differs from a local render"
note "job $JOB (sbatch -N 2) COMPLETED: node2's srun worker rendered $srun_tasks tasks; image identical to a local render"

# freeze_job_workers: SIGSTOP every worker process of this test's terrafarm: `terrafarm worker`
# processes, and the forked workers of a coordinator (a terrafarm whose parent is one).
freeze_job_workers() {
    for p in $(pgrep -f "^$TF "); do
        parent=$(ps -o ppid= -p "$p" | tr -d ' ')
        case "$(ps -o args= -p "$p")" in
        "$TF worker "*) kill -STOP "$p" ;;
        "$TF render "*) [ "$(ps -o comm= -p "$parent")" = terrafarm ] && kill -STOP "$p" ;;
        esac
    done
}

# ---- 2. requeued mid-render: the second run resumes ----
BIG=1280x720
submit "$T/job/big.exr" $BIG
i=0
until grep -q "rendering .* workers may join" "$T/job/slurm-$JOB.out" 2>/dev/null &&
    [ "$(stat -c %s "$T/job/big.exr" 2>/dev/null || echo 0)" -gt 200000 ]; do
    # PENDING, CONFIGURING, RUNNING, or "" while scontrol is briefly busy: not ended
    case "$(job_state "$JOB")" in COMPLETED | COMPLETING | FAILED | CANCELLED | TIMEOUT | NODE_FAIL | OUT_OF_MEMORY | BOOT_FAIL | DEADLINE | PREEMPTED)
        cat "$T/job/slurm-$JOB.out" 2>/dev/null
        fail "job $JOB ended ($(job_state "$JOB")) before it could be requeued" ;;
    esac
    i=$((i + 1)); [ $i -le 600 ] || fail "job $JOB wrote no rows in 60 s"
    sleep 0.1
done
# Freeze the job's workers (the coordinator's forked one, node2's srun worker): the render can
# no longer end before the requeue however fast the machine.  Every worker has joined by now
# (the script runs the coordinator with --wait-workers), and Slurm's kill of the requeued job
# sends SIGCONT before SIGTERM, so nothing stays stopped.
freeze_job_workers
[ "$(job_state "$JOB")" = RUNNING ] || fail "job $JOB is $(job_state "$JOB"), not running, with its workers frozen"
on_ctl scontrol requeue "$JOB" || fail "scontrol requeue $JOB"
i=0
until [ "$(job_state "$JOB")" = PENDING ]; do
    i=$((i + 1)); [ $i -le 600 ] || fail "job $JOB is $(job_state "$JOB"), not pending, after the requeue"
    sleep 0.1
done
# Slurm holds a requeued job back for cred_expire (10 s here), then starts it by itself.
note "job $JOB requeued mid-render ($(stat -c %s "$T/job/big.exr") bytes on disk)"
wait_done "$JOB" 120
grep -q "resuming" "$T/job/slurm-$JOB.out" ||
    { cat "$T/job/slurm-$JOB.out"; fail "the requeued job did not resume the partial image"; }
"$TF" render "$SCENE" --size $BIG -j 2 -q -o "$T/local-big.exr" || fail "local render"
cmp "$T/local-big.exr" "$T/job/big.exr" || fail "the requeued job's image differs from a local render"
note "requeued job resumed: $(grep -m1 resuming "$T/job/slurm-$JOB.out")"
note "ok"
