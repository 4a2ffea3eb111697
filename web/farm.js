/* farm.js: the standing farm's web view (farm.html).  Every second it reads the farm's JSON API
 * with the login cookie (GET /api/farm, /api/jobs, /api/jobs/ID for each running job's
 * dashboard link (a paint job's: its page), and /api/workers for admins) and redraws the tables;
 * a job's "paint" button opens a paint job of its scene; the controls POST with
 * the header X-Terrafarm-Request: 1, which the farm requires of cookie-authenticated POSTs (a
 * cross-site form cannot send it).  Everything a job says is shown as text, never as HTML.
 * document.body.dataset.refreshes counts the completed refreshes (for tests). */
'use strict';

const dashboards = {}; /* job id -> its render's dashboard URL, while it runs */
let refreshes = 0;

function el(tag, text, cls) {
  const e = document.createElement(tag);
  if (text !== undefined && text !== null) e.textContent = String(text);
  if (cls) e.className = cls;
  return e;
}

async function api(method, path, body) {
  const opts = { method, credentials: 'same-origin', headers: { 'X-Terrafarm-Request': '1' } };
  if (body !== undefined) {
    opts.headers['Content-Type'] = 'application/json';
    opts.body = JSON.stringify(body);
  }
  const r = await fetch(path, opts);
  if (r.status === 401) { window.location.href = '/'; throw new Error('logged out'); }
  const doc = r.status === 204 ? {} : await r.json();
  if (!r.ok) throw new Error(doc.error || (method + ' ' + path + ': HTTP ' + r.status));
  return doc;
}

function showError(msg, from) {
  const e = document.getElementById('error');
  e.textContent = msg || '';
  e.hidden = !msg;
  e.dataset.from = from || '';
}

function progressBar(percent) {
  const bar = el('div', null, 'bar');
  const fill = el('div');
  const p = percent === null || percent === undefined ? null : Math.max(0, Math.min(100, percent));
  fill.style.width = (p === null ? 0 : p) + '%';
  bar.append(fill, el('span', p === null ? '–' : p.toFixed(1) + ' %'));
  return bar;
}

function control(job, action, label, body) {
  const b = el('button', label);
  b.dataset.job = job.id;
  b.dataset.action = action;
  if (body !== undefined) b.dataset.body = JSON.stringify(body);
  /* what a click does is all in the button's attributes: an unchanged button is kept */
  b.addEventListener('click', () =>
    act(b.dataset.job, action, b.dataset.body === undefined ? undefined : JSON.parse(b.dataset.body)));
  return b;
}

async function act(id, action, body) {
  try {
    await api('POST', '/api/jobs/' + id + '/' + action, body === undefined ? {} : body);
    showError('');
    refresh();
  } catch (e) {
    showError('job ' + id + ': ' + e.message, 'control');
  }
}

/* Paint a job's scene (a still): POST /api/jobs/ID/paint queues a paint job whose page opens
 * at once; its row's link leads there. */
function paintButton(job) {
  const b = el('button', 'paint', 'paint');
  b.dataset.job = job.id;
  b.dataset.action = 'paint';
  b.title = 'see this scene come into focus on the farm\'s workers, and tune its view';
  b.addEventListener('click', async () => {
    try {
      const a = await api('POST', '/api/jobs/' + job.id + '/paint', {});
      showError('');
      document.getElementById('said').textContent =
        'paint job ' + a.id + ' opened: its link "paint view" appears in its row';
      refresh();
    } catch (e) {
      showError('job ' + job.id + ': ' + e.message, 'control');
    }
  });
  return b;
}

function controls(job) {
  const td = el('td');
  const paint = job.kind === 'paint';
  if (!paint && !job.frames) td.append(paintButton(job));
  if (['done', 'failed', 'cancelled'].includes(job.state)) return td;
  if (paint) {
    td.append(control(job, 'cancel', 'close'));
    return td;
  }
  if (job.state === 'paused') td.append(control(job, 'resume', 'resume'));
  else td.append(control(job, 'pause', 'pause'));
  td.append(control(job, 'cancel', 'cancel'),
            control(job, 'priority', 'prio +', { priority: Math.min(1000, job.priority + 1) }),
            control(job, 'priority', 'prio −', { priority: Math.max(-1000, job.priority - 1) }));
  return td;
}

function dashboardCell(job) {
  const td = el('td');
  const url = dashboards[job.id];
  if (job.state === 'running' && url && /^https?:\/\//.test(url)) {
    const a = el('a', job.kind === 'paint' ? 'paint view' : 'dashboard', 'dashboard');
    a.href = url;
    a.target = '_blank';
    a.rel = 'noopener noreferrer';
    td.append(a);
  }
  return td;
}

function jobRow(job) {
  const tr = el('tr');
  tr.dataset.job = job.id;
  tr.dataset.state = job.state;
  tr.dataset.kind = job.kind || 'render';
  const name = el('td', job.name);
  if (job.kind === 'paint') name.append(' ', el('span', 'paint', 'kind'));
  const state = el('td');
  state.append(el('span', job.state, 'state state-' + job.state));
  if (job.reason) state.title = job.reason;
  const prog = el('td');
  prog.append(progressBar(job.percent));
  tr.append(el('td', job.id, 'num'), name, el('td', job.owner), state, prog,
            el('td', job.priority, 'num'), el('td', job.pool), el('td', job.workers, 'num'),
            el('td', job.width + '×' + job.height + (job.frames ? ' ×' + job.frames : '')),
            controls(job), dashboardCell(job));
  return tr;
}

async function fetchDashboards(jobs) {
  for (const id of Object.keys(dashboards))
    if (!jobs.some(j => String(j.id) === id && j.state === 'running')) delete dashboards[id];
  await Promise.all(jobs.filter(j => j.state === 'running' && !dashboards[j.id]).map(async j => {
    const full = await api('GET', '/api/jobs/' + j.id);
    if (full.dashboard) dashboards[j.id] = full.dashboard;
  }));
}

/* The row shown for a job: its old row with only the cells that changed replaced, so a button
 * the pointer is pressing stays in the page (a button replaced between mousedown and mouseup
 * gets no click) and the refresh does not flicker. */
function mergeRow(row, fresh) {
  if (!row || row.cells.length !== fresh.cells.length) return fresh;
  Object.assign(row.dataset, fresh.dataset);
  const oldCells = [...row.cells], newCells = [...fresh.cells];
  oldCells.forEach((c, i) => { if (!c.isEqualNode(newCells[i])) row.replaceChild(newCells[i], c); });
  return row;
}

function drawJobs(jobs) {
  const body = document.querySelector('#jobs tbody');
  const shown = new Map([...body.rows].map(r => [r.dataset.job, r]));
  const rows = jobs.slice().reverse().map(j => mergeRow(shown.get(String(j.id)), jobRow(j)));
  rows.forEach((r, i) => { if (body.rows[i] !== r) body.insertBefore(r, body.rows[i] || null); });
  while (body.rows.length > rows.length) body.deleteRow(-1);
  document.getElementById('no-jobs').hidden = jobs.length > 0;
}

function workerRow(w) {
  const tr = el('tr');
  tr.dataset.worker = w.name;
  tr.append(el('td', w.name), el('td', w.pool), el('td', w.tags), el('td', w.job ? 'job ' + w.job : 'idle'),
            el('td', w.seen_s_ago.toFixed(1) + ' s ago', 'num'), el('td', w.sessions, 'num'),
            el('td', w.retreats, 'num'), el('td', w.terrains, 'num'));
  return tr;
}

function drawWorkers(doc) {
  document.getElementById('workers-box').hidden = false;
  document.querySelector('#workers tbody').replaceChildren(...doc.workers.map(workerRow));
  document.getElementById('assignments').textContent = '(' + doc.assignments + ' assignments)';
}

function drawSummary(farm, jobs) {
  const counts = {};
  for (const j of jobs) counts[j.state] = (counts[j.state] || 0) + 1;
  const parts = Object.entries(counts).map(([s, n]) => n + ' ' + s);
  document.getElementById('summary').textContent = 'v' + farm.version + ' · ' +
    (parts.join(', ') || 'no jobs') + ' · workers known: ' + farm.workers;
  document.getElementById('who').textContent = farm.caller.name + ' (' + farm.caller.role + ')';
  document.body.dataset.role = farm.caller.role;
}

let busy = false;
async function refresh() {
  if (busy) return;
  busy = true;
  try {
    const farm = await api('GET', '/api/farm');
    const jobs = (await api('GET', '/api/jobs')).jobs;
    drawSummary(farm, jobs);
    await fetchDashboards(jobs);
    drawJobs(jobs);
    if (farm.caller.role === 'admin') drawWorkers(await api('GET', '/api/workers'));
    document.body.dataset.refreshes = String(++refreshes);
    if (document.getElementById('error').dataset.from === 'refresh') showError('');
  } catch (e) {
    showError('cannot reach the farm: ' + e.message, 'refresh');
  } finally {
    busy = false;
  }
}

refresh();
setInterval(refresh, 1000);
