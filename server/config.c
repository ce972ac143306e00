/* config.c — see config.h. */
#include <arpa/inet.h>
#include <getopt.h>
#include <libgen.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "config.h"
#include "jsonfile.h"
#include "log.h"

void config_usage(FILE *out)
{
    fputs("usage: fxstreamd [options]\n"
          "Real-time effects server: runs OpenCL effects and streams their frames over WebSockets.\n"
          "\n"
          "  --port N           TCP port for HTTP and WebSocket (default 7681; 0 picks a free port)\n"
          "  --listen ADDR      address to bind (default 127.0.0.1)\n"
          "  --config FILE      JSON configuration file (see README.md); flags override it\n"
          "  --state-dir DIR    keep streams and parameters in DIR/streams.json across restarts\n"
          "  --device SPEC      OpenCL device: auto (default: a GPU if any, else the CPU), cpu, gpu,\n"
          "                     or P:D (platform index:device index, as `clinfo -l` lists them)\n"
          "  --web-root DIR     static files served at / (default: clients/web next to the binary)\n"
          "  --assets-dir DIR   OBJ models offered to compound_eye's `model` parameter (default: none)\n"
          "  --tls-cert FILE    PEM certificate (chain): serve only TLS (https://, wss://)\n"
          "  --tls-key FILE     PEM private key of --tls-cert\n"
          "  --log-level LEVEL  error, warn, info (default) or debug\n"
          "  --cluster URL      cluster mode: streams and parameters live in Redis at\n"
          "                     redis://HOST[:PORT][/DB], shared with the other daemons there\n"
          "                     (password: environment FXS_REDIS_PASSWORD)\n"
          "  --node-id NAME     this daemon's name in the cluster (default: the host name)\n"
          "  --role ROLE        in a cluster: compute (takes streams and computes them), edge\n"
          "                     (no OpenCL: relays the frames others compute) or both (default)\n"
          "  --help             this text\n"
          "\n"
          "Endpoints: GET /healthz (JSON), GET /metrics (Prometheus), WebSocket /v1/ws\n"
          "(subprotocol fxstream.v1; protocol/PROTOCOL.md).\n"
          "Access tokens: the config file's \"tokens\" and FXSTREAMD_TOKENS=role:token,...\n"
          "(roles view, tune, admin); with none the daemon listens on loopback only.\n",
          out);
}

static void config_defaults(struct config *cfg)
{
    memset(cfg, 0, sizeof *cfg);
    snprintf(cfg->listen, sizeof cfg->listen, "127.0.0.1");
    cfg->port = 7681;
    snprintf(cfg->device, sizeof cfg->device, "auto");
    cfg->log_level = LOG_INFO;
    cfg->pause_idle = true;
    cfg->limits = (struct limits){
        .max_connections = 1024,
        .max_streams = 64,
        .max_subscriptions = 16,
        .max_message_bytes = 64 * 1024,
        .max_json_depth = 32,
        .max_control_per_sec = 100,
        .max_queued_messages = 1024,
        .max_queued_bytes = 262144,
        .stall_timeout_s = 10,
        .max_buffered_bytes = 256 * 1024,
    };
    /* The web client next to the binary: <dir of fxstreamd>/../clients/web. */
    char exe[PATH_MAX];
    ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
    struct stat st;
    if (n > 0) {
        exe[n] = 0;
        snprintf(cfg->web_root, sizeof cfg->web_root, "%s/../clients/web", dirname(exe));
        if (stat(cfg->web_root, &st) || !S_ISDIR(st.st_mode)) cfg->web_root[0] = 0;
    }
}

static int config_int(const char *s, int min, int max, int *out)
{
    char *end;
    long v = strtol(s, &end, 10);
    if (!*s || *end || v < min || v > max) return -1;
    *out = (int)v;
    return 0;
}

static int config_str(char *dst, size_t cap, const char *src, const char *what, struct fx_err *err)
{
    if (strlen(src) >= cap) return fx_fail(err, "bad_request", what, "%s is too long", what);
    snprintf(dst, cap, "%s", src);
    return 0;
}

static int config_device(const char *spec, char *dst, size_t cap, struct fx_err *err)
{
    int p, d;
    char extra;
    bool ok = !strcmp(spec, "auto") || !strcmp(spec, "cpu") || !strcmp(spec, "gpu") ||
              (sscanf(spec, "%d:%d%c", &p, &d, &extra) == 2 && p >= 0 && d >= 0);
    if (!ok) return fx_fail(err, "bad_request", "device", "--device: expected auto, cpu, gpu or P:D, got \"%s\"", spec);
    return config_str(dst, cap, spec, "device", err);
}

/* ---- the JSON file ---- */

struct config_limit_key {
    const char *name;
    size_t offset;
    int min, max;
};

static const struct config_limit_key config_limit_keys[] = {
    {"max_connections", offsetof(struct limits, max_connections), 1, 100000},
    {"max_streams", offsetof(struct limits, max_streams), 1, 10000},
    {"max_subscriptions", offsetof(struct limits, max_subscriptions), 1, 1024},
    {"max_message_bytes", offsetof(struct limits, max_message_bytes), 1024, 16 * 1024 * 1024},
    {"max_json_depth", offsetof(struct limits, max_json_depth), 4, 1000},
    {"max_control_per_sec", offsetof(struct limits, max_control_per_sec), 1, 1000000},
    {"max_queued_messages", offsetof(struct limits, max_queued_messages), 16, 1000000},
    {"max_queued_bytes", offsetof(struct limits, max_queued_bytes), 65536, 256 * 1024 * 1024},
    {"stall_timeout_s", offsetof(struct limits, stall_timeout_s), 1, 3600},
    {"max_buffered_bytes", offsetof(struct limits, max_buffered_bytes), 16 * 1024, 64 * 1024 * 1024},
};

static int config_limits(const cJSON *obj, struct limits *l, struct fx_err *err)
{
    if (!cJSON_IsObject(obj)) return fx_fail(err, "bad_request", "limits", "limits: expected an object");
    for (const cJSON *e = obj->child; e; e = e->next) {
        const struct config_limit_key *k = NULL;
        for (size_t i = 0; i < sizeof config_limit_keys / sizeof *config_limit_keys; i++)
            if (!strcmp(config_limit_keys[i].name, e->string)) k = &config_limit_keys[i];
        if (!k) return fx_fail(err, "bad_request", e->string, "limits: unknown key \"%s\"", e->string);
        double v = e->valuedouble;
        if (!cJSON_IsNumber(e) || v != (int)v || v < k->min || v > k->max)
            return fx_fail(err, "bad_request", e->string, "limits.%s: expected an integer in [%d, %d]", k->name,
                           k->min, k->max);
        *(int *)((char *)l + k->offset) = (int)v;
    }
    return 0;
}

/* "tokens": [{"role": "tune", "token": "..."}] */
static int config_tokens(const cJSON *arr, struct access *a, struct fx_err *err)
{
    if (!cJSON_IsArray(arr)) return fx_fail(err, "bad_request", "tokens", "tokens: expected an array");
    for (const cJSON *t = arr->child; t; t = t->next) {
        const cJSON *role = cJSON_GetObjectItemCaseSensitive(t, "role");
        const cJSON *tok = cJSON_GetObjectItemCaseSensitive(t, "token");
        if (!cJSON_IsObject(t) || cJSON_GetArraySize(t) != 2 || !cJSON_IsString(role) || !cJSON_IsString(tok))
            return fx_fail(err, "bad_request", "tokens", "tokens: each entry is {\"role\": ..., \"token\": ...}");
        if (access_add_token(a, role->valuestring, tok->valuestring, "tokens", err)) return -1;
    }
    return 0;
}

/* A config key holding an array of strings (allowed_origins, allowed_hosts), each added by add. */
static int config_names(const cJSON *arr, struct access *a, int (*add)(struct access *, const char *, struct fx_err *),
                        struct fx_err *err)
{
    const char *k = arr->string;
    if (!cJSON_IsArray(arr)) return fx_fail(err, "bad_request", k, "%s: expected an array", k);
    for (const cJSON *o = arr->child; o; o = o->next) {
        if (!cJSON_IsString(o)) return fx_fail(err, "bad_request", k, "%s: expected strings", k);
        if (add(a, o->valuestring, err)) return -1;
    }
    return 0;
}

static int config_file_key(struct config *cfg, const cJSON *e, struct fx_err *err)
{
    const char *k = e->string;
    if (!strcmp(k, "allowed_hosts")) return config_names(e, &cfg->access, access_add_host, err);
    if (!strcmp(k, "limits")) return config_limits(e, &cfg->limits, err);
    if (!strcmp(k, "tokens")) return config_tokens(e, &cfg->access, err);
    if (!strcmp(k, "allowed_origins")) return config_names(e, &cfg->access, access_add_origin, err);
    if (!strcmp(k, "streams")) {
        if (!cJSON_IsArray(e)) return fx_fail(err, "bad_request", k, "streams: expected an array");
        cfg->streams = cJSON_Duplicate(e, 1);
        return 0;
    }
    if (!strcmp(k, "pause_idle")) {
        if (!cJSON_IsBool(e)) return fx_fail(err, "bad_request", k, "pause_idle: expected true or false");
        cfg->pause_idle = cJSON_IsTrue(e);
        return 0;
    }
    if (!strcmp(k, "port")) {
        if (!cJSON_IsNumber(e) || e->valuedouble != (int)e->valuedouble || e->valuedouble < 0 || e->valuedouble > 65535)
            return fx_fail(err, "bad_request", k, "port: expected an integer in [0, 65535]");
        cfg->port = (int)e->valuedouble;
        return 0;
    }
    static const char *const string_keys[] = {"listen", "state_dir", "web_root", "device", "assets_dir",
                                              "tls_cert", "tls_key", "cluster", "node_id", "role", "log_level", NULL};
    bool known = false;
    for (const char *const *n = string_keys; *n && !known; n++) known = !strcmp(*n, k);
    if (!known) return fx_fail(err, "bad_request", k, "unknown configuration key \"%s\"", k);
    if (!cJSON_IsString(e)) return fx_fail(err, "bad_request", k, "%s: expected a string", k);
    const char *v = e->valuestring;
    if (!strcmp(k, "listen")) return config_str(cfg->listen, sizeof cfg->listen, v, k, err);
    if (!strcmp(k, "state_dir")) return config_str(cfg->state_dir, sizeof cfg->state_dir, v, k, err);
    if (!strcmp(k, "web_root")) return config_str(cfg->web_root, sizeof cfg->web_root, v, k, err);
    if (!strcmp(k, "device")) return config_device(v, cfg->device, sizeof cfg->device, err);
    if (!strcmp(k, "assets_dir")) return config_str(cfg->assets_dir, sizeof cfg->assets_dir, v, k, err);
    if (!strcmp(k, "tls_cert")) return config_str(cfg->tls_cert, sizeof cfg->tls_cert, v, k, err);
    if (!strcmp(k, "tls_key")) return config_str(cfg->tls_key, sizeof cfg->tls_key, v, k, err);
    if (!strcmp(k, "cluster")) return cluster_parse_url(k, v, &cfg->cluster, err);
    if (!strcmp(k, "node_id")) return config_str(cfg->cluster.node_id, sizeof cfg->cluster.node_id, v, k, err);
    if (!strcmp(k, "role")) return cluster_parse_role(k, v, &cfg->cluster, err);
    int lv = log_parse_level(v); /* the last string key: log_level */
    if (lv < 0) return fx_fail(err, "bad_request", k, "log_level: expected error, warn, info or debug");
    cfg->log_level = lv;
    return 0;
}

#define CONFIG_MAX_BYTES (16L << 20)

static int config_load_file(struct config *cfg, const char *path, struct fx_err *err)
{
    cJSON *doc;
    char why[128] = "";
    if (jsonfile_read(path, CONFIG_MAX_BYTES, &doc, why, sizeof why))
        return fx_fail(err, "bad_request", "config", "cannot open config file %s", path);
    int rc = 0;
    if (!cJSON_IsObject(doc))
        rc = fx_fail(err, "bad_json", "config", "%s: %s", path, why[0] ? why : "not a JSON object");
    for (const cJSON *e = doc ? doc->child : NULL; e && !rc; e = e->next) rc = config_file_key(cfg, e, err);
    cJSON_Delete(doc);
    return rc;
}

/* ---- flags ---- */

enum {
    OPT_PORT = 1, OPT_LISTEN, OPT_CONFIG, OPT_STATE, OPT_DEVICE, OPT_WEB, OPT_LOG, OPT_HELP, OPT_ASSETS, OPT_CERT,
    OPT_KEY, OPT_CLUSTER, OPT_NODE, OPT_ROLE
};

static const struct option config_options[] = {
    {"port", required_argument, NULL, OPT_PORT},       {"listen", required_argument, NULL, OPT_LISTEN},
    {"config", required_argument, NULL, OPT_CONFIG},   {"state-dir", required_argument, NULL, OPT_STATE},
    {"device", required_argument, NULL, OPT_DEVICE},   {"web-root", required_argument, NULL, OPT_WEB},
    {"log-level", required_argument, NULL, OPT_LOG},   {"help", no_argument, NULL, OPT_HELP},
    {"assets-dir", required_argument, NULL, OPT_ASSETS}, {"tls-cert", required_argument, NULL, OPT_CERT},
    {"tls-key", required_argument, NULL, OPT_KEY},     {"cluster", required_argument, NULL, OPT_CLUSTER},
    {"node-id", required_argument, NULL, OPT_NODE},    {"role", required_argument, NULL, OPT_ROLE},
    {NULL, 0, NULL, 0},
};

static int config_flag(struct config *cfg, int opt, const char *arg, struct fx_err *err)
{
    switch (opt) {
    case OPT_PORT:
        if (config_int(arg, 0, 65535, &cfg->port))
            return fx_fail(err, "bad_request", "port", "--port: expected 0-65535, got \"%s\"", arg);
        return 0;
    case OPT_LISTEN: return config_str(cfg->listen, sizeof cfg->listen, arg, "--listen", err);
    case OPT_STATE: return config_str(cfg->state_dir, sizeof cfg->state_dir, arg, "--state-dir", err);
    case OPT_DEVICE: return config_device(arg, cfg->device, sizeof cfg->device, err);
    case OPT_WEB: return config_str(cfg->web_root, sizeof cfg->web_root, arg, "--web-root", err);
    case OPT_ASSETS: return config_str(cfg->assets_dir, sizeof cfg->assets_dir, arg, "--assets-dir", err);
    case OPT_CERT: return config_str(cfg->tls_cert, sizeof cfg->tls_cert, arg, "--tls-cert", err);
    case OPT_KEY: return config_str(cfg->tls_key, sizeof cfg->tls_key, arg, "--tls-key", err);
    case OPT_CLUSTER: return cluster_parse_url("--cluster", arg, &cfg->cluster, err);
    case OPT_NODE: return config_str(cfg->cluster.node_id, sizeof cfg->cluster.node_id, arg, "--node-id", err);
    case OPT_ROLE: return cluster_parse_role("--role", arg, &cfg->cluster, err);
    case OPT_LOG:
        if ((cfg->log_level = log_parse_level(arg)) < 0)
            return fx_fail(err, "bad_request", "log-level", "--log-level: expected error, warn, info or debug");
        return 0;
    default: return 0;
    }
}

static bool config_is_loopback(const char *addr)
{
    struct in_addr a;
    if (!strcmp(addr, "localhost")) return true;
    return inet_pton(AF_INET, addr, &a) == 1 && (ntohl(a.s_addr) >> 24) == 127;
}

/* Cluster mode: the node id (default: the host name) and the password from the environment. */
static int config_cluster(struct cluster_config *c, struct fx_err *err)
{
    if (!c->url[0]) {
        if (c->node_id[0]) return fx_fail(err, "bad_request", "node-id", "--node-id needs --cluster");
        if (c->role_set) return fx_fail(err, "bad_request", "role", "--role needs --cluster");
        return 0;
    }
    bool named = c->node_id[0];
    c->node_id_default = !named;
    if (!named && gethostname(c->node_id, sizeof c->node_id - 1))
        return fx_fail(err, "bad_request", "node-id", "cannot read the host name for the node id: set --node-id");
    if (!hub_valid_name(c->node_id))
        return fx_fail(err, "bad_request", "node-id", "node id \"%.63s\"%s must be 1-%d characters of A-Z a-z 0-9 _ . -%s",
                       c->node_id, named ? "" : " (the host name)", STREAM_NAME_MAX - 1, named ? "" : ": set --node-id");
    const char *pw = getenv("FXS_REDIS_PASSWORD");
    if (pw && strlen(pw) >= sizeof c->password)
        return fx_fail(err, "bad_request", "FXS_REDIS_PASSWORD", "FXS_REDIS_PASSWORD is too long (at most %zu bytes)",
                       sizeof c->password - 1);
    snprintf(c->password, sizeof c->password, "%s", pw ? pw : "");
    return 0;
}

/* Rules across keys, and files that must exist. */
static int config_check(const struct config *cfg, struct fx_err *err)
{
    struct stat st;
    if (cfg->web_root[0] && (stat(cfg->web_root, &st) || !S_ISDIR(st.st_mode)))
        return fx_fail(err, "bad_request", "web-root", "web root %s is not a directory", cfg->web_root);
    if (!cfg->tls_cert[0] != !cfg->tls_key[0])
        return fx_fail(err, "bad_request", "tls", "TLS needs both a certificate (--tls-cert) and its key (--tls-key)");
    const char *files[] = {cfg->tls_cert, cfg->tls_key};
    for (int i = 0; i < 2; i++)
        if (files[i][0] && access(files[i], R_OK))
            return fx_fail(err, "bad_request", "tls", "cannot read %s", files[i]);
    if (!cfg->access.ntokens && !config_is_loopback(cfg->listen))
        return fx_fail(err, "bad_request", "listen",
                       "no access tokens are configured, so every client would be admin: refusing to listen on %s "
                       "(configure tokens, README \"Security\", or listen on 127.0.0.1)",
                       cfg->listen);
    return 0;
}

enum config_result config_parse(int argc, char **argv, struct config *cfg, struct fx_err *err)
{
    config_defaults(cfg);
    const char *config_file = NULL;
    int opt;
    opterr = 0;
    optind = 1;
    /* First pass: --help, --config and unknown flags; the file is loaded before flags apply. */
    while ((opt = getopt_long(argc, argv, ":", config_options, NULL)) != -1) {
        if (opt == OPT_HELP) return CONFIG_HELP;
        if (opt == OPT_CONFIG) config_file = optarg;
        if (opt == '?') {
            fx_fail(err, "bad_request", NULL, "unknown option \"%s\" (see --help)", argv[optind - 1]);
            return CONFIG_ERROR;
        }
        if (opt == ':') {
            fx_fail(err, "bad_request", NULL, "option \"%s\" needs a value", argv[optind - 1]);
            return CONFIG_ERROR;
        }
    }
    if (optind < argc) {
        fx_fail(err, "bad_request", NULL, "unexpected argument \"%s\" (see --help)", argv[optind]);
        return CONFIG_ERROR;
    }
    if (config_file && config_load_file(cfg, config_file, err)) return CONFIG_ERROR;
    optind = 1;
    while ((opt = getopt_long(argc, argv, ":", config_options, NULL)) != -1)
        if (config_flag(cfg, opt, optarg, err)) return CONFIG_ERROR;
    const char *env = getenv("FXSTREAMD_TOKENS");
    if (env && access_add_env(&cfg->access, env, err)) return CONFIG_ERROR;
    return config_cluster(&cfg->cluster, err) || config_check(cfg, err) ? CONFIG_ERROR : CONFIG_OK;
}

void config_free(struct config *cfg)
{
    cJSON_Delete(cfg->streams);
    cfg->streams = NULL;
}
