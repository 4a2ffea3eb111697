#!/bin/sh
# tests/e2e/deploy_systemd.sh: deploy/systemd/terrafarm-worker@.service.
#   1. the lines that make it work: ExecStart runs `terrafarm worker --connect %i` with the
#      secret as a credential, it restarts between renders, it installs into multi-user.target;
#   2. `systemd-analyze verify` (skipped when absent) on a copy whose ExecStart points at the
#      built binary: no unknown keys, no bad values, an executable command.
set -u
ROOT=${TF_ROOT:-$(cd "$(dirname "$0")/../.." && pwd)}
TF=${TF_BIN:-$ROOT/bin/terrafarm}
U=$ROOT/deploy/systemd/terrafarm-worker@.service
fail() { echo "FAIL: $*"; exit 1; }
[ -r "$U" ] || fail "$U is missing"

need() {
    grep -q "$1" "$U" || fail "$U lacks a line matching: $1"
}
need '^ExecStart=/usr/local/bin/terrafarm worker --connect %i --secret-file %d/secret '
need '^LoadCredential=secret:/etc/terrafarm/secret$'
need '^Restart=always$'
need '^StartLimitIntervalSec=0$'
need '^After=network-online.target$'
need '^WantedBy=multi-user.target$'
need '^DynamicUser=yes$'
grep -q '^# .*systemctl enable --now terrafarm-worker@' "$U" || fail "no usage in the header comment"

command -v systemd-analyze >/dev/null 2>&1 || {
    echo "deploy_systemd: required lines present"
    echo "skipped: systemd-analyze is not installed (required lines were checked)"
    exit 77
}
T=$(mktemp -d "${TMPDIR:-/tmp}/tf-deploy-systemd.XXXXXX") || fail "mktemp"
trap 'rm -rf "$T"' EXIT
sed "s|/usr/local/bin/terrafarm|$TF|" "$U" >"$T/terrafarm-worker@.service"
(cd "$T" && systemd-analyze verify --man=no ./terrafarm-worker@.service) >"$T/verify.out" 2>&1
rc=$?
if [ $rc -ne 0 ] || [ -s "$T/verify.out" ]; then
    cat "$T/verify.out"
    fail "systemd-analyze verify found problems (exit $rc)"
fi
echo "deploy_systemd: ok (systemd-analyze verify clean)"
