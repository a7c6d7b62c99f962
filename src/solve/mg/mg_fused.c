/*
 * The CPU multigrid's fused passes on plain 3D levels (docs/METHOD.md, "Fused
 * passes on plain levels"): a red-black Gauss-Seidel sweep in one pass over
 * memory, pipelined plane by plane in slabs per thread, which can also start
 * from u = 0, restrict the residual into the coarse right-hand side or add
 * the prolonged coarse correction as it goes; with the rows only these passes
 * use (first colour from zero, residual rows summed for the restriction).
 */
#include "mg_internal.h"

#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

/* Colour col of plane k of a plain or binary level. */
static void rb_plane(const mg_state *m, const mg_level *L, int k, int col)
{
#if MG_AVX512
    if (L->plain && mg_avx512()) {
        hv__mg_rb_plane_avx512(m, L, k, col);
        return;
    }
#endif
    for (int j = 0; j < L->n[1]; j++)
        hv__mg_rb_row(m, L, j, k, col);
}

/* First colour of a sweep from u = 0 along one row: this colour's cells take
 * f / diag (all their neighbours are zero), the other colour's are set to zero,
 * so u need not be cleared (nor read) beforehand. */
MG_KERNEL static void rb_row_plain_zero(const mg_state *m, const mg_level *L, int j, int k, int col)
{
    const int nx = L->n[0];
    mg_plain_row R = mg_plain_row_at(m, L, j, k);
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
__attribute__((target("avx512f"))) static void rb_row_zero_avx512(const mg_state *m,
                                                                  const mg_level *L, int j, int k,
                                                                  int col)
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
        _mm512_mask_storeu_ps(
            ur + q, valid, _mm512_maskz_mul_ps(colour, _mm512_maskz_loadu_ps(valid, fr + q), inv));
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
MG_KERNEL static void residual_row_add(const mg_state *m, const mg_level *L, int j, int p,
                                       float *line)
{
    const int nx = L->n[0];
    const float cx = (float)L->c[0], cy = (float)L->c[1], cz = (float)L->c[2];
    mg_plain_row R = mg_plain_row_at(m, L, j, p);
    const float *u = L->u + R.base, *f = L->f + R.base;
    const float *ym = u + R.ym, *yp = u + R.yp, *zm = u + R.zm, *zp = u + R.zp;
    const float wym = (float)R.wym, wyp = (float)R.wyp, wzm = (float)R.wzm, wzp = (float)R.wzp;
    const float din = (float)(R.dyz + 2 * L->c[0]);
    for (int i = 1; i < nx - 1; i++) /* branch-free: vectorizes */
        line[i] +=
            f[i] - (din * u[i] - (cy * (wym * ym[i] + wyp * yp[i]) +
                                  cz * (wzm * zm[i] + wzp * zp[i]) + cx * (u[i - 1] + u[i + 1])));
    for (int i = 0; i < nx; i += (nx > 1 ? nx - 1 : 1)) {
        float s = cy * (wym * ym[i] + wyp * yp[i]) + cz * (wzm * zm[i] + wzp * zp[i]);
        float d = (float)R.dyz;
        if (i > 0) {
            s += cx * u[i - 1];
            d += cx;
        }
        if (i < nx - 1) {
            s += cx * u[i + 1];
            d += cx;
        }
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
__attribute__((target("avx512f"))) static void residual_row_avx512(const float *ur, const float *fr,
                                                                   const float *ym, const float *yp,
                                                                   const float *zm, const float *zp,
                                                                   int nx, float cx, float cym,
                                                                   float cyp, float czm, float czp,
                                                                   float dyz, float *line)
{
    const __m512 vcx = _mm512_set1_ps(cx), vcym = _mm512_set1_ps(cym), vcyp = _mm512_set1_ps(cyp),
                 vczm = _mm512_set1_ps(czm), vczp = _mm512_set1_ps(czp),
                 vdin = _mm512_set1_ps(dyz + 2 * cx);
    const int last = nx - 1;
    mg_x16 X = mg_x16_start(ur, nx);
    for (int c = 0, q = 0; c < X.nq; c++, q += 16) {
        __m512 uc, um, up;
        const __mmask16 valid = mg_x16_next(&X, c, &uc, &um, &up);
        __m512 sm =
            _mm512_fmadd_ps(vcx, _mm512_add_ps(um, up), _mm512_maskz_loadu_ps(valid, fr + q));
        sm = _mm512_fmadd_ps(vcym, _mm512_maskz_loadu_ps(valid, ym + q), sm);
        sm = _mm512_fmadd_ps(vcyp, _mm512_maskz_loadu_ps(valid, yp + q), sm);
        sm = _mm512_fmadd_ps(vczm, _mm512_maskz_loadu_ps(valid, zm + q), sm);
        sm = _mm512_fmadd_ps(vczp, _mm512_maskz_loadu_ps(valid, zp + q), sm);
        __m512 d = vdin;
        if (c == 0)
            d = _mm512_mask_mov_ps(d, 1, _mm512_set1_ps(nx > 1 ? dyz + cx : dyz));
        if (c + 1 == X.nq && last > 0)
            d = _mm512_mask_mov_ps(d, (__mmask16)(1u << (last - q)), _mm512_set1_ps(dyz + cx));
        __m512 r = _mm512_fnmadd_ps(d, uc, sm);
        __m512 l = _mm512_loadu_ps(line + q);
        _mm512_storeu_ps(line + q,
                         _mm512_mask_add_ps(l, valid, l, r)); /* line stays zero beyond nx */
    }
}

/* restrict_x with x coarsened: even and odd cells of 32 split by permutes. */
__attribute__((target("avx512f"))) static void restrict_x_avx512(const float *line, int nx,
                                                                 float scale, float *out)
{
    const __m512i ev = _mm512_set_epi32(30, 28, 26, 24, 22, 20, 18, 16, 14, 12, 10, 8, 6, 4, 2, 0);
    const __m512i od = _mm512_set_epi32(31, 29, 27, 25, 23, 21, 19, 17, 15, 13, 11, 9, 7, 5, 3, 1);
    const __m512 vs = _mm512_set1_ps(scale);
    const int nc = (nx + 1) / 2;
    for (int I = 0; I < nc; I += 16) {
        int c = nc - I < 16 ? nc - I : 16;
        __m512 a = _mm512_loadu_ps(line + 2 * I), b = _mm512_loadu_ps(line + 2 * I + 16);
        __m512 s =
            _mm512_add_ps(_mm512_permutex2var_ps(a, ev, b), _mm512_permutex2var_ps(a, od, b));
        _mm512_mask_storeu_ps(out + I, (__mmask16)(c == 16 ? 0xFFFFu : (1u << c) - 1u),
                              _mm512_mul_ps(s, vs));
    }
}
#endif

/* Coarse row (J,K) of C->f: the mean of its children's fine residuals f - A u
 * (planes 2K, 2K+1 or K, rows 2J, 2J+1 or J, x pairs), computed from u here, so
 * the fine residual is never stored; children beyond odd edges count as zero,
 * as in hv__mg_restrict_field. u must be final on the children's planes and the
 * planes beside them. */
static void restrict_residual_row(const mg_state *m, const mg_level *L, mg_level *C, int J, int K,
                                  float scale)
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
    float
        line[MG_ROW_BUF + 32]; /* zero beyond nx: restrict_x_avx512 reads whole pairs of vectors */
    memset(line, 0, (size_t)(nx + 32) * sizeof(float));
    float *out = C->f + C->sy * (size_t)J + C->sz * (size_t)K;
#if MG_AVX512
    if (mg_avx512()) {
        const float cx = (float)L->c[0], cy = (float)L->c[1], cz = (float)L->c[2];
        for (int b = 0; b < nk; b++)
            for (int a = 0; a < nj; a++) {
                const int j = js[a], k = ks[b];
                const float *ur = L->u + L->sy * (size_t)j + L->sz * (size_t)k;
                const float wym = j > 0, wyp = j<L->n[1] - 1, wzm = k> 0, wzp = k < L->n[2] - 1;
                const float dyz = (float)m->alpha + cy * (wym + wyp) + cz * (wzm + wzp);
                residual_row_avx512(ur, L->f + (ur - L->u), wym ? ur - L->sy : ur,
                                    wyp ? ur + L->sy : ur, wzm ? ur - L->sz : ur,
                                    wzp ? ur + L->sz : ur, nx, cx, cy * wym, cy * wyp, cz * wzm,
                                    cz * wzp, dyz, line);
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
static int coarse_first(const mg_level *L, int K) { return L->coarsen[2] ? 2 * K : K; }

static int coarse_last(const mg_level *L, int K)
{
    return L->coarsen[2] && 2 * K + 1 < L->n[2] ? 2 * K + 1 : coarse_first(L, K);
}

static void restrict_residual_plane(const mg_state *m, const mg_level *L, mg_level *C, int K,
                                    float scale)
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
static void rb_pair(const mg_state *m, mg_level *L, int k, int A, int zero, const mg_level *P,
                    float *line, mg_level *R, int K, float scale)
{
    const int ny = L->n[1];
    int J = 0; /* coarse rows of plane K of R written so far */
    for (int j = 0; j < ny; j++) {
        if (R) /* spread over the rows; its fine planes' neighbours are final */
            for (int J1 = (int)((int64_t)(j + 1) * R->n[1] / ny); J < J1; J++)
                restrict_residual_row(m, L, R, J, K, scale);
        if (P) /* u += P u_C on row j of plane k+1 first: colour A on row j of plane k reads it */
            hv__mg_prolong_row_plain(L, P, j, k + 1, line, 0);
        if (zero)
            rb_row_zero(m, L, j, k, A);
        else
            hv__mg_rb_row(m, L, j, k, A);
        if (j > 0)
            hv__mg_rb_row(m, L, j - 1, k - 1, !A);
    }
    hv__mg_rb_row(m, L, ny - 1, k - 1, !A);
}

/* One red-black sweep of a plain 3D level in a single pass over memory, with
 * (mode) the first colour from u = 0 (MG_FS_ZERO), the residual and its
 * restriction to C->f after the sweep (MG_FS_RESTRICT: the fine residual is never
 * stored), or u += P u_C before it (MG_FS_PROLONG, C plain).
 *
 * Each thread owns a slab of planes [k0,k1) (k0 even) and runs it as a pipeline:
 * colour `first` on plane k, then the other colour on plane k-1, whose
 * neighbours are final by then. Across slab edges the order of a two-colour
 * sweep is kept by doing colour `first` on each slab's first plane before
 * anything else and the other colour on it after everything else, so a sweep
 * has 2 to 4 barriers instead of a few per plane. Same arithmetic as two
 * colour sweeps, half the memory traffic. */
void hv__mg_fused_pass(const mg_state *m, mg_level *L, mg_level *C, int mode, int first)
{
    const int nz = L->n[2], ny = L->n[1];
    float scale = 1.0f;
    if (mode == MG_FS_RESTRICT) {
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
        /* MG_FS_RESTRICT: coarse planes whose fine planes are in [k0+2, k1-2] are
         * written in the pipeline from Kin on, once their last fine plane's
         * neighbours are final; those that touch k0, k0+1 or k1-1 (whose
         * neighbours are final only after the slab edges) at the end. */
        const int Kfirst = L->coarsen[2] ? k0 / 2 : k0;
        const int Kin = L->coarsen[2] ? k0 / 2 + 1 : k0 + 2;
        int Knext = Kin;
        if (mode == MG_FS_PROLONG) {
            if (own) {
                for (int k = k0; k <= k0 + 1 && k < k1; k++)
                    for (int j = 0; j < ny; j++)
                        hv__mg_prolong_row_plain(L, C, j, k, line, 0);
                if (k1 - 1 > k0 + 1)
                    for (int j = 0; j < ny; j++)
                        hv__mg_prolong_row_plain(L, C, j, k1 - 1, line, 0);
            }
#pragma omp barrier
        }
        /* colour A on the first plane */
        if (own && mode == MG_FS_ZERO)
            for (int j = 0; j < ny; j++)
                rb_row_zero(m, L, j, k0, A);
        else if (own)
            rb_plane(m, L, k0, A);
#pragma omp barrier
        if (own) {
            for (int k = k0 + 1; k < k1; k++) {
                const int pro = mode == MG_FS_PROLONG && k + 1 >= k0 + 2 && k + 1 <= k1 - 2;
                if (k - 1 > k0) {
                    /* u is final on planes <= k-2: residuals of planes <= k-3 */
                    int rk = -1;
                    if (mode == MG_FS_RESTRICT && coarse_first(L, Knext) < k1 &&
                        coarse_last(L, Knext) <= k - 3)
                        rk = Knext++;
                    rb_pair(m, L, k, A, mode == MG_FS_ZERO, pro ? C : NULL, line,
                            rk >= 0 ? C : NULL, rk, scale);
                } else {
                    if (pro)
                        for (int j = 0; j < ny; j++)
                            hv__mg_prolong_row_plain(L, C, j, k + 1, line, 0);
                    if (mode == MG_FS_ZERO)
                        for (int j = 0; j < ny; j++)
                            rb_row_zero(m, L, j, k, A);
                    else
                        rb_plane(m, L, k, A);
                }
            }
            if (k1 - 1 > k0)
                rb_plane(m, L, k1 - 1, B);
            while (mode == MG_FS_RESTRICT && coarse_first(L, Knext) < k1 &&
                   coarse_last(L, Knext) <= k1 - 2)
                restrict_residual_plane(m, L, C, Knext++, scale);
        }
#pragma omp barrier
        /* colour B on the first plane (its neighbour k0-1 is final now) */
        if (own)
            rb_plane(m, L, k0, B);
        if (mode == MG_FS_RESTRICT) {
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
