/* compound_eye.h — effect `compound_eye` (seed 004, Sagawa 2014; spec: digest 004).
 *
 * The effect traces view rays through a lattice of overlapping ommatidium spheres onto
 * a pigment plane (kernels/compound_eye.cl). Mode "lut" sends, on each change of a
 * parameter that affects it, one kind 4 frame holding the pigment tile, the lens
 * look-up table and the far-field macro map (eye_lut.h, PROTOCOL.md §7.6); mode "bake"
 * sends a kind 2 EXR per view change: the shaded texture of a model (eye_model.h) in its
 * UV space. This header is what the tests and the benchmark use besides effect_ops. */
#ifndef FX_COMPOUND_EYE_H
#define FX_COMPOUND_EYE_H

#include "err.h"
#include "../params.h"
#include "compound_eye_layout.h" /* kernels/: struct eye_optics, EYE_* */
#include "compound_eye_params.h"

struct ocl;
struct eye_pigment; /* eye_lut.h */

#define COMPOUND_EYE_CL "compound_eye.cl" /* kernels/, and its build options */
#define COMPOUND_EYE_CL_OPTS "-cl-fast-relaxed-math"

extern const struct param_def compound_eye_params[];
extern const struct effect_ops compound_eye_effect;

/* The build options of kernels/compound_eye.cl for the device (COMPOUND_EYE_OPTS_MAX bytes at
 * most) and the rays per work-item they give its kernels: 16 where the device's preferred
 * float vector width is 16 (AVX-512), else 8. */
#define COMPOUND_EYE_OPTS_MAX 96
int compound_eye_build_options(struct ocl *ocl, char *opts);

/* The optics of the parameters. */
void eye_optics_from_params(const struct compound_eye_config *params, struct eye_optics *o);
/* The pigment pattern of the parameters (the tests' reference draws the same one). */
void eye_pigment_from_params(const struct compound_eye_config *params, struct eye_pigment *pg);

/* Effect state, exposed for tests and the benchmark. */
struct compound_eye;
struct compound_eye *compound_eye_new(struct ocl *ocl, const struct compound_eye_config *params, struct fx_err *err);
int compound_eye_set(struct compound_eye *ce, const struct compound_eye_config *params, struct fx_err *err);
void compound_eye_free(struct compound_eye *ce);

/* Mode lut: computes the three products and packs the kind 4 container; returns its
 * bytes through data and len (owned by ce, valid until the next call). */
int compound_eye_table(struct compound_eye *ce, const void **data, size_t *len, struct fx_err *err);

/* Mode bake: renders the view texture into rgba (size*size*4 floats, row 0 at the top). */
int compound_eye_bake(struct compound_eye *ce, float *rgba, struct fx_err *err);
int compound_eye_bake_size(const struct compound_eye *ce);

/* Where the last table or view's time went, milliseconds: the kernel on the device, launching
 * it and reading its results back (the wall time of the kernel's launches less kernel), the
 * pigment tile (computed and uploaded when its parameters are set) and a table's packing
 * stages (eye_lut.h: atlas layout, macro map, zstd). */
struct compound_eye_split {
    double kernel, launch_read, pigment, atlas, macro, zstd;
    double lane_use; /* the share of its lane-slots that did work (eye_order.h; NAN: a GPU, index order) */
};
void compound_eye_split(const struct compound_eye *ce, struct compound_eye_split *out);

#endif
