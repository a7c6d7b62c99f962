/*
 * OpenCL devices for the opencl solver backend (HV_BACKEND_OPENCL).
 *
 * The backend runs on one device, chosen by the environment variable
 *     HEATVOX_OPENCL_DEVICE="P:D"      platform index P, device index D
 *     HEATVOX_OPENCL_DEVICE="<text>"   first device whose name contains <text>
 *                                      (case-insensitive)
 * and, when it is unset or empty, the first GPU, else the first device.
 * `heatvox devices` lists what is available.
 *
 * Create OpenCL solvers after any fork(): a child forked from a process that
 * holds an OpenCL context may hang.
 */
#ifndef HEATVOX_OPENCL_H
#define HEATVOX_OPENCL_H

#include "core.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct hv_opencl_device {
    int platform; /* P in HEATVOX_OPENCL_DEVICE="P:D" */
    int device;   /* D */
    char name[128];
    char platform_name[128];
    char version[128];   /* CL_DEVICE_VERSION, e.g. "OpenCL 3.0 PoCL ..." */
    uint64_t global_mem; /* bytes */
    int compute_units;
    int fp64;     /* double precision: the defect correction runs on the device */
    int gpu;      /* a GPU (else CPU or accelerator) */
    int selected; /* the device the opencl backend would use now */
} hv_opencl_device;

/* Lists the OpenCL devices of every platform into out[0..max) (out may be
 * NULL when max is 0) and sets *count to the number found, which may exceed
 * max. Marks the selected device (none when HEATVOX_OPENCL_DEVICE names no
 * device). HV_ERR_UNSUPPORTED when no OpenCL platform is installed. */
HV_API hv_status hv_opencl_list_devices(hv_opencl_device *out, int max, int *count);

/* The device the opencl backend would use, into *out (may be NULL).
 * HV_ERR_UNSUPPORTED when there is no OpenCL platform or device,
 * HV_ERR_INVALID_ARG when HEATVOX_OPENCL_DEVICE names no device; the message
 * (hv_last_error) says which and lists the devices. Cheap (no context is
 * created). HV_BACKEND_AUTO uses it to take a GPU when there is one
 * (hv_backend_resolve in solve.h). */
HV_API hv_status hv_opencl_probe(hv_opencl_device *out);

#ifdef __cplusplus
}
#endif
#endif
