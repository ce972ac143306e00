/* frame_plan.h — pacing of a fixed-step simulation: how many substeps of dt each frame of a
 * stream runs, so that simulated time keeps up with the wall clock (time_scale), and what a
 * frame cut short does with the time it left undone.
 *
 * A frame owes round(wall dt x time_scale / dt) substeps, the fraction carried to the next
 * frame, at most max_substeps (then the stream runs slower than real time and /metrics shows
 * its real-time factor). The substeps get the frame period less the last frame's read-back and
 * encoding (emit_ms) and a margin; as many run as fit at the recent time per substep. The plan
 * comes from the average of earlier frames, since the clock can only be read where the host
 * waits for the device (sync points): deciding there, all or nothing per interval, would leave
 * much of each period idle. The fraction of a substep a cut frame could not use goes to the
 * next frame's budget (rounding down every frame would waste half a substep a frame), and the
 * simulated time a cut frame leaves undone is carried up to one frame's worth, so a frame
 * slowed by the host catches up in the next ones; beyond that it is dropped, and a scene too
 * slow for the machine streams at a steady frame rate. A frame still stops at a sync point once
 * it is over budget. One substep of the next frame may run beside a frame's encoding (the
 * device is otherwise idle then); it counts against the next frame's substeps. Times are the
 * frame's own: the engine may run other streams between its slices (effect.h).
 *
 * The plan is pure bookkeeping around a simulation's callbacks, so it is tested without
 * OpenCL (test_frame_plan). */
#ifndef FX_FRAME_PLAN_H
#define FX_FRAME_PLAN_H

#include <stdbool.h>

#include "err.h"

#define FRAME_PLAN_MARGIN_MS 1.0 /* frame period kept free beyond the substeps and the frame's encoding */

struct frame_plan {
    /* settings (frame_plan_set) */
    double dt;        /* simulated seconds of a substep */
    double period_ms; /* wall time of a frame, 1000 / fps */
    double time_scale;
    int max_substeps;
    /* across frames */
    double carry;     /* simulated seconds owed to the coming frames (< 0: run ahead) */
    double step_ms;   /* recent wall time per substep (moving average; 0 = none yet) */
    double fit_frac;  /* the fraction of a substep that the budgets of frames cut short left over */
    double emit_ms;   /* wall time of the last frame's read-back and encoding, with the substep beside it */
    int ahead;        /* substeps of the coming frame already run beside the last encoding (0 or 1) */
    /* the frame in progress, which may run over several slices: planned, done, its time budget
     * and the time its substeps took so far (ms) */
    bool busy;
    int n, done;
    double budget_ms, spent_ms;
};

/* What the plan drives: one substep, whether the next one is a sync point (the host waits for
 * the device there, so the clock tells the time the substeps took), draining the queue, and the
 * clock (milliseconds, monotonic). */
struct frame_plan_sim {
    void *self;
    int (*substep)(void *self, struct fx_err *err);
    bool (*syncs)(void *self);
    int (*finish)(void *self, struct fx_err *err);
    double (*now_ms)(void *self);
};

/* New settings (a live parameter change keeps the carry and the timing). */
void frame_plan_set(struct frame_plan *p, double dt, double fps, double time_scale, int max_substeps);
/* A fresh start (create, reset): nothing owed, no frame in progress. */
void frame_plan_reset(struct frame_plan *p);

/* Plans a frame dt_wall seconds after the last: sets n and the budget, marks it busy. */
void frame_plan_begin(struct frame_plan *p, double dt_wall);
/* Runs the planned substeps until slice_end (clock seconds, INFINITY: no limit): it stops before
 * a substep that would end after it, at the recent time per substep, once one ran; the queue
 * is then drained. 0 when the frame's substeps are done (or its budget cut them short: the
 * rest is carried), EFFECT_MORE, or -1 with err; busy stays set only with EFFECT_MORE. */
int frame_plan_run(struct frame_plan *p, const struct frame_plan_sim *sim, double slice_end, struct fx_err *err);
/* Drops the frame in progress (a parameter change), its undone substeps carried. */
void frame_plan_abandon(struct frame_plan *p);
/* Passes `undone` substeps on to the next frames, up to one frame's worth of simulated time. */
void frame_plan_carry(struct frame_plan *p, int undone);

/* Whether a substep of the coming frame should run beside this frame's encoding (the coming
 * frame will step at all); when it should, it is booked against that frame. */
bool frame_plan_run_ahead(struct frame_plan *p);
/* Records the wall time of the frame's read-back and encoding (the next budget leaves it out). */
void frame_plan_emitted(struct frame_plan *p, double emit_ms);

#endif
