#!/bin/sh
# tests/e2e/deploy_ssh.sh: deploy/ssh-workers.sh, the ssh launcher.
#   1. syntax (sh -n) and one-line usage errors;
#   2. --dry-run prints exactly the expected commands for a host list (comments, blank lines,
#      per-host worker counts, user@host, a secret path that needs quoting), and each printed
#      line, run by a shell, hands ssh exactly the intended words;
#   3. a real launch through a stand-in ssh (runs the remote command locally, in a home
#      directory per host): the secret is pushed owner-only, two "hosts" join a real coordinator
#      on loopback, the render completes, the launcher reports success; an unreachable host
#      makes it fail naming that host.
set -u
ROOT=${TF_ROOT:-$(cd "$(dirname "$0")/../.." && pwd)}
TF=${TF_BIN:-$ROOT/bin/terrafarm}
L=$ROOT/deploy/ssh-workers.sh
fail() { echo "FAIL: $*"; exit 1; }
T=$(mktemp -d "${TMPDIR:-/tmp}/tf-deploy-ssh.XXXXXX") || fail "mktemp"
COORD=""
trap '[ -n "$COORD" ] && kill "$COORD" 2>/dev/null; rm -rf "$T"' EXIT

sh -n "$L" || fail "sh -n $L"
out=$(sh "$L" --dry-run hosts 2>&1) && fail "missing --connect accepted"
[ "$(printf '%s\n' "$out" | wc -l)" -eq 1 ] || fail "usage error is not one line: $out"
printf 'a 0\n' >"$T/bad-hosts"
out=$(sh "$L" --dry-run --connect c:1 "$T/bad-hosts" 2>&1) && fail "worker count 0 accepted"
case "$out" in *"bad worker count '0'"*) ;; *) fail "unclear error for a bad count: $out" ;; esac

# ---- 2. dry run ----
cat >"$T/hosts" <<'HOSTS'
# render farm
node1 4
alice@node-2.example.org   # all its CPUs

10.0.0.7 2
HOSTS
printf 'k\n' >"$T/local secret"
sh "$L" --dry-run --connect coord.example.org:7878 --push-secret "$T/local secret" \
    --secret-file "tf keys/secret" -j 3 "$T/hosts" >"$T/dry.out" 2>&1 || fail "dry run failed"
q="'"
cat >"$T/dry.expected" <<EXPECTED
ssh -o BatchMode=yes node1 'umask 077 && mkdir -p $q\\$q${q}tf keys$q\\$q$q && cat >$q\\$q${q}tf keys/secret$q\\$q$q' <'$T/local secret'
ssh -o BatchMode=yes alice@node-2.example.org 'umask 077 && mkdir -p $q\\$q${q}tf keys$q\\$q$q && cat >$q\\$q${q}tf keys/secret$q\\$q$q' <'$T/local secret'
ssh -o BatchMode=yes 10.0.0.7 'umask 077 && mkdir -p $q\\$q${q}tf keys$q\\$q$q && cat >$q\\$q${q}tf keys/secret$q\\$q$q' <'$T/local secret'
ssh -o BatchMode=yes node1 'exec terrafarm worker --connect coord.example.org:7878 --secret-file $q\\$q${q}tf keys/secret$q\\$q$q --backend c -j 4'
ssh -o BatchMode=yes alice@node-2.example.org 'exec terrafarm worker --connect coord.example.org:7878 --secret-file $q\\$q${q}tf keys/secret$q\\$q$q --backend c -j 3'
ssh -o BatchMode=yes 10.0.0.7 'exec terrafarm worker --connect coord.example.org:7878 --secret-file $q\\$q${q}tf keys/secret$q\\$q$q --backend c -j 2'
EXPECTED
diff "$T/dry.expected" "$T/dry.out" || fail "--dry-run output differs from the expected commands"
# Each printed line is a real shell command: with a recording "ssh" first on PATH, the words
# ssh receives are the host and the remote command, whose own words are the intended ones.
mkdir -p "$T/rec"
cat >"$T/rec/ssh" <<'REC'
#!/bin/sh
while [ "$1" = -o ]; do shift 2; done
printf '%s\n' "host=$1"
eval "set -- $2"
for w in "$@"; do printf 'word=%s\n' "$w"; done
REC
chmod +x "$T/rec/ssh"
line=$(sed -n 5p "$T/dry.out")
(PATH="$T/rec:$PATH" eval "$line") >"$T/words" || fail "printed line 5 does not run: $line"
printf '%s\n' host=alice@node-2.example.org word=exec word=terrafarm word=worker word=--connect \
    word=coord.example.org:7878 word=--secret-file "word=tf keys/secret" word=--backend word=c \
    word=-j word=3 >"$T/words.expected"
diff "$T/words.expected" "$T/words" || fail "the printed command does not carry the intended words"

# ---- 3. a real launch through a stand-in ssh ----
cat >"$T/fake-ssh" <<'FAKE'
#!/bin/sh
# Stand-in for ssh: runs the remote command locally, in $FAKE_HOMES/HOST as its home.
while [ "$1" = -o ]; do shift 2; done
host=$1
shift
case "$host" in unreachable*) echo "ssh: connect to host $host: No route to host" >&2; exit 255 ;; esac
mkdir -p "$FAKE_HOMES/$host" && cd "$FAKE_HOMES/$host" && HOME=$PWD exec sh -c "$*"
FAKE
chmod +x "$T/fake-ssh"
export FAKE_HOMES="$T/homes"
umask 077
head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$T/secret"
# --wait-workers 2: no task is dealt before both hosts' workers joined, so neither can find the
# render already finished by the other (a loaded machine may start hostB's seconds after hostA's)
"$TF" render "$ROOT/scenes/default.scene" --size 160x90 -j 0 --listen 127.0.0.1:0 --wait-workers 2 \
    --secret-file "$T/secret" -o "$T/ssh.exr" --stats "$T/ssh.json" >"$T/coord.log" 2>&1 &
COORD=$!
i=0
until port=$(sed -n 's/.*may join at 127\.0\.0\.1:\([0-9]*\).*/\1/p' "$T/coord.log") && [ -n "$port" ]; do
    i=$((i + 1))
    if [ $i -gt 100 ] || ! kill -0 "$COORD" 2>/dev/null; then
        cat "$T/coord.log"
        fail "coordinator did not start"
    fi
    sleep 0.1
done
printf 'hostA 1\nhostB 1\n' >"$T/real-hosts"
timeout 60 sh "$L" --ssh "$T/fake-ssh -o BatchMode=yes" --bin "$TF" --connect "127.0.0.1:$port" \
    --push-secret "$T/secret" "$T/real-hosts" >"$T/launch.out" 2>&1 ||
    { cat "$T/launch.out"; fail "the launch failed"; }
wait "$COORD" || { cat "$T/coord.log"; fail "the coordinator failed"; }
COORD=""
grep -q "all 2 worker hosts finished" "$T/launch.out" || { cat "$T/launch.out"; fail "no success line"; }
grep -q "^hostA: " "$T/launch.out" || fail "output is not prefixed with the host"
for h in hostA hostB; do
    s="$FAKE_HOMES/$h/.config/terrafarm/secret"
    cmp -s "$s" "$T/secret" || fail "$h: secret not pushed"
    [ "$(stat -c %a "$s")" = 600 ] || fail "$h: pushed secret has mode $(stat -c %a "$s")"
done
[ "$(grep -c '"kind": "networked"' "$T/ssh.json")" -eq 2 ] || fail "stats do not list 2 networked workers"
echo "deploy_ssh: 2 hosts launched through ssh rendered 160x90; secret pushed with mode 600"

printf 'unreachable-1\n' >"$T/down-hosts"
sh "$L" --ssh "$T/fake-ssh" --connect "127.0.0.1:$port" "$T/down-hosts" >"$T/down.out" 2>&1 &&
    fail "an unreachable host was reported as a success"
grep -q "unreachable-1: worker exited with status 255" "$T/down.out" ||
    { cat "$T/down.out"; fail "the failing host is not named"; }
echo "deploy_ssh: ok"
