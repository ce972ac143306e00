/* wave_sources.h — the energy wave's sources unpacked from its parameters, and the eq. (5.1)
 * animation of the curve weights (seed 000, Watanabe 2016; digest 000 §2, §4).
 *
 * energy_wave reads them once per parameter change and derives each frame's curve weights
 * once; it packs both for its kernel and hands both to the light rig (light_rig.h), so the
 * two see the same scene at the same time without re-reading the parameter document. */
#ifndef FX_WAVE_SOURCES_H
#define FX_WAVE_SOURCES_H

#include "energy_wave_params.h" /* WAVE_MAX_SRC, WAVE_MAX_W */

struct wave_point {
    double pos[3], coef;
};

struct wave_line {
    double pos[3], dir[3], coef; /* dir: unit */
};

/* Centre circle: c + R (cos φ e1 + sin φ e2); e1, e2, e3 (the axis) orthonormal. */
struct wave_torus {
    double c[3], e1[3], e2[3], e3[3], R, coef;
};

/* Quadratic Bézier b[0..2] with B-spline strength weights w[0..nw-1] (eq. 3.25). */
struct wave_curve {
    double b[3][3], coef;
    int nw;
    double w[WAVE_MAX_W];
};

struct wave_sources {
    int np, nl, nt, nc;
    struct wave_point point[WAVE_MAX_SRC];
    struct wave_line line[WAVE_MAX_SRC];
    struct wave_torus torus[WAVE_MAX_SRC];
    struct wave_curve curve[WAVE_MAX_SRC];
    int animate;      /* multiply W by the eq. (5.1) pulses */
    double anim_rate; /* animation frames per second of stream time */
};

/* Unpacks a complete validated energy_wave document (directions normalised, torus frames built). */
void wave_sources_read(const struct energy_wave_config *params, struct wave_sources *s);

/* Each curve's weights at stream time sim_time: W, times the pulses when animate is on. */
void wave_sources_weights(const struct wave_sources *s, double sim_time, double w[][WAVE_MAX_W]);

/* Weights of eq. (5.1) at animation frame `frame` for n weights (digest §4): one pulse. */
void wave_anim_weights(double frame, int n, double *w);
/* The stream's animation: eq. (5.1)'s pulse started again every wave_anim_period(n) = 7n + 10
 * frames, overlapping pulses summed and clamped at 1, so the curve is never dark between two
 * sweeps (a single looped sweep of 7(n-1) + 50 frames would leave every weight 0, a blank
 * texture, for ~10 frames). */
double wave_anim_period(int n);
void wave_loop_weights(double frame, int n, double *w);

#endif
