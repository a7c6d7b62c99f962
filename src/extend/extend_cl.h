/* Private: the extension off a level set on an OpenCL device (extend_cl.c). */
#ifndef HV_HEAT_EXTEND_CL_H
#define HV_HEAT_EXTEND_CL_H

#include "extend_internal.h"
#include "heatvox/opencl.h"

#include <stdint.h>

/* The device's buffers and solvers, kept between calls of one extender. */
typedef struct hv_extend_cl hv_extend_cl;

/* What the device path needs of the extender. */
typedef struct hv_extend_grid {
    const hv_extender *e;
    int dim, n[3]; /* n[2] = 1 in 2D */
    double h;
    size_t count;
    const uint8_t *solid; /* NULL without obstacles */
    const hv_extend_opts *o;
} hv_extend_grid;

/* hv_extend_many with backend opencl once the arguments are checked (phi
 * finite, nrhs right-hand sides): weights, every solve (the level boxes of the
 * host path), the closest-point evaluation and the later levels on the
 * device; reads back the outputs and the counts the stats need. *state is
 * created on first use (and freed with hv__extend_cl_destroy). Fills S but for
 * t_total. */
hv_status hv__extend_cl_run(hv_extend_cl **state, const hv_extend_grid *g, const float *phi,
                            int nfields, const hv_extend_field *f, int nrhs, hv_extend_stats *S);
void hv__extend_cl_destroy(hv_extend_cl **state);

/* Creates *state when it is NULL: on the caller's context, device and queue
 * when ctx is not NULL (hv_opencl_extender_create), else on heatvox's own. */
hv_status hv__extend_cl_prepare(hv_extend_cl **state, const hv_extend_grid *g, cl_context ctx,
                                cl_device_id dev, cl_command_queue queue);

/* The context, device and queue of x (any may be NULL). */
void hv__extend_cl_queue(const hv_extend_cl *x, cl_context *ctx, cl_device_id *dev,
                         cl_command_queue *queue);

/* hv_opencl_extend once the extender is checked: the fields are buffers on
 * x's context (checked here), copied on the device into x's planes and back. */
hv_status hv__extend_cl_run_dev(hv_extend_cl *x, const hv_extend_grid *g, cl_mem phi, int nfields,
                                const hv_opencl_field *f, int nrhs, hv_extend_stats *S);

#endif
