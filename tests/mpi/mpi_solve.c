/* The petsc backend under mpirun (make mpi-check runs it on 1 to 4 ranks):
 * every rank solves the same problems with petsc (distributed) and with mg
 * (alone), and the two must agree to 1e-6 relative on plain boxes of odd
 * sizes that split unevenly, in 2D and 3D, heat steps and Neumann Poisson,
 * with solid cells crossing rank boundaries and with a fluid region split in
 * two by a wall (one constant of the null space per region). The iteration
 * count must be the same on every rank. Rank 0 prints one line per case;
 * the exit status is 0 only when every case passes on every rank. */
#include "heatvox/heatvox.h"
#include "mpi_cases.h"

#include <math.h>
#include <mpi.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
    const char *name;
    int dim, n[3];
    double alpha, beta;
    int solid; /* MPI_SOLID_* (mpi_cases.h) */
} mcase;

static int run(const mcase *k, int rank)
{
    const size_t count = (size_t)k->n[0] * k->n[1] * (k->dim == 3 ? k->n[2] : 1);
    double *f = malloc(count * sizeof *f), *a = malloc(count * sizeof *a),
           *b = malloc(count * sizeof *b);
    uint8_t *solid = k->solid ? calloc(count, 1) : NULL;
    if (!f || !a || !b || (k->solid && !solid)) {
        fprintf(stderr, "mpi_solve: out of memory\n");
        return 1;
    }
    unsigned seed = 12345;
    const int nz = k->dim == 3 ? k->n[2] : 1;
    for (int z = 0; z < nz; z++)
        for (int y = 0; y < k->n[1]; y++)
            for (int x = 0; x < k->n[0]; x++) {
                const size_t c = x + (size_t)k->n[0] * (y + (size_t)k->n[1] * z);
                f[c] = mpi_rnd(&seed);
                if (solid)
                    solid[c] = mpi_solid(k->solid, k->n, x, y, z);
            }
    hv_problem p = {k->dim, {k->n[0], k->n[1], k->n[2]}, 1.0 / k->n[0], solid, k->alpha, k->beta};
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.tol = 1e-10;
    o.max_iter = 500;
    hv_solver *sp = NULL, *sm = NULL;
    hv_solve_info ip, im;
    hv_status st;
    o.backend = HV_BACKEND_PETSC;
    if ((st = hv_solver_create(&sp, &p, &o)) || (st = hv_solver_solve_d(sp, f, a, &ip))) {
        fprintf(stderr, "mpi_solve: %s: petsc: %s\n", k->name, hv_last_error());
        return 1;
    }
    o.backend = HV_BACKEND_MG;
    if ((st = hv_solver_create(&sm, &p, &o)) || (st = hv_solver_solve_d(sm, f, b, &im))) {
        fprintf(stderr, "mpi_solve: %s: mg: %s\n", k->name, hv_last_error());
        return 1;
    }
    double dmax = 0, umax = 0;
    for (size_t c = 0; c < count; c++) {
        dmax = fmax(dmax, fabs(a[c] - b[c]));
        umax = fmax(umax, fabs(b[c]));
    }
    const double rel = dmax / umax;
    int it[2] = {ip.iterations, -ip.iterations}, itr[2];
    MPI_Allreduce(it, itr, 2, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
    const int same_iters = itr[0] == -itr[1];
    double worst;
    MPI_Allreduce(&rel, &worst, 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
    const int ok = worst <= 1e-6 && same_iters && ip.reason == HV_STOP_CONVERGED &&
                   ip.relres <= 1e-10 * 1.01;
    if (rank == 0)
        printf("  %-34s %d ranks: petsc %3d iterations (relres %.1e), mg %2d; max relative "
               "difference %.2e%s\n",
               k->name, hv_mpi_size(), ip.iterations, ip.relres, im.iterations, worst,
               ok ? "" : "  FAILED");
    hv_solver_destroy(&sp);
    hv_solver_destroy(&sm);
    free(f);
    free(a);
    free(b);
    free(solid);
    return !ok;
}

int main(int argc, char **argv)
{
    MPI_Init(&argc, &argv);
    static const mcase cases[] = {
        {"heat step, 3D box 17x13x11", 3, {17, 13, 11}, 1, 4.0 / (17 * 17), 0},
        {"Poisson, 3D box 20x18x16", 3, {20, 18, 16}, 0, 1, 0},
        {"heat step, 2D box 33x27", 2, {33, 27, 1}, 1, 4.0 / (33 * 33), 0},
        {"Poisson, 2D box 45x31", 2, {45, 31, 1}, 0, 1, 0},
        {"heat step, 3D ball and baffles 24^3", 3, {24, 24, 24}, 1, 4.0 / (24 * 24), 1},
        {"Poisson, 3D ball and baffles 23x21x19", 3, {23, 21, 19}, 0, 1, 1},
        {"Poisson, 2D ball and baffles 40x36", 2, {40, 36, 1}, 0, 1, 1},
        {"Poisson, 3D box cut in two 22x14x12", 3, {22, 14, 12}, 0, 1, 2},
        {"Poisson, 2D box cut in two 30x20", 2, {30, 20, 1}, 0, 1, 2},
    };
    int bad = 0;
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++)
        bad += run(&cases[i], hv_mpi_rank());
    const int rank = hv_mpi_rank();
    int all = 0;
    MPI_Allreduce(&bad, &all, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
    if (rank == 0)
        printf("mpi_solve: %d ranks, %s\n", hv_mpi_size(), all ? "FAILED" : "all cases passed");
    hv_petsc_finalize();
    MPI_Finalize();
    return all ? 1 : 0;
}
