/* fxload_report.h — what fxload reports: the per-second table (one line per row as the run
 * goes), the summary at the end (per stream, totals, set results, the thresholds, the
 * distinct error messages on stderr) and the JSON document of --json (options, connections,
 * totals, streams with their kinds, sets, thresholds, errors, seconds). Reads the run's
 * state, never changes it, but for closing the --json file. */
#ifndef FXLOAD_REPORT_H
#define FXLOAD_REPORT_H

struct ld;
struct ld_row;
struct ld_thresholds;

/* The per-second table's header and one row's line, to ld.tout unless --quiet. */
void ld_table_header(const struct ld *ld);
void ld_table_line(const struct ld *ld, const struct ld_row *r);
/* The summary of the finished run to ld.tout, its errors to stderr. */
void ld_summary(const struct ld *ld, const struct ld_thresholds *t);
/* Writes the JSON report to ld.json and closes it. Returns 0, or -1 after saying why on stderr. */
int ld_write_json(struct ld *ld, const struct ld_thresholds *t);

#endif
