// gl.js — small shared pieces of the renderers: the linear → sRGB encoding every
// ShaderMaterial applies itself (they bypass three's colour management), and a
// full-screen quad for composite passes.
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
