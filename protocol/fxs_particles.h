/* fxs_particles.h — the particle frame codec of protocol fxstream.v1 (kind 1 frames).
 *
 * One implementation shared by the daemon (encode) and libfxclient (decode), compiled
 * into both libraries, so the two sides cannot disagree. The byte layout is specified
 * in protocol/PROTOCOL.md; clients/web has the JavaScript decoder. */
#ifndef FXS_PARTICLES_H
#define FXS_PARTICLES_H

#include <stddef.h>
#include <stdint.h>

/* Codec id of kind 1 payloads in the frame header. */
#define FXS_CODEC_PARTICLES 1u

/* Particles as the encoder takes them and the decoder returns them. */
struct fxs_particles {
    uint32_t n;
    float *xyz;      /* 3n */
    float *temp;     /* n, kelvin */
    float *fuel;     /* n */
    uint8_t *flags;  /* n: enum flame_flag bits (type, flame) */
};

struct fxs_particles_opts {
    int pos_bits;    /* quantisation of each coordinate relative to the frame's bounds, 8..24 */
};

/* Encodes p into a newly allocated buffer (*out, *out_len; free()). Returns 0, or -1 with
 * a message in err (errlen bytes). */
int fxs_particles_encode(const struct fxs_particles *p, const struct fxs_particles_opts *opts, uint8_t **out,
                         size_t *out_len, char *err, size_t errlen);
/* Decodes a payload into p (arrays allocated; free with fxs_particles_free). Returns 0,
 * or -1 with a message: truncated, corrupt or oversized input never reads out of bounds. */
int fxs_particles_decode(const uint8_t *buf, size_t len, struct fxs_particles *p, char *err, size_t errlen);
void fxs_particles_free(struct fxs_particles *p);

#endif
