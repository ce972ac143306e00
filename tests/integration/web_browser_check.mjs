// web_browser_check.mjs — the browser client in Debian's chromium (headless, software
// WebGL through SwiftShader), driven by playwright-core, against a real fxstreamd on a
// random loopback port that this script starts (and restarts, for the reconnect check).
// Checks: the page loads and subscribes to every default stream; frames arrive and are
// drawn (canvas read back: the flame region bright and warm, the wave billboard lit, the
// toon scene lit with its shadows); a panel slider changes the server's rev and the
// picture; a change made in a second page appears in the first; a server error shows next
// to its field; compound eyes (created here, mode lut and bake) show a lattice of facets
// with pigment, the look-up-table view agrees with the server's bake from the same eye, and
// the lattice follows the client-side density; the flame view alone (decoded in a worker by
// the WebAssembly decoder; volume by default; PBVR not
// blown out, hotter at the base, moving; orbit drag and double-click home; the hdr mode;
// velocity lines: the view toggle turns the stream's velocities on, lines are drawn and
// change the picture, and a view-only page is told instead); the page reconnects after a
// daemon restart.
// Screenshots go to build/artifacts/. Every wait is bounded. Last line: "test_web_browser: N passed, M failed".
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { ART, checker, collectErrors, fxctlAt, launchBrowser, sleep, startDaemon, stopDaemon, until } from './web_lib.mjs';

const LOOK_ONLY = process.argv.includes('--look'); // screenshots only (development)
const checks = checker('test_web_browser');
const check = checks.check;
// Bounded: about 210 s on an idle 2-core machine (SwiftShader renders every view); the limit
// leaves room for a loaded one.
const hardStop = setTimeout(() => { console.log('FAIL overall time limit (420 s)'); finish(1); }, 420000);

const stateDir = mkdtempSync(join(tmpdir(), 'fxs-web-state-'));
const profile = mkdtempSync(join(tmpdir(), 'fxs-web-profile-'));
let daemon = null, ctx = null;

async function finish(code) {
  clearTimeout(hardStop);
  try { await ctx?.close(); } catch { /* ignore */ }
  await stopDaemon(daemon);
  try { rmSync(profile, { recursive: true, force: true }); } catch { /* chromium may still be writing */ }
  rmSync(stateDir, { recursive: true, force: true });
  checks.summary();
  process.exit(code ?? (checks.failed ? 1 : 0));
}

async function healthRev(port, stream) {
  const h = await (await fetch(`http://127.0.0.1:${port}/healthz`)).json();
  return h.streams.find((s) => s.stream === stream)?.rev;
}

// A lil-gui controller of stream S for parameter path P (data-param set by panel.js).
const ctl = (page, stream, path) => page.locator(`[data-stream="${stream}"] [data-param="${path}"]`).first();
async function openFolder(page, stream) { // the stream's folder and its "advanced" folder
  const f = page.locator(`.lil-gui[data-stream="${stream}"]`).first();
  if (await f.evaluate((el) => el.classList.contains('closed'))) await f.locator(':scope > .title').click();
  const adv = f.locator('.lil-gui[data-group="advanced"]').first();
  if (await adv.evaluate((el) => el.classList.contains('closed'))) await adv.locator(':scope > .title').click();
}
async function setNumber(page, stream, path, value) {
  const input = ctl(page, stream, path).locator('input:not(.fxs-log)').first(); // the typed field, not a log slider
  await input.evaluate((el) => { // open the folders around it (lists and vectors start closed)
    const closed = [];
    for (let f = el.parentElement; f; f = f.parentElement) if (f.classList.contains('lil-gui') && f.classList.contains('closed')) closed.push(f);
    for (const f of closed.reverse()) f.querySelector(':scope > .title').click();
  });
  await sleep(600);
  await input.fill(String(value));
  await input.press('Enter');
}

// ---- compound eye (PROTOCOL.md §11.3) ----------------------------------------------------

// Luminance (0-255) of the view of `stream` read back from the canvas (drawn with
// preserveDrawingBuffer), row 0 at the top.
async function grabView(page, stream, kind = 'eye') {
  return page.evaluate(([name, kind]) => {
    const s = window.fxs.sample(kind, name), c = document.getElementById('view'), pr = c.width / c.clientWidth;
    const x = Math.round(s.css.left * pr), y = Math.round(s.css.top * pr), w = Math.round(s.css.w * pr), h = Math.round(s.css.h * pr);
    const g = document.createElement('canvas');
    g.width = w; g.height = h;
    const ctx2 = g.getContext('2d');
    ctx2.drawImage(c, x, y, w, h, 0, 0, w, h);
    const px = ctx2.getImageData(0, 0, w, h).data, lum = new Array(w * h);
    for (let i = 0; i < w * h; i++) lum[i] = Math.round(0.2126 * px[4 * i] + 0.7152 * px[4 * i + 1] + 0.0722 * px[4 * i + 2]);
    return { w, h, lum };
  }, [stream, kind]);
}
// The eye's disc (pixels brighter than the dark background) and a box of half size 0.45 r
// inside it around its centre.
function eyeBox(img) {
  let x0 = img.w, x1 = -1, y0 = img.h, y1 = -1;
  for (let y = 0; y < img.h; y++)
    for (let x = 0; x < img.w; x++)
      if (img.lum[y * img.w + x] > 40) { x0 = Math.min(x0, x); x1 = Math.max(x1, x); y0 = Math.min(y0, y); y1 = Math.max(y1, y); }
  const r = Math.max(0, Math.min(x1 - x0, y1 - y0) / 2), half = Math.floor(0.45 * r);
  return { cx: Math.round((x0 + x1) / 2), cy: Math.round((y0 + y1) / 2), r, half };
}
function boxPixels(img, b) {
  const out = [];
  for (let y = b.cy - b.half; y < b.cy + b.half; y++) for (let x = b.cx - b.half; x < b.cx + b.half; x++) out.push(img.lum[y * img.w + x] ?? 0);
  return out;
}
function boxStats(v) {
  const n = Math.max(1, v.length), mean = v.reduce((a, x) => a + x, 0) / n;
  const std = Math.sqrt(v.reduce((a, x) => a + (x - mean) ** 2, 0) / n);
  return { mean: +mean.toFixed(1), std: +std.toFixed(1), dark: +(v.filter((x) => x < 70).length / n).toFixed(3), pale: +(v.filter((x) => x > 150).length / n).toFixed(3) };
}
// Lattice period: the highest autocorrelation of the derivative (edges: lens borders and
// highlights, without the slow shading and the pupils) past its first zero, along x or y
// (whichever has the clearer peak).
function period(v, side) {
  const along = (at) => { // at(i, j): pixel j of line i
    const d = [];
    for (let i = 0; i < side; i++) for (let j = 0; j + 1 < side; j++) d.push(at(i, j + 1) - at(i, j));
    const n = side - 1, ac = (lag) => {
      let s = 0, s0 = 0;
      for (let i = 0; i < side; i++) for (let j = 0; j + lag < n; j++) { s += d[i * n + j] * d[i * n + j + lag]; s0 += d[i * n + j] ** 2; }
      return s / Math.max(s0, 1e-9);
    };
    let lag = 1;
    while (lag < side / 2 && ac(lag) > 0) lag++;
    let best = { lag: 0, c: -1 };
    for (; lag < side / 2; lag++) { const c = ac(lag); if (c > best.c) best = { lag, c: +c.toFixed(3) }; }
    return best;
  };
  const x = along((i, j) => v[i * side + j]), y = along((i, j) => v[j * side + i]);
  return x.c >= y.c ? { ...x, axis: 'x' } : { ...y, axis: 'y' };
}
function correlation(a, b) {
  const n = a.length, ma = a.reduce((s, x) => s + x, 0) / n, mb = b.reduce((s, x) => s + x, 0) / n;
  let sab = 0, saa = 0, sbb = 0;
  for (let i = 0; i < n; i++) { sab += (a[i] - ma) * (b[i] - mb); saa += (a[i] - ma) ** 2; sbb += (b[i] - mb) ** 2; }
  return +(sab / Math.sqrt(saa * sbb + 1e-9)).toFixed(3);
}
// Both views of the page, the lut view's box applied to both (same camera, same rect size).
async function eyeImages(page) {
  const lut = await grabView(page, 'eyelut'), bake = await grabView(page, 'eyebake'), b = eyeBox(lut);
  const lv = boxPixels(lut, b), bv = boxPixels(bake, b);
  return { box: b, bakeBox: eyeBox(bake), lut: boxStats(lv), bake: boxStats(bv), period: period(lv, 2 * b.half), corr: correlation(lv, bv) };
}

// The dark pseudopupils on an eye view: the disc's pixels darker than 55% of its median,
// counted per block of r/15, blocks at least 30% dark joined 8-connected; groups of >= 3
// blocks are pupils, each with its distance from the disc's centre in radii.
function pupils(img) {
  let x0 = img.w, x1 = -1, y0 = img.h, y1 = -1;
  for (let y = 0; y < img.h; y++) for (let x = 0; x < img.w; x++)
    if (img.lum[y * img.w + x] > 40) { x0 = Math.min(x0, x); x1 = Math.max(x1, x); y0 = Math.min(y0, y); y1 = Math.max(y1, y); }
  const cx = (x0 + x1) / 2, cy = (y0 + y1) / 2, r = Math.min(x1 - x0, y1 - y0) / 2;
  const B = Math.max(3, Math.round(r / 15)), gw = Math.ceil(img.w / B), gh = Math.ceil(img.h / B);
  const inside = [];
  for (let y = 0; y < img.h; y++) for (let x = 0; x < img.w; x++) if (Math.hypot(x - cx, y - cy) < 0.92 * r) inside.push(img.lum[y * img.w + x]);
  inside.sort((a, b) => a - b);
  const med = inside[inside.length >> 1], dark = 0.55 * med;
  const frac = new Float32Array(gw * gh), n = new Float32Array(gw * gh);
  for (let y = 0; y < img.h; y++) for (let x = 0; x < img.w; x++) {
    if (Math.hypot(x - cx, y - cy) >= 0.92 * r) continue;
    const k = Math.floor(y / B) * gw + Math.floor(x / B);
    n[k]++; if (img.lum[y * img.w + x] < dark) frac[k]++;
  }
  for (let k = 0; k < frac.length; k++) frac[k] = n[k] > B * B / 2 ? frac[k] / n[k] : 0;
  const seen = new Int32Array(gw * gh).fill(-1), comps = [];
  for (let k = 0; k < frac.length; k++) {
    if (frac[k] < 0.3 || seen[k] >= 0) continue;
    const stack = [k], c = { n: 0, x: 0, y: 0 }; seen[k] = comps.length;
    while (stack.length) {
      const q = stack.pop(), qx = q % gw, qy = Math.floor(q / gw);
      c.n++; c.x += qx; c.y += qy;
      for (let dy = -1; dy <= 1; dy++) for (let dx = -1; dx <= 1; dx++) {
        const nx = qx + dx, ny = qy + dy, m = ny * gw + nx;
        if (nx < 0 || ny < 0 || nx >= gw || ny >= gh || seen[m] >= 0 || frac[m] < 0.3) continue;
        seen[m] = comps.length; stack.push(m);
      }
    }
    comps.push(c);
  }
  const big = comps.filter((c) => c.n >= 3).map((c) => ({ n: c.n, d: +(Math.hypot((c.x / c.n + 0.5) * B - cx, (c.y / c.n + 0.5) * B - cy) / r).toFixed(2) }));
  return { r: Math.round(r), B, med, all: comps.length, pupils: big };
}

// The default compound eye from the default camera shows the phenomenon: one
// central pseudopupil and the six side pupils of the hexagonal lattice.
async function defaultEyeCheck(ctx, port) {
  const page = await ctx.newPage();
  await page.setViewportSize({ width: 800, height: 560 });
  await page.goto(`http://127.0.0.1:${port}/?streams=eye&grid=1x1&aa=0&drawfps=2`, { timeout: 20000 });
  await until(() => page.evaluate(() => (window.fxs.stats().eye?.drawn ?? 0) > 0), 20000, 300);
  await sleep(1000);
  const p = pupils(await grabView(page, 'eye'));
  await page.screenshot({ path: join(ART, 'web-eye-default.png') });
  const central = p.pupils.filter((q) => q.d < 0.15).length, side = p.pupils.filter((q) => q.d >= 0.4 && q.d < 0.9).length;
  check(central === 1 && side === 6 && p.pupils.length === 7, 'the default eye shows 1 central and 6 side pupils', JSON.stringify(p));
  await page.close();
}

async function eyeChecks(ctx, port, fxctl, url) {
  await defaultEyeCheck(ctx, port);
  // black dots on a pale base, ringless: the checks below tell pupils from lenses by brightness
  const same = ['density=40', 'lattice=square', 'eye=[0.4,0.3,3]', 'light=[0.4,0.6,1]', 'base_color=[0.8,0.78,0.72]',
    'dot_color=[0.02,0.02,0.02]', 'ring_inner=0', 'ring_outer=0'];
  fxctl('create', 'compound_eye', 'eyelut', ...same);
  fxctl('create', 'compound_eye', 'eyebake', 'mode=bake', 'bake_size=512', ...same);
  const page = await ctx.newPage();
  await page.setViewportSize({ width: 1300, height: 560 });
  await page.goto(url.replace('drawfps=1', 'drawfps=2&grid=2x1&streams=eyelut,eyebake'), { timeout: 20000 });
  const sub = await until(() => page.evaluate(() => document.body.dataset.subscribed), 20000);
  check(sub === 'eyelut,eyebake', 'eye page (?streams=) subscribes to the two compound eyes only', String(sub));
  const ready = await until(async () => {
    const s = await page.evaluate(() => [window.fxs.stats(), window.fxs.eye('eyelut'), window.fxs.eye('eyebake')]);
    return s[0].eyelut?.drawn > 0 && s[0].eyebake?.drawn > 0 ? s : null;
  }, 20000, 300);
  const [, li, bi] = ready || [];
  check(li && li.mode === 'lut' && li.lutRev === 1 && li.cells === 32 && li.dirs === 32 && li.atlas === 1088 && li.lattice === 0,
        'a lens table (kind 4) arrives, decodes and is drawn', JSON.stringify(ready));
  check(bi && bi.mode === 'bake' && bi.bake === 512, 'a bake texture (kind 2 EXR) arrives and is drawn', JSON.stringify(bi));
  // The labels' second line is written once a second (main.js): wait for it, not for the
  // label (a loaded CI host read the first line alone within the old 3 s).
  const lensRe = /lens table rev 1 · received \d+ s ago/;
  let eyeLabel = '';
  await until(async () => lensRe.test(eyeLabel = (await page.evaluate(() => document.querySelector('.label[data-view="eyelut:eye"]')?.textContent)) || ''), 8000);
  check(lensRe.test(eyeLabel), 'the lut eye shows its table rev and age, not a dead 0 fps', String(eyeLabel));
  await sleep(1200);
  const sq = await eyeImages(page);
  await page.screenshot({ path: join(ART, 'web-eye.png') });
  console.log('eye square', JSON.stringify(sq));
  check(sq.box.r > 60 && sq.lut.mean > 80, 'lut view: the eye is drawn (a lit disc)', JSON.stringify(sq.box));
  check(sq.lut.std > 15 && sq.lut.dark > 0.02 && sq.lut.pale > 0.2, 'lut view: facets with pigment (dark pupils among pale lenses)', JSON.stringify(sq.lut));
  check(sq.period.c > 0.2 && sq.period.lag >= 6 && sq.period.lag <= 60, 'lut view: a lattice (autocorrelation peak at the lens pitch)', JSON.stringify(sq.period));
  check(sq.bake.mean > 80 && sq.bake.std > 15 && Math.abs(sq.bakeBox.r - sq.box.r) < 0.1 * sq.box.r, 'bake view: the baked texture is on the same model', JSON.stringify({ bake: sq.bake, r: sq.bakeBox.r }));
  check(sq.corr > 0.75, 'lut and bake views agree (same eye, same density): pupils in the same places', `correlation ${sq.corr}`);

  // density is a client uniform in mode lut: no new table, and the lattice pitch halves.
  const framesBefore = (await page.evaluate(() => window.fxs.stats())).eyelut.frames;
  fxctl('set', 'eyelut', 'density=80');
  await until(() => page.evaluate(() => window.fxs.streams.get('eyelut').params.density === 80), 5000);
  await sleep(1200);
  const dense = await eyeImages(page), after = await page.evaluate(() => [window.fxs.stats().eyelut.frames, window.fxs.eye('eyelut').lutRev]);
  const ratio = sq.period.lag / Math.max(1, dense.period.lag);
  check(after[0] === framesBefore && after[1] === 1, 'a density change sends no new table', JSON.stringify(after));
  check(dense.period.c > 0.2 && ratio > 1.6 && ratio < 2.5, 'twice the density halves the lattice pitch on screen', `${sq.period.lag} px -> ${dense.period.lag} px (${JSON.stringify(dense.period)})`);

  // The hexagonal lattice: a new table (new rev), and the views agree again.
  fxctl('set', 'eyelut', 'density=40', 'lattice=hex');
  fxctl('set', 'eyebake', 'lattice=hex');
  const hexReady = await until(async () => {
    const [l, b] = await page.evaluate(() => [window.fxs.eye('eyelut'), window.fxs.eye('eyebake')]);
    return l.lattice === 1 && l.lutRev === 3 && b.bakeRev >= 2 ? [l, b] : null;
  }, 15000, 300);
  check(!!hexReady, 'lattice=hex: a new table with the new param_rev replaces the old one', JSON.stringify(hexReady));
  await sleep(1500);
  const hex = await eyeImages(page);
  await page.screenshot({ path: join(ART, 'web-eye-hex.png') });
  console.log('eye hex', JSON.stringify(hex));
  // (the look-up is a one-texel tent, against speckles, so the pupils are a little soft)
  check(hex.lut.std > 15 && hex.lut.dark > 0.015 && hex.period.c > 0.1, 'hex lut view: facets with pigment', JSON.stringify({ lut: hex.lut, period: hex.period }));
  check(hex.corr > 0.75, 'hex: lut and bake views agree', `correlation ${hex.corr}`);

  // Orbit the lut view with the mouse: the pseudopupils move with the camera and nothing is
  // sent to the server (the look-up table is the point): same rev, no new frame.
  const still = await page.evaluate(() => [window.fxs.stats().eyelut, window.fxs.eye('eyelut').lutRev]);
  const before = await grabView(page, 'eyelut');
  const r = await page.evaluate(() => {
    const s = window.fxs.sample('eye', 'eyelut'), b = document.getElementById('view').getBoundingClientRect();
    return { x: b.left + s.css.left + s.css.w / 2, y: b.top + s.css.top + s.css.h / 2 };
  });
  await page.mouse.move(r.x, r.y);
  await page.mouse.down();
  await page.mouse.move(r.x + 70, r.y + 25, { steps: 2 });
  await page.mouse.up();
  await sleep(1200);
  const turned = await grabView(page, 'eyelut');
  const after2 = await page.evaluate(() => [window.fxs.stats().eyelut, window.fxs.eye('eyelut').lutRev]);
  let diff = 0;
  for (let i = 0; i < before.lum.length; i++) diff += Math.abs(before.lum[i] - turned.lum[i]);
  diff /= before.lum.length;
  check(diff > 4 && after2[0].rev === still[0].rev && after2[0].frames === still[0].frames && after2[1] === still[1],
    'dragging the lut view turns the eye and moves the pseudopupils with no message to the server',
    `mean |change| ${diff.toFixed(1)}, rev ${still[0].rev} -> ${after2[0].rev}, frames ${still[0].frames} -> ${after2[0].frames}`);
  await page.screenshot({ path: join(ART, 'web-eye-orbit.png') });
  await page.close();
  fxctl('destroy', 'eyelut');
  fxctl('destroy', 'eyebake');
}

// The energy wave's glow is a bloom: an isolated torus seen face-on, its radial brightness
// profile outside the ring falls monotonically (no ghost rings, which a glow of a few fixed taps
// draws as copies of the ring around it). Also the screenshot of the wave view.
async function waveChecks(ctx, port, fxctl, main) {
  fxctl('create', 'energy_wave', 'ring', 'tori=[{"center":[0,0,0],"axis":[0,0,1],"R":3,"coef":5.1}]', 'curves=[]',
    'animate=false', 'light_rig=false', 'fps=3');
  // The open page learns of the new stream from the created event (no reload) and shows it.
  const shown = await until(() => main.evaluate(() => window.fxs.views.includes('ring:wave') && document.body.dataset.subscribed.includes('ring')), 10000);
  check(shown, 'a stream created elsewhere appears in an open page', String(await main.evaluate(() => window.fxs.views)));
  const page = await ctx.newPage();
  await page.setViewportSize({ width: 700, height: 420 });
  await page.goto(`http://127.0.0.1:${port}/?streams=ring&grid=1x1&aa=0&drawfps=2`, { timeout: 20000 });
  check(await until(() => page.evaluate(() => (window.fxs.stats().ring?.drawn ?? 0) > 1), 20000, 300), 'torus stream drawn');
  await sleep(800);
  const img = await grabView(page, 'ring', 'wave');
  await page.screenshot({ path: join(ART, 'web-wave-torus.png') });
  const cx = img.w / 2, cy = img.h / 2, rmax = Math.floor(Math.min(img.w, img.h) * 0.45), prof = new Array(rmax).fill(0), cnt = new Array(rmax).fill(0);
  for (let y = 0; y < img.h; y++)
    for (let x = 0; x < img.w; x++) {
      const r = Math.floor(Math.hypot(x + 0.5 - cx, y + 0.5 - cy));
      if (r < rmax) { prof[r] += img.lum[y * img.w + x]; cnt[r]++; }
    }
  for (let r = 0; r < rmax; r++) prof[r] /= Math.max(1, cnt[r]);
  let peak = 0;
  for (let r = 0; r < rmax; r++) if (prof[r] > prof[peak]) peak = r;
  let low = prof[peak], bump = 0, at = -1;
  for (let r = peak + 1; r < rmax; r++) {
    if (prof[r] - low > bump) { bump = prof[r] - low; at = r; }
    low = Math.min(low, prof[r]);
  }
  const profile = prof.filter((_, r) => r % 8 === 0).map((v) => Math.round(v));
  check(prof[peak] > 60 && bump <= 2, 'the torus glow falls off monotonically outside the ring (a bloom, no ghost rings)',
    `ring at ${peak} px (${prof[peak].toFixed(0)}), largest rise outside ${bump.toFixed(1)} at ${at} px; profile every 8 px ${JSON.stringify(profile)}`);
  await page.close();
  fxctl('destroy', 'ring');
  const gone = await until(() => main.evaluate(() => !window.fxs.views.some((v) => v.startsWith('ring:'))), 10000);
  check(gone, 'and disappears when it is destroyed', String(await main.evaluate(() => window.fxs.views)));
}

// ---- the tuning panel ---------------------------------------------------------------------

const serverParams = async (port, stream) => {
  const d = await (await fetch(`http://127.0.0.1:${port}/healthz`)).json(); // (rev only there)
  return d.streams.find((s) => s.stream === stream);
};
const pageParams = (page, stream) => page.evaluate((s) => window.fxs.streams.get(s).params, stream);
const action = (page, stream, a) => page.locator(`.lil-gui[data-stream="${stream}"] [data-action="${a}"]`).first();

// Folders by describe's groups with doc lines shown; typed numbers; ↺ per parameter; the
// presets folder (load a thesis figure, save, a second page sees the save, delete); every
// parameter back to its default.
async function panelChecks(ctx, page, port, url) {
  const groups = await page.evaluate(() => [...document.querySelectorAll('.lil-gui[data-stream="flame"] [data-group]')].map((f) => f.dataset.group));
  check(JSON.stringify(groups) === JSON.stringify(['look', 'presets', 'advanced', 'sources', 'forces', 'combustion', 'diffusion', 'numerics', 'output', 'display']),
    'the flame panel: look, presets, then advanced with a folder per describe group and the display settings', JSON.stringify(groups));
  const doc = await page.evaluate(() => {
    const d = document.querySelector('.lil-gui[data-stream="energy"] [data-param="beta"] + .fxs-doc');
    return d && d.offsetHeight > 0 ? d.textContent : null;
  });
  check(doc && doc.includes('attenuation offset'), 'each parameter shows its doc line (not only a tooltip)', String(doc));
  const logs = await page.evaluate(() => [...document.querySelectorAll('.lil-gui[data-stream="flame"] input.fxs-log')].map((e) => e.closest('[data-param]').dataset.param));
  check(logs.includes('max_particles') && !logs.includes('k_buo'), 'logarithmic sliders where max/min >= 100 (flame: max_particles, not k_buo)', JSON.stringify(logs));

  // ↺: alpha (moved by the slider above) back to its default 1.
  await ctl(page, 'energy', 'alpha').locator('[data-reset="alpha"]').click();
  const alpha = await until(() => page.evaluate(() => window.fxs.streams.get('energy').params.alpha === 1), 10000);
  check(alpha, 'the ↺ button puts one parameter back to its default (alpha 1)');

  // Presets: a thesis figure loads all or nothing over the defaults.
  await action(page, 'energy', 'preset').locator('select').selectOption('thesis-fig5.1');
  check(await action(page, 'energy', 'delete').locator('button').isDisabled(), 'a built-in preset cannot be deleted (button disabled)');
  await action(page, 'energy', 'load').locator('button').click();
  const loaded = await until(async () => { const p = await pageParams(page, 'energy'); return p.tori?.[0]?.R === 0.9 && p.curves.length === 0 ? p : null; }, 10000);
  check(!!loaded && loaded.beta === 1, 'load preset: Fig. 5.1 (a torus with R 0.9) over the defaults (beta back to 1)', JSON.stringify(loaded?.tori));
  const page2 = await ctx.newPage();
  await page2.setViewportSize({ width: 560, height: 420 });
  await page2.goto(url.replace('drawfps=1', 'drawfps=0.5'), { timeout: 20000 });
  await until(() => page2.evaluate(() => document.body.dataset.subscribed?.includes('energy')), 30000);
  await action(page, 'energy', 'name').locator('input').fill('web-look');
  await action(page, 'energy', 'save').locator('button').click();
  const saved = await until(() => page.evaluate(() => document.querySelector('.lil-gui[data-stream="energy"] .fxs-preset-status')?.textContent === 'saved web-look'), 10000);
  check(saved, 'save values as preset: saved (status line)');
  const seen = await until(() => page2.evaluate(() => [...document.querySelectorAll('.lil-gui[data-stream="energy"] [data-action="preset"] option')].some((o) => o.value === 'web-look')), 10000);
  check(seen, 'a second page lists the new preset at once (preset_saved event)');
  await page2.close();
  check(!(await action(page, 'energy', 'delete').locator('button').isDisabled()), 'your own preset can be deleted');
  await action(page, 'energy', 'delete').locator('button').click();
  const deleted = await until(() => page.evaluate(() => ![...document.querySelectorAll('.lil-gui[data-stream="energy"] [data-action="preset"] option')].some((o) => o.value === 'web-look')), 10000);
  check(deleted, 'delete preset removes it from the list');
  await page.locator('.lil-gui[data-stream="energy"]').first().screenshot({ path: join(ART, 'web-panel-presets.png') });

  // Every parameter back to its defaults in one set.
  const rev0 = (await serverParams(port, 'energy')).rev;
  await action(page, 'energy', 'defaults').locator('button').click();
  const back = await until(async () => { const p = await pageParams(page, 'energy'); return p.tori[0]?.R === 3 && p.curves.length === 0 ? p : null; }, 10000);
  check(!!back && (await serverParams(port, 'energy')).rev === rev0 + 1, 'all parameters to defaults: the default torus (R 3), in one set');
}

// The flame view alone: the volume mode by default (its look is test_web_look's); PBVR not blown out (of the flame's pixels
// brighter than 10%, at most 15% have every channel >= 0.98), hotter at the base than at the
// top, moving; the orbit camera turns with a mouse drag and a double-click brings it home;
// the hdr mode keeps the hot core under white too. Screenshots of both modes. Velocity
// lines: the "pbvr: velocity lines" toggle sets the stream's velocities (the page has the
// admin role of a daemon without tokens); frames then carry velocities, line vertices are
// drawn, and on a paused stream (time_scale 0: the same particles every frame) the picture
// with lines differs from the one without and has more lit pixels; toggling off sets
// velocities back.
async function flameChecks(ctx, port, fxctl) {
  const page = await ctx.newPage();
  await page.setViewportSize({ width: 600, height: 400 });
  await page.goto(`http://127.0.0.1:${port}/?streams=flame&grid=1x1&aa=0&drawfps=2&rl=2`, { timeout: 20000 });
  const drawn = () => page.evaluate(() => window.fxs.stats().flame?.drawn ?? 0);
  const nextDraw = async () => { const d = await drawn(); return until(async () => (await drawn()) > d, 8000, 100); };
  // The white share of a flickering flame: the mean of five looks 0.5 s apart. One look ranges
  // 2-17% on the same stream (medians 6-7% over 40 looks), so a single look near the 15% bound
  // would pass or fail by chance.
  const whiteMean = async () => {
    const w = [];
    for (let i = 0; i < 5; i++) {
      const l = await page.evaluate(() => window.fxs.flameLook());
      if (l) w.push(l.white);
      await sleep(500);
    }
    return w.length === 5 ? { mean: w.reduce((s, x) => s + x, 0) / 5, looks: w } : null;
  };
  check(await until(async () => (await drawn()) > 2, 30000, 500), 'flame view: frames drawn');
  const decoder = await page.evaluate(() => window.fxs.particleDecoder());
  check(decoder.engine === 'wasm' && !decoder.error, 'flame frames decoded in a worker by the C decoder as WebAssembly', JSON.stringify(decoder));
  const info = await page.evaluate(() => window.fxs.flame());
  check(info?.mode === 'volume', 'the flame view defaults to the volume mode', JSON.stringify(info));
  await page.evaluate(() => { window.fxs.flameSettings.mode = 'pbvr'; });
  await nextDraw();
  const a = await page.evaluate(() => window.fxs.flameLook());
  await sleep(500);
  await nextDraw();
  const b = await page.evaluate(() => window.fxs.flameLook());
  await page.screenshot({ path: join(ART, 'web-flame-pbvr.png') });
  const aw = await whiteMean();
  check(a && a.bright > 0.01 && aw && aw.mean <= 0.15, 'PBVR: at most 15% of the bright flame pixels are white',
    JSON.stringify({ a, aw }));
  check(a?.lower && a?.upper && a.lower.gr > a.upper.gr, 'PBVR: the lower third is hotter (yellower) than the upper third',
    JSON.stringify([a?.lower, a?.upper]));
  check(a && b && a.hash !== b.hash, 'PBVR: two looks 0.5 s apart differ');
  // Orbit: drag across the view turns the camera; a double-click brings it home.
  const home = info?.cam;
  await page.mouse.move(130, 200);
  await page.mouse.down();
  await page.mouse.move(230, 190, { steps: 2 });
  await page.mouse.up();
  const turned = (await page.evaluate(() => window.fxs.flame()))?.cam;
  const dist = (p, q) => Math.hypot(p[0] - q[0], p[1] - q[1], p[2] - q[2]);
  check(home && turned && dist(home, turned) > 0.05, 'a mouse drag turns the flame camera', JSON.stringify([home, turned]));
  await page.mouse.dblclick(130, 200);
  const back = (await page.evaluate(() => window.fxs.flame()))?.cam;
  check(home && back && dist(home, back) < 1e-6, 'a double-click brings it home', JSON.stringify([home, back]));
  await page.evaluate(() => { window.fxs.flameSettings.mode = 'hdr'; });
  await sleep(1500); // redrawn every display frame (drawfps=2), new stream frame or not
  const h = await page.evaluate(() => window.fxs.flameLook());
  await page.screenshot({ path: join(ART, 'web-flame-hdr.png') });
  const hw = await whiteMean();
  check(h && h.bright > 0.005 && hw && hw.mean <= 0.15, 'hdr: lit, and at most 15% of the bright flame pixels are white',
    JSON.stringify({ h, hw }));
  await page.evaluate(() => { window.fxs.flameSettings.mode = 'pbvr'; });
  const toggle = async () => page.evaluate(() => document.querySelector('.lil-gui [data-view="velLines"] input').click());
  await toggle();
  const lines = await until(async () => { const f = await page.evaluate(() => window.fxs.flame()); return f?.velocities && f.lineVertices > 0 ? f : null; }, 20000, 300);
  const velocities = () => JSON.parse(fxctl('get', 'flame').toString()).params.velocities;
  check(velocities() === true && !!lines,
    'velocity lines toggle: the stream sends velocities and line vertices are drawn', JSON.stringify(lines));
  fxctl('set', 'flame', 'time_scale=0'); // no new frames: the view redraws the last one (drawfps=2)
  await sleep(1500);
  const on = await page.evaluate(() => window.fxs.flameLook());
  await page.evaluate(() => { window.fxs.flameSettings.velLines = false; }); // the view only: same frame, no lines
  await sleep(1200);
  const off = await page.evaluate(() => window.fxs.flameLook());
  check(on && off && on.hash !== off.hash && on.bright > off.bright, 'velocity lines change the picture of the same frame (more lit pixels)',
    JSON.stringify({ on: on?.bright, off: off?.bright }));
  await page.evaluate(() => { window.fxs.flameSettings.velLines = true; });
  await toggle(); // off through the control: this page turned velocities on, so it turns them off
  check(await until(async () => velocities() === false, 10000, 300),
    'toggling the lines off sets the stream\'s velocities back');
  fxctl('set', 'flame', 'time_scale=1');
  await page.close();
}

try {
  daemon = await startDaemon(0, stateDir);
  const port = daemon.port;
  // The default streams, made cheaper for a 2-core machine running software WebGL, and the
  // wave's pulse off so the billboard is never momentarily dark.
  const fxctl = fxctlAt(port);
  fxctl('set', 'flame', 'fps=8');
  fxctl('set', 'energy', 'fps=3', 'animate=false');
  ctx = await launchBrowser(profile, { width: 800, height: 480 });
  const page = ctx.pages()[0] || await ctx.newPage();
  const logs = collectErrors(page);
  const url = `http://127.0.0.1:${port}/?rl=2&aa=0&drawfps=1`;
  const resp = await page.goto(url, { timeout: 20000 });
  check(resp && resp.ok(), 'page served at / by fxstreamd');
  const product = await (await fetch(`http://127.0.0.1:${port}/dist/app.js`)).text();
  check(product.length > 1000 && !product.includes('window.fxs') && !product.includes('FXS_TEST=!0'),
    'the product bundle carries no test hooks (the tests load dist/app-test.js in its place)');
  const connected = await until(() => page.evaluate(() => document.body.dataset.conn === 'connected'), 20000);
  check(connected, 'connects (state shown: connected)');
  const subscribed = await until(() => page.evaluate(() => document.body.dataset.subscribed), 30000);
  check(subscribed === 'energy,flame,eye', 'subscribes to every default stream', String(subscribed));
  const drawn = await until(async () => {
    const s = await page.evaluate(() => window.fxs.stats());
    return s.energy?.drawn > 2 && s.flame?.drawn > 1 && s.energy.kinds.includes(3) ? s : null;
  }, 40000, 500);
  check(!!drawn, 'frames arrive (kinds 1, 2, 3) and are drawn', JSON.stringify(drawn || await page.evaluate(() => window.fxs.stats())));
  await sleep(500);
  const flame = await page.evaluate(() => window.fxs.sample('flame'));
  const wave = await page.evaluate(() => window.fxs.sample('wave'));
  const scene = await page.evaluate(() => window.fxs.sample('scene'));
  await page.screenshot({ path: join(ART, 'web-viewer.png') });
  console.log('samples', JSON.stringify({ flame, wave, scene }), JSON.stringify(await page.evaluate(() => window.fxs.flame())), JSON.stringify(await page.evaluate(() => window.fxs.stats())));
  if (LOOK_ONLY) { console.log(JSON.stringify(await page.evaluate(() => window.fxsRecent))); console.log('clock', Date.now(), await page.evaluate(() => [Date.now(), performance.timeOrigin + performance.now()])); console.log(logs.join('\n')); await finish(0); }
  check(flame && flame.warm > 0.003 && flame.max > 180 && flame.mean[0] > 1.1 * flame.mean[2], 'flame region is bright and warm', JSON.stringify(flame));
  check(wave && wave.lit > 0.01 && wave.mean[2] > wave.mean[0], 'wave billboard is not empty (and blue, C_e)', JSON.stringify(wave));
  const rig = await page.evaluate(() => window.fxs.scene());
  check(rig && rig.rig && rig.nSeg === 12, 'toon scene has the light rig (12 segments of the torus, constants)', JSON.stringify(rig));
  check(rig && rig.shadows.length === 4 && rig.shadows.every((s) => s.k[1] < 0), 'every model casts a shadow downwards', JSON.stringify(rig?.shadows));
  check(scene && scene.lit > 0.3, 'toon scene is lit', JSON.stringify(scene));
  const sceneLum = scene ? 0.2126 * scene.mean[0] + 0.7152 * scene.mean[1] + 0.0722 * scene.mean[2] : 0;
  // (the home view frames the whole floor disc, with the dark background around it)
  check(sceneLum > 30 && sceneLum < 145, 'toon scene exposure: a mid-grey ground, not a white sheet (mean luminance 30-145)',
    sceneLum.toFixed(1));
  check(logs.length === 0, 'no console errors', logs.slice(0, 5).join(' | '));
  // The overlay: skipped frames by who skipped them and per kind, every figure defined in a tooltip.
  const label = await page.evaluate(() => { const el = document.querySelector('.label[data-view="energy:wave"]'); return { text: el?.textContent, title: el?.title }; });
  check(/skipped by server: .*· replaced \d+/.test(label.text || '') && /ms: age of the frames/.test(label.title || ''),
    'stats overlay: server skips per kind apart from frames replaced here, figures defined in a tooltip', JSON.stringify(label));

  // A panel toggle and slider: the feature texture off, then the attenuation gain up.
  await openFolder(page, 'energy');
  const rev0 = await healthRev(port, 'energy');
  await ctl(page, 'energy', 'features').locator('input').click();
  const rev1 = await until(async () => { const r = await healthRev(port, 'energy'); return r > rev0 ? r : null; }, 10000);
  check(rev1 > rev0, 'a panel toggle changes the server rev', `${rev0} -> ${rev1}`);
  await until(() => page.evaluate((r) => window.fxs.stats().energy.rev >= r, rev1), 5000);
  await sleep(800);
  const before = await page.evaluate(() => window.fxs.sample('wave'));
  const slider = ctl(page, 'energy', 'alpha').locator('input.fxs-log'); // 0.01-100: a logarithmic slider
  await slider.scrollIntoViewIfNeeded();
  const box = await slider.boundingBox();
  await page.mouse.move(box.x + 2, box.y + box.height / 2);
  await page.mouse.down();
  await page.mouse.move(box.x + box.width * 0.5, box.y + box.height / 2, { steps: 5 });
  await page.mouse.move(box.x + box.width * 0.95, box.y + box.height / 2, { steps: 5 });
  await page.mouse.up();
  const rev2 = await until(async () => { const r = await healthRev(port, 'energy'); return r > rev1 ? r : null; }, 10000);
  check(rev2 > rev1, 'moving the alpha slider changes the server rev', `${rev1} -> ${rev2}`);
  const alpha = await until(async () => {
    const a = await page.evaluate(() => window.fxs.streams.get('energy').params.alpha);
    return a > 20 ? a : null;
  }, 5000) ?? await page.evaluate(() => window.fxs.streams.get('energy').params.alpha);
  check(alpha > 20, 'the slider sent a large alpha', String(alpha));
  await until(() => page.evaluate((r) => window.fxs.stats().energy.rev >= r, rev2), 5000);
  const after = await until(async () => {
    const a = await page.evaluate(() => window.fxs.sample('wave'));
    return a.lit > 1.3 * before.lit || a.mean[2] > 1.3 * before.mean[2] ? a : null;
  }, 15000, 1000) || await page.evaluate(() => window.fxs.sample('wave'));
  check(after.lit > 1.5 * before.lit || after.mean[2] > 1.5 * before.mean[2], 'and the picture (the wave brightens)', `${JSON.stringify(before)} -> ${JSON.stringify(after)}`);
  await page.screenshot({ path: join(ART, 'web-after-slider.png') });

  // A second page changes beta; the first shows it (the params broadcast).
  const page2 = await ctx.newPage();
  await page2.setViewportSize({ width: 560, height: 420 });
  await page2.goto(url.replace("drawfps=1", "drawfps=0.5"), { timeout: 20000 });
  await until(() => page2.evaluate(() => document.body.dataset.subscribed?.split(',').includes('energy')), 30000);
  await openFolder(page2, 'energy');
  await setNumber(page2, 'energy', 'beta', 2.5);
  const seen = await until(() => page.evaluate(() => {
    const el = document.querySelector('[data-stream="energy"] [data-param="beta"] input:not(.fxs-log)');
    return el && Number(el.value) === 2.5 && window.fxs.streams.get('energy').params.beta === 2.5;
  }), 10000);
  check(seen, 'a change made in a second page appears in the first');
  // A value the server refuses: the error shows next to the field.
  await setNumber(page2, 'energy', 'tori[0].R', 500); // the default torus's radius, over its 100
  const err = await until(() => page2.evaluate(() => document.querySelector('.fxs-param-error')?.textContent), 10000);
  check(err && err.includes('tori[0].R') && err.includes('bad_param'), 'a server error shows next to its field', String(err));
  await page2.screenshot({ path: join(ART, 'web-panel-error.png') });
  await page2.close();

  await panelChecks(ctx, page, port, url);
  await flameChecks(ctx, port, fxctl);
  await waveChecks(ctx, port, fxctl, page);
  await eyeChecks(ctx, port, fxctl, url);

  // Restart the daemon on the same port: the page reconnects and frames flow again.
  await stopDaemon(daemon);
  const down = await until(() => page.evaluate(() => document.body.dataset.conn !== 'connected'), 10000);
  check(down, 'shows the lost connection');
  daemon = await startDaemon(port, stateDir);
  const framesBefore = await page.evaluate(() => window.fxs.stats().flame?.frames ?? 0);
  const back = await until(async () => {
    const s = await page.evaluate(() => ({ c: document.body.dataset.conn, f: window.fxs.stats().flame?.frames ?? 0 }));
    return s.c === 'connected' && s.f > framesBefore + 2;
  }, 30000, 500);
  check(back, 'reconnects with backoff after a restart and frames flow again');

  // With access tokens (PROTOCOL.md §3.11): no token says so; ?token= authenticates and leaves the address bar.
  await stopDaemon(daemon);
  const token = 'web-view-token-0123456789';
  daemon = await startDaemon(port, stateDir, { FXSTREAMD_TOKENS: `view:${token}` });
  const p3 = await ctx.newPage();
  const revView = await healthRev(port, 'flame');
  await p3.goto(`http://127.0.0.1:${port}/`);
  const refused = await until(() => p3.evaluate(() => document.body.dataset.conn === 'unauthorized'), 15000);
  check(refused, 'without a token the page says the daemon needs one');
  await p3.goto(`http://127.0.0.1:${port}/?token=${token}`);
  const authed = await until(() => p3.evaluate(() => document.body.dataset.conn === 'connected'), 15000);
  check(authed && !p3.url().includes('token'), 'with ?token= it authenticates and drops the token from the URL', p3.url());
  await until(() => p3.evaluate(() => window.fxs.streams.get('flame')?.params), 10000);
  await p3.evaluate(() => document.querySelector('.lil-gui [data-view="velLines"] input').click());
  const note = await until(() => p3.evaluate(() => document.body.dataset.velNote), 5000);
  check(/role \(view\) may not change/.test(note || '') && (await healthRev(port, 'flame')) === revView,
    'a view-only page turning velocity lines on is told to ask for a tune token, and sends no set', String(note));
  await p3.close();
} catch (e) {
  check(false, 'browser session', e.stack || String(e));
}
await finish();
