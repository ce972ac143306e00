/* wave_sources.c — see wave_sources.h. Reads the validated document (params.h accessors);
 * no state. */
#include "wave_sources.h"

#include <math.h>
#include <string.h>

#include "../params.h"
#include "../vec3.h"

static void ws_read_points_lines(const cJSON *p, struct wave_sources *s)
{
    const cJSON *it;
    cJSON_ArrayForEach(it, cJSON_GetObjectItemCaseSensitive(p, "points")) {
        if (s->np >= WAVE_MAX_SRC) break;
        struct wave_point *pt = &s->point[s->np++];
        params_vec3(it, "pos", pt->pos);
        pt->coef = params_num(it, "coef");
    }
    cJSON_ArrayForEach(it, cJSON_GetObjectItemCaseSensitive(p, "lines")) {
        if (s->nl >= WAVE_MAX_SRC) break;
        struct wave_line *ln = &s->line[s->nl++];
        params_vec3(it, "pos", ln->pos);
        params_vec3(it, "dir", ln->dir);
        vec3_normalize(ln->dir);
        ln->coef = params_num(it, "coef");
    }
}

/* Torus frame: e3 = axis, e1 any unit normal to it, e2 = e3 × e1 (the field is symmetric
 * about the axis, so the choice of e1 does not matter). */
static void ws_read_tori(const cJSON *p, struct wave_sources *s)
{
    const cJSON *it;
    cJSON_ArrayForEach(it, cJSON_GetObjectItemCaseSensitive(p, "tori")) {
        if (s->nt >= WAVE_MAX_SRC) break;
        struct wave_torus *t = &s->torus[s->nt++];
        params_vec3(it, "center", t->c);
        params_vec3(it, "axis", t->e3);
        vec3_normalize(t->e3);
        vec3_any_normal(t->e3, t->e1);
        vec3_cross(t->e3, t->e1, t->e2);
        t->R = params_num(it, "R");
        t->coef = params_num(it, "coef");
    }
}

static void ws_read_curves(const cJSON *p, struct wave_sources *s)
{
    static const char *const names[3] = {"p0", "p1", "p2"};
    const cJSON *it, *w;
    cJSON_ArrayForEach(it, cJSON_GetObjectItemCaseSensitive(p, "curves")) {
        if (s->nc >= WAVE_MAX_SRC) break;
        struct wave_curve *c = &s->curve[s->nc++];
        for (int k = 0; k < 3; k++) params_vec3(it, names[k], c->b[k]);
        c->coef = params_num(it, "coef");
        cJSON_ArrayForEach(w, cJSON_GetObjectItemCaseSensitive(it, "W")) if (c->nw < WAVE_MAX_W) c->w[c->nw++] = w->valuedouble;
    }
}

void wave_sources_read(const cJSON *params, struct wave_sources *s)
{
    memset(s, 0, sizeof *s);
    ws_read_points_lines(params, s);
    ws_read_tori(params, s);
    ws_read_curves(params, s);
    s->animate = params_bool(params, "animate");
    s->anim_rate = params_num(params, "anim_rate");
}

void wave_sources_weights(const struct wave_sources *s, double sim_time, double w[][WAVE_MAX_W])
{
    for (int i = 0; i < s->nc; i++) {
        const struct wave_curve *c = &s->curve[i];
        if (s->animate) wave_loop_weights(sim_time * s->anim_rate, c->nw, w[i]);
        for (int k = 0; k < c->nw; k++) w[i][k] = c->w[k] * (s->animate ? w[i][k] : 1.0);
    }
}

void wave_anim_weights(double frame, int n, double *w)
{
    for (int i = 0; i < n; i++) {
        double th = (frame - 7.0 * i) * M_PI / 25.0;
        if (th < 0.0 || th > 2.0 * M_PI) th = 0.0;
        double v = (-cos(th) + 0.8) / 1.5;
        w[i] = v < 0.0 ? 0.0 : (v > 1.0 ? 1.0 : v);
    }
}

double wave_anim_period(int n) { return 7.0 * n + 10.0; }

void wave_loop_weights(double frame, int n, double *w)
{
    double period = wave_anim_period(n), f = fmod(frame, period), one[WAVE_MAX_W];
    if (f < 0) f += period;
    for (int i = 0; i < n; i++) w[i] = 0;
    /* the pulses started 0, 1, ... periods ago that have not yet left the curve (7(n-1) + 50) */
    for (double age = f; age <= 7.0 * (n - 1) + 50.0; age += period) {
        wave_anim_weights(age, n, one);
        for (int i = 0; i < n; i++) w[i] = fmin(1.0, w[i] + one[i]);
    }
}
