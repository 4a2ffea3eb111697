#!/bin/sh
# deploy_ssh_real.sh: deploy/ssh-workers.sh against a real OpenSSH server.
#
# A private sshd (openssh-server) on 127.0.0.1 at a free port, with its own host key, config,
# authorized_keys and pid file in the test's temp dir (the system's sshd and its config are
# never touched); a key pair generated for the run.  A coordinator listens on loopback with a
# secret; ssh-workers.sh pushes the secret over ssh (--push-secret) and starts two worker
# "hosts" (both 127.0.0.1 through sshd) in the foreground; the render waits for both
# (--wait-workers 2).  The image must be byte-identical
# to a local render, both workers must have rendered, and the pushed secret must be mode 600.
# Skips (77) with the reason when sshd or ssh-keygen is missing or sshd cannot start here.
# shellcheck disable=SC1091 # lib.sh: the shared e2e helpers (say, fail, skip, e2e_*, same)
. "$(dirname "$0")/lib.sh"
e2e_init
SSHD=$(command -v sshd || echo /usr/sbin/sshd)
[ -x "$SSHD" ] || skip "openssh-server (sshd) is not installed (make deps)"
command -v ssh >/dev/null 2>&1 || skip "ssh (openssh-client) is not installed"
command -v ssh-keygen >/dev/null 2>&1 || skip "ssh-keygen is not installed"
[ "$(id -u)" -eq 0 ] || skip "needs root: sshd must switch to the logged-in user"
SIZE=240x135
USER_NAME=$(id -un)

ssh-keygen -q -t ed25519 -N '' -f "$T/host_key" || fail "ssh-keygen (host key)"
ssh-keygen -q -t ed25519 -N '' -f "$T/id" || fail "ssh-keygen (client key)"
cp "$T/id.pub" "$T/authorized_keys"
chmod 600 "$T/authorized_keys"
# sshd refuses to start without its privilege-separation directory; Debian's package creates
# it at boot (tmpfiles.d), a container may not have it
[ -d /run/sshd ] || mkdir -m 755 /run/sshd
PORT=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
cat >"$T/sshd_config" <<CONF
ListenAddress 127.0.0.1
Port $PORT
HostKey $T/host_key
PidFile $T/sshd.pid
AuthorizedKeysFile $T/authorized_keys
PubkeyAuthentication yes
PasswordAuthentication no
KbdInteractiveAuthentication no
UsePAM no
PermitRootLogin prohibit-password
StrictModes no
AllowUsers $USER_NAME
LogLevel ERROR
CONF
"$SSHD" -t -f "$T/sshd_config" 2>"$T/sshd.err" || skip "sshd rejects the test config: $(head -1 "$T/sshd.err")"
"$SSHD" -D -e -f "$T/sshd_config" 2>"$T/sshd.log" &
SSHD_PID=$!
e2e_track $SSHD_PID
SSH="ssh -F /dev/null -p $PORT -i $T/id -o BatchMode=yes -o StrictHostKeyChecking=no -o UserKnownHostsFile=$T/known_hosts -o LogLevel=ERROR"
i=0
until $SSH "$USER_NAME@127.0.0.1" true </dev/null 2>"$T/ssh.err"; do
    kill -0 $SSHD_PID 2>/dev/null || skip "sshd cannot run here: $(head -1 "$T/sshd.log")"
    i=$((i + 1)); [ $i -le 50 ] || fail "cannot log in through the test sshd: $(cat "$T/ssh.err")"
    sleep 0.1
done
say "sshd on 127.0.0.1:$PORT accepts the generated key"

umask 077
head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$T/secret"
umask 022
# --wait-workers 2: no task before both hosts' workers have joined.  Without it the first to
# join could finish the small render before the second connected, which then found no
# coordinator ("Connection refused") and made ssh-workers.sh fail; with it, as a worker joins
# already asking for a task, the first two tasks go one to each, so each renders something.
"$TF_BIN" render "$SCENE" --size $SIZE -j 0 --wait-workers 2 --listen 127.0.0.1:0 \
    --secret-file "$T/secret" -o "$T/ssh.exr" --stats "$T/ssh.json" 2>"$T/coord.log" &
COORD=$!
e2e_track $COORD
P=$(e2e_port "$T/coord.log") || fail "the coordinator did not listen: $(cat "$T/coord.log")"
printf '%s 1\n%s 1\n' "$USER_NAME@127.0.0.1" "$USER_NAME@127.0.0.1" >"$T/hosts.txt"
"$TF_ROOT/deploy/ssh-workers.sh" --connect "127.0.0.1:$P" --ssh "$SSH" --bin "$TF_BIN" \
    --push-secret "$T/secret" --secret-file "$T/remote/secret" "$T/hosts.txt" >"$T/ssh-workers.log" 2>&1 ||
    fail "ssh-workers.sh failed: $(cat "$T/ssh-workers.log")"
wait_exit $COORD 60
# shellcheck disable=SC2154 # rc: set by wait_exit
[ "$rc" -eq 0 ] || fail "coordinator exited with $rc: $(cat "$T/coord.log")"
grep -q "all 2 worker hosts finished" "$T/ssh-workers.log" || fail "ssh-workers.sh: $(cat "$T/ssh-workers.log")"
[ "$(stat -c %a "$T/remote/secret")" = 600 ] || fail "the pushed secret is mode $(stat -c %a "$T/remote/secret")"
cmp -s "$T/secret" "$T/remote/secret" || fail "the pushed secret differs"
n=$(grep -c '"kind": "networked"' "$T/ssh.json")
[ "$n" -eq 2 ] || fail "expected 2 networked workers in the stats, got $n"
grep '"kind": "networked"' "$T/ssh.json" | grep -q '"tasks": 0,' && fail "a worker rendered no task"
"$TF_BIN" render "$SCENE" --listen 127.0.0.1:0 --size $SIZE -j 2 -q -o "$T/local.exr" ||
    fail "local render failed"
same "$T/local.exr" "$T/ssh.exr" "render through ssh-workers.sh and a real sshd"
exit 0
