/* fxctl.c — the command-line client of fxstreamd, built on libfxclient.
 *
 * Owns argument parsing, turning one command into one fxstream.v1 request, and
 * printing: on a terminal, replies for people (fxctl_print.h); with --json or when
 * stdout is not a terminal, every reply is one line of JSON (easy to pipe into jq or a
 * script). Every failure is one line on stderr with exit status 1 (server or
 * transport) or 2 (usage); notes (a set that restarts the simulation, a stale first
 * frame) go to stderr too. `subscribe` also owns writing frames to disk. */
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include <libwebsockets.h>

#include "codec/exr.h"
#include "fxclient.h"
#include "fxctl_print.h"
#include "fxs_engine.h"
#include "fxs_particles.h"
#include "fxs_lut.h"
#include "png.h"
#include "suggest.h"

#define FXCTL_DEFAULT_URL "ws://127.0.0.1:7681/v1/ws"
#define FXCTL_DEFAULT_TIMEOUT_MS 10000
#define FXCTL_STALE_MS 1000 /* a first frame older than this gets a note */

enum { FXCTL_OK = 0, FXCTL_FAIL = 1, FXCTL_USAGE = 2 };

struct fxctl_opts {
    const char *url;
    int timeout_ms;
    struct fxc_options conn; /* token, CA file */
    long frames;       /* subscribe --frames, 0 when not given */
    long count;        /* watch --count, 0 = until interrupted */
    double max_fps;    /* subscribe --max-fps, < 0 when not given */
    int kind;          /* subscribe --kind, 0 = every kind */
    const char *encoding; /* subscribe --encoding, NULL when not given */
    const char *out_dir;
    int human;         /* stdout is a terminal and no --json: print for people */
    const char *cmd;
    char **args;       /* positional arguments after the command */
    int nargs;
};

static const char fxctl_help[] =
    "usage: fxctl [--url ws://HOST[:PORT][/PATH]] [--timeout MS] COMMAND [ARGS]\n"
    "\n"
    "Talks to fxstreamd over WebSocket (protocol fxstream.v1).\n"
    "\n"
    "commands:\n"
    "  list                          streams: name, effect, subscribers, rev, fps\n"
    "  describe EFFECT               an effect's parameter schema and outputs\n"
    "  create EFFECT NAME [K=V ...]  new stream NAME running EFFECT, optional params\n"
    "  destroy NAME                  remove stream NAME\n"
    "  get NAME                      complete parameters of NAME with their rev\n"
    "  set NAME K=V [K=V ...]        change parameters (all or nothing)\n"
    "  reset NAME                    restart NAME's simulation\n"
    "  subscribe NAME --frames N [--max-fps F] [--kind K] [--encoding E] [--out DIR]\n"
    "                                receive N frames of NAME (only of kind K, 1..4,\n"
    "                                with --kind; particles and textures in encoding\n"
    "                                E, default or engine); prints the subscribed\n"
    "                                reply, then one JSON line per frame (stream,\n"
    "                                channel, kind, seq, param_rev, sim_time,\n"
    "                                server_time_us, latency_ms, codec, payload_bytes,\n"
    "                                width and height, or count, flags) and any params\n"
    "                                event of NAME; with --out writes the payload to\n"
    "                                DIR/NAME-SEQ.exr (texture; the engine encoding's\n"
    "                                halves as an EXR), DIR/NAME-SEQ-PROD.png\n"
    "                                per look-up-table product (kind 4), the decoded\n"
    "                                particles to DIR/NAME-SEQ.ply (kind 1, binary PLY,\n"
    "                                x y z temperature fuel flags, or x y z temperature\n"
    "                                in the engine encoding, then vx vy vz if the\n"
    "                                stream sends velocities, and the\n"
    "                                payload as received to .bin) or the\n"
    "                                payload to .bin (others), and the line to\n"
    "                                DIR/NAME-SEQ.json; a light-rig frame (kind 3),\n"
    "                                which shares its texture's SEQ, goes to\n"
    "                                DIR/NAME-SEQ-rig.bin and .json. Fails when the stream is\n"
    "                                destroyed or the server goes away.\n"
    "  presets [EFFECT]              presets of EFFECT (or of every effect): effect, name,\n"
    "                                builtin, doc, params\n"
    "  preset load NAME PRESET       give stream NAME its effect's defaults with PRESET's\n"
    "                                values over them (like set: all or nothing)\n"
    "  preset save NAME PRESET [DOC] save stream NAME's parameters as PRESET (admin)\n"
    "  preset delete EFFECT PRESET   delete a user preset of EFFECT (admin)\n"
    "  watch [--count N]             prints the list reply, then every created and\n"
    "                                destroyed event (streams made or removed by\n"
    "                                anyone) as a JSON line; stops after N events\n"
    "                                (each within --timeout), else runs until\n"
    "                                interrupted or the server goes away\n"
    "\n"
    "K=V: K is a top-level parameter name; V is JSON (wind=[1,0,0], n=3, on=true,\n"
    "mode=\"simpson\"); a V that is not valid JSON is taken as a string (mode=simpson).\n"
    "\n"
    "options (also as --opt=VALUE):\n"
    "  --url URL      server, default $FXCTL_URL or " FXCTL_DEFAULT_URL "\n"
    "                 (port 7681 and path /v1/ws when omitted; wss:// for TLS)\n"
    "  --token T      access token (default $FXSTREAM_TOKEN; PROTOCOL.md §3.11)\n"
    "  --ca-file F    PEM bundle that signs a wss:// server's certificate\n"
    "                 (default $FXSTREAM_CA_FILE, else the system's)\n"
    "  --json         print every reply as one line of JSON (the default when stdout\n"
    "                 is not a terminal; on a terminal describe, get, set, list and\n"
    "                 presets print tables)\n"
    "  --timeout MS   limit for connecting, for each reply and, with subscribe, for\n"
    "                 each frame (with watch --count, each event; default 10000)\n"
    "  --help, -h     this text\n"
    "\n"
    "output: on a terminal, describe is a table per parameter group, get is aligned\n"
    "name = value, set shows the values it changed and the new rev, list and presets are\n"
    "tables; otherwise (or with --json) each reply is one line of JSON (the server's\n"
    "reply object without the request id). A set that restarts the simulation and a\n"
    "first frame older than 1 s are noted on stderr. Errors go to stderr as\n"
    "\"fxctl: CODE: MESSAGE\" for server errors or \"fxctl: WHAT\" for transport errors.\n"
    "exit status: 0 success, 1 server or transport error, 2 usage error (bad URL too).\n"
    "environment: FXCTL_URL default URL; FXSTREAM_TOKEN, FXSTREAM_CA_FILE as above;\n"
    "FXCTL_LWS_LOG libwebsockets log level bits\n"
    "(default 0, silent).\n";

static int fxctl_usage(const char *why, const char *arg)
{
    fprintf(stderr, "fxctl: %s%s%s\nTry 'fxctl --help'.\n", why, arg ? ": " : "", arg ? arg : "");
    return FXCTL_USAGE;
}

/* ---- arguments ------------------------------------------------------------------ */

static int fxctl_parse_long(const char *s, long min, long *out)
{
    char *end;
    long v;
    errno = 0;
    v = strtol(s, &end, 10);
    if (errno || end == s || *end || v < min) return -1;
    *out = v;
    return 0;
}

/* Applies option `name` with value `val`. Returns 0, or FXCTL_USAGE. */
static int fxctl_set_opt(struct fxctl_opts *o, const char *name, const char *val)
{
    long n;
    char *end;
    if (!val) return fxctl_usage("option needs a value", name);
    if (!strcmp(name, "--url")) {
        o->url = val;
    } else if (!strcmp(name, "--token")) {
        o->conn.token = val;
    } else if (!strcmp(name, "--ca-file")) {
        o->conn.ca_file = val;
    } else if (!strcmp(name, "--timeout")) {
        if (fxctl_parse_long(val, 1, &n) || n > 3600000) return fxctl_usage("--timeout needs milliseconds, 1..3600000", val);
        o->timeout_ms = (int)n;
    } else if (!strcmp(name, "--frames")) {
        if (fxctl_parse_long(val, 1, &o->frames)) return fxctl_usage("--frames needs a positive integer", val);
    } else if (!strcmp(name, "--max-fps")) {
        o->max_fps = strtod(val, &end);
        if (end == val || *end || !(o->max_fps >= FXS_MAX_FPS_MIN && o->max_fps <= FXS_MAX_FPS_MAX))
            return fxctl_usage("--max-fps needs a number in [0.01, 1000]", val);
    } else if (!strcmp(name, "--kind")) {
        if (fxctl_parse_long(val, 1, &n) || n > FXS_KIND_MAX) return fxctl_usage("--kind needs a frame kind, 1..4", val);
        o->kind = (int)n;
    } else if (!strcmp(name, "--encoding")) {
        if (strcmp(val, "default") && strcmp(val, "engine")) return fxctl_usage("--encoding needs default or engine", val);
        o->encoding = val;
    } else if (!strcmp(name, "--count")) {
        if (fxctl_parse_long(val, 1, &o->count)) return fxctl_usage("--count needs a positive integer", val);
    } else if (!strcmp(name, "--out")) {
        o->out_dir = val;
    } else {
        return fxctl_usage("unknown option", name);
    }
    return 0;
}

/* Handles argv[*i], an option; may consume argv[*i + 1]. */
static int fxctl_take_opt(struct fxctl_opts *o, int argc, char **argv, int *i)
{
    char name[32];
    const char *eq = strchr(argv[*i], '=');
    if (!eq) {
        const char *opt = argv[*i];
        return fxctl_set_opt(o, opt, *i + 1 < argc ? argv[++*i] : NULL);
    }
    if ((size_t)(eq - argv[*i]) >= sizeof name) return fxctl_usage("unknown option", argv[*i]);
    snprintf(name, sizeof name, "%.*s", (int)(eq - argv[*i]), argv[*i]);
    return fxctl_set_opt(o, name, eq + 1);
}

/* Fills o from argv. Returns 0, FXCTL_USAGE, or -1 after printing --help. */
static int fxctl_parse_args(struct fxctl_opts *o, int argc, char **argv)
{
    int i, only_positional = 0, r;
    for (i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (!only_positional && !strcmp(a, "-h")) {
            fputs(fxctl_help, stdout);
            return -1;
        } else if (only_positional || strncmp(a, "--", 2) != 0 || a[2] == 0) {
            if (!only_positional && !strcmp(a, "--")) { only_positional = 1; continue; }
            if (!o->cmd) o->cmd = a;
            else o->args[o->nargs++] = argv[i];
        } else if (!strcmp(a, "--help")) {
            fputs(fxctl_help, stdout);
            return -1;
        } else if (!strcmp(a, "--json")) {
            o->human = 0;
        } else if ((r = fxctl_take_opt(o, argc, argv, &i))) {
            return r;
        }
    }
    if (!o->cmd) return fxctl_usage("no command given", NULL);
    return 0;
}

/* Adds "K=V" to obj; V parsed as JSON, or taken as a string when it is not JSON. */
static int fxctl_add_kv(cJSON *obj, const char *kv)
{
    const char *eq = strchr(kv, '=');
    char *key;
    cJSON *v;
    if (!eq || eq == kv) return fxctl_usage("expected KEY=VALUE", kv);
    for (const cJSON *e = obj->child; e; e = e->next)
        if (strlen(e->string) == (size_t)(eq - kv) && !strncmp(e->string, kv, (size_t)(eq - kv)))
            return fxctl_usage("parameter given twice", e->string);
    v = cJSON_ParseWithOpts(eq + 1, NULL, 1);
    if (!v) v = cJSON_CreateString(eq + 1);
    key = strndup(kv, (size_t)(eq - kv));
    if (!v || !key) {
        free(key);
        cJSON_Delete(v);
        fprintf(stderr, "fxctl: out of memory\n");
        return FXCTL_FAIL;
    }
    cJSON_AddItemToObject(obj, key, v);
    free(key);
    return 0;
}

/* ---- commands -> requests --------------------------------------------------------- */

struct fxctl_cmd {
    const char *name;
    int min_args, max_args; /* max_args < 0: unlimited */
    const char *first_field; /* "effect" or "stream": what args[0] is */
    const char *synopsis;
};

static const struct fxctl_cmd fxctl_cmds[] = {
    { "list", 0, 0, NULL, "list" },
    { "describe", 1, 1, "effect", "describe EFFECT" },
    { "create", 2, -1, "effect", "create EFFECT NAME [K=V ...]" },
    { "destroy", 1, 1, "stream", "destroy NAME" },
    { "get", 1, 1, "stream", "get NAME" },
    { "set", 2, -1, "stream", "set NAME K=V [K=V ...]" },
    { "reset", 1, 1, "stream", "reset NAME" },
    { "subscribe", 1, 1, "stream", "subscribe NAME --frames N [--max-fps F] [--kind K] [--encoding E] [--out DIR]" },
    { "watch", 0, 0, NULL, "watch [--count N]" },
    { "presets", 0, 1, "effect", "presets [EFFECT]" },
    { "preset", 3, 4, NULL, "preset load NAME PRESET | preset save NAME PRESET [DOC] | preset delete EFFECT PRESET" },
};

/* `preset VERB ...`: the op and the field its first argument fills. */
static const struct {
    const char *verb, *op, *first_field;
    int max_args;
} fxctl_preset_verbs[] = {
    { "load", "preset_load", "stream", 3 },
    { "save", "preset_save", "stream", 4 },
    { "delete", "preset_delete", "effect", 3 },
};

static int fxctl_preset_verb(const char *verb)
{
    for (int i = 0; i < (int)(sizeof fxctl_preset_verbs / sizeof fxctl_preset_verbs[0]); i++)
        if (!strcmp(fxctl_preset_verbs[i].verb, verb)) return i;
    return -1;
}

static const struct fxctl_cmd *fxctl_find_cmd(const char *name)
{
    for (size_t i = 0; i < sizeof fxctl_cmds / sizeof fxctl_cmds[0]; i++)
        if (!strcmp(fxctl_cmds[i].name, name)) return &fxctl_cmds[i];
    return NULL;
}

static int fxctl_unknown_cmd(const char *name)
{
    struct suggest sg;
    char hint[96], why[160];
    suggest_init(&sg, name);
    for (size_t i = 0; i < sizeof fxctl_cmds / sizeof fxctl_cmds[0]; i++) suggest_offer(&sg, fxctl_cmds[i].name);
    snprintf(why, sizeof why, "unknown command%s", suggest_text(&sg, hint, sizeof hint));
    return fxctl_usage(why, name);
}

/* Checks argument counts and command-specific options before any network I/O. */
static int fxctl_validate(const struct fxctl_opts *o, const struct fxctl_cmd *cmd)
{
    int sub = !strcmp(cmd->name, "subscribe");
    if (o->nargs < cmd->min_args || (cmd->max_args >= 0 && o->nargs > cmd->max_args)) {
        fprintf(stderr, "fxctl: wrong number of arguments; usage: fxctl %s\nTry 'fxctl --help'.\n", cmd->synopsis);
        return FXCTL_USAGE;
    }
    if (!sub && (o->frames || o->max_fps >= 0 || o->kind || o->encoding || o->out_dir))
        return fxctl_usage("--frames, --max-fps, --kind, --encoding and --out go with subscribe only", NULL);
    if (sub && !o->frames) return fxctl_usage("subscribe needs --frames N", NULL);
    if (o->count && strcmp(cmd->name, "watch")) return fxctl_usage("--count goes with watch only", NULL);
    if (!strcmp(cmd->name, "preset")) {
        int v = fxctl_preset_verb(o->args[0]);
        if (v < 0) return fxctl_usage("preset needs load, save or delete", o->args[0]);
        if (o->nargs > fxctl_preset_verbs[v].max_args) {
            fprintf(stderr, "fxctl: wrong number of arguments; usage: fxctl %s\nTry 'fxctl --help'.\n", cmd->synopsis);
            return FXCTL_USAGE;
        }
    }
    return 0;
}

/* The request of `preset VERB A PRESET [DOC]`. */
static void fxctl_build_preset(const struct fxctl_opts *o, cJSON *req)
{
    int v = fxctl_preset_verb(o->args[0]);
    cJSON_AddStringToObject(req, "op", fxctl_preset_verbs[v].op);
    cJSON_AddStringToObject(req, fxctl_preset_verbs[v].first_field, o->args[1]);
    cJSON_AddStringToObject(req, "name", o->args[2]);
    if (o->nargs > 3) cJSON_AddStringToObject(req, "doc", o->args[3]);
}

/* Builds the request of a command. Returns 0, or an exit status. */
static int fxctl_build(const struct fxctl_opts *o, const struct fxctl_cmd *cmd, cJSON **out)
{
    cJSON *req = cJSON_CreateObject(), *params = NULL;
    int i = 1, r = 0;
    *out = req;
    if (!req) return FXCTL_FAIL;
    if (!strcmp(cmd->name, "preset")) {
        fxctl_build_preset(o, req);
        return 0;
    }
    cJSON_AddStringToObject(req, "op", strcmp(cmd->name, "watch") ? cmd->name : "list");
    if (cmd->first_field && o->nargs) cJSON_AddStringToObject(req, cmd->first_field, o->args[0]);
    if (!strcmp(cmd->name, "create")) cJSON_AddStringToObject(req, "stream", o->args[i++]);
    if (o->max_fps >= 0) cJSON_AddNumberToObject(req, "max_fps", o->max_fps);
    if (o->encoding) cJSON_AddStringToObject(req, "encoding", o->encoding);
    if (i < o->nargs) params = cJSON_AddObjectToObject(req, "params");
    for (; i < o->nargs && !r; i++) r = fxctl_add_kv(params, o->args[i]);
    return r;
}

/* ---- output -------------------------------------------------------------------------- */

static void fxctl_print_json(FILE *f, cJSON *j)
{
    char *s = cJSON_PrintUnformatted(j);
    if (s) fprintf(f, "%s\n", s);
    free(s);
}

/* Shortest of %.15g / %.17g that reads back as v (cJSON's rule); non-finite as 0. */
static void fxctl_fmt_double(char *buf, size_t len, double v)
{
    if (!isfinite(v)) v = 0;
    snprintf(buf, len, "%.15g", v);
    if (strtod(buf, NULL) != v) snprintf(buf, len, "%.17g", v);
}

/* Milliseconds from the frame's server time to its arrival. */
static double fxctl_age_ms(const struct fxc_msg *m)
{
    return ((double)m->recv_time_us - (double)m->header.server_time_us) / 1000.0;
}

/* Formats one frame's header as a JSON line (no newline) into buf. */
static void fxctl_frame_line(char *buf, size_t len, const char *stream, const struct fxc_msg *m)
{
    const struct fxs_header *h = &m->header;
    cJSON *name = cJSON_CreateString(stream);
    char *qname = cJSON_PrintUnformatted(name);
    char size[96], sim[32];
    if (h->kind == FXS_KIND_TEXTURE || h->kind == FXS_KIND_LUT)
        snprintf(size, sizeof size, "\"width\":%" PRIu32 ",\"height\":%" PRIu32, h->count_or_width, h->height);
    else
        snprintf(size, sizeof size, "\"count\":%" PRIu32, h->count_or_width);
    fxctl_fmt_double(sim, sizeof sim, h->sim_time);
    snprintf(buf, len,
             "{\"stream\":%s,\"channel\":%" PRIu32 ",\"kind\":%u,\"seq\":%" PRIu64 ",\"param_rev\":%" PRIu32
             ",\"sim_time\":%s,\"server_time_us\":%" PRIu64 ",\"latency_ms\":%.3f,\"codec\":%" PRIu32
             ",\"payload_bytes\":%" PRIu32 ",%s,\"flags\":%" PRIu32 "}",
             qname ? qname : "null", h->channel, (unsigned)h->kind, h->seq, h->param_rev,
             sim, h->server_time_us,
             fxctl_age_ms(m), h->codec, h->payload_bytes,
             size, h->flags);
    free(qname);
    cJSON_Delete(name);
}

static int fxctl_write_file(const char *path, const void *data, size_t len)
{
    FILE *f = fopen(path, "wb");
    int ok = f && fwrite(data, 1, len, f) == len;
    if (f && fclose(f)) ok = 0;
    if (!ok) fprintf(stderr, "fxctl: cannot write %s: %s\n", path, strerror(errno));
    return ok ? 0 : -1;
}

/* Writes decoded particles as binary little-endian PLY: float x y z temperature, then float
 * fuel and uchar flags when the frame carries them (codecs 2 and 3, not the engine encoding),
 * then float vx vy vz when it carries velocities. */
static int fxctl_write_ply(const char *path, uint32_t codec, const struct fxs_particles *p)
{
    FILE *f = fopen(path, "wb");
    int ok = f != NULL, attrs = p->fuel && p->flags;
    size_t size = 16 + (attrs ? 5 : 0) + (p->vel ? 12 : 0);
    if (ok)
        ok = fprintf(f, "ply\nformat binary_little_endian 1.0\ncomment fxstream kind 1 codec %" PRIu32 "\nelement vertex %" PRIu32
                        "\nproperty float x\nproperty float y\nproperty float z\nproperty float temperature\n"
                        "%s%send_header\n", codec, p->n, attrs ? "property float fuel\nproperty uchar flags\n" : "",
                     p->vel ? "property float vx\nproperty float vy\nproperty float vz\n" : "") > 0;
    for (uint32_t i = 0; ok && i < p->n; i++) {
        uint8_t rec[33], *r = rec;
        float v[8] = { p->xyz[3 * i], p->xyz[3 * i + 1], p->xyz[3 * i + 2], p->temp[i], attrs ? p->fuel[i] : 0 };
        int nv = attrs ? 5 : 4;
        if (p->vel) memcpy(v + nv, p->vel + 3 * (size_t)i, 12);
        for (int c = 0; c < nv + (p->vel ? 3 : 0); c++) {
            uint32_t u;
            memcpy(&u, &v[c], 4);
            fxs_put_u32(r, u);
            r += 4;
            if (attrs && c == 4) *r++ = p->flags[i]; /* the flags byte sits between fuel and vx */
        }
        ok = fwrite(rec, 1, size, f) == size;
    }
    if (f && fclose(f)) ok = 0;
    if (!ok) fprintf(stderr, "fxctl: cannot write %s: %s\n", path, strerror(errno));
    return ok ? 0 : -1;
}

static int fxctl_is_particles(const struct fxs_header *h)
{
    return h->kind == FXS_KIND_PARTICLES && (h->codec == FXS_CODEC_PARTICLES || h->codec == FXS_CODEC_PARTICLES_BLOCKS ||
                                             h->codec == FXS_CODEC_ENGINE);
}

/* Decodes a particle frame (codec 2, 3 or the engine encoding); checks the count against the header. */
static int fxctl_decode_particles(const struct fxc_msg *m, struct fxs_particles *p)
{
    char err[256];
    int rc = m->header.codec == FXS_CODEC_ENGINE
                 ? fxs_engine_decode_particles(m->payload, m->header.payload_bytes, p, err, sizeof err)
                 : fxs_particles_decode(m->payload, m->header.payload_bytes, p, err, sizeof err);
    if (rc) {
        fprintf(stderr, "fxctl: frame %" PRIu64 ": %s\n", m->header.seq, err);
        return -1;
    }
    if (p->n != m->header.count_or_width) {
        fprintf(stderr, "fxctl: frame %" PRIu64 ": header count %" PRIu32 " but %" PRIu32 " particles in the payload\n",
                m->header.seq, m->header.count_or_width, p->n);
        fxs_particles_free(p);
        return -1;
    }
    return 0;
}

/* Writes each product of a look-up table container (kind 4 codec 1) as BASE-NAME.png. */
static int fxctl_write_lut(const char *base, const struct fxc_msg *m)
{
    char msg[160] = "", path[4300];
    struct fxs_lut_product e;
    const uint8_t *p = m->payload;
    size_t len = m->header.payload_bytes;
    int count = fxs_lut_entry(p, len, 0, &e, msg, sizeof msg);
    for (int i = 0; i < count && !msg[0]; i++) {
        uint8_t *px = fxs_lut_entry(p, len, i, &e, msg, sizeof msg) < 0 ? NULL : fxs_lut_texels(p, len, &e, msg, sizeof msg);
        if (!px) break;
        snprintf(path, sizeof path, "%s-%s.png", base, e.name);
        if (png_write_rgba8(path, px, e.width, e.height)) snprintf(msg, sizeof msg, "cannot write %.100s: %.40s", path, strerror(errno));
        free(px);
    }
    if (!msg[0]) return 0;
    fprintf(stderr, "fxctl: frame %" PRIu64 ": %s\n", m->header.seq, msg);
    return -1;
}

/* Writes an engine-encoded texture (kind 2 codec 16) as the EXR of its halves, the same pixels
 * the default encoding's EXR holds (uncompressed). Checks its size against the header. */
static int fxctl_write_engine_exr(const char *path, const struct fxc_msg *m)
{
    const struct fxs_header *h = &m->header;
    struct fxs_engine_info info;
    struct fx_buf exr = { 0 };
    struct fx_err e = { 0 };
    float *texels = NULL;
    char err[256];
    int r = -1;
    if (fxs_engine_decode_texture(m->payload, h->payload_bytes, &info, &texels, err, sizeof err))
        fprintf(stderr, "fxctl: frame %" PRIu64 ": %s\n", h->seq, err);
    else if (info.width != h->count_or_width || info.height != h->height)
        fprintf(stderr, "fxctl: frame %" PRIu64 ": header %" PRIu32 "x%" PRIu32 " but a %" PRIu32 "x%" PRIu32 " payload\n",
                h->seq, h->count_or_width, h->height, info.width, info.height);
    else if (exr_write_mem(&(struct exr_image){ (int)info.width, (int)info.height, info.format == FXS_ENGINE_RGBA16F ? 4 : 1,
                                                texels, EXR_CODEC_NONE }, &exr, &e))
        fprintf(stderr, "fxctl: frame %" PRIu64 ": %s\n", h->seq, e.message);
    else
        r = fxctl_write_file(path, exr.data, exr.len);
    free(texels);
    fx_buf_free(&exr);
    return r;
}

/* Writes the frame's data file: .exr (texture codec 1, or the decoded engine encoding), .ply
 * (particles, decoded, and the payload as received in .bin, for other decoders to compare) or
 * .bin, plus one PNG per product of a look-up table (kind 4 codec 1). */
static int fxctl_save_payload(const char *base, const struct fxc_msg *m, const struct fxs_particles *p)
{
    const struct fxs_header *h = &m->header;
    int exr = h->kind == FXS_KIND_TEXTURE && h->codec == FXS_CODEC_EXR;
    int engine_exr = h->kind == FXS_KIND_TEXTURE && h->codec == FXS_CODEC_ENGINE;
    char path[4200], raw[4200];
    snprintf(path, sizeof path, "%s.%s", base, p ? "ply" : exr || engine_exr ? "exr" : "bin");
    snprintf(raw, sizeof raw, "%s.bin", base);
    if (h->kind == FXS_KIND_LUT && h->codec == FXS_CODEC_LUT_PACK && fxctl_write_lut(base, m)) return -1;
    if (p && fxctl_write_ply(path, h->codec, p)) return -1;
    if (engine_exr && fxctl_write_engine_exr(path, m)) return -1;
    return fxctl_write_file(p || engine_exr ? raw : path, m->payload, h->payload_bytes);
}

/* Writes DIR/STREAM-SEQ.{exr|ply|bin} and DIR/STREAM-SEQ.json; a light-rig frame (kind 3) is
 * sent with its texture under the same seq, so it goes to DIR/STREAM-SEQ-rig.{bin,json}. */
static int fxctl_save_frame(const char *dir, const char *stream, const struct fxc_msg *m, const char *line,
                            const struct fxs_particles *p)
{
    const struct fxs_header *h = &m->header;
    char path[4096], *safe = strdup(stream);
    int r;
    if (!safe) return -1;
    for (char *c = safe; *c; c++)
        if (*c == '/') *c = '_';
    snprintf(path, sizeof path, "%s/%s-%" PRIu64 "%s", dir, safe, h->seq, h->kind == FXS_KIND_LIGHT_RIG ? "-rig" : "");
    free(safe);
    r = fxctl_save_payload(path, m, p);
    strncat(path, ".json", sizeof path - strlen(path) - 1);
    if (!r) {
        char *text = malloc(strlen(line) + 2);
        r = text ? 0 : -1;
        if (text) {
            sprintf(text, "%s\n", line);
            r = fxctl_write_file(path, text, strlen(text));
            free(text);
        }
    }
    return r;
}

/* ---- subscribe --------------------------------------------------------------------------- */

struct fxctl_sub {
    const struct fxctl_opts *o;
    const char *stream;
    uint32_t channel;
    long got;
};

static int fxctl_on_frame(struct fxctl_sub *s, const struct fxc_msg *m)
{
    char line[1024];
    struct fxs_particles p = { 0 };
    int particles = s->o->out_dir && fxctl_is_particles(&m->header), r = 0;
    if (m->header.channel != s->channel || (s->o->kind && m->header.kind != s->o->kind)) return 0;
    if (particles && fxctl_decode_particles(m, &p)) return FXCTL_FAIL;
    fxctl_frame_line(line, sizeof line, s->stream, m);
    printf("%s\n", line);
    fflush(stdout);
    if (!s->got++ && fxctl_age_ms(m) > FXCTL_STALE_MS)
        fprintf(stderr, "fxctl: note: the first frame is %.1f s old (the stream's newest, sent at once on subscribe: it "
                        "only sends on change, or it is paused)\n", fxctl_age_ms(m) / 1000);
    if (s->o->out_dir && fxctl_save_frame(s->o->out_dir, s->stream, m, line, particles ? &p : NULL)) r = FXCTL_FAIL;
    fxs_particles_free(&p);
    return r;
}

/* Prints the stream's params events; fails when the stream goes away. */
static int fxctl_on_event(struct fxctl_sub *s, cJSON *ev)
{
    const char *op = cJSON_GetObjectItemCaseSensitive(ev, "op")->valuestring;
    const cJSON *st = cJSON_GetObjectItemCaseSensitive(ev, "stream");
    const cJSON *why = cJSON_GetObjectItemCaseSensitive(ev, "reason");
    int mine = cJSON_IsString(st) && !strcmp(st->valuestring, s->stream);
    if (!mine) return 0;
    if (!strcmp(op, "params")) {
        fxctl_print_json(stdout, ev);
        fflush(stdout);
    } else if (!strcmp(op, "unsubscribed")) {
        fprintf(stderr, "fxctl: unsubscribed from stream \"%s\" (%s) after %ld of %ld frames\n", s->stream,
                cJSON_IsString(why) ? why->valuestring : "no reason given", s->got, s->o->frames);
        return FXCTL_FAIL;
    } else if (!strcmp(op, "error")) {
        fprintf(stderr, "fxctl: stream \"%s\" reported: ", s->stream);
        fxctl_print_json(stderr, ev);
    }
    return 0;
}

static int fxctl_make_dir(const char *dir)
{
    if (!mkdir(dir, 0777) || errno == EEXIST) return 0;
    fprintf(stderr, "fxctl: cannot create %s: %s\n", dir, strerror(errno));
    return FXCTL_FAIL;
}

static int fxctl_subscribe(struct fxc_client *c, const struct fxctl_opts *o, const cJSON *reply)
{
    const cJSON *ch = cJSON_GetObjectItemCaseSensitive(reply, "channel");
    struct fxctl_sub s = { o, o->args[0], 0, 0 };
    char err[512];
    int r = 0;
    if (!cJSON_IsNumber(ch)) {
        fprintf(stderr, "fxctl: subscribed reply without a channel\n");
        return FXCTL_FAIL;
    }
    s.channel = (uint32_t)ch->valuedouble;
    while (!r && s.got < o->frames) {
        struct fxc_msg m;
        int n = fxc_next(c, &m, o->timeout_ms, err, sizeof err);
        if (n <= 0) {
            if (n == 0)
                fprintf(stderr, "fxctl: timeout after %d ms waiting for frame %ld of %ld of \"%s\"\n",
                        o->timeout_ms, s.got + 1, o->frames, s.stream);
            else
                fprintf(stderr, "fxctl: %s\n", err);
            return FXCTL_FAIL;
        }
        r = m.type == FXC_MSG_FRAME ? fxctl_on_frame(&s, &m) : fxctl_on_event(&s, m.event);
        fxc_msg_free(&m);
    }
    return r;
}

/* After the list reply: prints created/destroyed events until o->count of them (each within
 * the timeout) or, without --count, until the connection ends. */
static int fxctl_watch(struct fxc_client *c, const struct fxctl_opts *o)
{
    char err[512];
    for (long seen = 0; !o->count || seen < o->count;) {
        struct fxc_msg m;
        int n = fxc_next(c, &m, o->count ? o->timeout_ms : 1000, err, sizeof err);
        if (n == 0 && !o->count) continue;
        if (n <= 0) {
            if (n == 0) fprintf(stderr, "fxctl: timeout after %d ms waiting for event %ld of %ld\n", o->timeout_ms, seen + 1, o->count);
            else fprintf(stderr, "fxctl: %s\n", err);
            return FXCTL_FAIL;
        }
        if (m.type == FXC_MSG_EVENT) {
            const char *op = cJSON_GetObjectItemCaseSensitive(m.event, "op")->valuestring;
            if (!strcmp(op, "created") || !strcmp(op, "destroyed")) {
                fxctl_print_json(stdout, m.event);
                fflush(stdout);
                seen++;
            }
        }
        fxc_msg_free(&m);
    }
    return 0;
}

/* After an accepted set: a note on stderr naming the parameters whose change restarted the
 * simulation (describe's `update`). Best effort: a failed lookup prints nothing. */
static void fxctl_restart_note(struct fxc_client *c, const struct fxctl_opts *o, const cJSON *req)
{
    const char *stream = cJSON_GetObjectItemCaseSensitive(req, "stream")->valuestring, *effect = NULL;
    cJSON *list = NULL, *desc = NULL, *q = cJSON_CreateObject();
    char err[256], names[512] = "";
    cJSON_AddStringToObject(q, "op", "list");
    if (!fxc_request(c, q, &list, o->timeout_ms, err, sizeof err))
        for (const cJSON *s = cJSON_GetObjectItemCaseSensitive(list, "streams")->child; s; s = s->next)
            if (!strcmp(cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(s, "stream")), stream))
                effect = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(s, "effect"));
    cJSON_Delete(q);
    q = cJSON_CreateObject();
    cJSON_AddStringToObject(q, "op", "describe");
    cJSON_AddStringToObject(q, "effect", effect ? effect : "");
    if (effect && !fxc_request(c, q, &desc, o->timeout_ms, err, sizeof err))
        for (const cJSON *p = cJSON_GetObjectItemCaseSensitive(desc, "params")->child; p; p = p->next) {
            const char *name = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(p, "name"));
            if (cJSON_GetObjectItemCaseSensitive(cJSON_GetObjectItemCaseSensitive(req, "params"), name) &&
                !strcmp(cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(p, "update")), "restart"))
                snprintf(names + strlen(names), sizeof names - strlen(names), "%s%s", names[0] ? ", " : "", name);
        }
    if (names[0]) fprintf(stderr, "fxctl: note: changing %s restarted the simulation of %s (sim_time back to 0)\n", names, stream);
    cJSON_Delete(q);
    cJSON_Delete(list);
    cJSON_Delete(desc);
}

/* ---- main ------------------------------------------------------------------------------------ */

static int fxctl_run(const struct fxctl_opts *o, const struct fxctl_cmd *cmd, const cJSON *req)
{
    struct fxc_client *c;
    cJSON *reply;
    char err[512];
    int r;
    if (o->out_dir && fxctl_make_dir(o->out_dir)) return FXCTL_FAIL;
    if ((r = fxc_connect_with(&c, o->url, &o->conn, o->timeout_ms, err, sizeof err))) {
        fprintf(stderr, "fxctl: %s\n", err);
        return r == -2 ? FXCTL_USAGE : FXCTL_FAIL;
    }
    r = fxc_request(c, req, &reply, o->timeout_ms, err, sizeof err);
    if (r) {
        fprintf(stderr, "fxctl: %s\n", err);
        r = FXCTL_FAIL;
    } else {
        cJSON_DeleteItemFromObjectCaseSensitive(reply, "id");
        const cJSON *only = !strcmp(cmd->name, "set") ? cJSON_GetObjectItemCaseSensitive(req, "params") : NULL;
        if (!o->human || !fxctl_print_human(stdout, reply, only)) fxctl_print_json(stdout, reply);
        fflush(stdout);
        if (!strcmp(cmd->name, "set")) fxctl_restart_note(c, o, req);
        if (!strcmp(cmd->name, "subscribe")) r = fxctl_subscribe(c, o, reply);
        if (!strcmp(cmd->name, "watch")) r = fxctl_watch(c, o);
    }
    cJSON_Delete(reply);
    fxc_close(c);
    return r;
}

int main(int argc, char **argv)
{
    struct fxctl_opts o = { .timeout_ms = FXCTL_DEFAULT_TIMEOUT_MS, .max_fps = -1, .human = isatty(STDOUT_FILENO) };
    const struct fxctl_cmd *cmd = NULL;
    const char *log = getenv("FXCTL_LWS_LOG");
    cJSON *req = NULL;
    int r;
    o.url = getenv("FXCTL_URL") && *getenv("FXCTL_URL") ? getenv("FXCTL_URL") : FXCTL_DEFAULT_URL;
    o.conn.token = getenv("FXSTREAM_TOKEN");
    o.conn.ca_file = getenv("FXSTREAM_CA_FILE");
    lws_set_log_level(log ? atoi(log) : 0, NULL);
    if (!(o.args = calloc((size_t)argc, sizeof *o.args))) return FXCTL_FAIL;
    r = fxctl_parse_args(&o, argc, argv);
    if (r == 0 && !(cmd = fxctl_find_cmd(o.cmd))) r = fxctl_unknown_cmd(o.cmd);
    if (r == 0) r = fxctl_validate(&o, cmd);
    if (r == 0) r = fxctl_build(&o, cmd, &req);
    if (r == 0) r = fxctl_run(&o, cmd, req);
    cJSON_Delete(req);
    free(o.args);
    return r < 0 ? FXCTL_OK : r;
}
