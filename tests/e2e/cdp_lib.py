"""tests/e2e/cdp_lib.py: a real headless Chromium driven over the DevTools protocol
(--remote-debugging-pipe: NUL-separated JSON on fds 3 and 4, no extra Python modules), and a
reader of the 8-bit PNGs terrafarm writes, for the browser tests (cdp_paint.py).

    ch = Chrome(chromium)            # exits 77 if Chromium cannot start here
    ch.open(url); ch.eval("1 + 1"); ch.click_at(x, y); ch.screenshot(path)
    ch.finish(code, lines)           # prints lines, closes Chromium, exits
"""
import atexit, base64, json, os, select, shutil, signal, struct, subprocess, sys, tempfile, time
import zlib


def group_running(pgid):
    """Does any process of group pgid still run (a zombie runs no more)?"""
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            with open("/proc/%s/stat" % pid) as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == pgid and fields[0] != "Z":
            return True
    return False


class Chrome:
    def __init__(self, chromium, width=1280, height=1280):
        self.profile = tempfile.mkdtemp(prefix="tf-chromium-")
        to_r, self.to_w = os.pipe()
        self.from_r, from_w = os.pipe()
        args = [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                "--no-first-run", "--disable-background-networking", "--disable-component-update",
                "--disable-sync", "--disable-dev-shm-usage", "--user-data-dir=" + self.profile,
                "--window-size=%d,%d" % (width, height), "--remote-debugging-pipe", "about:blank"]

        def child_fds():
            os.dup2(to_r, 3)
            os.dup2(from_w, 4)
        self.log = open(os.path.join(self.profile, "chromium.log"), "w")
        # Chromium and its helpers (network service, renderers) in a process group of their
        # own, so that stop() can wait for them all and end them if need be: the browser
        # killed alone left a helper writing into the profile after it was removed, and its own
        # temporary directory (org.chromium.Chromium.*) in TMPDIR, one each a test
        self.proc = subprocess.Popen(args, pass_fds=(3, 4), preexec_fn=child_fds,
                                     stdout=self.log, stderr=self.log, start_new_session=True)
        atexit.register(self.stop)
        os.close(to_r)
        os.close(from_w)
        self.buf = b""
        self.next_id = 0
        self.session = None

    def stop(self):
        """Closes Chromium (Browser.close: it removes its own temporary files then), or kills its
        whole process group if it does not exit, waits until none of it runs, and removes the
        profile.  Safe to call twice (finish, then atexit)."""
        if self.proc.returncode is None:
            try:
                os.write(self.to_w, json.dumps({"id": 1 << 30, "method": "Browser.close"})
                         .encode() + b"\0")
                self.proc.wait(60)
            except (OSError, subprocess.TimeoutExpired):
                pass
        if self.proc.returncode is None:
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                pass
        deadline = time.time() + 10
        while group_running(self.proc.pid) and time.time() < deadline:
            time.sleep(0.05)
        self.log.close()
        shutil.rmtree(self.profile, ignore_errors=True)

    def finish(self, code, lines=()):
        for line in lines:
            print(line)
        self.stop()
        sys.exit(code)

    def _read(self, deadline):
        while b"\0" not in self.buf:
            left = deadline - time.time()
            if left <= 0:
                self.finish(1, ["FAIL: Chromium did not answer in time"])
            r, _, _ = select.select([self.from_r], [], [], left)
            if not r:
                continue
            chunk = os.read(self.from_r, 1 << 20)
            if not chunk:
                self.log.flush()
                tail = open(os.path.join(self.profile, "chromium.log")).read()[-600:]
                self.finish(77, ["Chromium cannot run here: it closed the DevTools pipe: " +
                                 tail.strip().replace("\n", " | ")])
            self.buf += chunk
        msg, self.buf = self.buf.split(b"\0", 1)
        return json.loads(msg)

    def call(self, method, params=None, timeout=60, session=True):
        self.next_id += 1
        m = {"id": self.next_id, "method": method, "params": params or {}}
        if session and self.session:
            m["sessionId"] = self.session
        os.write(self.to_w, json.dumps(m).encode() + b"\0")
        deadline = time.time() + timeout
        while True:
            r = self._read(deadline)
            if r.get("id") == self.next_id:
                if "error" in r:
                    self.finish(1, ["FAIL: DevTools %s: %s" % (method, r["error"])])
                return r["result"]

    def open(self, url):
        target = self.call("Target.createTarget", {"url": url}, session=False)["targetId"]
        self.session = self.call("Target.attachToTarget", {"targetId": target, "flatten": True},
                                 session=False)["sessionId"]

    def eval(self, expression, timeout=60):
        """The value of a JavaScript expression (awaited if a promise), or None on an exception."""
        r = self.call("Runtime.evaluate", {"expression": expression, "returnByValue": True,
                                           "awaitPromise": True}, timeout)
        if "exceptionDetails" in r:
            return None
        return r["result"].get("value")

    def click_at(self, x, y):
        for kind in ("mousePressed", "mouseReleased"):
            self.call("Input.dispatchMouseEvent", {"type": kind, "x": x, "y": y,
                                                   "button": "left", "clickCount": 1})

    def screenshot(self, path, clip=None):
        params = {"format": "png"}
        if clip:
            params["clip"] = clip
        data = self.call("Page.captureScreenshot", params)["data"]
        open(path, "wb").write(base64.b64decode(data))


def read_png_rgb(path):
    """(width, height, bytes of RGB rows) of an 8-bit RGB or RGBA, non-interlaced PNG."""
    data = open(path, "rb").read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError("%s: not a PNG" % path)
    at, idat, w = 8, b"", 0
    while at < len(data):
        n, kind = struct.unpack(">I4s", data[at:at + 8])
        body = data[at + 8:at + 8 + n]
        if kind == b"IHDR":
            w, h, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", body)
            if depth != 8 or ctype not in (2, 6) or interlace:
                raise ValueError("%s: not an 8-bit RGB(A) PNG" % path)
            bpp = 3 if ctype == 2 else 4
        elif kind == b"IDAT":
            idat += body
        at += 12 + n
    raw, stride, rows, prev = zlib.decompress(idat), w * bpp, [], bytearray(w * bpp)
    for y in range(h):
        f, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b, c = prev[i], prev[i - bpp] if i >= bpp else 0
            if f == 1: line[i] = (line[i] + a) & 255
            elif f == 2: line[i] = (line[i] + b) & 255
            elif f == 3: line[i] = (line[i] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(bytes(line) if bpp == 3 else bytes(v for k, v in enumerate(line) if k % 4 != 3))
        prev = line
    return w, h, b"".join(rows)


def psnr(a, b):
    """PSNR in dB of two equal-length byte strings (inf when equal)."""
    import math
    se = sum((x - y) * (x - y) for x, y in zip(a, b))
    return float("inf") if se == 0 else 10 * math.log10(255.0 * 255.0 * len(a) / se)
