/* flame_ref.h — double-precision C reference for the flame effect (seed 002, Mabuchi 2012,
 * digest digests/002-flame-sph.md), used only by tests and benches.
 *
 * Everything is brute force and literal so that it can be read against the digest: the
 * Müller-2003 kernels (§2.3, with the corrected spiky-gradient sign of §9 #1), an O(N²)
 * neighbour search, density (3.10), pressure (3.11), the pressure force in the difference
 * form of eq 3.12 (sign-fixed, §2.5) and in Müller's symmetric form, viscosity (3.13),
 * heat and fuel diffusion (3.20, 3.21) literal or stabilised (§9 #4), chemistry
 * (3.17-3.19 with the fuel_eps flame test of §9 #12), buoyancy (3.16), wind (§9 #15: a uniform
 * acceleration, and §2.14's drag toward a wind velocity across `up`) and
 * one symplectic Euler step of Algorithm 3.2 (§2.9, §2.10) for gas, sources and obstacles.
 *
 * It is written independently of server/effects/flame.c and kernels/flame.cl on purpose:
 * the two must agree only because both follow the digest. */
#ifndef FX_FLAME_REF_H
#define FX_FLAME_REF_H

#include <cjson/cJSON.h>

enum flame_ref_type { FLAME_REF_GAS = 0, FLAME_REF_SOURCE = 1, FLAME_REF_OBSTACLE = 2 };

struct flame_ref_params {
    double dt, h, d, mass;           /* d = particle diameter in metres */
    double k_stiff, k_visc, rho_rest;
    int symmetric_pressure;          /* 0: difference form (3.12), 1: Müller symmetric */
    double k_buo, up[3], gravity[3], wind[3];
    double wind_velocity[3], wind_drag; /* §2.14 drag model; wind_drag [1/s], 0: none */
    double T_amb, T_ign, k_rs, k_cf, k_pt, k_h, k_f;
    int stabilized;                  /* 0: literal diffusion, 1: §9 #4 convex weights */
    double omega_max, k_cool, fuel_eps;
    int resample_interval, insert_nbr_threshold;
    /* Not in the digest: also scale the viscous force when its explicit number
     * dt k_visc Σ(m/ρ_j)∇²W / ρ_i exceeds omega_max (stabilised mode only). 0 by default;
     * the device tests set it to mirror server/effects/flame.c's documented choice. */
    int cap_viscosity;
};

struct flame_ref_particle {
    double r[3], v[3], T, F;
    int type; /* enum flame_ref_type */
};

/* One SPH evaluation of particle i (everything the device reads back after flame_eval). */
struct flame_ref_eval {
    double rho, p;
    double f_press[3], f_visc[3]; /* force densities */
    double dT_diff, dF_diff;      /* diffusion parts of dT/dt, dF/dt */
    double dT_react, dF_react;    /* reaction parts (0 unless a flame particle) */
    double dT, dF;                /* totals: reaction + diffusion (cooling is applied in integrate) */
    double n[3];                  /* Müller colour-field normal, Σ (m/ρ) ∇W_poly6(r_i - r_j) */
    int nbr, flame_nbr;           /* j != i with |r_ij| <= h, and flame ones among them */
    int is_flame;
};

/* Table 3.1 values plus the digest's proposals (§3, §10). */
void flame_ref_defaults(struct flame_ref_params *p);
/* Reads a complete flame parameter document (names of flame_params); missing entries
 * keep their current value in p; mass <= 0 means derived (§9 #6). Returns the number of
 * parameters read. */
int flame_ref_params_from_json(const cJSON *doc, struct flame_ref_params *p);

/* §9 #6: the mass giving rho_rest on a cubic lattice of spacing d (poly6, self included). */
double flame_ref_lattice_mass(double h, double d, double rho_rest);

/* Kernels (digest §2.3); all vanish for r >= h. x is the argument vector. */
double flame_ref_w_poly6(double r, double h);
double flame_ref_w_spiky(double r, double h);
double flame_ref_w_visc(double r, double h);
void flame_ref_grad_poly6(const double x[3], double h, double out[3]);
void flame_ref_grad_spiky(const double x[3], double h, double out[3]); /* -45/(πh^6)(h-r)² x/r */
double flame_ref_lap_visc(double r, double h);                          /* 45/(πh^6)(h-r) */

double flame_ref_dist(const double a[3], const double b[3]);
int flame_ref_is_flame(const struct flame_ref_params *p, double T, double F);
int flame_ref_is_solid(int type);

/* Brute-force neighbours j != i of particle i with |r_ij| <= h (indices into idx, up to
 * max). Returns the count (which may exceed max). */
int flame_ref_neighbours(const struct flame_ref_params *p, const struct flame_ref_particle *ps, int n, int i,
                         int *idx, int max);

/* Density (3.10) of every particle, into rho[n]. */
void flame_ref_density(const struct flame_ref_params *p, const struct flame_ref_particle *ps, int n, double *rho);
/* Full evaluation of every particle (density, pressure, forces, derivatives, counts). */
void flame_ref_eval_all(const struct flame_ref_params *p, const struct flame_ref_particle *ps, int n,
                        struct flame_ref_eval *out);

/* Reaction rate S (3.17), 0 for a non-flame particle. */
double flame_ref_reaction(const struct flame_ref_params *p, double T, double F);
/* Buoyancy force density (3.16) for temperature T, into f (adds). */
void flame_ref_buoyancy(const struct flame_ref_params *p, double T, double f[3]);

/* Drag toward the air (§2.14 [P], f = ρ k_drag (v_wind − v)) on a gas velocity v, across up
 * only: the part of v − wind_velocity normal to up decays by exp(−wind_drag dt), the exact
 * solution over one step; the part along up is untouched. */
void flame_ref_drag(const struct flame_ref_params *p, double v[3]);

/* Integrates one particle from its evaluation e (reaction/diffusion, buoyancy with the
 * updated T, wind, gravity, then the drag; symplectic Euler; sources fixed; obstacles
 * r += dt v). */
void flame_ref_integrate(const struct flame_ref_params *p, const struct flame_ref_eval *e,
                         struct flame_ref_particle *q);
/* One step of Algorithm 3.2 without resampling: eval_all then integrate every particle.
 * ev may be NULL (then allocated internally); returns 0, or -1 when out of memory. */
int flame_ref_step(const struct flame_ref_params *p, struct flame_ref_particle *ps, int n,
                   struct flame_ref_eval *ev);

/* Logistic solution of the isolated-particle chemistry (§2.7) at time t. */
double flame_ref_logistic_T(const struct flame_ref_params *p, double T0, double F0, double t);

#endif
