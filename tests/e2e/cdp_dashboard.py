#!/usr/bin/env python3
"""tests/e2e/cdp_dashboard.py: drive a real headless Chromium at the dashboard of a running
render over the DevTools protocol (--remote-debugging-pipe: NUL-separated JSON on fds 3 and 4,
no extra Python modules), sample what the page shows while the render runs, save a screenshot,
and check it: no error shown, workers listed, progress rising, finished stamps drawn.

usage: cdp_dashboard.py CHROMIUM URL SCREENSHOT.png [SECONDS]
Exit 0 if every check holds, 1 with one line per failed check, 77 if Chromium cannot start."""
import base64, json, os, subprocess, sys, tempfile, time

chromium, url, shot = sys.argv[1], sys.argv[2], sys.argv[3]
limit = float(sys.argv[4]) if len(sys.argv) > 4 else 40.0

profile = tempfile.mkdtemp(prefix="tf-chromium-")
to_chrome_r, to_chrome_w = os.pipe()
from_chrome_r, from_chrome_w = os.pipe()
args = [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync",
        "--disable-dev-shm-usage", "--user-data-dir=" + profile, "--window-size=1280,1280",
        "--remote-debugging-pipe", "about:blank"]
def child_fds():
    os.dup2(to_chrome_r, 3)
    os.dup2(from_chrome_w, 4)
log = open(os.path.join(profile, "chromium.log"), "w")
proc = subprocess.Popen(args, pass_fds=(3, 4), preexec_fn=child_fds, stdout=log, stderr=log)
os.close(to_chrome_r)
os.close(from_chrome_w)
buf = b""
next_id = 0

def finish(code, lines=()):
    for line in lines:
        print(line)
    try:
        proc.kill()
        proc.wait(5)
    except Exception:
        pass
    subprocess.call(["rm", "-rf", profile])
    sys.exit(code)

def read_message(deadline):
    global buf
    import select
    while b"\0" not in buf:
        left = deadline - time.time()
        if left <= 0:
            finish(1, ["FAIL: Chromium did not answer in time"])
        r, _, _ = select.select([from_chrome_r], [], [], left)
        if not r:
            continue
        chunk = os.read(from_chrome_r, 1 << 20)
        if not chunk:
            log.flush()
            tail = open(os.path.join(profile, "chromium.log")).read()[-600:]
            finish(77, ["Chromium cannot run here: it closed the DevTools pipe: " + tail.strip().replace("\n", " | ")])
        buf += chunk
    msg, buf = buf.split(b"\0", 1)
    return json.loads(msg)

def call(method, params=None, session=None, timeout=20):
    global next_id
    next_id += 1
    m = {"id": next_id, "method": method, "params": params or {}}
    if session:
        m["sessionId"] = session
    os.write(to_chrome_w, json.dumps(m).encode() + b"\0")
    deadline = time.time() + timeout
    while True:
        r = read_message(deadline)
        if r.get("id") == next_id:
            if "error" in r:
                finish(1, ["FAIL: DevTools %s: %s" % (method, r["error"])])
            return r["result"]

target = call("Target.createTarget", {"url": url})["targetId"]
session = call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]

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
