// web_views_check.mjs — the page's views (clients/web/src: FlameView, WaveView, SceneView,
// EyeView) against the contract main.js relies on (clients/web/src/view.js), under node
// without a GPU: each keeps viewFaults, the kinds are VIEW_KINDS one each, a view with
// nothing to show draws nothing and returns false, a frame of a kind no view knows is
// ignored, dispose works; and viewFaults itself names what a broken view lacks. The last line
// is "test_web_views: N passed, M failed".
import { checker } from './web_lib.mjs';
import { VIEW_KINDS, viewFaults } from '../../clients/web/src/view.js';
import { FlameView } from '../../clients/web/src/flame.js';
import { WaveView } from '../../clients/web/src/wave.js';
import { SceneView } from '../../clients/web/src/scene.js';
import { EyeView } from '../../clients/web/src/eye.js';

// SceneView paints its feature textures on a 2D canvas: one that takes every call.
globalThis.document = { createElement: () => ({ getContext: () => new Proxy({}, { get: () => () => {} }) }) };

const c = checker('test_web_views');
const wave = new WaveView('energy');
const views = [new FlameView('flame'), wave, new SceneView('energy', wave.wt), new EyeView('eye')];
const rect = { x: 0, y: 0, w: 320, h: 240 };

for (const v of views) {
  const faults = viewFaults(v);
  c.check(faults.length === 0, `${v.constructor.name} keeps the View contract`, faults.join('; '));
}
c.check(JSON.stringify(views.map((v) => v.kind)) === JSON.stringify(VIEW_KINDS), 'one view of each kind in VIEW_KINDS, in its order',
  views.map((v) => v.kind).join(', '));
for (const v of views) {
  let drew, err = '';
  try { drew = v.render(null, rect, 0); } catch (e) { err = e.message; }
  c.check(drew === false && !err, `${v.constructor.name}: nothing to show yet, render draws nothing and returns false`, err || String(drew));
}
const unknown = { kind: 99, codec: 1, channel: 1, seq: 1n, paramRev: 1, headerBytes: 64, payloadBytes: 0, count: 0, height: 0 };
for (const v of views) {
  let took, drew, err = '';
  try { took = v.onFrame(unknown, new ArrayBuffer(64)); drew = v.render(null, rect, 0); } catch (e) { err = e.message; }
  c.check(took === false && drew === false && !err, `${v.constructor.name}: a frame of an unknown kind is ignored`, err || `${took} ${drew}`);
}
for (const v of views) {
  let err = '';
  try { v.dispose(); } catch (e) { err = e.message; }
  c.check(!err, `${v.constructor.name}: dispose`, err);
}

const broken = viewFaults({ kind: 'fire', stream: '', render() { return false; }, info: 3 });
const want = ['kind "fire" is not one of', 'stream is not a stream name', 'setParams() is missing', 'onFrame() is missing',
  'dispose() is missing', 'info is not a function'];
c.check(broken.length === want.length && want.every((w, i) => broken[i].startsWith(w)), 'viewFaults names what a broken view lacks',
  broken.join('; '));
c.check(viewFaults(null).length === 1, 'viewFaults: null is no view');
c.summary();
process.exit(c.failed ? 1 : 0);
