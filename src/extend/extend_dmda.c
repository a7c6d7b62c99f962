/* The extension on the caller's DMDA (petsc.h), in builds with HV_HAVE_PETSC.
 *
 * No rank holds more than its box: each rank runs hv_extend_many's pipeline
 * (extend_vhm.c) on its own cells plus a ghost layer as wide as a closest
 * point can reach (out_band voxels times GRAD_MAX, plus the interpolation's
 * stencil), with the hooks of hv_extend_dist: the counts that decide when to
 * stop are summed over the ranks, and every diffusion level is solved on the
 * whole grid by a solver on the caller's layout (dmda.c), from the
 * right-hand sides of the ranks' own cells; its solution comes back into the
 * ghost layer by the DMDA's ghost exchange. What a rank evaluates for its own
 * cells then reads the same solutions as a single process would, and the
 * trust threshold is computed from global norms and the requested tolerance,
 * so the ranks agree with one process up to the solves' tolerance.
 *
 * Communication per call: one ghost exchange of phi and of each field
 * component, of width `ghost`; per level, three sums or maxima; per
 * right-hand side of a level past 0, one solve over the ranks and one ghost
 * exchange. */
#include "heatvox/petsc.h"
#include "extend_internal.h"
#include "petsc/dmda.h"
#include "core/error.h"

#include <limits.h>
#include <stdlib.h>
#include <string.h>

#ifdef HV_HAVE_PETSC
#include <petscdmda.h>

/* The widest ghost layer the band solve of level 0 may ask for. */
#define MAX_GHOST 48

struct hv_dmda_extender {
    DM user;                        /* the caller's, referenced */
    DM dag;                         /* the caller's layout with the ghost layer (box stencil) */
    Vec gl;                         /* dag's local vector */
    Vec x;                          /* a level's solution (made on first use) */
    hv_dmda_solver *sv[MAX_LEVELS]; /* level l: I - t 16^l Lap, made on first use */
    hv_extender *e;                 /* on this rank's ghosted box */
    hv_extend_dist dist;
    /* Closest points past the box: the table (extend_internal.h), the
     * ranks' first cells along each axis (m[a] + 1 of them), its used slots
     * by owner, the cells of this box other ranks read (in the order they
     * asked), the counts and offsets of both directions, per rank. */
    hv_extend_remote rem;
    PetscInt *first[3], mr[3];
    size_t *order, *serve, nserve;
    int *sc, *sd, *rc, *rd;
    MPI_Comm comm;
    int dim, ghost;
    double h;
    PetscInt xs[3], xm[3], gs[3], gm[3]; /* owned and ghosted corners and sizes */
    size_t nloc, nown;
};

static size_t dist_sum(void *user, size_t v)
{
    hv_dmda_extender *X = user;
    unsigned long long a = v, s = 0;
    MPI_Allreduce(&a, &s, 1, MPI_UNSIGNED_LONG_LONG, MPI_SUM, X->comm);
    return (size_t)s;
}

/* The ghosted box's cell of owned cell (i, j, k) (global indices). */
static size_t local_cell(const hv_dmda_extender *X, PetscInt i, PetscInt j, PetscInt k)
{
    return (size_t)(i - X->gs[0]) +
           (size_t)X->gm[0] * ((size_t)(j - X->gs[1]) + (size_t)X->gm[1] * (size_t)(k - X->gs[2]));
}

/* A global vector of the caller's layout onto the ghosted box, as floats. */
static hv_status to_local(hv_dmda_extender *X, Vec v, float *out)
{
    /* The caller's layout is dag's: its global vectors scatter straight
     * into dag's local one. */
    HV_PETSC_CHK(DMGlobalToLocalBegin(X->dag, v, INSERT_VALUES, X->gl),
                 "DMGlobalToLocal (is it a global vector of the DMDA?)");
    HV_PETSC_CHK(DMGlobalToLocalEnd(X->dag, v, INSERT_VALUES, X->gl), "DMGlobalToLocal");
    const PetscScalar *a;
    HV_PETSC_CHK(VecGetArrayRead(X->gl, &a), "VecGetArrayRead");
    for (size_t c = 0; c < X->nloc; c++)
        out[c] = (float)a[c];
    VecRestoreArrayRead(X->gl, &a);
    return HV_OK;
}

/* ---- closest points past the box ------------------------------------------- */

/* The rank that owns global cell g, and its indices. */
static int owner(const hv_dmda_extender *X, size_t g, PetscInt ijk[3])
{
    const hv_extend_remote *R = &X->rem;
    ijk[0] = (PetscInt)(g % (size_t)R->gn[0]);
    ijk[1] = (PetscInt)(g / (size_t)R->gn[0] % (size_t)R->gn[1]);
    ijk[2] = (PetscInt)(g / ((size_t)R->gn[0] * (size_t)R->gn[1]));
    int r[3] = {0, 0, 0};
    for (int a = 0; a < 3; a++)
        while (r[a] + 1 < X->mr[a] && X->first[a][r[a] + 1] <= ijk[a])
            r[a]++;
    return r[0] + (int)X->mr[0] * (r[1] + (int)X->mr[1] * r[2]);
}

/* st on every rank, or an error when another rank failed (collective). */
static hv_status together(hv_dmda_extender *X, hv_status st)
{
    if (dist_sum(X, st != HV_OK) && !st)
        return hv__error(HV_ERR_NOMEM, "extend: another rank ran out of memory");
    return st;
}

/* The counts of the requests (sc: to each rank, rc: from each) times w,
 * with their offsets; 0 when they exceed an int. */
static int scaled(hv_dmda_extender *X, int w, int *sc, int *sd, int *rc, int *rd)
{
    int P = 0;
    MPI_Comm_size(X->comm, &P);
    long long s = 0, r = 0;
    for (int q = 0; q < P; q++) {
        sc[q] = X->sc[q] * w;
        rc[q] = X->rc[q] * w;
        sd[q] = (int)s;
        rd[q] = (int)r;
        s += sc[q];
        r += rc[q];
        if (s > INT_MAX || r > INT_MAX)
            return 0;
    }
    return 1;
}

/* Stage 0: the corners this rank's closest points past the box read go to
 * their owners, which answer with phi there; the points are checked, and
 * the corners of those that pass are marked in the owners' need. Stage 1:
 * the owners answer with the solutions of level 0 there. */
static hv_status dist_remote(void *user, hv_extender *e, const float *phi, uint8_t *need, int stage)
{
    hv_dmda_extender *X = user;
    hv_extend_remote *R = &X->rem;
    int P = 0;
    MPI_Comm_size(X->comm, &P);
    const int ns = stage ? e->nsol : 1;
    hv_status st = HV_OK;
    void *sbuf = NULL, *rbuf = NULL;
    int *c4 = malloc(4 * (size_t)P * sizeof *c4);
    if (!c4)
        st = hv__error(HV_ERR_NOMEM, "extend: out of memory");
    if (stage == 0) {
        /* The corners, by owner. */
        if (!st)
            st = hv__extend_remote_collect(e, phi);
        if (!st) {
            float *fp = realloc(R->phi, (R->cap ? R->cap : 1) * sizeof *fp);
            if (fp)
                R->phi = fp;
            uint8_t *rp = fp ? realloc(R->read, R->cap ? R->cap : 1) : NULL;
            if (rp)
                R->read = rp;
            size_t *op = rp ? realloc(X->order, (R->used ? R->used : 1) * sizeof *op) : NULL;
            if (op)
                X->order = op;
            if (!op)
                st = hv__error(HV_ERR_NOMEM, "extend: out of memory for %zu closest-point cells",
                               R->used);
            else if (R->used > INT_MAX)
                st = hv__error(HV_ERR_INVALID_ARG,
                               "extend: this rank's closest points read %zu cells of other "
                               "ranks, more than one MPI message holds",
                               R->used);
        }
        if ((st = together(X, st)))
            goto out;
        memset(X->sc, 0, (size_t)P * sizeof *X->sc);
        PetscInt ijk[3];
        for (size_t s = 0; s < R->cap; s++)
            if (R->key[s])
                X->sc[owner(X, R->key[s] - 1, ijk)]++;
        for (int q = 0, o = 0; q < P; q++) {
            X->sd[q] = o;
            o += X->sc[q];
        }
        memcpy(c4, X->sd, (size_t)P * sizeof *c4);
        for (size_t s = 0; s < R->cap; s++)
            if (R->key[s])
                X->order[c4[owner(X, R->key[s] - 1, ijk)]++] = s;
        (void)MPI_Alltoall(X->sc, 1, MPI_INT, X->rc, 1, MPI_INT, X->comm);
        X->nserve = 0;
        for (int q = 0; q < P; q++) {
            X->rd[q] = (int)X->nserve;
            X->nserve += (size_t)X->rc[q];
        }
        size_t *sv = realloc(X->serve, (X->nserve ? X->nserve : 1) * sizeof *sv);
        if (sv)
            X->serve = sv;
        if (X->nserve > INT_MAX)
            st = hv__error(HV_ERR_INVALID_ARG,
                           "extend: other ranks' closest points read %zu cells of this rank's "
                           "box, more than one MPI message holds",
                           X->nserve);
        else if (!sv || !(sbuf = malloc((R->used ? R->used : 1) * sizeof(uint64_t))) ||
                 !(rbuf = malloc((X->nserve ? X->nserve : 1) * sizeof(uint64_t))))
            st = hv__error(HV_ERR_NOMEM, "extend: out of memory for the closest points' cells");
        if ((st = together(X, st)))
            goto out;
        uint64_t *sk = sbuf, *rk = rbuf;
        for (size_t q = 0; q < R->used; q++)
            sk[q] = R->key[X->order[q]] - 1;
        (void)MPI_Alltoallv(sk, X->sc, X->sd, MPI_UINT64_T, rk, X->rc, X->rd, MPI_UINT64_T,
                            X->comm);
        for (size_t q = 0; q < X->nserve; q++) {
            owner(X, (size_t)rk[q], ijk);
            X->serve[q] = local_cell(X, ijk[0], ijk[1], ijk[2]);
        }
        /* phi there, back; the check; the marks, out. */
        float *sf = rbuf, *rf = sbuf;
        for (size_t q = 0; q < X->nserve; q++)
            sf[q] = phi[X->serve[q]];
        (void)MPI_Alltoallv(sf, X->rc, X->rd, MPI_FLOAT, rf, X->sc, X->sd, MPI_FLOAT, X->comm);
        for (size_t q = 0; q < R->used; q++)
            R->phi[X->order[q]] = rf[q];
        hv__extend_remote_check(e, phi, need);
        uint8_t *sm = sbuf, *rm = rbuf;
        for (size_t q = 0; q < R->used; q++)
            sm[q] = R->read[X->order[q]];
        (void)MPI_Alltoallv(sm, X->sc, X->sd, MPI_UINT8_T, rm, X->rc, X->rd, MPI_UINT8_T, X->comm);
        for (size_t q = 0; need && q < X->nserve; q++)
            if (rm[q])
                need[X->serve[q]] = 1;
        goto out;
    }
    /* Stage 1: the solutions, ns per corner. */
    int *sc = c4, *sd = c4 ? c4 + P : NULL, *rc = c4 ? c4 + 2 * P : NULL,
        *rd = c4 ? c4 + 3 * P : NULL;
    float *sol = NULL;
    if (!st && !scaled(X, ns, sc, sd, rc, rd))
        st = hv__error(HV_ERR_INVALID_ARG,
                       "extend: the closest points past this rank's box read more values than "
                       "one MPI message holds");
    if (!st && (!(sol = realloc(R->sol, (R->cap ? R->cap : 1) * (size_t)ns * sizeof *sol)) ||
                !(sbuf = malloc((X->nserve * (size_t)ns + 1) * sizeof(float))) ||
                !(rbuf = malloc((R->used * (size_t)ns + 1) * sizeof(float)))))
        st = hv__error(HV_ERR_NOMEM, "extend: out of memory for the closest points' solutions");
    if (sol)
        R->sol = sol;
    if ((st = together(X, st)))
        goto out;
    float *sf = sbuf, *rf = rbuf;
    for (size_t q = 0; q < X->nserve; q++)
        memcpy(sf + q * (size_t)ns, e->sol + X->serve[q] * (size_t)ns, (size_t)ns * sizeof *sf);
    (void)MPI_Alltoallv(sf, rc, rd, MPI_FLOAT, rf, sc, sd, MPI_FLOAT, X->comm);
    for (size_t q = 0; q < R->used; q++)
        memcpy(R->sol + X->order[q] * (size_t)ns, rf + q * (size_t)ns, (size_t)ns * sizeof *rf);
out:
    free(sbuf);
    free(rbuf);
    free(c4);
    return st;
}

static hv_status dist_solve(void *user, hv_extender *e, int l, int nrhs, int nfields,
                            const hv_extend_field *f, double *thr, hv_extend_stats *S)
{
    hv_dmda_extender *X = user;
    hv_status st;
    if (!X->sv[l]) {
        hv_solver_opts so;
        hv_solver_opts_default(&so);
        so.tol = e->o.tol;
        so.max_iter = 500;
        /* Short times (those the band solve takes in one process) are well
         * conditioned: Jacobi-preconditioned CG, nothing to set up. */
        const double ts = e->o.t_scale * pow(LEVEL_FACTOR, l), t = ts * X->h * X->h;
        if ((st = hv__dmda_solver_create(&X->sv[l], X->user, X->h, 1.0, t, NULL, &so,
                                         ts <= BAND_MAX_T_SCALE ? HV_PC_JACOBI : -1)))
            return st;
    }
    Vec b = hv__dmda_rhs(X->sv[l]);
    const size_t k = (size_t)e->nsol;
    double relmax = 0, wn = 0;
    for (int r = 0; r < nrhs; r++) {
        const rhs_part p = rhs_locate(r, nfields, f);
        PetscScalar *a;
        HV_PETSC_CHK(VecGetArray(b, &a), "VecGetArray");
        size_t q = 0;
        for (PetscInt kk = X->xs[2]; kk < X->xs[2] + X->xm[2]; kk++)
            for (PetscInt j = X->xs[1]; j < X->xs[1] + X->xm[1]; j++)
                for (PetscInt i = X->xs[0]; i < X->xs[0] + X->xm[0]; i++, q++)
                    a[q] = rhs_value(e, f, p, local_cell(X, i, j, kk));
        VecRestoreArray(b, &a);
        if (r == 0) {
            PetscReal n2;
            HV_PETSC_CHK(VecNorm(b, NORM_2, &n2), "VecNorm");
            wn = n2;
        }
        hv_solve_info info;
        if (!X->x) /* the solutions of levels past the band solve */
            HV_PETSC_CHK(DMCreateGlobalVector(X->user, &X->x), "DMCreateGlobalVector");
        if ((st = hv__dmda_solve(X->sv[l], X->x, &info)))
            return st;
        relmax = fmax(relmax, info.relres);
        /* The solution on the ghosted box. */
        HV_PETSC_CHK(DMGlobalToLocalBegin(X->dag, X->x, INSERT_VALUES, X->gl), "DMGlobalToLocal");
        HV_PETSC_CHK(DMGlobalToLocalEnd(X->dag, X->x, INSERT_VALUES, X->gl), "DMGlobalToLocal");
        const PetscScalar *u;
        HV_PETSC_CHK(VecGetArrayRead(X->gl, &u), "VecGetArrayRead");
        for (size_t c = 0; c < X->nloc; c++)
            e->sol[c * k + (size_t)r] = (float)u[c];
        VecRestoreArrayRead(X->gl, &u);
        S->solves++;
    }
    S->relres = fmax(S->relres, relmax);
    if (l == 0)
        S->solve_cells = X->nown;
    *thr = fmax(RELIABLE * fmax(fmax(relmax, e->o.tol), 1e-14) * wn, 1e-30);
    return HV_OK;
}

static double dist_max(void *user, double v)
{
    hv_dmda_extender *X = user;
    double m = v;
    MPI_Allreduce(&v, &m, 1, MPI_DOUBLE, MPI_MAX, X->comm);
    return m;
}

static hv_status create(hv_dmda_extender *X, DM da, double h, const hv_extend_opts *o)
{
    HV_PETSC_CHK(PetscObjectReference((PetscObject)da), "PetscObjectReference");
    X->user = da;
    X->comm = PetscObjectComm((PetscObject)da);
    X->h = h;
    PetscInt dim = 3;
    HV_PETSC_CHK(DMDAGetInfo(da, &dim, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL,
                             NULL, NULL),
                 "DMDAGetInfo (is it a DMDA?)");
    /* The ghost layer: what a cell's closest point reaches (out_band voxels
     * along a gradient up to GRAD_MAX, its interpolation stencil and the
     * gradient's), plus, for level 0 on the band, what the band solve of
     * those cells depends on: its sweeps reach one cell each, from a band
     * grown by BOX_MARGIN sqrt(t) around the cells read, whose marks come
     * from closest points as far again. The band solve takes it when the
     * layer stays under MAX_GHOST cells; else level 0 is solved over all
     * ranks as the others are. */
    hv_extender probe;
    memset(&probe, 0, sizeof probe);
    probe.dim = (int)dim;
    probe.o = *o;
    /* Every cell (out_band 0): the layer of the weights' closest points;
     * closest points past it are read from their owners (dist_remote). */
    const double ob = o->out_band > 0 ? o->out_band : fmax(o->band, 1.0);
    const int reach = (int)ceil(GRAD_MAX * ob) + 2;
    const int band_ghost = 2 * reach + hv__extend_band_iters(&probe, o->t_scale) + 2 +
                           (int)lround(BOX_MARGIN * sqrt(o->t_scale));
    /* A DMDA's ghost layer comes from the next rank only: no wider than the
     * narrowest box. */
    PetscInt m[3] = {1, 1, 1}, narrow = PETSC_MAX_INT;
    const PetscInt *l[3] = {NULL, NULL, NULL};
    HV_PETSC_CHK(DMDAGetInfo(da, NULL, NULL, NULL, NULL, &m[0], &m[1], &m[2], NULL, NULL, NULL,
                             NULL, NULL, NULL),
                 "DMDAGetInfo");
    HV_PETSC_CHK(DMDAGetOwnershipRanges(da, &l[0], &l[1], &l[2]), "DMDAGetOwnershipRanges");
    for (int a = 0; a < dim; a++)
        for (PetscInt r = 0; r < m[a]; r++)
            if (m[a] > 1 && l[a][r] < narrow)
                narrow = l[a][r];
    X->dist.band0 = o->t_scale <= BAND_MAX_T_SCALE && !o->box_only && band_ghost <= MAX_GHOST &&
                    band_ghost <= narrow;
    X->ghost = X->dist.band0 ? band_ghost : reach;
    if (X->ghost > narrow)
        return hv__error(HV_ERR_INVALID_ARG,
                         "extend: out_band %g needs a ghost layer of %d cells, and the narrowest "
                         "rank's box is %d cells wide (fewer ranks, or a narrower band)",
                         ob, X->ghost, (int)narrow);
    hv_status st = hv__dmda_like(da, X->ghost, 1, &X->dag, &X->dim);
    if (st)
        return st;
    HV_PETSC_CHK(DMCreateLocalVector(X->dag, &X->gl), "DMCreateLocalVector");
    DMDAGetCorners(X->dag, &X->xs[0], &X->xs[1], &X->xs[2], &X->xm[0], &X->xm[1], &X->xm[2]);
    DMDAGetGhostCorners(X->dag, &X->gs[0], &X->gs[1], &X->gs[2], &X->gm[0], &X->gm[1], &X->gm[2]);
    if (X->dim == 2) {
        X->xs[2] = X->gs[2] = 0;
        X->xm[2] = X->gm[2] = 1;
    }
    X->nloc = (size_t)X->gm[0] * X->gm[1] * X->gm[2];
    X->nown = (size_t)X->xm[0] * X->xm[1] * X->xm[2];
    hv_extend_opts eo = *o;
    eo.backend = HV_BACKEND_MG; /* the band solve on level 0; the others are the hook's */
    const int n[3] = {(int)X->gm[0], (int)X->gm[1], (int)X->gm[2]};
    if ((st = hv_extender_create(&X->e, X->dim, n, h, NULL, &eo)))
        return st;
    X->dist.user = X;
    X->dist.sum = dist_sum;
    X->dist.max = dist_max;
    for (int a = 0; a < 3; a++) {
        X->dist.own_lo[a] = (int)(X->xs[a] - X->gs[a]);
        X->dist.own_hi[a] = (int)(X->xs[a] - X->gs[a] + X->xm[a] - 1);
    }
    X->dist.solve = dist_solve;
    /* Closest points past the box. */
    PetscInt N[3] = {1, 1, 1};
    HV_PETSC_CHK(DMDAGetInfo(da, NULL, &N[0], &N[1], &N[2], NULL, NULL, NULL, NULL, NULL, NULL,
                             NULL, NULL, NULL),
                 "DMDAGetInfo");
    int P = 0;
    MPI_Comm_size(X->comm, &P);
    if (!(X->sc = malloc(4 * (size_t)P * sizeof *X->sc)))
        return hv__error(HV_ERR_NOMEM, "extend: out of memory");
    X->sd = X->sc + P;
    X->rc = X->sc + 2 * P;
    X->rd = X->sc + 3 * P;
    for (int a = 0; a < 3; a++) {
        X->mr[a] = a < X->dim ? m[a] : 1;
        if (!(X->first[a] = malloc((size_t)(X->mr[a] + 1) * sizeof *X->first[a])))
            return hv__error(HV_ERR_NOMEM, "extend: out of memory");
        X->first[a][0] = 0;
        for (PetscInt r = 0; r < X->mr[a]; r++)
            X->first[a][r + 1] = X->first[a][r] + (a < X->dim ? l[a][r] : 1);
        X->rem.go[a] = (int)X->gs[a];
        X->rem.gn[a] = a < X->dim ? (int)N[a] : 1;
        X->rem.cut[a][0] = X->gs[a] > 0;
        X->rem.cut[a][1] = X->gs[a] + X->gm[a] < X->rem.gn[a];
        /* Level 0 by the band solve on the box is the one process's within
         * reach of the owned cells only (the layer's design, above): points
         * that far read the box, so that their stencils stay within reach
         * (as an output band's do); points past them read the owners'.
         * Solved over all ranks, the whole layer holds the solutions. */
        X->rem.lo[a] = X->dist.band0 ? X->dist.own_lo[a] - (reach - 2) : 0;
        X->rem.hi[a] = X->dist.band0 ? X->dist.own_hi[a] + (reach - 2) : n[a] - 1;
    }
    X->dist.rem = &X->rem;
    X->dist.remote = dist_remote;
    X->e->dist = &X->dist;
    return HV_OK;
}

static hv_status hv_dmda_extender_create_body(hv_dmda_extender **out, DM da, double h,
                                              const hv_extend_opts *opts)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_dmda_extender_create: out is NULL");
    *out = NULL;
    hv_extend_opts o;
    hv_extend_opts_default(&o);
    if (opts)
        o = *opts;
    if (!(h > 0) || !isfinite(h))
        return hv__error(HV_ERR_INVALID_ARG, "hv_dmda_extender_create: h must be > 0, got %g", h);
    if (!(o.out_band >= 0) || o.out_band > 64)
        return hv__error(HV_ERR_INVALID_ARG,
                         "hv_dmda_extender_create: out_band must lie in [0, 64] voxels (0: every "
                         "cell; the ghost layer grows with it), got %g",
                         o.out_band);
    hv_status st = hv_petsc_init();
    if (st)
        return st;
    hv_dmda_extender *X = calloc(1, sizeof *X);
    if (!X)
        return hv__error(HV_ERR_NOMEM, "extend: out of memory");
    if ((st = create(X, da, h, &o))) {
        hv_dmda_extender_destroy(&X);
        return st;
    }
    *out = X;
    return HV_OK;
}

static hv_status extend(hv_dmda_extender *X, Vec phi, int nfields, const hv_dmda_field *fields,
                        hv_extend_stats *stats, float *work)
{
    hv_status st;
    float *lphi = work;
    hv_extend_field ef[MAX_FIELDS_PER_CALL];
    float *w = work + X->nloc;
    if ((st = to_local(X, phi, lphi)))
        return st;
    for (int i = 0; i < nfields; i++) {
        ef[i].ncomp = fields[i].ncomp;
        for (int c = 0; c < 3; c++) {
            ef[i].in[c] = NULL;
            ef[i].out[c] = NULL;
        }
        for (int c = 0; c < fields[i].ncomp; c++) {
            if ((st = to_local(X, fields[i].v[c], w)))
                return st;
            ef[i].in[c] = w;
            ef[i].out[c] = w + X->nloc;
            w += 2 * X->nloc;
        }
    }
    if ((st = hv_extend_many(X->e, lphi, nfields, ef, stats)))
        return st;
    /* Back into the caller's vectors: this rank's cells inside the output band. */
    const double ob = X->e->o.out_band * X->h;
    for (int i = 0; i < nfields; i++)
        for (int c = 0; c < fields[i].ncomp; c++) {
            PetscScalar *a;
            HV_PETSC_CHK(VecGetArray(fields[i].v[c], &a), "VecGetArray");
            size_t q = 0;
            for (PetscInt k = X->xs[2]; k < X->xs[2] + X->xm[2]; k++)
                for (PetscInt j = X->xs[1]; j < X->xs[1] + X->xm[1]; j++)
                    for (PetscInt ii = X->xs[0]; ii < X->xs[0] + X->xm[0]; ii++, q++) {
                        const size_t lc = local_cell(X, ii, j, k);
                        if (!(ob > 0) || fabs(lphi[lc]) < ob)
                            a[q] = ef[i].out[c][lc];
                    }
            VecRestoreArray(fields[i].v[c], &a);
        }
    return HV_OK;
}

static hv_status hv_dmda_extend_body(hv_dmda_extender *X, Vec phi, int nfields,
                                     const hv_dmda_field *fields, hv_extend_stats *stats)
{
    if (!X || !phi || nfields < 0 || nfields > MAX_FIELDS_PER_CALL || (nfields && !fields))
        return hv__error(HV_ERR_INVALID_ARG, "hv_dmda_extend: bad arguments");
    size_t ncomp = 0;
    for (int i = 0; i < nfields; i++) {
        if (fields[i].ncomp < 1 || fields[i].ncomp > 3)
            return hv__error(HV_ERR_INVALID_ARG, "hv_dmda_extend: field %d has %d components", i,
                             fields[i].ncomp);
        for (int c = 0; c < fields[i].ncomp; c++)
            if (!fields[i].v[c])
                return hv__error(HV_ERR_INVALID_ARG,
                                 "hv_dmda_extend: field %d component %d has no vector", i, c);
        ncomp += (size_t)fields[i].ncomp;
    }
    /* The vectors must be global vectors of the DMDA on every rank. */
    hv_status st = HV_OK;
    PetscInt nl = -1;
    VecGetLocalSize(phi, &nl);
    for (int i = 0; i < nfields && (size_t)nl == X->nown; i++)
        for (int c = 0; c < fields[i].ncomp && (size_t)nl == X->nown; c++)
            VecGetLocalSize(fields[i].v[c], &nl);
    if ((size_t)nl != X->nown)
        st = hv__error(HV_ERR_INVALID_ARG,
                       "hv_dmda_extend: phi and the fields must be global vectors of the "
                       "extender's DMDA (%d cells on this rank, not %d)",
                       (int)nl, (int)X->nown);
    float *work = st ? NULL : malloc((1 + 2 * ncomp) * X->nloc * sizeof *work);
    if (!st && !work)
        st = hv__error(HV_ERR_NOMEM, "extend: out of memory");
    /* Every rank must reach the collective calls, or none. */
    if (dist_sum(X, st != HV_OK)) {
        free(work);
        return st ? st : hv__error(HV_ERR_NOMEM, "extend: out of memory on another rank");
    }
    st = extend(X, phi, nfields, fields, stats, work);
    free(work);
    return st;
}

int hv_dmda_extender_ghost(const hv_dmda_extender *X, int *band0)
{
    if (band0)
        *band0 = X ? X->dist.band0 : 0;
    return X ? X->ghost : 0;
}

void hv_dmda_extender_destroy(hv_dmda_extender **xp)
{
    if (!xp || !*xp)
        return;
    hv_dmda_extender *X = *xp;
    for (int l = 0; l < MAX_LEVELS; l++)
        hv_dmda_solver_destroy(&X->sv[l]);
    hv_extender_destroy(&X->e);
    free(X->rem.key);
    free(X->rem.phi);
    free(X->rem.sol);
    free(X->rem.read);
    free(X->order);
    free(X->serve);
    free(X->sc);
    for (int a = 0; a < 3; a++)
        free(X->first[a]);
    VecDestroy(&X->x);
    VecDestroy(&X->gl);
    DMDestroy(&X->dag);
    DMDestroy(&X->user);
    free(X);
    *xp = NULL;
}

static hv_status extend_block(hv_block_io *B, const hv_extend_opts *o, double h, const float *phi,
                              int nfields, const hv_extend_field *f, hv_extend_stats *stats, Vec *v)
{
    for (int i = 0, q = 0; i < nfields; i++)
        for (int c = 0; c < f[i].ncomp; c++, q++)
            HV_PETSC_CHK(DMCreateGlobalVector(B->da, &v[q]), "DMCreateGlobalVector");
    Vec gphi;
    HV_PETSC_CHK(DMCreateGlobalVector(B->da, &gphi), "DMCreateGlobalVector");
    hv_status st = hv__block_in(B, phi, NULL, gphi);
    hv_dmda_field df[MAX_FIELDS_PER_CALL];
    for (int i = 0, q = 0; i < nfields && !st; i++) {
        df[i].ncomp = f[i].ncomp;
        for (int c = 0; c < 3; c++)
            df[i].v[c] = c < f[i].ncomp ? v[q + c] : NULL;
        for (int c = 0; c < f[i].ncomp && !st; c++)
            st = hv__block_in(B, phi ? f[i].in[c] : NULL, NULL, v[q + c]);
        q += f[i].ncomp;
    }
    hv_dmda_extender *X = NULL;
    if (!st)
        st = hv_dmda_extender_create(&X, B->da, h, o);
    if (!st)
        st = hv_dmda_extend(X, gphi, nfields, df, stats);
    hv_dmda_extender_destroy(&X);
    /* Rank 0: the band's values, the background elsewhere. */
    const double ob = o->out_band * h;
    for (int i = 0, q = 0; i < nfields && !st; i++)
        for (int c = 0; c < f[i].ncomp && !st; c++, q++) {
            float *out = phi ? f[i].out[c] : NULL;
            st = hv__block_out(B, v[q], out);
            for (size_t k = 0; out && ob > 0 && k < B->count; k++)
                if (!(fabs(phi[k]) < ob))
                    out[k] = o->background;
        }
    VecDestroy(&gphi);
    return st;
}

static hv_status hv_petsc_extend_block_body(int dim, const int n[3], double h,
                                            const hv_extend_opts *opts, const float *phi,
                                            int nfields, const hv_extend_field *f,
                                            hv_extend_stats *stats)
{
    if ((dim != 2 && dim != 3) || !n || !opts || nfields < 1 || nfields > MAX_FIELDS_PER_CALL || !f)
        return hv__error(HV_ERR_INVALID_ARG, "hv_petsc_extend_block: bad arguments");
    int ncomp = 0;
    for (int i = 0; i < nfields; i++) {
        if (f[i].ncomp < 1 || f[i].ncomp > 3)
            return hv__error(HV_ERR_INVALID_ARG,
                             "hv_petsc_extend_block: field %d has %d components", i, f[i].ncomp);
        ncomp += f[i].ncomp;
    }
    hv_status st = hv_petsc_init();
    if (st)
        return st;
    /* Rank 0's block is the block: its shape and voxel size go to every rank,
     * and with them whether rank 0 has one (no level set: it failed to read
     * it, and every rank returns). */
    int rank = 0;
    MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
    double hdr[5] = {phi != NULL, n[0], n[1], n[2], h};
    (void)MPI_Bcast(hdr, 5, MPI_DOUBLE, 0, PETSC_COMM_WORLD);
    if (!hdr[0])
        return rank ? hv__error(HV_ERR_INVALID_ARG, "extend: rank 0 has no block to extend")
                    : hv__error(HV_ERR_INVALID_ARG, "hv_petsc_extend_block: no level set");
    const int nb[3] = {(int)hdr[1], (int)hdr[2], (int)hdr[3]};
    h = hdr[4];
    hv_block_io B;
    Vec *v = calloc((size_t)ncomp, sizeof *v);
    st = v ? HV_OK : hv__error(HV_ERR_NOMEM, "extend: out of memory");
    int bad = st != HV_OK, anybad = 0;
    MPI_Allreduce(&bad, &anybad, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
    if (anybad) {
        free(v);
        return st ? st : hv__error(HV_ERR_NOMEM, "extend: out of memory on another rank");
    }
    if (!(st = hv__block_create(&B, dim, nb)))
        st = extend_block(&B, opts, h, rank ? NULL : phi, nfields, f, stats, v);
    for (int q = 0; q < ncomp; q++)
        VecDestroy(&v[q]);
    free(v);
    hv__block_destroy(&B);
    return st;
}

hv_status hv_dmda_extender_create(hv_dmda_extender **out, DM da, double h,
                                  const hv_extend_opts *opts)
{
    HV_PETSC_QUIETLY(hv_dmda_extender_create_body(out, da, h, opts));
}

hv_status hv_dmda_extend(hv_dmda_extender *X, Vec phi, int nfields, const hv_dmda_field *fields,
                         hv_extend_stats *stats)
{
    HV_PETSC_QUIETLY(hv_dmda_extend_body(X, phi, nfields, fields, stats));
}

hv_status hv_petsc_extend_block(int dim, const int n[3], double h, const hv_extend_opts *opts,
                                const float *phi, int nfields, const hv_extend_field *f,
                                hv_extend_stats *stats)
{
    HV_PETSC_QUIETLY(hv_petsc_extend_block_body(dim, n, h, opts, phi, nfields, f, stats));
}

#else /* without PETSc */

hv_status hv_petsc_extend_block(int dim, const int n[3], double h, const hv_extend_opts *opts,
                                const float *phi, int nfields, const hv_extend_field *f,
                                hv_extend_stats *stats)
{
    (void)dim;
    (void)n;
    (void)h;
    (void)opts;
    (void)phi;
    (void)nfields;
    (void)f;
    (void)stats;
    return hv__error(HV_ERR_UNSUPPORTED,
                     "the distributed extension needs heatvox built with MPI and PETSc (make mpi)");
}

hv_status hv_dmda_extender_create(hv_dmda_extender **out, DM da, double h,
                                  const hv_extend_opts *opts)
{
    (void)da;
    (void)h;
    (void)opts;
    if (out)
        *out = NULL;
    return hv__error(HV_ERR_UNSUPPORTED,
                     "the extension on a DMDA needs heatvox built with MPI and PETSc (make mpi)");
}

hv_status hv_dmda_extend(hv_dmda_extender *e, Vec phi, int nfields, const hv_dmda_field *fields,
                         hv_extend_stats *stats)
{
    (void)e;
    (void)phi;
    (void)nfields;
    (void)fields;
    (void)stats;
    return hv__error(HV_ERR_UNSUPPORTED, "the extension on a DMDA is not in this build");
}

int hv_dmda_extender_ghost(const hv_dmda_extender *e, int *band0)
{
    (void)e;
    if (band0)
        *band0 = 0;
    return 0;
}

void hv_dmda_extender_destroy(hv_dmda_extender **e)
{
    if (e)
        *e = NULL;
}

#endif
