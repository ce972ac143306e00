// fxs_particles.js — browser/Node decoder of fxstream.v1 kind 1 particle payloads
// (codec 1, protocol/PROTOCOL.md §7.5) and parser of the 64-byte frame header (§7.1).
//
// Plain ES module, no dependencies, no build step: the entropy stage is a static-table
// rANS that takes a few lines here. Mirrors protocol/fxs_particles.c (the C decoder)
// value for value: positions, T and F are float32(lo + q * step) computed in double,
// so both decoders give identical floats (checked against tests/data/particles/).
//
//   import { parseHeader, decode } from './fxs_particles.js';
//   const h = parseHeader(msg);                       // throws on a bad frame
//   if (h.kind === 1 && h.codec === 1) {
//     const p = decode(new Uint8Array(msg, h.headerBytes, h.payloadBytes));
//     // p.n, p.xyz (Float32Array 3n), p.temp, p.fuel (Float32Array n), p.flags (Uint8Array n)
//   }

export const KIND_PARTICLES = 1;
export const CODEC_PARTICLES = 1;
export const MAX_PARTICLES = 1 << 22;

const PROB_BITS = 12;
const PROB_SCALE = 1 << PROB_BITS;
const RANS_L = 1 << 23;
const NTOK = 72;
const NSTREAMS = 8;
const HEADER_BYTES = 64;
// value kinds (table order)
const CELL = 0, XSAME = 1, XNEW = 2, Y = 3;
const POW2 = Array.from({ length: 33 }, (_, i) => 2 ** i);

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

function readTables(b, pos) {
  const tabs = [];
  for (let s = 0; s < NSTREAMS; s++) {
    if (pos >= b.length) fail('corrupt frequency table');
    const nsym = b[pos++];
    if (nsym > NTOK) fail('corrupt frequency table');
    const freq = new Uint32Array(NTOK), start = new Uint32Array(NTOK);
    let sum = 0;
    for (let t = 0; t < nsym; t++) {
      if (pos >= b.length) fail('corrupt frequency table');
      let f = b[pos++];
      if (f & 0x80) {
        if (pos >= b.length || b[pos] & 0x80) fail('corrupt frequency table');
        f = (f & 0x7f) | (b[pos++] << 7);
      }
      if (f > PROB_SCALE) fail('corrupt frequency table');
      freq[t] = f;
      sum += f;
    }
    if (sum !== PROB_SCALE && sum !== 0) fail('corrupt frequency table');
    const lookup = new Uint8Array(PROB_SCALE);
    for (let t = 1; t < NTOK; t++) start[t] = start[t - 1] + freq[t - 1];
    for (let t = 0; t < nsym; t++) lookup.fill(t, start[t], start[t] + freq[t]);
    tabs.push({ nsym, freq, start, lookup });
  }
  return { tabs, pos };
}

function parsePayloadHeader(b) {
  if (b.length < HEADER_BYTES || b[0] !== 0x46 || b[1] !== 0x58 || b[2] !== 0x50 || b[3] !== 0x31)
    fail('not a codec 1 payload (short or bad magic)');
  if (b[4] !== 1) fail('unsupported version');
  const v = new DataView(b.buffer, b.byteOffset, b.byteLength);
  const f = { posBits: b[5], tempBits: b[6], fuelBits: b[7], cellBits: b[8], n: v.getUint32(12, true) };
  f.lo = [v.getFloat32(16, true), v.getFloat32(20, true), v.getFloat32(24, true), v.getFloat32(40, true), v.getFloat32(48, true)];
  f.hi = [v.getFloat32(28, true), v.getFloat32(32, true), v.getFloat32(36, true), v.getFloat32(44, true), v.getFloat32(52, true)];
  f.ransBytes = v.getUint32(56, true);
  f.bitsBytes = v.getUint32(60, true);
  if (f.posBits < 8 || f.posBits > 24 || f.tempBits < 2 || f.tempBits > 16 || f.fuelBits < 2 || f.fuelBits > 16)
    fail('bad bit widths');
  if (f.cellBits > 10 || f.cellBits > f.posBits) fail('bad cell_bits');
  if (f.n > MAX_PARTICLES) fail('particle count over the limit');
  for (let c = 0; c < 5; c++)
    if (!Number.isFinite(f.lo[c]) || !Number.isFinite(f.hi[c]) || f.lo[c] > f.hi[c]) fail('bad bounds');
  return f;
}

// The decoding state: rANS reader and LSB-first raw-bit reader over one byte array.
class Reader {
  constructor(b, rp, rend, bend, tabs) {
    this.b = b; this.rp = rp; this.rend = rend; this.bp = rend; this.bend = bend; this.tabs = tabs;
    this.acc = 0; this.cnt = 0;
    if (rend - rp < 4) fail('corrupt particle data');
    this.x = (b[rp] | (b[rp + 1] << 8) | (b[rp + 2] << 16) | (b[rp + 3] << 24)) >>> 0;
    this.rp += 4;
  }
  bits(n) { // n <= 16 per call keeps acc within 32 bits
    while (this.cnt < n) {
      if (this.bp >= this.bend) fail('corrupt particle data');
      this.acc |= this.b[this.bp++] << this.cnt;
      this.cnt += 8;
    }
    const v = this.acc & ((1 << n) - 1);
    this.acc >>>= n;
    this.cnt -= n;
    return v;
  }
  extra(n) {
    return n <= 16 ? this.bits(n) : this.bits(16) + this.bits(n - 16) * 65536;
  }
  get(stream) {
    const t = this.tabs[stream];
    if (!t.nsym) fail('corrupt particle data');
    const slot = this.x & (PROB_SCALE - 1);
    const s = t.lookup[slot];
    // x < 2^31 throughout, so 32-bit integer operations are exact
    let x = t.freq[s] * (this.x >>> PROB_BITS) + slot - t.start[s];
    while (x < RANS_L) {
      if (this.rp >= this.rend) fail('corrupt particle data');
      x = (x << 8) | this.b[this.rp++];
    }
    this.x = x;
    if (s < 16) return s;
    const nb = 3 + ((s - 16) >> 1);
    return (2 + ((s - 16) & 1)) * POW2[nb] + this.extra(nb);
  }
}

const unzigzag = (z) => (z & 1 ? -((z + 1) / 2) : z / 2); // z < 2^17

function decodeAll(f, rd, out) {
  const k = f.cellBits, m = f.posBits - k, omask = 2 ** m - 1, cm = 2 ** k - 1;
  const steps = [0, 1, 2, 3, 4].map((c) => (f.hi[c] - f.lo[c]) / (2 ** (c < 3 ? f.posBits : c === 3 ? f.tempBits : f.fuelBits) - 1));
  const cellLimit = 2 ** (3 * k), tlim = 2 ** f.tempBits, flim = 2 ** f.fuelBits;
  const [lx, ly, lz, lt, lf] = f.lo, [sx, sy, sz, st, sf] = steps, m2 = 2 ** m;
  let cell = 0, x = 0, t = 0, fu = 0;
  const { xyz, temp, fuel, flags } = out;
  for (let j = 0; j < f.n; j++) {
    const gap = rd.get(CELL);
    const same = gap === 0 && j > 0;
    const vx = rd.get(same ? XSAME : XNEW);
    if (vx > omask) fail('corrupt particle data');
    const vy = rd.get(Y), vz = rd.get(Y + 1), dt = rd.get(Y + 2), df = rd.get(Y + 3), fl = rd.get(Y + 4);
    cell += gap;
    x = same ? x + vx : vx;
    t += unzigzag(dt);
    fu += unzigzag(df);
    if (cell >= cellLimit || x > omask || vy > omask || vz > omask) fail('corrupt particle data');
    if (t < 0 || t >= tlim || fu < 0 || fu >= flim || fl > 255) fail('corrupt particle data');
    const cx = cell & cm, cy = (cell >>> k) & cm, cz = cell >>> (2 * k); // cell < 2^30
    xyz[3 * j] = lx + (cx * m2 + x) * sx;
    xyz[3 * j + 1] = ly + (cy * m2 + vy) * sy;
    xyz[3 * j + 2] = lz + (cz * m2 + vz) * sz;
    temp[j] = lt + t * st;
    fuel[j] = lf + fu * sf;
    flags[j] = fl;
  }
  if (rd.rp !== rd.rend || rd.x !== RANS_L || rd.bp !== rd.bend || rd.acc !== 0) fail('corrupt particle data');
}

/**
 * Decodes a codec 1 payload (the bytes after the frame header).
 * Returns {n, xyz: Float32Array(3n), temp: Float32Array(n), fuel: Float32Array(n), flags: Uint8Array(n)}.
 * Throws Error('particles: ...') on truncated, corrupt or oversized input.
 */
export function decode(buf) {
  const b = bytesOf(buf);
  const f = parsePayloadHeader(b);
  const out = { n: f.n, xyz: new Float32Array(3 * f.n), temp: new Float32Array(f.n), fuel: new Float32Array(f.n), flags: new Uint8Array(f.n) };
  if (f.n === 0) {
    if (f.ransBytes || f.bitsBytes || b.length !== HEADER_BYTES) fail('bad sizes');
    return out;
  }
  const { tabs, pos } = readTables(b, HEADER_BYTES);
  if (pos + f.ransBytes + f.bitsBytes !== b.length) fail('section sizes do not match the payload length');
  const rd = new Reader(b, pos, pos + f.ransBytes, pos + f.ransBytes + f.bitsBytes, tabs);
  decodeAll(f, rd, out);
  return out;
}

/** Decodes a whole kind 1 frame (header + payload); returns {header, particles}. */
export function decodeFrame(buf) {
  const header = parseHeader(buf);
  if (header.kind !== KIND_PARTICLES || header.codec !== CODEC_PARTICLES) throw new Error('frame: not a codec 1 particle frame');
  const particles = decode(payloadOf(buf, header));
  if (particles.n !== header.count) throw new Error('frame: count does not match the payload');
  return { header, particles };
}
