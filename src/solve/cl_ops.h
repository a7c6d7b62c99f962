/*
 * Private: grid operations on an OpenCL device for the heat methods and the
 * solver: per-region sums and mean projections (one constant per connected
 * fluid region, docs/METHOD.md, "Multigrid"), face gradient and divergence
 * (as src/ops/faces.c), the heat methods' face normalization, ratio and axpy.
 * Arrays are cl_mem of float unless named _d (double, fp64 devices only).
 * Everything is enqueued on cl's queue; errors surface at hv_cl_check /
 * hv_cl_finish.
 */
#ifndef HV_SOLVE_CL_OPS_H
#define HV_SOLVE_CL_OPS_H

#include "cl_core.h"
#include "heatvox/solve.h"

/* Cells sorted by region and cut into chunks (one work-group each), so that
 * per-region sums take two kernels whatever the number and size of regions. */
typedef struct hv_cl_regions {
    size_t count;      /* cells */
    int nregion;
    size_t nchunk;
    cl_mem region;     /* int32 labels (-1 = none), NULL for one region = the whole grid */
    cl_mem perm;       /* region-sorted cells, NULL without labels */
    cl_mem cb;         /* chunk bounds in perm, nchunk + 1 */
    cl_mem rc;         /* first chunk of each region, nregion + 1 */
    cl_mem rinv;       /* acc_t 1 / cells per region */
    cl_mem part;       /* acc_t per chunk */
    cl_mem sum;        /* acc_t per region: the result of the last sum or mean */
} hv_cl_regions;

/* region: NULL (one region, all cells) or count labels in [0, nregion) and -1. */
hv_status hv_cl_regions_create(hv_cl *cl, hv_cl_regions *R, size_t count, const int32_t *region,
                               int nregion);
void hv_cl_regions_destroy(hv_cl_regions *R);
/* R->sum[r] = sum (mean: mean) of v over region r. */
void hv_cl_region_sums(hv_cl *cl, hv_cl_regions *R, cl_mem v, int mean);
/* v -= its region's mean; 0 outside every region. */
void hv_cl_project(hv_cl *cl, hv_cl_regions *R, cl_mem v);
void hv_cl_project_d(hv_cl *cl, hv_cl_regions *R, cl_mem v);

/* g[a] (axis-a faces, a < dim) = face gradient of u; solid may be NULL (uint8 per cell). */
void hv_cl_face_gradient(hv_cl *cl, int dim, const int n[3], double h, cl_mem solid, cl_mem u,
                         cl_mem const g[3]);
/* out = divergence of the face field F (F[2] unused in 2D). */
void hv_cl_face_divergence(hv_cl *cl, int dim, const int n[3], double h, cl_mem solid,
                           cl_mem const F[3], cl_mem out);
/* out[a] = axis-a component of the normalized mean of the cell vectors v at
 * axis-a faces (v[2] unused in 2D); 0 on walls, solid faces and where the
 * mean's largest component is <= eps. */
void hv_cl_face_normalize(hv_cl *cl, int dim, const int n[3], cl_mem solid, cl_mem const v[3],
                          cl_mem const out[3], double eps);
/* out = b > eps ? a / b : 0 */
void hv_cl_ratio(hv_cl *cl, size_t n, cl_mem a, cl_mem b, cl_mem out, double eps);
/* y += alpha x */
void hv_cl_axpy(hv_cl *cl, size_t n, double alpha, cl_mem x, cl_mem y);

/* Surface samples binned for the trilinear splat (kernels/heat.cl): sorted by
 * the base cell of their stencil, with fractional coordinates, clamped at the
 * block as hv_trilinear (src/heat/surface.c) does. Bin once, splat as many
 * value sets as needed. */
typedef struct hv_cl_splat {
    cl_int N[4];       /* nx, ny, nz (1 in 2D), dim */
    size_t count;      /* cells */
    size_t npts;
    uint32_t *order;   /* host: sorted position -> sample index */
    float *stage;      /* host: values on their way to the device */
    cl_mem base;       /* uint32 base cell per sorted sample */
    cl_mem start;      /* uint32, count + 1: samples of base cell b are [start[b], start[b+1]) */
    cl_mem frac;       /* float4 per sorted sample */
    cl_mem val;        /* float per sorted sample */
} hv_cl_splat;

/* Bins npts samples at world positions x (3 doubles each; the third is
 * ignored in 2D) on the grid of dim (2 or 3) with n cells, voxel size h and
 * the corner origin (cell centres at origin + (i + 1/2) h). */
hv_status hv_cl_splat_create(hv_cl *cl, hv_cl_splat *S, int dim, const int n[3], double h,
                             const double origin[3], size_t npts, const double *x);
void hv_cl_splat_destroy(hv_cl_splat *S);
/* out (count floats) = sum over samples p of w_p(c) * scale * val[p * stride],
 * w_p the trilinear (bilinear) weights: the splat of sdf.c as a gather, in
 * acc_t, independent of scheduling. val == NULL splats scale per sample. */
hv_status hv_cl_splat_run(hv_cl *cl, hv_cl_splat *S, const double *val, size_t stride, double scale,
                          cl_mem out);

/* out[q] (npts floats, sorted order) = trilinear interpolation of v at sorted
 * sample q, the transpose of the splat (interp in src/heat/sdf.c); S->order[q]
 * names the sample. */
void hv_cl_splat_sample(hv_cl *cl, hv_cl_splat *S, cl_mem v, cl_mem out);

/* phi -= shift; then, with local_shift, phi -= taper(den) num / den, the
 * zero-set correction of src/heat/sdf.c (den above 100 tau, full at 1000 tau). */
void hv_cl_sdf_shift(hv_cl *cl, size_t n, cl_mem phi, cl_mem num, cl_mem den, double shift,
                     double tau, int local_shift);

/* rhs = -div X / h of the signed heat method (build_rhs in src/heat/sdf.c)
 * on a 3D grid: X normalized at each face from the first of nlev levels of
 * ncomp (3: vectors, 1: a scalar whose gradient is taken) diffused fields in Y
 * (level l, component b at float offset (l * ncomp + b) * count) whose face
 * vector is longer than tau[l] (nlev acc_t on the device). Adds the faces
 * with no such level to dead[0] (uint32 on the device). */
void hv_cl_sdf_rhs(hv_cl *cl, const int n[3], double h, cl_mem Y, int nlev, int ncomp, cl_mem tau,
                   cl_mem rhs, cl_mem dead);

/* Solves A u = f with a solver of the opencl backend, f and u float device
 * buffers in cl's context (src/solve/opencl.c): the device keeps the fields,
 * the host reads only residual norms. The queue that wrote f must be finished;
 * on return u is complete. Other backends: HV_ERR_UNSUPPORTED. Semantics of
 * hv_solver_solve (Poisson right-hand sides projected, u zero on solid cells,
 * nonzero_guess honoured). Devices without fp64 go through the host. */
hv_status hv_cl_solver_solve(hv_solver *s, cl_mem f, cl_mem u, hv_solve_info *info);
/* The same with f and u double device buffers (hv_solver_solve_d's
 * precision): fp64 devices only, else HV_ERR_UNSUPPORTED. f is zeroed on
 * solid cells as the front end does (also for heat steps). */
hv_status hv_cl_solver_solve_d(hv_solver *s, cl_mem f, cl_mem u, hv_solve_info *info);

#endif
