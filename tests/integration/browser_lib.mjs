// browser_lib.mjs — what the browser suites share: a real fxstreamd on a random loopback
// port (started, stopped), Debian's chromium through playwright-core with SwiftShader WebGL,
// bounded polling, and a view of the page read back as RGBA bytes.
import { chromium } from 'playwright-core';
import { spawn } from 'node:child_process';
import { join, resolve, dirname } from 'node:path';
import { fileURLToPath } from 'node:url';

export const ROOT = resolve(dirname(fileURLToPath(import.meta.url)), '..', '..');
export const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

/** Polls fn every `step` ms until it returns something truthy or `ms` pass; the last value. */
export async function until(fn, ms, step = 200) {
  const end = Date.now() + ms;
  let v;
  while (Date.now() < end) {
    try { v = await fn(); if (v) return v; } catch { /* retry */ }
    await sleep(step);
  }
  return v;
}

/** build/fxstreamd on `port` (0: any), its state in stateDir; resolves {proc, port} once it listens. */
export function startDaemon(port, stateDir, env = {}) {
  return new Promise((res, rej) => {
    const p = spawn(join(ROOT, 'build', 'fxstreamd'), ['--port', String(port), '--state-dir', stateDir, '--log-level', 'warn'],
      { stdio: ['ignore', 'pipe', 'pipe'], env: { ...process.env, ...env } });
    let out = '';
    const t = setTimeout(() => rej(new Error('daemon did not start: ' + out)), 15000);
    p.stdout.on('data', (d) => {
      out += d;
      const m = out.match(/127\.0\.0\.1:(\d+)\//);
      if (m) { clearTimeout(t); res({ proc: p, port: Number(m[1]) }); }
    });
    p.stderr.on('data', () => {}); // drained: a full pipe would block the daemon
    p.on('exit', () => rej(new Error('daemon exited: ' + out)));
  });
}

export function stopDaemon(d) {
  return new Promise((res) => {
    if (!d || d.proc.exitCode !== null) { res(); return; }
    const t = setTimeout(() => { d.proc.kill('SIGKILL'); res(); }, 5000);
    d.proc.once('exit', () => { clearTimeout(t); res(); });
    d.proc.kill('SIGTERM');
  });
}

/** A headless chromium context with software WebGL (SwiftShader) in profile dir `profile`. */
export function launchChromium(profile, options = {}) {
  return chromium.launchPersistentContext(profile, {
    executablePath: '/usr/bin/chromium', headless: true,
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run', '--disable-background-networking',
      '--disable-component-update', '--disable-sync', '--use-angle=swiftshader', '--enable-unsafe-swiftshader'],
    ...options,
  });
}

/** The pixels of the view of `kind` (and `stream`) as drawn: {w, h, px: RGBA bytes, rows from
 *  the top, css: the view's rectangle in CSS pixels}, at the canvas's own resolution. */
export async function grabView(page, kind, stream) {
  const g = await page.evaluate(([kind, name]) => {
    const s = window.fxs.sample(kind, name), c = document.getElementById('view'), pr = c.width / c.clientWidth;
    const x = Math.round(s.css.left * pr), y = Math.round(s.css.top * pr);
    const w = Math.min(c.width, Math.round((s.css.left + s.css.w) * pr)) - x, h = Math.min(c.height, Math.round((s.css.top + s.css.h) * pr)) - y;
    const g = document.createElement('canvas');
    g.width = w; g.height = h;
    const ctx = g.getContext('2d');
    ctx.drawImage(c, x, y, w, h, 0, 0, w, h);
    const px = ctx.getImageData(0, 0, w, h).data;
    let bin = '';
    for (let i = 0; i < px.length; i += 8192) bin += String.fromCharCode(...px.subarray(i, i + 8192));
    return { w, h, b64: btoa(bin), css: s.css };
  }, [kind, stream]);
  return { w: g.w, h: g.h, px: Buffer.from(g.b64, 'base64'), css: g.css };
}
