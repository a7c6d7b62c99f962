/*
 * Private to the aggregation levels (agg_*.c, mg_agg.h): the operator of a
 * level as the files see it and what each file gives the others.
 *   agg_op.c         a level's rows, its product and its spectral bound
 *   agg_aggregate.c  the aggregates of a level
 *   agg_galerkin.c   the Galerkin coarse operators
 *   agg_bottom.c     the bottom level's factor and solve
 *   agg_cycle.c      the cycle on the coarse levels
 *   agg_pack.c       the CPU cycle's packing of built levels
 *   agg_build.c      building the levels and freeing them
 */
#ifndef HV_SOLVE_MG_AGG_INTERNAL_H
#define HV_SOLVE_MG_AGG_INTERNAL_H

#include "core/error.h"
#include "mg_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

#define AGG_OMEGA (4.0 / 3.0) /* prolongation smoothing: omega / lmax(D^-1 A) */
#define AGG_BOTTOM 600        /* a level this small is solved by Cholesky */
#define AGG_STALL 1200        /* more than this and not coarsening: give up */
#define AGG_TRUNCATE 0.05     /* coarse levels' P: entries below this times the row's largest go */
#define AGG_STRONG 1e-6       /* |a_ij| below this times sqrt(a_ii a_jj) joins nothing */
#define AGG_DEGREE 2          /* Chebyshev degree on the coarse levels */
#define AGG_PAR_MIN 16384     /* levels below this many unknowns run on one thread */

/* The operator of level l: the fine level's stencil (F) or a sparse matrix. */
typedef struct agg_op {
    const mg_level *F;
    int dim;
    double alpha;
    const mg_csr *A;
    const float *dinv;
    int32_t n;
    const uint8_t *faces; /* fine level of a mask: bit 2b+hi for each open face */
    const mg_alevel *lv;  /* the level (templates of plain rows) */
} agg_op;

static inline agg_op level_op(const mg_agg *g, int l)
{
    agg_op o = {NULL, g->dim, g->alpha, NULL, NULL, g->lv[l].n, NULL, &g->lv[l]};
    if (l == 0) {
        o.F = g->fine;
        o.dinv = g->fine->dinv;
        o.faces = g->faces;
    } else {
        o.A = &g->lv[l].A;
        o.dinv = g->lv[l].dinv;
    }
    return o;
}

/* Entries a row of a coarse level can have: a template's at most (5^3). */
#define ROW_MAX 125

/* ---- agg_classes.c ---- */
#define AGG_SPLIT UINT64_MAX              /* a block's code: more than one aggregate */
#define AGG_OUTSIDE 0x8080808080808080ull /* the code of a block outside the grid */
#define AGG_CLASS_MAX 65536               /* classes of rows computed at most */
#define AGG_CLASS_RADIUS 6 /* neighbourhoods wider than this many blocks: no classes */
/* Per block of level 1 (3D binary fine levels): its 8 fine cells as bytes
 * (open faces, 0x40 fluid, 0x80 outside the grid), or AGG_SPLIT where the
 * block holds a cell of another aggregate than the block's own. */
void hv__agg_fine_codes(const mg_agg *g, uint64_t *code);
/* Per block of level l + 1 (l >= 1): two codes of the rows of level l in
 * it (offsets and values, diagonals), AGG_SPLIT in both where it or one of
 * its blocks of level l holds more than one unknown; bid[B] the block's one
 * unknown of level l + 1 (-1 split or empty); *reach the farthest a row of
 * level l reaches, in blocks of level l along an axis. Returns 0, or -1 out
 * of memory. */
int hv__agg_level_codes(const mg_agg *g, int l, int32_t *bid, uint64_t *ca, uint64_t *cb,
                        int *reach);
/* fp[2b], fp[2b + 1]: block b's fingerprint, hashes of the (2r+1)^3 blocks
 * around it (codes ca for the first, cb for the second), (0, 0) where one
 * of them is AGG_SPLIT. Returns 0, or -1 out of memory. */
int hv__agg_fingerprints(const int e[3], int r, const uint64_t *ca, const uint64_t *cb,
                         uint64_t *fp);
/* cls[b]: the class of block b among those not skipped with a fingerprint,
 * numbered from 0 where two blocks or more share it (at most max classes),
 * else -1. Returns the number of classes, or -1 out of memory. */
int32_t hv__agg_classes(size_t nb, const uint64_t *fp, const uint8_t *skip, int32_t *cls,
                        int32_t max);
/* Whether row classes are used (HV_AGG_NOCLASS=1 turns them off: the tests
 * compare the levels both ways). */
int hv__agg_classes_on(void);

/* ---- agg_op.c ---- */
/* Row c of coarse level L: pointers into its matrix, or for a plain row the
 * template's entries in bc/bv (ROW_MAX each). The hierarchy's set-up only:
 * hv__mg_agg_pack changes the matrices. */
int hv__agg_level_row(const mg_alevel *L, int32_t c, int32_t *bc, float *bv, const int32_t **col,
                      const float **val);
/* Row c: its entries (the diagonal first on the fine level), in bc/bv
 * (ROW_MAX entries) for the fine level and plain rows, else pointers into
 * the matrix. */
int hv__agg_op_row(const agg_op *o, int32_t c, int32_t *bc, float *bv, const int32_t **col,
                   const float **val);
/* y = A x on a level. */
void hv__agg_op_apply(const agg_op *o, const float *x, float *y);
/* Largest eigenvalue of D^-1 A by power iteration (times 1.1, as the
 * geometric levels' bound); x and y are work of o->n. */
double hv__agg_op_lmax(const agg_op *o, float *x, float *y);
/* y = M x (rows of M). */
void hv__agg_csr_apply(const mg_csr *M, const float *x, float *y);

/* ---- agg_aggregate.c ---- */
/* Aggregates of level l: L->agg, members (mrp, mem) and level l+1's size,
 * coordinates and extent. */
hv_status hv__agg_aggregate(mg_agg *g, int l);

/* ---- agg_galerkin.c ---- */
/* Level l+1's operator P^T A P from a coarse level l by sparse products. */
hv_status hv__agg_galerkin_csr(mg_agg *g, int l, double wp);
/* Level 1's operator from the fine level (aggregates built). */
hv_status hv__agg_galerkin0(mg_agg *g, double wp);
void hv__agg_csr_free(mg_csr *m);

/* ---- agg_bottom.c ---- */
/* The bottom level's dense Cholesky factor (and its regions). */
hv_status hv__agg_bottom_factor(mg_agg *g);

#endif
