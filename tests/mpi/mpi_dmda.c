/* The solver and the extension on a caller's DMDA (petsc.h) under mpirun
 * (make mpi-check runs it on 1 to 4 ranks). Every rank also computes the
 * single-process answer on the whole grid (mg) and compares its own cells:
 *   - solves: heat steps and Neumann Poisson, 2D and 3D, odd sizes, solids
 *     crossing rank boundaries, a box cut in two by a wall (two regions,
 *     labelled across the ranks), to 1e-6 relative; with the automatic choice
 *     (PFMG in 3D unless Poisson has several regions, else BoomerAMG), and the
 *     3D cases with solids with BoomerAMG, GAMG and (one region) PFMG too;
 *   - the extension off a sphere and a torus, a sphere moved between two
 *     calls of one extender, to 1e-5 relative on the output band, within 0.02
 *     of the exact extension, the cells outside the band untouched;
 *   - a NaN in the level set on one rank: HV_ERR_NUMERIC on every rank, the
 *     fields unchanged;
 *   - the distance from points, voxels and a sphere mesh, without solids,
 *     around a ball and baffles (2D and 3D), in a box cut in two by a wall
 *     with a source on one side, an object reused with other sources: equal
 *     to the single process's to 1e-3 voxel and 1e-5 relative, the same
 *     unreachable and solid cells and the same counts (stages, regions,
 *     source cells, sources in solid); a voxel outside the grid: the same
 *     error on every rank.
 * Rank 0 prints one line per case; the exit status is 0 only when every case
 * passes on every rank. */
#include "heatvox/heatvox.h"
#include "mpi_cases.h"

#include <petscdmda.h>

#include <math.h>
#include <mpi.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int rank;

/* 1 when every rank says ok; rank 0 prints the line. */
static int report(int ok, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static int report(int ok, const char *fmt, ...)
{
    int all = 0;
    MPI_Allreduce(&ok, &all, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
    if (rank == 0) {
        va_list ap;
        va_start(ap, fmt);
        printf("  ");
        vprintf(fmt, ap);
        printf("%s\n", all ? "" : "  FAILED");
        va_end(ap);
    }
    return all;
}

static DM make_da(int dim, const int n[3])
{
    DM da;
    if (dim == 3)
        DMDACreate3d(PETSC_COMM_WORLD, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE,
                     DMDA_STENCIL_STAR, n[0], n[1], n[2], PETSC_DECIDE, PETSC_DECIDE, PETSC_DECIDE,
                     1, 1, NULL, NULL, NULL, &da);
    else
        DMDACreate2d(PETSC_COMM_WORLD, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE, DMDA_STENCIL_STAR, n[0],
                     n[1], PETSC_DECIDE, PETSC_DECIDE, 1, 1, NULL, NULL, &da);
    DMSetUp(da);
    return da;
}

/* Calls fn(c, q) for this rank's cells: c the whole grid's index, q the
 * global vector's local index. */
#define FOR_OWNED(da, dim, n, body)                                                                \
    do {                                                                                           \
        PetscInt xs_, ys_, zs_, xm_, ym_, zm_;                                                     \
        DMDAGetCorners(da, &xs_, &ys_, &zs_, &xm_, &ym_, &zm_);                                    \
        if ((dim) == 2) {                                                                          \
            zs_ = 0;                                                                               \
            zm_ = 1;                                                                               \
        }                                                                                          \
        size_t q = 0;                                                                              \
        for (PetscInt k_ = zs_; k_ < zs_ + zm_; k_++)                                              \
            for (PetscInt j_ = ys_; j_ < ys_ + ym_; j_++)                                          \
                for (PetscInt i_ = xs_; i_ < xs_ + xm_; i_++, q++) {                               \
                    const size_t c = i_ + (size_t)(n)[0] * (j_ + (size_t)(n)[1] * k_);             \
                    body;                                                                          \
                }                                                                                  \
    } while (0)

typedef struct {
    const char *name;
    int dim, n[3];
    double alpha, beta;
    int solid; /* MPI_SOLID_* (mpi_cases.h) */
    int regions;
} scase;

static int solve_case(const scase *k)
{
    const int nz = k->dim == 3 ? k->n[2] : 1;
    const size_t count = (size_t)k->n[0] * k->n[1] * nz;
    double *f = malloc(count * sizeof *f), *b = malloc(count * sizeof *b);
    uint8_t *solid = calloc(count, 1);
    unsigned seed = 777;
    for (int z = 0; z < nz; z++)
        for (int y = 0; y < k->n[1]; y++)
            for (int x = 0; x < k->n[0]; x++) {
                const size_t c = x + (size_t)k->n[0] * (y + (size_t)k->n[1] * z);
                f[c] = mpi_rnd(&seed);
                solid[c] = mpi_solid(k->solid, k->n, x, y, z);
            }
    const double h = 1.0 / k->n[0];
    hv_problem p = {k->dim, {k->n[0], k->n[1], k->n[2]}, h, k->solid ? solid : NULL, k->alpha,
                    k->beta};
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.tol = 1e-10;
    o.max_iter = 500;
    o.backend = HV_BACKEND_MG;
    hv_solver *sm = NULL;
    hv_solve_info im, id;
    if (hv_solver_create(&sm, &p, &o) || hv_solver_solve_d(sm, f, b, &im)) {
        fprintf(stderr, "mpi_dmda: %s: mg: %s\n", k->name, hv_last_error());
        return 0;
    }
    hv_solver_destroy(&sm);
    DM da = make_da(k->dim, k->n);
    Vec vf, vu, vs;
    DMCreateGlobalVector(da, &vf);
    VecDuplicate(vf, &vu);
    VecDuplicate(vf, &vs);
    PetscScalar *af, *as;
    VecGetArray(vf, &af);
    VecGetArray(vs, &as);
    FOR_OWNED(da, k->dim, k->n, {
        af[q] = f[c];
        as[q] = solid[c];
    });
    VecRestoreArray(vf, &af);
    VecRestoreArray(vs, &as);
    hv_dmda_solver *s = NULL;
    hv_status st = hv_dmda_solver_create(&s, da, h, k->alpha, k->beta, k->solid ? vs : NULL, &o);
    if (!st)
        st = hv_dmda_solver_solve(s, vf, vu, &id);
    if (st)
        fprintf(stderr, "mpi_dmda: %s: %s\n", k->name, hv_last_error());
    double dmax = 0, umax = 0;
    if (!st) {
        const PetscScalar *au;
        VecGetArrayRead(vu, &au);
        FOR_OWNED(da, k->dim, k->n, {
            dmax = fmax(dmax, fabs(au[q] - b[c]));
            umax = fmax(umax, fabs(b[c]));
        });
        VecRestoreArrayRead(vu, &au);
    }
    double worst = 0, um = 0;
    MPI_Allreduce(&dmax, &worst, 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
    MPI_Allreduce(&umax, &um, 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
    const int regions = hv_dmda_solver_regions(s);
    const int ok = report(!st && worst / um <= 1e-6 && id.reason == HV_STOP_CONVERGED &&
                              (k->alpha > 0 || regions == k->regions),
                          "solver on a DMDA, %-38s %d ranks: %3d iterations (mg %2d, %s), %d "
                          "regions, max relative difference to mg %.2e",
                          k->name, hv_mpi_size(), id.iterations, im.iterations,
                          hv_stop_reason_str(id.reason), regions, worst / um);
    hv_dmda_solver_destroy(&s);
    VecDestroy(&vf);
    VecDestroy(&vu);
    VecDestroy(&vs);
    DMDestroy(&da);
    free(f);
    free(b);
    free(solid);
    return ok;
}

/* ---- the extension ---------------------------------------------------------- */

enum { SPHERE, TORUS, SMALL_SPHERE };

/* phi and the closest point of cell centre x (box [0, 1]^3). */
static double shape(int which, const double c0[3], const double x[3], double cp[3])
{
    if (which != TORUS) {
        const double d[3] = {x[0] - c0[0], x[1] - c0[1], x[2] - c0[2]};
        const double r = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]),
                     R = which == SPHERE ? 0.3 : 0.15;
        for (int a = 0; a < 3; a++)
            cp[a] = c0[a] + d[a] * R / fmax(r, 1e-12);
        return r - R;
    }
    const double R = 0.28, r0 = 0.1, px = x[0] - c0[0], py = x[1] - c0[1], pz = x[2] - c0[2];
    const double q = sqrt(px * px + py * py);
    const double ring[3] = {px * R / q, py * R / q, 0};
    const double d[3] = {px - ring[0], py - ring[1], pz - ring[2]};
    const double dn = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    for (int a = 0; a < 3; a++)
        cp[a] = c0[a] + ring[a] + d[a] * r0 / fmax(dn, 1e-12);
    return dn - r0;
}

static void velocity(const double p[3], double v[3])
{
    v[0] = sin(3 * p[0]) + p[2];
    v[1] = cos(2 * p[1]);
    v[2] = p[0] * p[1] - 0.5 * p[2];
}

typedef struct {
    int n;
    float *phi, *in[3], *ref[3];
    double *exact[3];
} ext_data;

static void ext_make(ext_data *D, int which, const double c0[3])
{
    const int n = D->n;
    const size_t count = (size_t)n * n * n;
    const double h = 1.0 / n;
    for (size_t c = 0; c < count; c++) {
        const double x[3] = {(c % n + 0.5) * h, (c / n % n + 0.5) * h, (c / n / n + 0.5) * h};
        double cp[3], v[3];
        const double phi = shape(which, c0, x, cp);
        velocity(cp, v);
        D->phi[c] = (float)phi;
        for (int a = 0; a < 3; a++) {
            D->exact[a][c] = v[a];
            D->in[a][c] = fabs(phi) < 1.5 * h ? (float)v[a] : 5.0f;
        }
    }
}

/* The single-process answer: hv_extend_many with mg, with o's box_only (the
 * band solve, or every level solved to the tolerance).
 *
 * Cells read at themselves (where phi is no distance: a torus's axis) take
 * the first level whose weight passes the solve's trust bound. One process
 * solves level 1 on a band too, whose bound is looser than the ranks'
 * solves of that level (and of level 0 when the boxes are too narrow for
 * the band), so such cells may settle a level later: on the torus's axis
 * they lie 4.7e-2 (relative) apart, as one process's own two solvers
 * (box_only or not) do. EXT_DENSE_EXACT compares them. */
static int ext_reference(ext_data *D, const hv_extend_opts *o)
{
    const int n3[3] = {D->n, D->n, D->n};
    hv_extend_opts so = *o;
    so.backend = HV_BACKEND_MG;
    hv_extender *e = NULL;
    hv_extend_field f = {3, {D->in[0], D->in[1], D->in[2]}, {D->ref[0], D->ref[1], D->ref[2]}};
    if (hv_extender_create(&e, 3, n3, 1.0 / D->n, NULL, &so) || hv_extend_many(e, D->phi, 1, &f, NULL)) {
        fprintf(stderr, "mpi_dmda: reference: %s\n", hv_last_error());
        hv_extender_destroy(&e);
        return 0;
    }
    hv_extender_destroy(&e);
    return 1;
}

/* One call of X on D's input; compares with D's reference. */
static int ext_check(hv_dmda_extender *X, DM da, ext_data *D, const hv_extend_opts *o,
                     const char *name)
{
    const int n3[3] = {D->n, D->n, D->n};
    const double h = 1.0 / D->n, ob = o->out_band * h;
    Vec phi, v[3];
    DMCreateGlobalVector(da, &phi);
    for (int a = 0; a < 3; a++)
        VecDuplicate(phi, &v[a]);
    PetscScalar *p;
    VecGetArray(phi, &p);
    FOR_OWNED(da, 3, n3, p[q] = D->phi[c]);
    VecRestoreArray(phi, &p);
    for (int a = 0; a < 3; a++) {
        VecGetArray(v[a], &p);
        FOR_OWNED(da, 3, n3, p[q] = D->in[a][c]);
        VecRestoreArray(v[a], &p);
    }
    hv_dmda_field f = {3, {v[0], v[1], v[2]}};
    hv_extend_stats S;
    hv_status st = hv_dmda_extend(X, phi, 1, &f, &S);
    if (st)
        fprintf(stderr, "mpi_dmda: %s: %s\n", name, hv_last_error());
    double dmax = 0, rmax = 0, emax = 0, eref = 0;
    int untouched = 1;
    for (int a = 0; a < 3 && !st; a++) {
        const PetscScalar *r;
        VecGetArrayRead(v[a], &r);
        FOR_OWNED(da, 3, n3, {
            if (!(ob > 0) || fabs(D->phi[c]) < ob) {
                dmax = fmax(dmax, fabs(r[q] - D->ref[a][c]));
                rmax = fmax(rmax, fabs(D->ref[a][c]));
                emax = fmax(emax, fabs(r[q] - D->exact[a][c]));
                eref = fmax(eref, fabs(D->ref[a][c] - D->exact[a][c]));
            } else if (r[q] != D->in[a][c]) {
                untouched = 0;
            }
        });
        VecRestoreArrayRead(v[a], &r);
    }
    double g[4] = {dmax, rmax, emax, eref}, G[4];
    MPI_Allreduce(g, G, 4, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
    unsigned long long rem = st ? 0 : S.remote_cells, remote = 0;
    MPI_Allreduce(&rem, &remote, 1, MPI_UNSIGNED_LONG_LONG, MPI_SUM, MPI_COMM_WORLD);
    /* Every cell on 2 or more ranks, a small sphere in a corner: the other
     * boxes' closest points lie past their ghost layers (or, with the band
     * solve on each box, past the part of it that holds level 0). */
    const int want_remote = !(ob > 0) && hv_mpi_size() > 1 && strstr(name, "corner");
    /* Every cell: as accurate as one process (whose error grows away from
     * the surface, where closest points of float phi are less exact). */
    const double elim = ob > 0 ? 0.02 : fmax(0.02, 1.001 * G[3] + 1e-4);
    const int ok = report(!st && untouched && G[0] <= 1e-5 * G[1] && G[2] <= elim &&
                              (!want_remote || remote > (unsigned long long)D->n * D->n * D->n / 8),
                          "extension on a DMDA, %-28s %d ranks: %d levels, %d solves, %llu "
                          "cells read past the ghost layer; max relative difference to one "
                          "process %.1e; max error %.4f (one process %.4f)",
                          name, hv_mpi_size(), S.levels, S.solves, remote, G[0] / G[1], G[2],
                          G[3]);
    for (int a = 0; a < 3; a++)
        VecDestroy(&v[a]);
    VecDestroy(&phi);
    return ok;
}

/* What extend_cases extends: the band |phi| < 3 voxels; every cell (out_band
 * 0: closest points lie past the ghost layer, on other ranks' boxes, and are
 * read from them); every cell with every level solved to the tolerance
 * (box_only; see ext_reference). */
enum { EXT_BAND, EXT_DENSE, EXT_DENSE_EXACT };

/* split: boxes along x and y only. */
static int extend_cases(int n, int split, int mode)
{
    const int dense = mode != EXT_BAND;
    ext_data D = {n, NULL, {NULL}, {NULL}, {NULL}};
    const size_t count = (size_t)D.n * D.n * D.n;
    D.phi = malloc(count * sizeof *D.phi);
    for (int a = 0; a < 3; a++) {
        D.in[a] = malloc(count * sizeof *D.in[a]);
        D.ref[a] = malloc(count * sizeof *D.ref[a]);
        D.exact[a] = malloc(count * sizeof *D.exact[a]);
    }
    hv_extend_opts o;
    hv_extend_opts_default(&o);
    o.out_band = dense ? 0 : 3;
    o.box_only = mode == EXT_DENSE_EXACT;
    const int n3[3] = {D.n, D.n, D.n};
    DM da = make_da(3, n3);
    if (split) {
        /* Boxes split along x and y only, wide enough for the band solve. */
        const int P = hv_mpi_size(), mx = P == 4 ? 2 : P, my = P == 4 ? 2 : 1;
        DMDestroy(&da);
        DMDACreate3d(PETSC_COMM_WORLD, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE,
                     DMDA_STENCIL_STAR, n, n, n, mx, my, 1, 1, 1, NULL, NULL, NULL, &da);
        DMSetUp(da);
    }
    hv_dmda_extender *X = NULL;
    int ok = 1, band0 = 0;
    if (hv_dmda_extender_create(&X, da, 1.0 / D.n, &o)) {
        fprintf(stderr, "mpi_dmda: extender: %s\n", hv_last_error());
        return 0;
    }
    const int ghost = hv_dmda_extender_ghost(X, &band0);
    if (rank == 0)
        printf("  extension on a DMDA, %d^3%s: ghost layer %d cells, level 0 %s\n", n,
               mode == EXT_BAND ? "" : mode == EXT_DENSE ? ", every cell" : ", every cell, box_only",
               ghost, band0 ? "on each rank's band" : "over all ranks");
    if (split)
        ok &= report(band0, "extension on a DMDA, %d^3 split along x and y: the band solve on "
                            "each box",
                     n);
    static const struct {
        const char *name;
        int which;
        double c[3];
    } cases[] = {{"sphere", SPHERE, {0.5, 0.5, 0.5}},
                 {"torus", TORUS, {0.5, 0.5, 0.5}},
                 {"sphere moved, same extender", SPHERE, {0.45, 0.53, 0.56}},
                 {"small sphere in a corner", SMALL_SPHERE, {0.22, 0.2, 0.24}}};
    for (size_t i = 0; i < 4; i++) {
        /* The torus's axis: see ext_reference. Split boxes: the moved sphere
         * adds nothing. */
        if ((mode == EXT_DENSE && cases[i].which == TORUS) || (split && i == 2))
            continue;
        char name[64];
        snprintf(name, sizeof name, "%s%s", cases[i].name,
                 mode == EXT_BAND ? "" : mode == EXT_DENSE ? ", every cell" : ", every cell, exact");
        ext_make(&D, cases[i].which, cases[i].c);
        ok &= ext_reference(&D, &o);
        ok &= ext_check(X, da, &D, &o, name);
    }

    if (split || dense)
        goto done;
    /* A NaN on the last rank's first cell: every rank fails, nothing changes. */
    ext_make(&D, SPHERE, cases[0].c);
    Vec phi, v;
    DMCreateGlobalVector(da, &phi);
    VecDuplicate(phi, &v);
    PetscScalar *p;
    VecGetArray(phi, &p);
    FOR_OWNED(da, 3, n3, p[q] = D.phi[c]);
    if (rank == hv_mpi_size() - 1)
        p[0] = NAN;
    VecRestoreArray(phi, &p);
    VecSet(v, 2.5);
    hv_dmda_field f = {1, {v, NULL, NULL}};
    hv_status st = hv_dmda_extend(X, phi, 1, &f, NULL);
    PetscReal vmin, vmax;
    VecMin(v, NULL, &vmin);
    VecMax(v, NULL, &vmax);
    ok &= report(st == HV_ERR_NUMERIC && vmin == 2.5 && vmax == 2.5,
                 "extension on a DMDA, NaN on rank %d: %s on rank %d, fields unchanged",
                 hv_mpi_size() - 1, hv_status_str(st), rank);
    VecDestroy(&v);
    VecDestroy(&phi);
done:
    hv_dmda_extender_destroy(&X);
    DMDestroy(&da);
    free(D.phi);
    for (int a = 0; a < 3; a++) {
        free(D.in[a]);
        free(D.ref[a]);
        free(D.exact[a]);
    }
    return ok;
}

/* ---- the distance ----------------------------------------------------------- */

typedef struct {
    const char *name;
    int dim, n[3];
    int solid;    /* MPI_SOLID_* (mpi_cases.h) */
    int sources;  /* 0 a point and a voxel, 1 a point moved, 2 a sphere mesh, 3 a voxel in
                     solid, 4 the voxel on the other side of the cut */
    int keep;     /* 1: reuse the previous case's object (same grid and solid) */
} dcase;

/* The case's sources, in world coordinates of the block at origin, voxel
 * size h. */
static void dist_sources(const dcase *k, const double *org, double h, double pts[6], int vox[6],
                         hv_mesh **mesh, hv_distance_sources *src)
{
    memset(src, 0, sizeof *src);
    const double L[3] = {k->n[0] * h, k->n[1] * h, k->n[2] * h};
    const double f[2][3] = {{0.2, 0.3, 0.4}, {0.8, 0.7, 0.35}};
    const int m = k->sources == 1;
    for (int a = 0; a < 3; a++)
        pts[a] = org[a] + f[m][a] * L[a];
    if (k->dim == 2)
        pts[2] = 0;
    vox[0] = k->n[0] / 8;
    vox[1] = k->n[1] - 2;
    vox[2] = k->dim == 3 ? k->n[2] / 2 : 0;
    src->points = pts;
    src->npoints = 1;
    src->voxels = vox;
    src->nvoxels = 1;
    if (k->sources == 2) {
        const double c[3] = {org[0] + 0.3 * L[0], org[1] + 0.5 * L[1], org[2] + 0.5 * L[2]};
        hv_mesh_make_sphere(mesh, c, 0.15 * L[0], 2);
        src->mesh = *mesh;
        src->npoints = src->nvoxels = 0;
    }
    if (k->sources == 4) /* across the wall of the box cut in two */
        vox[0] = k->n[0] - 3;
    if (k->sources == 3) { /* the ball's centre: solid */
        vox[0] = k->n[0] / 2;
        vox[1] = k->n[1] / 2;
        vox[2] = k->dim == 3 ? k->n[2] / 2 : 0;
    }
}

static int distance_case(const dcase *k, hv_dmda_distance **keep, DM *kda, Vec *ksolid)
{
    const int nz = k->dim == 3 ? k->n[2] : 1;
    const double h = 1.0 / k->n[0], org[3] = {-0.75, 0.25, k->dim == 3 ? 1.5 : -0.5 * h};
    hv_grid *g = NULL;
    hv_grid_create(&g, k->dim, k->n, h, org);
    if (k->solid)
        hv_grid_add_mask(g);
    for (int z = 0; z < nz; z++)
        for (int y = 0; y < k->n[1]; y++)
            for (int x = 0; x < k->n[0]; x++) {
                const size_t c = x + (size_t)k->n[0] * (y + (size_t)k->n[1] * z);
                if (k->solid)
                    g->solid[c] = mpi_solid(k->solid, k->n, x, y, z);
            }
    double pts[6];
    int vox[6];
    hv_mesh *mesh = NULL;
    hv_distance_sources src;
    dist_sources(k, org, h, pts, vox, &mesh, &src);
    hv_distance_opts o;
    hv_distance_opts_default(&o);
    o.backend = HV_BACKEND_MG;
    o.whole_stages = 1; /* the DMDA's stages run on the whole box */
    hv_distance_stats sr, sd;
    if (hv_distance_compute(g, &src, &o, &sr)) {
        fprintf(stderr, "mpi_dmda: %s: one process: %s\n", k->name, hv_last_error());
        return 0;
    }
    if (!k->keep) {
        hv_dmda_distance_destroy(keep);
        VecDestroy(ksolid);
        DMDestroy(kda);
        *kda = make_da(k->dim, k->n);
        if (k->solid) {
            DMCreateGlobalVector(*kda, ksolid);
            PetscScalar *as;
            VecGetArray(*ksolid, &as);
            FOR_OWNED(*kda, k->dim, k->n, as[q] = g->solid[c]);
            VecRestoreArray(*ksolid, &as);
        }
    }
    hv_status st = HV_OK;
    if (!*keep)
        st = hv_dmda_distance_create(keep, *kda, h, org, *ksolid, &o);
    Vec d;
    DMCreateGlobalVector(*kda, &d);
    if (!st)
        st = hv_dmda_distance_compute(*keep, &src, d, &sd);
    if (st)
        fprintf(stderr, "mpi_dmda: %s: %s\n", k->name, hv_last_error());
    double dmax = 0, vmax = 0;
    int same_inf = 1;
    if (!st) {
        const PetscScalar *ad;
        VecGetArrayRead(d, &ad);
        FOR_OWNED(*kda, k->dim, k->n, {
            const double a = g->v[c];
            const double b = ad[q];
            if (isfinite(a) != isfinite(b))
                same_inf = 0;
            else if (isfinite(a)) {
                dmax = fmax(dmax, fabs(a - b));
                vmax = fmax(vmax, fabs(a));
            }
        });
        VecRestoreArrayRead(d, &ad);
    }
    MPI_Allreduce(MPI_IN_PLACE, &dmax, 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
    MPI_Allreduce(MPI_IN_PLACE, &vmax, 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
    const int same_stats = !st && sd.stages == sr.stages && sd.regions == sr.regions &&
                           sd.source_cells == sr.source_cells &&
                           sd.sources_in_solid == sr.sources_in_solid &&
                           sd.unreachable_cells == sr.unreachable_cells &&
                           sd.dead_faces == sr.dead_faces;
    const int ok = report(!st && same_inf && same_stats && dmax / h <= 1e-3 && dmax / vmax <= 1e-5,
                          "distance on a DMDA, %-40s %d ranks: %2d stages (one process %2d), %zu "
                          "regions, %zu source cells, %zu in solid, %zu unreachable; max "
                          "difference %.1e voxel, %.1e relative",
                          k->name, hv_mpi_size(), sd.stages, sr.stages, sd.regions,
                          sd.source_cells, sd.sources_in_solid, sd.unreachable_cells, dmax / h,
                          dmax / vmax);
    VecDestroy(&d);
    hv_mesh_destroy(&mesh);
    hv_grid_destroy(&g);
    return ok;
}

static int distance_cases(void)
{
    static const dcase cases[] = {
        {"point and voxel, 3D 29x23x19", 3, {29, 23, 19}, 0, 0, 0},
        {"point moved, same object", 3, {29, 23, 19}, 0, 1, 1},
        {"ball and baffles, 3D 36x30x26", 3, {36, 30, 26}, 1, 0, 0},
        {"ball and baffles, a voxel in solid, same object", 3, {36, 30, 26}, 1, 3, 1},
        {"cut in two, a source on one side, 3D 30x17x13", 3, {30, 17, 13}, 2, 0, 0},
        {"cut in two, a source on each side, same object", 3, {30, 17, 13}, 2, 4, 1},
        {"sphere mesh source, 3D 32x26x22", 3, {32, 26, 22}, 0, 2, 0},
        {"ball and baffles, 2D 61x47", 2, {61, 47, 1}, 1, 0, 0},
    };
    hv_dmda_distance *D = NULL;
    DM da = NULL;
    Vec solid = NULL;
    int ok = 1;
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++)
        ok &= distance_case(&cases[i], &D, &da, &solid);
    /* The solvers made once and kept for every call of an object. */
    static const dcase kept[] = {
        {"ball and baffles, solvers kept, 3D 36x30x26", 3, {36, 30, 26}, 1, 0, 0},
        {"solvers kept, a voxel in solid, same object", 3, {36, 30, 26}, 1, 3, 1},
    };
    hv_petsc_option("-hv_distance_keep_solvers", "true");
    for (size_t i = 0; i < sizeof kept / sizeof kept[0]; i++)
        ok &= distance_case(&kept[i], &D, &da, &solid);
    hv_petsc_option("-hv_distance_keep_solvers", "false");
    /* A voxel outside the grid: the same error on every rank. */
    const int bad[3] = {99, 0, 0};
    hv_distance_sources src = {bad, 1, NULL, 0, NULL};
    Vec d;
    DMCreateGlobalVector(da, &d);
    hv_status st = hv_dmda_distance_compute(D, &src, d, NULL);
    ok &= report(st == HV_ERR_INVALID_ARG && strstr(hv_last_error(), "outside"),
                 "distance on a DMDA, a voxel outside the grid: %s (%s)", hv_status_str(st),
                 hv_last_error());
    VecDestroy(&d);
    hv_dmda_distance_destroy(&D);
    /* A solid vector of another layout: refused, on every rank. */
    Vec other;
    VecCreateMPI(PETSC_COMM_WORLD, 5, PETSC_DETERMINE, &other);
    st = hv_dmda_distance_create(&D, da, 0.1, NULL, other, NULL);
    ok &= report(st == HV_ERR_INVALID_ARG && !D, "distance on a DMDA, a solid vector of 5 cells a "
                                                 "rank: %s (%s)",
                 hv_status_str(st), hv_last_error());
    VecDestroy(&other);
    /* A keep option that is no boolean: refused, on every rank. */
    hv_petsc_option("-hv_distance_keep_solvers", "maybe");
    st = hv_dmda_distance_create(&D, da, 0.1, NULL, solid, NULL);
    hv_petsc_option("-hv_distance_keep_solvers", "false");
    ok &= report(st == HV_ERR_INVALID_ARG && !D && strstr(hv_last_error(), "keep_solvers"),
                 "distance on a DMDA, -hv_distance_keep_solvers maybe: %s (%s)",
                 hv_status_str(st), hv_last_error());
    VecDestroy(&solid);
    DMDestroy(&da);
    /* A box narrower than the ghost layer: refused, on every rank. */
    const int P = hv_mpi_size();
    if (P > 1) {
        PetscInt lx[4] = {2, 10, 10, 10};
        DMDACreate3d(PETSC_COMM_WORLD, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE,
                     DMDA_STENCIL_STAR, 2 + 10 * (P - 1), 12, 12, P, 1, 1, 1, 1, lx, NULL, NULL,
                     &da);
        DMSetUp(da);
        st = hv_dmda_distance_create(&D, da, 0.1, NULL, NULL, NULL);
        ok &= report(st == HV_ERR_INVALID_ARG && !D,
                     "distance on a DMDA, a box 2 cells wide: %s (%s)", hv_status_str(st),
                     hv_last_error());
        DMDestroy(&da);
    }
    return ok;
}

int main(int argc, char **argv)
{
    MPI_Init(&argc, &argv);
    hv_petsc_init();
    rank = hv_mpi_rank();
    static const scase cases[] = {
        {"heat step, 3D 17x13x11", 3, {17, 13, 11}, 1, 4.0 / (17 * 17), 0, 0},
        {"Poisson, 3D 20x18x16", 3, {20, 18, 16}, 0, 1, 0, 1},
        {"heat step, 2D 33x27", 2, {33, 27, 1}, 1, 4.0 / (33 * 33), 0, 0},
        {"heat step, 3D ball and baffles 24^3", 3, {24, 24, 24}, 1, 4.0 / (24 * 24), 1, 0},
        {"Poisson, 3D ball and baffles 23x21x19", 3, {23, 21, 19}, 0, 1, 1, 1},
        {"Poisson, 3D cut in two 22x14x12", 3, {22, 14, 12}, 0, 1, 2, 2},
        {"Poisson, 2D cut in two 30x20", 2, {30, 20, 1}, 0, 1, 2, 2},
    };
    int ok = 1;
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++)
        ok &= solve_case(&cases[i]);
    /* The other preconditioners (-hv_petsc_pc) on the 3D cases with solids.
     * PFMG breaks down on a Poisson problem with two separate regions (its
     * coarse grids do not see the null space), so not the box cut in two. */
    static const char *const pcs[] = {"boomeramg", "pfmg", "gamg"};
    for (int q = 0; q < 3; q++) {
        hv_petsc_option("-hv_petsc_pc", pcs[q]);
        if (rank == 0)
            printf("  -hv_petsc_pc %s:\n", pcs[q]);
        for (size_t i = 3; i < (q == 1 ? 5u : 6u); i++)
            ok &= solve_case(&cases[i]);
    }
    hv_petsc_option("-hv_petsc_pc", "auto");
    ok &= extend_cases(40, 0, EXT_BAND);
    ok &= extend_cases(90, 1, EXT_BAND);
    ok &= extend_cases(40, 0, EXT_DENSE);
    ok &= extend_cases(100, 1, EXT_DENSE);
    ok &= extend_cases(40, 0, EXT_DENSE_EXACT);
    ok &= distance_cases();
    if (rank == 0)
        printf("mpi_dmda: %d ranks, %s\n", hv_mpi_size(), ok ? "all cases passed" : "FAILED");
    hv_petsc_finalize();
    MPI_Finalize();
    return ok ? 0 : 1;
}
