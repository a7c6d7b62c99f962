/*
 * Private: grid operations on an OpenCL device for the heat methods and the
 * solver: per-region sums and mean projections (one constant per connected
 * fluid region, docs/METHOD.md, "Multigrid"), face gradient and divergence
 * (as src/ops/faces.c), the heat methods' face normalization, ratio and axpy.
 * Their kernels (kernels/reduce.cl, faces.cl, pointwise.cl) are this
 * folder's module, hv__cl_ops_module. The device-resident solve is
 * src/solve/cl/solve_cl.h's. Steps of one heat method live with it (its
 * device path in src/sdf/, src/distance/, src/extend/) and build their own
 * kernels (cl_core.h, hv_cl_module).
 * Arrays are cl_mem of float unless named _d (double, fp64 devices only).
 * Everything is enqueued on cl's queue; errors surface at hv__cl_check /
 * hv__cl_finish.
 */
#ifndef HV_CL_CL_OPS_H
#define HV_CL_CL_OPS_H

#include "cl_core.h"

/* The module of these operations' kernels. hv__cl_ops_open builds it on cl
 * where errors can be reported (its launches open it otherwise). */
extern const hv_cl_module hv__cl_ops_module;
hv_status hv__cl_ops_open(hv_cl *cl);

/* S[slot] (acc_t) = sum over n of a*b (b NULL: of a), float vectors. */
void hv__cl_dot_f(hv_cl *cl, cl_mem a, cl_mem b, size_t n, cl_mem S, int slot);
/* part[group] = sum of a*b over the group's block of n doubles, the groups of
 * hv__cl_range_red(n) (fp64 handles only). */
void hv__cl_dot_parts_d(hv_cl *cl, cl_mem a, cl_mem b, size_t n, cl_mem part);
/* S[slot] = sum of nparts acc_t partials. */
void hv__cl_finish_sum(hv_cl *cl, cl_mem part, size_t nparts, cl_mem S, int slot);

/* Cells sorted by region and cut into chunks (one work-group each), so that
 * per-region sums take two kernels whatever the number and size of regions. */
typedef struct hv_cl_regions {
    size_t count; /* cells */
    int nregion;
    size_t nchunk;
    cl_mem region; /* int32 labels (-1 = none), NULL for one region = the whole grid */
    cl_mem perm;   /* region-sorted cells, NULL without labels */
    cl_mem cb;     /* chunk bounds in perm, nchunk + 1 */
    cl_mem rc;     /* first chunk of each region, nregion + 1 */
    cl_mem rinv;   /* acc_t 1 / cells per region */
    cl_mem part;   /* acc_t per chunk */
    cl_mem sum;    /* acc_t per region: the result of the last sum or mean */
} hv_cl_regions;

/* region: NULL (one region, all cells) or count labels in [0, nregion) and -1. */
hv_status hv__cl_regions_create(hv_cl *cl, hv_cl_regions *R, size_t count, const int32_t *region,
                                int nregion);
void hv__cl_regions_destroy(hv_cl_regions *R);
/* R->sum[r] = sum (mean: mean) of v over region r. */
void hv__cl_region_sums(hv_cl *cl, hv_cl_regions *R, cl_mem v, int mean);
/* v -= its region's mean; 0 outside every region. */
void hv__cl_project(hv_cl *cl, hv_cl_regions *R, cl_mem v);
void hv__cl_project_d(hv_cl *cl, hv_cl_regions *R, cl_mem v);

/* g[a] (axis-a faces, a < dim) = face gradient of u; solid may be NULL (uint8 per cell). */
void hv__cl_face_gradient(hv_cl *cl, int dim, const int n[3], double h, cl_mem solid, cl_mem u,
                          cl_mem const g[3]);
/* out = divergence of the face field F (F[2] unused in 2D). */
void hv__cl_face_divergence(hv_cl *cl, int dim, const int n[3], double h, cl_mem solid,
                            cl_mem const F[3], cl_mem out);
/* out[a] = axis-a component of the normalized mean of the cell vectors v at
 * axis-a faces (v[2] unused in 2D); 0 on walls, solid faces and where the
 * mean's largest component is <= eps. */
void hv__cl_face_normalize(hv_cl *cl, int dim, const int n[3], cl_mem solid, cl_mem const v[3],
                           cl_mem const out[3], double eps);
/* out = b > eps ? a / b : 0 */
void hv__cl_ratio(hv_cl *cl, size_t n, cl_mem a, cl_mem b, cl_mem out, double eps);
/* y += alpha x */
void hv__cl_axpy(hv_cl *cl, size_t n, double alpha, cl_mem x, cl_mem y);
/* out[0..n) = the exclusive prefix sums of in[0..n) (uint32; out may not be
 * in). To have the total, scan n + 1 entries whose last is 0. */
hv_status hv__cl_scan_u32(hv_cl *cl, cl_mem in, cl_mem out, size_t n);

#endif
