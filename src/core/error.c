#include "error.h"

#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include <time.h>
#include <sys/resource.h>

#ifdef _OPENMP
#include <omp.h>
#endif

static _Thread_local char last_error[1024];
static hv_log_fn log_fn;
static void *log_user;
static hv_progress_fn progress_fn;
static void *progress_user;

const char *hv_status_str(hv_status s)
{
    switch (s) {
    case HV_OK: return "ok";
    case HV_ERR_INVALID_ARG: return "invalid argument";
    case HV_ERR_NOMEM: return "out of memory";
    case HV_ERR_IO: return "i/o error";
    case HV_ERR_PARSE: return "malformed input";
    case HV_ERR_NUMERIC: return "numeric error";
    case HV_ERR_UNSUPPORTED: return "unsupported";
    case HV_ERR_BACKEND: return "backend failure";
    case HV_ERR_CANCELLED: return "cancelled";
    case HV_ERR_INTERNAL: return "internal error";
    }
    return "unknown status";
}

const char *hv_last_error(void) { return last_error; }

void hv_clear_error(void) { last_error[0] = '\0'; }

hv_status hv__error(hv_status s, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(last_error, sizeof last_error, fmt, ap);
    va_end(ap);
    return s;
}

void hv_set_log(hv_log_fn fn, void *user)
{
    log_fn = fn;
    log_user = user;
}

void hv__log(hv_log_level level, const char *fmt, ...)
{
    if (!log_fn)
        return;
    char buf[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    log_fn(level, buf, log_user);
}

void hv_set_progress(hv_progress_fn fn, void *user)
{
    progress_fn = fn;
    progress_user = user;
}

hv_status hv__progress(double fraction, const char *stage)
{
    if (progress_fn && progress_fn(fraction, stage, progress_user))
        return hv__error(HV_ERR_CANCELLED, "cancelled during %s", stage);
    return HV_OK;
}

static double span_lo, span_hi;

void hv__progress_span(double lo, double hi)
{
    span_lo = lo;
    span_hi = hi;
}

hv_status hv__progress_part(double part, const char *stage)
{
    part = part < 0 ? 0 : part > 1 ? 1 : part;
    return hv__progress(span_lo + (span_hi - span_lo) * part, stage);
}

const char *hv_version(void) { return HV_VERSION_STRING; }

double hv_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

size_t hv_peak_rss(void)
{
    /* VmHWM: getrusage's maximum carries a parent's over exec and cannot be
     * reset. */
    FILE *f = fopen("/proc/self/status", "r");
    char line[256];
    unsigned long long kb = 0;
    int found = 0;
    while (f && !found && fgets(line, sizeof line, f))
        found = sscanf(line, "VmHWM: %llu", &kb) == 1;
    if (f)
        fclose(f);
    if (found)
        return (size_t)kb * 1024u;
    struct rusage ru;
    if (getrusage(RUSAGE_SELF, &ru) != 0)
        return 0;
    return (size_t)ru.ru_maxrss * 1024u;
}

hv_status hv_peak_rss_reset(void)
{
    /* "5" resets the high-water mark to the current resident set. */
    FILE *f = fopen("/proc/self/clear_refs", "w");
    if (!f)
        return hv__error(HV_ERR_UNSUPPORTED, "hv_peak_rss_reset: /proc/self/clear_refs: %s",
                         strerror(errno));
    const int ok = fputs("5", f) >= 0;
    if (fclose(f) != 0 || !ok)
        return hv__error(HV_ERR_UNSUPPORTED, "hv_peak_rss_reset: /proc/self/clear_refs refused "
                                             "the reset (Linux before 4.0?)");
    return HV_OK;
}

void hv_set_threads(int n)
{
#ifdef _OPENMP
    omp_set_num_threads(n > HV_MAX_THREADS ? HV_MAX_THREADS : n > 0 ? n : omp_get_num_procs());
#else
    (void)n;
#endif
}

int hv_get_threads(void)
{
#ifdef _OPENMP
    return omp_get_max_threads();
#else
    return 1;
#endif
}
