/* energy_wave.h — effect `energy_wave` (seed 000, Watanabe 2016): per-texel line
 * integral of an energy field of point / line / torus / quadratic Bézier sources,
 * seen from a camera, streamed as OpenEXR textures.
 *
 * Besides the effect_ops (energy_wave_effect, registered in registry.c), the module
 * exposes a direct rendering API so tests and benches can compare the OpenCL kernels with
 * the double-precision C reference (tests/ref/; tests/ref/kernel_probe.h runs test entry points
 * into the kernel file's device functions, which only the tests compile). */
#ifndef FX_ENERGY_WAVE_H
#define FX_ENERGY_WAVE_H

#include "../effect.h"
#include "energy_wave_params.h"

struct ocl;
struct energy_wave;

#define ENERGY_WAVE_CL "energy_wave.cl" /* kernels/, and its build options */
#define ENERGY_WAVE_CL_OPTS "-cl-fast-relaxed-math"

extern const struct effect_ops energy_wave_effect;
extern const struct param_def energy_wave_params[]; /* {0}-terminated */

/* Creates a renderer from a complete validated parameter document. */
struct energy_wave *energy_wave_new(struct ocl *ocl, const struct energy_wave_config *params, struct fx_err *err);
/* Replaces the parameters (complete validated document). */
int energy_wave_set(struct energy_wave *ew, const struct energy_wave_config *params, struct fx_err *err);
/* Renders raw B (before any colour map) for stream time sim_time (which drives the W
 * animation when enabled) into out: width*height floats, row 0 at the top. */
int energy_wave_render(struct energy_wave *ew, double sim_time, float *out, struct fx_err *err);
void energy_wave_free(struct energy_wave *ew);

/* Where the device time of the last completed frame went (profiling events): the render
 * kernel and the read-back of its texels, over the frame's pieces (one, unless the engine's
 * slices cut it). The rest of a frame's wall time is host work: weights, uploads, launches. */
struct energy_wave_split {
    double kernel_ms, read_back_ms;
    int pieces;
};
void energy_wave_last_split(const struct energy_wave *ew, struct energy_wave_split *out);

/* The kernel's curve record (16 floats, kernels/energy_wave.cl) of the Bézier b with strength
 * coef, nw weights and the lit parameter range [t_lo, t_hi]. */
void energy_wave_pack_curve(float *dst, const double b[3][3], double coef, int nw, double t_lo, double t_hi);
/* The kernel's strength row of a curve with weights w[0..nw-1]: 3(nw − 2) floats, a quadratic
 * per span (kernels/energy_wave_layout.h). */
void energy_wave_pack_strength(float *dst, int nw, const double *w);

#endif
