// particles_js_bench.mjs — decode time of particle payloads in node (V8, the engine of
// Chrome) with both browser decoders of clients/web/fxs_particles.js: decode() in
// JavaScript and the C decoder as WebAssembly (clients/web/dist/fxs_particles.wasm).
// bench_particles runs it on the payloads it wrote:
//   node tests/bench/particles_js_bench.mjs WASM DIR_OR_FILE...
// (a directory stands for its *.bin files). One line per file: "FILE N JS_MS_PER_M
// WASM_MS_PER_M" (the best of several runs, after a warm-up), or "FILE error MESSAGE".
import { readFileSync, readdirSync, statSync } from 'node:fs';
import { join } from 'node:path';
import { decode, loadWasmDecoder } from '../../clients/web/fxs_particles.js';

const [wasmPath, ...args] = process.argv.slice(2);
const files = args.flatMap((a) => (statSync(a).isDirectory()
  ? readdirSync(a).filter((f) => f.endsWith('.bin')).sort().map((f) => join(a, f)) : [a]));
const wasm = await loadWasmDecoder(readFileSync(wasmPath));

// Best time per particle of decoding b with dec, in ms per million particles.
function best(dec, b) {
  const n = dec(b).n, runs = Math.max(5, Math.min(60, Math.round(2e6 / Math.max(n, 1))));
  let t = Infinity;
  for (let r = 0; r < runs; r++) {
    const t0 = performance.now();
    dec(b);
    t = Math.min(t, performance.now() - t0);
  }
  return { n, ms: (t * 1e6) / Math.max(n, 1) };
}

for (const file of files) {
  try {
    const b = new Uint8Array(readFileSync(file));
    const js = best(decode, b), w = best(wasm, b);
    console.log(`${file} ${js.n} ${js.ms.toFixed(1)} ${w.ms.toFixed(1)}`);
  } catch (e) {
    console.log(`${file} error ${e.message}`);
  }
}
