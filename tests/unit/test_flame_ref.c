/* test_flame_ref.c — checks the flame C reference (tests/ref/flame_ref.c) against the
 * analytic properties of digest 002 §8, groups A and B, before it is trusted as the
 * ground truth of test_flame_kernel.
 *
 * A: kernel quadratures over the ball (= 1 ± 1e-3), zero support beyond h, derivatives
 * against finite differences, the corrected spiky-gradient sign, the d = h/2 lattice
 * (interior ρ = 1 ± 0.5 %, 32 neighbours), zero forces and derivatives in a uniform
 * field, pressure toward lower density, zero pressure force on a symmetric pair,
 * the isolated density 0.1939. B: the isolated burning particle (invariant T + 100F,
 * worked step 1200/10 → 1260/9.4, logistic curve within 1 %), no-ignition cases,
 * exact buoyancy Δv, the wind drag of §2.14 (exact decay across up, none along it), the
 * stabilised diffusion bound, and the JSON reader. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../ref/flame_ref.h"
#include "check.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

#define TFR_LAT 11 /* lattice side: the centre's neighbours' neighbours are all interior */

/* ---------------------------------------------------------------- helpers */

/* ∫_0^h 4π r² w(r) dr by composite Simpson (n even); r²w → 0 at r = 0 for every kernel. */
static double tfr_ball_integral(double (*w)(double, double), double h)
{
    const int n = 20000;
    double s = 0, dr = h / n;
    for (int k = 0; k <= n; k++) {
        double r = k * dr, g = k == 0 ? 0 : 4 * M_PI * r * r * w(r, h);
        s += g * (k == 0 || k == n ? 1 : (k % 2 ? 4 : 2));
    }
    return s * dr / 3;
}

static double tfr_lap_visc_fd(double r, double h)
{
    double e = 1e-5 * h;
    double w0 = flame_ref_w_visc(r, h), wp = flame_ref_w_visc(r + e, h), wm = flame_ref_w_visc(r - e, h);
    return (wp - 2 * w0 + wm) / (e * e) + 2 / r * (wp - wm) / (2 * e);
}

/* side³ lattice of spacing s centred on the origin, all gas at T, F, v = 0. */
static struct flame_ref_particle *tfr_lattice(int side, double s, double T, double F, int *n)
{
    struct flame_ref_particle *ps = calloc((size_t)side * side * side, sizeof *ps);
    int c = 0, half = side / 2;
    for (int i = 0; i < side; i++)
        for (int j = 0; j < side; j++)
            for (int k = 0; k < side; k++) {
                ps[c].r[0] = (i - half) * s;
                ps[c].r[1] = (j - half) * s;
                ps[c].r[2] = (k - half) * s;
                ps[c].T = T;
                ps[c].F = F;
                c++;
            }
    *n = c;
    return ps;
}

static int tfr_centre(int side) { return (side / 2) * side * side + (side / 2) * side + side / 2; }

static double tfr_norm(const double v[3]) { return sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }

/* ---------------------------------------------------------------- group A */

static void test_kernel_quadrature(void)
{
    double h = 0.01125;
    CHECK_NEAR(tfr_ball_integral(flame_ref_w_poly6, h), 1.0, 1e-3);
    CHECK_NEAR(tfr_ball_integral(flame_ref_w_spiky, h), 1.0, 1e-3);
    CHECK_NEAR(tfr_ball_integral(flame_ref_w_visc, h), 1.0, 1e-3);
    CHECK_NEAR(tfr_ball_integral(flame_ref_w_poly6, 0.004), 1.0, 1e-3);
}

static void test_kernel_support(void)
{
    double h = 0.01125, x[3] = {0, 0.6 * h, 0.8 * h}, far[3] = {0, 0, 1.5 * h}, g[3];
    const double rs[] = {h, 1.0000001 * h, 2 * h, 1e3 * h};
    for (int k = 0; k < 4; k++) {
        CHECK(flame_ref_w_poly6(rs[k], h) == 0, "poly6(%g h)", rs[k] / h);
        CHECK(flame_ref_w_spiky(rs[k], h) == 0, "spiky(%g h)", rs[k] / h);
        CHECK(flame_ref_w_visc(rs[k], h) == 0, "visc(%g h)", rs[k] / h);
        CHECK(flame_ref_lap_visc(rs[k], h) == 0, "lap visc(%g h)", rs[k] / h);
    }
    flame_ref_grad_spiky(x, h, g); /* |x| = h exactly */
    CHECK(g[0] == 0 && g[1] == 0 && g[2] == 0, "spiky gradient at r = h: %g %g %g", g[0], g[1], g[2]);
    flame_ref_grad_poly6(far, h, g);
    CHECK(g[2] == 0, "poly6 gradient beyond h: %g", g[2]);
    flame_ref_grad_spiky(far, h, g);
    CHECK(g[2] == 0, "spiky gradient beyond h: %g", g[2]);
}

/* ∇W_spiky points toward the origin (along -x) and matches d/dr of W_spiky. */
static void test_spiky_gradient_sign(void)
{
    double h = 0.01125;
    for (int k = 1; k < 10; k++) {
        double r = k * 0.1 * h, x[3] = {0.48 * r, -0.6 * r, 0.64 * r}, g[3];
        flame_ref_grad_spiky(x, h, g);
        double dot = g[0] * x[0] + g[1] * x[1] + g[2] * x[2];
        CHECK(dot < 0, "r = %g h: dot(∇W, x) = %g must be < 0", r / h, dot);
        double e = 1e-7 * h, fd = (flame_ref_w_spiky(r + e, h) - flame_ref_w_spiky(r - e, h)) / (2 * e);
        CHECK(fabs(-tfr_norm(g) - fd) <= 1e-5 * fabs(fd), "|∇W| %g vs dW/dr %g", tfr_norm(g), fd);
    }
}

/* ∇W_poly6 and ∇²W_visc against finite differences of W. */
static void test_kernel_derivatives(void)
{
    double h = 0.01125;
    for (int k = 1; k < 10; k++) {
        double r = k * 0.1 * h, x[3] = {0, 0, r}, g[3], e = 1e-7 * h;
        flame_ref_grad_poly6(x, h, g);
        double fd = (flame_ref_w_poly6(r + e, h) - flame_ref_w_poly6(r - e, h)) / (2 * e);
        CHECK(fabs(g[2] - fd) <= 1e-5 * fabs(fd) + 1e-9, "poly6 grad at %g h: %g vs %g", r / h, g[2], fd);
        double lap = flame_ref_lap_visc(r, h), lfd = tfr_lap_visc_fd(r, h);
        CHECK(fabs(lap - lfd) <= 1e-4 * lap, "visc laplacian at %g h: %g vs %g", r / h, lap, lfd);
    }
}

/* Lattice d = h/2, m = 1.7626e-7: interior ρ = 1.000 ± 0.5 % and 32 neighbours. */
static void test_lattice_density(void)
{
    struct flame_ref_params p;
    flame_ref_defaults(&p);
    int n;
    struct flame_ref_particle *ps = tfr_lattice(TFR_LAT, p.h / 2, p.T_amb, 0, &n);
    struct flame_ref_eval *ev = calloc((size_t)n, sizeof *ev);
    flame_ref_eval_all(&p, ps, n, ev);
    int c = tfr_centre(TFR_LAT);
    CHECK_NEAR(ev[c].rho, 1.0, 5e-3);
    CHECK(ev[c].nbr == 32, "interior neighbours %d, want 32", ev[c].nbr);
    CHECK(flame_ref_neighbours(&p, ps, n, c, NULL, 0) == 32, "brute-force neighbour count");
    CHECK_NEAR(flame_ref_lattice_mass(p.h, p.h / 2, 1.0), 1.7626e-7, 1e-11);
    CHECK(ev[0].nbr == 10 && ev[0].rho < 0.6, "corner: %d neighbours, rho %g", ev[0].nbr, ev[0].rho);
    free(ps);
    free(ev);
}

/* Uniform p, v, T, F: interior pressure and viscous forces and diffusion are zero. */
static void test_uniform_field(void)
{
    struct flame_ref_params p;
    flame_ref_defaults(&p);
    int n;
    struct flame_ref_particle *ps = tfr_lattice(TFR_LAT, p.h / 2, 800, 50, &n);
    for (int i = 0; i < n; i++) ps[i].v[0] = 0.3, ps[i].v[2] = -0.1;
    struct flame_ref_eval *ev = calloc((size_t)n, sizeof *ev);
    for (int form = 0; form < 2; form++) {
        p.symmetric_pressure = form;
        flame_ref_eval_all(&p, ps, n, ev);
        int c = tfr_centre(TFR_LAT);
        double fp = tfr_norm(ev[c].f_press), fv = tfr_norm(ev[c].f_visc);
        CHECK(fp < 1e-6 * fabs(ev[c].p) / p.h + 1e-9, "form %d: pressure force %g", form, fp);
        CHECK(fv == 0, "viscous force %g", fv);
        CHECK(ev[c].dT_diff == 0 && ev[c].dF_diff == 0, "diffusion %g %g", ev[c].dT_diff, ev[c].dF_diff);
        CHECK(tfr_norm(ev[c].n) < 1e-6, "colour normal %g", tfr_norm(ev[c].n));
        CHECK(ev[c].dT == 0 && ev[c].dF == 0, "T = 800 < T_ign: no reaction (%g %g)", ev[c].dT, ev[c].dF);
    }
    free(ps);
    free(ev);
}

/* Lattice compressed for x < 0: interior particles near the interface are pushed to +x. */
static void test_pressure_direction(void)
{
    struct flame_ref_params p;
    flame_ref_defaults(&p);
    int n;
    double d = p.h / 2;
    struct flame_ref_particle *ps = tfr_lattice(TFR_LAT, d, p.T_amb, 0, &n);
    for (int i = 0; i < n; i++)
        if (ps[i].r[0] < 0) ps[i].r[0] *= 0.8;
    struct flame_ref_eval *ev = calloc((size_t)n, sizeof *ev);
    for (int form = 0; form < 2; form++) {
        p.symmetric_pressure = form;
        p.rho_rest = form ? 0.5 : 1.0; /* symmetric form: positive pressures everywhere */
        flame_ref_eval_all(&p, ps, n, ev);
        for (int i = 0; i < n; i++) {
            int interior = fabs(ps[i].r[1]) < 1.5 * d && fabs(ps[i].r[2]) < 1.5 * d;
            if (!interior || fabs(ps[i].r[0]) > 1.1 * d) continue;
            CHECK(ev[i].f_press[0] > 0, "form %d x = %g: f_x %g must point to lower density", form,
                  ps[i].r[0], ev[i].f_press[0]);
        }
    }
    free(ps);
    free(ev);
}

/* Difference form: a symmetric pair feels no pressure force; isolated ρ = 0.1939. */
static void test_pair_and_isolated(void)
{
    struct flame_ref_params p;
    flame_ref_defaults(&p);
    struct flame_ref_particle ps[2] = {{.r = {0, 0, 0}, .T = 300}, {.r = {0.4 * p.h, 0.2 * p.h, 0}, .T = 300}};
    struct flame_ref_eval ev[2];
    flame_ref_eval_all(&p, ps, 2, ev);
    CHECK(tfr_norm(ev[0].f_press) == 0 && tfr_norm(ev[1].f_press) == 0, "pair pressure force %g %g",
          tfr_norm(ev[0].f_press), tfr_norm(ev[1].f_press));
    CHECK(ev[0].nbr == 1 && ev[1].nbr == 1, "pair neighbours");
    double iso = p.mass * 315.0 / (64 * M_PI * p.h * p.h * p.h);
    flame_ref_eval_all(&p, ps, 1, ev);
    CHECK_NEAR(ev[0].rho, iso, 1e-12);
    CHECK_NEAR(ev[0].rho, 0.1939, 5e-5);
    CHECK(ev[0].nbr == 0 && ev[0].flame_nbr == 0, "isolated counts");
}

/* The Müller normal points toward the neighbours (inward); insertion goes the other way. */
static void test_colour_normal(void)
{
    struct flame_ref_params p;
    flame_ref_defaults(&p);
    int n;
    struct flame_ref_particle *ps = tfr_lattice(5, p.h / 2, p.T_amb, 0, &n);
    struct flame_ref_eval *ev = calloc((size_t)n, sizeof *ev);
    flame_ref_eval_all(&p, ps, n, ev);
    int top = 2 * 25 + 2 * 5 + 4; /* (0, 0, +2d): on the top face */
    CHECK(ev[top].n[2] < 0 && fabs(ev[top].n[0]) < 1e-9 * fabs(ev[top].n[2]), "top normal %g %g %g",
          ev[top].n[0], ev[top].n[1], ev[top].n[2]);
    CHECK(ev[top].nbr < p.insert_nbr_threshold, "a face particle (%d neighbours) gets an insertion",
          ev[top].nbr);
    free(ps);
    free(ev);
}

/* ---------------------------------------------------------------- group B */

static void tfr_isolated(struct flame_ref_particle *q, double T, double F)
{
    memset(q, 0, sizeof *q);
    q->T = T;
    q->F = F;
}

static void test_worked_step(void)
{
    struct flame_ref_params p;
    flame_ref_defaults(&p);
    struct flame_ref_particle q;
    struct flame_ref_eval e;
    tfr_isolated(&q, 1200, 10);
    flame_ref_step(&p, &q, 1, &e);
    CHECK_NEAR(flame_ref_reaction(&p, 1200, 10), 120, 1e-12);
    CHECK_NEAR(q.T, 1260, 1e-9);
    CHECK_NEAR(q.F, 9.4, 1e-12);
}

/* E = T + 100F conserved; T follows the logistic curve within 1 %. */
static void test_invariant_logistic(void)
{
    struct flame_ref_params p;
    flame_ref_defaults(&p);
    struct flame_ref_particle q;
    tfr_isolated(&q, 1200, 10);
    double E0 = q.T + p.k_pt / p.k_cf * q.F, worst_e = 0, worst_l = 0;
    for (int s = 1; s <= 200; s++) {
        flame_ref_step(&p, &q, 1, NULL);
        double E = q.T + p.k_pt / p.k_cf * q.F;
        worst_e = fmax(worst_e, fabs(E - E0) / E0);
        double an = flame_ref_logistic_T(&p, 1200, 10, s * p.dt);
        worst_l = fmax(worst_l, fabs(q.T - an) / an);
    }
    CHECK(worst_e < 1e-12, "invariant drift %g", worst_e);
    CHECK(worst_l < 0.01, "logistic deviation %g", worst_l);
    CHECK(fabs(q.T - 2200) < 0.01 * 2200, "T(0.2 s) = %g, want → 2200", q.T);
}

static void test_no_ignition(void)
{
    struct flame_ref_params p;
    flame_ref_defaults(&p);
    const double cases[][2] = {{900, 10}, {1500, 0}, {1500, 0.0009}, {1000, 50}};
    for (int c = 0; c < 4; c++) {
        struct flame_ref_particle q;
        tfr_isolated(&q, cases[c][0], cases[c][1]);
        for (int s = 0; s < 300; s++) flame_ref_step(&p, &q, 1, NULL);
        CHECK(q.T == cases[c][0] && q.F == cases[c][1], "T0 %g F0 %g -> %g %g", cases[c][0], cases[c][1], q.T,
              q.F);
    }
}

/* Δv_z per step = dt k_buo (T - T_amb)/ρ exactly; no vertical motion at T_amb. */
static void test_buoyancy(void)
{
    struct flame_ref_params p;
    flame_ref_defaults(&p);
    struct flame_ref_particle q;
    tfr_isolated(&q, 2000, 0);
    double rho = p.mass * 315.0 / (64 * M_PI * pow(p.h, 3)), want = p.dt * p.k_buo * 1700 / rho;
    for (int s = 1; s <= 5; s++) {
        double v0 = q.v[2];
        flame_ref_step(&p, &q, 1, NULL);
        CHECK_NEAR(q.v[2] - v0, want, 1e-12 * want);
        CHECK(q.T == 2000 && q.v[0] == 0 && q.v[1] == 0, "T %g vx %g vy %g", q.T, q.v[0], q.v[1]);
    }
    tfr_isolated(&q, p.T_amb, 0);
    for (int s = 0; s < 5; s++) flame_ref_step(&p, &q, 1, NULL);
    CHECK(q.v[2] == 0 && q.r[2] == 0, "v_z %g at T_amb", q.v[2]);
}

/* §2.14 drag: across up, v − wind_velocity decays as exp(−k t) (exact at every step, so n
 * steps match the continuous solution); along up v is untouched (buoyancy stays the net
 * vertical force); wind_drag 0 changes nothing. */
static void test_drag(void)
{
    struct flame_ref_params p;
    flame_ref_defaults(&p);
    CHECK(p.wind_drag == 0, "the digest's default has no drag: %g", p.wind_drag);
    p.dt = 0.003;
    p.wind_drag = 30;
    p.k_buo = 0;
    const double w[3] = {2, -1, 5};
    memcpy(p.wind_velocity, w, sizeof w);
    struct flame_ref_particle q;
    tfr_isolated(&q, p.T_amb, 0);
    q.v[0] = 0.5, q.v[1] = 0.5, q.v[2] = 1;
    for (int s = 1; s <= 20; s++) {
        flame_ref_step(&p, &q, 1, NULL);
        double decay = exp(-p.wind_drag * s * p.dt);
        CHECK_NEAR(q.v[0], w[0] + (0.5 - w[0]) * decay, 1e-12);
        CHECK_NEAR(q.v[1], w[1] + (0.5 - w[1]) * decay, 1e-12);
        CHECK(q.v[2] == 1, "step %d: v along up %g", s, q.v[2]);
    }
    /* another up: the drag acts on x and z, y is along up */
    double up[3] = {0, 1, 0}, v[3] = {0.5, 0.5, 1};
    memcpy(p.up, up, sizeof up);
    flame_ref_drag(&p, v);
    double keep = exp(-p.wind_drag * p.dt);
    CHECK_NEAR(v[0], w[0] + (0.5 - w[0]) * keep, 1e-12);
    CHECK_NEAR(v[2], w[2] + (1 - w[2]) * keep, 1e-12);
    CHECK(v[1] == 0.5, "v along up %g", v[1]);
    p.wind_drag = 0;
    flame_ref_drag(&p, v);
    CHECK_NEAR(v[0], w[0] + (0.5 - w[0]) * keep, 1e-12);
}

/* Literal fuel diffusion overshoots (λ ≫ 1); the stabilised form stays a convex mix. */
static void test_stabilised_diffusion(void)
{
    struct flame_ref_params p;
    flame_ref_defaults(&p);
    int n;
    struct flame_ref_particle *ps = tfr_lattice(7, p.h / 2, 1800, 0, &n);
    int c = tfr_centre(7);
    ps[c].F = 100;
    ps[c].T = 900; /* below T_ign: pure diffusion */
    struct flame_ref_eval *ev = calloc((size_t)n, sizeof *ev);
    flame_ref_eval_all(&p, ps, n, ev);
    double Fnew = ps[c].F + p.dt * ev[c].dF, Tnew = ps[c].T + p.dt * ev[c].dT;
    CHECK(Fnew >= 0 && Fnew <= 100, "stabilised F %g", Fnew);
    CHECK(Tnew >= 900 && Tnew <= 1800, "stabilised T %g", Tnew);
    p.stabilized = 0;
    flame_ref_eval_all(&p, ps, n, ev);
    CHECK(ps[c].F + p.dt * ev[c].dF < 0, "literal fuel diffusion overshoots: %g", ps[c].F + p.dt * ev[c].dF);
    free(ps);
    free(ev);
}

static void test_obstacle_source(void)
{
    struct flame_ref_params p;
    flame_ref_defaults(&p);
    struct flame_ref_particle ps[2] = {{.r = {0, 0, 0}, .T = 2000, .F = 100, .type = FLAME_REF_SOURCE},
                                       {.r = {0, 0.5 * p.h, 0}, .v = {0, -0.2, 0}, .T = 300,
                                        .type = FLAME_REF_OBSTACLE}};
    for (int s = 1; s <= 10; s++) flame_ref_step(&p, ps, 2, NULL);
    CHECK(ps[0].T == 2000 && ps[0].F == 100 && ps[0].r[2] == 0, "source moved or changed");
    CHECK_NEAR(ps[1].r[1], 0.5 * p.h - 10 * 0.001 * 0.2, 1e-15);
    CHECK(ps[1].T == 300 && ps[1].F == 0, "obstacle T/F changed");
}

static void test_params_json(void)
{
    struct flame_ref_params p;
    flame_ref_defaults(&p);
    cJSON *doc = cJSON_Parse("{\"h\":0.02,\"k_buo\":0.03,\"T_amb\":310,\"up\":[0,2,0],"
                             "\"diffusion_mode\":\"literal\",\"pressure_form\":\"symmetric\","
                             "\"particle_diameter\":0.4,\"wind_accel\":[1,0,0],\"wind_velocity\":[0,2,0],"
                             "\"wind_drag\":25}");
    int got = flame_ref_params_from_json(doc, &p);
    CHECK(got == 10, "read %d", got);
    CHECK(p.wind_velocity[1] == 2 && p.wind_drag == 25, "wind velocity %g, drag %g", p.wind_velocity[1], p.wind_drag);
    CHECK(p.h == 0.02 && p.k_buo == 0.03 && p.T_amb == 310 && p.up[1] == 1, "values");
    CHECK(!p.stabilized && p.symmetric_pressure && fabs(p.d - 0.008) < 1e-15 && p.wind[0] == 1, "modes");
    cJSON_Delete(doc);
}

int main(void)
{
    RUN(test_kernel_quadrature);
    RUN(test_kernel_support);
    RUN(test_spiky_gradient_sign);
    RUN(test_kernel_derivatives);
    RUN(test_lattice_density);
    RUN(test_uniform_field);
    RUN(test_pressure_direction);
    RUN(test_pair_and_isolated);
    RUN(test_colour_normal);
    RUN(test_worked_step);
    RUN(test_invariant_logistic);
    RUN(test_no_ignition);
    RUN(test_buoyancy);
    RUN(test_drag);
    RUN(test_stabilised_diffusion);
    RUN(test_obstacle_source);
    RUN(test_params_json);
    return CHECK_DONE();
}
