/*
 * Private: the coarse levels of the CPU multigrid on grids with solid cells,
 * by smoothed aggregation (docs/METHOD.md, "Coarse levels that keep the
 * walls").
 *
 * Each level's unknowns are grouped by the 2x2x2 (2x2) blocks of their
 * coordinates, and a block's unknowns split into the parts that its own
 * couplings connect: cells on the two sides of a wall never share an
 * aggregate. The prolongation is the aggregates' indicator smoothed by one
 * damped Jacobi step, P = (I - omega/lmax D^-1 A) P0, and the coarse operator
 * is Galerkin's, A_c = P^T A P. Neither P nor A reaches through a wall, so the
 * coarse operators keep every wall and every region cut off by walls (its own
 * null space for Poisson). Coarse operators are sparse rows (CSR) of up to a
 * few hundred entries, except level 1's rows in open space, which are one
 * template at fixed index offsets. P and P^T are sparse rows on the deeper
 * levels; the fine level and level 1 apply them from their own operator, the
 * aggregates and D.
 */
#ifndef HV_SOLVE_MG_AGG_H
#define HV_SOLVE_MG_AGG_H

#include "mg_level.h"

#include <math.h>
#include <stddef.h>
#include <stdint.h>

#define MG_AGG_MAX_LEVELS 24
/* HV_COARSE_AUTO: a solver whose solve took more than MG_AGG_SWITCH
 * iterations at a mean residual reduction worse than MG_AGG_SLOW per
 * iteration (the geometric levels stalling at walls; a tight tolerance alone
 * is no reason) builds aggregation levels before its next solve: their set-up
 * pays off only over several solves. */
#define MG_AGG_SWITCH 16
#define MG_AGG_SLOW 0.4

static inline int mg_agg_slow(int iterations, double relres)
{
    return iterations > MG_AGG_SWITCH && relres > 0 && pow(relres, 1.0 / iterations) > MG_AGG_SLOW;
}

/* HV_COARSE_AUTO within a solve: after MG_AGG_PROBE iterations, the mean
 * reduction from the first iteration's residual r1 to the last one's r (the
 * first falls faster than the rest: what the geometric levels resolve) worse
 * than MG_AGG_SLOW, at which reaching tol would take more than MG_AGG_SWITCH
 * iterations in all. */
#define MG_AGG_PROBE 4

static inline int mg_agg_stalls(int steps, double r1, double r, double tol)
{
    if (!(r > tol) || !(r1 > 0) || steps < 1)
        return 0;
    double rate = pow(r / r1, 1.0 / steps);
    if (!(rate > MG_AGG_SLOW))
        return 0;
    return rate >= 1 || steps + 1 + log(tol / r) / log(rate) > MG_AGG_SWITCH;
}

/* mg_agg_stalls over a probe's residual history. */
static inline int mg_agg_probe_stalls(const hv_solve_info *probe, double tol)
{
    return probe->nhistory > 2 &&
           mg_agg_stalls(probe->iterations - 1, probe->history[1], probe->relres, tol);
}

/* Sparse rows. Once the hierarchy is built (hv__mg_agg_pack), a matrix whose
 * every row spans fewer than 65536 columns holds them as 16-bit offsets co
 * from the row's first column cb[r] instead of ci (then NULL). */
typedef struct mg_csr {
    int32_t n;  /* rows */
    size_t *rp; /* n + 1 row starts */
    int32_t *ci;
    float *v;
    int32_t *cb;  /* packed: each row's smallest column */
    uint16_t *co; /* packed: column - cb[row], MG_CSR_PAD entries past the last */
} mg_csr;

#define MG_CSR_PAD 16
#define MG_CLS_GROUP 0xFFFF
#define MG_GROUP 8

/* Level l of the aggregation hierarchy; lv[0] is the grid's fine level, whose
 * operator is the matrix-free stencil of an mg_level (A unused there). */
typedef struct mg_alevel {
    int32_t n;    /* unknowns */
    mg_csr A;     /* levels >= 1 */
    mg_csr P, R;  /* levels >= 1: the prolongation from the next level, and P^T */
    float *dinv;  /* levels >= 1 (the fine level's is the mg_level's) */
    double lmax;  /* eigenvalue bound of D^-1 A */
    int32_t *agg; /* unknown -> aggregate (next level's unknown), -1 for empty rows */
    size_t *mrp;  /* next level's unknown I: members mem[mrp[I] .. mrp[I+1]) */
    int32_t *mem; /* (n_next + 1 starts) */
    int32_t *xyz; /* levels >= 1: 3 block coordinates per unknown */
    int ext[3];   /* coordinate extent of the level */
    int32_t live; /* unknowns with a row (the others are blocks without fluid) */
    /* Level 1 in open space: rows marked in plain[] are the template (tn
     * entries at index offsets toff with values tval) and hold no entries in
     * A once the hierarchy is built (mg_agg_compress). */
    uint8_t *plain;
    int tn;
    int32_t toff[125];
    float tval[125];
    /* The CPU cycle's further templates (hv__mg_agg_pack): stored rows that
     * repeat along the box's faces and the walls, the same entries at the
     * same offsets. cls[c] = 0 for a row in A, 1 for a plain row, 2 + k for
     * row class k (cn[k] entries at offsets coff, values cval, each class
     * cw apart), whose rows then hold no entries in A. NULL when packing found
     * none. */
    uint16_t *cls;
    int ncls;
    int cw; /* class k's entries at coff, cval + cw k */
    int *cn;
    int32_t *coff;
    float *cval;
    /* Rows of a class that make no run of a few rows along x (cls[c] =
     * MG_CLS_GROUP): in groups of MG_GROUP rows of one class, grow[MG_GROUP g
     * ..] the rows of group g (a class's last group repeats its last row),
     * gcls[g] its class, the groups in the order their rows filled them. */
    int32_t ngrp;
    int32_t *grow;
    int32_t *gcls;
    int32_t nagg;                 /* aggregates made of them (next level's non-empty unknowns) */
    float *u, *f, *r, *d, *t, *s; /* work: t, s for the transfers */
} mg_alevel;

typedef struct mg_agg {
    int dim;
    double alpha;
    const mg_level *fine;
    uint8_t *faces; /* binary fine level: bit 2b+hi per open face of each cell */
    int nlev;       /* levels, the fine one included; the last is solved directly */
    mg_alevel lv[MG_AGG_MAX_LEVELS];
    int32_t nb;   /* bottom unknowns */
    double *chol; /* bottom: Cholesky factor (nb x nb, lower), Poisson regularized per region */
    int32_t *region;
    int nregion;
    double *bx;          /* nb doubles of work */
    size_t bytes;        /* memory held */
    size_t class_copies; /* coarse rows copied from their class's row */
} mg_agg;

/* Builds the aggregation hierarchy under fine level F (weighted, with dinv).
 * Returns HV_OK with *out NULL where aggregation does not apply (grids of 2^31
 * cells or more, or levels that stop coarsening early); the caller then keeps
 * its geometric levels. */
hv_status hv__mg_agg_build(mg_agg **out, const mg_level *F, int dim, double alpha);
void hv__mg_agg_free(mg_agg *g);
/* Packs the hierarchy for the CPU cycle: level 1's rows that repeat into row
 * classes (mg_alevel's cls), the columns of every matrix whose rows fit into
 * 16-bit offsets (mg_csr). The OpenCL backend uploads it unpacked. Leaves a
 * part as it is where memory is short. */
void hv__mg_agg_pack(mg_agg *g);
/* Frees all but the bottom level's factor and the level sizes (the OpenCL
 * backend, once it has uploaded the levels). */
void hv__mg_agg_keep_bottom(mg_agg *g);
/* u += the coarse-grid correction of residual r on the fine level: P (one
 * symmetric V-cycle on levels 1..) P^T r. */
void hv__mg_agg_correct(mg_agg *g, const float *r, float *u);
/* u = the bottom level's solution for f (the Cholesky factor; Poisson:
 * mean-free per region), nb floats each. */
void hv__mg_agg_bottom(mg_agg *g, const float *f, float *u);

#endif
