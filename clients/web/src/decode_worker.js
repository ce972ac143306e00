// decode_worker.js — the page's particle decoding thread (particle_decoder.js sends the
// payloads): the C decoder as WebAssembly (fxs_particles.wasm, next to this bundle in
// dist/), or fxs_particles.js's decode() where the module cannot be compiled (a browser
// without WebAssembly SIMD); the decoded arrays are transferred back, not copied. Bundled by
// build.mjs into dist/decode_worker.js as a classic worker script.
import { decode, loadWasmDecoder } from '../fxs_particles.js';

const decoder = loadWasmDecoder(new URL('fxs_particles.wasm', self.location.href)).then(
  (wasm) => ({ engine: 'wasm', decode: wasm }),
  (e) => {
    console.warn(`particle decoder: WebAssembly unavailable (${e.message}); decoding in JavaScript`);
    return { engine: 'js', decode };
  });

self.onmessage = async (e) => {
  const { id, payload } = e.data, { engine, decode: run } = await decoder;
  try {
    const particles = run(new Uint8Array(payload));
    const transfer = [particles.xyz.buffer, particles.temp.buffer, particles.fuel.buffer, particles.flags.buffer];
    if (particles.vel) transfer.push(particles.vel.buffer);
    self.postMessage({ id, engine, particles }, transfer);
  } catch (err) {
    self.postMessage({ id, engine, error: err.message });
  }
};
