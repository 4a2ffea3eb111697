#!/bin/sh
# tests/e2e/deploy_slurm.sh: deploy/slurm/terrafarm.sbatch.
#   1. bash -n, the #SBATCH header, a clear error outside a job;
#   2. TF_DRY_RUN=1 inside a faked 3-node job prints exactly: the secret in the job directory,
#      the coordinator on the first node's address with --listen and --secret-file, and one
#      srun step of 2 workers on the other nodes (--relative=1) using each node's CPUs;
#   3. a real run with stand-ins for scontrol and srun (srun starts its tasks locally): the
#      coordinator listens on loopback, two srun "nodes" render with it, the job exits 0 and
#      the secret is gone afterwards.
set -u
ROOT=${TF_ROOT:-$(cd "$(dirname "$0")/../.." && pwd)}
TF=${TF_BIN:-$ROOT/bin/terrafarm}
S=$ROOT/deploy/slurm/terrafarm.sbatch
fail() { echo "FAIL: $*"; exit 1; }
command -v bash >/dev/null 2>&1 || { echo "skipped: bash is not installed"; exit 77; }
T=$(mktemp -d "${TMPDIR:-/tmp}/tf-deploy-slurm.XXXXXX") || fail "mktemp"
trap 'rm -rf "$T"' EXIT

bash -n "$S" || fail "bash -n $S"
grep -q '^#SBATCH --nodes=' "$S" || fail "no #SBATCH --nodes line"
grep -q '^# Usage: *sbatch ' "$S" || fail "no usage in the header comment"
out=$(env -u SLURM_JOB_ID bash "$S" scene 2>&1) && fail "ran outside a Slurm job"
[ "$out" = "terrafarm.sbatch: not inside a Slurm job (submit with sbatch)" ] || fail "unclear error: $out"

# Stand-ins: scontrol expands the node list; srun runs --ntasks copies of its command here.
mkdir -p "$T/bin" "$T/job dir"
cat >"$T/bin/scontrol" <<'FAKE'
#!/bin/sh
[ "$1 $2" = "show hostnames" ] || exit 1
printf 'node07\nnode08\nnode09\n'
FAKE
cat >"$T/bin/srun" <<'FAKE'
#!/bin/sh
n=1
while [ $# -gt 0 ]; do
    case "$1" in --ntasks=*) n=${1#--ntasks=}; shift ;; -*) shift ;; *) break ;; esac
done
echo "srun: $n task(s): $*" >&2
i=0 pids=""
while [ $i -lt "$n" ]; do
    "$@" &
    pids="$pids $!" i=$((i + 1))
done
status=0
for p in $pids; do wait "$p" || status=1; done
exit $status
FAKE
chmod +x "$T/bin/scontrol" "$T/bin/srun"

# ---- 2. dry run ----
(cd "$T" && PATH="$T/bin:$PATH" SLURM_JOB_ID=4321 SLURM_JOB_NODELIST='node[07-09]' \
    SLURM_JOB_NUM_NODES=3 SLURM_CPUS_ON_NODE=16 SLURM_SUBMIT_DIR="$T/job dir" \
    TF_LISTEN_HOST=10.1.2.3 TF_DRY_RUN=1 TF_BIN=/opt/tf/terrafarm \
    bash "$S" scenes/alps.scene alps.exr --stats alps.json) >"$T/dry.out" 2>"$T/dry.err" ||
    { cat "$T/dry.err"; fail "dry run failed"; }
J=$(printf '%s' "$T/job dir" | sed 's/ /\\ /g')
cat >"$T/dry.expected" <<EXPECTED
(umask 077; head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \\n' >$J/.terrafarm-4321.secret)
/opt/tf/terrafarm render scenes/alps.scene -o alps.exr --resume --listen 10.1.2.3:14321 --secret-file $J/.terrafarm-4321.secret -j 16 --wait-workers 48 --stats alps.json &
srun --nodes=2 --ntasks=2 --ntasks-per-node=1 --relative=1 --cpus-per-task=16 --kill-on-bad-exit=0 /opt/tf/terrafarm worker --connect 10.1.2.3:14321 --secret-file $J/.terrafarm-4321.secret -j 16 &
EXPECTED
diff "$T/dry.expected" "$T/dry.out" || fail "dry-run commands differ from the expected ones"
grep -q "coordinator on node07 (10.1.2.3:14321), 2 worker node(s)" "$T/dry.err" ||
    fail "no summary line on stderr"
[ ! -e "$T/job dir/.terrafarm-4321.secret" ] || fail "the dry run wrote a secret"

# ---- 3. a real run on stand-ins ----
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])' 2>/dev/null) ||
    port=$((20000 + $$ % 10000))
(cd "$T" && PATH="$T/bin:$PATH" SLURM_JOB_ID=77 SLURM_JOB_NODELIST='node[07-09]' \
    SLURM_JOB_NUM_NODES=3 SLURM_CPUS_ON_NODE=1 SLURM_SUBMIT_DIR="$T/job dir" \
    TF_LISTEN_HOST=127.0.0.1 TF_PORT=$port TF_LOCAL_WORKERS=0 TF_BIN="$TF" \
    timeout 60 bash "$S" "$ROOT/scenes/default.scene" "$T/job dir/out.exr" --size 160x90 \
    --stats "$T/job dir/out.json") >"$T/run.log" 2>&1 || { cat "$T/run.log"; fail "the job failed"; }
[ -s "$T/job dir/out.exr" ] || fail "no image"
n=$(grep -c '"kind": "networked"' "$T/job dir/out.json")
[ "$n" -eq 2 ] || { cat "$T/run.log"; fail "expected 2 srun workers in the stats, found $n"; }
[ ! -e "$T/job dir/.terrafarm-77.secret" ] || fail "the job left its secret behind"
echo "deploy_slurm: dry run exact; a 3-node stand-in job rendered with 2 srun workers"
echo "deploy_slurm: ok"
