// web/paint.js: Raypaint's page (web/paint.html).  It long-polls the view's display messages
// (/api/paint/updates) and draws each one as coordinator/paint/paint_raster.c does, with the
// same integer arithmetic, so the canvas is the server's picture byte for byte: lattice nodes
// as bilinearly shaded quads, exact nodes as the render's pixels.  A click or a drag marks the
// area to paint first; the camera, sun and mist controls post a new view, which the server
// starts within a frame; messages of an old view are never drawn (the server serves only the
// current view's, and this page keeps only the generation it is told).  Controls are POSTs with
// the token in a header (from the tf_token cookie), never the cookie alone.
"use strict";

const paint = {
  gen: 0, end: 0, width: 0, height: 0, img: null, dirty: false, view: null, viewGen: -1,
  messages: 0, bytes: 0, changedAt: 0, changedFrom: 0, latencyMs: null, errors: 0,
  interest: null, interestSent: null, // the area clicked, and the promise of its POST
};
window.paint = paint;
const $ = (id) => document.getElementById(id);
const canvas = $("picture");
const ctx = canvas.getContext("2d");

function cookieToken() {
  const m = document.cookie.match(/(?:^|;\s*)tf_token=([^;]*)/);
  return m ? decodeURIComponent(m[1]) : "";
}

async function control(path, body) {
  const r = await fetch(path, {
    method: "POST", cache: "no-store",
    headers: { "X-Terrafarm-Token": cookieToken() || "loopback", "Content-Type": "application/json" },
    body: JSON.stringify(body || {}),
  });
  const text = await r.text();
  $("said").textContent = r.ok ? "" : text.trim();
  return r.ok ? JSON.parse(text || "{}") : null;
}

// ---- drawing: paint_raster.h, the same arithmetic ----

function axis(x, s, d, limit) {
  const end = Math.min(x + s, limit), pos = [];
  for (let p = x; p < end; p += d) pos.push(p);
  pos.push(end);
  return pos;
}

function shadeCell(data, w, x0, x1, y0, y1, src, i00, i10, i01, i11) {
  const D = 4 * (x1 - x0) * (y1 - y0), half = Math.floor(D / 2);
  for (let py = y0; py < y1; py++) {
    const ay = 2 * (py - y0) + 1, by = 2 * (y1 - y0) - ay;
    let o = (py * w + x0) * 4;
    for (let px = x0; px < x1; px++, o += 4) {
      const ax = 2 * (px - x0) + 1, bx = 2 * (x1 - x0) - ax;
      for (let ch = 0; ch < 3; ch++)
        data[o + ch] = Math.floor((src[i00 + ch] * bx * by + src[i10 + ch] * ax * by +
                                   src[i01 + ch] * bx * ay + src[i11 + ch] * ax * ay + half) / D);
      data[o + 3] = 255;
    }
  }
}

function drawLattice(x, y, s, d, src, at) {
  const w = paint.width, xs = axis(x, s, d, w), ys = axis(y, s, d, paint.height);
  const ni = xs.length, data = paint.img.data;
  for (let j = 0; j + 1 < ys.length; j++)
    for (let i = 0; i + 1 < ni; i++) {
      const i00 = at + (j * ni + i) * 3;
      shadeCell(data, w, xs[i], xs[i + 1], ys[j], ys[j + 1], src, i00, i00 + 3,
                i00 + ni * 3, i00 + ni * 3 + 3);
    }
  return xs.length * ys.length * 3;
}

function drawExact(x, y, s, src, at) {
  const w = paint.width, pw = Math.min(x + s, w) - x, ph = Math.min(y + s, paint.height) - y;
  const data = paint.img.data;
  for (let r = 0; r < ph; r++)
    for (let c = 0; c < pw; c++) {
      const o = ((y + r) * w + x + c) * 4, i = at + (r * pw + c) * 3;
      data[o] = src[i]; data[o + 1] = src[i + 1]; data[o + 2] = src[i + 2]; data[o + 3] = 255;
      paint.exact[(y + r) * w + x + c] = 1;
    }
  return pw * ph * 3;
}

function apply(buf) {
  const dv = new DataView(buf), src = new Uint8Array(buf);
  let at = 0;
  while (at + 20 <= buf.byteLength) {
    const kind = dv.getUint32(at, true), x = dv.getUint32(at + 4, true), y = dv.getUint32(at + 8, true);
    const s = dv.getUint32(at + 12, true), d = dv.getUint32(at + 16, true);
    at += 20;
    at += kind === 1 ? drawLattice(x, y, s, d, src, at) : drawExact(x, y, s, src, at);
    paint.messages++;
  }
  paint.bytes += buf.byteLength;
  paint.dirty = true;
}

function flush() {
  if (paint.dirty && paint.img) ctx.putImageData(paint.img, 0, 0);
  paint.dirty = false;
}
paint.flush = flush;
function frame() { flush(); requestAnimationFrame(frame); }

function resize(w, h) {
  if (paint.width === w && paint.height === h) return;
  paint.width = canvas.width = w;
  paint.height = canvas.height = h;
  paint.img = ctx.createImageData(w, h);
  paint.exact = new Uint8Array(w * h);
}

// What share of the pixels inside and outside area a are exact (the tests' measure of "the
// area pointed at first").
paint.exactShares = (a) => {
  let inside = 0, outside = 0;
  for (let y = 0; y < paint.height; y++)
    for (let x = 0; x < paint.width; x++) {
      const e = paint.exact[y * paint.width + x];
      if (x >= a.x && x < a.x + a.w && y >= a.y && y < a.y + a.h) inside += e; else outside += e;
    }
  const n = a.w * a.h;
  return [inside / n, outside / (paint.width * paint.height - n)];
};

// The canvas as RGB bytes, base64 (the tests compare it with the render's PNG).
paint.rgb = () => {
  flush();
  const d = ctx.getImageData(0, 0, paint.width, paint.height).data;
  let bin = "";
  for (let i = 0; i < d.length; i += 4) bin += String.fromCharCode(d[i], d[i + 1], d[i + 2]);
  return btoa(bin);
};

// A new view: the old picture dimmed until the new one covers it.
function newView(gen) {
  const data = paint.img.data;
  for (let i = 0; i < data.length; i += 4) {
    data[i] >>= 1; data[i + 1] >>= 1; data[i + 2] >>= 1;
  }
  paint.gen = gen;
  paint.end = 0;
  paint.messages = 0;
  paint.exact.fill(0);
  paint.dirty = true;
}

async function poll() {
  for (;;) {
    try {
      const r = await fetch(`/api/paint/updates?gen=${paint.gen}&from=${paint.end}&wait=1000`,
                            { cache: "no-store" });
      if (!r.ok) throw new Error(`updates: ${r.status}`);
      const gen = Number(r.headers.get("X-Paint-Gen")), end = Number(r.headers.get("X-Paint-End"));
      const buf = await r.arrayBuffer();
      if (gen !== paint.gen) newView(gen);
      if (buf.byteLength) {
        apply(buf);
        if (paint.changedAt && gen > paint.changedFrom && paint.latencyMs === null)
          paint.latencyMs = performance.now() - paint.changedAt;
      }
      paint.end = end;
      $("error").hidden = true;
    } catch (e) {
      paint.errors++;
      $("error").textContent = String(e.message || e);
      $("error").hidden = false;
      await new Promise((ok) => setTimeout(ok, 1000));
    }
  }
}

// ---- status ----

function showFigures(s) {
  const c = s.counts, pct = (100 * c.exact_pixels / Math.max(1, c.pixels)).toFixed(1);
  const state = s.painted_s >= 0 ? "painted" : s.paused ? "paused" : "painting";
  $("state").textContent = state;
  $("state").className = "badge " + state;
  $("pause").textContent = s.paused ? "resume" : "pause";
  $("figures").textContent = `view ${s.gen} · ${pct}% exact · ${c.samples} samples · ` +
    `${s.workers} workers · coarse ${s.coarse_s >= 0 ? s.coarse_s.toFixed(3) + " s" : "…"} · ` +
    `painted ${s.painted_s >= 0 ? s.painted_s.toFixed(2) + " s" : "…"}` +
    (s.stale ? ` · ${s.stale} stale dropped` : "") + (s.refused ? ` · ${s.refused} refused` : "");
}

function showView(v) {
  paint.view = v;
  // a slider never clamps the scene's own value: its range grows to hold it
  const set = (id, value) => {
    const e = $(id);
    if (value > Number(e.max)) e.max = String(value * 2);
    if (value < Number(e.min)) e.min = String(value);
    e.value = value;
    e.nextElementSibling.value = value;
  };
  set("fov", v.camera.fov);
  set("azimuth", ((v.sun.azimuth % 360) + 360) % 360);
  set("elevation", v.sun.elevation);
  $("mist").checked = v.mist.enabled;
  set("density", v.mist.density);
  set("falloff", v.mist.falloff);
}

async function statusOnce() {
  try {
    const r = await fetch("/api/paint/status", { cache: "no-store" });
    if (!r.ok) return false;
    const s = await r.json();
    resize(s.width, s.height);
    if (s.gen !== paint.viewGen) { paint.viewGen = s.gen; showView(s.view); }
    showFigures(s);
    paint.status = s;
    return true;
  } catch (e) {
    return false; /* the updates loop reports */
  }
}

async function status() {
  for (;;) {
    await statusOnce();
    await new Promise((ok) => setTimeout(ok, 400));
  }
}

// ---- the controls ----

function postView(view) {
  paint.changedAt = performance.now();
  paint.changedFrom = paint.gen;
  paint.latencyMs = null;
  paint.view = view;
  return control("/api/paint/view", view);
}
paint.postView = postView;

const sub = (a, b) => a.map((v, i) => v - b[i]);
const add = (a, b, k) => a.map((v, i) => v + k * b[i]);
const norm = (a) => { const l = Math.hypot(...a) || 1; return a.map((v) => v / l); };
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];

// The camera after one step of a move (orbits turn 10 degrees about the point looked at).
function moved(cam, move) {
  const p = cam.position, l = cam.look_at, f = norm(sub(l, p)), r = norm(cross(f, cam.up));
  const step = 0.08 * Math.hypot(...sub(l, p));
  const both = (dir, k) => ({ position: add(p, dir, k), look_at: add(l, dir, k) });
  if (move === "forward") return both(f, step);
  if (move === "back") return both(f, -step);
  if (move === "left") return both(r, -step);
  if (move === "right") return both(r, step);
  if (move === "up") return both(norm(cam.up), step);
  if (move === "down") return both(norm(cam.up), -step);
  if (move === "tilt") return { position: p, look_at: add(l, norm(cam.up), -step) };
  const a = (move === "orbit-left" ? 10 : -10) * Math.PI / 180, d = sub(p, l);
  const turned = [d[0] * Math.cos(a) - d[1] * Math.sin(a), d[0] * Math.sin(a) + d[1] * Math.cos(a), d[2]];
  return { position: add(l, turned, 1), look_at: l };
}

function controlsView() {
  const v = JSON.parse(JSON.stringify(paint.view));
  v.camera.fov = Number($("fov").value);
  v.sun.azimuth = Number($("azimuth").value);
  v.sun.elevation = Number($("elevation").value);
  v.mist.enabled = $("mist").checked;
  v.mist.density = Number($("density").value);
  v.mist.falloff = Number($("falloff").value);
  return v;
}

function wireControls() {
  for (const b of document.querySelectorAll("[data-move]"))
    b.addEventListener("click", () => {
      if (!paint.view) return;
      const v = controlsView();
      Object.assign(v.camera, moved(v.camera, b.dataset.move));
      postView(v);
    });
  for (const id of ["fov", "azimuth", "elevation", "mist", "density", "falloff"]) {
    $(id).addEventListener("input", () => {
      if ($(id).nextElementSibling) $(id).nextElementSibling.value = $(id).value;
    });
    $(id).addEventListener("change", () => paint.view && postView(controlsView()));
  }
  $("pause").addEventListener("click", () =>
    control(paint.status && paint.status.paused ? "/api/paint/resume" : "/api/paint/pause"));
  $("save").addEventListener("click", async () => {
    const a = await control("/api/paint/save");
    if (a) $("said").textContent = `saved to ${a.saved}`;
  });
  $("submit").addEventListener("click", async () => {
    const a = await control("/api/paint/submit");
    if (a) $("said").textContent = `submitted: job ${a.id}`;
  });
}

// ---- pointing: an area of interest, in image pixels ----

function imageXY(e) {
  const b = canvas.getBoundingClientRect();
  return [Math.floor((e.clientX - b.left) * canvas.width / b.width),
          Math.floor((e.clientY - b.top) * canvas.height / b.height)];
}

function wirePointing() {
  let from = null;
  canvas.addEventListener("mousedown", (e) => { from = imageXY(e); });
  canvas.addEventListener("mouseup", (e) => {
    if (!from) return;
    const to = imageXY(e), w = paint.width, h = paint.height;
    let x = Math.min(from[0], to[0]), y = Math.min(from[1], to[1]);
    let aw = Math.abs(to[0] - from[0]), ah = Math.abs(to[1] - from[1]);
    if (aw < 4 && ah < 4) { // a click: an eighth of the picture around it
      aw = Math.max(16, Math.floor(w / 8)); ah = Math.max(16, Math.floor(h / 8));
      x = to[0] - Math.floor(aw / 2); y = to[1] - Math.floor(ah / 2);
    }
    x = Math.max(0, Math.min(x, w - 1)); y = Math.max(0, Math.min(y, h - 1));
    aw = Math.max(1, Math.min(aw, w - x)); ah = Math.max(1, Math.min(ah, h - y));
    from = null;
    paint.interest = { x, y, w: aw, h: ah };
    paint.interestSent = control("/api/paint/interest", paint.interest); // the server's answer
    $("said").textContent = `painting ${aw}x${ah} at ${x},${y} first`;
  });
}

async function start() {
  while (!(await statusOnce())) await new Promise((ok) => setTimeout(ok, 500));
  wireControls();
  wirePointing();
  status();
  poll();
  requestAnimationFrame(frame);
}
start();
