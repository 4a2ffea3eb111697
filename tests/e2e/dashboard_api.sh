#!/bin/sh
# dashboard_api.sh: every endpoint of the dashboard's JSON API during a real render, checked
# for shape and for sense while it runs (progress only grows, workers and tasks are the farm's,
# the preview is a PNG, the event stream streams), and its final state -- fetched by an
# --on-done command while the dashboard still serves it -- checked against what --stats
# reports; `terrafarm status` (text and --json); and the image must be byte-identical to one
# rendered with --http none.  Then a 3-frame sequence: /api/status names the frame being
# written, the frames done and the frames asked for, mid-render (workers frozen) and at the end.
. "$(dirname "$0")/lib.sh"
e2e_init
SIZE=1280x720
say "reference render without a dashboard"
render -q -j 2 --size $SIZE --tasks stamps:64x64 --http none -o "$T/ref.exr" || fail "reference: $(cat "$T/last.err")"

cat >"$T/final.py" <<'PY'
import json, os, sys, urllib.request
d = sys.argv[1]
json.dump(dict((k, v) for k, v in os.environ.items() if k.startswith("TERRAFARM_")), open(d + "/ondone_env.json", "w"))
base = os.environ["TERRAFARM_DASHBOARD"]
for name in ("status", "workers", "events", "tasks", "history"):
    with urllib.request.urlopen(base + "api/" + name, timeout=10) as r:
        open(d + "/final_" + name + ".json", "wb").write(r.read())
# The event stream, read here because the dashboard is sure to serve until this command ends
# (read after the polls instead, a busy machine could finish the render and close it first):
# until it has replayed a join for every worker of the render, or 30 s.
import socket, time
nworkers = len(json.load(open(d + "/final_workers.json"))["workers"])
host, port = base.split("//")[1].rstrip("/").rsplit(":", 1)
stream = b""
try:
    s = socket.create_connection((host, int(port)), timeout=30)
    s.sendall(b"GET /api/events/stream HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
    t_end = time.time() + 30
    while stream.count(b"event: join") < nworkers and time.time() < t_end:
        c = s.recv(65536)
        if not c:
            break
        stream += c
    s.close()
except OSError as e:
    stream += ("error: %s" % e).encode()
open(d + "/stream.txt", "wb").write(stream)
PY
say "render with the dashboard on loopback, polled while it runs"
"$TF_BIN" render "$SCENE" --listen 127.0.0.1:0 --http 127.0.0.1:0 -j 2 --size $SIZE \
    --tasks stamps:64x64 --stats "$T/stats.json" -o "$T/out.exr" \
    --on-done "python3 '$T/final.py' '$T'" 2>"$T/coord.err" &
pid=$!; e2e_track $pid
freeze_workers_at_birth $pid 2
i=0
while ! grep -q 'dashboard at' "$T/coord.err" 2>/dev/null; do
    kill -0 $pid 2>/dev/null || fail "render ended early: $(cat "$T/coord.err")"
    sleep 0.05; i=$((i + 1)); [ $i -lt 400 ] || fail "no dashboard URL logged: $(cat "$T/coord.err")"
done
url=$(sed -n 's/.*dashboard at \(http:[^ ]*\).*/\1/p' "$T/coord.err" | head -1)
hostport=$(echo "$url" | sed 's#http://\([^/]*\)/#\1#')
"$TF_BIN" status "$hostport" >"$T/status.txt" 2>"$T/status.err" || fail "terrafarm status: $(cat "$T/status.err")"
"$TF_BIN" status "$hostport" --json >"$T/status.json" 2>>"$T/status.err" || fail "terrafarm status --json: $(cat "$T/status.err")"
python3 - "$url" "$T" "$pid" "$(dirname "$0")" >"$T/poll.out" 2>&1 <<'PY' || { thaw_workers $pid; cat "$T/poll.out"; fail "polling the API"; }
import json, signal, socket, sys, time, urllib.request, urllib.error
base, d, coordinator = sys.argv[1], sys.argv[2], sys.argv[3]
sys.path.insert(0, sys.argv[4])
from worker_slices import run_slices, signal_workers
# The workers were frozen at birth.  They run in slices until a poll shows the render part
# done with a preview to fetch; frozen then, it cannot end, so three polls while rendering
# are certain on a machine of any speed.  Then it runs free, polled until it ends.
def poll():
    p = {}
    for name in ("status", "workers", "events", "tasks", "history"):
        with urllib.request.urlopen(base + "api/" + name, timeout=30) as r:
            assert r.headers["Content-Type"] == "application/json", r.headers["Content-Type"]
            p[name] = json.loads(r.read())
    return p
def under_way(p):
    st = p["status"]
    return st["state"] == "rendering" and 0 < st["percent"] < 100 and st["preview_stamps"] > 0
png = None
try:
    polls = run_slices(coordinator, poll,
                       lambda p: under_way(p) or p["status"]["state"] not in ("starting", "rendering"))
    if under_way(polls[-1]):
        with urllib.request.urlopen(base + "api/preview.png", timeout=30) as r:
            png = r.read()
        for i in range(2):
            polls.append(poll())
finally:
    signal_workers(coordinator, signal.SIGCONT)
t_end = time.time() + 90
while time.time() < t_end and polls[-1]["status"]["state"] in ("starting", "rendering"):
    try:
        polls.append(poll())
    except (urllib.error.URLError, ConnectionError, socket.timeout):
        break
    time.sleep(0.15)
json.dump(polls, open(d + "/polls.json", "w"))
if png is not None:
    open(d + "/preview.png", "wb").write(png)
print("%d polls" % len(polls))
PY
cat "$T/poll.out"
wait_exit $pid 120
[ $rc -eq 0 ] || fail "render exited $rc: $(cat "$T/coord.err")"
same "$T/ref.exr" "$T/out.exr" "render with the dashboard"

say "checking what the API said against --stats"
python3 - "$T" <<'PY' || fail "the API disagrees with the render (above)"
import json, os, sys
d = sys.argv[1]
L = lambda n: json.load(open(d + "/" + n))
stats, polls = L("stats.json"), L("polls.json")
fs, fw, fe, ft, fh = (L("final_%s.json" % n) for n in ("status", "workers", "events", "tasks", "history"))
env = L("ondone_env.json")
bad = []
def check(cond, what):
    if not cond:
        bad.append(what)
# while it ran
running = [p for p in polls if p["status"]["state"] == "rendering"]
check(len(running) >= 3, "fewer than 3 polls while rendering (%d)" % len(running))
check(any(0 < p["status"]["percent"] < 100 for p in running), "no poll saw the render part done")
for key in ("rows_written", "rays_total", "tasks_written", "percent", "elapsed_s"):
    seq = [p["status"][key] for p in polls]
    check(seq == sorted(seq), "%s went down while rendering: %s" % (key, seq))
for k in ("scene", "size", "frame", "frames_total", "rows_written", "rows_total", "percent",
          "elapsed_s", "eta_s", "rays_per_s", "samples_per_pixel_avg", "watermark",
          "outstanding_tasks", "workers_connected", "workers_joined", "workers_seen"):
    check(k in fs, "status lacks %s" % k)
check(fs["frame"] is None and fs["frames_total"] is None, "a still has frame/frames_total set")
ids = {w["id"] for w in stats["workers"]}
for p in running:
    s = p["status"]
    check(0 <= s["outstanding_tasks"] <= s["watermark"] or s["outstanding_tasks"] <= stats["max_outstanding_tasks"],
          "outstanding %d beyond the watermark %d" % (s["outstanding_tasks"], s["watermark"]))
    check(s["eta_s"] is None or s["eta_s"] >= 0, "negative ETA")
    for w in p["workers"]["workers"]:
        check(w["id"] in ids, "worker %s is not in the statistics" % w["id"])
        check(w["state"] in ("busy", "idle", "left", "dropped"), "worker state %s" % w["state"])
        check(w["busy_fraction"] is None or 0 <= w["busy_fraction"] <= 1, "busy fraction %s" % w["busy_fraction"])
        fin = [x for x in stats["workers"] if x["id"] == w["id"]][0]
        check(w["tasks"] <= fin["tasks"] and w["rays"] <= fin["rays"], "worker %d did more mid-render than at the end" % w["id"])
    t = p["tasks"]
    check(t["width"] == stats["width"] and t["height"] == stats["height"], "tasks: wrong image size")
    for o in t["outstanding"]:
        check(o["id"] >= t["tasks_written"], "an outstanding task below the write front")
        check(0 <= o["x"] and o["x"] + o["w"] <= t["width"] and 0 <= o["y"] and o["y"] + o["h"] <= t["height"], "task %d outside the image" % o["id"])
        check(o["state"] in ("queued", "held", "done"), "task state %s" % o["state"])
        check(o["state"] != "held" or o["worker"] in ids, "task %d held by an unknown worker %s" % (o["id"], o["worker"]))
check(any(o["state"] == "held" for p in running for o in p["tasks"]["outstanding"]), "no poll saw a task held by a worker")
# the end, as the dashboard showed it to --on-done, against --stats
check(fs["state"] == "finished" and fs["exit_status"] == 0, "final state %s / %s" % (fs["state"], fs["exit_status"]))
for k_api, k_stats in (("width", "width"), ("height", "height"), ("rows_total", "height"),
                       ("rows_written", "height"), ("scene", "scene"), ("output", "output"),
                       ("tasks", "tasks"), ("tasks_total", "tasks_total"),
                       ("rays_total", "rays_total"), ("tasks_redealt", "tasks_redealt"),
                       ("max_outstanding_tasks", "max_outstanding_tasks"),
                       ("rows_resumed", "rows_resumed"), ("task_failures", "task_failures")):
    check(fs[k_api] == stats[k_stats], "final %s %r != --stats %s %r" % (k_api, fs[k_api], k_stats, stats[k_stats]))
check(abs(fs["samples_per_pixel_avg"] - stats["samples_per_pixel_avg"]) < 1e-6, "samples/pixel differ")
check(fs["watermark"] <= stats["watermark"], "final watermark above the largest")
check(fs["tasks_written"] == stats["tasks_total"], "tasks_written %d != tasks_total" % fs["tasks_written"])
check(fs["workers_joined"] == len(stats["workers"]) > 0,
      "workers_joined %d, --stats names %d workers" % (fs["workers_joined"], len(stats["workers"])))
check(abs(fs["percent"] - 100) < 1e-9 and fs["eta_s"] == 0, "final percent/eta %s %s" % (fs["percent"], fs["eta_s"]))
check(fs["workers_seen"] == len(fw["workers"]) >= fs["workers_joined"],
      "workers_seen %d, /api/workers lists %d, %d joined" % (fs["workers_seen"], len(fw["workers"]),
                                                           fs["workers_joined"]))
api_w = sorted((w["id"], w["kind"], w["host"], w["backend"], w["tasks"], w["rays"]) for w in fw["workers"])
st_w = sorted((w["id"], w["kind"], w["host"], w["backend"], w["tasks"], w["rays"]) for w in stats["workers"])
check(api_w == st_w, "final workers %s != --stats %s" % (api_w, st_w))
for w in fw["workers"]:
    fin = [x for x in stats["workers"] if x["id"] == w["id"]][0]
    check(abs(w["busy_s"] - fin["busy_s"]) < 0.002, "worker %d busy_s %s != %s" % (w["id"], w["busy_s"], fin["busy_s"]))
    check(w["connected_since"] is not None and w["last_heard_s"] is not None, "worker %d without times" % w["id"])
kinds = [e["kind"] for e in fe["events"]]
joins = {e["worker"] for e in fe["events"] if e["kind"] == "join"}
check(joins == ids, "join events for %s, workers %s" % (joins, ids))
check(kinds[-1] == "end" and "finished" in fe["events"][-1]["text"], "the last event is not the end: %s" % kinds[-3:])
check(all(e["time"].endswith("Z") and e["elapsed_s"] >= 0 for e in fe["events"]), "event times")
seqs = [e["seq"] for e in fe["events"]]
check(seqs == sorted(seqs) and len(set(seqs)) == len(seqs), "event numbers not increasing")
check(ft["outstanding"] == [] and ft["tasks_written"] == stats["tasks_total"], "tasks outstanding at the end")
ts = [x["t"] for x in fh["samples"]]
check(len(ts) >= 3 and ts == sorted(ts), "history samples %s" % ts[:5])
rs = [x["rays"] for x in fh["samples"]]
check(rs == sorted(rs) and rs[-1] <= stats["rays_total"], "history rays")
# the stream
stream = open(d + "/stream.txt", "rb").read().decode("utf-8", "replace")
check("text/event-stream" in stream, "the stream is not text/event-stream: %r" % stream[:200])
ev = [b for b in stream.split("\n\n") if "event: join" in b]
check(len(ev) >= len(ids), "the stream replayed %d join events for %d workers" % (len(ev), len(ids)))
for b in ev:
    data = [l[6:] for l in b.split("\n") if l.startswith("data: ")]
    check(data and json.loads(data[0])["kind"] == "join", "a stream event is not JSON: %r" % b)
# the preview
png = open(d + "/preview.png", "rb").read() if os.path.exists(d + "/preview.png") else b""
check(png[:8] == b"\x89PNG\r\n\x1a\n", "the preview is not a PNG")
w, h = int.from_bytes(png[16:20], "big"), int.from_bytes(png[20:24], "big")
check(w == 512 and h == 288, "preview %dx%d, expected 512x288 for 1280x720" % (w, h))
# --on-done's environment
check(env.get("TERRAFARM_STATUS") == "ok" and env.get("TERRAFARM_EXIT") == "0", "on-done status %s/%s" % (env.get("TERRAFARM_STATUS"), env.get("TERRAFARM_EXIT")))
check(env.get("TERRAFARM_OUTPUT") == stats["output"] and env.get("TERRAFARM_SCENE", "").endswith("default.scene"), "on-done output/scene")
check(float(env.get("TERRAFARM_WALL_S", "0")) >= stats["wall_s"] - 0.01, "on-done wall time")
check(env.get("TERRAFARM_ROWS") == str(stats["height"]) and env.get("TERRAFARM_SIZE") == "%dx%d" % (stats["width"], stats["height"]), "on-done rows/size")
# terrafarm status
st = json.load(open(d + "/status.json"))
check(st["state"] in ("starting", "rendering", "finished") and isinstance(st["workers"], list), "status --json")
txt = open(d + "/status.txt").read()
check("state      " in txt and "default.scene 1280x720" in txt, "terrafarm status text: %r" % txt[:200])
for b in bad:
    print("FAIL:", b)
print("%d polls while rendering, %d events, %d workers: %s" % (len(running), len(fe["events"]), len(ids), "ok" if not bad else "%d problems" % len(bad)))
sys.exit(1 if bad else 0)
PY
say "a 3-frame sequence (scenes/flyby.scene) with the dashboard"
FLYBY=$TF_ROOT/scenes/flyby.scene
cat >"$T/final_seq.py" <<'PY'
import os, sys, urllib.request
with urllib.request.urlopen(os.environ["TERRAFARM_DASHBOARD"] + "api/status", timeout=10) as r:
    open(sys.argv[1] + "/seq_final.json", "wb").write(r.read())
PY
"$TF_BIN" render "$FLYBY" --listen 127.0.0.1:0 --http 127.0.0.1:0 --frames 0-2 -j 2 \
    --size 320x180 --tasks stamps:32x32 --stats "$T/seq_stats.json" -o "$T/seq/f.####.exr" \
    --on-done "python3 '$T/final_seq.py' '$T'" 2>"$T/seq.err" &
pid=$!; e2e_track $pid
freeze_workers_at_birth $pid 2
url=$(dashboard_url "$T/seq.err" $pid)
python3 - "$url" "$T" "$pid" "$(dirname "$0")" <<'PY' || { thaw_workers $pid; fail "polling the sequence's API"; }
import json, sys, urllib.request
base, d, coordinator = sys.argv[1], sys.argv[2], sys.argv[3]
sys.path.insert(0, sys.argv[4])
from worker_slices import run_slices
# The workers, frozen at birth, run in slices until the API shows the render under way with
# tasks out; they stay frozen while that view is kept.
def poll():
    got = {}
    for name in ("status", "tasks"):
        with urllib.request.urlopen(base + "api/" + name, timeout=30) as r:
            got[name] = r.read()
    return got
def enough(got):
    st, tk = json.loads(got["status"]), json.loads(got["tasks"])
    return st.get("state") != "starting" and (st.get("state") != "rendering" or tk.get("outstanding"))
got = run_slices(coordinator, poll, enough)[-1]
for name in ("status", "tasks"):
    open(d + "/seq_frozen_" + name + ".json", "wb").write(got[name])
PY
thaw_workers $pid
python3 - "$url" "$T" >"$T/seq_poll.out" 2>&1 <<'PY' || { cat "$T/seq_poll.out"; fail "polling the sequence's API"; }
import json, socket, sys, time, urllib.request, urllib.error
base, d = sys.argv[1], sys.argv[2]
polls = []
t_end = time.time() + 60
while time.time() < t_end:
    try:
        with urllib.request.urlopen(base + "api/status", timeout=5) as r:
            p = json.loads(r.read())
    except (urllib.error.URLError, ConnectionError, socket.timeout):
        break
    polls.append(p)
    if p["state"] != "rendering":
        break
    time.sleep(0.05)
json.dump(polls, open(d + "/seq_polls.json", "w"))
PY
wait_exit $pid 120
[ $rc -eq 0 ] || fail "sequence render exited $rc: $(cat "$T/seq.err")"
python3 - "$T" <<'PY' || fail "the sequence's dashboard disagrees with the render (above)"
import json, sys
d = sys.argv[1]
L = lambda n: json.load(open(d + "/" + n))
stats, fz, ft, fin, polls = (L(n) for n in ("seq_stats.json", "seq_frozen_status.json",
                                            "seq_frozen_tasks.json", "seq_final.json", "seq_polls.json"))
bad = []
def check(cond, what):
    if not cond:
        bad.append(what)
H = stats["height"]
check([f["frame"] for f in stats["frames"]] == [0, 1, 2], "--stats frames %s" % stats["frames"])
check(fz["state"] == "rendering", "the frozen poll saw %s, not rendering" % fz["state"])
running = [p for p in polls if p["state"] == "rendering"]
# Between the last row queued and the end of the run (the last frame finished, workers told to
# stop) the state still reads "rendering" with every frame done: the view must then be whole.
finishing = [p for p in running if p["frames_done"] == 3]
for p in finishing:
    check(p["frame"] == 2 and p["rows_written"] == p["rows_total"] == 3 * H,
          "finishing with frame %s, rows %s of %s" % (p["frame"], p["rows_written"], p["rows_total"]))
for p in [fz] + [p for p in running if p not in finishing]:
    check(p["frames_total"] == 3, "frames_total %s while rendering" % p["frames_total"])
    check(p["frames_done"] in (0, 1, 2), "frames_done %s while rendering" % p["frames_done"])
    # frames 0-2, none complete before: the frame being written is the first not done
    check(p["frame"] == p["frames_done"], "frame %s with %s frames done" % (p["frame"], p["frames_done"]))
    check(p["rows_total"] == 3 * H and p["frames_done"] * H <= p["rows_written"] < 3 * H,
          "rows %s of %s with %s frames done" % (p["rows_written"], p["rows_total"], p["frames_done"]))
seq = [(p["frames_done"], p["rows_written"]) for p in [fz] + polls]
check(seq == sorted(seq), "frames done / rows went down: %s" % seq)
check(all(o["frame"] in (0, 1, 2) for o in ft["outstanding"]) and ft["outstanding"],
      "outstanding tasks' frames: %s" % [o.get("frame") for o in ft["outstanding"]])
check(fin["state"] == "finished" and fin["frame"] == 2 and fin["frames_done"] == 3 and
      fin["frames_total"] == 3, "final frame %s, %s of %s done (%s)" %
      (fin["frame"], fin["frames_done"], fin["frames_total"], fin["state"]))
check(fin["rows_written"] == fin["rows_total"] == 3 * H and abs(fin["percent"] - 100) < 1e-9,
      "final rows %s of %s" % (fin["rows_written"], fin["rows_total"]))
check(fin["tasks_total"] == stats["tasks_total"] and fin["rays_total"] == stats["rays_total"],
      "final tasks/rays %s %s != --stats %s %s" % (fin["tasks_total"], fin["rays_total"],
                                                   stats["tasks_total"], stats["rays_total"]))
for b in bad:
    print("FAIL:", b)
print("sequence: %d polls, frozen at frame %s (%s done): %s" % (len(polls), fz["frame"], fz["frames_done"], "ok" if not bad else "%d problems" % len(bad)))
sys.exit(1 if bad else 0)
PY
say "ok"
