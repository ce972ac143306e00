/* frame_plan.c — pacing of a fixed-step simulation's frames (frame_plan.h): the plan of a
 * frame, its substeps run in slices, and the carry of what a cut frame left undone. */
#include "frame_plan.h"

#include <math.h>

#include "effect.h" /* EFFECT_MORE */

/* Simulated seconds one frame of the stream covers. */
static double frame_plan_frame_sim(const struct frame_plan *p) { return p->period_ms * 1e-3 * p->time_scale; }

void frame_plan_set(struct frame_plan *p, double dt, double fps, double time_scale, int max_substeps)
{
    p->dt = dt;
    p->period_ms = 1000.0 / fps;
    p->time_scale = time_scale;
    p->max_substeps = max_substeps;
}

void frame_plan_reset(struct frame_plan *p)
{
    p->carry = 0;
    p->ahead = 0;
    p->busy = false;
}

void frame_plan_carry(struct frame_plan *p, int undone)
{
    p->carry = fmin(p->carry + undone * p->dt, frame_plan_frame_sim(p));
}

void frame_plan_begin(struct frame_plan *p, double dt_wall)
{
    p->carry += dt_wall * p->time_scale;
    /* The substeps this frame owes: none when the one run ahead covered them (carry < 0), and
     * at most max_substeps counting that one. */
    int n = (int)fmax(floor(p->carry / p->dt + 0.5), 0), most = p->max_substeps - p->ahead;
    p->ahead = 0;
    if (n > most) {
        n = most;
        p->carry = 0;
    } else {
        p->carry -= n * p->dt;
    }
    /* The budget: the period less the last frame's read-back and encoding and a margin, at
     * least half the period; as many substeps as fit at the recent time per substep. */
    double budget = fmax(p->period_ms - p->emit_ms - FRAME_PLAN_MARGIN_MS, 0.5 * p->period_ms);
    double fitf = p->step_ms > 0 ? budget / p->step_ms + p->fit_frac : n;
    int fit = (int)fitf;
    p->fit_frac = 0;
    if (n > fit) {
        int cut = fit > 1 ? fit : 1;
        frame_plan_carry(p, n - cut);
        n = cut;
        p->fit_frac = fmax(fitf - n, 0); /* < 1: n = floor(fitf), or 1 when fitf < 1 */
    }
    p->busy = true;
    p->n = n;
    p->done = 0;
    p->budget_ms = budget;
    p->spent_ms = 0;
}

int frame_plan_run(struct frame_plan *p, const struct frame_plan_sim *sim, double slice_end, struct fx_err *err)
{
    double t0 = sim->now_ms(sim->self), synced_ms = t0, end_ms = slice_end * 1e3;
    int ran = 0, since_sync = 0;
    while (p->done < p->n) {
        if (ran && p->step_ms > 0 && synced_ms + (since_sync + 1) * p->step_ms > end_ms) {
            if (sim->finish(sim->self, err)) {
                p->busy = false;
                return -1;
            }
            p->spent_ms += sim->now_ms(sim->self) - t0;
            return EFFECT_MORE;
        }
        bool synced = sim->syncs(sim->self);
        if (sim->substep(sim->self, err)) {
            p->busy = false;
            return -1;
        }
        p->done++;
        ran++;
        since_sync++;
        if (!synced) continue;
        synced_ms = sim->now_ms(sim->self); /* the sync point waited for the device */
        since_sync = 0;
        if (p->done < p->n && p->spent_ms + synced_ms - t0 > p->budget_ms) {
            frame_plan_carry(p, p->n - p->done);
            p->n = p->done;
        }
    }
    p->busy = false;
    if (ran && sim->finish(sim->self, err)) return -1;
    p->spent_ms += sim->now_ms(sim->self) - t0;
    if (p->done > 0) {
        double per = p->spent_ms / p->done;
        p->step_ms = p->step_ms > 0 ? 0.7 * p->step_ms + 0.3 * per : per;
    }
    return 0;
}

void frame_plan_abandon(struct frame_plan *p)
{
    if (p->busy) frame_plan_carry(p, p->n - p->done);
    p->busy = false;
}

bool frame_plan_run_ahead(struct frame_plan *p)
{
    if (!(p->time_scale > 0 && p->carry + frame_plan_frame_sim(p) >= 0.5 * p->dt)) return false;
    p->carry -= p->dt;
    p->ahead = 1;
    return true;
}

void frame_plan_emitted(struct frame_plan *p, double emit_ms) { p->emit_ms = emit_ms; }
