/* fxs_engine.h — the engine encoding of protocol fxstream.v1 (PROTOCOL.md §7.8): kind 1 and
 * kind 2 payloads that a game engine turns into a texture with built-in calls and no loop over
 * particles or pixels (Godot 3: PoolByteArray.decompress, Image.create_from_data). A payload is
 * a 48-byte header and one zstd frame of raw half-float texels:
 *   particles: RGBA16F, one texel per particle, FXS_ENGINE_PARTICLE_WIDTH texels a row, rows
 *              padded with zeros: (x, y, z) - origin, temperature in K; with velocities a second
 *              layer of the same size below it: (vx, vy, vz, 0);
 *   textures:  the frame's texels, R16F (one channel) or RGBA16F (four), row 0 at the top.
 *
 * Shared by the daemon (encoder, server/engine.c) and libfxclient (decoder, fxctl), as
 * fxs_particles.h is. Depends on libc and libzstd only. */
#ifndef FXS_ENGINE_H
#define FXS_ENGINE_H

#include <stddef.h>
#include <stdint.h>

#include "fxs_frame.h" /* FXS_CODEC_ENGINE, the frame header's codec of these payloads */
#include "fxs_particles.h"

#define FXS_ENGINE_MAGIC "FXE1"
#define FXS_ENGINE_VERSION 1u
#define FXS_ENGINE_HEADER_BYTES 64u
/* Texels a row of a particle payload: within every GPU's texture limits up to 2^22 particles. */
#define FXS_ENGINE_PARTICLE_WIDTH 1024u
/* Most texels (width x height x layers) one payload may hold; decoders reject more. */
#define FXS_ENGINE_MAX_TEXELS (1u << 24)
#define FXS_ENGINE_FLAG_VELOCITIES 1u
/* zstd level the daemon encodes with (zstd's default: within 1% of level 1's speed on these
 * payloads, 1-6% smaller). */
#define FXS_ENGINE_ZSTD_LEVEL 3

enum fxs_engine_format {
    FXS_ENGINE_RGBA16F = 1, /* 4 halves a texel, 8 bytes */
    FXS_ENGINE_R16F = 2,    /* 1 half a texel, 2 bytes */
};

/* The payload header. */
struct fxs_engine_info {
    uint32_t format;   /* enum fxs_engine_format */
    uint32_t layers;   /* images stacked top to bottom: 1, or 2 (particles with velocities) */
    uint32_t width;    /* texels a row */
    uint32_t height;   /* rows of one layer */
    uint32_t count;    /* particles (kind 1); 0 for textures */
    uint32_t raw_bytes;/* width x height x layers x bytes a texel: the decompressed size */
    uint32_t flags;    /* FXS_ENGINE_FLAG_VELOCITIES */
    float origin[3];   /* particles: the centre of their bounds, what positions are offsets from */
    float extent[3];   /* particles: half the size of their bounds (a culling box); textures: 0 */
    uint32_t header_bytes;
};

/* Encodes n particles (xyz, temp and, when set, vel of p; fuel and flags are not carried) into a
 * newly allocated payload (*out, *out_len; free()). Positions are stored as offsets from the
 * centre of their bounds, so their precision follows the flame's size, not its distance from
 * the world's origin. Returns 0, or -1 with a message (a value that is not finite or whose
 * half overflows). */
int fxs_engine_encode_particles(const struct fxs_particles *p, int zstd_level, uint8_t **out, size_t *out_len,
                                char *err, size_t errlen);
/* Encodes a texture of width x height texels of `channels` (1 or 4) floats each, row 0 first;
 * values beyond the half range become infinities, as in the EXR the default encoding sends. */
int fxs_engine_encode_texture(const float *texels, uint32_t width, uint32_t height, uint32_t channels,
                              int zstd_level, uint8_t **out, size_t *out_len, char *err, size_t errlen);

/* Reads and checks a payload's header and the size of its zstd frame (not its contents).
 * Returns 0, or -1 with a message. */
int fxs_engine_info(const uint8_t *buf, size_t len, struct fxs_engine_info *info, char *err, size_t errlen);
/* The particle count of a particle payload and whether it carries velocities, from its header
 * (checked, the texels not decompressed). 0, or -1 with a message. */
int fxs_engine_particles_info(const uint8_t *buf, size_t len, uint32_t *n, int *vel, char *err, size_t errlen);
/* Decodes a particle payload into the caller's arrays of `capacity` particles: p->xyz (origin
 * added back) and p->temp are required; p->vel may be NULL (not written), and is written only
 * when the payload carries velocities; p->fuel and p->flags are never written (the encoding has
 * neither). Returns 0 with p->n set; 1 when the payload holds more than capacity particles (p->n
 * = how many, nothing written); -1 with a message: truncated, corrupt or oversized input never
 * reads out of bounds. */
int fxs_engine_decode_particles_into(const uint8_t *buf, size_t len, struct fxs_particles *p, uint32_t capacity,
                                     char *err, size_t errlen);
/* fxs_engine_decode_particles_into into newly allocated arrays: p->n, p->xyz, p->temp and, with
 * velocities, p->vel; p->fuel and p->flags are NULL. Free with fxs_particles_free. 0, or -1. */
int fxs_engine_decode_particles(const uint8_t *buf, size_t len, struct fxs_particles *p, char *err, size_t errlen);
/* Decodes a texture payload into the caller's `capacity` floats (info->width x height x channels,
 * row 0 first; channels 4 for RGBA16F, 1 for R16F). Returns 0 with *info filled; 1 when texels
 * is NULL or too small (*info filled: it says the size, nothing written); -1 with a message. */
int fxs_engine_decode_texture_into(const uint8_t *buf, size_t len, struct fxs_engine_info *info, float *texels,
                                   size_t capacity, char *err, size_t errlen);
/* fxs_engine_decode_texture_into into *texels, newly allocated (free()). 0, or -1 with a message. */
int fxs_engine_decode_texture(const uint8_t *buf, size_t len, struct fxs_engine_info *info, float **texels,
                              char *err, size_t errlen);

/* IEEE 754 binary16 conversions: to half rounds to nearest even, overflowing to infinity. */
uint16_t fxs_half_from_float(float f);
float fxs_half_to_float(uint16_t h);

#endif
