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

/* The device handle of x (its context, queue and built modules). */
struct hv_cl *hv__extend_cl_handle(hv_extend_cl *x);

/* ---- narrow bands in tiles on the device (extend_tiles_cl.c) ---- */

/* Right-hand sides a tile extension takes on the device (1 + per field 1
 * or 4): a private array of each evaluating work-item. */
#define HV_EXTEND_TILES_CL_MAX_R 17
/* Device bytes per tile of the block: its map, four masks, two counts. */
#define HV_EXTEND_TILES_CL_BYTES (4 + 4 * 64 + 2 * 4)

/* Made on the extender's device state (hv__extend_cl_prepare) at first use:
 * HV_ERR_UNSUPPORTED on a device without double precision. */
hv_status hv__extend_tiles_cl_prepare(hv_extender *e);
void hv__extend_tiles_cl_destroy(struct hv_extend_tiles_cl **state);

/* hv_extend_tiles on the device once the arguments are checked: the level
 * set and the fields go to the device, the outputs come back (the tiles'
 * values and active words; `active` is the caller's to count).
 * HV_ERR_UNSUPPORTED past HV_EXTEND_TILES_CL_MAX_R right-hand sides. */
hv_status hv__extend_tiles_cl_run(hv_extender *e, const hv_tiles *phi, int nfields,
                                  hv_extend_tiles_field *f, hv_extend_stats *S);

/* hv_opencl_extend_tiles once the extender is checked: the buffers on the
 * extender's context (checked here). */
hv_status hv__extend_tiles_cl_run_dev(hv_extender *e, const hv_opencl_tiles *phi, int nfields,
                                      const hv_opencl_tiles_field *f, hv_extend_stats *S);

#endif
