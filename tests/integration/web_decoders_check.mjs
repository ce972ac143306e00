// web_decoders_check.mjs — checks clients/web/src/rig.js (kind 3 decoder, point light,
// shadow direction) and the frame header parser of clients/web/fxs_particles.js against
// the C encoder's output. argv: VECDIR (rig-N.bin whole frames + rig-N.json expected values
// from test_light_rig --dump) and REALDIR (fxctl --out of a real daemon: energy-SEQ.bin
// payloads of kind 3 and lines.txt). Prints "test_web_decoders: N passed, M failed".
import { readFileSync, existsSync } from 'node:fs';
import { parseHeader, payloadOf } from '../../clients/web/fxs_particles.js';
import { decodeRig, RigState, pointLight, shadeM, rampColor, shadowDir, SEG_FLOATS } from '../../clients/web/src/rig.js';

const [vecDir, realDir] = process.argv.slice(2);
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
  check(lines.length === 6 && rigs.length >= 2, 'real daemon: texture and light-rig frames interleaved', `${lines.length} lines, ${rigs.length} rig`);
  let okAll = rigs.length > 0;
  for (const l of rigs) {
    const path = `${realDir}/energy-${l.seq}.bin`;
    if (!existsSync(path)) { okAll = false; continue; }
    const rig = decodeRig(new Uint8Array(readFileSync(path)));
    const c = rig.constants;
    okAll &&= l.codec === 1 && rig.nSeg === l.count && rig.nSeg === 16 && rig.hasConstants && c.bands.length === 2 &&
      c.bands[1].mMin === 0.25 && c.bands[1].rgb[1] === 0.5 && Math.abs(c.shadowTheta - Math.PI / 3) < 1e-6 &&
      rig.seg[0] === Math.fround(-13.2) && rig.seg[1] === Math.fround(-4.2) && rig.source[0] === 4 && rig.index[8] === 1;
  }
  check(okAll, 'real daemon: kind 3 payloads decode (16 curve chords from p0, the ramp just set, theta 60 deg)');
}

console.log(`test_web_decoders: ${passed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
