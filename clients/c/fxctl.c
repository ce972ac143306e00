/* fxctl.c — the command-line client of fxstreamd, built on libfxclient's public API
 * (fxclient.h), as any program outside the tree would be.
 *
 * Owns argument parsing, turning one command into one fxstream.v1 request, and
 * printing: on a terminal, replies for people (fxctl_print.h); with --json or when
 * stdout is not a terminal, every reply is one line of JSON (easy to pipe into jq or a
 * script). Every failure is one line on stderr with exit status 1 (server or
 * transport) or 2 (usage); notes (a set that restarts the simulation, a stale first
 * frame) go to stderr too. `subscribe` counts steps in fxctl_sub.h, which prints and
 * writes the frames with fxctl_save.h. */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cjson/cJSON.h>

#include "fxclient.h"
#include "fxctl_print.h"
#include "fxctl_sub.h"
#include "suggest.h"

#define FXCTL_DEFAULT_URL "ws://127.0.0.1:7681/v1/ws"
#define FXCTL_DEFAULT_TIMEOUT_MS 10000

enum { FXCTL_OK = 0, FXCTL_FAIL = 1, FXCTL_USAGE = 2 };

struct fxctl_opts {
    const char *url;
    int timeout_ms;
    struct fxc_options conn; /* token, CA file */
    long frames;       /* subscribe --frames: steps, or frames of --kind; 0 when not given */
    long count;        /* watch --count, 0 = until interrupted */
    double max_fps;    /* subscribe --max-fps, < 0 when not given */
    int kind;          /* subscribe --kind, 0 = every kind */
    const char *encoding; /* subscribe --encoding, NULL when not given */
    long max_particles;   /* subscribe --max-particles, 0 when not given */
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
    "  subscribe NAME --frames N [--max-fps F] [--kind K] [--encoding E]\n"
    "            [--max-particles P] [--out DIR]\n"
    "                                receive N steps of NAME (a step: the frames computed\n"
    "                                together, e.g. energy's texture and its light rig),\n"
    "                                or with --kind N frames of kind K (1 particles,\n"
    "                                2 texture, 3 light rig, 4 look-up table); with\n"
    "                                --encoding engine particles and textures come in\n"
    "                                the engine encoding (PROTOCOL.md §7.8); with\n"
    "                                --max-particles at most P particles a frame\n"
    "                                (1000..4194304; the server serves the largest of\n"
    "                                its steps 1000, 2000, 5000, ... 2000000 at most P,\n"
    "                                its reply's max_particles); prints the\n"
    "                                subscribed reply, then one JSON line per frame (stream,\n"
    "                                channel, kind, seq, param_rev, sim_time,\n"
    "                                server_time_us, latency_ms, codec, payload_bytes,\n"
    "                                width and height, or count and, when a budget cut\n"
    "                                the frame to a subset, total: the stream frame's\n"
    "                                count; flags) and any params\n"
    "                                event of NAME; with --out writes the payload to\n"
    "                                DIR/NAME-SEQ.exr (texture: codec 1 as received, the\n"
    "                                engine encoding's halves as an EXR, its payload to\n"
    "                                .bin), DIR/NAME-SEQ-PROD.png per look-up-table\n"
    "                                product (kind 4), the decoded particles to\n"
    "                                DIR/NAME-SEQ.ply (kind 1: binary PLY, x y z\n"
    "                                temperature fuel flags, or x y z temperature in the\n"
    "                                engine encoding, then vx vy vz if the stream sends\n"
    "                                velocities, and the payload as received to .bin) or the\n"
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
    "                 is not a terminal; on a terminal replies print for people, below)\n"
    "  --timeout MS   limit for connecting, for each reply and, with subscribe, for\n"
    "                 each step (frame of --kind: other kinds and events do not extend\n"
    "                 it; the error names the kinds that came); with watch --count,\n"
    "                 for each event (default 10000)\n"
    "  --help, -h     this text\n"
    "\n"
    "output: on a terminal, describe is a table per parameter group, get is aligned\n"
    "name = value, set shows the values it changed and the new rev, preset load the\n"
    "values that changed and what they were, list and presets are tables, create,\n"
    "destroy, reset and preset save/delete one sentence; otherwise (or with --json) each\n"
    "reply is one line of JSON (the server's reply object without the request id). A\n"
    "set that restarts the simulation and a first frame older than 1 s are noted on\n"
    "stderr. Errors go to stderr as\n"
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
    } else if (!strcmp(name, "--max-particles")) {
        if (fxctl_parse_long(val, FXS_MAX_PARTICLES_MIN, &o->max_particles) || o->max_particles > FXS_MAX_PARTICLES_MAX)
            return fxctl_usage("--max-particles needs an integer in [1000, 4194304]", val);
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
    { "subscribe", 1, 1, "stream",
      "subscribe NAME --frames N [--max-fps F] [--kind K] [--encoding E] [--max-particles P] [--out DIR]" },
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
    if (!sub && (o->frames || o->max_fps >= 0 || o->kind || o->encoding || o->max_particles || o->out_dir))
        return fxctl_usage("--frames, --max-fps, --kind, --encoding, --max-particles and --out go with subscribe only",
                           NULL);
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
    if (o->max_particles) cJSON_AddNumberToObject(req, "max_particles", (double)o->max_particles);
    if (i < o->nargs) params = cJSON_AddObjectToObject(req, "params");
    for (; i < o->nargs && !r; i++) r = fxctl_add_kv(params, o->args[i]);
    return r;
}

/* ---- output -------------------------------------------------------------------------- */

static void fxctl_print_json(FILE *f, const cJSON *j)
{
    char *s = cJSON_PrintUnformatted(j);
    if (s) fprintf(f, "%s\n", s);
    free(s);
}

/* Sends req and parses its reply: the reply object without its id, or NULL (with `report`,
 * after printing the error, "fxctl: code: message" or the transport's, on stderr). */
static cJSON *fxctl_ask(struct fxc_client *c, const struct fxctl_opts *o, const cJSON *req, int report)
{
    struct fxc_event ev;
    char err[512], *text = cJSON_PrintUnformatted(req);
    cJSON *reply = NULL;
    int r = text ? fxc_request(c, text, &ev, o->timeout_ms, err, sizeof err) : -1;
    if (!text) snprintf(err, sizeof err, "out of memory");
    if (!r && !(reply = cJSON_Parse(ev.json))) snprintf(err, sizeof err, "out of memory");
    if (!reply && report) fprintf(stderr, "fxctl: %s\n", err);
    cJSON_DeleteItemFromObjectCaseSensitive(reply, "id");
    fxc_event_free(&ev);
    free(text);
    return reply;
}

/* ---- subscribe and watch ------------------------------------------------------------- */

static int fxctl_make_dir(const char *dir)
{
    if (!mkdir(dir, 0777) || errno == EEXIST) return 0;
    fprintf(stderr, "fxctl: cannot create %s: %s\n", dir, strerror(errno));
    return FXCTL_FAIL;
}

/* After the subscribed reply: fxctl_sub.h. */
static int fxctl_frames(struct fxc_client *c, const struct fxctl_opts *o, const cJSON *reply)
{
    const cJSON *ch = cJSON_GetObjectItemCaseSensitive(reply, "channel");
    struct fxctl_sub_opts so = { o->args[0], o->frames, o->kind, o->timeout_ms, o->out_dir };
    if (cJSON_IsNumber(ch)) return fxctl_subscribe(c, &so, (uint32_t)ch->valuedouble) ? FXCTL_FAIL : 0;
    fprintf(stderr, "fxctl: subscribed reply without a channel\n");
    return FXCTL_FAIL;
}

/* After the list reply: prints created/destroyed events until o->count of them (each within
 * the timeout) or, without --count, until the connection ends. */
static int fxctl_watch(struct fxc_client *c, const struct fxctl_opts *o)
{
    char err[512];
    for (long seen = 0; !o->count || seen < o->count;) {
        struct fxc_event ev;
        int n = fxc_poll(c, &ev, o->count ? o->timeout_ms : 1000, err, sizeof err);
        if (n == 0 && !o->count) continue;
        if (n <= 0) {
            if (n == 0) fprintf(stderr, "fxctl: timeout after %d ms waiting for event %ld of %ld\n", o->timeout_ms, seen + 1, o->count);
            else fprintf(stderr, "fxctl: %s\n", err);
            return FXCTL_FAIL;
        }
        if (ev.type == FXC_EVENT_TEXT && !ev.id && (!strcmp(ev.op, "created") || !strcmp(ev.op, "destroyed"))) {
            printf("%s\n", ev.json);
            fflush(stdout);
            seen++;
        }
        fxc_event_free(&ev);
    }
    return 0;
}

/* The first element of obj's array or object `name`, or NULL. */
static const cJSON *fxctl_first(const cJSON *obj, const char *name)
{
    const cJSON *a = cJSON_GetObjectItemCaseSensitive(obj, name);
    return a ? a->child : NULL;
}

/* The effect of stream (from list), or NULL; *list keeps the reply that owns it. */
static const char *fxctl_effect_of(struct fxc_client *c, const struct fxctl_opts *o, const char *stream, cJSON **list)
{
    cJSON *q = cJSON_CreateObject();
    cJSON_AddStringToObject(q, "op", "list");
    *list = fxctl_ask(c, o, q, 0);
    cJSON_Delete(q);
    for (const cJSON *s = fxctl_first(*list, "streams"); s; s = s->next)
        if (!strcmp(cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(s, "stream")), stream))
            return cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(s, "effect"));
    return NULL;
}

/* After an accepted set: a note on stderr naming the parameters whose change restarted the
 * simulation (describe's `update`). Best effort: a failed lookup prints nothing. */
static void fxctl_restart_note(struct fxc_client *c, const struct fxctl_opts *o, const cJSON *req)
{
    const char *stream = cJSON_GetObjectItemCaseSensitive(req, "stream")->valuestring;
    cJSON *list, *desc = NULL, *q = cJSON_CreateObject();
    const char *effect = fxctl_effect_of(c, o, stream, &list);
    char names[512] = "";
    cJSON_AddStringToObject(q, "op", "describe");
    cJSON_AddStringToObject(q, "effect", effect ? effect : "");
    if (effect && (desc = fxctl_ask(c, o, q, 0)))
        for (const cJSON *p = fxctl_first(desc, "params"); p; p = p->next) {
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

/* A preset load on a terminal: the stream's parameters before it, for the diff; NULL else
 * (or when the get fails: the load then reports the error). */
static cJSON *fxctl_params_before(struct fxc_client *c, const struct fxctl_opts *o, const cJSON *req)
{
    cJSON *q, *reply;
    if (!o->human || strcmp(cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(req, "op")), "preset_load")) return NULL;
    q = cJSON_CreateObject();
    cJSON_AddStringToObject(q, "op", "get");
    cJSON_AddStringToObject(q, "stream", cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(req, "stream")));
    reply = fxctl_ask(c, o, q, 0);
    cJSON_Delete(q);
    return reply;
}

/* The names of the parameters whose values differ between before's and reply's documents. */
static cJSON *fxctl_changed(const cJSON *before, const cJSON *reply)
{
    const cJSON *old = cJSON_GetObjectItemCaseSensitive(before, "params");
    cJSON *names = cJSON_CreateObject();
    for (const cJSON *p = fxctl_first(reply, "params"); p && names; p = p->next)
        if (!cJSON_Compare(p, cJSON_GetObjectItemCaseSensitive(old, p->string), 1)) cJSON_AddTrueToObject(names, p->string);
    return names;
}

/* Prints the reply: for people on a terminal (a set's values, a preset load's changes), else
 * as one line of JSON. */
static void fxctl_print_reply(const struct fxctl_opts *o, const struct fxctl_cmd *cmd, const cJSON *req,
                              const cJSON *reply, const cJSON *before)
{
    const cJSON *only = !strcmp(cmd->name, "set") ? cJSON_GetObjectItemCaseSensitive(req, "params") : NULL;
    cJSON *changed = before ? fxctl_changed(before, reply) : NULL;
    if (!o->human ||
        !fxctl_print_human(stdout, reply, changed ? changed : only, before ? cJSON_GetObjectItemCaseSensitive(before, "params") : NULL))
        fxctl_print_json(stdout, reply);
    fflush(stdout);
    cJSON_Delete(changed);
}

static int fxctl_run(const struct fxctl_opts *o, const struct fxctl_cmd *cmd, const cJSON *req)
{
    struct fxc_client *c;
    cJSON *reply, *before;
    char err[512];
    int r = 0;
    if (o->out_dir && fxctl_make_dir(o->out_dir)) return FXCTL_FAIL;
    if ((r = fxc_connect(&c, o->url, &o->conn, o->timeout_ms, err, sizeof err))) {
        fprintf(stderr, "fxctl: %s\n", err);
        return r == -2 ? FXCTL_USAGE : FXCTL_FAIL;
    }
    before = fxctl_params_before(c, o, req);
    if (!(reply = fxctl_ask(c, o, req, 1))) {
        r = FXCTL_FAIL;
    } else {
        fxctl_print_reply(o, cmd, req, reply, before);
        if (!strcmp(cmd->name, "set")) fxctl_restart_note(c, o, req);
        if (!strcmp(cmd->name, "subscribe")) r = fxctl_frames(c, o, reply);
        if (!strcmp(cmd->name, "watch")) r = fxctl_watch(c, o);
    }
    cJSON_Delete(before);
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
    if (log) fxc_set_log(atoi(log), NULL);
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
