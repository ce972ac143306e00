/* test_frame_plan.c — the pacing of a fixed-step simulation's frames (frame_plan.h), without
 * OpenCL: the substeps a frame owes with the fraction carried, max_substeps, frames cut to the
 * time budget (the undone time carried up to a frame's worth, the fit fraction passed on), the
 * substep run ahead of the next frame, slices and the budget check at sync points. The
 * simulation is a counter and the clock a number the substeps advance. */
#include <math.h>

#include "check.h"
#include "effect.h"
#include "frame_plan.h"

/* A simulation whose substeps take cost_ms on its own clock and sync every `every` substeps. */
struct tfp_sim {
    int substeps, finishes, every;
    double clock_ms, cost_ms;
};

static int tfp_substep(void *self, struct fx_err *err)
{
    struct tfp_sim *s = self;
    (void)err;
    s->substeps++;
    s->clock_ms += s->cost_ms;
    return 0;
}

static bool tfp_syncs(void *self)
{
    struct tfp_sim *s = self;
    return s->substeps % s->every == 0;
}

static int tfp_finish(void *self, struct fx_err *err)
{
    (void)err;
    ((struct tfp_sim *)self)->finishes++;
    return 0;
}

static double tfp_now_ms(void *self) { return ((struct tfp_sim *)self)->clock_ms; }

static struct frame_plan_sim tfp_ops(struct tfp_sim *s)
{
    return (struct frame_plan_sim){s, tfp_substep, tfp_syncs, tfp_finish, tfp_now_ms};
}

/* A plan of dt 3 ms at 30 frames/s in real time, at most 24 substeps. */
static struct frame_plan tfp_plan(double time_scale)
{
    struct frame_plan p = {0};
    frame_plan_set(&p, 0.003, 30, time_scale, 24);
    frame_plan_reset(&p);
    return p;
}

/* Without timing yet, a frame owes round(1/30 / dt) substeps and the fraction is carried: 30
 * frames simulate one second to within half a substep. */
static void test_real_time(void)
{
    struct frame_plan p = tfp_plan(1);
    int total = 0;
    for (int f = 0; f < 30; f++) {
        frame_plan_begin(&p, 1.0 / 30);
        CHECK(p.busy && (p.n == 11 || p.n == 12), "frame %d: %d substeps", f, p.n);
        total += p.n;
        p.busy = false;
        CHECK(fabs(p.carry) <= 0.5 * p.dt + 1e-12, "frame %d: carry %g", f, p.carry);
    }
    CHECK_NEAR(total * 0.003, 1.0, 0.0015);
}

/* Past max_substeps the stream runs slower than real time: the excess is dropped, not owed. */
static void test_max_substeps(void)
{
    struct frame_plan p = tfp_plan(10);
    frame_plan_begin(&p, 1.0 / 30);
    CHECK(p.n == 24 && p.carry == 0, "%d substeps, carry %g", p.n, p.carry);
    p.busy = false;
    /* the substep run ahead beside the encoding counts against the next frame's 24 */
    CHECK(frame_plan_run_ahead(&p), "no substep ahead");
    frame_plan_begin(&p, 1.0 / 30);
    CHECK(p.n == 23, "%d substeps after one ahead", p.n);
}

/* A frame whose substeps do not fit its budget is cut to what fits; the undone time is carried
 * up to one frame's worth, and the fraction of a substep the budget left passes on, so frames
 * cut at 3.25 substeps' worth run 3, 3, 3, 4, ... (13 in 4 frames), not 3 each. */
static void test_cut_frames(void)
{
    struct frame_plan p = tfp_plan(1);
    p.emit_ms = 1000.0 / 30 - FRAME_PLAN_MARGIN_MS - 26; /* a budget of 26 ms */
    p.step_ms = 8;                                       /* 3.25 substeps fit */
    int total = 0;
    for (int f = 0; f < 4; f++) {
        frame_plan_begin(&p, 1.0 / 30);
        CHECK_NEAR(p.budget_ms, 26, 1e-9);
        total += p.n;
        p.busy = false;
        CHECK(p.carry <= 1.0 / 30 + 1e-12, "frame %d: carry %g beyond a frame's worth", f, p.carry);
        CHECK(p.fit_frac >= 0 && p.fit_frac < 1, "fit fraction %g", p.fit_frac);
    }
    CHECK(total == 13, "%d substeps in 4 cut frames", total);
    /* the budget is at least half the period, however long the last encoding took */
    p.emit_ms = 1000;
    frame_plan_begin(&p, 1.0 / 30);
    CHECK_NEAR(p.budget_ms, 500.0 / 30, 1e-9);
}

/* Paused (time_scale 0): nothing owed, nothing run ahead. */
static void test_paused(void)
{
    struct frame_plan p = tfp_plan(0);
    frame_plan_begin(&p, 1.0 / 30);
    CHECK(p.n == 0, "%d substeps while paused", p.n);
    CHECK(!frame_plan_run_ahead(&p), "a substep ahead while paused");
}

/* A frame run in slices stops before a substep that would end past the slice, and goes on at
 * the next call; a substep that syncs past the budget cuts the frame there, the rest carried. */
static void test_run_slices_and_budget(void)
{
    struct frame_plan p = tfp_plan(1);
    struct tfp_sim s = {.every = 5, .clock_ms = 1000, .cost_ms = 2};
    struct frame_plan_sim ops = tfp_ops(&s);
    struct fx_err err = {0};
    p.step_ms = 2;
    frame_plan_begin(&p, 1.0 / 30);
    int n = p.n, rc = frame_plan_run(&p, &ops, (s.clock_ms + 5) / 1e3, &err);
    CHECK(rc == EFFECT_MORE && p.busy && p.done == 2 && s.finishes == 1, "rc %d, %d done, busy %d", rc, p.done, p.busy);
    int calls = 1;
    while (rc == EFFECT_MORE && calls < 100) {
        rc = frame_plan_run(&p, &ops, (s.clock_ms + 5) / 1e3, &err);
        calls++;
    }
    CHECK(rc == 0 && !p.busy && p.done == n && s.substeps == n, "rc %d: %d of %d substeps", rc, s.substeps, n);
    CHECK(calls > 2, "%d calls", calls);
    CHECK_NEAR(p.step_ms, 2, 1e-9);

    /* substeps that take 10 ms where 2 were expected: the frame stops at the first sync point
     * over its budget (substeps 0 and 5 sync: at 60 ms, after the sixth, of a 32 ms budget),
     * and what it left is owed to the next frames */
    struct frame_plan q = tfp_plan(1);
    struct tfp_sim slow = {.every = 5, .clock_ms = 0, .cost_ms = 10};
    struct frame_plan_sim sops = tfp_ops(&slow);
    q.step_ms = 2;
    frame_plan_begin(&q, 1.0 / 30);
    double carry0 = q.carry;
    int planned = q.n;
    rc = frame_plan_run(&q, &sops, INFINITY, &err);
    CHECK(rc == 0 && q.done == 6 && q.n == 6 && slow.substeps == 6, "rc %d: %d of %d planned", rc, q.done, planned);
    CHECK_NEAR(q.carry, fmin(carry0 + (planned - 6) * q.dt, 1.0 / 30), 1e-12);
}

/* A parameter change drops the frame in progress; its undone substeps are owed. */
static void test_abandon(void)
{
    struct frame_plan p = tfp_plan(1);
    frame_plan_begin(&p, 1.0 / 30);
    double carry0 = p.carry;
    p.done = 4;
    frame_plan_abandon(&p);
    CHECK(!p.busy, "still busy");
    CHECK_NEAR(p.carry, carry0 + (p.n - 4) * p.dt, 1e-12);
    frame_plan_reset(&p);
    CHECK(p.carry == 0 && p.ahead == 0 && !p.busy, "reset kept state");
}

int main(void)
{
    RUN(test_real_time);
    RUN(test_max_substeps);
    RUN(test_cut_frames);
    RUN(test_paused);
    RUN(test_run_slices_and_budget);
    RUN(test_abandon);
    return CHECK_DONE();
}
