/* Private: the signed heat method's field stages on an OpenCL device, and the
 * device steps they are made of (sdf_cl.c, kernels/heat.cl). */
#ifndef HV_HEAT_SDF_CL_H
#define HV_HEAT_SDF_CL_H

#include "sdf_internal.h"
#include "cl/cl_core.h"

#include <stdint.h>

/* Stages 2-6 of hv_sdf_compute for backend opencl: splats the samples q into
 * the grid of g, diffuses nlev levels (t = S->t * 16^k), normalizes on faces
 * (the vector field, or for unsig the scalar's gradient), takes the divergence,
 * solves the Poisson step and shifts the zero set (globally, and locally when
 * o->local_shift and !unsig), all on the device; writes phi into g->v and the
 * fields of S those stages fill. */
hv_status hv__sdf_heat_cl(const hv_quad *q, hv_grid *g, int nlev, int unsig, const hv_sdf_opts *o,
                          hv_sdf_stats *S);

/* ---- device steps (kernels/heat.cl) ----------------------------------------
 * Enqueued on cl's queue, errors at hv__cl_check / hv__cl_finish, as the grid
 * operations of src/cl/cl_ops.h. Their kernels are built on first use
 * (hv__cl_module_open). */

/* Surface samples binned for the trilinear splat (kernels/heat.cl): sorted by
 * the base cell of their stencil, with fractional coordinates, clamped at the
 * block as hv__trilinear (src/geom/surface.c) does. Bin once, splat as many
 * value sets as needed. */
typedef struct hv_cl_splat {
    cl_int N[4];  /* nx, ny, nz (1 in 2D), dim */
    size_t count; /* cells */
    size_t npts;
    uint32_t *order; /* host: sorted position -> sample index */
    float *stage;    /* host: values on their way to the device */
    cl_mem base;     /* uint32 base cell per sorted sample */
    cl_mem start;    /* uint32, count + 1: samples of base cell b are [start[b], start[b+1]) */
    cl_mem frac;     /* float4 per sorted sample */
    cl_mem val;      /* float per sorted sample */
} hv_cl_splat;

/* Bins npts samples at world positions x (3 doubles each; the third is
 * ignored in 2D) on the grid of dim (2 or 3) with n cells, voxel size h and
 * the corner origin (cell centres at origin + (i + 1/2) h). */
hv_status hv__cl_splat_create(hv_cl *cl, hv_cl_splat *S, int dim, const int n[3], double h,
                              const double origin[3], size_t npts, const double *x);
void hv__cl_splat_destroy(hv_cl_splat *S);
/* out (count floats) = sum over samples p of w_p(c) * scale * val[p * stride],
 * w_p the trilinear (bilinear) weights: the splat of sdf.c as a gather, in
 * acc_t, independent of scheduling. val == NULL splats scale per sample. */
hv_status hv__cl_splat_run(hv_cl *cl, hv_cl_splat *S, const double *val, size_t stride,
                           double scale, cl_mem out);

/* out[q] (npts floats, sorted order) = trilinear interpolation of v at sorted
 * sample q, the transpose of the splat (interp in src/sdf/sdf.c); S->order[q]
 * names the sample. */
void hv__cl_splat_sample(hv_cl *cl, hv_cl_splat *S, cl_mem v, cl_mem out);

/* phi -= shift; then, with local_shift, phi -= taper(den) num / den, the
 * zero-set correction of src/sdf/sdf.c (den above 100 tau, full at 1000 tau). */
void hv__cl_sdf_shift(hv_cl *cl, size_t n, cl_mem phi, cl_mem num, cl_mem den, double shift,
                      double tau, int local_shift);

/* rhs = -div X / h of the signed heat method (build_rhs in src/sdf/sdf.c)
 * on a 3D grid: X normalized at each face from the first of nlev levels of
 * ncomp (3: vectors, 1: a scalar whose gradient is taken) diffused fields in Y
 * (level l, component b at float offset (l * ncomp + b) * count) whose face
 * vector is longer than tau[l] (nlev acc_t on the device). Adds the faces
 * with no such level to dead[0] (uint32 on the device). */
void hv__cl_sdf_rhs(hv_cl *cl, const int n[3], double h, cl_mem Y, int nlev, int ncomp, cl_mem tau,
                    cl_mem rhs, cl_mem dead);

#endif
