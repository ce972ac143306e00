/* fxs_frame.h — the 64-byte binary frame header of protocol fxstream.v1.
 *
 * Shared verbatim by the daemon and the C client library, so both sides agree on
 * one definition. The header is little-endian on the wire; these helpers pack and
 * unpack it byte by byte so the code is correct on any host byte order and never
 * depends on struct layout or alignment. See protocol/PROTOCOL.md for the spec. */
#ifndef FXS_FRAME_H
#define FXS_FRAME_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "fxs_bytes.h"

#define FXS_MAGIC "FXS1"
#define FXS_HEADER_BYTES 64u

enum fxs_kind {
    FXS_KIND_PARTICLES = 1,
    FXS_KIND_TEXTURE = 2,
    FXS_KIND_LIGHT_RIG = 3,
    FXS_KIND_LUT = 4,
};
#define FXS_KIND_MAX 4

/* Header flags (PROTOCOL.md §7.1): bits 0-30 are the kind's; bit 31 marks a frame computed
 * before its stream paused, sent to a subscriber that made it run again (§8.3). */
#define FXS_FLAG_BEFORE_PAUSE 0x80000000u

/* The range of subscribe's max_fps (PROTOCOL.md §3.5): at least one step every 100 s, so a
 * subscription's interval always fits the daemon's timers. */
#define FXS_MAX_FPS_MIN 0.01
#define FXS_MAX_FPS_MAX 1000.0

/* The range of subscribe's max_particles (PROTOCOL.md §3.5): particles per kind 1 frame, served
 * as the largest step of the daemon's ladder (1000, 2000, 5000, ... 2000000) at most the value. */
#define FXS_MAX_PARTICLES_MIN 1000u
#define FXS_MAX_PARTICLES_MAX 4194304u

/* Codecs of kind 1 (particles) payloads (PROTOCOL.md §7.5; protocol/fxs_particles.h). */
enum fxs_particle_codec {
    FXS_CODEC_PARTICLES = 2,        /* one block */
    FXS_CODEC_PARTICLES_BLOCKS = 3, /* several blocks back to back (§7.5.8), read alike */
};

/* A subscription's encoding (PROTOCOL.md §3.5): the default codecs, or the engine encoding of
 * kinds 1 and 2 (FXS_CODEC_ENGINE, §7.8). Kinds 3 and 4 have one form, the same in both. */
enum fxs_encoding {
    FXS_ENCODING_DEFAULT = 0,
    FXS_ENCODING_ENGINE = 1,
};
#define FXS_ENCODING_COUNT 2
/* The encoding's name in subscribe's `encoding`. */
static inline const char *fxs_encoding_name(enum fxs_encoding e)
{
    return e == FXS_ENCODING_ENGINE ? "engine" : "default";
}

/* The codec of kind 1 and kind 2 payloads in the engine encoding (fxs_engine.h). */
#define FXS_CODEC_ENGINE 16u

/* Whether frames of a kind differ between encodings (kinds 1 and 2). */
static inline int fxs_kind_has_engine_form(int kind)
{
    return kind == FXS_KIND_PARTICLES || kind == FXS_KIND_TEXTURE;
}

/* The encoding a frame of this kind and codec is a form of. */
static inline enum fxs_encoding fxs_frame_encoding(int kind, uint32_t codec)
{
    return fxs_kind_has_engine_form(kind) && codec == FXS_CODEC_ENGINE ? FXS_ENCODING_ENGINE : FXS_ENCODING_DEFAULT;
}

/* Codecs of kind 2 (texture) payloads. */
enum fxs_texture_codec {
    FXS_CODEC_EXR = 1, /* payload is a complete OpenEXR file */
};

/* Codecs of kind 3 (light rig) payloads. */
enum fxs_rig_codec {
    FXS_CODEC_LIGHT_RIG = 1, /* "FXR1": centre-line segments + constants (PROTOCOL.md §7.7) */
};

/* Codecs of kind 4 (look-up table) payloads. */
enum fxs_lut_codec {
    FXS_CODEC_LUT_PACK = 1, /* "FXL1" container of named products (PROTOCOL.md §7.6) */
};

struct fxs_header {
    uint16_t header_bytes;
    uint16_t kind;
    uint32_t channel;
    uint32_t param_rev;
    uint64_t seq;
    double sim_time;
    uint64_t server_time_us;
    uint32_t codec;
    uint32_t payload_bytes;
    uint32_t count_or_width;
    uint32_t height;
    uint32_t flags;
};

/* Writes the 64 header bytes at out (`total` 0: fxs_header_set_total). */
static inline void fxs_header_pack(const struct fxs_header *h, uint8_t out[FXS_HEADER_BYTES])
{
    uint64_t t;
    memset(out, 0, FXS_HEADER_BYTES);
    memcpy(out, FXS_MAGIC, 4);
    fxs_put_u16(out + 4, FXS_HEADER_BYTES);
    fxs_put_u16(out + 6, h->kind);
    fxs_put_u32(out + 8, h->channel);
    fxs_put_u32(out + 12, h->param_rev);
    fxs_put_u64(out + 16, h->seq);
    memcpy(&t, &h->sim_time, 8);
    fxs_put_u64(out + 24, t);
    fxs_put_u64(out + 32, h->server_time_us);
    fxs_put_u32(out + 40, h->codec);
    fxs_put_u32(out + 44, h->payload_bytes);
    fxs_put_u32(out + 48, h->count_or_width);
    fxs_put_u32(out + 52, h->height);
    fxs_put_u32(out + 56, h->flags);
}

/* The header's u32 at offset 60 (PROTOCOL.md §7.1), outside struct fxs_header so that struct's
 * layout (part of libfxclient's ABI) stays as it was: in a kind 1 frame that is a subset of the
 * stream's frame (subscribe's max_particles), `total`, the particle count of the frame it was
 * drawn from; 0 in every other frame. frame: at least FXS_HEADER_BYTES bytes. */
#define FXS_HEADER_TOTAL_OFFSET 60
static inline uint32_t fxs_header_total(const uint8_t *frame) { return fxs_get_u32(frame + FXS_HEADER_TOTAL_OFFSET); }
static inline void fxs_header_set_total(uint8_t *frame, uint32_t total) { fxs_put_u32(frame + FXS_HEADER_TOTAL_OFFSET, total); }

/* Parses a frame of len bytes. Returns 0 and fills h, or -1 when the bytes are not a
 * valid v1 frame: short buffer, bad magic, header_bytes < 64 or beyond the buffer, or
 * a payload_bytes that does not match what follows the header. */
static inline int fxs_header_unpack(const uint8_t *buf, size_t len, struct fxs_header *h)
{
    uint64_t t;
    if (len < FXS_HEADER_BYTES || memcmp(buf, FXS_MAGIC, 4) != 0) return -1;
    h->header_bytes = fxs_get_u16(buf + 4);
    if (h->header_bytes < FXS_HEADER_BYTES || h->header_bytes > len) return -1;
    h->kind = fxs_get_u16(buf + 6);
    h->channel = fxs_get_u32(buf + 8);
    h->param_rev = fxs_get_u32(buf + 12);
    h->seq = fxs_get_u64(buf + 16);
    t = fxs_get_u64(buf + 24);
    memcpy(&h->sim_time, &t, 8);
    h->server_time_us = fxs_get_u64(buf + 32);
    h->codec = fxs_get_u32(buf + 40);
    h->payload_bytes = fxs_get_u32(buf + 44);
    h->count_or_width = fxs_get_u32(buf + 48);
    h->height = fxs_get_u32(buf + 52);
    h->flags = fxs_get_u32(buf + 56);
    if ((size_t)h->payload_bytes != len - h->header_bytes) return -1;
    return 0;
}

#endif
