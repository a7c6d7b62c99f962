/* Private: the signed heat method's field stages on an OpenCL device (sdf_cl.c). */
#ifndef HV_HEAT_SDF_CL_H
#define HV_HEAT_SDF_CL_H

#include "sdf_internal.h"

/* Stages 2-6 of hv_sdf_compute for backend opencl: splats the samples q into
 * the grid of g, diffuses nlev levels (t = S->t * 16^k), normalizes on faces
 * (the vector field, or for unsig the scalar's gradient), takes the divergence,
 * solves the Poisson step and shifts the zero set (globally, and locally when
 * o->local_shift and !unsig), all on the device; writes phi into g->v and the
 * fields of S those stages fill. */
hv_status hv_sdf_heat_cl(const hv_quad *q, hv_grid *g, int nlev, int unsig, const hv_sdf_opts *o,
                         hv_sdf_stats *S);

#endif
