/* test_json_strict.c — the strict JSON reader (server/json_strict.c): exactly one value with
 * optional whitespace, no duplicate members at any depth, no U+0000 in keys or values (escaped
 * or raw), and a reason for every refusal; RFC 8259's grammar exactly: numbers, whitespace,
 * string characters and escapes, UTF-8. */
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
    JS_BAD("{\"a\" 1}", "malformed JSON near byte 5");
    JS_BAD("[1,]", "malformed JSON near byte 3");
    JS_BAD("{\"a\":1,}", "malformed JSON near byte 7");
    JS_BAD("[tru]", "malformed JSON near byte 1");
    JS_BAD("\"abc", "never ends");
}

/* RFC 8259 §6: number = [ minus ] int [ frac ] [ exp ], int = zero / digit1-9 *DIGIT. */
static void test_numbers(void)
{
    JS_OK("[0, -0, 1, -1, 10, 0.5, -0.5, 1e5, 1E+5, 1e-5, 0e0, 123.456e-7, 1e999]");
    JS_BAD("{\"op\":\"set\",\"stream\":\"energy\",\"params\":{\"divisions\":0200}}", "leading zero");
    JS_BAD("01", "invalid number at byte 0: a leading zero");
    JS_BAD("[-00]", "invalid number at byte 1: a leading zero");
    JS_BAD("1.", "a digit must follow '.'");
    JS_BAD("[1.e0]", "a digit must follow '.'");
    JS_BAD(".5", "malformed JSON");
    JS_BAD("-", "a digit must follow '-'");
    JS_BAD("[-x]", "a digit must follow '-'");
    JS_BAD("1e", "a digit must follow the exponent");
    JS_BAD("[1e+]", "a digit must follow the exponent");
    JS_BAD("+1", "malformed JSON");
    JS_BAD("0x10", "trailing data");
    JS_BAD("[Infinity]", "malformed JSON");
    JS_BAD("[NaN]", "malformed JSON");
}

/* RFC 8259 §2: whitespace is space, tab, line feed, carriage return; nothing else. */
static void test_whitespace(void)
{
    JS_OK(" \t\r\n[ 1 ,\t2\r,\n3 ] \t\r\n");
    JS_BAD("\f{\"op\":\"list\"}", "malformed JSON near byte 0: byte 0x0c");
    JS_BAD("{\"op\":\"list\"}\f", "trailing data after the JSON value at byte 13");
    JS_BAD("[1,\v2]", "byte 0x0b");
    JS_BAD("{\x01\"op\":\"list\"}", "byte 0x01");
    JS_BAD("[1]\x01", "trailing data");
    JS_BAD("\xc2\xa0[1]", "byte 0xc2"); /* U+00A0 no-break space */
}

/* RFC 8259 §7: control characters in strings are escaped; only the listed escapes exist. */
static void test_strings(void)
{
    JS_OK("[\"\\\" \\\\ \\/ \\b \\f \\n \\r \\t \\u001f \\uD83D\\uDE00 \\u00e9\"]");
    JS_OK("[\"\xc3\xa9 \xe2\x82\xac \xf0\x9f\x98\x80 \x7f\"]"); /* é € 😀 DEL */
    JS_BAD("{\"op\":\"li\x01st\"}", "raw control character U+0001 in a string at byte 9");
    JS_BAD("[\"a\tb\"]", "U+0009");
    JS_BAD("[\"a\nb\"]", "U+000A");
    JS_BAD("{\"a\x1f\":1}", "U+001F");
    JS_BAD("[\"\\x41\"]", "invalid escape in a string at byte 2");
    JS_BAD("[\"\\'\"]", "invalid escape");
    JS_BAD("[\"\\u12\"]", "four hex digits");
    JS_BAD("[\"\\u12G4\"]", "four hex digits");
    JS_BAD("[\"\\uD800\"]", "unpaired UTF-16 surrogate \\uD800");
    JS_BAD("[\"\\uDC00x\"]", "unpaired UTF-16 surrogate \\uDC00");
    JS_BAD("[\"\\uD800\\u0041\"]", "unpaired");
}

/* RFC 8259 §8.1: JSON text is UTF-8. A name with the byte 0xff read from presets.json would
 * otherwise be sent raw in a text frame. */
static void test_utf8(void)
{
    JS_BAD("[\"a\xff" "b\"]", "invalid UTF-8 in a string at byte 3");
    JS_BAD("[\"\xc3\"]", "invalid UTF-8");                 /* cut off by the quote */
    JS_BAD("[\"\xe2\x82\"]", "invalid UTF-8");             /* truncated */
    JS_BAD("[\"\xc0\xaf\"]", "invalid UTF-8");             /* overlong '/' */
    JS_BAD("[\"\xed\xa0\x80\"]", "invalid UTF-8");         /* a surrogate */
    JS_BAD("[\"\xf4\x90\x80\x80\"]", "invalid UTF-8");    /* above U+10FFFF */
    JS_BAD("[\"\x80\"]", "invalid UTF-8");                 /* a lone continuation byte */
}

/* cJSON's own limit (1000 levels) is kept, with a message. */
static void test_depth(void)
{
    static char deep[2 * 1001 + 1]; /* 1001 '[' then 1001 ']' */
    for (int i = 0; i < 1001; i++) deep[i] = '[', deep[1001 + i] = ']';
    js_case(deep + 1, 2 * 1000, 1, "");
    js_case(deep, 2 * 1001, 0, "nested deeper than 1000 levels");
}

int main(void)
{
    RUN(test_accepts);
    RUN(test_trailing);
    RUN(test_duplicates);
    RUN(test_nul);
    RUN(test_malformed);
    RUN(test_numbers);
    RUN(test_whitespace);
    RUN(test_strings);
    RUN(test_utf8);
    RUN(test_depth);
    return CHECK_DONE();
}
