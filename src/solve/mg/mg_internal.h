/*
 * Private to the CPU multigrid backend: its state, the constants its passes
 * share, the plain-row helpers that inline into row loops in several files,
 * and what each file provides to the others (docs/METHOD.md, "Multigrid"):
 *   mg_cpu.c       which kernels this CPU runs (mg_cpu.h)
 *   mg_rows.c      smoother and residual rows (AVX-512, AVX2, baseline) and
 *                  the level-wide sweeps made of them
 *   mg_transfer.c  restriction, prolongation and the PCG's weighted P^T
 *   mg_fused.c     the fused one-pass sweeps of plain 3D levels
 *   mg_cycle.c     smoothing, the V-cycle and full multigrid
 *   agg_*.c        the coarse levels by smoothed aggregation (mg_agg.h,
 *                  agg_internal.h)
 *   mg_backend.c   the backend's entry points and its steps of the outer
 *                  iterations (iterate.h)
 */
#ifndef HV_SOLVE_MG_INTERNAL_H
#define HV_SOLVE_MG_INTERNAL_H

#include "mg_agg.h"
#include "mg_cpu.h"
#include "mg_level.h"

#include <stddef.h>

#if MG_AVX512
/* A float row of nx cells walked in 16-lane chunks, each chunk's x neighbours
 * formed by lane shifts (valignd) of the chunks beside it, zero lanes beyond
 * the row's ends: one load per chunk instead of two unaligned ones that
 * straddle cache lines. mg_x16_start, then mg_x16_next for chunks 0 .. nq-1
 * in order. A kernel may store into the row's cells of one colour between
 * calls: the neighbours it reads are of the other. */
typedef struct mg_x16 {
    const float *row;
    int nq;
    __mmask16 tail; /* the last chunk's lanes inside the row */
    __m512i prev, cur;
} mg_x16;

__attribute__((target("avx512f"))) static inline mg_x16 mg_x16_start(const float *row, int nx)
{
    mg_x16 s;
    s.row = row;
    s.nq = (nx + 15) / 16;
    s.tail = (__mmask16)(nx % 16 ? (1u << (nx % 16)) - 1u : 0xFFFFu);
    s.prev = _mm512_setzero_si512();
    s.cur = _mm512_castps_si512(_mm512_maskz_loadu_ps(s.nq > 1 ? 0xFFFF : s.tail, row));
    return s;
}

/* Chunk c: its cells in *u, their x neighbours in *um and *up; returns the
 * chunk's lanes inside the row. */
__attribute__((target("avx512f"))) static inline __mmask16 mg_x16_next(mg_x16 *s, int c, __m512 *u,
                                                                       __m512 *um, __m512 *up)
{
    __m512i next = c + 1 < s->nq ? _mm512_castps_si512(_mm512_maskz_loadu_ps(
                                       c + 2 < s->nq ? 0xFFFF : s->tail, s->row + 16 * (c + 1)))
                                 : _mm512_setzero_si512();
    *u = _mm512_castsi512_ps(s->cur);
    *um = _mm512_castsi512_ps(_mm512_alignr_epi32(s->cur, s->prev, 15));
    *up = _mm512_castsi512_ps(_mm512_alignr_epi32(next, s->cur, 1));
    s->prev = s->cur;
    s->cur = next;
    return c + 1 < s->nq ? (__mmask16)0xFFFF : s->tail;
}
#endif

/* Levels below this many cells run on one thread: fork-join and barrier costs
 * dominate there (measured: 84% of a 2048^2 solve spun in barriers without it). */
#define MG_PAR_MIN 32768
/* Rows up to this length take the vectorized smoother path. */
#define MG_ROW_BUF 4096
/* Heat steps with solid cells hand over from defect correction to PCG after a
 * correction whose cycles reduced the residual by less than this each. */
#define MG_STAT_SLOW 0.3

typedef struct mg_state {
    const hv_setup *s;
    int dim;
    double alpha;
    int nlev;
    mg_level lv[MG_MAX_LEVELS];
    hv_smoother smoother;
    int pre, post;
    int use_pcg;     /* solid cells: PCG (and its vectors) */
    int stat_masked; /* heat step with solid cells: defect correction first (mg_backend.c) */
    double *rd;      /* fine double work: the residual */
    double *zsum;    /* PCG, Poisson: per-thread sums for z's projection */
    size_t zsum_per; /* doubles per thread in zsum (whole cache lines) */
    int zsum_threads;
    float *p;                    /* PCG's direction (A p is formed in double) */
    double *q;                   /* PCG: A p */
    float *pnorm[MG_MAX_LEVELS]; /* PCG: 1 / prolongation weight sum per fine cell, where
                                    the coarse level is weighted (renormalized) */
    float *rt_work;              /* PCG: hv__mg_restrict_transpose's work, rt_threads slices */
    int rt_threads;
    hv_solver_stats model; /* traffic model (hv__mg_model_stats_cpu) */
    mg_agg *agg;           /* coarse levels by aggregation (solid cells), or NULL */
    int agg_tried;         /* aggregation was built or tried */
    int fine_only;         /* the geometric levels stop at the fine one (aggregation first) */
    int agg_pending;       /* AUTO: build it before the next solve */
} mg_state;

/* v = 0 (n floats), on several threads on large levels. */
static inline void mg_zero_f(float *v, size_t n)
{
#pragma omp parallel for schedule(static) if (n > MG_PAR_MIN)
    for (size_t i = 0; i < n; i++)
        v[i] = 0.0f;
}

/* Neighbour rows and diagonal of a plain-level row (walls drop their faces). */
typedef struct mg_plain_row {
    size_t base;
    ptrdiff_t ym, yp, zm, zp;  /* offsets of the neighbour rows (0 at a wall) */
    double wym, wyp, wzm, wzp; /* 1 for an open face, 0 at a wall */
    double dyz;                /* alpha + the y and z face coefficients */
} mg_plain_row;

static inline mg_plain_row mg_plain_row_at(const mg_state *m, const mg_level *L, int j, int k)
{
    mg_plain_row R;
    R.base = L->sy * (size_t)j + L->sz * (size_t)k;
    R.wym = j > 0;
    R.wyp = j < L->n[1] - 1;
    R.wzm = m->dim == 3 && k > 0;
    R.wzp = m->dim == 3 && k < L->n[2] - 1;
    R.ym = R.wym ? -(ptrdiff_t)L->sy : 0;
    R.yp = R.wyp ? (ptrdiff_t)L->sy : 0;
    R.zm = R.wzm ? -(ptrdiff_t)L->sz : 0;
    R.zp = R.wzp ? (ptrdiff_t)L->sz : 0;
    R.dyz = m->alpha + L->c[1] * (R.wym + R.wyp) + L->c[2] * (R.wzm + R.wzp);
    return R;
}

/* out = f - A u along one plain row, for float or double vectors (T); the
 * interior loop has no branches so that it vectorizes. */
#define MG_PLAIN_ROW_RESIDUAL(T, TO, L, R, U, F, OUTROW, NORM)                                     \
    do {                                                                                           \
        const int nx_ = (L)->n[0];                                                                 \
        const T *u_ = (U) + (R).base, *f_ = (F) + (R).base;                                        \
        TO *o_ = (OUTROW);                                                                         \
        const T cx_ = (T)(L)->c[0], cy_ = (T)(L)->c[1], cz_ = (T)(L)->c[2];                        \
        const T wym_ = (T)(R).wym, wyp_ = (T)(R).wyp, wzm_ = (T)(R).wzm, wzp_ = (T)(R).wzp;        \
        const T *ym_ = u_ + (R).ym, *yp_ = u_ + (R).yp, *zm_ = u_ + (R).zm, *zp_ = u_ + (R).zp;    \
        const T din_ = (T)((R).dyz + 2 * (L)->c[0]);                                               \
        for (int i_ = 0; i_ < nx_; i_++) {                                                         \
            T s_ =                                                                                 \
                cy_ * (wym_ * ym_[i_] + wyp_ * yp_[i_]) + cz_ * (wzm_ * zm_[i_] + wzp_ * zp_[i_]); \
            T d_;                                                                                  \
            if (i_ > 0 && i_ < nx_ - 1) {                                                          \
                s_ += cx_ * (u_[i_ - 1] + u_[i_ + 1]);                                             \
                d_ = din_;                                                                         \
            } else {                                                                               \
                d_ = (T)(R).dyz;                                                                   \
                if (i_ > 0) {                                                                      \
                    s_ += cx_ * u_[i_ - 1];                                                        \
                    d_ += cx_;                                                                     \
                }                                                                                  \
                if (i_ < nx_ - 1) {                                                                \
                    s_ += cx_ * u_[i_ + 1];                                                        \
                    d_ += cx_;                                                                     \
                }                                                                                  \
            }                                                                                      \
            T r_ = f_[i_] - (d_ * u_[i_] - s_);                                                    \
            o_[i_] = (TO)r_;                                                                       \
            NORM += (double)r_ * (double)r_;                                                       \
        }                                                                                          \
    } while (0)

/* Levels whose red-black sweeps run plane by plane in one pass (hv__mg_fused_pass
 * in MG_FS_PLAIN mode): 3D levels, plain or weighted. */
static inline int mg_level_sweep_fusable(const mg_state *m, const mg_level *L)
{
    return m->dim == 3 && L->n[2] >= 3 && L->n[1] >= 8 && L->n[0] <= MG_ROW_BUF;
}

/* Plain levels, whose fused passes also start from zero, restrict and prolong. */
static inline int mg_level_fusable(const mg_state *m, const mg_level *L)
{
    return L->plain && mg_level_sweep_fusable(m, L);
}

/* ---------- mg_rows.c ---------- */

/* One colour (col) of row (j,k) of a plain level (MG_KERNEL). */
void hv__mg_rb_row_plain(const mg_state *m, const mg_level *L, float *u, const float *f, int j,
                         int k, int col);
#if MG_AVX512
/* One colour of plane k of a plain level in AVX-512 rows. */
__attribute__((target("avx512f"))) void hv__mg_rb_plane_avx512(const mg_state *m, const mg_level *L,
                                                               int k, int col);
#endif
/* One colour of row (j,k) of a plain or weighted level, in place on L->u. */
void hv__mg_rb_row(const mg_state *m, const mg_level *L, int j, int k, int col);
/* One colour of a red-black Gauss-Seidel sweep over a level. */
void hv__mg_rb_sweep(const mg_state *m, mg_level *L, int col);
/* L->r = L->f - A L->u (float). */
void hv__mg_level_residual(const mg_state *m, mg_level *L);
/* Jacobi (cd = 0) or Chebyshev step from L->r: d = cd d + cr D^-1 r, u += d. */
void hv__mg_level_jacobi_update(const mg_state *m, mg_level *L, double cd, double cr);

/* ---------- mg_transfer.c ---------- */

/* f_C = mean of the children of src (children beyond an odd edge count as 0). */
void hv__mg_restrict_field(const mg_state *m, const mg_level *F, const float *src, mg_level *C);
/* Row (j,k) of u_F += P u_C (= when set) from a plain coarse level; line:
 * C->n[0] floats of work (MG_KERNEL). */
void hv__mg_prolong_row_plain(mg_level *F, const mg_level *C, int j, int k, float *line, int set);
/* u_F += P u_C (u_F = P u_C when set). */
void hv__mg_prolong_add(const mg_state *m, mg_level *F, const mg_level *C, int set);

/* ---------- mg_fused.c ---------- */

enum { MG_FS_PLAIN, MG_FS_ZERO, MG_FS_RESTRICT, MG_FS_PROLONG };
/* One red-black sweep of a fusable level in one pass over memory, the first
 * colour `first`; mode MG_FS_ZERO, MG_FS_RESTRICT or MG_FS_PROLONG fuses the
 * start from u = 0, the restriction of the residual to C->f or u += P u_C. */
void hv__mg_fused_pass(const mg_state *m, mg_level *L, mg_level *C, int mode, int first);

/* ---------- mg_cycle.c ---------- */

/* One V-cycle on level l (u from zero unless guess; sym: the symmetric cycle
 * of PCG), and full multigrid for lv[0].f. The result is in lv[0].u. */
void hv__mg_vcycle(const mg_state *m, int l, int guess, int sym);
void hv__mg_fmg(const mg_state *m);

#endif
