/* Private: pieces of the heat-method distance shared between its files. */
#ifndef HV_HEAT_DISTANCE_INTERNAL_H
#define HV_HEAT_DISTANCE_INTERNAL_H

#include "heatvox/heat.h"

#define HV_DIST_REF_RADIUS 3.0

/* Adds the source weights of src onto w (one double per cell of g, zeroed by
 * the caller): voxels weigh 1, points 1 spread trilinearly over the fluid cells
 * among their 8 neighbours, mesh samples their area / h^2 the same way.
 * ref (one float per cell, +INFINITY on entry) receives, on the fluid cells
 * within HV_DIST_REF_RADIUS voxels of a source item (voxel centre, point, mesh
 * sample), the least distance from the cell centre to one: the distance those
 * cells should have (when no obstacle intervenes), used to place the zero.
 * *in_solid counts sources with no fluid cell to land on. */
hv_status hv_dist_splat(const hv_grid *g, const hv_distance_sources *src, double *w, float *ref,
                        size_t *in_solid);

#endif
