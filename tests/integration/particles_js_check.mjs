// particles_js_check.mjs — decodes the C encoder's codec 2 test vectors (tests/data/particles/*.bin), alone and back to back as codec 3 payloads,
// with both browser decoders of clients/web/fxs_particles.js, decode() (JavaScript) and
// loadWasmDecoder() (the C decoder as WebAssembly: clients/web/dist/fxs_particles.wasm, which
// make builds; missing, it fails), and compares with what the C decoder gave (*.json):
// every float bit for bit (both decoders compute float32(lo + q * step) in double), flags
// exactly, velocities (§7.5.7) exactly where the C decoder gave them and none elsewhere. Also: a frame header round trip, and truncated/corrupt payloads must throw a
// "particles:" error, never return garbage silently or crash; on every corrupted vector the
// two decoders give the same particles or the same error. Prints
// "test_particles_js: N passed, M failed" last; exit status 1 on any failure.
import { readFileSync, readdirSync } from 'node:fs';
import { join, dirname } from 'node:path';
import { fileURLToPath } from 'node:url';
import { decode as decodeJs, decodeFrame, loadWasmDecoder, parseHeader } from '../../clients/web/fxs_particles.js';

const root = join(dirname(fileURLToPath(import.meta.url)), '..', '..');
const dir = join(root, 'tests', 'data', 'particles');
const wasmPath = join(root, 'clients', 'web', 'dist', 'fxs_particles.wasm');
let passed = 0, failed = 0;

function checkNamed(name, fn) {
  try {
    const why = fn();
    if (why) throw new Error(why);
    passed++;
    console.log(`ok   ${name}`);
  } catch (e) {
    failed++;
    console.log(`FAIL ${name}: ${e.message}`);
  }
}

const check = checkNamed;

// The result of decoding bin: {p} or {error}.
function outcome(decode, bin) {
  try {
    return { p: decode(bin) };
  } catch (e) {
    return { error: e.message };
  }
}

function compare(got, want) {
  if (got.n !== want.n) return `n ${got.n} vs ${want.n}`;
  if (!want.vel !== !got.vel) return `velocities: ${got.vel ? 'decoded' : 'none'}, C gave ${want.vel ? 'them' : 'none'}`;
  for (const key of ['xyz', 'temp', 'fuel', 'flags', ...(want.vel ? ['vel'] : [])]) {
    if (got[key].length !== want[key].length) return `${key}: length ${got[key].length} vs ${want[key].length}`;
    for (let i = 0; i < want[key].length; i++) {
      const w = key === 'flags' ? want[key][i] : Math.fround(want[key][i]);
      if (!Object.is(got[key][i], w)) return `${key}[${i}] = ${got[key][i]}, C gave ${w}`;
    }
  }
  return null;
}

// null when decode() of bin cut to each of lengths throws a "particles:" error.
function cutsRejected(decode, bin, lengths) {
  for (const l of lengths) {
    try {
      decode(bin.subarray(0, l));
      return `decoded when cut to ${l} of ${bin.length} bytes`;
    } catch (e) {
      if (!e.message.startsWith('particles: ')) return `cut to ${l}: ${e.message}`;
    }
  }
  return null;
}

function frameOf(payload, n) {
  const msg = new Uint8Array(64 + payload.length);
  const v = new DataView(msg.buffer);
  msg.set([0x46, 0x58, 0x53, 0x31]);
  v.setUint16(4, 64, true);
  v.setUint16(6, 1, true);
  v.setUint32(8, 7, true);
  v.setBigUint64(16, 42n, true);
  v.setFloat64(24, 1.5, true);
  v.setUint32(40, 2, true);
  v.setUint32(44, payload.length, true);
  v.setUint32(48, n, true);
  msg.set(payload, 64);
  return msg;
}

const names = readdirSync(dir).filter((f) => f.endsWith('.bin')).map((f) => f.slice(0, -4)).sort();
check('test vectors present', () => (names.length >= 4 ? null : `only ${names.length} in ${dir}`));

// Every check below, once per decoder: `decode` is the decoder under test, `tag` names it
// (and prefixes its checks).
function decoderChecks(tag, decode) {
  const check = (what, fn) => checkNamed(`${tag}: ${what}`, fn);
  for (const name of names) {
    const bin = new Uint8Array(readFileSync(join(dir, `${name}.bin`)));
    const want = JSON.parse(readFileSync(join(dir, `${name}.json`), 'utf8'));
    check(`vector ${name} (n=${want.n})`, () => compare(decode(bin), want));
    if (tag === 'js') check(`vector ${name} as a frame`, () => {
      const { header, particles } = decodeFrame(frameOf(bin, want.n).buffer);
      if (header.seq !== 42n || header.channel !== 7 || header.simTime !== 1.5) return 'header fields';
      return compare(particles, want);
    });
    check(`vector ${name} truncated`, () => cutsRejected(decode, bin, bin.keys()));
    check(`vector ${name} corrupt bytes`, () => {
      let seed = 1;
      for (let t = 0; t < 500; t++) {
        const bad = bin.slice();
        seed = (seed * 1103515245 + 12345) >>> 0;
        bad[seed % bad.length] ^= 1 + (seed >>> 24) % 255;
        const got = outcome(decode, bad);
        if (got.error && !got.error.startsWith('particles: ')) return `unexpected error ${got.error}`;
        if (got.p && got.p.xyz.length !== 3 * got.p.n) return 'inconsistent output';
        if (tag !== 'js') { // the same result as the JavaScript decoder's, error or particles
          const js = outcome(decodeJs, bad);
          if (js.error !== got.error) return `byte ${seed % bad.length}: ${got.error ?? 'decoded'}, JavaScript: ${js.error ?? 'decoded'}`;
          const why = js.p && compare(got.p, js.p);
          if (why) return `byte ${seed % bad.length}: ${why}`;
        }
      }
      return null;
    });
  }
  // Codec 3 (§7.5.8): blocks back to back decode as the blocks' particles in order.
  const vec = (name) => ({ bin: new Uint8Array(readFileSync(join(dir, `${name}.bin`))),
    want: JSON.parse(readFileSync(join(dir, `${name}.json`), 'utf8')) });
  function concat(parts) {
    const out = new Uint8Array(parts.reduce((s, p) => s + p.length, 0));
    let at = 0;
    for (const p of parts) { out.set(p, at); at += p.length; }
    return out;
  }
  function merged(wants) {
    const m = { n: 0, xyz: [], temp: [], fuel: [], flags: [], vel: wants[0].vel ? [] : undefined };
    for (const w of wants) {
      m.n += w.n;
      for (const key of ['xyz', 'temp', 'fuel', 'flags', ...(m.vel ? ['vel'] : [])]) m[key].push(...w[key]);
    }
    return m;
  }
  for (const set of [['flame64', 'seven_8bit', 'real_flame600', 'empty'], ['flame64_vel', 'empty_vel', 'seven_vel_4bit', 'real_vel600_12bit']]) {
    const vs = set.map(vec), bin = concat(vs.map((v) => v.bin)), want = merged(vs.map((v) => v.want));
    check(`codec 3: ${set.join(' + ')} back to back`, () => compare(decode(bin), want));
    if (tag === 'js') check(`codec 3: ${set.join(' + ')} as a frame`, () => {
      const f = frameOf(bin, want.n);
      new DataView(f.buffer).setUint32(40, 3, true);
      return compare(decodeFrame(f.buffer).particles, want);
    });
    check(`codec 3: ${set.join(' + ')} cut anywhere is rejected`, () => {
      const ends = vs.map((_, k) => vs.slice(0, k + 1).reduce((s, v) => s + v.bin.length, 0)); // block boundaries
      return cutsRejected(decode, bin, Array.from({ length: bin.length }, (_, l) => l).filter((l) => l % 7 === 1 && !ends.includes(l)));
    });
  }
  const rejects = (bin, want) => {
    try {
      decode(bin);
      return 'accepted';
    } catch (e) {
      return e.message.includes(want) ? null : e.message;
    }
  };
  check('codec 3: blocks with and without velocities rejected', () =>
    rejects(concat([vec('flame64').bin, vec('flame64_vel').bin]), 'blocks disagree on velocities'));
  check('codec 3: 64 empty blocks decode, 65 are rejected', () => {
    const e = vec('empty').bin;
    if (decode(concat(Array(64).fill(e))).n !== 0) return '64 empty blocks';
    return rejects(concat(Array(65).fill(e)), 'more blocks than allowed');
  });
  check('codec 3: trailing garbage after a block rejected', () =>
    rejects(concat([vec('flame64').bin, new TextEncoder().encode('garbage!')]), 'not a codec 2 payload'));
  check('unknown attribute mode rejected', () => {
    const bin = new Uint8Array(readFileSync(join(dir, 'real_flame600.bin')));
    if (bin[11] !== 1) return `real_flame600 uses attribute mode ${bin[11]}, expected 1`;
    const bad = bin.slice();
    bad[11] = 2;
    try {
      decode(bad);
      return 'accepted';
    } catch (e) {
      return e.message.startsWith('particles: ') ? null : e.message;
    }
  });
  check('velocity vectors present', () => (names.filter((n) => n.includes('vel')).length >= 3 ? null : 'fewer than 3'));
  check('velocity block: bad flags, bits, reserved bytes and bounds rejected', () => {
    const bin = new Uint8Array(readFileSync(join(dir, 'flame64_vel.bin')));
    if (!(bin[11] & 0x10)) return `flame64_vel has attr_mode ${bin[11]}`;
    const cases = [[11, 0x30], [11, bin[11] & 15], [64, 1], [64, 17], [65, 1], [67, 128], [71, 0xff], [79, 0x7f]];
    for (const [at, val] of cases) {
      const bad = bin.slice();
      bad[at] = val;
      if (at === 79) bad[78] = 0x80; // vmax z = +inf (0x7f800000)
      try {
        decode(bad);
        return `byte ${at} = ${val} accepted`;
      } catch (e) {
        if (!e.message.startsWith('particles: ')) return e.message;
      }
    }
    return null;
  });
  check('version 2 payload (replaced by version 3) rejected, naming the version', () => {
    const old = new Uint8Array(readFileSync(join(dir, 'replaced', 'flame64_version2.bin')));
    if (old[4] !== 2) return 'the file is not a version 2 payload';
    try {
      decode(old);
      return 'accepted';
    } catch (e) {
      return e.message === 'particles: unsupported version (this decoder reads version 3)' ? null : e.message;
    }
  });
  check('codec 1 payload rejected', () => {
    const bin = new Uint8Array(readFileSync(join(dir, 'flame64.bin')));
    const old = bin.slice();
    old[3] = 0x31; // 'FXP1'
    old[4] = 1;
    try {
      decode(old);
      return 'accepted';
    } catch (e) {
      return e.message.startsWith('particles: ') ? null : e.message;
    }
  });
}

decoderChecks('js', decodeJs);
let wasm = null, wasmError = null;
try {
  wasm = await loadWasmDecoder(readFileSync(wasmPath));
} catch (e) {
  wasmError = e.message;
}
check('the WebAssembly decoder loads (make builds clients/web/dist/fxs_particles.wasm)', () => wasmError);
if (wasm) decoderChecks('wasm', wasm);

check('header: bad magic rejected', () => {
  try {
    parseHeader(new Uint8Array(64));
    return 'accepted';
  } catch (e) {
    return null;
  }
});

console.log(`test_particles_js: ${passed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
