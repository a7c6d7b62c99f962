/* Private: the solver on a DMDA (dmda.c) as the extension on a DMDA
 * (extend_dmda.c) uses it, in builds with HV_HAVE_PETSC. */
#ifndef HV_SOLVE_DMDA_H
#define HV_SOLVE_DMDA_H

#include "heatvox/petsc.h"

#ifdef HV_HAVE_PETSC
/* A DMDA with the layout of user's (sizes, ownership ranges) and one degree
 * of freedom, stencil width `width`, box (1) or star (0) stencil; *dim its
 * dimension. Refuses what the solvers do not handle (dof > 1, periodic). */
hv_status hv__dmda_like(DM user, int width, int box, DM *out, int *dim);

/* The solver's right-hand side vector: fill it, then hv__dmda_solve. */
Vec hv__dmda_rhs(hv_dmda_solver *s);

/* Solves for the right-hand side in hv__dmda_rhs(s) (overwritten: solid
 * rows and the null space taken out) into u. */
hv_status hv__dmda_solve(hv_dmda_solver *s, Vec u, hv_solve_info *info);
#endif

#endif
