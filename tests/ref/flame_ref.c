/* flame_ref.c — double-precision reference of the flame SPH model (see flame_ref.h).
 *
 * Written from the digest (digests/002-flame-sph.md §2, §3, §9), never from the device
 * code. O(N²) everywhere: it is meant for inputs of a few thousand particles. */
#include "flame_ref.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

/* ---------------------------------------------------------------- parameters */

void flame_ref_defaults(struct flame_ref_params *p)
{
    memset(p, 0, sizeof *p);
    p->dt = 0.001;
    p->h = 0.01125;
    p->d = 0.5 * p->h;
    p->mass = 1.7626e-7;
    p->k_stiff = 10.0;
    p->k_visc = 0.005;
    p->rho_rest = 1.0;
    p->k_buo = 0.01;
    p->up[2] = 1.0;
    p->T_amb = 300.0;
    p->T_ign = 1000.0;
    p->k_rs = 0.01;
    p->k_cf = 5.0;
    p->k_pt = 500.0;
    p->k_h = 0.02;
    p->k_f = 0.001;
    p->stabilized = 1;
    p->omega_max = 0.5;
    p->fuel_eps = 0.001;
    p->resample_interval = 5;
    p->insert_nbr_threshold = 24;
}

/* The first of the given names present in doc, or NULL (names may differ in case). */
static const cJSON *flame_ref_item(const cJSON *doc, const char *const *names)
{
    for (; *names; names++) {
        const cJSON *it = cJSON_GetObjectItemCaseSensitive(doc, *names);
        if (it) return it;
    }
    return NULL;
}

static int flame_ref_num(const cJSON *doc, const char *const *names, double *out)
{
    const cJSON *it = flame_ref_item(doc, names);
    if (!cJSON_IsNumber(it)) return 0;
    *out = it->valuedouble;
    return 1;
}

static int flame_ref_vec(const cJSON *doc, const char *const *names, double out[3])
{
    const cJSON *it = flame_ref_item(doc, names);
    if (!cJSON_IsArray(it) || cJSON_GetArraySize(it) != 3) return 0;
    for (int k = 0; k < 3; k++) out[k] = cJSON_GetArrayItem(it, k)->valuedouble;
    return 1;
}

static int flame_ref_enum(const cJSON *doc, const char *const *names, const char *yes, int *out)
{
    const cJSON *it = flame_ref_item(doc, names);
    if (!cJSON_IsString(it)) return 0;
    *out = strncmp(it->valuestring, yes, strlen(yes)) == 0;
    return 1;
}

#define FLAME_REF_NAMES(...) ((const char *const[]){__VA_ARGS__, NULL})

static int flame_ref_read_sph(const cJSON *doc, struct flame_ref_params *p)
{
    int n = 0;
    double diam = -1;
    n += flame_ref_num(doc, FLAME_REF_NAMES("dt"), &p->dt);
    n += flame_ref_num(doc, FLAME_REF_NAMES("h"), &p->h);
    n += flame_ref_num(doc, FLAME_REF_NAMES("mass"), &p->mass);
    n += flame_ref_num(doc, FLAME_REF_NAMES("k_stiff", "k_stiffness"), &p->k_stiff);
    n += flame_ref_num(doc, FLAME_REF_NAMES("k_viscosity", "k_visc"), &p->k_visc);
    n += flame_ref_num(doc, FLAME_REF_NAMES("rho_rest"), &p->rho_rest);
    n += flame_ref_enum(doc, FLAME_REF_NAMES("pressure_form"), "sym", &p->symmetric_pressure);
    if (flame_ref_num(doc, FLAME_REF_NAMES("particle_diameter"), &diam)) n++;
    p->d = diam > 0 ? diam * p->h : 0.5 * p->h;
    return n;
}

static int flame_ref_read_forces(const cJSON *doc, struct flame_ref_params *p)
{
    int n = 0;
    n += flame_ref_num(doc, FLAME_REF_NAMES("k_buo"), &p->k_buo);
    n += flame_ref_vec(doc, FLAME_REF_NAMES("up"), p->up);
    n += flame_ref_vec(doc, FLAME_REF_NAMES("gravity"), p->gravity);
    n += flame_ref_vec(doc, FLAME_REF_NAMES("wind_accel", "wind"), p->wind);
    n += flame_ref_vec(doc, FLAME_REF_NAMES("wind_velocity"), p->wind_velocity);
    n += flame_ref_num(doc, FLAME_REF_NAMES("wind_drag"), &p->wind_drag);
    double len = sqrt(p->up[0] * p->up[0] + p->up[1] * p->up[1] + p->up[2] * p->up[2]);
    if (len > 0)
        for (int k = 0; k < 3; k++) p->up[k] /= len;
    return n;
}

static int flame_ref_read_heat(const cJSON *doc, struct flame_ref_params *p)
{
    int n = 0;
    double v;
    n += flame_ref_num(doc, FLAME_REF_NAMES("T_amb", "t_amb"), &p->T_amb);
    n += flame_ref_num(doc, FLAME_REF_NAMES("T_ign", "t_ign"), &p->T_ign);
    n += flame_ref_num(doc, FLAME_REF_NAMES("k_rs"), &p->k_rs);
    n += flame_ref_num(doc, FLAME_REF_NAMES("k_cf"), &p->k_cf);
    n += flame_ref_num(doc, FLAME_REF_NAMES("k_pt"), &p->k_pt);
    n += flame_ref_num(doc, FLAME_REF_NAMES("k_h"), &p->k_h);
    n += flame_ref_num(doc, FLAME_REF_NAMES("k_f"), &p->k_f);
    n += flame_ref_enum(doc, FLAME_REF_NAMES("diffusion_mode"), "stab", &p->stabilized);
    n += flame_ref_num(doc, FLAME_REF_NAMES("omega_max"), &p->omega_max);
    n += flame_ref_num(doc, FLAME_REF_NAMES("k_cool"), &p->k_cool);
    n += flame_ref_num(doc, FLAME_REF_NAMES("fuel_eps"), &p->fuel_eps);
    if (flame_ref_num(doc, FLAME_REF_NAMES("resample_interval"), &v)) {
        p->resample_interval = (int)v;
        n++;
    }
    if (flame_ref_num(doc, FLAME_REF_NAMES("insert_nbr_threshold"), &v)) {
        p->insert_nbr_threshold = (int)v;
        n++;
    }
    return n;
}

double flame_ref_lattice_mass(double h, double d, double rho_rest)
{
    int r = (int)(h / d) + 1;
    double w = 0;
    for (int i = -r; i <= r; i++)
        for (int j = -r; j <= r; j++)
            for (int k = -r; k <= r; k++) w += flame_ref_w_poly6(d * sqrt((double)(i * i + j * j + k * k)), h);
    return rho_rest / w;
}

int flame_ref_params_from_json(const cJSON *doc, struct flame_ref_params *p)
{
    const cJSON *sim = cJSON_GetObjectItemCaseSensitive(doc, "sim");
    if (cJSON_IsObject(sim)) doc = sim; /* nested form of digest §10 */
    int n = flame_ref_read_sph(doc, p) + flame_ref_read_forces(doc, p) + flame_ref_read_heat(doc, p);
    if (p->mass <= 0) p->mass = flame_ref_lattice_mass(p->h, p->d, p->rho_rest); /* §9 #6 */
    return n;
}

/* ---------------------------------------------------------------- kernels */

double flame_ref_w_poly6(double r, double h)
{
    if (r < 0 || r >= h) return 0;
    double q = h * h - r * r;
    return 315.0 / (64.0 * M_PI * pow(h, 9)) * q * q * q;
}

double flame_ref_w_spiky(double r, double h)
{
    if (r < 0 || r >= h) return 0;
    double q = h - r;
    return 15.0 / (M_PI * pow(h, 6)) * q * q * q;
}

double flame_ref_w_visc(double r, double h)
{
    if (r <= 0 || r >= h) return 0; /* singular at 0; r²W is what integrates */
    return 15.0 / (2.0 * M_PI * h * h * h) * (-r * r * r / (2 * h * h * h) + r * r / (h * h) + h / (2 * r) - 1);
}

void flame_ref_grad_poly6(const double x[3], double h, double out[3])
{
    double r2 = x[0] * x[0] + x[1] * x[1] + x[2] * x[2];
    double c = r2 < h * h ? -945.0 / (32.0 * M_PI * pow(h, 9)) * (h * h - r2) * (h * h - r2) : 0;
    for (int k = 0; k < 3; k++) out[k] = c * x[k];
}

void flame_ref_grad_spiky(const double x[3], double h, double out[3])
{
    double r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
    double c = (r > 0 && r < h) ? -45.0 / (M_PI * pow(h, 6)) * (h - r) * (h - r) / r : 0;
    for (int k = 0; k < 3; k++) out[k] = c * x[k];
}

double flame_ref_lap_visc(double r, double h)
{
    if (r < 0 || r >= h) return 0;
    return 45.0 / (M_PI * pow(h, 6)) * (h - r);
}

/* ---------------------------------------------------------------- helpers */

double flame_ref_dist(const double a[3], const double b[3])
{
    double dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
    return sqrt(dx * dx + dy * dy + dz * dz);
}

int flame_ref_is_flame(const struct flame_ref_params *p, double T, double F)
{
    return T > p->T_ign && F > p->fuel_eps;
}

int flame_ref_is_solid(int type) { return type == FLAME_REF_SOURCE || type == FLAME_REF_OBSTACLE; }

int flame_ref_neighbours(const struct flame_ref_params *p, const struct flame_ref_particle *ps, int n, int i,
                         int *idx, int max)
{
    int c = 0;
    for (int j = 0; j < n; j++) {
        if (j == i || flame_ref_dist(ps[i].r, ps[j].r) > p->h) continue;
        if (c < max && idx) idx[c] = j;
        c++;
    }
    return c;
}

void flame_ref_density(const struct flame_ref_params *p, const struct flame_ref_particle *ps, int n, double *rho)
{
    for (int i = 0; i < n; i++) {
        double s = 0;
        for (int j = 0; j < n; j++) s += p->mass * flame_ref_w_poly6(flame_ref_dist(ps[i].r, ps[j].r), p->h);
        rho[i] = s;
    }
}

double flame_ref_reaction(const struct flame_ref_params *p, double T, double F)
{
    return flame_ref_is_flame(p, T, F) ? p->k_rs * T * F : 0;
}

void flame_ref_buoyancy(const struct flame_ref_params *p, double T, double f[3])
{
    for (int k = 0; k < 3; k++) f[k] += p->k_buo * (T - p->T_amb) * p->up[k];
}

/* ---------------------------------------------------------------- evaluation */

/* Eq 3.11 clamped at 0 in both pressure forms (no tension at the gas's free boundary). */
static double flame_ref_pressure(const struct flame_ref_params *p, double rho)
{
    return fmax(0, p->k_stiff * (rho - p->rho_rest));
}

/* Pressure force of pair (i, j) on i: the sign-fixed difference form (3.12) or Müller's. */
static void flame_ref_pair_pressure(const struct flame_ref_params *p, const struct flame_ref_particle *ps,
                                    const struct flame_ref_eval *ev, int i, int j, double f[3])
{
    double x[3], g[3], c;
    for (int k = 0; k < 3; k++) x[k] = ps[j].r[k] - ps[i].r[k];
    if (!p->symmetric_pressure) {
        flame_ref_grad_spiky(x, p->h, g); /* ∇W(r_j - r_i): points from j to i */
        c = p->mass / ev[j].rho * (ev[j].p - ev[i].p);
    } else {
        for (int k = 0; k < 3; k++) x[k] = -x[k];
        flame_ref_grad_spiky(x, p->h, g); /* ∇W(r_i - r_j): points from i to j */
        c = -p->mass * (ev[i].p + ev[j].p) / (2 * ev[j].rho);
    }
    for (int k = 0; k < 3; k++) f[k] += c * g[k];
}

/* Diffusion of one quantity: coef[j] = k·c_ij·(m/ρ_j)·∇²W, val the field. */
static double flame_ref_diffuse(const struct flame_ref_params *p, const double *coef, const double *dval, int cnt)
{
    double wsum = 0, s = 0;
    for (int a = 0; a < cnt; a++) {
        wsum += p->dt * coef[a];
        s += coef[a] * dval[a];
    }
    if (p->stabilized && wsum > p->omega_max) s *= p->omega_max / wsum;
    return s;
}

/* Optional viscosity cap (see cap_viscosity); wsum = Σ (m/ρ_j) ∇²W_visc. */
static void flame_ref_cap_viscosity(const struct flame_ref_params *p, double rho_i, double wsum, double f[3])
{
    double w = p->dt * p->k_visc * wsum / rho_i;
    if (!p->cap_viscosity || !p->stabilized || w <= p->omega_max) return;
    for (int k = 0; k < 3; k++) f[k] *= p->omega_max / w;
}

static void flame_ref_eval_forces(const struct flame_ref_params *p, const struct flame_ref_particle *ps, int n,
                                  struct flame_ref_eval *ev, int i, double *buf)
{
    struct flame_ref_eval *e = &ev[i];
    double *ch = buf, *dTv = buf + n, *cf = buf + 2 * n, *dFv = buf + 3 * n;
    int cnt = 0;
    double wv = 0;
    for (int j = 0; j < n; j++) {
        double r = flame_ref_dist(ps[i].r, ps[j].r);
        if (j == i || r > p->h) continue;
        double vol = p->mass / ev[j].rho, lap = flame_ref_lap_visc(r, p->h), x[3], g[3];
        flame_ref_pair_pressure(p, ps, ev, i, j, e->f_press);
        for (int k = 0; k < 3; k++) e->f_visc[k] += p->k_visc * vol * (ps[j].v[k] - ps[i].v[k]) * lap;
        for (int k = 0; k < 3; k++) x[k] = ps[i].r[k] - ps[j].r[k];
        flame_ref_grad_poly6(x, p->h, g);
        for (int k = 0; k < 3; k++) e->n[k] += vol * g[k];
        wv += vol * lap;
        ch[cnt] = p->k_h * vol * lap;
        dTv[cnt] = ps[j].T - ps[i].T;
        cf[cnt] = p->k_f * 0.5 * (ps[i].T + ps[j].T) * vol * lap;
        dFv[cnt] = ps[j].F - ps[i].F;
        e->nbr++;
        e->flame_nbr += flame_ref_is_flame(p, ps[j].T, ps[j].F);
        cnt++;
    }
    flame_ref_cap_viscosity(p, ev[i].rho, wv, e->f_visc);
    e->dT_diff = flame_ref_diffuse(p, ch, dTv, cnt);
    e->dF_diff = flame_ref_diffuse(p, cf, dFv, cnt);
}

void flame_ref_eval_all(const struct flame_ref_params *p, const struct flame_ref_particle *ps, int n,
                        struct flame_ref_eval *out)
{
    double *rho = malloc(sizeof(double) * (size_t)(n > 0 ? n : 1));
    double *buf = malloc(sizeof(double) * 4 * (size_t)(n > 0 ? n : 1));
    if (!rho || !buf) {
        free(rho);
        free(buf);
        return;
    }
    memset(out, 0, sizeof *out * (size_t)n);
    flame_ref_density(p, ps, n, rho);
    for (int i = 0; i < n; i++) {
        out[i].rho = rho[i];
        out[i].p = flame_ref_pressure(p, rho[i]);
    }
    for (int i = 0; i < n; i++) {
        struct flame_ref_eval *e = &out[i];
        flame_ref_eval_forces(p, ps, n, out, i, buf);
        e->is_flame = flame_ref_is_flame(p, ps[i].T, ps[i].F);
        double S = flame_ref_reaction(p, ps[i].T, ps[i].F);
        /* a step burns at most the fuel left after diffusion, so T + (k_pt/k_cf) F holds at any
         * dt (kernels/flame.cl fl_burn) */
        double Fd = fmax(0, ps[i].F + p->dt * e->dF_diff), burn = p->dt * p->k_cf * S;
        if (burn > Fd) S *= Fd / burn;
        e->dT_react = p->k_pt * S;
        e->dF_react = -p->k_cf * S;
        e->dT = e->dT_react + e->dT_diff;
        e->dF = e->dF_react + e->dF_diff;
    }
    free(rho);
    free(buf);
}

/* ---------------------------------------------------------------- integration */

void flame_ref_drag(const struct flame_ref_params *p, double v[3])
{
    /* dv/dt = k (w - v) on the part normal to up, solved exactly over dt */
    double rel[3], along = 0, keep = exp(-p->wind_drag * p->dt);
    for (int k = 0; k < 3; k++) rel[k] = v[k] - p->wind_velocity[k];
    for (int k = 0; k < 3; k++) along += rel[k] * p->up[k];
    for (int k = 0; k < 3; k++) v[k] -= (1 - keep) * (rel[k] - along * p->up[k]);
}

void flame_ref_integrate(const struct flame_ref_params *p, const struct flame_ref_eval *e,
                         struct flame_ref_particle *q)
{
    if (q->type == FLAME_REF_SOURCE) return;
    if (q->type == FLAME_REF_OBSTACLE) {
        for (int k = 0; k < 3; k++) q->r[k] += p->dt * q->v[k];
        return;
    }
    q->T += p->dt * (e->dT - p->k_cool * (q->T - p->T_amb)); /* §9 #13, explicit */
    q->F += p->dt * e->dF;
    if (q->F < 0) q->F = 0;
    double f[3];
    for (int k = 0; k < 3; k++) f[k] = e->f_press[k] + e->f_visc[k];
    flame_ref_buoyancy(p, q->T, f); /* with the updated T (§2.10) */
    for (int k = 0; k < 3; k++) q->v[k] += p->dt * (f[k] / e->rho + p->gravity[k] + p->wind[k]);
    flame_ref_drag(p, q->v);
    for (int k = 0; k < 3; k++) q->r[k] += p->dt * q->v[k];
}

int flame_ref_step(const struct flame_ref_params *p, struct flame_ref_particle *ps, int n,
                   struct flame_ref_eval *ev)
{
    struct flame_ref_eval *own = NULL;
    if (!ev) {
        own = malloc(sizeof *own * (size_t)(n > 0 ? n : 1));
        if (!own) return -1;
        ev = own;
    }
    flame_ref_eval_all(p, ps, n, ev);
    for (int i = 0; i < n; i++) flame_ref_integrate(p, &ev[i], &ps[i]);
    free(own);
    return 0;
}

double flame_ref_logistic_T(const struct flame_ref_params *p, double T0, double F0, double t)
{
    double E = T0 + p->k_pt / p->k_cf * F0;
    return E / (1 + (E / T0 - 1) * exp(-p->k_rs * p->k_cf * E * t));
}
