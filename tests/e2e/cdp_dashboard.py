#!/usr/bin/env python3
"""tests/e2e/cdp_dashboard.py: drive a real headless Chromium at the dashboard of a running
render over the DevTools protocol (cdp_lib.py), sample what the page shows while the render
runs, save a screenshot, and check it: no error shown, workers listed, progress rising,
finished stamps drawn, the throughput plotted, the whole picture once finished.

usage: cdp_dashboard.py CHROMIUM URL SCREENSHOT.png SECONDS COORDINATOR_PID
The coordinator's forked workers must be frozen (lib.sh freeze_workers_at_birth): they run in
slices (worker_slices.py) until the page has shown the render part done, stamps drawn and
progress risen, so the page is sure to see the render under way on a machine of any speed; the
screenshot is taken then; then they run free to the end.  SECONDS bounds the whole check.
Exit 0 if every check holds, 1 with one line per failed check, 77 if Chromium cannot start."""
import base64, json, os, signal, sys, time

chromium, url, shot = sys.argv[1], sys.argv[2], sys.argv[3]
limit, coordinator = float(sys.argv[4]), int(sys.argv[5])

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cdp_lib import Chrome  # noqa: E402  (the DevTools plumbing the browser tests share)
from worker_slices import signal_workers  # noqa: E402

ch = Chrome(chromium, 1280, 1280)


def finish(code, lines=()):
    ch.finish(code, lines)


def call(method, params=None, session=None, timeout=20):
    return ch.call(method, params, timeout, session=session is not None)


ch.open(url)
session = ch.session

PROBE = """JSON.stringify({
  data: Object.assign({}, document.body ? document.body.dataset : {}),
  error: (document.getElementById('error') && !document.getElementById('error').hidden)
         ? document.getElementById('error').textContent : null,
  rows: document.querySelectorAll('#workers tbody tr').length,
  events: document.querySelectorAll('#events li').length,
  percentText: (document.getElementById('percent') || {}).textContent,
  title: document.title
})"""

def screenshot():
    """The page down to the workers table ($TF_SHOT_SCALE shrinks it, e.g. for the README)."""
    r = call("Runtime.evaluate", {"returnByValue": True, "expression":
             "(document.getElementById('workers-box') || document.body).getBoundingClientRect().bottom"},
             session)
    bottom = r["result"].get("value") or 1280
    clip = {"x": 0, "y": 0, "width": 1280, "height": min(1280, int(bottom) + 12),
            "scale": float(os.environ.get("TF_SHOT_SCALE", "1"))}
    return call("Page.captureScreenshot", {"format": "png", "clip": clip}, session)["data"]

def probe():
    r = call("Runtime.evaluate", {"expression": PROBE, "returnByValue": True}, session)
    return json.loads(r["result"]["value"]) if r["result"].get("type") == "string" else None


def ended(d):
    return d.get("state") in ("finished", "failed", "interrupted")


def under_way(seen):
    """The page has shown the render running, part done, stamps drawn, progress risen."""
    run = [v for v in seen if v["data"].get("state") == "rendering"]
    pcts = {float(v["data"].get("percent", -1)) for v in run}
    last = run[-1]["data"] if run else {}
    return (len(pcts) >= 2 and 0 < float(last.get("percent", 0)) < 100 and
            int(last.get("previewPixels", 0)) > 0 and int(last.get("stampsDrawn", 0)) > 0 and
            run[-1]["events"] > 0 and run[-1]["rows"] > 0)


samples = []
start = time.time()
shot_taken = False
try:
    # Slices: the workers run 50 ms, are frozen again, and the page gets a second to show it
    # (its polls are half a second apart, the dashboard's snapshots 200 ms).
    while time.time() - start < limit and not under_way(samples):
        signal_workers(coordinator, signal.SIGCONT)
        time.sleep(0.05)
        signal_workers(coordinator, signal.SIGSTOP)
        for _ in range(4):
            time.sleep(0.25)
            v = probe()
            if v:
                samples.append(v)
        if samples and ended(samples[-1]["data"]):
            break
    if under_way(samples):  # mid-render, workers frozen: the screenshot for the README
        open(shot, "wb").write(base64.b64decode(screenshot()))
        shot_taken = True
finally:
    signal_workers(coordinator, signal.SIGCONT)
while time.time() - start < limit and not (samples and ended(samples[-1]["data"])):
    time.sleep(0.25)
    v = probe()
    if v:
        samples.append(v)

# Finished: the page must come to show the whole picture and its final plot (the coordinator
# keeps serving the final state while --on-done runs); data-ended says its last poll is drawn.
final = samples[-1]["data"] if samples else {}
if ended(final):
    while not (final.get("ended") == "1" and int(final.get("previewTotal", 0)) > 0 and
               final.get("previewPixels") == final.get("previewTotal")) and time.time() - start < limit:
        time.sleep(0.25)
        v = probe()
        if v:
            final = v["data"]

rendering = [s for s in samples if s["data"].get("state") == "rendering"]
problems = []
errors = [s["error"] for s in samples if s["error"]]
if errors:
    problems.append("FAIL: the page showed an error: %s" % errors[0])
if not rendering:
    problems.append("FAIL: the page never showed the render running (states seen: %s)" %
                    sorted({s["data"].get("state") for s in samples}))
else:
    pcts = [float(s["data"].get("percent", -1)) for s in rendering]
    if len(set(pcts)) < 2 or max(pcts) <= min(pcts):
        problems.append("FAIL: progress did not rise while rendering: %s" % pcts)
    if max(s["rows"] for s in rendering) < 1:
        problems.append("FAIL: no worker listed in the workers table")
    if max(int(s["data"].get("stampsDrawn", 0)) for s in rendering) < 1 or \
       max(int(s["data"].get("previewPixels", 0)) for s in rendering) < 1:
        problems.append("FAIL: no finished stamp drawn on the image while rendering")
    if max(s["events"] for s in rendering) < 1:
        problems.append("FAIL: the event log stayed empty (no join seen)")
if max([int(s["data"].get("plotPoints", 0)) for s in samples] + [int(final.get("plotPoints", 0))]) < 1:
    problems.append("FAIL: the throughput plot has no point")
if not ended(final):
    problems.append("FAIL: the page never showed the render ended (last state %s)" % final.get("state"))
if ended(final) and final.get("ended") != "1":
    problems.append("FAIL: the page did not finish drawing the final state")
if final.get("state") == "finished" and final.get("previewPixels") != final.get("previewTotal"):
    problems.append("FAIL: the finished page shows %s of the picture's %s pixels" %
                    (final.get("previewPixels"), final.get("previewTotal")))
if not shot_taken:
    try:
        open(shot, "wb").write(base64.b64decode(screenshot()))
    except SystemExit:
        raise
if not problems:
    last = rendering[-1]
    print("page ok: %d samples while rendering, progress %s%% -> %s%%, %d workers listed, "
          "%s stamps drawn, %d events; screenshot %s" % (
              len(rendering), rendering[0]["data"]["percent"], last["data"]["percent"],
              max(s["rows"] for s in rendering), max(int(s["data"].get("stampsDrawn", 0)) for s in rendering),
              max(s["events"] for s in rendering), shot))
try:
    call("Browser.close", timeout=5)
except SystemExit:
    pass
finish(1 if problems else 0, problems)
