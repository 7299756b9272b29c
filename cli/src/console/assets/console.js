// goby console: the page's script. Reads the fleet from the console's
// server (a snapshot, then live server-sent events), draws the map and the
// plots on canvases, lists the messages, and builds the commander's form
// from the message definitions the server loaded. No library, nothing
// fetched from elsewhere.
'use strict';

const S = {
  nodes: new Map(),      // name -> node summary, with track and links
  messages: [],          // log entries, oldest first
  commands: new Map(),   // id -> command
  origin: null,
  seq: 0,
  source: '',
  connection: { connected: false, detail: 'connecting' },
  picked: null,
  forms: [],
  clock: null,           // a replay's virtual time (seconds since 1970); null: live
};

// What the tests and the measurements read: the state, and when each
// message was first shown (Date.now() of the frame that drew it).
const goby = window.goby = {
  state: S,
  shownAt: {},            // message seq -> ms since the epoch
  readyAt: null,          // performance.now() when the first snapshot was drawn
  snapshots: 0,
  errors: [],
};
window.addEventListener('error', (e) => goby.errors.push(String(e.message)));

const $ = (id) => document.getElementById(id);
const el = (tag, props, ...children) => {
  const e = document.createElement(tag);
  if (props) {
    for (const [k, v] of Object.entries(props)) {
      if (k === 'class') e.className = v;
      else if (k === 'text') e.textContent = v;
      else if (k.startsWith('on')) e.addEventListener(k.slice(2), v);
      else if (v !== undefined && v !== null && v !== false) e.setAttribute(k, v === true ? '' : v);
    }
  }
  for (const c of children) {
    if (c !== null && c !== undefined) e.append(c instanceof Node ? c : String(c));
  }
  return e;
};

const PALETTE = ['#1f77b4', '#d62728', '#2ca02c', '#9467bd', '#ff7f0e', '#17becf', '#8c564b', '#e377c2', '#7f7f7f', '#bcbd22'];
function colorOf(name) {
  const names = [...S.nodes.keys()].sort();
  const i = names.indexOf(name);
  return PALETTE[(i < 0 ? 0 : i) % PALETTE.length];
}

// A replay's clock, or the wall clock.
const now = () => (S.clock ?? Date.now() / 1000);
function age(t) {
  if (!t) return '—';
  const s = Math.max(0, now() - t);
  if (s < 120) return `${s.toFixed(0)} s`;
  if (s < 7200) return `${(s / 60).toFixed(0)} min`;
  return `${(s / 3600).toFixed(1)} h`;
}
// Times of day: local live, UTC in a replay (whose run is in UTC, as its
// header says).
function clock(t) {
  if (!t) return '';
  const d = new Date(t * 1000);
  return S.clock === null ? d.toTimeString().slice(0, 8) : d.toISOString().slice(11, 19);
}
const short = (type) => (type || '').split('.').pop();
const fmt = (v, digits = 1) => (v === null || v === undefined || Number.isNaN(v) ? '—' : Number(v).toFixed(digits));

// ---------------------------------------------------------------- events

function applySnapshot(snap) {
  S.nodes = new Map();
  for (const n of snap.nodes) S.nodes.set(n.name, n);
  S.messages = snap.messages || [];
  S.commands = new Map((snap.commands || []).map((c) => [c.id, c]));
  S.origin = snap.origin;
  S.seq = snap.seq;
  S.source = snap.source;
  if (snap.connection) S.connection = snap.connection;
  S.clock = snap.clock ?? null;
  goby.snapshots += 1;
  // The first gateway is picked until the operator picks another.
  if (S.picked === null || !S.nodes.has(S.picked)) {
    const first = [...S.nodes.values()].filter((n) => n.bridged).map((n) => n.name).sort()[0];
    S.picked = first ?? null;
  }
  renderMessages(true);
  renderCommands();
  updateNodeChoices();
  schedule();
}

function nodeOf(name) {
  let n = S.nodes.get(name);
  if (!n) {
    n = { name, track: [], links: [], queues: {} };
    S.nodes.set(name, n);
    updateNodeChoices();
  }
  return n;
}

function applyEvent(ev) {
  if (ev.event === 'snapshot') { applySnapshot(ev); return; }
  if (ev.seq !== undefined) {
    if (ev.seq <= S.seq) return;   // already in the snapshot
    S.seq = ev.seq;
  }
  switch (ev.event) {
    case 'node': {
      const n = nodeOf(ev.node.name);
      const { track, links } = n;
      Object.assign(n, ev.node);
      n.track = ev.node.track || track || [];
      n.links = ev.node.links || links || [];
      if (ev.node.bridged) updateNodeChoices();
      break;
    }
    case 'track': nodeOf(ev.node).track.push(ev.point); break;
    case 'link': nodeOf(ev.node).links.push(ev.point); break;
    case 'forecast': nodeOf(ev.node).forecast = ev.forecast; break;
    case 'gone': S.nodes.delete(ev.node); updateNodeChoices(); break;
    case 'origin': S.origin = ev.origin; break;
    case 'message':
      S.messages.push(ev.message);
      if (S.messages.length > 2000) S.messages.shift();
      addMessageRow(ev.message, true);
      break;
    case 'command': S.commands.set(ev.command.id, ev.command); renderCommands(); break;
    case 'source': S.connection = { connected: ev.connected, detail: ev.detail }; break;
    case 'clock': S.clock = ev.time; break;
    default: break;
  }
  schedule();
}

// With `?static` in the page's address, one snapshot (`/api/state`) and no
// event stream: a still picture, for a headless browser's screenshot (an
// open stream is a request that never ends, so a browser that waits for the
// network to be quiet, as `--virtual-time-budget` does, would wait forever).
const still = new URLSearchParams(window.location.search).has('static');
goby.still = still;

async function loadOnce() {
  const r = await fetch('/api/state');
  applySnapshot(await r.json());
  S.source = `${S.source} (a still picture: reload to update)`;
  // Drawn at once, not at the next animation frame: a headless browser
  // with a virtual time budget may spend its budget before any frame
  // comes, and dump a page never drawn.
  render();
}

function connect() {
  if (still) {
    loadOnce().catch((e) => goby.errors.push(String(e)));
    return;
  }
  const events = new EventSource('/api/events');
  events.onmessage = (m) => {
    try { applyEvent(JSON.parse(m.data)); } catch (e) { goby.errors.push(String(e)); }
  };
  events.onerror = () => {
    S.connection = { connected: false, detail: 'the console server is away; trying again' };
    schedule();
  };
}

// ---------------------------------------------------------------- drawing

let pending = false;
const freshRows = [];
function schedule() {
  if (pending) return;
  pending = true;
  requestAnimationFrame(() => {
    pending = false;
    render();
    const shown = Date.now();
    for (const seq of freshRows.splice(0)) goby.shownAt[seq] = shown;
    if (goby.readyAt === null && goby.snapshots > 0) goby.readyAt = performance.now();
  });
}

function render() {
  $('source').textContent = S.source;
  const pill = $('connection');
  const replayed = S.clock === null ? '' : `run time ${new Date(S.clock * 1000).toISOString().slice(0, 19).replace('T', ' ')} UTC; `;
  pill.textContent = replayed + (S.connection.connected ? (S.clock === null ? 'connected' : S.connection.detail) : S.connection.detail);
  pill.className = 'pill ' + (S.connection.connected ? 'up' : 'down');
  // Only a replay has a clock of its own: it takes no commands.
  if (S.clock !== null) {
    for (const [send, said] of [['cmd-send', 'cmd-said'], ['mac-send', 'mac-said']]) {
      $(send).disabled = true;
      $(said).textContent = 'a replay takes no commands';
    }
  }
  renderNodes();
  drawMap();
  renderDetail();
  renderMac();
}

function renderNodes() {
  const body = $('nodes').tBodies[0];
  body.replaceChildren();
  for (const n of [...S.nodes.values()].sort((a, b) => a.name.localeCompare(b.name))) {
    const bridge = n.bridged ? (n.online === false ? 'down' : n.online ? `up${n.reconnects ? '/' + n.reconnects : ''}` : '?') : 'link only';
    const p = n.position;
    const tr = el('tr', { 'data-node': n.name, class: n.name === S.picked ? 'picked' : '', onclick: () => pick(n.name) },
      el('td', null, el('span', { class: 'swatch', style: `background:${colorOf(n.name)}` }), n.name),
      el('td', { class: 'num' }, n.modem_id ?? '—'),
      el('td', null, bridge),
      el('td', { class: 'num' }, n.queued ?? 0),
      el('td', { class: 'num' }, n.received ?? 0),
      el('td', { class: 'num' }, n.acks ?? 0),
      el('td', { class: 'num' }, n.expires ?? 0),
      el('td', { title: n.driver_detail || '' }, n.driver || '—'),
      el('td', null, p ? `${fmt(p.x)}, ${fmt(p.y)} m (${age(p.t)})` : '—'),
      el('td', null, age(n.last_heard)));
    body.append(tr);
  }
}

function pick(name) {
  S.picked = name;
  renderMessages(true);
  schedule();
}

// The map: metres east (x) and north (y) of the origin, drawn to scale;
// the view fits every track unless the operator zoomed or panned.
const view = { fit: true, cx: 0, cy: 0, scale: 1 };

function sizeCanvas(canvas) {
  const ratio = window.devicePixelRatio || 1;
  const w = Math.max(50, Math.round(canvas.clientWidth));
  const h = Math.max(50, Math.round(canvas.clientHeight));
  if (canvas.width !== w * ratio || canvas.height !== h * ratio) {
    canvas.width = w * ratio;
    canvas.height = h * ratio;
  }
  const ctx = canvas.getContext('2d');
  ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
  return { ctx, w, h };
}

function niceStep(raw) {
  const p = Math.pow(10, Math.floor(Math.log10(raw)));
  for (const m of [1, 2, 5, 10]) if (m * p >= raw) return m * p;
  return 10 * p;
}

function fitView(w, h) {
  let minx = Infinity, maxx = -Infinity, miny = Infinity, maxy = -Infinity;
  for (const n of S.nodes.values()) {
    for (const p of n.track || []) {
      minx = Math.min(minx, p.x); maxx = Math.max(maxx, p.x);
      miny = Math.min(miny, p.y); maxy = Math.max(maxy, p.y);
    }
  }
  if (minx === Infinity) { view.cx = 0; view.cy = 0; view.scale = Math.min(w, h) / 1000; return false; }
  const spanx = Math.max(maxx - minx, 50), spany = Math.max(maxy - miny, 50);
  view.cx = (minx + maxx) / 2;
  view.cy = (miny + maxy) / 2;
  // Room for the names and ages written right of each node.
  view.cx = (minx + maxx) / 2 + 55 / Math.max(1e-9, Math.min((w - 190) / spanx, (h - 70) / spany));
  view.scale = Math.min((w - 190) / spanx, (h - 70) / spany);
  return true;
}

function drawMap() {
  const canvas = $('map');
  const { ctx, w, h } = sizeCanvas(canvas);
  const any = view.fit ? fitView(w, h) : true;
  const X = (x) => w / 2 + (x - view.cx) * view.scale;
  const Y = (y) => h / 2 - (y - view.cy) * view.scale;
  ctx.clearRect(0, 0, w, h);
  // The grid, every "nice" number of metres.
  const step = niceStep(90 / view.scale);
  ctx.strokeStyle = '#cfdde6';
  ctx.lineWidth = 1;
  ctx.fillStyle = '#6b8596';
  ctx.font = '11px system-ui, sans-serif';
  const x0 = view.cx - w / 2 / view.scale, x1 = view.cx + w / 2 / view.scale;
  const y0 = view.cy - h / 2 / view.scale, y1 = view.cy + h / 2 / view.scale;
  ctx.beginPath();
  for (let x = Math.ceil(x0 / step) * step; x <= x1; x += step) { ctx.moveTo(X(x), 0); ctx.lineTo(X(x), h); }
  for (let y = Math.ceil(y0 / step) * step; y <= y1; y += step) { ctx.moveTo(0, Y(y)); ctx.lineTo(w, Y(y)); }
  ctx.stroke();
  for (let x = Math.ceil(x0 / step) * step; x <= x1; x += step) ctx.fillText(`${Math.round(x)}`, X(x) + 2, h - 4);
  for (let y = Math.ceil(y0 / step) * step; y <= y1; y += step) ctx.fillText(`${Math.round(y)}`, 2, Y(y) - 2);
  // The origin.
  ctx.strokeStyle = '#8aa3b3';
  ctx.beginPath(); ctx.moveTo(X(0) - 6, Y(0)); ctx.lineTo(X(0) + 6, Y(0)); ctx.moveTo(X(0), Y(0) - 6); ctx.lineTo(X(0), Y(0) + 6); ctx.stroke();
  // North arrow and scale bar.
  ctx.fillStyle = '#33505f';
  ctx.beginPath(); ctx.moveTo(w - 20, 44); ctx.lineTo(w - 26, 60); ctx.lineTo(w - 14, 60); ctx.closePath(); ctx.fill();
  ctx.fillText('N', w - 24, 74);
  const bar = step * view.scale;
  ctx.fillRect(48, h - 28, bar, 3);
  ctx.fillText(step >= 1000 ? `${step / 1000} km` : `${step} m`, 48, h - 32);
  // Tracks, then the last positions with their names and ages.
  const names = [...S.nodes.keys()].sort();
  for (const name of names) {
    const n = S.nodes.get(name);
    const track = n.track || [];
    if (!track.length) continue;
    const color = colorOf(name);
    ctx.strokeStyle = color;
    ctx.globalAlpha = 0.75;
    ctx.lineWidth = 2;
    ctx.beginPath();
    track.forEach((p, i) => (i ? ctx.lineTo(X(p.x), Y(p.y)) : ctx.moveTo(X(p.x), Y(p.y))));
    ctx.stroke();
    ctx.globalAlpha = 1;
    for (const p of track.slice(0, -1)) { ctx.fillStyle = color; ctx.fillRect(X(p.x) - 1.5, Y(p.y) - 1.5, 3, 3); }
    const last = track[track.length - 1];
    // A gateway is a disc; a node heard only over the link, a ring.
    ctx.beginPath(); ctx.arc(X(last.x), Y(last.y), name === S.picked ? 8 : 6, 0, 2 * Math.PI);
    if (n.bridged) {
      ctx.fillStyle = color; ctx.fill();
      ctx.strokeStyle = '#fff'; ctx.lineWidth = 2; ctx.stroke();
    } else {
      ctx.fillStyle = '#fff'; ctx.fill();
      ctx.strokeStyle = color; ctx.lineWidth = 3; ctx.stroke();
    }
    ctx.fillStyle = '#10222e';
    ctx.font = '600 12px system-ui, sans-serif';
    ctx.fillText(name, X(last.x) + 10, Y(last.y) - 2);
    ctx.font = '11px system-ui, sans-serif';
    ctx.fillStyle = '#4c6473';
    ctx.fillText(`heard ${age(n.last_heard)} ago`, X(last.x) + 10, Y(last.y) + 12);
  }
  const placed = names.filter((k) => (S.nodes.get(k).track || []).length).length;
  const o = S.origin;
  $('map-note').textContent = `${placed} of ${S.nodes.size} nodes placed; metres east/north of ` +
    (o ? `${o.lat.toFixed(5)}, ${o.lon.toFixed(5)}${o.given ? '' : ' (first fix)'}` : 'the local origin');
  if (!any) {
    ctx.fillStyle = '#6b8596';
    ctx.font = '13px system-ui, sans-serif';
    ctx.fillText('No position reported yet (messages with x/y or lat/lon fields place their senders).', 14, 22);
  }
  goby.map = { placed, nodes: S.nodes.size, scale: view.scale };
}

function mapSetup() {
  const canvas = $('map');
  let drag = null;
  canvas.addEventListener('pointerdown', (e) => { drag = { x: e.clientX, y: e.clientY, moved: false }; canvas.setPointerCapture(e.pointerId); });
  canvas.addEventListener('pointermove', (e) => {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    if (Math.abs(dx) + Math.abs(dy) > 3) drag.moved = true;
    if (!drag.moved) return;
    view.fit = false;
    view.cx -= dx / view.scale; view.cy += dy / view.scale;
    drag.x = e.clientX; drag.y = e.clientY;
    schedule();
  });
  canvas.addEventListener('pointerup', (e) => {
    if (drag && !drag.moved) {
      // A click picks the nearest node within 20 px.
      const r = canvas.getBoundingClientRect();
      const px = e.clientX - r.left, py = e.clientY - r.top;
      let best = null, bestD = 20;
      for (const n of S.nodes.values()) {
        const p = (n.track || [])[n.track.length - 1];
        if (!p) continue;
        const d = Math.hypot(r.width / 2 + (p.x - view.cx) * view.scale - px, r.height / 2 - (p.y - view.cy) * view.scale - py);
        if (d < bestD) { best = n.name; bestD = d; }
      }
      if (best) pick(best);
    }
    drag = null;
  });
  canvas.addEventListener('wheel', (e) => { e.preventDefault(); zoom(e.deltaY < 0 ? 1.25 : 0.8); }, { passive: false });
  $('zoom-in').onclick = () => zoom(1.5);
  $('zoom-out').onclick = () => zoom(1 / 1.5);
  $('zoom-fit').onclick = () => { view.fit = true; schedule(); };
  window.addEventListener('resize', schedule);
}
function zoom(f) { view.fit = false; view.scale *= f; schedule(); }

// A time plot: each series [[t, v], ...] against the same time axis.
function plot(canvas, series, empty) {
  const { ctx, w, h } = sizeCanvas(canvas);
  ctx.clearRect(0, 0, w, h);
  const pts = series.flatMap((s) => s.points);
  ctx.font = '11px system-ui, sans-serif';
  if (!pts.length) {
    ctx.fillStyle = '#7b8d99';
    ctx.fillText(empty, 8, h / 2);
    return;
  }
  let t0 = Math.min(...pts.map((p) => p[0])), t1 = Math.max(...pts.map((p) => p[0]));
  let v0 = Math.min(...pts.map((p) => p[1])), v1 = Math.max(...pts.map((p) => p[1]));
  if (t1 - t0 < 10) { t0 -= 5; t1 += 5; }
  if (v1 - v0 < 1e-9) { v0 -= 1; v1 += 1; }
  const pad = (v1 - v0) * 0.1; v0 -= pad; v1 += pad;
  const L = 38, R = 8, T = 8, B = 16;
  const X = (t) => L + (t - t0) / (t1 - t0) * (w - L - R);
  const Y = (v) => T + (1 - (v - v0) / (v1 - v0)) * (h - T - B);
  ctx.strokeStyle = '#d8dee4';
  ctx.strokeRect(L, T, w - L - R, h - T - B);
  ctx.fillStyle = '#6b8596';
  ctx.fillText(v1.toFixed(1), 2, T + 8);
  ctx.fillText(v0.toFixed(1), 2, h - B);
  ctx.fillText(clock(t0), L, h - 3);
  const end = clock(t1);
  ctx.fillText(end, w - R - ctx.measureText(end).width, h - 3);
  series.forEach((s, i) => {
    ctx.strokeStyle = s.color; ctx.fillStyle = s.color; ctx.lineWidth = 1.5;
    ctx.beginPath();
    s.points.forEach((p, j) => (j ? ctx.lineTo(X(p[0]), Y(p[1])) : ctx.moveTo(X(p[0]), Y(p[1]))));
    ctx.stroke();
    for (const p of s.points) ctx.fillRect(X(p[0]) - 2, Y(p[1]) - 2, 4, 4);
    ctx.fillText(s.name, L + 6 + i * 70, T + 11);
  });
}

function series(links, key) {
  return links.filter((l) => l[key] !== undefined && l[key] !== null).map((l) => [l.t, l[key]]);
}

// The node's last link forecast (gobyd's `forecast` section): the depth it
// recommends in its band, and per peer the range, SNR and frame-error rate.
function forecastText(f) {
  if (!f) return '—';
  const b = f.band;
  const depth = b && b.recommended !== null && b.recommended !== undefined
    ? `go to ${fmt(b.recommended)} m (rate ${b.rate}, to ${b.peer})` : 'no depth';
  const peers = (f.peers || []).map((p) => {
    const fer = (p.rates || []).map((r) => `r${r.rate} ${r.fer.toFixed(2)}`).join(' ');
    const snr = p.snr === null || p.snr === undefined ? 'not reached' : `SNR ${p.snr.toFixed(1)} dB`;
    return `${p.node}: ${fmt(p.range)} m, ${snr}, FER ${fer}`;
  });
  return [depth, ...peers].join('; ') + ` (${age(f.forecast)} ago${f.error ? '; ' + f.error : ''})`;
}

function renderDetail() {
  const n = S.picked && S.nodes.get(S.picked);
  $('detail-name').textContent = n ? n.name : '—';
  const box = $('detail');
  if (!n) {
    box.className = 'muted';
    box.textContent = 'Pick a node in the table or on the map.';
    for (const id of ['plot-snr', 'plot-doppler', 'plot-frames']) plot($(id), [], '');
    return;
  }
  box.className = '';
  const p = n.position;
  const l = n.link;
  const kv = el('dl', { class: 'kv' });
  const row = (k, v) => kv.append(el('dt', null, k), el('dd', null, v));
  row('modem id', n.modem_id ?? '—');
  row('bridge', n.bridged ? `${n.online === false ? 'down' : 'up'}, ${n.reconnects || 0} reconnections, ${n.dropped || 0} dropped` : 'heard over the link only');
  row('driver', n.driver ? `${n.driver}${n.driver_detail ? ': ' + n.driver_detail : ''}` : '—');
  row('last heard', n.last_heard ? `${age(n.last_heard)} ago (${clock(n.last_heard)})` : '—');
  row('position', p ? `${fmt(p.x)} m E, ${fmt(p.y)} m N` + (p.lat !== null && p.lat !== undefined ? ` (${p.lat.toFixed(5)}, ${p.lon.toFixed(5)})` : '') +
    (p.depth !== null && p.depth !== undefined ? `, ${fmt(p.depth)} m deep` : '') + `, ${age(p.t)} ago by ${short(p.via)}` : '—');
  row('last reception', l ? `from ${l.src} at rate ${l.rate}, ${l.frames} frame(s), ${age(l.t)} ago` : '—');
  row('messages', `${n.received || 0} received, ${n.accepted || 0} queued from tx, ${n.acks || 0} acked, ${n.expires || 0} expired, ${n.drops || 0} dropped, ${n.errors || 0} refused`);
  const queues = Object.entries(n.queues || {});
  row('queues', queues.length ? queues.map(([t, s]) => `${short(t)}: ${s}`).join(', ') : '—');
  row('link forecast', forecastText(n.forecast));
  box.replaceChildren(kv);
  const links = n.links || [];
  const none = 'no Micro-Modem statistics in this node\'s receptions';
  plot($('plot-snr'), [
    { name: 'in', color: '#1f77b4', points: series(links, 'snr_in') },
    { name: 'out', color: '#d62728', points: series(links, 'snr_out') },
    { name: 'rss', color: '#2ca02c', points: series(links, 'snr_rss') },
  ], none);
  plot($('plot-doppler'), [{ name: 'doppler', color: '#9467bd', points: series(links, 'doppler') }], none);
  plot($('plot-frames'), [
    { name: 'frames', color: '#1f6f9a', points: series(links, 'frames') },
    { name: 'bad', color: '#b3261e', points: series(links, 'bad_frames') },
  ], 'no reception yet');
}

// ---------------------------------------------------------- medium access

// The picked node's medium access (its `mac`: the cycle, the MAC of its
// switcher running, the last rate chosen from the link), and the outcome
// of the last MAC request sent from the page.
const SLOT_COLORS = ['#7f7f7f', '#1f77b4', '#d62728', '#2ca02c', '#9467bd', '#ff7f0e', '#17becf', '#8c564b', '#e377c2', '#bcbd22'];
let macSent = null;   // { id, node } of the last MAC request sent

function slotText(s) {
  const dest = s.dest === 0 ? 'all' : s.dest === -1 ? 'queue' : s.dest;
  return `${s.src}→${dest} r${s.rate}`;
}

function macActiveText(a) {
  if (!a) return 'no MAC switcher heard of';
  const why = [a.reason, a.from ? `from ${a.from}` : ''].filter(Boolean).join(', ');
  const until = a.keep_alive_until ? `, keep-alive until ${clock(a.keep_alive_until)} (in ${Math.max(0, Math.round(a.keep_alive_until - now()))} s)` : '';
  const macs = a.macs && a.macs.length ? `; MACs ${a.macs.join(', ')}${a.default_mac ? ', default ' + a.default_mac : ''}` : '';
  return `${a.name}${why ? ' (' + why + ')' : ''}${until}${macs}${a.error ? '; refused: ' + a.error : ''}`;
}

function macCycleView(c) {
  const bar = el('div', { class: 'mac-bar' + (c.running ? '' : ' stopped'), id: 'mac-bar', title: 'the cycle, each slot as wide as it is long' });
  c.slots.forEach((s, i) => bar.append(el('div', {
    style: `flex:${Math.max(s.seconds, 0.01)};background:${SLOT_COLORS[Math.abs(s.src) % SLOT_COLORS.length]}`,
    title: `slot ${i}: ${slotText(s)}, ${fmt(s.seconds)} s, ${s.type}`,
  }, slotText(s))));
  const types = c.slots.some((s) => s.packet_types.length);
  const head = ['#', 'src', 'dest', 'rate', 's', 'type'].concat(types ? ['packet types'] : [], ['']);
  const table = el('table', { id: 'mac-cycle' }, el('thead', null, el('tr', null, ...head.map((h) => el('th', null, h)))));
  const body = el('tbody');
  c.slots.forEach((s, i) => body.append(el('tr', null,
    el('td', { class: 'num' }, i), el('td', { class: 'num' }, s.src), el('td', { class: 'num' }, s.dest),
    el('td', { class: 'num' }, s.rate), el('td', { class: 'num' }, fmt(s.seconds)), el('td', null, s.type),
    types ? el('td', null, s.packet_types.map(short).join(', ') || 'any') : null,
    el('td', null, [s.shared ? 'shared' : '', s.adaptive_rate ? 'adaptive rate' : ''].filter(Boolean).join(', ')))));
  table.append(body);
  return [bar, table];
}

function renderMac() {
  const n = S.picked && S.nodes.get(S.picked);
  $('mac-name').textContent = n ? n.name : '—';
  const box = $('mac-view');
  const said = $('mac-said');
  if (macSent) {
    const c = S.commands.get(macSent.id);
    if (c && c.state !== 'published') {
      said.textContent = `${c.type} to ${c.node}: ${c.state}${c.note ? ': ' + c.note : ''}`;
      said.className = c.state === 'applied' ? 'good' : 'bad';
    }
  }
  if (!n) { box.className = 'muted'; box.textContent = 'Pick a node in the table or on the map.'; return; }
  box.className = '';
  const mac = n.mac || {};
  const c = mac.cycle;
  const kv = el('dl', { class: 'kv' });
  const row = (k, v) => kv.append(el('dt', null, k), el('dd', null, v));
  row('MAC running', macActiveText(mac.active));
  row('cycle', c ? `${c.slots.length} slot${c.slots.length === 1 ? '' : 's'}, ${fmt(c.seconds)} s, ${c.running ? 'running' : 'stopped'}` +
    (c.update ? `; last ${c.update.update_type || 'update'} from ${c.from}` : c.from ? ` (${c.from})` : '') +
    (c.time ? `, ${age(c.time)} ago` : '') + (c.error ? `; refused: ${c.error}` : '') : 'not heard yet');
  const r = mac.rate;
  if (r) row('rate chosen', `${r.rate} for ${r.dest} in slot ${r.slot_index} (${r.reason}${r.snr !== null && r.snr !== undefined ? `, SNR ${fmt(r.snr)} dB` : ''}${r.slot_limited ? ', limited by the slot' : ''})`);
  box.replaceChildren(kv, ...(c ? macCycleView(c) : []));
  const names = (mac.active && mac.active.macs) || [];
  const list = $('mac-names');
  if ([...list.options].map((o) => o.value).join() !== names.join()) list.replaceChildren(...names.map((m) => el('option', { value: m })));
}

// A number when the text is one, else the text itself (the server says
// what is wrong with it).
function numberOr(text) {
  const t = text.trim();
  const x = Number(t);
  return t !== '' && Number.isFinite(x) ? x : t;
}

// `SRC DEST RATE SECONDS [TYPE]` a line: the slots of a MACUpdate.
function slotsOf(text) {
  return text.split('\n').map((l) => l.trim()).filter(Boolean).map((l) => {
    const [src, dest, rate, seconds, type] = l.split(/[\s,]+/);
    const slot = {};
    if (src !== undefined) slot.src = numberOr(src);
    if (dest !== undefined) slot.dest = numberOr(dest);
    if (rate !== undefined) slot.rate = numberOr(rate);
    if (seconds !== undefined) slot.slot_seconds = numberOr(seconds);
    if (type !== undefined) slot.type = type;
    return slot;
  });
}

const WITH_SLOTS = ['ASSIGN', 'PUSH_BACK', 'PUSH_FRONT', 'INSERT'];
const WITH_INDEX = ['INSERT', 'ERASE'];

// The body of `POST /api/mac` the form says.
function macDraft() {
  const node = S.picked;
  const kind = $('mac-kind').value;
  if (kind === 'SWITCH') {
    const sw = { mac: $('mac-switch').value.trim() };
    if ($('mac-keep').value.trim() !== '') sw.keep_alive_seconds = numberOr($('mac-keep').value);
    return { node, switch: sw };
  }
  const update = { update_type: kind };
  if (WITH_SLOTS.includes(kind)) update.slot = slotsOf($('mac-slots').value);
  if (WITH_INDEX.includes(kind)) {
    update.first_iterator = numberOr($('mac-first').value);
    update.second_iterator = numberOr($('mac-second').value);
  }
  if ($('mac-state').value) update.cycle_state = $('mac-state').value;
  return { node, update };
}

function showMacRows() {
  const kind = $('mac-kind').value;
  $('mac-slots-row').hidden = !WITH_SLOTS.includes(kind);
  $('mac-index-row').hidden = !WITH_INDEX.includes(kind);
  $('mac-switch-row').hidden = kind !== 'SWITCH';
  $('mac-state').parentElement.hidden = kind === 'SWITCH';
}

async function sendMac(e) {
  e.preventDefault();
  const said = $('mac-said');
  said.className = 'muted';
  const d = macDraft();
  if (!d.node) { said.textContent = 'Pick a node first.'; return; }
  try {
    const r = await fetch('/api/mac', { method: 'POST', headers: { 'content-type': 'application/json' }, body: JSON.stringify(d) });
    const answer = (r.headers.get('content-type') || '').includes('json') ? await r.json() : { error: await r.text() };
    if (answer.error) {
      said.textContent = `Not sent: ${answer.error}`;
      said.className = 'bad';
    } else {
      macSent = { id: answer.command, node: d.node };
      said.textContent = `Command ${answer.command} sent to ${d.node}; waiting for its answer.`;
    }
    goby.lastMac = answer;
  } catch (err) {
    said.textContent = `Not sent: ${err}`;
    said.className = 'bad';
    goby.lastMac = { error: String(err) };
  }
  schedule();
}

// ---------------------------------------------------------------- messages

function flatten(v, prefix, out) {
  if (v && typeof v === 'object' && !Array.isArray(v)) {
    for (const [k, x] of Object.entries(v)) flatten(x, prefix ? `${prefix}.${k}` : k, out);
  } else if (Array.isArray(v)) {
    if (!v.length) out.push([prefix, '[]']);
    v.forEach((x, i) => flatten(x, `${prefix}[${i}]`, out));
  } else {
    out.push([prefix, typeof v === 'string' ? v : JSON.stringify(v)]);
  }
  return out;
}

function messageRow(m, fresh) {
  let what = m.kind;
  let route = '';
  if (m.kind === 'rx') route = `${m.src}→${m.dest}`;
  if (m.kind === 'ack') route = `by ${m.by}`;
  if (m.kind === 'accepted') route = `id ${m.id ?? '—'}`;
  const fields = m.kind === 'error' ? el('span', null, `${m.error} (${m.topic})`) :
    flatten(m.msg, '', []).map(([k, v]) => el('span', null, el('b', null, `${k}: `), v));
  return el('tr', { 'data-seq': m.seq, class: fresh ? 'fresh' : '' },
    el('td', null, clock(m.time)),
    el('td', null, m.node),
    el('td', { class: `kind-${m.kind}` }, what),
    el('td', { title: m.type || '' }, short(m.type)),
    el('td', null, route),
    el('td', { class: 'fields' }, ...[].concat(fields)));
}

function shownHere(m) {
  return !$('msg-selected').checked || !S.picked || m.node === S.picked;
}

function addMessageRow(m, fresh) {
  freshRows.push(m.seq);
  if (!shownHere(m)) return;
  const body = $('messages').tBodies[0];
  body.prepend(messageRow(m, fresh));
  while (body.rows.length > 500) body.deleteRow(-1);
}

function renderMessages() {
  const body = $('messages').tBodies[0];
  body.replaceChildren();
  const shown = S.messages.filter(shownHere).slice(-500).reverse();
  for (const m of shown) body.append(messageRow(m, false));
  const at = Date.now();
  for (const m of S.messages) if (!(m.seq in goby.shownAt)) goby.shownAt[m.seq] = at;
}

// ---------------------------------------------------------------- commander

function renderCommands() {
  const body = $('commands').tBodies[0];
  body.replaceChildren();
  const all = [...S.commands.values()].sort((a, b) => b.id - a.id).slice(0, 50);
  for (const c of all) {
    body.append(el('tr', { 'data-command': c.id },
      el('td', { class: 'num' }, c.id),
      el('td', null, c.node),
      el('td', { title: c.type }, short(c.type)),
      el('td', { class: `state-${c.state}` }, c.state),
      el('td', null, [c.journal_id !== null && c.journal_id !== undefined ? `id ${c.journal_id}` : '', c.note].filter(Boolean).join(', ')),
      el('td', null, clock(c.sent))));
  }
}

function updateNodeChoices() {
  const sel = $('cmd-node');
  const names = [...S.nodes.values()].filter((n) => n.bridged).map((n) => n.name).sort();
  const have = [...sel.options].map((o) => o.value);
  if (names.join('\n') === have.join('\n')) return;
  const was = sel.value;
  sel.replaceChildren(...names.map((n) => el('option', { value: n }, n)));
  if (names.includes(was)) sel.value = was;
}

// An editor for one field: { el, get() } where get() is the field's
// proto3 JSON value, or undefined when unset.
function hintOf(f) {
  const parts = [];
  if (f.min !== undefined || f.max !== undefined) parts.push(`[${f.min ?? '…'}, ${f.max ?? '…'}]`);
  if (f.precision !== undefined && (f.kind === 'double' || f.kind === 'float')) parts.push(`${f.precision} decimal${f.precision === 1 ? '' : 's'}`);
  if (f.resolution !== undefined && f.resolution !== 1) parts.push(`step ${f.resolution}`);
  if (f.max_length !== undefined) parts.push(`≤ ${f.max_length} chars`);
  if (f.max_repeat !== undefined) parts.push(`${f.min_repeat ? f.min_repeat + '–' : '≤ '}${f.max_repeat} items`);
  if (f.in_head) parts.push('in head');
  if (f.codec && f.codec !== 'dccl.default2' && f.codec !== 'dccl.default3' && f.codec !== 'dccl.default4') parts.push(`codec ${f.codec}`);
  if (f.units) parts.push(f.units);
  if (f.static_value) parts.push(`static ${f.static_value}`);
  if (f.omit) parts.push('omitted');
  return parts.join(' · ');
}

function scalarEditor(f, path, onChange, required) {
  let input;
  let get;
  if (f.kind === 'enum') {
    input = el('select', { 'data-path': path, onchange: onChange });
    if (!required) input.append(el('option', { value: '' }, '(unset)'));
    for (const v of f.enum) input.append(el('option', { value: v.name }, `${v.name} (${v.number})`));
    if (f.default !== undefined) input.value = f.default;
    get = () => (input.value === '' ? undefined : input.value);
  } else if (f.kind === 'bool') {
    input = el('select', { 'data-path': path, onchange: onChange });
    if (!required) input.append(el('option', { value: '' }, '(unset)'));
    input.append(el('option', { value: 'false' }, 'false'), el('option', { value: 'true' }, 'true'));
    if (f.default !== undefined) input.value = String(f.default);
    get = () => (input.value === '' ? undefined : input.value === 'true');
  } else if (f.kind === 'string' || f.kind === 'bytes') {
    input = el('input', { type: 'text', 'data-path': path, oninput: onChange, placeholder: f.kind === 'bytes' ? 'base64' : '' });
    if (f.default !== undefined) input.value = f.default;
    get = () => (input.value === '' && !required ? undefined : input.value);
  } else {
    const numeric = f.kind === 'double' || f.kind === 'float';
    const step = numeric ? (f.precision !== undefined && f.precision >= 0 ? Math.pow(10, -f.precision) : 'any') : (f.resolution || 1);
    input = el('input', { type: 'number', 'data-path': path, step, min: f.min, max: f.max, oninput: onChange });
    if (f.default !== undefined) input.value = f.default;
    get = () => {
      if (input.value === '') return undefined;
      const n = Number(input.value);
      if (Number.isNaN(n)) return input.value;
      return f.int64 ? String(input.value) : n;
    };
  }
  return { el: input, get };
}

function messageEditor(form, path, onChange) {
  const box = el('div', { class: 'message' });
  const parts = [];
  for (const f of form.fields) {
    const p = path ? `${path}.${f.name}` : f.name;
    const ed = fieldEditor(f, p, onChange);
    parts.push([f.name, ed]);
    box.append(ed.el);
  }
  return {
    el: box,
    get: () => {
      const out = {};
      for (const [name, ed] of parts) {
        const v = ed.get();
        if (v !== undefined) out[name] = v;
      }
      return out;
    },
  };
}

function fieldEditor(f, path, onChange) {
  const required = f.label === 'required';
  const name = el('span', { class: 'name' }, f.name, el('span', { class: 'label' }, f.label));
  const hint = el('span', { class: 'hint' }, hintOf(f));
  const note = el('span', { class: 'note', 'data-note': path });
  if (f.label === 'repeated') {
    const list = el('div', { class: 'list' });
    const items = [];
    const max = f.max_repeat ?? Infinity;
    const add = el('button', { type: 'button', 'data-add': path }, '+ add');
    const refresh = () => { add.disabled = items.length >= max; };
    add.onclick = () => {
      const i = items.length;
      const p = `${path}[${i}]`;
      const ed = f.kind === 'message'
        ? (() => { const m = messageEditor(f.message, p, onChange); return { el: el('fieldset', null, el('legend', null, `${f.name}[${i}]`), m.el), get: m.get }; })()
        : scalarEditor(f, p, onChange, true);
      const item = { ed };
      const remove = el('button', { type: 'button', title: 'remove' }, '×');
      item.el = el('div', { class: 'item' }, ed.el, remove);
      remove.onclick = () => { items.splice(items.indexOf(item), 1); item.el.remove(); refresh(); onChange(); };
      items.push(item);
      list.append(item.el);
      refresh();
      onChange();
    };
    refresh();
    return {
      el: el('div', { class: 'field' }, name, el('div', null, list, add, hint, note)),
      get: () => (items.length ? items.map((i) => i.ed.get()) : undefined),
    };
  }
  if (f.kind === 'message') {
    const m = messageEditor(f.message, path, onChange);
    const set = el('fieldset', null, el('legend', null, `${f.name} (${short(f.message.name)})`), m.el);
    if (required) return { el: set, get: m.get };
    const include = el('input', { type: 'checkbox', 'data-include': path });
    m.el.hidden = true;
    include.onchange = () => { m.el.hidden = !include.checked; onChange(); };
    set.querySelector('legend').prepend(include);
    return { el: set, get: () => (include.checked ? m.get() : undefined) };
  }
  const ed = scalarEditor(f, path, onChange, required);
  return { el: el('div', { class: 'field' }, name, el('div', { class: 'value' }, ed.el, hint, note)), get: ed.get };
}

let editor = null;
let checkTimer = null;
let lastCheck = null;
// Whether the user has changed the form since it was drawn: until then a
// check that fails (an empty form's required fields) is not shown as an error.
let touched = false;

function buildForm() {
  const form = S.forms.find((f) => f.name === $('cmd-type').value);
  const box = $('cmd-fields');
  box.replaceChildren();
  editor = null;
  touched = false;
  if (!form) return;
  editor = messageEditor(form, '', () => { touched = true; clearTimeout(checkTimer); checkTimer = setTimeout(check, 150); });
  box.append(editor.el);
  check();
}

function draft() {
  return { node: $('cmd-node').value, type: $('cmd-type').value, msg: editor ? editor.get() : {} };
}
goby.draft = draft;

// Leaf paths where the message as sent and as decoded differ.
function differences(a, b, path, out) {
  if (a && typeof a === 'object' && b && typeof b === 'object') {
    const keys = new Set([...Object.keys(a), ...Object.keys(b)]);
    for (const k of keys) {
      const p = Array.isArray(a) ? `${path}[${k}]` : (path ? `${path}.${k}` : k);
      differences(a[k], b[k], p, out);
    }
  } else if (JSON.stringify(a) !== JSON.stringify(b) && !(typeof a === 'number' && typeof b === 'number' && Math.abs(a - b) < 1e-9)) {
    out.push([path, a, b]);
  }
  return out;
}

async function check() {
  const d = draft();
  const box = $('cmd-check');
  let result;
  try {
    const r = await fetch('/api/check', { method: 'POST', headers: { 'content-type': 'application/json' }, body: JSON.stringify(d) });
    result = await r.json();
  } catch (e) {
    result = { ok: false, error: `the console server did not answer: ${e}` };
  }
  lastCheck = result;
  goby.lastCheck = result;
  goby.checkedDraft = JSON.stringify(d);
  for (const e of document.querySelectorAll('#cmd-fields .changed')) e.classList.remove('changed');
  for (const e of document.querySelectorAll('#cmd-fields [data-note]')) e.textContent = '';
  $('cmd-send').disabled = !result.ok;
  if (!result.ok && !touched) {
    box.className = 'check';
    box.replaceChildren(el('span', { class: 'muted' }, 'Fill in the fields: what the codec makes of them shows here.'));
    return;
  }
  if (!result.ok) {
    box.className = 'check bad';
    box.textContent = `Cannot be encoded: ${result.error}`;
    return;
  }
  const diffs = differences(result.sent, result.back, '', []);
  const changes = result.changes || [];
  const moved = result.moved || [];
  box.className = 'check' + (diffs.length || changes.length || moved.length ? ' changes' : '');
  box.replaceChildren(el('div', null, `${result.bytes} of at most ${result.max_bytes ?? '?'} bytes: ${result.hex}`));
  if (changes.length || moved.length) {
    box.append(el('div', null, 'The codec would change (gobyd refuses such a message unless its type clamps):'),
      el('ul', null, ...changes.map((c) => el('li', null, `${c.field}: ${c.reason}`)), ...moved.map((m) => el('li', null, m))));
  }
  if (diffs.length) {
    box.append(el('div', null, 'The receiver will decode:'),
      el('ul', null, ...diffs.map(([p, a, b]) => el('li', null, `${p}: ${a === undefined ? '(unset)' : JSON.stringify(a)} → ${b === undefined ? '(unset)' : JSON.stringify(b)}`))));
    for (const [p, , b] of diffs) {
      const input = document.querySelector(`#cmd-fields [data-path="${CSS.escape(p)}"]`);
      if (input) input.classList.add('changed');
      const note = document.querySelector(`#cmd-fields [data-note="${CSS.escape(p)}"]`);
      if (note) note.textContent = `→ ${b === undefined ? '(unset)' : JSON.stringify(b)}`;
    }
  } else if (!changes.length && !moved.length) {
    box.append(el('div', null, 'Sent as it is: the receiver decodes these values.'));
  }
}

async function send(e) {
  e.preventDefault();
  const d = draft();
  const said = $('cmd-said');
  if (!d.node) { said.textContent = 'No gateway heard yet to send from.'; return; }
  try {
    const r = await fetch('/api/send', { method: 'POST', headers: { 'content-type': 'application/json' }, body: JSON.stringify(d) });
    const answer = await r.json();
    said.textContent = answer.error ? `Not sent: ${answer.error}` : `Command ${answer.command} published to ${d.node}.`;
    goby.lastSend = answer;
  } catch (err) {
    said.textContent = `Not sent: ${err}`;
    goby.lastSend = { error: String(err) };
  }
}

async function loadForms() {
  const r = await fetch('/api/forms');
  S.forms = await r.json();
  const sel = $('cmd-type');
  sel.replaceChildren(...S.forms.map((f) => el('option', { value: f.name }, f.name)));
  sel.onchange = buildForm;
  buildForm();
}

// ---------------------------------------------------------------- start

mapSetup();
$('commander').addEventListener('submit', send);
$('mac-form').addEventListener('submit', sendMac);
$('mac-kind').addEventListener('change', showMacRows);
showMacRows();
$('msg-selected').addEventListener('change', () => renderMessages());
setInterval(schedule, 1000);   // ages move on
loadForms().catch((e) => goby.errors.push(String(e)));
connect();
