/*
 * The CPU multigrid's grid transfers (docs/METHOD.md, "Multigrid"): the
 * mean-of-children restriction, cell-centred (bi/tri)linear prolongation with
 * its renormalization on weighted coarse levels (rows in AVX-512 and in AVX2
 * and baseline clones), and the PCG preconditioner's symmetric restriction
 * P^T with its weight sums (hv__mg_restrict_transpose, hv__mg_prolong_norm, declared
 * in mg_level.h for the OpenCL backend and the tests).
 */
#include "mg_internal.h"

#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

/* f_C = mean of the children of r_F (children beyond an odd edge count as 0). */
void hv__mg_restrict_field(const mg_state *m, const mg_level *F, const float *src, mg_level *C)
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
 * cell (i,j,k): the renormalization of hv__mg_prolong_add on weighted coarse levels. */
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

void hv__mg_prolong_norm(const mg_level *F, const mg_level *C, float *pn)
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
/* Fine row (j,k) of P^T (pn .* r) along x into xl (ncx coarse cells); g: nfx
 * floats of work. Coarse I takes 3/4 of fine 2I and 2I+1, 1/4 of 2I-1 and
 * 2I+2; a fine cell at a wall gives all its weight to I. */
static void restrict_t_row(const mg_level *F, const mg_level *C, const float *pn, const float *r,
                           int j, int k, float *g, float *xl)
{
    const int nfx = F->n[0], ncx = C->n[0];
    const size_t fb = F->sy * (size_t)j + F->sz * (size_t)k;
    const float *rr = r + fb;
    if (pn) {
        const float *pr = pn + fb;
        for (int i = 0; i < nfx; i++)
            g[i] = pr[i] * rr[i];
    } else {
        memcpy(g, rr, (size_t)nfx * sizeof(float));
    }
    if (!F->coarsen[0]) {
        memcpy(xl, g, (size_t)ncx * sizeof(float));
        return;
    }
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
}

/* Coarse plane K from its accumulated sums: scaled, 0 on empty coarse cells. */
static void restrict_t_flush(const mg_level *C, const float *acc, int K, float scale,
                             float *fcoarse)
{
    const int ncx = C->n[0];
    for (int J = 0; J < C->n[1]; J++) {
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

/* f_C = P^T r_F / 2^d: the restriction that makes the V-cycle a symmetric
 * operator, for use as a CG preconditioner (mean-of-children restriction is not
 * proportional to P^T, and CG then loses conjugacy: measured, Poisson in long
 * corridors stalled near 3e-2). Coarse cell I takes fine cells 2I-1 .. 2I+2
 * along each coarsened axis, weighted as prolong_axis weights them.
 *
 * Separable: P's weights are products of one weight per axis, so P^T is
 * applied along x to each fine row, then scattered along y and z into the
 * coarse planes (the transpose of prolong_axis, axis by axis). Each thread
 * owns coarse planes [K0,K1) and reads its fine planes once, in order, into
 * two accumulating coarse planes (a fine plane reaches at most two); a plane
 * is written out once its last fine plane is in. */
void hv__mg_restrict_transpose(const mg_level *F, const mg_level *C, int dim, const float *pn,
                               const float *r, float *fcoarse, float *work, int nthreads)
{
    const int *co = F->coarsen;
    int nchild = 1;
    for (int b = 0; b < dim; b++)
        nchild *= co[b] ? 2 : 1;
    const float scale = 1.0f / (float)nchild;
    const int nfy = F->n[1], nfz = F->n[2], ncx = C->n[0], ncy = C->n[1], ncz = C->n[2];
    const size_t plane = (size_t)ncx * ncy;
    int nt = 1;
#ifdef _OPENMP
    if (F->count > MG_PAR_MIN)
        nt = omp_get_max_threads() < nthreads ? omp_get_max_threads() : nthreads;
    if (nt > ncz)
        nt = ncz;
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
        float *xl = g + F->n[0], *acc = xl + ncx;
        const int K0 = (int)((int64_t)ncz * t / nt), K1 = (int)((int64_t)ncz * (t + 1) / nt);
        int owner[2] = {-1, -1}; /* the coarse plane in each accumulator */
        const int kfirst = co[2] ? (2 * K0 - 1 < 0 ? 0 : 2 * K0 - 1) : K0;
        const int klast = co[2] ? (2 * K1 > nfz - 1 ? nfz - 1 : 2 * K1) : K1 - 1;
        for (int k = kfirst; K0 < K1 && k <= klast; k++) {
            int nT = 0, K, Kb;
            float wk1, wk[2];
            float *ak[2];
            prolong_axis(co[2], ncz, k, &K, &Kb, &wk1);
            for (int q = 0; q < 2; q++) {
                const int Kq = q ? Kb : K;
                if ((q && Kb == K) || Kq < K0 || Kq >= K1)
                    continue;
                ak[nT] = acc + plane * (size_t)(Kq & 1);
                if (owner[Kq & 1] != Kq) {
                    memset(ak[nT], 0, plane * sizeof(float));
                    owner[Kq & 1] = Kq;
                }
                wk[nT] = prolong_axis_weight(co[2], ncz, k, Kq);
                nT += wk[nT] != 0;
            }
            for (int j = 0; nT > 0 && j < nfy; j++) {
                restrict_t_row(F, C, pn, r, j, k, g, xl);
                int J0, J1;
                float wj1;
                prolong_axis(co[1], ncy, j, &J0, &J1, &wj1);
                for (int q = 0; q < nT; q++) {
                    float *a0 = ak[q] + (size_t)ncx * J0, *a1 = ak[q] + (size_t)ncx * J1;
                    const float w0 = wk[q] * (1.0f - wj1), w1 = wk[q] * wj1;
                    for (int I = 0; I < ncx; I++)
                        a0[I] += w0 * xl[I];
                    if (w1 != 0)
                        for (int I = 0; I < ncx; I++)
                            a1[I] += w1 * xl[I];
                }
            }
            /* planes whose last fine plane was k */
            for (int q = 0; q < 2; q++) {
                const int Kq = owner[q];
                const int last = co[2] ? (2 * Kq + 2 > nfz - 1 ? nfz - 1 : 2 * Kq + 2) : Kq;
                if (Kq >= 0 && (last <= k || k == klast)) {
                    restrict_t_flush(C, acc + plane * (size_t)q, Kq, scale, fcoarse);
                    owner[q] = -1;
                }
            }
        }
    }
}

#if MG_AVX512
/* Fine row uf (nf cells) += P u_C (= P u_C when `set`) with x coarsened: the
 * coarse line a00 r00 + a01 r01 + a10 r10 + a11 r11 (the y and z weights) is
 * formed in registers, 16 coarse cells at a time; fine cell 2I takes 3/4
 * line[I] + 1/4 line[I-1], 2I+1 takes 3/4 line[I] + 1/4 line[I+1] (line[I]
 * alone at the walls), their neighbours come by lane shifts of the chunks
 * beside, and the two results are interleaved by permutes so that the fine
 * row is read and written in whole vectors. */
__attribute__((target("avx512f"))) static void prolong_row_avx512(
    float *uf, int nf, const float *r00, const float *r01, const float *r10, const float *r11,
    float a00, float a01, float a10, float a11, int nc, int set)
{
    const __m512 q3 = _mm512_set1_ps(0.75f), q1 = _mm512_set1_ps(0.25f);
    const __m512 w00 = _mm512_set1_ps(a00), w01 = _mm512_set1_ps(a01), w10 = _mm512_set1_ps(a10),
                 w11 = _mm512_set1_ps(a11);
    const __m512i lo = _mm512_set_epi32(23, 7, 22, 6, 21, 5, 20, 4, 19, 3, 18, 2, 17, 1, 16, 0);
    const __m512i hi =
        _mm512_set_epi32(31, 15, 30, 14, 29, 13, 28, 12, 27, 11, 26, 10, 25, 9, 24, 8);
    const int nq = (nc + 15) / 16;
#define PROLONG_LINE(I_, M_)                                                                       \
    _mm512_castps_si512(_mm512_fmadd_ps(                                                           \
        w11, _mm512_maskz_loadu_ps(M_, r11 + (I_)),                                                \
        _mm512_fmadd_ps(                                                                           \
            w10, _mm512_maskz_loadu_ps(M_, r10 + (I_)),                                            \
            _mm512_fmadd_ps(w01, _mm512_maskz_loadu_ps(M_, r01 + (I_)),                            \
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
#endif

/* Row (j,k) of u_F += P u_C from a plain coarse level: blend the (up to) four
 * coarse rows in y and z into one line (C->n[0] floats of work), then
 * interpolate along x: 4 + 2 flops per fine cell instead of 8 products. */
MG_KERNEL void hv__mg_prolong_row_plain(mg_level *F, const mg_level *C, int j, int k, float *line,
                                        int set)
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
    float line[3 * MG_ROW_BUF], lw[MG_ROW_BUF];
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
     * all of I where that neighbour is beyond a wall. The corrections at fine
     * resolution first (even and odd cells of each I, without branches inside),
     * then added where the fine cell is not empty. */
    float *vf = line + MG_ROW_BUF; /* 2 nc cells: nf, and one beyond when nf is odd */
    for (int I = 0; I < nc; I++) {
        const int lo = I > 0 ? I - 1 : I, hi = I + 1 < nc ? I + 1 : I;
        const float se = I > 0 ? 0.75f * line[I] + 0.25f * line[lo] : line[I];
        const float we = I > 0 ? 0.75f * lw[I] + 0.25f * lw[lo] : lw[I];
        const float so = I + 1 < nc ? 0.75f * line[I] + 0.25f * line[hi] : line[I];
        const float wo = I + 1 < nc ? 0.75f * lw[I] + 0.25f * lw[hi] : lw[I];
        vf[2 * I] = we > 0 ? se / (we > 0 ? we : 1.0f) : 0.0f;
        vf[2 * I + 1] = wo > 0 ? so / (wo > 0 ? wo : 1.0f) : 0.0f;
    }
    for (int i = 0; i < nf; i++)
        uf[i] += (!af || af[i] != 0.0f) ? vf[i] : 0.0f;
}

/* u_F += P u_C: cell-centred (bi/tri)linear interpolation. On weighted coarse
 * levels empty coarse cells are left out and the weights renormalized. */
void hv__mg_prolong_add(const mg_state *m, mg_level *F, const mg_level *C, int set)
{
    const int *co = F->coarsen;
    const float *uc = C->u;
    if (C->n[0] <= MG_ROW_BUF && C->plain) {
#pragma omp parallel for collapse(2) schedule(static) if (F->count > MG_PAR_MIN)
        for (int k = 0; k < F->n[2]; k++)
            for (int j = 0; j < F->n[1]; j++) {
                float line[MG_ROW_BUF];
                hv__mg_prolong_row_plain(F, C, j, k, line, set);
            }
        return;
    }
    if (set)
        mg_zero_f(F->u, F->count);
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
