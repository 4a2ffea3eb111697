#!/bin/sh
# tests/e2e/deploy_shellcheck.sh: every deployment script and every netns/deploy test script
# passes shellcheck (skipped when shellcheck is not installed) and its shell's syntax check.
set -u
ROOT=${TF_ROOT:-$(cd "$(dirname "$0")/../.." && pwd)}
fail() { echo "FAIL: $*"; exit 1; }
sh -n "$ROOT/deploy/ssh-workers.sh" || fail "sh -n deploy/ssh-workers.sh"
if command -v bash >/dev/null 2>&1; then
    bash -n "$ROOT/deploy/slurm/terrafarm.sbatch" || fail "bash -n deploy/slurm/terrafarm.sbatch"
fi
for t in "$ROOT"/tests/e2e/netns_*.sh "$ROOT"/tests/e2e/deploy_*.sh; do
    sh -n "$t" || fail "sh -n $t"
done
command -v shellcheck >/dev/null 2>&1 || { echo "skipped: shellcheck is not installed (syntax checked)"; exit 77; }
shellcheck "$ROOT/deploy/ssh-workers.sh" "$ROOT/deploy/slurm/terrafarm.sbatch" || fail "shellcheck deploy/"
shellcheck -s sh "$ROOT"/tests/e2e/netns_*.sh "$ROOT"/tests/e2e/deploy_*.sh || fail "shellcheck tests/e2e"
echo "deploy_shellcheck: ok"
