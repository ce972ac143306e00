/* flame_effect.h — effect `flame` as the engine runs it: the effect_ops (registered in
 * registry.c) over a simulation (flame.h) paced by a frame plan (frame_plan.h), streamed as
 * kind 1 particle frames. */
#ifndef FX_FLAME_EFFECT_H
#define FX_FLAME_EFFECT_H

#include "../effect.h"

struct flame;

extern const struct effect_ops flame_effect;

/* The simulation of a state flame_effect.create made, for tests and benches that step or read
 * it directly (flame.h). */
struct flame *flame_effect_sim(void *state);

#endif
