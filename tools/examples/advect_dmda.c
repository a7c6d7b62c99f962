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
 *   3. phi is advected on the band by fifth-order WENO (Jiang & Peng 2000)
 *      in space and the third-order TVD Runge-Kutta scheme of Shu & Osher
 *      in time, reading three ghost layers, each cell with the extended
 *      velocity at itself (a clamped cell next to the band, which the band
 *      grows into, with its band neighbour's); as in a narrow-band level
 *      set, phi is clamped to +-4 h off the band.
 * The program prints the sphere's centre (the centroid of phi < 0) and its
 * volume (a smeared Heaviside of phi, exact to O(h^2)) against the exact ones,
 * and the largest deviation of the extended velocity from the translation on
 * the band; it exits 1 when the centre is off by more than a quarter voxel,
 * the volume by more than 0.5% or the velocity by more than 1e-4 (relative). */
#include <heatvox/heatvox.h>
#include <petscdmda.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define BAND 4.0
#define GHOST 3 /* WENO5 reads three cells on either side */

static const double U[3] = {0.3, 0.1, 0.05};

/* The cells hv_dmda_extend writes: |phi| < out_band h, phi as a float. */
static int in_band(double phi, double h) { return fabs((double)(float)phi) < BAND * h; }

/* The WENO5 derivative from the five one-sided differences v1..v5 (Osher &
 * Fedkiw, Level Set Methods, eq. 3.28-3.34). */
static double weno5(double v1, double v2, double v3, double v4, double v5)
{
    const double s1 = 13.0 / 12 * (v1 - 2 * v2 + v3) * (v1 - 2 * v2 + v3) +
                      0.25 * (v1 - 4 * v2 + 3 * v3) * (v1 - 4 * v2 + 3 * v3);
    const double s2 = 13.0 / 12 * (v2 - 2 * v3 + v4) * (v2 - 2 * v3 + v4) +
                      0.25 * (v2 - v4) * (v2 - v4);
    const double s3 = 13.0 / 12 * (v3 - 2 * v4 + v5) * (v3 - 2 * v4 + v5) +
                      0.25 * (3 * v3 - 4 * v4 + v5) * (3 * v3 - 4 * v4 + v5);
    const double e = 1e-6 * fmax(fmax(v1 * v1, v2 * v2), fmax(fmax(v3 * v3, v4 * v4), v5 * v5)) +
                     1e-99;
    const double a1 = 0.1 / ((s1 + e) * (s1 + e)), a2 = 0.6 / ((s2 + e) * (s2 + e)),
                 a3 = 0.3 / ((s3 + e) * (s3 + e));
    return (a1 * (2 * v1 - 7 * v2 + 11 * v3) + a2 * (-v2 + 5 * v3 + 2 * v4) +
            a3 * (2 * v3 + 5 * v4 - v5)) /
           (6 * (a1 + a2 + a3));
}

typedef struct sim {
    DM da;
    int n;
    double h;
    PetscInt xs, ys, zs, xm, ym, zm;
    Vec phil, vl[3]; /* local (ghosted) copies */
    Vec bandl;       /* phi at the start of the step, ghosted: the band the velocity is on */
} sim;

/* phi at (q) moved by d cells along axis a, the index clamped to the box. */
static double at(const PetscScalar ***p, const PetscInt q[3], int a, int d, int n)
{
    PetscInt r[3] = {q[0], q[1], q[2]};
    r[a] = r[a] + d < 0 ? 0 : r[a] + d > n - 1 ? n - 1 : r[a] + d;
    return p[r[2]][r[1]][r[0]];
}

/* One stage: out = max(-4h, min(4h, a0 * phi0 + b (phi + dt L(phi)))) on the
 * cells that move, L(phi) = -u . grad phi upwinded by WENO5. The cells that
 * move, and where each reads its velocity, are those of the band the
 * extension filled at the start of the step (S->bandl), in every stage. */
static void stage(sim *S, Vec phi, Vec phi0, double a0, double b, double dt, Vec out, double *dev)
{
    const double h = S->h;
    DMGlobalToLocalBegin(S->da, phi, INSERT_VALUES, S->phil);
    DMGlobalToLocalEnd(S->da, phi, INSERT_VALUES, S->phil);
    const PetscScalar ***pl, ***p0, ***bl, ***va[3];
    PetscScalar ***po;
    DMDAVecGetArrayRead(S->da, S->phil, &pl);
    DMDAVecGetArrayRead(S->da, S->bandl, &bl);
    DMDAVecGetArrayRead(S->da, phi0, &p0);
    DMDAVecGetArray(S->da, out, &po);
    for (int a = 0; a < 3; a++)
        DMDAVecGetArrayRead(S->da, S->vl[a], &va[a]);
    for (PetscInt k = S->zs; k < S->zs + S->zm; k++)
        for (PetscInt j = S->ys; j < S->ys + S->ym; j++)
            for (PetscInt i = S->xs; i < S->xs + S->xm; i++) {
                const PetscInt q[3] = {i, j, k};
                const double c = pl[k][j][i];
                PetscInt from[3] = {i, j, k}; /* where the velocity is read */
                const int on = in_band(bl[k][j][i], h);
                int moves = on;
                for (int a = 0; a < 3 && !moves; a++)
                    for (int d = -1; d <= 1 && !moves; d += 2)
                        if (q[a] + d >= 0 && q[a] + d < S->n && in_band(at(bl, q, a, d, S->n), h)) {
                            moves = 1;
                            from[a] += d;
                        }
                if (!moves) {
                    po[k][j][i] = c;
                    continue;
                }
                double adv = 0;
                for (int a = 0; a < 3; a++) {
                    const double u = va[a][from[2]][from[1]][from[0]];
                    if (on)
                        *dev = fmax(*dev, fabs(u - U[a]) / U[0]);
                    double D[6]; /* D[m] = (phi[q+m-2] - phi[q+m-3]) / h, m = 0..5 */
                    for (int m = 0; m < 6; m++)
                        D[m] = (at(pl, q, a, m - 2, S->n) - at(pl, q, a, m - 3, S->n)) / h;
                    const double g = u > 0 ? weno5(D[0], D[1], D[2], D[3], D[4])
                                           : weno5(D[5], D[4], D[3], D[2], D[1]);
                    adv += u * g;
                }
                const double v = a0 * p0[k][j][i] + b * (c - dt * adv);
                po[k][j][i] = fmax(-BAND * h, fmin(BAND * h, v));
            }
    for (int a = 0; a < 3; a++)
        DMDAVecRestoreArrayRead(S->da, S->vl[a], &va[a]);
    DMDAVecRestoreArray(S->da, out, &po);
    DMDAVecRestoreArrayRead(S->da, phi0, &p0);
    DMDAVecRestoreArrayRead(S->da, S->bandl, &bl);
    DMDAVecRestoreArrayRead(S->da, S->phil, &pl);
}

/* The centroid (m[0..2] / m[3]) and volume (m[3] h^3) of phi < 0, each cell
 * counted by the part of it inside, clamp(1/2 - phi / h), over all ranks. */
static void centroid_volume(const sim *S, Vec phi, double M[4])
{
    const double h = S->h;
    double m[4] = {0, 0, 0, 0};
    const PetscScalar ***pr;
    DMDAVecGetArrayRead(S->da, phi, &pr);
    for (PetscInt k = S->zs; k < S->zs + S->zm; k++)
        for (PetscInt j = S->ys; j < S->ys + S->ym; j++)
            for (PetscInt i = S->xs; i < S->xs + S->xm; i++) {
                const double f = fmax(0, fmin(1, 0.5 - pr[k][j][i] / h));
                m[0] += f * (i + 0.5) * h;
                m[1] += f * (j + 0.5) * h;
                m[2] += f * (k + 0.5) * h;
                m[3] += f;
            }
    DMDAVecRestoreArrayRead(S->da, phi, &pr);
    MPI_Allreduce(m, M, 4, MPI_DOUBLE, MPI_SUM, PETSC_COMM_WORLD);
}

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

    sim S = {.n = n, .h = h};
    DMDACreate3d(PETSC_COMM_WORLD, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE,
                 DMDA_STENCIL_STAR, n, n, n, PETSC_DECIDE, PETSC_DECIDE, PETSC_DECIDE, 1, GHOST,
                 NULL, NULL, NULL, &S.da);
    DMSetUp(S.da);
    Vec phi, p1, p2, v[3];
    DMCreateGlobalVector(S.da, &phi);
    VecDuplicate(phi, &p1);
    VecDuplicate(phi, &p2);
    DMCreateLocalVector(S.da, &S.phil);
    VecDuplicate(S.phil, &S.bandl);
    for (int a = 0; a < 3; a++) {
        VecDuplicate(phi, &v[a]);
        VecDuplicate(S.phil, &S.vl[a]);
    }
    DMDAGetCorners(S.da, &S.xs, &S.ys, &S.zs, &S.xm, &S.ym, &S.zm);

    /* phi: the signed distance to the sphere at c0. */
    PetscScalar ***p;
    DMDAVecGetArray(S.da, phi, &p);
    for (PetscInt k = S.zs; k < S.zs + S.zm; k++)
        for (PetscInt j = S.ys; j < S.ys + S.ym; j++)
            for (PetscInt i = S.xs; i < S.xs + S.xm; i++) {
                const double x = (i + 0.5) * h - c0[0], y = (j + 0.5) * h - c0[1],
                             z = (k + 0.5) * h - c0[2];
                p[k][j][i] = fmax(-BAND * h, fmin(BAND * h, sqrt(x * x + y * y + z * z) - R));
            }
    DMDAVecRestoreArray(S.da, phi, &p);
    double M0[4];
    centroid_volume(&S, phi, M0);

    /* The extender, once: its ghost layers and its solvers are reused every step. */
    hv_extend_opts eo;
    hv_extend_opts_default(&eo);
    eo.out_band = BAND;
    hv_dmda_extender *X = NULL;
    if (hv_dmda_extender_create(&X, S.da, h, &eo)) {
        fprintf(stderr, "advect_dmda: %s\n", hv_last_error());
        return 1;
    }
    hv_dmda_field vel = {3, {v[0], v[1], v[2]}};
    double t_ext = 0, dev = 0;
    int solves = 0, ok = 0;
    for (int s = 1; s <= steps; s++) {
        /* 1. The flow's velocity on the interface cells, stale values elsewhere. */
        const PetscScalar ***pr;
        DMDAVecGetArrayRead(S.da, phi, &pr);
        for (int a = 0; a < 3; a++) {
            PetscScalar ***va;
            DMDAVecGetArray(S.da, v[a], &va);
            for (PetscInt k = S.zs; k < S.zs + S.zm; k++)
                for (PetscInt j = S.ys; j < S.ys + S.ym; j++)
                    for (PetscInt i = S.xs; i < S.xs + S.xm; i++)
                        va[k][j][i] = fabs(pr[k][j][i]) < 1.5 * h ? U[a] : 0;
            DMDAVecRestoreArray(S.da, v[a], &va);
        }
        DMDAVecRestoreArrayRead(S.da, phi, &pr);

        /* 2. Extend it off the interface, in place. */
        hv_extend_stats st;
        double t0 = MPI_Wtime();
        if (hv_dmda_extend(X, phi, 1, &vel, &st)) {
            fprintf(stderr, "advect_dmda: step %d: %s\n", s, hv_last_error());
            return 1;
        }
        t_ext += MPI_Wtime() - t0;
        solves += st.solves;
        for (int a = 0; a < 3; a++) {
            DMGlobalToLocalBegin(S.da, v[a], INSERT_VALUES, S.vl[a]);
            DMGlobalToLocalEnd(S.da, v[a], INSERT_VALUES, S.vl[a]);
        }
        DMGlobalToLocalBegin(S.da, phi, INSERT_VALUES, S.bandl);
        DMGlobalToLocalEnd(S.da, phi, INSERT_VALUES, S.bandl);

        /* 3. TVD Runge-Kutta 3 (Shu & Osher): phi1 = phi + dt L(phi),
         *    phi2 = 3/4 phi + 1/4 (phi1 + dt L(phi1)),
         *    phi  = 1/3 phi + 2/3 (phi2 + dt L(phi2)). */
        stage(&S, phi, phi, 0.0, 1.0, dt, p1, &dev);
        stage(&S, p1, phi, 0.75, 0.25, dt, p2, &dev);
        stage(&S, p2, phi, 1.0 / 3, 2.0 / 3, dt, p1, &dev);
        VecCopy(p1, phi);

        if (s % 10 == 0 || s == steps) {
            double M[4], err = 0, dv = 0;
            centroid_volume(&S, phi, M);
            for (int a = 0; a < 3; a++)
                err = fmax(err, fabs(M[a] / M[3] - (c0[a] + U[a] * s * dt)));
            const double vol_err = fabs(M[3] / M0[3] - 1);
            MPI_Allreduce(&dev, &dv, 1, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
            if (!rank)
                printf("step %3d  t %.4f  centre (%.4f %.4f %.4f), off by %.3f voxels  volume "
                       "%.5f (at the start %.5f, exact %.5f)  velocity off by %.1e  extension "
                       "%.3f s/step\n",
                       s, s * dt, M[0] / M[3], M[1] / M[3], M[2] / M[3], err / h,
                       M[3] * h * h * h, M0[3] * h * h * h, 4.0 / 3 * M_PI * R * R * R, dv,
                       t_ext / s);
            ok = err <= 0.25 * h && vol_err <= 0.005 && dv <= 1e-4;
        }
    }
    if (!rank)
        printf("advect_dmda: %d ranks, %d^3, %d steps, %d solves: %s\n", hv_mpi_size(), n, steps,
               solves, ok ? "ok" : "FAILED");
    hv_dmda_extender_destroy(&X);
    for (int a = 0; a < 3; a++) {
        VecDestroy(&v[a]);
        VecDestroy(&S.vl[a]);
    }
    VecDestroy(&phi);
    VecDestroy(&p1);
    VecDestroy(&p2);
    VecDestroy(&S.phil);
    VecDestroy(&S.bandl);
    DMDestroy(&S.da);
    PetscFinalize();
    return ok ? 0 : 1;
}
