// eye.js — the `compound_eye` stream (PROTOCOL.md §11.3, digest 004) on a 3D eye model.
// Mode `lut`: kind 4 frames carry the FXL1 container of §7.6 (PIGM / LLUT / LMAC RGBA8
// tables, each one zstd frame, decompressed here with fzstd); a ShaderMaterial does the
// §7.6 lookup per pixel (a one-texel tent inside a direction tile, bilinear across the 4
// nearest tiles; LMAC and the surface normal blended in as the lenses shrink below a few
// pixels) and shades with eq. 5.31 and the lens normal, so the pseudopupils follow the
// camera (the stream's `eye`, a live parameter that changes nothing on the wire in this
// mode) with no round trip. Mode `bake`: kind 2 EXR frames are the model's texture in its
// own UV space as seen from `eye`, so they go on the same model by uv, seen from `eye`. The
// built-in models mirror eye_model.c (rings, segments, stereographic uv); per vertex the
// tangent frame is the analytic ∂P/∂u, ∂P/∂v, so density·uv is the lattice coordinate of
// eq. 5.1; the ellipsoids are closed behind by a head of dark chitin (their back half). An
// OBJ model (not sent to clients) falls back to the hemisphere in mode lut and to the uv
// square in mode bake.
// The page draws it through the View contract (view.js).
import * as THREE from 'three';
import { ViewOrbit } from './orbit.js';
import { decompress } from 'fzstd';
import { SRGB_GLSL } from './gl.js';
import { WaveTexture } from './wave.js';

// ---- the FXL1 container (PROTOCOL.md §7.6) -----------------------------------------------

const TABLES = ['PIGM', 'LLUT', 'LMAC'];
const MAX_RAW = 128 << 20; // bytes of one decompressed table (64 × 66 tiles² is 71 MiB)

function fail(msg) { throw new Error(`lut_pack: ${msg}`); }

function readEntry(dv, at) {
  const u32 = (o) => dv.getUint32(at + o, true);
  return {
    name: String.fromCharCode(dv.getUint8(at), dv.getUint8(at + 1), dv.getUint8(at + 2), dv.getUint8(at + 3)),
    format: u32(4), codec: u32(8), width: u32(12), height: u32(16), offset: u32(20), stored: u32(24), raw: u32(28),
    tile: u32(32), tilesX: u32(36), tilesY: u32(40), inner: u32(44),
  };
}

// Checks an entry against the payload and decompresses its texels.
function entryTexels(bytes, e, dirEnd) {
  if (e.format !== 1) fail(`${e.name}: unsupported format ${e.format}`);
  if (e.codec !== 1) fail(`${e.name}: unsupported codec ${e.codec}`);
  if (!e.width || !e.height || e.raw !== e.width * e.height * 4) fail(`${e.name}: raw_bytes ${e.raw} is not ${e.width} × ${e.height} × 4`);
  if (e.raw > MAX_RAW) fail(`${e.name}: ${e.raw} bytes is over the ${MAX_RAW}-byte limit`);
  if (e.offset % 8 || e.offset < dirEnd || e.offset + e.stored > bytes.length)
    fail(`${e.name}: stored bytes [${e.offset}, ${e.offset + e.stored}) are outside the data area [${dirEnd}, ${bytes.length})`);
  let texels;
  try {
    texels = decompress(bytes.subarray(e.offset, e.offset + e.stored));
  } catch (err) {
    fail(`${e.name}: zstd: ${err.message}`);
  }
  if (texels.length !== e.raw) fail(`${e.name}: ${texels.length} bytes decompressed, ${e.raw} expected`);
  return texels;
}

function checkGeometry(p) {
  const { LLUT: l, LMAC: m, PIGM: g } = p.tables;
  if (!l || !m) fail(`missing ${l ? 'LMAC' : 'LLUT'}`);
  const tile = p.cells + 2 * p.gutter, side = p.dirs * tile;
  if (l.tile !== tile || l.inner !== p.cells || l.tilesX !== p.dirs || l.tilesY !== p.dirs || l.width !== side || l.height !== side)
    fail(`LLUT: ${l.width} × ${l.height} in tiles of ${l.tile} does not hold ${p.dirs}² tiles of ${p.cells} + 2 × ${p.gutter} texels`);
  if (m.width !== p.dirs || m.height !== p.dirs) fail(`LMAC: ${m.width} × ${m.height}, expected ${p.dirs}²`);
  if (g && (g.tilesX !== 1 || g.tilesY !== 1)) fail('PIGM: not one tile');
}

/** Decodes a kind 4 codec 1 payload (Uint8Array): the header constants and every known
 *  table {width, height, tile, tilesX, tilesY, inner, texels} by name. Throws on malformed input. */
export function decodeLutPack(bytes) {
  if (bytes.length < 64) fail(`${bytes.length} bytes is shorter than the 64-byte header`);
  const dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  if (String.fromCharCode(...bytes.subarray(0, 4)) !== 'FXL1') fail('bad magic (not FXL1)');
  const headerBytes = dv.getUint16(6, true), count = dv.getUint16(8, true), entryBytes = dv.getUint16(10, true);
  if (headerBytes < 64 || entryBytes < 48) fail(`header_bytes ${headerBytes} / entry_bytes ${entryBytes} too small`);
  const dirEnd = headerBytes + count * entryBytes;
  if (dirEnd > bytes.length) fail(`directory of ${count} entries ends at ${dirEnd}, past the ${bytes.length}-byte payload`);
  const f32 = (o) => dv.getFloat32(o, true), u32 = (o) => dv.getUint32(o, true);
  const p = {
    version: dv.getUint16(4, true), lattice: u32(12), tileH: f32(16), lensRadius: f32(20), refractiveIndex: f32(24),
    pigmentDepth: f32(28), maxPasses: u32(32), cells: u32(36), dirs: u32(40), gutter: u32(44), supersample: u32(48), tables: {},
  };
  if (p.lattice > 1) fail(`unknown lattice ${p.lattice}`);
  if (!p.cells || !p.dirs) fail(`cells ${p.cells}, dirs ${p.dirs}`);
  for (let i = 0; i < count; i++) {
    const e = readEntry(dv, headerBytes + i * entryBytes);
    if (!TABLES.includes(e.name)) continue; // unknown products are skipped (§7.6)
    if (p.tables[e.name]) fail(`${e.name} twice`);
    const { width, height, tile, tilesX, tilesY, inner } = e;
    p.tables[e.name] = { width, height, tile, tilesX, tilesY, inner, texels: entryTexels(bytes, e, dirEnd) };
  }
  checkGeometry(p);
  return p;
}

// ---- models (server/effects/eye_model.c) --------------------------------------------------

const RINGS = 32, SEGMENTS = 64;
const ELLIPSOIDS = { hemisphere: [1, 1, 1], insect_eye: [0.8, 0.65, 1.0] };

// Front half (z ≥ 0) of an ellipsoid: vertex (ring, seg) as eye_ellipsoid_vertex, uv the
// stereographic projection of the unit direction s, ∂P/∂u and ∂P/∂v differentiated from it.
function ellipsoidGeometry(ax) {
  const pos = [], uv = [], nrm = [], du = [], dv = [], index = [];
  for (let r = 0; r <= RINGS; r++)
    for (let k = 0; k <= SEGMENTS; k++) {
      const th = (0.5 * Math.PI * r) / RINGS, ph = (2 * Math.PI * k) / SEGMENTS;
      const s = [Math.sin(th) * Math.cos(ph), Math.sin(th) * Math.sin(ph), Math.cos(th)];
      const X = s[0] / (1 + s[2]), Y = s[1] / (1 + s[2]), d = 1 + X * X + Y * Y, g = 4 / (d * d); // X = 2u − 1
      const dsu = [g * (d - 2 * X * X), -2 * g * X * Y, -2 * g * X], dsv = [-2 * g * X * Y, g * (d - 2 * Y * Y), -2 * g * Y];
      pos.push(...s.map((c, i) => ax[i] * c));
      uv.push(0.5 + 0.5 * X, 0.5 + 0.5 * Y);
      nrm.push(...new THREE.Vector3(s[0] / ax[0], s[1] / ax[1], s[2] / ax[2]).normalize().toArray());
      du.push(...dsu.map((c, i) => ax[i] * c));
      dv.push(...dsv.map((c, i) => ax[i] * c));
    }
  const at = (r, k) => r * (SEGMENTS + 1) + k;
  for (let r = 0; r < RINGS; r++)
    for (let k = 0; k < SEGMENTS; k++) {
      index.push(at(r, k), at(r + 1, k), at(r + 1, k + 1));
      if (r > 0) index.push(at(r, k), at(r + 1, k + 1), at(r, k + 1)); // one triangle at the pole
    }
  return frameGeometry(pos, uv, nrm, du, dv, index);
}

// The back half (z ≤ 0) of the same ellipsoid, positions and normals only: the head behind
// the eye, so that no view into the open half-shell shows (drawn with CAP_FRAG).
function backGeometry(ax) {
  const g = new THREE.SphereGeometry(1, SEGMENTS, RINGS / 2, 0, 2 * Math.PI, Math.PI / 2, Math.PI / 2);
  g.rotateX(Math.PI / 2); // three's sphere has its pole on +y; here the eye looks along +z
  g.scale(...ax);
  g.computeVertexNormals();
  return g;
}

// The 2 × 2 square in z = 0 with uv the square (the built-in `plane`; also the fallback
// that shows a bake of an OBJ model as its uv layout).
function planeGeometry() {
  return frameGeometry([-1, -1, 0, 1, -1, 0, 1, 1, 0, -1, 1, 0], [0, 0, 1, 0, 1, 1, 0, 1], Array(4).fill([0, 0, 1]).flat(),
    Array(4).fill([2, 0, 0]).flat(), Array(4).fill([0, 2, 0]).flat(), [0, 1, 2, 0, 2, 3]);
}

function frameGeometry(pos, uv, nrm, du, dv, index) {
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.Float32BufferAttribute(pos, 3));
  g.setAttribute('uv', new THREE.Float32BufferAttribute(uv, 2));
  g.setAttribute('normal', new THREE.Float32BufferAttribute(nrm, 3));
  g.setAttribute('dPdu', new THREE.Float32BufferAttribute(du, 3));
  g.setAttribute('dPdv', new THREE.Float32BufferAttribute(dv, 3));
  g.setIndex(index);
  g.computeBoundingSphere();
  return g;
}

// The semi-axes of the ellipsoid drawn for a model in a mode, or null for the plane.
function modelAxes(name, mode) {
  if (ELLIPSOIDS[name]) return ELLIPSOIDS[name];
  return name === 'plane' || mode === 'bake' ? null : ELLIPSOIDS.hemisphere;
}

// ---- shaders --------------------------------------------------------------------------

const VERT = /* glsl */ `
attribute vec3 dPdu;
attribute vec3 dPdv;
varying vec2 vUv;
varying vec3 vWorld, vT, vB, vN;
void main() {
  vec4 w = modelMatrix * vec4(position, 1.0);
  vWorld = w.xyz;
  vT = mat3(modelMatrix) * dPdu;
  vB = mat3(modelMatrix) * dPdv;
  vN = mat3(modelMatrix) * normal;
  vUv = uv;
  gl_Position = projectionMatrix * viewMatrix * w;
}`;

// §7.6 lookup and eq. 5.31, as the protocol's pseudo-code.
const LUT_FRAG = /* glsl */ `
uniform sampler2D llut, lmac;
uniform vec2 atlas;
uniform float D, C, gutter, tileH, density, r, ka, kd, ks, shininess, pixelRatio;
uniform bool hex, lensNormal;
uniform vec3 eyePos, light;
varying vec2 vUv;
varying vec3 vWorld, vT, vB, vN;
${SRGB_GLSL}
// One direction tile at in-cell position q: four bilinear taps half a texel apart, a tent of
// one texel, so a lone texel that one ray of the table saw dark (a speck of pigment seen
// through a grazing multi-lens path) shows as a quarter of its contrast, not as a black
// speckle (the taps stay in the tile's one-texel gutter).
vec4 lut(vec2 tile, vec2 q) {
  vec2 texel = tile * (C + 2.0 * gutter) + gutter + q * C, h = vec2(0.5, -0.5);
  return 0.25 * (texture(llut, (texel + h.xx) / atlas) + texture(llut, (texel + h.xy) / atlas) +
                 texture(llut, (texel + h.yx) / atlas) + texture(llut, (texel + h.yy) / atlas));
}
// Offset (pitches) from the lens centre nearest to in-cell position q.
vec2 lensOffset(vec2 q) {
  vec2 p = q * vec2(1.0, tileH);
  if (!hex) return p - vec2(0.5);
  float h = tileH;
  vec2 c[6] = vec2[6](vec2(0.5, 0.25 * h), vec2(0.5, 1.25 * h), vec2(0.0, 0.75 * h), vec2(1.0, 0.75 * h),
                      vec2(0.0, -0.25 * h), vec2(1.0, -0.25 * h));
  vec2 best = p - c[0];
  for (int i = 1; i < 6; i++) if (dot(p - c[i], p - c[i]) < dot(best, best)) best = p - c[i];
  return best;
}
void main() {
  vec3 T = normalize(vT), B = normalize(vB), N = normalize(vN);
  vec2 a = density * vUv;                                   // eq. 5.1, cell units
  vec2 q = vec2(fract(a.x), fract(a.y / tileH));
  vec3 w = normalize(eyePos - vWorld);
  vec3 wl = vec3(dot(w, T), dot(w, B), max(dot(w, N), 1e-3));
  wl /= abs(wl.x) + abs(wl.y) + wl.z;
  vec2 o = vec2(wl.x + wl.y, wl.x - wl.y);                  // hemi-octahedral, [-1, 1]²
  vec2 f = clamp((o + 1.0) * 0.5 * D - 0.5, 0.0, D - 1.0);
  vec2 i0 = floor(f), k = f - i0, i1 = min(i0 + 1.0, D - 1.0);
  vec4 ct = mix(mix(lut(i0, q), lut(vec2(i1.x, i0.y), q), k.x),
                mix(lut(vec2(i0.x, i1.y), q), lut(i1, q), k.x), k.y);
  // Minification (towards the rim the lattice is foreshortened to less than a pixel a lens):
  // the lens's picture gives way to the macro map, its per-direction mean, and the lens
  // normal to the surface's, before either can alias into a moiré ring. The measure is lenses
  // per CSS pixel along the more foreshortened axis, so the look is the same on every screen.
  float cellsPerPixel = max(length(dFdx(a)), length(dFdy(a))) * pixelRatio;
  ct = mix(ct, texture(lmac, (f + 0.5) / D), smoothstep(0.2, 0.45, cellsPerPixel));
  vec2 c = lensOffset(q);
  vec3 Nl = lensNormal ? normalize(c.x * T + c.y * B + sqrt(max(r * r - dot(c, c), 0.0)) * N) : N;
  Nl = normalize(mix(Nl, N, smoothstep(0.15, 0.35, cellsPerPixel)));
  vec3 L = normalize(light);
  vec3 col = ct.rgb * (ka + kd * max(dot(Nl, L), 0.0)) + ks * pow(max(dot(Nl, normalize(L + w)), 0.0), shininess);
  gl_FragColor = vec4(linearToSRGB(col), 1.0);
}`;

// The bake: EXR texel (x, y) is uv ((x+½)/size, 1 − (y+½)/size) (§11.3); three's EXRLoader
// stores the rows bottom first, so texture coordinates are the uv themselves.
const BAKE_FRAG = /* glsl */ `
uniform sampler2D bake;
varying vec2 vUv;
${SRGB_GLSL}
void main() {
  vec4 t = texture(bake, vUv);
  gl_FragColor = vec4(linearToSRGB(t.rgb * t.a), 1.0);
}`;

// The head behind the eye: dark chitin with a soft highlight, lit by the stream's light.
const CAP_VERT = /* glsl */ `
varying vec3 vWorld, vN;
void main() {
  vec4 w = modelMatrix * vec4(position, 1.0);
  vWorld = w.xyz;
  vN = mat3(modelMatrix) * normal;
  gl_Position = projectionMatrix * viewMatrix * w;
}`;
const CAP_FRAG = /* glsl */ `
uniform vec3 color, light, eyePos;
varying vec3 vWorld, vN;
${SRGB_GLSL}
void main() {
  vec3 N = normalize(vN), L = normalize(light), V = normalize(eyePos - vWorld);
  vec3 col = color * (0.45 + 0.55 * max(dot(N, L), 0.0)) + 0.12 * pow(max(dot(N, normalize(L + V)), 0.0), 24.0);
  gl_FragColor = vec4(linearToSRGB(col), 1.0);
}`;
const CHITIN = [0.04, 0.028, 0.022];

// ---- textures ----------------------------------------------------------------------------

// A table as sampled by the §7.6 lookup: LINEAR, clamped, no mipmaps, rows unflipped.
function tableTexture(t) {
  const tex = new THREE.DataTexture(t.texels, t.width, t.height, THREE.RGBAFormat, THREE.UnsignedByteType);
  tex.minFilter = tex.magFilter = THREE.LinearFilter;
  tex.wrapS = tex.wrapT = THREE.ClampToEdgeWrapping;
  tex.generateMipmaps = false;
  tex.flipY = false;
  tex.colorSpace = THREE.NoColorSpace; // linear values / 255 (§7.6)
  tex.needsUpdate = true;
  return tex;
}

// ---- the view ----------------------------------------------------------------------------

const LUT_UNIFORMS = ['llut', 'lmac', 'atlas', 'D', 'C', 'gutter', 'tileH', 'r', 'hex', 'density', 'ka', 'kd', 'ks', 'shininess',
  'lensNormal', 'eyePos', 'light', 'pixelRatio'];

export class EyeView {
  constructor(stream) {
    this.stream = stream;
    this.kind = 'eye';
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(30, 1, 0.01, 100);
    this.params = null;
    this.lut = null;    // decodeLutPack result + paramRev
    this.textures = {}; // LLUT, LMAC
    this.bake = new WaveTexture();
    this.bakeRev = 0;
    this.newFrame = false;
    this.lutMat = new THREE.ShaderMaterial({
      vertexShader: VERT, fragmentShader: LUT_FRAG,
      uniforms: Object.fromEntries(LUT_UNIFORMS.map((k) => [k, { value: null }])),
    });
    this.bakeMat = new THREE.ShaderMaterial({ vertexShader: VERT, fragmentShader: BAKE_FRAG, uniforms: { bake: { value: null } } });
    this.mesh = new THREE.Mesh(new THREE.BufferGeometry(), this.lutMat);
    this.scene.add(this.mesh);
    this.capMat = new THREE.ShaderMaterial({
      vertexShader: CAP_VERT, fragmentShader: CAP_FRAG,
      uniforms: { color: { value: new THREE.Color(...CHITIN) }, light: { value: new THREE.Vector3(0, 0, 1) }, eyePos: { value: this.camera.position } },
    });
    this.cap = new THREE.Mesh(new THREE.BufferGeometry(), this.capMat);
    this.scene.add(this.cap);
    this.modelKey = '';
  }

  setParams(p) { this.params = p; }

  onFrame(h, buf) {
    if (h.kind === 4 && h.codec === 1) return this.onTable(h, new Uint8Array(buf, h.headerBytes, h.payloadBytes));
    if (h.kind === 2 && h.codec === 1) {
      this.bake.update(new Uint8Array(buf, h.headerBytes, h.payloadBytes));
      this.bakeRev = h.paramRev;
      this.newFrame = true;
      return true;
    }
    return false;
  }

  // A table older than the one held is dropped (latest parameters win, §7.6).
  onTable(h, payload) {
    if (this.lut && h.paramRev < this.lut.paramRev) return false;
    const p = decodeLutPack(payload);
    const l = p.tables.LLUT;
    if (l.width !== h.count || l.height !== h.height) fail(`LLUT ${l.width} × ${l.height} but the frame says ${h.count} × ${h.height}`);
    for (const name of ['LLUT', 'LMAC']) {
      this.textures[name]?.dispose();
      this.textures[name] = tableTexture(p.tables[name]);
    }
    this.lut = { ...p, paramRev: h.paramRev };
    this.newFrame = true;
    return true;
  }

  get mode() { return this.params?.mode === 'bake' ? 'bake' : 'lut'; }

  /** State for the page's test hooks. */
  info() {
    const l = this.lut;
    return { mode: this.mode, lutRev: l?.paramRev ?? 0, cells: l?.cells ?? 0, dirs: l?.dirs ?? 0, lattice: l?.lattice ?? -1,
      atlas: l ? l.tables.LLUT.width : 0, bake: this.bake.width, bakeRev: this.bakeRev };
  }

  useModel() {
    const key = `${this.params.model}:${this.mode}`;
    if (key === this.modelKey) return;
    const ax = modelAxes(this.params.model, this.mode);
    this.mesh.geometry.dispose();
    this.mesh.geometry = ax ? ellipsoidGeometry(ax) : planeGeometry();
    this.cap.geometry.dispose();
    this.cap.geometry = ax ? backGeometry(ax) : new THREE.BufferGeometry();
    this.cap.visible = !!ax;
    // what the camera frames and turns around: the closed ellipsoid, or the model alone
    this.bounds = ax ? new THREE.Sphere(new THREE.Vector3(), Math.max(...ax)) : this.mesh.geometry.boundingSphere;
    this.modelKey = key;
  }

  // Home: the stream's `eye` looking at the model's centre, the model's bounding sphere in
  // view. The orbit camera (orbit.js) starts there and goes back there when `eye` or the model
  // changes; in mode lut the shader shades from wherever the camera is, so the pseudopupils
  // follow the mouse with no message to the server (mode bake shows the texture baked for `eye`).
  placeCamera(aspect) {
    const eye = new THREE.Vector3(...this.params.eye);
    const bs = this.bounds, dist = Math.max(eye.distanceTo(bs.center), 1.05 * bs.radius);
    const half = Math.asin(Math.min(bs.radius / dist, 0.99)) * 1.2;
    const cam = this.camera;
    cam.fov = THREE.MathUtils.radToDeg(2 * Math.atan(Math.tan(half) / Math.min(aspect, 1)));
    cam.aspect = aspect;
    cam.near = dist / 100;
    cam.far = dist * 10;
    cam.updateProjectionMatrix();
    const key = `${this.params.eye}|${this.modelKey}`;
    if (key === this.homeKey) { this.orbit?.update(); return; }
    this.homeKey = key;
    const up = Math.abs(eye.clone().sub(bs.center).normalize().y) > 0.99 ? new THREE.Vector3(0, 0, 1) : new THREE.Vector3(0, 1, 0);
    if (this.orbit) this.orbit.setHome(eye, bs.center, up);
    else {
      cam.position.copy(eye);
      cam.up.copy(up);
      cam.lookAt(bs.center);
    }
  }

  // Mouse control on the shared canvas; css() gives this view's rectangle.
  attachControls(canvas, css) { this.orbit = new ViewOrbit(this.camera, canvas, css); this.homeKey = null; }

  lutUniforms(pixelRatio) {
    const l = this.lut, p = this.params, u = this.lutMat.uniforms;
    const values = {
      llut: this.textures.LLUT, lmac: this.textures.LMAC, atlas: new THREE.Vector2(l.tables.LLUT.width, l.tables.LLUT.height),
      D: l.dirs, C: l.cells, gutter: l.gutter, tileH: l.tileH, r: l.lensRadius, hex: l.lattice === 1,
      density: p.density, ka: p.ka, kd: p.kd, ks: p.ks, shininess: p.shininess, lensNormal: p.shading_normal !== 'object',
      eyePos: this.camera.position, light: new THREE.Vector3(...p.light), pixelRatio,
    };
    for (const [k, v] of Object.entries(values)) u[k].value = v;
  }

  render(renderer, rect) {
    const ready = this.params && (this.mode === 'lut' ? this.lut : this.bake.texture);
    if (!ready) return false;
    this.useModel();
    this.placeCamera(rect.w / rect.h);
    if (this.mode === 'lut') {
      this.lutUniforms(renderer.getPixelRatio());
      this.mesh.material = this.lutMat;
    } else {
      this.bakeMat.uniforms.bake.value = this.bake.texture;
      this.mesh.material = this.bakeMat;
    }
    this.capMat.uniforms.light.value.set(...this.params.light);
    renderer.setClearColor(0x080a10, 1);
    renderer.clear();
    renderer.render(this.scene, this.camera);
    const drew = this.newFrame;
    this.newFrame = false;
    return drew;
  }

  dispose() {
    for (const t of Object.values(this.textures)) t.dispose();
    this.bake.texture?.dispose();
    this.mesh.geometry.dispose();
    this.cap.geometry.dispose();
    this.capMat.dispose();
    this.lutMat.dispose();
    this.bakeMat.dispose();
    this.orbit?.dispose();
  }
}
