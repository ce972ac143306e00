// fxs_particles.js — browser/Node decoder of fxstream.v1 kind 1 particle payloads
// (codec 2, one block, and codec 3, blocks back to back: protocol/PROTOCOL.md §7.5) and
// parser of the 64-byte frame header (§7.1).
//
// Plain ES module, no dependencies, no build step: the entropy stage is an adaptive
// binary range coder (LZMA's) that takes a few lines here (Decoder.bit, the one place a
// decision is decoded). Mirrors protocol/fxs_particles_dec.c (the C decoder) value for value:
// positions, T, F and the optional velocities are float32(lo + q * step) or
// float32(q * step) computed in double, so both decoders give identical floats (checked
// against tests/data/particles/).
//
// The same decoder in C runs here as WebAssembly where it can (loadWasmDecoder), about
// twice as fast; this one is its fallback and the reference the tests hold both to.
//
//   import { parseHeader, decode } from './fxs_particles.js';
//   const h = parseHeader(msg);                       // throws on a bad frame
//   if (h.kind === 1 && (h.codec === 2 || h.codec === 3)) {
//     const p = decode(new Uint8Array(msg, h.headerBytes, h.payloadBytes));
//     // p.n, p.xyz (Float32Array 3n), p.temp, p.fuel (Float32Array n), p.flags (Uint8Array n),
//     // p.vel (Float32Array 3n, or null when the stream sends no velocities)
//   }

export const KIND_PARTICLES = 1;
export const CODEC_PARTICLES = 2;
export const CODEC_PARTICLES_BLOCKS = 3;
export const MAX_PARTICLES = 1 << 22;
export const MAX_BLOCKS = 64;

const HEADER_BYTES = 64;
const PROB_BITS = 12;
const PROB_INIT = 1 << (PROB_BITS - 1);
const ADAPT = 5;
const TOP = 1 << 24;
const NEAR = 8, SAME = 16;
const MAXK = 24;
const T_U = 2, F_U = 2, V_U = 2;
const SMALL_ESC = 7, SPROBS = 8 + MAXK; // small counts: a 3-level tree, then the escape's class
const VERSION = 3;
const HAS_VEL = 0x10, VEL_BLOCK = 16;
const IPROBS = (u) => u + 2 * MAXK;

function bytesOf(buf) {
  if (buf instanceof Uint8Array) return buf;
  if (buf instanceof ArrayBuffer) return new Uint8Array(buf);
  if (ArrayBuffer.isView(buf)) return new Uint8Array(buf.buffer, buf.byteOffset, buf.byteLength);
  throw new TypeError('fxs_particles: expected an ArrayBuffer or Uint8Array');
}

function fail(msg) {
  throw new Error('particles: ' + msg);
}

/** Parses the 64-byte frame header (PROTOCOL.md §7.1, reading rules §7.2). */
export function parseHeader(buf) {
  const b = bytesOf(buf);
  if (b.length < HEADER_BYTES || b[0] !== 0x46 || b[1] !== 0x58 || b[2] !== 0x53 || b[3] !== 0x31)
    throw new Error('frame: short or bad magic');
  const v = new DataView(b.buffer, b.byteOffset, b.byteLength);
  const h = {
    headerBytes: v.getUint16(4, true),
    kind: v.getUint16(6, true),
    channel: v.getUint32(8, true),
    paramRev: v.getUint32(12, true),
    seq: v.getBigUint64(16, true),
    simTime: v.getFloat64(24, true),
    serverTimeUs: v.getBigUint64(32, true),
    codec: v.getUint32(40, true),
    payloadBytes: v.getUint32(44, true),
    count: v.getUint32(48, true),
    height: v.getUint32(52, true),
    flags: v.getUint32(56, true),
    total: v.getUint32(60, true), // particles: the stream frame's count this one is a budget's subset of (§3.5), else 0
  };
  h.width = h.count;
  if (h.headerBytes < HEADER_BYTES || h.headerBytes > b.length) throw new Error('frame: bad header_bytes');
  if (h.payloadBytes !== b.length - h.headerBytes) throw new Error('frame: payload_bytes does not match');
  return h;
}

/** The payload of a frame as a Uint8Array view (no copy). */
export function payloadOf(buf, header) {
  const b = bytesOf(buf);
  return b.subarray(header.headerBytes, header.headerBytes + header.payloadBytes);
}

function parsePayloadHeader(b) {
  if (b.length < HEADER_BYTES || b[0] !== 0x46 || b[1] !== 0x58 || b[2] !== 0x50 || b[3] !== 0x32)
    fail('not a codec 2 payload (short or bad magic)');
  if (b[4] !== VERSION) fail(`unsupported version (this decoder reads version ${VERSION})`);
  if ((b[11] & ~HAS_VEL) > 1) fail('unknown attribute mode');
  const v = new DataView(b.buffer, b.byteOffset, b.byteLength);
  const f = { posBits: b[5], tempBits: b[6], fuelBits: b[7], abits: [b[8], b[9], b[10]], mode: b[11] & 15, n: v.getUint32(12, true) };
  f.vel = (b[11] & HAS_VEL) !== 0;
  f.headerBytes = HEADER_BYTES + (f.vel ? VEL_BLOCK : 0);
  if (f.vel) { // the velocity block (§7.5.7)
    if (b.length < f.headerBytes) fail('not a codec 2 payload (short or bad magic)');
    if (b[65] || b[66] || b[67]) fail('non-zero reserved bytes in the velocity block');
    f.velBits = b[64];
    f.vmax = [v.getFloat32(68, true), v.getFloat32(72, true), v.getFloat32(76, true)];
  }
  f.lo = [v.getFloat32(16, true), v.getFloat32(20, true), v.getFloat32(24, true), v.getFloat32(40, true), v.getFloat32(48, true)];
  f.hi = [v.getFloat32(28, true), v.getFloat32(32, true), v.getFloat32(36, true), v.getFloat32(44, true), v.getFloat32(52, true)];
  f.rcBytes = v.getUint32(56, true);
  f.bitsBytes = v.getUint32(60, true);
  if (f.posBits < 8 || f.posBits > 24 || f.tempBits < 2 || f.tempBits > 16 || f.fuelBits < 2 || f.fuelBits > 16)
    fail('bad bit widths');
  for (let a = 0; a < 3; a++) if (f.abits[a] > f.posBits) fail('bad axis bits');
  if (f.n > MAX_PARTICLES) fail('particle count over the limit');
  for (let c = 0; c < 5; c++)
    if (!Number.isFinite(f.lo[c]) || !Number.isFinite(f.hi[c]) || f.lo[c] > f.hi[c]) fail('bad bounds');
  if (f.vel && (f.velBits < 2 || f.velBits > 16)) fail('bad velocity bits');
  if (f.vel && !f.vmax.every((m) => Number.isFinite(m) && m >= 0)) fail('bad velocity bounds');
  return f;
}

const corrupt = () => fail('corrupt particle data');

// The decoder of both sections: one adaptive binary range decoder (LZMA's, 12-bit
// probabilities) for every modelled decision, and the LSB-first raw bits. decide() is the one
// place a decision is decoded (bit(): with an adaptive probability); int(), tree() and
// small() are the shapes built on it (§7.5.4).
// range and code are int32 bit patterns compared unsigned; Math.imul keeps the bound exact
// (< 2^32). Raw bits: at most 24 per read (acc holds < 32 bits).
class Decoder {
  constructor(b, rp, rend, bend) {
    if (rend - rp < 5 || b[rp] !== 0) corrupt();
    this.b = b; this.rp = rp + 5; this.rend = rend; this.bp = rend; this.bend = bend;
    this.range = -1; // 0xFFFFFFFF
    this.code = (b[rp + 1] << 24) | (b[rp + 2] << 16) | (b[rp + 3] << 8) | b[rp + 4];
    if (this.code === -1) corrupt();
    this.acc = 0; this.cnt = 0;
  }

  /** One decision with probability P[i] (of a 0), which then adapts; returns the bit. */
  bit(P, i) {
    const pr = P[i], bit = this.decide(pr);
    P[i] = bit ? pr - (pr >> ADAPT) : pr + (((1 << PROB_BITS) - pr) >> ADAPT);
    return bit;
  }

  /** One decision with the probability pr (of a 0), not adapted; returns the bit. */
  decide(pr) {
    const bound = Math.imul(this.range >>> PROB_BITS, pr);
    let bit;
    if ((this.code >>> 0) < (bound >>> 0)) { this.range = bound; bit = 0; }
    else { this.code = (this.code - bound) | 0; this.range = (this.range - bound) | 0; bit = 1; }
    if ((this.range >>> 0) < TOP) {
      if (this.rp >= this.rend) corrupt();
      this.range <<= 8;
      this.code = (this.code << 8) | this.b[this.rp++];
    }
    return bit;
  }

  /** m raw bits (m <= 24), low bit first. */
  raw(m) {
    let acc = this.acc, cnt = this.cnt;
    while (cnt < m) { if (this.bp >= this.bend) corrupt(); acc |= this.b[this.bp++] << cnt; cnt += 8; }
    this.acc = acc >>> m; this.cnt = cnt - m;
    return acc & ((1 << m) - 1);
  }

  /** An integer z >= 0 with the model P[o ...] of u + 48 probabilities: u unary decisions,
   *  the Exp-Golomb class k in unary, the top mantissa bit by class, k - 1 bits raw. */
  int(P, o, u) {
    for (let i = 0; i < u; i++) if (!this.bit(P, o + i)) return i;
    let k = 0;
    while (this.bit(P, o + u + k)) if (++k === MAXK) corrupt();
    if (!k) return u;
    const top = this.bit(P, o + u + MAXK + k);
    return ((((2 + top) << (k - 1)) | this.raw(k - 1)) >>> 0) + u - 1;
  }

  /** A small count with the model P[o ...] of SPROBS probabilities: s = 0 ... 7 down a
   *  3-level tree (P[o + 1 ... o + 7]); s < 7 is the count, 7 an escape: e = count - 6 >= 1,
   *  its class k in unary (P[o + 8 + i]), then its low k bits as direct bits (probability
   *  PROB_INIT, not adapted), high first. */
  small(P, o) {
    const s = this.tree(P, o, 3);
    if (s < SMALL_ESC) return s;
    let k = 0;
    while (this.bit(P, o + 8 + k)) if (++k === MAXK) corrupt();
    let e = 1;
    for (let i = 0; i < k; i++) e = 2 * e + this.decide(PROB_INIT);
    return e + SMALL_ESC - 1;
  }

  /** A value tree of `bits` bits with the model P[o + 1 ... o + 255]: the top min(bits, 8)
   *  bits high first (m = 1, then 2m + bit), then the low bits - 8 raw. */
  tree(P, o, bits) {
    const low = bits > 8 ? bits - 8 : 0, end = 1 << (bits - low);
    let m = 1;
    while (m < end) m = 2 * m + this.bit(P, o + m);
    return low ? ((m - end) << low) | this.raw(low) : m - end;
  }
}

const unzigzag = (z) => (z % 2 ? -(z + 1) / 2 : z / 2);
const rclass = (z) => (z < 2 ? z : z >= 32 ? 6 : 32 - Math.clz32(z));
function cclass(c) {
  if (c <= 8) return c - 2;
  if (c <= 12) return 7;
  if (c <= 16) return 8;
  if (c > 256) return 13;
  return 9 + (31 - Math.clz32(c - 1)) - 4;
}
const CCLASS = new Uint8Array(257);
for (let c = 2; c <= 256; c++) CCLASS[c] = cclass(c);
const models = (n) => new Uint16Array(n).fill(PROB_INIT);

// Splits from the top bit down; at each bit x, then y, then z (axes that have it).
function schedule(abits) {
  const axis = [], left = [], l = abits.slice();
  const top = Math.max(...abits);
  for (let b = top - 1; b >= 0; b--)
    for (let a = 0; a < 3; a++)
      if (b < abits[a]) {
        left.push(l.slice());
        axis.push(a);
        l[a]--;
      }
  left.push([0, 0, 0]);
  return { axis, left, depth: axis.length };
}

// The position tree level by level (§7.5.3): each level's nodes in order, a count each
// (small counts, models by count class and axis), the children with two or more points
// making the next level and lone ones the leaves, whose remaining bits come after the
// whole tree. A node's first particle places it, so the coordinates (< 2^24) go to X, Y, Z
// in tree order. Nodes and leaves are records of 5 integers in typed arrays: count (a
// leaf: its depth), first particle, x, y, z bits above its depth.
function decodeTree(f, d, X, Y, Z) {
  const { axis, left, depth } = schedule(f.abits);
  const P = models(14 * 3 * SPROBS), n = f.n, R = 5;
  let cur = new Int32Array(R * ((n >>> 1) + 1)), next = new Int32Array(cur.length), ncur = 0;
  const leaves = new Int32Array(R * n);
  let nl = 0;
  if (n === 1) nl = 1; // the root is the only leaf, at depth 0, all bits raw
  else if (n > 1) { cur[0] = n; ncur = 1; }
  for (let k = 0; k < depth && ncur; k++) {
    const a = axis[k], bit = 1 << (left[k][a] - 1);
    let nn = 0;
    for (let i = 0; i < R * ncur; i += R) {
      const c = cur[i], at = cur[i + 1], x = cur[i + 2], y = cur[i + 3], z = cur[i + 4];
      const lo = (c >>> 1) + unzigzag(d.small(P, ((c <= 256 ? CCLASS[c] : 13) * 3 + a) * SPROBS));
      if (lo < 0 || lo > c) corrupt();
      for (let h = 0; h < 2; h++) { // lower child, then upper
        const cc = h ? c - lo : lo, o = h ? at + lo : at, u = h ? bit : 0;
        if (cc === 0) continue;
        const out = cc >= 2 ? next : leaves, j = cc >= 2 ? R * nn++ : R * nl++;
        out[j] = cc >= 2 ? cc : k + 1; out[j + 1] = o;
        out[j + 2] = a === 0 ? x + u : x; out[j + 3] = a === 1 ? y + u : y; out[j + 4] = a === 2 ? z + u : z;
      }
    }
    [cur, next, ncur] = [next, cur, nn];
  }
  for (let i = 0; i < R * ncur; i += R) // identical points at full depth
    for (let j = cur[i + 1]; j < cur[i + 1] + cur[i]; j++) { X[j] = cur[i + 2]; Y[j] = cur[i + 3]; Z[j] = cur[i + 4]; }
  for (let i = 0; i < R * nl; i += R) {
    const l = left[leaves[i]], at = leaves[i + 1];
    X[at] = leaves[i + 2] + d.raw(l[0]); Y[at] = leaves[i + 3] + d.raw(l[1]); Z[at] = leaves[i + 4] + d.raw(l[2]);
  }
}

function outputs(f) {
  const r = Math.max(f.hi[0] - f.lo[0], f.hi[1] - f.lo[1], f.hi[2] - f.lo[2], 0);
  return {
    sp: r / (2 ** f.posBits - 1),
    st: (f.hi[3] - f.lo[3]) / (2 ** f.tempBits - 1),
    sf: (f.hi[4] - f.lo[4]) / (2 ** f.fuelBits - 1),
  };
}

// The nearest of particles j - 1 ... j - NEAR (the latest on ties; -1 for j = 0); squares
// of the quantised distances (< 2^50) are exact in doubles. The first kmax squared
// distances go to dist[k - 1] for mode 1's same-flags search.
function nearest(X, Y, Z, j, dist) {
  const cx = X[j], cy = Y[j], cz = Z[j], kn = j < NEAR ? j : NEAR;
  let nb = -1, bd = Infinity;
  for (let k = 1; k <= kn; k++) {
    const i = j - k, dx = cx - X[i], dy = cy - Y[i], dz = cz - Z[i], dd = dx * dx + dy * dy + dz * dz;
    dist[k - 1] = dd;
    if (dd < bd) { bd = dd; nb = i; }
  }
  return nb;
}

// Attribute mode 0: flags, T and F predicted from the nearest of the 8 particles before.
function decodeAttrs0(f, d, X, Y, Z, NB, out) {
  const n = f.n, TP = IPROBS(T_U), FP = IPROBS(F_U);
  const pt = models(7 * 8 * 2 * TP), pf = models(7 * 2 * 2 * FP), same = models(16), tree = models(256);
  const qt = new Int32Array(n), qf = new Int32Array(n), dist = new Float64Array(NEAR);
  const { sp, st, sf } = outputs(f);
  const tlim = 2 ** f.tempBits, flim = 2 ** f.fuelBits;
  const [lx, ly, lz, lt, lf] = f.lo;
  const { xyz, temp, fuel, flags } = out;
  let zt = 0, zf = 0;
  for (let j = 0; j < n; j++) {
    const nb = NB[j] = nearest(X, Y, Z, j, dist);
    const nt = nb < 0 ? 0 : qt[nb], nf = nb < 0 ? 0 : qf[nb], nfl = nb < 0 ? 0 : flags[nb], f0 = nf === 0 ? 1 : 0;
    let v = nfl;
    if (d.bit(same, (nfl & 7) * 2 + f0)) {
      v = d.tree(tree, 0, 8);
      if (v === nfl) corrupt();
    }
    zt = d.int(pt, ((rclass(zt) * 8 + (v & 7)) * 2 + f0) * TP, T_U);
    zf = d.int(pf, ((rclass(zf) * 2 + f0) * 2 + ((v >> 2) & 1)) * FP, F_U);
    const t = nt + unzigzag(zt), fu = nf + unzigzag(zf);
    if (t < 0 || t >= tlim || fu < 0 || fu >= flim) corrupt();
    qt[j] = t; qf[j] = fu; flags[j] = v;
    xyz[3 * j] = lx + X[j] * sp;
    xyz[3 * j + 1] = ly + Y[j] * sp;
    xyz[3 * j + 2] = lz + Z[j] * sp;
    temp[j] = lt + t * st;
    fuel[j] = lf + fu * sf;
  }
}

// Attribute mode 1: flags, T and F as value trees in contexts of the neighbours' values.
function decodeAttrs1(f, d, X, Y, Z, NB, out) {
  const n = f.n, tb = f.tempBits, fb = f.fuelBits;
  const vsame = models(18), vfl = models(9 * 256), vt = models(72 * 256), vf0 = models(256), vf = models(64 * 256);
  const qt = new Int32Array(n), qf = new Int32Array(n), last = new Int32Array(256).fill(-1);
  const dist = new Float64Array(NEAR);
  const { sp, st, sf } = outputs(f);
  const flim = 2 ** fb, t3 = tb > 3 ? tb - 3 : 0, t4 = tb > 4 ? tb - 4 : 0;
  const [lx, ly, lz, lt, lf] = f.lo;
  const { xyz, temp, fuel, flags } = out;
  for (let j = 0; j < n; j++) {
    const nb = NB[j] = nearest(X, Y, Z, j, dist);
    const nfl = nb < 0 ? 0 : flags[nb], nc = nb < 0 ? 8 : nfl & 7, nf0 = nb < 0 || qf[nb] === 0 ? 1 : 0;
    let v = nfl;
    if (d.bit(vsame, nc * 2 + nf0)) {
      v = d.tree(vfl, nc * 256, 8);
      if (v === nfl) corrupt();
    }
    const c = v & 7;
    flags[j] = v;
    // the same-flags neighbour: the nearest of j - 1 ... j - SAME with flags v, else last[v]
    const cx = X[j], cy = Y[j], cz = Z[j], kn = j < NEAR ? j : NEAR, kmax = j < SAME ? j : SAME;
    let sb = -1, bd = Infinity;
    for (let k = 1; k <= kn; k++) if (flags[j - k] === v && dist[k - 1] < bd) { bd = dist[k - 1]; sb = j - k; }
    for (let k = NEAR + 1; k <= kmax; k++) {
      const i = j - k;
      if (flags[i] !== v) continue;
      const dx = cx - X[i], dy = cy - Y[i], dz = cz - Z[i], dd = dx * dx + dy * dy + dz * dz;
      if (dd < bd) { bd = dd; sb = i; }
    }
    if (sb < 0) sb = last[v];
    const t = d.tree(vt, (c * 9 + (sb < 0 ? 8 : qt[sb] >>> t3)) * 256, tb);
    let fu = 0;
    if (d.bit(vf0, (c * 16 + (t >>> t4)) * 2 + nf0)) {
      fu = d.tree(vf, (c * 8 + (t >>> t3)) * 256, fb) + 1;
      if (fu >= flim) corrupt();
    }
    qt[j] = t; qf[j] = fu; last[v] = j;
    xyz[3 * j] = lx + cx * sp;
    xyz[3 * j + 1] = ly + cy * sp;
    xyz[3 * j + 2] = lz + cz * sp;
    temp[j] = lt + t * st;
    fuel[j] = lf + fu * sf;
  }
}

// Velocities (§7.5.7), after the attributes: per particle and axis the residual against
// the neighbour NB[j], in contexts of the residual decoded just before (x: the previous
// particle's x; y, z: this particle's x, y) and the particle's type.
function decodeVel(f, d, NB, out) {
  const n = f.n, VP = IPROBS(V_U), P = models(3 * 7 * 4 * VP), qv = new Int32Array(3 * n);
  const qmax = 2 ** (f.velBits - 1) - 1, step = f.vmax.map((m) => m / qmax);
  const { flags, vel } = out;
  let zx = 0;
  for (let j = 0; j < n; j++) {
    const nb = NB[j], type = flags[j] & 3;
    let zb = zx;
    for (let a = 0; a < 3; a++) {
      const z = d.int(P, ((a * 7 + rclass(zb)) * 4 + type) * VP, V_U);
      const q = (nb < 0 ? 0 : qv[3 * nb + a]) + unzigzag(z);
      if (q < -qmax || q > qmax) corrupt();
      qv[3 * j + a] = q;
      vel[3 * j + a] = q * step[a];
      zb = z;
      if (a === 0) zx = z;
    }
  }
}

// One block (§7.5.1–7.5.7) of b, whose header f was parsed, into out (views of its slice).
function decodeBlock(f, b, out) {
  const n = f.n;
  if (n === 0) {
    if (f.rcBytes || f.bitsBytes) fail('bad sizes');
    return;
  }
  const rend = f.headerBytes + f.rcBytes;
  const d = new Decoder(b, f.headerBytes, rend, rend + f.bitsBytes);
  const X = new Float64Array(n), Y = new Float64Array(n), Z = new Float64Array(n), NB = new Int32Array(n);
  decodeTree(f, d, X, Y, Z);
  (f.mode ? decodeAttrs1 : decodeAttrs0)(f, d, X, Y, Z, NB, out);
  if (f.vel) decodeVel(f, d, NB, out);
  if (d.rp !== d.rend) fail('corrupt particle data (range coder section not consumed exactly)');
  if (d.bp !== d.bend || d.acc !== 0) fail('corrupt particle data (raw bits not consumed exactly)');
}

// The blocks of a payload (§7.5.8): [{f, at, len}], checked; all carry velocities or none.
function blocksOf(b) {
  const blocks = [];
  let total = 0;
  for (let at = 0; at < b.length || blocks.length === 0;) {
    const f = parsePayloadHeader(b.subarray(at));
    const len = f.headerBytes + f.rcBytes + f.bitsBytes;
    if (len > b.length - at) fail('section sizes do not match the payload length');
    if (blocks.length && f.vel !== blocks[0].f.vel) fail('blocks disagree on velocities');
    if (blocks.length === MAX_BLOCKS) fail('more blocks than allowed');
    if ((total += f.n) > MAX_PARTICLES) fail('particle count over the limit');
    blocks.push({ f, at, len });
    at += len;
  }
  return blocks;
}

/**
 * Decodes a kind 1 payload of one block (codec 2) or more (codec 3), the bytes after the
 * frame header; the particles come block after block.
 * Returns {n, xyz: Float32Array(3n), temp: Float32Array(n), fuel: Float32Array(n), flags: Uint8Array(n),
 * vel: Float32Array(3n) (vx, vy, vz) when the payload carries velocities (§7.5.7), else null}.
 * Throws Error('particles: ...') on truncated, corrupt or oversized input.
 */
export function decode(buf) {
  const b = bytesOf(buf), blocks = blocksOf(b);
  const n = blocks.reduce((s, k) => s + k.f.n, 0), vel = blocks[0].f.vel;
  const out = { n, xyz: new Float32Array(3 * n), temp: new Float32Array(n), fuel: new Float32Array(n), flags: new Uint8Array(n),
    vel: vel ? new Float32Array(3 * n) : null };
  let o = 0;
  for (const { f, at, len } of blocks) {
    decodeBlock(f, b.subarray(at, at + len), { xyz: out.xyz.subarray(3 * o), temp: out.temp.subarray(o),
      fuel: out.fuel.subarray(o), flags: out.flags.subarray(o), vel: vel ? out.vel.subarray(3 * o) : null });
    o += f.n;
  }
  return out;
}

/**
 * The C decoder (protocol/fxs_particles_dec.c) compiled to WebAssembly (make builds
 * clients/web/dist/fxs_particles.wasm): resolves to a function with decode()'s contract,
 * the same particles and the same "particles: ..." errors, about twice as fast. source: the
 * module's bytes (ArrayBuffer, typed array), a WebAssembly.Module, or a URL to fetch.
 * Rejects when the module cannot be compiled here (e.g. a browser without WebAssembly SIMD):
 * decode() is then the decoder to use.
 */
export async function loadWasmDecoder(source) {
  let module = source;
  if (typeof source === 'string' || source instanceof URL) {
    const r = await fetch(source);
    if (!r.ok) throw new Error(`particles: cannot load ${source}: HTTP ${r.status}`);
    module = await r.arrayBuffer();
  }
  if (!(module instanceof WebAssembly.Module)) module = await WebAssembly.compile(bytesOf(module));
  const w = (await WebAssembly.instantiate(module, {})).exports;
  const view = (Type, at, count) => new Type(w.memory.buffer, at, count).slice(); // copies: memory can grow
  return (buf) => {
    const b = bytesOf(buf), at = w.fxs_wasm_alloc(b.length);
    if (!at) throw new Error('particles: out of memory');
    try {
      new Uint8Array(w.memory.buffer, at, b.length).set(b);
      if (w.fxs_wasm_decode(at, b.length)) {
        const msg = new Uint8Array(w.memory.buffer, w.fxs_wasm_error());
        throw new Error(new TextDecoder().decode(msg.subarray(0, msg.indexOf(0))));
      }
      const n = w.fxs_wasm_n(), vel = w.fxs_wasm_vel();
      return { n, xyz: view(Float32Array, w.fxs_wasm_xyz(), 3 * n), temp: view(Float32Array, w.fxs_wasm_temp(), n),
        fuel: view(Float32Array, w.fxs_wasm_fuel(), n), flags: view(Uint8Array, w.fxs_wasm_flags(), n),
        vel: vel ? view(Float32Array, vel, 3 * n) : null };
    } finally {
      w.fxs_wasm_free(at);
    }
  };
}

/** Decodes a whole kind 1 frame (header + payload); returns {header, particles}. */
export function decodeFrame(buf) {
  const header = parseHeader(buf);
  if (header.kind !== KIND_PARTICLES || (header.codec !== CODEC_PARTICLES && header.codec !== CODEC_PARTICLES_BLOCKS))
    throw new Error('frame: not a codec 2 or 3 particle frame');
  const particles = decode(payloadOf(buf, header));
  if (particles.n !== header.count) throw new Error('frame: count does not match the payload');
  return { header, particles };
}
