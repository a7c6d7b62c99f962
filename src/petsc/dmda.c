/* The solver on the caller's DMDA (petsc.h): (alpha I - beta Lap) u = f with
 * the caller's global vectors, in builds made with HV_HAVE_PETSC (make mpi).
 * The solver keeps its own DMDA with the caller's layout (same sizes and
 * ownership ranges, so its vectors and the caller's are interchangeable) and
 * a star stencil of width 1, assembles its rows once (as the petsc backend
 * does: Neumann walls, solid rows the identity), and for alpha = 0 labels the
 * connected fluid regions across the ranks: every fluid cell starts with its
 * own global index, and the smallest label spreads through the fluid cells of
 * each rank, then through the ghost layer to the neighbours, until no rank
 * changes a label. */
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

struct hv_dmda_solver {
    DM da;
    Mat A;
    KSP ksp;
    Vec b, r;
    Vec labels; /* alpha = 0: each cell's region label (-1 solid) */
    MatNullSpace null;
    Vec *basis;
    int nbasis, regions;
    uint8_t *solid; /* this rank's cells (NULL: none) */
    size_t nown;
    double tol;
    int max_iter, nonzero_guess;
};

hv_status hv__petsc_agree(DM da, hv_status st)
{
    int bad = st != HV_OK;
    MPI_Allreduce(MPI_IN_PLACE, &bad, 1, MPI_INT, MPI_MAX, PetscObjectComm((PetscObject)da));
    if (bad && !st)
        return hv__error(HV_ERR_BACKEND, "petsc: another rank failed (see its error)");
    return st;
}

hv_status hv__petsc_pc_kind(int dim, double alpha, int regions, int *kind)
{
    char name[32] = "auto";
    PetscBool set = PETSC_FALSE;
    HV_PETSC_CHK(PetscOptionsGetString(NULL, NULL, "-hv_petsc_pc", name, sizeof name, &set),
                 "PetscOptionsGetString");
    if (!strcmp(name, "auto"))
        /* The fastest where it works (docs/PERFORMANCE.md): PFMG in 3D, but
         * not on a Poisson problem with several regions. */
        *kind = dim == 3 && (alpha > 0 || regions <= 1) ? HV_PC_PFMG : HV_PC_BOOMERAMG;
    else if (!strcmp(name, "boomeramg"))
        *kind = HV_PC_BOOMERAMG;
    else if (!strcmp(name, "pfmg"))
        *kind = HV_PC_PFMG;
    else if (!strcmp(name, "gamg"))
        *kind = HV_PC_GAMG;
    else
        return hv__error(
            HV_ERR_INVALID_ARG,
            "petsc: -hv_petsc_pc %s: the preconditioners are auto, boomeramg, pfmg and "
            "gamg",
            name);
    if (*kind == HV_PC_PFMG && dim != 3)
        return hv__error(HV_ERR_INVALID_ARG,
                         "petsc: -hv_petsc_pc pfmg: hypre's structured matrices need a 3D grid");
    return HV_OK;
}

hv_status hv__petsc_pc_set(PC pc, int kind)
{
    if (kind == HV_PC_JACOBI) {
        HV_PETSC_CHK(PCSetType(pc, PCJACOBI), "PCSetType (jacobi)");
        return HV_OK;
    }
    if (kind == HV_PC_GAMG) {
        HV_PETSC_CHK(PCSetType(pc, PCGAMG), "PCSetType (gamg)");
        return HV_OK;
    }
    if (kind == HV_PC_PFMG) {
        HV_PETSC_CHK(PCSetType(pc, PCPFMG), "PCSetType (pfmg)");
        return HV_OK;
    }
    HV_PETSC_CHK(PCSetType(pc, PCHYPRE), "PCSetType (hypre)");
    HV_PETSC_CHK(PCHYPRESetType(pc, "boomeramg"), "PCHYPRESetType");
    return HV_OK;
}

hv_status hv__dmda_like(DM user, int width, int box, DM *out, int *dim)
{
    PetscInt d, M, N, P, m, n, p, dof, sw;
    DMBoundaryType bx, by, bz;
    DMDAStencilType stype;
    const PetscInt *lx, *ly, *lz;
    *out = NULL;
    if (!user)
        return hv__error(HV_ERR_INVALID_ARG, "dmda: no DMDA");
    HV_PETSC_CHK(DMDAGetInfo(user, &d, &M, &N, &P, &m, &n, &p, &dof, &sw, &bx, &by, &bz, &stype),
                 "DMDAGetInfo (is it a DMDA?)");
    if (d != 2 && d != 3)
        return hv__error(HV_ERR_INVALID_ARG, "dmda: a %dD DMDA; 2D or 3D only", (int)d);
    if (dof != 1)
        return hv__error(HV_ERR_INVALID_ARG, "dmda: %d degrees of freedom per cell; one only",
                         (int)dof);
    if (bx != DM_BOUNDARY_NONE || by != DM_BOUNDARY_NONE || (d == 3 && bz != DM_BOUNDARY_NONE))
        return hv__error(HV_ERR_INVALID_ARG,
                         "dmda: periodic or ghosted boundaries; the grid's faces are walls");
    HV_PETSC_CHK(DMDAGetOwnershipRanges(user, &lx, &ly, &lz), "DMDAGetOwnershipRanges");
    MPI_Comm comm = PetscObjectComm((PetscObject)user);
    const DMDAStencilType st = box ? DMDA_STENCIL_BOX : DMDA_STENCIL_STAR;
    PetscErrorCode ierr;
    if (d == 3)
        ierr = DMDACreate3d(comm, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE, st, M, N, P,
                            m, n, p, 1, width, lx, ly, lz, out);
    else
        ierr = DMDACreate2d(comm, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE, st, M, N, m, n, 1, width, lx,
                            ly, out);
    if (!ierr)
        ierr = DMSetUp(*out);
    if (ierr) {
        DMDestroy(out);
        return hv__petsc_fail(ierr, "creating a DMDA on the caller's layout");
    }
    *dim = (int)d;
    return HV_OK;
}

/* The rows this rank owns. sl: the solid flags with one ghost layer (NULL:
 * none), laid out as the DMDA's ghosted box. */
static hv_status assemble(hv_dmda_solver *s, int dim, double h, double alpha, double beta,
                          const PetscScalar *sl)
{
    PetscInt M, N, P, xs, ys, zs, xm, ym, zm, gxs, gys, gzs, gxm, gym, gzm;
    HV_PETSC_CHK(
        DMDAGetInfo(s->da, NULL, &M, &N, &P, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL),
        "DMDAGetInfo");
    DMDAGetCorners(s->da, &xs, &ys, &zs, &xm, &ym, &zm);
    DMDAGetGhostCorners(s->da, &gxs, &gys, &gzs, &gxm, &gym, &gzm);
    if (dim == 2) {
        zs = gzs = 0;
        zm = gzm = P = 1;
    }
    const PetscInt n[3] = {M, N, P};
#define GSOLID(i, j, k) (sl && sl[((k)-gzs) * gym * gxm + ((j)-gys) * gxm + ((i)-gxs)] != 0)
    const double off = -beta / (h * h);
    for (PetscInt k = zs; k < zs + zm; k++)
        for (PetscInt j = ys; j < ys + ym; j++)
            for (PetscInt i = xs; i < xs + xm; i++) {
                MatStencil row = {.k = k, .j = j, .i = i, .c = 0}, col[7];
                PetscScalar v[7];
                int m = 0;
                if (GSOLID(i, j, k)) {
                    col[0] = row;
                    v[0] = 1;
                    HV_PETSC_CHK(MatSetValuesStencil(s->A, 1, &row, 1, col, v, INSERT_VALUES),
                                 "MatSetValuesStencil");
                    continue;
                }
                int nf = 0;
                for (int a = 0; a < dim; a++)
                    for (int d = -1; d <= 1; d += 2) {
                        PetscInt q[3] = {i, j, k};
                        q[a] += d;
                        if (q[a] < 0 || q[a] >= n[a] || GSOLID(q[0], q[1], q[2]))
                            continue; /* a wall: no flux */
                        nf++;
                        col[m] = (MatStencil){.k = q[2], .j = q[1], .i = q[0], .c = 0};
                        v[m++] = off;
                    }
                col[m] = row;
                v[m++] = alpha + beta * nf / (h * h);
                HV_PETSC_CHK(MatSetValuesStencil(s->A, 1, &row, m, col, v, INSERT_VALUES),
                             "MatSetValuesStencil");
            }
#undef GSOLID
    HV_PETSC_CHK(MatAssemblyBegin(s->A, MAT_FINAL_ASSEMBLY), "MatAssemblyBegin");
    HV_PETSC_CHK(MatAssemblyEnd(s->A, MAT_FINAL_ASSEMBLY), "MatAssemblyEnd");
    return HV_OK;
}

static int cmp_label(const void *a, const void *b)
{
    const double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* The fluid regions across the ranks and one null-space vector per region. */
static hv_status regions(hv_dmda_solver *s, int dim)
{
    PetscInt M, N, xs, ys, zs, xm, ym, zm, gxs, gys, gzs, gxm, gym, gzm;
    HV_PETSC_CHK(DMDAGetInfo(s->da, NULL, &M, &N, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL,
                             NULL, NULL),
                 "DMDAGetInfo");
    DMDAGetCorners(s->da, &xs, &ys, &zs, &xm, &ym, &zm);
    DMDAGetGhostCorners(s->da, &gxs, &gys, &gzs, &gxm, &gym, &gzm);
    if (dim == 2) {
        zs = gzs = 0;
        zm = gzm = 1;
    }
    MPI_Comm comm = PetscObjectComm((PetscObject)s->da);
    Vec lab, loc;
    HV_PETSC_CHK(DMCreateGlobalVector(s->da, &lab), "DMCreateGlobalVector");
    HV_PETSC_CHK(DMCreateLocalVector(s->da, &loc), "DMCreateLocalVector");
    PetscScalar *a;
    VecGetArray(lab, &a);
    size_t q = 0;
    for (PetscInt k = zs; k < zs + zm; k++)
        for (PetscInt j = ys; j < ys + ym; j++)
            for (PetscInt i = xs; i < xs + xm; i++, q++)
                a[q] = s->solid && s->solid[q] ? -1 : (double)(i + M * (j + N * k));
    VecRestoreArray(lab, &a);
    /* Spread the smallest label: sweeps over this rank's cells reading the
     * ghost layer, then an exchange, until nothing changes anywhere. */
    const PetscInt sx = 1, sy = gxm, sz = gxm * gym;
    for (;;) {
        DMGlobalToLocalBegin(s->da, lab, INSERT_VALUES, loc);
        DMGlobalToLocalEnd(s->da, lab, INSERT_VALUES, loc);
        PetscScalar *L;
        VecGetArray(loc, &L);
        int changed = 0, again = 1;
        for (int sweep = 0; again; sweep++) {
            again = 0;
            for (PetscInt kk = 0; kk < zm; kk++)
                for (PetscInt jj = 0; jj < ym; jj++)
                    for (PetscInt ii = 0; ii < xm; ii++) {
                        /* alternate directions so that a label crosses the box in one pass */
                        const PetscInt k = sweep & 1 ? zs + zm - 1 - kk : zs + kk;
                        const PetscInt j = sweep & 1 ? ys + ym - 1 - jj : ys + jj;
                        const PetscInt i = sweep & 1 ? xs + xm - 1 - ii : xs + ii;
                        const PetscInt c = (k - gzs) * sz + (j - gys) * sy + (i - gxs) * sx;
                        if (L[c] < 0)
                            continue;
                        double m = L[c];
                        const PetscInt p[3] = {i, j, k}, lo[3] = {gxs, gys, gzs},
                                       hi[3] = {gxs + gxm, gys + gym, gzs + gzm},
                                       st[3] = {sx, sy, sz};
                        for (int ax = 0; ax < dim; ax++) {
                            if (p[ax] - 1 >= lo[ax] && L[c - st[ax]] >= 0 && L[c - st[ax]] < m)
                                m = L[c - st[ax]];
                            if (p[ax] + 1 < hi[ax] && L[c + st[ax]] >= 0 && L[c + st[ax]] < m)
                                m = L[c + st[ax]];
                        }
                        if (m < L[c]) {
                            L[c] = m;
                            again = changed = 1;
                        }
                    }
        }
        VecRestoreArray(loc, &L);
        DMLocalToGlobalBegin(s->da, loc, INSERT_VALUES, lab);
        DMLocalToGlobalEnd(s->da, loc, INSERT_VALUES, lab);
        int any = 0;
        MPI_Allreduce(&changed, &any, 1, MPI_INT, MPI_MAX, comm);
        if (!any)
            break;
    }
    VecDestroy(&loc);
    /* The labels in use, over all ranks. */
    const PetscScalar *ca;
    VecGetArrayRead(lab, &ca);
    double *mine = malloc((s->nown + 1) * sizeof *mine);
    int nm = 0;
    hv_status st = HV_OK;
    if (!mine)
        st = hv__error(HV_ERR_NOMEM, "petsc: out of memory");
    for (size_t c = 0; !st && c < s->nown; c++)
        if (ca[c] >= 0)
            mine[nm++] = ca[c];
    if (!st) {
        qsort(mine, (size_t)nm, sizeof *mine, cmp_label);
        int u = 0;
        for (int i = 0; i < nm; i++)
            if (!u || mine[i] != mine[u - 1])
                mine[u++] = mine[i];
        nm = u;
    }
    int size = 1, total = 0;
    MPI_Comm_size(comm, &size);
    int *counts = calloc((size_t)size, sizeof *counts),
        *displ = calloc((size_t)size, sizeof *displ);
    double *all = NULL;
    (void)MPI_Allgather(&nm, 1, MPI_INT, counts, 1, MPI_INT, comm);
    for (int r = 0; counts && displ && r < size; r++) {
        displ[r] = total;
        total += counts[r];
    }
    if (!st && (!counts || !displ || !(all = malloc(((size_t)total + 1) * sizeof *all))))
        st = hv__error(HV_ERR_NOMEM, "petsc: out of memory");
    int bad = st != HV_OK, anybad = 0;
    MPI_Allreduce(&bad, &anybad, 1, MPI_INT, MPI_MAX, comm);
    if (!anybad) {
        (void)MPI_Allgatherv(mine, nm, MPI_DOUBLE, all, counts, displ, MPI_DOUBLE, comm);
        qsort(all, (size_t)total, sizeof *all, cmp_label);
        int u = 0;
        for (int i = 0; i < total; i++)
            if (!u || all[i] != all[u - 1])
                all[u++] = all[i];
        s->regions = u;
    } else if (!st) {
        st = hv__error(HV_ERR_NOMEM, "petsc: out of memory on another rank");
    }
    free(mine);
    free(counts);
    free(displ);
    /* One vector per region: its indicator, normalized. */
    if (!st && s->regions > 0 && !(s->basis = calloc((size_t)s->regions, sizeof *s->basis)))
        st = hv__error(HV_ERR_NOMEM, "petsc: out of memory");
    for (int r = 0; !st && r < s->regions; r++) {
        PetscErrorCode ierr = DMCreateGlobalVector(s->da, &s->basis[r]);
        if (ierr) {
            st = hv__petsc_fail(ierr, "DMCreateGlobalVector");
            break;
        }
        s->nbasis = r + 1;
        PetscScalar *b;
        VecGetArray(s->basis[r], &b);
        for (size_t c = 0; c < s->nown; c++)
            b[c] = ca[c] == all[r] ? 1 : 0;
        VecRestoreArray(s->basis[r], &b);
        VecNormalize(s->basis[r], NULL);
    }
    free(all);
    VecRestoreArrayRead(lab, &ca);
    s->labels = lab;
    if (st)
        return st;
    if (s->regions == 0)
        return HV_OK; /* all solid: the identity */
    HV_PETSC_CHK(MatNullSpaceCreate(comm, PETSC_FALSE, s->regions, s->basis, &s->null),
                 "MatNullSpaceCreate");
    return HV_OK;
}

static hv_status create(hv_dmda_solver *s, DM user, double h, double alpha, double beta, Vec solid,
                        const hv_solver_opts *o, int pck)
{
    int dim = 3;
    hv_status st = hv__dmda_like(user, 1, 0, &s->da, &dim);
    if (st)
        return st;
    s->tol = o->tol;
    s->max_iter = o->max_iter;
    s->nonzero_guess = o->nonzero_guess;
    HV_PETSC_CHK(DMCreateGlobalVector(s->da, &s->b), "DMCreateGlobalVector");
    HV_PETSC_CHK(VecDuplicate(s->b, &s->r), "VecDuplicate");
    PetscInt nown;
    HV_PETSC_CHK(VecGetLocalSize(s->b, &nown), "VecGetLocalSize");
    s->nown = (size_t)nown;
    Vec sl = NULL;
    const PetscScalar *sla = NULL;
    if (solid) {
        /* What one rank alone can fail at, agreed before the collective
         * calls below. */
        PetscInt ns = -1;
        VecGetLocalSize(solid, &ns);
        if (ns != nown)
            st = hv__error(HV_ERR_INVALID_ARG,
                           "dmda: the solid vector is not a global vector of the DMDA (%d cells "
                           "on this rank, not %d)",
                           (int)ns, (int)nown);
        else if (!(s->solid = malloc(s->nown ? s->nown : 1)))
            st = hv__error(HV_ERR_NOMEM, "petsc: out of memory");
        if ((st = hv__petsc_agree(s->da, st)))
            return st;
        const PetscScalar *a;
        HV_PETSC_CHK(VecGetArrayRead(solid, &a), "VecGetArrayRead");
        for (size_t c = 0; c < s->nown; c++)
            s->solid[c] = a[c] != 0;
        VecRestoreArrayRead(solid, &a);
    }
    /* The regions first: the preconditioner depends on how many there are. */
    if (alpha == 0 && (st = regions(s, dim)))
        return st;
    if (pck < 0 && (st = hv__petsc_pc_kind(dim, alpha, s->regions, &pck)))
        return st;
    if (pck == HV_PC_PFMG)
        HV_PETSC_CHK(DMSetMatType(s->da, MATHYPRESTRUCT), "DMSetMatType (hypre struct)");
    HV_PETSC_CHK(DMCreateMatrix(s->da, &s->A), "DMCreateMatrix");
    if (solid) {
        /* Its ghost layer, for the neighbours' walls. */
        HV_PETSC_CHK(DMCreateLocalVector(s->da, &sl), "DMCreateLocalVector");
        HV_PETSC_CHK(VecCopy(solid, s->r), "VecCopy");
        HV_PETSC_CHK(DMGlobalToLocalBegin(s->da, s->r, INSERT_VALUES, sl), "DMGlobalToLocal");
        HV_PETSC_CHK(DMGlobalToLocalEnd(s->da, s->r, INSERT_VALUES, sl), "DMGlobalToLocal");
        HV_PETSC_CHK(VecGetArrayRead(sl, &sla), "VecGetArrayRead");
    }
    st = assemble(s, dim, h, alpha, beta, sla);
    if (sl) {
        VecRestoreArrayRead(sl, &sla);
        VecDestroy(&sl);
    }
    if (st)
        return st;
    if (s->null) {
        HV_PETSC_CHK(MatSetNullSpace(s->A, s->null), "MatSetNullSpace");
        HV_PETSC_CHK(MatSetTransposeNullSpace(s->A, s->null), "MatSetTransposeNullSpace");
    }
    MPI_Comm comm = PetscObjectComm((PetscObject)s->da);
    PC pc;
    HV_PETSC_CHK(KSPCreate(comm, &s->ksp), "KSPCreate");
    HV_PETSC_CHK(KSPSetOperators(s->ksp, s->A, s->A), "KSPSetOperators");
    HV_PETSC_CHK(KSPSetType(s->ksp, KSPCG), "KSPSetType");
    HV_PETSC_CHK(KSPSetNormType(s->ksp, KSP_NORM_UNPRECONDITIONED), "KSPSetNormType");
    HV_PETSC_CHK(KSPSetTolerances(s->ksp, s->tol, 1e-300, PETSC_DEFAULT, s->max_iter),
                 "KSPSetTolerances");
    HV_PETSC_CHK(KSPSetResidualHistory(s->ksp, NULL, HV_MAX_HISTORY, PETSC_TRUE),
                 "KSPSetResidualHistory");
    HV_PETSC_CHK(KSPGetPC(s->ksp, &pc), "KSPGetPC");
    if ((st = hv__petsc_pc_set(pc, pck)))
        return st;
    HV_PETSC_CHK(KSPSetFromOptions(s->ksp), "KSPSetFromOptions");
    HV_PETSC_CHK(KSPSetUp(s->ksp), "KSPSetUp (hypre BoomerAMG)");
    return HV_OK;
}

hv_status hv_dmda_solver_create(hv_dmda_solver **out, DM da, double h, double alpha, double beta,
                                Vec solid, const hv_solver_opts *opts)
{
    return hv__dmda_solver_create(out, da, h, alpha, beta, solid, opts, -1);
}

static hv_status hv__dmda_solver_create_body(hv_dmda_solver **out, DM da, double h, double alpha,
                                             double beta, Vec solid, const hv_solver_opts *opts,
                                             int pc)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_dmda_solver_create: out is NULL");
    *out = NULL;
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    if (opts)
        o = *opts;
    if (!(h > 0) || !(alpha >= 0) || !(beta > 0) || !isfinite(alpha) || !isfinite(beta))
        return hv__error(HV_ERR_INVALID_ARG,
                         "hv_dmda_solver_create: need h > 0, alpha >= 0 and beta > 0 (got %g, "
                         "%g, %g)",
                         h, alpha, beta);
    if (!(o.tol >= 1e-14 && o.tol < 1) || o.max_iter < 1)
        return hv__error(HV_ERR_INVALID_ARG,
                         "hv_dmda_solver_create: tol must lie in [1e-14, 1), max_iter >= 1");
    hv_status st = hv_petsc_init();
    if (st)
        return st;
    hv_dmda_solver *s = calloc(1, sizeof *s);
    if (!s)
        return hv__error(HV_ERR_NOMEM, "petsc: out of memory");
    if ((st = create(s, da, h, alpha, beta, solid, &o, pc))) {
        hv_dmda_solver_destroy(&s);
        return st;
    }
    *out = s;
    return HV_OK;
}

hv_status hv__dmda_solve(hv_dmda_solver *s, Vec u, hv_solve_info *info)
{
    double t0 = hv_now();
    memset(info, 0, sizeof *info);
    info->backend = HV_BACKEND_PETSC;
    if (s->solid) {
        PetscScalar *a;
        VecGetArray(s->b, &a);
        for (size_t c = 0; c < s->nown; c++)
            if (s->solid[c])
                a[c] = 0;
        VecRestoreArray(s->b, &a);
    }
    if (s->null)
        HV_PETSC_CHK(MatNullSpaceRemove(s->null, s->b), "MatNullSpaceRemove");
    PetscReal bnorm;
    HV_PETSC_CHK(VecNorm(s->b, NORM_2, &bnorm), "VecNorm");
    if (bnorm == 0) {
        HV_PETSC_CHK(VecSet(u, 0), "VecSet");
        info->reason = HV_STOP_CONVERGED;
        hv_info_push(info, 0);
        info->seconds = hv_now() - t0;
        return HV_OK;
    }
    HV_PETSC_CHK(KSPSetInitialGuessNonzero(s->ksp, s->nonzero_guess ? PETSC_TRUE : PETSC_FALSE),
                 "KSPSetInitialGuessNonzero");
    HV_PETSC_CHK(KSPSolve(s->ksp, s->b, u), "KSPSolve");
    PetscInt its, nh;
    const PetscReal *hist;
    KSPConvergedReason why;
    HV_PETSC_CHK(KSPGetIterationNumber(s->ksp, &its), "KSPGetIterationNumber");
    HV_PETSC_CHK(KSPGetResidualHistory(s->ksp, &hist, &nh), "KSPGetResidualHistory");
    HV_PETSC_CHK(KSPGetConvergedReason(s->ksp, &why), "KSPGetConvergedReason");
    for (PetscInt q = 0; q < nh; q++)
        hv_info_push(info, hist[q] / bnorm);
    if (s->null)
        HV_PETSC_CHK(MatNullSpaceRemove(s->null, u), "MatNullSpaceRemove");
    /* The true residual, as the other backends report it. */
    PetscReal rnorm;
    HV_PETSC_CHK(MatMult(s->A, u, s->r), "MatMult");
    HV_PETSC_CHK(VecAYPX(s->r, -1, s->b), "VecAYPX");
    HV_PETSC_CHK(VecNorm(s->r, NORM_2, &rnorm), "VecNorm");
    info->relres = rnorm / bnorm;
    info->iterations = (int)its;
    info->reason = why > 0                   ? HV_STOP_CONVERGED
                   : why == KSP_DIVERGED_ITS ? HV_STOP_MAX_ITER
                                             : HV_STOP_STAGNATED;
    info->seconds = hv_now() - t0;
    return HV_OK;
}

Vec hv__dmda_rhs(hv_dmda_solver *s) { return s->b; }

Vec hv__dmda_labels(const hv_dmda_solver *s) { return s->labels; }

static hv_status hv_dmda_solver_solve_body(hv_dmda_solver *s, Vec f, Vec u, hv_solve_info *info)
{
    if (!s || !f || !u)
        return hv__error(HV_ERR_INVALID_ARG, "hv_dmda_solver_solve: bad arguments");
    PetscInt nf, nu;
    HV_PETSC_CHK(VecGetLocalSize(f, &nf), "VecGetLocalSize");
    HV_PETSC_CHK(VecGetLocalSize(u, &nu), "VecGetLocalSize");
    if ((size_t)nf != s->nown || (size_t)nu != s->nown)
        return hv__error(HV_ERR_INVALID_ARG,
                         "hv_dmda_solver_solve: f and u must be global vectors of the DMDA");
    hv_solve_info local;
    HV_PETSC_CHK(VecCopy(f, s->b), "VecCopy");
    return hv__dmda_solve(s, u, info ? info : &local);
}

int hv_dmda_solver_regions(const hv_dmda_solver *s) { return s ? s->regions : 0; }

void hv_dmda_solver_destroy(hv_dmda_solver **sp)
{
    if (!sp || !*sp)
        return;
    hv_dmda_solver *s = *sp;
    for (int i = 0; i < s->nbasis; i++)
        VecDestroy(&s->basis[i]);
    free(s->basis);
    MatNullSpaceDestroy(&s->null);
    VecDestroy(&s->b);
    VecDestroy(&s->r);
    VecDestroy(&s->labels);
    KSPDestroy(&s->ksp);
    MatDestroy(&s->A);
    DMDestroy(&s->da);
    free(s->solid);
    free(s);
    *sp = NULL;
}

hv_status hv__dmda_solver_create(hv_dmda_solver **out, DM da, double h, double alpha, double beta,
                                 Vec solid, const hv_solver_opts *opts, int pc)
{
    HV_PETSC_QUIETLY(hv__dmda_solver_create_body(out, da, h, alpha, beta, solid, opts, pc));
}

hv_status hv_dmda_solver_solve(hv_dmda_solver *s, Vec f, Vec u, hv_solve_info *info)
{
    HV_PETSC_QUIETLY(hv_dmda_solver_solve_body(s, f, u, info));
}

/* ---- a block held by rank 0 ---------------------------------------------- */

hv_status hv__block_create(hv_block_io *B, int dim, const int n[3])
{
    memset(B, 0, sizeof *B);
    B->count = (size_t)n[0] * n[1] * (dim == 3 ? n[2] : 1);
    PetscErrorCode ierr;
    if (dim == 3)
        ierr = DMDACreate3d(PETSC_COMM_WORLD, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE,
                            DMDA_STENCIL_STAR, n[0], n[1], n[2], PETSC_DECIDE, PETSC_DECIDE,
                            PETSC_DECIDE, 1, 1, NULL, NULL, NULL, &B->da);
    else
        ierr = DMDACreate2d(PETSC_COMM_WORLD, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE, DMDA_STENCIL_STAR,
                            n[0], n[1], PETSC_DECIDE, PETSC_DECIDE, 1, 1, NULL, NULL, &B->da);
    if (ierr || (ierr = DMSetUp(B->da)) || (ierr = DMDACreateNaturalVector(B->da, &B->nat)) ||
        (ierr = VecScatterCreateToZero(B->nat, &B->toz, &B->zero)))
        return hv__petsc_fail(ierr, "setting up the distributed block");
    return HV_OK;
}

hv_status hv__block_in(hv_block_io *B, const float *a, const uint8_t *m, Vec g)
{
    if (a || m) { /* rank 0 */
        PetscScalar *z;
        HV_PETSC_CHK(VecGetArray(B->zero, &z), "VecGetArray");
        for (size_t c = 0; c < B->count; c++)
            z[c] = a ? a[c] : m[c] != 0;
        VecRestoreArray(B->zero, &z);
    }
    HV_PETSC_CHK(VecScatterBegin(B->toz, B->zero, B->nat, INSERT_VALUES, SCATTER_REVERSE),
                 "VecScatter");
    HV_PETSC_CHK(VecScatterEnd(B->toz, B->zero, B->nat, INSERT_VALUES, SCATTER_REVERSE),
                 "VecScatter");
    HV_PETSC_CHK(DMDANaturalToGlobalBegin(B->da, B->nat, INSERT_VALUES, g), "NaturalToGlobal");
    HV_PETSC_CHK(DMDANaturalToGlobalEnd(B->da, B->nat, INSERT_VALUES, g), "NaturalToGlobal");
    return HV_OK;
}

hv_status hv__block_out(hv_block_io *B, Vec g, float *out)
{
    HV_PETSC_CHK(DMDAGlobalToNaturalBegin(B->da, g, INSERT_VALUES, B->nat), "GlobalToNatural");
    HV_PETSC_CHK(DMDAGlobalToNaturalEnd(B->da, g, INSERT_VALUES, B->nat), "GlobalToNatural");
    HV_PETSC_CHK(VecScatterBegin(B->toz, B->nat, B->zero, INSERT_VALUES, SCATTER_FORWARD),
                 "VecScatter");
    HV_PETSC_CHK(VecScatterEnd(B->toz, B->nat, B->zero, INSERT_VALUES, SCATTER_FORWARD),
                 "VecScatter");
    if (out) {
        const PetscScalar *z;
        HV_PETSC_CHK(VecGetArrayRead(B->zero, &z), "VecGetArrayRead");
        for (size_t c = 0; c < B->count; c++)
            out[c] = (float)z[c];
        VecRestoreArrayRead(B->zero, &z);
    }
    return HV_OK;
}

void hv__block_destroy(hv_block_io *B)
{
    VecScatterDestroy(&B->toz);
    VecDestroy(&B->zero);
    VecDestroy(&B->nat);
    DMDestroy(&B->da);
}

#else /* without PETSc */

hv_status hv_dmda_solver_create(hv_dmda_solver **out, DM da, double h, double alpha, double beta,
                                Vec solid, const hv_solver_opts *opts)
{
    (void)da;
    (void)h;
    (void)alpha;
    (void)beta;
    (void)solid;
    (void)opts;
    if (out)
        *out = NULL;
    return hv__error(HV_ERR_UNSUPPORTED,
                     "solvers on a DMDA need heatvox built with MPI and PETSc (make mpi)");
}

hv_status hv_dmda_solver_solve(hv_dmda_solver *s, Vec f, Vec u, hv_solve_info *info)
{
    (void)s;
    (void)f;
    (void)u;
    (void)info;
    return hv__error(HV_ERR_UNSUPPORTED, "solvers on a DMDA are not in this build");
}

int hv_dmda_solver_regions(const hv_dmda_solver *s)
{
    (void)s;
    return 0;
}

void hv_dmda_solver_destroy(hv_dmda_solver **s)
{
    if (s)
        *s = NULL;
}

#endif
