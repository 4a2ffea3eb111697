#!/bin/sh
# farm_affinity.sh: horizontal-extent affinity (--affinity, coordinator/render/affinity.h) end to end.
# Two forked workers (--wait-workers 2: both joined before the first task is dealt) render
# 32x32 stamps of a 320-pixel-wide image: 10 stamps a band, 5 in each worker's column range.
# Checked, none of it by timing:
#   - the image is byte-identical to a single worker's and to an --affinity off render, with the
#     whole image dealt at once and with a tight watermark;
#   - the watermark bound holds (max_outstanding_tasks <= --watermark), and the tiles are in the
#     file in row order (the chunks walked in file order), whatever order they were rendered in;
#   - the statistics: affinity on/off, the ranges [0,160) and [160,320), takes adding up.  With
#     the whole image dealt at once, every take while both ranges still hold tasks is a first
#     choice, so at least the smaller range's tasks (4 stamps of 80 aside for the two first
#     deals and edge effects) are first choices, and a worker leaves its range at most a few
#     times (its own range empties once; only a re-dealt or duplicated task can send it back).
#     FIFO dealing interleaves the ranges, which that bound catches;
#   - rows:K tasks span the width: affinity is not in force there (stats say so);
#   - a bad --affinity value is one line and exit 2.
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=320x240
TASKS=stamps:32x32
ALL=80   # 10 x 8 stamps

render -q -j 1 --size $SIZE --tasks $TASKS -o "$T/ref.exr" || fail "single worker: $(cat "$T/last.err")"
render -q -j 2 --wait-workers 2 --size $SIZE --tasks $TASKS --watermark $ALL --affinity off \
    -o "$T/off.exr" --stats "$T/off.json" || fail "--affinity off: $(cat "$T/last.err")"
render -q -j 2 --wait-workers 2 --size $SIZE --tasks $TASKS --watermark $ALL \
    -o "$T/on.exr" --stats "$T/on.json" || fail "--affinity on (default): $(cat "$T/last.err")"
render -q -j 2 --wait-workers 2 --size $SIZE --tasks $TASKS --watermark 12 --affinity on \
    -o "$T/wm.exr" --stats "$T/wm.json" || fail "--affinity on, --watermark 12: $(cat "$T/last.err")"
same "$T/ref.exr" "$T/off.exr" "--affinity off, 2 workers"
same "$T/ref.exr" "$T/on.exr" "--affinity on, 2 workers, the whole image dealt at once"
same "$T/ref.exr" "$T/wm.exr" "--affinity on, 2 workers, --watermark 12"

# The tiles in file order: header, offset table, then [tx, ty, lx, ly, size, data] each.
for f in on wm; do
    python3 - "$T/$f.exr" $ALL <<'PY' || exit 1
import struct, sys
p, ntiles = sys.argv[1], int(sys.argv[2])
data = open(p, "rb").read()
pos = 8
while data[pos] != 0:
    pos = data.index(b"\0", pos) + 1
    pos = data.index(b"\0", pos) + 1
    (n,) = struct.unpack_from("<i", data, pos)
    pos += 4 + n
pos += 1 + 8 * ntiles
order = []
while pos + 20 <= len(data):
    tx, ty, lx, ly, n = struct.unpack_from("<iiiii", data, pos)
    order.append((ty, tx))
    pos += 20 + n
if len(order) != ntiles or order != sorted(order):
    sys.exit("FAIL: %s: tiles not in row order in the file: %r" % (p, order))
print("-- %s: %d tiles in the file in row order" % (p.split("/")[-1], len(order)))
PY
done

python3 - "$T/on.json" "$T/off.json" "$T/wm.json" $ALL <<'PY' || exit 1
import json, sys
on, off, wm = (json.load(open(p)) for p in sys.argv[1:4])
total = int(sys.argv[4])
def check(cond, what):
    if not cond:
        sys.exit("FAIL: " + what)
def show(name, s):
    for w in s["workers"]:
        print("-- %s: worker %d range %s: %d first, %d second, %d elsewhere, %d range switches"
              % (name, w["id"], w["affinity_range"], w["first_choice"], w["second_choice"],
                 w["elsewhere"], w["range_switches"]))
for name, s in (("on", on), ("off", off), ("watermark 12", wm)):
    show(name, s)
    check(s["tasks_total"] == total, "%s: tasks_total %d" % (name, s["tasks_total"]))
    check(len(s["workers"]) == 2, "%s: %d workers" % (name, len(s["workers"])))
    ranges = sorted(tuple(w["affinity_range"]) for w in s["workers"])
    check(ranges == [(0, 160), (160, 320)], "%s: ranges %r" % (name, ranges))
    takes = sum(w["first_choice"] + w["second_choice"] + w["elsewhere"] for w in s["workers"])
    check(takes >= total, "%s: %d takes counted for %d tasks" % (name, takes, total))
    check(all(w["elsewhere"] == 0 for w in s["workers"]), "%s: two ranges have no elsewhere" % name)
check(on["affinity"] is True and wm["affinity"] is True, "affinity not reported on")
check(off["affinity"] is False, "affinity not reported off")
check(wm["max_outstanding_tasks"] <= 12 and wm["watermark"] == 12,
      "watermark 12 broken: max_outstanding_tasks %d" % wm["max_outstanding_tasks"])
first = sum(w["first_choice"] for w in on["workers"])
print("-- on: %d of %d takes were first choices (off: %d)"
      % (first, total, sum(w["first_choice"] for w in off["workers"])))
check(2 * first >= total - 4, "on: only %d of %d takes were first choices" % (first, total))
extra = on["tasks_redealt"] + on["tasks_duplicated"]
for w in on["workers"]:
    check(w["range_switches"] <= 3 + 2 * extra,
          "on: worker %d left its range %d times (re-dealt or duplicated: %d): not affinity"
          % (w["id"], w["range_switches"], extra))
PY

say "rows:K tasks span the width: affinity is not in force"
render -q -j 2 --size $SIZE --tasks rows:8 -o "$T/rows.exr" --stats "$T/rows.json" ||
    fail "rows:8: $(cat "$T/last.err")"
[ "$(jstat affinity "$T/rows.json")" = False ] || fail "rows:8: affinity reported in force"
"$TF_BIN" render "$SCENE" --affinity maybe -o "$T/bad.exr" 2>"$T/bad.err"; rc=$?
[ $rc -eq 2 ] && [ "$(wc -l <"$T/bad.err")" -eq 1 ] || fail "--affinity maybe: exit $rc, $(cat "$T/bad.err")"
say "a bad --affinity: $(cat "$T/bad.err")"
echo "farm_affinity: identical images, watermark and file order kept, workers kept to their ranges"
