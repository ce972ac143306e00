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

#include <cjson/cJSON.h>

#include "../err.h"
#include "../params.h"

struct ocl;

/* Mirrors struct eye_optics in kernels/compound_eye.cl (4-byte fields only). */
enum eye_lattice { EYE_SQUARE = 0, EYE_HEX = 1 };
enum eye_search { EYE_SEARCH_EXACT = 0, EYE_SEARCH_SLICES = 1 };
enum eye_select { EYE_SELECT_ALL = 0, EYE_SELECT_THESIS4 = 1 };
enum eye_tir { EYE_TIR_REFLECT = 0, EYE_TIR_MISS = 1, EYE_TIR_ABSORB = 2 };
enum eye_status { EYE_LANDED = 0, EYE_MISSED = 1, EYE_ABSORBED = 2 };

struct eye_optics {
    float r;        /* lens radius, pitches */
    float n;        /* refractive index */
    float plane;    /* pigment plane depth below the surface, pitches */
    float tile_h;   /* lattice period along b: 1 (square) or sqrt(3) (hex) */
    int lattice, max_passes, search, slices, select, tir;
    int pad0, pad1;
};

#define EYE_SQRT3 1.7320508075688772
#define EYE_LANES 8 /* rays per work-item in every kernel (float8 lanes) */

extern const struct param_def compound_eye_params[];
extern const struct effect_ops compound_eye_effect;

/* The optics of a validated parameter document. */
void eye_optics_from_params(const cJSON *params, struct eye_optics *o);

/* Traces n rays on the device: entry points p[2k..2k+1] (pitches), unit directions
 * d[3k..3k+2] (d.z < 0). Fills land[2k..], status[k], passes[k], entered[k] and the
 * entry normal normal[3k..] (any output may be NULL). */
struct eye_rays_out {
    float *land;
    int *status, *passes, *entered;
    float *normal;
};
int eye_trace_rays(struct ocl *ocl, const struct eye_optics *o, int n, const float *p, const float *d,
                   struct eye_rays_out *out, struct fx_err *err);

/* Effect state, exposed for tests and the benchmark. */
struct compound_eye;
struct compound_eye *compound_eye_new(struct ocl *ocl, const cJSON *params, struct fx_err *err);
int compound_eye_set(struct compound_eye *ce, const cJSON *params, struct fx_err *err);
void compound_eye_free(struct compound_eye *ce);

/* Mode lut: computes the three products and packs the kind 4 container; returns its
 * bytes through data and len (owned by ce, valid until the next call). */
int compound_eye_table(struct compound_eye *ce, const void **data, size_t *len, struct fx_err *err);

/* Mode bake: renders the view texture into rgba (size*size*4 floats, row 0 at the top). */
int compound_eye_bake(struct compound_eye *ce, float *rgba, struct fx_err *err);
int compound_eye_bake_size(const struct compound_eye *ce);

#endif
