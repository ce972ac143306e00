/* fxload_errors.c — see fxload_errors.h. */
#include "fxload_errors.h"

#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "fxload_state.h"

void ld_note(struct ld *ld, const char *msg)
{
    for (int i = 0; i < ld->nerrs; i++)
        if (!strcmp(ld->errs[i].msg, msg)) {
            ld->errs[i].count++;
            return;
        }
    if (ld->nerrs < LD_MAX_ERRS) {
        snprintf(ld->errs[ld->nerrs].msg, sizeof ld->errs[0].msg, "%s", msg);
        ld->errs[ld->nerrs++].count = 1;
    } else {
        ld->other_errs++;
    }
}

void ld_error(struct ld *ld, const char *msg)
{
    ld->tot.errors++;
    ld_note(ld, msg);
}

void ld_error_text(const cJSON *m, char *buf, size_t len)
{
    const cJSON *code = cJSON_GetObjectItemCaseSensitive(m, "code");
    const cJSON *msg = cJSON_GetObjectItemCaseSensitive(m, "message");
    snprintf(buf, len, "%s: %s", cJSON_IsString(code) ? code->valuestring : "error",
             cJSON_IsString(msg) ? msg->valuestring : "(no message)");
}

int ld_is_error_code(const cJSON *m, const char *code)
{
    const cJSON *c = cJSON_GetObjectItemCaseSensitive(m, "code");
    return cJSON_IsString(c) && !strcmp(c->valuestring, code);
}

void ld_server_error(struct ld *ld, const char *what, const cJSON *m)
{
    char text[LD_ERR_MSG_MAX], line[2 * LD_ERR_MSG_MAX]; /* ld_note cuts it */
    ld_error_text(m, text, sizeof text);
    snprintf(line, sizeof line, "%s%s%s", what, *what ? ": " : "", text);
    ld_error(ld, line);
}

void ld_fatal(struct ld *ld, int status, const char *fmt, ...)
{
    va_list ap;
    fputs("fxload: ", stderr);
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fputc('\n', stderr);
    if (!ld->fatal) ld->fatal = status;
}

void ld_fatal_reply(struct ld *ld, int status, const char *what, const cJSON *m)
{
    char text[200];
    ld_error_text(m, text, sizeof text);
    ld_fatal(ld, status, "%s: %s", what, text);
}
