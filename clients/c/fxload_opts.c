/* fxload_opts.c — fxload's command line: one table of options (each with its own small
 * parser, fxctl's conventions: --opt VALUE or --opt=VALUE, one-line errors, exit 2), the
 * --set specs, and the checks of combinations and defaults (fxload_opts.h). */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fxload_opts.h"
#include "fxs_frame.h"

int ld_usage(const char *why, const char *arg)
{
    fprintf(stderr, "fxload: %s%s%s\nTry 'fxload --help'.\n", why, arg ? ": " : "", arg ? arg : "");
    return LD_USAGE;
}

int ld_parse_double(const char *s, double *out)
{
    char *end;
    double v;
    errno = 0;
    v = strtod(s, &end);
    if (errno || end == s || *end || !isfinite(v)) return -1;
    *out = v;
    return 0;
}

static int ld_parse_long(const char *s, long *out)
{
    char *end;
    long v;
    errno = 0;
    v = strtol(s, &end, 10);
    if (errno || end == s || *end) return -1;
    *out = v;
    return 0;
}

int ld_valid_stream_name(const char *s, size_t n)
{
    if (n < 1 || n > LD_NAME_MAX - 1) return 0;
    for (size_t i = 0; i < n; i++) {
        char c = s[i];
        if (!((c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' || c == '.' ||
              c == '-'))
            return 0;
    }
    return 1;
}

static int ld_valid_param_name(const char *s)
{
    if (!*s || strlen(s) > LD_NAME_MAX - 1) return 0;
    for (; *s; s++)
        if (!((*s >= 'A' && *s <= 'Z') || (*s >= 'a' && *s <= 'z') || (*s >= '0' && *s <= '9') || *s == '_'))
            return 0;
    return 1;
}

static int ld_is_integer_text(const char *s)
{
    size_t i = (s[0] == '-' || s[0] == '+') ? 1 : 0;
    if (!s[i]) return 0;
    for (; s[i]; i++)
        if (s[i] < '0' || s[i] > '9') return 0;
    return 1;
}

/* The value of --set after '=': LO..HI, or a JSON value. */
static int ld_parse_set_value(struct ld_setspec *sp, const char *val, const char *arg)
{
    const char *dd = strstr(val, "..");
    char lo[64], hi[64];
    if (dd && (size_t)(dd - val) < sizeof lo && strlen(dd + 2) < sizeof hi) {
        snprintf(lo, sizeof lo, "%.*s", (int)(dd - val), val);
        snprintf(hi, sizeof hi, "%s", dd + 2);
        if (ld_parse_double(lo, &sp->lo) || ld_parse_double(hi, &sp->hi) || sp->lo > sp->hi)
            return ld_usage("--set range needs numbers LO..HI with LO <= HI", arg);
        sp->range = 1;
        sp->integer = ld_is_integer_text(lo) && ld_is_integer_text(hi);
        return 0;
    }
    if (!*val || !(sp->value = cJSON_ParseWithOpts(val, NULL, 1)))
        return ld_usage("--set value must be LO..HI or a JSON value (strings in quotes)", arg);
    return 0;
}

/* Parses --set STREAM.PARAM=LO..HI or STREAM.PARAM=JSON. */
static int ld_parse_set(struct ld_setspec *sp, const char *arg)
{
    const char *eq = strchr(arg, '='), *dot;
    char lhs[160];
    if (!eq || eq == arg || (size_t)(eq - arg) >= sizeof lhs)
        return ld_usage("--set needs STREAM.PARAM=LO..HI or STREAM.PARAM=JSON", arg);
    snprintf(lhs, sizeof lhs, "%.*s", (int)(eq - arg), arg);
    dot = strrchr(lhs, '.');
    if (!dot || !ld_valid_stream_name(lhs, (size_t)(dot - lhs)) || !ld_valid_param_name(dot + 1))
        return ld_usage("--set needs STREAM.PARAM (a stream name, a dot, a top-level parameter name)", arg);
    snprintf(sp->stream, sizeof sp->stream, "%.*s", (int)(dot - lhs), lhs);
    snprintf(sp->param, sizeof sp->param, "%s", dot + 1);
    return ld_parse_set_value(sp, eq + 1, arg);
}

/* ---- the option table ------------------------------------------------------------ */

static int ld_opt_url(struct ld_opts *o, const char *v)
{
    if (o->nurls == LD_MAX_URLS) return ld_usage("--url may be given at most 16 times", v);
    o->urls[o->nurls++] = v;
    o->url = o->urls[0];
    return 0;
}

const char *ld_url_for(const struct ld_opts *o, long i) { return o->nurls ? o->urls[i % o->nurls] : o->url; }

void ld_urls_text(const struct ld_opts *o, char *out, size_t cap)
{
    size_t n = (size_t)snprintf(out, cap, "%s", o->url);
    for (int i = 1; i < o->nurls && n < cap; i++) n += (size_t)snprintf(out + n, cap - n, ", %s", o->urls[i]);
    if (o->nurls > 1 && n < cap) snprintf(out + n, cap - n, " (%d daemons)", o->nurls);
}
static int ld_opt_token(struct ld_opts *o, const char *v) { o->token = v; return 0; }
static int ld_opt_ca_file(struct ld_opts *o, const char *v) { o->ca_file = v; return 0; }
static int ld_opt_streams(struct ld_opts *o, const char *v) { o->streams_spec = v; return 0; }
static int ld_opt_quiet(struct ld_opts *o, const char *v) { (void)v; o->quiet = 1; return 0; }
static int ld_opt_payloads(struct ld_opts *o, const char *v) { (void)v; o->payloads = 1; return 0; }
static int ld_opt_keep(struct ld_opts *o, const char *v) { (void)v; o->keep = 1; return 0; }

static int ld_opt_connections(struct ld_opts *o, const char *v)
{
    if (ld_parse_long(v, &o->connections) || o->connections < 1 || o->connections > LD_MAX_CONNECTIONS)
        return ld_usage("--connections needs an integer from 1 to 10000", v);
    return 0;
}

static int ld_opt_mode(struct ld_opts *o, const char *v)
{
    if (!strcmp(v, "subscribe")) o->mode = LD_SUBSCRIBE;
    else if (!strcmp(v, "set")) o->mode = LD_SET;
    else return ld_usage("--mode must be subscribe or set", v);
    return 0;
}

static int ld_opt_max_fps(struct ld_opts *o, const char *v)
{
    if (ld_parse_double(v, &o->max_fps) || !(o->max_fps >= FXS_MAX_FPS_MIN && o->max_fps <= FXS_MAX_FPS_MAX))
        return ld_usage("--max-fps needs a number in [0.01, 1000]", v);
    return 0;
}

static int ld_opt_max_particles(struct ld_opts *o, const char *v)
{
    if (ld_parse_long(v, &o->max_particles) || o->max_particles < FXS_MAX_PARTICLES_MIN ||
        o->max_particles > FXS_MAX_PARTICLES_MAX)
        return ld_usage("--max-particles needs an integer in [1000, 4194304]", v);
    return 0;
}

static int ld_opt_set(struct ld_opts *o, const char *v)
{
    if (o->nsets >= LD_MAX_SETS) return ld_usage("too many --set options (at most 16)", v);
    return ld_parse_set(&o->sets[o->nsets++], v);
}

static int ld_opt_rate(struct ld_opts *o, const char *v)
{
    if (ld_parse_double(v, &o->rate) || !(o->rate > 0) || o->rate > 100000)
        return ld_usage("--rate needs messages per second in (0, 100000]", v);
    return 0;
}

static int ld_opt_duration(struct ld_opts *o, const char *v)
{
    if (ld_parse_double(v, &o->duration) || !(o->duration > 0) || o->duration > 86400)
        return ld_usage("--duration needs seconds in (0, 86400]", v);
    return 0;
}

static int ld_opt_ramp(struct ld_opts *o, const char *v)
{
    if (ld_parse_double(v, &o->ramp) || o->ramp < 0 || o->ramp > 86400)
        return ld_usage("--ramp needs seconds, 0 or more", v);
    o->ramp_given = 1;
    return 0;
}

static int ld_opt_json(struct ld_opts *o, const char *v)
{
    if (!*v) return ld_usage("--json needs a file name", NULL);
    o->json_path = v;
    return 0;
}

static int ld_opt_plot(struct ld_opts *o, const char *v)
{
    size_t n = strlen(v);
    if (n < 5 || (strcmp(v + n - 4, ".svg") && strcmp(v + n - 4, ".png")))
        return ld_usage("--plot needs a file name ending in .svg or .png", v);
    o->plot_path = v;
    return 0;
}

static int ld_opt_seed(struct ld_opts *o, const char *v)
{
    long s;
    if (ld_parse_long(v, &s) || s < 0) return ld_usage("--seed needs a non-negative integer", v);
    o->seed = (unsigned long)s;
    return 0;
}

static int ld_opt_max_p99(struct ld_opts *o, const char *v)
{
    if (ld_parse_double(v, &o->max_p99_ms) || !(o->max_p99_ms > 0) || o->max_p99_ms > 3600000)
        return ld_usage("--max-p99 needs milliseconds in (0, 3600000]", v);
    return 0;
}

static int ld_opt_min_delivered(struct ld_opts *o, const char *v)
{
    if (ld_parse_double(v, &o->min_delivered) || !(o->min_delivered > 0) || o->min_delivered > 100)
        return ld_usage("--min-delivered needs a percentage in (0, 100]", v);
    return 0;
}

static int ld_opt_max_skipped(struct ld_opts *o, const char *v)
{
    if (ld_parse_double(v, &o->max_skipped) || o->max_skipped < 0 || o->max_skipped >= 100)
        return ld_usage("--max-skipped needs a percentage in [0, 100)", v);
    return 0;
}

struct ld_optdef {
    const char *name;
    int takes_value;
    int (*set)(struct ld_opts *o, const char *val);
};

static const struct ld_optdef ld_optdefs[] = {
    { "--url", 1, ld_opt_url },
    { "--token", 1, ld_opt_token },
    { "--ca-file", 1, ld_opt_ca_file },
    { "--connections", 1, ld_opt_connections },
    { "--mode", 1, ld_opt_mode },
    { "--streams", 1, ld_opt_streams },
    { "--max-fps", 1, ld_opt_max_fps },
    { "--max-particles", 1, ld_opt_max_particles },
    { "--set", 1, ld_opt_set },
    { "--rate", 1, ld_opt_rate },
    { "--duration", 1, ld_opt_duration },
    { "--ramp", 1, ld_opt_ramp },
    { "--json", 1, ld_opt_json },
    { "--plot", 1, ld_opt_plot },
    { "--seed", 1, ld_opt_seed },
    { "--max-p99", 1, ld_opt_max_p99 },
    { "--min-delivered", 1, ld_opt_min_delivered },
    { "--max-skipped", 1, ld_opt_max_skipped },
    { "--quiet", 0, ld_opt_quiet },
    { "--payloads", 0, ld_opt_payloads },
    { "--keep", 0, ld_opt_keep },
};

static const struct ld_optdef *ld_find_opt(const char *name, size_t n)
{
    for (size_t i = 0; i < sizeof ld_optdefs / sizeof ld_optdefs[0]; i++)
        if (strlen(ld_optdefs[i].name) == n && !strncmp(ld_optdefs[i].name, name, n)) return &ld_optdefs[i];
    return NULL;
}

int ld_parse_args(struct ld_opts *o, int argc, char **argv, const char *help_text)
{
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *eq, *val;
        const struct ld_optdef *d;
        int r;
        if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
            fputs(help_text, stdout);
            return -1;
        }
        if (strncmp(a, "--", 2) != 0 || !a[2]) return ld_usage("unexpected argument", a);
        eq = strchr(a, '=');
        if (!(d = ld_find_opt(a, eq ? (size_t)(eq - a) : strlen(a)))) {
            char name[64];
            snprintf(name, sizeof name, "%.*s", eq ? (int)(eq - a) : (int)strlen(a), a);
            return ld_usage("unknown option", name);
        }
        if (!d->takes_value && eq) return ld_usage("option takes no value", d->name);
        val = eq ? eq + 1 : d->takes_value && i + 1 < argc ? argv[++i] : NULL;
        if (d->takes_value && !val) return ld_usage("option needs a value", d->name);
        if ((r = d->set(o, val))) return r;
    }
    return 0;
}

/* ---- combinations and defaults ---------------------------------------------------- */

static int ld_check_subscribe(const struct ld_opts *o)
{
    if (o->nsets) return ld_usage("--set goes with --mode set", NULL);
    if (o->rate >= 0) return ld_usage("--rate goes with --mode set", NULL);
    if (o->keep) return ld_usage("--keep goes with --mode set", NULL);
    return 0;
}

static int ld_check_set(struct ld_opts *o)
{
    if (o->streams_spec) return ld_usage("--streams goes with --mode subscribe (set mode uses --set)", NULL);
    if (o->max_fps >= 0) return ld_usage("--max-fps goes with --mode subscribe", NULL);
    if (o->max_particles) return ld_usage("--max-particles goes with --mode subscribe", NULL);
    if (o->min_delivered >= 0) return ld_usage("--min-delivered goes with --mode subscribe", NULL);
    if (o->max_skipped >= 0) return ld_usage("--max-skipped goes with --mode subscribe", NULL);
    if (o->rate < 0) o->rate = LD_DEFAULT_RATE;
    return o->nsets ? 0 : ld_parse_set(&o->sets[o->nsets++], LD_DEFAULT_SET);
}

int ld_opts_check(struct ld_opts *o)
{
    if (!o->ramp_given) o->ramp = o->duration > 2 ? 1 : o->duration / 2;
    if (o->ramp >= o->duration) return ld_usage("--ramp must be shorter than --duration", NULL);
    return o->mode == LD_SUBSCRIBE ? ld_check_subscribe(o) : ld_check_set(o);
}
