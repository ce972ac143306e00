// web_look_check.mjs — what an artist sees on opening the page, measured: the flame's default
// (volume) mode on the default scene, camera at home, a 1200x760 page, in Debian's chromium against a
// real fxstreamd. Over 20 drawn frames, from the view's pixels:
// - a continuous body: inside the silhouette (flame pixels above 5% of the frame's peak after a
//   9-pixel box blur) at most 3% holes (below 2% of the peak), and the variance of the
//   Laplacian there at most 1/4 of PBVR's on the same (paused) frame and camera;
// - colour: the brightest 10% of flame pixels yellow-white (mean G/R >= 0.75, B/R <= 0.6), at
//   most 15% of the flame's pixels at 255 in every channel, the top third redder than the
//   bottom third;
// - no stray light under the base: flame pixels brighter than 10% of the peak below the
//   sources' outline at most 0.5% of the flame's area;
// - it moves: the mean absolute frame-to-frame luminance change inside the silhouette at
//   least 3% of its mean luminance;
// - smoke: grey above the flame with smoke on, gone with it off; the ground grid hidden
//   behind the flame (no grid-coloured pixels in the flame's core);
// - a particle budget (?particles=2000) on the same paused frame keeps its extent, brightness and colour;
// - 200k particles drawn in pbvr and hdr keep the flame's extent and brightness (denseLook).
// With --shots DIR it also writes the README's pictures there. Last line: "test_web_look: N passed, M failed".
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { ART, checker, collectErrors, fxctlAt, launchBrowser, sleep, startDaemon, stopDaemon, until } from './web_lib.mjs';

const checks = checker('test_web_look');
const check = checks.check;
const shotsAt = process.argv.includes('--shots') ? process.argv[process.argv.indexOf('--shots') + 1] : null;
const hardStop = setTimeout(() => { console.log('FAIL overall time limit (560 s)'); finish(1); }, 560000);
const stateDir = mkdtempSync(join(tmpdir(), 'fxs-look-state-'));
const profile = mkdtempSync(join(tmpdir(), 'fxs-look-profile-'));
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

// Runs in the page: the figures above for the flame view's current pixels. Flame pixels are
// warm (R > B + 8) or near white; the bluish grid and grey smoke are not. The previous call's
// luminance is kept on window for the frame-to-frame change.
function flameFigures() {
  const info = window.fxs.flame(), s = window.fxs.sample('flame'), c = document.getElementById('view');
  const pr = c.width / c.clientWidth;
  const x0 = Math.round(s.css.left * pr), y0 = Math.round(s.css.top * pr), w = Math.round(s.css.w * pr), h = Math.round(s.css.h * pr);
  const g = document.createElement('canvas');
  g.width = w; g.height = h;
  const g2 = g.getContext('2d');
  g2.drawImage(c, x0, y0, w, h, 0, 0, w, h);
  const px = g2.getImageData(0, 0, w, h).data, n = w * h;
  const L = new Float32Array(n), F = new Float32Array(n);
  let peakF = 0;
  for (let i = 0; i < n; i++) {
    const R = px[4 * i], G = px[4 * i + 1], B = px[4 * i + 2];
    L[i] = 0.2126 * R + 0.7152 * G + 0.0722 * B;
    F[i] = R > B + 8 || Math.min(R, G, B) >= 200 ? L[i] : 0;
    peakF = Math.max(peakF, F[i]);
  }
  const blur = (src) => { // 9-pixel box blur (running sums), rows then columns
    const tmp = new Float32Array(n), out = new Float32Array(n);
    for (let y = 0; y < h; y++) {
      let a = 0;
      const row = y * w;
      for (let x = -4; x < w; x++) {
        if (x + 4 < w) a += src[row + x + 4];
        if (x - 5 >= 0) a -= src[row + x - 5];
        if (x >= 0) tmp[row + x] = a / (Math.min(w - 1, x + 4) - Math.max(0, x - 4) + 1);
      }
    }
    for (let x = 0; x < w; x++) {
      let a = 0;
      for (let y = -4; y < h; y++) {
        if (y + 4 < h) a += tmp[(y + 4) * w + x];
        if (y - 5 >= 0) a -= tmp[(y - 5) * w + x];
        if (y >= 0) out[y * w + x] = a / (Math.min(h - 1, y + 4) - Math.max(0, y - 4) + 1);
      }
    }
    return out;
  };
  const Fb = blur(F);
  let peakB = 0;
  for (let i = 0; i < n; i++) peakB = Math.max(peakB, Fb[i]);
  const sil = new Uint8Array(n), silRows = [];
  let area = 0, holes = 0, white = 0, lapS = 0, lapS2 = 0, lapN = 0, core = 0, coreGrid = 0, lum = 0;
  for (let y = 0; y < h; y++) for (let x = 0; x < w; x++) {
    const i = y * w + x;
    if (!(Fb[i] > 0.05 * peakB)) continue;
    sil[i] = 1; area++; silRows.push(y); lum += L[i];
    if (F[i] < 0.02 * peakF) holes++;
    if (px[4 * i] === 255 && px[4 * i + 1] === 255 && px[4 * i + 2] === 255) white++;
    if (x > 0 && y > 0 && x < w - 1 && y < h - 1) {
      const lap = 4 * L[i] - L[i - 1] - L[i + 1] - L[i - w] - L[i + w];
      lapS += lap; lapS2 += lap * lap; lapN++;
    }
    if (Fb[i] > 0.25 * peakB) { core++; if (px[4 * i + 2] > px[4 * i] + 4) coreGrid++; }
  }
  if (!area) return { area: 0 };
  // the brightest 10% of the silhouette's pixels (a luminance histogram), and its top and
  // bottom thirds (rows from the top) where the flame is above 10% of the peak
  const hist = new Uint32Array(256);
  for (let i = 0; i < n; i++) if (sil[i]) hist[Math.min(255, Math.floor(L[i]))]++;
  let cut = 255;
  for (let k = 0; cut > 0 && k + hist[cut] <= 0.1 * area; cut--) k += hist[cut];
  silRows.sort((a, b) => a - b);
  const r0 = silRows[Math.floor(0.02 * (silRows.length - 1))], r1 = silRows[Math.ceil(0.98 * (silRows.length - 1))], t = (r1 - r0) / 3;
  const sums = { top10: [0, 0, 0], topThird: [0, 0, 0], bottomThird: [0, 0, 0] };
  for (let i = 0; i < n; i++) {
    if (!sil[i]) continue;
    const y = Math.floor(i / w), rgb = [px[4 * i], px[4 * i + 1], px[4 * i + 2]];
    const add = (k) => { for (let c = 0; c < 3; c++) sums[k][c] += rgb[c]; };
    if (L[i] >= cut) add('top10');
    if (F[i] > 0.1 * peakF && y < r0 + t) add('topThird');
    if (F[i] > 0.1 * peakF && y > r1 - t) add('bottomThird');
  }
  const ratio = ([r, gg, b]) => ({ gr: gg / Math.max(1, r), br: b / Math.max(1, r) });
  const top10 = ratio(sums.top10), topThird = ratio(sums.topThird), bottomThird = ratio(sums.bottomThird);
  // stray light: flame pixels above 10% of the peak below the sources' outline (plus 2 pixels)
  const baseY = Math.round(info.baseRow * h) + 2;
  let below = 0;
  for (let y = Math.max(0, baseY); y < h; y++) for (let x = 0; x < w; x++) if (F[y * w + x] > 0.1 * peakF) below++;
  // smoke: grey pixels (channels within 14 of each other, luminance 14-200) above the flame's middle
  let grey = 0;
  const mid = Math.round((r0 + r1) / 2);
  for (let y = 0; y < mid; y++) for (let x = 0; x < w; x++) {
    const i = 4 * (y * w + x), R = px[i], G = px[i + 1], B = px[i + 2], l = L[y * w + x];
    if (Math.max(R, G, B) - Math.min(R, G, B) <= 14 && l >= 14 && l <= 200) grey++;
  }
  // frame-to-frame change inside the union of this and the last silhouette
  let moved = null;
  const prev = window.__flameFigPrev;
  if (prev && prev.L.length === n) {
    let d = 0, m = 0, k = 0;
    for (let i = 0; i < n; i++) if (sil[i] || prev.sil[i]) { d += Math.abs(L[i] - prev.L[i]); m += L[i]; k++; }
    moved = k && m ? d / m : 0;
  }
  window.__flameFigPrev = { L, sil };
  const lapMean = lapS / Math.max(1, lapN);
  return {
    w, h, peak: peakF, area: area / n, lum: lum / area, holes: holes / area, white: white / area, lapVar: lapS2 / Math.max(1, lapN) - lapMean * lapMean,
    top10, topThird, bottomThird, below: below / area, grey: grey / n, coreGrid: coreGrid / Math.max(1, core), moved,
  };
}

// The flame view's rectangle without its stats label, for the README.
async function flameClip(page) {
  await page.addStyleTag({ content: '.label { display: none }' });
  const css = await page.evaluate(() => window.fxs.sample('flame').css);
  return { x: css.left, y: css.top, width: css.w, height: css.h };
}

const median = (a) => { const s = [...a].sort((x, y) => x - y); return s[Math.floor((s.length - 1) / 2)]; };
const span = (a) => `min ${Math.min(...a).toFixed(4)}, median ${median(a).toFixed(4)}, max ${Math.max(...a).toFixed(4)}`;

async function flameLook(page, fxctl) {
  const drawn = () => page.evaluate(() => window.fxs.stats().flame?.drawn ?? 0);
  const nextDraw = async () => { const d = await drawn(); return until(async () => (await drawn()) > d, 10000, 100); };
  const figures = () => page.evaluate(flameFigures);
  check(await until(async () => (await drawn()) > 4, 60000, 500), 'flame view: frames drawn');
  const info = await page.evaluate(() => window.fxs.flame());
  check(info?.mode === 'volume', 'the flame is drawn as a volume by default', JSON.stringify(info));
  const f = [];
  let busy = 0;
  for (let i = 0; i < 20; i++) {
    await nextDraw();
    const t0 = Date.now();
    f.push(await figures());
    busy += Date.now() - t0;
  }
  console.log(`  info: 20 frames measured, ${(busy / 20).toFixed(0)} ms per frame's figures`);
  if (shotsAt) await page.screenshot({ path: join(shotsAt, 'flame.png'), clip: await flameClip(page), timeout: 120000 });
  await page.screenshot({ path: join(ART, 'web-look-flame.png'), timeout: 120000 });
  const col = (k) => f.map((x) => x[k]);
  console.log('  info: holes', span(col('holes')), '| white', span(col('white')), '| below', span(col('below')),
    '| moved', span(col('moved').slice(1)), '| top10 G/R', span(f.map((x) => x.top10.gr)), 'B/R', span(f.map((x) => x.top10.br)));
  check(f.every((x) => x.area > 0.01), 'a flame is drawn in every frame (>= 1% of the view)', span(col('area')));
  check(median(col('holes')) <= 0.03, 'continuous body: <= 3% holes inside the silhouette', span(col('holes')));
  check(median(f.map((x) => x.top10.gr)) >= 0.75 && median(f.map((x) => x.top10.br)) <= 0.6,
    'the brightest 10% are yellow-white (G/R >= 0.75, B/R <= 0.6)', JSON.stringify(f.map((x) => x.top10)));
  check(median(col('white')) <= 0.15, '<= 15% of the flame clipped to white', span(col('white')));
  check(median(f.map((x) => x.topThird.gr - x.bottomThird.gr)) < 0, 'the top third is redder than the bottom third',
    JSON.stringify(f.slice(0, 5).map((x) => [x.topThird.gr, x.bottomThird.gr])));
  check(median(col('below')) <= 0.005, 'no stray light under the base (<= 0.5% of the flame)', span(col('below')));
  check(median(col('moved').slice(1)) >= 0.03, 'it moves: frame-to-frame change >= 3% inside the silhouette', span(col('moved').slice(1)));
  check(median(col('coreGrid')) <= 0.005, 'the ground grid is hidden behind the flame', span(col('coreGrid')));

  // The same paused frame in both modes: the volume is smooth where PBVR is grainy.
  fxctl('set', 'flame', 'time_scale=0');
  await sleep(1500);
  await nextDraw();
  const vol = await figures();
  await page.evaluate(() => { window.fxs.flameSettings.mode = 'pbvr'; });
  await nextDraw(); await nextDraw();
  const pbvr = await figures();
  await page.screenshot({ path: join(ART, 'web-look-flame-pbvr.png'), timeout: 120000 });
  if (shotsAt) await page.screenshot({ path: join(shotsAt, 'flame-pbvr.png'), clip: await flameClip(page), timeout: 120000 });
  await page.evaluate(() => { window.fxs.flameSettings.mode = 'volume'; });
  check(vol.lapVar <= pbvr.lapVar / 4, 'smooth: Laplacian variance inside the silhouette <= 1/4 of PBVR\'s on the same frame',
    `volume ${vol.lapVar.toFixed(1)}, pbvr ${pbvr.lapVar.toFixed(1)}`);
  await nextDraw();
  const smokeOn = await figures();
  await page.evaluate(() => { window.fxs.flameSettings.smoke = false; });
  await nextDraw(); await nextDraw();
  const smokeOff = await figures();
  await page.evaluate(() => { window.fxs.flameSettings.smoke = true; });
  check(smokeOn.grey > 0.05 * smokeOn.area && smokeOff.grey < 0.3 * smokeOn.grey, 'grey smoke above the flame (>= 5% of the flame\'s area), on by default, gone when turned off',
    `on ${smokeOn.grey.toFixed(4)}, off ${smokeOff.grey.toFixed(4)} of the view; the flame ${smokeOn.area.toFixed(4)}`);
  fxctl('set', 'flame', 'time_scale=1');
}

// A particle budget (?particles=2000, PROTOCOL.md §3.5) on the same paused frame: the page draws
// the daemon's subset as standing for total / count particles each, so the flame keeps its extent,
// brightness and colour (flame.js): silhouette area and mean luminance within 25%, the brightest
// tenth's colour within 0.1, against the whole frame on the same camera.
async function budgetLook(ctx, port, fxctl, page) {
  fxctl('set', 'flame', 'time_scale=0');
  await sleep(1500);
  const drawnOn = (p) => p.evaluate(() => window.fxs.stats().flame?.drawn ?? 0);
  const d0 = await drawnOn(page);
  await until(async () => (await drawnOn(page)) > d0 + 1, 20000, 200);
  const whole = await page.evaluate(flameFigures);
  await page.close();
  const sub = await ctx.newPage();
  await sub.setViewportSize({ width: 1200, height: 760 });
  await sub.goto(`http://127.0.0.1:${port}/?streams=flame&grid=1x1&aa=0&drawfps=1&particles=2000`, { timeout: 20000 });
  check(await until(async () => (await drawnOn(sub)) > 2, 60000, 500), 'budget: the flame is drawn with ?particles=2000');
  const info = await sub.evaluate(() => window.fxs.flame());
  const label = await sub.evaluate(() => document.querySelector('.label')?.textContent ?? '');
  check(info?.count === 2000 && info.total > 2000 && /2,000 of [\d,]+ particles \(budget\)/.test(label),
    'budget: the daemon sends a subset of 2000 and the overlay names it', `${info?.count} of ${info?.total}; ${label}`);
  const part = await sub.evaluate(flameFigures);
  await sub.screenshot({ path: join(ART, 'web-look-flame-budget.png'), timeout: 120000 });
  const rel = (a, b) => Math.abs(a - b) / Math.max(1e-9, b);
  console.log(`  info: whole frame area ${whole.area.toFixed(4)} lum ${whole.lum.toFixed(1)} top10 G/R ${whole.top10.gr.toFixed(3)}; ` +
    `subset area ${part.area.toFixed(4)} lum ${part.lum.toFixed(1)} top10 G/R ${part.top10.gr.toFixed(3)}`);
  check(rel(part.area, whole.area) <= 0.25 && rel(part.lum, whole.lum) <= 0.25 && Math.abs(part.top10.gr - whole.top10.gr) <= 0.1,
    'budget: the subset keeps the flame\'s extent, brightness and colour (area, mean luminance within 25%, top tenth G/R within 0.1)',
    `area ${part.area.toFixed(4)} vs ${whole.area.toFixed(4)}, lum ${part.lum.toFixed(1)} vs ${whole.lum.toFixed(1)}, ` +
    `G/R ${part.top10.gr.toFixed(3)} vs ${whole.top10.gr.toFixed(3)}`);
  fxctl('set', 'flame', 'time_scale=1');
  return sub;
}

// Many particles in the modes that draw each one (pbvr, hdr): the paused frame made into 200k
// particles at the spacing of a finer stream (hooks.js flameDense), as the `large` preset's
// stream would be. Correctness on SwiftShader: every particle is drawn (the view's count), and
// the flame keeps its extent and brightness against the stream's own frame in the same mode
// (silhouette area and mean luminance within 35%; pbvr's luminance within 45%: one pass draws a
// whole number of sprites a particle, 1-2 at this spacing against 3-4). The time a draw takes is
// printed: a software renderer's, not a GPU's, so only how it grows with the particles. pbvr
// draws up to 8 sprites a particle in each of its `rl` passes (15 by default): here one pass.
async function denseLook(ctx, port, fxctl) {
  const page = await ctx.newPage();
  const logs = collectErrors(page);
  await page.setViewportSize({ width: 1200, height: 760 });
  await page.goto(`http://127.0.0.1:${port}/?streams=flame&grid=1x1&aa=0&drawfps=1`, { timeout: 20000 });
  const drawnOn = () => page.evaluate(() => window.fxs.stats().flame?.drawn ?? 0);
  check(await until(async () => (await drawnOn()) > 2, 60000, 500), 'dense: the flame is drawn');
  fxctl('set', 'flame', 'time_scale=0');
  await sleep(1500);
  const d0 = await drawnOn();
  await until(async () => (await drawnOn()) > d0, 20000, 200);
  const own = await page.evaluate(() => window.fxs.flame().count);
  for (const mode of ['pbvr', 'hdr']) {
    await page.evaluate((m) => { Object.assign(window.fxs.flameSettings, { mode: m, rl: 1 }); }, mode);
    const rows = [];
    for (const n of [own, 200000]) {
      const count = await page.evaluate((k) => window.fxs.flameDense(k), n);
      // drawn and measured in one evaluation: the page's next frame clears the canvas
      const r = await page.evaluate(`(() => ({ ms: window.fxs.flameDrawMs(1), f: (${flameFigures})() }))()`);
      rows.push({ n, count, ...r });
    }
    await page.evaluate(() => window.fxs.flameShow(true));
    await sleep(4000); // the page's own draw (drawfps=1) of the 200k frame
    await page.screenshot({ path: join(ART, `web-look-flame-200k-${mode}.png`), timeout: 120000 });
    await page.evaluate(() => window.fxs.flameShow(false));
    console.log(`  info: ${mode} draw on SwiftShader: ` + rows.map((r) => `${r.n} particles ${r.ms.toFixed(0)} ms (area ${r.f.area.toFixed(4)}, lum ${r.f.lum.toFixed(1)})`).join(', '));
    const [base, big] = rows, rel = (a, b) => Math.abs(a - b) / Math.max(1e-9, b), lumTol = mode === 'pbvr' ? 0.45 : 0.35;
    check(big.count === 200000, `${mode}: the view draws 200k particles`, `${big.count}`);
    check(rel(big.f.area, base.f.area) <= 0.35 && rel(big.f.lum, base.f.lum) <= lumTol,
      `${mode}: 200k particles at a finer spacing keep the flame's extent and brightness (area within 35%, mean luminance within ${100 * lumTol}%)`,
      `area ${big.f.area.toFixed(4)} vs ${base.f.area.toFixed(4)}, lum ${big.f.lum.toFixed(1)} vs ${base.f.lum.toFixed(1)}`);
  }
  check(logs.length === 0, 'dense: no console errors', logs.slice(0, 5).join(' | '));
  fxctl('set', 'flame', 'time_scale=1');
  await page.close();
}

// The README's pictures: every view of the default page, one at a time, without the stats labels.
async function viewShots(ctx, port) {
  const page = await ctx.newPage();
  await page.setViewportSize({ width: 1280, height: 800 });
  for (const [stream, kind, file] of [['energy', 'wave', 'energy-wave.png'], ['energy', 'scene', 'toon-scene.png'], ['eye', 'eye', 'eye.png']]) {
    await page.goto(`http://127.0.0.1:${port}/?streams=${stream}&grid=1x1&aa=0&drawfps=1&views=${kind}`, { timeout: 20000 });
    await page.addStyleTag({ content: '.label { display: none }' });
    const shown = await until(async () => { const v = await page.evaluate((k) => window.fxs.sample(k), kind); return v?.lit > 0.02 ? v : null; }, 60000, 500);
    await sleep(2000); // a few more draws: the wave's bloom and the scene's lights settle
    check(!!shown, `${stream}: the ${kind} view is drawn`);
    const css = shown?.css;
    if (css) await page.screenshot({ path: join(shotsAt, file), clip: { x: css.left, y: css.top, width: css.w, height: css.h }, timeout: 60000 });
  }
  await page.close();
}

try {
  daemon = await startDaemon(0, stateDir);
  const fxctl = fxctlAt(daemon.port);
  fxctl('set', 'flame', 'fps=8'); // the same flame, fewer frames for a 2-core machine drawing in software
  ctx = await launchBrowser(profile, { width: 1200, height: 760 });
  const page = ctx.pages()[0] || await ctx.newPage();
  const logs = collectErrors(page);
  await page.goto(`http://127.0.0.1:${daemon.port}/?streams=flame&grid=1x1&aa=0&drawfps=1`, { timeout: 20000 });
  await flameLook(page, fxctl);
  const sub = await budgetLook(ctx, daemon.port, fxctl, page);
  const subLogs = collectErrors(sub);
  await denseLook(ctx, daemon.port, fxctl);
  if (shotsAt) await viewShots(ctx, daemon.port);
  check(logs.length === 0 && subLogs.length === 0, 'no console errors', [...logs, ...subLogs].slice(0, 5).join(' | '));
} catch (e) {
  check(false, 'browser session', e.stack || String(e));
}
await finish();
