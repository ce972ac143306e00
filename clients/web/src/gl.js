// gl.js — small shared pieces of the renderers: the linear → sRGB encoding every
// ShaderMaterial applies itself (they bypass three's colour management), a full-screen
// quad for composite passes, ACES filmic tone mapping, and the glow tone map of the
// energy wave.
import * as THREE from 'three';

export const SRGB_GLSL = /* glsl */ `
vec3 linearToSRGB(vec3 c) {
  c = clamp(c, 0.0, 1.0);
  return mix(c * 12.92, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), c));
}`;

export function fullscreenQuad(fragmentShader, uniforms, extra = {}) {
  const material = new THREE.ShaderMaterial({
    vertexShader: 'varying vec2 vUv; void main() { vUv = uv; gl_Position = vec4(position.xy, 0.0, 1.0); }',
    fragmentShader, uniforms, depthTest: false, depthWrite: false, ...extra,
  });
  const mesh = new THREE.Mesh(new THREE.PlaneGeometry(2, 2), material);
  mesh.frustumCulled = false;
  const scene = new THREE.Scene();
  scene.add(mesh);
  return { scene, camera: new THREE.Camera(), material };
}

// three.js's ACES filmic tone mapping (ShaderChunk tonemapping_pars_fragment, the same
// matrices and RRT/ODT fit), with the exposure applied by the caller.
export const ACES_GLSL = /* glsl */ `
vec3 acesFilmic(vec3 color) {
  const mat3 inMat = mat3(vec3(0.59719, 0.07600, 0.02840), vec3(0.35458, 0.90834, 0.13383), vec3(0.04823, 0.01566, 0.83777));
  const mat3 outMat = mat3(vec3(1.60475, -0.10208, -0.00327), vec3(-0.53108, 1.10813, -0.07276), vec3(-0.07367, -0.00605, 1.07602));
  color = inMat * (color / 0.6);
  vec3 a = color * (color + 0.0245786) - 0.000090537;
  vec3 b = color * (0.983729 * color + 0.4329510) + 0.238081;
  return clamp(outMat * (a / b), 0.0, 1.0);
}`;

// The energy wave's display map: hue-preserving, for additive glows. The strongest channel m
// goes through 1 − e^(−m), the others keep their ratio to it, so a colour never clips channel
// by channel (ACES and a per-channel clamp turn an orange glow beige or yellow); only light
// far above the display's range, the hot core, turns white (the thesis's white-out, eq. 4.8).
export const GLOW_TONE_GLSL = /* glsl */ `
vec3 glowTone(vec3 c) {
  float m = max(max(c.r, c.g), c.b);
  if (m <= 1e-6) return vec3(0.0);
  return (1.0 - exp(-m)) * mix(c / m, vec3(1.0), smoothstep(2.0, 10.0, m));
}`;
