/*
 * The CPU multigrid's smoother and residual rows (docs/METHOD.md, "Multigrid"):
 * red-black Gauss-Seidel rows of plain levels in AVX-512 (chosen at run time,
 * mg_avx512) and in AVX2 and baseline clones (MG_KERNEL), the rows of weighted
 * levels, and the level-wide sweeps made of them: a red-black colour sweep,
 * the float residual and the Jacobi / Chebyshev update.
 */
#include "mg_internal.h"

#include <stdlib.h>
#include <string.h>

#if MG_AVX512
/* One colour (cells of parity i0) of a plain row of nx cells, walls included,
 * in 16-lane chunks aligned to the row start: the row's own values come from
 * one load per chunk, their x-neighbours by lane shifts (valignd) of the chunks
 * before and after, instead of two unaligned loads that straddle cache lines;
 * a wall cell's missing x-neighbour is a zero lane and its lane takes its own
 * diagonal (dyz + cx, or dyz alone when nx = 1). Every lane is computed and a
 * masked store keeps this colour's cells, so the other colour's (which this
 * row reads) are never written. The neighbour rows are read under the colour
 * mask: their cells of the other parity belong to the colour that other
 * threads are writing in this sweep, and a masked-off lane is not read (a
 * full load would be a data race, harmless on the hardware but undefined in
 * C11's memory model and reported by ThreadSanitizer). cym..czp are the face
 * coefficients, 0 at a y or z wall; dyz = alpha + the open y and z faces.
 * With dinv (a binary level's row: solid cells hold u = 0, so the plain
 * stencil serves once each cell takes its own inverse diagonal) the lanes
 * take dinv instead, 0 on solid cells, and dyz is unused. */
__attribute__((target("avx512f"))) static void rb_row_avx512(float *ur, const float *fr,
                                                             const float *ym, const float *yp,
                                                             const float *zm, const float *zp,
                                                             int nx, int i0, float cx, float cym,
                                                             float cyp, float czm, float czp,
                                                             float dyz, const float *dinv)
{
    const __m512 vcx = _mm512_set1_ps(cx), vcym = _mm512_set1_ps(cym), vcyp = _mm512_set1_ps(cyp),
                 vczm = _mm512_set1_ps(czm), vczp = _mm512_set1_ps(czp),
                 vinv = _mm512_set1_ps(1.0f / (dyz + 2 * cx));
    const float wall = dyz + cx, inv_wall = wall > 0 ? 1.0f / wall : 0.0f;
    const float inv_one = dyz > 0 ? 1.0f / dyz : 0.0f;
    const __mmask16 colour = i0 ? 0xAAAA : 0x5555; /* lane b is cell q + b, q even */
    const int last = nx - 1;
    mg_x16 X = mg_x16_start(ur, nx);
    for (int c = 0, q = 0; c < X.nq; c++, q += 16) {
        __m512 uc, um, up;
        const __mmask16 valid = mg_x16_next(&X, c, &uc, &um, &up);
        const __mmask16 own = colour & valid;
        __m512 sm = _mm512_fmadd_ps(vcx, _mm512_add_ps(um, up), _mm512_maskz_loadu_ps(own, fr + q));
        sm = _mm512_fmadd_ps(vcym, _mm512_maskz_loadu_ps(own, ym + q), sm);
        sm = _mm512_fmadd_ps(vcyp, _mm512_maskz_loadu_ps(own, yp + q), sm);
        sm = _mm512_fmadd_ps(vczm, _mm512_maskz_loadu_ps(own, zm + q), sm);
        sm = _mm512_fmadd_ps(vczp, _mm512_maskz_loadu_ps(own, zp + q), sm);
        __m512 inv = vinv;
        if (dinv)
            inv = _mm512_maskz_loadu_ps(own, dinv + q);
        else if (c == 0)
            inv = _mm512_mask_mov_ps(inv, 1, _mm512_set1_ps(nx > 1 ? inv_wall : inv_one));
        if (!dinv && c + 1 == X.nq && last > 0)
            inv = _mm512_mask_mov_ps(inv, (__mmask16)(1u << (last - q)), _mm512_set1_ps(inv_wall));
        _mm512_mask_storeu_ps(ur + q, own, _mm512_mul_ps(sm, inv));
    }
}
#endif

/* Plain-level interior row update: the hot loop of the smoother, branch-free. */
MG_KERNEL void hv__mg_rb_row_plain(const mg_state *m, const mg_level *L, float *u, const float *f,
                                   int j, int k, int col)
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
        rb_row_avx512(ur, fr, ym, yp, zm, zp, nx, i0, cx, cy * wym, cy * wyp, cz * wzm, cz * wzp,
                      dyz, NULL);
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
    /* This colour's cells alone: the neighbour rows' cells of the other parity
     * are being written by other threads in this sweep (see rb_row_avx512). */
    for (; i < last; i += 2)
        ur[i] = (fr[i] + cx * (ur[i - 1] + ur[i + 1]) + cy * (wym * ym[i] + wyp * yp[i]) +
                 cz * (wzm * zm[i] + wzp * zp[i])) *
                inv_in;
    if (i == last && last > 0) {
        float d = dyz + cx;
        float s = fr[i] + cx * ur[i - 1] + cy * (wym * ym[i] + wyp * yp[i]) +
                  cz * (wzm * zm[i] + wzp * zp[i]);
        ur[i] = s / d;
    }
}

#if MG_AVX512
/* One colour of plane k of a plain level: rb_row_avx512 over its rows, inlined
 * here, without hv__mg_rb_row_plain's call and set-up per row. */
__attribute__((target("avx512f"))) void hv__mg_rb_plane_avx512(const mg_state *m, const mg_level *L,
                                                               int k, int col)
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
                      (j + k + col) & 1, cx, cy * wym, cy * wyp, cz * wzm, cz * wzp, dyz, NULL);
    }
}
#endif

/* Off-diagonal sum at cell q of a weighted row (float; walls and solid faces
 * have weight 0 and read a finite value). */
#define WROW_SUM(R, u, q, cx, cy, cz)                                                              \
    ((cx) * ((R).wx[q] * (u)[(q)-1] + (R).wx[(q) + 1] * (u)[(q) + 1]) +                            \
     (cy) * ((R).wyl[q] * (u)[(R).ym + (q)] + (R).wyh[q] * (u)[(R).yp + (q)]) +                    \
     ((R).wzl ? (cz) * ((R).wzl[q] * (u)[(R).zm + (q)] + (R).wzh[q] * (u)[(R).zp + (q)]) : 0.0f))

/* Diagonal at cell q of a weighted row. */
#define WROW_DIAG(R, L, alpha, q, cx, cy, cz)                                                      \
    ((alpha) * (L)->a[(R).base + (q)] + (cx) * ((R).wx[q] + (R).wx[(q) + 1]) +                     \
     (cy) * ((R).wyl[q] + (R).wyh[q]) + ((R).wzl ? (cz) * ((R).wzl[q] + (R).wzh[q]) : 0.0f))

/* WROW_SUM at the first or last cell q of a row of nx, without the missing x neighbour. */
static inline float wrow_edge_sum(const mg_wrow *R, const float *u, int q, int nx, float cx,
                                  float cy, float cz)
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

#if MG_AVX512
/* One colour (cells of parity i0) of a weighted row in 16-lane chunks, as
 * rb_row_avx512, each face with its own weight (walls and the box's faces
 * weigh 0, so the zero lanes beyond the row's ends add nothing). */
__attribute__((target("avx512f"))) static void rb_wrow_avx512(const mg_wrow *R, float *u,
                                                              const float *f, const float *dinv,
                                                              int nx, int i0, float cx, float cy,
                                                              float cz)
{
    const __m512 vcx = _mm512_set1_ps(cx), vcy = _mm512_set1_ps(cy), vcz = _mm512_set1_ps(cz);
    const __mmask16 colour = i0 ? 0xAAAA : 0x5555;
    mg_x16 X = mg_x16_start(u, nx);
    for (int c = 0, q = 0; c < X.nq; c++, q += 16) {
        __m512 uc, um, up;
        const __mmask16 valid = mg_x16_next(&X, c, &uc, &um, &up);
        const __mmask16 own = colour & valid;
        __m512 sx = _mm512_mul_ps(_mm512_maskz_loadu_ps(own, R->wx + q), um);
        sx = _mm512_fmadd_ps(_mm512_maskz_loadu_ps(own, R->wx + q + 1), up, sx);
        __m512 sy = _mm512_mul_ps(_mm512_maskz_loadu_ps(own, R->wyl + q),
                                  _mm512_maskz_loadu_ps(own, u + R->ym + q));
        sy = _mm512_fmadd_ps(_mm512_maskz_loadu_ps(own, R->wyh + q),
                             _mm512_maskz_loadu_ps(own, u + R->yp + q), sy);
        __m512 sm = _mm512_fmadd_ps(vcx, sx, _mm512_maskz_loadu_ps(own, f + q));
        sm = _mm512_fmadd_ps(vcy, sy, sm);
        if (R->wzl) {
            __m512 sz = _mm512_mul_ps(_mm512_maskz_loadu_ps(own, R->wzl + q),
                                      _mm512_maskz_loadu_ps(own, u + R->zm + q));
            sz = _mm512_fmadd_ps(_mm512_maskz_loadu_ps(own, R->wzh + q),
                                 _mm512_maskz_loadu_ps(own, u + R->zp + q), sz);
            sm = _mm512_fmadd_ps(vcz, sz, sm);
        }
        _mm512_mask_storeu_ps(u + q, own, _mm512_mul_ps(sm, _mm512_maskz_loadu_ps(own, dinv + q)));
    }
}
#endif

/* One colour of row (j,k) of a weighted level: u = (f + S) / D, 0 where the row
 * of A is empty (dinv = 0). The first and last cells are done apart (their
 * missing x neighbour lies outside the row). Only this colour's cells are
 * read in the neighbour rows (see rb_row_avx512). */
MG_KERNEL static void rb_row_weighted(const mg_state *m, const mg_level *L, int j, int k, int col)
{
    const int nx = L->n[0];
    const float cx = (float)L->c[0], cy = (float)L->c[1], cz = (float)L->c[2];
    const mg_wrow R = mg_wrow_at(L, m->dim, j, k);
    float *u = L->u + R.base;
    const float *f = L->f + R.base, *dinv = L->dinv + R.base;
    int i = (j + k + col) & 1;
#if MG_AVX512
    if (L->binary && mg_avx512()) {
        rb_row_avx512(u, f, u + R.ym, u + R.yp, u + R.zm, u + R.zp, nx, i, cx, R.ym ? cy : 0,
                      R.yp ? cy : 0, R.zm ? cz : 0, R.zp ? cz : 0, 0, dinv);
        return;
    }
    if (mg_avx512()) {
        rb_wrow_avx512(&R, u, f, dinv, nx, i, cx, cy, cz);
        return;
    }
#endif
    if (i == 0)
        u[0] = (f[0] + wrow_edge_sum(&R, u, 0, nx, cx, cy, cz)) * dinv[0];
    if (nx > 1 && ((nx - 1) & 1) == i)
        u[nx - 1] = (f[nx - 1] + wrow_edge_sum(&R, u, nx - 1, nx, cx, cy, cz)) * dinv[nx - 1];
    if (i == 0)
        i = 2;
    if (L->binary) {
        /* solid neighbours hold u = 0: the plain stencil, with this cell's dinv */
        const float wym = R.ym != 0, wyp = R.yp != 0, wzm = R.zm != 0, wzp = R.zp != 0;
        const float *ym = u + R.ym, *yp = u + R.yp, *zm = u + R.zm, *zp = u + R.zp;
        for (; i < nx - 1; i += 2)
            u[i] = (f[i] + cx * (u[i - 1] + u[i + 1]) + cy * (wym * ym[i] + wyp * yp[i]) +
                    cz * (wzm * zm[i] + wzp * zp[i])) *
                   dinv[i];
    } else {
        for (; i < nx - 1; i += 2)
            u[i] = (f[i] + WROW_SUM(R, u, i, cx, cy, cz)) * dinv[i];
    }
}

#if MG_AVX512
/* u[q-1 .. q+6] and u[q+1 .. q+8] from the chunks before (p), at (c) and
 * after (n) q: lane shifts across the two halves (vperm2f128, vpalignr). */
__attribute__((target("avx2,fma"))) static inline __m256 x_minus(__m256 p, __m256 c)
{
    const __m256i t = _mm256_castps_si256(_mm256_permute2f128_ps(p, c, 0x21));
    return _mm256_castsi256_ps(_mm256_alignr_epi8(_mm256_castps_si256(c), t, 12));
}

__attribute__((target("avx2,fma"))) static inline __m256 x_plus(__m256 c, __m256 n)
{
    const __m256i t = _mm256_castps_si256(_mm256_permute2f128_ps(c, n, 0x21));
    return _mm256_castsi256_ps(_mm256_alignr_epi8(t, _mm256_castps_si256(c), 4));
}

/* One colour of a binary level's row in 8-lane AVX2 chunks, for the fused
 * pass alone: as rb_row_avx512 with dinv, but every lane is loaded and the
 * chunk stored whole, this colour's cells new and the other's as they were
 * (AMD's masked stores cost several times a whole one). In the fused pass a
 * thread owns a slab of planes: the rows it reads in full and the cells it
 * writes back unchanged are its own, or those of a neighbour slab's edge
 * plane at a time a barrier sets apart (mg_fused.c), so no other thread
 * touches them meanwhile. hv__mg_rb_sweep, whose threads share planes, keeps
 * rb_row_weighted. The row's last chunk reads under a mask: no lane outside
 * the row is read or written. */
__attribute__((target("avx2,fma"))) static void rb_brow_avx2(float *u, const float *f,
                                                             const float *dinv, const mg_wrow *R,
                                                             int nx, int i0, float cx,
                                                             const float c[4])
{
    const __m256 vcx = _mm256_set1_ps(cx), vcym = _mm256_set1_ps(c[0]), vcyp = _mm256_set1_ps(c[1]),
                 vczm = _mm256_set1_ps(c[2]), vczp = _mm256_set1_ps(c[3]);
    const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    const __m256 colour = _mm256_castsi256_ps(
        _mm256_set1_epi64x(i0 ? (int64_t)0xFFFFFFFF00000000LL : (int64_t)0x00000000FFFFFFFFLL));
    const float *ym = u + R->ym, *yp = u + R->yp, *zm = u + R->zm, *zp = u + R->zp;
    /* the row's own cells as they were before this chunk's store: its x
     * neighbours come from registers, never from a load that overlaps the
     * store just made (which the CPU cannot forward) */
    __m256 prev = _mm256_setzero_ps(),
           cur = nx >= 8 ? _mm256_loadu_ps(u)
                         : _mm256_maskload_ps(u, _mm256_cmpgt_epi32(_mm256_set1_epi32(nx), lane));
    for (int q = 0; q < nx; q += 8) {
        __m256 next = _mm256_setzero_ps(), fv, dv, a, b, cz, dz;
        if (q + 16 <= nx)
            next = _mm256_loadu_ps(u + q + 8);
        else if (q + 8 < nx)
            next = _mm256_maskload_ps(u + q + 8,
                                      _mm256_cmpgt_epi32(_mm256_set1_epi32(nx - q - 8), lane));
        if (q + 8 <= nx) {
            fv = _mm256_loadu_ps(f + q);
            dv = _mm256_loadu_ps(dinv + q);
            a = _mm256_loadu_ps(ym + q);
            b = _mm256_loadu_ps(yp + q);
            cz = _mm256_loadu_ps(zm + q);
            dz = _mm256_loadu_ps(zp + q);
        } else {
            const __m256i in = _mm256_cmpgt_epi32(_mm256_set1_epi32(nx - q), lane);
            fv = _mm256_maskload_ps(f + q, in);
            dv = _mm256_maskload_ps(dinv + q, in);
            a = _mm256_maskload_ps(ym + q, in);
            b = _mm256_maskload_ps(yp + q, in);
            cz = _mm256_maskload_ps(zm + q, in);
            dz = _mm256_maskload_ps(zp + q, in);
        }
        __m256 sm = _mm256_fmadd_ps(vcx, _mm256_add_ps(x_minus(prev, cur), x_plus(cur, next)), fv);
        sm = _mm256_fmadd_ps(vcym, a, sm);
        sm = _mm256_fmadd_ps(vcyp, b, sm);
        sm = _mm256_fmadd_ps(vczm, cz, sm);
        sm = _mm256_fmadd_ps(vczp, dz, sm);
        const __m256 out = _mm256_blendv_ps(cur, _mm256_mul_ps(sm, dv), colour);
        if (q + 8 <= nx) {
            _mm256_storeu_ps(u + q, out);
        } else {
            float buf[8];
            _mm256_storeu_ps(buf, out);
            memcpy(u + q, buf, (size_t)(nx - q) * sizeof *buf);
        }
        prev = cur;
        cur = next;
    }
}
#endif

/* rb_brow_avx2 in C, for the fused pass on CPUs without AVX2 (and in the
 * ThreadSanitizer build, which checks that pass's whole-row access this way):
 * every cell computed, this colour's kept; the x neighbours of the ends are
 * walls. */
MG_KERNEL static void rb_brow_whole(float *u, const float *f, const float *dinv, const mg_wrow *R,
                                    int nx, int i0, float cx, const float c[4])
{
    const float *ym = u + R->ym, *yp = u + R->yp, *zm = u + R->zm, *zp = u + R->zp;
    const float cym = c[0], cyp = c[1], czm = c[2], czp = c[3];
    for (int i = 0; i<nx; i += nx> 1 ? nx - 1 : 1) {
        const float s = f[i] + cx * ((i > 0 ? u[i - 1] : 0) + (i < nx - 1 ? u[i + 1] : 0)) +
                        cym * ym[i] + cyp * yp[i] + czm * zm[i] + czp * zp[i];
        if ((i & 1) == i0)
            u[i] = s * dinv[i];
    }
    /* a cell of the other colour reads its neighbours before this colour's
     * are written, as the vector row does: its result is dropped */
#pragma omp simd
    for (int i = 1; i < nx - 1; i++) {
        const float s = f[i] + cx * (u[i - 1] + u[i + 1]) + cym * ym[i] + cyp * yp[i] +
                        czm * zm[i] + czp * zp[i];
        u[i] = (i & 1) == i0 ? s * dinv[i] : u[i];
    }
}

/* One colour of row (j,k) of a weighted level in the fused pass: a binary
 * level's whole-row kernels where AVX-512's masked row does not run. */
__attribute__((noinline)) static void rb_row_fused_weighted(const mg_state *m, const mg_level *L,
                                                            int j, int k, int col)
{
#if MG_AVX512
    if (mg_avx512()) {
        rb_row_weighted(m, L, j, k, col);
        return;
    }
#endif
    if (!L->binary || m->dim != 3) {
        rb_row_weighted(m, L, j, k, col);
        return;
    }
    const mg_wrow R = mg_wrow_at(L, m->dim, j, k);
    const float cy = (float)L->c[1], cz = (float)L->c[2];
    const float c[4] = {R.ym ? cy : 0, R.yp ? cy : 0, R.zm ? cz : 0, R.zp ? cz : 0};
    float *u = L->u + R.base;
    const float *f = L->f + R.base, *dinv = L->dinv + R.base;
    const int i0 = (j + k + col) & 1;
#if MG_AVX512
    if (mg_avx2()) {
        rb_brow_avx2(u, f, dinv, &R, L->n[0], i0, (float)L->c[0], c);
        return;
    }
#endif
    rb_brow_whole(u, f, dinv, &R, L->n[0], i0, (float)L->c[0], c);
}

/* One colour of row (j,k) for the fused pass (mg_fused.c). */
void hv__mg_rb_row(const mg_state *m, const mg_level *L, int j, int k, int col)
{
    if (L->plain)
        hv__mg_rb_row_plain(m, L, L->u, L->f, j, k, col);
    else
        rb_row_fused_weighted(m, L, j, k, col);
}

void hv__mg_rb_sweep(const mg_state *m, mg_level *L, int col)
{
    float *u = L->u;
    const float *f = L->f;
    if (L->plain) {
#pragma omp parallel for collapse(2) schedule(static) if (L->count > MG_PAR_MIN)
        for (int k = 0; k < L->n[2]; k++)
            for (int j = 0; j < L->n[1]; j++)
                hv__mg_rb_row_plain(m, L, u, f, j, k, col);
        return;
    }
#pragma omp parallel for collapse(2) schedule(static) if (L->count > MG_PAR_MIN)
    for (int k = 0; k < L->n[2]; k++)
        for (int j = 0; j < L->n[1]; j++)
            rb_row_weighted(m, L, j, k, col);
}

#if MG_AVX512
/* Row of r = f - A u on a binary level in 16-lane chunks (as rb_row_avx512):
 * the plain stencil, each cell's diagonal 1 / dinv, r = f on empty rows. */
__attribute__((target("avx512f"))) static void residual_brow_avx512(
    const float *ur, const float *fr, const float *dinv, const float *ym, const float *yp,
    const float *zm, const float *zp, int nx, float cx, float cym, float cyp, float czm, float czp,
    float *rr)
{
    const __m512 vcx = _mm512_set1_ps(cx), vcym = _mm512_set1_ps(cym), vcyp = _mm512_set1_ps(cyp),
                 vczm = _mm512_set1_ps(czm), vczp = _mm512_set1_ps(czp);
    mg_x16 X = mg_x16_start(ur, nx);
    for (int c = 0, q = 0; c < X.nq; c++, q += 16) {
        __m512 uc, um, up;
        const __mmask16 valid = mg_x16_next(&X, c, &uc, &um, &up);
        __m512 f = _mm512_maskz_loadu_ps(valid, fr + q);
        __m512 sm = _mm512_fmadd_ps(vcx, _mm512_add_ps(um, up), f);
        sm = _mm512_fmadd_ps(vcym, _mm512_maskz_loadu_ps(valid, ym + q), sm);
        sm = _mm512_fmadd_ps(vcyp, _mm512_maskz_loadu_ps(valid, yp + q), sm);
        sm = _mm512_fmadd_ps(vczm, _mm512_maskz_loadu_ps(valid, zm + q), sm);
        sm = _mm512_fmadd_ps(vczp, _mm512_maskz_loadu_ps(valid, zp + q), sm);
        __m512 d = _mm512_maskz_loadu_ps(valid, dinv + q);
        __mmask16 full = _mm512_cmp_ps_mask(d, _mm512_setzero_ps(), _CMP_GT_OQ);
        __m512 du = _mm512_maskz_div_ps(full, uc, d);
        _mm512_mask_storeu_ps(rr + q, valid, _mm512_mask_sub_ps(f, full, sm, du));
    }
}
#endif

/* Row (j,k) of r = f - A u on a weighted level. */
MG_KERNEL static void residual_row_weighted(const mg_state *m, const mg_level *L, int j, int k)
{
    const float alpha = (float)m->alpha, cx = (float)L->c[0], cy = (float)L->c[1],
                cz = (float)L->c[2];
    const int nx = L->n[0];
    const mg_wrow R = mg_wrow_at(L, m->dim, j, k);
    const float *ur = L->u + R.base, *fr = L->f + R.base;
    float *rr = L->r + R.base;
#if MG_AVX512
    if (L->binary && mg_avx512()) {
        residual_brow_avx512(ur, fr, L->dinv + R.base, ur + R.ym, ur + R.yp, ur + R.zm, ur + R.zp,
                             nx, cx, R.ym ? cy : 0, R.yp ? cy : 0, R.zm ? cz : 0, R.zp ? cz : 0,
                             rr);
        return;
    }
#endif
    for (int q = 0; q<nx; q += nx - 1> 0 ? nx - 1 : 1) /* the first and last cells */
        rr[q] = fr[q] - (WROW_DIAG(R, L, alpha, q, cx, cy, cz) * ur[q] -
                         wrow_edge_sum(&R, ur, q, nx, cx, cy, cz));
    if (L->binary) { /* solid neighbours hold u = 0; D = 1 / dinv, 0 on empty rows */
        const float wym = R.ym != 0, wyp = R.yp != 0, wzm = R.zm != 0, wzp = R.zp != 0;
        const float *ym = ur + R.ym, *yp = ur + R.yp, *zm = ur + R.zm, *zp = ur + R.zp;
        const float *dv = L->dinv + R.base;
        for (int q = 1; q < nx - 1; q++) {
            float sn = cx * (ur[q - 1] + ur[q + 1]) + cy * (wym * ym[q] + wyp * yp[q]) +
                       cz * (wzm * zm[q] + wzp * zp[q]);
            rr[q] = dv[q] > 0 ? fr[q] - (ur[q] / dv[q] - sn) : fr[q];
        }
        return;
    }
    for (int q = 1; q < nx - 1; q++)
        rr[q] = fr[q] -
                (WROW_DIAG(R, L, alpha, q, cx, cy, cz) * ur[q] - WROW_SUM(R, ur, q, cx, cy, cz));
}

/* r = f - A u on a level (float). */
void hv__mg_level_residual(const mg_state *m, mg_level *L)
{
    const float *u = L->u, *f = L->f;
    float *r = L->r;
    if (L->plain) {
#pragma omp parallel for collapse(2) schedule(static) if (L->count > MG_PAR_MIN)
        for (int k = 0; k < L->n[2]; k++)
            for (int j = 0; j < L->n[1]; j++) {
                mg_plain_row R = mg_plain_row_at(m, L, j, k);
                float unused = 0;
                MG_PLAIN_ROW_RESIDUAL(float, float, L, R, u, f, r + R.base, unused);
                (void)unused;
            }
        return;
    }
#pragma omp parallel for collapse(2) schedule(static) if (L->count > MG_PAR_MIN)
    for (int k = 0; k < L->n[2]; k++)
        for (int j = 0; j < L->n[1]; j++)
            residual_row_weighted(m, L, j, k);
}

static double level_diag_at(const mg_state *m, const mg_level *L, size_t c, int i, int j, int k)
{
    return L->plain ? hv__mg_level_diag(L, m->dim, m->alpha, i, j, k)
                    : (L->dinv[c] > 0 ? 1.0 / L->dinv[c] : 0.0);
}

/* u += omega_k D^-1 r, the Jacobi-type update; with cheb != NULL the Chebyshev
 * recurrence d = rho*rho_old*d + 2 rho/delta D^-1 r (Chebyshev on D^-1 A,
 * docs/METHOD.md, "Multigrid"). */
void hv__mg_level_jacobi_update(const mg_state *m, mg_level *L, double cd, double cr)
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
