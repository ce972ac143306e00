/* test_flame_behaviour.c — digest 002 §8 group D: qualitative and statistical behaviour of
 * the flame effect (server/effects/flame.h) on whole scenes, on the OpenCL CPU device.
 *
 * D1-D4 run on the effect's untouched defaults (a 3 cm disc on a base plate, h 3.5 mm, dt 3 ms,
 * ~10.3k particles, ~2 ms a step on 2 cores): the digest's plateau window 2000-5000 is shortened
 * to 1000-2500 because N levels off within ~100 steps (measured: N(100-200) = 10.2k, plateau
 * 10.3k), which halves the cost. D5-D8 compare scenes and run at the thesis's scale (Table 3.1's
 * h, no base plate) on the digest's 3 cm disc (§9 #17, the size D8's
 * "3 cm discs 4-5 cm apart" needs; ~1.7k particles, ~1 ms a step) with the digest's step
 * counts (3 times the thesis's simulated time at the default dt). The binary takes ~50 s of CPU
 * of the 4 minutes allowed. Quantities are time averages over
 * samples every 10 steps, because N and the flame centroid fluctuate from one resampling
 * to the next; comparisons use batch means over 500-step windows for their noise. Seeds are fixed (the effect is deterministic, test_flame_kernel C7); no timing is
 * asserted. "Flame particles" here are gas particles with the flame flag: the burning
 * sources are flame particles too but fixed, so they would mask ignition and motion. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../ref/flame_ref.h"
#include "check.h"
#include "effects/flame.h"
#include "ocl.h"
#include "params.h"

#define TFB_DISC "{\"radius\":0.015}"
/* D5-D8: the thesis's scale (Table 3.1's h) and a free-floating source, as the digest states them */
#define TFB_THESIS_H 0.01125
#define TFB_THESIS "\"obstacles\":[],\"h\":0.01125"
#define TFB_SCENE "\"sources\":[" TFB_DISC "]," TFB_THESIS
#define TFB_EVERY 10 /* steps between samples */

static struct ocl *tfb_ocl;
static cJSON *tfb_defaults;
static double tfb_h, tfb_dt;

/* ---------------------------------------------------------------- scenes */

enum tfb_field { TFB_N, TFB_NFLAME, TFB_CZ, TFB_CX, TFB_VZ, TFB_Z90, TFB_SRCZ, TFB_NF };

struct tfb_series {
    int len;
    double (*v)[TFB_NF];
};

static struct flame *tfb_new(const char *partial)
{
    cJSON *in = cJSON_Parse(partial), *doc = NULL;
    struct fx_err err = {0};
    if (!in || params_merge(flame_params, tfb_defaults, in, &doc, &err)) {
        CHECK(0, "document %s: %s %s", partial, err.param, err.message);
        cJSON_Delete(in);
        return NULL;
    }
    cJSON_Delete(in);
    struct flame_config c;
    struct flame *fl = params_load(flame_params, doc, &c, sizeof c, &err) ? NULL : flame_new(tfb_ocl, &c, &err);
    CHECK(fl != NULL, "flame_new(%s): %s", partial, err.message);
    cJSON_Delete(doc);
    return fl;
}

static int tfb_is_flame_gas(const struct flame_particles *p, int i)
{
    return (p->flags[i] & FLAME_TYPE_MASK) == FLAME_GAS && (p->flags[i] & FLAME_IS_FLAME);
}

static int tfb_cmp(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* 90th percentile of the flame particles' heights (the flame tip), 0 without any. */
static double tfb_z90(const struct flame_particles *p, int nf)
{
    if (nf == 0) return 0;
    double *z = malloc(sizeof(double) * (size_t)nf);
    int c = 0;
    for (int i = 0; i < p->n; i++)
        if (tfb_is_flame_gas(p, i)) z[c++] = p->pos[4 * i + 2];
    qsort(z, (size_t)c, sizeof *z, tfb_cmp);
    double r = z[(int)(0.9 * (c - 1))];
    free(z);
    return r;
}

/* One sample of the state (up is +z in every scene here). */
static void tfb_sample(const struct flame_particles *p, double v[TFB_NF])
{
    double nf = 0, ns = 0;
    memset(v, 0, sizeof(double) * TFB_NF);
    for (int i = 0; i < p->n; i++) {
        if ((p->flags[i] & FLAME_TYPE_MASK) == FLAME_SOURCE) {
            ns++;
            v[TFB_SRCZ] += p->pos[4 * i + 2];
        }
        if (!tfb_is_flame_gas(p, i)) continue;
        nf++;
        v[TFB_CZ] += p->pos[4 * i + 2];
        v[TFB_CX] += p->pos[4 * i];
        v[TFB_VZ] += p->vel[4 * i + 2];
    }
    if (nf > 0)
        for (int k = TFB_CZ; k <= TFB_VZ; k++) v[k] /= nf;
    if (ns > 0) v[TFB_SRCZ] /= ns;
    v[TFB_N] = p->n;
    v[TFB_NFLAME] = nf;
    v[TFB_Z90] = tfb_z90(p, (int)nf);
}

/* Runs `steps` of the scene, sampling every TFB_EVERY steps; hook (may be NULL) sees each
 * state. Returns the number of samples taken. */
static int tfb_series(const char *partial, int steps, struct tfb_series *s,
                      void (*hook)(const struct flame_particles *, int step, void *), void *ctx)
{
    struct flame *fl = tfb_new(partial);
    s->len = 0;
    s->v = calloc((size_t)(steps / TFB_EVERY + 1), sizeof *s->v);
    struct fx_err err = {0};
    for (int done = 0; fl && done < steps; done += TFB_EVERY) {
        struct flame_particles p;
        if (flame_run(fl, TFB_EVERY, &err) || flame_read(fl, &p, &err)) {
            CHECK(0, "%s at step %d: %s", partial, done, err.message);
            break;
        }
        tfb_sample(&p, s->v[s->len++]);
        if (hook) hook(&p, done + TFB_EVERY, ctx);
        flame_particles_free(&p);
    }
    flame_free(fl);
    return s->len;
}

/* Mean of field f over the samples of steps (from, to]. */
static double tfb_mean(const struct tfb_series *s, enum tfb_field f, int from, int to)
{
    double sum = 0;
    int c = 0;
    for (int k = from / TFB_EVERY; k < to / TFB_EVERY && k < s->len; k++, c++) sum += s->v[k][f];
    return c ? sum / c : 0;
}

/* Least-squares slope (per step) and standard deviation of f over steps (from, to]. */
static void tfb_fit(const struct tfb_series *s, enum tfb_field f, int from, int to, double *slope, double *sd)
{
    double sx = 0, sy = 0, sxx = 0, sxy = 0, syy = 0;
    int c = 0;
    for (int k = from / TFB_EVERY; k < to / TFB_EVERY && k < s->len; k++, c++) {
        double x = (k + 1) * TFB_EVERY, y = s->v[k][f];
        sx += x, sy += y, sxx += x * x, sxy += x * y, syy += y * y;
    }
    *slope = c > 1 ? (c * sxy - sx * sy) / (c * sxx - sx * sx) : 0;
    *sd = c > 1 ? sqrt(fmax(0, syy / c - (sy / c) * (sy / c))) : 0;
}

/* Standard error of the mean of f over (from, to] from batch means of 500 steps. */
static double tfb_se(const struct tfb_series *s, enum tfb_field f, int from, int to)
{
    double m[64], sum = 0, ss = 0;
    int nb = 0;
    for (int w = from; w + 500 <= to && nb < 64; w += 500) sum += m[nb++] = tfb_mean(s, f, w, w + 500);
    if (nb < 2) return 0;
    for (int k = 0; k < nb; k++) ss += (m[k] - sum / nb) * (m[k] - sum / nb);
    return sqrt(ss / (nb - 1) / nb);
}

/* ---------------------------------------------------------------- D1 ignition */

/* First step (1-based) with a gas flame particle, or -1 within max_steps; *tmax gets the
 * hottest gas temperature seen. */
static int tfb_ignition_step(const char *partial, int max_steps, double *tmax)
{
    struct flame *fl = tfb_new(partial);
    struct fx_err err = {0};
    int first = -1;
    *tmax = 0;
    for (int s = 1; fl && s <= max_steps && first < 0; s++) {
        struct flame_particles p;
        if (flame_run(fl, 1, &err) || flame_read(fl, &p, &err)) {
            CHECK(0, "%s: %s", partial, err.message);
            break;
        }
        for (int i = 0; i < p.n; i++) {
            if ((p.flags[i] & FLAME_TYPE_MASK) != FLAME_GAS) continue;
            *tmax = fmax(*tmax, p.pos[4 * i + 3]);
            if (p.flags[i] & FLAME_IS_FLAME) first = s;
        }
        flame_particles_free(&p);
    }
    flame_free(fl);
    return first;
}

static void test_ignition_defaults(void)
{
    double tmax;
    int s = tfb_ignition_step("{}", 50, &tmax);
    printf("  info: effect defaults: first gas flame particle at step %d, hottest gas %.1f K\n", s, tmax);
    CHECK(s > 0, "effect defaults: no gas particle ignites within 50 steps (hottest %.1f K)", tmax);
}

static void test_ignition_base(void)
{
    double tmax;
    int s = tfb_ignition_step("{" TFB_SCENE "}", 50, &tmax);
    printf("  info: 3 cm disc: first gas flame particle at step %d\n", s);
    CHECK(s > 0, "3 cm disc: no gas particle ignites within 50 steps (hottest %.1f K)", tmax);
}

/* ---------------------------------------------------------------- D2-D4 on the base scene */

#define TFB_BASE_STEPS 2500
#define TFB_PLATEAU 1000 /* start of the plateau window (digest: 2000 of 5000) */

static struct tfb_series tfb_base;

/* D4 accumulators: flame-particle temperature near the axis (< 1h) and beyond 2h. */
struct tfb_core { double t_core, n_core, t_rim, n_rim; };

static void tfb_core_hook(const struct flame_particles *p, int step, void *ctx)
{
    struct tfb_core *c = ctx;
    if (step <= 500) return;
    for (int i = 0; i < p->n; i++) {
        if (!tfb_is_flame_gas(p, i)) continue;
        double r = hypot(p->pos[4 * i], p->pos[4 * i + 1]), T = p->pos[4 * i + 3];
        if (r < tfb_h) c->t_core += T, c->n_core++;
        if (r > 2 * tfb_h) c->t_rim += T, c->n_rim++;
    }
}

static struct tfb_core tfb_core;

static void tfb_base_run(void)
{
    if (tfb_base.v) return;
    tfb_series("{}", TFB_BASE_STEPS, &tfb_base, tfb_core_hook, &tfb_core);
}

/* D2: fast rise, then a plateau (slope < 5 % of the mean per 1000 steps, std/mean < 0.25,
 * the digest's criteria) over steps 1000-2500. */
static void test_growth_plateau(void)
{
    tfb_base_run();
    double rise = tfb_mean(&tfb_base, TFB_N, 100, 200), slope, sd;
    double plateau = tfb_mean(&tfb_base, TFB_N, TFB_PLATEAU, TFB_BASE_STEPS);
    tfb_fit(&tfb_base, TFB_N, TFB_PLATEAU, TFB_BASE_STEPS, &slope, &sd);
    printf("  info: defaults: N over steps 100-200 %.0f, plateau %d-%d %.0f (flame %.0f), slope %.2f %%/1000 steps, std/mean %.3f\n",
           rise, TFB_PLATEAU, TFB_BASE_STEPS, plateau, tfb_mean(&tfb_base, TFB_NFLAME, TFB_PLATEAU, TFB_BASE_STEPS),
           100 * slope * 1000 / plateau, sd / plateau);
    CHECK(tfb_base.len == TFB_BASE_STEPS / TFB_EVERY, "only %d samples", tfb_base.len);
    CHECK(plateau > 100, "plateau N %.0f", plateau);
    CHECK(rise >= 0.5 * plateau, "N over steps 100-200 %.0f is under half the plateau %.0f", rise, plateau);
    CHECK(fabs(slope) * 1000 < 0.05 * plateau, "plateau slope %.3g per step (mean %.0f)", slope, plateau);
    CHECK(sd < 0.25 * plateau, "plateau std %.1f, mean %.0f", sd, plateau);
}

/* D3: the flame centroid is more than 2h above the source after 500 steps, mean v_z > 0;
 * checked on the average over 500-2500 and on each 500-step window. */
static void test_flame_rises(void)
{
    tfb_base_run();
    double lift = tfb_mean(&tfb_base, TFB_CZ, 500, TFB_BASE_STEPS) - tfb_mean(&tfb_base, TFB_SRCZ, 500, TFB_BASE_STEPS);
    double vz = tfb_mean(&tfb_base, TFB_VZ, 500, TFB_BASE_STEPS);
    printf("  info: defaults: flame centroid %.4f m above the source (2h = %.4f), mean v_z %.3f m/s\n", lift, 2 * tfb_h, vz);
    CHECK(lift > 2 * tfb_h, "flame centroid %.4f m above the source, want > 2h = %.4f", lift, 2 * tfb_h);
    CHECK(vz > 0, "mean v_z of flame particles %.3f", vz);
    for (int w = 500; w < TFB_BASE_STEPS; w += 500) {
        double l = tfb_mean(&tfb_base, TFB_CZ, w, w + 500) - tfb_mean(&tfb_base, TFB_SRCZ, w, w + 500);
        CHECK(l > 2 * tfb_h && tfb_mean(&tfb_base, TFB_VZ, w, w + 500) > 0, "steps %d-%d: lift %.4f", w, w + 500, l);
    }
}

/* D4: white core, red rim: flame particles within 1h of the axis are hotter on average
 * than those beyond 2h. */
static void test_core_hotter(void)
{
    tfb_base_run();
    double core = tfb_core.n_core ? tfb_core.t_core / tfb_core.n_core : 0;
    double rim = tfb_core.n_rim ? tfb_core.t_rim / tfb_core.n_rim : 0;
    printf("  info: defaults: mean flame T within 1h of the axis %.0f K (%.0f samples), beyond 2h %.0f K (%.0f samples)\n", core,
           tfb_core.n_core, rim, tfb_core.n_rim);
    CHECK(tfb_core.n_core > 100 && tfb_core.n_rim > 100, "too few samples: core %.0f rim %.0f", tfb_core.n_core,
          tfb_core.n_rim);
    CHECK(core > rim, "core %.0f K not hotter than rim %.0f K", core, rim);
}

/* ---------------------------------------------------------------- D5, D6: fuel and wind */

#define TFB_CMP_STEPS 3000 /* long enough for 5 independent 500-step windows after the rise */

struct tfb_avg { double n, nflame, z90, cx, se_nflame, se_z90, se_cx; };

static void tfb_avg_from(const struct tfb_series *s, struct tfb_avg *a)
{
    a->n = tfb_mean(s, TFB_N, 500, TFB_CMP_STEPS);
    a->nflame = tfb_mean(s, TFB_NFLAME, 500, TFB_CMP_STEPS);
    a->z90 = tfb_mean(s, TFB_Z90, 500, TFB_CMP_STEPS);
    a->cx = tfb_mean(s, TFB_CX, 500, TFB_CMP_STEPS);
    a->se_nflame = tfb_se(s, TFB_NFLAME, 500, TFB_CMP_STEPS);
    a->se_z90 = tfb_se(s, TFB_Z90, 500, TFB_CMP_STEPS);
    a->se_cx = tfb_se(s, TFB_CX, 500, TFB_CMP_STEPS);
}

static void tfb_avg_of(const char *partial, struct tfb_avg *a)
{
    struct tfb_series s;
    tfb_series(partial, TFB_CMP_STEPS, &s, NULL, NULL);
    tfb_avg_from(&s, a);
    free(s.v);
}

/* The single 3 cm flame, shared by D6 (calm) and D8 (single N). */
static struct tfb_avg tfb_small;
static int tfb_small_done;

static void tfb_small_run(void)
{
    if (!tfb_small_done) tfb_avg_of("{" TFB_SCENE "}", &tfb_small);
    tfb_small_done = 1;
}

/* a > b beyond noise: by 3 combined standard errors. */
static int tfb_above(double a, double se_a, double b, double se_b) { return a - b > 3 * hypot(se_a, se_b); }

/* D5: F_init 120 gives at least the flame count and height of F_init 80. */
static void test_more_fuel(void)
{
    struct tfb_avg lo, hi;
    tfb_avg_of("{\"sources\":[{\"radius\":0.015,\"F_init\":80}]}", &lo);
    tfb_avg_of("{\"sources\":[{\"radius\":0.015,\"F_init\":120}]}", &hi);
    printf("  info: F_init 80: %.0f flame particles, tip %.4f m; F_init 120: %.0f, tip %.4f m\n", lo.nflame, lo.z90,
           hi.nflame, hi.z90);
    CHECK(tfb_above(hi.nflame, hi.se_nflame, lo.nflame, lo.se_nflame), "flame particles: F_init 120 %.0f ± %.0f vs "
          "80 %.0f ± %.0f", hi.nflame, hi.se_nflame, lo.nflame, lo.se_nflame);
    CHECK(hi.z90 >= lo.z90 - 3 * hypot(hi.se_z90, lo.se_z90), "flame tip: F_init 120 %.4f ± %.4f vs 80 %.4f ± %.4f",
          hi.z90, hi.se_z90, lo.z90, lo.se_z90);
}

/* D6: wind along +x moves the flame centroid downwind, more wind further, and strong wind
 * shrinks the time-averaged flame-particle count; for both wind models (§2.14): the uniform
 * wind_accel (m/s^2) and the drag toward a wind_velocity (m/s) at the default wind_drag. */
static void tfb_wind_case(const char *param, const double speeds[2], const char *unit)
{
    struct tfb_avg mid, strong, calm;
    char doc[256];
    tfb_small_run();
    calm = tfb_small;
    snprintf(doc, sizeof doc, "{" TFB_SCENE ",\"%s\":[%g,0,0]}", param, speeds[0]);
    tfb_avg_of(doc, &mid);
    snprintf(doc, sizeof doc, "{" TFB_SCENE ",\"%s\":[%g,0,0]}", param, speeds[1]);
    tfb_avg_of(doc, &strong);
    printf("  info: %s 0/%g/%g %s: centroid x %.4f/%.4f/%.4f m, flame particles %.0f/%.0f/%.0f, tip %.4f/%.4f/%.4f\n",
           param, speeds[0], speeds[1], unit, calm.cx, mid.cx, strong.cx, calm.nflame, mid.nflame, strong.nflame, calm.z90,
           mid.z90, strong.z90);
    CHECK(tfb_above(mid.cx, mid.se_cx, calm.cx, calm.se_cx), "%s %g: centroid x %.5f ± %.5f vs calm %.5f ± %.5f",
          param, speeds[0], mid.cx, mid.se_cx, calm.cx, calm.se_cx);
    CHECK(tfb_above(strong.cx, strong.se_cx, mid.cx, mid.se_cx), "%s %g: centroid x %.5f ± %.5f vs %g: %.5f", param,
          speeds[1], strong.cx, strong.se_cx, speeds[0], mid.cx);
    CHECK(tfb_above(calm.nflame, calm.se_nflame, strong.nflame, strong.se_nflame), "%s %g: %.0f ± %.0f flame "
          "particles vs calm %.0f ± %.0f", param, speeds[1], strong.nflame, strong.se_nflame, calm.nflame, calm.se_nflame);
}

static void test_wind(void)
{
    static const double accel[2] = {10, 40}, velocity[2] = {1, 4};
    tfb_wind_case("wind_accel", accel, "m/s^2");
    tfb_wind_case("wind_velocity", velocity, "m/s");
}

/* ---------------------------------------------------------------- D7 obstacle */

/* The plate (the effect's default obstacle, 4 x 4 cm across x and z moving at -0.2 m/s
 * along y) spans z = 0..4 cm, just above the source, where the flame is; it starts far
 * away and crosses the flame axis at step TFB_CROSS. */
#define TFB_CROSS 800

static void test_obstacle_pass(void)
{
    char doc[256];
    double y0 = 0.2 * TFB_CROSS * tfb_dt;
    snprintf(doc, sizeof doc, "{" TFB_SCENE ",\"obstacles\":[{\"pos\":[0,%.6f,0.02],\"velocity\":[0,-0.2,0]}]}", y0);
    struct tfb_series s;
    int steps = TFB_CROSS + 1400;
    tfb_series(doc, steps, &s, NULL, NULL);
    /* The plate overlaps the flame (radius ~ 1.5 cm + h) while |y| < 2.5 cm. */
    int half = (int)(0.025 / (0.2 * tfb_dt));
    double pre = tfb_mean(&s, TFB_NFLAME, TFB_CROSS - half - 400, TFB_CROSS - half);
    double during = tfb_mean(&s, TFB_NFLAME, TFB_CROSS - half / 2, TFB_CROSS + half);
    double after = tfb_mean(&s, TFB_NFLAME, TFB_CROSS + half + 500, TFB_CROSS + half + 1000);
    printf("  info: obstacle: flame particles before %.0f, while crossing %.0f, 500-1000 steps after %.0f\n", pre,
           during, after);
    CHECK(during < 0.9 * pre, "no dip while the plate crosses: %.0f vs %.0f before", during, pre);
    CHECK(after >= 0.8 * pre, "no recovery: %.0f vs %.0f before", after, pre);
    free(s.v);
}

/* ---------------------------------------------------------------- D8 merge */

struct tfb_merge { int snaps, merged; double zcut0; };

static int tfb_find(int *parent, int i)
{
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
}

/* True when the flame particles above zcut (at least 20) lie >= 90 % in one component of
 * the radius-h neighbour graph that reaches both sides of the midplane x = 0. */
static int tfb_merged_at(const struct flame_particles *p, double zcut)
{
    int m = 0, *idx = malloc(sizeof(int) * (size_t)p->n), *parent = malloc(sizeof(int) * (size_t)p->n);
    for (int i = 0; i < p->n; i++)
        if (tfb_is_flame_gas(p, i) && p->pos[4 * i + 2] > zcut) idx[m++] = i;
    for (int a = 0; a < m; a++) parent[a] = a;
    for (int a = 0; a < m; a++)
        for (int b = a + 1; b < m; b++) {
            const float *x = &p->pos[4 * idx[a]], *y = &p->pos[4 * idx[b]];
            double d2 = (x[0] - y[0]) * (x[0] - y[0]) + (x[1] - y[1]) * (x[1] - y[1]) + (x[2] - y[2]) * (x[2] - y[2]);
            if (d2 <= TFB_THESIS_H * TFB_THESIS_H) parent[tfb_find(parent, a)] = tfb_find(parent, b);
        }
    int best = -1, best_n = 0, ok = 0;
    for (int a = 0; a < m; a++) {
        int r = tfb_find(parent, a), c = 0;
        for (int b = 0; b < m; b++) c += tfb_find(parent, b) == r;
        if (c > best_n) best_n = c, best = r;
    }
    if (m >= 20 && best_n >= 0.9 * m) {
        double lo = 1, hi = -1;
        for (int a = 0; a < m; a++)
            if (tfb_find(parent, a) == best) lo = fmin(lo, p->pos[4 * idx[a]]), hi = fmax(hi, p->pos[4 * idx[a]]);
        ok = lo < -0.5 * TFB_THESIS_H && hi > 0.5 * TFB_THESIS_H;
    }
    free(idx);
    free(parent);
    return ok;
}

static void tfb_merge_hook(const struct flame_particles *p, int step, void *ctx)
{
    struct tfb_merge *mg = ctx;
    if (step <= 500 || step % 100) return;
    int merged = 0;
    for (int k = 1; k <= 6 && !merged; k++) merged = tfb_merged_at(p, mg->zcut0 + k * TFB_THESIS_H);
    mg->snaps++;
    mg->merged += merged;
}

/* D8: discs 4.5 cm apart (1.5 cm gap): one connected flame above some height, N ≈ 2x. */
static void test_two_flames_merge(void)
{
    tfb_small_run();
    struct tfb_series s;
    struct tfb_merge mg = {.zcut0 = 0};
    tfb_series("{\"sources\":[{\"radius\":0.015,\"center\":[-0.0225,0,0]},{\"radius\":0.015,\"center\":[0.0225,0,0]}],"
               TFB_THESIS "}",
               TFB_CMP_STEPS, &s, tfb_merge_hook, &mg);
    double two = tfb_mean(&s, TFB_N, 500, TFB_CMP_STEPS), one = tfb_small.n;
    printf("  info: merge: N %.0f vs single %.0f (ratio %.2f), merged in %d of %d snapshots\n", two, one, two / one,
           mg.merged, mg.snaps);
    CHECK(two > 1.5 * one && two < 2.5 * one, "two flames N %.0f vs single %.0f", two, one);
    CHECK(mg.merged * 2 >= mg.snaps && mg.snaps > 0, "merged in only %d of %d snapshots", mg.merged, mg.snaps);
    free(s.v);
}

int main(void)
{
    struct fx_err err = {0};
    if (ocl_open(&tfb_ocl, CHECK_DEVICE(), &err)) return CHECK_ABORT("ocl_open(%s): %s: %s", CHECK_DEVICE(), err.code, err.message);
    tfb_defaults = params_defaults(flame_params);
    struct flame_config defaults;
    if (!tfb_defaults || params_load(flame_params, tfb_defaults, &defaults, sizeof defaults, &err))
        return CHECK_ABORT("flame defaults: %s", err.message);
    tfb_h = defaults.h;
    tfb_dt = defaults.dt;
    RUN(test_ignition_defaults);
    RUN(test_ignition_base);
    RUN(test_growth_plateau);
    RUN(test_flame_rises);
    RUN(test_core_hotter);
    RUN(test_more_fuel);
    RUN(test_wind);
    RUN(test_obstacle_pass);
    RUN(test_two_flames_merge);
    free(tfb_base.v);
    cJSON_Delete(tfb_defaults);
    ocl_close(tfb_ocl);
    return CHECK_DONE();
}
