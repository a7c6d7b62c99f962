/*
 * The solver's interface for the heat methods' device paths (src/sdf/,
 * src/distance/, src/extend/): solves whose right-hand side and solution stay
 * in device buffers of the solver's context (cl_device.c).
 */
#ifndef HV_SOLVE_SOLVE_CL_H
#define HV_SOLVE_SOLVE_CL_H

#include "cl/cl_core.h"
#include "heatvox/solve.h"

/* Solves A u = f with a solver of the opencl backend, f and u float device
 * buffers in cl's context (cl_device.c): the device keeps the fields,
 * the host reads only residual norms. The queue that wrote f must be finished;
 * on return u is complete. Other backends: HV_ERR_UNSUPPORTED. Semantics of
 * hv_solver_solve (Poisson right-hand sides projected, u zero on solid cells,
 * nonzero_guess honoured). Devices without fp64 go through the host. */
hv_status hv__cl_solver_solve(hv_solver *s, cl_mem f, cl_mem u, hv_solve_info *info);
/* The same with f and u double device buffers (hv_solver_solve_d's
 * precision): fp64 devices only, else HV_ERR_UNSUPPORTED. f is zeroed on
 * solid cells as the front end does (also for heat steps). */
hv_status hv__cl_solver_solve_d(hv_solver *s, cl_mem f, cl_mem u, hv_solve_info *info);

#endif
