/* test_cluster_state.c — server/cluster.c without a Redis: --cluster URLs (accepted forms,
 * defaults, every refusal, a password never echoed), --role values, and the rule that keeps the local copy
 * in step with Redis's change counter (cluster_fit: the next change applies, an old one or
 * one seen while stale is skipped, a gap makes the copy stale until a reload). Talking to
 * Redis is tests/integration/test_cluster.py's part. */
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "cluster.h"

static void url_ok(const char *url, const char *host, int port, int db)
{
    struct cluster_config c = {0};
    struct fx_err err = {0};
    int rc = cluster_parse_url("--cluster", url, &c, &err);
    CHECK(rc == 0, "%s: %s", url, err.message);
    CHECK(!strcmp(c.host, host) && c.port == port && c.db == db && !strcmp(c.url, url), "%s -> %s %d %d", url, c.host,
          c.port, c.db);
}

static void url_bad(const char *url, const char *word)
{
    struct cluster_config c = {0};
    struct fx_err err = {0};
    int rc = cluster_parse_url("--cluster", url, &c, &err);
    CHECK(rc == -1 && !strcmp(err.code, "bad_request") && strstr(err.message, word) &&
              strstr(err.message, "--cluster"), "%s: %s", url, err.message);
}

static void test_urls(void)
{
    url_ok("redis://127.0.0.1", "127.0.0.1", 6379, 0);
    url_ok("redis://redis.fxstream.svc:6380", "redis.fxstream.svc", 6380, 0);
    url_ok("redis://localhost:1/15", "localhost", 1, 15);
    url_ok("redis://[::1]:7000/2", "::1", 7000, 2);
    url_ok("redis://h/0", "h", 6379, 0);
    url_bad("http://127.0.0.1", "not a redis:// URL");
    url_bad("rediss://127.0.0.1", "TLS");
    url_bad("redis://", "bad host");
    url_bad("redis://[::1", "bad host");
    url_bad("redis://a_b", "unexpected text");
    url_bad("redis://h:0", "port");
    url_bad("redis://h:65536", "port");
    url_bad("redis://h:", "port");
    url_bad("redis://h/", "database");
    url_bad("redis://h/10000", "database");
    url_bad("redis://h:1/2/3", "unexpected text");
    url_bad("redis://h?db=1", "unexpected text");
    struct cluster_config c = {0};
    struct fx_err err = {0};
    CHECK(cluster_parse_url("cluster", "redis://user:hunter2@h", &c, &err) == -1 && !strstr(err.message, "hunter2") &&
              strstr(err.message, "FXS_REDIS_PASSWORD") && !strncmp(err.message, "cluster:", 8),
          "credentials refused, not echoed, the key named: %s", err.message);
}

static void test_roles(void)
{
    static const struct { const char *s; enum cluster_role r; } ok[] = {
        {"compute", CLUSTER_ROLE_COMPUTE}, {"edge", CLUSTER_ROLE_EDGE}, {"both", CLUSTER_ROLE_BOTH}};
    for (size_t i = 0; i < sizeof ok / sizeof ok[0]; i++) {
        struct cluster_config c = {0};
        struct fx_err err = {0};
        CHECK(cluster_parse_role("--role", ok[i].s, &c, &err) == 0 && c.role == ok[i].r && c.role_set &&
                  !strcmp(cluster_role_name(c.role), ok[i].s), "role %s", ok[i].s);
    }
    const char *bad[] = {"", "Edge", "compute,edge", "edge\n"};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        struct cluster_config c = {0};
        struct fx_err err = {0};
        CHECK(cluster_parse_role("role", bad[i], &c, &err) == -1 && !c.role_set && !strcmp(err.code, "bad_request") &&
                  strstr(err.message, "compute, edge or both") && !strncmp(err.message, "role:", 5),
              "role \"%s\" refused: %s", bad[i], err.message);
    }
}

static void test_fit(void)
{
    struct cluster *cl;
    struct fx_err err = {0};
    struct cluster_config cfg = {.host = "127.0.0.1", .port = 6379, .url = "redis://127.0.0.1", .node_id = "t"};
    if (cluster_open(&cl, &cfg, &err)) {
        CHECK(0, "cluster_open: %s", err.message);
        return;
    }
    CHECK(!cluster_in_sync(cl) && cluster_fit(cl, 1) == CLUSTER_SKIP, "stale until loaded: changes are skipped");
    CHECK(cluster_next(cl) == NULL && !cluster_link_up(cl), "nothing queued, no link before cluster_follow");
    cluster_loaded(cl, 10);
    CHECK(cluster_in_sync(cl), "in sync once loaded at 10");
    CHECK(cluster_fit(cl, 9) == CLUSTER_SKIP && cluster_fit(cl, 10) == CLUSTER_SKIP, "changes in the load: skipped");
    CHECK(cluster_fit(cl, 11) == CLUSTER_APPLY && cluster_fit(cl, 12) == CLUSTER_APPLY, "the next ones apply");
    CHECK(cluster_fit(cl, 12) == CLUSTER_SKIP, "one's own change, already applied, comes back: skipped");
    CHECK(cluster_fit(cl, 14) == CLUSTER_GAP && !cluster_in_sync(cl), "13 missed: a gap, the copy is stale");
    CHECK(cluster_fit(cl, 15) == CLUSTER_SKIP, "stale: later changes wait for the reload");
    cluster_loaded(cl, 15);
    CHECK(cluster_fit(cl, 16) == CLUSTER_APPLY, "reloaded at 15: 16 applies");
    cluster_stale(cl);
    CHECK(!cluster_in_sync(cl) && cluster_fit(cl, 17) == CLUSTER_SKIP, "an event that does not fit: stale");
    struct cluster_status st;
    cluster_status(cl, &st);
    CHECK(!strcmp(st.node, "t") && !strcmp(st.url, "redis://127.0.0.1") && !st.link_up && !st.in_sync && st.seq == 16 &&
              !st.last_error[0], "status: node, url, link down, stale at 16");
    cluster_close(cl);
}

int main(void)
{
    RUN(test_urls);
    RUN(test_roles);
    RUN(test_fit);
    return CHECK_DONE();
}
