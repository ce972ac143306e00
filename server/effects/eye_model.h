/* eye_model.h — the models the compound eye bakes onto (digest §8.2): a few built-in
 * meshes generated in code and OBJ files from the configured assets directory.
 *
 * A model is chosen by NAME only, never by a client path: names are [A-Za-z0-9_-]{1,64};
 * the assets directory (config key `assets_dir`) is scanned once at start-up (compound_eye's
 * init, called by effects_init with the daemon's effect_env), and the
 * `model` parameter's choices are the built-in names followed by the stems of the
 * directory's *.obj files. Loading re-checks the name and bounds the file and its
 * counts. A model becomes a UV-space geometry atlas for the bake kernel: per texel the
 * world position, face normal and the thesis's texture-axis vectors D_u, D_v (eqs.
 * 5.2-5.15, per UV unit: the kernel applies the density R_t of eq. 5.1). */
#ifndef FX_EYE_MODEL_H
#define FX_EYE_MODEL_H

#include <stddef.h>

#include "err.h"

#define EYE_MODEL_MAX 64            /* built-ins + OBJ files offered */
#define EYE_MODEL_NAME_MAX 64
#define EYE_OBJ_MAX_BYTES (16 << 20)
#define EYE_OBJ_MAX_VERTICES 1000000 /* each of v and vt */
#define EYE_OBJ_MAX_TRIANGLES 1000000

/* The `model` parameter's choices, NULL-terminated; mutated only by eye_models_set_dir
 * (start-up, before any thread). */
extern const char *eye_model_names[EYE_MODEL_MAX + 1];

/* Sets the assets directory and rescans it ("" = none). Fails when it is not a directory. */
int eye_models_set_dir(const char *dir, struct fx_err *err);

/* 1 when name matches [A-Za-z0-9_-]{1,64}. */
int eye_model_name_ok(const char *name);

/* Triangles, expanded: pos 9 floats and uv 6 floats per triangle. */
struct eye_mesh {
    int ntri;
    float *pos, *uv;
};

/* Loads a built-in or OBJ model (errors name the file and line). */
int eye_model_load(const char *name, struct eye_mesh *m, struct fx_err *err);
/* Parses OBJ text (triangles and convex polygons with texture coordinates). */
int eye_obj_parse(const char *text, size_t len, const char *what, struct eye_mesh *m, struct fx_err *err);
void eye_mesh_free(struct eye_mesh *m);

/* Loads the model once per (name, file size, mtime) to report a bad file at `set` time;
 * param: the parameter name for the error. */
int eye_model_check(const char *name, struct fx_err *err);

/* The thesis's per-triangle frame (eqs. 5.4-5.15): P = Pc + a*Du + b*Dv for texture
 * coordinate (a, b). Returns -1 when the UVs are degenerate (|det| tiny). */
int eye_uv_frame(const float P[9], const float T[6], double Pc[3], double Du[3], double Dv[3]);

/* Rasterises the mesh into a size x size geometry atlas, 16 floats per texel:
 * (P, u), (N_face, v), (Du, mask), (Dv, 0). Texel (x, y) has its centre at
 * uv = ((x+0.5)/size, 1-(y+0.5)/size) (row 0 is v = 1); uncovered texels next to covered
 * ones (2 rings) copy their neighbour with mask 1, so seams filter cleanly. */
void eye_model_atlas(const struct eye_mesh *m, int size, float *geo);

#endif
