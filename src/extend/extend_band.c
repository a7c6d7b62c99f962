/* The band solve of the extension off a level set (extend_internal.h): the
 * first level's right-hand sides solved together on the cells near what is
 * read, by Chebyshev sweeps.
 *
 * For short diffusion times the first level's solutions matter only near the
 * cells that are read (closest-point stencils, cells read at themselves) and
 * the weights: (I - t Lap)^-1 decays like e^{-r / sqrt(t)}. On a narrow band
 * that is a small part of the box, so the first level solves on those cells
 * grown by BOX_MARGIN sqrt(t) voxels, rounded, only (u = 0 beyond: a
 * reflection of about e^{-2 BOX_MARGIN} of what reaches there, as for the
 * box's walls; 3 voxels at t = h^2/4, where the band and the box solves agree
 * to 6e-7 relative on a sphere), by Jacobi-preconditioned Chebyshev
 * iteration. The operator is diagonally dominant there (D^-1 A has its
 * spectrum in [1/(1+2ds), 2 - 1/(1+2ds)], s = t/h^2, d = dim), so a fixed
 * count of sweeps reaches the tolerance: no inner products, no hierarchy, one
 * streaming pass per sweep, and a solve that is linear in its right-hand side
 * (constants come back exactly). Float sweeps: the tolerance is
 * max(tol, BAND_TOL), a tenth of the extension's own error (3e-4 to 1e-3
 * relative; on the bunny at 256^3 its mean error reads the same to 4 digits at
 * 1e-5 and 3e-5).
 *
 * The sweep count and coefficients do not depend on the right-hand side, so
 * every right-hand side is swept at once. The band is stored compactly, x-run
 * after x-run with a zero ghost cell at each end, the R values of a cell side
 * by side (the layout of e->sol on that run, so results go out by memcpy).
 * Runs are cut into segments over which each transverse neighbour row is
 * wholly in the band or wholly out of it: a segment's cells and each of its
 * neighbour rows are then contiguous runs of len * R floats, and a sweep is a
 * flat vector loop per segment, its cost shared by all right-hand sides. One
 * right-hand side per sweep over x-runs of the whole grid was bound by the
 * latency of short runs scattered over the grid (3 ns a cell update). */
#include "extend_internal.h"
#include "core/error.h"

#include <math.h>
#include <omp.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define BAND_MAX_FRACTION 0.5 /* a band larger than this part of the box: the box solve */
#define BAND_TOL 3e-5
/* Smaller bands sweep on one thread (a barrier per sweep costs more). */
#define BAND_PAR_MIN 131072
/* Built for AVX2 and the baseline, picked at load time, as MG_KERNEL (GCC
 * only: clang's ThreadSanitizer instruments the load-time resolver, which then
 * runs before its runtime is up). */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define BAND_KERNEL __attribute__((target_clones("avx2", "default")))
#else
#define BAND_KERNEL
#endif

struct xrun {
    int j, k, x0, x1; /* row (j, k), cells x0 <= x < x1 */
};

static int band_layout(hv_extender *e, hv_extend_band *b, const size_t *first, int R);
static hv_status band_iterate(const hv_extender *e, hv_extend_band *b, double *thr,
                              hv_extend_stats *S);

/* Cells x0 .. x0 + len - 1 of one run (at compact cell `at`), whose neighbours
 * in rows j - 1, j + 1, k - 1, k + 1 start at compact cell nb[0..3] (the zero
 * block where that row has no band cell there or the grid ends), with one
 * diagonal d = 1 + s (neighbour count) for all of them. */
struct bseg {
    size_t at, nb[4];
    uint32_t len;
    float d;
};

int hv__extend_band_allowed(const hv_extender *e)
{
    return !e->solid && !e->o.box_only && e->o.t_scale <= BAND_MAX_T_SCALE &&
           (e->o.backend == HV_BACKEND_AUTO || e->o.backend == HV_BACKEND_MG);
}

int hv__extend_band_iters(const hv_extender *e, double s)
{
    /* Sweeps for the error bound 2 c^k / (1 + c^2k) <= tol, c = (sqrt(K) - 1) / (sqrt(K) + 1),
     * K = 1 + 4 d s the condition number of D^-1 A. */
    const double K = 1 + 4 * e->dim * s, c = (sqrt(K) - 1) / (sqrt(K) + 1);
    const double tol = fmax(e->o.tol, BAND_TOL);
    int k = 1;
    while (2 * pow(c, k) / (1 + pow(c, 2 * k)) > tol && k < 1000)
        k++;
    return k;
}

int hv__extend_band_level_allowed(const hv_extender *e, int l)
{
    return hv__extend_band_allowed(e) && e->o.t_scale * pow(LEVEL_FACTOR, l) <= BAND_MAX_T_SCALE;
}

int hv__extend_last_level(const hv_extender *e, double ob)
{
    /* An output cell lies within ob voxels of the zero set and the weights
     * reach `band` voxels from it: level l reaches sqrt(t_scale) 4^l voxels. */
    const double gap = ob - e->o.band;
    int l = 0;
    while (l + 1 < e->o.max_levels && sqrt(e->o.t_scale * pow(LEVEL_FACTOR, l)) < gap)
        l++;
    return l;
}

void hv__extend_band_free(hv_extend_band *b)
{
    free(b->runs);
    free(b->roff);
    free(b->segs);
    free(b->kstart);
    memset(b, 0, sizeof *b);
}

/* dst = src grown by m cells along x (box dilation, one axis). */
static void grow_x(uint8_t *dst, const uint8_t *src, const int n[3], int m)
{
    const long nl = (long)n[1] * n[2];
    const int nx = n[0];
#pragma omp parallel for schedule(static)
    for (long l = 0; l < nl; l++) {
        const uint8_t *s = src + (size_t)l * nx;
        uint8_t *d = dst + (size_t)l * nx;
        int last = -(1 << 29);
        for (int i = 0; i < nx; i++) {
            if (s[i])
                last = i;
            d[i] = (uint8_t)(i - last <= m);
        }
        last = 1 << 29;
        for (int i = nx - 1; i >= 0; i--) {
            if (s[i])
                last = i;
            if (last - i <= m)
                d[i] = 1;
        }
    }
}

/* dst = src grown by m rows: rows r = 0..nrows-1 of len contiguous bytes at
 * r * stride, in blocks of `outer` such groups `gstride` apart. A running count
 * of the set rows in the window [r - m, r + m], per byte: contiguous, so it
 * vectorizes (a strided scan per column would not). */
static void grow_rows(uint8_t *dst, const uint8_t *src, size_t len, int nrows, size_t stride,
                      long outer, size_t gstride, int m)
{
    const size_t chunk = 4096;
    const long nchunks = (long)((len + chunk - 1) / chunk);
#pragma omp parallel
    {
        uint8_t cnt[4096];
#pragma omp for collapse(2) schedule(static)
        for (long g = 0; g < outer; g++)
            for (long ch = 0; ch < nchunks; ch++) {
                const size_t x0 = (size_t)ch * chunk, w = len - x0 < chunk ? len - x0 : chunk;
                const uint8_t *s = src + (size_t)g * gstride + x0;
                uint8_t *d = dst + (size_t)g * gstride + x0;
                memset(cnt, 0, w);
                for (int r = 0; r < m && r < nrows; r++)
                    for (size_t x = 0; x < w; x++)
                        cnt[x] += s[(size_t)r * stride + x];
                for (int r = 0; r < nrows; r++) {
                    if (r + m < nrows)
                        for (size_t x = 0; x < w; x++)
                            cnt[x] += s[(size_t)(r + m) * stride + x];
                    if (r - m - 1 >= 0)
                        for (size_t x = 0; x < w; x++)
                            cnt[x] -= s[(size_t)(r - m - 1) * stride + x];
                    uint8_t *dr = d + (size_t)r * stride;
                    for (size_t x = 0; x < w; x++)
                        dr[x] = cnt[x] != 0;
                }
            }
    }
}

/* The segments of run q (rfirst: runs of grid row r are rfirst[r] ..
 * rfirst[r + 1] - 1). Writes them to out when out is non-NULL; returns their
 * count. */
static size_t run_segments(const hv_extender *e, const hv_extend_band *b, const size_t *rfirst,
                           size_t q, bseg *out)
{
    const xrun *r = &b->runs[q];
    const int nx = e->n[0], ny = e->n[1], nz = e->n[2];
    const int dj[4] = {-1, 1, 0, 0}, dk[4] = {0, 0, -1, 1};
    const int ndir = e->dim == 3 ? 4 : 2;
    size_t lo[4], hi[4];   /* runs of each neighbour row (lo == hi: none, or no row) */
    int exists[4], rc = 0; /* neighbour rows inside the grid: Neumann walls elsewhere */
    for (int d = 0; d < 4; d++) {
        int j = r->j + dj[d], k = r->k + dk[d];
        exists[d] = d < ndir && j >= 0 && j < ny && k >= 0 && k < nz;
        rc += exists[d];
        lo[d] = hi[d] = 0;
        if (exists[d]) {
            size_t row = (size_t)j + (size_t)ny * k;
            lo[d] = rfirst[row];
            hi[d] = rfirst[row + 1];
        }
    }
    /* Cut points: the run's ends, the cells next to the x walls (one neighbour
     * fewer), and the neighbour runs' ends inside the run. */
    int cut[64];
    int nc = 0, heap = 0;
    int *cuts = cut;
    size_t need = 4;
    for (int d = 0; d < 4; d++)
        need += 2 * (hi[d] - lo[d]);
    if (need > 64) {
        if (!(cuts = malloc(need * sizeof *cuts)))
            return (size_t)-1;
        heap = 1;
    }
    cuts[nc++] = r->x0;
    cuts[nc++] = r->x1;
    if (r->x0 == 0 && r->x1 > 1)
        cuts[nc++] = 1;
    if (r->x1 == nx && nx - 1 > r->x0)
        cuts[nc++] = nx - 1;
    for (int d = 0; d < 4; d++)
        for (size_t p = lo[d]; p < hi[d]; p++) {
            const xrun *o = &b->runs[p];
            if (o->x1 <= r->x0 || o->x0 >= r->x1)
                continue;
            if (o->x0 > r->x0)
                cuts[nc++] = o->x0;
            if (o->x1 < r->x1)
                cuts[nc++] = o->x1;
        }
    /* Sort (insertion: few cuts) and drop repeats. */
    for (int a = 1; a < nc; a++) {
        int v = cuts[a], z = a - 1;
        while (z >= 0 && cuts[z] > v) {
            cuts[z + 1] = cuts[z];
            z--;
        }
        cuts[z + 1] = v;
    }
    size_t ns = 0;
    size_t p[4];
    for (int d = 0; d < 4; d++)
        p[d] = lo[d];
    for (int a = 0; a + 1 < nc; a++) {
        const int xa = cuts[a], xb = cuts[a + 1];
        if (xb <= xa)
            continue;
        if (out) {
            bseg *g = &out[ns];
            g->at = b->roff[q] + 1 + (size_t)(xa - r->x0);
            g->len = (uint32_t)(xb - xa);
            g->d = (float)(1 + b->s * (rc + (xa > 0) + (xb < nx)));
            for (int d = 0; d < 4; d++) {
                /* Neighbour runs are sorted by x: advance to the first ending after xa. */
                while (p[d] < hi[d] && b->runs[p[d]].x1 <= xa)
                    p[d]++;
                const xrun *o = p[d] < hi[d] ? &b->runs[p[d]] : NULL;
                g->nb[d] = o && o->x0 <= xa ? b->roff[p[d]] + 1 + (size_t)(xa - o->x0) : b->zero;
            }
        }
        ns++;
    }
    if (heap)
        free(cuts);
    return ns;
}

/* Builds the band from b->need: grown, cut into x-runs and segments, laid out
 * compactly for R right-hand sides. Returns 0 (and frees nothing) when the
 * band is not worth it (more than BAND_MAX_FRACTION of box_cells), 1 when
 * built, -1 when out of memory. s: the diffusion time in units of h^2. */
int hv__extend_band_build(hv_extender *e, hv_extend_band *b, size_t box_cells, int R, double s)
{
    const int m = (int)lround(BOX_MARGIN * sqrt(s));
    if (!e->bg0 && !(e->bg0 = hv_malloc(e->count)))
        return -1;
    if (!e->bg1 && !(e->bg1 = hv_malloc(e->count)))
        return -1;
    uint8_t *g0 = e->bg0, *g1 = e->bg1;
    /* x, then y (rows of one plane), then z (planes); src values are 0/1 and
     * windows hold at most 2m + 1 <= 255 of them. */
    grow_x(g0, b->need, e->n, m);
    const size_t nx = (size_t)e->n[0], plane = nx * e->n[1];
    grow_rows(g1, g0, nx, e->n[1], nx, e->n[2], plane, m);
    uint8_t *dom = g1;
    if (e->dim == 3) {
        grow_rows(g0, g1, plane, e->n[2], plane, 1, 0, m);
        dom = g0;
    }
    /* Runs per row, then their offsets, then the runs, rows in parallel. */
    const size_t rows = (size_t)e->n[1] * e->n[2];
    size_t *first = malloc((rows + 1) * sizeof *first);
    if (!first)
        return -1;
    size_t cells = 0;
#pragma omp parallel for reduction(+ : cells) schedule(static)
    for (size_t r = 0; r < rows; r++) {
        const uint8_t *d = dom + r * e->n[0];
        size_t cr = 0, cc = 0;
        for (int x = 0; x < e->n[0]; x++) {
            cc += d[x];
            cr += d[x] && (x == 0 || !d[x - 1]);
        }
        first[r + 1] = cr;
        cells += cc;
    }
    first[0] = 0;
    for (size_t r = 0; r < rows; r++)
        first[r + 1] += first[r];
    const size_t nr = first[rows];
    if ((double)cells > BAND_MAX_FRACTION * (double)box_cells || !cells) {
        free(first);
        return 0;
    }
    b->runs = malloc(nr * sizeof *b->runs);
    b->roff = malloc(nr * sizeof *b->roff);
    if (!b->runs || !b->roff) {
        free(first);
        return -1;
    }
#pragma omp parallel for schedule(static)
    for (size_t r = 0; r < rows; r++) {
        const uint8_t *d = dom + r * e->n[0];
        size_t q = first[r];
        for (int x = 0; x < e->n[0]; x++)
            if (d[x] && (x == 0 || !d[x - 1])) {
                int x1 = x;
                while (x1 < e->n[0] && d[x1])
                    x1++;
                b->runs[q++] = (xrun){(int)(r % e->n[1]), (int)(r / e->n[1]), x, x1};
            }
    }
    b->nruns = nr;
    b->cells = cells;
    b->s = s;
    int rc = band_layout(e, b, first, R);
    free(first);
    return rc;
}

/* The second half of hv__extend_band_build: from b->runs, b->nruns, b->cells
 * and b->s, with first[r] .. first[r + 1] - 1 the runs of row r, lays out the
 * segments, the sweep count and the work arrays. 1 when built, -1 when out of
 * memory. */
static int band_layout(hv_extender *e, hv_extend_band *b, const size_t *first, int R)
{
    const size_t nr = b->nruns, nx = (size_t)e->n[0];
    size_t *sfirst = malloc((nr + 1) * sizeof *sfirst);
    if (!sfirst)
        return -1;
    b->R = R;
    /* Compact layout: each run between two ghost cells, then the zero block. */
    size_t at = 0;
    for (size_t q = 0; q < nr; q++) {
        b->roff[q] = at;
        at += (size_t)(b->runs[q].x1 - b->runs[q].x0) + 2;
    }
    b->zero = at;
    b->ncompact = at + nx;
    /* Segments: counted per run, then written at their offsets. */
    int oom = 0;
#pragma omp parallel for reduction(| : oom) schedule(static)
    for (size_t q = 0; q < nr; q++) {
        size_t c = run_segments(e, b, first, q, NULL);
        oom |= c == (size_t)-1;
        sfirst[q + 1] = c;
    }
    sfirst[0] = 0;
    for (size_t q = 0; q < nr && !oom; q++)
        sfirst[q + 1] += sfirst[q];
    if (oom || !(b->segs = malloc((sfirst[nr] ? sfirst[nr] : 1) * sizeof *b->segs))) {
        free(sfirst);
        return -1;
    }
#pragma omp parallel for reduction(| : oom) schedule(static)
    for (size_t q = 0; q < nr; q++)
        oom |= run_segments(e, b, first, q, b->segs + sfirst[q]) == (size_t)-1;
    b->nsegs = sfirst[nr];
    if (oom || !(b->kstart = malloc(((size_t)e->n[2] + 1) * sizeof *b->kstart))) {
        free(sfirst);
        return -1;
    }
    for (int k = 0, q = 0; k <= e->n[2]; k++) {
        while ((size_t)q < nr && b->runs[q].k < k)
            q++;
        b->kstart[k] = sfirst[q];
    }
    free(sfirst);
    b->iters = hv__extend_band_iters(e, b->s);
    /* Work arrays, kept by the extender across calls. */
    const size_t need = b->ncompact * (size_t)R;
    if (need > e->bcap) {
        hv_free(e->bf);
        hv_free(e->bu0);
        hv_free(e->bu1);
        e->bcap = 0;
        e->bf = hv_malloc(need * sizeof(float));
        e->bu0 = hv_malloc(need * sizeof(float));
        e->bu1 = hv_malloc(need * sizeof(float));
        if (!e->bf || !e->bu0 || !e->bu1) {
            hv_free(e->bf);
            hv_free(e->bu0);
            hv_free(e->bu1);
            e->bf = e->bu0 = e->bu1 = NULL;
            return -1;
        }
        e->bcap = need;
    }
    b->f = e->bf;
    b->u0 = e->bu0;
    b->u1 = e->bu1;
    /* Sweeps write run cells only: ghosts and the zero block stay 0. */
    const size_t Rb = (size_t)R * sizeof(float);
#pragma omp parallel for if (b->cells >= BAND_PAR_MIN) schedule(static)
    for (size_t q = 0; q < nr; q++) {
        const size_t g0 = b->roff[q] * R,
                     g1 = (b->roff[q] + 1 + (b->runs[q].x1 - b->runs[q].x0)) * R;
        memset(b->u0 + g0, 0, Rb);
        memset(b->u1 + g0, 0, Rb);
        memset(b->u0 + g1, 0, Rb);
        memset(b->u1 + g1, 0, Rb);
    }
    memset(b->u0 + b->zero * R, 0, nx * Rb);
    memset(b->u1 + b->zero * R, 0, nx * Rb);
    return 1;
}

/* One Chebyshev update of segment g for every right-hand side:
 * out = cur + a (cur - out) + c D^-1 (f - A cur) (out holds the previous
 * iterate on entry). */
static inline __attribute__((always_inline)) void band_seg(const hv_extend_band *b, const bseg *g,
                                                           const float *cur, float *out, float a,
                                                           float c)
{
    const size_t R = (size_t)b->R, n = (size_t)g->len * R;
    const float s = (float)b->s, d = g->d, cd = c / d;
    const float *restrict f = b->f + g->at * R;
    const float *restrict u = cur + g->at * R;
    const float *restrict n0 = cur + g->nb[0] * R, *restrict n1 = cur + g->nb[1] * R,
                          *restrict n2 = cur + g->nb[2] * R, *restrict n3 = cur + g->nb[3] * R;
    const float *restrict um = u - R, *restrict up = u + R;
    float *restrict o = out + g->at * R;
#pragma omp simd
    for (size_t y = 0; y < n; y++) {
        float sum = n0[y] + n1[y] + n2[y] + n3[y] + um[y] + up[y];
        o[y] = u[y] + a * (u[y] - o[y]) + cd * (f[y] - (d * u[y] - s * sum));
    }
}

/* Segments q0 .. q1 - 1 (with an AVX2 clone picked at load time where the CPU has it). */
BAND_KERNEL static void band_segs(const hv_extend_band *b, size_t q0, size_t q1, const float *cur,
                                  float *out, float a, float c)
{
    for (size_t q = q0; q < q1; q++)
        band_seg(b, &b->segs[q], cur, out, a, c);
}

/* One Chebyshev sweep on the band (every segment). */
static void band_sweep(const hv_extend_band *b, const float *cur, float *out, float a, float c)
{
#pragma omp parallel if (b->cells >= BAND_PAR_MIN)
    {
        const size_t nt = (size_t)omp_get_num_threads(), t = (size_t)omp_get_thread_num();
        band_segs(b, b->nsegs * t / nt, b->nsegs * (t + 1) / nt, cur, out, a, c);
    }
}

/* The first sweep from x0 = 0: x1 = c D^-1 f, and x0 = 0 (the previous
 * iterate of the second sweep) on the band's cells. */
static void band_first(const hv_extend_band *b, float *x0, float *x1, float c)
{
    const size_t R = (size_t)b->R;
#pragma omp parallel for if (b->cells >= BAND_PAR_MIN) schedule(static)
    for (size_t q = 0; q < b->nsegs; q++) {
        const bseg *g = &b->segs[q];
        const size_t n = (size_t)g->len * R;
        const float cd = c / g->d, *f = b->f + g->at * R;
        float *o = x1 + g->at * R, *z = x0 + g->at * R;
        for (size_t y = 0; y < n; y++) {
            o[y] = cd * f[y];
            z[y] = 0;
        }
    }
}

static void band_plane(const hv_extend_band *b, int p, const float *cur, float *out, float a,
                       float c)
{
    band_segs(b, b->kstart[p], b->kstart[p + 1], cur, out, a, c);
}

/* Two Chebyshev sweeps in one pass over memory (3D): plane p gets the first
 * (A -> B) and plane p - 1 the second (B -> A) right after, while its
 * neighbours are still in cache. Plane p - 1's old A values are read by the
 * first sweep of planes p - 2 .. p only, all done by then. Threads take slabs
 * of planes; a slab's first and last planes get their second sweep after a
 * barrier, when the neighbouring slabs' first sweeps are done. */
static void band_sweep2(const hv_extender *e, const hv_extend_band *b, float *A, float *B, float a1,
                        float c1, float a2, float c2)
{
    const int nz = e->n[2];
#pragma omp parallel if (b->cells >= BAND_PAR_MIN)
    {
        const int nt = omp_get_num_threads(), t = omp_get_thread_num();
        /* Slabs of about equal segment counts: [k0, k1), each starting at the
         * first plane whose segments begin at or after its share. */
        const size_t lo = b->nsegs * (size_t)t / nt, hi = b->nsegs * (size_t)(t + 1) / nt;
        int k0 = 0, k1 = nz;
        if (t > 0)
            while (k0 < nz && b->kstart[k0] < lo)
                k0++;
        if (t < nt - 1) {
            k1 = 0;
            while (k1 < nz && b->kstart[k1] < hi)
                k1++;
        }
        for (int p = k0; p < k1; p++) {
            band_plane(b, p, A, B, a1, c1);
            if (p - 1 >= k0 + 1)
                band_plane(b, p - 1, B, A, a2, c2);
        }
#pragma omp barrier
        if (k1 > k0) {
            band_plane(b, k0, B, A, a2, c2);
            if (k1 - 1 > k0)
                band_plane(b, k1 - 1, B, A, a2, c2);
        }
    }
}

/* Per right-hand side r: the residual's 2-norm r2[r] and max-norm rinf[r] on
 * the band, and the 2-norm f2[r] of the right-hand side. acc: 3 R doubles per
 * thread of scratch. */
static void band_residual(const hv_extend_band *b, const float *u, double *acc, double *r2,
                          double *rinf, double *f2)
{
    const int R = b->R;
    const double s = b->s;
    for (int r = 0; r < R; r++)
        r2[r] = rinf[r] = f2[r] = 0;
#pragma omp parallel if (b->cells >= BAND_PAR_MIN)
    {
        double *a = acc + 3 * (size_t)R * omp_get_thread_num();
        for (int r = 0; r < 3 * R; r++)
            a[r] = 0;
#pragma omp for schedule(static)
        for (size_t q = 0; q < b->nsegs; q++) {
            const bseg *g = &b->segs[q];
            const float *v = u + g->at * R, *f = b->f + g->at * R;
            const float *nb[4];
            for (int d = 0; d < 4; d++)
                nb[d] = u + g->nb[d] * R;
            hv__band_run_residual(v, f, nb, g->len, R, g->d, s, a);
        }
#pragma omp critical(hv_band_residual)
        for (int r = 0; r < R; r++) {
            r2[r] += a[r];
            rinf[r] = fmax(rinf[r], a[R + r]);
            f2[r] += a[2 * R + r];
        }
    }
    for (int r = 0; r < R; r++) {
        r2[r] = sqrt(r2[r]);
        f2[r] = sqrt(f2[r]);
    }
}

/* Every right-hand side on the band's cells, side by side, into b->f. */
static void build_rhs_band(const hv_extender *e, hv_extend_band *b, int nfields,
                           const hv_extend_field *f)
{
    const int R = b->R, nx = e->n[0];
    rhs_part parts[1 + 4 * MAX_FIELDS_PER_CALL];
    for (int r = 0; r < R; r++)
        parts[r] = rhs_locate(r, nfields, f);
#pragma omp parallel for if (b->cells >= BAND_PAR_MIN) schedule(static)
    for (size_t q = 0; q < b->nruns; q++) {
        const xrun *run = &b->runs[q];
        const size_t row = (size_t)nx * (run->j + (size_t)e->n[1] * run->k);
        float *dst = b->f + (b->roff[q] + 1) * R;
        for (int x = run->x0; x < run->x1; x++, dst += R) {
            const size_t c = row + x;
            if (!(e->w[c] > 0)) {
                for (int r = 0; r < R; r++)
                    dst[r] = 0;
                continue;
            }
            for (int r = 0; r < R; r++)
                dst[r] = (float)rhs_value(e, f, parts[r], c);
        }
    }
}

/* Level 0 on the band: every right-hand side at once by Chebyshev sweeps;
 * solutions stored interleaved on the band's cells (level 0 reads nothing
 * else: closest-point stencils and cells read at themselves are band cells).
 * thr as in hv__extend_solve_level, from the max-norm bound |u - u*| <= |r|_inf (A has
 * unit diagonal excess, ||A^-1||_inf <= 1). */
hv_status hv__extend_band_solve(hv_extender *e, hv_extend_band *b, int nfields,
                                const hv_extend_field *f, double *thr, hv_extend_stats *S)
{
    const int R = b->R;
    build_rhs_band(e, b, nfields, f);
    hv_status st = band_iterate(e, b, thr, S);
    if (st)
        return st;
    /* The compact layout of a run is e->sol's on that run. */
    const int nx = e->n[0];
#pragma omp parallel for if (b->cells >= BAND_PAR_MIN) schedule(static)
    for (size_t q = 0; q < b->nruns; q++) {
        const xrun *r = &b->runs[q];
        const size_t c0 = (size_t)nx * (r->j + (size_t)e->n[1] * r->k) + r->x0;
        memcpy(e->sol + c0 * R, b->sol + (b->roff[q] + 1) * R,
               (size_t)(r->x1 - r->x0) * R * sizeof(float));
    }
    return HV_OK;
}

/* The sweeps alone: every right-hand side in b->f solved, b->sol pointing at
 * the solutions; *thr as hv__extend_band_solve's. */
static hv_status band_iterate(const hv_extender *e, hv_extend_band *b, double *thr,
                              hv_extend_stats *S)
{
    const int R = b->R;
    const double theta = 1, delta = 1 - 1 / (1 + 2 * e->dim * b->s), sigma = theta / delta;
    double *nrm = malloc((3 + 3 * (size_t)omp_get_max_threads()) * R * sizeof *nrm);
    if (!nrm)
        return hv__error(HV_ERR_NOMEM, "extend: out of memory");
    float *cur = b->u0, *old = b->u1;
    /* x1 = D^-1 f / theta from x0 = 0. */
    band_first(b, old, cur, (float)(1 / theta));
    double rho = 1 / sigma;
    int it = 1;
    /* Pairs of sweeps in one pass (3D): cur stays the array of the newest iterate. */
    for (; e->dim == 3 && it + 1 < b->iters; it += 2) {
        double r1 = 1 / (2 * sigma - rho), r2 = 1 / (2 * sigma - r1);
        band_sweep2(e, b, cur, old, (float)(r1 * rho), (float)(2 * r1 / delta), (float)(r2 * r1),
                    (float)(2 * r2 / delta));
        rho = r2;
    }
    for (; it < b->iters; it++) {
        double rn = 1 / (2 * sigma - rho);
        band_sweep(b, cur, old, (float)(rn * rho), (float)(2 * rn / delta));
        rho = rn;
        float *t = cur;
        cur = old;
        old = t;
    }
    band_residual(b, cur, nrm + 3 * (size_t)R, nrm, nrm + R, nrm + 2 * R);
    double relmax = 0;
    for (int r = 0; r < R; r++)
        relmax = fmax(relmax, nrm[2 * R + r] > 0 ? nrm[r] / nrm[2 * R + r] : 0);
    const double rinf0 = nrm[R];
    free(nrm);
    b->sol = cur;
    S->solves += R;
    S->relres = fmax(S->relres, relmax);
    if (!S->solve_cells)
        S->solve_cells = b->cells;
    *thr = fmax(RELIABLE * rinf0, 1e-30);
    return HV_OK;
}
