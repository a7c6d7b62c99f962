/* The test cases' inputs shared by tests/mpi/mpi_solve.c and mpi_dmda.c: a
 * reproducible right-hand side and the solid masks. */
#ifndef HV_TESTS_MPI_CASES_H
#define HV_TESTS_MPI_CASES_H

#include <stdint.h>

/* Uniform in [-0.5, 0.5), the same sequence on every rank. */
static inline double mpi_rnd(unsigned *s)
{
    *s = *s * 1664525u + 1013904223u;
    return (*s >> 8) / 16777216.0 - 0.5;
}

/* Solid masks on an n[0] x n[1] x n[2] grid (n[2] = 1 in 2D), cell (x, y, z):
 * MPI_SOLID_BAFFLES a ball of radius n[1]/4 in the middle and two baffles
 * one cell thick (x = n[0]/4 above y = n[1]/5, y = n[1]/3 right of x =
 * n[0]/2), crossing the ranks' boundaries; MPI_SOLID_CUT a wall at x = n[0]/2
 * cutting the box in two fluid regions. */
enum { MPI_SOLID_NONE, MPI_SOLID_BAFFLES, MPI_SOLID_CUT };
static inline uint8_t mpi_solid(int kind, const int n[3], int x, int y, int z)
{
    if (kind == MPI_SOLID_BAFFLES) {
        const double dx = x - 0.5 * n[0], dy = y - 0.5 * n[1], dz = n[2] > 1 ? z - 0.5 * n[2] : 0;
        const double r = 0.25 * n[1];
        return dx * dx + dy * dy + dz * dz < r * r || (x == n[0] / 4 && y > n[1] / 5) ||
               (y == n[1] / 3 && x > n[0] / 2);
    }
    return kind == MPI_SOLID_CUT && x == n[0] / 2;
}

#endif
