/* energy_wave_layout.h — the buffer layouts server/effects/energy_wave.c packs and
 * kernels/energy_wave.cl reads: one record per source (floats), the curves' strength
 * polynomials, the camera block, and the texels per work-item. Valid C and OpenCL C:
 * energy_wave.c includes it and the build (tools/embed_kernels.sh) prepends it to
 * energy_wave.cl, so the layout exists once. */
#ifndef ENERGY_WAVE_LAYOUT_H
#define ENERGY_WAVE_LAYOUT_H

#define EW_PT_STRIDE 4  /* point: pos.xyz, coef */
#define EW_LN_STRIDE 8  /* line: pos.xyz, coef, dir.xyz (unit), 0 */
#define EW_TO_STRIDE 16 /* torus: center.xyz, R, e1.xyz, coef, e2.xyz, 0, axis.xyz (unit), 0 */
#define EW_CV_STRIDE 16 /* curve: C0.xyz, coef, C1.xyz, |C2|², C2.xyz, C1·C2, |C1|², spans, t_lo, t_hi */
/* A curve's strength S(t) (the quadratic B-spline of its nw weights) is one quadratic per span
 * k = 0 … nw − 3 of the uniform knots: S = c0 + x(c1 + x·c2) with x = t·spans − k in [0, 1],
 * (c0, c1, c2) at spl[i·EW_SPL_ROW + 3k] for curve i. */
#define EW_MAX_SPANS 30
#define EW_SPL_ROW (3 * EW_MAX_SPANS)
/* Texels per work-item, the lanes of its vectors: 16 (float16) where the device's native float
 * vector is that wide (AVX-512), else 8; the host passes it to the build as -DEW_LANES. */
#define EW_LANES_WIDE 16
#define EW_LANES_NARROW 8

/* Camera block (EW_CAM_FLOATS floats): billboard centre C, l·r, l·(H/W)·u and the eye V as
 * xyz triples at these offsets, then ν, α, β and ε. */
#define EW_CAM_CENTER 0
#define EW_CAM_RIGHT 4
#define EW_CAM_UP 8
#define EW_CAM_EYE 12
#define EW_CAM_NU 15
#define EW_CAM_ALPHA 16
#define EW_CAM_BETA 17
#define EW_CAM_EPS 18
#define EW_CAM_FLOATS 20

#endif
