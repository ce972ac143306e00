// hooks.js — the browser tests' window into the page (tests/integration/web_*_check.mjs): the
// test bundle, dist/app-test.js, is this file; it marks the page as under test (the drawing
// buffer is kept for read-back), runs the page (src/main.js) and puts `window.fxs` on it: the
// streams and their stats, each view's info and pixel samples. The tests serve it in place of
// dist/app.js (web_lib.mjs openPage); the product bundle has none of this.
import './test_mode.js';
import { app } from '../src/main.js';
import { particleDecoderStatus } from '../src/particle_decoder.js';

// The drawn pixels of the first view of `kind` (and `stream`, if given): {entry, w, h, px},
// RGBA rows from the bottom (readPixels), or null when there is no such view.
function viewPixels(kind, stream) {
  const entry = app.layout.find((e) => e.view.kind === kind && (!stream || e.view.stream === stream));
  if (!entry) return null;
  const pr = app.renderer.getPixelRatio(), r = entry.rect;
  const x = Math.round(r.x * pr), y = Math.round(r.y * pr), w = Math.round(r.w * pr), h = Math.round(r.h * pr);
  const gl = app.renderer.getContext(), px = new Uint8Array(w * h * 4);
  gl.bindFramebuffer(gl.FRAMEBUFFER, null);
  gl.readPixels(x, y, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
  return { entry, w, h, px };
}

function sample(kind, stream) {
  const v = viewPixels(kind, stream);
  if (!v) return null;
  const { entry, w, h, px } = v;
  let sr = 0, sg = 0, sb = 0, lit = 0, bright = 0, warm = 0, max = 0;
  const n = w * h;
  for (let i = 0; i < n; i++) {
    const R = px[4 * i], G = px[4 * i + 1], B = px[4 * i + 2];
    sr += R; sg += G; sb += B;
    const l = 0.2126 * R + 0.7152 * G + 0.0722 * B;
    if (l > 24) lit++;
    if (l > 128) bright++;
    if (R > 96 && R >= G && G >= B && R > B + 32) warm++;
    if (l > max) max = l;
  }
  let hash = 0;
  for (let i = 0; i < px.length; i += 97) hash = (hash * 31 + px[i]) >>> 0;
  return { w, h, mean: [sr / n, sg / n, sb / n], lit: lit / n, bright: bright / n, warm: warm / n, max, hash, css: entry.css };
}

// The flame view's look, for the browser test's flame checks: of the flame's pixels brighter than 10%, the
// share with every channel >= 0.98 (blown out), and the mean colour of the lower and upper
// thirds of their rows (hotter = a larger G/R, towards yellow and white), and a hash. Flame
// pixels are warm (R > B) or near white; the stage's bluish grid and grey smoke are not.
function flameLook() {
  const v = viewPixels('flame');
  if (!v) return null;
  const { w, h, px } = v;
  const lit = (R, G, B) => 0.2126 * R + 0.7152 * G + 0.0722 * B > 25.5 && (R > B + 8 || Math.min(R, G, B) >= 200);
  const rows = [];
  let bright = 0, white = 0, hash = 0;
  for (let i = 0; i < w * h; i++) {
    const R = px[4 * i], G = px[4 * i + 1], B = px[4 * i + 2];
    if (!lit(R, G, B)) continue;
    bright++;
    if (R >= 250 && G >= 250 && B >= 250) white++;
    rows.push(Math.floor(i / w));
  }
  for (let i = 0; i < px.length; i += 97) hash = (hash * 31 + px[i]) >>> 0;
  if (!bright) return { bright: 0, white: 0, hash };
  rows.sort((a, b) => a - b); // rows counted from the bottom (readPixels)
  const lo = rows[Math.floor(0.02 * (rows.length - 1))], hi = rows[Math.ceil(0.98 * (rows.length - 1))];
  const third = (a, b) => {
    const m = [0, 0, 0, 0];
    for (let row = a; row < b; row++)
      for (let c = 0; c < w; c++) {
        const i = 4 * (row * w + c), R = px[i], G = px[i + 1], B = px[i + 2];
        if (!lit(R, G, B)) continue;
        m[0] += R; m[1] += G; m[2] += B; m[3]++;
      }
    return m[3] ? { rgb: m.slice(0, 3).map((v) => v / m[3]), gr: m[1] / Math.max(1, m[0]), n: m[3] } : null;
  };
  const t = (hi - lo) / 3;
  return { bright: bright / (w * h), white: white / bright, lower: third(lo, Math.round(lo + t)), upper: third(Math.round(hi - t), hi + 1), hash, rows: [lo, hi, h] };
}

// Drawing many particles (browser tests): the flame view's current frame made into n particles,
// each copied with a jitter inside its spacing, the spacing shrunk by (count / n)^(1/3) as a finer
// stream of the same flame (a smaller h) would have it. From the first call the view takes no
// more of the stream's frames and the page's own loop no longer draws it (flameDrawMs does, and
// flameShow(true) lets the page draw it again, for a screenshot). Returns the view's particle count.
function flameDense(n) {
  const v = app.views.find((x) => x.kind === 'flame');
  if (!v.orig) {
    v.orig = { n: v.count, xyz: v.ipos.array.slice(0, 3 * v.count), temp: v.itemp.array.slice(0, v.count), params: v.params };
    v.onFrame = () => false;
    v.draw = v.render.bind(v);
    flameShow(false);
  }
  const o = v.orig, d = v.frameOf().d * Math.cbrt(o.n / n);
  let seed = 12345;
  const rnd = () => { seed = (Math.imul(seed, 1664525) + 1013904223) >>> 0; return seed / 4294967296 - 0.5; };
  const xyz = new Float32Array(3 * n), temp = new Float32Array(n);
  for (let i = 0; i < n; i++) {
    const j = i % o.n, jit = i < o.n ? 0 : d;
    for (let c = 0; c < 3; c++) xyz[3 * i + c] = o.xyz[3 * j + c] + jit * rnd();
    temp[i] = o.temp[j];
  }
  v.params = { ...o.params, h: o.params.h * Math.cbrt(o.n / n) };
  v.showParticles({ n, xyz, temp, vel: null });
  return v.count;
}

// Whether the page's loop draws the flame view (flameDense stops it: a software renderer takes
// seconds a draw at 200k particles).
function flameShow(on) {
  const v = app.views.find((x) => x.kind === 'flame');
  v.render = on ? v.draw : () => false;
}

// The time one draw of the flame view takes, ms (the median of `draws`, each finished by a pixel
// read); the canvas keeps the last draw until the page's next frame clears it.
function flameDrawMs(draws = 3) {
  const e = app.layout.find((x) => x.view.kind === 'flame'), r = app.renderer, gl = r.getContext(), px = new Uint8Array(4);
  const ms = [];
  for (let k = 0; k < draws; k++) {
    const t0 = performance.now();
    r.setViewport(e.rect.x, e.rect.y, e.rect.w, e.rect.h);
    r.setScissor(e.rect.x, e.rect.y, e.rect.w, e.rect.h);
    r.setScissorTest(true);
    (e.view.draw ?? e.view.render).call(e.view, r, e.rect, 0);
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
    ms.push(performance.now() - t0);
  }
  return ms.sort((a, b) => a - b)[Math.floor((draws - 1) / 2)];
}

const { conn, streams, flameSettings } = app;
window.fxs = {
  conn, streams, get views() { return app.views.map((v) => `${v.stream}:${v.kind}`); }, sample,
  stats: () => Object.fromEntries([...streams.values()].map((s) => [s.name, { rev: s.rev, channel: s.channel, maxFps: s.maxFps, latency: s.stats.rate.latency, frames: s.stats.totalFrames, drawn: s.stats.totalDrawn, kinds: [...s.stats.kindsSeen], skipped: s.stats.skipped, error: s.error }])),
  flame: () => app.views.find((x) => x.kind === 'flame')?.info() ?? null,
  particleDecoder: particleDecoderStatus,
  flameLook,
  flameDense,
  flameDrawMs,
  flameShow,
  flameSettings,
  waveSettings: app.waveSettings,
  scene: (stream) => app.views.find((x) => x.kind === 'scene' && (!stream || x.stream === stream))?.info() ?? null,
  eye: (stream) => app.views.find((x) => x.kind === 'eye' && x.stream === stream)?.info() ?? null,
  wave: (stream) => app.views.find((x) => x.kind === 'wave' && (!stream || x.stream === stream))?.info() ?? null,
};
