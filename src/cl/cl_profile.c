/*
 * Kernel and transfer times of heatvox's own OpenCL queues, summed per name
 * across every handle of the process (HEATVOX_OPENCL_PROFILE=1). Each launch
 * keeps its event; a handle's events are read when it finishes its queue,
 * when it holds HV_CL_PROFILE_EVENTS of them, and when it closes.
 */
#include "cl_core.h"

#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#define PROFILE_NAMES 256

static pthread_mutex_t profile_lock = PTHREAD_MUTEX_INITIALIZER;
static hv_opencl_kernel_time profile[PROFILE_NAMES];
static int profile_count;

int hv__cl_profiling(void)
{
    static int on = -1;
    if (on < 0) {
        const char *e = getenv("HEATVOX_OPENCL_PROFILE");
        on = e && *e && strcmp(e, "0") != 0;
    }
    return on;
}

static void profile_add(const char *name, double seconds, double bytes)
{
    int i = 0;
    while (i < profile_count && strcmp(profile[i].name, name) != 0)
        i++;
    if (i == profile_count) {
        if (profile_count == PROFILE_NAMES)
            return;
        profile[profile_count++] = (hv_opencl_kernel_time){name, 0, 0.0, 0.0};
    }
    profile[i].launches++;
    profile[i].seconds += seconds;
    profile[i].bytes += bytes;
}

void hv__cl_profile_flush(hv_cl *cl)
{
    if (!cl->nev)
        return;
    clWaitForEvents((cl_uint)cl->nev, cl->ev);
    pthread_mutex_lock(&profile_lock);
    for (int i = 0; i < cl->nev; i++) {
        cl_ulong t0 = 0, t1 = 0;
        if (clGetEventProfilingInfo(cl->ev[i], CL_PROFILING_COMMAND_START, sizeof t0, &t0, NULL) ==
                CL_SUCCESS &&
            clGetEventProfilingInfo(cl->ev[i], CL_PROFILING_COMMAND_END, sizeof t1, &t1, NULL) ==
                CL_SUCCESS &&
            t1 >= t0)
            profile_add(cl->evname[i], (double)(t1 - t0) * 1e-9, (double)cl->evbytes[i]);
        clReleaseEvent(cl->ev[i]);
    }
    pthread_mutex_unlock(&profile_lock);
    cl->nev = 0;
}

cl_event *hv__cl_profile_event(hv_cl *cl, const char *name)
{
    if (!cl->profile)
        return NULL;
    if (cl->nev == HV_CL_PROFILE_EVENTS)
        hv__cl_profile_flush(cl);
    cl->evname[cl->nev] = name;
    cl->evbytes[cl->nev] = 0;
    return &cl->ev[cl->nev];
}

void hv__cl_profile_done(hv_cl *cl, cl_int e)
{
    if (cl->profile && e == CL_SUCCESS)
        cl->nev++;
}

void hv__cl_profile_moved(hv_cl *cl, cl_int e, size_t bytes)
{
    if (cl->profile && e == CL_SUCCESS)
        cl->evbytes[cl->nev++] = bytes;
}

void hv__cl_profile_count(hv_cl *cl, const char *name, size_t bytes)
{
    if (!cl->profile)
        return;
    pthread_mutex_lock(&profile_lock);
    profile_add(name, 0.0, (double)bytes);
    pthread_mutex_unlock(&profile_lock);
}

static int by_seconds(const void *a, const void *b)
{
    double x = ((const hv_opencl_kernel_time *)a)->seconds;
    double y = ((const hv_opencl_kernel_time *)b)->seconds;
    return (x < y) - (x > y);
}

int hv_opencl_profile_take(hv_opencl_kernel_time *out, int max)
{
    pthread_mutex_lock(&profile_lock);
    qsort(profile, (size_t)profile_count, sizeof profile[0], by_seconds);
    int n = profile_count;
    for (int i = 0; i < n && i < max; i++)
        out[i] = profile[i];
    profile_count = 0;
    pthread_mutex_unlock(&profile_lock);
    return n;
}
