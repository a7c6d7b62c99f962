/* The solver's kernels as one module (cl_mg.h). */
#include "cl_mg.h"

#include <stddef.h>

/* kernels/, embedded by the Makefile */
extern const char hv__kernel_mg[], hv__kernel_agg[], hv__kernel_fine[];

static const char *const solve_sources[] = {hv__kernel_mg, hv__kernel_agg, hv__kernel_fine, NULL};

static const char *const solve_kernels[] = {"mg_apply",
                                            "mg_residual",
                                            "mg_rbgs",
                                            "mg_cheb",
                                            "mg_jacobi",
                                            "mg_jacobi0",
                                            "mg_restrict_residual",
                                            "mg_restrict",
                                            "hv__mg_restrict_transpose",
                                            "mg_prolong",
                                            "mg_prolong_w",
                                            "mg_prolong_x2",
                                            "hv__mg_bottom_cg",
                                            "agg_spmv",
                                            "agg_apply",
                                            "agg_residual",
                                            "agg_cheb",
                                            "agg_prolong",
                                            "agg_scale",
                                            "agg_restrict0",
                                            "agg_inject0",
                                            "agg_prolong0",
                                            "fine_residual",
                                            "fine_apply",
                                            "fine_add",
                                            "fine_f2d",
                                            "fine_pcg_update",
                                            "fine_xpay",
                                            "fine_d2f",
                                            "fine_mask",
                                            NULL};

const hv_cl_module hv__clsolve_module = {"solver", solve_sources, solve_kernels, 0,
                                         HV_K_FINE_RESIDUAL};
