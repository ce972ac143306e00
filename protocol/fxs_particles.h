/* fxs_particles.h — the particle frame codec of protocol fxstream.v1 (kind 1 frames).
 *
 * One implementation shared by the daemon (encode) and libfxclient (decode), compiled
 * into both libraries, so the two sides cannot disagree. The byte layout is specified
 * in protocol/PROTOCOL.md; clients/web has the JavaScript decoder. */
#ifndef FXS_PARTICLES_H
#define FXS_PARTICLES_H

#include <stddef.h>
#include <stdint.h>

#include "fxs_frame.h" /* the codec ids: FXS_CODEC_PARTICLES, FXS_CODEC_PARTICLES_BLOCKS */

/* Particles as the encoder takes them and the decoder returns them. */
struct fxs_particles {
    uint32_t n;
    float *xyz;      /* 3n */
    float *temp;     /* n, kelvin */
    float *fuel;     /* n */
    uint8_t *flags;  /* n: enum flame_flag bits (type, flame) */
    float *vel;      /* 3n velocities (vx, vy, vz), or NULL: none. The encoder sends them when
                      * set (PROTOCOL.md §7.5.7); the decoder sets it only for payloads that
                      * carry them */
};

struct fxs_particles_opts {
    /* Positions: one step for all three axes, (largest extent of the frame's bounding box)
     * / (2^pos_bits - 1) (as Draco's -qp), 8..24. 0 = default. */
    int pos_bits;
    /* Bits of temperature and fuel relative to the frame's [min, max] of each, 2..16
     * (0 = default). Defaults below. */
    int temp_bits;
    int fuel_bits;
    /* Bits of each velocity component, sign included, 2..16 (0 = default): one step per axis,
     * (largest |v| of that axis) / (2^(vel_bits-1) - 1). Used only when p->vel is set. */
    int vel_bits;
    /* Threads to encode on (0 or 1: one). With more, a frame of at least
     * 2 * FXS_PARTICLES_BLOCK_MIN particles is cut into up to that many blocks of slabs along
     * its longest axis, quantised on the frame's common grid and coded in parallel (codec 3,
     * PROTOCOL.md §7.5.8); fxs_particles_codec tells which codec a payload is. */
    int threads;
};

#define FXS_PARTICLES_DEFAULT_POS_BITS 16
#define FXS_PARTICLES_DEFAULT_TEMP_BITS 10
#define FXS_PARTICLES_DEFAULT_FUEL_BITS 8
#define FXS_PARTICLES_DEFAULT_VEL_BITS 8
/* Most particles one payload may declare; the decoder rejects more (decompression bombs). */
#define FXS_PARTICLES_MAX_N (1u << 22)
/* Fewest particles an encoder puts in a block of its own, and most blocks a payload may
 * hold (decoders reject more, §7.5.8). */
#define FXS_PARTICLES_BLOCK_MIN 4096u
#define FXS_PARTICLES_MAX_BLOCKS 64u
/* Bytes of the payload's own header (PROTOCOL.md §7.5.1), and of the velocity block that
 * follows it in payloads with velocities (§7.5.7). */
#define FXS_PARTICLES_HEADER_BYTES 64u
#define FXS_PARTICLES_VEL_BLOCK_BYTES 16u

/* Encodes p into a newly allocated buffer (*out, *out_len; free()). Returns 0, or -1 with
 * a message in err (errlen bytes). */
int fxs_particles_encode(const struct fxs_particles *p, const struct fxs_particles_opts *opts, uint8_t **out,
                         size_t *out_len, char *err, size_t errlen);
/* The codec of an encoded payload: FXS_CODEC_PARTICLES_BLOCKS when it holds more than one
 * block, else FXS_CODEC_PARTICLES. */
uint32_t fxs_particles_codec(const uint8_t *payload, size_t len);
/* Decodes a payload of one or more blocks (codec 2 or 3) into p (arrays allocated; free with
 * fxs_particles_free). Returns 0, or -1 with a message: truncated, corrupt or oversized input
 * never reads out of bounds. */
int fxs_particles_decode(const uint8_t *buf, size_t len, struct fxs_particles *p, char *err, size_t errlen);
/* The particle count of a payload and whether it carries velocities, from its block headers
 * (checked, the sections not decoded). 0, or -1 with a message. */
int fxs_particles_info(const uint8_t *buf, size_t len, uint32_t *n, int *vel, char *err, size_t errlen);
/* Decodes into the caller's arrays of `capacity` particles: p->xyz, p->temp and p->flags are
 * required, p->fuel and p->vel may be NULL (not written). Returns 0 with p->n set; 1 when the
 * payload holds more than capacity particles (p->n = how many, nothing written); -1 with a
 * message as fxs_particles_decode. */
int fxs_particles_decode_into(const uint8_t *buf, size_t len, struct fxs_particles *p, uint32_t capacity, char *err,
                              size_t errlen);
void fxs_particles_free(struct fxs_particles *p);

#endif
