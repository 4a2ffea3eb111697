#!/bin/sh
# farm_verify.sh: spot checks catch a lying worker (--verify, coordinator/render/verify.h; docs/contract.md
# section 3). Three networked workers; one of them is a real `terrafarm worker` whose results pass
# through tests/tools/lying_proxy.py (connecting from 127.0.0.2, a machine of its own), which
# changes one byte of every result's packed chunks (sizes kept: the structural checks cannot see
# it).  With --verify 0.2 the coordinator must catch it (a mismatch decided by a third render),
# exclude it, deal its tasks again, and finish with an image identical to a clean render; the
# statistics report the checks and their cost.  The liar joins first and renders alone for a moment:
# its results must wait for a check all the same.  Without --verify the same liar gets its lies into
# the file (checked too, so the test can fail).
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=480x270
TASKS=rows:2
PROXY="$TF_ROOT/tests/tools/lying_proxy.py"

render -q -j 1 --size $SIZE --tasks $TASKS -o "$T/ref.exr" || fail "reference render: $(cat "$T/last.err")"

# honest_left PID LOG: an honest worker leaves with 0 -- or, when the other one and the liar
# finished the render before it was in (nothing makes it join in time: the liar must render
# alone first, so --wait-workers cannot help), it found the coordinator gone: exit 1 with
# "Connection refused" as its last word, the render itself a success.  Uses $tag, $crc.
honest_left() {
    wait_exit $1 30
    [ $rc -eq 0 ] && return 0
    if [ $rc -eq 1 ] && [ $crc -eq 0 ] && tail -1 "$2" | grep -q 'Connection refused'; then
        say "$tag: an honest worker came after the render was over: $(tail -1 "$2")"
        return 0
    fi
    fail "$tag: honest worker exited $rc (coordinator $crc: $(grep -v 'rows ' "$T/$tag.err" | tail -3)): $(grep -v 'debug: task' "$2")"
}

# farm TAG EXTRA...: coordinator (-j 0) + a liar through the proxy, alone at first, then two
# honest workers; waits for the coordinator (status in $rc).
farm() {
    tag=$1; shift
    honest_first=${HONEST_FIRST:-0}
    "$TF_BIN" render "$SCENE" -j 0 --size $SIZE --tasks ${FARM_TASKS:-$TASKS} --listen 127.0.0.1:0 \
        -o "$T/$tag.exr" --stats "$T/$tag.json" "$@" 2>"$T/$tag.err" &
    coord=$!; e2e_track $coord
    port=$(e2e_port "$T/$tag.err") || fail "coordinator printed no port: $(cat "$T/$tag.err")"
    python3 "$PROXY" 127.0.0.1 "$port" 127.0.0.2 "$honest_first" >"$T/$tag.proxy" 2>&1 &
    proxy=$!; e2e_track $proxy
    i=0
    until grep -q 'listening on' "$T/$tag.proxy" 2>/dev/null; do
        i=$((i + 1)); [ $i -gt 100 ] && fail "the proxy did not start: $(cat "$T/$tag.proxy")"
        sleep 0.1
    done
    pport=$(sed -n 's/listening on //p' "$T/$tag.proxy")
    # The liar comes first and is alone for a while: a lone worker cannot be checked by anyone,
    # so with --verify its results must wait for the others (nothing of it may reach the file
    # unchecked).  The honest workers join once it has told its first lie.
    "$TF_BIN" worker --connect 127.0.0.1:$pport -j 1 -q --timeout 2000 2>"$T/$tag.liar.err" &
    liar=$!; e2e_track $liar
    # With --verify, wait until the coordinator has accepted one of its results while it is
    # alone (it says the result waits for a second worker), not for the proxy, which sees the
    # result before the coordinator has checked it.  Without, for the proxy's first lie.
    i=0
    if [ "${LIAR_WAIT:-coordinator}" = coordinator ]; then
        wait_for='is the only worker; its results wait' wait_in="$T/$tag.err"
    else
        wait_for='altered a result\|passed a result' wait_in="$T/$tag.proxy"
    fi
    until grep -q "$wait_for" "$wait_in" 2>/dev/null; do
        i=$((i + 1)); [ $i -gt 600 ] && fail "$tag: the liar never rendered: $(cat "$T/$tag.liar.err")"
        sleep 0.1
    done
    "$TF_BIN" worker --connect 127.0.0.1:$port -j 1 -v 2>"$T/$tag.a.err" &
    a=$!; e2e_track $a
    "$TF_BIN" worker --connect 127.0.0.1:$port -j 1 -v 2>"$T/$tag.c.err" &
    c=$!; e2e_track $c
    wait_exit $coord 120
    crc=$rc
    honest_left $a "$T/$tag.a.err"
    honest_left $c "$T/$tag.c.err"
    wait_exit $liar 30
    kill $proxy 2>/dev/null
    rc=$crc
}

say "1. --verify 0.2 with one lying worker among three"
farm verify --verify 0.2
[ $rc -eq 0 ] || fail "render with --verify exited $rc: $(tail -5 "$T/verify.err")"
grep -q 'altered a result' "$T/verify.proxy" || fail "the liar never lied"
same "$T/ref.exr" "$T/verify.exr" "--verify 0.2 with a liar"
excluded=$(jstat workers_excluded "$T/verify.json")
mism=$(jstat verify_mismatches "$T/verify.json")
checks=$(jstat verify_checks "$T/verify.json")
cost=$(jstat verify_cost "$T/verify.json")
[ "$excluded" -ge 1 ] || fail "no worker excluded: $(grep -i 'lied\|verify\|differen' "$T/verify.err")"
[ "$mism" -ge 1 ] || fail "no mismatch counted"
grep -q 'lied: its result of task' "$T/verify.err" || fail "the log does not name the liar"
grep -q 'is the only worker; its results wait' "$T/verify.err" ||
    fail "the lone liar's results were not held for a check: $(grep -i verify "$T/verify.err")"
say "$(grep -m1 'lied:' "$T/verify.err")"
say "checks $checks, mismatches $mism, workers excluded $excluded, verify_cost $cost of the workers' time"

say "2. a liar that earns trust first: honest for its first 3 results, then lying"
# It passes its first check, so its later results are written unless the random 10% picks
# them: lies reach the file before one is caught.  The coordinator must take them back (the
# output rewound through the resume path, every task since dealt again) and still finish with
# the clean image.
HONEST_FIRST=3 FARM_TASKS=rows:1 farm trusted --verify 0.1
[ $rc -eq 0 ] || fail "render with a trusted liar exited $rc: $(grep -v 'rows ' "$T/trusted.err" | tail -5)"
grep -q 'altered a result' "$T/trusted.proxy" || fail "the trusted liar never lied"
render -q -j 1 --size $SIZE --tasks rows:1 -o "$T/ref1.exr" || fail "reference render (rows:1): $(cat "$T/last.err")"
same "$T/ref1.exr" "$T/trusted.exr" "--verify 0.1 with a liar that passed a check first"
[ "$(jstat workers_excluded "$T/trusted.json")" -ge 1 ] || fail "the trusted liar was not excluded"
if grep -q 'lied after passing a check: taking back' "$T/trusted.err"; then
    say "$(grep -m1 'taking back' "$T/trusted.err" | sed 's/^terrafarm: warning: //')"
else
    say "(the liar was caught before any of its lies was written this time)"
fi

say "3. the same liar without --verify: its lies reach the file"
LIAR_WAIT=proxy farm noverify
[ $rc -eq 0 ] || fail "render without --verify exited $rc: $(tail -5 "$T/noverify.err")"
if cmp -s "$T/ref.exr" "$T/noverify.exr"; then
    grep -q 'altered a result' "$T/noverify.proxy" && fail "lies were told but the image is identical: the test cannot see lies"
    say "(the liar rendered nothing this time)"
else
    say "without --verify the image differs from the reference, as expected"
fi
echo "farm_verify: liar caught and excluded, image identical; checks=$checks cost=$cost"
