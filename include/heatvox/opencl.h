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

#ifndef CL_TARGET_OPENCL_VERSION
#define CL_TARGET_OPENCL_VERSION 120
#endif
#include <CL/cl.h>

#ifdef __cplusplus
extern "C" {
#endif

/* The solver's problem, options and results (solve.h) and the extender's
 * (heat.h), by pointer: the device layer sits below them. Every public entry
 * that takes OpenCL objects is declared here. */
typedef struct hv_problem hv_problem;
typedef struct hv_solver_opts hv_solver_opts;
typedef struct hv_solve_info hv_solve_info;
typedef struct hv_solver hv_solver;
typedef struct hv_extender hv_extender;
typedef struct hv_extend_opts hv_extend_opts;
typedef struct hv_extend_stats hv_extend_stats;

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

/* ---- fields on the device ----
 * A solver on the caller's OpenCL context, device and in-order command queue,
 * whose right-hand side and solution are buffers of floats (the problem's
 * cells, x fastest) on that context: a simulation keeps its grids on the
 * device between steps, and only a few scalars per iteration cross to the
 * host. Everything that does not change between solves (the hierarchy, the
 * masks, the kernels) is made here, once; heatvox's kernels are built once
 * per context and kept while a solver on it lives. The context and queue are
 * retained until hv_solver_destroy. opts may be NULL (defaults); its backend
 * is ignored. HV_ERR_INVALID_ARG for a queue of another context or device, or
 * an out-of-order queue. */
HV_API hv_status hv_opencl_solver_create(hv_solver **out, const hv_problem *p,
                                         const hv_solver_opts *opts, cl_context ctx,
                                         cl_device_id dev, cl_command_queue queue);

/* Solves A u = f on the device: f and u are float buffers of at least the
 * problem's cells on the solver's context (u holds the guess when
 * opts->nonzero_guess). The commands go to the solver's queue after what the
 * caller enqueued there and have finished when it returns. Also for solvers
 * of hv_solver_create with the opencl backend, on the context that
 * hv_opencl_solver_queue names. info may be NULL. The solve stays on the
 * device (solid cells of f are ignored and get u = 0 there) except on a device
 * without fp64, where f and u go through the host's solver. */
HV_API hv_status hv_opencl_solve(hv_solver *sv, cl_mem f, cl_mem u, hv_solve_info *info);

/* The context, device and queue an opencl solver's commands go to (not
 * retained for the caller; any may be NULL). HV_ERR_UNSUPPORTED for a solver
 * of another backend. */
HV_API hv_status hv_opencl_solver_queue(hv_solver *sv, cl_context *ctx, cl_device_id *dev,
                                        cl_command_queue *queue);

/* ---- the extension with fields on the device ----
 * An extender (heat.h) on the caller's OpenCL context, device and in-order queue
 * (retained until hv_extender_destroy): phi and the fields are float buffers
 * of the extender's cells on that context, so that a simulation extends its
 * velocity every step without the grids leaving the device (the weights, the
 * solves, the closest-point evaluation and the later levels all run there;
 * a few counters per level cross to the host). opts->backend is ignored. */
typedef struct hv_opencl_field {
    int ncomp;     /* 1 (scalar) to 3 (vector) */
    cl_mem in[3];  /* float buffers of the extender's cells */
    cl_mem out[3]; /* may be in[] (in place) */
} hv_opencl_field;

HV_API hv_status hv_opencl_extender_create(hv_extender **out, int dim, const int n[3], double h,
                                           const uint8_t *solid, const hv_extend_opts *opts,
                                           cl_context ctx, cl_device_id dev,
                                           cl_command_queue queue);

/* hv_extend_many with phi and the fields on the device: an extender of
 * hv_opencl_extender_create, or of hv_extender_create with the opencl
 * backend (buffers on the context hv_opencl_extender_queue names). The
 * commands have finished when it returns. */
HV_API hv_status hv_opencl_extend(hv_extender *e, cl_mem phi, int nfields,
                                  const hv_opencl_field *fields, hv_extend_stats *stats);

/* ---- narrow bands in tiles with fields on the device ----
 * A narrow-band level set on the device as hv_tiles (grid.h) holds it on the
 * host, on the extender's block: count tiles; ijk int32 3 count (each tile's
 * first cell, on the block's 8^3 lattice), v float 512 count (v[t 512 + i +
 * 8 j + 64 k]), on 8 count 64-bit words (bit i + 8 j of word k: active). */
typedef struct hv_opencl_tiles {
    size_t count;
    cl_mem ijk, v, on;
} hv_opencl_tiles;

/* One field on the level set's tiles (ncomp 1 or 3), each component's
 * values and active words laid out as the level set's, extended in place as
 * hv_extend_tiles_field. */
typedef struct hv_opencl_tiles_field {
    int ncomp;
    cl_mem v[3];
    cl_mem on[3];
} hv_opencl_tiles_field;

/* hv_extend_tiles (heat.h) with the level set and the fields on the device:
 * an extender of hv_opencl_extender_create, or of hv_extender_create with
 * the opencl backend (buffers on the context hv_opencl_extender_queue
 * names), so that a simulation that keeps a narrow band on a GPU extends its
 * velocity every step without a copy to the host (a few counters per level
 * cross). The same values as hv_extend_tiles on the host. HV_ERR_UNSUPPORTED
 * on a device without double precision, or past 17 right-hand sides (1 + per
 * field 1, or 4 for a vector). The commands have finished when it returns. */
HV_API hv_status hv_opencl_extend_tiles(hv_extender *e, const hv_opencl_tiles *phi, int nfields,
                                        const hv_opencl_tiles_field *f, hv_extend_stats *stats);

/* The context, device and queue an extender's device work goes to (made on
 * first use for one of hv_extender_create with the opencl backend; any of
 * the three may be NULL). HV_ERR_UNSUPPORTED for an extender of another
 * backend. */
HV_API hv_status hv_opencl_extender_queue(hv_extender *e, cl_context *ctx, cl_device_id *dev,
                                          cl_command_queue *queue);

/* ---- kernel times and host traffic ----
 * With HEATVOX_OPENCL_PROFILE=1 in the environment, the queues heatvox makes
 * time every kernel and transfer with events and count the bytes that cross
 * between host and device; a caller's queue is timed whenever it was made
 * with CL_QUEUE_PROFILING_ENABLE. */
typedef struct hv_opencl_kernel_time {
    const char *name; /* the kernel, or "read", "write", "copy", "fill" */
    long launches;
    double seconds; /* device time, summed */
    double bytes;   /* "read": bytes to the host; "write": to the device (buffers made from
                       host memory included); 0 for the rest */
} hv_opencl_kernel_time;

/* The times summed since the last call, the largest first, into
 * out[0..max); returns how many names were timed (may exceed max) and
 * starts the sums again. Commands of handles still open are counted once
 * their queue finishes. */
HV_API int hv_opencl_profile_take(hv_opencl_kernel_time *out, int max);

#ifdef __cplusplus
}
#endif
#endif
