// scene.js — a small scene lit by the energy wave's light rig (kind 3, PROTOCOL.md §7.7;
// digest 003): a ground plane (the rig's shadow plane), a few objects and a character with
// a feature texture. Per fragment the light is the nearest point of the dominant centre-
// line segment, m = N·L unclamped indexes the toon ramp, the feature texture multiplies it
// and the result replaces the material colour (mixed by the rig's strength); outlines are
// back faces pushed out by d·|R_z| in view space; each model casts one clamped planar
// shadow (direction from rig.js shadowDir, with the sign fix), t < 0 discarded, each pixel
// darkened once (stencil). The wave itself is the stream's billboard, facing this camera.
// The home view frames the whole ground disc, every model and the wave for the view's
// aspect (fitHome).
// The page draws it through the View contract (view.js).
import * as THREE from 'three';
import { ViewOrbit } from './orbit.js';
import { SRGB_GLSL } from './gl.js';
import { decodeRig, RigState, pointLight, shadowDir, SEG_FLOATS } from './rig.js';
import { waveMaterial, applyWaveUniforms } from './wave.js';

const MAX_SEG = 64, MAX_BANDS = 8;

const TOON_VERT = /* glsl */ `
varying vec3 vWorld;
varying vec3 vNormal;
varying vec2 vUv;
void main() {
  vec4 w = modelMatrix * vec4(position, 1.0);
  vWorld = w.xyz;
  vNormal = normalize(mat3(modelMatrix) * normal);
  vUv = uv;
  gl_Position = projectionMatrix * viewMatrix * w;
}`;

const TOON_FRAG = /* glsl */ `
uniform sampler2D segTex;
uniform int nSeg;
uniform vec4 bands[${MAX_BANDS}];
uniform int nBands;
uniform float strength;
uniform bool useFeatures, haveRig;
uniform sampler2D featureTex;
uniform vec3 baseColor;
uniform float albedo;    // how much of the ramp's light the surface returns (the ground: mid grey)
varying vec3 vWorld;
varying vec3 vNormal;
varying vec2 vUv;
${SRGB_GLSL}
void main() {
  vec3 N = normalize(vNormal) * (gl_FrontFacing ? 1.0 : -1.0);
  vec3 M = vWorld;
  vec3 own = baseColor * (0.25 + 0.75 * max(dot(N, normalize(vec3(0.3, 1.0, 0.5))), 0.0));
  vec3 feat = texture2D(featureTex, vUv).rgb;
  vec3 col = own * feat;
  float best = -1.0;
  vec3 E = vec3(0.0);
  for (int i = 0; i < ${MAX_SEG}; i++) {
    if (i >= nSeg) break;
    vec4 a = texelFetch(segTex, ivec2(0, i), 0), b = texelFetch(segTex, ivec2(1, i), 0), c = texelFetch(segTex, ivec2(2, i), 0);
    if (c.x <= 0.0) continue;                               // a segment with no strength does not light
    float t = clamp(dot(M - a.xyz, b.xyz), a.w, b.w);       // eqs. 2.1-2.2 on the capsule
    vec3 e = a.xyz + t * b.xyz;
    float score = c.x / max(length(e - M), 1e-6);           // dominant term of the 1/d field
    if (score > best) { best = score; E = e; }
  }
  if (haveRig && best > 0.0) {
    vec3 L = E - M;
    float l = length(L);
    float m = l < 1e-6 ? 1.0 : clamp(dot(N, L / l), -1.0, 1.0);  // eq. 2.4, not clamped at 0
    vec3 S = bands[0].rgb;
    for (int i = 1; i < ${MAX_BANDS}; i++) if (i < nBands && m >= bands[i].w) S = bands[i].rgb;  // eq. 2.5
    vec3 H = useFeatures ? S * feat : S;                     // eq. 2.6
    col = mix(col, H * albedo, strength);
  }
  gl_FragColor = vec4(linearToSRGB(col), 1.0);
}`;

const OUTLINE_VERT = /* glsl */ `
uniform float d;
void main() {
  vec4 R = modelViewMatrix * vec4(position, 1.0);
  vec3 U = normalize(normalMatrix * normal);
  R.xyz += d * abs(R.z) * U;                                 // eq. 2.7
  gl_Position = projectionMatrix * R;
}`;
const OUTLINE_FRAG = `uniform vec3 color; ${SRGB_GLSL} void main() { gl_FragColor = vec4(linearToSRGB(color), 1.0); }`;

const SHADOW_VERT = /* glsl */ `
uniform vec3 kdir, planeI, planeY;
varying float vT;
varying vec3 vOnGround;
void main() {
  vec3 P = (modelMatrix * vec4(position, 1.0)).xyz;
  float t = dot(planeI - P, planeY) / dot(kdir, planeY);     // gap 2 closed form of eq. 2.28
  vT = t;
  vec3 G = P + t * kdir + planeY * 0.01;                     // eq. 2.31, lifted off the plane
  vOnGround = G - planeI;
  gl_Position = projectionMatrix * viewMatrix * vec4(G, 1.0);
}`;
// eq. 2.32, and only on the ground disc (centred at planeI): a long shadow ends at its edge.
const SHADOW_FRAG = `uniform vec3 color; uniform float opacity, groundR; varying float vT; varying vec3 vOnGround; ${SRGB_GLSL}
void main() { if (vT < 0.0 || length(vOnGround) > groundR) discard; gl_FragColor = vec4(linearToSRGB(color), opacity); }`;
const GROUND_R = 17;
// The home view looks from HOME_DIR (27° above the ground) at the middle of what it frames.
const HOME_DIR = new THREE.Vector3(0.45, 0.45, 0.77).normalize(), HOME_MARGIN = 0.92;
const boxCorners = (b) => [0, 1, 2, 3, 4, 5, 6, 7].map((k) => new THREE.Vector3(k & 1 ? b.max.x : b.min.x, k & 2 ? b.max.y : b.min.y, k & 4 ? b.max.z : b.min.z));

function canvasTexture(w, h, draw) {
  const c = document.createElement('canvas');
  c.width = w; c.height = h;
  const g = c.getContext('2d');
  g.fillStyle = '#fff';
  g.fillRect(0, 0, w, h);
  draw(g, w, h);
  const t = new THREE.CanvasTexture(c);
  t.wrapS = t.wrapT = THREE.RepeatWrapping;
  t.colorSpace = THREE.NoColorSpace;
  return t;
}

// Feature textures (digest 003 §2.2): white = unchanged, black = feature lines.
const faceTexture = () => canvasTexture(256, 128, (g) => {
  // sphere UVs: u = 0.25 faces +z, v up
  g.fillStyle = '#000';
  for (const x of [0.20, 0.30]) { g.beginPath(); g.ellipse(x * 256, 58, 7, 12, 0, 0, 2 * Math.PI); g.fill(); }
  g.lineWidth = 5; g.strokeStyle = '#000';
  g.beginPath(); g.arc(0.25 * 256, 70, 16, 0.2 * Math.PI, 0.8 * Math.PI); g.stroke();
  g.lineWidth = 3;
  g.beginPath(); g.moveTo(0, 98); g.lineTo(256, 98); g.stroke();   // headband
});
const stripeTexture = () => canvasTexture(128, 128, (g) => {
  g.fillStyle = '#222';
  for (let i = 0; i < 4; i++) g.fillRect(0, 14 + i * 32, 128, 5);
});
const bodyTexture = () => canvasTexture(128, 128, (g) => {
  g.fillStyle = '#111';
  g.fillRect(0, 54, 128, 8);                                         // belt
  for (const x of [16, 48, 80, 112]) { g.beginPath(); g.arc(x, 90, 5, 0, 2 * Math.PI); g.fill(); }  // buttons
});
const groundTexture = () => {
  const t = canvasTexture(256, 256, (g) => {
    g.fillStyle = '#c8c8c8';
    for (let y = 0; y < 8; y++) for (let x = 0; x < 8; x++) if ((x + y) % 2) g.fillRect(x * 32, y * 32, 32, 32);
  });
  t.repeat.set(6, 6);
  return t;
};

export class SceneView {
  constructor(stream, wave) {
    this.stream = stream;
    this.kind = 'scene';
    this.wave = wave; // the stream's WaveView: its decoded texture and display settings
    this.wt = wave.wt;
    this.rigState = new RigState();
    this.rig = null;
    this.params = null;
    this.newFrame = false;
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.5, 500);
    this.orbit = null;
    this.segData = new Float32Array(3 * MAX_SEG * 4);
    this.segTex = new THREE.DataTexture(this.segData, 3, MAX_SEG, THREE.RGBAFormat, THREE.FloatType);
    this.toonUniforms = {
      segTex: { value: this.segTex }, nSeg: { value: 0 }, nBands: { value: 0 }, strength: { value: 1 },
      bands: { value: Array.from({ length: MAX_BANDS }, () => new THREE.Vector4()) },
      useFeatures: { value: true }, haveRig: { value: false },
    };
    this.outlineUniforms = { d: { value: 0.005 }, color: { value: new THREE.Color(0, 0, 0) } };
    this.shadowColor = { value: new THREE.Color(0, 0, 0) };
    this.shadowOpacity = { value: 1 };
    this.models = [];
    this.prevI = new Map();
    this.buildScene();
    this.billboardMat = waveMaterial();
    this.billboard = new THREE.Mesh(new THREE.PlaneGeometry(1, 1), this.billboardMat);
    this.billboard.renderOrder = 10;
    this.billboard.visible = false;
    this.scene.add(this.billboard);
  }

  toon(color, feature, albedo = 1) {
    return new THREE.ShaderMaterial({
      vertexShader: TOON_VERT, fragmentShader: TOON_FRAG,
      uniforms: { ...this.toonUniforms, featureTex: { value: feature }, baseColor: { value: new THREE.Color(...color) },
        albedo: { value: albedo } },
    });
  }

  // One model: toon meshes, their outline duplicates, one shadow duplicate per mesh.
  addModel(name, parts, castShadow = true) {
    const group = new THREE.Group();
    group.name = name;
    const shadowUniforms = { kdir: { value: new THREE.Vector3(0, -1, 0) }, planeI: { value: new THREE.Vector3() }, planeY: { value: new THREE.Vector3(0, 1, 0) }, color: this.shadowColor, opacity: this.shadowOpacity, groundR: { value: GROUND_R } };
    const outlineMat = new THREE.ShaderMaterial({ vertexShader: OUTLINE_VERT, fragmentShader: OUTLINE_FRAG, uniforms: this.outlineUniforms, side: THREE.BackSide });
    const shadowMat = new THREE.ShaderMaterial({
      vertexShader: SHADOW_VERT, fragmentShader: SHADOW_FRAG, uniforms: shadowUniforms, transparent: true, depthWrite: false,
      stencilWrite: true, stencilRef: 0, stencilFunc: THREE.EqualStencilFunc, stencilZPass: THREE.IncrementStencilOp,
    });
    const outlines = [], shadows = [];
    for (const { geometry, material, position = [0, 0, 0], rotation = [0, 0, 0] } of parts) {
      const mesh = new THREE.Mesh(geometry, material);
      mesh.position.set(...position);
      mesh.rotation.set(...rotation);
      group.add(mesh);
      const ol = new THREE.Mesh(geometry, outlineMat);
      ol.position.copy(mesh.position); ol.rotation.copy(mesh.rotation);
      group.add(ol);
      outlines.push(ol);
      if (castShadow) {
        const sh = new THREE.Mesh(geometry, shadowMat);
        sh.position.copy(mesh.position); sh.rotation.copy(mesh.rotation);
        sh.renderOrder = 1;
        sh.frustumCulled = false;
        group.add(sh);
        shadows.push(sh);
      }
    }
    this.scene.add(group);
    const model = { name, group, outlines, shadows, shadowUniforms, castShadow };
    this.models.push(model);
    return model;
  }

  buildScene() {
    const white = [0.85, 0.85, 0.85];
    // A round ground of mid-grey albedo: the ramp's light is not a white sheet, and the
    // shadows (clipped to it) end at its edge instead of running out of the frame.
    this.ground = this.addModel('ground', [{ geometry: new THREE.CircleGeometry(GROUND_R, 96), material: this.toon([0.5, 0.55, 0.5], groundTexture(), 0.5), rotation: [-Math.PI / 2, 0, 0] }], false);
    this.ground.outlines.forEach((o) => (o.visible = false));
    const stripes = stripeTexture();
    this.addModel('box', [{ geometry: new THREE.BoxGeometry(4, 4, 4), material: this.toon([0.8, 0.3, 0.2], stripes) }]).group.position.set(-9, 2, 6);
    this.addModel('pillar', [{ geometry: new THREE.CylinderGeometry(1.4, 1.4, 9, 32), material: this.toon([0.3, 0.5, 0.8], stripes) }]).group.position.set(10, 4.5, -5);
    this.addModel('ball', [{ geometry: new THREE.SphereGeometry(2.2, 48, 24), material: this.toon([0.9, 0.8, 0.2], stripes) }]).group.position.set(7, 2.2, 7);
    // The character: legs, body with a belt, arms and a head with a face.
    const body = this.toon(white, bodyTexture()), head = this.toon(white, faceTexture()), limb = this.toon(white, stripes);
    const ch = this.addModel('character', [
      { geometry: new THREE.CapsuleGeometry(0.45, 2.2, 8, 16), material: limb, position: [-0.65, 1.5, 0] },
      { geometry: new THREE.CapsuleGeometry(0.45, 2.2, 8, 16), material: limb, position: [0.65, 1.5, 0] },
      { geometry: new THREE.CapsuleGeometry(1.3, 2.0, 8, 24), material: body, position: [0, 4.6, 0] },
      { geometry: new THREE.CapsuleGeometry(0.35, 2.4, 8, 16), material: limb, position: [-1.9, 5.0, 0], rotation: [0, 0, 0.35] },
      { geometry: new THREE.CapsuleGeometry(0.35, 2.4, 8, 16), material: limb, position: [1.9, 5.0, 0], rotation: [0, 0, -0.35] },
      { geometry: new THREE.SphereGeometry(1.35, 48, 24), material: head, position: [0, 7.8, 0] },
    ]);
    ch.group.position.set(-1, 0, 9);
    ch.group.rotation.y = 0.35;
    this.character = ch;
  }

  setParams(p) { this.params = p; }

  onFrame(h, buf) {
    if (h.kind === 2) { this.newFrame = true; return false; } // the texture is decoded by the wave view
    if (h.kind !== 3 || h.codec !== 1) return false;
    this.rig = this.rigState.update(decodeRig(new Uint8Array(buf, h.headerBytes, h.payloadBytes)));
    this.uploadRig();
    this.newFrame = true;
    return true;
  }

  uploadRig() {
    const rig = this.rig, c = rig.constants, u = this.toonUniforms;
    this.segData.fill(0);
    for (let i = 0; i < rig.nSeg; i++) {
      const s = rig.seg.subarray(SEG_FLOATS * i, SEG_FLOATS * i + 9), o = 12 * i;
      const fin = (v) => Math.max(-1e30, Math.min(1e30, v)); // ±∞ → ±1e30 for the GPU
      this.segData.set([s[0], s[1], s[2], fin(s[6]), s[3], s[4], s[5], fin(s[7]), s[8], 0, 0, 0], o);
    }
    this.segTex.needsUpdate = true;
    u.nSeg.value = rig.nSeg;
    if (!c) { u.haveRig.value = false; return; }
    u.haveRig.value = true;
    u.nBands.value = c.bands.length;
    c.bands.forEach((b, i) => u.bands.value[i].set(b.rgb[0], b.rgb[1], b.rgb[2], b.mMin));
    u.strength.value = c.strength;
    u.useFeatures.value = c.features;
    this.outlineUniforms.d.value = c.outlineWidth;
    this.outlineUniforms.color.value.setRGB(...c.outlineRgb);
    this.shadowColor.value.setRGB(...c.shadowRgb);
    this.shadowOpacity.value = c.shadowOpacity;
  }

  // Per model: B = bounding-box centre, W = its light, e = (B − W)/|B − W|, k clamped (rig.js).
  updateShadows() {
    const c = this.rig?.constants;
    const on = !!(c && c.shadow);
    const I = c ? new THREE.Vector3(...c.planeI) : new THREE.Vector3(), Y = c ? new THREE.Vector3(...c.planeY) : new THREE.Vector3(0, 1, 0);
    // the ground lies in the rig's plane
    this.ground.group.position.copy(I);
    this.ground.group.quaternion.setFromUnitVectors(new THREE.Vector3(0, 1, 0), Y);
    this.shadowInfo = [];
    for (const m of this.models) {
      if (!m.castShadow) continue;
      let visible = on;
      if (on) {
        const box = new THREE.Box3().setFromObject(m.group.children[0].parent, true);
        const B = box.getCenter(new THREE.Vector3()).toArray();
        const W = pointLight(this.rig, B);
        if (!W) visible = false;
        else {
          if (!this.prevI.has(m.name)) this.prevI.set(m.name, { i: null });
          const r = shadowDir(c, [B[0] - W[0], B[1] - W[1], B[2] - W[2]], this.prevI.get(m.name));
          m.shadowUniforms.kdir.value.set(...r.k);
          this.shadowInfo.push({ model: m.name, B, W, k: r.k, lambda: r.lambda, clamped: r.clamped });
        }
        m.shadowUniforms.planeI.value.copy(I);
        m.shadowUniforms.planeY.value.copy(Y);
      }
      for (const s of m.shadows) s.visible = visible;
    }
    const outline = !!(c && c.outline);
    for (const m of this.models) if (m !== this.ground) m.outlines.forEach((o) => (o.visible = outline));
  }

  // Models stand on the plane: their local origin sits on it.
  placeOnPlane() {
    const c = this.rig?.constants;
    if (!c || this.placedFor === c.planeI.join()) return;
    this.placedFor = c.planeI.join();
    const base = c.planeI[1];
    for (const m of this.models) if (m !== this.ground) m.group.position.y = (m.baseY ??= m.group.position.y) + base;
  }

  // Mouse control on the shared canvas (orbit.js); home is fitHome's view.
  attachControls(canvas, css) { this.orbit = new ViewOrbit(this.camera, canvas, css); }

  // What the home view must show: the ground disc's rim, every model's box and the wave's
  // billboard (world points).
  framedPoints() {
    const pts = [], I = this.ground.group.position, q = this.ground.group.quaternion;
    for (let k = 0; k < 32; k++) {
      const a = (2 * Math.PI * k) / 32;
      pts.push(new THREE.Vector3(GROUND_R * Math.cos(a), 0, GROUND_R * Math.sin(a)).applyQuaternion(q).add(I));
    }
    for (const m of this.models) if (m !== this.ground) pts.push(...boxCorners(new THREE.Box3().setFromObject(m.group)));
    if (this.billboard.visible) {
      const { x, y } = this.billboard.scale, c = this.billboard.position, r = Math.hypot(x, y) / 2;
      for (const d of [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]) pts.push(c.clone().addScaledVector(new THREE.Vector3(...d), r));
    }
    return pts;
  }

  // The home view for this aspect: from HOME_DIR, at the distance where every framed point
  // lies within HOME_MARGIN of the view's edges, aimed so that they sit in the middle (a few
  // rounds of: fit the distance, then move the target by the off-centre of the points'
  // projection). It is recomputed when the aspect or what it frames changes; the camera goes
  // there unless the user has moved it (a double-click takes it to the new home).
  fitHome(aspect) {
    const pts = this.framedPoints(), box = new THREE.Box3().setFromPoints(pts), target = box.getCenter(new THREE.Vector3());
    const key = `${aspect.toFixed(3)}|${box.min.toArray().map((v) => v.toFixed(2))}|${box.max.toArray().map((v) => v.toFixed(2))}`;
    if (key === this.homeKey) return;
    this.homeKey = key;
    const up = new THREE.Vector3(0, 1, 0), right = new THREE.Vector3().crossVectors(up, HOME_DIR).normalize();
    const camUp = new THREE.Vector3().crossVectors(HOME_DIR, right);
    const ty = Math.tan(THREE.MathUtils.degToRad(this.camera.fov / 2)) * HOME_MARGIN, tx = ty * aspect;
    let dist = 0;
    for (let round = 0; round < 4; round++) {
      dist = 0;
      for (const p of pts) {
        const q = p.clone().sub(target), depth = q.dot(HOME_DIR);
        dist = Math.max(dist, depth + Math.abs(q.dot(right)) / tx, depth + Math.abs(q.dot(camUp)) / ty);
      }
      const x = [Infinity, -Infinity], y = [Infinity, -Infinity];
      for (const p of pts) {
        const q = p.clone().sub(target), z = dist - q.dot(HOME_DIR);
        const px = q.dot(right) / z, py = q.dot(camUp) / z;
        x[0] = Math.min(x[0], px); x[1] = Math.max(x[1], px); y[0] = Math.min(y[0], py); y[1] = Math.max(y[1], py);
      }
      target.addScaledVector(right, (dist * (x[0] + x[1])) / 2).addScaledVector(camUp, (dist * (y[0] + y[1])) / 2);
    }
    const position = target.clone().addScaledVector(HOME_DIR, dist);
    if (!this.orbit) { this.camera.position.copy(position); this.camera.lookAt(target); }
    else this.orbit.setHome(position, target, up, !this.orbit.moved);
  }

  render(renderer, rect, t) {
    if (!this.params) return false;
    this.placeOnPlane();
    this.updateShadows();
    // the wave's billboard, moved along the stream's view ray to the depth of its centre line
    // and turned to face this camera
    if (this.wt.texture && this.rig && this.rig.nSeg) {
      const p = this.params, eye = new THREE.Vector3(...p.eye), ctr = new THREE.Vector3(...p.center);
      const f = ctr.clone().sub(eye), fl = f.length();
      f.normalize();
      const cen = new THREE.Vector3();
      for (let i = 0; i < this.rig.nSeg; i++) {
        const o = SEG_FLOATS * i, lo = this.rig.seg[o + 6], hi = this.rig.seg[o + 7];
        const a = Number.isFinite(lo) && Number.isFinite(hi) ? (lo + hi) / 2 : 0;
        cen.add(new THREE.Vector3(this.rig.seg[o] + a * this.rig.seg[o + 3], this.rig.seg[o + 1] + a * this.rig.seg[o + 4], this.rig.seg[o + 2] + a * this.rig.seg[o + 5]));
      }
      cen.divideScalar(this.rig.nSeg);
      const rho = Math.max(0.05, cen.clone().sub(eye).dot(f) / fl);
      this.billboard.position.copy(eye).addScaledVector(ctr.clone().sub(eye), rho);
      this.billboard.scale.set(p.size * rho, p.size * rho * this.wt.height / this.wt.width, 1);
      applyWaveUniforms(this.billboardMat, this.wt, p, this.wave.settings);
      this.billboard.visible = true;
    } else this.billboard.visible = false;
    this.camera.aspect = rect.w / rect.h;
    this.camera.updateProjectionMatrix();
    this.fitHome(this.camera.aspect);
    this.orbit?.update();
    this.billboard.quaternion.copy(this.camera.quaternion);
    renderer.setClearColor(0x0a0c12, 1);
    renderer.clear(true, true, true);
    renderer.render(this.scene, this.camera);
    const drew = this.newFrame;
    this.newFrame = false;
    return drew;
  }

  /** State for the page's test hooks: the rig, each model's shadow, and where the models and
   *  the wave's billboard are in the view (boxes as shares of its width and height from the
   *  top left, as last drawn). */
  info() {
    const rect = (pts) => {
      const v = pts.map((p) => p.clone().project(this.camera)), xs = v.map((p) => (p.x + 1) / 2), ys = v.map((p) => (1 - p.y) / 2);
      return { x0: Math.min(...xs), x1: Math.max(...xs), y0: Math.min(...ys), y1: Math.max(...ys) };
    };
    const models = this.models.filter((m) => m !== this.ground).map((m) => ({ name: m.name, ...rect(boxCorners(new THREE.Box3().setFromObject(m.group))) }));
    const bb = this.billboard.visible ? rect([[-0.5, -0.5], [0.5, -0.5], [-0.5, 0.5], [0.5, 0.5]].map(([x, y]) => new THREE.Vector3(x, y, 0).applyMatrix4(this.billboard.matrixWorld))) : null;
    return { rig: !!this.rig?.constants, nSeg: this.rig?.nSeg ?? 0, shadows: this.shadowInfo ?? [], models, billboard: bb, home: !this.orbit?.moved };
  }

  dispose() { this.segTex.dispose(); this.orbit?.dispose(); }
}
