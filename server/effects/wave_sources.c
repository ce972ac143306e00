/* wave_sources.c — see wave_sources.h. Reads the typed parameters (energy_wave_params.h);
 * no state. */
#include "wave_sources.h"

#include <math.h>
#include <string.h>

#include "../vec3.h"

static void ws_read_points_lines(const struct energy_wave_config *p, struct wave_sources *s)
{
    for (int i = 0; i < p->n_points; i++) {
        struct wave_point *pt = &s->point[s->np++];
        memcpy(pt->pos, p->points[i].pos, sizeof pt->pos);
        pt->coef = p->points[i].coef;
    }
    for (int i = 0; i < p->n_lines; i++) {
        struct wave_line *ln = &s->line[s->nl++];
        memcpy(ln->pos, p->lines[i].pos, sizeof ln->pos);
        memcpy(ln->dir, p->lines[i].dir, sizeof ln->dir);
        vec3_normalize(ln->dir);
        ln->coef = p->lines[i].coef;
    }
}

/* Torus frame: e3 = axis, e1 any unit normal to it, e2 = e3 × e1 (the field is symmetric
 * about the axis, so the choice of e1 does not matter). */
static void ws_read_tori(const struct energy_wave_config *p, struct wave_sources *s)
{
    for (int i = 0; i < p->n_tori; i++) {
        struct wave_torus *t = &s->torus[s->nt++];
        memcpy(t->c, p->tori[i].center, sizeof t->c);
        memcpy(t->e3, p->tori[i].axis, sizeof t->e3);
        vec3_normalize(t->e3);
        vec3_any_normal(t->e3, t->e1);
        vec3_cross(t->e3, t->e1, t->e2);
        t->R = p->tori[i].R;
        t->coef = p->tori[i].coef;
    }
}

static void ws_read_curves(const struct energy_wave_config *p, struct wave_sources *s)
{
    for (int i = 0; i < p->n_curves; i++) {
        const struct energy_wave_curve *in = &p->curves[i];
        struct wave_curve *c = &s->curve[s->nc++];
        memcpy(c->b[0], in->p0, sizeof c->b[0]);
        memcpy(c->b[1], in->p1, sizeof c->b[1]);
        memcpy(c->b[2], in->p2, sizeof c->b[2]);
        c->coef = in->coef;
        c->nw = in->n_W;
        memcpy(c->w, in->W, sizeof c->w[0] * (size_t)in->n_W);
    }
}

void wave_sources_read(const struct energy_wave_config *params, struct wave_sources *s)
{
    memset(s, 0, sizeof *s);
    ws_read_points_lines(params, s);
    ws_read_tori(params, s);
    ws_read_curves(params, s);
    s->animate = params->animate;
    s->anim_rate = params->anim_rate;
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
