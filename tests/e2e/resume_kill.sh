#!/bin/sh
# resume_kill.sh: docs/contract.md sections 2, 3 and 5: the coordinator can be SIGKILLed at any
# instant, with workers holding tasks, and `render --resume` continues the same render: rows on disk
# are kept (rows_resumed), never rendered again, and the final image is byte-identical to an
# uninterrupted render.  Kills land while the new file's header is written, the instant the file
# appears, as a resumed run starts, at ~30% of the output file's final size, inside the resume's
# copy of the verified chunks (or, if a disk too fast for the watching shell lets that copy end
# unseen, just after it), and at ~60% and ~90% (plus a random few milliseconds, so they fall
# anywhere, mid-write included).  Forked workers die with their coordinator (PR_SET_PDEATHSIG).
# Prints, per interruption, rows on disk after the kill and rows the next run resumed. RESUME_TASKS
# (default rows:1, a scanline file) picks the task shape: resume_kill_tiled.sh runs the same
# interruptions on a tiled file (stamps).
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=800x450
H=450
TASKS=${RESUME_TASKS:-rows:1}
ARGS="-j 2 --size $SIZE --tasks $TASKS"
PROBE_ARGS="--size $SIZE --tasks $TASKS"
say "tasks $TASKS"

say "reference: uninterrupted render, $SIZE"
render -q $ARGS -o "$T/ref.exr" || fail "reference render: $(cat "$T/last.err")"
full=$(wc -c <"$T/ref.exr")
mkdir "$T/out"
OUT="$T/out/img.exr"

# rand_ms N: a random number of milliseconds in [0, N)
rand_ms() { echo $(( $(od -An -N2 -tu2 /dev/urandom | tr -d ' ') % $1 )); }

prev_rows=0
run=0
lost=""   # per interruption: rows on disk after the kill that the next run did not keep
for pct in create early 0 30 copy 60 90; do
    run=$((run + 1))
    had_file=no; [ -e "$OUT" ] && had_file=yes
    : >"$T/run$run.err"
    # the copy run's marker of the old file: an x bit, which the file the copy makes lacks
    if [ $pct = copy ]; then
        chmod u+x "$OUT" || fail "run $run: no output file to resume"
    fi
    "$TF_BIN" render "$SCENE" $ARGS --resume --listen 127.0.0.1:0 -o "$OUT" 2>"$T/run$run.err" &
    coord=$!; e2e_track $coord
    netw=""
    if [ $pct = 60 ]; then
        # this run also has a networked worker: it must leave when its coordinator dies
        port=$(e2e_port "$T/run$run.err") || fail "run $run printed no port"
        "$TF_BIN" worker --connect 127.0.0.1:$port -j 1 2>"$T/netw.err" &
        netw=$!; e2e_track $netw
    fi
    if [ $pct = create ]; then
        # while the header is written to OUT.new.tmp, before it is renamed into place (that
        # lasts microseconds: the kill may land just after, which is fine too)
        i=0
        while [ ! -e "$OUT.new.tmp" ] && [ ! -e "$OUT" ]; do
            i=$((i + 1)); [ $i -lt 2000000 ] || fail "run $run: no $OUT.new.tmp appeared"
        done
        jitter=0
    elif [ $pct = early ]; then
        # the instant the output file appears (its header being written, no row yet): a busy
        # wait on the shell's built-in test, no sleep, so the kill follows within microseconds
        i=0
        while [ ! -e "$OUT" ]; do
            i=$((i + 1)); [ $i -lt 2000000 ] || fail "run $run: no output file appeared"
        done
        jitter=0
    elif [ $pct = copy ]; then
        # while --resume copies the verified chunks into OUT.resume.tmp, before its rename: a
        # busy wait, the coordinator stopped the instant the copy shows.  The copy lasts tens of
        # ms on ext4 (an fsync), far less on a faster disk or tmpfs, where a descheduled shell
        # may miss it: the wait also ends once OUT is no longer the old file (the copy renamed
        # over it: OUT has lost the x bit set above), and the kill then lands just after the
        # copy, which must lose nothing either.  The workers (forked before the copy) are
        # frozen at birth meanwhile, so the render cannot run on to its end however late this
        # shell stops it.
        freeze_workers_at_birth $coord 2 &
        freezer=$!
        i=0
        while [ ! -e "$OUT.resume.tmp" ] && [ -x "$OUT" ] && kill -0 $coord 2>/dev/null; do
            i=$((i + 1)); [ $i -lt 2000000 ] || fail "run $run: no $OUT.resume.tmp appeared"
        done
        kill -STOP $coord 2>/dev/null
        wait $freezer || fail "run $run: its workers were not frozen at birth: $(tail -3 "$T/run$run.err")"
        frozen=$(pgrep -P $coord)
        if [ -e "$OUT.resume.tmp" ]; then
            say "run $run stopped inside its copy of the verified chunks"
        else
            say "run $run had passed its copy of the verified chunks: killed just after it"
        fi
        jitter=0
    elif [ $pct -eq 0 ]; then
        # before this run writes its first row: as soon as it says it is rendering (workers
        # forked, tasks dealt)
        i=0
        while ! grep -q 'rendering ' "$T/run$run.err" && kill -0 $coord 2>/dev/null; do
            sleep 0.005; i=$((i + 1)); [ $i -lt 3000 ] || fail "run $run: never started rendering"
        done
        jitter=0
    else
        want=$((full * pct / 100))
        i=0
        while [ "$(wc -c 2>/dev/null <"$OUT" || echo 0)" -lt $want ] && kill -0 $coord 2>/dev/null; do
            sleep 0.01; i=$((i + 1)); [ $i -lt 12000 ] || fail "run $run: the output never reached $want bytes"
        done
        # Freeze the workers (forked and networked) at the mark: the coordinator can then only
        # write the results it already holds, so however fast or loaded the machine, the render
        # cannot run on to its end during the jitter (only at 90% can what it holds be the
        # rest of the image: then the file is complete, which the check below accepts).
        frozen="$(pgrep -P $coord) $netw"
        kill -STOP $frozen 2>/dev/null
        jitter=$(rand_ms 40)
    fi
    [ $jitter -gt 0 ] && sleep "0.$(printf %03d $jitter)"
    kids=$(pgrep -P $coord)
    if ! kill -0 $coord 2>/dev/null; then
        [ $pct = 90 ] && [ "$(rows_on_disk "$OUT")" = complete ] ||
            fail "run $run ended before the kill at ${pct}: $(cat "$T/run$run.err")"
    fi
    kill -KILL $coord 2>/dev/null
    wait $coord 2>/dev/null
    [ -n "${frozen:-}" ] && kill -CONT $frozen 2>/dev/null
    frozen=""
    # the forked workers must follow their coordinator
    i=0; while [ $i -lt 30 ]; do
        alive=""; for k in $kids; do [ "$(ps -o stat= -p $k 2>/dev/null | cut -c1)" ] && alive="$alive $k"; done
        [ -z "$alive" ] && break; sleep 0.1; i=$((i + 1))
    done
    no_leftovers $kids
    if [ -n "$netw" ]; then
        wait_exit $netw 10
        refused $rc || fail "the networked worker exited $rc after its coordinator was killed"
        say "networked worker left with status $rc: $(tail -1 "$T/netw.err")"
    fi
    said=$(grep -c 'resuming .* rows already on disk\|nothing to resume' "$T/run$run.err")
    if [ $said -eq 0 ] && { [ $pct = copy ] || [ $pct = create ] || [ $pct = early ]; }; then
        :   # killed in its first instants, before it could say what it resumes
    elif [ $had_file = yes ]; then
        [ -n "$lost" ] && lost="$lost, "
        got=$(sed -n 's/.*resuming .*: \([0-9]*\) of [0-9]* rows already on disk.*/\1/p' "$T/run$run.err")
        [ "$got" = "$prev_rows" ] || fail "run $run resumed '$got' rows, but $prev_rows were on disk after the previous kill: $(cat "$T/run$run.err")"
        lost="$lost$((prev_rows - got))"
    else
        grep -q 'nothing to resume, starting a fresh render' "$T/run$run.err" ||
            fail "run $run: --resume with no file did not say it starts afresh: $(cat "$T/run$run.err")"
    fi
    if [ ! -e "$OUT" ]; then
        say "kill $run ($pct, + ${jitter} ms): no output file yet"
        continue
    fi
    rows=$(rows_on_disk "$OUT")
    [ -n "$rows" ] || fail "after kill $run the partial file cannot be resumed"
    if [ "$rows" = complete ]; then
        # the kill landed after the file was finished (while the preview was written)
        [ $pct = 90 ] || fail "kill $run at $pct%: the file is already complete"
        say "kill $run at $pct% + ${jitter} ms: landed after the last row; the file is complete"
        prev_rows=$H
        break
    fi
    [ "$rows" -ge "$prev_rows" ] || fail "rows on disk went down: $prev_rows -> $rows"
    say "kill $run at $pct% of the file + ${jitter} ms ($(echo $kids | wc -w) workers died with it): $rows of $H rows on disk"
    prev_rows=$rows
done

say "final run: --resume to the end"
"$TF_BIN" render "$SCENE" $ARGS --resume --listen 127.0.0.1:0 -o "$OUT" --stats "$T/final.json" 2>"$T/final.err" ||
    fail "final resume failed: $(cat "$T/final.err")"
if [ $prev_rows -eq $H ]; then
    grep -q 'already complete' "$T/final.err" || fail "a complete file was not recognised: $(cat "$T/final.err")"
    echo '{"rows_resumed": '$H', "rows_rendered": 0}' >"$T/final.json"
fi
resumed=$(jstat rows_resumed "$T/final.json")
rendered=$(jstat rows_rendered "$T/final.json")
say "final run: rows_resumed $resumed, rows_rendered $rendered ($(grep -o 'resuming .*' "$T/final.err"))"
[ "$resumed" -eq "$prev_rows" ] || fail "rows_resumed $resumed but $prev_rows rows were on disk"
lost="$lost, $((prev_rows - resumed))"
say "rows on disk lost per interruption (on disk after the kill - resumed by the next run): $lost"
[ $((resumed + rendered)) -eq $H ] || fail "rows_resumed + rows_rendered = $((resumed + rendered)), not $H"
same "$T/ref.exr" "$OUT" "after 7 kills and resumes"
left=$(ls "$T/out" | grep -v '^img\.exr$\|^img\.png$' || true)
[ -z "$left" ] || fail "stray files beside the output: $left"
if command -v exrheader >/dev/null 2>&1; then
    exrheader "$OUT" >/dev/null 2>&1 || fail "exrheader cannot read the resumed file"
    say "exrheader reads the resumed file"
fi
echo "resume_kill ($TASKS): 7 interruptions, 0 rows on disk lost, image identical"
