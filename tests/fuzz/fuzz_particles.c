/* fuzz_particles.c — libFuzzer target: the particle decoder (protocol/fxs_particles_dec.c) on
 * raw payloads. Whatever decodes must re-encode and decode to the same count, with every
 * position and velocity finite (the decoder reconstructs from finite bounds) and velocities
 * after the round trip exactly when the input had them. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

#include "fxs_particles.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    struct fxs_particles p, q;
    char msg[256];
    if (fxs_particles_decode(data, size, &p, msg, sizeof msg)) return 0;
    for (uint32_t i = 0; i < 3 * p.n; i++)
        if (!isfinite(p.xyz[i]) || (p.vel && !isfinite(p.vel[i]))) abort();
    uint8_t *buf;
    size_t len;
    struct fxs_particles_opts o = {0};
    if (fxs_particles_encode(&p, &o, &buf, &len, msg, sizeof msg)) abort();
    if (fxs_particles_decode(buf, len, &q, msg, sizeof msg) || q.n != p.n || !q.vel != !p.vel) abort();
    fxs_particles_free(&q);
    free(buf);
    fxs_particles_free(&p);
    return 0;
}
