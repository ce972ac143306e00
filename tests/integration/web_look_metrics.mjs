// web_look_metrics.mjs — the look metrics of the energy wave, the toon scene and the compound
// eye, computed from a view's pixels: img = {w, h, px} with px RGBA bytes, rows from the top.
// Pure functions, used by web_look_wave_check.mjs; every figure is in display values
// (sRGB bytes) and luminance is Rec. 709's weighting of them.

export const lum = (r, g, b) => 0.2126 * r + 0.7152 * g + 0.0722 * b;

/** Hue in degrees [0, 360) and saturation (HSV, 0-1) of an RGB triple. */
export function hueSat(r, g, b) {
  const mx = Math.max(r, g, b), mn = Math.min(r, g, b), d = mx - mn;
  if (mx <= 0 || d <= 0) return { h: 0, s: 0 };
  let h = mx === r ? (g - b) / d : mx === g ? 2 + (b - r) / d : 4 + (r - g) / d;
  h *= 60;
  return { h: h < 0 ? h + 360 : h, s: d / mx };
}

/** The smallest angle between two hues, degrees. */
export const hueDist = (a, b) => { const d = Math.abs(a - b) % 360; return d > 180 ? 360 - d : d; };

/** Display bytes of a linear colour scaled so its strongest channel is 1 (its hue as shown). */
export function displayOf(rgb) {
  const m = Math.max(...rgb);
  return rgb.map((c) => {
    c = m > 0 ? c / m : 0;
    return 255 * (c <= 0.0031308 ? 12.92 * c : 1.055 * c ** (1 / 2.4) - 0.055);
  });
}

export function lumImage(img) {
  const L = new Float32Array(img.w * img.h);
  for (let i = 0; i < L.length; i++) L[i] = lum(img.px[4 * i], img.px[4 * i + 1], img.px[4 * i + 2]);
  return L;
}

// A (2r+1)² box blur of a w × h float image (edges clamped), by running sums.
export function boxBlur(L, w, h, r) {
  const pass = (src, n, m, at) => { // blur along the first index of at(i, j) for each j
    const out = new Float32Array(src.length);
    for (let j = 0; j < m; j++) {
      let s = 0;
      for (let k = -r; k <= r; k++) s += src[at(Math.min(n - 1, Math.max(0, k)), j)];
      for (let i = 0; i < n; i++) {
        out[at(i, j)] = s / (2 * r + 1);
        s += src[at(Math.min(n - 1, i + r + 1), j)] - src[at(Math.max(0, i - r), j)];
      }
    }
    return out;
  };
  return pass(pass(L, w, h, (i, j) => j * w + i), h, w, (i, j) => i * w + j);
}

/**
 * The energy wave view. bb: the billboard's rectangle in the view {x0, y0, x1, y1} (pixels).
 * - peak: the largest luminance after a 3 × 3 blur (one stray pixel is not the peak);
 * - width: the share of the view's width between the first and last column holding a pixel
 *   at >= 25% of the peak (the glow's body, not its faint tail);
 * - glow colour: the mean colour of the pixels at >= 10% of the peak that are not white-out
 *   (some channel below 250), its hue and saturation;
 * - border: the brightest pixel of the billboard's outer 2% of rows and columns, / peak;
 * - clipped: the share of the view's pixels with a channel at 255;
 * - bloom: through the peak along 0°, 45°, 90° and 135°, the run of pixels at >= 90% of the
 *   peak (the core) and at >= 10% (the glow); in the direction where the core is narrowest
 *   (across a ring or a beam), glow / core.
 */
export function waveMetrics(img, bb) {
  const { w, h, px } = img, L = boxBlur(lumImage(img), w, h, 1);
  let peak = 0, at = 0;
  for (let i = 0; i < L.length; i++) if (L[i] > peak) { peak = L[i]; at = i; }
  let x0 = w, x1 = -1, clipped = 0;
  const sum = [0, 0, 0];
  let n = 0;
  for (let y = 0; y < h; y++)
    for (let x = 0; x < w; x++) {
      const i = y * w + x, R = px[4 * i], G = px[4 * i + 1], B = px[4 * i + 2];
      if (R === 255 || G === 255 || B === 255) clipped++;
      if (peak <= 0 || L[i] < 0.1 * peak) continue;
      if (L[i] >= 0.25 * peak) { x0 = Math.min(x0, x); x1 = Math.max(x1, x); }
      if (Math.min(R, G, B) >= 250) continue;
      sum[0] += R; sum[1] += G; sum[2] += B; n++;
    }
  const mean = sum.map((s) => s / Math.max(1, n)), hs = hueSat(...mean);
  const m = Math.max(1, Math.round(0.02 * Math.min(bb.x1 - bb.x0, bb.y1 - bb.y0)));
  let border = 0;
  for (let y = Math.max(0, Math.round(bb.y0)); y < Math.min(h, Math.round(bb.y1)); y++)
    for (let x = Math.max(0, Math.round(bb.x0)); x < Math.min(w, Math.round(bb.x1)); x++) {
      const inside = x >= bb.x0 + m && x < bb.x1 - m && y >= bb.y0 + m && y < bb.y1 - m;
      if (!inside) border = Math.max(border, lum(px[4 * (y * w + x)], px[4 * (y * w + x) + 1], px[4 * (y * w + x) + 2]));
    }
  const px0 = at % w, py0 = Math.floor(at / w);
  const run = (dx, dy, frac) => {
    let len = 1;
    for (const s of [1, -1])
      for (let k = 1; ; k++) {
        const x = px0 + s * k * dx, y = py0 + s * k * dy;
        if (x < 0 || y < 0 || x >= w || y >= h || L[y * w + x] < frac * peak) break;
        len++;
      }
    return len * Math.hypot(dx, dy);
  };
  const dirs = [[1, 0], [1, 1], [0, 1], [-1, 1]].map(([dx, dy]) => ({ dir: [dx, dy], core: run(dx, dy, 0.9), half: run(dx, dy, 0.5), glow: run(dx, dy, 0.1) }));
  const across = dirs.reduce((a, d) => (d.core < a.core ? d : a));
  return {
    peak: +(peak / 255).toFixed(3), width: +((x1 - x0 + 1) / w).toFixed(3), hue: +hs.h.toFixed(1), sat: +hs.s.toFixed(3),
    mean: mean.map((v) => Math.round(v)), border: +(border / Math.max(peak, 1e-9)).toFixed(4), clipped: +(clipped / (w * h)).toFixed(4),
    core: +across.core.toFixed(1), half: +across.half.toFixed(1), glow: +across.glow.toFixed(1), bloom: +(across.glow / across.core).toFixed(2),
  };
}

// The median of a small array (sorted in place).
const median = (v) => { v.sort((a, b) => a - b); return v[v.length >> 1]; };

/**
 * The compound eye view: the model's silhouette is every pixel brighter than the background
 * (bg: its luminance) by 8.
 * - disc: its centre and radius (half the silhouette's box), fill (silhouette area over the
 *   ellipse inscribed in its box) and aspect (box width / height): a closed eye seen from any
 *   side is a full round disc, a half-shell seen from the side is half of one;
 * - colour: mean colour of the disc's inner 90% (radius), its hue and saturation;
 * - speckles: on the lit lattice (pixels whose 5 × 5 median is >= 60% of the disc's median),
 *   the share of dark isolated pixels: below half their 5 × 5 median, with none of their 8
 *   neighbours below 75% of it (a lens border is a line, a pupil an area);
 * - rimNoise (below);
 * - rim: with ref (the same view drawn at twice the resolution and averaged 2 × 2 down), the
 *   mean |luminance − ref| in the rim (0.85-0.98 radius) and in the middle (< 0.6 radius):
 *   aliasing, a moiré ring, is what the finer render does not have.
 */
export function eyeMetrics(img, bg, ref = null) {
  const { w, h, px } = img, L = lumImage(img);
  let x0 = w, x1 = -1, y0 = h, y1 = -1, area = 0;
  for (let y = 0; y < h; y++)
    for (let x = 0; x < w; x++)
      if (L[y * w + x] > bg + 8) { area++; x0 = Math.min(x0, x); x1 = Math.max(x1, x); y0 = Math.min(y0, y); y1 = Math.max(y1, y); }
  if (x1 < 0) return { area: 0, fill: 0, aspect: 0 };
  const cx = (x0 + x1 + 1) / 2, cy = (y0 + y1 + 1) / 2, bw = x1 - x0 + 1, bh = y1 - y0 + 1, R = Math.min(bw, bh) / 2;
  const rOf = (x, y) => Math.hypot(x + 0.5 - cx, y + 0.5 - cy) / R;
  const sum = [0, 0, 0], inner = [];
  for (let y = y0; y <= y1; y++)
    for (let x = x0; x <= x1; x++) {
      if (rOf(x, y) >= 0.9) continue;
      const i = y * w + x;
      sum[0] += px[4 * i]; sum[1] += px[4 * i + 1]; sum[2] += px[4 * i + 2];
      inner.push(L[i]);
    }
  const mean = sum.map((s) => s / Math.max(1, inner.length)), hs = hueSat(...mean), discMed = median(inner.slice());
  let lit = 0, specks = 0;
  const nb = [];
  for (let y = y0 + 2; y <= y1 - 2; y++)
    for (let x = x0 + 2; x <= x1 - 2; x++) {
      if (rOf(x, y) >= 0.9) continue;
      nb.length = 0;
      for (let dy = -2; dy <= 2; dy++) for (let dx = -2; dx <= 2; dx++) nb.push(L[(y + dy) * w + x + dx]);
      const m5 = median(nb);
      if (m5 < 0.6 * discMed) continue;
      lit++;
      const v = L[y * w + x];
      if (v >= 0.5 * m5) continue;
      let dark = 0;
      for (let dy = -1; dy <= 1; dy++) for (let dx = -1; dx <= 1; dx++) if ((dx || dy) && L[(y + dy) * w + x + dx] < 0.75 * m5) dark++;
      if (!dark) specks++;
    }
  const out = {
    area, cx: +cx.toFixed(1), cy: +cy.toFixed(1), r: +R.toFixed(1), fill: +(area / (Math.PI * bw * bh / 4)).toFixed(3), aspect: +(bw / bh).toFixed(3),
    hue: +hs.h.toFixed(1), sat: +hs.s.toFixed(3), lum: +(lum(...mean)).toFixed(1), mean: mean.map((v) => Math.round(v)),
    speckles: +(specks / Math.max(1, lit)).toFixed(5), specks, lit,
  };
  // Aliasing at the rim: in 0.85-0.97 of the radius, where the lattice is foreshortened to
  // a pixel or less a lens, the mean |luminance − its 3 × 3 mean|. A filtered rim is smooth at
  // the pixel scale (what a lens adds there is below a pixel); an aliased one sparkles and
  // beats into a moiré ring.
  const b3 = boxBlur(L, w, h, 1);
  const hf = [0, 0, 0, 0];
  for (let y = y0; y <= y1; y++)
    for (let x = x0; x <= x1; x++) {
      const r = rOf(x, y), k = r >= 0.85 && r < 0.97 ? 0 : r < 0.6 ? 2 : -1;
      if (k >= 0) { hf[k] += Math.abs(L[y * w + x] - b3[y * w + x]); hf[k + 1]++; }
    }
  out.rimNoise = +(hf[0] / Math.max(1, hf[1])).toFixed(2);
  out.midNoise = +(hf[2] / Math.max(1, hf[3])).toFixed(2);
  if (ref) {
    const Lr = lumImage(ref), e = { rim: [0, 0], mid: [0, 0] };
    for (let y = y0; y <= Math.min(y1, ref.h - 1); y++)
      for (let x = x0; x <= Math.min(x1, ref.w - 1); x++) {
        const r = rOf(x, y), d = Math.abs(L[y * w + x] - Lr[y * ref.w + x]);
        if (r >= 0.85 && r < 0.98) { e.rim[0] += d; e.rim[1]++; } else if (r < 0.6) { e.mid[0] += d; e.mid[1]++; }
      }
    out.rimErr = +(e.rim[0] / Math.max(1, e.rim[1])).toFixed(2);
    out.midErr = +(e.mid[0] / Math.max(1, e.mid[1])).toFixed(2);
  }
  return out;
}

/** Averages an image's 2 × 2 blocks: a render at twice the resolution, brought to the view's size. */
export function halve(img) {
  const w = img.w >> 1, h = img.h >> 1, px = new Uint8ClampedArray(w * h * 4);
  for (let y = 0; y < h; y++)
    for (let x = 0; x < w; x++)
      for (let c = 0; c < 4; c++) {
        const at = (dx, dy) => img.px[4 * ((2 * y + dy) * img.w + 2 * x + dx) + c];
        px[4 * (y * w + x) + c] = (at(0, 0) + at(1, 0) + at(0, 1) + at(1, 1) + 2) >> 2;
      }
  return { w, h, px };
}

/**
 * What the bloom adds: over the glow outside the core (pixels of the bloom-off picture at 2-50%
 * of its peak), the mean luminance with the bloom over that without, minus 1.
 */
export function bloomGain(on, off) {
  const Lon = lumImage(on), Loff = lumImage(off);
  let peak = 0;
  for (const v of Loff) peak = Math.max(peak, v);
  let a = 0, b = 0;
  for (let i = 0; i < Loff.length; i++) if (Loff[i] >= 0.02 * peak && Loff[i] <= 0.5 * peak) { a += Lon[i]; b += Loff[i]; }
  return +(a / Math.max(b, 1e-9) - 1).toFixed(3);
}

/**
 * The toon scene view. info: SceneView.info() (boxes as shares of the view); bg: the clear
 * colour's bytes.
 * - cut: the share of the view's outer 2-pixel frame that is not background (a floor or a model
 *   cut by the view's edge);
 * - lit side: in the models' boxes (less the wave's billboard), the brightest quarter of the
 *   pixels that are not background: their mean colour, its hue and saturation.
 */
export function sceneMetrics(img, info, bg) {
  const { w, h, px } = img, isBg = (i) => Math.abs(px[4 * i] - bg[0]) + Math.abs(px[4 * i + 1] - bg[1]) + Math.abs(px[4 * i + 2] - bg[2]) <= 12;
  let edge = 0, cut = 0;
  for (let y = 0; y < h; y++)
    for (let x = 0; x < w; x++) {
      if (x >= 2 && y >= 2 && x < w - 2 && y < h - 2) continue;
      edge++;
      if (!isBg(y * w + x)) cut++;
    }
  const inBox = (b, x, y) => b && x >= b.x0 * w && x < b.x1 * w && y >= b.y0 * h && y < b.y1 * h;
  const lit = [];
  for (let y = 0; y < h; y++)
    for (let x = 0; x < w; x++) {
      const i = y * w + x;
      if (isBg(i) || inBox(info.billboard, x, y) || !info.models.some((m) => inBox(m, x, y))) continue;
      lit.push([lum(px[4 * i], px[4 * i + 1], px[4 * i + 2]), i]);
    }
  lit.sort((a, b) => b[0] - a[0]);
  const top = lit.slice(0, lit.length >> 2), sum = [0, 0, 0];
  for (const [, i] of top) for (let c = 0; c < 3; c++) sum[c] += px[4 * i + c];
  const mean = sum.map((s) => s / Math.max(1, top.length)), hs = hueSat(...mean);
  const inside = info.models.every((m) => m.x0 >= 0 && m.y0 >= 0 && m.x1 <= 1 && m.y1 <= 1);
  return { cut: +(cut / edge).toFixed(4), inside, litHue: +hs.h.toFixed(1), litSat: +hs.s.toFixed(3), litMean: mean.map((v) => Math.round(v)), litPixels: top.length };
}
