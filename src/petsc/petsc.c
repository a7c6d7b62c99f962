/* The petsc backend (backend.h): (alpha I - beta Lap) u = f distributed over
 * the MPI ranks of PETSC_COMM_WORLD with PETSc, in builds made with
 * HV_HAVE_PETSC (make mpi). Every rank calls the front end with the same
 * whole grid (the programs run SPMD): each rank owns a box of a DMDA (star
 * stencil, one ghost layer), assembles its rows and takes its part of the
 * right-hand side; conjugate gradients preconditioned by hypre's PFMG or
 * BoomerAMG (-hv_petsc_pc, dmda.h) solve on all ranks together, and every rank gets the whole
 * solution back. Neumann walls and solid cells are in the rows (a fluid
 * cell's diagonal counts its fluid neighbours; a solid cell's row is the
 * identity); for alpha = 0 the null space is one constant per connected fluid
 * region, also when a region spans ranks (the front end labels the regions
 * on the whole grid). Without PETSc the backend exists and its create fails
 * with HV_ERR_UNSUPPORTED. */
#include "heatvox/petsc.h"
#include "solve/backend.h"
#include "dmda.h"
#include "core/error.h"

#include <stdlib.h>
#include <string.h>

#ifdef HV_HAVE_PETSC
#include <petscdmda.h>
#include <petscksp.h>

#include <math.h>

typedef struct {
    const hv_setup *s;
    DM da;
    Mat A;
    KSP ksp;
    Vec b, x, all;     /* right-hand side, solution (distributed), whole solution per rank */
    Vec r;             /* the true residual, made on the first solve */
    VecScatter toall;  /* x (natural ordering) -> all */
    Vec natural;       /* x in the natural (i fastest) ordering */
    MatNullSpace null; /* alpha = 0 */
    Vec *basis;        /* the null space's vectors */
    int nbasis;
} petsc_state;

hv_status hv__petsc_fail(PetscErrorCode ierr, const char *what)
{
    const char *text = NULL;
    PetscErrorMessage(ierr, &text, NULL);
    return hv__error(HV_ERR_BACKEND, "petsc: %s failed (PETSc error %d: %s)", what, (int)ierr,
                     text ? text : "?");
}

static void petsc_destroy(void *state)
{
    petsc_state *P = state;
    if (!P)
        return;
    for (int i = 0; i < P->nbasis; i++)
        VecDestroy(&P->basis[i]);
    free(P->basis);
    MatNullSpaceDestroy(&P->null);
    VecScatterDestroy(&P->toall);
    VecDestroy(&P->all);
    VecDestroy(&P->natural);
    VecDestroy(&P->b);
    VecDestroy(&P->x);
    VecDestroy(&P->r);
    KSPDestroy(&P->ksp);
    MatDestroy(&P->A);
    DMDestroy(&P->da);
    free(P);
}

static int solid_at(const hv_setup *s, size_t c) { return s->p.solid && s->p.solid[c]; }

/* The rows this rank owns: fluid cells alpha + beta nf / h^2 on the diagonal
 * and -beta / h^2 to each fluid neighbour; solid cells the identity. */
static hv_status assemble(petsc_state *P)
{
    const hv_setup *s = P->s;
    const int dim = s->p.dim;
    const int *n = s->p.n;
    const double h2 = s->p.h * s->p.h, off = -s->p.beta / h2;
    PetscInt xs, ys, zs, xm, ym, zm;
    HV_PETSC_CHK(DMDAGetCorners(P->da, &xs, &ys, &zs, &xm, &ym, &zm), "DMDAGetCorners");
    if (dim == 2) {
        zs = 0;
        zm = 1;
    }
    for (PetscInt k = zs; k < zs + zm; k++)
        for (PetscInt j = ys; j < ys + ym; j++)
            for (PetscInt i = xs; i < xs + xm; i++) {
                const size_t c = (size_t)i + (size_t)n[0] * ((size_t)j + (size_t)n[1] * k);
                MatStencil row = {.k = k, .j = j, .i = i, .c = 0}, col[7];
                PetscScalar v[7];
                int m = 0;
                if (solid_at(s, c)) {
                    col[0] = row;
                    v[0] = 1;
                    HV_PETSC_CHK(MatSetValuesStencil(P->A, 1, &row, 1, col, v, INSERT_VALUES),
                                 "MatSetValuesStencil");
                    continue;
                }
                const PetscInt ijk[3] = {i, j, k};
                int nf = 0;
                for (int a = 0; a < dim; a++)
                    for (int d = -1; d <= 1; d += 2) {
                        PetscInt q[3] = {ijk[0], ijk[1], ijk[2]};
                        q[a] += d;
                        if (q[a] < 0 || q[a] >= n[a])
                            continue; /* a wall: no flux */
                        const size_t cn =
                            (size_t)q[0] + (size_t)n[0] * ((size_t)q[1] + (size_t)n[1] * q[2]);
                        if (solid_at(s, cn))
                            continue; /* a solid neighbour: a wall too */
                        nf++;
                        col[m].i = q[0];
                        col[m].j = q[1];
                        col[m].k = q[2];
                        col[m].c = 0;
                        v[m++] = off;
                    }
                col[m] = row;
                v[m++] = s->p.alpha + s->p.beta * nf / h2;
                HV_PETSC_CHK(MatSetValuesStencil(P->A, 1, &row, m, col, v, INSERT_VALUES),
                             "MatSetValuesStencil");
            }
    HV_PETSC_CHK(MatAssemblyBegin(P->A, MAT_FINAL_ASSEMBLY), "MatAssemblyBegin");
    HV_PETSC_CHK(MatAssemblyEnd(P->A, MAT_FINAL_ASSEMBLY), "MatAssemblyEnd");
    return HV_OK;
}

/* For alpha = 0: per fluid region, its indicator normalized, on this rank's rows. */
static hv_status null_space(petsc_state *P)
{
    const hv_setup *s = P->s;
    const int nr = s->nregion;
    if (!(P->basis = calloc((size_t)nr, sizeof *P->basis)))
        return hv__error(HV_ERR_NOMEM, "petsc: out of memory");
    size_t *cells = calloc((size_t)nr, sizeof *cells);
    if (!cells)
        return hv__error(HV_ERR_NOMEM, "petsc: out of memory");
    for (size_t c = 0; c < s->count; c++) {
        const int r = s->region ? s->region[c] : 0;
        if (r >= 0)
            cells[r]++;
    }
    PetscInt xs, ys, zs, xm, ym, zm;
    DMDAGetCorners(P->da, &xs, &ys, &zs, &xm, &ym, &zm);
    if (s->p.dim == 2) {
        zs = 0;
        zm = 1;
    }
    hv_status st = HV_OK;
    for (int r = 0; r < nr && !st; r++) {
        PetscErrorCode ierr = DMCreateGlobalVector(P->da, &P->basis[r]);
        if (ierr) {
            st = hv__petsc_fail(ierr, "DMCreateGlobalVector");
            break;
        }
        P->nbasis = r + 1;
        const PetscScalar val = 1 / sqrt((double)cells[r]);
        PetscScalar *a;
        VecGetArray(P->basis[r], &a);
        size_t q = 0;
        for (PetscInt k = zs; k < zs + zm; k++)
            for (PetscInt j = ys; j < ys + ym; j++)
                for (PetscInt i = xs; i < xs + xm; i++, q++) {
                    const size_t c =
                        (size_t)i + (size_t)s->p.n[0] * ((size_t)j + (size_t)s->p.n[1] * k);
                    const int rc = s->region ? s->region[c] : (solid_at(s, c) ? -1 : 0);
                    a[q] = rc == r ? val : 0;
                }
        VecRestoreArray(P->basis[r], &a);
    }
    free(cells);
    if (st)
        return st;
    HV_PETSC_CHK(MatNullSpaceCreate(PETSC_COMM_WORLD, PETSC_FALSE, nr, P->basis, &P->null),
                 "MatNullSpaceCreate");
    HV_PETSC_CHK(MatSetNullSpace(P->A, P->null), "MatSetNullSpace");
    return HV_OK;
}

static hv_status petsc_create_body(void **state, const hv_setup *s)
{
    hv_status ist = hv_petsc_init();
    if (ist)
        return ist;
    petsc_state *P = calloc(1, sizeof *P);
    if (!P)
        return hv__error(HV_ERR_NOMEM, "petsc: out of memory");
    P->s = s;
    *state = P;
    const int *n = s->p.n;
    PetscErrorCode ierr;
    if (s->p.dim == 3)
        ierr = DMDACreate3d(PETSC_COMM_WORLD, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE,
                            DMDA_STENCIL_STAR, n[0], n[1], n[2], PETSC_DECIDE, PETSC_DECIDE,
                            PETSC_DECIDE, 1, 1, NULL, NULL, NULL, &P->da);
    else
        ierr = DMDACreate2d(PETSC_COMM_WORLD, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE, DMDA_STENCIL_STAR,
                            n[0], n[1], PETSC_DECIDE, PETSC_DECIDE, 1, 1, NULL, NULL, &P->da);
    int pck = HV_PC_BOOMERAMG;
    hv_status st = HV_OK;
    if (!ierr && (st = hv__petsc_pc_kind(s->p.dim, s->p.alpha, s->nregion, &pck))) {
        petsc_destroy(P);
        *state = NULL;
        return st;
    }
    if (!ierr && pck == HV_PC_PFMG)
        ierr = DMSetMatType(P->da, MATHYPRESTRUCT);
    if (ierr || (ierr = DMSetUp(P->da)) || (ierr = DMCreateMatrix(P->da, &P->A)) ||
        (ierr = DMCreateGlobalVector(P->da, &P->b)) || (ierr = VecDuplicate(P->b, &P->x)) ||
        (ierr = DMDACreateNaturalVector(P->da, &P->natural)) ||
        (ierr = VecScatterCreateToAll(P->natural, &P->toall, &P->all)))
        st = hv__petsc_fail(ierr, "setting up the distributed grid");
    if (!st)
        st = assemble(P);
    if (!st && s->p.alpha == 0)
        st = null_space(P);
    if (!st) {
        if ((ierr = KSPCreate(PETSC_COMM_WORLD, &P->ksp)) ||
            (ierr = KSPSetOperators(P->ksp, P->A, P->A)) || (ierr = KSPSetType(P->ksp, KSPCG)) ||
            (ierr = KSPSetNormType(P->ksp, KSP_NORM_UNPRECONDITIONED)) ||
            (ierr = KSPSetTolerances(P->ksp, s->o.tol, 1e-300, PETSC_DEFAULT, s->o.max_iter)) ||
            (ierr = KSPSetResidualHistory(P->ksp, NULL, HV_MAX_HISTORY, PETSC_TRUE)))
            st = hv__petsc_fail(ierr, "setting up the Krylov solver");
    }
    if (!st) {
        PC pc;
        if ((ierr = KSPGetPC(P->ksp, &pc)))
            st = hv__petsc_fail(ierr, "KSPGetPC");
        if (!st)
            st = hv__petsc_pc_set(pc, pck);
        if (!st && ((ierr = KSPSetFromOptions(P->ksp)) || (ierr = KSPSetUp(P->ksp))))
            st = hv__petsc_fail(ierr, "setting up the preconditioner");
    }
    if (st) {
        petsc_destroy(P);
        *state = NULL;
    }
    return st;
}

/* The whole grid's values into this rank's part of a global vector. */
static void scatter_in(petsc_state *P, const double *f, Vec v)
{
    const hv_setup *s = P->s;
    PetscInt xs, ys, zs, xm, ym, zm;
    DMDAGetCorners(P->da, &xs, &ys, &zs, &xm, &ym, &zm);
    if (s->p.dim == 2) {
        zs = 0;
        zm = 1;
    }
    PetscScalar *a;
    VecGetArray(v, &a);
    size_t q = 0;
    for (PetscInt k = zs; k < zs + zm; k++)
        for (PetscInt j = ys; j < ys + ym; j++)
            for (PetscInt i = xs; i < xs + xm; i++, q++)
                a[q] = f[(size_t)i + (size_t)s->p.n[0] * ((size_t)j + (size_t)s->p.n[1] * k)];
    VecRestoreArray(v, &a);
}

static hv_status petsc_solve_body(void *state, const double *f, double *u, hv_solve_info *info)
{
    petsc_state *P = state;
    const hv_setup *s = P->s;
    scatter_in(P, f, P->b);
    if (s->o.nonzero_guess) {
        scatter_in(P, u, P->x);
        HV_PETSC_CHK(KSPSetInitialGuessNonzero(P->ksp, PETSC_TRUE), "KSPSetInitialGuessNonzero");
    } else {
        HV_PETSC_CHK(KSPSetInitialGuessNonzero(P->ksp, PETSC_FALSE), "KSPSetInitialGuessNonzero");
    }
    PetscReal bnorm;
    HV_PETSC_CHK(VecNorm(P->b, NORM_2, &bnorm), "VecNorm");
    info->iterations = 0;
    info->nhistory = 0;
    info->cycles = 0;
    if (bnorm == 0) {
        memset(u, 0, s->count * sizeof *u);
        info->reason = HV_STOP_CONVERGED;
        hv_info_push(info, 0);
        return HV_OK;
    }
    HV_PETSC_CHK(KSPSolve(P->ksp, P->b, P->x), "KSPSolve");
    PetscInt its, nh;
    const PetscReal *hist;
    KSPConvergedReason why;
    HV_PETSC_CHK(KSPGetIterationNumber(P->ksp, &its), "KSPGetIterationNumber");
    HV_PETSC_CHK(KSPGetResidualHistory(P->ksp, &hist, &nh), "KSPGetResidualHistory");
    HV_PETSC_CHK(KSPGetConvergedReason(P->ksp, &why), "KSPGetConvergedReason");
    for (PetscInt q = 0; q < nh; q++)
        hv_info_push(info, hist[q] / bnorm);
    /* The true residual, as the other backends report it. */
    PetscReal rnorm;
    if (!P->r)
        HV_PETSC_CHK(VecDuplicate(P->b, &P->r), "VecDuplicate");
    HV_PETSC_CHK(MatMult(P->A, P->x, P->r), "MatMult");
    HV_PETSC_CHK(VecAYPX(P->r, -1, P->b), "VecAYPX");
    HV_PETSC_CHK(VecNorm(P->r, NORM_2, &rnorm), "VecNorm");
    info->relres = rnorm / bnorm;
    info->iterations = (int)its;
    info->reason = why > 0                   ? HV_STOP_CONVERGED
                   : why == KSP_DIVERGED_ITS ? HV_STOP_MAX_ITER
                                             : HV_STOP_STAGNATED;
    /* The whole solution on every rank. */
    HV_PETSC_CHK(DMDAGlobalToNaturalBegin(P->da, P->x, INSERT_VALUES, P->natural),
                 "GlobalToNatural");
    HV_PETSC_CHK(DMDAGlobalToNaturalEnd(P->da, P->x, INSERT_VALUES, P->natural), "GlobalToNatural");
    HV_PETSC_CHK(VecScatterBegin(P->toall, P->natural, P->all, INSERT_VALUES, SCATTER_FORWARD),
                 "VecScatter");
    HV_PETSC_CHK(VecScatterEnd(P->toall, P->natural, P->all, INSERT_VALUES, SCATTER_FORWARD),
                 "VecScatter");
    const PetscScalar *a;
    HV_PETSC_CHK(VecGetArrayRead(P->all, &a), "VecGetArrayRead");
    for (size_t c = 0; c < s->count; c++)
        u[c] = solid_at(s, c) ? 0 : a[c];
    VecRestoreArrayRead(P->all, &a);
    if (s->p.alpha == 0)
        hv__project_mean(s, u);
    return HV_OK;
}

static hv_status petsc_create(void **state, const hv_setup *s)
{
    HV_PETSC_QUIETLY(petsc_create_body(state, s));
}

static hv_status petsc_solve(void *state, const double *f, double *u, hv_solve_info *info)
{
    HV_PETSC_QUIETLY(petsc_solve_body(state, f, u, info));
}

const hv_backend_ops hv__backend_petsc_ops = {"petsc",       petsc_create, petsc_solve, NULL,
                                              petsc_destroy, NULL,         NULL};

int hv_petsc_available(void) { return 1; }

hv_status hv_petsc_option(const char *name, const char *value)
{
    if (!name || name[0] != '-')
        return hv__error(HV_ERR_INVALID_ARG, "petsc: an option name starts with '-'");
    hv_status st = hv_petsc_init();
    if (st)
        return st;
    PetscPushErrorHandler(PetscReturnErrorHandler, NULL);
    PetscErrorCode ierr = PetscOptionsSetValue(NULL, name, value);
    PetscPopErrorHandler();
    return ierr ? hv__petsc_fail(ierr, "PetscOptionsSetValue") : HV_OK;
}

hv_status hv_petsc_init(void)
{
    PetscBool up = PETSC_FALSE;
    PetscInitialized(&up);
    if (!up) {
        /* hv_petsc_finalize ends it. */
        PetscErrorCode ierr = PetscInitializeNoArguments();
        if (ierr)
            return hv__petsc_fail(ierr, "PetscInitialize");
        /* The library never prints: PETSc's errors come back as codes, and
         * hv_last_error says what failed. */
        PetscPushErrorHandler(PetscReturnErrorHandler, NULL);
    }
    return HV_OK;
}

void hv_petsc_finalize(void)
{
    PetscBool up = PETSC_FALSE, done = PETSC_FALSE;
    PetscInitialized(&up);
    PetscFinalized(&done);
    if (up && !done)
        PetscFinalize();
}

int hv_mpi_rank(void)
{
    int up = 0, rank = 0;
    MPI_Initialized(&up);
    if (up)
        MPI_Comm_rank(MPI_COMM_WORLD, &rank);
    return rank;
}

int hv_mpi_size(void)
{
    int up = 0, size = 1;
    MPI_Initialized(&up);
    if (up)
        MPI_Comm_size(MPI_COMM_WORLD, &size);
    return size;
}

#else /* without PETSc */

static hv_status petsc_create(void **state, const hv_setup *s)
{
    (void)s;
    *state = NULL;
    return hv__error(HV_ERR_UNSUPPORTED,
                     "the petsc backend needs heatvox built with MPI and PETSc (make mpi)");
}

static hv_status petsc_solve(void *state, const double *f, double *u, hv_solve_info *info)
{
    (void)state;
    (void)f;
    (void)u;
    (void)info;
    return hv__error(HV_ERR_UNSUPPORTED, "the petsc backend is not in this build");
}

static void petsc_destroy(void *state) { (void)state; }

const hv_backend_ops hv__backend_petsc_ops = {"petsc",       petsc_create, petsc_solve, NULL,
                                              petsc_destroy, NULL,         NULL};

int hv_petsc_available(void) { return 0; }
hv_status hv_petsc_option(const char *name, const char *value)
{
    (void)name;
    (void)value;
    return hv__error(HV_ERR_UNSUPPORTED, "PETSc needs heatvox built with MPI and PETSc (make mpi)");
}
hv_status hv_petsc_init(void)
{
    return hv__error(HV_ERR_UNSUPPORTED, "PETSc needs heatvox built with MPI and PETSc (make mpi)");
}
void hv_petsc_finalize(void) {}
int hv_mpi_rank(void) { return 0; }
int hv_mpi_size(void) { return 1; }

#endif
