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

/* With HEATVOX_OPENCL_PROFILE set, prints one JSON line per kernel and
 * transfer timed since the last call (bench "kernel", of = bench or the
 * command) to out, the largest first. */
void bench_device_profile(const char *bench, FILE *out);

#endif
