/* energy_ref.h — double-precision C reference for the energy_wave effect (seed 000,
 * digest digests/000-energy-wave.md), used only by tests and benches.
 *
 * It owns the ground truth the OpenCL kernels are checked against: the scene read from
 * an energy_wave parameter document, the camera's texel rays (S, E), the field psi(P),
 * the nearest point on a quadratic Bezier (corrected cubic of digest §2.2 with the
 * recommended Cardano/trigonometric solver, plus a brute-force search), the quadratic
 * B-spline strength S(t) by Cox-de Boor with the end span closed at t=1, the thesis's
 * composite Simpson integral, the closed forms of Abe and of digest §2.6 for point and
 * line sources, and a converged integral (adaptive Gauss-Kronrod split at every
 * primitive's closest approach, ~1e-9 relative) used as the exact B.
 *
 * It is written independently of server/effects/energy_wave.c on purpose: the two must
 * agree only because both follow the digest, so neither may borrow from the other. */
#ifndef FX_ENERGY_REF_H
#define FX_ENERGY_REF_H

#include <cjson/cJSON.h>
#include <stddef.h>

#define ENERGY_REF_MAX_PRIMS 64
#define ENERGY_REF_MAX_W 64

struct energy_ref_point { double pos[3], coef; };
struct energy_ref_line { double pos[3], dir[3], coef; };          /* dir is unit length */
struct energy_ref_torus { double center[3], axis[3], R, coef; };   /* axis is unit length */
struct energy_ref_curve { double b[3][3], coef; int nw; double w[ENERGY_REF_MAX_W]; };

struct energy_ref_camera {
    double eye[3], center[3], up[3];
    double size, nu;
    int width, height;
};

struct energy_ref_scene {
    int npoints, nlines, ntori, ncurves;
    struct energy_ref_point points[ENERGY_REF_MAX_PRIMS];
    struct energy_ref_line lines[ENERGY_REF_MAX_PRIMS];
    struct energy_ref_torus tori[ENERGY_REF_MAX_PRIMS];
    struct energy_ref_curve curves[ENERGY_REF_MAX_PRIMS];
    double epsilon, alpha, beta;
    int divisions;
    int no_attenuation; /* test flag, not a parameter: zeta(s) == 1 (digest §7 item 13) */
    struct energy_ref_camera cam;
};

/* ---- scene ---- */
/* Reads a parameter document (names of energy_wave_params). Missing scalars take the
 * thesis values (alpha = beta = 1, nu = 2, divisions = 200). Directions are normalised.
 * When "animate" is true each curve's W is multiplied by the looping eq. (5.1) weights
 * (energy_ref_loop_weights) at frame sim_time * anim_rate. Returns 0, or -1 with a message. */
int energy_ref_scene_from_json(const cJSON *doc, double sim_time, struct energy_ref_scene *sc, char *msg,
                               size_t msg_len);
/* Texel (i, j), column i left to right, row j top to bottom: ray start S and end E. */
void energy_ref_texel_ray(const struct energy_ref_scene *sc, int i, int j, double S[3], double E[3]);

/* ---- field ---- */
double energy_ref_point_dist(const struct energy_ref_point *p, const double P[3]);
double energy_ref_line_dist(const struct energy_ref_line *l, const double P[3]);
double energy_ref_torus_dist(const struct energy_ref_torus *t, const double P[3]);
/* Curve term S_adj(t*) / max(eps, L(P, curve)). */
double energy_ref_curve_term(const struct energy_ref_curve *c, double eps, const double P[3]);
double energy_ref_psi(const struct energy_ref_scene *sc, const double P[3]);
double energy_ref_zeta(const struct energy_ref_scene *sc, double s);

/* ---- cubic and nearest point ---- */
/* Real roots of x^3 + a x^2 + b x + c, ascending; returns their number (1..3; a double
 * root may appear twice). Digest §2.2 recommended solver, one Newton polish per root. */
int energy_ref_cubic(double a, double b, double c, double roots[3]);
void energy_ref_curve_eval(const double b[3][3], double t, double out[3]);
/* Distance from P to the Bezier b[0..2] and the parameter t* of the nearest point. */
double energy_ref_curve_nearest(const double b[3][3], const double P[3], double *t);
/* Same by sampling `samples` parameters and refining the best by golden section. */
double energy_ref_curve_nearest_brute(const double b[3][3], const double P[3], int samples, double *t);

/* ---- B-spline strength (digest §2.3) ---- */
int energy_ref_knots(int nw, double *U); /* writes nw + 3 knots (3.26), returns nw + 3 */
double energy_ref_bspline_basis(int nw, int i, double t); /* N_i^2(t), end span closed */
double energy_ref_bspline(int nw, const double *w, double t);
/* Eq. (5.1) weights at animation frame `frame` (digest §4). */
void energy_ref_anim_weights(double frame, int n, double *w);
/* The stream's looping animation: pulses started at every multiple m of P = 7n + 10 frames
 * (m <= frame), summed per weight and clamped at 1. */
void energy_ref_loop_weights(double frame, int n, double *w);

/* ---- integrals ---- */
typedef double (*energy_ref_fn)(double s, void *ctx);
/* Composite Simpson (3.33) on [a, b] with n (even) divisions, n + 1 samples. */
double energy_ref_simpson(energy_ref_fn f, void *ctx, double a, double b, int n);
/* Adaptive Gauss-Kronrod 7/15 on [a, b] to relative tolerance rel. */
double energy_ref_adaptive(energy_ref_fn f, void *ctx, double a, double b, double rel);
double energy_ref_ray_simpson(const struct energy_ref_scene *sc, const double S[3], const double E[3], int n);
double energy_ref_ray_converged(const struct energy_ref_scene *sc, const double S[3], const double E[3]);
double energy_ref_texel_simpson(const struct energy_ref_scene *sc, int i, int j, int n);
double energy_ref_texel_converged(const struct energy_ref_scene *sc, int i, int j);

/* ---- closed forms (digest §2.1, §2.6) ---- */
/* U(t) = A t^2 + 2 B t + C = |S + t(E-S) - M|^2 (2.11)-(2.13). */
void energy_ref_point_quad(const double M[3], const double S[3], const double E[3], double q[3]);
/* V(t) = D t^2 + 2 E t + F, squared distance to the line (M, unit D), compact (2.14)-(2.16). */
void energy_ref_line_quad(const double M[3], const double D[3], const double S[3], const double E[3],
                          double q[3]);
/* Integral over [0,1] of 1/sqrt(A t^2 + 2 B t + C) (corrected (2.8)). */
double energy_ref_abe_integral(double A, double B, double C);
/* Integral over [0,1] of alpha / ((s + beta)^2 sqrt(A s^2 + 2 B s + C)) (digest §2.6). */
double energy_ref_zeta_integral(double A, double B, double C, double alpha, double beta);

#endif
