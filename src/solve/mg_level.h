/*
 * Private: one level of the geometric multigrid hierarchy.
 *
 * The operator on a level is, per cell i,
 *     (A u)_i = alpha * a_i * u_i + sum_axes c_b * sum_faces w_f * (u_i - u_nb)
 * with c_b = beta / h_b^2. On the fine level a_i = 1 on fluid and 0 on solid
 * cells, w_f = 1 on faces between two fluid cells and 0 on walls and faces
 * touching solid. Coarse levels take a = mean of the 2^d children and w = mean
 * of the fine faces covering the coarse face (NOTES §2); a child beyond an odd
 * edge counts as solid, so odd sizes coarsen like any masked grid. A level whose
 * weights are all one inside is "plain" and stores no coefficient arrays.
 */
#ifndef HV_SOLVE_MG_LEVEL_H
#define HV_SOLVE_MG_LEVEL_H

#include <stddef.h>
#include <stdint.h>

typedef struct mg_level {
    int n[3];
    size_t count;
    size_t sy, sz;        /* cell strides */
    double c[3];          /* beta / h_b^2 (0 for axes beyond dim) */
    int coarsen[3];       /* the next level halves this axis */
    int plain;
    float *a;             /* cell weights (NULL when plain) */
    float *w[3];          /* face weights, n[b]+1 along b (NULL when plain) */
    float *dinv;          /* 1/diag (NULL when plain); 0 where the row is empty */
    float *u, *f, *r, *d; /* solution, right-hand side, residual, smoother work */
    double lmax;          /* eigenvalue bound of D^-1 A (Chebyshev) */
    /* bottom level only: connected regions (Poisson) and CG work */
    int nregion;
    int32_t *region;
    double *bx, *bb, *br, *bp, *bq;
} mg_level;

#endif
