#!/usr/bin/env python3
"""tests/e2e/cdp_farm_paint.py: Raypaint reached from the standing farm's web view, in a real
headless Chromium over the DevTools protocol (cdp_lib.py), as tests/e2e/farm_paint_browser.sh
asks: log in to the farm's page, click the "paint" button of a job with the mouse, see a paint
job appear with a "paint view" link, open that link, watch the paint page until the view is
painted (the canvas must then be the render's PNG preview byte for byte), and click the page's
"render on the farm" button (the page must say which job it queued).

usage: cdp_farm_paint.py CHROMIUM BASE_URL TOKEN JOB_ID REF_PNG SHOT.png
Prints "paint_job=N" and "submitted_job=M".  Exit 0 if every check holds, 1 with a FAIL line,
77 if Chromium cannot start."""
import json, os, re, sys, time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cdp_lib import Chrome, read_png_rgb  # noqa: E402

chromium, base, token, job, ref_png, shot = sys.argv[1:7]
ch = Chrome(chromium, 1280, 900)


def wait_for(expr, what, seconds):
    """Evaluate expr in the page until it is truthy; its value, or FAIL after the deadline."""
    end = time.time() + seconds
    while time.time() < end:
        v = ch.eval(expr)
        if v:
            return v
        time.sleep(0.1)
    ch.finish(1, ["FAIL: %s within %d s" % (what, seconds)])


def click(selector):
    """A real mouse click at the middle of the element."""
    xy = ch.eval("(() => { const e = document.querySelector(%s); if (!e) return null;"
                 " e.scrollIntoView(); const r = e.getBoundingClientRect();"
                 " return [r.x + r.width / 2, r.y + r.height / 2]; })()" % json.dumps(selector))
    if not xy:
        ch.finish(1, ["FAIL: nothing on the page matches %s" % selector])
    ch.click_at(xy[0], xy[1])


# 1. the farm's page, the job's paint button
ch.open(base + "/login?token=" + token)
button = 'tr[data-job="%s"] button[data-action="paint"]' % job
wait_for("!!document.querySelector(%s)" % json.dumps(button), "a paint button on job " + job, 60)
click(button)
print("clicked paint on job %s" % job)

# 2. the paint job's row and its link
ROW = ("(() => { const tr = document.querySelector('#jobs tr[data-kind=\"paint\"]');"
       " const a = tr && tr.querySelector('a.dashboard');"
       " return a ? {id: tr.dataset.job, href: a.href, text: a.textContent} : null; })()")
row = wait_for(ROW, "a paint job with a link in the queue", 60)
if row["text"] != "paint view" or not re.match(r"^http://127\.0\.0\.1:\d+/login\?token=[0-9a-f]{64}$",
                                               row["href"]):
    ch.finish(1, ["FAIL: the paint job's link is %r -> %s" % (row["text"], row["href"])])
print("paint_job=%s" % row["id"])

# 3. the link's page, painted
ch.open(row["href"])
wait_for("!!(window.paint && paint.img && paint.status)", "the paint page to start", 60)
DONE = ("paint.status && paint.status.painted_s >= 0 && paint.gen === paint.status.gen &&"
        " paint.end === paint.status.log_bytes")
wait_for(DONE, "the view to be painted and drawn", 300)
ch.screenshot(shot)
w, h, ref = read_png_rgb(ref_png)
import base64  # noqa: E402
canvas = base64.b64decode(ch.eval("paint.rgb()"))
if canvas != ref:
    diff = sum(1 for a, b in zip(canvas, ref) if a != b)
    ch.finish(1, ["FAIL: the painted canvas differs from the render's preview in %d of %d bytes"
                  % (diff, len(ref))])
print("the paint page's canvas is the render's preview (%dx%d)" % (w, h))

# 4. the page's Submit
click("#submit")
said = wait_for("(() => { const t = document.getElementById('said').textContent;"
                " return /submitted: job \\d+/.test(t) ? t : null; })()", "the page to say it submitted", 60)
print("submitted_job=%s" % re.search(r"job (\d+)", said).group(1))
ch.finish(0)
