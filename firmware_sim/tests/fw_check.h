/* fw_check.h - CHECK_FW, check.h's CHECK_STATUS for fw_status: the firmware
 * tests' assertion on a call's status. */
#ifndef FW_CHECK_H
#define FW_CHECK_H

#include "../../csrc/tests/check.h"
#include "fw_app.h"

#define CHECK_FW(expr, want)                                                              \
    do {                                                                                  \
        fw_status got_ = (expr);                                                          \
        ++check_count;                                                                    \
        if (got_ != (want)) {                                                             \
            ++check_failures;                                                             \
            fprintf(stderr, "%s:%d: %s returned %s, expected %s\n", __FILE__, __LINE__, #expr, \
                    fw_status_name(got_), fw_status_name(want));                          \
        }                                                                                 \
    } while (0)

#endif
