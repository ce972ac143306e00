// web_decoders_check.mjs — checks clients/web/src/rig.js (kind 3 decoder, point light,
// shadow direction), clients/web/src/eye.js (kind 4 FXL1 container and its zstd tables, the
// view's stale-table rule) and the frame header parser of clients/web/fxs_particles.js
// against the C side's output. argv: VECDIR (rig-N.bin whole frames + rig-N.json expected
// values from test_light_rig --dump), REALDIR (fxctl --out of a real daemon: energy-SEQ-rig.bin
// payloads of kind 3 and lines.txt), EYEDIR (fxctl --out of compound_eye streams eyesq
// and eyehex: NAME-SEQ.bin kind 4 payloads, NAME-SEQ-PROD.png decoded by protocol/fxs_lut.c,
// lines.txt) and FLAMEDIR (fxctl --out of the flame with velocities on: flame-SEQ.bin kind 1
// payloads and flame-SEQ.ply, what the C decoder gave). Prints "test_web_decoders: N passed,
// M failed".
import { readFileSync, existsSync, readdirSync } from 'node:fs';
import { inflateSync } from 'node:zlib';
import { decode, parseHeader, payloadOf } from '../../clients/web/fxs_particles.js';
import { decodeRig, RigState, pointLight, shadeM, rampColor, shadowDir, SEG_FLOATS } from '../../clients/web/src/rig.js';
import { decodeLutPack, EyeView } from '../../clients/web/src/eye.js';

const [vecDir, realDir, eyeDir, flameDir] = process.argv.slice(2);
let passed = 0, failed = 0;
function check(ok, name, detail = '') {
  if (ok) { passed++; console.log('ok   ' + name); } else { failed++; console.log('FAIL ' + name + (detail ? ': ' + detail : '')); }
}
const num = (x) => (x === 'inf' ? Infinity : x === '-inf' ? -Infinity : x);
const same = (a, b) => Object.is(Math.fround(num(b)), a) || a === Math.fround(num(b));

// 1. vectors from the C encoder
for (let n = 0; n < 3; n++) {
  const bin = readFileSync(`${vecDir}/rig-${n}.bin`), exp = JSON.parse(readFileSync(`${vecDir}/rig-${n}.json`, 'utf8'));
  const buf = new Uint8Array(bin.buffer, bin.byteOffset, bin.byteLength);
  const h = parseHeader(buf);
  check(h.kind === 3 && h.codec === 1 && h.channel === 3 && h.paramRev === 7 && h.seq === 42n &&
        h.serverTimeUs === 1795313709549000n && h.simTime === exp.sim_time && h.count === exp.segments.length,
        `vector ${n}: frame header`);
  check(h.payloadBytes === exp.payload_bytes, `vector ${n}: payload_bytes`);
  const rig = decodeRig(payloadOf(buf, h));
  check(rig.nSeg === exp.segments.length && rig.constantsId === exp.constants_id && rig.hasConstants === exp.has_constants,
        `vector ${n}: counts, constants_id, flag`);
  let bad = [];
  exp.segments.forEach((s, i) => {
    const o = SEG_FLOATS * i, got = rig.seg;
    const want = [...s.c, ...s.d, s.a_lo, s.a_hi, s.strength];
    want.forEach((w, k) => { if (!same(got[o + k], w)) bad.push(`seg ${i}[${k}] ${got[o + k]} vs ${w}`); });
    if (rig.source[i] !== s.source || rig.index[i] !== s.index) bad.push(`seg ${i} source/index`);
  });
  check(bad.length === 0, `vector ${n}: every segment value bit-identical`, bad.slice(0, 3).join('; '));
  if (exp.has_constants) {
    const c = rig.constants, e = exp.constants;
    bad = [];
    const cmp = (name, a, b) => { if (Array.isArray(b)) b.forEach((x, k) => { if (!same(a[k], x)) bad.push(name); }); else if (!same(a, b)) bad.push(name); };
    check(c.flags === e.flags, `vector ${n}: constants flags`);
    cmp('strength', c.strength, e.strength); cmp('outline_width', c.outlineWidth, e.outline_width);
    cmp('outline_rgb', c.outlineRgb, e.outline_rgb); cmp('shadow_theta', c.shadowTheta, e.shadow_theta);
    cmp('shadow_opacity', c.shadowOpacity, e.shadow_opacity); cmp('shadow_rgb', c.shadowRgb, e.shadow_rgb);
    cmp('plane_i', c.planeI, e.plane_i); cmp('plane_y', c.planeY, e.plane_y);
    cmp('plane_x', c.planeX, e.plane_x); cmp('plane_z', c.planeZ, e.plane_z);
    check(c.bands.length === e.bands.length, `vector ${n}: band count`);
    e.bands.forEach((b, i) => { cmp(`band ${i}`, [c.bands[i].mMin, ...c.bands[i].rgb], [b.m_min, ...b.rgb]); });
    check(bad.length === 0, `vector ${n}: constants bit-identical`, bad.join(', '));
  } else {
    check(rig.constants === null, `vector ${n}: no constants block`);
  }
}
// constants cache across a frame without them (vector 1 has vector 0's constants id)
{
  const st = new RigState();
  const load = (n) => { const b = readFileSync(`${vecDir}/rig-${n}.bin`); const u = new Uint8Array(b.buffer, b.byteOffset, b.byteLength); return decodeRig(payloadOf(u, parseHeader(u))); };
  st.update(load(0));
  const r1 = st.update(load(1));
  check(r1.constants !== null && r1.constants.bands.length === 3, 'frame without constants takes the cached block of its id');
  const r2 = st.update(load(2));
  const st2 = new RigState();
  check(st2.update(load(1)).constants === null && r2.constants.bands.length === 4, 'no constants before a frame that has them');
}
// malformed payloads are rejected
{
  const b = readFileSync(`${vecDir}/rig-0.bin`); const u = new Uint8Array(b.buffer, b.byteOffset, b.byteLength);
  const p = payloadOf(u, parseHeader(u));
  let threw = 0;
  for (const bad of [p.slice(0, p.length - 1), (() => { const q = p.slice(); q[0] = 0; return q; })(), (() => { const q = p.slice(); q[8] = 65; return q; })()]) {
    try { decodeRig(bad); } catch { threw++; }
  }
  check(threw === 3, 'truncated, bad magic and oversized segment count rejected', `${threw}/3`);
}

// 2. the client recipe against the digest's golden values (003 §5 items 4 and 9)
{
  const rig = { nSeg: 1, seg: new Float32Array([0, 0, 0, 1, 0, 0, 0, Infinity, 1, 0]) };
  const bands = { bands: [{ mMin: -1, rgb: [0, 0.2, 0.4] }, { mMin: -0.3, rgb: [0.5, 0.7, 0.9] }, { mMin: 0, rgb: [0.9, 0.9, 1] }] };
  const rows = [[[2, 1, 0], [0, -1, 0], 1, 2], [[2, 1, 0], [1, 0, 0], 0, 2], [[-1, 1, 0], [0, 1, 0], -0.70710678, 0], [[2, 1, 0], [0.9798, 0.2, 0], -0.2, 1]];
  let ok = true;
  for (const [M, N, m, band] of rows) {
    const E = pointLight(rig, M), got = shadeM(E, M, N);
    ok &&= Math.abs(got - m) < 1e-4 && rampColor(bands, got) === bands.bands[band].rgb;
  }
  check(ok, 'golden shading (digest 003 §5 item 4)');
  const c = { planeY: [0, 1, 0], planeX: [1, 0, 0], planeZ: [0, 0, 1], shadowTheta: Math.PI / 3 };
  const r = shadowDir(c, [3, 0.5, 0]);
  check(r.clamped && Math.abs(r.lambda * 180 / Math.PI - 99.46) < 0.005 && Math.abs(r.k[0] - 0.8660254) < 1e-6 &&
        Math.abs(r.k[1] + 0.5) < 1e-12, 'golden shadow direction with the sign fix (item 9)', JSON.stringify(r));
  const t = (0 - 1.7) / r.k[1];
  check(Math.abs(t - 3.4) < 1e-12 && Math.abs(0.2 + t * r.k[0] - 3.1445) < 5e-5, 'golden shadow point G = (3.1445, 0, 0.1)');
  const prev = { i: null }; shadowDir(c, [0, 0, 1], prev);
  const below = shadowDir(c, [0, 3, 0], prev);
  check(below.k.every(Number.isFinite) && Math.abs(below.k[2] - Math.sin(Math.PI / 3)) < 1e-12, 'light straight below keeps the previous direction');
}

// 3. frames of a real daemon (fxctl --out)
{
  const lines = existsSync(`${realDir}/lines.txt`) ? readFileSync(`${realDir}/lines.txt`, 'utf8').split('\n').filter((l) => l.startsWith('{"stream"')).map((l) => JSON.parse(l)) : [];
  const rigs = lines.filter((l) => l.kind === 3);
  check(lines.length - rigs.length === 3 && rigs.length >= 2, 'real daemon: texture and light-rig frames interleaved', `${lines.length} lines, ${rigs.length} rig`);
  let okAll = rigs.length > 0;
  for (const l of rigs) {
    const path = `${realDir}/energy-${l.seq}-rig.bin`;
    if (!existsSync(path)) { okAll = false; continue; }
    const rig = decodeRig(new Uint8Array(readFileSync(path)));
    const c = rig.constants;
    okAll &&= l.codec === 1 && rig.nSeg === l.count && rig.nSeg === 16 && rig.hasConstants && c.bands.length === 2 &&
      c.bands[1].mMin === 0.25 && c.bands[1].rgb[1] === 0.5 && Math.abs(c.shadowTheta - Math.PI / 3) < 1e-6 &&
      rig.seg[0] === Math.fround(-13.2) && rig.seg[1] === Math.fround(-4.2) && rig.source[0] === 4 && rig.index[8] === 1;
  }
  check(okAll, 'real daemon: kind 3 payloads decode (16 curve chords from p0, the ramp just set, theta 60 deg)');
}

// 4. kind 4 look-up tables of a real daemon against the C decoder (fxctl's PNGs)
// fxctl's PNG (png.c): 8-bit RGBA, filter 0 on every row, no interlace.
function readPng(path) {
  const d = readFileSync(path), w = d.readUInt32BE(16), h = d.readUInt32BE(20), idat = [];
  for (let i = 8; i < d.length;) {
    const n = d.readUInt32BE(i);
    if (d.toString('latin1', i + 4, i + 8) === 'IDAT') idat.push(d.subarray(i + 8, i + 8 + n));
    i += 12 + n;
  }
  const rows = inflateSync(Buffer.concat(idat)), px = new Uint8Array(w * h * 4);
  for (let y = 0; y < h; y++) {
    if (rows[y * (4 * w + 1)] !== 0) throw new Error(`${path}: row ${y} filter ${rows[y * (4 * w + 1)]}`);
    px.set(rows.subarray(y * (4 * w + 1) + 1, (y + 1) * (4 * w + 1)), 4 * w * y);
  }
  return { w, h, px };
}
const eyeLines = existsSync(`${eyeDir}/lines.txt`) ? readFileSync(`${eyeDir}/lines.txt`, 'utf8').split('\n').filter((l) => l.startsWith('{"stream"')).map((l) => JSON.parse(l)) : [];
const eyeWant = { eyesq: { lattice: 0, cells: 12, dirs: 10, r: 1, tileH: 1, pigm: [128, 128] }, eyehex: { lattice: 1, cells: 8, dirs: 12, r: 1.2, tileH: Math.sqrt(3), pigm: [128, 222] } };
check(eyeLines.length === 2 && eyeLines.every((l) => l.kind === 4 && l.codec === 1), 'real daemon: one kind 4 codec 1 frame per compound eye', JSON.stringify(eyeLines));
const eyePayload = {};
for (const l of eyeLines) {
  const want = eyeWant[l.stream], base = `${eyeDir}/${l.stream}-${l.seq}`, bytes = new Uint8Array(readFileSync(`${base}.bin`));
  eyePayload[l.stream] = { bytes, line: l };
  let p;
  try { p = decodeLutPack(bytes); } catch (e) { check(false, `${l.stream}: decodes`, e.message); continue; }
  check(p.lattice === want.lattice && p.cells === want.cells && p.dirs === want.dirs && p.gutter === 1 &&
        p.lensRadius === Math.fround(want.r) && Math.abs(p.tileH - want.tileH) < 1e-6 && p.refractiveIndex === Math.fround(1.491) &&
        p.maxPasses === 8 && p.supersample === 1, `${l.stream}: container constants are the stream's parameters`, JSON.stringify({ ...p, tables: undefined }));
  const side = want.dirs * (want.cells + 2), L = p.tables.LLUT, M = p.tables.LMAC, G = p.tables.PIGM;
  check(L.width === side && L.height === side && l.width === side && l.height === side && L.tile === want.cells + 2 && L.inner === want.cells &&
        M.width === want.dirs && G.width === want.pigm[0] && G.height === want.pigm[1], `${l.stream}: table sizes (LLUT ${side}², LMAC ${want.dirs}², PIGM ${want.pigm})`);
  for (const name of ['PIGM', 'LLUT', 'LMAC']) {
    const png = readPng(`${base}-${name}.png`), t = p.tables[name];
    const same = png.w === t.width && png.h === t.height && Buffer.compare(Buffer.from(png.px), Buffer.from(t.texels)) === 0;
    check(same, `${l.stream}: ${name} texels identical to the C decoder's`);
  }
  // §7.6 gutter: texel (0, 1+t) of a tile repeats (C, 1+t), (C+1, 1+t) repeats (1, 1+t).
  const C = p.cells, tex = (x, y) => L.texels.subarray(4 * (y * L.width + x), 4 * (y * L.width + x) + 4).join();
  let gutterOk = true;
  for (let t = 0; t < C; t++) {
    const x0 = 3 * (C + 2), y = 2 * (C + 2) + 1 + t;
    gutterOk &&= tex(x0, y) === tex(x0 + C, y) && tex(x0 + C + 1, y) === tex(x0 + 1, y);
  }
  check(gutterOk, `${l.stream}: LLUT tiles carry the periodic 1-texel gutter`);
  const dark = G.texels.filter((v, i) => i % 4 === 0 && v < 40).length, pale = G.texels.filter((v, i) => i % 4 === 0 && v > 180).length;
  check(dark > 0.05 * G.width * G.height && pale > 0.5 * G.width * G.height && G.texels.every((v, i) => i % 4 !== 3 || v === 255),
        `${l.stream}: PIGM is dark dots on the pale base colour, A = 255`, `${dark} dark, ${pale} pale`);
}

// Malformed containers: each must throw a clear error (never decode to something).
function expectError(bytes, what, pattern) {
  try {
    decodeLutPack(bytes);
    check(false, `malformed: ${what}`, 'decoded without an error');
  } catch (e) {
    check(pattern.test(e.message), `malformed: ${what} -> "${e.message}"`);
  }
}
const sq = eyePayload.eyesq?.bytes ?? new Uint8Array(0);
const dirEntry = (bytes, name) => { // byte offset of the directory entry called name
  const dv = new DataView(bytes.buffer, bytes.byteOffset), hb = dv.getUint16(6, true), eb = dv.getUint16(10, true);
  for (let i = 0; i < dv.getUint16(8, true); i++) if (String.fromCharCode(...bytes.subarray(hb + i * eb, hb + i * eb + 4)) === name) return hb + i * eb;
  return -1;
};
const patched = (fn) => { const b = sq.slice(); fn(new DataView(b.buffer), b); return b; };
if (sq.length) {
  expectError(sq.slice(0, 40), 'shorter than the header', /shorter than the 64-byte header/);
  expectError(sq.slice(0, 200), 'truncated inside the directory', /directory .* past the/);
  expectError(sq.slice(0, sq.length - 16), 'truncated inside the last table', /outside the data area/);
  expectError(patched((dv, b) => { b[3] = 0x32; }), 'bad magic', /bad magic/);
  expectError(patched((dv) => dv.setUint32(dirEntry(sq, 'LLUT') + 20, sq.length + 8, true)), 'LLUT offset out of range', /LLUT: stored bytes .* outside/);
  expectError(patched((dv) => dv.setUint32(dirEntry(sq, 'LMAC') + 20, 8, true)), 'LMAC offset inside the directory', /LMAC: stored bytes .* outside/);
  expectError(patched((dv) => dv.setUint16(8, 2000, true)), 'entry count past the payload', /directory of 2000 entries/);
  expectError(patched((dv) => dv.setUint16(10, 16, true)), 'entry_bytes too small', /entry_bytes 16 too small/);
  expectError(patched((dv) => dv.setUint32(dirEntry(sq, 'LLUT') + 28, 1234, true)), 'raw_bytes not width × height × 4', /LLUT: raw_bytes 1234/);
  expectError(patched((dv) => dv.setUint32(dirEntry(sq, 'LLUT') + 8, 7, true)), 'unknown codec', /LLUT: unsupported codec 7/);
  expectError(patched((dv, b) => { b[dv.getUint32(dirEntry(sq, 'LMAC') + 20, true)] ^= 0xff; }), 'LMAC not a zstd frame', /LMAC: zstd/);
  expectError(patched((dv, b) => { b.set([88, 88, 88, 88], dirEntry(sq, 'LMAC')); }), 'LMAC missing', /missing LMAC/);
  expectError(patched((dv) => dv.setUint32(40, 11, true)), 'LLUT does not hold dirs² tiles', /LLUT: .* does not hold 11²/);
  // An unknown product is skipped; a larger header and larger entries are honoured (§7.6).
  const renamed = patched((dv, b) => { b.set([81, 81, 81, 81], dirEntry(sq, 'PIGM')); });
  let ok;
  try { const p = decodeLutPack(renamed); ok = !p.tables.PIGM && p.tables.LLUT && !p.tables.QQQQ; } catch (e) { ok = false; }
  check(ok, 'an unknown product name is skipped');
  check(JSON.stringify(tablesOf(decodeLutPack(widen(sq)))) === JSON.stringify(tablesOf(decodeLutPack(sq))),
        'header_bytes 96 and entry_bytes 80 (later versions) decode to the same tables');
}
// The container re-laid with a 96-byte header and 80-byte entries (offsets moved by 80).
function widen(b) {
  const dv = new DataView(b.buffer, b.byteOffset), count = dv.getUint16(8, true), oldEnd = 64 + 64 * count, newEnd = 96 + 80 * count;
  const out = new Uint8Array(b.length + newEnd - oldEnd), ov = new DataView(out.buffer);
  out.set(b.subarray(0, 64));
  ov.setUint16(6, 96, true);
  ov.setUint16(10, 80, true);
  for (let i = 0; i < count; i++) {
    out.set(b.subarray(64 + 64 * i, 128 + 64 * i), 96 + 80 * i);
    out.fill(0xee, 96 + 80 * i + 64, 96 + 80 * (i + 1)); // an unknown tail
    ov.setUint32(96 + 80 * i + 20, dv.getUint32(64 + 64 * i + 20, true) + newEnd - oldEnd, true);
  }
  out.set(b.subarray(oldEnd), newEnd);
  return out;
}
function tablesOf(p) { return Object.fromEntries(Object.entries(p.tables).map(([k, t]) => [k, [t.width, t.height, Buffer.from(t.texels).toString('base64')]])); }

// The view: a whole kind 4 frame goes to the GPU textures; an older param_rev is dropped.
if (eyePayload.eyesq) {
  const { bytes, line } = eyePayload.eyesq;
  const frame = (rev, width = line.width) => {
    const buf = new Uint8Array(64 + bytes.length), dv = new DataView(buf.buffer);
    buf.set([70, 88, 83, 49]);
    dv.setUint16(4, 64, true); dv.setUint16(6, 4, true); dv.setUint32(8, 9, true); dv.setUint32(12, rev, true);
    dv.setBigUint64(16, 1n, true); dv.setUint32(40, 1, true); dv.setUint32(44, bytes.length, true);
    dv.setUint32(48, width, true); dv.setUint32(52, line.height, true);
    buf.set(bytes, 64);
    return buf.buffer;
  };
  const v = new EyeView('eyesq'), feed = (buf) => v.onFrame(parseHeader(buf), buf);
  const a = feed(frame(5)), tex = v.textures.LLUT;
  const b = feed(frame(3)), c = feed(frame(5)), d = feed(frame(6));
  check(a && v.info().lutRev === 6 && !b && c && d && tex.image.width === line.width && tex.flipY === false &&
        tex.generateMipmaps === false && tex.minFilter === 1006 && tex.magFilter === 1006, 'EyeView: tables uploaded (LINEAR, no mipmaps, no flipY); an older param_rev is dropped',
        JSON.stringify({ a, b, c, d, info: v.info() }));
  let threw = '';
  try { feed(frame(7, line.width + 2)); } catch (e) { threw = e.message; }
  check(/frame says/.test(threw) && v.info().lutRev === 6, 'EyeView: a table whose size differs from the frame header is refused', threw);
}

// Live flame frames with velocities: the JS decoder against the C decoder's PLY (x y z
// temperature fuel as f32, flags u8, then vx vy vz f32), every value bit for bit.
function readPly(path) {
  const b = readFileSync(path), end = b.indexOf('end_header\n') + 11, head = b.subarray(0, end).toString();
  const n = Number(/element vertex (\d+)/.exec(head)[1]), vel = head.includes('property float vx'), size = vel ? 33 : 21;
  const dv = new DataView(b.buffer, b.byteOffset + end, n * size), f32 = (o) => dv.getFloat32(o, true);
  const p = { n, xyz: [], temp: [], fuel: [], flags: [], vel: vel ? [] : null };
  for (let i = 0; i < n; i++) {
    const o = i * size;
    p.xyz.push(f32(o), f32(o + 4), f32(o + 8)); p.temp.push(f32(o + 12)); p.fuel.push(f32(o + 16)); p.flags.push(dv.getUint8(o + 20));
    if (vel) p.vel.push(f32(o + 21), f32(o + 25), f32(o + 29));
  }
  return p;
}
{
  const bins = flameDir && existsSync(flameDir) ? readdirSync(flameDir).filter((f) => /^flame-\d+\.bin$/.test(f)) : [];
  let withVel = 0, bad = [];
  for (const f of bins) {
    const want = readPly(`${flameDir}/${f.replace('.bin', '.ply')}`), b = readFileSync(`${flameDir}/${f}`);
    const got = decode(new Uint8Array(b.buffer, b.byteOffset, b.byteLength));
    if (got.n !== want.n || !got.vel !== !want.vel) { bad.push(`${f}: n ${got.n}/${want.n}, vel ${!!got.vel}/${!!want.vel}`); continue; }
    withVel += got.vel ? 1 : 0;
    for (const k of ['xyz', 'temp', 'fuel', 'flags', ...(got.vel ? ['vel'] : [])])
      for (let i = 0; i < want[k].length; i++)
        if (!Object.is(got[k][i], want[k][i])) { bad.push(`${f} ${k}[${i}] ${got[k][i]} vs C ${want[k][i]}`); break; }
  }
  check(bins.length >= 2 && withVel >= 1, 'live flame frames captured, some with velocities', `${bins.length} frames, ${withVel} with velocities`);
  check(bad.length === 0, 'live flame frames: JS decodes what the C decoder gave, velocities included', bad.slice(0, 3).join('; '));
}

console.log(`test_web_decoders: ${passed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
