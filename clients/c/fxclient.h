/* fxclient.h — libfxclient, the C client library of fxstreamd (protocol fxstream.v1).
 *
 * The public API: what `make install` puts in PREFIX/include/fxclient/ with fxs_frame.h (the
 * 64-byte frame header, the kind and codec numbers and the encodings) and fxs_bytes.h, and what the shared
 * library libfxclient.so.MAJOR exports (every other symbol is hidden). Build and link with
 * `pkg-config --cflags --libs fxclient`. C99 and C++ alike; no type of a dependency (cJSON,
 * libwebsockets) appears here: requests and replies are JSON text, frames are bytes, and the
 * decoders write into arrays the caller owns.
 *
 * One struct fxc_client is one WebSocket connection (ws://host:port/v1/ws or wss://,
 * subprotocol fxstream.v1) with its own libwebsockets context, serviced only inside this
 * library's calls, in the caller's thread: there is no background thread.
 *
 * Two ways to drive it:
 *   - blocking, for tools and set-up code: fxc_connect, fxc_request (send and wait for the
 *     reply), fxc_poll with a timeout;
 *   - from a game loop: fxc_open returns at once, the typed calls (fxc_subscribe, fxc_set,
 *     fxc_get, ...) and fxc_send only queue a request and return its id, and
 *     fxc_poll(c, &ev, 0, ...) never waits for the network: it reads what has arrived (at most
 *     FXC_POLL_BUDGET_US of work) and returns the next message, or 0 when there is none.
 *     Drain it once per frame:
 *
 *         struct fxc_event ev;
 *         while (fxc_poll(c, &ev, 0, err, sizeof err) == 1) { ...; fxc_event_free(&ev); }
 *
 *     Name resolution in fxc_open is the system's (getaddrinfo), which may block on a host
 *     name; an address literal (127.0.0.1, [::1]) never does.
 *
 * Threading: one client belongs to one thread at a time and its calls must not overlap; a
 * game that would rather not poll in its loop runs the client on a network thread and hands
 * the events (each self-contained until fxc_event_free) to the game thread through its own
 * queue. Separate clients are independent. fxc_set_log is process-wide.
 *
 * Messages: everything the server sends arrives through fxc_poll in order, as events: text
 * messages (the hello first, replies carrying the id their request got, `params` broadcasts,
 * `created`/`destroyed`, stream errors, `unsubscribed`) and binary frames (a parsed header and
 * the payload). A reply that fxc_wait or fxc_request is waiting for is handed to that call
 * instead. The queue is bounded: at most FXC_QUEUE_EVENTS text events without an id (the
 * oldest is dropped beyond that) and FXC_QUEUE_FRAMES_PER_CHANNEL frames per channel (the
 * latest frame wins, as on the server: the header's seq shows the gap). Drops are counted in
 * struct fxc_stats. A message above FXC_MAX_MESSAGE_BYTES closes the connection.
 *
 * Errors: every fallible call takes errbuf/errlen (either may be NULL/0) and writes one line
 * there: "bad URL ...", "connection refused by HOST:PORT", "WebSocket handshake failed ...",
 * "timeout after N ms ...", "server closed the connection (code C: reason)", or the server's
 * "code: message (param P)" for a request it rejected.
 *
 * Logging: quiet by default (libwebsockets prints nothing, not even its banner) until
 * fxc_set_log asks for more.
 *
 * Adding a payload decoder: a struct fxc_NAME (the caller's arrays and their capacity in, the
 * counts out) and one fxc_decode_NAME with the signature of the others, below. */
#ifndef FXCLIENT_H
#define FXCLIENT_H

#include <stddef.h>
#include <stdint.h>

#include "fxs_frame.h"

#ifdef __cplusplus
extern "C" {
#endif

#if defined(__GNUC__)
#define FXC_API __attribute__((visibility("default")))
#else
#define FXC_API
#endif

/* The version of this header; fxc_version() is the library's. The shared library's soname
 * carries the major (libfxclient.so.0), which changes whenever the ABI does. */
#define FXC_VERSION_MAJOR 0
#define FXC_VERSION_MINOR 1
#define FXC_VERSION_PATCH 0
#define FXC_VERSION "0.1.0"

#define FXC_DEFAULT_PORT 7681
#define FXC_DEFAULT_PATH "/v1/ws"
#define FXC_SUBPROTOCOL "fxstream.v1"
#define FXC_QUEUE_EVENTS 1024
#define FXC_QUEUE_FRAMES_PER_CHANNEL 4
#define FXC_MAX_MESSAGE_BYTES ((size_t)256 << 20)
#define FXC_MAX_QUEUED_SENDS 1024 /* requests waiting for the socket */
#define FXC_POLL_BUDGET_US 2000   /* most time fxc_poll(..., 0, ...) spends reading */

FXC_API const char *fxc_version(void);

/* ---- logging ------------------------------------------------------------------------------ */

/* libwebsockets' log levels, as its LLL_* bits. */
enum fxc_log_level { FXC_LOG_ERR = 1, FXC_LOG_WARN = 2, FXC_LOG_NOTICE = 4, FXC_LOG_INFO = 8, FXC_LOG_DEBUG = 16 };

/* Lets libwebsockets log `levels` (FXC_LOG_* bits; 0: nothing, the default) through emit
 * (NULL: to stderr). Process-wide, like libwebsockets' own setting: it also applies to any
 * other user of libwebsockets in the process. */
FXC_API void fxc_set_log(int levels, void (*emit)(int level, const char *line));

/* ---- connection --------------------------------------------------------------------------- */

struct fxc_client;

enum fxc_state {
    FXC_CONNECTING = 0, /* fxc_open returned; the hello has not arrived yet */
    FXC_OPEN = 1,       /* the server's hello arrived */
    FXC_CLOSED = 2,     /* ended or never came up: fxc_error says why */
};

/* Optional connection settings (PROTOCOL.md §3.11, README "Security"). Strings are copied. */
struct fxc_options {
    const char *token;   /* access token, sent as "Authorization: Bearer TOKEN"; NULL: none */
    const char *ca_file; /* PEM bundle that signs a wss:// server's certificate; NULL: the system's */
};

/* Starts connecting to url, ws://host[:port][/path] or wss://... (port 7681 and path /v1/ws
 * by default; IPv6 as ws://[::1]:7681), o NULL for no options, and returns at once with *out
 * in state FXC_CONNECTING. Requests may be sent right away: they go out after the handshake.
 * The outcome comes from fxc_poll: the hello event, or -1 with the reason (connection refused,
 * TLS or handshake failure, wrong subprotocol, an unknown token closing with "invalid token").
 * Returns 0; -2 when url is malformed; -1 when the host does not resolve or memory runs out
 * (*out = NULL, the reason in errbuf). */
FXC_API int fxc_open(struct fxc_client **out, const char *url, const struct fxc_options *o, char *errbuf,
                     size_t errlen);

/* fxc_open, then waits up to timeout_ms (< 0: no limit) for the server's hello. Returns 0
 * with *out open (the hello is also the first event fxc_poll returns), -2 for a malformed
 * url, -1 for anything else (*out = NULL, the reason in errbuf). */
FXC_API int fxc_connect(struct fxc_client **out, const char *url, const struct fxc_options *o, int timeout_ms,
                        char *errbuf, size_t errlen);

FXC_API enum fxc_state fxc_state(const struct fxc_client *c);

/* The server's hello ({"op":"hello","protocol","server","device","effects","limits","auth"})
 * as JSON text, NULL before it arrived; valid until fxc_close. */
FXC_API const char *fxc_hello(const struct fxc_client *c);

/* Why the connection failed or ended ("" while it is fine); valid until the next call. */
FXC_API const char *fxc_error(const struct fxc_client *c);

/* Closes the connection politely (close frame, a wait of at most 500 ms for the server's
 * answer) and frees everything, queued events included (events already returned stay valid
 * until fxc_event_free). NULL is a no-op. */
FXC_API void fxc_close(struct fxc_client *c);

/* ---- requests ------------------------------------------------------------------------------ */

/* Queues one request, a JSON object with "op" and its fields (PROTOCOL.md §3), as text. The
 * library gives it a fresh "id" (replacing one the text has) and returns that id (>= 1); the
 * reply is the text event carrying it. Returns -1 (errbuf says why) when json is not an object
 * with a string "op", the connection is closed, or FXC_MAX_QUEUED_SENDS requests wait. Never
 * waits for the network. */
FXC_API int64_t fxc_send(struct fxc_client *c, const char *json, char *errbuf, size_t errlen);

/* Typed requests: each builds the request and returns fxc_send's result. */
/* {"op":"subscribe","stream",max_fps}; max_fps <= 0: none (no cap beyond the stream's fps). */
FXC_API int64_t fxc_subscribe(struct fxc_client *c, const char *stream, double max_fps, char *errbuf, size_t errlen);
/* fxc_subscribe in an encoding (PROTOCOL.md §3.5): FXS_ENCODING_ENGINE asks for kind 1 and 2
 * frames in the engine encoding (codec 16, read by fxc_decode_particles and fxc_decode_texture);
 * FXS_ENCODING_DEFAULT is fxc_subscribe. Subscribing again to the same stream changes the
 * encoding (and max_fps) of the subscription. */
FXC_API int64_t fxc_subscribe_encoding(struct fxc_client *c, const char *stream, double max_fps,
                                       enum fxs_encoding enc, char *errbuf, size_t errlen);
/* fxc_subscribe_encoding with a particle budget (PROTOCOL.md §3.5 `max_particles`): at most
 * max_particles particles in each kind 1 frame, in [FXS_MAX_PARTICLES_MIN, FXS_MAX_PARTICLES_MAX]
 * (0: no budget, as fxc_subscribe_encoding). The server serves the largest step of its ladder
 * (1000, 2000, 5000, ... 2000000) at most the value; the `subscribed` reply's max_particles says
 * which. A frame with more particles than that comes as a subset of exactly that many, drawn in
 * proportion and the same particles frame to frame where they survive; fxc_frame_total tells
 * how many the stream's frame had, so what each particle stands for scales by total / count.
 * Subscribing again replaces the budget (0 removes it). A value outside the range is refused
 * here (-1), as the server would. */
FXC_API int64_t fxc_subscribe_budget(struct fxc_client *c, const char *stream, double max_fps, enum fxs_encoding enc,
                                     uint32_t max_particles, char *errbuf, size_t errlen);
FXC_API int64_t fxc_unsubscribe(struct fxc_client *c, const char *stream, char *errbuf, size_t errlen);
/* {"op":"get","stream"}: the reply is `params` (read values with fxc_param_number/_json). */
FXC_API int64_t fxc_get(struct fxc_client *c, const char *stream, char *errbuf, size_t errlen);
/* {"op":"set","stream","params"}: params_json is a JSON object of the values to change,
 * e.g. {"alpha":2,"wind_velocity":[2,0,0]} (all or nothing, PROTOCOL.md §3.8). */
FXC_API int64_t fxc_set(struct fxc_client *c, const char *stream, const char *params_json, char *errbuf,
                        size_t errlen);
/* fxc_set of one number: {"NAME":value}. */
FXC_API int64_t fxc_set_number(struct fxc_client *c, const char *stream, const char *name, double value,
                               char *errbuf, size_t errlen);

/* ---- events -------------------------------------------------------------------------------- */

enum fxc_event_type {
    FXC_EVENT_TEXT = 1,  /* a JSON message: a reply (id > 0) or an event (id 0) */
    FXC_EVENT_FRAME = 2, /* a binary frame whose header passed the reading rules (PROTOCOL.md §7.2) */
};

/* One message, owned by the caller from fxc_poll/fxc_wait until fxc_event_free; every pointer
 * in it stays valid until then (also after fxc_close). */
struct fxc_event {
    enum fxc_event_type type;
    uint64_t recv_time_us;   /* CLOCK_REALTIME when its last byte arrived; for a frame,
                                recv_time_us - header.server_time_us is its latency */
    const char *stream;      /* the message's "stream", or a frame's stream name when this client
                                subscribed to its channel; NULL when none */
    uint32_t channel;        /* a frame's channel; a `subscribed` reply's channel */
    /* FXC_EVENT_TEXT */
    const char *json;        /* the message as the server sent it, NUL-terminated */
    size_t json_len;
    const char *op;          /* its "op" */
    int64_t id;              /* the id fxc_send returned for the request this answers; 0: an event */
    int64_t rev;             /* `params`, `created`: the revision; else 0 */
    const char *code;        /* `error`: its code, message and param (NULL when absent) */
    const char *message;
    const char *param;
    /* FXC_EVENT_FRAME */
    struct fxs_header header;
    const uint8_t *payload;  /* header.payload_bytes bytes */
    void *internal;          /* the library's; released by fxc_event_free */
};

/* Takes the next event, servicing the connection for up to timeout_ms: 0 never waits (it
 * reads what has already arrived, for at most FXC_POLL_BUDGET_US), < 0 waits without limit.
 * Returns 1 with *ev filled, 0 when nothing came in time, or -1 when the connection is closed
 * (or failed to open) and nothing is queued (the reason in errbuf and fxc_error). */
FXC_API int fxc_poll(struct fxc_client *c, struct fxc_event *ev, int timeout_ms, char *errbuf, size_t errlen);

/* Waits up to timeout_ms (< 0: no limit) for the reply to request `id`, queueing what else
 * arrives. Returns 0 with the reply in *reply, 1 when the server answered with an error
 * (*reply holds it, errbuf "code: message (param P)"), -1 on timeout, a closed connection
 * or an id no request got (*reply zeroed; a reply that comes later arrives through fxc_poll). */
FXC_API int fxc_wait(struct fxc_client *c, int64_t id, struct fxc_event *reply, int timeout_ms, char *errbuf,
                     size_t errlen);

/* fxc_send then fxc_wait: one request, its reply (same results as fxc_wait; -1 also for what
 * fxc_send refuses). */
FXC_API int fxc_request(struct fxc_client *c, const char *json, struct fxc_event *reply, int timeout_ms,
                        char *errbuf, size_t errlen);

/* A kind 1 frame's `total` (PROTOCOL.md §7.1, offset 60) for a frame fxc_poll returned: the
 * particle count of the stream's frame it is a subset of (a subscription with a budget,
 * fxc_subscribe_budget), or 0 when it is the whole frame (and for every other kind). Bytes from
 * elsewhere: fxs_header_total. */
FXC_API uint32_t fxc_frame_total(const struct fxc_event *ev);

/* Releases what fxc_poll or fxc_wait put in ev and zeroes it. Safe on a zeroed event. */
FXC_API void fxc_event_free(struct fxc_event *ev);

/* A parameter of a `params` event (the reply to get, set, preset_load, or a broadcast):
 * fxc_param_number reads a number (0, or -1 when there is no such parameter or it is not a
 * number); fxc_param_json writes any value as JSON text into buf (0, or -1 when absent or it
 * does not fit in len bytes). */
FXC_API int fxc_param_number(const struct fxc_event *ev, const char *name, double *value);
FXC_API int fxc_param_json(const struct fxc_event *ev, const char *name, char *buf, size_t len);

struct fxc_stats {
    uint64_t frames_received;  /* valid binary frames received */
    uint64_t frames_dropped;   /* dropped from the queue because a newer frame of their channel came */
    uint64_t events_dropped;   /* dropped because the event queue was full */
    uint64_t bad_messages;     /* invalid frame headers, text that is not an object with "op" */
};

/* Counters since fxc_open. */
FXC_API void fxc_stats(const struct fxc_client *c, struct fxc_stats *out);

/* ---- payload decoders ------------------------------------------------------------------------
 *
 * Each takes a frame's header and payload (a FXC_EVENT_FRAME's, or bytes from elsewhere) and
 * writes into arrays the caller provides: set the pointers and the capacity, the decoder fills
 * them and the counts. Each returns
 *    0  decoded;
 *    1  an array is missing or too small: nothing was written to the arrays, the counts say what
 *       is needed (size the arrays, call again);
 *   -1  the frame is not of the decoder's kind and codec, or its payload is malformed (errbuf
 *       says which); a decoder never reads outside the payload.
 * The counts are also in the header (count_or_width, height), so arrays sized from it once
 * decode in one call. */

/* Kind 1 (PROTOCOL.md §7.5, §7.8): particles in the order of the payload (not the simulation's).
 * Codecs 2 and 3, the default encoding, carry every array. Codec 16, the engine encoding
 * (fxc_subscribe_encoding with FXS_ENCODING_ENGINE), carries positions, temperatures
 * and velocities as half floats (about 3 significant digits; positions relative to the centre
 * of the frame's bounds, so their precision follows the flame's size) and neither flags nor
 * fuel: has_flags and has_fuel are 0 and those arrays are neither needed nor written. */
struct fxc_particles {
    uint32_t capacity;   /* in: particles each array holds */
    float *xyz;          /* in: 3 * capacity floats, x y z per particle (metres) */
    float *temperature;  /* in: capacity floats, kelvin */
    uint8_t *flags;      /* in: capacity bytes: bits 0-1 type (0 gas, 1 burning source, 2 obstacle),
                            bit 2 flame (PROTOCOL.md §11.2); needed for codecs 2 and 3, not written
                            for codec 16 (may be NULL) */
    float *fuel;         /* in, optional: capacity floats, or NULL: not written */
    float *velocity;     /* in, optional: 3 * capacity floats (m/s), or NULL: not written */
    uint32_t count;      /* out: particles in the frame */
    int has_velocity;    /* out: the frame carries velocities (the stream's `velocities`) */
    int has_flags;       /* out: the frame carries flags (codecs 2 and 3; not the engine encoding) */
    int has_fuel;        /* out: the frame carries fuel (codecs 2 and 3; not the engine encoding) */
};
FXC_API int fxc_decode_particles(const struct fxs_header *h, const uint8_t *payload, struct fxc_particles *out,
                                 char *errbuf, size_t errlen);

/* Kind 2, codec 16 (PROTOCOL.md §7.8): a texture of the engine encoding (the energy wave's), as
 * floats from its half floats. The default encoding's kind 2 frames are OpenEXR files (codec 1):
 * read those with OpenEXR; this decoder refuses them. */
struct fxc_texture {
    size_t capacity;     /* in: floats texels holds */
    float *texels;       /* in: width * height * channels floats, a texel's channels together, row 0
                            (the top) first */
    uint32_t width, height; /* out: texels */
    uint32_t channels;   /* out: 1 (R) or 4 (RGBA) */
};
FXC_API int fxc_decode_texture(const struct fxs_header *h, const uint8_t *payload, struct fxc_texture *out,
                               char *errbuf, size_t errlen);

/* Kind 3, codec 1 (PROTOCOL.md §7.7): the energy wave's light rig. */
#define FXC_RIG_MAX_SEGMENTS 64
#define FXC_RIG_MAX_BANDS 8
struct fxc_rig_segment {
    float c[3], d[3];    /* the nearest point of M is c + a d, a = clamp((M - c) . d, a_lo, a_hi) */
    float a_lo, a_hi;
    float strength;      /* <= 0: does not light */
    int source, index;   /* 1 point, 2 line, 3 torus, 4 curve; the source's index in its list */
};
struct fxc_rig_band {
    float m_min, rgb[3]; /* the toon ramp: from lighting m_min on, colour rgb */
};
struct fxc_rig_constants {
    unsigned flags;      /* 1 feature textures, 2 outline, 4 shadow */
    float strength, outline_width, outline_rgb[3];
    float shadow_theta, shadow_opacity, shadow_rgb[3];   /* theta in radians */
    float plane_i[3], plane_y[3], plane_x[3], plane_z[3];
    int n_bands;
    struct fxc_rig_band bands[FXC_RIG_MAX_BANDS];
};
struct fxc_rig {
    int capacity;                     /* in: segments the array holds (FXC_RIG_MAX_SEGMENTS always do) */
    struct fxc_rig_segment *segments; /* in */
    int count;                        /* out: segments in the frame */
    uint32_t constants_id;            /* out: identifies the constants; they change rarely */
    int has_constants;                /* out: the frame carried them (else keep the last ones) */
    struct fxc_rig_constants constants; /* out, when has_constants */
};
FXC_API int fxc_decode_rig(const struct fxs_header *h, const uint8_t *payload, struct fxc_rig *out, char *errbuf,
                           size_t errlen);

/* Kind 4, codec 1 (PROTOCOL.md §7.6): the compound eye's look-up tables, several named RGBA8
 * products per frame (3 today). When the products cannot all be written (too few entries, an
 * rgba NULL or too small) it fills the count and the directory entries it has room for
 * (names, sizes), writes no texels and returns 1: give each product width * height * 4 bytes
 * and call again. */
struct fxc_lut_product {
    char name[5];                  /* out: "PIGM", "LLUT", "LMAC" */
    uint32_t width, height;        /* out: texels */
    uint32_t tile, tiles_x, tiles_y, inner; /* out: the atlas layout (§7.6) */
    uint8_t *rgba;                 /* in: width * height * 4 bytes (linear RGBA8), or NULL */
    size_t rgba_capacity;          /* in: bytes at rgba */
};
struct fxc_lut {
    int capacity;                      /* in: entries of products */
    struct fxc_lut_product *products;  /* in */
    int count;                         /* out: products in the frame */
    uint32_t lattice;                  /* out: the optics of the container header (§7.6) */
    float tile_h, lens_radius, refractive_index, pigment_depth;
    uint32_t max_passes, cells, dirs, gutter, supersample;
};
FXC_API int fxc_decode_lut(const struct fxs_header *h, const uint8_t *payload, struct fxc_lut *out, char *errbuf,
                           size_t errlen);

#ifdef __cplusplus
}
#endif

#endif
