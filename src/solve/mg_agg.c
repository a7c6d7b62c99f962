/*
 * Smoothed aggregation under the CPU multigrid's fine level (mg_agg.h,
 * docs/METHOD.md "Coarse levels that keep the walls"): the aggregates, the
 * Galerkin coarse operators, the transfers and the cycle on the coarse levels.
 */
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
#define AGG_STRONG 1e-6       /* |a_ij| below this times sqrt(a_ii a_jj) joins nothing */
#define AGG_DEGREE 2          /* Chebyshev degree on the coarse levels */
#define AGG_PAR_MIN 16384     /* levels below this many unknowns run on one thread */

/* ---------- a level's operator as rows ---------- */

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

static agg_op level_op(const mg_agg *g, int l)
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

/* Row c of coarse level L: pointers into its matrix, or for a plain row the
 * template's entries in bc/bv (ROW_MAX each). The hierarchy's set-up only:
 * hv__mg_agg_pack changes the matrices. */
static int level_row(const mg_alevel *L, int32_t c, int32_t *bc, float *bv, const int32_t **col,
                     const float **val)
{
    if (L->tn && L->plain[c]) {
        for (int e = 0; e < L->tn; e++) {
            bc[e] = c + L->toff[e];
            bv[e] = L->tval[e];
        }
        *col = bc;
        *val = bv;
        return L->tn;
    }
    size_t b = L->A.rp[c];
    *col = L->A.ci + b;
    *val = L->A.v + b;
    return (int)(L->A.rp[c + 1] - b);
}

/* Row c: its entries (the diagonal first on the fine level), in bc/bv
 * (ROW_MAX entries) for the fine level and plain rows, else pointers into
 * the matrix. */
static int op_row(const agg_op *o, int32_t c, int32_t *bc, float *bv, const int32_t **col,
                  const float **val)
{
    if (!o->F)
        return level_row(o->lv, c, bc, bv, col, val);
    const mg_level *L = o->F;
    size_t stride[3] = {1, L->sy, L->sz};
    if (o->faces) {
        unsigned f = o->faces[c];
        double d = o->alpha * L->a[c];
        int m = 1;
        for (int b = 0; b < 3; b++)
            for (int hi = 0; hi < 2; hi++)
                if (f & (1u << (2 * b + hi))) {
                    bc[m] = hi ? c + (int32_t)stride[b] : c - (int32_t)stride[b];
                    bv[m] = (float)-L->c[b];
                    d += L->c[b];
                    m++;
                }
        bc[0] = c;
        bv[0] = (float)d;
        *col = bc;
        *val = bv;
        return m;
    }
    int idx[3] = {(int)(c % L->n[0]), (int)((c / L->n[0]) % L->n[1]), (int)(c / L->sz)};
    double d = o->alpha * L->a[c];
    int m = 1;
    for (int b = 0; b < o->dim; b++)
        for (int hi = 0; hi < 2; hi++) {
            int f[3] = {idx[0], idx[1], idx[2]};
            f[b] += hi;
            if (f[b] <= 0 || f[b] >= L->n[b])
                continue;
            float w = L->w[b][mg_face_index(L, b, f[0], f[1], f[2])];
            if (w == 0.0f)
                continue;
            double cw = L->c[b] * w;
            bc[m] = hi ? c + (int32_t)stride[b] : c - (int32_t)stride[b];
            bv[m] = (float)-cw;
            d += cw;
            m++;
        }
    bc[0] = c;
    bv[0] = (float)d;
    *col = bc;
    *val = bv;
    return m;
}

/* Cell i of a fine row: y = D x - S over its faces (weights 0 on walls; the
 * neighbour read at the row's ends is the cell itself). */
#define FINE_CELL(i, im, ip)                                                                       \
    do {                                                                                           \
        float d_ = alpha * a[i] + cx * (wx[i] + wx[(i) + 1]) + cy * (wy[i] + wy[(i) + nx]);        \
        float s_ = cx * (wx[i] * xc[im] + wx[(i) + 1] * xc[ip]) +                                  \
                   cy * (wy[i] * xm[i] + wy[(i) + nx] * xp[i]);                                    \
        if (wz) {                                                                                  \
            d_ += cz * (wz[i] + wz[(i) + nxy]);                                                    \
            s_ += cz * (wz[i] * zm[i] + wz[(i) + nxy] * zp[i]);                                    \
        }                                                                                          \
        yr[i] = d_ * xc[i] - s_;                                                                   \
    } while (0)

/* y = A x on the fine level, row by row in float; the interior of a row
 * without branches so that it vectorizes. */
static void fine_apply(const agg_op *o, const float *x, float *y)
{
    const mg_level *L = o->F;
    const int nx = L->n[0], ny = L->n[1], nz = L->n[2];
    const size_t nxy = (size_t)nx * ny;
    const float cx = (float)L->c[0], cy = (float)L->c[1], cz = (float)L->c[2];
    const float alpha = (float)o->alpha;
#pragma omp parallel for collapse(2) schedule(static) if (L->count > AGG_PAR_MIN)
    for (int k = 0; k < nz; k++)
        for (int j = 0; j < ny; j++) {
            size_t base = L->sy * (size_t)j + L->sz * (size_t)k;
            const float *a = L->a + base;
            const float *wx = L->w[0] + (size_t)(nx + 1) * ((size_t)j + (size_t)ny * k);
            const float *wy = L->w[1] + (size_t)nx * ((size_t)j + (size_t)(ny + 1) * k);
            const float *wz = o->dim == 3 ? L->w[2] + base : NULL;
            const float *xc = x + base;
            const float *xm = xc - (j > 0 ? L->sy : 0), *xp = xc + (j < ny - 1 ? L->sy : 0);
            const float *zm = xc - (k > 0 ? L->sz : 0), *zp = xc + (k < nz - 1 ? L->sz : 0);
            float *yr = y + base;
            FINE_CELL(0, 0, nx > 1 ? 1 : 0);
            if (nx < 2)
                continue;
            if (wz) {
                for (int i = 1; i < nx - 1; i++) {
                    float d = alpha * a[i] + cx * (wx[i] + wx[i + 1]) + cy * (wy[i] + wy[i + nx]) +
                              cz * (wz[i] + wz[i + nxy]);
                    float s = cx * (wx[i] * xc[i - 1] + wx[i + 1] * xc[i + 1]) +
                              cy * (wy[i] * xm[i] + wy[i + nx] * xp[i]) +
                              cz * (wz[i] * zm[i] + wz[i + nxy] * zp[i]);
                    yr[i] = d * xc[i] - s;
                }
            } else {
                for (int i = 1; i < nx - 1; i++) {
                    float d = alpha * a[i] + cx * (wx[i] + wx[i + 1]) + cy * (wy[i] + wy[i + nx]);
                    float s = cx * (wx[i] * xc[i - 1] + wx[i + 1] * xc[i + 1]) +
                              cy * (wy[i] * xm[i] + wy[i + nx] * xp[i]);
                    yr[i] = d * xc[i] - s;
                }
            }
            FINE_CELL(nx - 1, nx - 2, nx - 1);
        }
}

/* Row r of M times x, in float with four partial sums (a chain of dependent
 * additions would bound the loop, not memory); x[col(q)] is xb[idx[q]]. */
#define CSR_DOT(xb, idx)                                                                           \
    do {                                                                                           \
        for (; q + 4 <= e; q += 4) {                                                               \
            s0 += M->v[q] * xb[idx[q]];                                                            \
            s1 += M->v[q + 1] * xb[idx[q + 1]];                                                    \
            s2 += M->v[q + 2] * xb[idx[q + 2]];                                                    \
            s3 += M->v[q + 3] * xb[idx[q + 3]];                                                    \
        }                                                                                          \
        for (; q < e; q++)                                                                         \
            s0 += M->v[q] * xb[idx[q]];                                                            \
    } while (0)

static inline float csr_row_dot_c(const mg_csr *M, int32_t r, const float *x)
{
    size_t q = M->rp[r], e = M->rp[r + 1];
    float s0 = 0, s1 = 0, s2 = 0, s3 = 0;
    if (M->co) {
        const float *xb = x + M->cb[r];
        CSR_DOT(xb, M->co);
    } else {
        CSR_DOT(x, M->ci);
    }
    return (s0 + s1) + (s2 + s3);
}
#undef CSR_DOT

#if MG_AVX512
/* The same in 16-lane gathers, two sums in flight; the row's last entries
 * under a mask (a masked-off lane reads nothing; packed offsets are padded,
 * so their last load stays inside the array). */
__attribute__((target("avx512f"))) static float csr_row_dot_avx512(const mg_csr *M, int32_t r,
                                                                   const float *x)
{
    size_t q = M->rp[r], e = M->rp[r + 1];
    __m512 s0 = _mm512_setzero_ps(), s1 = _mm512_setzero_ps();
    if (M->co) {
        const float *xb = x + M->cb[r];
        const __m256i *co = (const __m256i *)(M->co + q);
        for (; q + 32 <= e; q += 32, co += 2) {
            const __m512i i0 = _mm512_cvtepu16_epi32(_mm256_loadu_si256(co)),
                          i1 = _mm512_cvtepu16_epi32(_mm256_loadu_si256(co + 1));
            s0 = _mm512_fmadd_ps(_mm512_loadu_ps(M->v + q), _mm512_i32gather_ps(i0, xb, 4), s0);
            s1 =
                _mm512_fmadd_ps(_mm512_loadu_ps(M->v + q + 16), _mm512_i32gather_ps(i1, xb, 4), s1);
        }
        for (; q < e; q += 16, co++) {
            const __mmask16 k = e - q >= 16 ? (__mmask16)0xFFFF : (__mmask16)((1u << (e - q)) - 1);
            const __m512i i = _mm512_cvtepu16_epi32(_mm256_loadu_si256(co));
            const __m512 xv = _mm512_mask_i32gather_ps(_mm512_setzero_ps(), k, i, xb, 4);
            s0 = _mm512_fmadd_ps(_mm512_maskz_loadu_ps(k, M->v + q), xv, s0);
        }
        return _mm512_reduce_add_ps(_mm512_add_ps(s0, s1));
    }
    for (; q + 32 <= e; q += 32) {
        const __m512i i0 = _mm512_loadu_si512(M->ci + q), i1 = _mm512_loadu_si512(M->ci + q + 16);
        s0 = _mm512_fmadd_ps(_mm512_loadu_ps(M->v + q), _mm512_i32gather_ps(i0, x, 4), s0);
        s1 = _mm512_fmadd_ps(_mm512_loadu_ps(M->v + q + 16), _mm512_i32gather_ps(i1, x, 4), s1);
    }
    for (; q < e; q += 16) {
        const __mmask16 k = e - q >= 16 ? (__mmask16)0xFFFF : (__mmask16)((1u << (e - q)) - 1);
        const __m512i i = _mm512_maskz_loadu_epi32(k, M->ci + q);
        const __m512 xv = _mm512_mask_i32gather_ps(_mm512_setzero_ps(), k, i, x, 4);
        s0 = _mm512_fmadd_ps(_mm512_maskz_loadu_ps(k, M->v + q), xv, s0);
    }
    return _mm512_reduce_add_ps(_mm512_add_ps(s0, s1));
}

__attribute__((target("avx2,fma"))) static inline float hsum_avx2(__m256 s)
{
    __m128 h = _mm_add_ps(_mm256_castps256_ps128(s), _mm256_extractf128_ps(s, 1));
    h = _mm_add_ps(h, _mm_movehl_ps(h, h));
    return _mm_cvtss_f32(_mm_add_ss(h, _mm_movehdup_ps(h)));
}

/* The same in 8-lane AVX2 gathers, two sums in flight; the row's last
 * entries (fewer than 8) one by one. */
__attribute__((target("avx2,fma"))) static float csr_row_dot_avx2(const mg_csr *M, int32_t r,
                                                                  const float *x)
{
    size_t q = M->rp[r], e = M->rp[r + 1];
    __m256 s0 = _mm256_setzero_ps(), s1 = _mm256_setzero_ps();
    float t = 0;
    if (M->co) {
        const float *xb = x + M->cb[r];
        for (; q + 16 <= e; q += 16) {
            const __m256i i0 = _mm256_cvtepu16_epi32(_mm_loadu_si128((const __m128i *)(M->co + q))),
                          i1 = _mm256_cvtepu16_epi32(
                              _mm_loadu_si128((const __m128i *)(M->co + q + 8)));
            s0 = _mm256_fmadd_ps(_mm256_loadu_ps(M->v + q), _mm256_i32gather_ps(xb, i0, 4), s0);
            s1 = _mm256_fmadd_ps(_mm256_loadu_ps(M->v + q + 8), _mm256_i32gather_ps(xb, i1, 4), s1);
        }
        if (q + 8 <= e) {
            const __m256i i0 = _mm256_cvtepu16_epi32(_mm_loadu_si128((const __m128i *)(M->co + q)));
            s0 = _mm256_fmadd_ps(_mm256_loadu_ps(M->v + q), _mm256_i32gather_ps(xb, i0, 4), s0);
            q += 8;
        }
        for (; q < e; q++)
            t += M->v[q] * xb[M->co[q]];
        return hsum_avx2(_mm256_add_ps(s0, s1)) + t;
    }
    for (; q + 16 <= e; q += 16) {
        const __m256i i0 = _mm256_loadu_si256((const __m256i *)(M->ci + q)),
                      i1 = _mm256_loadu_si256((const __m256i *)(M->ci + q + 8));
        s0 = _mm256_fmadd_ps(_mm256_loadu_ps(M->v + q), _mm256_i32gather_ps(x, i0, 4), s0);
        s1 = _mm256_fmadd_ps(_mm256_loadu_ps(M->v + q + 8), _mm256_i32gather_ps(x, i1, 4), s1);
    }
    if (q + 8 <= e) {
        const __m256i i0 = _mm256_loadu_si256((const __m256i *)(M->ci + q));
        s0 = _mm256_fmadd_ps(_mm256_loadu_ps(M->v + q), _mm256_i32gather_ps(x, i0, 4), s0);
        q += 8;
    }
    for (; q < e; q++)
        t += M->v[q] * x[M->ci[q]];
    return hsum_avx2(_mm256_add_ps(s0, s1)) + t;
}
#endif

static inline float csr_row_dot(const mg_csr *M, int32_t r, const float *x)
{
#if MG_AVX512
    if (mg_avx512())
        return csr_row_dot_avx512(M, r, x);
    if (mg_avx2())
        return csr_row_dot_avx2(M, r, x);
#endif
    return csr_row_dot_c(M, r, x);
}

#define AGG_CHUNK 256

/* A template: tn entries at index offsets off with values val. */
typedef struct agg_tmpl {
    int tn;
    const int32_t *off;
    const float *val;
} agg_tmpl;

#if MG_AVX512
/* Sums of template entries t0, t0 + 2, ... < tn into a[0..nb) over x + off[t]
 * (+ 16 b for a[b]), lanes of k[b]. */
#define TEMPLATE_SUMS(a, t0, nb)                                                                   \
    for (int t = (t0); t < T->tn; t += 2) {                                                        \
        const __m512 v = _mm512_set1_ps(T->val[t]);                                                \
        const float *p = xb + T->off[t];                                                           \
        for (int b = 0; b < (nb); b++)                                                             \
            a[b] = _mm512_fmadd_ps(v, _mm512_maskz_loadu_ps(k[b], p + 16 * b), a[b]);              \
    }

/* nb (1..4) blocks of 16 rows from i0 on, of the m rows at c. */
__attribute__((target("avx512f"))) static inline void template_blocks_avx512(
    const agg_tmpl *T, const float *x, float *y, int32_t c, int32_t m, int32_t i0, int nb)
{
    __mmask16 k[4];
    __m512 e[4], o[4];
    for (int b = 0; b < 4; b++) {
        const int32_t r = m - i0 - 16 * b;
        k[b] = r >= 16 ? (__mmask16)0xFFFF : r > 0 ? (__mmask16)((1u << r) - 1) : 0;
        e[b] = o[b] = _mm512_setzero_ps();
    }
    const float *xb = x + c + i0;
    if (nb == 4) {
        TEMPLATE_SUMS(e, 0, 4)
        TEMPLATE_SUMS(o, 1, 4)
    } else {
        TEMPLATE_SUMS(e, 0, nb)
        TEMPLATE_SUMS(o, 1, nb)
    }
    for (int b = 0; b < nb; b++)
        _mm512_mask_storeu_ps(y + c + i0 + 16 * b, k[b], _mm512_add_ps(e[b], o[b]));
}
#undef TEMPLATE_SUMS

/* y = the template rows c .. c + m - 1, 64 at a time: the sums stay in
 * registers over the template's entries, in two sets (even and odd entries)
 * so that eight FMA chains are in flight; masked at the run's end, where a
 * masked-off lane reads nothing. */
__attribute__((target("avx512f"))) static void template_run_avx512(const agg_tmpl *T,
                                                                   const float *x, float *y,
                                                                   int32_t c, int32_t m)
{
    int32_t i0 = 0;
    for (; i0 + 64 <= m; i0 += 64)
        template_blocks_avx512(T, x, y, c, m, i0, 4);
    if (i0 < m)
        template_blocks_avx512(T, x, y, c, m, i0, (int)((m - i0 + 15) / 16));
}

/* Sums as TEMPLATE_SUMS in 8-lane blocks, loads under mask k[b] (masked
 * loads: only in a run's last blocks). */
#define TEMPLATE_SUMS8(a, t0, nb, LOAD)                                                            \
    for (int t = (t0); t < T->tn; t += 2) {                                                        \
        const __m256 v = _mm256_set1_ps(T->val[t]);                                                \
        const float *p = xb + T->off[t];                                                           \
        for (int b = 0; b < (nb); b++)                                                             \
            a[b] = _mm256_fmadd_ps(v, LOAD(p + 8 * b, k[b]), a[b]);                                \
    }
#define LOAD_FULL(p, k) _mm256_loadu_ps(p)
#define LOAD_MASKED(p, k) _mm256_maskload_ps(p, k)

/* nb (1..4, a constant once inlined: the sums stay in registers) blocks of 8
 * rows from i0 on, of the m rows at c; full blocks alone, or the run's last
 * blocks, summed under masks and stored through a buffer, so that nothing
 * outside the run is read or written. */
__attribute__((target("avx2,fma"), always_inline)) static inline void template_blocks_avx2(
    const agg_tmpl *T, const float *x, float *y, int32_t c, int32_t m, int32_t i0, const int nb,
    const int full)
{
    const float *xb = x + c + i0;
    __m256i k[4];
    __m256 e[4], o[4];
    for (int b = 0; b < nb; b++) {
        k[b] = _mm256_cmpgt_epi32(_mm256_set1_epi32(m - i0 - 8 * b),
                                  _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
        e[b] = o[b] = _mm256_setzero_ps();
    }
    if (full) {
        TEMPLATE_SUMS8(e, 0, nb, LOAD_FULL)
        TEMPLATE_SUMS8(o, 1, nb, LOAD_FULL)
    } else {
        TEMPLATE_SUMS8(e, 0, nb, LOAD_MASKED)
        TEMPLATE_SUMS8(o, 1, nb, LOAD_MASKED)
    }
    for (int b = 0; b < nb; b++) {
        const __m256 s = _mm256_add_ps(e[b], o[b]);
        const int32_t left = m - i0 - 8 * b;
        if (full || left >= 8) {
            _mm256_storeu_ps(y + c + i0 + 8 * b, s);
        } else {
            float buf[8];
            _mm256_storeu_ps(buf, s);
            memcpy(y + c + i0 + 8 * b, buf, (size_t)left * sizeof(float));
        }
    }
}
#undef TEMPLATE_SUMS8
#undef LOAD_FULL
#undef LOAD_MASKED

/* y = the template rows c .. c + m - 1, 32 at a time (as
 * template_run_avx512). */
__attribute__((target("avx2,fma"))) static void template_run_avx2(const agg_tmpl *T, const float *x,
                                                                  float *y, int32_t c, int32_t m)
{
    int32_t i0 = 0;
    for (; i0 + 32 <= m; i0 += 32)
        template_blocks_avx2(T, x, y, c, m, i0, 4, 1);
    switch ((m - i0 + 7) / 8) {
    case 1: template_blocks_avx2(T, x, y, c, m, i0, 1, 0); break;
    case 2: template_blocks_avx2(T, x, y, c, m, i0, 2, 0); break;
    case 3: template_blocks_avx2(T, x, y, c, m, i0, 3, 0); break;
    case 4: template_blocks_avx2(T, x, y, c, m, i0, 4, 0); break;
    }
}
#endif

/* y = the template rows c .. c + m - 1 (m <= AGG_CHUNK), vectorized over the
 * run. */
static void template_run(const agg_tmpl *T, const float *x, float *y, int32_t c, int32_t m)
{
#if MG_AVX512
    if (mg_avx512()) {
        template_run_avx512(T, x, y, c, m);
        return;
    }
    if (mg_avx2()) {
        template_run_avx2(T, x, y, c, m);
        return;
    }
#endif
    float acc[AGG_CHUNK];
    memset(acc, 0, (size_t)m * sizeof *acc);
    for (int t = 0; t < T->tn; t++) {
        const float v = T->val[t], *xs = x + c + T->off[t];
        for (int32_t i = 0; i < m; i++)
            acc[i] += v * xs[i];
    }
    memcpy(y + c, acc, (size_t)m * sizeof(float));
}

/* Row c's template class on level L (cls, else plain): 0 for a row in A,
 * else the class, its template in *T. */
static inline int row_template(const mg_alevel *L, int32_t c, agg_tmpl *T)
{
    int k = L->cls ? L->cls[c] : L->plain[c];
    if (k == 1)
        *T = (agg_tmpl){L->tn, L->toff, L->tval};
    else if (k > 1)
        *T = (agg_tmpl){L->cn[k - 2], L->coff + (size_t)L->cw * (k - 2),
                        L->cval + (size_t)L->cw * (k - 2)};
    return k;
}

/* y = A x on rows [c0, c1) of a level with templates: each run of rows of
 * one template as a stencil (vectorized over the run), the others from the
 * matrix. Runs, not whole chunks: the blocks at the ends of every x row of
 * blocks are not plain, so nearly every chunk holds a few. */
static void apply_chunk(const agg_op *o, const float *x, float *y, int32_t c0, int32_t c1)
{
    const mg_alevel *L = o->lv;
    for (int32_t c = c0; c < c1;) {
        agg_tmpl T;
        const int k = L->cls && L->cls[c] == MG_CLS_GROUP ? MG_CLS_GROUP : row_template(L, c, &T);
        if (!k) {
            y[c] = csr_row_dot(o->A, c, x);
            c++;
            continue;
        }
        int32_t e = c + 1;
        while (e < c1 && (L->cls ? L->cls[e] : L->plain[e]) == k)
            e++;
        if (k != MG_CLS_GROUP) /* else group_apply's */
            template_run(&T, x, y, c, e - c);
        c = e;
    }
}

/* y at the MG_GROUP rows of group g (mg_alevel's grow): their class's
 * entries, summed for all the rows at once, so that each entry costs one
 * load of x (a stored row's costs a column and a value too). */
#define GROUP_APPLY_BODY                                                                           \
    const int32_t *r = L->grow + (size_t)MG_GROUP * g;                                             \
    const int k = L->gcls[g], tn = L->cn[k];                                                       \
    const int32_t *off = L->coff + (size_t)L->cw * k;                                              \
    const float *val = L->cval + (size_t)L->cw * k;                                                \
    const float *p[MG_GROUP];                                                                      \
    float a[MG_GROUP];                                                                             \
    for (int i = 0; i < MG_GROUP; i++) {                                                           \
        p[i] = x + r[i];                                                                           \
        a[i] = 0;                                                                                  \
    }                                                                                              \
    for (int t = 0; t < tn; t++) {                                                                 \
        const int32_t d = off[t];                                                                  \
        const float v = val[t];                                                                    \
        for (int i = 0; i < MG_GROUP; i++)                                                         \
            a[i] += v * p[i][d];                                                                   \
    }                                                                                              \
    for (int i = 0; i < MG_GROUP; i++)                                                             \
        y[r[i]] = a[i];

/* Scalar on purpose: GCC's vectorizers would assemble the eight rows' loads
 * into vectors lane by lane, which costs more than the FMAs save. */
#define GROUP_SCALAR optimize("no-tree-vectorize")

#if MG_AVX512
__attribute__((target("avx2,fma"), GROUP_SCALAR)) static void group_apply_avx2(const mg_alevel *L,
                                                                               const float *x,
                                                                               float *y, int32_t g)
{
    GROUP_APPLY_BODY
}
#endif

__attribute__((GROUP_SCALAR)) static void group_apply(const mg_alevel *L, const float *x, float *y,
                                                      int32_t g)
{
#if MG_AVX512
    if (mg_avx2()) {
        group_apply_avx2(L, x, y, g);
        return;
    }
#endif
    GROUP_APPLY_BODY
}
#undef GROUP_APPLY_BODY
#undef GROUP_SCALAR

/* y = A x on a level. */
static void op_apply(const agg_op *o, const float *x, float *y)
{
    if (o->F) {
        fine_apply(o, x, y);
        return;
    }
    const mg_alevel *L = o->lv;
    if (L->tn || L->cls) {
        /* the chunks leave the grouped rows to the groups: no row is in both */
#pragma omp parallel if (o->n > AGG_PAR_MIN)
        {
#pragma omp for schedule(static) nowait
            for (int32_t c0 = 0; c0 < o->n; c0 += AGG_CHUNK)
                apply_chunk(o, x, y, c0, c0 + AGG_CHUNK < o->n ? c0 + AGG_CHUNK : o->n);
#pragma omp for schedule(static)
            for (int32_t g = 0; g < L->ngrp; g++)
                group_apply(L, x, y, g);
        }
        return;
    }
#pragma omp parallel for schedule(static) if (o->n > AGG_PAR_MIN)
    for (int32_t c = 0; c < o->n; c++)
        y[c] = csr_row_dot(o->A, c, x);
}

/* Largest eigenvalue of D^-1 A by power iteration (times 1.1, as the
 * geometric levels' bound). */
static double op_lmax(const agg_op *o, float *x, float *y)
{
    for (int32_t c = 0; c < o->n; c++) {
        uint64_t h = ((uint64_t)c + 1) * 0x9E3779B97F4A7C15ull;
        h ^= h >> 31;
        h *= 0xBF58476D1CE4E5B9ull;
        h ^= h >> 29;
        x[c] = o->dinv[c] > 0 ? (float)((double)(h >> 40) / (double)(1u << 24) - 0.5) : 0.0f;
    }
    double lam = 2.0;
    for (int it = 0; it < 10; it++) {
        op_apply(o, x, y);
        double xy = 0, xx = 0, yy = 0;
#pragma omp parallel for schedule(static) reduction(+ : xy, xx, yy) if (o->n > AGG_PAR_MIN)
        for (int32_t c = 0; c < o->n; c++) {
            double yc = (double)o->dinv[c] * y[c];
            xy += (double)x[c] * yc / (o->dinv[c] > 0 ? o->dinv[c] : 1.0f);
            xx += (double)x[c] * x[c] / (o->dinv[c] > 0 ? o->dinv[c] : 1.0f);
            yy += yc * yc;
            y[c] = (float)yc;
        }
        if (!(xx > 0) || !(yy > 0))
            break;
        lam = xy / xx;
        double s = 1.0 / sqrt(yy);
        for (int32_t c = 0; c < o->n; c++)
            x[c] = (float)(y[c] * s);
    }
    return 1.1 * lam;
}

/* ---------- aggregates ---------- */

/* Block coordinates of unknown c of level l. */
static void unknown_xyz(const mg_agg *g, int l, int32_t c, int xyz[3])
{
    if (l == 0) {
        const mg_level *L = g->fine;
        xyz[0] = (int)(c % L->n[0]);
        xyz[1] = (int)((c / L->n[0]) % L->n[1]);
        xyz[2] = (int)(c / L->sz);
        return;
    }
    for (int b = 0; b < 3; b++)
        xyz[b] = g->lv[l].xyz[3 * (size_t)c + b];
}

static int strong(float aij, float dii_inv, float djj_inv)
{
    double q = (double)aij * aij * dii_inv * djj_inv;
    return q > AGG_STRONG * AGG_STRONG;
}

/* The parts of one block (unknowns u[0..m) of level l) that couplings within
 * it connect: lab[q] = part of u[q]; returns the number of parts. */
static int block_parts(const agg_op *o, const int32_t *u, int m, int *lab)
{
    int parts = 0, stack[64];
    for (int q = 0; q < m; q++)
        lab[q] = -1;
    for (int q0 = 0; q0 < m; q0++) {
        if (lab[q0] >= 0)
            continue;
        int top = 0;
        stack[top++] = q0;
        lab[q0] = parts;
        while (top) {
            int q = stack[--top];
            int32_t bc[ROW_MAX];
            float bv[ROW_MAX];
            const int32_t *col;
            const float *val;
            int k = op_row(o, u[q], bc, bv, &col, &val);
            for (int e = 0; e < k; e++) {
                if (col[e] == u[q] || !strong(val[e], o->dinv[u[q]], o->dinv[col[e]]))
                    continue;
                for (int p = 0; p < m; p++)
                    if (u[p] == col[e] && lab[p] < 0) {
                        lab[p] = parts;
                        if (top < 64)
                            stack[top++] = p;
                    }
            }
        }
        parts++;
    }
    return parts;
}

/* Aggregates of level l: L->agg, members (mrp, mem) and level l+1's size,
 * coordinates and extent. */
static hv_status aggregate(mg_agg *g, int l)
{
    mg_alevel *L = &g->lv[l], *C = &g->lv[l + 1];
    agg_op o = level_op(g, l);
    int bx = (L->ext[0] + 1) / 2, by = (L->ext[1] + 1) / 2, bz = (L->ext[2] + 1) / 2;
    size_t nblk = (size_t)bx * by * bz;
    size_t *start = calloc(nblk + 1, sizeof *start);
    int32_t *order = malloc((size_t)L->n * sizeof *order);
    L->agg = malloc((size_t)L->n * sizeof *L->agg);
    if (!start || !order || !L->agg) {
        free(start);
        free(order);
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for aggregates of level %d", l);
    }
    /* Counting sort of the live unknowns by block. */
    for (int32_t c = 0; c < L->n; c++) {
        L->agg[c] = -1;
        if (!(o.dinv[c] > 0))
            continue;
        int x[3];
        unknown_xyz(g, l, c, x);
        start[(size_t)x[0] / 2 + bx * ((size_t)x[1] / 2 + by * ((size_t)x[2] / 2)) + 1]++;
    }
    for (size_t b = 0; b < nblk; b++)
        start[b + 1] += start[b];
    size_t live = start[nblk];
    size_t *fill = malloc(nblk * sizeof *fill);
    if (!fill) {
        free(start);
        free(order);
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for aggregates of level %d", l);
    }
    memcpy(fill, start, nblk * sizeof *fill);
    for (int32_t c = 0; c < L->n; c++) {
        if (!(o.dinv[c] > 0))
            continue;
        int x[3];
        unknown_xyz(g, l, c, x);
        order[fill[(size_t)x[0] / 2 + bx * ((size_t)x[1] / 2 + by * ((size_t)x[2] / 2))]++] = c;
    }
    free(fill);
    /* Parts of each block. Under the fine level, the first takes the block's
     * own index (a block without live unknowns leaves an empty one) and the
     * others come after all blocks: in open space level 1 is then a grid whose
     * neighbours are at fixed offsets (its template rows). Deeper, every
     * block's parts are numbered in turn, so that a row's columns stay within
     * a few planes of blocks of it (hv__mg_agg_pack). */
    const int grid = l == 0;
    size_t cap = nblk + 16, next = grid ? nblk : 0;
    C->xyz = malloc(3 * cap * sizeof *C->xyz);
    hv_status st = HV_OK;
    if (!C->xyz) {
        st = hv__error(HV_ERR_NOMEM, "multigrid: out of memory for aggregates of level %d", l);
        goto done;
    }
    for (size_t b = 0; b < nblk; b++) {
        const int32_t *u = order + start[b];
        int m = (int)(start[b + 1] - start[b]), lab[64];
        const int32_t bxyz[3] = {(int32_t)(b % bx), (int32_t)((b / bx) % by),
                                 (int32_t)(b / ((size_t)bx * by))};
        if (grid)
            memcpy(C->xyz + 3 * b, bxyz, sizeof bxyz);
        for (int q0 = 0; q0 < m; q0 += 64) {
            int mm = m - q0 < 64 ? m - q0 : 64;
            int parts = block_parts(&o, u + q0, mm, lab);
            for (int p = 0; p < parts; p++) {
                size_t id = b;
                if (!grid || p > 0 || q0 > 0) {
                    id = next++;
                    if (id >= cap) {
                        cap *= 2;
                        int32_t *x2 = realloc(C->xyz, 3 * cap * sizeof *x2);
                        if (!x2) {
                            st = hv__error(HV_ERR_NOMEM, "multigrid: out of memory for aggregates");
                            goto done;
                        }
                        C->xyz = x2;
                    }
                    memcpy(C->xyz + 3 * id, bxyz, sizeof bxyz);
                }
                for (int q = 0; q < mm; q++)
                    if (lab[q] == p)
                        L->agg[u[q0 + q]] = (int32_t)id;
            }
        }
    }
    if (next >= (size_t)INT32_MAX) {
        st = hv__error(HV_ERR_UNSUPPORTED, "multigrid: level %d has too many aggregates", l + 1);
        goto done;
    }
    C->n = (int32_t)next;
    /* Members grouped by aggregate. */
    L->mrp = calloc((size_t)C->n + 1, sizeof *L->mrp);
    L->mem = malloc((live ? live : 1) * sizeof *L->mem);
    if (!L->mrp || !L->mem) {
        st = hv__error(HV_ERR_NOMEM, "multigrid: out of memory for aggregates of level %d", l);
        goto done;
    }
    for (int32_t c = 0; c < L->n; c++)
        if (L->agg[c] >= 0)
            L->mrp[L->agg[c] + 1]++;
    L->nagg = 0;
    for (int32_t I = 0; I < C->n; I++) {
        L->nagg += L->mrp[I + 1] > 0;
        L->mrp[I + 1] += L->mrp[I];
    }
    L->live = (int32_t)live;
    for (size_t q = 0; q < live; q++) {
        int32_t c = order[q];
        L->mem[L->mrp[L->agg[c]]++] = c;
    }
    for (int32_t I = C->n; I > 0; I--)
        L->mrp[I] = L->mrp[I - 1];
    L->mrp[0] = 0;
    C->ext[0] = bx;
    C->ext[1] = by;
    C->ext[2] = bz;
done:
    free(start);
    free(order);
    return st;
}

/* ---------- Galerkin coarse operators ---------- */

/* A sparse accumulator over a level's unknowns, with the list of those touched. */
typedef struct spa {
    double *acc;
    int32_t *mark, gen;
    int32_t *idx;
    size_t nidx, cap;
} spa;

static int spa_init(spa *s, int32_t n)
{
    memset(s, 0, sizeof *s);
    s->acc = malloc(((size_t)n + 1) * sizeof *s->acc);
    s->mark = malloc(((size_t)n + 1) * sizeof *s->mark);
    s->idx = malloc(((size_t)n + 1) * sizeof *s->idx);
    s->cap = (size_t)n + 1;
    if (!s->acc || !s->mark || !s->idx)
        return -1;
    for (int32_t c = 0; c < n; c++)
        s->mark[c] = -1;
    return 0;
}

static void spa_free(spa *s)
{
    free(s->acc);
    free(s->mark);
    free(s->idx);
}

static void spa_start(spa *s)
{
    s->gen++;
    s->nidx = 0;
}

/* acc[c] += v (every column has room: idx holds n entries). Returns 0. */
static inline int spa_add(spa *s, int32_t c, double v)
{
    if (s->mark[c] != s->gen) {
        s->mark[c] = s->gen;
        s->acc[c] = v;
        s->idx[s->nidx++] = c;
    } else {
        s->acc[c] += v;
    }
    return 0;
}

/* Growing arrays of one thread's rows. */
typedef struct rows_out {
    int32_t *ci;
    float *v;
    size_t n, cap;
    int32_t *len;
} rows_out;

static int rows_push(rows_out *r, int32_t c, float v)
{
    if (r->n == r->cap) {
        size_t cap = r->cap ? 2 * r->cap : 4096;
        int32_t *ci = realloc(r->ci, cap * sizeof *ci);
        if (ci)
            r->ci = ci;
        float *vv = ci ? realloc(r->v, cap * sizeof *vv) : NULL;
        if (vv)
            r->v = vv;
        if (!ci || !vv)
            return -1;
        r->cap = cap;
    }
    r->ci[r->n] = c;
    r->v[r->n++] = v;
    return 0;
}

/* ---------- Galerkin on the coarse levels: sparse products ---------- */

/* One row of a product into a sparse accumulator (after spa_start), with
 * scratch of its own for each thread: zeroed memory, or a second sparse
 * accumulator (build_csr's `inner`). */
typedef int (*row_fn)(const void *ctx, void *scratch, int32_t row, spa *s);

/* out = the nrows rows that fn makes, over ncols columns; with `drop`,
 * entries off the diagonal below drop times the diagonal are left out. */
static hv_status build_csr(mg_csr *out, int32_t nrows, int32_t ncols, row_fn fn, const void *ctx,
                           size_t scratch_bytes, int32_t inner, double drop)
{
    memset(out, 0, sizeof *out);
    int nthr = 1;
#ifdef _OPENMP
    nthr = nrows > 2048 ? omp_get_max_threads() : 1;
#endif
    rows_out *outs = calloc((size_t)nthr, sizeof *outs);
    int32_t *len = malloc(((size_t)nrows + 1) * sizeof *len);
    int failed = !outs || !len;
#pragma omp parallel num_threads(nthr) if (nthr > 1)
    {
        int t = 0;
#ifdef _OPENMP
        t = omp_get_thread_num();
#endif
        spa cs = {0}, in = {0};
        void *scratch = scratch_bytes ? calloc(1, scratch_bytes) : inner > 0 ? (void *)&in : NULL;
        int bad = failed || spa_init(&cs, ncols) || (scratch_bytes && !scratch) ||
                  (inner > 0 && spa_init(&in, inner));
        int32_t r0 = (int32_t)((int64_t)nrows * t / nthr),
                r1 = (int32_t)((int64_t)nrows * (t + 1) / nthr);
        for (int32_t r = r0; r < r1 && !bad; r++) {
            spa_start(&cs);
            if (fn(ctx, scratch, r, &cs)) {
                bad = 1;
                break;
            }
            double diag = r < ncols && cs.mark[r] == cs.gen ? fabs(cs.acc[r]) : 0.0;
            int32_t n = 0;
            for (size_t q = 0; q < cs.nidx && !bad; q++) {
                int32_t c = cs.idx[q];
                double v = cs.acc[c];
                if (c != r && (v == 0 || (drop > 0 && !(fabs(v) > drop * diag))))
                    continue;
                bad = rows_push(&outs[t], c, (float)v) != 0;
                n++;
            }
            len[r] = n;
        }
        spa_free(&cs);
        spa_free(&in);
        if (scratch_bytes)
            free(scratch);
        if (bad) {
#pragma omp atomic write
            failed = 1;
        }
    }
    size_t nnz = 0;
    for (int t = 0; !failed && t < nthr; t++)
        nnz += outs[t].n;
    if (!failed) {
        out->n = nrows;
        out->rp = malloc(((size_t)nrows + 1) * sizeof *out->rp);
        out->ci = malloc((nnz ? nnz : 1) * sizeof *out->ci);
        out->v = malloc((nnz ? nnz : 1) * sizeof *out->v);
        failed = !out->rp || !out->ci || !out->v;
    }
    if (!failed) {
        out->rp[0] = 0;
        for (int32_t r = 0; r < nrows; r++)
            out->rp[r + 1] = out->rp[r] + (size_t)len[r];
        size_t at = 0;
        for (int t = 0; t < nthr; t++) {
            memcpy(out->ci + at, outs[t].ci, outs[t].n * sizeof *out->ci);
            memcpy(out->v + at, outs[t].v, outs[t].n * sizeof *out->v);
            at += outs[t].n;
        }
    }
    for (int t = 0; outs && t < nthr; t++) {
        free(outs[t].ci);
        free(outs[t].v);
    }
    free(outs);
    free(len);
    if (failed)
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for a coarse level's products");
    return HV_OK;
}

static void csr_free(mg_csr *m)
{
    free(m->rp);
    free(m->ci);
    free(m->v);
    free(m->cb);
    free(m->co);
    memset(m, 0, sizeof *m);
}

/* P = (I - wp D^-1 A) P0 of a coarse level, row by row. */
typedef struct p_ctx {
    const mg_alevel *L;
    const int32_t *agg;
    const float *dinv;
    double wp;
} p_ctx;

static int p_row(const void *ctx, void *scratch, int32_t c, spa *s)
{
    (void)scratch;
    const p_ctx *x = ctx;
    if (x->agg[c] < 0)
        return 0;
    if (spa_add(s, x->agg[c], 1.0))
        return -1;
    double f = -x->wp * x->dinv[c];
    int32_t bc[ROW_MAX];
    float bv[ROW_MAX];
    const int32_t *col;
    const float *val;
    int k = level_row(x->L, c, bc, bv, &col, &val);
    for (int q = 0; q < k; q++)
        if (x->agg[col[q]] >= 0 && spa_add(s, x->agg[col[q]], f * val[q]))
            return -1;
    return 0;
}

/* Row I of R A P: the row (R A)(I,:) in the inner accumulator, then times P.
 * No product is stored between the two. */
typedef struct rap_ctx {
    const mg_csr *R, *P;
    const mg_alevel *L;
} rap_ctx;

static int rap_row(const void *ctx, void *scratch, int32_t I, spa *s)
{
    const rap_ctx *m = ctx;
    spa *ra = scratch;
    int32_t bc[ROW_MAX];
    float bv[ROW_MAX];
    const int32_t *col;
    const float *val;
    spa_start(ra);
    for (size_t q = m->R->rp[I]; q < m->R->rp[I + 1]; q++) {
        int32_t c = m->R->ci[q];
        double r = m->R->v[q];
        int k = level_row(m->L, c, bc, bv, &col, &val);
        for (int p = 0; p < k; p++)
            spa_add(ra, col[p], r * val[p]);
    }
    for (size_t q = 0; q < ra->nidx; q++) {
        int32_t e = ra->idx[q];
        double x = ra->acc[e];
        for (size_t p = m->P->rp[e]; p < m->P->rp[e + 1]; p++)
            spa_add(s, m->P->ci[p], x * m->P->v[p]);
    }
    return 0;
}

/* T = M^T for M with ncols columns. */
static hv_status csr_transpose(const mg_csr *M, int32_t ncols, mg_csr *T)
{
    size_t nnz = M->rp[M->n];
    T->n = ncols;
    T->rp = calloc((size_t)ncols + 1, sizeof *T->rp);
    T->ci = malloc((nnz ? nnz : 1) * sizeof *T->ci);
    T->v = malloc((nnz ? nnz : 1) * sizeof *T->v);
    size_t *fill = malloc(((size_t)ncols + 1) * sizeof *fill);
    if (!T->rp || !T->ci || !T->v || !fill) {
        free(fill);
        csr_free(T);
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for a coarse level's products");
    }
    for (size_t q = 0; q < nnz; q++)
        T->rp[M->ci[q] + 1]++;
    for (int32_t c = 0; c < ncols; c++)
        T->rp[c + 1] += T->rp[c];
    memcpy(fill, T->rp, ((size_t)ncols + 1) * sizeof *fill);
    for (int32_t r = 0; r < M->n; r++)
        for (size_t q = M->rp[r]; q < M->rp[r + 1]; q++) {
            size_t at = fill[M->ci[q]]++;
            T->ci[at] = r;
            T->v[at] = M->v[q];
        }
    free(fill);
    return HV_OK;
}

/* Level l+1's operator P^T A P from a coarse level l by sparse products (row
 * by row of P^T, (P^T A) then P: nothing of the size of A P is held). */
static hv_status galerkin_csr(mg_agg *g, int l, double wp)
{
    mg_alevel *L = &g->lv[l], *C = &g->lv[l + 1];
    mg_csr P = {0}, R = {0};
    p_ctx pc = {L, L->agg, L->dinv, wp};
    hv_status st = build_csr(&P, L->n, C->n, p_row, &pc, 0, 0, 0);
    rap_ctx rap = {&R, &P, L};
    if (!st)
        st = csr_transpose(&P, C->n, &R);
    if (!st)
        st = build_csr(&C->A, C->n, C->n, rap_row, &rap, 0, L->n, 1e-9);
    if (st) {
        csr_free(&P);
        csr_free(&R);
        return st;
    }
    if (L->tn) {
        /* A level that is mostly template rows applies P and P^T from its
         * stencil as the fine level does: cheaper than the two matrices. */
        csr_free(&P);
        csr_free(&R);
        return HV_OK;
    }
    L->P = P; /* kept for the transfers */
    L->R = R;
    g->bytes += (P.rp[P.n] + R.rp[R.n]) * (sizeof(int32_t) + sizeof(float)) +
                ((size_t)P.n + R.n + 2) * sizeof(size_t);
    return HV_OK;
}

/* ---------- Galerkin from the fine level ---------- */

/* A small open-addressing accumulator over fine cells: the supports of one
 * coarse column's products on the fine level lie in an 8^3 box of cells. */
#define HASH_BITS 11
#define HASH_SIZE (1 << HASH_BITS)

typedef struct hacc {
    int32_t key[HASH_SIZE]; /* cell + 1; 0: empty */
    double val[HASH_SIZE];
    int32_t used[HASH_SIZE]; /* slots in insertion order */
    int n;
} hacc;

static inline int hacc_slot(hacc *h, int32_t c)
{
    uint32_t s = ((uint32_t)c * 2654435761u) >> (32 - HASH_BITS);
    for (;;) {
        if (h->key[s] == c + 1)
            return (int)s;
        if (h->key[s] == 0) {
            if (h->n >= HASH_SIZE / 2)
                return -1;
            h->key[s] = c + 1;
            h->val[s] = 0;
            h->used[h->n++] = (int32_t)s;
            return (int)s;
        }
        s = (s + 1) & (HASH_SIZE - 1);
    }
}

static void hacc_clear(hacc *h)
{
    for (int q = 0; q < h->n; q++)
        h->key[h->used[q]] = 0;
    h->n = 0;
}

typedef struct g0_scratch {
    hacc v, w;
    double t[HASH_SIZE];
} g0_scratch;

/* A coarse row copied from a template: the row of a block whose neighbourhood
 * is plain fluid, as offsets to the neighbouring blocks. */
typedef struct g0_template {
    int n;
    int off[125][3];
    double val[125];
} g0_template;

typedef struct g0_ctx {
    agg_op o;
    const mg_alevel *L, *C;
    double wp;
    const uint8_t *plain;    /* per level-1 unknown: a plain neighbourhood (or NULL) */
    const g0_template *tmpl; /* NULL until made */
} g0_ctx;

/* Row J of A_c = P^T A (P e_J): v = P e_J on the members of J and their
 * neighbours, w = A v, then w - wp A D^-1 w summed per aggregate
 * (P^T = P0^T (I - wp A D^-1)). */
static int g0_row(const void *ctx, void *scratch, int32_t J, spa *cs)
{
    const g0_ctx *x = ctx;
    const agg_op *o = &x->o;
    const mg_alevel *L = x->L;
    if (x->tmpl && x->plain[J])
        return 0; /* the template's row: level 1 takes it from there */
    g0_scratch *S = scratch;
    int32_t bc[ROW_MAX];
    float bv[ROW_MAX];
    const int32_t *col;
    const float *val;
    hacc_clear(&S->v);
    hacc_clear(&S->w);
    for (size_t q = L->mrp[J]; q < L->mrp[J + 1]; q++) {
        int k = op_row(o, L->mem[q], bc, bv, &col, &val);
        for (int e = 0; e < k; e++)
            if (L->agg[col[e]] >= 0 && hacc_slot(&S->v, col[e]) < 0)
                return -1;
    }
    /* P(c, J) = [agg c = J] - wp dinv_c sum over row c of a_cx [agg x = J],
     * and w = A v = sum over c of P(c, J) times row c (A is symmetric). */
    for (int q = 0; q < S->v.n; q++) {
        int32_t c = S->v.key[S->v.used[q]] - 1;
        int k = op_row(o, c, bc, bv, &col, &val);
        double sum = 0;
        for (int e = 0; e < k; e++)
            if (L->agg[col[e]] == J)
                sum += val[e];
        double pc = (L->agg[c] == J) - x->wp * o->dinv[c] * sum;
        if (pc == 0)
            continue;
        for (int e = 0; e < k; e++) {
            int h = hacc_slot(&S->w, col[e]);
            if (h < 0)
                return -1;
            S->w.val[h] += val[e] * pc;
        }
    }
    int nw = S->w.n;
    for (int q = 0; q < nw; q++) {
        int h = S->w.used[q];
        S->t[q] = x->wp * o->dinv[S->w.key[h] - 1] * S->w.val[h];
    }
    for (int q = 0; q < nw; q++) {
        if (S->t[q] == 0)
            continue;
        int k = op_row(o, S->w.key[S->w.used[q]] - 1, bc, bv, &col, &val);
        for (int e = 0; e < k; e++) {
            int h = hacc_slot(&S->w, col[e]);
            if (h < 0)
                return -1;
            S->w.val[h] -= val[e] * S->t[q];
        }
    }
    for (int q = 0; q < S->w.n; q++) {
        int h = S->w.used[q];
        int32_t I = L->agg[S->w.key[h] - 1];
        if (I >= 0 && spa_add(cs, I, S->w.val[h]))
            return -1;
    }
    return 0;
}

/* Blocks of level 1 whose 5^3 neighbourhood of blocks is whole and all fluid
 * (3D binary fine levels): their rows are all the same, up to the columns.
 * plain[J] per level-1 unknown (NULL when there are none). */
static hv_status plain_blocks(const mg_agg *g, uint8_t **plain_out)
{
    const mg_level *F = g->fine;
    const mg_alevel *C = &g->lv[1];
    *plain_out = NULL;
    if (g->dim != 3 || !F->binary)
        return HV_OK;
    int e[3] = {C->ext[0], C->ext[1], C->ext[2]};
    size_t nb = (size_t)e[0] * e[1] * e[2];
    uint8_t *full = malloc(nb), *tmp = malloc(nb), *plain = malloc((size_t)C->n + 1);
    if (!full || !tmp || !plain) {
        free(full);
        free(tmp);
        free(plain);
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for the coarse operator");
    }
    /* full: the block's 8 cells are in the grid and fluid with every face open. */
#pragma omp parallel for schedule(static) if (nb > AGG_PAR_MIN)
    for (size_t b = 0; b < nb; b++) {
        int bx = (int)(b % e[0]), by = (int)((b / e[0]) % e[1]),
            bz = (int)(b / ((size_t)e[0] * e[1]));
        int ok = 2 * bx + 1 < F->n[0] && 2 * by + 1 < F->n[1] && 2 * bz + 1 < F->n[2];
        for (int q = 0; ok && q < 8; q++) {
            size_t c = (size_t)(2 * bx + (q & 1)) + F->sy * (size_t)(2 * by + ((q >> 1) & 1)) +
                       F->sz * (size_t)(2 * bz + (q >> 2));
            ok = F->a[c] != 0.0f && g->faces[c] == 0x3f;
        }
        full[b] = (uint8_t)ok;
    }
    /* An AND over a window of 5 blocks along each axis, out of range counting as 0. */
    size_t stride[3] = {1, (size_t)e[0], (size_t)e[0] * e[1]};
    for (int a = 0; a < 3; a++) {
        uint8_t *src = a % 2 ? tmp : full, *dst = a % 2 ? full : tmp;
#pragma omp parallel for schedule(static) if (nb > AGG_PAR_MIN)
        for (size_t b = 0; b < nb; b++) {
            int x = (int)(b / stride[a] % e[a]), ok = x >= 2 && x + 2 < e[a];
            for (int d = -2; ok && d <= 2; d++)
                ok = src[b + (ptrdiff_t)d * (ptrdiff_t)stride[a]];
            dst[b] = (uint8_t)ok;
        }
    }
    /* After three passes the result is in tmp. */
    for (int32_t I = 0; I < C->n; I++) {
        const int32_t *p = C->xyz + 3 * (size_t)I;
        plain[I] = tmp[(size_t)p[0] + e[0] * ((size_t)p[1] + e[1] * (size_t)p[2])];
    }
    free(full);
    free(tmp);
    *plain_out = plain;
    return HV_OK;
}

/* Level 1's operator from the fine level (aggregates built). */
static hv_status galerkin0(mg_agg *g, double wp)
{
    mg_alevel *C = &g->lv[1];
    g0_ctx x = {level_op(g, 0), &g->lv[0], C, wp, NULL, NULL};
    uint8_t *plain;
    hv_status st = plain_blocks(g, &plain);
    if (st)
        return st;
    g0_template *T = NULL;
    int32_t J0 = -1;
    for (int32_t J = 0; plain && J < C->n && J0 < 0; J++)
        if (plain[J])
            J0 = J;
    if (J0 >= 0) {
        /* The template: one plain row, computed. */
        spa cs = {0};
        g0_scratch *S = calloc(1, sizeof *S);
        T = calloc(1, sizeof *T);
        if (!S || !T || spa_init(&cs, C->n) || (spa_start(&cs), g0_row(&x, S, J0, &cs)) ||
            cs.nidx > 125) {
            free(T);
            T = NULL;
        } else {
            const int32_t *p0 = C->xyz + 3 * (size_t)J0;
            for (size_t q = 0; q < cs.nidx; q++) {
                const int32_t *p = C->xyz + 3 * (size_t)cs.idx[q];
                for (int a = 0; a < 3; a++)
                    T->off[T->n][a] = p[a] - p0[a];
                T->val[T->n++] = cs.acc[cs.idx[q]];
            }
        }
        spa_free(&cs);
        free(S);
    }
    x.plain = plain;
    x.tmpl = T;
    st = build_csr(&C->A, C->n, C->n, g0_row, &x, sizeof(g0_scratch), 0, 1e-9);
    if (!st && T) {
        /* Level 1 keeps the template for its plain rows (as build_csr keeps
         * them: tiny entries off the diagonal left out). */
        double diag = 0;
        for (int e = 0; e < T->n; e++)
            if (!T->off[e][0] && !T->off[e][1] && !T->off[e][2])
                diag = fabs(T->val[e]);
        for (int e = 0; e < T->n; e++) {
            const int *d = T->off[e];
            int self = !d[0] && !d[1] && !d[2];
            if (!self && !(fabs(T->val[e]) > 1e-9 * diag))
                continue;
            C->toff[C->tn] = d[0] + C->ext[0] * (d[1] + C->ext[1] * d[2]);
            C->tval[C->tn++] = (float)T->val[e];
        }
        C->plain = plain;
        plain = NULL;
    }
    free(T);
    free(plain);
    return st;
}

/* ---------- the bottom level ---------- */

/* Connected regions of the bottom operator (Poisson: each its own null space). */
static hv_status bottom_regions(mg_agg *g, const agg_op *o)
{
    int32_t n = o->n, *stack = malloc((size_t)n * sizeof *stack);
    g->region = malloc((size_t)n * sizeof *g->region);
    if (!stack || !g->region) {
        free(stack);
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for the bottom level");
    }
    for (int32_t c = 0; c < n; c++)
        g->region[c] = -1;
    g->nregion = 0;
    for (int32_t c0 = 0; c0 < n; c0++) {
        if (g->region[c0] >= 0 || !(o->dinv[c0] > 0))
            continue;
        int32_t top = 0;
        stack[top++] = c0;
        g->region[c0] = g->nregion;
        while (top) {
            int32_t c = stack[--top];
            int32_t bc[ROW_MAX];
            float bv[ROW_MAX];
            const int32_t *col;
            const float *val;
            int k = op_row(o, c, bc, bv, &col, &val);
            for (int e = 0; e < k; e++)
                if (g->region[col[e]] < 0 && o->dinv[col[e]] > 0 && val[e] != 0) {
                    g->region[col[e]] = g->nregion;
                    stack[top++] = col[e];
                }
        }
        g->nregion++;
    }
    free(stack);
    return HV_OK;
}

/* The bottom level's dense Cholesky factor. Poisson adds sigma/|R| on every
 * pair of a region R (sigma: the mean diagonal), which leaves the mean-free
 * solution of a mean-free right-hand side unchanged and makes the matrix
 * definite; empty rows get a one on the diagonal. */
static hv_status bottom_factor(mg_agg *g)
{
    int l = g->nlev - 1;
    agg_op o = level_op(g, l);
    int32_t n = g->nb = o.n;
    hv_status st = bottom_regions(g, &o);
    if (st)
        return st;
    g->chol = calloc((size_t)n * n, sizeof *g->chol);
    g->bx = malloc(((size_t)n + 1) * sizeof *g->bx);
    double *cnt = calloc((size_t)g->nregion + 1, sizeof *cnt);
    if (!g->chol || !g->bx || !cnt) {
        free(cnt);
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for the bottom level");
    }
    double *M = g->chol, dsum = 0;
    for (int32_t c = 0; c < n; c++) {
        int32_t bc[ROW_MAX];
        float bv[ROW_MAX];
        const int32_t *col;
        const float *val;
        int k = op_row(&o, c, bc, bv, &col, &val);
        for (int e = 0; e < k; e++)
            M[(size_t)c * n + col[e]] += val[e];
        if (g->region[c] >= 0) {
            cnt[g->region[c]] += 1;
            dsum += M[(size_t)c * n + c];
        }
    }
    double sigma = n ? dsum / n : 1.0;
    for (int32_t i = 0; i < n; i++) {
        if (g->region[i] < 0) {
            for (int32_t j = 0; j < n; j++)
                M[(size_t)i * n + j] = M[(size_t)j * n + i] = 0;
            M[(size_t)i * n + i] = 1;
            continue;
        }
        for (int32_t j = 0; g->alpha == 0 && j < n; j++)
            if (g->region[j] == g->region[i])
                M[(size_t)i * n + j] += sigma / cnt[g->region[i]];
    }
    free(cnt);
    /* Symmetrize (float coarse rows), then factor in place (lower). */
    for (int32_t i = 0; i < n; i++)
        for (int32_t j = 0; j < i; j++) {
            double v = 0.5 * (M[(size_t)i * n + j] + M[(size_t)j * n + i]);
            M[(size_t)i * n + j] = M[(size_t)j * n + i] = v;
        }
    for (int32_t j = 0; j < n; j++) {
        double d = M[(size_t)j * n + j];
        for (int32_t k = 0; k < j; k++)
            d -= M[(size_t)j * n + k] * M[(size_t)j * n + k];
        if (!(d > 1e-12 * sigma))
            d = sigma; /* a direction float rounding left singular: damp it */
        d = sqrt(d);
        M[(size_t)j * n + j] = d;
#pragma omp parallel for schedule(static) if (n - j > 256)
        for (int32_t i = j + 1; i < n; i++) {
            double s = M[(size_t)i * n + j];
            for (int32_t k = 0; k < j; k++)
                s -= M[(size_t)i * n + k] * M[(size_t)j * n + k];
            M[(size_t)i * n + j] = s / d;
        }
    }
    return HV_OK;
}

/* u = A^-1 f on the bottom level (Poisson: mean-free per region). */
static void bottom_solve(mg_agg *g, const float *f, float *u)
{
    int32_t n = g->nb;
    const double *M = g->chol;
    double *x = g->bx;
    for (int32_t i = 0; i < n; i++) {
        double s = g->region[i] >= 0 ? f[i] : 0.0;
        for (int32_t k = 0; k < i; k++)
            s -= M[(size_t)i * n + k] * x[k];
        x[i] = s / M[(size_t)i * n + i];
    }
    for (int32_t i = n - 1; i >= 0; i--) {
        double s = x[i];
        for (int32_t k = i + 1; k < n; k++)
            s -= M[(size_t)k * n + i] * x[k];
        x[i] = s / M[(size_t)i * n + i];
    }
    for (int32_t i = 0; i < n; i++)
        u[i] = g->region[i] >= 0 ? (float)x[i] : 0.0f;
}

/* ---------- the cycle ---------- */

/* r = f - A u on a coarse level. */
static void level_residual(const agg_op *o, const float *f, const float *u, float *r)
{
    op_apply(o, u, r);
#pragma omp parallel for schedule(static) if (o->n > AGG_PAR_MIN)
    for (int32_t c = 0; c < o->n; c++)
        r[c] = f[c] - r[c];
}

/* Chebyshev smoothing of degree AGG_DEGREE on [lmax/8, lmax] (u from zero
 * when `zero`): the same polynomial before and after, so the cycle is
 * symmetric. */
static void level_smooth(const agg_op *o, mg_alevel *L, int zero)
{
    double lmax = L->lmax, lmin = lmax / 8;
    double theta = 0.5 * (lmax + lmin), delta = 0.5 * (lmax - lmin);
    double sigma = theta / delta, rho_old = 1.0 / sigma;
    int32_t n = o->n;
    for (int s = 0; s < AGG_DEGREE; s++) {
        double cd = 0, cr = 1.0 / theta;
        if (s > 0) {
            double rho = 1.0 / (2 * sigma - rho_old);
            cd = rho * rho_old;
            cr = 2 * rho / delta;
            rho_old = rho;
        }
        if (s == 0 && zero) {
#pragma omp parallel for schedule(static) if (n > AGG_PAR_MIN)
            for (int32_t c = 0; c < n; c++)
                L->r[c] = L->f[c];
        } else {
            level_residual(o, L->f, L->u, L->r);
        }
#pragma omp parallel for schedule(static) if (n > AGG_PAR_MIN)
        for (int32_t c = 0; c < n; c++) {
            float d = (float)((s ? cd * L->d[c] : 0.0) + cr * o->dinv[c] * L->r[c]);
            L->d[c] = d;
            L->u[c] = (s == 0 && zero ? 0.0f : L->u[c]) + d;
        }
    }
}

/* f_{l+1} = P^T r = P0^T (r - wp A D^-1 r) from level l's residual r. */
/* y = M x (rows of M). */
static void csr_apply(const mg_csr *M, const float *x, float *y)
{
#pragma omp parallel for schedule(static) if (M->n > AGG_PAR_MIN)
    for (int32_t r = 0; r < M->n; r++)
        y[r] = csr_row_dot(M, r, x);
}

/* Coefficients of the y-, y+, z-, z+ faces of row R of fine level F: c_b, or 0
 * at the box's faces (where R's neighbour offset is 0, the row itself). */
static void fine_cyz(const mg_level *F, const mg_wrow *R, float c[4])
{
    const float cy = (float)F->c[1], cz = (float)F->c[2];
    c[0] = R->ym ? cy : 0;
    c[1] = R->yp ? cy : 0;
    c[2] = R->zm ? cz : 0;
    c[3] = R->zp ? cz : 0;
}

/* sum_b c_b sum_nb x_nb s_nb (s NULL: 1) over the faces of cell i of a binary
 * fine row that the box has: the row's first and last cells, which the
 * interior loops leave out. */
static float fine_nb_sum(const mg_wrow *R, const float c[4], float cx, int nx, const float *x,
                         const float *s, int i)
{
    const size_t q = R->base + (size_t)i;
    const ptrdiff_t o[4] = {R->ym, R->yp, R->zm, R->zp};
    float v = 0;
    if (i > 0)
        v += cx * x[q - 1] * (s ? s[q - 1] : 1.0f);
    if (i < nx - 1)
        v += cx * x[q + 1] * (s ? s[q + 1] : 1.0f);
    for (int e = 0; e < 4; e++)
        v += c[e] * x[q + o[e]] * (s ? s[q + o[e]] : 1.0f);
    return v;
}

/* Row (j,k) of v = r - wp A D^-1 r on a binary fine level, without forming
 * D^-1 r: A D^-1 r = D dinv r - sum c_b dinv_nb r_nb, where D dinv is 1 on
 * rows with dinv > 0 and 0 on empty ones (solid cells; for Poisson, fluid
 * cells without an open face); dinv is 0 on solid cells, which closes their
 * faces. Neither the cell weights nor D are read. */
static void restrict0_row(const mg_level *F, int dim, double wp, const float *r, float *v, int j,
                          int k)
{
    const mg_wrow R = mg_wrow_at(F, dim, j, k);
    float c[4];
    fine_cyz(F, &R, c);
    const int nx = F->n[0];
    const float cx = (float)F->c[0], w = (float)wp;
    const float *d0 = F->dinv + R.base, *r0 = r + R.base;
    float *vr = v + R.base;
    for (int i = 0; i<nx; i += nx> 1 ? nx - 1 : 1)
        vr[i] = r0[i] - (d0[i] > 0 ? w : 0) * (r0[i] - fine_nb_sum(&R, c, cx, nx, r, F->dinv, i));
    const float *dm = d0 + R.ym, *dp = d0 + R.yp, *dzm = d0 + R.zm, *dzp = d0 + R.zp;
    const float *rm = r0 + R.ym, *rp = r0 + R.yp, *rzm = r0 + R.zm, *rzp = r0 + R.zp;
#pragma omp simd
    for (int i = 1; i < nx - 1; i++) {
        float sn = cx * (d0[i - 1] * r0[i - 1] + d0[i + 1] * r0[i + 1]) + c[0] * dm[i] * rm[i] +
                   c[1] * dp[i] * rp[i] + c[2] * dzm[i] * rzm[i] + c[3] * dzp[i] * rzp[i];
        vr[i] = r0[i] - (d0[i] > 0 ? w : 0) * (r0[i] - sn);
    }
}

/* Row (j,k) of u += t - wp D^-1 A t on a binary fine level, t = P0 u_1 (0 on
 * solid cells): D^-1 A t = t - dinv sum c_b t_nb on rows with dinv > 0, 0 on
 * empty ones. */
static void prolong0_row(const mg_level *F, int dim, double wp, const float *t, float *u, int j,
                         int k)
{
    const mg_wrow R = mg_wrow_at(F, dim, j, k);
    float c[4];
    fine_cyz(F, &R, c);
    const int nx = F->n[0];
    const float cx = (float)F->c[0], w = (float)wp;
    const float *dv = F->dinv + R.base, *t0 = t + R.base;
    float *ur = u + R.base;
    for (int i = 0; i<nx; i += nx> 1 ? nx - 1 : 1)
        ur[i] +=
            t0[i] - (dv[i] > 0 ? w : 0) * (t0[i] - dv[i] * fine_nb_sum(&R, c, cx, nx, t, NULL, i));
    const float *tm = t0 + R.ym, *tp = t0 + R.yp, *tzm = t0 + R.zm, *tzp = t0 + R.zp;
#pragma omp simd
    for (int i = 1; i < nx - 1; i++) {
        float sn = cx * (t0[i - 1] + t0[i + 1]) + c[0] * tm[i] + c[1] * tp[i] + c[2] * tzm[i] +
                   c[3] * tzp[i];
        ur[i] += t0[i] - (dv[i] > 0 ? w : 0) * (t0[i] - dv[i] * sn);
    }
}

/* f_1 = P^T r on a binary fine level: v = r - wp A D^-1 r row by row (D^-1 r
 * never stored), then summed over each aggregate's members. */
static void restrict0_binary(mg_agg *g, const float *r)
{
    const mg_level *F = g->fine;
    mg_alevel *L = &g->lv[0], *C = &g->lv[1];
    const double wp = AGG_OMEGA / L->lmax;
#pragma omp parallel for collapse(2) schedule(static) if (F->count > AGG_PAR_MIN)
    for (int k = 0; k < F->n[2]; k++)
        for (int j = 0; j < F->n[1]; j++)
            restrict0_row(F, g->dim, wp, r, L->t, j, k);
#pragma omp parallel for schedule(static) if (C->n > AGG_PAR_MIN)
    for (int32_t I = 0; I < C->n; I++) {
        double s = 0;
        for (size_t q = L->mrp[I]; q < L->mrp[I + 1]; q++)
            s += L->t[L->mem[q]];
        C->f[I] = (float)s;
    }
}

/* u += P u_1 on a binary fine level: t = P0 u_1, then u += t - wp D^-1 A t
 * row by row. */
static void prolong0_binary(mg_agg *g, float *u)
{
    const mg_level *F = g->fine;
    mg_alevel *L = &g->lv[0], *C = &g->lv[1];
    const double wp = AGG_OMEGA / L->lmax;
#pragma omp parallel for schedule(static) if (L->n > AGG_PAR_MIN)
    for (int32_t c = 0; c < L->n; c++)
        L->t[c] = L->agg[c] >= 0 ? C->u[L->agg[c]] : 0.0f;
#pragma omp parallel for collapse(2) schedule(static) if (F->count > AGG_PAR_MIN)
    for (int k = 0; k < F->n[2]; k++)
        for (int j = 0; j < F->n[1]; j++)
            prolong0_row(F, g->dim, wp, L->t, u, j, k);
}

static void restrict_to(mg_agg *g, int l, const float *r)
{
    mg_alevel *L = &g->lv[l], *C = &g->lv[l + 1];
    if (L->R.rp) {
        csr_apply(&L->R, r, C->f);
        return;
    }
    if (l == 0 && g->fine->binary) {
        restrict0_binary(g, r);
        return;
    }
    agg_op o = level_op(g, l);
    double wp = AGG_OMEGA / L->lmax;
#pragma omp parallel for schedule(static) if (o.n > AGG_PAR_MIN)
    for (int32_t c = 0; c < o.n; c++)
        L->t[c] = o.dinv[c] * r[c];
    op_apply(&o, L->t, L->s);
#pragma omp parallel for schedule(static) if (C->n > AGG_PAR_MIN)
    for (int32_t I = 0; I < C->n; I++) {
        double s = 0;
        for (size_t q = L->mrp[I]; q < L->mrp[I + 1]; q++) {
            int32_t c = L->mem[q];
            s += r[c] - wp * L->s[c];
        }
        C->f[I] = (float)s;
    }
}

/* u_l += P u_{l+1} = v - wp D^-1 A v with v = P0 u_{l+1}. */
static void prolong_add(mg_agg *g, int l, float *u)
{
    mg_alevel *L = &g->lv[l], *C = &g->lv[l + 1];
    if (l == 0 && g->fine->binary) {
        prolong0_binary(g, u);
        return;
    }
    if (L->P.rp) {
        csr_apply(&L->P, C->u, L->t);
#pragma omp parallel for schedule(static) if (L->n > AGG_PAR_MIN)
        for (int32_t c = 0; c < L->n; c++)
            u[c] += L->t[c];
        return;
    }
    agg_op o = level_op(g, l);
    double wp = AGG_OMEGA / L->lmax;
#pragma omp parallel for schedule(static) if (o.n > AGG_PAR_MIN)
    for (int32_t c = 0; c < o.n; c++)
        L->t[c] = L->agg[c] >= 0 ? C->u[L->agg[c]] : 0.0f;
    op_apply(&o, L->t, L->s);
#pragma omp parallel for schedule(static) if (o.n > AGG_PAR_MIN)
    for (int32_t c = 0; c < o.n; c++)
        u[c] += (float)(L->t[c] - wp * o.dinv[c] * L->s[c]);
}

/* One symmetric V-cycle from zero on level l >= 1 for lv[l].f into lv[l].u. */
static void cycle(mg_agg *g, int l)
{
    mg_alevel *L = &g->lv[l];
    if (l == g->nlev - 1) {
        bottom_solve(g, L->f, L->u);
        return;
    }
    agg_op o = level_op(g, l);
    level_smooth(&o, L, 1);
    level_residual(&o, L->f, L->u, L->r);
    restrict_to(g, l, L->r);
    cycle(g, l + 1);
    prolong_add(g, l, L->u);
    level_smooth(&o, L, 0);
}

void hv__mg_agg_bottom(mg_agg *g, const float *f, float *u) { bottom_solve(g, f, u); }

void hv__mg_agg_correct(mg_agg *g, const float *r, float *u)
{
    restrict_to(g, 0, r);
    cycle(g, 1);
    prolong_add(g, 0, u);
}

/* ---------- building and freeing ---------- */

static size_t bytes_saved(size_t before, size_t after)
{
    return before > after ? before - after : 0;
}

/* M's columns as 16-bit offsets from each row's smallest where every row
 * spans fewer than 65536 (mg_csr); returns the bytes saved. */
static size_t csr_pack(mg_csr *M)
{
    if (!M->rp || !M->ci)
        return 0;
    const size_t nnz = M->rp[M->n];
    int32_t *cb = malloc(((size_t)M->n + 1) * sizeof *cb);
    uint16_t *co = malloc((nnz + MG_CSR_PAD) * sizeof *co);
    if (!cb || !co) {
        free(cb);
        free(co);
        return 0;
    }
    int fits = 1; /* each thread's copy starts at 1 too */
#pragma omp parallel for schedule(static) reduction(&& : fits) if (M->n > AGG_PAR_MIN)
    for (int32_t r = 0; r < M->n; r++) {
        if (!fits)
            continue;
        int32_t lo = INT32_MAX, hi = INT32_MIN;
        for (size_t q = M->rp[r]; q < M->rp[r + 1]; q++) {
            lo = M->ci[q] < lo ? M->ci[q] : lo;
            hi = M->ci[q] > hi ? M->ci[q] : hi;
        }
        if (lo > hi)
            lo = hi = 0;
        if ((int64_t)hi - lo > UINT16_MAX) {
            fits = 0;
            continue;
        }
        cb[r] = lo;
        for (size_t q = M->rp[r]; q < M->rp[r + 1]; q++)
            co[q] = (uint16_t)(M->ci[q] - lo);
    }
    if (!fits) {
        free(cb);
        free(co);
        return 0;
    }
    memset(co + nnz, 0, MG_CSR_PAD * sizeof *co);
    free(M->ci);
    M->ci = NULL;
    M->cb = cb;
    M->co = co;
    return bytes_saved(nnz * sizeof(int32_t),
                       (nnz + MG_CSR_PAD) * sizeof(uint16_t) + (size_t)M->n * sizeof(int32_t));
}

#define CLS_MIN 32    /* rows that a row class needs to become a template */
#define CLS_MAX 65000 /* row classes at most (cls is 16-bit) */
#define CLS_RUN 8     /* consecutive rows of a class that it serves at least */
#define CLS_WIDTH 512 /* entries of a class at most */

/* Hash of row c's entries, columns relative to c. */
static uint64_t row_hash(const mg_csr *A, int32_t c)
{
    uint64_t h = 1469598103934665603ull ^ (uint64_t)(A->rp[c + 1] - A->rp[c]);
    for (size_t q = A->rp[c]; q < A->rp[c + 1]; q++) {
        uint32_t bits;
        memcpy(&bits, &A->v[q], sizeof bits);
        h = (h ^ (uint32_t)(A->ci[q] - c)) * 1099511628211ull;
        h = (h ^ bits) * 1099511628211ull;
    }
    return h ^ (h >> 29);
}

/* Rows a and b hold the same entries (bit for bit) at the same offsets. */
static int rows_equal(const mg_csr *A, int32_t a, int32_t b)
{
    size_t qa = A->rp[a], qb = A->rp[b], len = A->rp[a + 1] - qa;
    if (A->rp[b + 1] - qb != len)
        return 0;
    for (size_t e = 0; e < len; e++)
        if (A->ci[qa + e] - a != A->ci[qb + e] - b)
            return 0;
    return memcmp(A->v + qa, A->v + qb, len * sizeof *A->v) == 0;
}

/* The slot of row c's class in an open-addressing table of rows (rep, key;
 * mask + 1 slots), claimed for c where the class is new. */
static size_t class_slot(const mg_csr *A, int32_t c, int32_t *rep, uint64_t *key, size_t mask)
{
    const uint64_t h = row_hash(A, c);
    size_t s = (size_t)h & mask;
    while (rep[s] >= 0 && !(key[s] == h && rows_equal(A, rep[s], c)))
        s = (s + 1) & mask;
    if (rep[s] < 0) {
        rep[s] = c;
        key[s] = h;
    }
    return s;
}

/* A without the rows that a class serves (cls[r] != 0): their ranges empty. */
static int csr_drop_rows(mg_csr *A, const uint16_t *cls)
{
    size_t kept = 0;
    for (int32_t r = 0; r < A->n; r++)
        kept += cls[r] ? 0 : A->rp[r + 1] - A->rp[r];
    int32_t *ci = malloc((kept ? kept : 1) * sizeof *ci);
    float *v = malloc((kept ? kept : 1) * sizeof *v);
    if (!ci || !v) {
        free(ci);
        free(v);
        return -1;
    }
    size_t at = 0, from = A->rp[0];
    for (int32_t r = 0; r < A->n; r++) {
        const size_t b = from, e = A->rp[r + 1];
        from = e;
        A->rp[r] = at;
        if (cls[r])
            continue;
        memcpy(ci + at, A->ci + b, (e - b) * sizeof *ci);
        memcpy(v + at, A->v + b, (e - b) * sizeof *v);
        at += e - b;
    }
    A->rp[A->n] = at;
    free(A->ci);
    free(A->v);
    A->ci = ci;
    A->v = v;
    return 0;
}

/* Emits the open group of class k (fill rows, padded with its last row). */
static void group_emit(mg_alevel *L, int32_t *open, int *fill, int k)
{
    int32_t *g = L->grow + (size_t)MG_GROUP * L->ngrp;
    for (int i = 0; i < MG_GROUP; i++)
        g[i] = open[(size_t)MG_GROUP * k + (i < fill[k] ? i : fill[k] - 1)];
    L->gcls[L->ngrp++] = k;
    fill[k] = 0;
}

/* The rows of classes in runs along x shorter than CLS_RUN (a stencil over
 * a few lanes costs more than their sparse rows) into groups of MG_GROUP rows
 * of one class (mg_alevel's grow), marked MG_CLS_GROUP in cls: the rows
 * beside walls across x, each of its own class but for its neighbours along
 * y and z. -1 where memory is short. */
static int class_groups(mg_alevel *L, uint16_t *cls, int ncls)
{
    size_t nshort = 0;
    for (int32_t c = 0; c < L->n;) {
        int32_t e = c + 1;
        while (e < L->n && cls[e] == cls[c])
            e++;
        nshort += cls[c] > 1 && e - c < CLS_RUN ? (size_t)(e - c) : 0;
        c = e;
    }
    const size_t maxg = nshort / MG_GROUP + (size_t)ncls;
    int32_t *open = malloc((size_t)ncls * MG_GROUP * sizeof *open);
    int *fill = calloc((size_t)ncls, sizeof *fill);
    L->grow = malloc((maxg ? maxg : 1) * MG_GROUP * sizeof *L->grow);
    L->gcls = malloc((maxg ? maxg : 1) * sizeof *L->gcls);
    L->ngrp = 0;
    if (!open || !fill || !L->grow || !L->gcls) {
        free(open);
        free(fill);
        return -1;
    }
    for (int32_t c = 0; c < L->n;) {
        int32_t e = c + 1;
        while (e < L->n && cls[e] == cls[c])
            e++;
        for (int32_t r = c; cls[c] > 1 && e - c < CLS_RUN && r < e; r++) {
            const int k = cls[r] - 2;
            open[(size_t)MG_GROUP * k + fill[k]++] = r;
            if (fill[k] == MG_GROUP)
                group_emit(L, open, fill, k);
        }
        if (cls[c] > 1 && e - c < CLS_RUN)
            for (int32_t r = c; r < e; r++)
                cls[r] = MG_CLS_GROUP;
        c = e;
    }
    for (int k = 0; k < ncls; k++)
        if (fill[k])
            group_emit(L, open, fill, k);
    free(open);
    free(fill);
    return 0;
}

/* Row classes of a level with a template (mg_alevel's cls): the stored rows
 * grouped by their entries relative to the row, each group of CLS_MIN rows
 * or more a template of its own. Returns the bytes saved (0 where it finds
 * none or memory is short). */
static size_t row_classes(mg_alevel *L)
{
    const mg_csr *A = &L->A;
    if (!A->ci)
        return 0;
    const uint8_t *plain = L->plain;
    size_t nstored = 0, slots = 64;
    for (int32_t c = 0; c < L->n; c++)
        nstored += !(plain && plain[c]) && A->rp[c + 1] > A->rp[c];
    while (slots < 2 * nstored)
        slots *= 2;
    int32_t *rep = malloc(slots * sizeof *rep), *slot_of = malloc((size_t)L->n * sizeof *slot_of);
    int32_t *cnt = calloc(slots, sizeof *cnt);
    uint64_t *key = malloc(slots * sizeof *key);
    uint16_t *cls = calloc((size_t)L->n, sizeof *cls);
    size_t saved = 0;
    if (!rep || !slot_of || !cnt || !key || !cls)
        goto done;
    for (size_t s = 0; s < slots; s++)
        rep[s] = -1;
    for (int32_t c = 0; c < L->n; c++) {
        size_t len = A->rp[c + 1] - A->rp[c];
        slot_of[c] = -1;
        if ((plain && plain[c]) || len == 0 || len > CLS_WIDTH)
            continue;
        slot_of[c] = (int32_t)class_slot(A, c, rep, key, slots - 1);
        cnt[slot_of[c]]++;
    }
    /* cnt becomes each slot's class (-1: none), in the order of the table */
    int ncls = 0;
    for (size_t s = 0; s < slots; s++)
        cnt[s] = cnt[s] >= CLS_MIN && ncls < CLS_MAX ? ncls++ : -1;
    if (!ncls)
        goto done;
    L->cn = malloc((size_t)ncls * sizeof *L->cn);
    L->cw = 1;
    for (size_t s = 0; s < slots; s++)
        if (cnt[s] >= 0 && A->rp[rep[s] + 1] - A->rp[rep[s]] > (size_t)L->cw)
            L->cw = (int)(A->rp[rep[s] + 1] - A->rp[rep[s]]);
    L->coff = malloc((size_t)ncls * L->cw * sizeof *L->coff);
    L->cval = malloc((size_t)ncls * L->cw * sizeof *L->cval);
    if (!L->cn || !L->coff || !L->cval)
        goto fail;
    for (size_t s = 0; s < slots; s++) {
        if (cnt[s] < 0)
            continue;
        const int k = cnt[s];
        const int32_t r = rep[s];
        L->cn[k] = (int)(A->rp[r + 1] - A->rp[r]);
        for (int e = 0; e < L->cn[k]; e++) {
            L->coff[(size_t)k * L->cw + e] = A->ci[A->rp[r] + e] - r;
            L->cval[(size_t)k * L->cw + e] = A->v[A->rp[r] + e];
        }
    }
    size_t before = A->rp[L->n];
    for (int32_t c = 0; c < L->n; c++)
        cls[c] = plain && plain[c]                         ? 1
                 : slot_of[c] >= 0 && cnt[slot_of[c]] >= 0 ? 2 + cnt[slot_of[c]]
                                                           : 0;
    if (class_groups(L, cls, ncls) || csr_drop_rows(&L->A, cls))
        goto fail;
    L->cls = cls;
    L->ncls = ncls;
    cls = NULL;
    saved = bytes_saved((before - L->A.rp[L->n]) * (sizeof(int32_t) + sizeof(float)),
                        (size_t)L->n * sizeof *L->cls +
                            (size_t)ncls *
                                ((size_t)L->cw * (sizeof(int32_t) + sizeof(float)) + sizeof(int)) +
                            (size_t)L->ngrp * (MG_GROUP + 1) * sizeof(int32_t));
    goto done;
fail:
    free(L->cn);
    free(L->coff);
    free(L->cval);
    free(L->grow);
    free(L->gcls);
    L->cn = NULL;
    L->coff = NULL;
    L->cval = NULL;
    L->grow = NULL;
    L->gcls = NULL;
    L->ngrp = 0;
done:
    free(rep);
    free(slot_of);
    free(cnt);
    free(key);
    free(cls);
    return saved;
}

void hv__mg_agg_pack(mg_agg *g)
{
    for (int l = 1; l < g->nlev; l++) {
        mg_alevel *L = &g->lv[l];
        size_t saved = row_classes(L);
        saved += csr_pack(&L->A) + csr_pack(&L->P) + csr_pack(&L->R);
        g->bytes -= saved < g->bytes ? saved : 0;
    }
}

static hv_status level_work(mg_agg *g, int l)
{
    mg_alevel *L = &g->lv[l];
    size_t n = (size_t)L->n + 1;
    if (l > 0) {
        L->dinv = malloc(n * sizeof(float));
        L->u = calloc(n, sizeof(float));
        L->f = calloc(n, sizeof(float));
        L->r = calloc(n, sizeof(float));
        L->d = calloc(n, sizeof(float));
        if (!L->dinv || !L->u || !L->f || !L->r || !L->d)
            return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for level %d", l);
        for (int32_t c = 0; c < L->n; c++) {
            int32_t bc[ROW_MAX];
            float bv[ROW_MAX];
            const int32_t *col;
            const float *val;
            int k = level_row(L, c, bc, bv, &col, &val);
            double d = 0;
            for (int q = 0; q < k; q++)
                if (col[q] == c)
                    d += val[q];
            L->dinv[c] = d > 0 ? (float)(1.0 / d) : 0.0f;
        }
        g->bytes += 5 * n * sizeof(float) + 3 * n * sizeof(int32_t) + n * sizeof(size_t) +
                    L->A.rp[L->n] * (sizeof(int32_t) + sizeof(float));
    }
    L->t = calloc(n, sizeof(float));
    L->s = calloc(n, sizeof(float));
    if (!L->t || !L->s)
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for level %d", l);
    g->bytes += 2 * n * sizeof(float);
    return HV_OK;
}

void hv__mg_agg_keep_bottom(mg_agg *g)
{
    for (int l = 0; l < MG_AGG_MAX_LEVELS; l++) {
        mg_alevel *L = &g->lv[l];
        void *all[] = {L->dinv, L->agg, L->mrp, L->mem, L->xyz, L->u, L->f, L->r, L->d, L->t, L->s};
        for (size_t i = 0; i < sizeof all / sizeof all[0]; i++)
            free(all[i]);
        csr_free(&L->A);
        csr_free(&L->P);
        csr_free(&L->R);
        free(L->plain);
        free(L->cls);
        free(L->cn);
        free(L->coff);
        free(L->cval);
        free(L->grow);
        free(L->gcls);
        int32_t n = L->n;
        memset(L, 0, sizeof *L);
        L->n = n;
    }
    free(g->faces);
    g->faces = NULL;
    g->fine = NULL;
}

void hv__mg_agg_free(mg_agg *g)
{
    if (!g)
        return;
    for (int l = 0; l < MG_AGG_MAX_LEVELS; l++) {
        mg_alevel *L = &g->lv[l];
        csr_free(&L->A);
        csr_free(&L->P);
        csr_free(&L->R);
        free(L->plain);
        free(L->cls);
        free(L->cn);
        free(L->coff);
        free(L->cval);
        free(L->grow);
        free(L->gcls);
        free(L->dinv);
        free(L->agg);
        free(L->mrp);
        free(L->mem);
        free(L->xyz);
        free(L->u);
        free(L->f);
        free(L->r);
        free(L->d);
        free(L->t);
        free(L->s);
    }
    free(g->faces);
    free(g->chol);
    free(g->region);
    free(g->bx);
    free(g);
}

/* The open faces of each fine cell, for op_row without index arithmetic
 * (binary levels only: their open faces all weigh one). */
static hv_status fine_faces(mg_agg *g)
{
    const mg_level *L = g->fine;
    if (!L->binary)
        return HV_OK;
    if (!(g->faces = malloc(L->count)))
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for the fine level's faces");
#pragma omp parallel for collapse(2) schedule(static) if (L->count > AGG_PAR_MIN)
    for (int k = 0; k < L->n[2]; k++)
        for (int j = 0; j < L->n[1]; j++)
            for (int i = 0; i < L->n[0]; i++) {
                unsigned f = 0;
                for (int b = 0; b < g->dim; b++)
                    for (int hi = 0; hi < 2; hi++) {
                        int x[3] = {i, j, k};
                        x[b] += hi;
                        if (x[b] > 0 && x[b] < L->n[b] &&
                            L->w[b][mg_face_index(L, b, x[0], x[1], x[2])] != 0.0f)
                            f |= 1u << (2 * b + hi);
                    }
                g->faces[(size_t)i + L->sy * j + L->sz * k] = (uint8_t)f;
            }
    g->bytes += L->count;
    return HV_OK;
}

hv_status hv__mg_agg_build(mg_agg **out, const mg_level *F, int dim, double alpha)
{
    *out = NULL;
    if (F->plain || !F->dinv || F->count >= (size_t)INT32_MAX)
        return HV_OK;
    mg_agg *g = calloc(1, sizeof *g);
    if (!g)
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory");
    g->dim = dim;
    g->alpha = alpha;
    g->fine = F;
    g->lv[0].n = (int32_t)F->count;
    for (int b = 0; b < 3; b++)
        g->lv[0].ext[b] = F->n[b];
    hv_status st = fine_faces(g);
    if (st)
        goto fail;
    int l = 0;
    for (;; l++) {
        mg_alevel *L = &g->lv[l];
        if ((st = level_work(g, l)))
            goto fail;
        agg_op o = level_op(g, l);
        /* The fine level's bound is Gershgorin's (its rows are diagonally
         * dominant); the coarse levels' by power iteration. */
        L->lmax = l == 0 ? 2.0 : op_lmax(&o, L->t, L->s);
        if (L->n <= AGG_BOTTOM || l + 1 == MG_AGG_MAX_LEVELS)
            break;
        if ((st = aggregate(g, l)))
            goto fail;
        if ((double)L->nagg > 0.8 * L->live) {
            if (L->n > AGG_STALL || l == 0)
                goto none; /* not coarsening: keep the geometric levels */
            free(L->agg);
            free(L->mrp);
            free(L->mem);
            L->agg = NULL;
            L->mrp = NULL;
            L->mem = NULL;
            break;
        }
        g->bytes += (size_t)L->n * 2 * sizeof(int32_t) + (size_t)g->lv[l + 1].n * sizeof(size_t);
        if ((st = l == 0 ? galerkin0(g, AGG_OMEGA / L->lmax)
                         : galerkin_csr(g, l, AGG_OMEGA / L->lmax)))
            goto fail;
    }
    g->nlev = l + 1;
    if (g->nlev < 2)
        goto none;
    if ((st = bottom_factor(g)))
        goto fail;
    g->bytes += (size_t)g->nb * g->nb * sizeof(double);
    *out = g;
    return HV_OK;
none:
    hv__mg_agg_free(g);
    return HV_OK;
fail:
    hv__mg_agg_free(g);
    return st;
}
