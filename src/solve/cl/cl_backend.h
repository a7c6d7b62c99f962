/*
 * Private to the OpenCL backend: what the backend (cl_backend.c) gives the
 * device-resident entries (cl_device.c), which take the front end's solver
 * and reach the backend's state through it.
 */
#ifndef HV_SOLVE_CL_BACKEND_H
#define HV_SOLVE_CL_BACKEND_H

#include "cl/cl_core.h"
#include "solve/backend.h"

/* Whether float device fields solve on the device as they are (fp64 there);
 * else they go through the host front end. */
int hv__clsolve_takes_floats(const void *state);
/* The state's handle and setup. */
hv_cl *hv__clsolve_cl(const void *state);
const hv_setup *hv__clsolve_setup(const void *state);
/* hv__cl_solver_solve on the state once the entry's checks passed (float
 * fields; hv__clsolve_takes_floats), and hv__cl_solver_solve_d's (double
 * fields; HV_ERR_UNSUPPORTED without fp64). Both fill info's seconds and
 * backend. */
hv_status hv__clsolve_floats(void *state, cl_mem f, cl_mem u, hv_solve_info *info);
hv_status hv__clsolve_doubles(void *state, cl_mem f, cl_mem u, hv_solve_info *info);

#endif
