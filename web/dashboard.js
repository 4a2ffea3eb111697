// web/dashboard.js: the terrafarm dashboard's behaviour (web/index.html).  Polls the JSON API
// (/api/status, /api/workers, /api/tasks every half second, /api/history now and then), follows
// the event stream (/api/events/stream, server-sent events), draws the preview as it comes
// into focus with the outstanding tasks outlined, and plots throughput and speedup.  Controls
// are POSTs carrying the token in a header (read from the tf_token cookie), never the cookie
// alone, so a page from elsewhere cannot forge them.  The body's data-* attributes summarise
// what is shown, for the browser test (tests/e2e/dashboard_browser.sh).
"use strict";

const $ = (id) => document.getElementById(id);
const POLL_MS = 500;
let status = null, tasks = null, history = [], preview = null, previewKey = -1, previewBusy = false;
let previewWanted = null; // {key, stamps}: the newest asked for; a load in flight fetches it next
let tick = 0, ended = false, events = 0;

function cookieToken() {
  const m = document.cookie.match(/(?:^|;\s*)tf_token=([^;]*)/);
  return m ? decodeURIComponent(m[1]) : null;
}

async function getJSON(path) {
  const r = await fetch(path, { cache: "no-store" });
  if (!r.ok) throw new Error(path + ": HTTP " + r.status + " " + (await r.text()).trim());
  return r.json();
}

async function control(path, body) {
  const out = $("control-result");
  try {
    const r = await fetch(path, {
      method: "POST",
      headers: { "X-Terrafarm-Token": cookieToken() || "loopback", "Content-Type": "application/json" },
      body: body ? JSON.stringify(body) : "",
    });
    const text = (await r.text()).trim();
    let msg = text;
    try { msg = JSON.parse(text).message || text; } catch (e) { /* plain text */ }
    out.textContent = (r.ok ? "" : "refused (" + r.status + "): ") + msg;
  } catch (e) {
    out.textContent = "failed: " + e.message;
  }
}

function showError(msg) {
  const e = $("error");
  e.textContent = msg;
  e.hidden = false;
  document.body.dataset.error = msg;
}

function clearError() {
  $("error").hidden = true;
  delete document.body.dataset.error;
}

function fmtDuration(s) {
  if (s === null || s === undefined || s < 0 || !isFinite(s)) return "\u2013";
  s = Math.round(s);
  const h = Math.floor(s / 3600), m = Math.floor(s / 60) % 60, sec = s % 60;
  const two = (v) => String(v).padStart(2, "0");
  return h ? h + ":" + two(m) + ":" + two(sec) : m + ":" + two(sec);
}

function fmtRate(r) {
  if (r >= 1e9) return (r / 1e9).toFixed(2) + " G";
  if (r >= 1e6) return (r / 1e6).toFixed(2) + " M";
  if (r >= 1e3) return (r / 1e3).toFixed(1) + " k";
  return r.toFixed(0);
}

function renderStatus(s) {
  const b = document.body;
  b.dataset.state = s.state;
  b.dataset.percent = s.percent.toFixed(2);
  b.dataset.rowsWritten = s.rows_written;
  $("scene").textContent = s.scene + " \u2014 " + s.size + " \u2014 " + s.tasks;
  const st = $("state");
  st.textContent = s.state;
  st.className = "badge " + s.state;
  const fr = $("frames");
  if (s.frames_total !== null) {
    fr.hidden = false;
    fr.textContent = "frame " + s.frame + " \u2014 " + s.frames_done + " of " + s.frames_total +
      " frames done";
  } else {
    fr.hidden = true;
  }
  $("bar-fill").style.width = s.percent.toFixed(1) + "%";
  $("rows").textContent = s.rows_written + " / " + s.rows_total;
  $("percent").textContent = s.percent.toFixed(1) + " %";
  $("elapsed").textContent = fmtDuration(s.elapsed_s);
  $("eta").textContent = s.state === "finished" ? "done" : fmtDuration(s.eta_s);
  $("rate").textContent = fmtRate(s.rays_per_s_recent);
  $("spp").textContent = s.samples_per_pixel_avg.toFixed(2);
  $("outstanding").textContent = s.outstanding_tasks;
  $("watermark").textContent = s.watermark;
  $("redealt").textContent = s.tasks_redealt;
  const wm = $("wm-value");
  wm.min = s.watermark_min;
  wm.max = s.watermark_max;
  if (document.activeElement !== wm) wm.placeholder = s.watermark;
  const running = s.state === "rendering" || s.state === "starting";
  $("stop").disabled = $("wm-set").disabled = !running;
  $("stamps").textContent = s.preview_stamps + " stamps drawn";
  document.title = "terrafarm " + s.percent.toFixed(0) + "% " + s.scene;
}

function cell(tr, text, cls) {
  const td = document.createElement("td");
  td.textContent = text;
  if (cls) td.className = cls;
  tr.appendChild(td);
  return td;
}

function renderWorkers(list) {
  const body = $("workers").tBodies[0];
  body.replaceChildren();
  let live = 0;
  for (const w of list) {
    const tr = document.createElement("tr");
    tr.className = w.state;
    tr.dataset.worker = w.id;
    cell(tr, w.id);
    cell(tr, w.kind);
    cell(tr, w.host);
    cell(tr, w.backend);
    cell(tr, w.state, w.state);
    cell(tr, w.task === null ? "" : w.task);
    cell(tr, w.tasks);
    cell(tr, (w.rays / 1e6).toFixed(2));
    cell(tr, w.busy_fraction === null ? "" : (100 * w.busy_fraction).toFixed(0) + " %");
    cell(tr, w.connected_since === null ? "" : new Date(w.connected_since).toLocaleTimeString());
    cell(tr, w.last_heard_ago_s === null ? "" : w.last_heard_ago_s.toFixed(1) + " s ago");
    const td = cell(tr, "");
    if (w.state === "busy" || w.state === "idle") {
      const btn = document.createElement("button");
      btn.type = "button";
      btn.textContent = "drop";
      btn.addEventListener("click", () => control("/api/workers/" + w.id + "/drop"));
      td.appendChild(btn);
      live++;
    }
    body.appendChild(tr);
  }
  document.body.dataset.workers = list.length;
  document.body.dataset.workersLive = live;
  $("worker-count").textContent = live + " connected, " + list.length + " seen";
}

// Warm colours for workers, so that none is mistaken for the green of "done".
const PALETTE = ["#ffb347", "#ff6f91", "#ffd166", "#c792ea", "#4fc3f7", "#f78c6c", "#ff9ff3", "#feca57"];
function workerColour(id) {
  return PALETTE[(id - 1 + PALETTE.length * 1000) % PALETTE.length];
}

// The preview, then the outstanding tasks outlined on it.
function drawImage() {
  if (!status) return;
  const c = $("image");
  const scale = Math.min(1, 960 / status.width);
  const cw = Math.max(1, Math.round(status.width * scale)), ch = Math.max(1, Math.round(status.height * scale));
  if (c.width !== cw || c.height !== ch) { c.width = cw; c.height = ch; }
  const g = c.getContext("2d");
  g.fillStyle = "#0b0d10";
  g.fillRect(0, 0, cw, ch);
  if (preview) {
    g.imageSmoothingEnabled = true;
    g.drawImage(preview, 0, 0, cw, ch);
  }
  if (!tasks || status.state !== "rendering") return;
  g.lineWidth = 1.5;
  g.font = "11px sans-serif";
  for (const t of tasks.outstanding) {
    const x = t.x * scale, y = t.y * scale, w = t.w * scale, h = t.h * scale;
    if (t.state === "held") {
      g.setLineDash([]);
      g.lineWidth = 2.5;
      g.strokeStyle = workerColour(t.worker);
      g.strokeRect(x + 1.5, y + 1.5, w - 3, h - 3);
      g.lineWidth = 1.5;
      const label = "w" + t.worker;
      g.fillStyle = "rgba(11, 13, 16, 0.75)";
      g.fillRect(x + 3, y + 3, g.measureText(label).width + 4, 13);
      g.fillStyle = workerColour(t.worker);
      g.fillText(label, x + 5, y + 13);
    } else if (t.state === "queued") {
      g.setLineDash([4, 3]);
      g.strokeStyle = "#8899aa";
      g.strokeRect(x + 1, y + 1, w - 2, h - 2);
    } else {
      g.setLineDash([]);
      g.strokeStyle = "rgba(92, 208, 138, 0.6)";
      g.strokeRect(x + 1, y + 1, w - 2, h - 2);
    }
  }
  g.setLineDash([]);
}

// How much of the preview is drawn: its opaque pixels, counted once per new preview.
function countDrawn(img) {
  const o = document.createElement("canvas");
  o.width = img.naturalWidth;
  o.height = img.naturalHeight;
  const g = o.getContext("2d");
  g.drawImage(img, 0, 0);
  const px = g.getImageData(0, 0, o.width, o.height).data;
  let n = 0;
  for (let i = 3; i < px.length; i += 4) if (px[i] > 0) n++;
  document.body.dataset.previewPixels = n;
  document.body.dataset.previewTotal = o.width * o.height;
}

function loadPreview(key, stamps) {
  previewWanted = {key, stamps};
  if (previewBusy) return; // onload asks for previewWanted: the final picture is never skipped
  previewBusy = true;
  const img = new Image();
  img.onload = () => {
    preview = img;
    previewKey = key;
    previewBusy = false;
    document.body.dataset.stampsDrawn = stamps; // of this picture, not of the newest status
    countDrawn(img);
    drawImage();
    if (previewWanted.key !== previewKey) loadPreview(previewWanted.key, previewWanted.stamps);
  };
  img.onerror = () => { previewBusy = false; showError("cannot load the preview image"); };
  img.src = "/api/preview.png?v=" + key;
}

function drawPlot() {
  const c = $("plot"), g = c.getContext("2d");
  const W = c.width, H = c.height, L = 40, R = 34, T = 10, B = 22;
  g.fillStyle = "#0b0d10";
  g.fillRect(0, 0, W, H);
  // rates over spans of at least a second: results arrive in lumps, a task at a time
  const pts = [];
  for (let i = 1, a = history[0]; i < history.length; i++) {
    const b = history[i], dt = b.t - a.t;
    if (dt < 1.0) continue;
    pts.push({ t: b.t, rays: (b.rays - a.rays) / dt / 1e6, busy: (b.busy_s - a.busy_s) / dt, workers: b.workers });
    a = b;
  }
  const first = history[0], last = history[history.length - 1];
  if (pts.length < 1 && history.length > 1 && last.t > first.t) { // under a second in all: one rate
    const dt = last.t - first.t;
    pts.push({ t: last.t, rays: (last.rays - first.rays) / dt / 1e6, busy: (last.busy_s - first.busy_s) / dt, workers: last.workers });
  }
  document.body.dataset.plotPoints = pts.length;
  if (pts.length < 1) return;
  const tmax = Math.max(1, pts[pts.length - 1].t);
  const rmax = Math.max(0.01, ...pts.map((p) => p.rays)) * 1.1;
  const bmax = Math.max(1, ...pts.map((p) => Math.max(p.busy, p.workers))) * 1.1;
  const X = (t) => L + (W - L - R) * t / tmax;
  g.strokeStyle = "#2a3038";
  g.fillStyle = "#7d8a97";
  g.font = "10px sans-serif";
  for (let k = 0; k <= 4; k++) {
    const y = T + (H - T - B) * k / 4;
    g.beginPath(); g.moveTo(L, y); g.lineTo(W - R, y); g.stroke();
    g.fillText((rmax * (1 - k / 4)).toFixed(2), 2, y + 3);
    g.fillText((bmax * (1 - k / 4)).toFixed(1), W - R + 4, y + 3);
  }
  g.fillText("0", L, H - 6);
  g.fillText(fmtDuration(tmax), W - R - 24, H - 6);
  const line = (key, max, colour) => {
    g.strokeStyle = colour;
    g.lineWidth = 2;
    g.beginPath();
    pts.forEach((p, i) => {
      const y = T + (H - T - B) * (1 - p[key] / max);
      if (i) g.lineTo(X(p.t), y); else g.moveTo(X(p.t), y);
    });
    g.stroke();
  };
  line("rays", rmax, "#3c8dde");
  line("busy", bmax, "#ffb347");
}

function addEvent(e) {
  const li = document.createElement("li");
  li.className = e.kind;
  li.value = e.seq;
  const t = new Date(e.time).toLocaleTimeString();
  li.textContent = t + "  " + e.kind + (e.worker !== null ? "  worker " + e.worker : "") +
    (e.task !== null ? "  task " + e.task : "") + "  " + e.text;
  const list = $("events");
  list.insertBefore(li, list.firstChild);
  while (list.children.length > 300) list.removeChild(list.lastChild);
  document.body.dataset.events = ++events;
}

function followEvents() {
  const es = new EventSource("/api/events/stream");
  for (const kind of ["join", "leave", "redeal", "failure", "exclusion", "control", "end"])
    es.addEventListener(kind, (m) => addEvent(JSON.parse(m.data)));
  es.addEventListener("status", (m) => {
    if (ended) return;
    status = JSON.parse(m.data);
    renderStatus(status);
    if (status.state !== "rendering" && status.state !== "starting") {
      // the coordinator says how it ended, then the stream closes; one last poll fetches the
      // final picture, workers and tasks (the stream carries none of them) and ends polling
      es.close();
      poll();
    }
  });
  es.onerror = () => { if (ended) es.close(); };
}

async function poll() {
  if (ended) return;
  tick++;
  try {
    const [s, w, t] = await Promise.all([getJSON("/api/status"), getJSON("/api/workers"), getJSON("/api/tasks")]);
    status = s;
    tasks = t;
    renderStatus(s);
    renderWorkers(w.workers);
    if (tick % 4 === 1 || s.state !== "rendering") {
      history = (await getJSON("/api/history")).samples;
      drawPlot();
    }
    const key = s.preview_stamps * 1000003 + s.rows_written;
    if (key !== previewKey) loadPreview(key, s.preview_stamps);
    drawImage();
    clearError();
    document.body.dataset.polls = tick;
    if (s.state !== "rendering" && s.state !== "starting") {
      ended = true;
      document.body.dataset.ended = "1"; // the final history and plot are drawn
      return; // final: nothing more will change
    }
  } catch (e) {
    if (status && status.state !== "rendering" && status.state !== "starting") {
      ended = true;
      return;
    }
    if (status && status.state === "rendering" && tick > 2) {
      // the coordinator went away mid-render (stopped, or the last poll missed the end)
      showError("lost the coordinator: " + e.message);
    } else {
      showError("cannot reach the coordinator: " + e.message);
    }
  }
  setTimeout(poll, POLL_MS);
}

document.addEventListener("DOMContentLoaded", () => {
  $("stop").addEventListener("click", () => {
    if (confirm("Stop the render? The rows on disk stay; --resume continues it.")) control("/api/stop");
  });
  $("wm-set").addEventListener("click", () => {
    const v = parseInt($("wm-value").value, 10);
    if (Number.isInteger(v)) control("/api/watermark", { watermark: v });
  });
  document.body.dataset.state = "connecting";
  followEvents();
  poll();
});
