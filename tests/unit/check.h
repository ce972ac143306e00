/* check.h — the unit-test harness: named tests made of checks.
 *
 * A test passes when none of its checks fails. Each binary's main() runs its tests with RUN
 * and ends with `return CHECK_DONE();`, which prints "<suite>: N passed, M failed" (the suite
 * is the source file's name, test_foo) for tests/run.sh to add up and exits non-zero on any
 * failure; a set-up that fails first ends with `return CHECK_ABORT("why %s", ...);`. Failed
 * checks print file, line, expression and a message. Kernel tests open CHECK_DEVICE(): the
 * CPU device (PoCL) unless FX_OCL_DEVICE names another (e.g. "gpu", to check a GPU driver). */
#ifndef FX_CHECK_H
#define FX_CHECK_H

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static inline const char *CHECK_DEVICE(void)
{
    const char *d = getenv("FX_OCL_DEVICE");
    return d && *d ? d : "cpu";
}

static int check_fails_in_test;
static int check_tests_passed, check_tests_failed;

#define CHECK(cond, ...)                                                            \
    do {                                                                            \
        if (!(cond)) {                                                              \
            check_fails_in_test++;                                                  \
            fprintf(stderr, "  FAIL %s:%d: %s: ", __FILE__, __LINE__, #cond);       \
            fprintf(stderr, __VA_ARGS__);                                           \
            fputc('\n', stderr);                                                    \
        }                                                                           \
    } while (0)

/* |a - b| <= tol, printing both values on failure. */
#define CHECK_NEAR(a, b, tol)                                                       \
    do {                                                                            \
        double check_a_ = (a), check_b_ = (b);                                      \
        CHECK(fabs(check_a_ - check_b_) <= (tol), "%.12g vs %.12g (tol %.3g)",      \
              check_a_, check_b_, (double)(tol));                                   \
    } while (0)

#define RUN(test)                                                                   \
    do {                                                                            \
        check_fails_in_test = 0;                                                    \
        test();                                                                     \
        if (check_fails_in_test) check_tests_failed++; else check_tests_passed++;   \
        printf("%s %s\n", check_fails_in_test ? "FAIL" : "ok  ", #test);            \
        fflush(stdout);                                                             \
    } while (0)

static inline int check_summary(const char *file)
{
    const char *base = strrchr(file, '/') ? strrchr(file, '/') + 1 : file;
    int len = (int)(strrchr(base, '.') ? strrchr(base, '.') - base : (long)strlen(base));
    printf("%.*s: %d passed, %d failed\n", len, base, check_tests_passed, check_tests_failed);
    return check_tests_failed ? 1 : 0;
}

/* The summary line and exit status of this file's suite. */
#define CHECK_DONE() check_summary(__FILE__)

/* A set-up that failed before the tests could run: one failed test, the reason, the summary. */
#define CHECK_ABORT(...)                                                                \
    (fprintf(stderr, "  set-up failed: "), fprintf(stderr, __VA_ARGS__), fputc('\n', stderr), \
     check_tests_failed++, CHECK_DONE())

#endif
