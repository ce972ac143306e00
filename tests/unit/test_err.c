/* test_err.c — server/err.h: fx_fail's messages and parameter paths are valid UTF-8 however
 * they were cut or whatever client bytes they quote: fx_utf8_sanitize keeps
 * well-formed sequences and turns every other byte into '?'. */
#include <string.h>

#include "check.h"
#include "err.h"

static void sane(const char *in, const char *want)
{
    char s[64];
    snprintf(s, sizeof s, "%s", in);
    fx_utf8_sanitize(s);
    CHECK(!strcmp(s, want), "\"%s\" -> \"%s\", want \"%s\"", in, s, want);
}

static void test_sanitize(void)
{
    sane("plain ascii", "plain ascii");
    sane("caf\xc3\xa9 \xe2\x82\xac \xf0\x9f\x94\xa5", "caf\xc3\xa9 \xe2\x82\xac \xf0\x9f\x94\xa5"); /* é € U+1F525 */
    sane("cut \xc3", "cut ?");                  /* a lead byte without its continuation */
    sane("cut \xe2\x82\"", "cut ??\"");         /* cut inside a 3-byte character, then a quote */
    sane("\xc0\xaf overlong", "?? overlong");   /* overlong '/' */
    sane("\xed\xa0\x80 surrogate", "??? surrogate");
    sane("\xf4\x90\x80\x80 > U+10FFFF", "???? > U+10FFFF");
    sane("\xff\xfe", "??");
    sane("\x80 lone continuation", "? lone continuation");
}

static void test_fail_message(void)
{
    struct fx_err err;
    char name[80];
    memset(name, 'a', 63);
    memcpy(name + 63, "\xc3\xa9", 3); /* 63 ASCII letters, then é: "%.64s" cuts é in two */
    fx_fail(&err, "unknown_op", "op", "unknown op \"%.64s\"", name);
    CHECK(!strcmp(err.message + strlen(err.message) - 3, "a?\""), "cut character replaced: %s", err.message);
    char longname[400];
    memset(longname, 'b', sizeof longname);
    for (size_t i = 1; i + 1 < sizeof longname; i += 2) longname[i] = (char)0xc3, longname[i + 1] = (char)0xa9;
    longname[sizeof longname - 1] = 0;
    fx_fail(&err, "bad_param", longname, "unknown parameter \"%s\"", longname); /* both truncated */
    char copy[sizeof err.message];
    memcpy(copy, err.message, sizeof copy);
    fx_utf8_sanitize(copy);
    CHECK(!strcmp(copy, err.message), "message truncated inside a character stays valid");
    memcpy(copy, err.param, sizeof err.param);
    fx_utf8_sanitize(copy);
    CHECK(!strcmp(copy, err.param), "param truncated inside a character stays valid");
}

int main(void)
{
    RUN(test_sanitize);
    RUN(test_fail_message);
    return CHECK_DONE();
}
