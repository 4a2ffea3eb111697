#!/usr/bin/env python3
"""tests/e2e/cdp_dashboard.py: drive a real headless Chromium at the dashboard of a running
render over the DevTools protocol (cdp_lib.py), sample what the page shows while the render
runs, save a screenshot, and check it: no error shown, workers listed, progress rising,
finished stamps drawn.

usage: cdp_dashboard.py CHROMIUM URL SCREENSHOT.png [SECONDS]
Exit 0 if every check holds, 1 with one line per failed check, 77 if Chromium cannot start."""
import base64, json, os, sys, time

chromium, url, shot = sys.argv[1], sys.argv[2], sys.argv[3]
limit = float(sys.argv[4]) if len(sys.argv) > 4 else 40.0

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cdp_lib import Chrome  # noqa: E402  (the DevTools plumbing the browser tests share)

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

samples = []
start = time.time()
shot_taken = False
while time.time() - start < limit:
    r = call("Runtime.evaluate", {"expression": PROBE, "returnByValue": True}, session)
    v = json.loads(r["result"]["value"]) if r["result"].get("type") == "string" else None
    if v:
        samples.append(v)
        d = v["data"]
        # mid-render, once something is drawn: the screenshot for the README
        if (not shot_taken and d.get("state") == "rendering" and
                float(d.get("percent", 0)) >= 30 and int(d.get("previewPixels", 0)) > 0 and
                v["events"] > 0):
            png = screenshot()
            open(shot, "wb").write(base64.b64decode(png))
            shot_taken = True
        if d.get("state") in ("finished", "failed", "interrupted"):
            break
    time.sleep(0.25)

# Finished: the page must come to show the whole picture (the coordinator keeps serving the final
# state while --on-done runs); a page that stopped at the picture of its last poll while
# rendering shows the last stamps missing.
final = samples[-1]["data"] if samples else {}
if final.get("state") == "finished":
    end = time.time() + 8
    while not (int(final.get("previewTotal", 0)) > 0 and
               final.get("previewPixels") == final.get("previewTotal")) and time.time() < end:
        time.sleep(0.25)
        r = call("Runtime.evaluate", {"expression": PROBE, "returnByValue": True}, session)
        if r["result"].get("type") == "string":
            final = json.loads(r["result"]["value"])["data"]

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
    if max(int(s["data"].get("plotPoints", 0)) for s in samples) < 1:
        problems.append("FAIL: the throughput plot has no point")
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
