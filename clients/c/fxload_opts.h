/* fxload_opts.h — fxload's command line: the options of a run as parsed (struct ld_opts and
 * its --set specs), their limits and defaults, the checks of their combinations, and the exit
 * statuses the help text promises. The bottom of fxload's files: it includes none of the
 * others and knows nothing of a run; the --streams groups are parsed by fxload_plan.c, which
 * knows the run's streams. */
#ifndef FXLOAD_OPTS_H
#define FXLOAD_OPTS_H

#include <stddef.h>

#include <cjson/cJSON.h>

#define LD_DEFAULT_URL "ws://127.0.0.1:7681/v1/ws"
#define LD_MAX_CONNECTIONS 10000
#define LD_MAX_URLS 16     /* --url repeated: daemons of a cluster */
#define LD_MAX_SETS 16
#define LD_NAME_MAX 64    /* stream and parameter names, with the terminating 0 */
#define LD_DEFAULT_STREAMS "energy,flame"
#define LD_DEFAULT_SET "energy.alpha=0.5..2"
#define LD_DEFAULT_RATE 10

/* Exit statuses (docs/fxload.md). */
enum { LD_OK = 0, LD_FAIL = 1, LD_USAGE = 2, LD_DEGRADED = 3, LD_THRESHOLD = 4 };
enum ld_mode { LD_SUBSCRIBE = 0, LD_SET = 1 };

struct ld_setspec {
    char stream[LD_NAME_MAX];
    char param[LD_NAME_MAX];
    int range, integer; /* LO..HI; integers when both are */
    double lo, hi;
    cJSON *value;       /* a fixed JSON value (range 0) */
};

struct ld_opts {
    const char *url;             /* the first --url (or the default): for messages */
    const char *urls[LD_MAX_URLS]; /* every --url; connection i goes to urls[i % nurls] */
    int nurls;
    const char *token, *ca_file; /* --token / $FXSTREAM_TOKEN, --ca-file / $FXSTREAM_CA_FILE */
    long connections;
    enum ld_mode mode;
    const char *streams_spec;
    double max_fps;              /* < 0: not given */
    long max_particles;          /* subscribe's max_particles; 0: not given */
    struct ld_setspec sets[LD_MAX_SETS];
    int nsets;
    double rate;                 /* < 0: not given */
    double duration, ramp;
    int ramp_given;
    const char *json_path, *plot_path;
    int quiet, payloads;
    int keep;                    /* set mode: leave the values set at the end of the run */
    double max_p99_ms, min_delivered, max_skipped; /* thresholds; < 0: not given */
    unsigned long seed;
};

/* "fxload: WHY[: ARG]" and the hint to --help on stderr. Returns LD_USAGE. */
int ld_usage(const char *why, const char *arg);
/* Fills o from argv. Returns 0, LD_USAGE, or -1 after printing help_text (--help). */
int ld_parse_args(struct ld_opts *o, int argc, char **argv, const char *help_text);
/* Checks the combinations of options against the mode and fills the defaults (--ramp, set
 * mode's --rate and --set). Returns 0 or LD_USAGE. */
int ld_opts_check(struct ld_opts *o);
/* The URL connection i goes to, and all of them as text for messages ("A" or "A, B (2 daemons)"). */
const char *ld_url_for(const struct ld_opts *o, long i);
void ld_urls_text(const struct ld_opts *o, char *out, size_t cap);
/* A finite number, the whole of s. Returns 0, or -1 (out unchanged). */
int ld_parse_double(const char *s, double *out);
/* Whether the n bytes at s are a stream name (1-63 of A-Z a-z 0-9 _ . -). */
int ld_valid_stream_name(const char *s, size_t n);

#endif
