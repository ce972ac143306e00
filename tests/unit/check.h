/* check.h — the unit-test harness: named tests made of checks.
 *
 * A test passes when none of its checks fails. Each binary ends with the line
 * "<binary>: N passed, M failed" that tests/run.sh adds up, and exits non-zero on
 * any failure. Failed checks print file, line, expression and a message. */
#ifndef FX_CHECK_H
#define FX_CHECK_H

#include <math.h>
#include <stdio.h>

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

static inline int check_summary(const char *name)
{
    printf("%s: %d passed, %d failed\n", name, check_tests_passed, check_tests_failed);
    return check_tests_failed ? 1 : 0;
}

#endif
