/* Private pieces of the signed heat method (src/heat/). */
#ifndef HV_HEAT_SDF_INTERNAL_H
#define HV_HEAT_SDF_INTERNAL_H

#include "heatvox/sdf.h"

/* Surface quadrature: triangles subdivided until sub-edges are <= h/2; one
 * point per sub-triangle at its centroid. Points outside the box [lo, hi]
 * (the voxel block) are dropped. */
typedef struct hv_quad {
    size_t count;
    double *x;      /* 3 * count positions */
    double *w;      /* 3 * count area-weighted normals (vector areas) */
    double *area;   /* count areas */
} hv_quad;

hv_status hv_quad_build(const hv_mesh *m, double h, const double lo[3], const double hi[3],
                        hv_quad *q);
void hv_quad_free(hv_quad *q);

/* Trilinear weights of world point x on the cell centres of g (clamped to the
 * block): base cell in c0, weights for the 8 corners (x fastest) in w, and the
 * per-axis steps (0 where clamped to one cell) in step. */
void hv_trilinear(const hv_grid *g, const double x[3], size_t *c0, size_t step[3], double w[8]);

/* Closest point on triangle abc to p; returns the squared distance. */
double hv_point_triangle_d2(const double p[3], const double a[3], const double b[3],
                            const double c[3]);

/* Exact unsigned distance from every cell centre of g to the triangles of m:
 * rasterized within `band` cells of each triangle, then propagated by
 * closest-triangle sweeps. Writes dist (world units) and, if tri is not NULL,
 * the nearest triangle (UINT32_MAX where none). band_cells counts rasterized cells. */
hv_status hv_exact_distance(const hv_mesh *m, const hv_grid *g, double band, float *dist,
                            uint32_t *tri, size_t *band_cells);

#endif
