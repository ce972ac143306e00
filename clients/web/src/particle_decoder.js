// particle_decoder.js — the flame's particle frames decoded off the main thread: one Web
// Worker for the page (decode_worker.js, bundled to dist/) runs the C decoder as
// WebAssembly (dist/fxs_particles.wasm), or fxs_particles.js's decode() where that module
// cannot run, and transfers the decoded arrays back. Each ParticleDecoder (one per view)
// keeps the latest-frame-wins rule of PROTOCOL.md §8.1 on this side too: while one of its
// frames is being decoded, a newer one replaces the frame waiting, whose promise resolves to
// null. Where no worker can be started the frames are decoded here, in JavaScript.
import { decode, payloadOf } from '../fxs_particles.js';

let worker = null, nextId = 1;
const inFlight = new Map(); // request id -> { resolve, reject }
const status = { engine: 'none', error: null }; // the worker's decoder ('wasm' or 'js') once it answers

function workerOrNull() {
  if (worker !== null) return worker || null;
  try {
    worker = new Worker(new URL('./decode_worker.js', import.meta.url));
  } catch (e) {
    worker = false;
    status.error = `no decoder worker (${e.message}); decoding on the main thread`;
    return null;
  }
  worker.onmessage = (e) => {
    const { id, particles, error, engine } = e.data, r = inFlight.get(id);
    inFlight.delete(id);
    status.engine = engine;
    if (error) r.reject(new Error(error));
    else r.resolve(particles);
  };
  worker.onerror = (e) => { // the worker could not load or run: every frame waiting fails, later ones decode here
    e.preventDefault();
    worker.terminate();
    worker = false;
    status.error = `the decoder worker failed (${e.message || 'not loaded'}); decoding on the main thread`;
    for (const r of inFlight.values()) r.reject(new Error(status.error));
    inFlight.clear();
  };
  return worker;
}

// One payload decoded in the worker (its own copy, transferred), or here without one.
function decodePayload(payload) {
  const w = workerOrNull();
  if (!w) {
    status.engine = 'main-thread js';
    return Promise.resolve().then(() => decode(payload));
  }
  const id = nextId++;
  return new Promise((resolve, reject) => {
    inFlight.set(id, { resolve, reject });
    w.postMessage({ id, payload: payload.buffer }, [payload.buffer]);
  });
}

/** The decoder the page uses ('wasm', 'js', 'main-thread js', or 'none' before the first
 *  frame) and why it is not the worker's, if so. */
export function particleDecoderStatus() {
  return { ...status };
}

export class ParticleDecoder {
  constructor() {
    this.busy = false;
    this.waiting = null; // { payload, resolve, reject } of the newest frame not yet sent
  }

  /** Resolves to decode()'s {n, xyz, temp, fuel, flags, vel} for the frame (h, buf), or to
   *  null when a newer frame replaced it before its turn; rejects with the decoder's error. */
  decode(h, buf) {
    const payload = payloadOf(buf, h).slice(); // a copy: buf stays whole for other views of the frame
    return new Promise((resolve, reject) => {
      this.waiting?.resolve(null);
      this.waiting = { payload, resolve, reject };
      this.pump();
    });
  }

  pump() {
    if (this.busy || !this.waiting) return;
    const job = this.waiting;
    this.waiting = null;
    this.busy = true;
    decodePayload(job.payload).then(job.resolve, job.reject).finally(() => {
      this.busy = false;
      this.pump();
    });
  }
}
