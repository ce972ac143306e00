// web_look_wave_check.mjs — the look of the energy wave, its toon scene and the compound
// eye, measured on the default streams of a real fxstreamd (random loopback port) in Debian's
// chromium (headless, SwiftShader WebGL) at 1600 × 1000, the page's default 2 × 2 layout (the
// flame stream left out: its look is another suite's). Every figure comes from the views'
// pixels read back (web_look_metrics.mjs says how each is computed):
// - energy wave: fills >= 30% of the view's width in a saturated colour (the glow's mean colour
//   >= 0.5 saturated, within 20° of the stream's C_e); the glow around the brightest core spans
//   >= 3 × the core's width and the bloom adds >= 10% to it; at alpha 0.3, 0.5, 1, 2 and 4 the
//   billboard's outer 2% of rows and columns stay below 2% of the peak; at alpha 0.5, 1 and 2
//   the peak is >= 20% of display white and <= 20% of the view is clipped; README's example
//   of a brighter, orange glow is orange (hue within 15° of 30°, >= 0.5 saturated: not beige);
// - toon scene: nothing at the view's edge but background (floor disc and models inside), and
//   the lit side of the models takes the wave's hue (within 20° of C_e's, >= 0.3 saturated),
//   blue by default and orange with README's orange;
// - compound eye: pigmented (mean colour >= 0.35 saturated), no black speckles on the lit
//   lattice (<= 1 per 10,000 pixels), no moiré at the rim (against the same view drawn at twice
//   the resolution: mean difference in the rim <= 3.5% of the disc's brightness), and closed:
//   a full round disc from home and after turning it 90° and 180° with the mouse.
// Screenshots go to build/artifacts/look-*.png. Every wait is bounded.
// Last line: "test_web_look_wave: N passed, M failed".
import { execFileSync } from 'node:child_process';
import { mkdtempSync, readFileSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { ART, ROOT, checker, sleep, until, startDaemon, stopDaemon, launchBrowser, grabView } from './web_lib.mjs';
import { waveMetrics, bloomGain, sceneMetrics, eyeMetrics, halve, hueDist, hueSat, displayOf, lum } from './web_look_metrics.mjs';

const checks = checker('test_web_look_wave');
const check = (ok, name, detail = '') => checks.check(ok, ok && detail ? `${name}: ${detail}` : name, detail);
// Bounded: about 100 s on an idle 2-core machine (SwiftShader draws three views at 1600 × 1000);
// the limit leaves room for a loaded one.
const hardStop = setTimeout(() => { console.log('FAIL overall time limit (420 s)'); finish(1); }, 420000);

const stateDir = mkdtempSync(join(tmpdir(), 'fxs-look-state-'));
const profiles = [];
let daemon = null;
const contexts = [];
async function finish(code) {
  clearTimeout(hardStop);
  for (const c of contexts) try { await c.close(); } catch { /* ignore */ }
  await stopDaemon(daemon);
  for (const p of [stateDir, ...profiles]) try { rmSync(p, { recursive: true, force: true }); } catch { /* chromium may still be writing */ }
  checks.summary();
  process.exit(code ?? (checks.failed ? 1 : 0));
}
async function browser(options) {
  const profile = mkdtempSync(join(tmpdir(), 'fxs-look-profile-'));
  profiles.push(profile);
  const { viewport, ...rest } = options;
  const ctx = await launchBrowser(profile, viewport, rest);
  contexts.push(ctx);
  return ctx.pages()[0] || ctx.newPage();
}

const PAGE = { width: 1600, height: 1000 };
const SCENE_BG = [10, 12, 18], EYE_BG = lum(8, 10, 16); // the views' clear colours
// README's example of a colour: `build/fxctl set energy ARGS  # a brighter, orange glow`.
const README_ORANGE = readFileSync(join(ROOT, 'README.md'), 'utf8').match(/^build\/fxctl set energy (.*?)\s+# a brighter, orange glow$/m);
const README_ARGS = README_ORANGE ? README_ORANGE[1].split(/\s+/).map((a) => a.replace(/^'(.*)'$/, '$1')) : [];
const ORANGE = JSON.parse(README_ARGS.find((a) => a.startsWith('color_energy='))?.slice(13) ?? 'null');
const within = (a, b, deg) => hueDist(a, b) <= deg;
const hueOf = (rgb) => hueSat(...displayOf(rgb)).h;

// The wave view once a texture of param_rev >= rev has been drawn, with its billboard in pixels.
async function waveLook(page, rev) {
  const ok = await until(() => page.evaluate((r) => (window.fxs.wave('energy')?.drawnRev ?? 0) >= r, rev), 20000, 250);
  if (!ok) return null;
  await sleep(600); // the next display frame has the settings of now
  const img = await grabView(page, 'wave', 'energy'), info = await page.evaluate(() => window.fxs.wave('energy'));
  const b = info.billboard;
  return { img, m: waveMetrics(img, { x0: b.x0 * img.w, x1: b.x1 * img.w, y0: b.y0 * img.h, y1: b.y1 * img.h }) };
}

// A screenshot of one view, without its stats label (its figures would be stale in a picture).
async function shot(page, kind, stream, name) {
  const css = await page.evaluate(([k, s]) => window.fxs.sample(k, s).css, [kind, stream]);
  await page.evaluate(() => { document.getElementById('labels').style.visibility = 'hidden'; });
  await page.screenshot({ path: join(ART, name), clip: { x: css.left, y: css.top, width: css.w, height: css.h } });
  await page.evaluate(() => { document.getElementById('labels').style.visibility = ''; });
}

async function waveChecks(page, set, p0) {
  const look = await waveLook(page, 1);
  check(!!look, 'the default energy wave is drawn');
  if (!look) return;
  const { m } = look, ceHue = hueOf(p0.color_energy);
  console.log('wave default', JSON.stringify(m));
  await shot(page, 'wave', 'energy', 'look-energy-wave.png');
  check(m.width >= 0.3, 'the default wave fills >= 30% of the view\'s width', `${(100 * m.width).toFixed(1)}%`);
  check(m.sat >= 0.5 && within(m.hue, ceHue, 20), 'in a saturated colour: its C_e', `glow hue ${m.hue}° (C_e ${ceHue.toFixed(1)}°), saturation ${m.sat}`);
  check(m.bloom >= 3, 'the glow around the brightest core spans >= 3 x the core', `core ${m.core} px, glow ${m.glow} px`);
  const bloom = await page.evaluate(() => window.fxs.waveSettings.bloom);
  await page.evaluate(() => { window.fxs.waveSettings.bloom = 0; });
  await sleep(1500);
  const off = await grabView(page, 'wave', 'energy');
  await page.evaluate((b) => { window.fxs.waveSettings.bloom = b; }, bloom);
  await sleep(1500);
  const gain = bloomGain(await grabView(page, 'wave', 'energy'), off);
  check(gain >= 0.1, 'the bloom is visible: it adds >= 10% to the glow', `+${(100 * gain).toFixed(1)}%`);

  for (const alpha of [0.3, 0.5, 1, 2, 4]) {
    const rev = set(`alpha=${alpha}`);
    const a = await waveLook(page, rev);
    if (!a) { check(false, `alpha ${alpha}: a new texture is drawn`); continue; }
    console.log(`wave alpha ${alpha}`, JSON.stringify(a.m));
    check(a.m.border <= 0.02, `alpha ${alpha}: no hard edge (the billboard's outer 2% below 2% of the peak)`, `${(100 * a.m.border).toFixed(2)}%`);
    if ([0.5, 1, 2].includes(alpha))
      check(a.m.peak >= 0.2 && a.m.clipped <= 0.2, `alpha ${alpha}: neither blank (peak >= 20% of white) nor blown out (<= 20% clipped)`,
        `peak ${(100 * a.m.peak).toFixed(0)}%, clipped ${(100 * a.m.clipped).toFixed(1)}%`);
    if (alpha === 4) await shot(page, 'wave', 'energy', 'look-energy-alpha4.png');
  }
  check(ORANGE && README_ARGS.includes('alpha=2'), 'README has its example of a brighter, orange glow', README_ARGS.join(' '));
  if (!ORANGE) return;
  const rev = set(...README_ARGS);
  const o = await waveLook(page, rev);
  console.log('wave orange', JSON.stringify(o?.m));
  check(o && within(o.m.hue, 30, 15) && o.m.sat >= 0.5, `README's ${README_ARGS.join(' ')} is orange (hue within 15° of 30°, not beige: saturation >= 0.5)`,
    `hue ${o?.m.hue}°, saturation ${o?.m.sat}`);
  if (o) await shot(page, 'wave', 'energy', 'look-energy-orange.png');
}

// The toon scene's lit side with the wave's colour now (rev: the change that set it, drawn).
async function sceneLook(page, rev) {
  await until(() => page.evaluate((r) => (window.fxs.wave('energy')?.drawnRev ?? 0) >= r, rev), 20000, 250);
  await sleep(1200);
  const img = await grabView(page, 'scene', 'energy'), info = await page.evaluate(() => window.fxs.scene('energy'));
  return { info, m: sceneMetrics(img, info, SCENE_BG) };
}

async function sceneChecks(page, set, p0) {
  const orange = await sceneLook(page, await page.evaluate(() => window.fxs.streams.get('energy').rev));
  await shot(page, 'scene', 'energy', 'look-toon-orange.png');
  const blue = await sceneLook(page, set(`alpha=${p0.alpha}`, `color_energy=${JSON.stringify(p0.color_energy)}`)); // the defaults
  await shot(page, 'scene', 'energy', 'look-toon-scene.png');
  console.log('scene', JSON.stringify({ blue: blue.m, orange: orange.m }));
  const blueHue = hueOf(p0.color_energy), orangeHue = ORANGE ? hueOf(ORANGE) : NaN;
  check(blue.info.home && blue.m.cut === 0 && blue.m.inside, 'toon scene: the home view shows the floor disc and every model (nothing at the view\'s edge)',
    `edge not background ${(100 * blue.m.cut).toFixed(2)}%, models inside ${blue.m.inside}`);
  check(within(blue.m.litHue, blueHue, 20) && blue.m.litSat >= 0.3, 'toon scene: the lit side takes the wave\'s blue',
    `hue ${blue.m.litHue}° (C_e ${blueHue.toFixed(1)}°), saturation ${blue.m.litSat}, ${blue.m.litPixels} pixels`);
  check(ORANGE && within(orange.m.litHue, orangeHue, 20) && orange.m.litSat >= 0.3, 'and moves to its orange with README\'s orange',
    `hue ${orange.m.litHue}° (C_e ${orangeHue.toFixed(1)}°), saturation ${orange.m.litSat}, ${orange.m.litPixels} pixels`);
}

// The eye alone in the first cell of the 2 × 2 layout (the size it has on the default page).
async function eyePage(scale, port) {
  const page = await browser({ viewport: PAGE, deviceScaleFactor: scale });
  await page.goto(`http://127.0.0.1:${port}/?streams=eye&grid=2x2&aa=0&drawfps=2`, { timeout: 20000 });
  const ok = await until(() => page.evaluate(() => (window.fxs.stats().eye?.drawn ?? 0) > 0), 30000, 300);
  await sleep(1500);
  return ok ? page : null;
}

async function eyeChecks(main, port) {
  const page = await eyePage(1, port), fine = await eyePage(2, port);
  check(page && fine, 'the default eye is drawn (at 1x and 2x resolution)');
  if (!page || !fine) return;
  const img = await grabView(page, 'eye', 'eye'), ref = halve(await grabView(fine, 'eye', 'eye'));
  const m = eyeMetrics(img, EYE_BG, Math.abs(ref.w - img.w) <= 1 && Math.abs(ref.h - img.h) <= 1 ? ref : null);
  console.log('eye', JSON.stringify(m));
  await shot(main, 'eye', 'eye', 'look-eye.png');
  check(m.sat >= 0.35, 'the default eye is pigmented (not bone white)', `mean colour ${JSON.stringify(m.mean)}, saturation ${m.sat}`);
  check(m.speckles <= 1e-4, 'no black speckles on the lit lattice (<= 1 per 10,000 pixels)', `${m.specks} in ${m.lit} pixels`);
  check(m.rimErr !== undefined && m.rimErr <= 0.035 * m.lum, 'no moiré at the rim (within 3.5% of a render at twice the resolution)',
    `rim ${m.rimErr}, middle ${m.midErr}, disc brightness ${m.lum}`);
  const round = (e) => e.fill >= 0.95 && e.aspect >= 0.9 && e.aspect <= 1.1;
  check(round(m), 'closed: a full round disc from the home camera', `fill ${m.fill}, aspect ${m.aspect}`);
  // Turn it with the mouse: OrbitControls turns 2π per canvas height dragged, so a quarter of
  // the height is 90° (the side of the eye) and half is 180° (its back).
  const css = await page.evaluate(() => window.fxs.sample('eye', 'eye').css);
  for (const [deg, dx] of [[90, PAGE.height / 4], [180, PAGE.height / 4]]) {
    const x = css.left + css.w / 2 - dx / 2, y = css.top + css.h / 2;
    await page.mouse.move(x, y);
    await page.mouse.down();
    await page.mouse.move(x + dx, y, { steps: 8 });
    await page.mouse.up();
    await sleep(1500);
    const e = eyeMetrics(await grabView(page, 'eye', 'eye'), EYE_BG);
    await shot(page, 'eye', 'eye', `look-eye-${deg}.png`);
    check(e.area > 0 && round(e), `closed: a full round disc after turning it ${deg}° (no open cut)`, `fill ${e.fill}, aspect ${e.aspect}`);
  }
}

try {
  daemon = await startDaemon(0, stateDir);
  const port = daemon.port, url = `ws://127.0.0.1:${port}`;
  const fxctl = (...a) => execFileSync(join(ROOT, 'build', 'fxctl'), ['--url', url, '--json', ...a], { timeout: 15000 }).toString();
  const set = (...a) => JSON.parse(fxctl('set', 'energy', ...a)).rev; // the new rev
  set('fps=4'); // the default scene is still: fewer frames of the same picture for a 2-core machine
  const page = await browser({ viewport: PAGE });
  const logs = [];
  page.on('console', (m) => { if ((m.type() === 'error' || m.type() === 'warning') && !m.text().includes('GL Driver Message')) logs.push(m.text()); });
  page.on('pageerror', (e) => logs.push('pageerror: ' + e.message));
  await page.goto(`http://127.0.0.1:${port}/?streams=energy,eye&grid=2x2&aa=0&drawfps=2`, { timeout: 20000 });
  const drawn = await until(async () => {
    const s = await page.evaluate(() => window.fxs.stats());
    return s.energy?.drawn > 1 && s.eye?.drawn > 0 && s.energy.kinds.includes(3) ? s : null;
  }, 40000, 500);
  check(!!drawn, 'the default energy wave, its light rig and the eye arrive and are drawn', JSON.stringify(drawn));
  if (drawn) {
    await sleep(1000);
    await page.screenshot({ path: join(ART, 'look-page.png') });
    const p0 = await page.evaluate(() => window.fxs.streams.get('energy').params); // the defaults (fps aside)
    await waveChecks(page, set, p0);
    await sceneChecks(page, set, p0);
    await eyeChecks(page, port);
    await page.screenshot({ path: join(ART, 'look-page-end.png') });
  }
  check(logs.length === 0, 'no console errors', logs.slice(0, 5).join(' | '));
} catch (e) {
  check(false, 'browser session', e.stack || String(e));
}
await finish();
