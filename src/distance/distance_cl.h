/* Private: the heat-method distance's stages on an OpenCL device (distance_cl.c). */
#ifndef HV_HEAT_DISTANCE_CL_H
#define HV_HEAT_DISTANCE_CL_H

#include "distance_internal.h"

/* Everything of a distance query after the sources and the regions, for
 * backend opencl: the stages (hv__dist_stages over the device's fields: two
 * diffusion solves each, trust, face assignment, next front), the
 * divergence, the Poisson solve by psolver (the hv_distance's solver, made
 * for backend opencl and kept across queries), and the per-region offsets;
 * writes g->v (the one read of a field) and the stage, solve and timing
 * fields of S. region: per cell >= 0 region with a source, -1 solid, -2
 * fluid out of reach (nregions regions); w: the source weights (the first
 * front); ref: as hv__dist_splat. Sets *handled to 0 and does nothing when
 * the device lacks fp64 (the host path then runs, in double as always). */
hv_status hv__distance_heat_cl(hv_grid *g, const hv_distance_opts *o, hv_solver *psolver,
                               const int32_t *region, size_t nregions, const double *w,
                               const float *ref, hv_distance_stats *S, int *handled);

#endif
