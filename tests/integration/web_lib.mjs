// web_lib.mjs — what the browser suites share: named checks counted into the summary line,
// bounded waits, a real fxstreamd on a loopback port (started, restarted, stopped), fxctl
// against it, and Debian's chromium (headless, software WebGL through SwiftShader) driven by
// playwright-core.
import { chromium } from 'playwright-core';
import { spawn, execFileSync } from 'node:child_process';
import { mkdirSync } from 'node:fs';
import { join, resolve, dirname } from 'node:path';
import { fileURLToPath } from 'node:url';

export const ROOT = resolve(dirname(fileURLToPath(import.meta.url)), '..', '..');
export const ART = join(ROOT, 'build', 'artifacts');
mkdirSync(ART, { recursive: true });

export const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

// Bounded polling: the first truthy value of fn, or its last value after ms.
export async function until(fn, ms, step = 200) {
  const end = Date.now() + ms;
  let v;
  while (Date.now() < end) { try { v = await fn(); if (v) return v; } catch { /* retry */ } await sleep(step); }
  return v;
}

// Named checks, printed as "ok"/"FAIL" lines with the seconds since start; summary() prints
// the suite's last line "NAME: N passed, M failed".
export function checker(name) {
  const t0 = Date.now();
  const c = {
    passed: 0, failed: 0,
    check(ok, what, detail = '') {
      what = `${what} [${((Date.now() - t0) / 1000).toFixed(1)} s]`;
      if (ok) { c.passed++; console.log('ok   ' + what); } else { c.failed++; console.log('FAIL ' + what + (detail ? ': ' + detail : '')); }
    },
    summary() { console.log(`${name}: ${c.passed} passed, ${c.failed} failed`); },
  };
  return c;
}

// fxstreamd on `port` (0: a free one) with its state in stateDir; resolves when it listens.
export function startDaemon(port, stateDir, env = {}) {
  return new Promise((res, rej) => {
    const p = spawn(join(ROOT, 'build', 'fxstreamd'), ['--port', String(port), '--state-dir', stateDir, '--log-level', 'warn'],
      { stdio: ['ignore', 'pipe', 'pipe'], env: { ...process.env, ...env } });
    let out = '', err = '', up = false;
    const t = setTimeout(() => rej(new Error('daemon did not start: ' + out)), 15000);
    p.stdout.on('data', (d) => {
      out += d;
      const m = out.match(/127\.0\.0\.1:(\d+)\//);
      if (m && !up) { up = true; clearTimeout(t); res({ proc: p, port: Number(m[1]) }); }
    });
    p.stderr.on('data', (d) => { err = (err + d).slice(-2000); });
    p.on('exit', (code, sig) => {
      if (!up) rej(new Error('daemon exited: ' + out + err));
      else if (!p.stopping) console.log(`  daemon exited unexpectedly (status ${code}, signal ${sig}): ${err}`);
    });
  });
}

export function stopDaemon(d) {
  return new Promise((res) => {
    if (!d || d.proc.exitCode !== null) { res(); return; }
    const t = setTimeout(() => { d.proc.kill('SIGKILL'); res(); }, 5000);
    d.proc.once('exit', () => { clearTimeout(t); res(); });
    d.proc.stopping = true;
    d.proc.kill('SIGTERM');
  });
}

// build/fxctl against the daemon on port; returns its stdout.
export const fxctlAt = (port) => (...a) => execFileSync(join(ROOT, 'build', 'fxctl'), ['--url', `ws://127.0.0.1:${port}`, ...a], { timeout: 15000 });

// Every page of the context gets the test bundle (dist/app-test.js: the page with the tests'
// hooks, window.fxs) in place of the product's dist/app.js.
export async function launchBrowser(profile, viewport, options = {}) {
  const ctx = await chromium.launchPersistentContext(profile, {
    executablePath: '/usr/bin/chromium', headless: true, viewport, ...options,
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run', '--disable-background-networking',
      '--disable-component-update', '--disable-sync', '--use-angle=swiftshader', '--enable-unsafe-swiftshader'],
  });
  await ctx.route(/\/dist\/app\.js(\?.*)?$/, (route) =>
    route.fulfill({ path: join(ROOT, 'clients', 'web', 'dist', 'app-test.js'), contentType: 'text/javascript' }));
  return ctx;
}

// Console errors and page errors of `page`, without the GL driver's performance notes.
export function collectErrors(page) {
  const logs = [];
  page.on('console', (m) => { if ((m.type() === 'error' || m.type() === 'warning') && !m.text().includes('GL Driver Message')) logs.push(m.text()); });
  page.on('pageerror', (e) => logs.push('pageerror: ' + e.message));
  return logs;
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
