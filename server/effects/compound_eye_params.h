/* compound_eye_params.h — the compound eye's typed parameters (struct compound_eye_config):
 * what params_load makes of a document by compound_eye_params (compound_eye.c), and all the
 * effect reads. A member is the parameter of the same name (params.h PARAM_AT), so a name
 * exists once; params_table_check proves the table and the struct agree. */
#ifndef FX_COMPOUND_EYE_PARAMS_H
#define FX_COMPOUND_EYE_PARAMS_H

enum eye_mode { EYE_MODE_LUT, EYE_MODE_BAKE };
enum eye_normal { EYE_NORMAL_OBJECT, EYE_NORMAL_LENS };

struct compound_eye_config {
    int mode, lattice; /* enum eye_mode; EYE_SQUARE | EYE_HEX */
    double density, lens_radius, refractive_index, pigment_depth;
    int max_passes, sphere_search, slice_steps, neighbor_select, tir_policy; /* EYE_SEARCH_*, EYE_SELECT_*, EYE_TIR_* */
    double dot_radius, dot_softness, dot_color[3], base_color[3], ring_inner, ring_outer, ring_color[3];
    double glow_radius, glow_color[3];
    int pigment_res, lut_cells, lut_dirs, lut_supersample;
    double ka, kd, ks, shininess;
    int shading_normal, model, bake_size; /* enum eye_normal; an index in eye_model_names */
    double eye[3], light[3];
    int compression; /* enum exr_codec */
    double fps;
};

#endif
