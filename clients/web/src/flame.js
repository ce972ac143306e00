// flame.js — the `flame` stream (kind 1 particles, codec 2, decoded by fxs_particles.js) in
// one of two modes, on a fixed stage (a ground grid in centimetres and each source's outline,
// in world units) with an orbit camera that never re-frames on the particles:
//
// pbvr (default), the thesis's particle-based volume rendering (digest 002 §4.4–4.6): per
//   physics particle n = floor(n_max·heat + u) render particles (heat = (T − T_amb) /
//   (T_max − T_amb)), each at a random offset from one shared table indexed only by (pass r,
//   emission k), never by the buffer index (the server re-sorts); opaque sprites with a holey
//   alpha texture (poly6 radial × improved Perlin noise) and an alpha test (§4.5 fix: discard
//   below the threshold), depth test and depth write; RL passes averaged with weight 1/RL
//   (the accumulation buffer), times an intensity scale. Colour from the chromaticity-
//   normalised blackbody table; particles cooler than the smoke threshold drawn the same way
//   in a user grey (§4.4 "smoke"), so the hot core is not a blown-out white. Optional
//   velocity lines (§4.4, "a line per render element ... from r to r + s·v") when the stream
//   sends velocities (its `velocities` parameter, PROTOCOL.md §7.5.7): one segment per
//   physics particle over the composited picture, additive, in the particle's colour (grey
//   for smoke) fading from the particle to the tip, fainter for cooler particles, so the
//   flow reads as streaks rather than a hairball.
// hdr: soft round additive sprites whose emission is the blackbody colour times a luminance
//   that grows with heat, in linear HDR, tone-mapped with three's ACES filmic curve and an
//   exposure control: a hot core is bright but rolls off instead of clipping.
import * as THREE from 'three';
import { decode, payloadOf } from '../fxs_particles.js';
import { ACES_GLSL, SRGB_GLSL, fullscreenQuad } from './gl.js';
import { ViewOrbit } from './orbit.js';

const NMAX = 8, RL_MAX = 32;
// digest 002 §4.2: chromaticity-normalised blackbody colours, linear RGB (800 … 3000 K)
const BB_T = [800, 1000, 1200, 1500, 1800, 2000, 2200, 2500, 2800, 3000];
const BB_RGB = [[1, 0.059, 0], [1, 0.116, 0], [1, 0.189, 0], [1, 0.314, 0.009], [1, 0.45, 0.088], [1, 0.543, 0.172],
  [1, 0.638, 0.283], [1, 0.778, 0.503], [1, 0.914, 0.783], [1, 1, 1]];

export const FLAME_DEFAULTS = {
  mode: 'pbvr', rl: 15, threshold: 0.3, intensity: 1.0, smoke: true, smokeT: 1000, smokeColor: '#595959',
  whiteT: 4000, exposure: 1.0, velLines: false, velScale: 0.005,
};
const LINE_ALPHA = 0.3; // a hot particle's segment at the particle; × (0.35 + 0.65 heat), fading to the tip

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

// Improved Perlin noise (Perlin 2002) in 2D: quintic fade, gradients from a permutation table.
function perlin2(seed) {
  const rnd = mulberry32(seed), p = Array.from({ length: 256 }, (_, i) => i);
  for (let i = 255; i > 0; i--) { const j = Math.floor(rnd() * (i + 1)); [p[i], p[j]] = [p[j], p[i]]; }
  const perm = [...p, ...p];
  const fade = (t) => t * t * t * (t * (t * 6 - 15) + 10);
  const grad = (h, x, y) => ((h & 1) ? -x : x) + ((h & 2) ? -y : y);
  return (x, y) => {
    const X = Math.floor(x) & 255, Y = Math.floor(y) & 255, xf = x - Math.floor(x), yf = y - Math.floor(y);
    const u = fade(xf), v = fade(yf), a = perm[X] + Y, b = perm[X + 1] + Y;
    const x1 = grad(perm[a], xf, yf) + u * (grad(perm[b], xf - 1, yf) - grad(perm[a], xf, yf));
    const x2 = grad(perm[a + 1], xf, yf - 1) + u * (grad(perm[b + 1], xf - 1, yf - 1) - grad(perm[a + 1], xf, yf - 1));
    return x1 + v * (x2 - x1); // about [-1, 1]
  };
}

// 64² sprite alpha: poly6 radial profile (1 − s²)³, times noise of 4 cells across when holey.
function spriteTexture(holey) {
  const N = 64, noise = perlin2(7), data = new Uint8Array(N * N * 4);
  for (let y = 0; y < N; y++)
    for (let x = 0; x < N; x++) {
      const u = (x + 0.5) / N * 2 - 1, v = (y + 0.5) / N * 2 - 1, s2 = Math.min(1, u * u + v * v);
      const radial = Math.pow(1 - s2, 3), n = holey ? Math.min(1, Math.max(0, 0.6 + 0.9 * noise((x / N) * 4, (y / N) * 4))) : 1;
      data.set([255, 255, 255, Math.round(radial * n * 255)], 4 * (y * N + x));
    }
  const t = new THREE.DataTexture(data, N, N, THREE.RGBAFormat);
  t.magFilter = t.minFilter = THREE.LinearFilter;
  t.needsUpdate = true;
  return t;
}

const COMMON_VERT = /* glsl */ `
uniform float tAmb, tMax, radius, pointScale;
uniform vec3 bbRGB[10];
uniform float bbT[10];
attribute float slot;
attribute vec3 ipos;
attribute float itemp;
varying vec3 vColor;
varying float vAlphaP;
vec3 blackbody(float T) {
  T *= 3000.0 / tMax;  // the table's white (3000 K) moved to the white point tMax
  if (T <= bbT[0]) return bbRGB[0];
  for (int i = 1; i < 10; i++)
    if (T <= bbT[i]) return mix(bbRGB[i - 1], bbRGB[i], (T - bbT[i - 1]) / (bbT[i] - bbT[i - 1]));
  return bbRGB[9];
}
float heatOf(float T) { return clamp((T - tAmb) / (tMax - tAmb), 0.0, 1.0); }
void place(vec3 p, float size) {
  vec4 mv = modelViewMatrix * vec4(p, 1.0);
  gl_Position = projectionMatrix * mv;
  gl_PointSize = clamp(pointScale * size / max(-mv.z, 1e-4), 1.0, 96.0);
}
void hide() { gl_Position = vec4(2.0, 2.0, 2.0, 1.0); gl_PointSize = 0.0; }`;

const PBVR_VERT = /* glsl */ `${COMMON_VERT}
uniform sampler2D randTex;
uniform float pass, nmax, smokeT, smokeOn, smokeAlpha;
uniform vec3 smokeColor;
void main() {
  vec4 rnd = texelFetch(randTex, ivec2(int(slot), int(pass)), 0);
  float u = texelFetch(randTex, ivec2(0, int(pass)), 0).w;   // the pass's dither
  bool hot = itemp >= smokeT;
  float smoke = clamp((itemp - tAmb) / max(smokeT - tAmb, 1.0), 0.0, 1.0);
  float n = hot ? floor(nmax * heatOf(itemp) + u) : smokeOn * floor(0.5 * nmax * smoke + u);
  if (slot >= n) { hide(); return; }
  place(ipos + radius * (2.0 * rnd.xyz - 1.0), 3.0 * radius);
  vColor = hot ? blackbody(itemp) : smokeColor;
  vAlphaP = hot ? clamp(itemp / tMax, 0.0, 1.0) : smokeAlpha;
}`;

const PBVR_FRAG = /* glsl */ `
uniform sampler2D alphaTex;
uniform float threshold;
varying vec3 vColor;
varying float vAlphaP;
void main() {
  if (texture2D(alphaTex, gl_PointCoord).a * vAlphaP < threshold) discard;  // §4.5 fix
  gl_FragColor = vec4(vColor, 1.0);                                         // opaque
}`;

// A velocity line: vertex `end` 0 at the particle, 1 at ipos + velScale · ivel (world units).
const LINE_VERT = /* glsl */ `${COMMON_VERT}
attribute float end;
attribute vec3 ivel;
uniform float velScale, smokeT, smokeOn, lineAlpha;
uniform vec3 smokeColor;
varying float vA;
void main() {
  bool hot = itemp >= smokeT;
  float a = hot ? lineAlpha * (0.35 + 0.65 * heatOf(itemp)) : smokeOn * 0.35 * lineAlpha;
  if (a <= 0.0) { hide(); return; }
  gl_Position = projectionMatrix * modelViewMatrix * vec4(ipos + end * velScale * ivel, 1.0);
  vColor = hot ? blackbody(itemp) : smokeColor;
  vA = a * (1.0 - 0.8 * end);
}`;

const LINE_FRAG = /* glsl */ `
varying vec3 vColor;
varying float vA;
${SRGB_GLSL}
void main() { gl_FragColor = vec4(linearToSRGB(vColor) * vA, 1.0); }  // additive over the picture
`;

const HDR_VERT = /* glsl */ `${COMMON_VERT}
void main() {
  float heat = heatOf(itemp);
  if (heat <= 0.0) { hide(); return; }
  place(ipos, 5.0 * radius);
  vColor = blackbody(itemp) * heat * heat;  // emission grows with heat; colour from the table
  vAlphaP = 1.0;
}`;

const HDR_FRAG = /* glsl */ `
uniform sampler2D alphaTex;
uniform float gain;
varying vec3 vColor;
void main() {
  gl_FragColor = vec4(vColor * gain * texture2D(alphaTex, gl_PointCoord).a, 1.0);  // additive
}`;

// The stage: a 40 cm ground grid of 1 cm cells normal to `up` and each source's outline.
function makeStage() {
  const g = new THREE.Group();
  const grid = new THREE.GridHelper(0.4, 40, 0x4a5060, 0x262a33);
  const axis = new THREE.Group();
  axis.add(grid);
  g.add(axis);
  g.userData = { axis, outlines: new THREE.Group() };
  g.add(g.userData.outlines);
  return g;
}

export class FlameView {
  constructor(stream) {
    this.stream = stream;
    this.kind = 'flame';
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(35, 1, 0.002, 20);
    this.settings = { ...FLAME_DEFAULTS };
    this.params = null;
    this.stageKey = '';
    this.count = 0;
    this.capacity = 0;
    this.newFrame = false;
    this.stage = makeStage();
    this.scene.add(this.stage);
    const common = {
      tAmb: { value: 300 }, tMax: { value: 3000 }, radius: { value: 0.002 }, pointScale: { value: 500 },
      bbT: { value: BB_T }, bbRGB: { value: BB_RGB.map((c) => new THREE.Vector3(...c)) },
    };
    this.pbvr = new THREE.ShaderMaterial({
      vertexShader: PBVR_VERT, fragmentShader: PBVR_FRAG,
      uniforms: {
        ...common, randTex: { value: randomTable() }, alphaTex: { value: spriteTexture(true) }, pass: { value: 0 },
        nmax: { value: NMAX }, threshold: { value: 0.3 }, smokeT: { value: 1000 }, smokeOn: { value: 1 },
        smokeAlpha: { value: 0.5 }, smokeColor: { value: new THREE.Color(0.1, 0.1, 0.1) },
      },
      depthTest: true, depthWrite: true, blending: THREE.NoBlending,
    });
    this.hdr = new THREE.ShaderMaterial({
      vertexShader: HDR_VERT, fragmentShader: HDR_FRAG,
      uniforms: { ...common, alphaTex: { value: spriteTexture(false) }, gain: { value: 0.08 } },
      depthTest: true, depthWrite: false, blending: THREE.AdditiveBlending, transparent: true,
    });
    this.lineMat = new THREE.ShaderMaterial({
      vertexShader: LINE_VERT, fragmentShader: LINE_FRAG,
      uniforms: {
        ...common, velScale: { value: 0.005 }, smokeT: { value: 1000 }, smokeOn: { value: 1 }, lineAlpha: { value: LINE_ALPHA },
        smokeColor: { value: new THREE.Color(0.35, 0.35, 0.35) },
      },
      depthTest: false, depthWrite: false, blending: THREE.AdditiveBlending, transparent: true,
    });
    this.geoms = { pbvr: null, hdr: null, lines: null };
    this.points = new THREE.Points(new THREE.BufferGeometry(), this.pbvr);
    this.points.frustumCulled = false;
    this.scene.add(this.points);
    this.lines = new THREE.LineSegments(new THREE.BufferGeometry(), this.lineMat);
    this.lines.frustumCulled = false;
    this.lineScene = new THREE.Scene();
    this.lineScene.add(this.lines);
    this.hasVel = false;     // the latest frame carried velocities
    this.lineVertices = 0;   // vertices of velocity lines in the latest draw (three's renderer.info)
    this.targets = {};
    this.accumulate = fullscreenQuad(/* glsl */ `
      uniform sampler2D src; uniform float weight; varying vec2 vUv;
      void main() { gl_FragColor = vec4(texture2D(src, vUv).rgb * weight, 1.0); }`,
    { src: { value: null }, weight: { value: 1 } }, { blending: THREE.AdditiveBlending, transparent: true });
    this.composite = fullscreenQuad(/* glsl */ `
      uniform sampler2D src; uniform float scale; uniform int aces; varying vec2 vUv;
      ${SRGB_GLSL}
      ${ACES_GLSL}
      void main() {
        vec3 c = texture2D(src, vUv).rgb * scale;
        gl_FragColor = vec4(linearToSRGB(aces == 1 ? acesFilmic(c) : c), 1.0);
      }`, { src: { value: null }, scale: { value: 1 }, aces: { value: 0 } });
    this.orbit = null;
  }

  // Mouse control on the shared canvas; css() gives this view's rectangle.
  attachControls(canvas, css) { this.orbit = new ViewOrbit(this.camera, canvas, css); this.frameStage(); }

  setParams(params) {
    this.params = params;
    const key = JSON.stringify([params.sources, params.up, params.space_scale]);
    if (key !== this.stageKey) { this.stageKey = key; this.buildStage(); }
  }

  // The stream in world units: units per metre, up, a horizontal side vector, the particle
  // spacing d and the first burning source's centre (base).
  frameOf() {
    const pr = this.params || {}, scale = pr.space_scale ?? 1;
    const up = new THREE.Vector3(...(pr.up || [0, 0, 1])).normalize();
    const side = Math.abs(up.y) < 0.9 ? new THREE.Vector3(0, -1, 0) : new THREE.Vector3(1, 0, 0);
    side.addScaledVector(up, -side.dot(up)).normalize();
    const src = (pr.sources || []).find((s) => s.enabled !== false) || { center: [0, 0, 0], radius: 0.015 };
    const d = (pr.particle_diameter ?? 0.5) * (pr.h ?? 0.01125) * scale; // particle spacing
    return { scale, up, side, d, base: new THREE.Vector3(...(src.center || [0, 0, 0])).multiplyScalar(scale) };
  }

  buildStage() {
    const { scale, up, base, d } = this.frameOf(), { axis, outlines } = this.stage.userData;
    axis.quaternion.setFromUnitVectors(new THREE.Vector3(0, 1, 0), up);
    axis.position.copy(base).addScaledVector(up, -2.5 * d);
    axis.scale.setScalar(scale);
    for (const c of [...outlines.children]) { outlines.remove(c); c.geometry.dispose(); c.material.dispose(); }
    for (const s of this.params?.sources || []) {
      if (s.enabled === false) continue;
      const ring = new THREE.BufferGeometry().setFromPoints(
        Array.from({ length: 64 }, (_, i) => new THREE.Vector3(Math.cos(i / 32 * Math.PI), 0, Math.sin(i / 32 * Math.PI)).multiplyScalar(s.radius * scale)));
      const line = new THREE.LineLoop(ring, new THREE.LineBasicMaterial({ color: 0x9a7a52 }));
      line.quaternion.setFromUnitVectors(new THREE.Vector3(0, 1, 0), up);
      line.position.copy(new THREE.Vector3(...(s.center || [0, 0, 0])).multiplyScalar(scale));
      outlines.add(line);
    }
    if (!this.orbit?.moved) this.frameStage();
  }

  // The camera's home: level with the lower flame, 42 cm away, looking at 7 cm above the source.
  frameStage() {
    if (!this.orbit) return;
    const { scale, up, side, base } = this.frameOf();
    const target = base.clone().addScaledVector(up, 0.07 * scale);
    this.orbit.setHome(target.clone().addScaledVector(side, 0.42 * scale).addScaledVector(up, 0.03 * scale), target, up);
  }

  // An instanced geometry over the shared per-particle attributes, `slots` sprites per particle.
  geometry(slots) {
    const g = new THREE.InstancedBufferGeometry();
    g.setAttribute('slot', new THREE.BufferAttribute(Float32Array.from({ length: slots }, (_, i) => i), 1));
    g.setAttribute('position', new THREE.BufferAttribute(new Float32Array(slots * 3), 3));
    g.setAttribute('ipos', this.ipos);
    g.setAttribute('itemp', this.itemp);
    return g;
  }

  // The velocity lines: two vertices (end 0, 1) per particle, instanced like the sprites.
  lineGeometry() {
    const g = this.geometry(2);
    g.setAttribute('end', new THREE.BufferAttribute(new Float32Array([0, 1]), 1));
    g.setAttribute('ivel', this.ivel);
    return g;
  }

  onFrame(h, buf) {
    if (h.kind !== 1 || (h.codec !== 2 && h.codec !== 3)) return false;
    const p = decode(payloadOf(buf, h));
    if (p.n > this.capacity) {
      // New geometries: three fixes an instanced geometry's largest instance count when it
      // first draws it, so growing the attributes in place would draw only the old count.
      this.capacity = Math.max(p.n, 2 * this.capacity, 1024);
      this.ipos = new THREE.InstancedBufferAttribute(new Float32Array(3 * this.capacity), 3);
      this.itemp = new THREE.InstancedBufferAttribute(new Float32Array(this.capacity), 1);
      this.ivel = new THREE.InstancedBufferAttribute(new Float32Array(3 * this.capacity), 3);
      for (const a of [this.ipos, this.itemp, this.ivel]) a.setUsage(THREE.DynamicDrawUsage);
      for (const g of Object.values(this.geoms)) g?.dispose();
      this.geoms = { pbvr: this.geometry(NMAX), hdr: this.geometry(1), lines: this.lineGeometry() };
      this.lines.geometry = this.geoms.lines;
    }
    this.ipos.array.set(p.xyz);
    this.itemp.array.set(p.temp);
    this.ipos.needsUpdate = this.itemp.needsUpdate = true;
    this.hasVel = p.vel !== null;
    if (this.hasVel) {
      this.ivel.array.set(p.vel);
      this.ivel.needsUpdate = true;
    }
    this.count = p.n;
    this.geoms.pbvr.instanceCount = this.geoms.hdr.instanceCount = this.geoms.lines.instanceCount = p.n;
    this.newFrame = true;
    return true;
  }

  target(name, w, h, depth) {
    let t = this.targets[name];
    if (!t || t.width !== w || t.height !== h) {
      t?.dispose();
      t = this.targets[name] = new THREE.WebGLRenderTarget(w, h, { type: THREE.HalfFloatType, depthBuffer: depth });
    }
    return t;
  }

  setUniforms(w, h) {
    const pr = this.params || {}, s = this.settings, { scale, d } = this.frameOf();
    for (const m of [this.pbvr, this.hdr]) {
      m.uniforms.tAmb.value = pr.T_amb ?? 300;
      m.uniforms.tMax.value = s.whiteT;
      m.uniforms.radius.value = d;
      m.uniforms.pointScale.value = h / (2 * Math.tan(THREE.MathUtils.degToRad(this.camera.fov / 2)));
    }
    const u = this.pbvr.uniforms, lu = this.lineMat.uniforms;
    u.threshold.value = s.threshold;
    lu.velScale.value = s.velScale; // tAmb, tMax and the table: the uniforms all three materials share
    for (const m of [u, lu]) {
      m.smokeOn.value = s.smoke ? 1 : 0;
      m.smokeT.value = s.smokeT;
      m.smokeColor.value.set(s.smokeColor).convertSRGBToLinear();
    }
    this.camera.aspect = w / h;
    this.camera.near = 0.002 * scale;
    this.camera.far = 20 * scale;
    this.camera.updateProjectionMatrix();
  }

  render(renderer, rect) {
    if (!this.count) return false;
    const w = Math.max(1, Math.round(rect.w)), h = Math.max(1, Math.round(rect.h)), s = this.settings;
    this.orbit?.update();
    this.setUniforms(w, h);
    const hdr = s.mode === 'hdr';
    this.points.material = hdr ? this.hdr : this.pbvr;
    this.points.geometry = hdr ? this.geoms.hdr : this.geoms.pbvr;
    renderer.setScissorTest(false);
    renderer.setClearColor(0x000000, 1);
    let out;
    if (hdr) {
      out = this.target('hdr', w, h, true);
      renderer.setRenderTarget(out);
      renderer.clear(true, true, false);
      renderer.render(this.scene, this.camera);
    } else {
      out = this.target('accum', w, h, false);
      const pass = this.target('pass', w, h, true), rl = Math.max(1, Math.min(RL_MAX, Math.round(s.rl)));
      renderer.setRenderTarget(out);
      renderer.clear(true, false, false);
      this.accumulate.material.uniforms.src.value = pass.texture;
      this.accumulate.material.uniforms.weight.value = 1 / rl;
      for (let r = 0; r < rl; r++) { // one opaque, depth-tested pass per row of the random table
        this.pbvr.uniforms.pass.value = r;
        renderer.setRenderTarget(pass);
        renderer.clear(true, true, false);
        renderer.render(this.scene, this.camera);
        renderer.setRenderTarget(out);
        renderer.render(this.accumulate.scene, this.accumulate.camera);
      }
    }
    renderer.setRenderTarget(null);
    renderer.setViewport(rect.x, rect.y, rect.w, rect.h);
    renderer.setScissor(rect.x, rect.y, rect.w, rect.h);
    renderer.setScissorTest(true);
    const cu = this.composite.material.uniforms;
    cu.src.value = out.texture;
    cu.scale.value = hdr ? s.exposure : s.intensity;
    cu.aces.value = hdr ? 1 : 0;
    renderer.render(this.composite.scene, this.composite.camera);
    this.lineVertices = 0;
    if (!hdr && s.velLines && this.hasVel) { // over the picture, in this view's rectangle
      renderer.render(this.lineScene, this.camera);
      this.lineVertices = 2 * renderer.info.render.lines;
    }
    const drew = this.newFrame;
    this.newFrame = false;
    return drew;
  }

  info() {
    return {
      mode: this.settings.mode, count: this.count, cam: this.camera.position.toArray(), target: this.orbit?.target?.toArray(),
      velocities: this.hasVel, lineVertices: this.lineVertices,
    };
  }

  dispose() {
    for (const t of Object.values(this.targets)) t.dispose();
    for (const g of Object.values(this.geoms)) g?.dispose();
    this.pbvr.dispose();
    this.hdr.dispose();
    this.lineMat.dispose();
    this.orbit?.dispose();
  }
}
