// wave.js — the `energy_wave` texture (kind 2, codec 1: an OpenEXR file, decoded by three's
// EXRLoader) on a camera-facing billboard. Channel Y (raw energy B, HDR) is coloured by the
// thesis's map C = (1 − B)·C_b + B·C_e (digest 000 §2.7, eq. 4.8) with the stream's own
// colour_energy / colour_background, computed in HDR so B > 1 whites out, plus a glow: a
// wide blur of B (24 taps on three rings) added in C_e. RGBA textures are used as sent.
// The view's camera is the stream's: eye, center, up, size (PROTOCOL.md §11.1).
import * as THREE from 'three';
import { EXRLoader } from 'three/examples/jsm/loaders/EXRLoader.js';
import { SRGB_GLSL } from './gl.js';

const FRAG = /* glsl */ `
uniform sampler2D tex;
uniform bool isY;
uniform vec3 ce, cb;
uniform float glowGain, glowRadius, fade, blackLevel, levelGain;
uniform vec2 texel;
varying vec2 vUv;
${SRGB_GLSL}
// Display levels (a choice of this page, not of the thesis): B' = max(B − black, 0)·gain
// removes the 1/d field's broad floor (B ≈ 0.4 everywhere in the default scene) so the
// billboard does not show as a lit square; black 0, gain 1 is the thesis's map exactly.
float energy(vec2 uv) {
  vec4 t = texture2D(tex, uv);
  return max((isY ? t.r : t.a) - blackLevel, 0.0) * levelGain;
}
void main() {
  vec4 t = texture2D(tex, vUv);
  vec3 col;
  float B = energy(vUv);
  if (isY) col = max((1.0 - B) * cb, 0.0) + B * ce;   // eq. 4.8 in HDR: clamped only at display
  else col = t.rgb * min(B / max(t.a, 1e-3), 1.0);
  float g = 0.0;
  for (int ring = 1; ring <= 3; ring++) {
    float r = glowRadius * float(ring) / 3.0;
    for (int k = 0; k < 8; k++) {
      float a = 6.2831853 * (float(k) + 0.5 * float(ring)) / 8.0;
      g += energy(vUv + r * vec2(cos(a), sin(a)) * texel) / float(ring);
    }
  }
  col += glowGain * g / 14.67 * ce;
  // Edges of the billboard fade out so the quad never shows as a rectangle.
  vec2 e = smoothstep(vec2(0.0), vec2(fade), vUv) * smoothstep(vec2(0.0), vec2(fade), 1.0 - vUv);
  gl_FragColor = vec4(linearToSRGB(col * e.x * e.y), 1.0);
}`;

export function waveMaterial() {
  return new THREE.ShaderMaterial({
    vertexShader: 'varying vec2 vUv; void main() { vUv = uv; gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0); }',
    fragmentShader: FRAG,
    uniforms: {
      tex: { value: null }, isY: { value: true }, ce: { value: new THREE.Color(0.35, 0.75, 1) }, cb: { value: new THREE.Color(0, 0, 0) },
      glowGain: { value: 0.6 }, glowRadius: { value: 24 }, blackLevel: { value: 0.55 }, levelGain: { value: 1.6 }, fade: { value: 0.04 }, texel: { value: new THREE.Vector2(1 / 256, 1 / 256) },
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
  u.texel.value.set(1 / Math.max(1, wt.width), 1 / Math.max(1, wt.height));
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
    this.params = null;
    this.newFrame = false;
    this.listeners = [];
  }

  setParams(p) { this.params = p; }

  onFrame(h, buf) {
    if (h.kind !== 2 || h.codec !== 1) return false;
    this.wt.update(new Uint8Array(buf, h.headerBytes, h.payloadBytes));
    this.newFrame = true;
    return true;
  }

  render(renderer, rect) {
    if (!this.wt.texture || !this.params) return false;
    streamCamera(this.params, rect.w / rect.h, this.camera, this.billboard, this.wt);
    applyWaveUniforms(this.material, this.wt, this.params);
    renderer.setClearColor(0x000000, 1);
    renderer.clear();
    renderer.render(this.scene, this.camera);
    const drew = this.newFrame;
    this.newFrame = false;
    return drew;
  }

  dispose() { this.material.dispose(); this.wt.texture?.dispose(); }
}
