#!/bin/sh
# farm_watermark.sh: the watermark bounds the tasks dealt beyond the write front
# (max_outstanding_tasks <= watermark in the statistics) for several watermarks, the image does
# not depend on it, and --stats holds every key of docs/contract.md section 5 with sane values.
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=240x135

render -q -j 1 --size $SIZE --tasks stamps:40x40 -o "$T/ref.exr" || fail "reference render: $(cat "$T/last.err")"
# stamps:40x40 -> 6 tasks per band: the smallest watermark allowed is 6
for wm in 6 8 13 40; do
    render -q -j 2 --size $SIZE --tasks stamps:40x40 --watermark $wm -o "$T/w$wm.exr" \
        --stats "$T/w$wm.json" || fail "--watermark $wm: $(cat "$T/last.err")"
    python3 - "$T/w$wm.json" $wm <<'PY' || exit 1
import json, sys
s = json.load(open(sys.argv[1])); wm = int(sys.argv[2])
print("-- watermark %d: max_outstanding_tasks %d, watermark in stats %d"
      % (wm, s["max_outstanding_tasks"], s["watermark"]))
if s["watermark"] != wm:
    sys.exit("FAIL: stats report watermark %d, asked for %d" % (s["watermark"], wm))
if not 1 <= s["max_outstanding_tasks"] <= wm:
    sys.exit("FAIL: max_outstanding_tasks %d exceeds the watermark %d" % (s["max_outstanding_tasks"], wm))
PY
    same "$T/ref.exr" "$T/w$wm.exr" "--watermark $wm"
done

say "a watermark below one band of tasks is refused with a clear message"
if render -q -j 1 --size $SIZE --tasks stamps:40x40 --watermark 5 -o "$T/bad.exr"; then
    fail "--watermark 5 with 6 tasks per band was accepted"
fi
grep -q 'watermark' "$T/last.err" || fail "unclear refusal: $(cat "$T/last.err")"
[ "$(wc -l <"$T/last.err")" -eq 1 ] || fail "refusal is not one line: $(cat "$T/last.err")"
say "refused: $(cat "$T/last.err")"

say "every docs/contract.md section 5 key in --stats"
python3 - "$T/w8.json" <<'PY' || exit 1
import json, sys
s = json.load(open(sys.argv[1]))
keys = ["wall_s", "width", "height", "tasks_total", "tasks_redealt", "rows_resumed",
        "rows_rendered", "rays_total", "samples_per_pixel_avg", "max_outstanding_tasks",
        "watermark", "max_tuple_bytes", "workers"]
missing = [k for k in keys if k not in s]
if missing:
    sys.exit("FAIL: missing keys %s" % missing)
def check(cond, what):
    if not cond:
        sys.exit("FAIL: " + what)
check((s["width"], s["height"]) == (240, 135), "width/height %r" % ((s["width"], s["height"]),))
check(s["tasks_total"] == 6 * 4, "tasks_total %d, expected 24 stamps of 40x40" % s["tasks_total"])
check(s["rows_resumed"] == 0 and s["rows_rendered"] == 135, "rows_resumed/rendered %d/%d" % (s["rows_resumed"], s["rows_rendered"]))
check(s["rays_total"] >= 240 * 135, "rays_total %d below one per pixel" % s["rays_total"])
check(s["samples_per_pixel_avg"] >= 1, "samples_per_pixel_avg %r" % s["samples_per_pixel_avg"])
check(s["max_tuple_bytes"] > 0 and s["wall_s"] > 0, "max_tuple_bytes / wall_s not positive")
check(isinstance(s["workers"], list) and len(s["workers"]) == 2, "workers: %r" % s["workers"])
for w in s["workers"]:
    for k in ("id", "kind", "tasks", "rays", "busy_s"):
        check(k in w, "worker without %s: %r" % (k, w))
    check(w["kind"] in ("forked", "networked"), "worker kind %r" % w["kind"])
check(sum(w["tasks"] for w in s["workers"]) == s["tasks_total"], "workers' tasks do not sum to tasks_total")
check(sum(w["rays"] for w in s["workers"]) == s["rays_total"], "workers' rays do not sum to rays_total")
print("-- all %d keys present; workers %s" % (len(keys), [(w["id"], w["kind"], w["tasks"]) for w in s["workers"]]))
PY
echo "farm_watermark: watermark respected, statistics complete"
