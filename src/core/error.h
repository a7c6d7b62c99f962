/* Private: recording errors and logging from inside the library. */
#ifndef HV_CORE_ERROR_H
#define HV_CORE_ERROR_H

#include "heatvox/core.h"

#include <stdio.h>

/* Records a formatted message for this thread and returns s, so that the
 * function detecting an error can write `return hv__error(HV_ERR_IO, "...")`. */
hv_status hv__error(hv_status s, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

/* Sends a message to the log callback, if any. */
void hv__log(hv_log_level level, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

/* Calls the progress callback; returns HV_ERR_CANCELLED if it asked to stop. */
hv_status hv__progress(double fraction, const char *stage);
/* A stage that reports its own progress: hv__progress_span sets the fraction
 * it starts and ends at, hv__progress_part(part, stage) reports part in [0,1]
 * of it (to be called where no other thread calls the callback). */
void hv__progress_span(double lo, double hi);
hv_status hv__progress_part(double part, const char *stage);

/* Bytes a run may take (SIZE_MAX where unknown): the least of the machine's
 * physical memory, the memory limit of the process's cgroup and its
 * address-space limit (ulimit -v). Size checks such as hv_check_dims compare
 * a run's needs against it. what, when not NULL, gets "machine", "cgroup" or
 * "ulimit": which one is the least. */
size_t hv__memory_limit(const char **what);
/* That limit for a message that ends "more than %s": "this machine's 25.3
 * GB", "the 8 GB its cgroup allows", ...; buf of 96 bytes is enough. */
const char *hv__memory_limit_text(char *buf, size_t size);

/* The temporary of an output file (hv_tmp_name) opened for writing, its name
 * in tmp; NULL with *st set (the file named) when it cannot be made. The
 * writer then calls hv_tmp_commit, or hv_tmp_discard on failure. */
FILE *hv__tmp_open(const char *path, char *tmp, size_t tmpsize, hv_status *st);

#endif
