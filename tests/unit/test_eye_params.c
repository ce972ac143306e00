/* test_eye_params.c — the compound eye's parameter validation (table and cross-parameter
 * rules through effect_params, the one path create/set/config share), model names
 * (built-ins, assets-directory OBJ files, traversal attempts), the OBJ reader's limits and
 * errors, and the UV-space geometry atlas. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "check.h"
#include "effect.h"
#include "effects/compound_eye.h"
#include "effects/eye_model.h"

static const struct effect_ops *tep_fx;

/* Expects `partial` to be rejected as bad_param naming `param`. */
static void tep_reject(const char *partial, const char *param)
{
    struct fx_err err = {0};
    cJSON *p = cJSON_Parse(partial);
    cJSON *doc = effect_params(tep_fx, NULL, p, &err);
    CHECK(doc == NULL, "%s was accepted", partial);
    CHECK(!strcmp(err.code, "bad_param") && !strcmp(err.param, param), "%s: got %s (%s): %s", partial, err.code,
          err.param, err.message);
    cJSON_Delete(doc);
    cJSON_Delete(p);
}

static void tep_accept(const char *partial)
{
    struct fx_err err = {0};
    cJSON *p = cJSON_Parse(partial);
    cJSON *doc = effect_params(tep_fx, NULL, p, &err);
    CHECK(doc != NULL, "%s rejected: %s", partial, err.message);
    cJSON_Delete(doc);
    cJSON_Delete(p);
}

static void test_table(void)
{
    tep_accept("{}");
    tep_reject("{\"lattice\":\"triangle\"}", "lattice");
    tep_reject("{\"mode\":\"stream\"}", "mode");
    tep_reject("{\"lens_radius\":5}", "lens_radius");
    tep_reject("{\"refractive_index\":2.0}", "refractive_index");
    tep_reject("{\"max_passes\":2.5}", "max_passes");
    tep_reject("{\"lut_cells\":128}", "lut_cells");
    tep_reject("{\"light\":[0,0,0]}", "light");
    tep_reject("{\"tir_policy\":\"ignore\"}", "tir_policy");
}

static void test_cross_rules(void)
{
    tep_reject("{\"lens_radius\":0.6,\"lattice\":\"square\"}", "lens_radius"); /* gaps on the square lattice */
    tep_accept("{\"lens_radius\":0.6,\"lattice\":\"hex\"}");
    tep_reject("{\"ring_inner\":0.3,\"ring_outer\":0.2}", "ring_inner");
}

static void tep_write(const char *path, const char *text)
{
    FILE *f = fopen(path, "w");
    CHECK(f != NULL, "cannot write %s", path);
    if (f) fputs(text, f), fclose(f);
}

static void test_model_names(void)
{
    char dir[] = "/tmp/fxs-eye-assetsXXXXXX", path[256];
    CHECK(mkdtemp(dir) != NULL, "mkdtemp");
    snprintf(path, sizeof path, "%s/wing-2.obj", dir);
    tep_write(path, "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n");
    snprintf(path, sizeof path, "%s/broken.obj", dir);
    tep_write(path, "v 0 0 0\nv 1 0 0\nv 1 1 nope\nf 1/1 2/2 3/3\n");
    snprintf(path, sizeof path, "%s/bad name.obj", dir);
    tep_write(path, "v 0 0 0\n");
    struct fx_err err = {0};
    CHECK(eye_models_set_dir("/nonexistent/fxs", &err) == -1 && !strcmp(err.param, "assets_dir"), "missing dir refused");
    CHECK(eye_models_set_dir(dir, &err) == 0, "set dir: %s", err.message);
    int found = 0, spaced = 0;
    for (int i = 0; eye_model_names[i]; i++) {
        found += !strcmp(eye_model_names[i], "wing-2") || !strcmp(eye_model_names[i], "broken");
        spaced += strchr(eye_model_names[i], ' ') != NULL;
    }
    CHECK(found == 2 && spaced == 0, "offered models: %d found, %d with a space", found, spaced);
    tep_accept("{\"model\":\"wing-2\",\"mode\":\"bake\"}");
    tep_accept("{\"model\":\"insect_eye\"}");
    tep_reject("{\"model\":\"broken\"}", "model");
    tep_reject("{\"model\":\"../../etc/passwd\"}", "model");
    tep_reject("{\"model\":\"/etc/passwd\"}", "model");
    tep_reject("{\"model\":\"bad name\"}", "model");
    tep_reject("{\"model\":\"missing\"}", "model");
    struct eye_mesh m;
    CHECK(eye_model_load("../wing-2", &m, &err) == -1 && strstr(err.message, "[A-Za-z0-9_-]"), "loader re-checks names");
    CHECK(eye_model_load("wing-2", &m, &err) == 0 && m.ntri == 2, "quad -> 2 triangles (%d)", m.ntri);
    eye_mesh_free(&m);
    CHECK(eye_model_load("broken", &m, &err) == -1 && strstr(err.message, "broken.obj line 3"), "error names the line: %s",
          err.message);
    remove(path);
    snprintf(path, sizeof path, "%s/wing-2.obj", dir);
    remove(path);
    snprintf(path, sizeof path, "%s/broken.obj", dir);
    remove(path);
    rmdir(dir);
    eye_models_set_dir("", &err);
}

static void test_obj_errors(void)
{
    struct eye_mesh m;
    struct fx_err err = {0};
    static const struct { const char *text, *needle; } bad[] = {
        {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "texture coordinates"},
        {"v 0 0 0\nvt 0 0\nf 1/1 2/1 3/1\n", "line 3"},
        {"v 0 0 0\nvt 0 0\nf 1/1 1/1\n", "fewer than 3"},
        {"vt 0\n", "\"vt\" needs 2"},
        {"# nothing\n", "no faces"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        int rc = eye_obj_parse(bad[i].text, strlen(bad[i].text), "t.obj", &m, &err);
        CHECK(rc == -1 && strstr(err.message, bad[i].needle), "case %zu: %s", i, err.message);
    }
    const char *neg = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\nf -3/-3/1 -2/-2/1 -1/-1/1\n";
    CHECK(eye_obj_parse(neg, strlen(neg), "t.obj", &m, &err) == 0 && m.ntri == 1, "negative indices: %s", err.message);
    eye_mesh_free(&m);
}

/* The plane's atlas covers every texel; its positions follow the UV layout. */
static void test_atlas(void)
{
    struct eye_mesh m;
    struct fx_err err = {0};
    CHECK(eye_model_load("plane", &m, &err) == 0, "plane: %s", err.message);
    const int S = 64;
    float *geo = malloc((size_t)S * S * 16 * sizeof(float));
    eye_model_atlas(&m, S, geo);
    int covered = 0;
    for (int i = 0; i < S * S; i++) covered += geo[16 * i + 11] == 1.0f;
    CHECK(covered == S * S, "%d of %d texels covered", covered, S * S);
    const float *g = geo + 16 * (0 * S + S - 1); /* top-right texel: u ~ 1, v ~ 1 -> (1, 1, 0) */
    CHECK_NEAR(g[0], 1.0 - 1.0 / S, 1e-5);
    CHECK_NEAR(g[1], 1.0 - 1.0 / S, 1e-5);
    CHECK_NEAR(g[6], 1.0, 1e-6);
    CHECK_NEAR(g[8], 2.0, 1e-5); /* dP/du: 2 world units per UV unit */
    free(geo);
    eye_mesh_free(&m);
    CHECK(eye_model_load("hemisphere", &m, &err) == 0 && m.ntri > 1000, "hemisphere: %d triangles", m.ntri);
    eye_mesh_free(&m);
}

int main(void)
{
    tep_fx = effect_find("compound_eye");
    if (!tep_fx) return CHECK_ABORT("effect compound_eye not registered");
    RUN(test_table);
    RUN(test_cross_rules);
    RUN(test_model_names);
    RUN(test_obj_errors);
    RUN(test_atlas);
    return CHECK_DONE();
}
