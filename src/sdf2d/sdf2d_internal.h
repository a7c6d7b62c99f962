/* Private pieces of the 2D signed heat method, shared by its files: the method
 * (sdf2d.c), curve repair (sdf2d_repair.c, sdf2d_orient.c) and the exact
 * distance (sdf2d_exact.c); hv__sdf2d_all_pairs is for the tests. */
#ifndef HV_HEAT_SDF2D_INTERNAL_H
#define HV_HEAT_SDF2D_INTERNAL_H

#include "heatvox/sdf2d.h"

#include <math.h>
#include <stddef.h>
#include <stdint.h>

/* 1: the repair tests every loop against every other for nesting, without the
 * spatial index (the quadratic reference the index must agree with bit for
 * bit). 0 by default; tests only, not thread-safe to change during a run. */
extern int hv__sdf2d_all_pairs;

/* A segment from point a to point b (indices into the curves' points). */
typedef struct sdf2d_seg {
    uint32_t a, b;
} sdf2d_seg;

static inline double sdf2d_seg_len(const double *P, sdf2d_seg s)
{
    return hypot(P[2 * s.b] - P[2 * s.a], P[2 * s.b + 1] - P[2 * s.a + 1]);
}

/* Union-find root with path halving. */
static inline uint32_t sdf2d_uf_find(uint32_t *p, uint32_t x)
{
    while (p[x] != x) {
        p[x] = p[p[x]];
        x = p[x];
    }
    return x;
}

/* qsort order of uint64_t keys. */
static inline int sdf2d_by_u64(const void *a, const void *b)
{
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return (x > y) - (x < y);
}

/* Welds points within tol, splits segments at points lying on them (tol > 0),
 * drops zero-length and duplicate segments, and orients every chain (h: the
 * cell size, for the overlap search). *Sp (malloc'ed, *ns segments) may be
 * replaced by a new array; the counts of st are added to. sdf2d_repair.c. */
hv_status hv__sdf2d_repair(const double *P, size_t np, sdf2d_seg **Sp, size_t *ns, double tol,
                           double h, hv_sdf2d_stats *st);

/* Which chains to reverse as a whole: turn[c] ^= 1 for chain c (members
 * mstart[c] .. mstart[c+1]-1 of members, each consistent along itself; deg the
 * CSR offsets of the points' incident segments). sdf2d_orient.c. */
hv_status hv__sdf2d_orient_chains(const double *P, sdf2d_seg *S, const uint32_t *deg, uint32_t nc,
                                  const uint32_t *mstart, const uint32_t *members, double tol,
                                  uint8_t *turn, hv_sdf2d_stats *st);

/* dist[c] = distance from cell centre c of the n[0] x n[1] grid (cell size h,
 * corner org) to the nearest of the ns segments. sdf2d_exact.c. */
hv_status hv__sdf2d_exact_distance(const double *P, const sdf2d_seg *S, size_t ns, const int n[2],
                                   double h, const double org[2], double *dist);

/* sg[c] = -1 inside, +1 outside: the generalized winding number of the ns
 * segments above 1/2 at cell centre c, evaluated hierarchically (dist: the
 * exact distance of each cell). evals (may be NULL) counts evaluations.
 * sdf2d_winding.c. */
hv_status hv__sdf2d_winding_sign(const double *P, const sdf2d_seg *S, size_t ns, const int n[2],
                                 double h, const double org[2], const double *dist, int8_t *sg,
                                 size_t *evals);

#endif
