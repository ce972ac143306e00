/* energy_wave_params.h — the energy wave's typed parameters (struct energy_wave_config): what
 * params_load makes of a document by energy_wave_params (energy_wave.c), and what the effect,
 * its sources (wave_sources.c) and its light rig (light_rig.c) read.
 *
 * A member is the parameter of the same name (params.h PARAM_AT), so a name exists once;
 * params_table_check proves the table and the struct agree. A header of its own so that the
 * sources and the rig read it without including the effect. */
#ifndef FX_ENERGY_WAVE_PARAMS_H
#define FX_ENERGY_WAVE_PARAMS_H

#include <stdbool.h>

#include "fxs_rig.h" /* FXS_RIG_MAX_BANDS */

#define WAVE_MAX_SRC 16 /* sources of each type */
#define WAVE_MAX_W 32   /* strength weights per curve */

enum ew_mode { EW_MODE_SIMPSON, EW_MODE_ADAPTIVE };
enum ew_output { EW_OUTPUT_Y, EW_OUTPUT_RGBA };

struct energy_wave_point {
    double pos[3], coef;
};

struct energy_wave_line {
    double pos[3], dir[3], coef;
};

struct energy_wave_torus {
    double center[3], axis[3], R, coef;
};

struct energy_wave_curve {
    double p0[3], p1[3], p2[3], coef, W[WAVE_MAX_W];
    int n_W;
};

struct energy_wave_band {
    double m_min, color[3];
};

struct energy_wave_config {
    struct energy_wave_point points[WAVE_MAX_SRC];
    int n_points;
    struct energy_wave_line lines[WAVE_MAX_SRC];
    int n_lines;
    struct energy_wave_torus tori[WAVE_MAX_SRC];
    int n_tori;
    struct energy_wave_curve curves[WAVE_MAX_SRC];
    int n_curves;
    double epsilon, alpha, beta;
    int divisions, mode; /* mode: enum ew_mode */
    double eye[3], center[3], up[3], size;
    int width, height;
    double nu, fps;
    int compression, output; /* enum exr_codec, enum ew_output */
    double color_energy[3], color_background[3];
    bool animate;
    double anim_rate;
    bool light_rig;
    int curve_segments, torus_segments;
    double light_strength;
    struct energy_wave_band ramp[FXS_RIG_MAX_BANDS];
    int n_ramp;
    bool features, outline;
    double outline_width, outline_color[3];
    bool shadow;
    double shadow_theta, shadow_color[3], shadow_opacity, shadow_plane_point[3], shadow_plane_normal[3];
};

#endif
