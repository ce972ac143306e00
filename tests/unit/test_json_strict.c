/* test_json_strict.c — the strict JSON reader (server/json_strict.c): exactly one value with
 * optional whitespace, no duplicate members at any depth, no U+0000 in keys or values (escaped
 * or raw), and a reason for every refusal (issue 15 items 9-11). */
#include <string.h>

#include "check.h"
#include "json_strict.h"

static void js_case(const char *text, size_t len, int ok, const char *why_has)
{
    char why[128] = "";
    cJSON *v = json_strict_parse(text, len, why, sizeof why);
    CHECK((v != NULL) == ok, "%s: %s (%s)", text, ok ? "refused" : "accepted", why);
    if (!ok) CHECK(strstr(why, why_has) != NULL, "%s: reason \"%s\" lacks \"%s\"", text, why, why_has);
    cJSON_Delete(v);
}

#define JS_OK(t) js_case(t, sizeof t - 1, 1, "")
#define JS_BAD(t, why) js_case(t, sizeof t - 1, 0, why)

static void test_accepts(void)
{
    JS_OK("{\"op\":\"list\"}");
    JS_OK("  {\"op\":\"list\",\"id\":1}\r\n\t ");
    JS_OK("[1,2,{\"a\":{\"b\":[{\"c\":1},{\"c\":2}]}}]"); /* same name in sibling objects */
    JS_OK("{\"s\":\"a\\\\u0000\"}");                   /* an escaped backslash, then text */
    JS_OK("{\"s\":\"\\u0001 \\u00e9 \\\"q\\\"\"}");
}

static void test_trailing(void)
{
    JS_BAD("{\"op\":\"list\"}{\"op\":\"destroy\",\"stream\":\"energy\"}", "trailing data after the JSON value at byte 13");
    JS_BAD("[1] x", "trailing data");
    JS_BAD("{\"op\":\"list\"} ,", "trailing data");
}

static void test_duplicates(void)
{
    JS_BAD("{\"op\":\"get\",\"op\":\"destroy\"}", "duplicate member \"op\"");
    JS_BAD("{\"params\":{\"fps\":1,\"x\":2,\"fps\":3}}", "duplicate member \"fps\"");
    JS_BAD("[{\"a\":[{\"b\":1,\"b\":1}]}]", "duplicate member \"b\"");
}

static void test_nul(void)
{
    JS_BAD("{\"op\":\"list\\u0000x\"}", "U+0000");
    JS_BAD("{\"a\\u0000\":1}", "U+0000");
    js_case("{\"op\":\"li\0st\"}", 14, 0, "U+0000"); /* a raw NUL byte */
    JS_BAD("{\"stream\":\"ab\\u0000cd\"}", "U+0000 (byte 13)");
}

static void test_malformed(void)
{
    JS_BAD("{\"op\":", "malformed JSON near byte");
    JS_BAD("", "malformed JSON");
}

int main(void)
{
    RUN(test_accepts);
    RUN(test_trailing);
    RUN(test_duplicates);
    RUN(test_nul);
    RUN(test_malformed);
    return CHECK_DONE();
}
