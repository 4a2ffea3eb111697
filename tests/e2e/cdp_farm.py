#!/usr/bin/env python3
"""tests/e2e/cdp_farm.py: drive a real headless Chromium at a standing farm's web view over the
DevTools protocol (cdp_lib.py), as tests/e2e/farm_browser.sh asks: log in through /login?token=, see the queue with
its states, click "resume" on the paused job with the mouse and see it run to done, see a running
job's dashboard link (and that it answers), see the workers table, save a screenshot.

usage: cdp_farm.py CHROMIUM BASE_URL TOKEN SHOT.png READY_FILE PAUSED_ID JOB_ID... --worker-pid FILE
       [--limit S]
READY_FILE is created once the page shows every job (the caller then starts the worker).  The
caller writes the staying worker's PID to FILE, the worker frozen (SIGSTOP) from birth: it and
its forked processes run in slices of 20 ms, the page looked at only once it has refreshed
while they are frozen, until a running job's dashboard link has been seen and has answered --
frozen, no job can end while the page shows it and its dashboard is asked, on a machine of any
speed -- then they run free to the end.
Exit 0 if every check holds, 1 with a FAIL line per failed check, 77 if Chromium cannot start."""
import base64, http.client, json, os, signal, sys, time, urllib.parse

args = sys.argv[1:]
limit = 300.0
if "--limit" in args:
    i = args.index("--limit")
    limit = float(args[i + 1])
    del args[i:i + 2]
i = args.index("--worker-pid")
worker_pid_file = args[i + 1]
del args[i:i + 2]
chromium, base, token, shot, ready_file, paused = args[:6]
jobs = [paused] + args[6:]

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cdp_lib import Chrome  # noqa: E402  (the DevTools plumbing the browser tests share)
from worker_slices import signal_workers  # noqa: E402

ch = Chrome(chromium, 1280, 900)


def finish(code, lines=()):
    ch.finish(code, lines)


def call(method, params=None, session=None, timeout=60):
    return ch.call(method, params, timeout, session=session is not None)


ch.open(base + "/login?token=" + token)
session = ch.session

PROBE = """JSON.stringify({
  refreshes: +(document.body && document.body.dataset.refreshes || 0),
  role: document.body ? document.body.dataset.role : null,
  error: (document.getElementById('error') && !document.getElementById('error').hidden)
         ? document.getElementById('error').textContent : null,
  jobs: Array.from(document.querySelectorAll('#jobs tbody tr')).map(tr => ({
    id: tr.dataset.job, state: tr.dataset.state,
    bar: (tr.querySelector('.bar > div') || {style: {}}).style.width,
    dashboard: (tr.querySelector('a.dashboard') || {}).href || null})),
  workers: Array.from(document.querySelectorAll('#workers tbody tr')).map(tr => tr.dataset.worker),
  workersShown: !!document.getElementById('workers-box') && !document.getElementById('workers-box').hidden
})"""


def probe():
    r = call("Runtime.evaluate", {"expression": PROBE, "returnByValue": True}, session)
    v = r["result"].get("value")
    return json.loads(v) if isinstance(v, str) else None


def state_of(v, job):
    return next((j["state"] for j in v["jobs"] if j["id"] == job), None)


def click(selector):
    """A real mouse click at the middle of the element; False if it is not on the page."""
    expr = ("(() => { const e = document.querySelector(%s); if (!e) return null; e.scrollIntoView();"
            " const r = e.getBoundingClientRect(); return [r.x + r.width / 2, r.y + r.height / 2]; })()"
            % json.dumps(selector))
    xy = call("Runtime.evaluate", {"expression": expr, "returnByValue": True}, session)["result"].get("value")
    if not xy:
        return False
    for kind in ("mousePressed", "mouseReleased"):
        call("Input.dispatchMouseEvent", {"type": kind, "x": xy[0], "y": xy[1], "button": "left",
                                          "clickCount": 1}, session)
    return True


def screenshot():
    """The page down to the workers table."""
    r = call("Runtime.evaluate", {"returnByValue": True, "expression":
             "document.getElementById('workers-box').getBoundingClientRect().bottom"}, session)
    bottom = r["result"].get("value") or 900
    clip = {"x": 0, "y": 0, "width": 1280, "height": min(900, int(bottom) + 16), "scale": 1}
    data = call("Page.captureScreenshot", {"format": "png", "clip": clip}, session)["data"]
    open(shot, "wb").write(base64.b64decode(data))


def dashboard_answers(url):
    """The render's dashboard login answers with a redirect that sets its cookie."""
    u = urllib.parse.urlsplit(url)
    try:
        c = http.client.HTTPConnection(u.hostname, u.port, timeout=30)
        c.request("GET", u.path + "?" + u.query)
        r = c.getresponse()
        ok = r.status == 303 and bool(r.getheader("Set-Cookie"))
        c.close()
        return ok
    except OSError:
        return False  # the job ended meanwhile


def wait_for(cond, what, seconds):
    """Sample the page until cond(sample) holds; the last sample, or FAIL after the deadline."""
    end = time.time() + seconds
    while time.time() < end:
        v = probe()
        if v and v["error"]:
            finish(1, ["FAIL: the page shows an error: %s" % v["error"]])
        if v and cond(v):
            return v
        time.sleep(0.25)
    finish(1, ["FAIL: %s within %d s (last: %s)" % (what, seconds, json.dumps(probe())[:400])])


start = time.time()
v = wait_for(lambda v: v["refreshes"] > 0 and all(state_of(v, j) for j in jobs),
             "the page never listed jobs %s" % jobs, 60)
if state_of(v, paused) != "paused":
    finish(1, ["FAIL: job %s shows %s, not paused" % (paused, state_of(v, paused))])
if v["role"] != "admin" or not v["workersShown"]:
    finish(1, ["FAIL: logged in as %s, workers table shown: %s" % (v["role"], v["workersShown"])])
print("page lists jobs %s: %s" % (jobs, [state_of(v, j) for j in jobs]))

# Refreshes keep an unchanged button: the page used to rebuild every row once a second, and a
# click whose press and release straddled a rebuild was lost (no click event at all).
resume = 'tr[data-job="%s"] button[data-action="resume"]' % paused
def page(expr):
    return call("Runtime.evaluate", {"expression": expr, "returnByValue": True}, session)["result"].get("value")
mark = page("(() => { const b = document.querySelector(%s); if (!b) return -1; window.tfKept = b;"
            " return +document.body.dataset.refreshes; })()" % json.dumps(resume))
if mark is None or mark < 0:
    finish(1, ["FAIL: no resume button on job %s" % paused])
wait_for(lambda v: v["refreshes"] >= mark + 2, "two more refreshes", 60)
if not page("window.tfKept.isConnected && document.querySelector(%s) === window.tfKept" % json.dumps(resume)):
    finish(1, ["FAIL: a refresh replaced job %s's resume button (a click across it is lost)" % paused])
print("job %s's resume button kept across two refreshes" % paused)
if not click(resume):
    finish(1, ["FAIL: no resume button on job %s" % paused])
wait_for(lambda v: state_of(v, paused) != "paused", "the click did not resume job %s" % paused, 60)
print("clicked resume on job %s" % paused)
open(ready_file, "w").close()


def worker_signal(sig):
    """sig to the staying worker, then to its forked processes (stopped first, it forks none
    that the second step would miss)."""
    try:
        os.kill(worker, sig)
    except ProcessLookupError:
        pass
    signal_workers(worker, sig)


def run_slice():
    """Let the worker run 20 ms, freeze it, and wait until the page has refreshed since (a
    refresh begun before the freeze ends first: two)."""
    worker_signal(signal.SIGCONT)
    time.sleep(0.02)
    worker_signal(signal.SIGSTOP)
    r = probe()["refreshes"]
    wait_for(lambda v: v["refreshes"] >= r + 2, "two refreshes after a slice", 60)


wait_for(lambda v: os.path.exists(worker_pid_file), "the worker's PID", 60)
worker = int(open(worker_pid_file).read())
worker_signal(signal.SIGSTOP)
seen_link = shot_taken = False
seen_workers = set()
end = start + limit
while time.time() < end:
    if not seen_link:
        run_slice()
    v = probe()
    if v["error"]:
        finish(1, ["FAIL: the page shows an error: %s" % v["error"]])
    seen_workers |= set(v["workers"])
    for j in v["jobs"]:
        if j["dashboard"] and not seen_link:
            if not j["dashboard"].startswith(base.rsplit(":", 1)[0]) or "/login?token=" not in j["dashboard"]:
                finish(1, ["FAIL: job %s's dashboard link is %s" % (j["id"], j["dashboard"])])
            seen_link = dashboard_answers(j["dashboard"]) or seen_link
            print("job %s running, its dashboard at %s" % (j["id"], j["dashboard"].split("?")[0]))
            if seen_link:
                worker_signal(signal.SIGCONT)  # seen: now the worker runs free
        if j["dashboard"] and not shot_taken and j["bar"] not in ("", "0%") and v["workers"]:
            screenshot()
            shot_taken = True
    if all(state_of(v, j) == "done" for j in jobs):
        break
    time.sleep(0.25)
problems = []
states = [state_of(v, j) for j in jobs]
if any(s != "done" for s in states):
    problems.append("FAIL: jobs %s are %s after %d s, not all done" % (jobs, states, limit))
if not seen_link:
    problems.append("FAIL: no running job ever showed a working dashboard link")
if not seen_workers:
    problems.append("FAIL: the workers table stayed empty")
if any(j["bar"] != "100%" for j in v["jobs"] if j["state"] == "done"):
    problems.append("FAIL: a done job's bar is not full: %s" % v["jobs"])
if not shot_taken:
    screenshot()
if not problems:
    print("page ok: jobs %s done, workers seen %s, screenshot %s" % (jobs, sorted(seen_workers), shot))
finish(1 if problems else 0, problems)
