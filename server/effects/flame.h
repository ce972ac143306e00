/* flame.h — the simulation of effect `flame` (seed 002, Mabuchi 2012): the SPH flame, every
 * step on the OpenCL device.
 *
 * The effect_ops that stream it (flame_effect) are flame_effect.h's; the parameters
 * flame_params.h's. The direct API lets tests and benches load arbitrary particle sets
 * (lattices, isolated particles), evaluate one SPH pass without integrating, run steps, and
 * read the state back to compare with the double-precision C reference (tests/ref/flame_ref.c). */
#ifndef FX_FLAME_H
#define FX_FLAME_H

#include <stdbool.h>
#include <stdint.h>

#include "../effect.h"
#include "flame_layout.h" /* kernels/: FP_* indices, FL_* flags */
#include "flame_params.h"

struct ocl;
struct flame;

/* Particle flags (bits of flame_particles.flags, and of the codec's flag byte). */
enum flame_flag {
    FLAME_GAS = FL_GAS,            /* type in bits 0-1 */
    FLAME_SOURCE = FL_SOURCE,      /* burning solid: fixed, holds T_init/F_init (digest §2.13) */
    FLAME_OBSTACLE = FL_OBSTACLE,  /* non-burning solid moved kinematically (digest §9 #16) */
    FLAME_TYPE_MASK = FL_TYPE,
    FLAME_IS_FLAME = FL_FLAME,     /* T > T_ign and F > fuel_eps (digest §9 #12) */
};

/* Host copy of the particle state, structure of arrays, n particles. */
struct flame_particles {
    int n;
    float *pos;        /* 4n: x, y, z, T */
    float *vel;        /* 4n: vx, vy, vz, F */
    uint32_t *flags;   /* n */
    uint32_t *id;      /* n, stable across sorting; new particles get fresh ids */
    /* Filled by flame_read after a step or flame_eval (ignored by flame_load): */
    float *rho;        /* n */
    float *pressure;   /* n */
    float *force;      /* 4n: force density xyz, w unused */
    float *dT, *dF;    /* n: total time derivatives (reaction + diffusion) */
    uint16_t *nbr;     /* n: neighbours j != i within h */
    uint16_t *flame_nbr; /* n: flame particles among them */
};

/* Allocates every array of p for n particles (zeroed). */
int flame_particles_alloc(struct flame_particles *p, int n);
void flame_particles_free(struct flame_particles *p);

/* A simulation with the parameters c (params_load of a complete validated document); it
 * starts with the scene's solids. flame_set changes them live (the caller keeps c). */
struct flame *flame_new(struct ocl *ocl, const struct flame_config *c, struct fx_err *err);
int flame_set(struct flame *fl, const struct flame_config *c, struct fx_err *err);
/* Replaces the particles with p (pos, vel, flags, id), e.g. a test lattice. */
int flame_load(struct flame *fl, const struct flame_particles *p, struct fx_err *err);
/* Neighbour search, density, pressure, forces and derivatives for the current state,
 * without integrating or resampling, so flame_read shows one SPH evaluation. */
int flame_eval(struct flame *fl, struct fx_err *err);
/* Advances `steps` time steps of dt (Algorithm 3.2 with resampling every interval). */
int flame_run(struct flame *fl, int steps, struct fx_err *err);
/* Reads the whole state back (allocates out; free with flame_particles_free). */
int flame_read(struct flame *fl, struct flame_particles *out, struct fx_err *err);
int flame_count(const struct flame *fl);
/* How a step sorts and compacts: wide (one work item per element: a counting sort and device
 * scans, for GPUs) or in FL_BLOCKS serial blocks (CPU devices). Both give the same state bit
 * for bit; flame_new picks by the device, tests and benches may switch between steps. */
void flame_set_wide(struct flame *fl, bool wide);
uint64_t flame_steps(const struct flame *fl); /* steps since creation or reset */
double flame_sim_seconds(const struct flame *fl); /* simulated seconds since creation or reset */
void flame_free(struct flame *fl);

/* Substeps as the effect paces them (flame_effect.c, frame_plan.h). flame_substep runs one
 * (the device may still work on it; no error-flag read); flame_substep_begin enqueues one and
 * flame_substep_end completes it (a resampling step's totals), so the host can work meanwhile;
 * flame_substep_syncs: the next substep waits for the device (a resampling step). flame_finish
 * drains the queue. */
int flame_substep(struct flame *fl, struct fx_err *err);
int flame_substep_begin(struct flame *fl, struct fx_err *err);
int flame_substep_end(struct flame *fl, struct fx_err *err);
bool flame_substep_syncs(const struct flame *fl);
int flame_finish(struct flame *fl, struct fx_err *err);
/* Back to the scene's solids at time 0 (the protocol's reset). */
int flame_reset(struct flame *fl, struct fx_err *err);
/* Reads a frame's particles (flame_count of them: pos and vel 4 floats each, flags and the stable
 * id one each) and checks the error flag: the count, or -1 with err (a runaway included). */
int flame_read_frame(struct flame *fl, float *pos, float *vel, uint32_t *flags, uint32_t *id, struct fx_err *err);

#endif
