// web_budget_check.mjs — the page's particle budget under node (clients/web/src/budget.js): the
// ladder it asks on, the rules that move a budget (link-bound, draw-bound, room to grow), and how
// the flame view draws a budget's subset so it keeps the flame's brightness and extent (flame.js:
// spacing, sprite sizes and emission from the header's total). The page asking for it against a
// real daemon is web_browser_check.mjs's. The last line is "test_web_budget: N passed, M failed".
import { checker } from './web_lib.mjs';
import { BUDGET_LADDER, DRAW_MAX, drawLimit, ladderFloor, nextBudget } from '../../clients/web/src/budget.js';
import { FlameView } from '../../clients/web/src/flame.js';

const c = checker('test_web_budget');
const near = (a, b) => Math.abs(a - b) <= 1e-9 * Math.max(1, Math.abs(b));

c.check(ladderFloor(150000) === 100000 && ladderFloor(200000) === 200000 && ladderFloor(999) === 1000 && ladderFloor(5e6) === 2000000,
  'ladderFloor: the largest 1-2-5 step at or below the value (the smallest below 1000)');
c.check(drawLimit(null) === DRAW_MAX && drawLimit('30000') === 20000 && drawLimit('x') === DRAW_MAX && drawLimit('-5') === DRAW_MAX,
  '?particles=N: a ladder step at or below N; absent or not a positive number: DRAW_MAX');

const base = { budget: 200000, limit: 200000, full: 59000, late: false, onTime: true, atTopRate: true, bytesPerSec: 8e6,
  bytesPerParticle: 4.5, fps: 30, drawFps: 60 };
c.check(nextBudget(base) === 200000, 'on time with every particle served: the budget stays');
c.check(nextBudget({ ...base, late: true, onTime: false, bytesPerSec: 2e6 }) === 10000,
  'late while drawing fast: what the bytes received carry at the stream\'s rate (0.8 x 2 MB/s / 30 fps / 4.5 B = 11.9k -> 10k)');
c.check(nextBudget({ ...base, late: true, onTime: false, bytesPerSec: 1e9 }) === 20000,
  'late on a wide link: at most half of what was served (59k -> 29.5k -> 20k)');
c.check(nextBudget({ ...base, budget: 1000, late: true, onTime: false }) === 1000, 'late at the smallest step: the budget stays (the rate cap takes over)');
c.check(nextBudget({ ...base, budget: 10000 }) === 20000, 'on time at the full rate with particles left out: one step up');
c.check(nextBudget({ ...base, budget: 10000, atTopRate: false }) === 10000, 'below the stream\'s rate: the rate grows first');
c.check(nextBudget({ ...base, budget: 20000, limit: 20000 }) === 20000, 'never above the page\'s own limit');
c.check(nextBudget({ ...base, full: 1e6, budget: 200000, drawFps: 12 }) === 100000, 'drawing under 20 frames/s with many particles: half as many');
c.check(nextBudget({ ...base, full: 9500, budget: 200000, drawFps: 12, late: true }) === 200000,
  'drawing under 20 frames/s with a small flame: the budget stays (its particles are not what is slow)');
c.check(BUDGET_LADDER.every((s, i) => i === 0 || s > BUDGET_LADDER[i - 1]), 'the ladder increases');

// The view: a subset of 1000 standing for 8000 particles.
const v = new FlameView('flame'), n = 1000;
const frame = (m) => ({ n: m, xyz: new Float32Array(3 * m), temp: new Float32Array(m).fill(1500), fuel: new Float32Array(m), flags: new Uint8Array(m), vel: null });
v.params = { h: 0.0035, particle_diameter: 0.5 }; // the default stream's spacing, which the gains are set for
v.showParticles(frame(n));
v.setUniforms(320, 240);
const r0 = v.splat.uniforms.radius.value, p0 = v.pbvr.uniforms.radius.value, g0 = v.hdr.uniforms.gain.value;
c.check(v.info().total === n && v.splat.uniforms.weight.value === 1 && near(p0, r0), 'a whole frame: every particle stands for itself');
v.showParticles(frame(n), 8 * n);
v.setUniforms(320, 240);
const u = v.splat.uniforms;
c.check(v.info().count === n && v.info().total === 8 * n, 'info: the subset\'s count and the stream\'s total');
c.check(near(u.radius.value, 2 * r0) && near(v.hdr.uniforms.radius.value, 2 * r0),
  'volume and hdr kernels grow with the spacing, (total / count)^(1/3) = 2', `${u.radius.value / r0}`);
c.check(near(u.weight.value, 2) && near(v.hdr.uniforms.gain.value, 2 * g0),
  'volume and hdr emission per particle x 2: summed over the kernels\' area the brightness holds');
c.check(near(v.pbvr.uniforms.radius.value, Math.sqrt(8) * p0), 'pbvr\'s opaque sprites cover the area of the left-out ones: x (total / count)^(1/2)');
v.showParticles(frame(n), 0);
v.setUniforms(320, 240);
c.check(v.splat.uniforms.weight.value === 1 && near(v.splat.uniforms.radius.value, r0), 'the next whole frame: back to one particle each');
// A finer stream (h 1.75 mm: half the spacing, 8x the particles in the same flame) draws each
// particle's emission at half and half as many pbvr sprites a particle, a coarser one larger
// sprites, so the flame keeps its brightness and coverage.
v.params = { h: 0.00175, particle_diameter: 0.5 };
v.setUniforms(320, 240);
c.check(near(v.splat.uniforms.weight.value, 0.5) && near(v.hdr.uniforms.gain.value, 0.5 * g0) && near(v.hdr.uniforms.radius.value, 0.5 * r0),
  'a finer stream: volume and hdr emission per particle in proportion to the spacing (x 1/2), kernels at its spacing');
c.check(near(v.pbvr.uniforms.radius.value, 0.5 * p0) && near(v.pbvr.uniforms.fill.value, 0.5),
  'a finer stream: pbvr\'s sprites at its spacing, half as many a particle, so their coverage holds');
v.params = { h: 0.007, particle_diameter: 0.5 };
v.setUniforms(320, 240);
c.check(near(v.pbvr.uniforms.radius.value, 2 * Math.SQRT2 * p0) && v.pbvr.uniforms.fill.value === 1 && near(v.hdr.uniforms.gain.value, 2 * g0),
  'a coarser stream (h 7 mm): pbvr\'s sprites x 2^(3/2), hdr emission x 2');
c.summary();
process.exit(c.failed ? 1 : 0);
