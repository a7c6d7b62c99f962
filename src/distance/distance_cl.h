/* Private: the heat-method distance's stages on an OpenCL device (distance_cl.c). */
#ifndef HV_HEAT_DISTANCE_CL_H
#define HV_HEAT_DISTANCE_CL_H

#include "distance_internal.h"

/* Everything of hv_distance_compute after the sources and the regions, for
 * backend opencl: the marching stages (two diffusion solves each, trust, face
 * assignment, next front), the divergence, the Poisson solve and the
 * per-region offsets, with the fields on the device; writes g->v (the one
 * read of a field) and the stage, solve and timing fields of S. region: per
 * cell >= 0 region with a source, -1 solid, -2 fluid out of reach (nregions
 * regions); w: the source weights (the first front); ref: as hv__dist_splat.
 * Sets *handled to 0 and does nothing when the device lacks fp64 (the host
 * path then runs, in double as always). */
hv_status hv__distance_heat_cl(hv_grid *g, const hv_distance_opts *o, const int32_t *region,
                               size_t nregions, const double *w, const float *ref,
                               hv_distance_stats *S, int *handled);

#endif
