/* eye_model.c — see eye_model.h. */
#include "eye_model.h"

#include <ctype.h>
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#define EYE_PI 3.14159265358979323846
#define EYE_RINGS 32    /* built-in meshes: latitude rings of the front half */
#define EYE_SEGMENTS 64 /* and longitude segments */
#define EYE_FACE_MAX 64 /* vertices of one OBJ polygon */

static const char *const eye_builtin[] = {"hemisphere", "insect_eye", "plane", NULL};
const char *eye_model_names[EYE_MODEL_MAX + 1] = {"hemisphere", "insect_eye", "plane", NULL};
static char eye_assets_dir[4096];
static char eye_obj_names[EYE_MODEL_MAX][EYE_MODEL_NAME_MAX + 1];

int eye_model_name_ok(const char *name)
{
    size_t n = strlen(name);
    if (n == 0 || n > EYE_MODEL_NAME_MAX) return 0;
    for (size_t i = 0; i < n; i++)
        if (!isalnum((unsigned char)name[i]) && name[i] != '_' && name[i] != '-') return 0;
    return 1;
}

static int eye_is_builtin(const char *name)
{
    for (int i = 0; eye_builtin[i]; i++)
        if (!strcmp(eye_builtin[i], name)) return i;
    return -1;
}

static int eye_name_cmp(const void *a, const void *b) { return strcmp(a, b); }

int eye_models_set_dir(const char *dir, struct fx_err *err)
{
    int nb = 0, no = 0;
    while (eye_builtin[nb]) eye_model_names[nb] = eye_builtin[nb], nb++;
    eye_model_names[nb] = NULL;
    eye_assets_dir[0] = 0;
    if (!dir || !dir[0]) return 0;
    if (strlen(dir) >= sizeof eye_assets_dir) return fx_fail(err, "bad_request", "assets_dir", "assets_dir is too long");
    DIR *d = opendir(dir);
    if (!d) return fx_fail(err, "bad_request", "assets_dir", "assets_dir %s: %s", dir, strerror(errno));
    snprintf(eye_assets_dir, sizeof eye_assets_dir, "%s", dir);
    for (struct dirent *e; (e = readdir(d)) && nb + no < EYE_MODEL_MAX;) {
        size_t n = strlen(e->d_name);
        if (n <= 4 || strcmp(e->d_name + n - 4, ".obj")) continue;
        char stem[EYE_MODEL_NAME_MAX + 1];
        if (n - 4 > EYE_MODEL_NAME_MAX) continue;
        memcpy(stem, e->d_name, n - 4);
        stem[n - 4] = 0;
        char path[sizeof eye_assets_dir + 300];
        struct stat st;
        snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
        if (lstat(path, &st) || !S_ISREG(st.st_mode)) continue; /* links and the rest are not models */
        if (eye_model_name_ok(stem) && eye_is_builtin(stem) < 0) memcpy(eye_obj_names[no++], stem, n - 3);
    }
    closedir(d);
    qsort(eye_obj_names, (size_t)no, sizeof eye_obj_names[0], eye_name_cmp);
    for (int i = 0; i < no; i++) eye_model_names[nb + i] = eye_obj_names[i];
    eye_model_names[nb + no] = NULL;
    return 0;
}

void eye_mesh_free(struct eye_mesh *m)
{
    free(m->pos);
    free(m->uv);
    m->pos = m->uv = NULL;
    m->ntri = 0;
}

static int eye_mesh_alloc(struct eye_mesh *m, int ntri, struct fx_err *err)
{
    m->ntri = 0;
    m->pos = malloc((size_t)ntri * 9 * sizeof(float));
    m->uv = malloc((size_t)ntri * 6 * sizeof(float));
    if (!m->pos || !m->uv) {
        eye_mesh_free(m);
        return fx_fail(err, "internal", "model", "out of memory for %d triangles", ntri);
    }
    return 0;
}

static void eye_mesh_add(struct eye_mesh *m, const float p[3][3], const float t[3][2])
{
    memcpy(m->pos + 9 * m->ntri, p, 9 * sizeof(float));
    memcpy(m->uv + 6 * m->ntri, t, 6 * sizeof(float));
    m->ntri++;
}

/* ---- built-in models ------------------------------------------------------------- */

/* Front half (z >= 0) of an ellipsoid with semi-axes ax; texture coordinates are the
 * stereographic projection of the unit-sphere direction from the south pole, which is
 * conformal on the sphere (digest G19 asks for conformal UVs). */
static void eye_ellipsoid_vertex(const double ax[3], int ring, int seg, float p[3], float t[2])
{
    double th = 0.5 * EYE_PI * ring / EYE_RINGS, ph = 2.0 * EYE_PI * seg / EYE_SEGMENTS;
    double s[3] = {sin(th) * cos(ph), sin(th) * sin(ph), cos(th)};
    for (int k = 0; k < 3; k++) p[k] = (float)(ax[k] * s[k]);
    t[0] = (float)(0.5 + 0.5 * s[0] / (1.0 + s[2]));
    t[1] = (float)(0.5 + 0.5 * s[1] / (1.0 + s[2]));
}

static int eye_builtin_ellipsoid(const double ax[3], struct eye_mesh *m, struct fx_err *err)
{
    if (eye_mesh_alloc(m, EYE_RINGS * EYE_SEGMENTS * 2, err)) return -1;
    for (int r = 0; r < EYE_RINGS; r++)
        for (int s = 0; s < EYE_SEGMENTS; s++) {
            float p[4][3], t[4][2];
            eye_ellipsoid_vertex(ax, r, s, p[0], t[0]);
            eye_ellipsoid_vertex(ax, r + 1, s, p[1], t[1]);
            eye_ellipsoid_vertex(ax, r + 1, s + 1, p[2], t[2]);
            eye_ellipsoid_vertex(ax, r, s + 1, p[3], t[3]);
            float pa[3][3], ta[3][2], pb[3][3], tb[3][2];
            int ia[3] = {0, 1, 2}, ib[3] = {0, 2, 3};
            for (int k = 0; k < 3; k++) {
                memcpy(pa[k], p[ia[k]], sizeof pa[k]);
                memcpy(ta[k], t[ia[k]], sizeof ta[k]);
                memcpy(pb[k], p[ib[k]], sizeof pb[k]);
                memcpy(tb[k], t[ib[k]], sizeof tb[k]);
            }
            if (r > 0) eye_mesh_add(m, pb, tb); /* at the pole p[0] == p[3]: one triangle */
            eye_mesh_add(m, pa, ta);
        }
    return 0;
}

static int eye_builtin_plane(struct eye_mesh *m, struct fx_err *err)
{
    static const float p[2][3][3] = {{{-1, -1, 0}, {1, -1, 0}, {1, 1, 0}}, {{-1, -1, 0}, {1, 1, 0}, {-1, 1, 0}}};
    static const float t[2][3][2] = {{{0, 0}, {1, 0}, {1, 1}}, {{0, 0}, {1, 1}, {0, 1}}};
    if (eye_mesh_alloc(m, 2, err)) return -1;
    eye_mesh_add(m, p[0], t[0]);
    eye_mesh_add(m, p[1], t[1]);
    return 0;
}

/* ---- OBJ ------------------------------------------------------------------------- */

struct eye_obj {
    float *v, *vt;
    int nv, nvt, capv, capvt;
    struct eye_mesh *m;
    int captri;
};

static int eye_obj_push(float **arr, int *n, int *cap, int width, const float *x)
{
    if (*n == *cap) {
        int c = *cap ? 2 * *cap : 1024;
        float *p = realloc(*arr, (size_t)c * width * sizeof(float));
        if (!p) return -1;
        *arr = p;
        *cap = c;
    }
    memcpy(*arr + (size_t)*n * width, x, (size_t)width * sizeof(float));
    (*n)++;
    return 0;
}

/* Reads up to `want` finite floats from s; returns how many. */
static int eye_obj_floats(const char *s, float *out, int want)
{
    int k = 0;
    while (k < want) {
        char *end;
        double x = strtod(s, &end);
        if (end == s || !isfinite(x)) break;
        out[k++] = (float)x;
        s = end;
    }
    return k;
}

/* One face vertex "v/vt[/vn]" into 0-based indices; -1 on error. */
static int eye_obj_ref(const char *tok, const struct eye_obj *o, int *iv, int *ivt)
{
    char *end;
    long a = strtol(tok, &end, 10), b;
    if (end == tok || *end != '/') return -1;
    tok = end + 1;
    b = strtol(tok, &end, 10);
    if (end == tok || (*end && *end != '/')) return -1;
    a = a < 0 ? o->nv + a : a - 1;
    b = b < 0 ? o->nvt + b : b - 1;
    if (a < 0 || a >= o->nv || b < 0 || b >= o->nvt) return -1;
    *iv = (int)a;
    *ivt = (int)b;
    return 0;
}

static int eye_obj_face(struct eye_obj *o, char *rest, const char *what, int line, struct fx_err *err)
{
    int iv[EYE_FACE_MAX], ivt[EYE_FACE_MAX], n = 0;
    for (char *tok = strtok(rest, " \t\r"); tok; tok = strtok(NULL, " \t\r")) {
        if (n == EYE_FACE_MAX)
            return fx_fail(err, "bad_param", "model", "%s line %d: face with more than %d vertices", what, line, EYE_FACE_MAX);
        if (eye_obj_ref(tok, o, &iv[n], &ivt[n]))
            return fx_fail(err, "bad_param", "model",
                           "%s line %d: face vertex \"%.32s\" needs existing v/vt indices (texture coordinates are required)",
                           what, line, tok);
        n++;
    }
    if (n < 3) return fx_fail(err, "bad_param", "model", "%s line %d: face with fewer than 3 vertices", what, line);
    for (int k = 1; k + 1 < n; k++) { /* fan */
        if (o->m->ntri == EYE_OBJ_MAX_TRIANGLES)
            return fx_fail(err, "bad_param", "model", "%s: more than %d triangles", what, EYE_OBJ_MAX_TRIANGLES);
        if (o->m->ntri == o->captri) {
            int c = o->captri ? 2 * o->captri : 1024;
            float *p = realloc(o->m->pos, (size_t)c * 9 * sizeof(float)), *t = p ? realloc(o->m->uv, (size_t)c * 6 * sizeof(float)) : NULL;
            if (p) o->m->pos = p;
            if (!t) return fx_fail(err, "internal", "model", "out of memory reading %s", what);
            o->m->uv = t;
            o->captri = c;
        }
        float p[3][3], t[3][2];
        int idx[3] = {0, k, k + 1};
        for (int j = 0; j < 3; j++) {
            memcpy(p[j], o->v + 3 * (size_t)iv[idx[j]], sizeof p[j]);
            memcpy(t[j], o->vt + 2 * (size_t)ivt[idx[j]], sizeof t[j]);
        }
        eye_mesh_add(o->m, p, t);
    }
    return 0;
}

static int eye_obj_line(struct eye_obj *o, char *s, const char *what, int line, struct fx_err *err)
{
    while (*s == ' ' || *s == '\t') s++;
    float x[3];
    if (s[0] == 'v' && (s[1] == ' ' || s[1] == '\t')) {
        if (eye_obj_floats(s + 2, x, 3) != 3)
            return fx_fail(err, "bad_param", "model", "%s line %d: \"v\" needs 3 finite numbers", what, line);
        if (o->nv == EYE_OBJ_MAX_VERTICES)
            return fx_fail(err, "bad_param", "model", "%s: more than %d vertices", what, EYE_OBJ_MAX_VERTICES);
        return eye_obj_push(&o->v, &o->nv, &o->capv, 3, x) ? fx_fail(err, "internal", "model", "out of memory") : 0;
    }
    if (s[0] == 'v' && s[1] == 't' && (s[2] == ' ' || s[2] == '\t')) {
        if (eye_obj_floats(s + 3, x, 2) != 2)
            return fx_fail(err, "bad_param", "model", "%s line %d: \"vt\" needs 2 finite numbers", what, line);
        if (o->nvt == EYE_OBJ_MAX_VERTICES)
            return fx_fail(err, "bad_param", "model", "%s: more than %d texture coordinates", what, EYE_OBJ_MAX_VERTICES);
        return eye_obj_push(&o->vt, &o->nvt, &o->capvt, 2, x) ? fx_fail(err, "internal", "model", "out of memory") : 0;
    }
    if (s[0] == 'f' && (s[1] == ' ' || s[1] == '\t')) return eye_obj_face(o, s + 2, what, line, err);
    return 0; /* comments, normals, groups, materials, smoothing: not needed */
}

int eye_obj_parse(const char *text, size_t len, const char *what, struct eye_mesh *m, struct fx_err *err)
{
    struct eye_obj o = {.m = m};
    memset(m, 0, sizeof *m);
    int rc = 0, line = 1;
    char buf[1024];
    for (size_t i = 0; i < len && !rc; line++) {
        size_t j = i;
        while (j < len && text[j] != '\n') j++;
        if (j - i >= sizeof buf) rc = fx_fail(err, "bad_param", "model", "%s line %d: longer than %zu bytes", what, line, sizeof buf - 1);
        else if (memchr(text + i, 0, j - i)) rc = fx_fail(err, "bad_param", "model", "%s line %d: NUL byte (not a text OBJ)", what, line);
        else {
            memcpy(buf, text + i, j - i);
            buf[j - i] = 0;
            rc = eye_obj_line(&o, buf, what, line, err);
        }
        i = j + 1;
    }
    if (!rc && m->ntri == 0) rc = fx_fail(err, "bad_param", "model", "%s: no faces", what);
    free(o.v);
    free(o.vt);
    if (rc) eye_mesh_free(m);
    return rc;
}

static int eye_obj_path(const char *name, char *path, size_t cap, struct stat *st, struct fx_err *err)
{
    if (!eye_model_name_ok(name))
        return fx_fail(err, "bad_param", "model", "model name \"%.64s\" must match [A-Za-z0-9_-]{1,64}", name);
    if (!eye_assets_dir[0]) return fx_fail(err, "bad_param", "model", "model \"%s\": no assets_dir configured", name);
    snprintf(path, cap, "%s/%s.obj", eye_assets_dir, name);
    /* lstat: a symlink is refused, not followed, so a link to /etc/passwd cannot have its lines
     * quoted in a parse error */
    if (lstat(path, st) || !S_ISREG(st->st_mode))
        return fx_fail(err, "bad_param", "model", "model \"%s\": no regular file %s.obj in the assets directory "
                                                  "(symbolic links are not followed)", name, name);
    if (st->st_size > EYE_OBJ_MAX_BYTES)
        return fx_fail(err, "bad_param", "model", "model \"%s\": %lld bytes is over the %d-byte limit", name,
                       (long long)st->st_size, EYE_OBJ_MAX_BYTES);
    return 0;
}

static int eye_obj_load(const char *name, struct eye_mesh *m, struct fx_err *err)
{
    char path[4200], what[96];
    struct stat st;
    if (eye_obj_path(name, path, sizeof path, &st, err)) return -1;
    int fd = open(path, O_RDONLY | O_NOFOLLOW | O_CLOEXEC); /* no link swapped in after the lstat */
    FILE *f = fd >= 0 ? fdopen(fd, "rb") : NULL;
    if (fd >= 0 && !f) close(fd);
    char *text = malloc((size_t)st.st_size + 1);
    size_t n = f && text ? fread(text, 1, (size_t)st.st_size, f) : 0;
    if (f) fclose(f);
    if (!f || !text || n != (size_t)st.st_size) {
        free(text);
        return fx_fail(err, "bad_param", "model", "model \"%s\": cannot read %s.obj", name, name);
    }
    snprintf(what, sizeof what, "%s.obj", name);
    int rc = eye_obj_parse(text, n, what, m, err);
    free(text);
    return rc;
}

int eye_model_load(const char *name, struct eye_mesh *m, struct fx_err *err)
{
    static const double hemisphere[3] = {1, 1, 1}, insect[3] = {0.8, 0.65, 1.0};
    memset(m, 0, sizeof *m);
    switch (eye_is_builtin(name)) {
    case 0: return eye_builtin_ellipsoid(hemisphere, m, err);
    case 1: return eye_builtin_ellipsoid(insect, m, err);
    case 2: return eye_builtin_plane(m, err);
    default: return eye_obj_load(name, m, err);
    }
}

int eye_model_check(const char *name, struct fx_err *err)
{
    static pthread_mutex_t mu = PTHREAD_MUTEX_INITIALIZER;
    static char last[EYE_MODEL_NAME_MAX + 1];
    static struct stat last_st;
    static struct fx_err last_err;
    static int last_rc = 1; /* 1: nothing cached */
    char path[4200];
    struct stat st;
    if (eye_is_builtin(name) >= 0) return 0;
    if (eye_obj_path(name, path, sizeof path, &st, err)) return -1;
    pthread_mutex_lock(&mu);
    int rc = last_rc;
    if (rc == 1 || strcmp(last, name) || st.st_size != last_st.st_size || st.st_mtime != last_st.st_mtime) {
        struct eye_mesh m;
        memset(&last_err, 0, sizeof last_err);
        rc = eye_obj_load(name, &m, &last_err);
        eye_mesh_free(&m);
        snprintf(last, sizeof last, "%s", name);
        last_st = st;
        last_rc = rc;
    }
    if (rc && err) *err = last_err;
    pthread_mutex_unlock(&mu);
    return rc;
}

/* ---- UV frames and the atlas ----------------------------------------------------- */

int eye_uv_frame(const float P[9], const float T[6], double Pc[3], double Du[3], double Dv[3])
{
    double t10[2] = {T[2] - T[0], T[3] - T[1]}, t20[2] = {T[4] - T[0], T[5] - T[1]}; /* (5.6), (5.7) */
    double det = t10[0] * t20[1] - t20[0] * t10[1];
    double scale = fabs(t10[0]) + fabs(t10[1]) + fabs(t20[0]) + fabs(t20[1]);
    if (!(fabs(det) > 1e-12 * scale * scale)) return -1;
    /* (5.14)-(5.15): [[i,k],[j,l]] = A^-1 with A = (T10, T20) as columns */
    double i = t20[1] / det, j = -t10[1] / det, k = -t20[0] / det, l = t10[0] / det;
    for (int c = 0; c < 3; c++) {
        double p10 = P[3 + c] - P[c], p20 = P[6 + c] - P[c]; /* (5.4), (5.5) */
        Du[c] = i * p10 + j * p20;                           /* (5.8) */
        Dv[c] = k * p10 + l * p20;                           /* (5.9) */
        Pc[c] = P[c] - T[0] * Du[c] - T[1] * Dv[c];          /* (5.3) with P_e = P_0 */
    }
    return 0;
}

static void eye_atlas_triangle(const float *P, const float *T, int size, float *geo)
{
    double Pc[3], Du[3], Dv[3];
    if (eye_uv_frame(P, T, Pc, Du, Dv)) return; /* degenerate UVs: skipped (digest 004 §2.3) */
    double e1[3], e2[3], N[3];
    for (int c = 0; c < 3; c++) e1[c] = P[3 + c] - P[c], e2[c] = P[6 + c] - P[c];
    N[0] = e1[1] * e2[2] - e1[2] * e2[1];
    N[1] = e1[2] * e2[0] - e1[0] * e2[2];
    N[2] = e1[0] * e2[1] - e1[1] * e2[0];
    double nl = sqrt(N[0] * N[0] + N[1] * N[1] + N[2] * N[2]);
    if (!(nl > 0)) return;
    double x[3], y[3]; /* texel-space corners: x = u*size - 0.5, y = (1-v)*size - 0.5 */
    for (int k = 0; k < 3; k++) x[k] = T[2 * k] * size - 0.5, y[k] = (1.0 - T[2 * k + 1]) * size - 0.5;
    int x0 = (int)fmax(0, ceil(fmin(x[0], fmin(x[1], x[2])))), x1 = (int)fmin(size - 1, floor(fmax(x[0], fmax(x[1], x[2]))));
    int y0 = (int)fmax(0, ceil(fmin(y[0], fmin(y[1], y[2])))), y1 = (int)fmin(size - 1, floor(fmax(y[0], fmax(y[1], y[2]))));
    double det = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]);
    const double eps = -1e-9;
    for (int ty = y0; ty <= y1; ty++)
        for (int tx = x0; tx <= x1; tx++) {
            double b1 = ((tx - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (ty - y[0])) / det;
            double b2 = ((x[1] - x[0]) * (ty - y[0]) - (tx - x[0]) * (y[1] - y[0])) / det;
            if (b1 < eps || b2 < eps || 1.0 - b1 - b2 < eps) continue;
            double u = (tx + 0.5) / size, v = 1.0 - (ty + 0.5) / size;
            float *g = geo + 16 * ((size_t)ty * size + tx);
            for (int c = 0; c < 3; c++) {
                g[c] = (float)(Pc[c] + u * Du[c] + v * Dv[c]); /* (5.2) */
                g[4 + c] = (float)(N[c] / nl);
                g[8 + c] = (float)Du[c];
                g[12 + c] = (float)Dv[c];
            }
            g[3] = (float)u;
            g[7] = (float)v;
            g[11] = 1.0f;
            g[15] = 0.0f;
        }
}

/* One ring of gutter: each empty texel copies its first covered 4-neighbour. */
static void eye_atlas_dilate(int size, float *geo, unsigned char *was)
{
    static const int dx[4] = {1, -1, 0, 0}, dy[4] = {0, 0, 1, -1};
    for (size_t i = 0; i < (size_t)size * size; i++) was[i] = geo[16 * i + 11] != 0.0f;
    for (int y = 0; y < size; y++)
        for (int x = 0; x < size; x++) {
            if (was[(size_t)y * size + x]) continue;
            for (int k = 0; k < 4; k++) {
                int nx = x + dx[k], ny = y + dy[k];
                if (nx < 0 || ny < 0 || nx >= size || ny >= size || !was[(size_t)ny * size + nx]) continue;
                memcpy(geo + 16 * ((size_t)y * size + x), geo + 16 * ((size_t)ny * size + nx), 16 * sizeof(float));
                break;
            }
        }
}

void eye_model_atlas(const struct eye_mesh *m, int size, float *geo)
{
    memset(geo, 0, (size_t)size * size * 16 * sizeof(float));
    for (int t = 0; t < m->ntri; t++) eye_atlas_triangle(m->pos + 9 * t, m->uv + 6 * t, size, geo);
    unsigned char *was = malloc((size_t)size * size);
    if (!was) return; /* no gutter then; the atlas itself is complete */
    for (int ring = 0; ring < 2; ring++) eye_atlas_dilate(size, geo, was);
    free(was);
}
