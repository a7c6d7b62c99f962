/* Private pieces of the signed heat method (src/heat/). */
#ifndef HV_HEAT_SDF_INTERNAL_H
#define HV_HEAT_SDF_INTERNAL_H

#include "heatvox/sdf.h"

#include <string.h>

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

/* Ericson, Real-Time Collision Detection, 5.1.5: closest point on a triangle
 * by Voronoi regions. diff = p - closest point; region as in sdf_internal.h. */
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

/* Exact unsigned distance from every cell centre of g to the triangles of m:
 * rasterized within `band` cells of each triangle, then carried to the rest of
 * the grid by closest-triangle sweeps, up to the distance `cap` (world units;
 * INFINITY for the whole grid): cells farther than cap get INFINITY. Writes
 * dist (world units) and, if tri is not NULL, the nearest triangle
 * (UINT32_MAX where none). band_cells counts rasterized cells. */
hv_status hv__exact_distance(const hv_mesh *m, const hv_grid *g, double band, double cap,
                             float *dist, uint32_t *tri, size_t *band_cells);

/* Fast generalized winding number over a subset of a mesh's faces. */
typedef struct hv_wn_node {
    double c[3], N[3], r; /* area-weighted centre, summed vector area, radius */
    int left, right;      /* children or -1 */
    size_t first, count;  /* range in order[] */
} hv_wn_node;

typedef struct hv_wn_tree {
    const double *V;
    const uint32_t *T;
    uint32_t *order;
    signed char *sign; /* -1 for faces taken reversed */
    hv_wn_node *nodes;
    int nnodes;
} hv_wn_tree;

/* Builds the tree over faces[0..nfaces) of (V, T); flip (may be NULL) reverses faces. */
hv_status hv__wn_build(hv_wn_tree *W, const double *V, const uint32_t *T, const uint32_t *faces,
                       size_t nfaces, const uint8_t *flip);
/* Winding number at p, leaving out face `skip` (UINT32_MAX: none). */
double hv__wn_eval(const hv_wn_tree *W, const double p[3], uint32_t skip);
/* The same with clusters farther than beta times their radius taken as
 * dipoles (hv__wn_eval: 2.5; smaller is faster and coarser). */
double hv__wn_eval_beta(const hv_wn_tree *W, const double p[3], uint32_t skip, double beta);
void hv__wn_free(hv_wn_tree *W);

/* Angle-weighted pseudonormals of a mesh, with cleanliness of each feature. */
typedef struct hv_pseudo {
    double *fn;      /* 3 * ntris unit face normals */
    double *vn;      /* 3 * nverts angle-weighted vertex normals */
    uint32_t *other; /* 3 * ntris: face across each edge, UINT32_MAX if the edge is not clean */
    uint8_t *vok;    /* nverts: every edge at the vertex is clean */
    uint8_t *ftrust; /* ntris: 0 not yet known, 1 the face bounds a solid (winding number
                        about 1/2 on it), 2 not */
    hv_wn_tree W;    /* over all faces, for ftrust */
    int have_W;
} hv_pseudo;

hv_status hv__pseudo_build(const hv_mesh *m, hv_pseudo *ps);
void hv__pseudo_free(hv_pseudo *ps);
/* Sign (+1 outside, -1 inside) from the pseudonormal of triangle tri's feature
 * nearest to p, where that feature is clean; 0 where it is not. Where that
 * sign differs from `current` it is only given when the feature's faces bound
 * a solid (tested on demand; thread-safe). */
int hv__pseudo_sign(hv_pseudo *ps, const hv_mesh *m, uint32_t tri, const double p[3], int current);

/* The sign of each cell of g from the generalized winding number of m (inside
 * above 1/2; ps->W), evaluated hierarchically (sign_winding.c): cubes far from
 * the surface (dist: the exact distance, INFINITY where not computed) whose
 * corners agree take one sign; cells within dlim of their nearest triangle
 * tri[c] (tri may be NULL) take its pseudonormal's sign where that feature
 * is clean and bounds a solid. out[c] = -1e-6 h inside, +1e-6 h outside.
 * evals counts winding-number evaluations, ps_used cells signed by
 * pseudonormals (either may be NULL). */
hv_status hv__winding_sign(const hv_mesh *m, const hv_grid *g, const float *dist,
                           const uint32_t *tri, hv_pseudo *ps, double dlim, float *out,
                           size_t *evals, size_t *ps_used);

#endif
