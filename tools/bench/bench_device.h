/* The device's own figures for heatvox bench solve --backend opencl
 * (tools/bench/bench_device.c). */
#ifndef HV_TOOLS_BENCH_DEVICE_H
#define HV_TOOLS_BENCH_DEVICE_H

#include <heatvox/heatvox.h>

#include <stdio.h>

typedef struct bench_device {
    char name[128];
    double setup_seconds;    /* hv_opencl_solver_create */
    double seconds;          /* best solve with the fields on the device (wall) */
    double event_seconds;    /* that solve between two profiled markers */
    double transfer_seconds; /* f to the device and u back, as floats (events) */
    double copy_gbs;         /* clEnqueueCopyBuffer, read + write, best of five */
    int iterations;
    double relres;
    double kernel_seconds; /* device time of the kernels per timed solve (events) */
    double launches;       /* kernels and transfers enqueued per timed solve */
} bench_device;

/* Solves p (options o) on the device heatvox would take, on a context and
 * profiling queue of its own, R times after a warm-up. */
hv_status bench_device_solve(const hv_problem *p, const hv_solver_opts *o, const float *f,
                             int repeat, bench_device *d);

/* The device's figures of one run of a device pipeline (bench band, bench
 * extend-band, bench extend-loop): its kernels' device time by stage, the
 * bytes that crossed (host_bytes_in: host to device, host_bytes_out: device
 * to host, buffers made from host memory included), the commands enqueued,
 * and the device's copy bandwidth measured in the same run. */
/* Stages a device run reports at most. */
#define BENCH_DEVICE_STAGES 16

typedef struct bench_device_run {
    char name[128];
    double kernel_seconds; /* all kernels, summed */
    double stage_seconds[BENCH_DEVICE_STAGES];
    const char *stage_names[BENCH_DEVICE_STAGES];
    int nstages;
    double host_bytes_in, host_bytes_out;
    double launches;
    double copy_gbs;
} bench_device_run;

/* Starts counting: HEATVOX_OPENCL_PROFILE=1 before the library's first
 * OpenCL call (the environment is read once), and what was counted before
 * dropped. */
void bench_device_run_begin(void);
/* Ends it: the kernels whose names start with prefixes[k] summed into stage
 * k (names[k] its JSON name), the transfers, and the copy bandwidth over
 * copy_bytes (at least 256 MiB where the device allows). */
hv_status bench_device_run_end(bench_device_run *d, const char *const *prefixes,
                               const char *const *names, int nstages, size_t copy_bytes);
/* d's stages of one name summed into the first of them (prefixes of one
 * stage given apart). */
void bench_device_run_merge(bench_device_run *d);
/* Prints d's fields as JSON members (",\"device\":...") to out. */
void bench_device_run_json(const bench_device_run *d, FILE *out);

/* With HEATVOX_OPENCL_PROFILE set, prints one JSON line per kernel and
 * transfer timed since the last call (bench "kernel", of = bench or the
 * command) to out, the largest first. */
void bench_device_profile(const char *bench, FILE *out);

#endif
