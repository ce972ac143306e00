// rig.js — decoder of fxstream.v1 kind 3 light-rig payloads (codec 1 "rig1",
// protocol/PROTOCOL.md §7.7) and the JavaScript side of the client recipe: the light
// position of a point (nearest point of the dominant centre-line segment) and the clamped
// shadow direction of a caster, with the thesis's sign error fixed (digest 003 §6 gap 1).
//
// Plain ES module without dependencies so node tests it against the C encoder's frames
// (tests/integration/test_web_decoders.sh); mirrors protocol/fxs_rig.c.

export const KIND_LIGHT_RIG = 3;
export const CODEC_LIGHT_RIG = 1;
export const SEG_FLOATS = 10; // C xyz, D xyz, a_lo, a_hi, strength, (source, index packed below)
const HEADER = 32, SEG = 40, CONST_FIXED = 96, BAND = 16, MAX_SEG = 64, MAX_BANDS = 8;

function fail(msg) { throw new Error('rig: ' + msg); }

/** Decodes a payload (Uint8Array). Returns {nSeg, seg: Float32Array(10 n), source:
 * Uint16Array(n), index: Uint16Array(n), constantsId, hasConstants, constants|null}. */
export function decodeRig(b) {
  if (!(b instanceof Uint8Array)) b = new Uint8Array(b);
  if (b.length < HEADER || b[0] !== 0x46 || b[1] !== 0x58 || b[2] !== 0x52 || b[3] !== 0x31) fail('short or bad magic');
  const v = new DataView(b.buffer, b.byteOffset, b.byteLength);
  if (v.getUint16(4, true) !== 1) fail('unsupported version');
  const hb = v.getUint16(6, true), n = v.getUint16(8, true), sb = v.getUint16(10, true);
  const flags = v.getUint32(12, true), constantsId = v.getUint32(16, true), cb = v.getUint32(20, true);
  const hasConstants = (flags & 1) !== 0;
  if (hb < HEADER || sb < SEG || n > MAX_SEG) fail('bad sizes');
  if ((!hasConstants && cb) || (hasConstants && cb < CONST_FIXED) || hb + n * sb + cb !== b.length) fail('sizes do not add up');
  const seg = new Float32Array(SEG_FLOATS * n), source = new Uint16Array(n), index = new Uint16Array(n);
  for (let i = 0; i < n; i++) {
    const o = hb + i * sb;
    for (let k = 0; k < 9; k++) seg[SEG_FLOATS * i + k] = v.getFloat32(o + 4 * k, true);
    source[i] = v.getUint16(o + 36, true);
    index[i] = v.getUint16(o + 38, true);
  }
  let constants = null;
  if (hasConstants) {
    const c = hb + n * sb;
    const f = (o) => v.getFloat32(c + o, true), f3 = (o) => [f(o), f(o + 4), f(o + 8)];
    const nb = v.getUint16(c, true);
    if (nb < 1 || nb > MAX_BANDS || cb < CONST_FIXED + nb * BAND) fail('bad band count');
    const cf = v.getUint16(c + 2, true);
    constants = {
      flags: cf, features: !!(cf & 1), outline: !!(cf & 2), shadow: !!(cf & 4),
      strength: f(4), outlineWidth: f(8), outlineRgb: f3(12),
      shadowTheta: f(24), shadowOpacity: f(28), shadowRgb: f3(32),
      planeI: f3(44), planeY: f3(56), planeX: f3(68), planeZ: f3(80),
      bands: [],
    };
    for (let i = 0; i < nb; i++) constants.bands.push({ mMin: f(CONST_FIXED + BAND * i), rgb: f3(CONST_FIXED + BAND * i + 4) });
  }
  return { nSeg: n, seg, source, index, constantsId, hasConstants, constants };
}

/** Keeps the constants across frames that omit them (PROTOCOL.md §7.7): returns the rig
 * with .constants filled from the cache when the ids match, else null constants. */
export class RigState {
  constructor() { this.cache = new Map(); this.rig = null; }
  update(rig) {
    if (rig.hasConstants) { this.cache.clear(); this.cache.set(rig.constantsId, rig.constants); }
    else rig.constants = this.cache.get(rig.constantsId) || null;
    this.rig = rig;
    return rig;
  }
}

const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];

/** Nearest point of segment i to M (eq. 2.1-2.2 on a capsule). */
export function nearestOnSegment(rig, i, M) {
  const s = rig.seg, o = SEG_FLOATS * i;
  let a = (M[0] - s[o]) * s[o + 3] + (M[1] - s[o + 1]) * s[o + 4] + (M[2] - s[o + 2]) * s[o + 5];
  a = Math.min(Math.max(a, s[o + 6]), s[o + 7]);
  return [s[o] + a * s[o + 3], s[o + 1] + a * s[o + 4], s[o + 2] + a * s[o + 5]];
}

/** The light position of M: nearest point of the segment with the largest strength/distance
 * among those with strength > 0; null when none lights. */
export function pointLight(rig, M) {
  let best = null, bestScore = 0;
  for (let i = 0; i < rig.nSeg; i++) {
    const st = rig.seg[SEG_FLOATS * i + 8];
    if (!(st > 0)) continue;
    const E = nearestOnSegment(rig, i, M);
    const d = Math.hypot(E[0] - M[0], E[1] - M[1], E[2] - M[2]);
    const score = st / Math.max(d, 1e-6);
    if (best === null || score > bestScore) { best = E; bestScore = score; }
  }
  return best;
}

/** m = N·normalize(E − M), not clamped at 0 (eq. 2.4). */
export function shadeM(E, M, N) {
  const L = [E[0] - M[0], E[1] - M[1], E[2] - M[2]], l = Math.hypot(...L);
  if (l < 1e-9) return 1;
  return Math.max(-1, Math.min(1, dot(N, L) / l));
}

/** The band colour of m. */
export function rampColor(constants, m) {
  let pick = 0;
  constants.bands.forEach((b, i) => { if (m >= b.mMin) pick = i; });
  return constants.bands[pick].rgb;
}

/** Shadow direction k for light direction e = (B − W)/|B − W| (eqs. 2.13-2.22). prev is an
 * object {i: [x,y,z]|null} holding the previous frame's in-plane direction (gap 11).
 * Returns {k, lambda, clamped}. */
export function shadowDir(c, e, prev = { i: null }) {
  const Y = c.planeY, X = c.planeX, Z = c.planeZ, theta = c.shadowTheta;
  let n = Math.hypot(...e);
  e = n < 1e-12 ? [-Y[0], -Y[1], -Y[2]] : [e[0] / n, e[1] / n, e[2] / n]; // B on the axis: straight down
  const lambda = Math.acos(Math.max(-1, Math.min(1, -dot(e, Y))));
  if (lambda <= theta) return { k: e, lambda, clamped: false };
  const ex = dot(e, X), ez = dot(e, Z);
  const f = [ex * X[0] + ez * Z[0], ex * X[1] + ez * Z[1], ex * X[2] + ez * Z[2]];
  n = Math.hypot(...f);
  let i;
  if (n > 1e-9) { i = [f[0] / n, f[1] / n, f[2] / n]; prev.i = i; }
  else i = prev.i || X; // light straight below: keep the previous frame's direction
  // Sign fix, digest 003 §6 gap 1: the thesis's j = i × Y (eqs. 2.17-2.22) turns i towards +Y
  // (angle π − θ from −Y: a shadow towards the light, hidden by eq. 2.32). Rotate the other way:
  const s = Math.sin(theta), co = Math.cos(theta);
  return { k: [s * i[0] - co * Y[0], s * i[1] - co * Y[1], s * i[2] - co * Y[2]], lambda, clamped: true };
}
