/* The device's own figures for `heatvox bench solve --backend opencl`: the
 * solve with its fields already on the device (hv_opencl_solve on a context
 * and profiling queue of the benchmark's own), the transfers that the
 * host-array interface adds, apart, and the device's copy bandwidth
 * (clEnqueueCopyBuffer, read + write) measured in the same run, so that the
 * solve's modelled traffic can be set against it. */
#include "bench_device.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Seconds between the ends of two profiled markers or commands. */
static double event_span(cl_event a, cl_event b)
{
    cl_ulong t0 = 0, t1 = 0;
    if (clGetEventProfilingInfo(a, CL_PROFILING_COMMAND_END, sizeof t0, &t0, NULL) != CL_SUCCESS ||
        clGetEventProfilingInfo(b, CL_PROFILING_COMMAND_END, sizeof t1, &t1, NULL) != CL_SUCCESS)
        return 0;
    return (double)(t1 - t0) * 1e-9;
}

/* A command's own duration on the device, from its profiling event. */
static double event_seconds(cl_event e)
{
    cl_ulong t0 = 0, t1 = 0;
    clWaitForEvents(1, &e);
    if (clGetEventProfilingInfo(e, CL_PROFILING_COMMAND_START, sizeof t0, &t0, NULL) !=
            CL_SUCCESS ||
        clGetEventProfilingInfo(e, CL_PROFILING_COMMAND_END, sizeof t1, &t1, NULL) != CL_SUCCESS)
        return 0;
    return (double)(t1 - t0) * 1e-9;
}

/* The device heatvox would take, with a context and a profiling queue. */
static hv_status open_device(bench_device *d, cl_context *ctx, cl_device_id *dev,
                             cl_command_queue *q)
{
    hv_opencl_device info;
    hv_status st = hv_opencl_probe(&info);
    if (st)
        return st;
    snprintf(d->name, sizeof d->name, "%s", info.name);
    cl_platform_id ps[64];
    cl_device_id ds[64];
    cl_uint np = 0, nd = 0;
    if (clGetPlatformIDs(64, ps, &np) != CL_SUCCESS || info.platform >= (int)np ||
        clGetDeviceIDs(ps[info.platform], CL_DEVICE_TYPE_ALL, 64, ds, &nd) != CL_SUCCESS ||
        info.device >= (int)nd)
        return HV_ERR_BACKEND;
    *dev = ds[info.device];
    cl_int e;
    *ctx = clCreateContext(NULL, 1, dev, NULL, NULL, &e);
    if (e != CL_SUCCESS)
        return HV_ERR_BACKEND;
    *q = clCreateCommandQueue(*ctx, *dev, CL_QUEUE_PROFILING_ENABLE, &e);
    if (e != CL_SUCCESS) {
        clReleaseContext(*ctx);
        return HV_ERR_BACKEND;
    }
    return HV_OK;
}

/* Best of five device-to-device copies of `bytes`, in GB/s (read + write). */
static double copy_gbs(cl_context ctx, cl_command_queue q, size_t bytes)
{
    cl_int e1, e2;
    cl_mem a = clCreateBuffer(ctx, CL_MEM_READ_WRITE, bytes, NULL, &e1);
    cl_mem b = clCreateBuffer(ctx, CL_MEM_READ_WRITE, bytes, NULL, &e2);
    double best = 0;
    if (e1 == CL_SUCCESS && e2 == CL_SUCCESS) {
        const cl_uchar one = 1;
        clEnqueueFillBuffer(q, a, &one, 1, 0, bytes, 0, NULL, NULL);
        for (int t = 0; t < 6; t++) {
            cl_event ev;
            if (clEnqueueCopyBuffer(q, a, b, 0, 0, bytes, 0, NULL, &ev) != CL_SUCCESS)
                break;
            double s = event_seconds(ev);
            clReleaseEvent(ev);
            if (t > 0 && s > 0 && 2.0 * bytes / s / 1e9 > best)
                best = 2.0 * bytes / s / 1e9;
        }
    }
    if (e1 == CL_SUCCESS)
        clReleaseMemObject(a);
    if (e2 == CL_SUCCESS)
        clReleaseMemObject(b);
    return best;
}

/* The copy reference: copies of at least 256 MiB (as the host's reference)
 * or of bytes, half the largest buffer at most, in GB/s. */
static double copy_reference(cl_context ctx, cl_device_id dev, cl_command_queue q, size_t bytes)
{
    cl_ulong mem = 0;
    clGetDeviceInfo(dev, CL_DEVICE_MAX_MEM_ALLOC_SIZE, sizeof mem, &mem, NULL);
    size_t cb = bytes > (256u << 20) ? bytes : (256u << 20);
    if (mem && cb > mem / 2)
        cb = (size_t)(mem / 2);
    return copy_gbs(ctx, q, cb);
}

/* Kernel times taken from the library (hv_opencl_profile_take) before
 * bench_device_profile prints them: the device solves' own, and those that
 * ran before them. */
#define PROFILE_MAX 128
static hv_opencl_kernel_time taken[PROFILE_MAX];
static int ntaken;

/* Takes the library's kernel times into `taken`; returns their sum and sets
 * *launches to their count. */
static double take_profile(double *launches)
{
    hv_opencl_kernel_time t[PROFILE_MAX];
    int n = hv_opencl_profile_take(t, PROFILE_MAX);
    double sum = 0;
    *launches = 0;
    for (int i = 0; i < n && i < PROFILE_MAX; i++) {
        sum += t[i].seconds;
        *launches += (double)t[i].launches;
        int k = 0;
        while (k < ntaken && strcmp(taken[k].name, t[i].name) != 0)
            k++;
        if (k == ntaken) {
            if (ntaken == PROFILE_MAX)
                continue;
            taken[ntaken++] = (hv_opencl_kernel_time){t[i].name, 0, 0.0, 0.0};
        }
        taken[k].launches += t[i].launches;
        taken[k].seconds += t[i].seconds;
    }
    return sum;
}

/* Repeat solves with the fields on the device, after a warm-up: the best
 * wall time (the call returns with its commands finished) and, for that run,
 * the device time between two markers around it. */
static hv_status time_device(hv_solver *sv, cl_command_queue q, cl_mem f, cl_mem u, int repeat,
                             bench_device *d)
{
    d->seconds = 1e30;
    double launches;
    for (int r = 0; r <= repeat; r++) {
        if (r == 1)
            take_profile(&launches); /* the warm-up's kernels, apart */
        cl_event m0, m1;
        clEnqueueMarkerWithWaitList(q, 0, NULL, &m0);
        clFinish(q);
        hv_solve_info info;
        double t0 = hv_now();
        hv_status st = hv_opencl_solve(sv, f, u, &info);
        double t = hv_now() - t0;
        clEnqueueMarkerWithWaitList(q, 0, NULL, &m1);
        clFinish(q);
        double ev = event_span(m0, m1);
        clReleaseEvent(m0);
        clReleaseEvent(m1);
        if (st)
            return st;
        if ((r > 0 || repeat == 0) && t < d->seconds) {
            d->seconds = t;
            d->event_seconds = ev;
            d->iterations = info.iterations;
            d->relres = info.relres;
        }
    }
    /* The queue profiles (open_device), so the library timed every command. */
    const int timed = repeat > 0 ? repeat : 1;
    d->kernel_seconds = take_profile(&launches) / timed;
    d->launches = launches / timed;
    return HV_OK;
}

hv_status bench_device_solve(const hv_problem *p, const hv_solver_opts *o, const float *f,
                             int repeat, bench_device *d)
{
    memset(d, 0, sizeof *d);
    cl_context ctx;
    cl_device_id dev;
    cl_command_queue q;
    hv_status st = open_device(d, &ctx, &dev, &q);
    if (st)
        return st;
    size_t count = (size_t)p->n[0] * p->n[1] * (p->dim == 3 ? p->n[2] : 1);
    const size_t bytes = count * sizeof(float);
    cl_int e1, e2;
    cl_mem fd = clCreateBuffer(ctx, CL_MEM_READ_WRITE, bytes, NULL, &e1);
    cl_mem ud = clCreateBuffer(ctx, CL_MEM_READ_WRITE, bytes, NULL, &e2);
    hv_solver *sv = NULL;
    if (e1 != CL_SUCCESS || e2 != CL_SUCCESS) {
        st = HV_ERR_NOMEM;
        goto out;
    }
    /* The transfers of the host-array interface: f in, u out, as floats. */
    cl_event w, r;
    clEnqueueWriteBuffer(q, fd, CL_TRUE, 0, bytes, f, 0, NULL, &w);
    float *back = hv_malloc(bytes);
    if (!back) {
        clReleaseEvent(w);
        st = HV_ERR_NOMEM;
        goto out;
    }
    clEnqueueReadBuffer(q, fd, CL_TRUE, 0, bytes, back, 0, NULL, &r);
    d->transfer_seconds = event_seconds(w) + event_seconds(r);
    clReleaseEvent(w);
    clReleaseEvent(r);
    hv_free(back);
    double t0 = hv_now();
    if ((st = hv_opencl_solver_create(&sv, p, o, ctx, dev, q)))
        goto out;
    d->setup_seconds = hv_now() - t0;
    if ((st = time_device(sv, q, fd, ud, repeat, d)))
        goto out;
    d->copy_gbs = copy_reference(ctx, dev, q, bytes);
out:
    hv_solver_destroy(&sv);
    if (e1 == CL_SUCCESS)
        clReleaseMemObject(fd);
    if (e2 == CL_SUCCESS)
        clReleaseMemObject(ud);
    clReleaseCommandQueue(q);
    clReleaseContext(ctx);
    return st;
}

void bench_device_run_begin(void)
{
    setenv("HEATVOX_OPENCL_PROFILE", "1", 1);
    hv_opencl_kernel_time t[PROFILE_MAX];
    hv_opencl_profile_take(t, PROFILE_MAX);
}

/* The copy reference on a context of its own. */
static hv_status run_copy(bench_device_run *d, size_t bytes)
{
    bench_device info;
    cl_context ctx;
    cl_device_id dev;
    cl_command_queue q;
    hv_status st = open_device(&info, &ctx, &dev, &q);
    if (st)
        return st;
    snprintf(d->name, sizeof d->name, "%s", info.name);
    d->copy_gbs = copy_reference(ctx, dev, q, bytes);
    clReleaseCommandQueue(q);
    clReleaseContext(ctx);
    return HV_OK;
}

hv_status bench_device_run_end(bench_device_run *d, const char *const *prefixes,
                               const char *const *names, int nstages, size_t copy_bytes)
{
    hv_opencl_kernel_time t[PROFILE_MAX];
    const int n = hv_opencl_profile_take(t, PROFILE_MAX);
    memset(d, 0, sizeof *d);
    d->nstages = nstages < BENCH_DEVICE_STAGES ? nstages : BENCH_DEVICE_STAGES;
    for (int k = 0; k < d->nstages; k++)
        d->stage_names[k] = names[k];
    for (int i = 0; i < n && i < PROFILE_MAX; i++) {
        d->launches += (double)t[i].launches;
        if (!strcmp(t[i].name, "write")) {
            d->host_bytes_in += t[i].bytes;
            continue;
        }
        if (!strcmp(t[i].name, "read")) {
            d->host_bytes_out += t[i].bytes;
            continue;
        }
        if (!strcmp(t[i].name, "copy") || !strcmp(t[i].name, "fill"))
            continue;
        d->kernel_seconds += t[i].seconds;
        for (int k = 0; k < d->nstages; k++)
            if (!strncmp(t[i].name, prefixes[k], strlen(prefixes[k]))) {
                d->stage_seconds[k] += t[i].seconds;
                break;
            }
    }
    return run_copy(d, copy_bytes);
}

void bench_device_run_merge(bench_device_run *d)
{
    bench_device_run e = *d;
    e.nstages = 0;
    for (int k = 0; k < d->nstages; k++) {
        int at = 0;
        while (at < e.nstages && strcmp(e.stage_names[at], d->stage_names[k]))
            at++;
        if (at == e.nstages) {
            e.stage_names[at] = d->stage_names[k];
            e.stage_seconds[at] = 0;
            e.nstages++;
        }
        e.stage_seconds[at] += d->stage_seconds[k];
    }
    *d = e;
}

void bench_device_run_json(const bench_device_run *d, FILE *out)
{
    fprintf(out, ",\"device\":\"%s\",\"device_seconds\":%.6f,\"stage_device_seconds\":{", d->name,
            d->kernel_seconds);
    for (int k = 0; k < d->nstages; k++)
        fprintf(out, "%s\"%s\":%.6f", k ? "," : "", d->stage_names[k], d->stage_seconds[k]);
    fprintf(out,
            "},\"host_bytes_in\":%.0f,\"host_bytes_out\":%.0f,\"launches\":%.0f,"
            "\"copy_gbs\":%.2f",
            d->host_bytes_in, d->host_bytes_out, d->launches, d->copy_gbs);
}

static int by_seconds(const void *a, const void *b)
{
    double x = ((const hv_opencl_kernel_time *)a)->seconds;
    double y = ((const hv_opencl_kernel_time *)b)->seconds;
    return (x < y) - (x > y);
}

void bench_device_profile(const char *bench, FILE *out)
{
    double launches;
    take_profile(&launches);
    const char *e = getenv("HEATVOX_OPENCL_PROFILE");
    if (!e || !*e || !strcmp(e, "0"))
        return;
    qsort(taken, (size_t)ntaken, sizeof taken[0], by_seconds);
    double total = 0;
    for (int i = 0; i < ntaken; i++)
        total += taken[i].seconds;
    for (int i = 0; i < ntaken; i++)
        fprintf(out,
                "{\"bench\":\"kernel\",\"of\":\"%s\",\"name\":\"%s\",\"launches\":%ld,"
                "\"seconds\":%.6f,\"share\":%.4f}\n",
                bench, taken[i].name, taken[i].launches, taken[i].seconds,
                total > 0 ? taken[i].seconds / total : 0.0);
    fflush(out);
    ntaken = 0;
}
