/* check.h - the few assertion macros the host C tests need. Each test file
 * is one executable; CTest runs it and reads its exit code. */
#ifndef RHONN_CHECK_H
#define RHONN_CHECK_H

#include <stdio.h>

static int check_failures = 0;
static int check_count = 0;

#define CHECK(cond)                                                              \
    do {                                                                         \
        ++check_count;                                                           \
        if (!(cond)) {                                                           \
            ++check_failures;                                                    \
            fprintf(stderr, "%s:%d: CHECK failed: %s\n", __FILE__, __LINE__, #cond); \
        }                                                                        \
    } while (0)

#define CHECK_STATUS(expr, want)                                                 \
    do {                                                                         \
        rhonn_status got_ = (expr);                                              \
        ++check_count;                                                           \
        if (got_ != (want)) {                                                    \
            ++check_failures;                                                    \
            fprintf(stderr, "%s:%d: %s returned %s, expected %s\n", __FILE__, __LINE__, \
                    #expr, rhonn_status_name(got_), rhonn_status_name(want));    \
        }                                                                        \
    } while (0)

#define RUN(test)                                                                \
    do {                                                                         \
        int before_ = check_failures;                                            \
        test();                                                                  \
        printf("%s %s\n", check_failures == before_ ? "ok  " : "FAIL", #test);  \
    } while (0)

#define CHECK_SUMMARY()                                                          \
    (printf("%d checks, %d failed\n", check_count, check_failures), check_failures != 0)

#endif
