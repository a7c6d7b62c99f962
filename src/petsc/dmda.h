/* Private: the solver on a DMDA (dmda.c) as the extension on a DMDA
 * (extend_dmda.c) uses it, in builds with HV_HAVE_PETSC. */
#ifndef HV_PETSC_DMDA_H
#define HV_PETSC_DMDA_H

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

/* A Poisson solver's (alpha = 0) region labels: a global vector of its
 * DMDA, -1 on solid cells, and on fluid cells a label shared by the cells of
 * one connected region and by no other (NULL for alpha != 0). */
Vec hv__dmda_labels(const hv_dmda_solver *s);

/* Solves for the right-hand side in hv__dmda_rhs(s) (overwritten: solid
 * rows and the null space taken out) into u. */
hv_status hv__dmda_solve(hv_dmda_solver *s, Vec u, hv_solve_info *info);

/* A whole block held by rank 0 and a DMDA of it over PETSC_COMM_WORLD (star
 * stencil, width 1, PETSc's partition): rank 0's arrays go to the ranks'
 * boxes and back through the natural (x-fastest) ordering. */
typedef struct hv_block_io {
    DM da;
    Vec nat, zero; /* the natural vector; its whole on rank 0 */
    VecScatter toz;
    size_t count; /* cells */
} hv_block_io;
hv_status hv__block_create(hv_block_io *B, int dim, const int n[3]);
/* g (a global vector of B->da) = rank 0's values a, or its mask m (0 / 1);
 * the other ranks pass NULL for both. Collective. */
hv_status hv__block_in(hv_block_io *B, const float *a, const uint8_t *m, Vec g);
/* Rank 0's out (the other ranks pass NULL) = g, rounded to floats. */
hv_status hv__block_out(hv_block_io *B, Vec g, float *out);
void hv__block_destroy(hv_block_io *B);
#endif

#endif
