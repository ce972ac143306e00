/* flame_shape.c — see flame_shape.h. */
#include "flame_shape.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void flame_shape_init(struct flame_shape_acc *a, const double c[3], const double up[3], double T_ign)
{
    memset(a, 0, sizeof *a);
    double n = sqrt(up[0] * up[0] + up[1] * up[1] + up[2] * up[2]);
    for (int k = 0; k < 3; k++) {
        a->c[k] = c[k];
        a->up[k] = up[k] / n;
    }
    a->T_ign = T_ign;
}

static int fs_cmp(const void *x, const void *y)
{
    double u = *(const double *)x, v = *(const double *)y;
    return (u > v) - (u < v);
}

/* q-quantile (0..1) of v[0..n) (sorted in place); 0 when empty. */
static double fs_quantile(double *v, size_t n, double q)
{
    if (!n) return 0;
    qsort(v, n, sizeof *v, fs_cmp);
    size_t i = (size_t)floor(q * (double)(n - 1) + 0.5);
    return v[i < n ? i : n - 1];
}

void flame_shape_add(struct flame_shape_acc *a, const struct flame_particles *p)
{
    size_t first = a->n;
    for (int i = 0; i < p->n; i++) {
        if ((p->flags[i] & FLAME_TYPE_MASK) != FLAME_GAS || p->pos[4 * i + 3] < a->T_ign) continue;
        double d[3], hgt = 0, w2 = 0;
        for (int k = 0; k < 3; k++) d[k] = p->pos[4 * i + k] - a->c[k];
        for (int k = 0; k < 3; k++) hgt += d[k] * a->up[k];
        for (int k = 0; k < 3; k++) {
            double l = d[k] - hgt * a->up[k];
            a->lat[k] += l;
            w2 += l * l;
        }
        if (a->n == a->cap) {
            a->cap = a->cap ? 2 * a->cap : 1 << 16;
            a->h = realloc(a->h, a->cap * sizeof *a->h);
            a->w = realloc(a->w, a->cap * sizeof *a->w);
        }
        a->h[a->n] = hgt;
        a->w[a->n++] = sqrt(w2);
        a->height_sum += hgt;
    }
    a->p99 = realloc(a->p99, (size_t)(a->frames + 1) * sizeof *a->p99);
    size_t m = a->n - first;
    double *tmp = malloc((m ? m : 1) * sizeof *tmp);
    memcpy(tmp, a->h + first, m * sizeof *tmp);
    a->p99[a->frames++] = fs_quantile(tmp, m, 0.99);
    free(tmp);
    a->particles += p->n;
}

void flame_shape_result(struct flame_shape_acc *a, struct flame_shape *out)
{
    memset(out, 0, sizeof *out);
    if (!a->frames) return;
    size_t below = 0;
    for (size_t i = 0; i < a->n; i++) below += a->h[i] < 0;
    out->below = a->n ? (double)below / (double)a->n : 0;
    out->centroid_h = a->n ? a->height_sum / (double)a->n : 0;
    for (int k = 0; k < 3; k++) out->centroid_lat[k] = a->n ? a->lat[k] / (double)a->n : 0;
    out->burning = (double)a->n / a->frames;
    out->particles = a->particles / a->frames;
    double s = 0, s2 = 0;
    for (int f = 0; f < a->frames; f++) {
        s += a->p99[f];
        s2 += a->p99[f] * a->p99[f];
    }
    double mean = s / a->frames, var = fmax(0, s2 / a->frames - mean * mean);
    out->flicker = mean > 0 ? sqrt(var) / mean : 0;
    out->H90 = fs_quantile(a->h, a->n, 0.9);
    out->W90 = fs_quantile(a->w, a->n, 0.9);
}

void flame_shape_free(struct flame_shape_acc *a)
{
    free(a->h);
    free(a->w);
    free(a->p99);
    memset(a, 0, sizeof *a);
}

const char *flame_shape_preset(const char *name)
{
    for (const struct effect_preset *p = flame_presets; p && p->name; p++)
        if (!strcmp(p->name, name)) return p->params;
    return NULL;
}

static void fs_vec(const cJSON *v, double out[3])
{
    for (int k = 0; k < 3; k++) out[k] = cJSON_GetArrayItem(v, k)->valuedouble;
}

static void fs_add(void *ctx, struct flame_shape_acc *acc, const struct flame_particles *p)
{
    (void)ctx;
    flame_shape_add(acc, p);
}

int flame_shape_run(struct ocl *ocl, const cJSON *doc, double warm_s, double seconds, struct flame_shape *out,
                    struct fx_err *err)
{
    return flame_shape_frames(ocl, doc, warm_s, seconds, fs_add, NULL, out, err);
}

int flame_shape_frames(struct ocl *ocl, const cJSON *doc, double warm_s, double seconds, flame_shape_each each,
                       void *ctx, struct flame_shape *out, struct fx_err *err)
{
    struct flame_config cfg;
    struct flame *fl = params_load(flame_params, doc, &cfg, sizeof cfg, err) ? NULL : flame_new(ocl, &cfg, err);
    if (!fl) return -1;
    double dt = cfg.dt, c[3] = {0, 0, 0}, up[3];
    int ns = 0;
    const cJSON *src;
    cJSON_ArrayForEach(src, cJSON_GetObjectItem(doc, "sources")) {
        if (cJSON_IsFalse(cJSON_GetObjectItem(src, "enabled"))) continue;
        double sc[3];
        fs_vec(cJSON_GetObjectItem(src, "center"), sc);
        for (int k = 0; k < 3; k++) c[k] += sc[k];
        ns++;
    }
    for (int k = 0; k < 3 && ns; k++) c[k] /= ns;
    fs_vec(cJSON_GetObjectItem(doc, "up"), up);
    int per_frame = (int)lround(1.0 / 30 / dt), rc = flame_run(fl, (int)lround(warm_s / dt), err);
    struct flame_shape_acc acc;
    flame_shape_init(&acc, c, up, cfg.T_ign);
    for (int f = 0; !rc && f < (int)lround(seconds * 30); f++) {
        struct flame_particles p;
        rc = flame_run(fl, per_frame > 0 ? per_frame : 1, err) || flame_read(fl, &p, err);
        if (rc) break;
        each(ctx, &acc, &p);
        flame_particles_free(&p);
    }
    flame_shape_result(&acc, out);
    flame_shape_free(&acc);
    flame_free(fl);
    return rc ? -1 : 0;
}
