// fxs_particles.js — browser/Node decoder of fxstream.v1 kind 1 particle payloads
// (codec 2, protocol/PROTOCOL.md §7.5) and parser of the 64-byte frame header (§7.1).
//
// Plain ES module, no dependencies, no build step: the entropy stage is an adaptive
// binary range coder (LZMA's) that takes a few lines here. Mirrors
// protocol/fxs_particles.c (the C decoder) value for value: positions, T and F are
// float32(lo + q * step) computed in double, so both decoders give identical floats
// (checked against tests/data/particles/).
//
//   import { parseHeader, decode } from './fxs_particles.js';
//   const h = parseHeader(msg);                       // throws on a bad frame
//   if (h.kind === 1 && h.codec === 2) {
//     const p = decode(new Uint8Array(msg, h.headerBytes, h.payloadBytes));
//     // p.n, p.xyz (Float32Array 3n), p.temp, p.fuel (Float32Array n), p.flags (Uint8Array n)
//   }

export const KIND_PARTICLES = 1;
export const CODEC_PARTICLES = 2;
export const MAX_PARTICLES = 1 << 22;

const HEADER_BYTES = 64;
const PROB_BITS = 12;
const PROB_INIT = 1 << (PROB_BITS - 1);
const ADAPT = 5;
const TOP = 1 << 24;
const NEAR = 8, SAME = 16;
const MAXK = 24;
const CNT_U = 3, T_U = 2, F_U = 2;
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
  if (b[4] !== 2) fail('unsupported version');
  if (b[11] > 1) fail('unknown attribute mode');
  const v = new DataView(b.buffer, b.byteOffset, b.byteLength);
  const f = { posBits: b[5], tempBits: b[6], fuelBits: b[7], abits: [b[8], b[9], b[10]], mode: b[11], n: v.getUint32(12, true) };
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
  return f;
}

const corrupt = () => fail('corrupt particle data');

// Adaptive binary range decoder (LZMA's, 12-bit probabilities) and LSB-first raw bits.
class Reader {
  constructor(b, rp, rend, bend) {
    if (rend - rp < 5 || b[rp] !== 0) corrupt();
    this.b = b; this.rp = rp + 5; this.rend = rend; this.bp = rend; this.bend = bend;
    this.range = -1; // 0xFFFFFFFF
    this.code = (b[rp + 1] << 24) | (b[rp + 2] << 16) | (b[rp + 3] << 8) | b[rp + 4];
    if (this.code === -1) corrupt();
    this.acc = 0; this.cnt = 0;
  }
  // range and code are kept as int32 bit patterns (small integers for the engine), compared unsigned
  bit(p, i) { // p: Uint16Array of probabilities, i: index
    const pr = p[i], bound = Math.imul(this.range >>> PROB_BITS, pr); // < 2^32, exact
    let bit, range, code = this.code;
    if ((code >>> 0) < (bound >>> 0)) {
      range = bound;
      p[i] = pr + (((1 << PROB_BITS) - pr) >> ADAPT);
      bit = 0;
    } else {
      code = (code - bound) | 0;
      range = (this.range - bound) | 0;
      p[i] = pr - (pr >> ADAPT);
      bit = 1;
    }
    if ((range >>> 0) < TOP) { // code < range < 2^24 here
      if (this.rp >= this.rend) corrupt();
      range = range << 8;
      code = (code << 8) | this.b[this.rp++];
    }
    this.range = range;
    this.code = code;
    return bit;
  }
  raw(n) { // n <= 16 per call keeps acc within 32 bits
    while (this.cnt < n) {
      if (this.bp >= this.bend) corrupt();
      this.acc |= this.b[this.bp++] << this.cnt;
      this.cnt += 8;
    }
    const v = this.acc & ((1 << n) - 1);
    this.acc >>>= n;
    this.cnt -= n;
    return v;
  }
  rawBits(n) {
    return n <= 16 ? this.raw(n) : this.raw(16) + this.raw(n - 16) * 65536;
  }
  // unary prefix of u decisions, Exp-Golomb class in unary, top mantissa bit modelled
  int(p, o, u) {
    for (let i = 0; i < u; i++) if (!this.bit(p, o + i)) return i;
    let k = 0;
    while (this.bit(p, o + u + k)) if (++k === MAXK) corrupt();
    let e = 1;
    if (k) e = (2 + this.bit(p, o + u + MAXK + k)) * 2 ** (k - 1) + this.rawBits(k - 1);
    return e + u - 1;
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

// The position tree, depth first without recursion: the upper child of a split waits on
// an explicit stack (at most one entry per depth) while the lower one is decoded.
function decodeTree(f, rd, q) {
  const { axis, left, depth } = schedule(f.abits);
  const cnt = new Uint16Array(14 * 3 * IPROBS(CNT_U)).fill(PROB_INIT);
  const CP = IPROBS(CNT_U);
  const bitOf = new Float64Array(depth), lx = new Int32Array(depth + 1), ly = new Int32Array(depth + 1), lz = new Int32Array(depth + 1);
  for (let d = 0; d < depth; d++) bitOf[d] = 2 ** (left[d][axis[d]] - 1);
  for (let d = 0; d <= depth; d++) { lx[d] = left[d][0]; ly[d] = left[d][1]; lz[d] = left[d][2]; }
  const ax = Int32Array.from(axis);
  const sc = new Float64Array(depth + 1), sd = new Int32Array(depth + 1);
  const sx = new Float64Array(depth + 1), sy = new Float64Array(depth + 1), sz = new Float64Array(depth + 1);
  let sp = 0, out = 0, c = f.n, d = 0, bx = 0, by = 0, bz = 0;
  for (;;) {
    while (c >= 2 && d < depth) {
      const a = ax[d], bit = bitOf[d];
      const z = rd.int(cnt, (cclass(c) * 3 + a) * CP, CNT_U);
      const lo = (c - (c % 2)) / 2 + (z % 2 ? -(z + 1) / 2 : z / 2);
      if (lo < 0 || lo > c) corrupt();
      d++;
      if (lo && lo < c) {
        sc[sp] = c - lo; sd[sp] = d;
        sx[sp] = a === 0 ? bx + bit : bx; sy[sp] = a === 1 ? by + bit : by; sz[sp] = a === 2 ? bz + bit : bz;
        sp++;
        c = lo;
      } else if (!lo) {
        if (a === 0) bx += bit; else if (a === 1) by += bit; else bz += bit;
      }
    }
    if (c === 1) { bx += rd.rawBits(lx[d]); by += rd.rawBits(ly[d]); bz += rd.rawBits(lz[d]); }
    if (out + c > f.n) corrupt();
    for (let k = 0; k < c; k++, out++) { q[3 * out] = bx; q[3 * out + 1] = by; q[3 * out + 2] = bz; }
    if (sp === 0) break;
    sp--;
    c = sc[sp]; d = sd[sp]; bx = sx[sp]; by = sy[sp]; bz = sz[sp];
  }
  if (out !== f.n) corrupt();
}

function outputs(f, out) {
  const r = Math.max(f.hi[0] - f.lo[0], f.hi[1] - f.lo[1], f.hi[2] - f.lo[2], 0);
  return {
    sp: r / (2 ** f.posBits - 1),
    st: (f.hi[3] - f.lo[3]) / (2 ** f.tempBits - 1),
    sf: (f.hi[4] - f.lo[4]) / (2 ** f.fuelBits - 1),
  };
}

// Attribute mode 0: flags, T and F predicted from the nearest of the 8 particles before.
function decodeAttrs0(f, rd, q, out) {
  const n = f.n, TP = IPROBS(T_U), FP = IPROBS(F_U);
  const pt = new Uint16Array(7 * 8 * 2 * TP).fill(PROB_INIT), pf = new Uint16Array(7 * 2 * 2 * FP).fill(PROB_INIT);
  const same = new Uint16Array(16).fill(PROB_INIT), tree = new Uint16Array(256).fill(PROB_INIT);
  const qt = new Int32Array(n), qf = new Int32Array(n);
  const { sp, st, sf } = outputs(f, out);
  const tlim = 2 ** f.tempBits, flim = 2 ** f.fuelBits;
  const [lx, ly, lz, lt, lf] = f.lo;
  const { xyz, temp, fuel, flags } = out;
  let zt = 0, zf = 0;
  for (let j = 0; j < n; j++) {
    // nearest of the NEAR particles before j (the latest on ties); squares < 2^50 are exact
    let nb = -1, bd = Infinity;
    const cx = q[3 * j], cy = q[3 * j + 1], cz = q[3 * j + 2];
    for (let k = 1; k <= NEAR && k <= j; k++) {
      const o = 3 * (j - k), dx = cx - q[o], dy = cy - q[o + 1], dz = cz - q[o + 2];
      const dd = dx * dx + dy * dy + dz * dz;
      if (dd < bd) { bd = dd; nb = j - k; }
    }
    const nt = nb < 0 ? 0 : qt[nb], nf = nb < 0 ? 0 : qf[nb], nfl = nb < 0 ? 0 : flags[nb];
    const f0 = nf === 0 ? 1 : 0;
    let v = nfl;
    if (rd.bit(same, (nfl & 7) * 2 + f0)) {
      let m = 1;
      while (m < 256) m = 2 * m + rd.bit(tree, m);
      v = m - 256;
      if (v === nfl) corrupt();
    }
    const ot = ((rclass(zt) * 8 + (v & 7)) * 2 + f0) * TP, of = ((rclass(zf) * 2 + f0) * 2 + ((v >> 2) & 1)) * FP;
    zt = rd.int(pt, ot, T_U);
    zf = rd.int(pf, of, F_U);
    const t = nt + unzigzag(zt), fu = nf + unzigzag(zf);
    if (t < 0 || t >= tlim || fu < 0 || fu >= flim) corrupt();
    qt[j] = t; qf[j] = fu; flags[j] = v;
    xyz[3 * j] = lx + cx * sp;
    xyz[3 * j + 1] = ly + cy * sp;
    xyz[3 * j + 2] = lz + cz * sp;
    temp[j] = lt + t * st;
    fuel[j] = lf + fu * sf;
  }
}

// The top min(bits, 8) bits with the bit tree p[o + m], then the low bits - 8 raw.
function tree(rd, p, o, bits) {
  const low = bits > 8 ? bits - 8 : 0, end = 1 << (bits - low);
  let m = 1;
  while (m < end) m = 2 * m + rd.bit(p, o + m);
  m -= end;
  return low ? m * (1 << low) + rd.raw(low) : m;
}

const topOf = (v, bits, keep) => (bits > keep ? v >>> (bits - keep) : v);

// Attribute mode 1: flags, T and F as values in contexts of the neighbours' values.
function decodeAttrs1(f, rd, q, out) {
  const n = f.n, tb = f.tempBits, fb = f.fuelBits;
  const vsame = new Uint16Array(18).fill(PROB_INIT), vfl = new Uint16Array(9 * 256).fill(PROB_INIT);
  const vt = new Uint16Array(72 * 256).fill(PROB_INIT), vf0 = new Uint16Array(256).fill(PROB_INIT);
  const vf = new Uint16Array(64 * 256).fill(PROB_INIT);
  const qt = new Int32Array(n), qf = new Int32Array(n), last = new Int32Array(256).fill(-1);
  const dist = new Float64Array(SAME);
  const { sp, st, sf } = outputs(f, out);
  const flim = 2 ** fb;
  const [lx, ly, lz, lt, lf] = f.lo;
  const { xyz, temp, fuel, flags } = out;
  for (let j = 0; j < n; j++) {
    const cx = q[3 * j], cy = q[3 * j + 1], cz = q[3 * j + 2], kmax = j < SAME ? j : SAME;
    let nb = -1, bd = Infinity;
    for (let k = 1; k <= kmax; k++) {
      const o = 3 * (j - k), dx = cx - q[o], dy = cy - q[o + 1], dz = cz - q[o + 2];
      const dd = dx * dx + dy * dy + dz * dz;
      dist[k - 1] = dd;
      if (k <= NEAR && dd < bd) { bd = dd; nb = j - k; }
    }
    const nfl = nb < 0 ? 0 : flags[nb], nc = nb < 0 ? 8 : nfl & 7, nf0 = nb < 0 || qf[nb] === 0 ? 1 : 0;
    let v = nfl;
    if (rd.bit(vsame, nc * 2 + nf0)) {
      v = tree(rd, vfl, nc * 256, 8);
      if (v === nfl) corrupt();
    }
    const c = v & 7;
    flags[j] = v;
    let sb = -1;
    bd = Infinity;
    for (let k = 1; k <= kmax; k++) if (flags[j - k] === v && dist[k - 1] < bd) { bd = dist[k - 1]; sb = j - k; }
    if (sb < 0) sb = last[v];
    const tctx = sb < 0 ? 8 : topOf(qt[sb], tb, 3);
    const t = tree(rd, vt, (c * 9 + tctx) * 256, tb);
    let fu = 0;
    if (rd.bit(vf0, (c * 16 + topOf(t, tb, 4)) * 2 + nf0)) {
      fu = tree(rd, vf, (c * 8 + topOf(t, tb, 3)) * 256, fb) + 1;
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

/**
 * Decodes a codec 2 payload (the bytes after the frame header).
 * Returns {n, xyz: Float32Array(3n), temp: Float32Array(n), fuel: Float32Array(n), flags: Uint8Array(n)}.
 * Throws Error('particles: ...') on truncated, corrupt or oversized input.
 */
export function decode(buf) {
  const b = bytesOf(buf);
  const f = parsePayloadHeader(b);
  if (HEADER_BYTES + f.rcBytes + f.bitsBytes !== b.length) fail('section sizes do not match the payload length');
  const out = { n: f.n, xyz: new Float32Array(3 * f.n), temp: new Float32Array(f.n), fuel: new Float32Array(f.n), flags: new Uint8Array(f.n) };
  if (f.n === 0) {
    if (f.rcBytes || f.bitsBytes) fail('bad sizes');
    return out;
  }
  const rend = HEADER_BYTES + f.rcBytes;
  const rd = new Reader(b, HEADER_BYTES, rend, rend + f.bitsBytes);
  const q = new Float64Array(3 * f.n);
  decodeTree(f, rd, q);
  (f.mode ? decodeAttrs1 : decodeAttrs0)(f, rd, q, out);
  if (rd.rp !== rd.rend) fail('corrupt particle data (range coder section not consumed exactly)');
  if (rd.bp !== rd.bend || rd.acc !== 0) fail('corrupt particle data (raw bits not consumed exactly)');
  return out;
}

/** Decodes a whole kind 1 frame (header + payload); returns {header, particles}. */
export function decodeFrame(buf) {
  const header = parseHeader(buf);
  if (header.kind !== KIND_PARTICLES || header.codec !== CODEC_PARTICLES) throw new Error('frame: not a codec 2 particle frame');
  const particles = decode(payloadOf(buf, header));
  if (particles.n !== header.count) throw new Error('frame: count does not match the payload');
  return { header, particles };
}
