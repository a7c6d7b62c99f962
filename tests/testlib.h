/* Small helpers shared by the Check suites. */
#ifndef HV_TESTLIB_H
#define HV_TESTLIB_H

#include "heatvox/heatvox.h"
#include <check.h>
#include <stdint.h>

/* Deterministic uniform numbers in [-0.5, 0.5). */
double tl_rand(uint64_t *state);
/* Fills v with tl_rand values. */
void tl_fill_random(float *v, size_t n, uint64_t seed);
/* Directory with the shared meshes ($HEATVOX_SHARED or ../shared), or NULL
 * when absent (the caller skips and says so). */
const char *tl_shared_dir(void);
/* Runs the suite and returns the process exit code. */
int tl_run(Suite *s);

#define TL_ASSERT_OK(expr)                                                                         \
    do {                                                                                           \
        hv_status st_ = (expr);                                                                    \
        ck_assert_msg(st_ == HV_OK, "%s failed: %s: %s", #expr, hv_status_str(st_), hv_last_error()); \
    } while (0)

#endif
