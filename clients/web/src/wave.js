// wave.js — the `energy_wave` texture (kind 2, codec 1: an OpenEXR file, decoded by three's
// EXRLoader) on a camera-facing billboard. Channel Y (raw energy B, HDR) is coloured by the
// thesis's map C = (1 − B)·C_b + B·C_e (digest 000 §2.7, eq. 4.8) with the stream's own
// colour_energy / colour_background, in linear HDR so B > 1 is brighter than white; RGBA
// textures are used as sent. The wave view renders that into a half-float target, adds a
// bloom (three's UnrealBloomPass: a bright-pass, a mip chain of separable Gaussian blurs)
// and tone-maps with ACES filmic into its viewport; the toon scene's billboard uses the same
// material with sRGB output and no bloom. The view's camera is the stream's: eye, center,
// up, size (PROTOCOL.md §11.1).
// The page draws it through the View contract (view.js).
import * as THREE from 'three';
import { EXRLoader } from 'three/examples/jsm/loaders/EXRLoader.js';
import { UnrealBloomPass } from 'three/examples/jsm/postprocessing/UnrealBloomPass.js';
import { ACES_GLSL, SRGB_GLSL, fullscreenQuad } from './gl.js';

export const WAVE_DEFAULTS = { bloom: 0.6, exposure: 0.8 };

const FRAG = /* glsl */ `
uniform sampler2D tex;
uniform bool isY, linearOut;
uniform vec3 ce, cb;
uniform float fade, blackLevel, levelGain;
varying vec2 vUv;
${SRGB_GLSL}
void main() {
  vec4 t = texture2D(tex, vUv);
  // Display levels (a choice of this page, not of the thesis): B' = max(B − black, 0)·gain
  // removes the 1/d field's broad floor (B ≈ 0.4 everywhere in the default scene) so the
  // billboard does not show as a lit square; black 0, gain 1 is the thesis's map exactly.
  float B = max((isY ? t.r : t.a) - blackLevel, 0.0) * levelGain;
  vec3 col = isY ? max((1.0 - B) * cb, 0.0) + B * ce    // eq. 4.8 in HDR: clamped only at display
                 : t.rgb * min(B / max(t.a, 1e-3), 1.0);
  // Edges of the billboard fade out so the quad never shows as a rectangle.
  vec2 e = smoothstep(vec2(0.0), vec2(fade), vUv) * smoothstep(vec2(0.0), vec2(fade), 1.0 - vUv);
  col *= e.x * e.y;
  gl_FragColor = vec4(linearOut ? col : linearToSRGB(col), 1.0);
}`;

export function waveMaterial() {
  return new THREE.ShaderMaterial({
    vertexShader: 'varying vec2 vUv; void main() { vUv = uv; gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0); }',
    fragmentShader: FRAG,
    uniforms: {
      tex: { value: null }, isY: { value: true }, linearOut: { value: false }, ce: { value: new THREE.Color(0.35, 0.75, 1) },
      cb: { value: new THREE.Color(0, 0, 0) }, blackLevel: { value: 0.55 }, levelGain: { value: 1.6 }, fade: { value: 0.04 },
    },
    blending: THREE.AdditiveBlending, depthWrite: false, transparent: true, side: THREE.DoubleSide,
  });
}

/** Decodes kind 2 EXR frames into one reusable half-float texture. */
export class WaveTexture {
  constructor() {
    this.loader = new EXRLoader();
    this.loader.setDataType(THREE.HalfFloatType);
    this.texture = null;
    this.isY = true;
    this.width = this.height = 0;
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

export function applyWaveUniforms(material, wt, params) {
  const u = material.uniforms;
  u.tex.value = wt.texture;
  u.isY.value = wt.isY;
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
    this.bloom = new UnrealBloomPass(new THREE.Vector2(256, 256), 0.6, 0.4, 0.7);
    this.composite = fullscreenQuad(/* glsl */ `
      uniform sampler2D src; uniform float exposure; varying vec2 vUv;
      ${SRGB_GLSL}
      ${ACES_GLSL}
      void main() { gl_FragColor = vec4(linearToSRGB(acesFilmic(texture2D(src, vUv).rgb * exposure)), 1.0); }`,
    { src: { value: null }, exposure: { value: 1 } });
  }

  setParams(p) { this.params = p; }

  onFrame(h, buf) {
    if (h.kind !== 2 || h.codec !== 1) return false;
    this.wt.update(new Uint8Array(buf, h.headerBytes, h.payloadBytes));
    this.newFrame = true;
    return true;
  }

  // HDR into a half-float target, the bloom added there, ACES into the view's rectangle.
  render(renderer, rect) {
    if (!this.wt.texture || !this.params) return false;
    const w = Math.max(1, Math.round(rect.w)), h = Math.max(1, Math.round(rect.h));
    if (!this.target || this.target.width !== w || this.target.height !== h) {
      this.target?.dispose();
      this.target = new THREE.WebGLRenderTarget(w, h, { type: THREE.HalfFloatType, depthBuffer: false });
      this.bloom.setSize(w, h);
    }
    streamCamera(this.params, w / h, this.camera, this.billboard, this.wt);
    applyWaveUniforms(this.material, this.wt, this.params);
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
    const drew = this.newFrame;
    this.newFrame = false;
    return drew;
  }

  dispose() { this.material.dispose(); this.wt.texture?.dispose(); this.target?.dispose(); this.bloom.dispose(); }
}
