#!/usr/bin/env python3
"""tests/e2e/cdp_paint.py: headless Chromium at Raypaint's page (terrafarm paint, started
--paused), driven over the DevTools protocol (cdp_lib.py).  What it checks, in this order:

  1. the page is up and has drawn nothing while paused;
  2. a click on the picture marks an area of interest (the page posts it);
  3. the painting is then run in steps, with paint's forked workers frozen (SIGSTOP) between
     them -- resume until the paint has dealt its tasks (as many as it deals at once: the
     frozen workers answer none meanwhile), pause, thaw the workers until every dealt task is
     answered and drawn, freeze them again -- and the canvas is read after each step: the area
     clicked is all exact while most of the rest is not, and the picture sharpens (its PSNR
     against the final picture rises from the first coarse step to the last).  A step is thus
     one deal of tasks whatever the machine's speed; after the steps (80 at most) the
     workers run free, to the end of this view and through the next;
  4. painted, the canvas is the render's PNG preview byte for byte (REF_PNG);
  5. the camera is moved with the page's own control: the next view is painted while running,
     and the latency from the click to its first pixels is measured; painted, its canvas is
     written to OUT/canvas2.rgb (the shell compares it with a render of the scene the page's
     Save writes) and the page must have seen exactly one new view.
Timings are printed, never judged.  A screenshot mid-paint goes to OUT/paint.png.

usage: cdp_paint.py CHROMIUM URL REF_PNG OUT PAINT_PID
PAINT_PID is the `terrafarm paint` process (started --paused): its children are its workers.
Exit 0 if every check holds, 1 with one line per failed check, 77 if Chromium cannot start."""
import base64, json, os, signal, sys, time, urllib.request

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cdp_lib import Chrome, psnr, read_png_rgb
from worker_slices import signal_workers  # noqa: E402

chromium, url, ref_png, out = sys.argv[1:5]
painter = int(sys.argv[5])
url = url.rstrip("/") + "/"
ch = Chrome(chromium)
problems = []


def status():
    with urllib.request.urlopen(url + "api/paint/status", timeout=10) as r:
        return json.loads(r.read())


def wait_for(cond, what, seconds=120):
    end = time.time() + seconds
    while time.time() < end:
        v = cond()
        if v:
            return v
        time.sleep(0.02)
    ch.finish(1, ["FAIL: timed out waiting for " + what])


def page(expr):
    return ch.eval(expr)


def control(path):
    return page("control('/api/paint/%s').then(a => a !== null)" % path)


def drawn_all(s):
    """Every dealt task answered and the page has drawn the whole log of the view."""
    return (s["outstanding"] == 0 and
            page("paint.gen === %d && paint.end === %d" % (s["gen"], s["log_bytes"])))


def canvas():
    return base64.b64decode(page("paint.rgb()"))


# 1. up, paused, nothing drawn
ch.open(url)
wait_for(lambda: page("!!(window.paint && paint.img && paint.status)"), "the page to start", 60)
s = status()
if not s["paused"] or s["counts"]["samples"] != 0:
    problems.append("FAIL: a --paused paint traced %d samples before being resumed" %
                    s["counts"]["samples"])
w, h = s["width"], s["height"]

# 2. a click at (3/4, 1/3) of the picture
box = page("(() => { const b = document.getElementById('picture').getBoundingClientRect();"
           " return [b.left, b.top, b.width, b.height]; })()")
ch.click_at(box[0] + box[2] * 0.75, box[1] + box[3] * 0.33)
area = wait_for(lambda: page("paint.interest || null"), "the click to mark an area", 20)
# The area is queued for the paint loop once the server has answered its POST; the resumes below
# are queued after it, and the loop takes its commands in order, so it holds before any deal.
if not page("paint.interestSent.then(a => a !== null)"):
    ch.finish(1, ["FAIL: the server refused the area of interest"])

# 3. steps.  Paused, the paint deals nothing; its workers (forked before its page was up) are
# frozen.  Resumed, it deals in one go as many tasks as it keeps out (two a worker, plus one) and
# no more until results come back, which frozen workers cannot send: so once the status shows
# tasks out, pausing makes the step exactly that deal, on a machine of any speed.
signal_workers(painter, signal.SIGSTOP)
steps, shares_when_done, first_draw_ms, shot = [], None, None, False
t_resume = time.time()
while len(steps) < 80:
    before = status()
    if before["painted_s"] >= 0:
        break
    if not control("resume"):
        problems.append("FAIL: the page's resume control was refused")
        break
    wait_for(lambda: (lambda s: s["outstanding"] > 0 or s["painted_s"] >= 0)(status()),
             "tasks dealt after resuming")
    control("pause")
    signal_workers(painter, signal.SIGCONT)
    s = wait_for(lambda: (lambda s: s if drawn_all(s) else None)(status()), "the step to be drawn")
    signal_workers(painter, signal.SIGSTOP)
    if first_draw_ms is None:
        first_draw_ms = (time.time() - t_resume) * 1000
    inside, outside = page("paint.exactShares(paint.interest)")
    steps.append((s["counts"]["exact_pixels"], s["counts"]["samples"], canvas()))
    if shares_when_done is None and inside == 1.0:
        shares_when_done = (inside, outside)
    if not shot and s["counts"]["exact_pixels"] > 0.3 * w * h:
        ch.screenshot(os.path.join(out, "paint.png"))
        shot = True
signal_workers(painter, signal.SIGCONT)
control("resume")
s = wait_for(lambda: (lambda s: s if s["painted_s"] >= 0 and drawn_all(s) else None)(status()),
             "the view to be painted")

# 4. the painted picture is the render's
final = canvas()
rw, rh, ref = read_png_rgb(ref_png)
if (rw, rh) != (w, h) or final != ref:
    diff = sum(1 for a, b in zip(final, ref) if a != b)
    problems.append("FAIL: the painted canvas differs from the render's preview (%dx%d vs %dx%d, "
                    "%d bytes differ)" % (w, h, rw, rh, diff))
if shares_when_done is None:
    problems.append("FAIL: the area clicked never became exact before the end")
elif shares_when_done[1] >= 0.5:
    problems.append("FAIL: the area clicked was not painted first: when it was all exact, "
                    "%.0f%% of the rest was exact too" % (100 * shares_when_done[1]))
curve = [psnr(c, final) for _, _, c in steps]
if len(steps) < 3:
    problems.append("FAIL: the picture came in %d steps; a progressive paint takes more" %
                    len(steps))
elif not (curve[-1] > curve[0]):
    problems.append("FAIL: the picture did not sharpen: PSNR %.1f dB at the first step, %.1f at "
                    "the last" % (curve[0], curve[-1]))

# 5. a new view from the page's own camera control
g1 = page("paint.gen")
page("document.querySelector('[data-move=orbit-left]').click(); true")
wait_for(lambda: page("paint.gen === %d && paint.messages > 0" % (g1 + 1)), "the new view's first pixels", 60)
latency = page("paint.latencyMs")
s2 = wait_for(lambda: (lambda s: s if s["gen"] == g1 + 1 and s["painted_s"] >= 0 and drawn_all(s)
                       else None)(status()), "the new view to be painted")
open(os.path.join(out, "canvas2.rgb"), "wb").write(canvas())
if not page("control('/api/paint/save').then(a => !!a)"):
    problems.append("FAIL: the page's save control failed")
if page("paint.gen") != g1 + 1 or s2["gen"] != g1 + 1:
    problems.append("FAIL: one camera move made views %d (page) and %d (server) after %d" %
                    (page("paint.gen"), s2["gen"], g1))

print("steps=%d first_draw_ms=%.0f interest_inside=%.2f outside=%.2f latency_ms=%s stale=%d" % (
    len(steps), first_draw_ms or -1, shares_when_done[0] if shares_when_done else -1,
    shares_when_done[1] if shares_when_done else -1,
    "%.0f" % latency if latency is not None else "?", s2["stale"]))
print("psnr_db=" + ",".join("%.1f" % c for c in curve))
ch.finish(1 if problems else 0, problems)
