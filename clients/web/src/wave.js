// wave.js — the `energy_wave` texture (kind 2, codec 1: an OpenEXR file, decoded by three's
// EXRLoader) on a camera-facing billboard. Channel Y (raw energy B, HDR) is coloured by the
// thesis's map C = (1 − B)·C_b + B·C_e (digest 000 §2.7, eq. 4.8) with the stream's own
// colour_energy / colour_background, in linear HDR so B > 1 is brighter than white; RGBA
// textures are used as sent. The wave view renders that into a half-float target, adds a
// bloom (three's UnrealBloomPass: a bright-pass, a mip chain of separable Gaussian blurs,
// weighted towards the fine levels so the halo hugs the core instead of fogging the view)
// and maps it to the display with the hue-preserving glow tone map (gl.js); the toon scene's
// billboard uses the same material and map, without the bloom. The view's camera is the
// stream's: eye, center, up, size (PROTOCOL.md §11.1).
//
// Display levels, a choice of this page (the thesis gives none). The 1/d field never falls to
// zero inside the billboard (B at its border is a quarter of the peak for the default ring),
// and integrated along a ray it falls off only like log(1/d) around a source. So each frame the page
// measures that floor F, the median B over the texture's outer 2% of rows and columns, and
// shows B' = gain · F · max(B/F − floor, 0)^contrast: the floor removed (a little more than
// the median, `floor` = 1.15) and the log profile steepened into a glow (`contrast` 2). B and
// F both scale with alpha and the coefficients, so the glow keeps its shape at any alpha and
// grows brighter in proportion. A window, a superellipse over the billboard's outer 30%
// reaching 0 before its border, fades what is left, so the billboard's edge never shows.
// This is done here rather than on the server, so the EXR stays the thesis's raw B for every
// other client.
// The page draws it through the View contract (view.js).
import * as THREE from 'three';
import { EXRLoader } from 'three/examples/jsm/loaders/EXRLoader.js';
import { UnrealBloomPass } from 'three/examples/jsm/postprocessing/UnrealBloomPass.js';
import { GLOW_TONE_GLSL, SRGB_GLSL, fullscreenQuad } from './gl.js';

// bloom: the bloom's strength; exposure: linear scale before the tone map; floor, gain,
// contrast: the levels above (floor 0, gain 1, contrast 1 is the thesis's map, with B
// relative to the floor).
export const WAVE_DEFAULTS = { bloom: 1.2, exposure: 1, floor: 1.15, gain: 1.5, contrast: 2 };
// The bloom's bright-pass threshold (luminance) and its mip levels' weights, finest first: no
// weight on the two widest levels, whose light would fog the whole view.
const BLOOM = { radius: 0, threshold: 0.6, factors: [1, 0.7, 0.3, 0, 0] };

const FRAG = /* glsl */ `
uniform sampler2D tex;
uniform bool isY, linearOut;
uniform vec3 ce, cb;
uniform float floorB, floorK, gain, contrast, exposure;
varying vec2 vUv;
${SRGB_GLSL}
${GLOW_TONE_GLSL}
const float MAX_B = 8.0;                  // white-hot already: more would only widen the bloom's haze
const float WINDOW_N = 3.0, EDGE = 0.3;   // the window's superellipse exponent and width (of the half-side)
void main() {
  vec4 t = texture2D(tex, vUv);
  float B = min(gain * floorB * pow(max((isY ? t.r : t.a) / floorB - floorK, 0.0), contrast), MAX_B);
  vec3 col = isY ? max((1.0 - B) * cb, 0.0) + B * ce    // eq. 4.8 in HDR: white-out left to the tone map
                 : t.rgb * min(B / max(t.a, 1e-3), 1.0);
  vec2 p = pow(abs(2.0 * vUv - 1.0), vec2(WINDOW_N));
  col *= 1.0 - smoothstep(1.0 - EDGE, 0.98, pow(p.x + p.y, 1.0 / WINDOW_N));
  gl_FragColor = vec4(linearOut ? col : linearToSRGB(glowTone(col * exposure)), 1.0);
}`;

export function waveMaterial() {
  return new THREE.ShaderMaterial({
    vertexShader: 'varying vec2 vUv; void main() { vUv = uv; gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0); }',
    fragmentShader: FRAG,
    uniforms: {
      tex: { value: null }, isY: { value: true }, linearOut: { value: false }, ce: { value: new THREE.Color(1, 1, 1) },
      cb: { value: new THREE.Color(0, 0, 0) }, floorB: { value: 1 }, floorK: { value: WAVE_DEFAULTS.floor },
      gain: { value: WAVE_DEFAULTS.gain }, contrast: { value: WAVE_DEFAULTS.contrast }, exposure: { value: WAVE_DEFAULTS.exposure },
    },
    blending: THREE.AdditiveBlending, depthWrite: false, transparent: true, side: THREE.DoubleSide,
  });
}

// The median of channel c over the outer 2% of rows and columns (at least one) of a half-float
// image with ch channels.
function borderMedian(data, w, h, ch, c) {
  const m = Math.max(1, Math.round(0.02 * Math.min(w, h))), v = [];
  const at = (x, y) => v.push(THREE.DataUtils.fromHalfFloat(data[(y * w + x) * ch + c]));
  for (let y = 0; y < h; y++) {
    if (y < m || y >= h - m) for (let x = 0; x < w; x++) at(x, y);
    else for (let k = 0; k < m; k++) { at(k, y); at(w - 1 - k, y); }
  }
  v.sort((a, b) => a - b);
  return v[v.length >> 1];
}

/** Decodes kind 2 EXR frames into one reusable half-float texture. */
export class WaveTexture {
  constructor() {
    this.loader = new EXRLoader();
    this.loader.setDataType(THREE.HalfFloatType);
    this.texture = null;
    this.isY = true;
    this.width = this.height = 0;
    this.floorOf = null; // the frame data floorValue was measured on
    this.floorValue = 1;
  }

  /** The floor F: the median B (A for RGBA) on the texture's border, measured once a frame
   *  when first asked for (the eye's bake textures never are). */
  get floor() {
    const data = this.texture?.image.data;
    if (data && data !== this.floorOf) {
      this.floorValue = Math.max(borderMedian(data, this.width, this.height, this.isY ? 1 : 4, this.isY ? 0 : 3), 1e-4);
      this.floorOf = data;
    }
    return this.floorValue;
  }

  update(payload) {
    const d = this.loader.parse(payload.buffer.byteLength === payload.byteLength ? payload.buffer : payload.slice().buffer);
    this.isY = d.format === THREE.RedFormat;
    if (!this.texture || this.width !== d.width || this.height !== d.height || this.texture.format !== d.format) {
      this.texture?.dispose();
      this.texture = new THREE.DataTexture(d.data, d.width, d.height, d.format, d.type);
      this.texture.minFilter = this.texture.magFilter = THREE.LinearFilter;
      this.texture.generateMipmaps = false;
      this.texture.flipY = false;
      this.width = d.width;
      this.height = d.height;
    } else {
      this.texture.image.data = d.data;
    }
    this.texture.needsUpdate = true;
    return this.texture;
  }
}

export function applyWaveUniforms(material, wt, params, settings) {
  const u = material.uniforms;
  u.tex.value = wt.texture;
  u.isY.value = wt.isY;
  u.floorB.value = wt.floor;
  u.floorK.value = settings.floor;
  u.gain.value = settings.gain;
  u.contrast.value = settings.contrast;
  u.exposure.value = settings.exposure;
  if (params) {
    u.ce.value.setRGB(...params.color_energy);
    u.cb.value.setRGB(...params.color_background);
  }
}

/** The stream's camera: eye, center, up; the billboard (size × size·H/W) at center. */
export function streamCamera(params, aspect, camera, billboard, wt) {
  const eye = new THREE.Vector3(...params.eye), ctr = new THREE.Vector3(...params.center);
  const dist = eye.distanceTo(ctr), bw = params.size, bh = params.size * (wt.height || params.height) / (wt.width || params.width);
  const halfH = Math.max(bh / 2, bw / 2 / aspect) * 1.08;
  camera.fov = THREE.MathUtils.radToDeg(2 * Math.atan(halfH / dist));
  camera.aspect = aspect;
  camera.near = dist / 100;
  camera.far = dist * 100;
  camera.position.copy(eye);
  camera.up.set(...params.up);
  camera.lookAt(ctr);
  camera.updateProjectionMatrix();
  billboard.position.copy(ctr);
  billboard.scale.set(bw, bh, 1);
  billboard.up.set(...params.up);
  billboard.lookAt(eye);
}

export class WaveView {
  constructor(stream) {
    this.stream = stream;
    this.kind = 'wave';
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.1, 1000);
    this.wt = new WaveTexture();
    this.material = waveMaterial();
    this.billboard = new THREE.Mesh(new THREE.PlaneGeometry(1, 1), this.material);
    this.scene.add(this.billboard);
    this.material.uniforms.linearOut.value = true;
    this.params = null;
    this.newFrame = false;
    this.settings = { ...WAVE_DEFAULTS }; // main.js shares one object among the wave views
    this.target = null;
    this.bloom = new UnrealBloomPass(new THREE.Vector2(256, 256), WAVE_DEFAULTS.bloom, BLOOM.radius, BLOOM.threshold);
    this.bloom.compositeMaterial.uniforms.bloomFactors.value = BLOOM.factors;
    this.composite = fullscreenQuad(/* glsl */ `
      uniform sampler2D src; uniform float exposure; varying vec2 vUv;
      ${SRGB_GLSL}
      ${GLOW_TONE_GLSL}
      void main() { gl_FragColor = vec4(linearToSRGB(glowTone(texture2D(src, vUv).rgb * exposure)), 1.0); }`,
    { src: { value: null }, exposure: { value: 1 } });
  }

  setParams(p) { this.params = p; }

  onFrame(h, buf) {
    if (h.kind !== 2 || h.codec !== 1) return false;
    this.wt.update(new Uint8Array(buf, h.headerBytes, h.payloadBytes));
    this.frameRev = h.paramRev;
    this.newFrame = true;
    return true;
  }

  // HDR into a half-float target, the bloom added there, the glow tone map into the view's rectangle.
  render(renderer, rect) {
    if (!this.wt.texture || !this.params) return false;
    const w = Math.max(1, Math.round(rect.w)), h = Math.max(1, Math.round(rect.h));
    if (!this.target || this.target.width !== w || this.target.height !== h) {
      this.target?.dispose();
      this.target = new THREE.WebGLRenderTarget(w, h, { type: THREE.HalfFloatType, depthBuffer: false });
      this.bloom.setSize(w, h);
    }
    streamCamera(this.params, w / h, this.camera, this.billboard, this.wt);
    applyWaveUniforms(this.material, this.wt, this.params, this.settings);
    renderer.setScissorTest(false);
    renderer.setRenderTarget(this.target);
    renderer.setClearColor(0x000000, 1);
    renderer.clear(true, false, false);
    renderer.render(this.scene, this.camera);
    this.bloom.strength = this.settings.bloom;
    if (this.bloom.strength > 0) this.bloom.render(renderer, null, this.target, 0, false);
    renderer.setRenderTarget(null);
    renderer.setViewport(rect.x, rect.y, rect.w, rect.h);
    renderer.setScissor(rect.x, rect.y, rect.w, rect.h);
    renderer.setScissorTest(true);
    this.composite.material.uniforms.src.value = this.target.texture;
    this.composite.material.uniforms.exposure.value = this.settings.exposure;
    renderer.render(this.composite.scene, this.composite.camera);
    this.drawnRev = this.frameRev;
    const drew = this.newFrame;
    this.newFrame = false;
    return drew;
  }

  /** State for the page's test hooks: the param_rev of the texture last drawn, the floor and
   *  the billboard's rectangle in the view, as shares of its width and height from the top
   *  left (as last drawn). */
  info() {
    const c = [[-0.5, -0.5], [0.5, 0.5]].map(([x, y]) => new THREE.Vector3(x, y, 0).applyMatrix4(this.billboard.matrixWorld).project(this.camera));
    const xs = c.map((v) => (v.x + 1) / 2), ys = c.map((v) => (1 - v.y) / 2);
    return { drawnRev: this.drawnRev ?? 0, floor: this.wt.floor, billboard: { x0: Math.min(...xs), x1: Math.max(...xs), y0: Math.min(...ys), y1: Math.max(...ys) } };
  }

  dispose() { this.material.dispose(); this.wt.texture?.dispose(); this.target?.dispose(); this.bloom.dispose(); }
}
