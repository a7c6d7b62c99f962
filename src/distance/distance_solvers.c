/* The solvers of the heat-method distance's stages (distance_internal.h),
 * made the same way by the host path (distance_heat.c) and the device path
 * (distance_cl.c). */
#include "distance_internal.h"

hv_coarse hv__dist_poisson_coarse(const hv_distance_opts *o, const uint8_t *solid)
{
    return o->coarse == HV_COARSE_AUTO && solid ? HV_COARSE_AGGREGATION : o->coarse;
}

hv_status hv__dist_solver(hv_solver **s, int dim, const int n[3], double h, const uint8_t *solid,
                          double alpha, double beta, double tol, hv_backend backend,
                          hv_coarse coarse)
{
    hv_problem p = {dim, {n[0], n[1], n[2]}, h, solid, alpha, beta};
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.backend = backend;
    o.coarse = coarse;
    o.tol = tol;
    o.max_iter = 200;
    return hv_solver_create(s, &p, &o);
}
