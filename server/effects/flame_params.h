/* flame_params.h — the flame's parameters: the table (flame_params), its typed struct
 * (struct flame_config, what the simulation is handed) and their packing into the kernels'
 * parameter array (FP_* of flame_layout.h).
 *
 * A member of struct flame_config is a parameter of the same name (params.h PARAM_AT), so a
 * name exists once; params_table_check proves the table and the struct agree. */
#ifndef FX_FLAME_PARAMS_H
#define FX_FLAME_PARAMS_H

#include <stdbool.h>

#include "../effect.h"
#include "flame_layout.h" /* kernels/: FP_* indices */

#define FLAME_MAX_SOLIDS 16 /* sources, and obstacles */
#define FLAME_VMAX 200.0    /* |v| beyond this (m/s) is a runaway */

#ifndef FL_CELLS_PER_H
/* Cells of edge 2h: a particle sets up 4 rows, not 9 (cells of h) or 25 (h/2). The row set-up,
 * not the candidates, is most of fl_density's time on the sparse default flame (~8 neighbours),
 * so cells of 2h make the density pass about 1.5x faster there, and the dense lattice blocks
 * of bench_flame faster too; cells of 2.5h or 3h gain nothing more (docs/performance-log.md). */
#define FL_CELLS_PER_H 0.5
#endif
/* Cells along x per cell of the other axes (flame.cl's FP_INV_CELLX). */
#ifndef FL_XCELLS
#define FL_XCELLS 4
#endif

enum flame_obstacle_shape { FLAME_PLATE, FLAME_BOX };
enum flame_pressure_form { FLAME_PRESSURE_DIFFERENCE, FLAME_PRESSURE_SYMMETRIC };
enum flame_diffusion_mode { FLAME_DIFFUSION_STABILIZED, FLAME_DIFFUSION_LITERAL };

/* A burning disc (item of `sources`). */
struct flame_source {
    double center[3], radius, T_init, F_init;
    bool enabled;
};

/* A solid that does not burn (item of `obstacles`). */
struct flame_obstacle {
    int shape; /* enum flame_obstacle_shape */
    double size[3], pos[3], velocity[3];
};

/* Every parameter of the flame, typed (params_load); the table in flame_params.c says each
 * one's range, default and meaning. */
struct flame_config {
    struct flame_source sources[FLAME_MAX_SOLIDS];
    int n_sources;
    struct flame_obstacle obstacles[FLAME_MAX_SOLIDS];
    int n_obstacles;
    double wind_accel[3], wind_velocity[3], wind_drag, k_buo, up[3], k_stiff, k_viscosity, rho_rest;
    int pressure_form; /* enum flame_pressure_form */
    double T_amb, T_ign, k_rs, k_cf, k_pt, k_h, k_f;
    int diffusion_mode; /* enum flame_diffusion_mode */
    double omega_max, k_cool, fuel_eps;
    int resample_interval, insert_nbr_threshold;
    double h, particle_diameter, mass, dt;
    int max_substeps, max_particles, seed;
    double fps, time_scale, space_scale;
    int pos_bits;
    bool velocities;
    int vel_bits;
};

extern const struct param_def flame_params[]; /* {0}-terminated */
extern const struct effect_preset flame_presets[]; /* {0}-terminated */

/* The kernels' parameter array of c: the table's slotted values as they are, and what derives
 * from them (kernel constants of h and the mass, the unit up vector, the drag over one step). */
void flame_params_pack(const struct flame_config *c, float P[FP_COUNT]);

/* c's up vector, normalised. */
void flame_params_up(const struct flame_config *c, double up[3]);

#endif
