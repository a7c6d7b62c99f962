/* Private: the solver on a DMDA (dmda.c) as the extension on a DMDA
 * (extend_dmda.c) uses it, in builds with HV_HAVE_PETSC. */
#ifndef HV_SOLVE_DMDA_H
#define HV_SOLVE_DMDA_H

#include "heatvox/petsc.h"

#ifdef HV_HAVE_PETSC
#include <petscksp.h>

/* A failed PETSc call as heatvox's error: HV_ERR_BACKEND naming the call and
 * PETSc's message. HV_PETSC_CHK returns it from the calling function. */
hv_status hv__petsc_fail(PetscErrorCode ierr, const char *what);
#define HV_PETSC_CHK(call, what)                                                                   \
    do {                                                                                           \
        PetscErrorCode ierr_ = (call);                                                             \
        if (ierr_)                                                                                 \
            return hv__petsc_fail(ierr_, what);                                                    \
    } while (0)

/* The body of a public entry point: PETSc started, its errors returned as
 * codes rather than printed while `call` runs (the library never prints). */
#define HV_PETSC_QUIETLY(call)                                                                     \
    do {                                                                                           \
        if (hv_petsc_init())                                                                       \
            return hv__error(HV_ERR_BACKEND, "petsc: PETSc could not start");                      \
        PetscPushErrorHandler(PetscReturnErrorHandler, NULL);                                      \
        const hv_status st_ = (call);                                                              \
        PetscPopErrorHandler();                                                                    \
        return st_;                                                                                \
    } while (0)

/* st, or an error when st failed on another rank of da's communicator
 * (collective: every rank calls it at the same point). */
hv_status hv__petsc_agree(DM da, hv_status st);

/* The preconditioner, from the PETSc option -hv_petsc_pc (petsc.h): auto
 * (the default: hypre's PFMG in 3D unless alpha = 0 and the fluid has
 * several regions, else BoomerAMG), BoomerAMG, PFMG (3D; the matrix must
 * then be MATHYPRESTRUCT) or PETSc's GAMG. */
enum { HV_PC_BOOMERAMG, HV_PC_PFMG, HV_PC_GAMG, HV_PC_JACOBI };
hv_status hv__petsc_pc_kind(int dim, double alpha, int regions, int *kind);
hv_status hv__petsc_pc_set(PC pc, int kind);

/* A DMDA with the layout of user's (sizes, ownership ranges) and one degree
 * of freedom, stencil width `width`, box (1) or star (0) stencil; *dim its
 * dimension. Refuses what the solvers do not handle (dof > 1, periodic). */
hv_status hv__dmda_like(DM user, int width, int box, DM *out, int *dim);

/* hv_dmda_solver_create with the preconditioner pc (HV_PC_*; -1: the
 * option's). HV_PC_JACOBI suits short heat steps, whose operator is
 * conditioned like 1 + 4 dim t / h^2: CG converges in a few dozen sweeps
 * with nothing to set up. */
hv_status hv__dmda_solver_create(hv_dmda_solver **out, DM da, double h, double alpha, double beta,
                                 Vec solid, const hv_solver_opts *opts, int pc);

/* The solver's right-hand side vector: fill it, then hv__dmda_solve. */
Vec hv__dmda_rhs(hv_dmda_solver *s);

/* Solves for the right-hand side in hv__dmda_rhs(s) (overwritten: solid
 * rows and the null space taken out) into u. */
hv_status hv__dmda_solve(hv_dmda_solver *s, Vec u, hv_solve_info *info);
#endif

#endif
