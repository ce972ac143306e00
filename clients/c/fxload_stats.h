/* fxload_stats.h — fxload's measurements: what each frame and set reply adds to the counters
 * (frames, bytes, seq gaps and latency per stream and kind, set round trips), the delivered
 * rate (subscriber-seconds and the frames the stream's fps promised over them), and the
 * per-second rows cut from the running totals. The counters are kept in struct ld
 * (fxload_state.h); nothing here sends or prints. */
#ifndef FXLOAD_STATS_H
#define FXLOAD_STATS_H

#include <stddef.h>
#include <stdint.h>

#include <cjson/cJSON.h>

struct ld;
struct ld_conn;
struct ld_row;
struct ld_stream;
struct fxs_header;

/* Frames delivered per subscriber per second against the target rate. */
struct ld_delivery {
    int known;              /* 0: no subscriber-time or the stream's fps unknown */
    double fps, target, pct;
};

/* Seconds since the run started. */
double ld_now(const struct ld *ld);
void ld_count_frame(struct ld *ld, struct ld_conn *lc, const struct fxs_header *h, size_t bytes, uint64_t now);
void ld_count_set_reply(struct ld *ld, struct ld_conn *lc, const cJSON *m, const char *op, uint64_t now);
/* Ends the row being measured at `now` (seconds since t0): its counts move into a new row of
 * ld.rows. Returns that row, or NULL when there was no memory for it (counted as an error). */
const struct ld_row *ld_row_end(struct ld *ld, double now);
/* Subscriber-time up to now (seconds since t0); called before `active` changes. */
void ld_stats_advance(struct ld *ld, double now);
void ld_stats_sub_start(struct ld *ld, struct ld_stream *st);
void ld_stats_sub_end(struct ld *ld, struct ld_stream *st);
/* The stream's fps as the server reports it (`get` reply, `params` broadcast). */
void ld_stats_set_fps(struct ld *ld, struct ld_stream *st, double fps);
/* Skipped frames in % of the frames due (received + skipped) over the run; 0 when none. */
double ld_skipped_pct(const struct ld *ld);
/* Frames of the stream's most delivered kind: the stream steps a subscriber saw. */
uint64_t ld_stream_steps(const struct ld_stream *st);
struct ld_delivery ld_delivered(const struct ld_stream *st, uint64_t frames);
const char *ld_kind_name(int kind);

#endif
