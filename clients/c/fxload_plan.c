/* fxload_plan.c — see fxload_plan.h. */
#include "fxload_plan.h"

#include <stdio.h>
#include <string.h>

#include "fxload_opts.h"
#include "fxload_state.h"

/* The index of the stream called name, added when new; -1 when LD_MAX_STREAMS are known. */
static int ld_stream_add(struct ld *ld, const char *name, size_t n)
{
    for (int i = 0; i < ld->nstreams; i++)
        if (strlen(ld->streams[i].name) == n && !strncmp(ld->streams[i].name, name, n)) return i;
    if (ld->nstreams >= LD_MAX_STREAMS) return -1;
    snprintf(ld->streams[ld->nstreams].name, sizeof ld->streams[0].name, "%.*s", (int)n, name);
    return ld->nstreams++;
}

struct ld_stream *ld_stream_find(struct ld *ld, const char *name)
{
    for (int i = 0; i < ld->nstreams; i++)
        if (!strcmp(ld->streams[i].name, name)) return &ld->streams[i];
    return NULL;
}

/* Adds the streams of one group, STREAM[+STREAM...], to g. item is for messages. */
static int ld_parse_group_streams(struct ld *ld, struct ld_group *g, char *s, const char *item)
{
    while (s && *s) {
        char *plus = strchr(s, '+');
        size_t n = plus ? (size_t)(plus - s) : strlen(s);
        int idx;
        if (!ld_valid_stream_name(s, n)) return ld_usage("--streams: invalid stream name (A-Z a-z 0-9 _ . -, 1-63)", item);
        if (g->n >= LD_MAX_GROUP) return ld_usage("--streams: at most 16 streams in one group", item);
        if ((idx = ld_stream_add(ld, s, n)) < 0) return ld_usage("--streams: at most 64 distinct streams", item);
        for (int k = 0; k < g->n; k++)
            if (g->stream[k] == idx) return ld_usage("--streams: a stream twice in one group", item);
        g->stream[g->n++] = idx;
        s = plus ? plus + 1 : NULL;
        if (plus && !*s) return ld_usage("--streams: empty stream name after +", item);
    }
    return g->n ? 0 : ld_usage("--streams: empty group", item);
}

/* One item of --streams, GROUP[:WEIGHT], len bytes at p. */
static int ld_parse_group(struct ld *ld, const char *p, size_t len, const char *spec)
{
    struct ld_group *g;
    char item[1024], *colon;
    if (!len || len >= sizeof item) return ld_usage("--streams: empty or too long item", spec);
    if (ld->ngroups >= LD_MAX_GROUPS) return ld_usage("--streams: at most 64 groups", spec);
    snprintf(item, sizeof item, "%.*s", (int)len, p);
    g = &ld->groups[ld->ngroups++];
    g->weight = 1;
    if ((colon = strchr(item, ':'))) {
        *colon = 0;
        if (ld_parse_double(colon + 1, &g->weight) || !(g->weight > 0) || g->weight > 1e6)
            return ld_usage("--streams: WEIGHT must be a positive number", item[0] ? colon + 1 : spec);
    }
    return ld_parse_group_streams(ld, g, item, p);
}

/* Parses --streams: GROUP[:WEIGHT],... with GROUP = STREAM[+STREAM...]. */
static int ld_parse_streams(struct ld *ld, const char *spec)
{
    const char *p = spec;
    if (!*spec) return ld_usage("--streams needs at least one stream", NULL);
    while (*p) {
        const char *end = strchr(p, ',');
        size_t len = end ? (size_t)(end - p) : strlen(p);
        int r = ld_parse_group(ld, p, len, spec);
        if (r) return r;
        p += len;
        if (*p == ',' && !*++p) return ld_usage("--streams: empty item at the end", spec);
    }
    return 0;
}

int ld_plan_streams(struct ld *ld)
{
    const struct ld_opts *o = ld->o;
    if (o->mode == LD_SUBSCRIBE) return ld_parse_streams(ld, o->streams_spec ? o->streams_spec : LD_DEFAULT_STREAMS);
    for (int i = 0; i < o->nsets; i++)
        if (ld_stream_add(ld, o->sets[i].stream, strlen(o->sets[i].stream)) < 0) return ld_usage("--set: at most 64 distinct streams", NULL);
    return 0;
}

/* Smooth weighted round-robin. */
int ld_plan_next_group(struct ld *ld)
{
    double total = 0;
    int best = 0;
    for (int g = 0; g < ld->ngroups; g++) {
        ld->groups[g].current += ld->groups[g].weight;
        total += ld->groups[g].weight;
        if (ld->groups[g].current > ld->groups[best].current) best = g;
    }
    ld->groups[best].current -= total;
    return best;
}
