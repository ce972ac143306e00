/* fuzz_control.c — libFuzzer target: the control-message parser and everything behind it
 * (session.c dispatch, strict field checks, parameter validation of create/set for every
 * effect, limits). One input is a sequence of messages separated by newlines, run on a
 * fresh server (no engine, no OpenCL: streams are created but never stepped), so that
 * create-then-set sequences are reachable. Replies are drained and must parse as JSON. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"
#include "session.h"

static void fz_drain(struct session *s)
{
    struct outmsg *m;
    while ((m = session_pop(s))) {
        cJSON *j = cJSON_ParseWithLength((const char *)m->data + FRAME_HEADROOM, m->len);
        if (!j) abort(); /* the server only sends valid JSON */
        cJSON_Delete(j);
        free(m);
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static struct server srv;
    static struct session ss;
    log_set_level(LOG_ERROR);
    memset(&srv, 0, sizeof srv);
    srv.cfg.limits = (struct limits){.max_connections = 4, .max_streams = 4, .max_subscriptions = 4,
                                     .max_message_bytes = 1 << 16, .max_json_depth = 32,
                                     .max_control_per_sec = 1 << 20, .max_queued_messages = 1 << 20, .max_queued_bytes = 1 << 30,
                                     .stall_timeout_s = 10};
    hub_init(&srv.hub, srv.cfg.limits.max_streams, false);
    session_open(&ss, &srv, ACCESS_ADMIN);
    for (size_t i = 0; i < size;) {
        const uint8_t *nl = memchr(data + i, '\n', size - i);
        size_t n = nl ? (size_t)(nl - (data + i)) : size - i;
        session_receive(&ss, data + i, n, true, false);
        fz_drain(&ss);
        i += n + 1;
    }
    session_close(&ss);
    hub_free(&srv.hub);
    return 0;
}
