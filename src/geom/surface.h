/* Surface quadrature of a mesh and trilinear weights on a grid (surface.c). */
#ifndef HV_HEAT_SURFACE_H
#define HV_HEAT_SURFACE_H

#include "heatvox/grid.h"
#include "heatvox/mesh.h"

/* Surface quadrature: triangles subdivided until sub-edges are <= h; one
 * point per sub-triangle at its centroid. Points outside the box [lo, hi]
 * (the voxel block) are dropped. */
typedef struct hv_quad {
    size_t count;
    double *x;    /* 3 * count positions */
    double *w;    /* 3 * count area-weighted normals (vector areas) */
    double *area; /* count areas */
} hv_quad;

hv_status hv__quad_build(const hv_mesh *m, double h, const double lo[3], const double hi[3],
                         hv_quad *q);
void hv__quad_free(hv_quad *q);

/* Trilinear weights of world point x on the cell centres of g (clamped to the
 * block): base cell in c0, weights for the 8 corners (x fastest) in w, and the
 * per-axis steps (0 where clamped to one cell) in step. */
void hv__trilinear(const hv_grid *g, const double x[3], size_t *c0, size_t step[3], double w[8]);

#endif
