/* energy_wave.h — effect `energy_wave` (seed 000, Watanabe 2016): per-texel line
 * integral of an energy field of point / line / torus / quadratic Bézier sources,
 * seen from a camera, streamed as OpenEXR textures.
 *
 * Besides the effect_ops (energy_wave_effect, registered in registry.c), the module
 * exposes a direct rendering API and its device-side helpers so tests and benches can
 * compare the OpenCL kernels with the double-precision C reference (tests/ref/). */
#ifndef FX_ENERGY_WAVE_H
#define FX_ENERGY_WAVE_H

#include <cjson/cJSON.h>

#include "../effect.h"

struct ocl;
struct energy_wave;

extern const struct effect_ops energy_wave_effect;
extern const struct param_def energy_wave_params[]; /* {0}-terminated */

/* Creates a renderer from a complete validated parameter document. */
struct energy_wave *energy_wave_new(struct ocl *ocl, const cJSON *params, struct fx_err *err);
/* Replaces the parameters (complete validated document). */
int energy_wave_set(struct energy_wave *ew, const cJSON *params, struct fx_err *err);
/* Renders raw B (before any colour map) for stream time sim_time (which drives the W
 * animation when enabled) into out: width*height floats, row 0 at the top. */
int energy_wave_render(struct energy_wave *ew, double sim_time, float *out, struct fx_err *err);
void energy_wave_free(struct energy_wave *ew);

/* Device-side helpers run through test kernels in kernels/energy_wave.cl, n inputs each.
 * Cubic x^3 + a x^2 + b x + c = 0: abc is 3n floats; roots 3n floats (the real roots
 * ascending, unused slots 0); nroots n ints. */
int energy_wave_dev_cubic(struct ocl *ocl, int n, const float *abc, float *roots, int *nroots,
                          struct fx_err *err);
/* Quadratic B-spline strength S(t) (digest §2.3, end span closed at t=1) for weights
 * w[0..nw-1] at n parameters t. */
int energy_wave_dev_bspline(struct ocl *ocl, int nw, const float *w, int n, const float *t, float *out,
                            struct fx_err *err);
/* Nearest point of the Bézier curve b = {B0, B1, B2} (9 floats) to n points p (3n floats):
 * distance and curve parameter t* in [0,1]. */
int energy_wave_dev_curve_nearest(struct ocl *ocl, const float b[9], int n, const float *p, float *dist,
                                  float *tparam, struct fx_err *err);

/* Weights of eq. (5.1) at animation frame `frame` for n weights (digest §4): one pulse. */
void energy_wave_anim_weights(double frame, int n, double *w);
/* The stream's animation: eq. (5.1)'s pulse started again every energy_wave_anim_period(n)
 * = 7n + 10 frames, overlapping pulses summed and clamped at 1, so the curve is never dark
 * between two sweeps (a single looped sweep of 7(n-1) + 50 frames left every weight 0 for
 * ~10 frames: the blank textures of issue 14). */
double energy_wave_anim_period(int n);
void energy_wave_loop_weights(double frame, int n, double *w);

#endif
