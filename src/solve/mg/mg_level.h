/*
 * Private: one level of the geometric multigrid hierarchy.
 *
 * The operator on a level is, per cell i,
 *     (A u)_i = alpha * a_i * u_i + sum_axes c_b * sum_faces w_f * (u_i - u_nb)
 * with c_b = beta / h_b^2. On the fine level a_i = 1 on fluid and 0 on solid
 * cells, w_f = 1 on faces between two fluid cells and 0 on walls and faces
 * touching solid. Coarse levels take a = mean of the 2^d children and w = mean
 * of the fine faces covering the coarse face (docs/METHOD.md, "Multigrid"); a
 * child beyond an odd edge counts as solid, so odd sizes coarsen like any
 * masked grid. A level whose weights are all one inside is "plain" and stores
 * no coefficient arrays.
 */
#ifndef HV_SOLVE_MG_LEVEL_H
#define HV_SOLVE_MG_LEVEL_H

#include "solve/backend.h"

#include <stddef.h>
#include <stdint.h>

/* The row kernels are built twice, for AVX2 and the baseline, and picked at
 * load time (GCC function multiversioning): they are arithmetic-bound once the
 * passes are fused (SSE: 52% of a 256^3 solve in the sweep rows). The sanitizer
 * builds keep the clones, so `make sanitize` checks the rows that run. */
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define MG_MULTIVERSION 1
#define MG_KERNEL __attribute__((target_clones("avx2", "default")))
/* and for double rows, which AVX-512 takes in half the instructions */
#define MG_KERNEL_512 __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#define MG_MULTIVERSION 0
#define MG_KERNEL
#define MG_KERNEL_512
#endif

#define MG_MAX_LEVELS 40
#define MG_BOTTOM_CELLS 512

typedef struct mg_level {
    int n[3];
    size_t count;
    size_t sy, sz;  /* cell strides */
    double c[3];    /* beta / h_b^2 (0 for axes beyond dim) */
    int coarsen[3]; /* the next level halves this axis */
    int plain;
    int binary;           /* weighted, with a = 0/1 and w_f = a_c a_nb inside (the fine
                             level of a mask): where u stays 0 on empty cells, as the
                             CPU cycle keeps it, A u needs no weights but dinv */
    float *a;             /* cell weights (NULL when plain) */
    float *w[3];          /* face weights, n[b]+1 along b (NULL when plain) */
    float *dinv;          /* 1/diag (NULL when plain); 0 where the row is empty */
    float *u, *f, *r, *d; /* solution, right-hand side, residual, smoother work */
    double lmax;          /* eigenvalue bound of D^-1 A (Chebyshev) */
    /* bottom level only: connected regions (Poisson) and CG work */
    int nregion;
    int32_t *region;
    double *bwork; /* MG_BOTTOM_WORK doubles per cell for hv__mg_bottom_cg (CPU backend) */
} mg_level;

/* The host-side hierarchy that every multigrid backend (CPU, OpenCL) builds the
 * same way: level sizes, coarsening flags, coefficients (a, w, dinv on weighted
 * levels), Chebyshev bounds and the bottom level's regions (Poisson only).
 * Work vectors (u, f, r, d, b*) are left NULL for the backend to allocate. */
typedef struct mg_hierarchy {
    int dim;
    double alpha;
    int nlev;
    mg_level lv[MG_MAX_LEVELS];
} mg_hierarchy;

/* Builds H for setup s; with_lmax estimates lmax (Chebyshev) on every level.
 * On failure H holds nothing to free. */
hv_status hv__mg_hierarchy_build(mg_hierarchy *H, const hv_setup *s, int with_lmax);
/* The same with at most max_levels levels; below MG_MAX_LEVELS the last level
 * gets no bottom regions (for a caller that puts other coarse levels under
 * the fine one). */
hv_status hv__mg_hierarchy_build_to(mg_hierarchy *H, const hv_setup *s, int with_lmax,
                                    int max_levels);
/* Frees what hv__mg_hierarchy_build allocated (coefficients and bottom regions). */
void hv__mg_hierarchy_free(mg_hierarchy *H);
void hv__mg_level_free_coeffs(mg_level *L);

/* Levels, sizes, a memory-traffic model of one outer iteration and memory held,
 * for hv_solver_get_stats (the mg and opencl backends share the hierarchy). */
void hv__mg_model_stats(const mg_level *lv, int nlev, int dim, hv_smoother smoother, int pre,
                        int post, int pcg, hv_solver_stats *st);
/* The same for the CPU backend (mg_backend.c), whose fused passes (mg_fused.c) move
 * fewer bytes on plain 3D levels and whose plain fine correction is a single
 * pass. */
void hv__mg_model_stats_cpu(const mg_level *lv, int nlev, int dim, hv_smoother smoother, int pre,
                            int post, int pcg, hv_solver_stats *st);

/* Diagonal of the operator at cell (i,j,k) (plain or weighted level). */
double hv__mg_level_diag(const mg_level *L, int dim, double alpha, int i, int j, int k);
/* y = A x in double on a level. */
void hv__mg_level_apply_d(const mg_level *L, int dim, double alpha, const double *x, double *y);
/* Row (j,k) of y = A x in double from x in float, into yrow (n[0] values). */
void hv__mg_level_apply_row_f(const mg_level *L, int dim, double alpha, const float *x,
                              double *yrow, int j, int k);
/* The same from x in double. */
void hv__mg_level_apply_row_d(const mg_level *L, int dim, double alpha, const double *x,
                              double *yrow, int j, int k);

/* Doubles per bottom cell that hv__mg_bottom_cg needs as work. */
#define MG_BOTTOM_WORK 5
/* The bottom level's solve, shared by the backends: u = A^-1 f by CG to 1e-12
 * relative in double (Neumann Poisson: f and u projected mean-free per
 * connected region). work: MG_BOTTOM_WORK * L->count doubles. */
void hv__mg_bottom_cg(const mg_level *L, int dim, double alpha, const float *f, float *u,
                      double *work);

/* The symmetric restriction of the PCG preconditioner (mg_transfer.c; the
 * OpenCL backend uploads pn and runs the same gather in kernels/mg.cl).
 * hv__mg_prolong_norm: pn[fine cell] = 1 / (sum of the prolongation weights that
 * reach non-empty cells of the weighted coarse level C), 0 on solid fine cells
 * and where no weight reaches.
 * hv__mg_restrict_transpose: fc = P^T (pn .* r) / 2^(coarsened axes), 0 on empty
 * coarse cells; pn is NULL when C is plain (weights then sum to one). */
void hv__mg_prolong_norm(const mg_level *F, const mg_level *C, float *pn);
void hv__mg_restrict_transpose(const mg_level *F, const mg_level *C, int dim, const float *pn,
                               const float *r, float *fc, float *work, int nthreads);
/* Floats of work per thread that hv__mg_restrict_transpose needs for F -> C (it
 * runs on at most nthreads threads, each with its own slice of work). */
static inline size_t mg_restrict_transpose_work(const mg_level *F, const mg_level *C)
{
    size_t n = (size_t)F->n[0] + (size_t)C->n[0] + 2 * (size_t)C->n[0] * (size_t)C->n[1];
    return (n + 15) & ~(size_t)15;
}

/* Index of the axis-a face (i,j,k) (the low face of cell (i,j,k)). */
static inline size_t mg_face_index(const mg_level *L, int a, int i, int j, int k)
{
    size_t m0 = (size_t)L->n[0] + (a == 0), m1 = (size_t)L->n[1] + (a == 1);
    return (size_t)i + m0 * ((size_t)j + m1 * (size_t)k);
}

/* Row (j,k) of a weighted level as flat arrays, for loops without branches:
 * cell i of the row has x faces wx[i] (low) and wx[i+1] (high), y faces wyl[i]
 * and wyh[i], z faces wzl[i] and wzh[i] (3D; NULL in 2D), and neighbour rows
 * ym/yp/zm/zp as offsets from the row (0, the row itself, where the face is a
 * wall: its weight is 0 there and the value read is finite). */
typedef struct mg_wrow {
    size_t base;
    const float *wx, *wyl, *wyh, *wzl, *wzh;
    ptrdiff_t ym, yp, zm, zp;
} mg_wrow;

static inline mg_wrow mg_wrow_at(const mg_level *L, int dim, int j, int k)
{
    const size_t nx = (size_t)L->n[0], ny = (size_t)L->n[1];
    mg_wrow R;
    R.base = L->sy * (size_t)j + L->sz * (size_t)k;
    R.wx = L->w[0] + (nx + 1) * ((size_t)j + ny * (size_t)k);
    R.wyl = L->w[1] + nx * ((size_t)j + (ny + 1) * (size_t)k);
    R.wyh = R.wyl + nx;
    R.ym = j > 0 ? -(ptrdiff_t)L->sy : 0;
    R.yp = j < L->n[1] - 1 ? (ptrdiff_t)L->sy : 0;
    R.wzl = R.wzh = NULL;
    R.zm = R.zp = 0;
    if (dim == 3) {
        R.wzl = L->w[2] + nx * ((size_t)j + ny * (size_t)k);
        R.wzh = R.wzl + nx * ny;
        R.zm = k > 0 ? -(ptrdiff_t)L->sz : 0;
        R.zp = k < L->n[2] - 1 ? (ptrdiff_t)L->sz : 0;
    }
    return R;
}

/* Off-diagonal sum  sum_faces c_b w_f u_nb  and diagonal at cell (i,j,k).
 * m is anything with fields dim and alpha; the body serves float and double
 * vectors. kernels/mg.cl computes the same stencil on devices. */
#define MG_STENCIL(L, m, U, i, j, k, c, S, D)                                                      \
    do {                                                                                           \
        if ((L)->plain) {                                                                          \
            double cx_ = (L)->c[0], cy_ = (L)->c[1], cz_ = (L)->c[2];                              \
            D = (m)->alpha;                                                                        \
            S = 0;                                                                                 \
            if (i > 0) {                                                                           \
                S += cx_ * U[c - 1];                                                               \
                D += cx_;                                                                          \
            }                                                                                      \
            if (i < (L)->n[0] - 1) {                                                               \
                S += cx_ * U[c + 1];                                                               \
                D += cx_;                                                                          \
            }                                                                                      \
            if (j > 0) {                                                                           \
                S += cy_ * U[c - (L)->sy];                                                         \
                D += cy_;                                                                          \
            }                                                                                      \
            if (j < (L)->n[1] - 1) {                                                               \
                S += cy_ * U[c + (L)->sy];                                                         \
                D += cy_;                                                                          \
            }                                                                                      \
            if ((m)->dim == 3) {                                                                   \
                if (k > 0) {                                                                       \
                    S += cz_ * U[c - (L)->sz];                                                     \
                    D += cz_;                                                                      \
                }                                                                                  \
                if (k < (L)->n[2] - 1) {                                                           \
                    S += cz_ * U[c + (L)->sz];                                                     \
                    D += cz_;                                                                      \
                }                                                                                  \
            }                                                                                      \
        } else {                                                                                   \
            const float *wx_ = (L)->w[0], *wy_ = (L)->w[1];                                        \
            size_t fx_ = mg_face_index(L, 0, i, j, k), fy_ = mg_face_index(L, 1, i, j, k);         \
            double wl_, wh_;                                                                       \
            D = (m)->alpha * (L)->a[c];                                                            \
            S = 0;                                                                                 \
            wl_ = wx_[fx_];                                                                        \
            wh_ = wx_[fx_ + 1];                                                                    \
            if (wl_ != 0)                                                                          \
                S += (L)->c[0] * wl_ * U[c - 1];                                                   \
            if (wh_ != 0)                                                                          \
                S += (L)->c[0] * wh_ * U[c + 1];                                                   \
            D += (L)->c[0] * (wl_ + wh_);                                                          \
            wl_ = wy_[fy_];                                                                        \
            wh_ = wy_[fy_ + (size_t)(L)->n[0]];                                                    \
            if (wl_ != 0)                                                                          \
                S += (L)->c[1] * wl_ * U[c - (L)->sy];                                             \
            if (wh_ != 0)                                                                          \
                S += (L)->c[1] * wh_ * U[c + (L)->sy];                                             \
            D += (L)->c[1] * (wl_ + wh_);                                                          \
            if ((m)->dim == 3) {                                                                   \
                size_t fz_ = mg_face_index(L, 2, i, j, k);                                         \
                wl_ = (L)->w[2][fz_];                                                              \
                wh_ = (L)->w[2][fz_ + (L)->sz];                                                    \
                if (wl_ != 0)                                                                      \
                    S += (L)->c[2] * wl_ * U[c - (L)->sz];                                         \
                if (wh_ != 0)                                                                      \
                    S += (L)->c[2] * wh_ * U[c + (L)->sz];                                         \
                D += (L)->c[2] * (wl_ + wh_);                                                      \
            }                                                                                      \
        }                                                                                          \
    } while (0)

#endif
