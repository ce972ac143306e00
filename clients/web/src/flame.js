// flame.js — the `flame` stream (kind 1 particles, codec 2) drawn as in digest 002 §4.6:
// per physics particle n = floor(n_max·heat + u) render particles (heat = (T − T_amb) /
// (T_max − T_amb)), each an additive sprite at a random offset from a shared table indexed
// only by (repeat pass r, emission k) (never by the buffer index: the server re-sorts),
// with a holey alpha texture (poly6 radial × noise) and an alpha test, coloured by the
// blackbody table (T_max = 3000 K white). The RL passes are averaged with weight 1/RL into
// a half-float target (additive passes commute, so one instanced draw holds them all),
// then tone-mapped into the view. Particles come from fxs_particles.js (bit-identical to C).
import * as THREE from 'three';
import { decode, payloadOf } from '../fxs_particles.js';
import { SRGB_GLSL, fullscreenQuad } from './gl.js';

const NMAX = 8, RL_MAX = 32;
// digest 002 §4.2: chromaticity-normalised blackbody colours, linear RGB (800 … 3000 K)
const BB_T = [800, 1000, 1200, 1500, 1800, 2000, 2200, 2500, 2800, 3000];
const BB_RGB = [[1, 0.059, 0], [1, 0.116, 0], [1, 0.189, 0], [1, 0.314, 0.009], [1, 0.45, 0.088], [1, 0.543, 0.172],
  [1, 0.638, 0.283], [1, 0.778, 0.503], [1, 0.914, 0.783], [1, 1, 1]];

/** Linear blackbody colour of T (the same table the shader interpolates; for tests). */
export function blackbody(T) {
  if (T <= BB_T[0]) return BB_RGB[0];
  for (let i = 1; i < BB_T.length; i++)
    if (T <= BB_T[i]) {
      const f = (T - BB_T[i - 1]) / (BB_T[i] - BB_T[i - 1]);
      return BB_RGB[i].map((v, c) => BB_RGB[i - 1][c] + f * (v - BB_RGB[i - 1][c]));
    }
  return BB_RGB[BB_RGB.length - 1];
}

function mulberry32(seed) {
  return () => {
    seed |= 0; seed = (seed + 0x6d2b79f5) | 0;
    let t = Math.imul(seed ^ (seed >>> 15), 1 | seed);
    t = (t + Math.imul(t ^ (t >>> 7), 61 | t)) ^ t;
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
}

// The shared random table: RL_MAX rows (passes) × NMAX columns (emission index), xyz offset + w dither.
function randomTable() {
  const rnd = mulberry32(1000), data = new Float32Array(RL_MAX * NMAX * 4);
  for (let i = 0; i < data.length; i++) data[i] = rnd();
  const t = new THREE.DataTexture(data, NMAX, RL_MAX, THREE.RGBAFormat, THREE.FloatType);
  t.needsUpdate = true;
  return t;
}

// 64² alpha texture: poly6 radial profile (1 − s²)³ × value noise of 4 cells across (§4.4).
function alphaTexture() {
  const N = 64, rnd = mulberry32(7), g = [];
  for (let i = 0; i < 25; i++) g.push(rnd());
  const lat = (x, y) => g[(y % 5) * 5 + (x % 5)];
  const noise = (x, y) => {
    const xi = Math.floor(x), yi = Math.floor(y), fx = x - xi, fy = y - yi;
    const sx = fx * fx * (3 - 2 * fx), sy = fy * fy * (3 - 2 * fy);
    const a = lat(xi, yi) + sx * (lat(xi + 1, yi) - lat(xi, yi)), b = lat(xi, yi + 1) + sx * (lat(xi + 1, yi + 1) - lat(xi, yi + 1));
    return a + sy * (b - a);
  };
  const data = new Uint8Array(N * N * 4);
  for (let y = 0; y < N; y++)
    for (let x = 0; x < N; x++) {
      const u = (x + 0.5) / N * 2 - 1, v = (y + 0.5) / N * 2 - 1, s2 = Math.min(1, u * u + v * v);
      const radial = Math.pow(1 - s2, 3), n = 0.55 + 0.9 * noise((x / N) * 4, (y / N) * 4) - 0.2;
      const a = Math.max(0, Math.min(1, radial * n * 1.25));
      data.set([255, 255, 255, Math.round(a * 255)], 4 * (y * N + x));
    }
  const t = new THREE.DataTexture(data, N, N, THREE.RGBAFormat);
  t.magFilter = t.minFilter = THREE.LinearFilter;
  t.needsUpdate = true;
  return t;
}

const VERT = /* glsl */ `
uniform sampler2D randTex;
uniform float rl, nmax, tAmb, tMax, radius, pointScale;
attribute float slot;
attribute vec3 ipos;
attribute float itemp;
varying vec3 vColor;
varying float vAlphaP;
uniform vec3 bbRGB[10];
uniform float bbT[10];
vec3 blackbody(float T) {
  if (T <= bbT[0]) return bbRGB[0];
  for (int i = 1; i < 10; i++)
    if (T <= bbT[i]) return mix(bbRGB[i - 1], bbRGB[i], (T - bbT[i - 1]) / (bbT[i] - bbT[i - 1]));
  return bbRGB[9];
}
void main() {
  float r = floor(slot / nmax), k = slot - r * nmax;
  vec4 rnd = texelFetch(randTex, ivec2(int(k), int(r)), 0);
  float heat = clamp((itemp - tAmb) / (tMax - tAmb), 0.0, 1.0);
  float n = floor(nmax * heat + texelFetch(randTex, ivec2(0, int(r)), 0).w);
  if (r >= rl || k >= n) { gl_Position = vec4(2.0, 2.0, 2.0, 1.0); gl_PointSize = 0.0; return; }
  vec3 p = ipos + radius * (2.0 * rnd.xyz - 1.0);
  vec4 mv = modelViewMatrix * vec4(p, 1.0);
  gl_Position = projectionMatrix * mv;
  gl_PointSize = clamp(pointScale * 2.0 * radius / max(-mv.z, 1e-4), 1.0, 64.0);
  vColor = blackbody(itemp);
  vAlphaP = clamp(itemp / tMax, 0.0, 1.0);
}`;

const FRAG = /* glsl */ `
uniform sampler2D alphaTex;
uniform float threshold, gain, rl;
varying vec3 vColor;
varying float vAlphaP;
void main() {
  float a = texture2D(alphaTex, gl_PointCoord).a * vAlphaP;
  if (a < threshold) discard;                  // §4.5 fix: discard below the threshold
  gl_FragColor = vec4(vColor * gain / rl, 1.0); // additive, averaged over the RL passes
}`;

export class FlameView {
  constructor(stream) {
    this.stream = stream;
    this.kind = 'flame';
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(35, 1, 0.001, 100);
    this.settings = { rl: 15, threshold: 0.35, gain: 0.22, exposure: 1.0, sprite: 1.0 };
    this.params = null;
    this.count = 0;
    this.capacity = 0;
    this.center = null;
    this.extent = 0.1;
    this.newFrame = false;
    this.geom = new THREE.InstancedBufferGeometry();
    this.slots = 0;
    this.setSlots(15);
    this.material = new THREE.ShaderMaterial({
      vertexShader: VERT, fragmentShader: FRAG,
      uniforms: {
        randTex: { value: randomTable() }, alphaTex: { value: alphaTexture() },
        rl: { value: 15 }, nmax: { value: NMAX }, tAmb: { value: 300 }, tMax: { value: 3000 },
        radius: { value: 0.003 }, pointScale: { value: 500 }, threshold: { value: 0.35 }, gain: { value: 1.6 },
        bbT: { value: BB_T }, bbRGB: { value: BB_RGB.map((c) => new THREE.Vector3(...c)) },
      },
      blending: THREE.AdditiveBlending, depthTest: false, depthWrite: false, transparent: true,
    });
    this.points = new THREE.Points(this.geom, this.material);
    this.points.frustumCulled = false;
    this.scene.add(this.points);
    this.target = null;
    this.composite = fullscreenQuad(/* glsl */ `
      uniform sampler2D src; uniform float exposure; varying vec2 vUv;
      ${SRGB_GLSL}
      void main() {
        vec3 c = texture2D(src, vUv).rgb;
        c = 1.0 - exp(-c * exposure);               // soft HDR roll-off: the hot core saturates to white
        gl_FragColor = vec4(linearToSRGB(c), 1.0);
      }`, { src: { value: null }, exposure: { value: 1.4 } });
  }

  // RL × n_max render-particle slots per physics particle (pass r, emission k).
  setSlots(rl) {
    if (this.slots === rl * NMAX) return;
    this.slots = rl * NMAX;
    this.geom.setAttribute('slot', new THREE.BufferAttribute(new Float32Array(this.slots).map((_, i) => i), 1));
    this.geom.setAttribute('position', new THREE.BufferAttribute(new Float32Array(this.slots * 3), 3));
  }

  setParams(params) { this.params = params; }

  onFrame(h, buf) {
    if (h.kind !== 1 || h.codec !== 2) return false;
    const p = decode(payloadOf(buf, h));
    if (p.n > this.capacity) {
      // A new geometry: three fixes an instanced geometry's largest instance count when it
      // first draws it, so growing the attributes in place would draw only the old count.
      this.capacity = Math.max(p.n, 2 * this.capacity, 1024);
      const old = this.geom;
      this.geom = new THREE.InstancedBufferGeometry();
      this.slots = 0;
      this.setSlots(Math.max(1, Math.round(this.settings.rl)));
      this.points.geometry = this.geom;
      old.dispose();
      this.ipos = new THREE.InstancedBufferAttribute(new Float32Array(3 * this.capacity), 3);
      this.itemp = new THREE.InstancedBufferAttribute(new Float32Array(this.capacity), 1);
      this.ipos.setUsage(THREE.DynamicDrawUsage);
      this.itemp.setUsage(THREE.DynamicDrawUsage);
      this.geom.setAttribute('ipos', this.ipos);
      this.geom.setAttribute('itemp', this.itemp);
    }
    this.ipos.array.set(p.xyz);
    this.itemp.array.set(p.temp);
    this.ipos.needsUpdate = this.itemp.needsUpdate = true;
    this.count = p.n;
    this.geom.instanceCount = p.n;
    this.frameBounds(p);
    this.newFrame = true;
    return true;
  }

  // Frames the camera on the hot particles (smoothed, so the view does not jump).
  frameBounds(p) {
    const tAmb = this.params?.T_amb ?? 300;
    const axes = [[], [], []];
    const step = Math.max(1, Math.floor(p.n / 4000));
    for (let i = 0; i < p.n; i += step) {
      if (p.temp[i] < tAmb + 300 || (p.flags[i] & 3) === 2) continue;
      for (let c = 0; c < 3; c++) axes[c].push(p.xyz[3 * i + c]);
    }
    if (axes[0].length < 8) return;
    const lo = [], hi = [];
    for (let c = 0; c < 3; c++) { // 2nd and 98th percentiles: a few stray hot particles do not move the view
      const a = Float32Array.from(axes[c]).sort();
      lo[c] = a[Math.floor(0.02 * (a.length - 1))];
      hi[c] = a[Math.ceil(0.98 * (a.length - 1))];
    }
    const ctr = lo.map((v, c) => (v + hi[c]) / 2), ext = Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], 1e-3);
    if (!this.center) { this.center = ctr; this.extent = ext; }
    else { this.center = this.center.map((v, c) => v + 0.1 * (ctr[c] - v)); this.extent += 0.1 * (ext - this.extent); }
  }

  render(renderer, rect, t) {
    if (!this.count) return false;
    const w = Math.max(1, Math.round(rect.w)), h = Math.max(1, Math.round(rect.h));
    if (!this.target || this.target.width !== w || this.target.height !== h) {
      this.target?.dispose();
      this.target = new THREE.WebGLRenderTarget(w, h, { type: THREE.HalfFloatType, depthBuffer: false });
    }
    const pr = this.params || {};
    const scale = pr.space_scale ?? 1, hsup = (pr.h ?? 0.01125) * scale, d = (pr.particle_diameter ?? 0.5) * hsup;
    const up = new THREE.Vector3(...(pr.up || [0, 0, 1])).normalize();
    const side = Math.abs(up.y) < 0.9 ? new THREE.Vector3(0, -1, 0) : new THREE.Vector3(1, 0, 0);
    side.addScaledVector(up, -side.dot(up)).normalize();
    const ctr = new THREE.Vector3(...this.center);
    const dist = (this.extent * 0.9 + 4 * d) / Math.tan(THREE.MathUtils.degToRad(this.camera.fov / 2));
    this.camera.up.copy(up);
    this.camera.position.copy(ctr).addScaledVector(side, dist);
    this.camera.lookAt(ctr);
    this.camera.aspect = w / h;
    this.camera.near = dist / 100;
    this.camera.far = dist * 10;
    this.camera.updateProjectionMatrix();
    const u = this.material.uniforms, s = this.settings;
    u.rl.value = Math.max(1, Math.min(RL_MAX, Math.round(s.rl)));
    this.setSlots(u.rl.value);
    u.threshold.value = s.threshold;
    u.gain.value = s.gain;
    u.tAmb.value = pr.T_amb ?? 300;
    u.radius.value = d * s.sprite;
    u.pointScale.value = h / (2 * Math.tan(THREE.MathUtils.degToRad(this.camera.fov / 2)));
    renderer.setRenderTarget(this.target);
    renderer.setViewport(0, 0, w, h);
    renderer.setScissorTest(false);
    renderer.setClearColor(0x000000, 1);
    renderer.clear(true, false, false);
    renderer.render(this.scene, this.camera);
    renderer.setRenderTarget(null);
    renderer.setViewport(rect.x, rect.y, rect.w, rect.h);
    renderer.setScissor(rect.x, rect.y, rect.w, rect.h);
    renderer.setScissorTest(true);
    this.composite.material.uniforms.src.value = this.target.texture;
    this.composite.material.uniforms.exposure.value = s.exposure;
    renderer.render(this.composite.scene, this.composite.camera);
    const drew = this.newFrame;
    this.newFrame = false;
    return drew;
  }

  dispose() { this.target?.dispose(); this.geom.dispose(); this.material.dispose(); }
}
