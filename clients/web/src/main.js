// main.js — the fxstream browser client: connects to the daemon it was served from (or
// ?url=ws://…), lists the streams, subscribes to each, and renders every kind in one WebGL2
// canvas split into views: flame particles, the energy-wave billboard, a toon scene lit by
// the wave's light rig, and the compound eye. A lil-gui panel per stream is generated from
// `describe`; a stats overlay per view; operator status (health, streams) in the side bar.
// Query options: url=, flame=pbvr|hdr (the flame's mode; volume by default), rl=N (PBVR's repeat
// passes), grid=COLSxROWS, aa=0 (no multisampling), drawfps=N (draw at most N frames a
// second, e.g. under software WebGL), streams=A,B (show only these streams), views=K,L (only
// these kinds of view: flame, wave, scene, eye), particles=N (draw at most N particles a
// frame of a particle stream: the budget asked of the daemon, budget.js).
// Every view keeps the View contract of view.js (what main.js may call, and when).
import * as THREE from 'three';
import GUI from 'lil-gui';
import { parseHeader } from '../fxs_particles.js';
import { Conn } from './conn.js';
import { StreamPanel } from './panel.js';
import { STATS_HELP, StreamStats } from './stats.js';
import { drawLimit, nextBudget } from './budget.js';
import { FLAME_DEFAULTS, FLAME_MODES, FlameView } from './flame.js';
import { WAVE_DEFAULTS, WaveView } from './wave.js';
import { SceneView } from './scene.js';
import { EyeView } from './eye.js';

const q = new URLSearchParams(location.search);
const wsUrl = q.get('url') || `${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/v1/ws`;
const httpBase = wsUrl.replace(/^ws/, 'http').replace(/\/v1\/ws.*$/, '');
const only = q.get('streams')?.split(',');
const onlyViews = q.get('views')?.split(',');
// Access token (PROTOCOL.md §3.11): ?token= once, then kept for the tab and removed from the
// address bar so it does not stay in the history.
const token = q.get('token') || sessionStorage.getItem('fxstream-token') || '';
if (q.has('token')) {
  sessionStorage.setItem('fxstream-token', token);
  q.delete('token');
  history.replaceState(null, '', `${location.pathname}${q.toString() ? `?${q}` : ''}${location.hash}`);
}
const $ = (id) => document.getElementById(id);

const canvas = $('view');
// The drawing buffer is kept after compositing only in the test bundle (it reads the canvas back).
const renderer = new THREE.WebGLRenderer({ canvas, antialias: q.get('aa') !== '0', stencil: true, preserveDrawingBuffer: !!globalThis.FXS_TEST, powerPreference: 'high-performance' });
renderer.autoClear = false;
renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));

const gui = new GUI({ container: $('panel'), title: 'streams', width: 320 });
// The flame's look (FlameView.settings, shared by every flame view): ?flame=hdr picks the mode.
const flameSettings = { ...FLAME_DEFAULTS, mode: FLAME_MODES.includes(q.get('flame')) ? q.get('flame') : FLAME_DEFAULTS.mode, rl: Number(q.get('rl')) || FLAME_DEFAULTS.rl };
const waveSettings = { ...WAVE_DEFAULTS }; // WaveView.settings, shared by every wave view
const velNote = Object.assign(document.createElement('div'), { className: 'fxs-doc fxs-vel-note' });

// The page's own settings of each effect's views, for its panel: the look folder's and the
// rest ("advanced → display"). They change only this page's picture.
function viewControls(effect) {
  const f = flameSettings, w = waveSettings;
  switch (effect) {
    case 'flame': return {
      look: [
        { obj: f, key: 'mode', choices: FLAME_MODES, label: 'drawn as', doc: 'volume: a continuous glowing body; pbvr: the thesis\'s particle-based volume rendering; hdr: additive sprites' },
        { obj: f, key: 'intensity', min: 0.2, max: 4, step: 0.01, label: 'intensity', doc: 'brightness of the fire' },
        { obj: f, key: 'whiteT', min: 1500, max: 8000, step: 50, label: 'white point (K)', doc: 'the temperature drawn yellow-white: lower it for a hotter-looking fire' },
        { obj: f, key: 'tongues', min: 0, max: 3, step: 0.01, label: 'turbulence (tongues)', doc: 'volume: how much the edge breaks into rising tongues' },
        { obj: f, key: 'smoke', label: 'smoke', doc: 'grey smoke where the gas has cooled' },
        { obj: f, key: 'smokeColor', color: true, label: 'smoke colour' },
      ],
      display: [
        { obj: f, key: 'density', min: 0.2, max: 4, step: 0.01, label: 'volume: density', doc: 'how quickly the fire becomes opaque' },
        { obj: f, key: 'smokeDensity', min: 0, max: 4, step: 0.01, label: 'volume: smoke density' },
        { obj: f, key: 'kernel', min: 2, max: 12, step: 0.5, label: 'volume: kernel (spacings)', doc: 'width of each particle\'s soft kernel, in particle spacings' },
        { obj: f, key: 'rl', min: 1, max: 32, step: 1, label: 'pbvr: repeat passes RL' },
        { obj: f, key: 'threshold', min: 0.05, max: 0.95, step: 0.01, label: 'pbvr: alpha test' },
        { obj: f, key: 'smokeT', min: 300, max: 3000, step: 10, label: 'smoke below T (K)' },
        { obj: f, key: 'velLines', label: 'velocity lines', onChange: velocityLines },
        { obj: f, key: 'velScale', min: 0.001, max: 0.05, step: 0.001, label: 'velocity-line scale (s)' },
        { obj: f, key: 'exposure', min: 0.05, max: 8, step: 0.01, label: 'hdr: exposure' },
      ],
    };
    case 'energy_wave': return {
      look: [{ obj: w, key: 'bloom', min: 0, max: 3, step: 0.01, label: 'bloom', doc: 'glow around the bright core' }],
      display: [
        { obj: w, key: 'exposure', min: 0.1, max: 8, step: 0.01, label: 'exposure' },
        { obj: w, key: 'floor', min: 0, max: 2, step: 0.01, label: 'floor removed (x border B)', doc: 'the field\'s level at the billboard\'s border, taken away so the glow fades to black' },
        { obj: w, key: 'gain', min: 0.1, max: 5, step: 0.01, label: 'level gain' },
        { obj: w, key: 'contrast', min: 1, max: 4, step: 0.01, label: 'contrast (glow falloff)' },
      ],
    };
    default: return { look: [], display: [] };
  }
}

const streams = new Map(); // name -> {name, effect, channel, params, rev, views, panel, stats, error}
const byChannel = new Map();
const schemas = new Map(); // effect -> describe reply
let views = []; // in display order
const labels = new Map(); // view -> div

function setState(s, detail) {
  const el = $('conn');
  el.textContent = detail ? `${s} (${detail})` : s;
  el.className = `state-${s}`;
  document.body.dataset.conn = s;
}

const conn = new Conn(wsUrl, { onOpen: setup, onEvent, onFrame, onState: setState, token });

async function describe(effect) {
  if (!schemas.has(effect)) schemas.set(effect, await conn.request('describe', { effect }));
  return schemas.get(effect);
}

function makeViews(st) {
  let vs = [];
  switch (st.effect) {
    case 'flame': {
      const v = new FlameView(st.name);
      v.settings = flameSettings;
      vs = [v];
      break;
    }
    case 'energy_wave': {
      const w = new WaveView(st.name);
      w.settings = waveSettings;
      vs = [w, new SceneView(st.name, w)];
      break;
    }
    case 'compound_eye': vs = [new EyeView(st.name)]; break;
    default: break;
  }
  // Every 3D view turns, zooms and pans with the mouse over it (orbit.js); the wave is a texture.
  for (const v of vs) v.attachControls?.(canvas, () => lastLayout.find((e) => e.view === v)?.css ?? null);
  return vs;
}

function rebuildViewList() {
  const order = { flame: 0, wave: 1, scene: 2, eye: 3 };
  views = [...streams.values()].flatMap((s) => s.views).filter((v) => !onlyViews || onlyViews.includes(v.kind))
    .sort((a, b) => order[a.kind] - order[b.kind]);
  for (const [v, el] of labels) if (!views.includes(v)) { el.remove(); labels.delete(v); }
  for (const v of views) if (!labels.has(v)) {
    const el = document.createElement('div');
    el.className = 'label';
    el.dataset.view = `${v.stream}:${v.kind}`;
    $('labels').appendChild(el);
    labels.set(v, el);
  }
}

function applyParams(st, params, rev) {
  st.params = params;
  st.rev = rev;
  for (const v of st.views) v.setParams(params);
  if (st.effect === 'flame') velocityNote();
}

// Velocity lines need the flame stream's velocities (its `velocities` parameter, off by
// default so frames cost no more). Turning the lines on sets it on every shown flame stream
// that lacks it, when this page's role may `set` (tune, admin); otherwise the note says who
// can. Turning them off sets it back on the streams this page turned it on for.
const velTurnedOn = new Set(); // flame streams whose velocities this page switched on
const velPending = new Set();  // ... and whose set is in flight
let velError = '';             // the last refused set
function velocityLines(on) {
  velError = '';
  for (const st of streams.values()) {
    if (st.effect !== 'flame' || !st.params) continue;
    const want = on ? true : velTurnedOn.has(st.name) ? false : null;
    if (want === null || st.params.velocities === want || !conn.canTune()) continue;
    if (on) velTurnedOn.add(st.name); else velTurnedOn.delete(st.name);
    velPending.add(st.name);
    conn.request('set', { stream: st.name, params: { velocities: want } })
      .then((m) => { applyParams(st, m.params, m.rev); st.panel?.update(m.params, m.rev); },
        (e) => { velError = `${st.name}: ${e.code}: ${e.message}`; })
      .finally(() => { velPending.delete(st.name); velocityNote(); });
  }
  velocityNote();
}

function velocityNote() {
  const without = [...streams.values()].filter((st) => st.effect === 'flame' && st.params && !st.params.velocities);
  const names = without.map((st) => st.name).join(', ');
  if (!without.length) velError = ''; // a refused or late set that has taken effect after all
  velNote.textContent = velError || !flameSettings.velLines || !without.length ? velError
    : without.every((st) => velPending.has(st.name)) ? `turning velocities on for ${names}…`
      : conn.canTune() ? `${names} sends no velocities: set velocities=true in its output folder (or toggle the lines again)`
        : `${names} sends no velocities, and this page's role (${conn.role}) may not change that: ask someone with a ` +
          'tune token to set velocities=true, or open the page with ?token= of one';
  document.body.dataset.velNote = velNote.textContent;
}

async function attach(info) {
  let st = streams.get(info.stream);
  if (st && st.effect !== info.effect) { detach(st); st = null; }
  const schema = await describe(info.effect);
  const got = await conn.request('get', { stream: info.stream });
  if (!st) {
    st = { name: info.stream, effect: info.effect, channel: 0, stats: new StreamStats(), views: [], panel: null, error: '', pending: new Map() };
    st.views = makeViews(st);
    streams.set(st.name, st);
    rebuildViewList();
  }
  applyParams(st, got.params, got.rev);
  const api = {
    set: (partial) => conn.request('set', { stream: st.name, params: partial }).then((m) => { applyParams(st, m.params, m.rev); return m; }),
    request: (op, fields) => conn.request(op, fields),
    applied: (m) => applyParams(st, m.params, m.rev),
  };
  if (st.panel) st.panel.update(st.params, st.rev);
  else {
    st.panel = new StreamPanel(gui, st.name, st.effect, schema, st.params, st.rev, api, viewControls(st.effect));
    if (st.effect === 'flame') st.panel.folder.domElement.querySelector('[data-view="velLines"]')?.after(velNote);
  }
  st.maxFps = START_FPS;
  st.minLat = undefined;
  st.maxParticles = schema.outputs?.some((o) => o.kind === 1) ? particleLimit : undefined;
  const sub = await subscribe(st);
  st.channel = sub.channel;
  byChannel.set(sub.channel, st);
}

function detach(st) {
  for (const v of st.views) v.dispose?.();
  st.panel?.destroy();
  streams.delete(st.name);
  byChannel.delete(st.channel);
  rebuildViewList();
}

// Subscribes to a stream as the page paces it: its rate cap, and its particle budget when it sends
// particles. A daemon that does not offer budgets (cluster mode, PROTOCOL.md §3.13, or an older
// one) refuses the option: the page then goes on without one and says why in the overlay.
async function subscribe(st) {
  const budget = st.maxParticles ? { max_particles: st.maxParticles } : {};
  try {
    return await conn.request('subscribe', { stream: st.name, max_fps: st.maxFps, ...budget });
  } catch (e) {
    if (e.param !== 'max_particles') throw e;
    st.maxParticles = undefined;
    st.budgetNote = `all particles: the daemon offers no budget (${e.message})`;
    return conn.request('subscribe', { stream: st.name, max_fps: st.maxFps });
  }
}

let maxSubscriptions = 16;
function markSubscribed() {
  document.body.dataset.subscribed = [...streams.values()].filter((s) => s.channel).map((s) => s.name).join(',');
}

async function setup(hello) {
  $('device').textContent = hello.device;
  $('server').textContent = hello.server;
  byChannel.clear();
  try {
    const list = await conn.request('list');
    if (only) list.streams = list.streams.filter((s) => only.includes(s.stream));
    const names = new Set(list.streams.map((s) => s.stream));
    for (const st of [...streams.values()]) if (!names.has(st.name)) detach(st);
    maxSubscriptions = hello.limits?.max_subscriptions ?? 16;
    for (const s of list.streams.slice(0, maxSubscriptions)) await attach(s);
    markSubscribed();
  } catch (e) {
    console.warn('setup failed', e);
  }
}

function onEvent(m) {
  if (m.op === 'created' && !m.id) { // made by another connection (PROTOCOL.md §4)
    if ((!only || only.includes(m.stream)) && !streams.has(m.stream) && streams.size < maxSubscriptions)
      attach(m).then(markSubscribed).catch((e) => console.warn('attach failed', e));
  } else if (m.op === 'destroyed' && !m.id) {
    const st = streams.get(m.stream);
    if (st) { detach(st); markSubscribed(); }
  } else if (m.op === 'params') {
    const st = streams.get(m.stream);
    if (!st) return;
    applyParams(st, m.params, m.rev);
    st.panel?.update(m.params, m.rev);
  } else if ((m.op === 'preset_saved' || m.op === 'preset_deleted') && !m.id) { // another panel's preset
    for (const st of streams.values()) if (st.effect === m.effect) st.panel?.refreshPresets();
  } else if (m.op === 'unsubscribed' && m.reason) {
    const st = streams.get(m.stream);
    if (st) detach(st);
  } else if (m.op === 'error' && m.stream) {
    const st = streams.get(m.stream);
    if (st) st.error = m.message;
  }
}

// Latest frame wins on this side too (PROTOCOL.md §8.1): a message only replaces the
// stream's pending frame of its kind; the draw loop decodes the newest one. A page that
// draws slower than frames arrive skips (counted) instead of building a backlog.
function onFrame(buf) {
  let h;
  try { h = parseHeader(buf); } catch { return; }
  const st = byChannel.get(h.channel);
  if (!st) return;
  st.stats.frame(h, buf.byteLength);
  if (h.kind === 1 && h.count) {
    st.fullParticles = h.total || h.count;
    st.bytesPerParticle = buf.byteLength / h.count;
  }
  if (st.pending.has(h.kind)) st.stats.replace();
  st.pending.set(h.kind, { h, buf });
}

function deliver(st) {
  // textures before light rigs, so a rig frame finds its texture
  for (const kind of [...st.pending.keys()].sort()) {
    const { h, buf } = st.pending.get(kind);
    st.pending.delete(kind);
    for (const v of st.views) {
      try {
        const shown = v.onFrame(h, buf); // a promise where the view decodes off the main thread
        if (shown instanceof Promise) shown.catch((e) => { st.error = `frame ${h.seq}: ${e.message}`; });
      } catch (e) { st.error = `frame ${h.seq}: ${e.message}`; }
    }
  }
}

// ---- layout and drawing ------------------------------------------------------------------

function layout() {
  const w = canvas.clientWidth, h = canvas.clientHeight, n = Math.max(1, views.length);
  let cols = Math.ceil(Math.sqrt(n)), rows = Math.ceil(n / cols);
  const g = q.get('grid');
  if (g) [cols, rows] = g.split('x').map(Number);
  return views.map((v, i) => {
    const c = i % cols, r = Math.floor(i / cols);
    const rw = w / cols, rh = h / rows;
    return { view: v, css: { left: c * rw, top: r * rh, w: rw, h: rh }, rect: { x: Math.round(c * rw), y: Math.round(h - (r + 1) * rh), w: Math.round(rw), h: Math.round(rh) } };
  });
}

// Pacing. A browser reads its WebSocket eagerly into its own buffers, so the server's
// "latest frame wins" (TCP back-pressure) never engages when the page itself is the slow
// part: frames would queue in the browser and latency grow without bound. Each
// subscription therefore carries max_fps (re-subscribing only replaces it, PROTOCOL.md
// §3.5), adjusted every 2 s: halved while frames arrive later than the stream's best
// latency + 250 ms, doubled (within 50 ms) or raised by 30% (within 100 ms) up to the
// stream's fps while they are on time; subscriptions start at 2 steps/s. max_fps counts
// stream steps, so an energy wave's light rig comes with its texture. The comparison is
// with the best latency seen, so unsynchronised clocks do not matter. A page drawing under
// 20 frames/s runs about one message task per frame, so there the caps also share the draw
// rate among the messages of all subscribed streams' steps. A particle stream's budget
// (budget.js) moves first: fewer particles before fewer frames.
const START_FPS = 2;
const particleLimit = drawLimit(q.get('particles'));
let rafCount = 0;
setInterval(() => {
  const drawFps = rafCount / 2;
  rafCount = 0;
  if (conn.state !== 'connected') return;
  const messages = [...streams.values()].reduce((a, s) => a + (s.effect === 'energy_wave' && s.params?.light_rig ? 2 : 1), 0);
  for (const st of streams.values()) {
    if (!st.channel || !st.maxFps) continue;
    const lat = st.stats.rate.latency;
    if (!Number.isNaN(lat)) st.minLat = Math.min(st.minLat ?? Infinity, lat);
    const excess = Number.isNaN(lat) ? 0 : lat - st.minLat, top = st.params?.fps ?? 30;
    const budget = st.maxParticles && nextBudget({
      budget: st.maxParticles, limit: particleLimit, full: st.fullParticles, late: excess > 250, onTime: excess < 50,
      atTopRate: st.maxFps >= top, bytesPerSec: st.stats.rate.kBps * 1024, bytesPerParticle: st.bytesPerParticle,
      fps: Math.min(top, st.maxFps), drawFps,
    });
    let cap = st.maxFps;
    if (excess > 250 && !(budget < st.maxParticles)) cap = Math.max(0.5, cap * 0.5);
    else if (excess < 100) cap = Math.min(top, cap * (excess < 50 ? 2 : 1.3));
    if (drawFps < 20) cap = Math.min(cap, Math.max(0.5, drawFps / Math.max(1, messages)));
    if (Math.abs(cap - st.maxFps) < 0.1 * st.maxFps && budget === st.maxParticles) continue;
    st.maxFps = Math.round(cap * 10) / 10;
    st.maxParticles = budget;
    subscribe(st).catch(() => {});
  }
}, 2000);

let lastLayout = [];
const drawCap = Number(q.get('drawfps')) || 0; // frames drawn per second at most (0: every display frame)
let lastDraw = -1e9;
function frame(t) {
  if (drawCap && t - lastDraw < 1000 / drawCap - 2) { requestAnimationFrame(frame); return; }
  lastDraw = t;
  rafCount++;
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (canvas.width !== Math.round(w * renderer.getPixelRatio()) || canvas.height !== Math.round(h * renderer.getPixelRatio())) renderer.setSize(w, h, false);
  renderer.setScissorTest(false);
  renderer.setClearColor(0x05060a, 1);
  renderer.clear(true, true, true);
  for (const st of streams.values()) deliver(st);
  lastLayout = layout();
  const drawnStreams = new Set();
  for (const { view, rect, css } of lastLayout) {
    const v = view;
    renderer.setViewport(rect.x, rect.y, rect.w, rect.h);
    renderer.setScissor(rect.x, rect.y, rect.w, rect.h);
    renderer.setScissorTest(true);
    let drew = false;
    try { drew = v.render(renderer, rect, t / 1000); } catch (e) { const st = streams.get(v.stream); if (st) st.error = `render: ${e.message}`; }
    if (drew) drawnStreams.add(v.stream);
    const el = labels.get(v);
    if (el) Object.assign(el.style, { left: `${css.left}px`, top: `${css.top}px`, width: `${css.w}px` });
  }
  for (const name of drawnStreams) streams.get(name)?.stats.drawn();
  requestAnimationFrame(frame);
}
requestAnimationFrame(frame);

// The flame view's particles, and how many the stream has when the page's budget drew a subset.
function particlesText(info, note) {
  const n = (x) => x.toLocaleString('en-US');
  return info.total > info.count ? `\n${n(info.count)} of ${n(info.total)} particles (budget)` :
    `\n${n(info.count)} particles${note ? ` (${note})` : ''}`;
}

const VIEW_TITLES = { flame: 'flame particles', wave: 'energy wave', scene: 'light rig: toon scene', eye: 'compound eye' };
setInterval(() => {
  for (const st of streams.values()) st.stats.tick(1);
  for (const [v, el] of labels) {
    const st = streams.get(v.stream);
    if (!st) continue;
    const lut = v.kind === 'eye' && st.params?.mode === 'lut';
    el.textContent = `${v.stream} · ${VIEW_TITLES[v.kind]} · rev ${st.rev}\n` +
      `${lut ? st.stats.tableText(v.info().lutRev) : st.stats.text()}${v.kind === 'flame' ? particlesText(v.info(), st.budgetNote) : ''}` +
      `${st.error ? '\n⚠ ' + st.error : ''}`;
    el.title = STATS_HELP;
  }
  const tot = [...streams.values()].reduce((a, s) => ({ fps: a.fps + s.stats.rate.fps, kB: a.kB + s.stats.rate.kBps }), { fps: 0, kB: 0 });
  $('totals').textContent = `${streams.size} streams · ${tot.fps.toFixed(1)} frames/s · ${tot.kB.toFixed(1)} kB/s`;
}, 1000);

// ---- operator status (health and streams, as the status page) ---------------------------

async function health() {
  try {
    const hz = await (await fetch(`${httpBase}/healthz`)).json();
    $('health').textContent = `${hz.status} · v${hz.version} · up ${Math.round(hz.uptime_s)} s · ${hz.connections} connections · ${hz.platform}`;
    const rows = hz.streams.map((s) => `<tr><td>${s.stream}</td><td>${s.effect}</td><td>${s.rev}</td><td>${s.subscribers}</td><td class="err">${s.last_error ? String(s.last_error).replace(/</g, '&lt;') : ''}</td></tr>`);
    $('health-streams').innerHTML = rows.join('');
  } catch {
    $('health').textContent = 'unreachable';
  }
}
setInterval(health, 2000);
health();

// ---- what the browser tests read (clients/web/test/hooks.js; not used by the page) -------

export const app = {
  conn, streams, renderer, flameSettings, waveSettings,
  get views() { return views; },
  get layout() { return lastLayout; },
};
