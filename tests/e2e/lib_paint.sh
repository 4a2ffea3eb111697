# lib_paint.sh: starting `terrafarm paint` in the paint tests (sourced after lib.sh).
#
# start_paint LOG ARGS...: terrafarm paint $SCENE ARGS in the background, its stderr to LOG;
# waits for its page and sets PAINT_PID and PAINT_URL (http://127.0.0.1:PORT/), and
# PAINT_WORKERS (the networked workers' HOST:PORT) when it listens for them.
start_paint() {
    sp_log=$1; shift
    "$TF_BIN" paint "$SCENE" "$@" 2>"$sp_log" &
    PAINT_PID=$!; e2e_track $PAINT_PID
    i=0
    while ! grep -q 'paint: open http' "$sp_log" 2>/dev/null; do
        kill -0 $PAINT_PID 2>/dev/null || fail "terrafarm paint ended early: $(cat "$sp_log")"
        sleep 0.1; i=$((i + 1)); [ $i -lt 600 ] || fail "terrafarm paint logged no page: $(cat "$sp_log")"
    done
    PAINT_URL=$(sed -n 's/.*paint: open \(http:[^ ]*\).*/\1/p' "$sp_log" | head -1)
    PAINT_WORKERS=$(sed -n 's/.*worker --connect HOST:\([0-9]*\).*/127.0.0.1:\1/p' "$sp_log" | head -1)
}

# paint_status FIELD: one field of the paint's /api/paint/status (a number or a string).
paint_status() {
    python3 -c 'import json,sys,urllib.request
d = json.load(urllib.request.urlopen(sys.argv[1] + "api/paint/status", timeout=10))
for k in sys.argv[2].split("."): d = d[k]
print(d)' "$PAINT_URL" "$1"
}

# wait_painted SECONDS: until the paint's current view is painted.
wait_painted() {
    i=0
    while [ "$(paint_status painted_s | cut -c1)" = "-" ]; do
        kill -0 $PAINT_PID 2>/dev/null || fail "terrafarm paint ended: $(tail -3 "$T/paint.err")"
        sleep 0.1; i=$((i + 1)); [ $i -lt $(($1 * 10)) ] || fail "not painted within $1 s"
    done
}
