/* The heat-method distance on the caller's DMDA (petsc.h), in builds with
 * HV_HAVE_PETSC.
 *
 * No rank holds more than its box: each rank runs the stages of the single
 * process (hv__dist_march, distance_heat.c) on its own cells plus a ghost
 * layer of GHOST cells. What a stage computes for a cell reads its
 * neighbours only (face directions, fronts, the divergence), so the ghost
 * layer of the heat solutions, exchanged after each solve, gives every owned
 * cell and every face next to one what a single process computes; the
 * splatting reads sources within HV_DIST_REF_RADIUS voxels. The rest is
 * global: the heat and Poisson solves run over all ranks (dmda.c), the fluid
 * regions are labelled across the ranks once, at create, by the Poisson
 * solver, and the counts, norms and the per-region shift are summed over the
 * ranks. The result equals the single process's up to the solves'
 * tolerances (docs/METHOD.md, "Distributed pipelines").
 *
 * Communication per stage: two solves over the ranks, two ghost exchanges of
 * GHOST cells and four sums; then one Poisson solve and a sum of 2 doubles
 * per region. */
#include "heatvox/petsc.h"
#include "distance_internal.h"
#include "petsc/dmda.h"
#include "core/error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#ifdef HV_HAVE_PETSC
#include <petscdmda.h>

/* The ghost layer: sources within HV_DIST_REF_RADIUS voxels of an owned cell
 * lie in it, with a cell to spare. */
#define GHOST ((int)HV_DIST_REF_RADIUS + 1)

struct hv_dmda_distance {
    DM user;                 /* the caller's, referenced */
    DM dag;                  /* the caller's layout with the ghost layer (box stencil) */
    Vec gl, x;               /* dag's local vector; a solution */
    hv_dmda_solver *heat[2]; /* I - t Lap, I - T_RATIO t Lap, during the stages */
    hv_dmda_solver *poisson; /* -Lap, after them */
    PetscBool keep;          /* -hv_distance_keep_solvers: all three kept from create */
    MPI_Comm comm;
    hv_distance_opts o;
    hv_grid full; /* the whole grid's shape (no arrays) */
    PetscInt xs[3], xm[3], gs[3], gm[3];
    size_t nloc, nown;
    uint8_t *solid; /* the ghosted box (NULL: no solid) */
    double *label;  /* the ghosted box's region labels */
};

static void dist_sum(void *user, double *v, int n)
{
    hv_dmda_distance *D = user;
    if (n > 0)
        MPI_Allreduce(MPI_IN_PLACE, v, n, MPI_DOUBLE, MPI_SUM, D->comm);
}

/* The box cell of whole-grid cell (i, j, k). */
static size_t box_cell(const hv_dmda_distance *D, PetscInt i, PetscInt j, PetscInt k)
{
    return (size_t)(i - D->gs[0]) +
           (size_t)D->gm[0] * ((size_t)(j - D->gs[1]) + (size_t)D->gm[1] * (size_t)(k - D->gs[2]));
}

/* A global vector of the caller's layout onto the ghosted box. */
static hv_status to_box(hv_dmda_distance *D, Vec v, double *out)
{
    /* The caller's layout is dag's: its global vectors scatter straight
     * into dag's local one. */
    HV_PETSC_CHK(DMGlobalToLocalBegin(D->dag, v, INSERT_VALUES, D->gl),
                 "DMGlobalToLocal (is it a global vector of the DMDA?)");
    HV_PETSC_CHK(DMGlobalToLocalEnd(D->dag, v, INSERT_VALUES, D->gl), "DMGlobalToLocal");
    const PetscScalar *a;
    HV_PETSC_CHK(VecGetArrayRead(D->gl, &a), "VecGetArrayRead");
    memcpy(out, a, D->nloc * sizeof *out);
    VecRestoreArrayRead(D->gl, &a);
    return HV_OK;
}

/* The caller's solid vector again, from the box's flags (NULL: no solid). */
static hv_status solid_vec(hv_dmda_distance *D, Vec *v)
{
    *v = NULL;
    if (!D->solid)
        return HV_OK;
    HV_PETSC_CHK(DMCreateGlobalVector(D->user, v), "DMCreateGlobalVector");
    PetscScalar *a;
    HV_PETSC_CHK(VecGetArray(*v, &a), "VecGetArray"); /* the caller destroys *v */
    size_t c = 0;
    for (PetscInt k = D->xs[2]; k < D->xs[2] + D->xm[2]; k++)
        for (PetscInt j = D->xs[1]; j < D->xs[1] + D->xm[1]; j++)
            for (PetscInt i = D->xs[0]; i < D->xs[0] + D->xm[0]; i++)
                a[c++] = D->solid[box_cell(D, i, j, k)];
    VecRestoreArray(*v, &a);
    return HV_OK;
}

/* The solvers a solve of kind q needs (dist_hooks): the two heat steps, or,
 * once they are done with, Poisson. No more than two exist at once: a
 * multigrid solver holds about 350 bytes per cell (docs/PERFORMANCE.md),
 * and building them again takes about 3% of a call. With D->keep, all three
 * are made once and kept (the solid and the diffusion times never change). */
static hv_status need_solvers(hv_dmda_distance *D, int q)
{
    if (q < 2 ? D->heat[0] != NULL : D->poisson != NULL)
        return HV_OK;
    Vec solid;
    hv_status st = hv__petsc_agree(D->dag, solid_vec(D, &solid));
    if (st) {
        VecDestroy(&solid);
        return st;
    }
    hv_solver_opts so;
    hv_solver_opts_default(&so);
    so.max_iter = 500;
    so.tol = D->o.diffuse_tol;
    const double h = D->full.h, th = D->o.t_scale * h * h;
    if (q < 2) {
        /* The heat steps take the default preconditioner too: at 64^3 with
         * baffles PFMG's 16 iterations per solve took half the time of
         * Jacobi-preconditioned CG's 94 (docs/PERFORMANCE.md). */
        for (int r = 0; r < 2 && !st; r++)
            st = hv__dmda_solver_create(&D->heat[r], D->user, h, 1.0, th * (r ? T_RATIO : 1), solid,
                                        &so, -1);
    } else {
        if (!D->keep) {
            hv_dmda_solver_destroy(&D->heat[0]);
            hv_dmda_solver_destroy(&D->heat[1]);
        }
        so.tol = D->o.poisson_tol;
        so.max_iter = 200;
        st = hv__dmda_solver_create(&D->poisson, D->user, h, 0.0, 1.0, solid, &so, -1);
    }
    VecDestroy(&solid);
    return hv__petsc_agree(D->dag, st);
}

static void drop_solvers(hv_dmda_distance *D, int always)
{
    if (D->keep && !always)
        return;
    hv_dmda_solver_destroy(&D->heat[0]);
    hv_dmda_solver_destroy(&D->heat[1]);
    hv_dmda_solver_destroy(&D->poisson);
}

static hv_status dist_solve(void *user, int q, const double *f, double *u, hv_solve_info *info)
{
    hv_dmda_distance *D = user;
    hv_status st = need_solvers(D, q);
    if (st)
        return st;
    hv_dmda_solver *s = q < 2 ? D->heat[q] : D->poisson;
    PetscScalar *a;
    HV_PETSC_CHK(VecGetArray(hv__dmda_rhs(s), &a), "VecGetArray");
    size_t c = 0;
    for (PetscInt k = D->xs[2]; k < D->xs[2] + D->xm[2]; k++)
        for (PetscInt j = D->xs[1]; j < D->xs[1] + D->xm[1]; j++)
            for (PetscInt i = D->xs[0]; i < D->xs[0] + D->xm[0]; i++)
                a[c++] = f[box_cell(D, i, j, k)];
    VecRestoreArray(hv__dmda_rhs(s), &a);
    if ((st = hv__dmda_solve(s, D->x, info)))
        return st;
    info->backend = HV_BACKEND_PETSC;
    return to_box(D, D->x, u);
}

static hv_status create(hv_dmda_distance *D, DM da, double h, const double origin[3], Vec solid)
{
    HV_PETSC_CHK(PetscObjectReference((PetscObject)da), "PetscObjectReference");
    D->user = da;
    D->comm = PetscObjectComm((PetscObject)da);
    /* A DMDA's ghost layer comes from the next rank only. */
    PetscInt m[3] = {1, 1, 1};
    const PetscInt *l[3] = {NULL, NULL, NULL};
    HV_PETSC_CHK(DMDAGetInfo(da, NULL, NULL, NULL, NULL, &m[0], &m[1], &m[2], NULL, NULL, NULL,
                             NULL, NULL, NULL),
                 "DMDAGetInfo (is it a DMDA?)");
    HV_PETSC_CHK(DMDAGetOwnershipRanges(da, &l[0], &l[1], &l[2]), "DMDAGetOwnershipRanges");
    for (int a = 0; a < 3; a++)
        for (PetscInt r = 0; m[a] > 1 && l[a] && r < m[a]; r++)
            if (l[a][r] < GHOST)
                return hv__error(HV_ERR_INVALID_ARG,
                                 "distance: a rank's box is %d cells wide along %c, and the "
                                 "distance needs %d (fewer ranks, or a larger grid)",
                                 (int)l[a][r], "xyz"[a], GHOST);
    int dim = 3;
    hv_status st = hv__dmda_like(da, GHOST, 1, &D->dag, &dim);
    if (st)
        return st;
    PetscInt N[3] = {1, 1, 1};
    HV_PETSC_CHK(DMDAGetInfo(da, NULL, &N[0], &N[1], &N[2], NULL, NULL, NULL, NULL, NULL, NULL,
                             NULL, NULL, NULL),
                 "DMDAGetInfo");
    D->full.dim = dim;
    D->full.h = h;
    for (int a = 0; a < 3; a++) {
        D->full.n[a] = a < dim ? (int)N[a] : 1;
        D->full.origin[a] = origin ? origin[a] : 0;
    }
    HV_PETSC_CHK(DMCreateLocalVector(D->dag, &D->gl), "DMCreateLocalVector");
    HV_PETSC_CHK(DMCreateGlobalVector(da, &D->x), "DMCreateGlobalVector");
    DMDAGetCorners(D->dag, &D->xs[0], &D->xs[1], &D->xs[2], &D->xm[0], &D->xm[1], &D->xm[2]);
    DMDAGetGhostCorners(D->dag, &D->gs[0], &D->gs[1], &D->gs[2], &D->gm[0], &D->gm[1], &D->gm[2]);
    if (dim == 2) {
        D->xs[2] = D->gs[2] = 0;
        D->xm[2] = D->gm[2] = 1;
    }
    D->nloc = (size_t)D->gm[0] * D->gm[1] * D->gm[2];
    D->nown = (size_t)D->xm[0] * D->xm[1] * D->xm[2];
    D->label = malloc(D->nloc * sizeof *D->label);
    if (PetscOptionsGetBool(NULL, NULL, "-hv_distance_keep_solvers", &D->keep, NULL))
        st = hv__error(HV_ERR_INVALID_ARG,
                       "distance: -hv_distance_keep_solvers takes true or false");
    if (solid && D->label && !(D->solid = malloc(D->nloc)))
        st = hv__error(HV_ERR_NOMEM, "distance: out of memory");
    if (!D->label)
        st = hv__error(HV_ERR_NOMEM, "distance: out of memory");
    PetscInt ns = (PetscInt)D->nown;
    if (solid)
        VecGetLocalSize(solid, &ns);
    if (!st && (size_t)ns != D->nown)
        st = hv__error(HV_ERR_INVALID_ARG,
                       "distance: the solid vector is not a global vector of the DMDA (%d cells "
                       "on this rank, not %zu)",
                       (int)ns, D->nown);
    if ((st = hv__petsc_agree(D->dag, st)))
        return st;
    if (solid) {
        double *s = (double *)D->label; /* staging */
        if ((st = to_box(D, solid, s)))
            return st;
        for (size_t c = 0; c < D->nloc; c++)
            D->solid[c] = s[c] != 0;
    }
    /* The fluid regions, labelled across the ranks by a Poisson solver. */
    if ((st = need_solvers(D, 2)) || (st = to_box(D, hv__dmda_labels(D->poisson), D->label)))
        return st;
    drop_solvers(D, 0);
    return HV_OK;
}

static hv_status hv_dmda_distance_create_body(hv_dmda_distance **out, DM da, double h,
                                              const double origin[3], Vec solid,
                                              const hv_distance_opts *opts)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_dmda_distance_create: out is NULL");
    *out = NULL;
    if (!(h > 0) || !isfinite(h))
        return hv__error(HV_ERR_INVALID_ARG, "hv_dmda_distance_create: h must be > 0, got %g", h);
    hv_distance_opts o;
    hv_distance_opts_default(&o);
    if (opts)
        o = *opts;
    const hv_distance_sources none = {NULL, 0, NULL, 0, NULL};
    hv_status st = hv__dist_check_opts(&o, &none);
    if (st)
        return st;
    hv_dmda_distance *D = calloc(1, sizeof *D);
    if (!D)
        return hv__error(HV_ERR_NOMEM, "distance: out of memory");
    D->o = o;
    if ((st = create(D, da, h, origin, solid))) {
        hv_dmda_distance_destroy(&D);
        return st;
    }
    *out = D;
    return HV_OK;
}

static int cmp_double(const void *a, const void *b)
{
    const double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* The regions holding a source, numbered alike on every rank: the labels of
 * the owned source cells, gathered from all ranks. Fills b->region on the
 * box and the counts of S. */
static hv_status source_regions(hv_dmda_distance *D, hv_dist_box *b, const double *w,
                                hv_distance_stats *S)
{
    double *mine = malloc((D->nown + 1) * sizeof *mine), *all = NULL;
    int size = 1, nm = 0, total = 0;
    MPI_Comm_size(D->comm, &size);
    int *counts = calloc((size_t)size, sizeof *counts),
        *displ = calloc((size_t)size, sizeof *displ);
    hv_status st =
        mine && counts && displ ? HV_OK : hv__error(HV_ERR_NOMEM, "distance: out of memory");
    for (PetscInt k = D->xs[2]; !st && k < D->xs[2] + D->xm[2]; k++)
        for (PetscInt j = D->xs[1]; j < D->xs[1] + D->xm[1]; j++)
            for (PetscInt i = D->xs[0]; i < D->xs[0] + D->xm[0]; i++) {
                const size_t c = box_cell(D, i, j, k);
                if (w[c] > 0 && D->label[c] >= 0 && (!nm || mine[nm - 1] != D->label[c]))
                    mine[nm++] = D->label[c];
            }
    if (!st) {
        qsort(mine, (size_t)nm, sizeof *mine, cmp_double);
        int u = 0;
        for (int i = 0; i < nm; i++)
            if (!u || mine[i] != mine[u - 1])
                mine[u++] = mine[i];
        nm = u;
    }
    if (!(st = hv__petsc_agree(D->dag, st))) {
        (void)MPI_Allgather(&nm, 1, MPI_INT, counts, 1, MPI_INT, D->comm);
        for (int r = 0; r < size; r++) {
            displ[r] = total;
            total += counts[r];
        }
        if (!(all = malloc(((size_t)total + 1) * sizeof *all)))
            st = hv__error(HV_ERR_NOMEM, "distance: out of memory");
        if (!(st = hv__petsc_agree(D->dag, st)))
            (void)MPI_Allgatherv(mine, nm, MPI_DOUBLE, all, counts, displ, MPI_DOUBLE, D->comm);
    }
    int u = 0;
    if (!st) {
        qsort(all, (size_t)total, sizeof *all, cmp_double);
        for (int i = 0; i < total; i++)
            if (!u || all[i] != all[u - 1])
                all[u++] = all[i];
        if (!(b->region = malloc(D->nloc * sizeof *b->region)))
            st = hv__error(HV_ERR_NOMEM, "distance: out of memory");
    }
    double un = 0;
    for (size_t c = 0; !st && c < D->nloc; c++) {
        const double *hit =
            D->label[c] < 0 ? NULL : bsearch(&D->label[c], all, (size_t)u, sizeof *all, cmp_double);
        b->region[c] = D->label[c] < 0 ? -1 : hit ? (int32_t)(hit - all) : -2;
    }
    for (PetscInt k = D->xs[2]; !st && k < D->xs[2] + D->xm[2]; k++)
        for (PetscInt j = D->xs[1]; j < D->xs[1] + D->xm[1]; j++)
            for (PetscInt i = D->xs[0]; i < D->xs[0] + D->xm[0]; i++)
                un += b->region[box_cell(D, i, j, k)] == -2;
    free(mine);
    free(all);
    free(counts);
    free(displ);
    if ((st = hv__petsc_agree(D->dag, st)))
        return st;
    dist_sum(D, &un, 1);
    S->regions = (size_t)u;
    S->unreachable_cells = (size_t)un;
    return HV_OK;
}

static hv_status distance(hv_dmda_distance *D, const hv_distance_sources *src, Vec dist,
                          hv_distance_stats *S, hv_dist_box *b, double *w, double *u, double *u2,
                          uint8_t *inside, uint8_t *ok, float *ref)
{
    /* Sources: the box is a window of the whole grid. */
    const double t0 = hv_now();
    hv_grid g = D->full;
    for (int a = 0; a < 3; a++) {
        g.n[a] = (int)D->gm[a];
        g.origin[a] = D->full.origin[a] + (double)D->gs[a] * D->full.h;
    }
    g.solid = D->solid;
    hv_dist_window win = {&D->full, {0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
    for (int a = 0; a < 3; a++) {
        win.off[a] = (int)D->gs[a];
        win.own_lo[a] = (int)D->xs[a];
        win.own_hi[a] = (int)(D->xs[a] + D->xm[a]);
    }
    for (size_t c = 0; c < D->nloc; c++)
        ref[c] = INFINITY;
    hv_status st = hv__dist_splat(&g, &win, src, w, ref, &S->sources_in_solid);
    if ((st = hv__petsc_agree(D->dag, st))) /* the same sources everywhere: the same error */
        return st;
    double cnt[2] = {(double)S->sources_in_solid, 0};
    for (PetscInt k = D->xs[2]; k < D->xs[2] + D->xm[2]; k++)
        for (PetscInt j = D->xs[1]; j < D->xs[1] + D->xm[1]; j++)
            for (PetscInt i = D->xs[0]; i < D->xs[0] + D->xm[0]; i++)
                cnt[1] += w[box_cell(D, i, j, k)] > 0;
    dist_sum(D, cnt, 2);
    S->sources_in_solid = (size_t)cnt[0];
    S->source_cells = (size_t)cnt[1];
    if ((st = hv__dist_no_source(S)) || (st = source_regions(D, b, w, S)))
        return st;
    S->t_splat = hv_now() - t0;
    S->t = D->o.t_scale * D->full.h * D->full.h;
    S->backend = HV_BACKEND_PETSC;

    float *out = ref; /* the march reads ref before it writes out */
    if ((st = hv__dist_march(b, &D->o, w, u, u2, inside, ok, ref, out, S)))
        return st;
    PetscScalar *a;
    HV_PETSC_CHK(VecGetArray(dist, &a), "VecGetArray (is dist a global vector of the DMDA?)");
    size_t c = 0;
    for (PetscInt k = D->xs[2]; k < D->xs[2] + D->xm[2]; k++)
        for (PetscInt j = D->xs[1]; j < D->xs[1] + D->xm[1]; j++)
            for (PetscInt i = D->xs[0]; i < D->xs[0] + D->xm[0]; i++)
                a[c++] = out[box_cell(D, i, j, k)];
    VecRestoreArray(dist, &a);
    return HV_OK;
}

static hv_status hv_dmda_distance_compute_body(hv_dmda_distance *D, const hv_distance_sources *src,
                                               Vec dist, hv_distance_stats *stats)
{
    if (!D || !src || !dist)
        return hv__error(HV_ERR_INVALID_ARG, "hv_dmda_distance_compute: NULL argument");
    const double t_start = hv_now();
    hv_distance_stats lst;
    hv_distance_stats *S = stats ? stats : &lst;
    memset(S, 0, sizeof *S);
    hv_status st = hv__dist_check_opts(&D->o, src);
    if (st)
        return st;
    PetscInt nl = 0;
    HV_PETSC_CHK(VecGetLocalSize(dist, &nl), "VecGetLocalSize");
    if ((size_t)nl != D->nown)
        st = hv__error(
            HV_ERR_INVALID_ARG,
            "hv_dmda_distance_compute: dist has %d cells on this rank, the DMDA's box %zu", (int)nl,
            D->nown);
    hv_dist_box b = {0};
    const int n[3] = {(int)D->gm[0], (int)D->gm[1], (int)D->gm[2]};
    hv__dist_box_init(&b, D->full.dim, n, D->full.h, D->solid);
    for (int a = 0; a < 3; a++) {
        b.lo[a] = (int)(D->xs[a] - D->gs[a]);
        b.hi[a] = b.lo[a] + (int)D->xm[a];
    }
    const hv_dist_hooks hk = {D, dist_sum, dist_solve};
    b.hk = &hk;
    double *w = hv_calloc(D->nloc, sizeof *w), *u = hv_malloc(D->nloc * sizeof *u),
           *u2 = hv_malloc(D->nloc * sizeof *u2);
    uint8_t *inside = calloc(D->nloc, 1), *ok = malloc(D->nloc);
    float *ref = hv_malloc(D->nloc * sizeof *ref);
    if (!st && (!w || !u || !u2 || !inside || !ok || !ref))
        st = hv__error(HV_ERR_NOMEM, "distance: out of memory for a box of %zu cells", D->nloc);
    for (int a = 0; !st && a < b.dim; a++)
        if (!(b.X[a] = hv_malloc(b.nface[a] * sizeof(float))))
            st = hv__error(HV_ERR_NOMEM, "distance: out of memory for face arrays");
    if (!(st = hv__petsc_agree(D->dag, st)))
        st = distance(D, src, dist, S, &b, w, u, u2, inside, ok, ref);
    drop_solvers(D, 0);
    hv_free(w);
    hv_free(u);
    hv_free(u2);
    free(inside);
    free(ok);
    hv_free(ref);
    for (int a = 0; a < 3; a++)
        hv_free(b.X[a]);
    free(b.region);
    S->t_total = hv_now() - t_start;
    return st;
}

void hv_dmda_distance_destroy(hv_dmda_distance **dp)
{
    if (!dp || !*dp)
        return;
    hv_dmda_distance *D = *dp;
    drop_solvers(D, 1);
    VecDestroy(&D->x);
    VecDestroy(&D->gl);
    DMDestroy(&D->dag);
    DMDestroy(&D->user);
    free(D->solid);
    free(D->label);
    free(D);
    *dp = NULL;
}

hv_status hv_dmda_distance_create(hv_dmda_distance **out, DM da, double h, const double origin[3],
                                  Vec solid, const hv_distance_opts *opts)
{
    HV_PETSC_QUIETLY(hv_dmda_distance_create_body(out, da, h, origin, solid, opts));
}

hv_status hv_dmda_distance_compute(hv_dmda_distance *D, const hv_distance_sources *src, Vec dist,
                                   hv_distance_stats *stats)
{
    HV_PETSC_QUIETLY(hv_dmda_distance_compute_body(D, src, dist, stats));
}

/* ---- a whole grid held by rank 0 ----------------------------------------- */

/* Rank 0's count items of size sz at *p, sent to every rank (allocated
 * there; the caller frees them on ranks > 0). */
static hv_status bcast_items(void **p, size_t count, size_t sz, int rank)
{
    hv_status st = HV_OK;
    if (count && rank && !(*p = malloc(count * sz)))
        st = hv__error(HV_ERR_NOMEM, "distance: out of memory for the sources");
    int bad = st != HV_OK;
    MPI_Allreduce(MPI_IN_PLACE, &bad, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
    if (bad)
        return st ? st : hv__error(HV_ERR_NOMEM, "distance: out of memory on another rank");
    const size_t chunk = (size_t)1 << 30, bytes = count * sz;
    for (size_t o = 0; o < bytes; o += chunk)
        (void)MPI_Bcast((char *)*p + o, (int)(bytes - o < chunk ? bytes - o : chunk), MPI_BYTE, 0,
                        PETSC_COMM_WORLD);
    return HV_OK;
}

static hv_status distance_block(hv_block_io *B, hv_grid *g, const hv_grid *hdr, int has_solid,
                                const hv_distance_sources *src, const hv_distance_opts *o,
                                hv_distance_stats *stats)
{
    Vec solid = NULL, dist = NULL;
    hv_dmda_distance *D = NULL;
    HV_PETSC_CHK(DMCreateGlobalVector(B->da, &dist), "DMCreateGlobalVector");
    hv_status st = HV_OK;
    if (has_solid) {
        PetscErrorCode ierr = DMCreateGlobalVector(B->da, &solid);
        st = ierr ? hv__petsc_fail(ierr, "DMCreateGlobalVector")
                  : hv__block_in(B, NULL, g ? g->solid : NULL, solid);
    }
    if (!st)
        st = hv_dmda_distance_create(&D, B->da, hdr->h, hdr->origin, solid, o);
    if (!st)
        st = hv_dmda_distance_compute(D, src, dist, stats);
    if (!st)
        st = hv__block_out(B, dist, g ? g->v : NULL);
    hv_dmda_distance_destroy(&D);
    VecDestroy(&solid);
    VecDestroy(&dist);
    return st;
}

static hv_status hv_petsc_distance_block_body(hv_grid *g, const hv_distance_sources *src,
                                              const hv_distance_opts *opts,
                                              hv_distance_stats *stats)
{
    int rank = 0;
    MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
    /* Rank 0's grid and sources: their shape first. */
    double hdr[15] = {0};
    const int have = !rank && g && src && g->v && (!src->nvoxels || src->voxels) &&
                     (!src->npoints || src->points);
    if (have) {
        hdr[0] = 1;
        hdr[1] = g->dim;
        hdr[2] = g->h;
        for (int a = 0; a < 3; a++) {
            hdr[3 + a] = g->n[a];
            hdr[6 + a] = g->origin[a];
        }
        hdr[9] = g->solid != NULL;
        hdr[10] = (double)src->nvoxels;
        hdr[11] = (double)src->npoints;
        hdr[12] = src->mesh ? 1 : 0;
        hdr[13] = src->mesh ? (double)src->mesh->nverts : 0;
        hdr[14] = src->mesh ? (double)src->mesh->ntris : 0;
    }
    (void)MPI_Bcast(hdr, 15, MPI_DOUBLE, 0, PETSC_COMM_WORLD);
    if (!hdr[0])
        return rank ? hv__error(HV_ERR_INVALID_ARG, "distance: rank 0 has no grid")
                    : hv__error(HV_ERR_INVALID_ARG, "hv_petsc_distance_block: no grid or sources, "
                                                    "or source counts without arrays");
    hv_grid G;
    memset(&G, 0, sizeof G);
    G.dim = (int)hdr[1];
    G.h = hdr[2];
    for (int a = 0; a < 3; a++) {
        G.n[a] = (int)hdr[3 + a];
        G.origin[a] = hdr[6 + a];
    }
    hv_distance_opts o;
    hv_distance_opts_default(&o);
    if (!rank && opts)
        o = *opts;
    (void)MPI_Bcast(&o, (int)sizeof o, MPI_BYTE, 0, PETSC_COMM_WORLD);
    /* The sources on every rank. */
    hv_mesh mesh;
    memset(&mesh, 0, sizeof mesh);
    hv_distance_sources s = {NULL, (size_t)hdr[10], NULL, (size_t)hdr[11], hdr[12] ? &mesh : NULL};
    void *vox = rank ? NULL : (void *)src->voxels, *pts = rank ? NULL : (void *)src->points;
    void *verts = NULL, *tris = NULL;
    if (!rank && src->mesh) {
        verts = src->mesh->verts;
        tris = src->mesh->tris;
    }
    mesh.nverts = (size_t)hdr[13];
    mesh.ntris = (size_t)hdr[14];
    hv_status st = bcast_items(&vox, s.nvoxels, 3 * sizeof(int), rank);
    if (!st)
        st = bcast_items(&pts, s.npoints, 3 * sizeof(double), rank);
    if (!st)
        st = bcast_items(&verts, mesh.nverts, 3 * sizeof(double), rank);
    if (!st)
        st = bcast_items(&tris, mesh.ntris, 3 * sizeof(uint32_t), rank);
    s.voxels = vox;
    s.points = pts;
    mesh.verts = verts;
    mesh.tris = tris;
    hv_block_io B;
    memset(&B, 0, sizeof B);
    if (!st && !(st = hv__block_create(&B, G.dim, G.n)))
        st = distance_block(&B, rank ? NULL : g, &G, hdr[9] != 0, &s, &o, stats);
    hv__block_destroy(&B);
    if (rank) {
        free(vox);
        free(pts);
        free(verts);
        free(tris);
    }
    return st;
}

hv_status hv_petsc_distance_block(hv_grid *g, const hv_distance_sources *src,
                                  const hv_distance_opts *opts, hv_distance_stats *stats)
{
    HV_PETSC_QUIETLY(hv_petsc_distance_block_body(g, src, opts, stats));
}

#else /* without PETSc */

hv_status hv_dmda_distance_create(hv_dmda_distance **out, DM da, double h, const double origin[3],
                                  Vec solid, const hv_distance_opts *opts)
{
    (void)da;
    (void)h;
    (void)origin;
    (void)solid;
    (void)opts;
    if (out)
        *out = NULL;
    return hv__error(HV_ERR_UNSUPPORTED,
                     "the distance on a DMDA needs heatvox built with MPI and PETSc (make mpi)");
}

hv_status hv_dmda_distance_compute(hv_dmda_distance *D, const hv_distance_sources *src, Vec dist,
                                   hv_distance_stats *stats)
{
    (void)D;
    (void)src;
    (void)dist;
    (void)stats;
    return hv__error(HV_ERR_UNSUPPORTED,
                     "the distance on a DMDA needs heatvox built with MPI and PETSc (make mpi)");
}

void hv_dmda_distance_destroy(hv_dmda_distance **D)
{
    if (D)
        *D = NULL;
}

hv_status hv_petsc_distance_block(hv_grid *g, const hv_distance_sources *src,
                                  const hv_distance_opts *opts, hv_distance_stats *stats)
{
    (void)g;
    (void)src;
    (void)opts;
    (void)stats;
    return hv__error(HV_ERR_UNSUPPORTED,
                     "the distributed distance needs heatvox built with MPI and PETSc (make mpi)");
}

#endif
