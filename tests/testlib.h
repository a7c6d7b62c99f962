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
/* Directory of test meshes: $HEATVOX_TEST_DATA, else ../shared/meshes; NULL
 * when it does not exist (the caller skips and says so). */
const char *tl_test_data(void);

/* 1 in a build under AddressSanitizer or ThreadSanitizer (make sanitize,
 * make tsan) unless HEATVOX_TEST_LONG is set: suites that repeat one path
 * over many sizes, cases or kill times run a few of them there, since what the
 * sanitizers look for shows in one pass; make check runs every one. */
int tl_sanitized(void);
/* 1 when HEATVOX_TEST_LONG is set and not "0" (make check-long). */
int tl_long(void);

/* Skips: `make check` counts the lines these print and ends with
 * "check: N passed, M failed, K skipped". A test that cannot run here calls
 * TL_SKIP (it prints "SKIP: ..." and returns, so Check's pass is taken back);
 * a suite that does not register a test prints "NOT RUN: ..." for it through
 * TL_ADD_IF. Only absent data or hardware may skip: a reader that fails on a
 * file that exists is a failure. */
void tl_skip(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
#define TL_SKIP(...)                                                                               \
    do {                                                                                           \
        tl_skip(__VA_ARGS__);                                                                      \
        return;                                                                                    \
    } while (0)
void tl_not_run(const char *test, const char *why);
#define TL_ADD_IF(tc, test, ok, why)                                                               \
    do {                                                                                           \
        if (ok)                                                                                    \
            tcase_add_test(tc, test);                                                              \
        else                                                                                       \
            tl_not_run(#test, why);                                                                \
    } while (0)
/* Runs the suite and returns the process exit code. */
int tl_run(Suite *s);
/* PoCL compiles each kernel on first use: unless POCL_CACHE_DIR is set, keep
 * its cache with the build (../pocl-cache beside the test binary argv0). */
void tl_pocl_cache(const char *argv0);
/* The heatvox command, as an absolute path: $HEATVOX_BIN, else the one of the
 * build this suite belongs to (BUILD/heatvox); NULL (the caller fails or
 * skips, saying so) when it is not there. */
const char *tl_heatvox_bin(void);
/* Removes a file or a directory tree (no error when absent). */
void tl_rm_rf(const char *path);
/* Runs a shell command with stdout discarded and stderr in dir/stderr.txt,
 * copied into err (may be NULL); returns its exit code (-1: no exit). */
int tl_run_cmd(const char *cmd, const char *dir, char *err, size_t errsize);

/* A scratch directory /tmp/hv_<name>_XXXXXX (into dir) holding the scenes of
 * `heatvox make-scenes` in sc/; bin gets the command's absolute path. Fails
 * the test when either cannot be had. */
void tl_scratch_scenes(const char *name, char *dir, size_t dirsize, char *bin, size_t binsize);
/* Runs `cd dir && 'bin' ARGS` (ARGS from fmt); stderr into err (may be NULL).
 * Returns the exit code. */
int tl_hv(const char *dir, const char *bin, char *err, size_t errsize, const char *fmt, ...)
    __attribute__((format(printf, 5, 6)));

#define TL_ASSERT_OK(expr)                                                                         \
    do {                                                                                           \
        hv_status st_ = (expr);                                                                    \
        ck_assert_msg(st_ == HV_OK, "%s failed: %s: %s", #expr, hv_status_str(st_),                \
                      hv_last_error());                                                            \
    } while (0)

/* The bytes heatvox's OpenCL queues moved to the device and to the host,
 * and the reads, since the last call (HEATVOX_OPENCL_PROFILE=1 set before
 * the first OpenCL call; hv_opencl_profile_take). */
void tl_cl_traffic(double *to_device, double *to_host, long *reads);

#endif
