/* The stages' tiles and their local heat steps (distance_internal.h;
 * docs/METHOD.md, "Heat method", "Stages on tiles").
 *
 * A stage's diffusion matters only where its front can reach: (I - t Lap)^-1
 * decays like e^{-kappa r}, kappa h ~ 1/sqrt(t_scale), and its cells are
 * trusted only out to where u falls to the solve's error bound. So a stage
 * solves on the tiles (DIST_TILE cells a side) within `reach` tiles of a
 * tile that holds a front weight (the core; behind the front only those next
 * to a front tile), and one ring of tiles more (the halo: its cells are
 * solved, never trusted, so that the Neumann reflection at the band's edge,
 * about e^{-2 kappa 8h} of what reaches it, stays out of the trusted cells).
 * Every cell then takes part in a few stages, not in all of them.
 *
 * The band's cells are stored compactly, tile after tile (DIST_TILE^dim
 * cells each, list order), and both heat steps are solved there by
 * Jacobi-preconditioned Chebyshev iteration: D^-1 A has its spectrum in
 * [1/(1+2ds), 2 - 1/(1+2ds)] (s = t/h^2, d = dim; Gershgorin, and A >= I), so
 * a fixed count of sweeps reaches the tolerance. No inner products, no
 * hierarchy to build per stage, one streaming pass per sweep; the residual
 * is measured once at the end. */
#include "distance_internal.h"
#include "core/error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

#define CAP 250 /* tile distances are capped here */

static const double zero_row[DIST_TILE];

hv_status hv__dist_tiles_init(hv_dist_box *b, int band)
{
    hv_dist_tiles *T = &b->tl;
    memset(T, 0, sizeof *T);
    T->cells = 1;
    T->count = 1;
    for (int a = 0; a < 3; a++) {
        T->tn[a] = a < b->dim ? DIST_TILE : 1;
        T->nt[a] = (b->n[a] + T->tn[a] - 1) / T->tn[a];
        T->cells *= (size_t)T->tn[a];
        T->count *= (size_t)T->nt[a];
    }
    T->band = band;
    T->reach = DIST_FIRST_REACH;
    T->list = malloc(T->count * sizeof *T->list);
    if (!T->list)
        return hv__error(HV_ERR_NOMEM, "distance: out of memory for %zu tiles", T->count);
    T->nlist = T->ncore = T->count;
    for (size_t t = 0; t < T->count; t++)
        T->list[t] = (uint32_t)t;
    if (!band)
        return HV_OK;
    T->slot = malloc(T->count * sizeof *T->slot);
    T->nbr = malloc(6 * T->count * sizeof *T->nbr);
    T->fluid = calloc(T->count, sizeof *T->fluid);
    T->open_faces = calloc(T->count, sizeof *T->open_faces);
    T->front = calloc(T->count, 1);
    T->dist = malloc(T->count);
    T->dist2 = malloc(T->count);
    if (!T->slot || !T->nbr || !T->fluid || !T->open_faces || !T->front || !T->dist || !T->dist2)
        return hv__error(HV_ERR_NOMEM, "distance: out of memory for %zu tiles", T->count);
    T->nlist = T->ncore = 0;
    return HV_OK;
}

void hv__dist_tiles_free(hv_dist_tiles *T)
{
    free(T->list);
    free(T->slot);
    free(T->nbr);
    free(T->fluid);
    free(T->open_faces);
    free(T->front);
    free(T->dist);
    free(T->dist2);
    hv_free(T->code);
    hv_free(T->f);
    for (int q = 0; q < 4; q++)
        hv_free(T->x[q]);
    memset(T, 0, sizeof *T);
}

/* The faces below cell (i, j, k) (one per axis) that are open and have no
 * direction yet. */
static int open_faces_of(const hv_dist_box *b, int i, int j, int k)
{
    const int ijk[3] = {i, j, k};
    int m = 0;
    for (int a = 0; a < b->dim; a++) {
        size_t m0 = (size_t)b->n[0] + (a == 0), m1 = (size_t)b->n[1] + (a == 1);
        m += ijk[a] > 0 && isnan(b->X[a][i + m0 * (j + m1 * k)]);
    }
    return m;
}

void hv__dist_tiles_fluid(hv_dist_box *b)
{
    hv_dist_tiles *T = &b->tl;
#pragma omp parallel for schedule(dynamic, 16)
    for (size_t t = 0; t < T->count; t++) {
        int lo[3], len[3], nf = 0;
        hv__dist_tile_cells(b, t, lo, len);
        for (int k = lo[2]; k < lo[2] + len[2]; k++)
            for (int j = lo[1]; j < lo[1] + len[1]; j++)
                for (int i = lo[0]; i < lo[0] + len[0]; i++)
                    nf += b->region[i + b->cs[1] * j + b->cs[2] * k] >= 0;
        T->fluid[t] = nf;
    }
}

void hv__dist_tiles_start(hv_dist_box *b, const double *w)
{
    hv_dist_tiles *T = &b->tl;
    hv__dist_tiles_fluid(b);
#pragma omp parallel for schedule(dynamic, 16)
    for (size_t t = 0; t < T->count; t++) {
        int lo[3], len[3], fr = 0, open = 0;
        hv__dist_tile_cells(b, t, lo, len);
        for (int k = lo[2]; k < lo[2] + len[2]; k++)
            for (int j = lo[1]; j < lo[1] + len[1]; j++)
                for (int i = lo[0]; i < lo[0] + len[0]; i++) {
                    fr |= w[i + b->cs[1] * j + b->cs[2] * k] > 0;
                    open += open_faces_of(b, i, j, k);
                }
        T->open_faces[t] = open;
        T->front[t] = (uint8_t)fr;
    }
}

double hv__dist_core_step(const hv_dist_tiles *T)
{
    /* every cell within DIST_TILE reach - (DIST_TILE - 1) voxels of a front
     * cell is on a core tile */
    if (!T->band)
        return INFINITY;
    return DIST_TILE * T->reach - (DIST_TILE - 1) - FRONT_BAND - 1;
}

void hv__dist_core_next(hv_dist_tiles *T, double full, int dim, double tau)
{
    const double trust = full + FRONT_MARGIN / hv__dist_axis_kappa(dim, tau);
    T->reach = hv__dist_next_reach(fmin(trust, full + FRONT_BAND + DIST_CORE_MARGIN));
}

/* One axis of the capped chessboard distance to the front tiles: dst(t) =
 * min over offsets o along axis a of max(|o|, src(t + o e_a)). */
static void dist_axis(const hv_dist_tiles *T, const uint8_t *src, uint8_t *dst, int a, int cap)
{
    size_t stride = 1;
    for (int b = 0; b < a; b++)
        stride *= (size_t)T->nt[b];
    const int na = T->nt[a];
#pragma omp parallel for schedule(static)
    for (size_t t = 0; t < T->count; t++) {
        int ta = (int)((t / stride) % (size_t)na), best = src[t];
        for (int o = 1; o < best && o <= cap; o++) {
            if (ta - o >= 0) {
                int v = src[t - o * stride] > o ? src[t - o * stride] : o;
                best = v < best ? v : best;
            }
            if (ta + o < na) {
                int v = src[t + o * stride] > o ? src[t + o * stride] : o;
                best = v < best ? v : best;
            }
        }
        dst[t] = (uint8_t)best;
    }
}

/* The band cell codes of listed tile q: 0 off the unknowns (solid cells, cells
 * of regions without a source, cells past the grid), else 1 + the number of
 * open faces to other cells of the band. A closed face's neighbour holds 0
 * (a cell that is no unknown, or zero_row beyond the band), so the sweeps add
 * every neighbour and take the diagonal from the code. */
static void tile_codes(const hv_dist_box *b, size_t q)
{
    const hv_dist_tiles *T = &b->tl;
    int lo[3], len[3];
    hv__dist_tile_cells(b, T->list[q], lo, len);
    uint8_t *m = T->code + q * T->cells;
    memset(m, 0, T->cells);
    const int32_t *nb = T->nbr + 6 * q;
    for (int lz = 0; lz < len[2]; lz++)
        for (int ly = 0; ly < len[1]; ly++)
            for (int lx = 0; lx < len[0]; lx++) {
                const int l[3] = {lx, ly, lz};
                size_t c = (lo[0] + lx) + b->cs[1] * (lo[1] + ly) + b->cs[2] * (lo[2] + lz);
                if (b->region[c] < 0)
                    continue;
                int v = 1;
                for (int a = 0; a < b->dim; a++) {
                    int g = lo[a] + l[a];
                    v += g > 0 && (l[a] > 0 || nb[2 * a] >= 0) && b->region[c - b->cs[a]] >= 0;
                    v += g + 1 < b->n[a] && (l[a] + 1 < len[a] || nb[2 * a + 1] >= 0) &&
                         b->region[c + b->cs[a]] >= 0;
                }
                m[lx + T->tn[0] * (ly + T->tn[1] * lz)] = (uint8_t)v;
            }
}

/* The slots of listed tile q's six face neighbours (-1: none in the band). */
static void tile_neighbours(hv_dist_tiles *T, size_t q)
{
    size_t t = T->list[q], r = t, stride = 1;
    for (int a = 0; a < 3; a++) {
        int ta = (int)(r % (size_t)T->nt[a]);
        r /= (size_t)T->nt[a];
        T->nbr[6 * q + 2 * a] = ta > 0 ? T->slot[t - stride] : -1;
        T->nbr[6 * q + 2 * a + 1] = ta + 1 < T->nt[a] ? T->slot[t + stride] : -1;
        stride *= (size_t)T->nt[a];
    }
}

/* Tile t has a core tile among its 26 neighbours (and itself). */
static int near_core(const hv_dist_tiles *T, size_t t)
{
    int ti[3];
    size_t r = t;
    for (int a = 0; a < 3; a++) {
        ti[a] = (int)(r % (size_t)T->nt[a]);
        r /= (size_t)T->nt[a];
    }
    for (int dz = -1; dz <= 1; dz++)
        for (int dy = -1; dy <= 1; dy++)
            for (int dx = -1; dx <= 1; dx++) {
                int x = ti[0] + dx, y = ti[1] + dy, z = ti[2] + dz;
                if (x < 0 || y < 0 || z < 0 || x >= T->nt[0] || y >= T->nt[1] || z >= T->nt[2])
                    continue;
                size_t o = x + (size_t)T->nt[0] * (y + (size_t)T->nt[1] * z);
                if (T->slot[o] == -2)
                    return 1;
            }
    return 0;
}

/* Lists the core tiles (slot -2 while listing), then the halo. */
static void list_tiles(hv_dist_tiles *T)
{
    T->ncore = T->nlist = 0;
    for (size_t t = 0; t < T->count; t++) {
        int d = T->dist[t];
        T->slot[t] = -1;
        if (T->fluid[t] && d <= T->reach && (T->open_faces[t] > 0 || d <= 1)) {
            T->slot[t] = -2;
            T->list[T->ncore++] = (uint32_t)t;
        }
    }
    T->nlist = T->ncore;
    for (size_t t = 0; t < T->count; t++)
        if (T->slot[t] == -1 && T->fluid[t] && T->dist[t] <= T->reach + 1 && near_core(T, t))
            T->list[T->nlist++] = (uint32_t)t;
    for (size_t q = 0; q < T->nlist; q++)
        T->slot[T->list[q]] = (int32_t)q;
}

/* Room for the band's compact arrays. */
static hv_status band_room(hv_dist_tiles *T)
{
    size_t need = T->nlist * T->cells;
    if (need <= T->cap)
        return HV_OK;
    size_t cap = need + need / 4;
    hv_free(T->code);
    hv_free(T->f);
    for (int q = 0; q < 4; q++)
        hv_free(T->x[q]);
    T->code = hv_malloc(cap);
    T->f = hv_malloc(cap * sizeof *T->f);
    int bad = !T->code || !T->f;
    for (int q = 0; q < 4; q++)
        bad |= !(T->x[q] = hv_malloc(cap * sizeof *T->x[q]));
    T->cap = bad ? 0 : cap;
    if (bad)
        return hv__error(HV_ERR_NOMEM, "distance: out of memory for a band of %zu cells", need);
    return HV_OK;
}

hv_status hv__dist_band_select(hv_dist_box *b, uint8_t *ok)
{
    hv_dist_tiles *T = &b->tl;
    /* the previous stage's trusted cells are forgotten */
    const size_t nclear = ok ? T->ncore : 0;
#pragma omp parallel for schedule(dynamic, 16)
    for (size_t q = 0; q < nclear; q++) {
        int lo[3], len[3];
        hv__dist_tile_cells(b, T->list[q], lo, len);
        for (int k = lo[2]; k < lo[2] + len[2]; k++)
            for (int j = lo[1]; j < lo[1] + len[1]; j++)
                memset(ok + lo[0] + b->cs[1] * j + b->cs[2] * k, 0, (size_t)len[0]);
    }
    const int cap = T->reach + 2 < CAP ? T->reach + 2 : CAP;
    for (size_t t = 0; t < T->count; t++)
        T->dist[t] = T->front[t] ? 0 : (uint8_t)cap;
    dist_axis(T, T->dist, T->dist2, 0, cap);
    dist_axis(T, T->dist2, T->dist, 1, cap);
    dist_axis(T, T->dist, T->dist2, 2, cap);
    memcpy(T->dist, T->dist2, T->count);
    list_tiles(T);
    hv_status st = band_room(T);
    if (st)
        return st;
#pragma omp parallel for schedule(dynamic, 16)
    for (size_t q = 0; q < T->nlist; q++) {
        tile_neighbours(T, q);
        tile_codes(b, q);
    }
    return HV_OK;
}

/* Row pointers of listed tile q, row (ly, lz), into the band array x: the row
 * itself and its four transverse neighbour rows (zero_row where none). */
typedef struct band_rows {
    const double *ym, *yp, *zm, *zp;
    double xm, xp; /* the x-neighbours of the row's ends */
} band_rows;

static const double *nb_row(const hv_dist_tiles *T, const double *x, int32_t s, int ly, int lz)
{
    return s >= 0 ? x + (size_t)s * T->cells + (size_t)T->tn[0] * (ly + (size_t)T->tn[1] * lz)
                  : zero_row;
}

static inline void rows_of(const hv_dist_tiles *T, const double *x, size_t q, int ly, int lz,
                           band_rows *R)
{
    const int32_t *nb = T->nbr + 6 * q;
    const double *r = x + q * T->cells + (size_t)T->tn[0] * (ly + (size_t)T->tn[1] * lz);
    const int ty = T->tn[1], tz = T->tn[2], tx = T->tn[0];
    R->ym = ly > 0 ? r - tx : nb_row(T, x, nb[2], ty - 1, lz);
    R->yp = ly + 1 < ty ? r + tx : nb_row(T, x, nb[3], 0, lz);
    R->zm = lz > 0 ? r - (size_t)tx * ty : nb_row(T, x, nb[4], ly, tz - 1);
    R->zp = lz + 1 < tz ? r + (size_t)tx * ty : nb_row(T, x, nb[5], ly, 0);
    R->xm = nb[0] >= 0 ? nb_row(T, x, nb[0], ly, lz)[tx - 1] : 0;
    R->xp = nb[1] >= 0 ? nb_row(T, x, nb[1], ly, lz)[0] : 0;
}

/* The row's cells and their x-neighbours, as three rows of DIST_TILE. */
static inline void row_x(const double *r, const band_rows *R, double xl[DIST_TILE],
                         double xr[DIST_TILE])
{
    xl[0] = R->xm;
    xr[DIST_TILE - 1] = R->xp;
    for (int l = 1; l < DIST_TILE; l++) {
        xl[l] = r[l - 1];
        xr[l - 1] = r[l];
    }
}

/* One Chebyshev sweep on listed tile q: prev <- omega (cur + D^-1 (f - A cur)
 * - prev) + prev, on the unknowns (0 elsewhere). */
static void sweep_tile(const hv_dist_tiles *T, size_t q, const double *cur, double *prev, double s,
                       double omega)
{
    for (int lz = 0; lz < T->tn[2]; lz++)
        for (int ly = 0; ly < T->tn[1]; ly++) {
            band_rows R;
            rows_of(T, cur, q, ly, lz, &R);
            size_t o = q * T->cells + (size_t)DIST_TILE * (ly + (size_t)T->tn[1] * lz);
            const double *r = cur + o, *f = T->f + o;
            const uint8_t *code = T->code + o;
            double *p = prev + o, xl[DIST_TILE], xr[DIST_TILE];
            row_x(r, &R, xl, xr);
            for (int l = 0; l < DIST_TILE; l++) {
                double c = code[l], d = 1 + s * (c > 1 ? c - 1 : 0);
                double nb = xl[l] + xr[l] + R.ym[l] + R.yp[l] + R.zm[l] + R.zp[l];
                double v = omega * ((f[l] - (d * r[l] - s * nb)) / d + r[l] - p[l]) + p[l];
                p[l] = c > 0 ? v : 0;
            }
        }
}

#if defined(__x86_64__) && defined(__GNUC__)
#define SWEEP_SIMD 1
/* The rows of sweep_tile in vector registers: with AVX-512 a row of
 * DIST_TILE doubles in one register, the x-neighbours by lane shifts
 * (valignq) with the neighbour tiles' end cells; with AVX2 and FMA in two,
 * the same operations in the same order (the same values). */
__attribute__((target("avx512f,avx2"))) static inline void row_avx512(const double *cur,
                                                                      double *prev, const double *f,
                                                                      const band_rows *R, size_t o,
                                                                      __m512d c, __m512d vs,
                                                                      __m512d vo)
{
    const __m512d one = _mm512_set1_pd(1), zero = _mm512_setzero_pd();
    const __m512i x = _mm512_castpd_si512(_mm512_loadu_pd(cur + o));
    const __m512d xl =
        _mm512_castsi512_pd(_mm512_alignr_epi64(x, _mm512_castpd_si512(_mm512_set1_pd(R->xm)), 7));
    const __m512d xr =
        _mm512_castsi512_pd(_mm512_alignr_epi64(_mm512_castpd_si512(_mm512_set1_pd(R->xp)), x, 1));
    const __m512d d = _mm512_fmadd_pd(vs, _mm512_max_pd(_mm512_sub_pd(c, one), zero), one);
    __m512d nb = _mm512_add_pd(_mm512_add_pd(xl, xr),
                               _mm512_add_pd(_mm512_loadu_pd(R->ym), _mm512_loadu_pd(R->yp)));
    nb = _mm512_add_pd(nb, _mm512_add_pd(_mm512_loadu_pd(R->zm), _mm512_loadu_pd(R->zp)));
    const __m512d xc = _mm512_castsi512_pd(x), p = _mm512_loadu_pd(prev + o);
    const __m512d au = _mm512_fmsub_pd(d, xc, _mm512_mul_pd(vs, nb));
    const __m512d corr = _mm512_div_pd(_mm512_sub_pd(_mm512_loadu_pd(f + o), au), d);
    const __m512d v = _mm512_fmadd_pd(vo, _mm512_sub_pd(_mm512_add_pd(corr, xc), p), p);
    const __mmask8 known = _mm512_cmp_pd_mask(c, zero, _CMP_GT_OQ);
    _mm512_storeu_pd(prev + o, _mm512_maskz_mov_pd(known, v));
}

__attribute__((target("avx512f,avx2"))) static inline __m512d codes_avx512(const uint8_t *code)
{
    return _mm512_cvtepi32_pd(_mm256_cvtepu8_epi32(_mm_loadl_epi64((const __m128i *)code)));
}

/* Half a row (lanes h .. h + 3) of row_avx512's update with AVX2: xl and xr
 * the cells' x-neighbours. */
__attribute__((target("avx2,fma"))) static inline __m256d half_avx2(
    const double *xc_, const double *p_, const double *f_, const band_rows *R, int h, __m256d xl,
    __m256d xr, __m256d c, __m256d vs, __m256d vo)
{
    const __m256d one = _mm256_set1_pd(1), zero = _mm256_setzero_pd();
    const __m256d d = _mm256_fmadd_pd(vs, _mm256_max_pd(_mm256_sub_pd(c, one), zero), one);
    __m256d nb = _mm256_add_pd(_mm256_add_pd(xl, xr), _mm256_add_pd(_mm256_loadu_pd(R->ym + h),
                                                                    _mm256_loadu_pd(R->yp + h)));
    nb = _mm256_add_pd(nb, _mm256_add_pd(_mm256_loadu_pd(R->zm + h), _mm256_loadu_pd(R->zp + h)));
    const __m256d xc = _mm256_loadu_pd(xc_ + h), p = _mm256_loadu_pd(p_ + h);
    const __m256d au = _mm256_fmsub_pd(d, xc, _mm256_mul_pd(vs, nb));
    const __m256d corr = _mm256_div_pd(_mm256_sub_pd(_mm256_loadu_pd(f_ + h), au), d);
    const __m256d v = _mm256_fmadd_pd(vo, _mm256_sub_pd(_mm256_add_pd(corr, xc), p), p);
    return _mm256_and_pd(v, _mm256_cmp_pd(c, zero, _CMP_GT_OQ));
}

__attribute__((target("avx2,fma"))) static inline void row_avx2(const double *cur, double *prev,
                                                                const double *f, const band_rows *R,
                                                                size_t o, const __m256d c[2],
                                                                __m256d vs, __m256d vo)
{
    const double *r = cur + o;
    const __m256d lo = _mm256_loadu_pd(r), hi = _mm256_loadu_pd(r + 4);
    /* xl = (xm, r0, r1, r2 | r3 .. r6), xr = (r1 .. r4 | r5, r6, r7, xp) */
    const __m256d xl0 = _mm256_blend_pd(_mm256_permute4x64_pd(lo, 0x90), _mm256_set1_pd(R->xm), 1);
    const __m256d xr1 = _mm256_blend_pd(_mm256_permute4x64_pd(hi, 0xF9), _mm256_set1_pd(R->xp), 8);
    const __m256d v0 =
        half_avx2(r, prev + o, f + o, R, 0, xl0, _mm256_loadu_pd(r + 1), c[0], vs, vo);
    const __m256d v1 =
        half_avx2(r, prev + o, f + o, R, 4, _mm256_loadu_pd(r + 3), xr1, c[1], vs, vo);
    _mm256_storeu_pd(prev + o, v0);
    _mm256_storeu_pd(prev + o + 4, v1);
}

__attribute__((target("avx2,fma"))) static inline void codes_avx2(const uint8_t *code, __m256d c[2])
{
    const __m128i b = _mm_cvtepu8_epi32(_mm_loadl_epi64((const __m128i *)code));
    c[0] = _mm256_cvtepi32_pd(b);
    c[1] = _mm256_cvtepi32_pd(
        _mm_cvtepu8_epi32(_mm_srli_si128(_mm_loadl_epi64((const __m128i *)code), 4)));
}

/* sweep_tile, one register row at a time. */
__attribute__((target("avx512f,avx2"))) static void sweep_tile_avx512(const hv_dist_tiles *T,
                                                                      size_t q, const double *cur,
                                                                      double *prev, double s,
                                                                      double omega)
{
    const __m512d vs = _mm512_set1_pd(s), vo = _mm512_set1_pd(omega);
    for (int lz = 0; lz < T->tn[2]; lz++)
        for (int ly = 0; ly < T->tn[1]; ly++) {
            size_t o = q * T->cells + (size_t)DIST_TILE * (ly + (size_t)T->tn[1] * lz);
            band_rows R;
            rows_of(T, cur, q, ly, lz, &R);
            row_avx512(cur, prev, T->f, &R, o, codes_avx512(T->code + o), vs, vo);
        }
}

__attribute__((target("avx2,fma"))) static void sweep_tile_avx2(const hv_dist_tiles *T, size_t q,
                                                                const double *cur, double *prev,
                                                                double s, double omega)
{
    const __m256d vs = _mm256_set1_pd(s), vo = _mm256_set1_pd(omega);
    for (int lz = 0; lz < T->tn[2]; lz++)
        for (int ly = 0; ly < T->tn[1]; ly++) {
            size_t o = q * T->cells + (size_t)DIST_TILE * (ly + (size_t)T->tn[1] * lz);
            band_rows R;
            __m256d c[2];
            rows_of(T, cur, q, ly, lz, &R);
            codes_avx2(T->code + o, c);
            row_avx2(cur, prev, T->f, &R, o, c, vs, vo);
        }
}

/* Both right-hand sides' sweeps on listed tile q in one pass (the codes, the
 * weights and the row pointers read once): the same values as two sweeps. */
__attribute__((target("avx512f,avx2"))) static void sweep2_tile_avx512(
    const hv_dist_tiles *T, size_t q, double *const cur[2], double *const prev[2],
    const double s[2], const double omega[2])
{
    const __m512d vs0 = _mm512_set1_pd(s[0]), vo0 = _mm512_set1_pd(omega[0]);
    const __m512d vs1 = _mm512_set1_pd(s[1]), vo1 = _mm512_set1_pd(omega[1]);
    for (int lz = 0; lz < T->tn[2]; lz++)
        for (int ly = 0; ly < T->tn[1]; ly++) {
            size_t o = q * T->cells + (size_t)DIST_TILE * (ly + (size_t)T->tn[1] * lz);
            const __m512d c = codes_avx512(T->code + o);
            band_rows R;
            rows_of(T, cur[0], q, ly, lz, &R);
            row_avx512(cur[0], prev[0], T->f, &R, o, c, vs0, vo0);
            rows_of(T, cur[1], q, ly, lz, &R);
            row_avx512(cur[1], prev[1], T->f, &R, o, c, vs1, vo1);
        }
}

__attribute__((target("avx2,fma"))) static void sweep2_tile_avx2(const hv_dist_tiles *T, size_t q,
                                                                 double *const cur[2],
                                                                 double *const prev[2],
                                                                 const double s[2],
                                                                 const double omega[2])
{
    const __m256d vs0 = _mm256_set1_pd(s[0]), vo0 = _mm256_set1_pd(omega[0]);
    const __m256d vs1 = _mm256_set1_pd(s[1]), vo1 = _mm256_set1_pd(omega[1]);
    for (int lz = 0; lz < T->tn[2]; lz++)
        for (int ly = 0; ly < T->tn[1]; ly++) {
            size_t o = q * T->cells + (size_t)DIST_TILE * (ly + (size_t)T->tn[1] * lz);
            __m256d c[2];
            codes_avx2(T->code + o, c);
            band_rows R;
            rows_of(T, cur[0], q, ly, lz, &R);
            row_avx2(cur[0], prev[0], T->f, &R, o, c, vs0, vo0);
            rows_of(T, cur[1], q, ly, lz, &R);
            row_avx2(cur[1], prev[1], T->f, &R, o, c, vs1, vo1);
        }
}
#else
#define SWEEP_SIMD 0
#endif

/* Which rows run: 2 AVX-512, 1 AVX2 with FMA, 0 the baseline C, as the CPU
 * has them and HV_NO512 and HV_NOAVX2 allow, as for the multigrid's kernels
 * (asked from the calling thread). */
static int band_simd(void)
{
#if SWEEP_SIMD
    static int simd = -1;
    if (simd < 0) {
        const char *e5 = getenv("HV_NO512"), *e2 = getenv("HV_NOAVX2");
        const int no512 = e5 && *e5 && strcmp(e5, "0"), noavx2 = e2 && *e2 && strcmp(e2, "0");
        simd = __builtin_cpu_supports("avx512f") && !no512                                  ? 2
               : __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") && !noavx2 ? 1
                                                                                            : 0;
    }
    return simd;
#else
    return 0;
#endif
}

static void band_sweep(const hv_dist_tiles *T, const double *cur, double *prev, double s,
                       double omega)
{
    const int simd = band_simd();
#pragma omp parallel for schedule(static)
    for (size_t q = 0; q < T->nlist; q++) {
#if SWEEP_SIMD
        if (simd == 2) {
            sweep_tile_avx512(T, q, cur, prev, s, omega);
            continue;
        }
        if (simd == 1) {
            sweep_tile_avx2(T, q, cur, prev, s, omega);
            continue;
        }
#endif
        sweep_tile(T, q, cur, prev, s, omega);
    }
    (void)simd;
}

/* Both right-hand sides' sweeps: fused where the CPU has the vector rows. */
static void band_sweep2(const hv_dist_tiles *T, double *const cur[2], double *const prev[2],
                        const double s[2], const double omega[2])
{
#if SWEEP_SIMD
    const int simd = band_simd();
    if (simd) {
#pragma omp parallel for schedule(static)
        for (size_t q = 0; q < T->nlist; q++) {
            if (simd == 2)
                sweep2_tile_avx512(T, q, cur, prev, s, omega);
            else
                sweep2_tile_avx2(T, q, cur, prev, s, omega);
        }
        return;
    }
#endif
    for (int r = 0; r < 2; r++)
        band_sweep(T, cur[r], prev[r], s[r], omega[r]);
}

/* ||f - A x||^2 and ||f||^2 over the band. */
static void band_residual(const hv_dist_tiles *T, const double *x, double s, double out[2])
{
    double rr = 0, ff = 0;
#pragma omp parallel for schedule(static) reduction(+ : rr, ff)
    for (size_t q = 0; q < T->nlist; q++)
        for (int lz = 0; lz < T->tn[2]; lz++)
            for (int ly = 0; ly < T->tn[1]; ly++) {
                band_rows R;
                rows_of(T, x, q, ly, lz, &R);
                size_t o = q * T->cells + (size_t)DIST_TILE * (ly + (size_t)T->tn[1] * lz);
                double xl[DIST_TILE], xr[DIST_TILE];
                row_x(x + o, &R, xl, xr);
                for (int l = 0; l < DIST_TILE; l++) {
                    const uint8_t c = T->code[o + l];
                    if (!c)
                        continue;
                    double nb = xl[l] + xr[l] + R.ym[l] + R.yp[l] + R.zm[l] + R.zp[l];
                    double r = T->f[o + l] - ((1 + s * (c - 1)) * x[o + l] - s * nb);
                    rr += r * r;
                    ff += T->f[o + l] * T->f[o + l];
                }
            }
    out[0] = rr;
    out[1] = ff;
}

int hv__dist_band_sweeps(int dim, double s, double tol)
{
    /* the A-norm bound 2 c^k / (1 + c^2k), c = (sqrt(K) - 1) / (sqrt(K) + 1), K = 1 + 4 d s,
     * under tol; the residual measured after the sweeps is what the trust bound
     * takes (6e-14 against 1e-13 on a 64^2 x 48 wall) */
    const double K = 1 + 4 * dim * s, c = (sqrt(K) - 1) / (sqrt(K) + 1);
    int k = 1;
    while (2 * pow(c, k) / (1 + pow(c, 2 * k)) > tol && k < 2000)
        k++;
    return k;
}

double hv__dist_band_rho2(int dim, double s)
{
    const double rho = 1 - 1 / (1 + 2 * dim * s);
    return rho * rho;
}

double hv__dist_band_omega(double omega, double rho2, int k)
{
    return k == 0 ? 1 / (1 - rho2 / 2) : 1 / (1 - rho2 * omega / 4);
}

/* x[r] = (I - s[r] Lap)^-1 f on the band for both right-hand sides (the
 * results: out[r], one of T->x[2r], T->x[2r + 1]), sweeps[r] sweeps each; the
 * sweeps both need run in one pass. */
static void band_chebyshev(hv_dist_tiles *T, int dim, const double s[2], const int sweeps[2],
                           const double *out[2])
{
    const size_t n = T->nlist * T->cells;
    double *cur[2], *prev[2], omega[2] = {1, 1}, r2[2];
    for (int r = 0; r < 2; r++) {
        cur[r] = T->x[2 * r];
        prev[r] = T->x[2 * r + 1];
        memset(cur[r], 0, n * sizeof *cur[r]);
        memset(prev[r], 0, n * sizeof *prev[r]);
        r2[r] = hv__dist_band_rho2(dim, s[r]);
    }
    const int both = sweeps[0] < sweeps[1] ? sweeps[0] : sweeps[1];
    for (int k = 0; k < sweeps[0] || k < sweeps[1]; k++) {
        if (k < both)
            band_sweep2(T, cur, prev, s, omega);
        for (int r = 0; r < 2; r++) {
            if (k >= sweeps[r])
                continue;
            if (k >= both)
                band_sweep(T, cur[r], prev[r], s[r], omega[r]);
            double *t = cur[r];
            cur[r] = prev[r];
            prev[r] = t;
            omega[r] = hv__dist_band_omega(omega[r], r2[r], k);
        }
    }
    out[0] = cur[0];
    out[1] = cur[1];
}

/* The band's values of x onto the core tiles' cells of the whole-box array u. */
static void band_scatter(const hv_dist_box *b, const double *x, double *u)
{
    const hv_dist_tiles *T = &b->tl;
#pragma omp parallel for schedule(dynamic, 16)
    for (size_t q = 0; q < T->ncore; q++) {
        int lo[3], len[3];
        hv__dist_tile_cells(b, T->list[q], lo, len);
        for (int lz = 0; lz < len[2]; lz++)
            for (int ly = 0; ly < len[1]; ly++)
                memcpy(u + lo[0] + b->cs[1] * (lo[1] + ly) + b->cs[2] * (lo[2] + lz),
                       x + q * T->cells + (size_t)T->tn[0] * (ly + (size_t)T->tn[1] * lz),
                       (size_t)len[0] * sizeof *u);
    }
}

/* The source weights w onto the band array f. */
static void band_gather(const hv_dist_box *b, const double *w)
{
    const hv_dist_tiles *T = &b->tl;
#pragma omp parallel for schedule(dynamic, 16)
    for (size_t q = 0; q < T->nlist; q++) {
        int lo[3], len[3];
        hv__dist_tile_cells(b, T->list[q], lo, len);
        double *f = T->f + q * T->cells;
        memset(f, 0, T->cells * sizeof *f);
        for (int lz = 0; lz < len[2]; lz++)
            for (int ly = 0; ly < len[1]; ly++)
                memcpy(f + (size_t)T->tn[0] * (ly + (size_t)T->tn[1] * lz),
                       w + lo[0] + b->cs[1] * (lo[1] + ly) + b->cs[2] * (lo[2] + lz),
                       (size_t)len[0] * sizeof *f);
    }
}

hv_status hv__dist_band_solve(hv_dist_box *b, const double *w, double *u, double *u2, double tol,
                              hv_solve_info info[2])
{
    hv_dist_tiles *T = &b->tl;
    band_gather(b, w);
    const double s[2] = {1 / b->tau[0], 1 / b->tau[1]};
    const int sweeps[2] = {hv__dist_band_sweeps(b->dim, s[0], tol),
                           hv__dist_band_sweeps(b->dim, s[1], tol)};
    const double *x[2];
    band_chebyshev(T, b->dim, s, sweeps, x);
    for (int q = 0; q < 2; q++) {
        double r[2];
        band_residual(T, x[q], s[q], r);
        band_scatter(b, x[q], q ? u2 : u);
        memset(&info[q], 0, sizeof info[q]);
        info[q].iterations = sweeps[q];
        info[q].relres = r[1] > 0 ? sqrt(r[0] / r[1]) : 0;
        info[q].backend = HV_BACKEND_MG;
    }
    return HV_OK;
}

size_t hv__dist_band_cells(const hv_dist_box *b)
{
    const hv_dist_tiles *T = &b->tl;
    size_t n = 0;
    for (size_t q = 0; q < T->nlist; q++)
        n += (size_t)T->fluid[T->list[q]];
    return n;
}
