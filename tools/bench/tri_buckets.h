/* Exact closest points on a triangle mesh for the benchmarks that score
 * against a mesh (bench extend-band, bench points): the triangles bucketed
 * in a hash grid of cubes, so that a query within distance r of the mesh
 * searches only the buckets the box x +- r meets. (tools/bench/tri_buckets.c) */
#ifndef HV_TOOLS_BENCH_TRI_BUCKETS_H
#define HV_TOOLS_BENCH_TRI_BUCKETS_H

#include <heatvox/mesh.h>

typedef struct tri_buckets {
    const hv_mesh *m;   /* not owned: must outlive the buckets */
    double lo[3], size; /* bucket (i,j,k) is lo + [i, i+1) size along each axis */
    size_t mask;        /* hash slots - 1 (a power of two minus one) */
    uint64_t *key;      /* per slot: packed bucket + 1, 0 when empty */
    uint32_t *first, *count;
    uint32_t *tri; /* triangle indices, grouped by bucket */
} tri_buckets;

/* Buckets of edge `size` (world units; a few voxels) over m's triangles. */
hv_status tri_buckets_build(tri_buckets *b, const hv_mesh *m, double size);
void tri_buckets_free(tri_buckets *b);

/* The closest point cp to x on the mesh, exact when it lies within r of x.
 * Returns 0, or -1 when no triangle lies in the buckets searched. */
int tri_buckets_closest(const tri_buckets *b, const double x[3], double r, double cp[3]);

/* Closest point to p on triangle abc. */
void tri_closest_point(const double p[3], const double *a, const double *b, const double *c,
                       double out[3]);

#endif
