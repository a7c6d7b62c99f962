/* Smoothed aggregation (agg_internal.h): a level's operator: its rows, its product
 * (the fine level's stencil, templates, sparse rows) and its spectral bound. */
#include "agg_internal.h"

int hv__agg_level_row(const mg_alevel *L, int32_t c, int32_t *bc, float *bv, const int32_t **col,
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

int hv__agg_op_row(const agg_op *o, int32_t c, int32_t *bc, float *bv, const int32_t **col,
                   const float **val)
{
    if (!o->F)
        return hv__agg_level_row(o->lv, c, bc, bv, col, val);
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

void hv__agg_op_apply(const agg_op *o, const float *x, float *y)
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
double hv__agg_op_lmax(const agg_op *o, float *x, float *y)
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
        hv__agg_op_apply(o, x, y);
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

void hv__agg_csr_apply(const mg_csr *M, const float *x, float *y)
{
#pragma omp parallel for schedule(static) if (M->n > AGG_PAR_MIN)
    for (int32_t r = 0; r < M->n; r++)
        y[r] = csr_row_dot(M, r, x);
}
