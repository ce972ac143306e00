/* light_rig.h — the light rig of the energy wave (seed 003, Nito 2011; spec: digest 003 §7,
 * wire format: protocol/fxs_rig.h, PROTOCOL.md §7.7).
 *
 * Owns the rig's parameters (their cross-field checks and their reading) and the derivation
 * of each frame's rig: the wave's centre line as capsule segments with a strength each, from
 * the sources and curve weights energy_wave has already unpacked for that frame
 * (wave_sources.h). Every per-pixel and per-vertex computation belongs to the client
 * (digest §7); the C references of the client's shading are in tests/ref/light_ref.h. */
#ifndef FX_LIGHT_RIG_H
#define FX_LIGHT_RIG_H

#include "err.h"
#include "fxs_rig.h"
#include "wave_sources.h"

/* The rig's settings, read once per parameter change. */
struct light_rig {
    int curve_segments, torus_segments; /* chords per Bézier curve and per torus circle */
    struct fxs_rig_consts k;            /* the constants block of every frame */
};

/* Cross-field rules of the rig's parameters in a complete energy_wave document (the ramp's
 * bands ascend strictly in m_min). 0, or -1 with err naming the field. */
int light_rig_check(const struct energy_wave_config *params, struct fx_err *err);
/* Reads the settings from a complete validated document. */
void light_rig_read(const struct energy_wave_config *params, struct light_rig *lr);
/* The rig of the sources whose curves have the weights w (wave_sources_weights) this frame. */
void light_rig_build(const struct light_rig *lr, const struct wave_sources *src, const double w[][WAVE_MAX_W],
                     struct fxs_rig *out);

/* Quadratic B-spline strength S(t) of weights w[0..nw-1] (seed 000 eqs. 3.24-3.26, the
 * end span closed at t = 1 as in the energy_wave kernel). */
double light_rig_bspline(int nw, const double *w, double t);

#endif
