// flame.js — the `flame` stream (kind 1 particles, codec 2, decoded in a worker: particle_decoder.js) in
// one of three modes, on a fixed stage (a ground grid in centimetres and each source's outline,
// in world units) with an orbit camera that never re-frames on the particles:
//
// volume (default), a continuous emissive body as real-time fire is drawn in games: each
//   particle is splatted as a soft Gaussian kernel (a few particle spacings wide) into a
//   half-resolution float target that sums emission (hot particles, growing with heat),
//   emission × heat and smoke density (cooling gas); nothing is splatted below the sources'
//   plane (the plate). A composite pass maps the emission-weighted mean heat through a fire
//   ramp (deep red → orange → yellow-white), turns emission into opacity with 1 − e^(−gain·E)
//   so the core saturates to the ramp's colour instead of clipping to white, breaks the edge
//   into rising tongues with animated noise (a displacement that grows with height and a
//   modulation of the emission), and lays grey smoke under the fire; the result is blended
//   over the stage with premultiplied alpha, so the grid is hidden behind the flame.
//   Splatting on the client keeps the wire format and the server's cost unchanged, and one
//   draw of N sprites plus one full-screen pass is cheap on any WebGL2 GPU.
// pbvr, the thesis's particle-based volume rendering (digest 002 §4.4–4.6): per
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
//   that grows with heat, in linear HDR, tone-mapped with three's ACES filmic curve on the
//   luminance (the hue kept) and an exposure control: a hot core is bright but rolls off
//   instead of clipping.
// The page draws it through the View contract (view.js).
import * as THREE from 'three';
import { ParticleDecoder } from './particle_decoder.js';
import { ACES_GLSL, SRGB_GLSL, fullscreenQuad } from './gl.js';
import { ViewOrbit } from './orbit.js';

const NMAX = 8, RL_MAX = 32;
// digest 002 §4.2: chromaticity-normalised blackbody colours, linear RGB (800 … 3000 K)
const BB_T = [800, 1000, 1200, 1500, 1800, 2000, 2200, 2500, 2800, 3000];
const BB_RGB = [[1, 0.059, 0], [1, 0.116, 0], [1, 0.189, 0], [1, 0.314, 0.009], [1, 0.45, 0.088], [1, 0.543, 0.172],
  [1, 0.638, 0.283], [1, 0.778, 0.503], [1, 0.914, 0.783], [1, 1, 1]];

// volume: kernel diameter in particle spacings, and the emission → opacity gain of 1 − e^(−gain·E)
const VOLUME_KERNEL = 7, VOLUME_GAIN = 0.4, VOLUME_SMOKE_GAIN = 0.4, VOLUME_HEAT_SCALE = 1.35, VOLUME_TONGUES = 2.2;
export const FLAME_MODES = ['volume', 'pbvr', 'hdr'];
export const FLAME_DEFAULTS = {
  mode: 'volume', rl: 15, threshold: 0.3, intensity: 1.0, smoke: true, smokeT: 1000, smokeColor: '#595959',
  whiteT: 4000, exposure: 1.0, velLines: false, velScale: 0.005, tongues: 1.0, smokeDensity: 1.0, density: 1.0, kernel: VOLUME_KERNEL,
};
const HDR_GAIN = 0.08; // hdr: a sprite's emission scale
// The particle spacing the gains are set for: the default stream's (particle_diameter 0.5 x h 3.5 mm).
const D_REF = 0.00175;
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
uniform vec3 upW, clipPoint;   // nothing is drawn below the sources' plane (what leaks under the plate)
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
void hide() { gl_Position = vec4(2.0, 2.0, 2.0, 1.0); gl_PointSize = 0.0; }
bool belowClip(vec3 p) { return dot(p - clipPoint, upW) < -radius; }`;

const PBVR_VERT = /* glsl */ `${COMMON_VERT}
uniform sampler2D randTex;
uniform float pass, nmax, fill, smokeT, smokeOn, smokeAlpha;  // fill: the share of nmax a particle may use
uniform vec3 smokeColor;
void main() {
  vec4 rnd = texelFetch(randTex, ivec2(int(slot), int(pass)), 0);
  float u = texelFetch(randTex, ivec2(0, int(pass)), 0).w;   // the pass's dither
  bool hot = itemp >= smokeT;
  float smoke = clamp((itemp - tAmb) / max(smokeT - tAmb, 1.0), 0.0, 1.0);
  float n = hot ? floor(nmax * fill * heatOf(itemp) + u) : smokeOn * floor(0.5 * nmax * fill * smoke + u);
  if (slot >= n || belowClip(ipos)) { hide(); return; }
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
  if (heat <= 0.0 || belowClip(ipos)) { hide(); return; }
  place(ipos, 5.0 * radius);
  vColor = blackbody(min(itemp, 0.75 * tMax)) * heat * heat;  // emission grows with heat; the hottest pale yellow, not white
  vAlphaP = 1.0;
}`;

const HDR_FRAG = /* glsl */ `
uniform sampler2D alphaTex;
uniform float gain;
varying vec3 vColor;
void main() {
  gl_FragColor = vec4(vColor * gain * texture2D(alphaTex, gl_PointCoord).a, 1.0);  // additive
}`;

// volume: one soft Gaussian kernel per particle, summed into a float target: (emission,
// emission × heat, smoke density, 1). Below the clip plane (the sources' plane)
// the kernel is cut with a short fade, so no light is drawn under the base.
const SPLAT_VERT = /* glsl */ `${COMMON_VERT}
uniform float smokeT, smokeOn, kernel, weight;  // weight: particles each one stands for, ^(1/3)
uniform vec2 upScreen;   // world-up component of the camera's right and up vectors
varying vec4 vW;
varying vec3 vClip;      // the particle's height above the clip plane, its change across the sprite (x, y)
void main() {
  float heat = heatOf(itemp);
  bool hot = itemp >= smokeT;
  float smoke = smokeOn * clamp((itemp - tAmb) / max(smokeT - tAmb, 1.0), 0.0, 1.0);
  float e = hot ? heat * sqrt(heat) : 0.0;
  if (e <= 0.0 && smoke <= 0.0) { hide(); return; }
  float size = kernel * radius;
  place(ipos, size);
  vW = weight * vec4(e, e * heat, hot ? 0.0 : smoke, 1.0);
  vClip = vec3(dot(ipos - clipPoint, upW), 0.5 * size * upScreen);
}`;

const SPLAT_FRAG = /* glsl */ `
uniform float clipFade;
varying vec4 vW;
varying vec3 vClip;
void main() {
  vec2 q = 2.0 * gl_PointCoord - 1.0;
  float r2 = dot(q, q);
  if (r2 >= 1.0) discard;
  float h = vClip.x + q.x * vClip.y - q.y * vClip.z;   // gl_PointCoord's y grows downwards
  float g = (exp(-3.0 * r2) - 0.0498) * smoothstep(0.0, clipFade, h);
  gl_FragColor = vW * g;
}`;

// 2D value noise and fbm for the composite's tongues.
const NOISE_GLSL = /* glsl */ `
float hash12(vec2 p) { vec3 q = fract(vec3(p.xyx) * 0.1031); q += dot(q, q.yzx + 33.33); return fract((q.x + q.y) * q.z); }
float vnoise(vec2 p) {
  vec2 i = floor(p), f = fract(p), u = f * f * (3.0 - 2.0 * f);
  return mix(mix(hash12(i), hash12(i + vec2(1, 0)), u.x), mix(hash12(i + vec2(0, 1)), hash12(i + vec2(1, 1)), u.x), u.y);
}
float fbm(vec2 p) { float a = 0.5, s = 0.0; for (int i = 0; i < 4; i++) { s += a * vnoise(p); p = p * 2.03 + 17.1; a *= 0.5; } return s / 0.9375; }`;

// The fire ramp over the emission-weighted mean heat, in display (sRGB) values.
const RAMP_GLSL = /* glsl */ `
vec3 fireRamp(float h) {
  const vec3 c0 = vec3(0.30, 0.03, 0.01), c1 = vec3(0.80, 0.16, 0.02), c2 = vec3(1.00, 0.42, 0.06),
             c3 = vec3(1.00, 0.70, 0.22), c4 = vec3(1.00, 0.92, 0.55);
  h = clamp(h, 0.0, 1.0) * 4.0;
  if (h < 1.0) return mix(c0, c1, h);
  if (h < 2.0) return mix(c1, c2, h - 1.0);
  if (h < 3.0) return mix(c2, c3, h - 2.0);
  return mix(c3, c4, h - 3.0);
}`;

const VOLUME_FRAG = /* glsl */ `
uniform sampler2D src;
uniform vec2 viewPx;        // the view's size in pixels
uniform float pxPerM, baseY, time, gain, intensity, tongues, smokeGain, heatScale, glow, glowLod;
uniform vec3 smokeColor;    // display values
varying vec2 vUv;
${NOISE_GLSL}
${RAMP_GLSL}
void main() {
  vec2 m = vUv * viewPx / pxPerM;                       // metres across the view plane
  float above = max(0.0, (vUv.y - baseY) * viewPx.y / pxPerM);
  vec2 flow = m * 55.0 - vec2(0.0, 9.0 * time);         // ~2 cm cells rising at ~16 cm/s
  vec2 d = vec2(fbm(flow), fbm(flow + vec2(5.2, 1.3))) - 0.5;
  vec2 uv = vUv + tongues * d * vec2(0.004 + 0.12 * above, 0.12 * above) * pxPerM / viewPx;
  vec4 s = texture2D(src, uv);
  float breakup = mix(1.0, 0.45 + 1.1 * fbm(m * 90.0 - vec2(0.0, 14.0 * time)), clamp(0.5 * tongues, 0.0, 1.0));
  float E = s.r * breakup;
  float heat = heatScale * s.g / max(s.r, 1e-6);
  float af = 1.0 - exp(-gain * E);
  vec3 fire = fireRamp(heat * (0.55 + 0.45 * af)) * af * intensity;
  float as = 1.0 - exp(-smokeGain * s.b);
  vec4 wide = textureLod(src, vUv, glowLod);                              // the emission around, for the glow
  float ag = glow * (1.0 - exp(-gain * wide.r)) * (1.0 - af) * smoothstep(baseY - 0.01, baseY + 0.01, vUv.y);
  vec3 halo = fireRamp(0.6 * heatScale * wide.g / max(wide.r, 1e-6)) * ag;
  float a = 1.0 - (1.0 - af) * (1.0 - as);
  gl_FragColor = vec4(fire + smokeColor * as * (1.0 - af) + halo * (1.0 - as), a);  // premultiplied; the halo adds light
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
    this.total = 0;
    this.capacity = 0;
    this.newFrame = false;
    this.stage = makeStage();
    this.scene.add(this.stage);
    const common = {
      tAmb: { value: 300 }, tMax: { value: 3000 }, radius: { value: 0.002 }, pointScale: { value: 500 },
      upW: { value: new THREE.Vector3(0, 0, 1) }, clipPoint: { value: new THREE.Vector3(0, 0, -1e9) },
      bbT: { value: BB_T }, bbRGB: { value: BB_RGB.map((c) => new THREE.Vector3(...c)) },
    };
    // pbvr has a radius of its own: a budget's subset grows its sprites more (setUniforms).
    this.pbvr = new THREE.ShaderMaterial({
      vertexShader: PBVR_VERT, fragmentShader: PBVR_FRAG,
      uniforms: {
        ...common, radius: { value: 0.002 }, randTex: { value: randomTable() }, alphaTex: { value: spriteTexture(true) }, pass: { value: 0 },
        nmax: { value: NMAX }, fill: { value: 1 }, threshold: { value: 0.3 }, smokeT: { value: 1000 }, smokeOn: { value: 1 },
        smokeAlpha: { value: 0.5 }, smokeColor: { value: new THREE.Color(0.1, 0.1, 0.1) },
      },
      depthTest: true, depthWrite: true, blending: THREE.NoBlending,
    });
    this.hdr = new THREE.ShaderMaterial({
      vertexShader: HDR_VERT, fragmentShader: HDR_FRAG,
      uniforms: { ...common, alphaTex: { value: spriteTexture(false) }, gain: { value: HDR_GAIN } },
      depthTest: true, depthWrite: false, blending: THREE.AdditiveBlending, transparent: true,
    });
    this.splat = new THREE.ShaderMaterial({
      vertexShader: SPLAT_VERT, fragmentShader: SPLAT_FRAG,
      uniforms: {
        ...common, smokeT: { value: 1000 }, smokeOn: { value: 1 }, kernel: { value: VOLUME_KERNEL }, weight: { value: 1 }, clipFade: { value: 0.001 },
        upScreen: { value: new THREE.Vector2() },
      },
      depthTest: false, depthWrite: false, transparent: true, blending: THREE.CustomBlending,
      blendEquation: THREE.AddEquation, blendSrc: THREE.OneFactor, blendDst: THREE.OneFactor,
      blendSrcAlpha: THREE.OneFactor, blendDstAlpha: THREE.OneFactor,
    });
    this.volume = fullscreenQuad(VOLUME_FRAG, {
      src: { value: null }, viewPx: { value: new THREE.Vector2(1, 1) }, pxPerM: { value: 1 }, baseY: { value: 0 }, time: { value: 0 },
      gain: { value: VOLUME_GAIN }, intensity: { value: 1 }, tongues: { value: 1 }, smokeGain: { value: 0.2 }, heatScale: { value: VOLUME_HEAT_SCALE },
      glow: { value: 0.35 }, glowLod: { value: 4 },
      smokeColor: { value: new THREE.Color() },
    }, {
      transparent: true, blending: THREE.CustomBlending, blendEquation: THREE.AddEquation,
      blendSrc: THREE.OneFactor, blendDst: THREE.OneMinusSrcAlphaFactor,
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
        if (aces == 1) { // ACES on the luminance only, so bright gas keeps its hue instead of going grey-white
          float L = dot(c, vec3(0.2126, 0.7152, 0.0722));
          c = L > 1e-6 ? c * (acesFilmic(vec3(L)).g / L) : c;
        }
        gl_FragColor = vec4(linearToSRGB(c), 1.0);
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

  // The camera's home: level with the lower flame, looking at the flame's middle above the
  // sources' centre; for the default 3 cm disc 42 cm away and 7 cm up, closer for smaller
  // sources (down to 0.35 times that for a candle's wick).
  frameStage() {
    if (!this.orbit) return;
    const { scale, up, side } = this.frameOf(), { centre, extent } = this.sourcesExtent(up);
    const k = Math.min(1, Math.max(0.35, extent / 0.015)) * scale;
    const target = centre.multiplyScalar(scale).addScaledVector(up, 0.07 * k);
    this.orbit.setHome(target.clone().addScaledVector(side, 0.42 * k).addScaledVector(up, 0.03 * k), target, up);
  }

  // The burning sources' centre (metres) and the radius of the circle across `up` holding them.
  sourcesExtent(up) {
    const src = (this.params?.sources || []).filter((s) => s.enabled !== false);
    if (!src.length) return { centre: new THREE.Vector3(), extent: 0.015 };
    const at = (s) => new THREE.Vector3(...(s.center || [0, 0, 0]));
    const centre = src.reduce((a, s) => a.add(at(s)), new THREE.Vector3()).divideScalar(src.length);
    let extent = 0;
    for (const s of src) {
      const d = at(s).sub(centre);
      extent = Math.max(extent, d.addScaledVector(up, -d.dot(up)).length() + (s.radius ?? 0.015));
    }
    return { centre, extent };
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

  // Decoded off the main thread (particle_decoder.js); the promise settles when the frame is
  // shown, or skipped for a newer one, and rejects with the decoder's error.
  onFrame(h, buf) {
    if (h.kind !== 1 || (h.codec !== 2 && h.codec !== 3)) return false;
    this.decoder ??= new ParticleDecoder();
    return this.decoder.decode(h, buf).then((p) => p && this.showParticles(p, h.total));
  }

  // total: the stream's particles when p is a budget's subset of them (PROTOCOL.md §3.5), else 0.
  showParticles(p, total = 0) {
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
    this.total = Math.max(total, p.n);
    this.geoms.pbvr.instanceCount = this.geoms.hdr.instanceCount = this.geoms.lines.instanceCount = p.n;
    this.newFrame = true;
    return true;
  }

  target(name, w, h, depth, mipmaps = false) {
    let t = this.targets[name];
    if (!t || t.width !== w || t.height !== h) {
      t?.dispose();
      t = this.targets[name] = new THREE.WebGLRenderTarget(w, h, {
        type: THREE.HalfFloatType, depthBuffer: depth, generateMipmaps: mipmaps,
        minFilter: mipmaps ? THREE.LinearMipmapLinearFilter : THREE.LinearFilter,
      });
    }
    return t;
  }

  setUniforms(w, h) {
    const pr = this.params || {}, s = this.settings, { scale, d, up, base } = this.frameOf();
    this.pbvr.uniforms.upW.value.copy(up); // the uniforms every material shares
    this.pbvr.uniforms.clipPoint.value.copy(this.clipPoint(up, base, scale));
    // A subset of the stream's particles (a budget) stands for total / count particles each:
    // their spacing is (total / count)^(1/3) times the stream's, so the kernels and sprites grow
    // by that and the summed emission (volume, hdr) by as much again per particle; pbvr's opaque
    // sprites cover the area the left-out ones would have, (total / count)^(1/2).
    // Likewise a stream of another resolution (h: a finer one has more, smaller particles in the
    // same flame) draws its particles' emission and pbvr's coverage in proportion to its spacing
    // (res = d / D_REF), so a flame looks as bright and as dense at any resolution: a sprite
    // column's light or coverage grows as 1 / spacing at a fixed emission and sprite count. pbvr
    // takes fewer sprites a particle for a finer stream (fill; smaller sprites fall below a pixel)
    // and larger ones for a coarser one.
    const stand = this.total / Math.max(1, this.count), grow = Math.cbrt(stand);
    const res = (pr.particle_diameter ?? 0.5) * (pr.h ?? 0.01125) / D_REF;
    for (const m of [this.pbvr, this.hdr, this.splat]) {
      m.uniforms.tAmb.value = pr.T_amb ?? 300;
      m.uniforms.tMax.value = s.whiteT;
      m.uniforms.radius.value = d * (m === this.pbvr ? Math.sqrt(stand * Math.max(1, res)) : grow);
      m.uniforms.pointScale.value = h / (2 * Math.tan(THREE.MathUtils.degToRad(this.camera.fov / 2)));
    }
    this.splat.uniforms.weight.value = grow * res;
    this.pbvr.uniforms.fill.value = Math.min(1, res);
    this.hdr.uniforms.gain.value = HDR_GAIN * grow * res;
    const u = this.pbvr.uniforms, lu = this.lineMat.uniforms;
    u.threshold.value = s.threshold;
    lu.velScale.value = s.velScale; // tAmb, tMax and the table: the uniforms all three materials share
    this.splat.uniforms.smokeOn.value = s.smoke ? 1 : 0;
    this.splat.uniforms.smokeT.value = s.smokeT;
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

  render(renderer, rect, time = 0) {
    if (!this.count) return false;
    const w = Math.max(1, Math.round(rect.w)), h = Math.max(1, Math.round(rect.h)), s = this.settings;
    this.orbit?.update();
    this.setUniforms(w, h);
    if (s.mode === 'volume') this.renderVolume(renderer, rect, w, h, time);
    else this.renderParticles(renderer, rect, w, h);
    this.lineVertices = 0;
    if (s.mode !== 'hdr' && s.velLines && this.hasVel) { // over the picture, in this view's rectangle
      renderer.render(this.lineScene, this.camera);
      this.lineVertices = 2 * renderer.info.render.lines;
    }
    const drew = this.newFrame;
    this.newFrame = false;
    return drew;
  }

  // volume: the stage straight into the view, the kernels into a half-resolution target,
  // then the fire composited over the stage (premultiplied alpha).
  renderVolume(renderer, rect, w, h, time) {
    const s = this.settings, { up, base, scale, d } = this.frameOf();
    const sw = Math.max(1, Math.round(w / 2)), sh = Math.max(1, Math.round(h / 2));
    const splat = this.target('splat', sw, sh, false, true), su = this.splat.uniforms;
    this.camera.updateMatrixWorld();
    const right = new THREE.Vector3().setFromMatrixColumn(this.camera.matrixWorld, 0);
    const camUp = new THREE.Vector3().setFromMatrixColumn(this.camera.matrixWorld, 1);
    su.upScreen.value.set(right.dot(up), camUp.dot(up));
    su.clipFade.value = d;
    su.kernel.value = s.kernel;
    su.pointScale.value = sh / (2 * Math.tan(THREE.MathUtils.degToRad(this.camera.fov / 2)));
    this.points.material = this.splat;
    this.points.geometry = this.geoms.hdr;
    this.stage.visible = false;
    renderer.setRenderTarget(splat);
    renderer.setClearColor(0x000000, 0);
    renderer.clear(true, false, false);
    renderer.render(this.scene, this.camera);
    this.stage.visible = true;
    this.points.visible = false;
    renderer.setRenderTarget(null);
    renderer.setViewport(rect.x, rect.y, rect.w, rect.h);
    renderer.setScissor(rect.x, rect.y, rect.w, rect.h);
    renderer.setScissorTest(true);
    renderer.render(this.scene, this.camera);
    this.points.visible = true;
    const vu = this.volume.material.uniforms, pxPerM = this.pxPerMetre(h, base, scale);
    vu.src.value = splat.texture;
    vu.viewPx.value.set(w, h);
    vu.pxPerM.value = pxPerM;
    vu.baseY.value = this.screenY(base);
    vu.time.value = time;
    vu.intensity.value = s.intensity;
    vu.gain.value = VOLUME_GAIN * s.density;
    vu.tongues.value = VOLUME_TONGUES * s.tongues;
    vu.smokeGain.value = s.smoke ? VOLUME_SMOKE_GAIN * s.smokeDensity : 0;
    vu.smokeColor.value.set(s.smokeColor);
    renderer.render(this.volume.scene, this.volume.camera);
  }

  // The plane below which nothing is drawn: through the lowest burning source's centre
  // (the sources' plane; what leaks around the plate under it is not flame).
  clipPoint(up, base, scale) {
    let low = Infinity;
    for (const src of this.params?.sources || []) if (src.enabled !== false) low = Math.min(low, new THREE.Vector3(...(src.center || [0, 0, 0])).dot(up));
    return up.clone().multiplyScalar((Number.isFinite(low) ? low : base.dot(up) / scale) * scale);
  }

  // Pixels per world metre at the flame's base, and a point's height in the view (0 bottom, 1 top).
  pxPerMetre(h, base, scale) {
    const dist = Math.max(1e-6, this.camera.position.distanceTo(base));
    return scale * h / (2 * dist * Math.tan(THREE.MathUtils.degToRad(this.camera.fov / 2)));
  }

  screenY(p) { return 0.5 + 0.5 * p.clone().project(this.camera).y; }

  // pbvr and hdr: particle sprites into float targets, then composited into the view.
  renderParticles(renderer, rect, w, h) {
    const s = this.settings, hdr = s.mode === 'hdr';
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
  }

  // What the view shows, for the stats overlay and the browser tests: baseRow is the lowest
  // point of the sources' outlines on screen, as a fraction of the view's height from the top.
  info() {
    return {
      mode: this.settings.mode, count: this.count, total: this.total, cam: this.camera.position.toArray(), target: this.orbit?.target?.toArray(),
      velocities: this.hasVel, lineVertices: this.lineVertices, baseRow: this.baseRow(),
    };
  }

  baseRow() {
    let low = null;
    for (const line of this.stage.userData.outlines.children) {
      line.updateMatrixWorld();
      const pos = line.geometry.attributes.position, p = new THREE.Vector3();
      for (let i = 0; i < pos.count; i++) {
        p.fromBufferAttribute(pos, i).applyMatrix4(line.matrixWorld).project(this.camera);
        low = Math.max(low ?? -Infinity, 0.5 - 0.5 * p.y);
      }
    }
    return low;
  }

  dispose() {
    for (const t of Object.values(this.targets)) t.dispose();
    for (const g of Object.values(this.geoms)) g?.dispose();
    this.pbvr.dispose();
    this.hdr.dispose();
    this.splat.dispose();
    this.volume.material.dispose();
    this.lineMat.dispose();
    this.orbit?.dispose();
  }
}
