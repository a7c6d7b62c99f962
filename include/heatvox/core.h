/*
 * heatvox core: status codes, per-thread error messages, logging, version.
 *
 * Every fallible public function returns an hv_status (HV_OK = 0). The function
 * that detects an error records a message with detail (file, line, argument);
 * hv_last_error() returns it for the calling thread. The library never prints.
 */
#ifndef HEATVOX_CORE_H
#define HEATVOX_CORE_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define HV_VERSION_MAJOR 0
#define HV_VERSION_MINOR 1
#define HV_VERSION_PATCH 0
#define HV_VERSION_STRING "0.1.0"

/* Marks the library's public functions: the shared library is built with
 * -fvisibility=hidden and exports these alone. */
#if defined(__GNUC__) || defined(__clang__)
#define HV_API __attribute__((visibility("default")))
#else
#define HV_API
#endif

typedef enum hv_status {
    HV_OK = 0,
    HV_ERR_INVALID_ARG, /* an argument is out of range or inconsistent */
    HV_ERR_NOMEM,       /* an allocation failed or would exceed memory */
    HV_ERR_IO,          /* a file could not be opened, read or written */
    HV_ERR_PARSE,       /* an input file is malformed */
    HV_ERR_NUMERIC,     /* NaN or Inf in an input, or a numeric breakdown */
    HV_ERR_UNSUPPORTED, /* a feature or backend is not available */
    HV_ERR_BACKEND,     /* a backend library (OpenCL, FFTW, OpenVDB) failed */
    HV_ERR_CANCELLED,   /* a progress callback asked to stop */
    HV_ERR_INTERNAL     /* a bug in heatvox */
} hv_status;

/* Static name of a status ("invalid argument", ...). Never NULL. */
HV_API const char *hv_status_str(hv_status s);

/* Detailed message of the last error on this thread ("" when none).
 * The pointer stays valid until the next heatvox call on this thread. */
HV_API const char *hv_last_error(void);

/* Clears this thread's error message. */
HV_API void hv_clear_error(void);

/* Log levels and a process-wide log callback (default: no output). */
typedef enum hv_log_level { HV_LOG_ERROR = 0, HV_LOG_WARN, HV_LOG_INFO, HV_LOG_DEBUG } hv_log_level;
typedef void (*hv_log_fn)(hv_log_level level, const char *msg, void *user);
HV_API void hv_set_log(hv_log_fn fn, void *user);

/* Progress callback: fraction in [0,1] and a stage name; return non-zero to cancel
 * (the running call then returns HV_ERR_CANCELLED). */
typedef int (*hv_progress_fn)(double fraction, const char *stage, void *user);
HV_API void hv_set_progress(hv_progress_fn fn, void *user);

/* HV_VERSION_STRING of the library that is running (which may be newer than
 * the headers a program was built with). */
HV_API const char *hv_version(void);

/* Output files written safely: every writer creates a temporary file beside the
 * target and renames it into place only when complete, so a failed or
 * interrupted run never leaves a partial file under the requested name. */

/* Fills tmp (size tmpsize) with a unique temporary name in target's directory
 * ("<dir>/.<base>.tmp-<pid>-<n>"). The temporary is registered so that
 * hv_tmp_cleanup_all() (async-signal-safe, for a SIGINT handler) can unlink it.
 * Temporaries of base left by processes that are gone (SIGKILL, a crash) are
 * removed first. A target that is itself a temporary this process staged is
 * returned as it is: a writer handed a caller's temporary writes into it, and
 * its hv_tmp_commit leaves the rename to the caller. */
HV_API hv_status hv_tmp_name(const char *target, char *tmp, size_t tmpsize);

/* Renames tmp onto target and unregisters it; on failure unlinks tmp. Where
 * tmp is target (a caller's temporary, see hv_tmp_name), does nothing. */
HV_API hv_status hv_tmp_commit(const char *tmp, const char *target);

/* Unlinks tmp and unregisters it (for error paths). */
HV_API void hv_tmp_discard(const char *tmp);

/* Unlinks every registered temporary; async-signal-safe. */
HV_API void hv_tmp_cleanup_all(void);

/* Wall-clock seconds from a monotonic clock. */
HV_API double hv_now(void);

/* Peak resident memory of this process in bytes (0 if unknown): Linux's
 * high-water mark (VmHWM), which starts anew at exec and at
 * hv_peak_rss_reset; elsewhere getrusage's maximum. */
HV_API size_t hv_peak_rss(void);

/* Starts the high-water mark of hv_peak_rss anew from the memory resident
 * now (Linux 4.0 and later: /proc/self/clear_refs), so that a benchmark can
 * measure two runs in one process. HV_ERR_UNSUPPORTED where it cannot. */
HV_API hv_status hv_peak_rss_reset(void);

/* Most worker threads the library runs: thread counts above it are refused by
 * the options that take one, and hv_set_threads clamps to it (libgomp crashes
 * when it cannot create the threads it was asked for). */
#define HV_MAX_THREADS 1024

/* Number of worker threads the CPU kernels use; 0 restores the default (all
 * cores); at most HV_MAX_THREADS. */
HV_API void hv_set_threads(int n);
HV_API int hv_get_threads(void);

#ifdef __cplusplus
}
#endif
#endif
