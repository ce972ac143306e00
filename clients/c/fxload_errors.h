/* fxload_errors.h — what went wrong during an fxload run: the distinct messages shown at the
 * end (counted as errors, which make the exit status 3, or only noted), the server's error
 * replies as text, and the fatal errors that end a run at once. The messages are kept in
 * struct ld (fxload_state.h): ld.errs, ld.other_errs, ld.tot.errors, ld.fatal. */
#ifndef FXLOAD_ERRORS_H
#define FXLOAD_ERRORS_H

#include <stddef.h>

#include <cjson/cJSON.h>

struct ld;

/* Records msg among the distinct messages shown at the end (not counted as an error). */
void ld_note(struct ld *ld, const char *msg);
/* ld_note, counted as an error (exit status 3). */
void ld_error(struct ld *ld, const char *msg);
/* "code: message" of the server's error message m. */
void ld_error_text(const cJSON *m, char *buf, size_t len);
int ld_is_error_code(const cJSON *m, const char *code);
/* Counts the server's error message m: "WHAT: code: message" among the errors. */
void ld_server_error(struct ld *ld, const char *what, const cJSON *m);
/* Ends the run at once with exit status `status` (the first one given wins), after
 * "fxload: MESSAGE" on stderr. */
void ld_fatal(struct ld *ld, int status, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
/* ld_fatal with "WHAT: code: message" of the server's error reply m. */
void ld_fatal_reply(struct ld *ld, int status, const char *what, const cJSON *m);

#endif
