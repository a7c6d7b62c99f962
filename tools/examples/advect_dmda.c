/* advect_dmda: a level-set simulation on a PETSc DMDA that extends its
 * velocity off the interface every time step with heatvox (petsc.h).
 *
 *   make mpi
 *   mpirun -n 4 build-mpi/advect_dmda [--n N] [--steps S]
 *
 * A sphere of radius 0.2 in the unit box moves with the velocity (0.3, 0.1,
 * 0.05). As in a two-phase flow solver, the velocity is known only on the
 * cells at the interface (|phi| < 1.5 h); the cells off it hold stale
 * values. Each step:
 *   1. the interface cells get the velocity of the flow (here the
 *      translation, with a stale value of 0 written everywhere else first);
 *   2. hv_dmda_extend carries it off the interface to the band |phi| < 4 h,
 *      in place, on each rank's own cells (the extender and its solvers are
 *      made once, before the loop);
 *   3. phi is advected on the band by first-order upwinding, reading one
 *      ghost layer; as in a narrow-band level set, phi is clamped to
 *      +-4 h off the band.
 * The program prints the sphere's centre (the centroid of phi < 0) against
 * the exact one (the volume shrinks by the upwinding's numerical diffusion,
 * about a fifth over 14 voxels of travel at 40^3; a simulation would use a
 * higher-order scheme and reinitialize), and the largest deviation of the extended velocity from the
 * translation on the band; it exits 1 when the centre is off by more than a
 * voxel or the velocity by more than 1e-4 (relative). */
#include <heatvox/heatvox.h>
#include <petscdmda.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define BAND 4.0

static const double U[3] = {0.3, 0.1, 0.05};

/* The cells hv_dmda_extend writes: |phi| < out_band h, phi as a float. */
static int in_band(double phi, double h) { return fabs((double)(float)phi) < BAND * h; }

int main(int argc, char **argv)
{
    int n = 48, steps = 40;
    for (int i = 1; i + 1 < argc; i += 2) {
        if (!strcmp(argv[i], "--n"))
            n = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--steps"))
            steps = atoi(argv[i + 1]);
    }
    if (n < 16 || steps < 1) {
        fprintf(stderr, "usage: advect_dmda [--n N (>= 16)] [--steps S (>= 1)]\n");
        return 2;
    }
    PetscInitialize(&argc, &argv, NULL, NULL);
    int rank;
    MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
    const double h = 1.0 / n, R = 0.2, c0[3] = {0.35, 0.4, 0.45};
    const double dt = 0.5 * h / sqrt(U[0] * U[0] + U[1] * U[1] + U[2] * U[2]);

    DM da;
    DMDACreate3d(PETSC_COMM_WORLD, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE,
                 DMDA_STENCIL_STAR, n, n, n, PETSC_DECIDE, PETSC_DECIDE, PETSC_DECIDE, 1, 1, NULL,
                 NULL, NULL, &da);
    DMSetUp(da);
    Vec phi, phil, v[3], vl[3];
    DMCreateGlobalVector(da, &phi);
    DMCreateLocalVector(da, &phil);
    for (int a = 0; a < 3; a++)
    {
        VecDuplicate(phi, &v[a]);
        VecDuplicate(phil, &vl[a]);
    }
    PetscInt xs, ys, zs, xm, ym, zm;
    DMDAGetCorners(da, &xs, &ys, &zs, &xm, &ym, &zm);

    /* phi: the signed distance to the sphere at c0. */
    PetscScalar ***p;
    DMDAVecGetArray(da, phi, &p);
    for (PetscInt k = zs; k < zs + zm; k++)
        for (PetscInt j = ys; j < ys + ym; j++)
            for (PetscInt i = xs; i < xs + xm; i++) {
                const double x = (i + 0.5) * h - c0[0], y = (j + 0.5) * h - c0[1],
                             z = (k + 0.5) * h - c0[2];
                p[k][j][i] = fmax(-BAND * h, fmin(BAND * h, sqrt(x * x + y * y + z * z) - R));
            }
    DMDAVecRestoreArray(da, phi, &p);

    /* The extender, once: its ghost layers and its solvers are reused every step. */
    hv_extend_opts eo;
    hv_extend_opts_default(&eo);
    eo.out_band = BAND;
    hv_dmda_extender *X = NULL;
    if (hv_dmda_extender_create(&X, da, h, &eo)) {
        fprintf(stderr, "advect_dmda: %s\n", hv_last_error());
        return 1;
    }
    hv_dmda_field vel = {3, {v[0], v[1], v[2]}};
    double t_ext = 0, dev = 0;
    int solves = 0;
    for (int s = 1; s <= steps; s++) {
        /* 1. The flow's velocity on the interface cells, stale values elsewhere. */
        const PetscScalar ***pr;
        DMDAVecGetArrayRead(da, phi, &pr);
        for (int a = 0; a < 3; a++) {
            PetscScalar ***va;
            DMDAVecGetArray(da, v[a], &va);
            for (PetscInt k = zs; k < zs + zm; k++)
                for (PetscInt j = ys; j < ys + ym; j++)
                    for (PetscInt i = xs; i < xs + xm; i++)
                        va[k][j][i] = fabs(pr[k][j][i]) < 1.5 * h ? U[a] : 0;
            DMDAVecRestoreArray(da, v[a], &va);
        }
        DMDAVecRestoreArrayRead(da, phi, &pr);

        /* 2. Extend it off the interface, in place. */
        hv_extend_stats st;
        double t0 = MPI_Wtime();
        if (hv_dmda_extend(X, phi, 1, &vel, &st)) {
            fprintf(stderr, "advect_dmda: step %d: %s\n", s, hv_last_error());
            return 1;
        }
        t_ext += MPI_Wtime() - t0;
        solves += st.solves;

        /* 3. Advect phi on the band, upwind. A clamped cell next to the band
         *    moves too (the band grows into it), with its band neighbour's
         *    velocity. */
        DMGlobalToLocalBegin(da, phi, INSERT_VALUES, phil);
        DMGlobalToLocalEnd(da, phi, INSERT_VALUES, phil);
        for (int a = 0; a < 3; a++) {
            DMGlobalToLocalBegin(da, v[a], INSERT_VALUES, vl[a]);
            DMGlobalToLocalEnd(da, v[a], INSERT_VALUES, vl[a]);
        }
        const PetscScalar ***pl, ***va[3];
        PetscScalar ***pn;
        DMDAVecGetArrayRead(da, phil, &pl);
        DMDAVecGetArray(da, phi, &pn);
        for (int a = 0; a < 3; a++)
            DMDAVecGetArrayRead(da, vl[a], &va[a]);
        for (PetscInt k = zs; k < zs + zm; k++)
            for (PetscInt j = ys; j < ys + ym; j++)
                for (PetscInt i = xs; i < xs + xm; i++) {
                    const double c = pl[k][j][i];
                    const PetscInt q[3] = {i, j, k};
                    PetscInt from[3] = {i, j, k}; /* where the velocity is read */
                    int moves = in_band(c, h);
                    for (int a = 0; a < 3 && !moves; a++)
                        for (int d = -1; d <= 1 && !moves; d += 2) {
                            PetscInt nb[3] = {i, j, k};
                            nb[a] += d;
                            if (nb[a] >= 0 && nb[a] < n && in_band(pl[nb[2]][nb[1]][nb[0]], h)) {
                                moves = 1;
                                memcpy(from, nb, sizeof nb);
                            }
                        }
                    if (!moves)
                        continue;
                    double adv = 0;
                    for (int a = 0; a < 3; a++) {
                        const double u = va[a][from[2]][from[1]][from[0]];
                        if (in_band(c, h))
                            dev = fmax(dev, fabs(u - U[a]) / U[0]);
                        PetscInt m[3] = {q[0], q[1], q[2]}, pp[3] = {q[0], q[1], q[2]};
                        m[a] = q[a] > 0 ? q[a] - 1 : q[a];
                        pp[a] = q[a] < n - 1 ? q[a] + 1 : q[a];
                        const double dm = (c - pl[m[2]][m[1]][m[0]]) / h,
                                     dp = (pl[pp[2]][pp[1]][pp[0]] - c) / h;
                        adv += u * (u > 0 ? dm : dp);
                    }
                    pn[k][j][i] = fmax(-BAND * h, fmin(BAND * h, c - dt * adv));
                }
        for (int a = 0; a < 3; a++)
            DMDAVecRestoreArrayRead(da, vl[a], &va[a]);
        DMDAVecRestoreArray(da, phi, &pn);
        DMDAVecRestoreArrayRead(da, phil, &pl);

        /* The centre: the centroid of phi < 0. */
        if (s % 10 == 0 || s == steps) {
            double m[4] = {0, 0, 0, 0}, M[4];
            DMDAVecGetArrayRead(da, phi, &pr);
            for (PetscInt k = zs; k < zs + zm; k++)
                for (PetscInt j = ys; j < ys + ym; j++)
                    for (PetscInt i = xs; i < xs + xm; i++)
                        if (pr[k][j][i] < 0) {
                            m[0] += (i + 0.5) * h;
                            m[1] += (j + 0.5) * h;
                            m[2] += (k + 0.5) * h;
                            m[3] += 1;
                        }
            DMDAVecRestoreArrayRead(da, phi, &pr);
            MPI_Allreduce(m, M, 4, MPI_DOUBLE, MPI_SUM, PETSC_COMM_WORLD);
            double err = 0;
            for (int a = 0; a < 3; a++)
                err = fmax(err, fabs(M[a] / M[3] - (c0[a] + U[a] * s * dt)));
            double dv = 0;
            MPI_Allreduce(&dev, &dv, 1, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
            if (!rank)
                printf("step %3d  t %.4f  centre (%.4f %.4f %.4f), off by %.3f voxels  volume "
                       "%.5f (exact %.5f)  velocity off by %.1e  extension %.3f s/step\n",
                       s, s * dt, M[0] / M[3], M[1] / M[3], M[2] / M[3], err / h,
                       M[3] * h * h * h, 4.0 / 3 * M_PI * R * R * R, dv, t_ext / s);
            if (s == steps) {
                const int ok = err <= h && dv <= 1e-4;
                if (!rank)
                    printf("advect_dmda: %d ranks, %d^3, %d steps, %d solves: %s\n",
                           hv_mpi_size(), n, steps, solves, ok ? "ok" : "FAILED");
                hv_dmda_extender_destroy(&X);
                for (int a = 0; a < 3; a++)
                {
                    VecDestroy(&v[a]);
                    VecDestroy(&vl[a]);
                }
                VecDestroy(&phi);
                VecDestroy(&phil);
                DMDestroy(&da);
                PetscFinalize();
                return ok ? 0 : 1;
            }
        }
    }
    return 0; /* not reached */
}
