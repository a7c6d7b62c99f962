/*
 * Matrix-free geometric multigrid for (alpha I - beta Laplacian) u = f on
 * cell-centred grids with Neumann walls and solid cells (docs/METHOD.md,
 * "Multigrid").
 *
 * Float V-cycles (red-black Gauss-Seidel, weighted Jacobi or Chebyshev
 * smoothing; mean-of-children restriction; cell-centred linear prolongation;
 * CG on the bottom level) inside a double-precision defect-correction loop, so
 * tolerances reach 1e-10 although the hierarchy is float. With solid cells the
 * cycle preconditions CG instead (thin walls can stall plain geometric MG), and
 * the smoother order is then made symmetric. Solves from a zero guess start with
 * full multigrid, which saves one cycle of five for the heat step at 1e-6.
 */
#include "mg_level.h"
#include "backend.h"
#include "core/error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

/* MG_KERNEL (mg_level.h): row kernels built for AVX2 and the baseline. */
#if MG_MULTIVERSION
#define MG_AVX512 1
#include <immintrin.h>
#else
#define MG_AVX512 0
#endif

/* Levels below this many cells run on one thread: fork-join and barrier costs
 * dominate there (measured: 84% of a 2048^2 solve spun in barriers without it). */
#define MG_PAR_MIN 32768
/* Most V-cycles per double correction in the automatic mode (3D; one less in 2D). */
#define MG_AUTO_CYCLES 3
/* Rows up to this length take the vectorized smoother path. */
#define MG_ROW_BUF 4096

typedef struct mg_state {
    const hv_setup *s;
    int dim;
    double alpha;
    int nlev;
    mg_level lv[MG_MAX_LEVELS];
    hv_smoother smoother;
    int pre, post;
    int use_pcg;
    double *rd, *p, *z, *q; /* fine double work */
    float *pnorm[MG_MAX_LEVELS]; /* PCG: 1 / prolongation weight sum per fine cell, where
                                    the coarse level is weighted (renormalized) */
    float *rt_work;              /* PCG: mg_restrict_transpose's work, rt_threads slices */
    int rt_threads;
    hv_solver_stats model;       /* traffic model (mg_model_stats_cpu) */
} mg_state;

static void zero_f(float *v, size_t n)
{
#pragma omp parallel for schedule(static) if (n > MG_PAR_MIN)
    for (size_t i = 0; i < n; i++)
        v[i] = 0.0f;
}

/* ---------- stencil kernels ---------- */

#if MG_AVX512
/* One colour (cells of parity i0) of a plain row of nx cells, walls included,
 * in 16-lane chunks aligned to the row start: the row's own values come from
 * one load per chunk, their x-neighbours by lane shifts (valignd) of the chunks
 * before and after, instead of two unaligned loads that straddle cache lines;
 * a wall cell's missing x-neighbour is a zero lane and its lane takes its own
 * diagonal (dyz + cx, or dyz alone when nx = 1). Every lane is computed and a
 * masked store keeps this colour's cells, so the other colour's (which this
 * row reads) are never written. cym..czp are the face coefficients, 0 at a
 * y or z wall; dyz = alpha + the open y and z faces. */
__attribute__((target("avx512f"))) static void rb_row_avx512(
    float *ur, const float *fr, const float *ym, const float *yp, const float *zm, const float *zp,
    int nx, int i0, float cx, float cym, float cyp, float czm, float czp, float dyz)
{
    const __m512 vcx = _mm512_set1_ps(cx), vcym = _mm512_set1_ps(cym), vcyp = _mm512_set1_ps(cyp),
                 vczm = _mm512_set1_ps(czm), vczp = _mm512_set1_ps(czp),
                 vinv = _mm512_set1_ps(1.0f / (dyz + 2 * cx));
    const float wall = dyz + cx, inv_wall = wall > 0 ? 1.0f / wall : 0.0f;
    const float inv_one = dyz > 0 ? 1.0f / dyz : 0.0f;
    const __mmask16 colour = i0 ? 0xAAAA : 0x5555; /* lane b is cell q + b, q even */
    const int nq = (nx + 15) / 16, last = nx - 1;
    const __mmask16 tail = (__mmask16)(nx % 16 ? (1u << (nx % 16)) - 1u : 0xFFFFu);
    __m512i prev = _mm512_setzero_si512();
    __m512i cur = _mm512_castps_si512(_mm512_maskz_loadu_ps(nq > 1 ? 0xFFFF : tail, ur));
    for (int c = 0, q = 0; c < nq; c++, q += 16) {
        __mmask16 valid = c + 1 < nq ? (__mmask16)0xFFFF : tail;
        __m512i next = c + 1 < nq
                           ? _mm512_castps_si512(_mm512_maskz_loadu_ps(c + 2 < nq ? 0xFFFF : tail, ur + q + 16))
                           : _mm512_setzero_si512();
        __m512 um = _mm512_castsi512_ps(_mm512_alignr_epi32(cur, prev, 15));
        __m512 up = _mm512_castsi512_ps(_mm512_alignr_epi32(next, cur, 1));
        __m512 sm = _mm512_fmadd_ps(vcx, _mm512_add_ps(um, up), _mm512_maskz_loadu_ps(valid, fr + q));
        sm = _mm512_fmadd_ps(vcym, _mm512_maskz_loadu_ps(valid, ym + q), sm);
        sm = _mm512_fmadd_ps(vcyp, _mm512_maskz_loadu_ps(valid, yp + q), sm);
        sm = _mm512_fmadd_ps(vczm, _mm512_maskz_loadu_ps(valid, zm + q), sm);
        sm = _mm512_fmadd_ps(vczp, _mm512_maskz_loadu_ps(valid, zp + q), sm);
        __m512 inv = vinv;
        if (c == 0)
            inv = _mm512_mask_mov_ps(inv, 1, _mm512_set1_ps(nx > 1 ? inv_wall : inv_one));
        if (c + 1 == nq && last > 0)
            inv = _mm512_mask_mov_ps(inv, (__mmask16)(1u << (last - q)), _mm512_set1_ps(inv_wall));
        _mm512_mask_storeu_ps(ur + q, colour & valid, _mm512_mul_ps(sm, inv));
        prev = cur;
        cur = next;
    }
}

/* Fine row uf (nf cells) += P u_C (= P u_C when `set`) with x coarsened: the
 * coarse line a00 r00 + a01 r01 + a10 r10 + a11 r11 (the y and z weights) is
 * formed in registers, 16 coarse cells at a time; fine cell 2I takes 3/4
 * line[I] + 1/4 line[I-1], 2I+1 takes 3/4 line[I] + 1/4 line[I+1] (line[I]
 * alone at the walls), their neighbours come by lane shifts of the chunks
 * beside, and the two results are interleaved by permutes so that the fine
 * row is read and written in whole vectors. */
__attribute__((target("avx512f"))) static void prolong_row_avx512(float *uf, int nf, const float *r00,
                                                                  const float *r01, const float *r10,
                                                                  const float *r11, float a00, float a01,
                                                                  float a10, float a11, int nc, int set)
{
    const __m512 q3 = _mm512_set1_ps(0.75f), q1 = _mm512_set1_ps(0.25f);
    const __m512 w00 = _mm512_set1_ps(a00), w01 = _mm512_set1_ps(a01), w10 = _mm512_set1_ps(a10),
                 w11 = _mm512_set1_ps(a11);
    const __m512i lo = _mm512_set_epi32(23, 7, 22, 6, 21, 5, 20, 4, 19, 3, 18, 2, 17, 1, 16, 0);
    const __m512i hi = _mm512_set_epi32(31, 15, 30, 14, 29, 13, 28, 12, 27, 11, 26, 10, 25, 9, 24, 8);
    const int nq = (nc + 15) / 16;
#define PROLONG_LINE(I_, M_)                                                                          \
    _mm512_castps_si512(_mm512_fmadd_ps(                                                              \
        w11, _mm512_maskz_loadu_ps(M_, r11 + (I_)),                                                   \
        _mm512_fmadd_ps(w10, _mm512_maskz_loadu_ps(M_, r10 + (I_)),                                   \
                        _mm512_fmadd_ps(w01, _mm512_maskz_loadu_ps(M_, r01 + (I_)),                   \
                                        _mm512_mul_ps(w00, _mm512_maskz_loadu_ps(M_, r00 + (I_)))))))
    const __mmask16 tail = (__mmask16)(nc % 16 ? (1u << (nc % 16)) - 1u : 0xFFFFu);
    __m512i prev = _mm512_setzero_si512();
    __m512i cur = PROLONG_LINE(0, nq > 1 ? (__mmask16)0xFFFF : tail);
    for (int c = 0, I = 0; c < nq; c++, I += 16) {
        __m512i next = c + 1 < nq ? PROLONG_LINE(I + 16, c + 2 < nq ? (__mmask16)0xFFFF : tail)
                                  : _mm512_setzero_si512();
        __m512 l = _mm512_castsi512_ps(cur);
        __m512 t = _mm512_mul_ps(q3, l);
        __m512 e = _mm512_fmadd_ps(q1, _mm512_castsi512_ps(_mm512_alignr_epi32(cur, prev, 15)), t);
        __m512 o = _mm512_fmadd_ps(q1, _mm512_castsi512_ps(_mm512_alignr_epi32(next, cur, 1)), t);
        if (c == 0)
            e = _mm512_mask_mov_ps(e, 1, l);
        if (c + 1 == nq)
            o = _mm512_mask_mov_ps(o, (__mmask16)(1u << (nc - 1 - I)), l);
        int nfc = nf - 2 * I; /* fine cells left from 2I */
        __mmask16 m0 = (__mmask16)(nfc >= 16 ? 0xFFFFu : (1u << nfc) - 1u);
        __mmask16 m1 = (__mmask16)(nfc >= 32 ? 0xFFFFu : nfc > 16 ? (1u << (nfc - 16)) - 1u : 0u);
        float *d = uf + 2 * I;
        __m512 v0 = _mm512_permutex2var_ps(e, lo, o), v1 = _mm512_permutex2var_ps(e, hi, o);
        if (!set) {
            v0 = _mm512_add_ps(_mm512_maskz_loadu_ps(m0, d), v0);
            v1 = _mm512_add_ps(_mm512_maskz_loadu_ps(m1, d + 16), v1);
        }
        _mm512_mask_storeu_ps(d, m0, v0);
        if (m1)
            _mm512_mask_storeu_ps(d + 16, m1, v1);
        prev = cur;
        cur = next;
    }
#undef PROLONG_LINE
}

/* The AVX-512 kernels where the CPU has them, unless HV_NO512 is set to
 * anything but empty or 0 (the tests run the other path that way). */
static int mg_avx512(void)
{
    static int have = -1;
    if (have < 0) {
        const char *e = getenv("HV_NO512");
        have = __builtin_cpu_supports("avx512f") && !(e && *e && strcmp(e, "0")) ? 1 : 0;
    }
    return have;
}
#endif

/* Plain-level interior row update: the hot loop of the smoother, branch-free. */
MG_KERNEL static void rb_row_plain(const mg_state *m, const mg_level *L, float *u, const float *f, int j,
                         int k, int col)
{
    const int nx = L->n[0];
    const float cx = (float)L->c[0], cy = (float)L->c[1], cz = (float)L->c[2];
    const size_t base = L->sy * (size_t)j + L->sz * (size_t)k;
    float *ur = u + base;
    const float *fr = f + base;
    const float wym = j > 0, wyp = j < L->n[1] - 1;
    const float wzm = (m->dim == 3 && k > 0), wzp = (m->dim == 3 && k < L->n[2] - 1);
    const float *ym = j > 0 ? ur - L->sy : ur, *yp = j < L->n[1] - 1 ? ur + L->sy : ur;
    const float *zm = wzm ? ur - L->sz : ur, *zp = wzp ? ur + L->sz : ur;
    const float dyz = (float)m->alpha + cy * (wym + wyp) + cz * (wzm + wzp);
    const float inv_in = 1.0f / (dyz + 2 * cx);
    int i0 = (j + k + col) & 1;
#if MG_AVX512
    if (mg_avx512()) {
        rb_row_avx512(ur, fr, ym, yp, zm, zp, nx, i0, cx, cy * wym, cy * wyp, cz * wzm, cz * wzp, dyz);
        return;
    }
#endif
    int i = i0;
    if (i == 0) {
        float d = dyz + (nx > 1 ? cx : 0);
        float s = fr[0] + (nx > 1 ? cx * ur[1] : 0) + cy * (wym * ym[0] + wyp * yp[0]) +
                  cz * (wzm * zm[0] + wzp * zp[0]);
        ur[0] = d > 0 ? s / d : 0;
        i = 2;
    }
    int last = nx - 1;
    if (nx <= MG_ROW_BUF) {
        /* Update every interior cell into a buffer (contiguous, so it vectorizes;
         * the other colour's values are not changed by this colour), then keep
         * this colour's cells: twice the flops, a fraction of the time. */
        float buf[MG_ROW_BUF];
        for (int q = 1; q < last; q++)
            buf[q] = (fr[q] + cx * (ur[q - 1] + ur[q + 1]) + cy * (wym * ym[q] + wyp * yp[q]) +
                      cz * (wzm * zm[q] + wzp * zp[q])) *
                     inv_in;
        for (; i < last; i += 2)
            ur[i] = buf[i];
    } else {
        for (; i < last; i += 2)
            ur[i] = (fr[i] + cx * (ur[i - 1] + ur[i + 1]) + cy * (wym * ym[i] + wyp * yp[i]) +
                     cz * (wzm * zm[i] + wzp * zp[i])) *
                    inv_in;
    }
    if (i == last && last > 0) {
        float d = dyz + cx;
        float s = fr[i] + cx * ur[i - 1] + cy * (wym * ym[i] + wyp * yp[i]) +
                  cz * (wzm * zm[i] + wzp * zp[i]);
        ur[i] = s / d;
    }
}

#if MG_AVX512
/* One colour of plane k of a plain level: rb_row_avx512 over its rows, inlined
 * here, without rb_row_plain's call and set-up per row. */
__attribute__((target("avx512f"))) static void rb_plane_avx512(const mg_state *m, const mg_level *L, int k,
                                                               int col)
{
    const int nx = L->n[0], ny = L->n[1];
    const float cx = (float)L->c[0], cy = (float)L->c[1], cz = (float)L->c[2];
    const float wzm = m->dim == 3 && k > 0, wzp = m->dim == 3 && k < L->n[2] - 1;
    const ptrdiff_t zmo = wzm ? -(ptrdiff_t)L->sz : 0, zpo = wzp ? (ptrdiff_t)L->sz : 0;
    for (int j = 0; j < ny; j++) {
        float *ur = L->u + L->sy * (size_t)j + L->sz * (size_t)k;
        const float *fr = L->f + (ur - L->u);
        const float wym = j > 0, wyp = j < ny - 1;
        const float dyz = (float)m->alpha + cy * (wym + wyp) + cz * (wzm + wzp);
        rb_row_avx512(ur, fr, wym ? ur - L->sy : ur, wyp ? ur + L->sy : ur, ur + zmo, ur + zpo, nx,
                      (j + k + col) & 1, cx, cy * wym, cy * wyp, cz * wzm, cz * wzp, dyz);
    }
}
#endif

/* Colour col of plane k of a plain level. */
static void rb_plane_plain(const mg_state *m, const mg_level *L, int k, int col)
{
#if MG_AVX512
    if (mg_avx512()) {
        rb_plane_avx512(m, L, k, col);
        return;
    }
#endif
    for (int j = 0; j < L->n[1]; j++)
        rb_row_plain(m, L, L->u, L->f, j, k, col);
}

/* Off-diagonal sum at cell q of a weighted row (float; walls and solid faces
 * have weight 0 and read a finite value). */
#define WROW_SUM(R, u, q, cx, cy, cz)                                                              \
    ((cx) * ((R).wx[q] * (u)[(q) - 1] + (R).wx[(q) + 1] * (u)[(q) + 1]) +                          \
     (cy) * ((R).wyl[q] * (u)[(R).ym + (q)] + (R).wyh[q] * (u)[(R).yp + (q)]) +                     \
     ((R).wzl ? (cz) * ((R).wzl[q] * (u)[(R).zm + (q)] + (R).wzh[q] * (u)[(R).zp + (q)]) : 0.0f))

/* Diagonal at cell q of a weighted row. */
#define WROW_DIAG(R, L, alpha, q, cx, cy, cz)                                                      \
    ((alpha) * (L)->a[(R).base + (q)] + (cx) * ((R).wx[q] + (R).wx[(q) + 1]) +                     \
     (cy) * ((R).wyl[q] + (R).wyh[q]) + ((R).wzl ? (cz) * ((R).wzl[q] + (R).wzh[q]) : 0.0f))

/* WROW_SUM at the first or last cell q of a row of nx, without the missing x neighbour. */
static inline float wrow_edge_sum(const mg_wrow *R, const float *u, int q, int nx, float cx, float cy,
                                  float cz)
{
    float s = cy * (R->wyl[q] * u[R->ym + q] + R->wyh[q] * u[R->yp + q]);
    if (R->wzl)
        s += cz * (R->wzl[q] * u[R->zm + q] + R->wzh[q] * u[R->zp + q]);
    if (q > 0)
        s += cx * R->wx[q] * u[q - 1];
    if (q < nx - 1)
        s += cx * R->wx[q + 1] * u[q + 1];
    return s;
}

/* One colour of row (j,k) of a weighted level: u = (f + S) / D, 0 where the row
 * of A is empty (dinv = 0). The first and last cells are done apart (their
 * missing x neighbour lies outside the row); the interior is computed for both
 * colours into a buffer, a loop without branches, and this colour kept. */
MG_KERNEL static void rb_row_weighted(const mg_state *m, const mg_level *L, int j, int k, int col)
{
    const int nx = L->n[0];
    const float cx = (float)L->c[0], cy = (float)L->c[1], cz = (float)L->c[2];
    const mg_wrow R = mg_wrow_at(L, m->dim, j, k);
    float *u = L->u + R.base;
    const float *f = L->f + R.base, *dinv = L->dinv + R.base;
    int i = (j + k + col) & 1;
    if (i == 0)
        u[0] = (f[0] + wrow_edge_sum(&R, u, 0, nx, cx, cy, cz)) * dinv[0];
    if (nx > 1 && ((nx - 1) & 1) == i)
        u[nx - 1] = (f[nx - 1] + wrow_edge_sum(&R, u, nx - 1, nx, cx, cy, cz)) * dinv[nx - 1];
    if (i == 0)
        i = 2;
    if (L->binary && nx <= MG_ROW_BUF) {
        /* solid neighbours hold u = 0: the plain stencil, with this cell's dinv */
        const float wym = R.ym != 0, wyp = R.yp != 0, wzm = R.zm != 0, wzp = R.zp != 0;
        const float *ym = u + R.ym, *yp = u + R.yp, *zm = u + R.zm, *zp = u + R.zp;
        float buf[MG_ROW_BUF];
        for (int q = 1; q < nx - 1; q++)
            buf[q] = (f[q] + cx * (u[q - 1] + u[q + 1]) + cy * (wym * ym[q] + wyp * yp[q]) +
                      cz * (wzm * zm[q] + wzp * zp[q])) *
                     dinv[q];
        for (; i < nx - 1; i += 2)
            u[i] = buf[i];
    } else if (nx <= MG_ROW_BUF) {
        float buf[MG_ROW_BUF];
        if (R.wzl) {
            for (int q = 1; q < nx - 1; q++)
                buf[q] = (f[q] + cx * (R.wx[q] * u[q - 1] + R.wx[q + 1] * u[q + 1]) +
                          cy * (R.wyl[q] * u[R.ym + q] + R.wyh[q] * u[R.yp + q]) +
                          cz * (R.wzl[q] * u[R.zm + q] + R.wzh[q] * u[R.zp + q])) *
                         dinv[q];
        } else {
            for (int q = 1; q < nx - 1; q++)
                buf[q] = (f[q] + cx * (R.wx[q] * u[q - 1] + R.wx[q + 1] * u[q + 1]) +
                          cy * (R.wyl[q] * u[R.ym + q] + R.wyh[q] * u[R.yp + q])) *
                         dinv[q];
        }
        for (; i < nx - 1; i += 2)
            u[i] = buf[i];
    } else {
        for (; i < nx - 1; i += 2)
            u[i] = (f[i] + WROW_SUM(R, u, i, cx, cy, cz)) * dinv[i];
    }
}

static void rb_sweep(const mg_state *m, mg_level *L, int col)
{
    float *u = L->u;
    const float *f = L->f;
    if (L->plain) {
#pragma omp parallel for collapse(2) schedule(static) if (L->count > MG_PAR_MIN)
        for (int k = 0; k < L->n[2]; k++)
            for (int j = 0; j < L->n[1]; j++)
                rb_row_plain(m, L, u, f, j, k, col);
        return;
    }
#pragma omp parallel for collapse(2) schedule(static) if (L->count > MG_PAR_MIN)
    for (int k = 0; k < L->n[2]; k++)
        for (int j = 0; j < L->n[1]; j++)
            rb_row_weighted(m, L, j, k, col);
}

/* Neighbour rows and diagonal of a plain-level row (walls drop their faces). */
typedef struct plain_row {
    size_t base;
    ptrdiff_t ym, yp, zm, zp; /* offsets of the neighbour rows (0 at a wall) */
    double wym, wyp, wzm, wzp; /* 1 for an open face, 0 at a wall */
    double dyz;                /* alpha + the y and z face coefficients */
} plain_row;

static inline plain_row plain_row_at(const mg_state *m, const mg_level *L, int j, int k)
{
    plain_row R;
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
#define PLAIN_ROW_RESIDUAL(T, TO, L, R, U, F, OUTROW, NORM)                                            \
    do {                                                                                              \
        const int nx_ = (L)->n[0];                                                                    \
        const T *u_ = (U) + (R).base, *f_ = (F) + (R).base;                                           \
        TO *o_ = (OUTROW);                                                                            \
        const T cx_ = (T)(L)->c[0], cy_ = (T)(L)->c[1], cz_ = (T)(L)->c[2];                           \
        const T wym_ = (T)(R).wym, wyp_ = (T)(R).wyp, wzm_ = (T)(R).wzm, wzp_ = (T)(R).wzp;           \
        const T *ym_ = u_ + (R).ym, *yp_ = u_ + (R).yp, *zm_ = u_ + (R).zm, *zp_ = u_ + (R).zp;       \
        const T din_ = (T)((R).dyz + 2 * (L)->c[0]);                                                  \
        for (int i_ = 0; i_ < nx_; i_++) {                                                            \
            T s_ = cy_ * (wym_ * ym_[i_] + wyp_ * yp_[i_]) + cz_ * (wzm_ * zm_[i_] + wzp_ * zp_[i_]); \
            T d_;                                                                                     \
            if (i_ > 0 && i_ < nx_ - 1) {                                                             \
                s_ += cx_ * (u_[i_ - 1] + u_[i_ + 1]);                                                \
                d_ = din_;                                                                            \
            } else {                                                                                  \
                d_ = (T)(R).dyz;                                                                      \
                if (i_ > 0) { s_ += cx_ * u_[i_ - 1]; d_ += cx_; }                                    \
                if (i_ < nx_ - 1) { s_ += cx_ * u_[i_ + 1]; d_ += cx_; }                              \
            }                                                                                         \
            T r_ = f_[i_] - (d_ * u_[i_] - s_);                                                       \
            o_[i_] = (TO)r_;                                                                          \
            NORM += (double)r_ * (double)r_;                                                          \
        }                                                                                             \
    } while (0)

/* Row (j,k) of r = f - A u on a weighted level. */
MG_KERNEL static void residual_row_weighted(const mg_state *m, const mg_level *L, int j, int k)
{
    const float alpha = (float)m->alpha, cx = (float)L->c[0], cy = (float)L->c[1], cz = (float)L->c[2];
    const int nx = L->n[0];
    const mg_wrow R = mg_wrow_at(L, m->dim, j, k);
    const float *ur = L->u + R.base, *fr = L->f + R.base;
    float *rr = L->r + R.base;
    for (int q = 0; q < nx; q += nx - 1 > 0 ? nx - 1 : 1) /* the first and last cells */
        rr[q] = fr[q] - (WROW_DIAG(R, L, alpha, q, cx, cy, cz) * ur[q] - wrow_edge_sum(&R, ur, q, nx, cx, cy, cz));
    if (L->binary) { /* solid neighbours hold u = 0; D = 1 / dinv, 0 on empty rows */
        const float wym = R.ym != 0, wyp = R.yp != 0, wzm = R.zm != 0, wzp = R.zp != 0;
        const float *ym = ur + R.ym, *yp = ur + R.yp, *zm = ur + R.zm, *zp = ur + R.zp;
        const float *dv = L->dinv + R.base;
        for (int q = 1; q < nx - 1; q++) {
            float sn = cx * (ur[q - 1] + ur[q + 1]) + cy * (wym * ym[q] + wyp * yp[q]) + cz * (wzm * zm[q] + wzp * zp[q]);
            rr[q] = dv[q] > 0 ? fr[q] - (ur[q] / dv[q] - sn) : fr[q];
        }
        return;
    }
    for (int q = 1; q < nx - 1; q++)
        rr[q] = fr[q] - (WROW_DIAG(R, L, alpha, q, cx, cy, cz) * ur[q] - WROW_SUM(R, ur, q, cx, cy, cz));
}

/* r = f - A u on a level (float). */
static void level_residual(const mg_state *m, mg_level *L)
{
    const float *u = L->u, *f = L->f;
    float *r = L->r;
    if (L->plain) {
#pragma omp parallel for collapse(2) schedule(static) if (L->count > MG_PAR_MIN)
        for (int k = 0; k < L->n[2]; k++)
            for (int j = 0; j < L->n[1]; j++) {
                plain_row R = plain_row_at(m, L, j, k);
                float unused = 0;
                PLAIN_ROW_RESIDUAL(float, float, L, R, u, f, r + R.base, unused);
                (void)unused;
            }
        return;
    }
#pragma omp parallel for collapse(2) schedule(static) if (L->count > MG_PAR_MIN)
    for (int k = 0; k < L->n[2]; k++)
        for (int j = 0; j < L->n[1]; j++)
            residual_row_weighted(m, L, j, k);
}

/* y = A x in double on a level (fine residuals, bottom CG). */
static void level_apply_d(const mg_state *m, const mg_level *L, const double *x, double *y)
{
    mg_level_apply_d(L, m->dim, m->alpha, x, y);
}

static double level_diag_at(const mg_state *m, const mg_level *L, size_t c, int i, int j, int k)
{
    return L->plain ? mg_level_diag(L, m->dim, m->alpha, i, j, k) : (L->dinv[c] > 0 ? 1.0 / L->dinv[c] : 0.0);
}

/* u += omega_k D^-1 r, the Jacobi-type update; with cheb != NULL the Chebyshev
 * recurrence d = rho*rho_old*d + 2 rho/delta D^-1 r (Chebyshev on D^-1 A,
 * docs/METHOD.md, "Multigrid"). */
static void level_jacobi_update(const mg_state *m, mg_level *L, double cd, double cr)
{
#pragma omp parallel for collapse(2) schedule(static) if (L->count > MG_PAR_MIN)
    for (int k = 0; k < L->n[2]; k++)
        for (int j = 0; j < L->n[1]; j++)
            for (int i = 0; i < L->n[0]; i++) {
                size_t c = (size_t)i + L->sy * j + L->sz * k;
                double dg = level_diag_at(m, L, c, i, j, k);
                double z = dg > 0 ? L->r[c] / dg : 0.0;
                double d = cd * L->d[c] + cr * z;
                L->d[c] = (float)d;
                L->u[c] += (float)d;
            }
}

enum { FS_PLAIN, FS_ZERO, FS_RESTRICT, FS_PROLONG };
static int level_fusable(const mg_state *m, const mg_level *L);
static void fused_pass(const mg_state *m, mg_level *L, mg_level *C, int mode, int first);

static void smooth(const mg_state *m, mg_level *L, int steps, int reverse)
{
    if (steps <= 0)
        return;
    if (m->smoother == HV_SMOOTH_RBGS) {
        int fused = level_fusable(m, L);
        for (int s = 0; s < steps; s++) {
            if (fused) {
                fused_pass(m, L, NULL, FS_PLAIN, reverse ? 1 : 0);
                continue;
            }
            rb_sweep(m, L, reverse ? 1 : 0);
            rb_sweep(m, L, reverse ? 0 : 1);
        }
    } else if (m->smoother == HV_SMOOTH_JACOBI) {
        double omega = m->dim == 3 ? 6.0 / 7.0 : 4.0 / 5.0;
        for (int s = 0; s < steps; s++) {
            level_residual(m, L);
            level_jacobi_update(m, L, 0.0, omega);
        }
    } else {
        /* Chebyshev of degree 2*steps on [lmax/8, lmax]. */
        double lmax = L->lmax, lmin = lmax / 8;
        double theta = 0.5 * (lmax + lmin), delta = 0.5 * (lmax - lmin);
        double sigma = theta / delta, rho_old = 1.0 / sigma;
        level_residual(m, L);
        level_jacobi_update(m, L, 0.0, 1.0 / theta);
        for (int s = 1; s < 2 * steps; s++) {
            double rho = 1.0 / (2 * sigma - rho_old);
            level_residual(m, L);
            level_jacobi_update(m, L, rho * rho_old, 2 * rho / delta);
            rho_old = rho;
        }
    }
}

/* f_C = mean of the children of r_F (children beyond an odd edge count as 0). */
static void restrict_field(const mg_state *m, const mg_level *F, const float *src, mg_level *C)
{
    const int *co = F->coarsen;
    int nchild = 1;
    for (int b = 0; b < m->dim; b++)
        nchild *= co[b] ? 2 : 1;
    const float scale = 1.0f / (float)nchild;
#pragma omp parallel for collapse(2) schedule(static) if (F->count > MG_PAR_MIN)
    for (int K = 0; K < C->n[2]; K++)
        for (int J = 0; J < C->n[1]; J++)
            for (int I = 0; I < C->n[0]; I++) {
                int i0 = co[0] ? 2 * I : I, j0 = co[1] ? 2 * J : J, k0 = co[2] ? 2 * K : K;
                int i1 = co[0] && i0 + 1 < F->n[0] ? i0 + 1 : i0;
                int j1 = co[1] && j0 + 1 < F->n[1] ? j0 + 1 : j0;
                int k1 = co[2] && k0 + 1 < F->n[2] ? k0 + 1 : k0;
                float s = 0;
                for (int k = k0; k <= k1; k++)
                    for (int j = j0; j <= j1; j++)
                        for (int i = i0; i <= i1; i++)
                            s += src[(size_t)i + F->sy * j + F->sz * k];
                C->f[(size_t)I + C->sy * J + C->sz * K] = s * scale;
            }
}

static void restrict_residual(const mg_state *m, const mg_level *F, mg_level *C)
{
    restrict_field(m, F, F->r, C);
}

/* Per-axis prolongation stencil: fine index i takes 3/4 of coarse I = i/2 and
 * 1/4 of the neighbour on i's side, mirrored (all weight on I) at walls. */
static inline void prolong_axis(int coarsen, int nc, int i, int *I0, int *I1, float *w1)
{
    if (!coarsen) {
        *I0 = *I1 = i;
        *w1 = 0.0f;
        return;
    }
    int I = i >> 1, nb = (i & 1) ? I + 1 : I - 1;
    *I0 = I;
    if (nb < 0 || nb >= nc) {
        *I1 = I;
        *w1 = 0.0f;
    } else {
        *I1 = nb;
        *w1 = 0.25f;
    }
}

/* Sum of the prolongation weights that reach non-empty coarse cells from fine
 * cell (i,j,k): the renormalization of prolong_add on weighted coarse levels. */
static float prolong_weight_sum(const mg_level *F, const mg_level *C, int i, int j, int k)
{
    const int *co = F->coarsen;
    int I[2], J[2], K[2];
    float wi1, wj1, wk1;
    prolong_axis(co[0], C->n[0], i, &I[0], &I[1], &wi1);
    prolong_axis(co[1], C->n[1], j, &J[0], &J[1], &wj1);
    prolong_axis(co[2], C->n[2], k, &K[0], &K[1], &wk1);
    float wi[2] = {1 - wi1, wi1}, wj[2] = {1 - wj1, wj1}, wk[2] = {1 - wk1, wk1}, ws = 0;
    for (int c = 0; c < 2; c++)
        for (int b = 0; b < 2; b++)
            for (int a = 0; a < 2; a++) {
                float w = wk[c] * wj[b] * wi[a];
                if (w != 0 && C->a[(size_t)I[a] + C->sy * J[b] + C->sz * K[c]] != 0.0f)
                    ws += w;
            }
    return ws;
}

void mg_prolong_norm(const mg_level *F, const mg_level *C, float *pn)
{
#pragma omp parallel for collapse(2) schedule(static) if (F->count > MG_PAR_MIN)
    for (int k = 0; k < F->n[2]; k++)
        for (int j = 0; j < F->n[1]; j++)
            for (int i = 0; i < F->n[0]; i++) {
                size_t fc = (size_t)i + F->sy * j + F->sz * k;
                float ws = (F->plain || F->a[fc] != 0.0f) ? prolong_weight_sum(F, C, i, j, k) : 0;
                pn[fc] = ws > 0 ? 1.0f / ws : 0.0f;
            }
}

/* Weight of coarse index I in the prolongation stencil of fine index i (one axis). */
static inline float prolong_axis_weight(int coarsen, int nc, int i, int I)
{
    int I0, I1;
    float w1;
    prolong_axis(coarsen, nc, i, &I0, &I1, &w1);
    return (I0 == I ? 1 - w1 : 0) + (I1 == I ? w1 : 0);
}

/* f_C = P^T r_F / 2^d: the restriction that makes the V-cycle a symmetric
 * operator, for use as a CG preconditioner (mean-of-children restriction is not
 * proportional to P^T, and CG then loses conjugacy: measured, Poisson in long
 * corridors stalled near 3e-2). Coarse cell I takes fine cells 2I-1 .. 2I+2
 * along each coarsened axis, weighted as prolong_axis weights them. */
void mg_restrict_transpose(const mg_level *F, const mg_level *C, int dim, const float *pn,
                           const float *r, float *fcoarse, float *work, int nthreads)
{
    const int *co = F->coarsen;
    int nchild = 1;
    for (int b = 0; b < dim; b++)
        nchild *= co[b] ? 2 : 1;
    const float scale = 1.0f / (float)nchild;
    const int nfx = F->n[0], nfy = F->n[1], ncx = C->n[0], ncy = C->n[1];
    /* Separable: P's weights are products of one weight per axis, so P^T is
     * applied along x to each fine row, then scattered along y and z into the
     * coarse plane (the transpose of prolong_axis, axis by axis). */
    int nt = 1;
#ifdef _OPENMP
    if (F->count > MG_PAR_MIN)
        nt = omp_get_max_threads() < nthreads ? omp_get_max_threads() : nthreads;
#else
    (void)nthreads;
#endif
#pragma omp parallel num_threads(nt) if (nt > 1)
    {
        int t = 0;
#ifdef _OPENMP
        t = omp_get_thread_num();
#endif
        float *g = work + (size_t)t * mg_restrict_transpose_work(F, C);
        float *xl = g + nfx, *acc = xl + ncx;
#pragma omp for schedule(static)
        for (int K = 0; K < C->n[2]; K++) {
            memset(acc, 0, (size_t)ncx * ncy * sizeof(float));
            const int klo = co[2] ? 2 * K - 1 : K, khi = co[2] ? 2 * K + 2 : K;
            for (int k = klo < 0 ? 0 : klo; k <= khi && k < F->n[2]; k++) {
                const float wk = prolong_axis_weight(co[2], C->n[2], k, K);
                if (wk == 0)
                    continue;
                for (int j = 0; j < nfy; j++) {
                    const size_t fb = F->sy * (size_t)j + F->sz * (size_t)k;
                    const float *rr = r + fb;
                    if (pn) {
                        const float *pr = pn + fb;
                        for (int i = 0; i < nfx; i++)
                            g[i] = pr[i] * rr[i];
                    } else {
                        memcpy(g, rr, (size_t)nfx * sizeof(float));
                    }
                    /* along x: coarse I takes 3/4 of fine 2I and 2I+1, 1/4 of 2I-1
                     * and 2I+2; a fine cell at a wall gives all its weight to I */
                    if (co[0]) {
                        for (int I = 0; I < ncx; I++) {
                            const int i0 = 2 * I;
                            float v = 0.75f * g[i0];
                            if (i0 + 1 < nfx)
                                v += 0.75f * g[i0 + 1];
                            if (i0 > 0)
                                v += 0.25f * g[i0 - 1];
                            if (i0 + 2 < nfx)
                                v += 0.25f * g[i0 + 2];
                            xl[I] = v;
                        }
                        xl[0] += 0.25f * g[0];
                        if ((nfx & 1) == 0)
                            xl[ncx - 1] += 0.25f * g[nfx - 1];
                    } else {
                        memcpy(xl, g, (size_t)ncx * sizeof(float));
                    }
                    /* along y: fine row j goes to its two coarse rows */
                    int J0, J1;
                    float wj1;
                    prolong_axis(co[1], ncy, j, &J0, &J1, &wj1);
                    float *a0 = acc + (size_t)ncx * J0, *a1 = acc + (size_t)ncx * J1;
                    const float w0 = wk * (1.0f - wj1), w1 = wk * wj1;
                    for (int I = 0; I < ncx; I++)
                        a0[I] += w0 * xl[I];
                    if (w1 != 0)
                        for (int I = 0; I < ncx; I++)
                            a1[I] += w1 * xl[I];
                }
            }
            for (int J = 0; J < ncy; J++) {
                const size_t cb = C->sy * (size_t)J + C->sz * (size_t)K;
                const float *ar = acc + (size_t)ncx * J;
                float *out = fcoarse + cb;
                if (C->plain)
                    for (int I = 0; I < ncx; I++)
                        out[I] = ar[I] * scale;
                else
                    for (int I = 0; I < ncx; I++)
                        out[I] = C->a[cb + I] != 0.0f ? ar[I] * scale : 0.0f;
            }
        }
    }
}

static void restrict_transpose(const mg_state *m, int l)
{
    mg_restrict_transpose(&m->lv[l], &m->lv[l + 1], m->dim, m->pnorm[l], m->lv[l].r,
                          m->lv[l + 1].f, m->rt_work, m->rt_threads);
}

/* Row (j,k) of u_F += P u_C from a plain coarse level: blend the (up to) four
 * coarse rows in y and z into one line (C->n[0] floats of work), then
 * interpolate along x: 4 + 2 flops per fine cell instead of 8 products. */
MG_KERNEL static void prolong_row_plain(mg_level *F, const mg_level *C, int j, int k, float *line, int set)
{
    const int *co = F->coarsen;
    const float *uc = C->u;
    int K0, K1, J0, J1;
    float wk1, wj1;
    prolong_axis(co[2], C->n[2], k, &K0, &K1, &wk1);
    prolong_axis(co[1], C->n[1], j, &J0, &J1, &wj1);
    const float *r00 = uc + C->sy * J0 + C->sz * K0, *r01 = uc + C->sy * J1 + C->sz * K0;
    const float *r10 = uc + C->sy * J0 + C->sz * K1, *r11 = uc + C->sy * J1 + C->sz * K1;
    const float a00 = (1 - wk1) * (1 - wj1), a01 = (1 - wk1) * wj1;
    const float a10 = wk1 * (1 - wj1), a11 = wk1 * wj1;
    float *uf = F->u + F->sy * (size_t)j + F->sz * (size_t)k;
    const int nc = C->n[0], nf = F->n[0];
#if MG_AVX512
    if (mg_avx512() && co[0]) {
        prolong_row_avx512(uf, nf, r00, r01, r10, r11, a00, a01, a10, a11, nc, set);
        return;
    }
#endif
    for (int I = 0; I < nc; I++)
        line[I] = a00 * r00[I] + a01 * r01[I] + a10 * r10[I] + a11 * r11[I];
    if (set) /* u_F = P u_C: the row is cleared while it is in cache */
        memset(uf, 0, (size_t)nf * sizeof(float));
    if (!co[0]) {
        for (int i = 0; i < nf; i++)
            uf[i] += line[i];
        return;
    }
    /* i = 2I takes 3/4 line[I] + 1/4 line[I-1]; i = 2I+1 takes 3/4 line[I] + 1/4 line[I+1]. */
    uf[0] += line[0];
    for (int I = 1; I < nc; I++)
        uf[2 * I] += 0.75f * line[I] + 0.25f * line[I - 1];
    for (int I = 0; I + 1 < nc && 2 * I + 1 < nf; I++)
        uf[2 * I + 1] += 0.75f * line[I] + 0.25f * line[I + 1];
    if (2 * (nc - 1) + 1 < nf)
        uf[2 * (nc - 1) + 1] += line[nc - 1];
}

/* Row (j,k) of u_F += P u_C from a weighted coarse level of at most MG_ROW_BUF
 * cells per row: the four coarse rows blended in y and z into a line of values
 * and a line of weights (empty coarse cells left out), then interpolated along
 * x and divided, on fluid fine cells where some weight reaches. */
MG_KERNEL static void prolong_row_weighted(mg_level *F, const mg_level *C, int j, int k)
{
    const int *co = F->coarsen;
    int K0, K1, J0, J1;
    float wk1, wj1;
    prolong_axis(co[2], C->n[2], k, &K0, &K1, &wk1);
    prolong_axis(co[1], C->n[1], j, &J0, &J1, &wj1);
    const size_t o00 = C->sy * J0 + C->sz * K0, o01 = C->sy * J1 + C->sz * K0;
    const size_t o10 = C->sy * J0 + C->sz * K1, o11 = C->sy * J1 + C->sz * K1;
    const float a00 = (1 - wk1) * (1 - wj1), a01 = (1 - wk1) * wj1;
    const float a10 = wk1 * (1 - wj1), a11 = wk1 * wj1;
    const float *uc = C->u, *ac = C->a;
    const int nc = C->n[0], nf = F->n[0];
    float line[MG_ROW_BUF], lw[MG_ROW_BUF];
    for (int I = 0; I < nc; I++) {
        const float m00 = ac[o00 + I] != 0.0f ? a00 : 0.0f, m01 = ac[o01 + I] != 0.0f ? a01 : 0.0f;
        const float m10 = ac[o10 + I] != 0.0f ? a10 : 0.0f, m11 = ac[o11 + I] != 0.0f ? a11 : 0.0f;
        line[I] = m00 * uc[o00 + I] + m01 * uc[o01 + I] + m10 * uc[o10 + I] + m11 * uc[o11 + I];
        lw[I] = m00 + m01 + m10 + m11;
    }
    const size_t fb = F->sy * (size_t)j + F->sz * (size_t)k;
    float *uf = F->u + fb;
    const float *af = F->plain ? NULL : F->a + fb;
    if (!co[0]) {
        for (int i = 0; i < nf; i++)
            if ((!af || af[i] != 0.0f) && lw[i] > 0)
                uf[i] += line[i] / lw[i];
        return;
    }
    /* i = 2I takes 3/4 of I and 1/4 of I-1, i = 2I+1 3/4 of I and 1/4 of I+1;
     * all of I where that neighbour is beyond a wall */
    for (int i = 0; i < nf; i++) {
        const int I = i >> 1, nb = (i & 1) ? I + 1 : I - 1;
        float s, w;
        if (nb < 0 || nb >= nc) {
            s = line[I];
            w = lw[I];
        } else {
            s = 0.75f * line[I] + 0.25f * line[nb];
            w = 0.75f * lw[I] + 0.25f * lw[nb];
        }
        if ((!af || af[i] != 0.0f) && w > 0)
            uf[i] += s / w;
    }
}

/* u_F += P u_C: cell-centred (bi/tri)linear interpolation. On weighted coarse
 * levels empty coarse cells are left out and the weights renormalized. */
static void prolong_add(const mg_state *m, mg_level *F, const mg_level *C, int set)
{
    const int *co = F->coarsen;
    const float *uc = C->u;
    if (C->n[0] <= MG_ROW_BUF && C->plain) {
#pragma omp parallel for collapse(2) schedule(static) if (F->count > MG_PAR_MIN)
        for (int k = 0; k < F->n[2]; k++)
            for (int j = 0; j < F->n[1]; j++) {
                float line[MG_ROW_BUF];
                prolong_row_plain(F, C, j, k, line, set);
            }
        return;
    }
    if (set)
        zero_f(F->u, F->count);
    if (C->n[0] <= MG_ROW_BUF) {
#pragma omp parallel for collapse(2) schedule(static) if (F->count > MG_PAR_MIN)
        for (int k = 0; k < F->n[2]; k++)
            for (int j = 0; j < F->n[1]; j++)
                prolong_row_weighted(F, C, j, k);
        return;
    }
#pragma omp parallel for collapse(2) schedule(static) if (F->count > MG_PAR_MIN)
    for (int k = 0; k < F->n[2]; k++)
        for (int j = 0; j < F->n[1]; j++) {
            int K0, K1, J0, J1;
            float wk1, wj1;
            prolong_axis(co[2], C->n[2], k, &K0, &K1, &wk1);
            prolong_axis(co[1], C->n[1], j, &J0, &J1, &wj1);
            float wk[2] = {1.0f - wk1, wk1}, wj[2] = {1.0f - wj1, wj1};
            size_t rows[2][2];
            rows[0][0] = C->sy * J0 + C->sz * K0;
            rows[0][1] = C->sy * J1 + C->sz * K0;
            rows[1][0] = C->sy * J0 + C->sz * K1;
            rows[1][1] = C->sy * J1 + C->sz * K1;
            size_t fbase = F->sy * (size_t)j + F->sz * (size_t)k;
            for (int i = 0; i < F->n[0]; i++) {
                size_t fc = fbase + i;
                if (!F->plain && F->a[fc] == 0.0f)
                    continue;
                int I0, I1;
                float wi1;
                prolong_axis(co[0], C->n[0], i, &I0, &I1, &wi1);
                float wi[2] = {1.0f - wi1, wi1};
                int Is[2] = {I0, I1};
                float s = 0, ws = 0;
                for (int a = 0; a < 2; a++)
                    for (int b = 0; b < 2; b++)
                        for (int e = 0; e < 2; e++) {
                            float w = wk[a] * wj[b] * wi[e];
                            if (w == 0.0f)
                                continue;
                            size_t cc = rows[a][b] + Is[e];
                            if (!C->plain && C->a[cc] == 0.0f)
                                continue;
                            s += w * uc[cc];
                            ws += w;
                        }
                if (ws > 0)
                    F->u[fc] += C->plain ? s : s / ws;
            }
        }
}

/* ---------- bottom solve ---------- */

static void bottom_solve(const mg_state *m, mg_level *L)
{
    mg_bottom_cg(L, m->dim, m->alpha, L->f, L->u, L->bwork);
}

/* ---------- fused passes on plain 3D levels ---------- */

/* Levels whose red-black sweeps run plane by plane in one pass (rb_sweep_fused). */
static int level_fusable(const mg_state *m, const mg_level *L)
{
    return L->plain && m->dim == 3 && L->n[2] >= 3 && L->n[1] >= 8 && L->n[0] <= MG_ROW_BUF;
}

/* First colour of a sweep from u = 0 along one row: this colour's cells take
 * f / diag (all their neighbours are zero), the other colour's are set to zero,
 * so u need not be cleared (nor read) beforehand. */
MG_KERNEL static void rb_row_plain_zero(const mg_state *m, const mg_level *L, int j, int k, int col)
{
    const int nx = L->n[0];
    plain_row R = plain_row_at(m, L, j, k);
    float *ur = L->u + R.base;
    const float *fr = L->f + R.base;
    const float inv_in = (float)(1.0 / (R.dyz + 2 * L->c[0]));
    const int par = (j + k + col) & 1;
    for (int i = 0; i < nx; i++)
        ur[i] = (i & 1) == par ? fr[i] * inv_in : 0.0f;
    if (par == 0) {
        double d = R.dyz + (nx > 1 ? L->c[0] : 0);
        ur[0] = d > 0 ? (float)(fr[0] / d) : 0.0f;
    }
    if (nx > 1 && ((nx - 1) & 1) == par)
        ur[nx - 1] = (float)(fr[nx - 1] / (R.dyz + L->c[0]));
}

#if MG_AVX512
/* rb_row_plain_zero in whole vectors: this colour's cells take f times the
 * inverse diagonal (walls in-vector, as in rb_row_avx512), the other colour's
 * are stored as zero. */
__attribute__((target("avx512f"))) static void rb_row_zero_avx512(const mg_state *m, const mg_level *L, int j,
                                                                  int k, int col)
{
    const int nx = L->n[0], ny = L->n[1];
    const float cx = (float)L->c[0], cy = (float)L->c[1], cz = (float)L->c[2];
    const float wzm = m->dim == 3 && k > 0, wzp = m->dim == 3 && k < L->n[2] - 1;
    const int nq = (nx + 15) / 16, last = nx - 1;
    const __mmask16 tail = (__mmask16)(nx % 16 ? (1u << (nx % 16)) - 1u : 0xFFFFu);
    float *ur = L->u + L->sy * (size_t)j + L->sz * (size_t)k;
    const float *fr = L->f + (ur - L->u);
    const float wym = j > 0, wyp = j < ny - 1;
    const float dyz = (float)m->alpha + cy * (wym + wyp) + cz * (wzm + wzp);
    const float wall = dyz + cx, inv_wall = wall > 0 ? 1.0f / wall : 0.0f;
    const float inv_one = dyz > 0 ? 1.0f / dyz : 0.0f;
    const __m512 vinv = _mm512_set1_ps(1.0f / (dyz + 2 * cx));
    const __mmask16 colour = (j + k + col) & 1 ? 0xAAAA : 0x5555;
    for (int c = 0, q = 0; c < nq; c++, q += 16) {
        __mmask16 valid = c + 1 < nq ? (__mmask16)0xFFFF : tail;
        __m512 inv = vinv;
        if (c == 0)
            inv = _mm512_mask_mov_ps(inv, 1, _mm512_set1_ps(nx > 1 ? inv_wall : inv_one));
        if (c + 1 == nq && last > 0)
            inv = _mm512_mask_mov_ps(inv, (__mmask16)(1u << (last - q)), _mm512_set1_ps(inv_wall));
        _mm512_mask_storeu_ps(ur + q, valid, _mm512_maskz_mul_ps(colour, _mm512_maskz_loadu_ps(valid, fr + q), inv));
    }
}
#endif

static void rb_row_zero(const mg_state *m, const mg_level *L, int j, int k, int col)
{
#if MG_AVX512
    if (mg_avx512()) {
        rb_row_zero_avx512(m, L, j, k, col);
        return;
    }
#endif
    rb_row_plain_zero(m, L, j, k, col);
}

/* line[i] += (f - A u)[i] along row (j,p) of a plain level. */
MG_KERNEL static void residual_row_add(const mg_state *m, const mg_level *L, int j, int p, float *line)
{
    const int nx = L->n[0];
    const float cx = (float)L->c[0], cy = (float)L->c[1], cz = (float)L->c[2];
    plain_row R = plain_row_at(m, L, j, p);
    const float *u = L->u + R.base, *f = L->f + R.base;
    const float *ym = u + R.ym, *yp = u + R.yp, *zm = u + R.zm, *zp = u + R.zp;
    const float wym = (float)R.wym, wyp = (float)R.wyp, wzm = (float)R.wzm, wzp = (float)R.wzp;
    const float din = (float)(R.dyz + 2 * L->c[0]);
    for (int i = 1; i < nx - 1; i++) /* branch-free: vectorizes */
        line[i] += f[i] - (din * u[i] - (cy * (wym * ym[i] + wyp * yp[i]) + cz * (wzm * zm[i] + wzp * zp[i]) +
                                         cx * (u[i - 1] + u[i + 1])));
    for (int i = 0; i < nx; i += (nx > 1 ? nx - 1 : 1)) {
        float s = cy * (wym * ym[i] + wyp * yp[i]) + cz * (wzm * zm[i] + wzp * zp[i]);
        float d = (float)R.dyz;
        if (i > 0) { s += cx * u[i - 1]; d += cx; }
        if (i < nx - 1) { s += cx * u[i + 1]; d += cx; }
        line[i] += f[i] - (d * u[i] - s);
    }
}

/* out[I] = scale * (line[2I] + line[2I+1]) for the nc = ceil(nx/2) coarse
 * cells of a row (line[nx] counts as zero), or scale * line[I] when x is not
 * coarsened. */
MG_KERNEL static void restrict_x(const float *line, int nx, int coarsen, float scale, float *out)
{
    if (!coarsen) {
        for (int i = 0; i < nx; i++)
            out[i] = line[i] * scale;
        return;
    }
    for (int I = 0; I < nx / 2; I++)
        out[I] = (line[2 * I] + line[2 * I + 1]) * scale;
    if (nx & 1)
        out[nx / 2] = line[nx - 1] * scale;
}

#if MG_AVX512
/* residual_row_add in 16-lane chunks, walls in-vector, as rb_row_avx512. */
__attribute__((target("avx512f"))) static void residual_row_avx512(
    const float *ur, const float *fr, const float *ym, const float *yp, const float *zm, const float *zp,
    int nx, float cx, float cym, float cyp, float czm, float czp, float dyz, float *line)
{
    const __m512 vcx = _mm512_set1_ps(cx), vcym = _mm512_set1_ps(cym), vcyp = _mm512_set1_ps(cyp),
                 vczm = _mm512_set1_ps(czm), vczp = _mm512_set1_ps(czp), vdin = _mm512_set1_ps(dyz + 2 * cx);
    const int nq = (nx + 15) / 16, last = nx - 1;
    const __mmask16 tail = (__mmask16)(nx % 16 ? (1u << (nx % 16)) - 1u : 0xFFFFu);
    __m512i prev = _mm512_setzero_si512();
    __m512i cur = _mm512_castps_si512(_mm512_maskz_loadu_ps(nq > 1 ? 0xFFFF : tail, ur));
    for (int c = 0, q = 0; c < nq; c++, q += 16) {
        __mmask16 valid = c + 1 < nq ? (__mmask16)0xFFFF : tail;
        __m512i next = c + 1 < nq
                           ? _mm512_castps_si512(_mm512_maskz_loadu_ps(c + 2 < nq ? 0xFFFF : tail, ur + q + 16))
                           : _mm512_setzero_si512();
        __m512 um = _mm512_castsi512_ps(_mm512_alignr_epi32(cur, prev, 15));
        __m512 up = _mm512_castsi512_ps(_mm512_alignr_epi32(next, cur, 1));
        __m512 sm = _mm512_fmadd_ps(vcx, _mm512_add_ps(um, up), _mm512_maskz_loadu_ps(valid, fr + q));
        sm = _mm512_fmadd_ps(vcym, _mm512_maskz_loadu_ps(valid, ym + q), sm);
        sm = _mm512_fmadd_ps(vcyp, _mm512_maskz_loadu_ps(valid, yp + q), sm);
        sm = _mm512_fmadd_ps(vczm, _mm512_maskz_loadu_ps(valid, zm + q), sm);
        sm = _mm512_fmadd_ps(vczp, _mm512_maskz_loadu_ps(valid, zp + q), sm);
        __m512 d = vdin;
        if (c == 0)
            d = _mm512_mask_mov_ps(d, 1, _mm512_set1_ps(nx > 1 ? dyz + cx : dyz));
        if (c + 1 == nq && last > 0)
            d = _mm512_mask_mov_ps(d, (__mmask16)(1u << (last - q)), _mm512_set1_ps(dyz + cx));
        __m512 r = _mm512_fnmadd_ps(d, _mm512_castsi512_ps(cur), sm);
        __m512 l = _mm512_loadu_ps(line + q);
        _mm512_storeu_ps(line + q, _mm512_mask_add_ps(l, valid, l, r)); /* line stays zero beyond nx */
        prev = cur;
        cur = next;
    }
}

/* restrict_x with x coarsened: even and odd cells of 32 split by permutes. */
__attribute__((target("avx512f"))) static void restrict_x_avx512(const float *line, int nx, float scale,
                                                                 float *out)
{
    const __m512i ev = _mm512_set_epi32(30, 28, 26, 24, 22, 20, 18, 16, 14, 12, 10, 8, 6, 4, 2, 0);
    const __m512i od = _mm512_set_epi32(31, 29, 27, 25, 23, 21, 19, 17, 15, 13, 11, 9, 7, 5, 3, 1);
    const __m512 vs = _mm512_set1_ps(scale);
    const int nc = (nx + 1) / 2;
    for (int I = 0; I < nc; I += 16) {
        int c = nc - I < 16 ? nc - I : 16;
        __m512 a = _mm512_loadu_ps(line + 2 * I), b = _mm512_loadu_ps(line + 2 * I + 16);
        __m512 s = _mm512_add_ps(_mm512_permutex2var_ps(a, ev, b), _mm512_permutex2var_ps(a, od, b));
        _mm512_mask_storeu_ps(out + I, (__mmask16)(c == 16 ? 0xFFFFu : (1u << c) - 1u), _mm512_mul_ps(s, vs));
    }
}
#endif

/* Coarse row (J,K) of C->f: the mean of its children's fine residuals f - A u
 * (planes 2K, 2K+1 or K, rows 2J, 2J+1 or J, x pairs), computed from u here, so
 * the fine residual is never stored; children beyond odd edges count as zero,
 * as in restrict_field. u must be final on the children's planes and the
 * planes beside them. */
static void restrict_residual_row(const mg_state *m, const mg_level *L, mg_level *C, int J, int K, float scale)
{
    const int *co = L->coarsen;
    const int nx = L->n[0];
    int js[2], ks[2], nj = 0, nk = 0;
    js[nj++] = co[1] ? 2 * J : J;
    if (co[1] && 2 * J + 1 < L->n[1])
        js[nj++] = 2 * J + 1;
    ks[nk++] = co[2] ? 2 * K : K;
    if (co[2] && 2 * K + 1 < L->n[2])
        ks[nk++] = 2 * K + 1;
    float line[MG_ROW_BUF + 32]; /* zero beyond nx: restrict_x_avx512 reads whole pairs of vectors */
    memset(line, 0, (size_t)(nx + 32) * sizeof(float));
    float *out = C->f + C->sy * (size_t)J + C->sz * (size_t)K;
#if MG_AVX512
    if (mg_avx512()) {
        const float cx = (float)L->c[0], cy = (float)L->c[1], cz = (float)L->c[2];
        for (int b = 0; b < nk; b++)
            for (int a = 0; a < nj; a++) {
                const int j = js[a], k = ks[b];
                const float *ur = L->u + L->sy * (size_t)j + L->sz * (size_t)k;
                const float wym = j > 0, wyp = j < L->n[1] - 1, wzm = k > 0, wzp = k < L->n[2] - 1;
                const float dyz = (float)m->alpha + cy * (wym + wyp) + cz * (wzm + wzp);
                residual_row_avx512(ur, L->f + (ur - L->u), wym ? ur - L->sy : ur, wyp ? ur + L->sy : ur,
                                    wzm ? ur - L->sz : ur, wzp ? ur + L->sz : ur, nx, cx, cy * wym, cy * wyp,
                                    cz * wzm, cz * wzp, dyz, line);
            }
        if (co[0])
            restrict_x_avx512(line, nx, scale, out);
        else
            restrict_x(line, nx, 0, scale, out);
        return;
    }
#endif
    for (int b = 0; b < nk; b++)
        for (int a = 0; a < nj; a++)
            residual_row_add(m, L, js[a], ks[b], line);
    restrict_x(line, nx, co[0], scale, out);
}

/* The fine planes of coarse plane K: [first, last]. */
static int coarse_first(const mg_level *L, int K)
{
    return L->coarsen[2] ? 2 * K : K;
}

static int coarse_last(const mg_level *L, int K)
{
    return L->coarsen[2] && 2 * K + 1 < L->n[2] ? 2 * K + 1 : coarse_first(L, K);
}

static void restrict_residual_plane(const mg_state *m, const mg_level *L, mg_level *C, int K, float scale)
{
    for (int J = 0; J < C->n[1]; J++)
        restrict_residual_row(m, L, C, J, K, scale);
}

/* Colour A on plane k (from u = 0 when `zero`; after u += P u_C on plane k+1
 * row by row when P; with R, coarse plane K of R->f restricted from the
 * residual alongside) and the other colour on plane k-1 one row behind it, so that the rows streaming in (plane k+1 and f, read
 * by colour A) interleave with rows already in cache (colour B): 12-30% off a
 * plain pass against the two planes one after the other, here. A cell of
 * colour B on row j-1 of plane k-1 reads only colour-A cells, final by then
 * (row j-1 of plane k was just done); colour A on row j of plane k reads the
 * colour-B cell below it before that one is updated, as a two-colour sweep
 * does. */
static void rb_pair(const mg_state *m, mg_level *L, int k, int A, int zero, const mg_level *P, float *line,
                    mg_level *R, int K, float scale)
{
    const int ny = L->n[1];
    int J = 0; /* coarse rows of plane K of R written so far */
    for (int j = 0; j < ny; j++) {
        if (R) /* spread over the rows; its fine planes' neighbours are final */
            for (int J1 = (int)((int64_t)(j + 1) * R->n[1] / ny); J < J1; J++)
                restrict_residual_row(m, L, R, J, K, scale);
        if (P) /* u += P u_C on row j of plane k+1 first: colour A on row j of plane k reads it */
            prolong_row_plain(L, P, j, k + 1, line, 0);
        if (zero)
            rb_row_zero(m, L, j, k, A);
        else
            rb_row_plain(m, L, L->u, L->f, j, k, A);
        if (j > 0)
            rb_row_plain(m, L, L->u, L->f, j - 1, k - 1, !A);
    }
    rb_row_plain(m, L, L->u, L->f, ny - 1, k - 1, !A);
}

/* One red-black sweep of a plain 3D level in a single pass over memory, with
 * (mode) the first colour from u = 0 (FS_ZERO), the residual and its
 * restriction to C->f after the sweep (FS_RESTRICT: the fine residual is never
 * stored), or u += P u_C before it (FS_PROLONG, C plain).
 *
 * Each thread owns a slab of planes [k0,k1) (k0 even) and runs it as a pipeline:
 * colour `first` on plane k, then the other colour on plane k-1, whose
 * neighbours are final by then. Across slab edges the order of a two-colour
 * sweep is kept by doing colour `first` on each slab's first plane before
 * anything else and the other colour on it after everything else, so a sweep
 * has 2 to 4 barriers instead of a few per plane. Same arithmetic as two
 * colour sweeps, half the memory traffic. */
static void fused_pass(const mg_state *m, mg_level *L, mg_level *C, int mode, int first)
{
    const int nz = L->n[2], ny = L->n[1];
    float scale = 1.0f;
    if (mode == FS_RESTRICT) {
        int nchild = 1;
        for (int b = 0; b < m->dim; b++)
            nchild *= L->coarsen[b] ? 2 : 1;
        scale = 1.0f / (float)nchild;
    }
    int nt = 1;
#ifdef _OPENMP
    if (L->count > MG_PAR_MIN) {
        nt = omp_get_max_threads();
        if (nt > nz / 4)
            nt = nz / 4 > 0 ? nz / 4 : 1;
    }
#endif
    int chunk = (nz + nt - 1) / nt;
    chunk += chunk & 1;
#pragma omp parallel num_threads(nt) if (nt > 1)
    {
        int t = 0;
#ifdef _OPENMP
        t = omp_get_thread_num();
#endif
        int k0 = t * chunk, k1 = k0 + chunk < nz ? k0 + chunk : nz;
        if (k0 > nz)
            k0 = nz;
        const int own = k1 > k0;
        float line[MG_ROW_BUF];
        const int A = first, B = !first;
        /* FS_RESTRICT: coarse planes whose fine planes are in [k0+2, k1-2] are
         * written in the pipeline from Kin on, once their last fine plane's
         * neighbours are final; those that touch k0, k0+1 or k1-1 (whose
         * neighbours are final only after the slab edges) at the end. */
        const int Kfirst = L->coarsen[2] ? k0 / 2 : k0;
        const int Kin = L->coarsen[2] ? k0 / 2 + 1 : k0 + 2;
        int Knext = Kin;
        if (mode == FS_PROLONG) {
            if (own) {
                for (int k = k0; k <= k0 + 1 && k < k1; k++)
                    for (int j = 0; j < ny; j++)
                        prolong_row_plain(L, C, j, k, line, 0);
                if (k1 - 1 > k0 + 1)
                    for (int j = 0; j < ny; j++)
                        prolong_row_plain(L, C, j, k1 - 1, line, 0);
            }
#pragma omp barrier
        }
        /* colour A on the first plane */
        if (own && mode == FS_ZERO)
            for (int j = 0; j < ny; j++)
                rb_row_zero(m, L, j, k0, A);
        else if (own)
            rb_plane_plain(m, L, k0, A);
#pragma omp barrier
        if (own) {
            for (int k = k0 + 1; k < k1; k++) {
                const int pro = mode == FS_PROLONG && k + 1 >= k0 + 2 && k + 1 <= k1 - 2;
                if (k - 1 > k0) {
                    /* u is final on planes <= k-2: residuals of planes <= k-3 */
                    int rk = -1;
                    if (mode == FS_RESTRICT && coarse_first(L, Knext) < k1 && coarse_last(L, Knext) <= k - 3)
                        rk = Knext++;
                    rb_pair(m, L, k, A, mode == FS_ZERO, pro ? C : NULL, line, rk >= 0 ? C : NULL, rk, scale);
                } else {
                    if (pro)
                        for (int j = 0; j < ny; j++)
                            prolong_row_plain(L, C, j, k + 1, line, 0);
                    if (mode == FS_ZERO)
                        for (int j = 0; j < ny; j++)
                            rb_row_zero(m, L, j, k, A);
                    else
                        rb_plane_plain(m, L, k, A);
                }
            }
            if (k1 - 1 > k0)
                rb_plane_plain(m, L, k1 - 1, B);
            while (mode == FS_RESTRICT && coarse_first(L, Knext) < k1 && coarse_last(L, Knext) <= k1 - 2)
                restrict_residual_plane(m, L, C, Knext++, scale);
        }
#pragma omp barrier
        /* colour B on the first plane (its neighbour k0-1 is final now) */
        if (own)
            rb_plane_plain(m, L, k0, B);
        if (mode == FS_RESTRICT) {
#pragma omp barrier
            if (own) {
                for (int K = Kfirst; K < Kin && coarse_first(L, K) < k1; K++)
                    restrict_residual_plane(m, L, C, K, scale);
                while (coarse_first(L, Knext) < k1)
                    restrict_residual_plane(m, L, C, Knext++, scale);
            }
        }
    }
}

/* ---------- cycles ---------- */

/* One V-cycle on level l for A u_l = f_l; u_l holds the initial guess when
 * `guess`, else starts from zero. `sym` reverses the post-smoothing order. */
static void vcycle(const mg_state *m, int l, int guess, int sym)
{
    mg_level *L = (mg_level *)&m->lv[l];
    if (l == m->nlev - 1) {
        bottom_solve(m, L);
        return;
    }
    mg_level *C = (mg_level *)&m->lv[l + 1];
    if (m->smoother == HV_SMOOTH_RBGS && !sym && m->pre >= 1 && m->post >= 1 && level_fusable(m, L)) {
        /* Same arithmetic as below, fewer passes over the level. */
        int s0 = 0;
        if (!guess) {
            if (m->pre >= 2) {
                fused_pass(m, L, NULL, FS_ZERO, 0);
                s0 = 1;
            } else {
                zero_f(L->u, L->count);
            }
        }
        for (int s = s0; s < m->pre - 1; s++)
            fused_pass(m, L, NULL, FS_PLAIN, 0);
        fused_pass(m, L, C, FS_RESTRICT, 0);
        vcycle(m, l + 1, 0, sym);
        int s1 = 0;
        if (C->plain && C->n[0] <= MG_ROW_BUF) {
            fused_pass(m, L, (mg_level *)C, FS_PROLONG, 0);
            s1 = 1;
        } else {
            prolong_add(m, L, C, 0);
        }
        for (int s = s1; s < m->post; s++)
            fused_pass(m, L, NULL, FS_PLAIN, 0);
        return;
    }
    if (!guess)
        zero_f(L->u, L->count);
    if (m->smoother != HV_SMOOTH_RBGS)
        zero_f(L->d, L->count);
    smooth(m, L, m->pre, 0);
    level_residual(m, L);
    if (sym)
        restrict_transpose(m, l);
    else
        restrict_residual(m, L, (mg_level *)&m->lv[l + 1]);
    vcycle(m, l + 1, 0, sym);
    prolong_add(m, L, &m->lv[l + 1], 0);
    if (m->smoother != HV_SMOOTH_RBGS)
        zero_f(L->d, L->count);
    smooth(m, L, m->post, sym);
}

/* Full multigrid: restrict f down, solve the bottom, then interpolate and
 * V-cycle on each finer level (docs/METHOD.md, "Multigrid": meant for Poisson;
 * measured, it also takes the heat step's first factor from 0.014 to 0.009). */
static void fmg(const mg_state *m)
{
    for (int l = 0; l + 1 < m->nlev; l++) {
        mg_level *F = (mg_level *)&m->lv[l];
        restrict_field(m, F, F->f, (mg_level *)&m->lv[l + 1]);
    }
    bottom_solve(m, (mg_level *)&m->lv[m->nlev - 1]);
    for (int l = m->nlev - 2; l >= 0; l--) {
        mg_level *L = (mg_level *)&m->lv[l];
        prolong_add(m, L, &m->lv[l + 1], 1);
        vcycle(m, l, 1, 0);
    }
}

/* ---------- backend entry points ---------- */

static void mg_destroy(void *state)
{
    mg_state *m = state;
    if (!m)
        return;
    for (int l = 0; l < m->nlev; l++) {
        mg_level *L = &m->lv[l];
        hv_free(m->pnorm[l]);
        mg_level_free_coeffs(L);
        hv_free(L->u);
        hv_free(L->f);
        hv_free(L->r);
        hv_free(L->d);
        free(L->region);
        free(L->bwork);
    }
    hv_free(m->rt_work);
    hv_free(m->rd);
    hv_free(m->p);
    hv_free(m->z);
    hv_free(m->q);
    free(m);
}

static hv_status mg_create(void **state, const hv_setup *s)
{
    mg_state *m = calloc(1, sizeof *m);
    if (!m)
        return hv_error(HV_ERR_NOMEM, "multigrid: out of memory");
    m->s = s;
    m->dim = s->p.dim;
    m->alpha = s->p.alpha;
    m->smoother = s->o.smoother;
    m->pre = s->o.pre_smooth;
    m->post = s->o.post_smooth;
    m->use_pcg = s->p.solid != NULL;
    hv_status st = HV_OK;

    /* Levels and coefficients (mg_setup.c); the state takes them over. */
    mg_hierarchy H;
    if ((st = mg_hierarchy_build(&H, s, m->smoother == HV_SMOOTH_CHEBYSHEV)))
        goto fail;
    m->nlev = H.nlev;
    memcpy(m->lv, H.lv, (size_t)H.nlev * sizeof H.lv[0]);
    for (int l = 0; l < m->nlev; l++) {
        mg_level *L = &m->lv[l];
        L->u = hv_calloc(L->count, sizeof(float));
        L->f = hv_calloc(L->count, sizeof(float));
        L->r = hv_calloc(L->count, sizeof(float));
        if (m->smoother != HV_SMOOTH_RBGS)
            L->d = hv_calloc(L->count, sizeof(float));
        if (!L->u || !L->f || !L->r || (m->smoother != HV_SMOOTH_RBGS && !L->d)) {
            st = hv_error(HV_ERR_NOMEM, "multigrid: out of memory for level %d (%zu cells)", l,
                          L->count);
            goto fail;
        }
    }
    /* PCG restricts with P^T; renormalized prolongation needs its weight sums. */
    for (int l = 0; m->use_pcg && l + 1 < m->nlev; l++) {
        const mg_level *F = &m->lv[l], *C = &m->lv[l + 1];
        if (C->plain)
            continue;
        float *pn = m->pnorm[l] = hv_malloc(F->count * sizeof(float));
        if (!pn) {
            st = hv_error(HV_ERR_NOMEM, "multigrid: out of memory for level %d weights", l);
            goto fail;
        }
        mg_prolong_norm(F, C, pn);
    }
    if (m->use_pcg && m->nlev > 1) {
        size_t per = 0;
        for (int l = 0; l + 1 < m->nlev; l++) {
            size_t w = mg_restrict_transpose_work(&m->lv[l], &m->lv[l + 1]);
            per = w > per ? w : per;
        }
        m->rt_threads = 1;
#ifdef _OPENMP
        m->rt_threads = omp_get_max_threads();
#endif
        if (!(m->rt_work = hv_malloc((size_t)m->rt_threads * per * sizeof(float)))) {
            st = hv_error(HV_ERR_NOMEM, "multigrid: out of memory for the restriction's work");
            goto fail;
        }
    }
    /* Bottom: CG work. */
    mg_level *L = &m->lv[m->nlev - 1];
    if (!(L->bwork = malloc(MG_BOTTOM_WORK * L->count * sizeof(double)))) {
        st = hv_error(HV_ERR_NOMEM, "multigrid: out of memory for the bottom solver");
        goto fail;
    }
    size_t n0 = s->count;
    m->rd = hv_malloc(n0 * sizeof(double));
    if (m->use_pcg) {
        m->p = hv_malloc(n0 * sizeof(double));
        m->z = hv_malloc(n0 * sizeof(double));
        m->q = hv_malloc(n0 * sizeof(double));
    }
    if (!m->rd || (m->use_pcg && (!m->p || !m->z || !m->q))) {
        st = hv_error(HV_ERR_NOMEM, "multigrid: out of memory for %zu-cell work vectors", n0);
        goto fail;
    }
    mg_model_stats_cpu(m->lv, m->nlev, m->dim, m->smoother, m->pre, m->post, m->use_pcg, &m->model);
    *state = m;
    return HV_OK;
fail:
    mg_destroy(m);
    return st;
}

/* Level-0 float right-hand side = f - A x computed in double; returns its norm.
 * Weighted (masked) levels also keep the double residual in rd for PCG. */
static double fine_residual(const mg_state *m, const double *f, const double *x)
{
    const mg_level *L = &m->lv[0];
    double *rd = m->rd;
    double nn = 0;
    if (L->plain) {
        /* One pass: the residual in double, stored as the cycle's float input. */
#pragma omp parallel for collapse(2) reduction(+ : nn) schedule(static) if (L->count > MG_PAR_MIN)
        for (int k = 0; k < L->n[2]; k++)
            for (int j = 0; j < L->n[1]; j++) {
                plain_row R = plain_row_at(m, L, j, k);
                PLAIN_ROW_RESIDUAL(double, float, L, R, x, f, L->f + R.base, nn);
            }
        return sqrt(nn);
    }
    level_apply_d(m, L, x, rd);
#pragma omp parallel for reduction(+ : nn) schedule(static) if (L->count > MG_PAR_MIN)
    for (size_t c = 0; c < L->count; c++) {
        double r = (L->plain || L->a[c] != 0.0f) ? f[c] - rd[c] : 0.0;
        rd[c] = r;
        L->f[c] = (float)r;
        nn += r * r;
    }
    return sqrt(nn);
}

static int stagnated(const hv_solve_info *info)
{
    int n = info->nhistory;
    return n >= 5 && info->history[n - 1] > 0.95 * info->history[n - 4];
}

/* One row of the fused outer pass: xo = x + e (x == NULL: a zero x), and the
 * cycle's next float right-hand side fo = f - A xo in double; returns the sum
 * of squares of the residual. Neighbour values are formed on the fly from x and
 * e, so xo may not alias x. */
#define UPDATE_ROW_BODY(HASX)                                                                      \
    do {                                                                                          \
        const int nx = L->n[0];                                                                   \
        const double *f_ = f + R.base;                                                            \
        const float *e_ = e + R.base;                                                             \
        double *xo_ = xo + R.base;                                                                \
        float *fo_ = fo + R.base;                                                                 \
        const double cx = L->c[0], cy = L->c[1], cz = L->c[2];                                    \
        const double wym = R.wym, wyp = R.wyp, wzm = R.wzm, wzp = R.wzp;                          \
        const ptrdiff_t ym = R.ym, yp = R.yp, zm = R.zm, zp = R.zp;                               \
        const double din = R.dyz + 2 * cx;                                                        \
        double rb[MG_ROW_BUF];                                                                    \
        double acc[8] = {0, 0, 0, 0, 0, 0, 0, 0};                                                 \
        /* the interior in chunks of MG_ROW_BUF: the residual per cell into rb without            \
         * branches (vectorizes), then its squares in 8 partial sums (a serial sum does not) */   \
        for (int c0 = 1; c0 < nx - 1; c0 += MG_ROW_BUF) {                                         \
            const int c1 = nx - 1 - c0 < MG_ROW_BUF ? nx - 1 : c0 + MG_ROW_BUF;                   \
            for (int i = c0; i < c1; i++) {                                                       \
                double v = XE(i);                                                                 \
                double s = cy * (wym * XE(i + ym) + wyp * XE(i + yp)) +                           \
                           cz * (wzm * XE(i + zm) + wzp * XE(i + zp)) + cx * (XE(i - 1) + XE(i + 1)); \
                double r = f_[i] - (din * v - s);                                                 \
                xo_[i] = v;                                                                       \
                fo_[i] = (float)r;                                                                \
                rb[i - c0] = r;                                                                   \
            }                                                                                     \
            int q0 = 0;                                                                           \
            for (; q0 + 8 <= c1 - c0; q0 += 8)                                                    \
                for (int q = 0; q < 8; q++)                                                       \
                    acc[q] += rb[q0 + q] * rb[q0 + q];                                            \
            for (; q0 < c1 - c0; q0++)                                                            \
                acc[0] += rb[q0] * rb[q0];                                                        \
        }                                                                                         \
        for (int i = 0; i < nx; i += (nx > 1 ? nx - 1 : 1)) {                                     \
            double v = XE(i);                                                                     \
            double s = cy * (wym * XE(i + ym) + wyp * XE(i + yp)) +                               \
                       cz * (wzm * XE(i + zm) + wzp * XE(i + zp));                                \
            double d = R.dyz;                                                                     \
            if (i > 0) { s += cx * XE(i - 1); d += cx; }                                          \
            if (i < nx - 1) { s += cx * XE(i + 1); d += cx; }                                     \
            double r = f_[i] - (d * v - s);                                                       \
            xo_[i] = v;                                                                           \
            fo_[i] = (float)r;                                                                    \
            acc[1] += r * r;                                                                      \
        }                                                                                         \
        return ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7])); \
    } while (0)

MG_KERNEL static double update_row_x(const mg_level *L, plain_row R, const double *x, const float *e,
                           const double *f, double *xo, float *fo)
{
    const double *x_ = x + R.base;
#define XE(p) (x_[p] + (double)e_[p])
    UPDATE_ROW_BODY(1);
#undef XE
}

MG_KERNEL static double update_row_0(const mg_level *L, plain_row R, const double *x, const float *e,
                           const double *f, double *xo, float *fo)
{
#define XE(p) ((double)e_[p])
    (void)x;
    UPDATE_ROW_BODY(0);
#undef XE
}

/* Plain fine level, one pass: xo = x + e with e the cycle's correction (level
 * 0's u), and level 0's f = f - A xo (double arithmetic, float storage).
 * Returns ||f - A xo||. */
static double update_residual(const mg_state *m, const double *x, const double *f, double *xo)
{
    const mg_level *L = &m->lv[0];
    const float *e = L->u;
    float *fo = L->f;
    double nn = 0;
#pragma omp parallel for collapse(2) reduction(+ : nn) schedule(static) if (L->count > MG_PAR_MIN)
    for (int k = 0; k < L->n[2]; k++)
        for (int j = 0; j < L->n[1]; j++) {
            plain_row R = plain_row_at(m, L, j, k);
            nn += x ? update_row_x(L, R, x, e, f, xo, fo) : update_row_0(L, R, x, e, f, xo, fo);
        }
    return sqrt(nn);
}

/* Level 0's f = (float) f, returning ||f|| (the residual of a zero guess). */
static double load_rhs(const mg_state *m, const double *f)
{
    const mg_level *L = &m->lv[0];
    double nn = 0;
#pragma omp parallel for reduction(+ : nn) schedule(static) if (L->count > MG_PAR_MIN)
    for (size_t c = 0; c < L->count; c++) {
        L->f[c] = (float)f[c];
        nn += f[c] * f[c];
    }
    return sqrt(nn);
}

/* Defect correction on a plain fine level. The iterate alternates between u
 * and the work vector rd (the fused update reads one and writes the other);
 * Poisson's mean, to which the residual is blind, is removed once at the end. */
static hv_status mg_solve_stationary(mg_state *m, const double *f, double *u, hv_solve_info *info)
{
    const hv_setup *s = m->s;
    const size_t n = s->count;
    double *cur = u, *alt = m->rd;
    int have_x = s->o.nonzero_guess;
    double fn, rel;
    hv_status st = HV_OK;
    if (have_x) {
        fn = hv_norm2(s, f);
        rel = fn > 0 ? fine_residual(m, f, u) / fn : 0;
    } else {
        fn = load_rhs(m, f);
        rel = fn > 0 ? 1.0 : 0.0;
    }
    if (fn == 0) {
        memset(u, 0, n * sizeof *u);
        hv_info_push(info, 0.0);
        info->reason = HV_STOP_CONVERGED;
        return HV_OK;
    }
    hv_info_push(info, rel);
    info->reason = HV_STOP_MAX_ITER;
    /* Cycles per correction: fixed, or (auto, RBGS) as many as the per-cycle
     * factor measured so far says the tolerance needs, at most 3 in 3D and 2 in
     * 2D. Float cycles in a row reduce the residual as much as corrections do
     * until about 1e-4 per correction (measured: Poisson 256^3 gives the same
     * residuals either way; 2048^2 Poisson drifts after 3), so the double pass
     * runs once per few cycles. Chebyshev and Jacobi keep one cycle per
     * iteration, cycle for cycle like the OpenCL backend. */
    int fixed = s->o.cycles_per_iteration;
    if (!fixed && m->smoother != HV_SMOOTH_RBGS)
        fixed = 1;
    double rho = 0.1; /* per-cycle factor assumed until one is measured */
    for (int it = 0; it < s->o.max_iter; it++) {
        if (rel <= s->o.tol)
            break;
        int nc = fixed;
        if (!nc) {
            /* 25% margin: the first factor includes the better FMG cycle */
            double need = ceil(1.25 * log(s->o.tol / rel) / log(rho));
            int mx = MG_AUTO_CYCLES - (m->dim == 2);
            nc = !(need > 1) ? 1 : need > mx ? mx : (int)need;
        }
        for (int q = 0; q < nc; q++) {
            if (q == 0 && it == 0 && !s->o.nonzero_guess) {
                fmg(m);
                continue;
            }
            double t0 = hv_now();
            vcycle(m, 0, q > 0, 0);
            info->cycle_seconds += hv_now() - t0;
            info->cycles_timed++;
            /* a cycle from a guess sweeps u instead of setting it: + 4 B per cell */
            info->cycle_bytes += m->model.bytes_per_cycle + (q > 0 ? 4.0 * (double)n : 0.0);
        }
        info->cycles += nc;
        double prev = rel;
        rel = update_residual(m, have_x ? cur : NULL, f, alt) / fn;
        if (rel > 0 && prev > 0) {
            rho = pow(rel / prev, 1.0 / nc);
            rho = rho < 1e-3 ? 1e-3 : rho > 0.9 ? 0.9 : rho;
        }
        double *t = cur;
        cur = alt;
        alt = t;
        have_x = 1;
        info->iterations = it + 1;
        hv_info_push(info, rel);
        if (!isfinite(rel)) {
            st = hv_error(HV_ERR_NUMERIC, "multigrid diverged (residual %g)", rel);
            break;
        }
        if (stagnated(info) && rel > s->o.tol) {
            info->reason = HV_STOP_STAGNATED;
            break;
        }
    }
    if (rel <= s->o.tol && st == HV_OK)
        info->reason = HV_STOP_CONVERGED;
    if (!have_x) { /* converged before any cycle: the zero guess */
        memset(u, 0, n * sizeof *u);
        return st;
    }
    if (m->alpha == 0) {
        double sum = 0;
#pragma omp parallel for reduction(+ : sum) schedule(static) if (n > MG_PAR_MIN)
        for (size_t c = 0; c < n; c++)
            sum += cur[c];
        double mean = sum / (double)n;
#pragma omp parallel for schedule(static) if (n > MG_PAR_MIN)
        for (size_t c = 0; c < n; c++)
            u[c] = cur[c] - mean;
    } else if (cur != u) {
#pragma omp parallel for schedule(static) if (n > MG_PAR_MIN)
        for (size_t c = 0; c < n; c++)
            u[c] = cur[c];
    }
    return st;
}

/* z = M r: one symmetric V-cycle from zero on r (float), projected for Poisson. */
static void precondition(mg_state *m, const double *r, double *z)
{
    mg_level *L0 = &m->lv[0];
#pragma omp parallel for schedule(static) if (L0->count > MG_PAR_MIN)
    for (size_t c = 0; c < L0->count; c++)
        L0->f[c] = (float)r[c];
    vcycle(m, 0, 0, 1);
#pragma omp parallel for schedule(static) if (L0->count > MG_PAR_MIN)
    for (size_t c = 0; c < L0->count; c++)
        z[c] = L0->u[c];
    if (m->alpha == 0)
        hv_project_mean(m->s, z);
}

static double pdot(const double *a, const double *b, size_t n)
{
    double s = 0;
#pragma omp parallel for reduction(+ : s) schedule(static) if (n > MG_PAR_MIN)
    for (size_t i = 0; i < n; i++)
        s += a[i] * b[i];
    return s;
}

/* Preconditioned CG in double with a symmetric V-cycle (masked grids). */
static hv_status mg_solve_pcg(mg_state *m, const double *f, double *u, hv_solve_info *info,
                              double fn)
{
    const hv_setup *s = m->s;
    size_t n = s->count;
    double *r = m->rd, *p = m->p, *z = m->z, *q = m->q;
    double rel = fine_residual(m, f, u) / fn;
    hv_info_push(info, rel);
    if (rel <= s->o.tol) {
        info->reason = HV_STOP_CONVERGED;
        return HV_OK;
    }
    precondition(m, r, z);
    info->cycles = 1;
    memcpy(p, z, n * sizeof *p);
    double rz = pdot(r, z, n), best = rel;
    int since_best = 0;
    for (int it = 0; it < s->o.max_iter; it++) {
        level_apply_d(m, &m->lv[0], p, q);
        double pq = pdot(p, q, n);
        if (!(pq > 0)) {
            info->reason = HV_STOP_STAGNATED;
            return HV_OK;
        }
        double al = rz / pq, nn = 0;
#pragma omp parallel for reduction(+ : nn) schedule(static) if (n > MG_PAR_MIN)
        for (size_t c = 0; c < n; c++) {
            u[c] += al * p[c];
            r[c] -= al * q[c];
            nn += r[c] * r[c];
        }
        rel = sqrt(nn) / fn;
        info->iterations = it + 1;
        hv_info_push(info, rel);
        if (!isfinite(rel))
            return hv_error(HV_ERR_NUMERIC, "preconditioned CG diverged (residual %g)", rel);
        if (rel <= s->o.tol)
            break;
        if (rel < 0.9 * best) {
            best = rel;
            since_best = 0;
        } else if (++since_best >= 50) {
            info->reason = HV_STOP_STAGNATED;
            break;
        }
        precondition(m, r, z);
        info->cycles++;
        double rz2 = pdot(r, z, n), be = rz2 / rz;
        rz = rz2;
#pragma omp parallel for schedule(static) if (n > MG_PAR_MIN)
        for (size_t c = 0; c < n; c++)
            p[c] = z[c] + be * p[c];
    }
    if (m->alpha == 0)
        hv_project_mean(s, u);
    /* Report the true residual of the returned iterate. */
    rel = fine_residual(m, f, u) / fn;
    info->relres = rel;
    if (info->reason != HV_STOP_STAGNATED)
        info->reason = rel <= s->o.tol * 1.0001 ? HV_STOP_CONVERGED : HV_STOP_MAX_ITER;
    return HV_OK;
}

static hv_status mg_solve(void *state, const double *f, double *u, hv_solve_info *info)
{
    mg_state *m = state;
    const hv_setup *s = m->s;
    if (!m->use_pcg)
        return mg_solve_stationary(m, f, u, info);
    if (!s->o.nonzero_guess)
        memset(u, 0, s->count * sizeof *u);
    double fn = hv_norm2(s, f);
    if (fn == 0) {
        memset(u, 0, s->count * sizeof *u);
        hv_info_push(info, 0.0);
        info->reason = HV_STOP_CONVERGED;
        return HV_OK;
    }
    hv_status st = mg_solve_pcg(m, f, u, info, fn);
    if (st == HV_OK && s->p.solid)
        for (size_t c = 0; c < s->count; c++)
            if (s->p.solid[c])
                u[c] = 0;
    return st;
}

static void mg_stats(const void *state, hv_solver_stats *st)
{
    const mg_state *m = state;
    mg_model_stats_cpu(m->lv, m->nlev, m->dim, m->smoother, m->pre, m->post, m->use_pcg, st);
}

const hv_backend_ops hv_backend_mg_ops = {"mg", mg_create, mg_solve, NULL, mg_destroy, mg_stats};
