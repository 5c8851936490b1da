/* SPDX-License-Identifier: LGPL-2.1-or-later */
/* main() for a gst-check suite that reports each test case on stdout as TAP, so that
 * `meson test` counts (and names) the cases. GST_CHECKS still selects cases. */
#ifndef __LFTAG_CHECK_MAIN_H__
#define __LFTAG_CHECK_MAIN_H__

#include <gst/check/check.h>

#define LFTAG_CHECK_MAIN(name)                        \
  int main(int argc, char** argv) {                   \
    gst_check_init(&argc, &argv);                     \
    SRunner* runner = srunner_create(name##_suite()); \
    srunner_set_tap(runner, "-");                     \
    srunner_run_all(runner, CK_SILENT);               \
    int failed = srunner_ntests_failed(runner);       \
    srunner_free(runner);                             \
    return failed == 0 ? 0 : 1;                       \
  }

#endif /* __LFTAG_CHECK_MAIN_H__ */
