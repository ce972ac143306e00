/* test_suggest.c — common/suggest.c, the "did you mean" of the daemon's errors and of fxctl's
 * commands: the distance counts an adjacent transposition as one edit (optimal string
 * alignment), so swapped letters are suggested like a dropped or changed one, within a third
 * of the word's length. */
#include <string.h>

#include "check.h"
#include "suggest.h"

/* The suggestion for word among the NULL-terminated candidates: the hint text. */
static const char *hint_for(const char *word, const char *const *cands, char *buf, size_t len)
{
    struct suggest s;
    suggest_init(&s, word);
    for (; *cands; cands++) suggest_offer(&s, *cands);
    return suggest_text(&s, buf, len);
}

static void want(const char *word, const char *const *cands, const char *best)
{
    char buf[96], exp[96] = "";
    if (best) snprintf(exp, sizeof exp, " (did you mean \"%s\"?)", best);
    hint_for(word, cands, buf, sizeof buf);
    CHECK(!strcmp(buf, exp), "%s: got \"%s\", want \"%s\"", word, buf, exp);
}

static const char *const flame_params[] = { "k_buo", "k_stiff", "k_visc", "h", "fps", "wind_velocity", NULL };
static const char *const energy_params[] = { "alpha", "beta", "divisions", "mode", "color_energy", NULL };
static const char *const commands[] = { "list", "describe", "create", "destroy", "get", "set", "reset",
                                        "subscribe", "watch", "presets", "preset", NULL };

static void test_transpositions(void)
{
    want("k_bou", flame_params, "k_buo");
    want("alhpa", energy_params, "alpha");
    want("lsit", commands, "list");
    want("dsecribe", commands, "describe");
    want("candel", (const char *const[]){ "candle", "torch", NULL }, "candle");
}

static void test_other_edits(void)
{
    want("alpa", energy_params, "alpha");     /* a letter dropped */
    want("alphaa", energy_params, "alpha");   /* one added */
    want("sett", commands, "set");
    want("k_visk", flame_params, "k_visc");   /* one changed */
    want("alpha", energy_params, NULL);       /* an exact match is no suggestion */
}

static void test_limits(void)
{
    want("zzzzz", energy_params, NULL);      /* nothing near */
    want("ab", energy_params, NULL);         /* 'alpha' is 3 edits from 'ab' */
    want("lahpa", energy_params, NULL);      /* two transpositions in 5 letters: over a third */
    /* a swap in a word whose other letters also differ counts each edit once */
    want("blhpa", energy_params, NULL);
}

int main(void)
{
    RUN(test_transpositions);
    RUN(test_other_edits);
    RUN(test_limits);
    return CHECK_DONE();
}
