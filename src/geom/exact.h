/* Closest points on triangles and the exact distance from a grid to a mesh (exact.c). */
#ifndef HV_HEAT_EXACT_H
#define HV_HEAT_EXACT_H

#include "heatvox/grid.h"
#include "heatvox/mesh.h"

#include <stdint.h>
#include <string.h>

/* Ericson, Real-Time Collision Detection, 5.1.5: closest point on a triangle
 * by Voronoi regions. diff = p - closest point; region as in hv__point_triangle_region. */
static inline double hv_closest(const double p[3], const double a[3], const double b[3],
                                const double c[3], double q[3], int *region)
{
    double ab[3], ac[3], ap[3];
    for (int i = 0; i < 3; i++) {
        ab[i] = b[i] - a[i];
        ac[i] = c[i] - a[i];
        ap[i] = p[i] - a[i];
    }
#define DOT(u, v) ((u)[0] * (v)[0] + (u)[1] * (v)[1] + (u)[2] * (v)[2])
    double d1 = DOT(ab, ap), d2 = DOT(ac, ap);
    if (d1 <= 0 && d2 <= 0) {
        memcpy(q, ap, sizeof ap);
        *region = 1;
        return DOT(ap, ap);
    }
    double bp[3] = {p[0] - b[0], p[1] - b[1], p[2] - b[2]};
    double d3 = DOT(ab, bp), d4 = DOT(ac, bp);
    if (d3 >= 0 && d4 <= d3) {
        memcpy(q, bp, sizeof bp);
        *region = 2;
        return DOT(bp, bp);
    }
    double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) {
        double v = d1 / (d1 - d3);
        for (int i = 0; i < 3; i++)
            q[i] = ap[i] - v * ab[i];
        *region = 4;
        return DOT(q, q);
    }
    double cp[3] = {p[0] - c[0], p[1] - c[1], p[2] - c[2]};
    double d5 = DOT(ab, cp), d6 = DOT(ac, cp);
    if (d6 >= 0 && d5 <= d6) {
        memcpy(q, cp, sizeof cp);
        *region = 3;
        return DOT(cp, cp);
    }
    double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) {
        double w = d2 / (d2 - d6);
        for (int i = 0; i < 3; i++)
            q[i] = ap[i] - w * ac[i];
        *region = 6;
        return DOT(q, q);
    }
    double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
        double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        for (int i = 0; i < 3; i++)
            q[i] = bp[i] - w * (c[i] - b[i]);
        *region = 5;
        return DOT(q, q);
    }
    double denom = 1.0 / (va + vb + vc);
    double v = vb * denom, w = vc * denom;
    for (int i = 0; i < 3; i++)
        q[i] = ap[i] - ab[i] * v - ac[i] * w;
    *region = 0;
    return DOT(q, q);
#undef DOT
}

/* Closest point on triangle abc to p; returns the squared distance. */
double hv__point_triangle_d2(const double p[3], const double a[3], const double b[3],
                             const double c[3]);

/* The same with p - closest point in diff and the closest feature in region:
 * 0 the face, 1..3 vertex a, b, c, 4 edge ab, 5 edge bc, 6 edge ca. */
double hv__point_triangle_region(const double p[3], const double a[3], const double b[3],
                                 const double c[3], double diff[3], int *region);

/* The distance of triangle t written into the cells of one box [blo, bhi]
 * (indices of the block with the given origin and h, inclusive) within W of
 * it, as the grid raster of hv__exact_distance does: best[] over the box (x
 * fastest, cell blo first) keeps the least (float distance bits << 32 | t),
 * UINT64_MAX where none. Not thread-safe on one box. */
void hv__exact_raster_tile(const hv_mesh *m, const double origin[3], double h, const int blo[3],
                           const int bhi[3], uint32_t t, double W, uint64_t *best);

/* Exact unsigned distance from every cell centre of g to the triangles of m:
 * rasterized within `band` cells of each triangle, then carried to the rest of
 * the grid by closest-triangle sweeps, up to the distance `cap` (world units;
 * INFINITY for the whole grid): cells farther than cap get INFINITY. Writes
 * dist (world units) and, if tri is not NULL, the nearest triangle
 * (UINT32_MAX where none). band_cells counts rasterized cells. */
hv_status hv__exact_distance(const hv_mesh *m, const hv_grid *g, double band, double cap,
                             float *dist, uint32_t *tri, size_t *band_cells);

#endif
