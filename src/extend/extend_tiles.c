/* The extension off a narrow-band level set given as 8^3 tiles (heat.h,
 * hv_extend_tiles): hv_extend_many's pipeline on the band's cells alone, with
 * nothing of the block's size but a map of its tiles.
 *
 * 1. Classify: per tile of the level set, the weights (|phi| < band h), the
 *    output cells (active, |phi| < out_band h) and where each is read (its
 *    closest point, or itself), exactly as extend_eval.c does on a dense grid;
 *    the cells a solve must answer for are marked in bit masks of the tiles
 *    and their neighbours.
 * 2. Per diffusion level: the marked cells as x-runs per row, grown by
 *    BOX_MARGIN sqrt(t) voxels along x, y and z (unions of runs, never a
 *    mask of the block): the cells hv_extend_many's band solve takes. They
 *    are solved as a wave through the planes (extend_wave.c: the band
 *    solve's sweeps, a dozen planes held at a time) with the right-hand sides
 *    built from the tiles, and the solutions kept at the marked cells only.
 * 3. Per tile, every output cell reads its ratios from those solutions;
 *    cells a level does not reach go to the next, on their own band, and the
 *    levels stop at the first whose reach covers the output band.
 *
 * With the same cells, the same sweeps and the same reads, the values are
 * those of hv_extend_many on the dense block bit for bit (check_extend_tiles).
 * Cells of the block outside the tiles read as the level set's background
 * (the largest |phi| of the tiles) with the sign of the cell that looks at
 * them: no zero crossing lies between two neighbours unless both are within
 * a voxel of it, hence in a tile. */
#include "extend_internal.h"
#include "extend_cl.h"
#include "core/error.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define TS HV_TILE
#define TCELLS (HV_TILE * HV_TILE * HV_TILE)
/* Fewer tiles than this classify and evaluate on one thread. */
#define PAR_MIN_TILES 16

/* Kept by the extender between calls: the tile maps of the block. */
struct hv_extend_sparse {
    int tn[3];     /* tiles per axis */
    int32_t *map;  /* per tile of the block: the level set's tile + 1, 0 none */
    int32_t *cmap; /* per tile of the block: its marks' slot + 1, 0 none */
};

void hv__extend_sparse_destroy(struct hv_extend_sparse **sp)
{
    if (!sp || !*sp)
        return;
    free((*sp)->map);
    free((*sp)->cmap);
    free(*sp);
    *sp = NULL;
}

/* ---- sets of cells as x-runs per row ------------------------------------- */

typedef hv_xrows rowset;

static void rowset_free(rowset *s)
{
    hv_free(s->first);
    hv_free(s->x);
    memset(s, 0, sizeof *s);
}

static size_t rowset_cells(const rowset *s)
{
    size_t c = 0;
    for (size_t q = 0; q < s->nruns; q++)
        c += (size_t)(s->x[2 * q + 1] - s->x[2 * q]);
    return c;
}

typedef struct {
    int32_t *v;
    size_t n, cap;
} ibuf;

static int ibuf_push(ibuf *b, int32_t x0, int32_t x1)
{
    if (b->n + 2 > b->cap) {
        size_t cap = b->cap ? 2 * b->cap : 256;
        int32_t *v = realloc(b->v, cap * sizeof *v);
        if (!v)
            return -1;
        b->v = v;
        b->cap = cap;
    }
    b->v[b->n++] = x0;
    b->v[b->n++] = x1;
    return 0;
}

/* Merges the intervals of b (pairs, any order) in place: sorted, overlapping
 * and touching ones joined. Returns the pairs left. */
static size_t merge_intervals(ibuf *b)
{
    const size_t n = b->n / 2;
    int32_t *v = b->v;
    for (size_t a = 1; a < n; a++) { /* insertion: a handful of runs per row */
        int32_t x0 = v[2 * a], x1 = v[2 * a + 1];
        size_t z = a;
        while (z > 0 && v[2 * (z - 1)] > x0) {
            v[2 * z] = v[2 * (z - 1)];
            v[2 * z + 1] = v[2 * (z - 1) + 1];
            z--;
        }
        v[2 * z] = x0;
        v[2 * z + 1] = x1;
    }
    size_t m = 0;
    for (size_t a = 0; a < n; a++) {
        if (m && v[2 * a] <= v[2 * (m - 1) + 1]) {
            if (v[2 * a + 1] > v[2 * (m - 1) + 1])
                v[2 * (m - 1) + 1] = v[2 * a + 1];
            continue;
        }
        v[2 * m] = v[2 * a];
        v[2 * m + 1] = v[2 * a + 1];
        m++;
    }
    b->n = 2 * m;
    return m;
}

/* out = in grown by m cells along axis a (0: x, 1: y, 2: z), within the
 * block: per row, the union of the runs of the rows within m (y, z) or of its
 * own runs widened (x). Counted, then written. */
static hv_status rowset_grow(const int n[3], const rowset *in, rowset *out, int a, int m)
{
    const size_t rows = (size_t)n[1] * (in->k1 - in->k0);
    memset(out, 0, sizeof *out);
    out->k0 = in->k0;
    out->k1 = in->k1;
    if (!(out->first = hv_malloc((rows + 1) * sizeof *out->first)))
        return hv__error(HV_ERR_NOMEM, "extend: out of memory for the band's rows");
    int oom = 0;
    for (int pass = 0; pass < 2 && !oom; pass++) {
#pragma omp parallel reduction(| : oom)
        {
            ibuf b = {NULL, 0, 0};
#pragma omp for schedule(dynamic, 256)
            for (size_t r = 0; r < rows; r++) {
                const int j = (int)(r % n[1]), k = (int)(r / n[1]) + in->k0;
                b.n = 0;
                if (a == 0) {
                    for (size_t q = in->first[r]; q < in->first[r + 1] && !oom; q++) {
                        int x0 = in->x[2 * q] - m, x1 = in->x[2 * q + 1] + m;
                        oom |= ibuf_push(&b, x0 < 0 ? 0 : x0, x1 > n[0] ? n[0] : x1);
                    }
                } else {
                    const int c = a == 1 ? j : k, c0 = a == 1 ? 0 : in->k0,
                              c1 = a == 1 ? n[1] : in->k1;
                    const int lo = c - m < c0 ? c0 : c - m, hi = c + m >= c1 ? c1 - 1 : c + m;
                    for (int d = lo; d <= hi && !oom; d++) {
                        const size_t s = a == 1 ? (size_t)d + (size_t)n[1] * (k - in->k0)
                                                : (size_t)j + (size_t)n[1] * (d - in->k0);
                        for (size_t q = in->first[s]; q < in->first[s + 1] && !oom; q++)
                            oom |= ibuf_push(&b, in->x[2 * q], in->x[2 * q + 1]);
                    }
                }
                if (oom)
                    continue;
                const size_t cnt = merge_intervals(&b);
                if (pass == 0)
                    out->first[r + 1] = cnt;
                else if (cnt)
                    memcpy(out->x + 2 * out->first[r], b.v, 2 * cnt * sizeof *b.v);
            }
            free(b.v);
        }
        if (pass == 0 && !oom) {
            out->first[0] = 0;
            for (size_t r = 0; r < rows; r++)
                out->first[r + 1] += out->first[r];
            out->nruns = out->first[rows];
            if (!(out->x = hv_malloc((2 * out->nruns + 2) * sizeof *out->x)))
                oom = 1;
        }
    }
    if (oom) {
        rowset_free(out);
        return hv__error(HV_ERR_NOMEM, "extend: out of memory for the band's rows");
    }
    return HV_OK;
}

/* ---- the call's state ------------------------------------------------------ */

typedef struct {
    hv_extender *e;
    struct hv_extend_sparse *sp;
    const hv_tiles *P;
    int nfields, R; /* fields; right-hand sides (1 + per field 1 or ncomp + 1) */
    hv_extend_tiles_field *f;
    float bg;       /* the level set's background: the largest |phi| of the tiles */
    double bh, ob;  /* band and output band, world units (ob 0: every active voxel) */
    uint8_t *pend;  /* per tile cell: 0 done or not an output, 1 read at the closest
                       point, 2 at itself */
    size_t ncand;   /* tiles with marks: the level set's and their neighbours */
    int32_t *cand;  /* 3 per marked tile: its tile coordinates, sorted by (k, j, i) */
    uint64_t *mark; /* 8 per marked tile: the cells a level answers for */
    /* The fields at the weighted cells, compact: cell c of tile t (bit c of
     * smask[8 t ..]) has its nfc values (every component of every field) at
     * sval + (sbase[t] + rank of c) nfc. */
    uint64_t *smask;
    size_t *sbase;
    float *sval;
    int nfc;
} tctx;

static inline size_t tile_id(const struct hv_extend_sparse *sp, int ti, int tj, int tk)
{
    return (size_t)ti + (size_t)sp->tn[0] * ((size_t)tj + (size_t)sp->tn[1] * tk);
}

/* phi at block cell (i, j, k); ref: the value of the cell that looks (its
 * sign for cells outside the tiles). */
static inline float tphi(const tctx *x, int i, int j, int k, float ref)
{
    const int32_t t = x->sp->map[tile_id(x->sp, i >> 3, j >> 3, k >> 3)];
    if (!t)
        return copysignf(x->bg, ref);
    return x->P->v[(size_t)(t - 1) * TCELLS + (i & 7) + TS * (j & 7) + TS * TS * (k & 7)];
}

static inline void mark_cell(const tctx *x, int i, int j, int k)
{
    const int32_t s = x->sp->cmap[tile_id(x->sp, i >> 3, j >> 3, k >> 3)];
    if (!s)
        return; /* cannot happen: every cell a cell reads lies in a neighbouring tile */
    uint64_t *w = &x->mark[8 * (size_t)(s - 1) + (k & 7)];
    const uint64_t bit = (uint64_t)1 << ((i & 7) + TS * (j & 7));
    if (!(__atomic_load_n(w, __ATOMIC_RELAXED) & bit))
        __atomic_fetch_or(w, bit, __ATOMIC_RELAXED);
}

/* Where a cell is read: itself (m = 1) or 8 trilinear corners from c[]
 * stepping d[] along each axis. */
typedef struct {
    int m, c[3], d[3];
    double wt[8];
} tstencil;

static inline void stencil_self(tstencil *s, int i, int j, int k)
{
    s->m = 1;
    s->c[0] = i;
    s->c[1] = j;
    s->c[2] = k;
    s->d[0] = s->d[1] = s->d[2] = 0;
    s->wt[0] = 1;
}

static inline void corner(const tstencil *s, int q, int p[3])
{
    p[0] = s->c[0] + ((q & 1) ? s->d[0] : 0);
    p[1] = s->c[1] + ((q & 2) ? s->d[1] : 0);
    p[2] = s->c[2] + ((q & 4) ? s->d[2] : 0);
}

/* extend_eval.c's evaluation_point on the tiles, with the same arithmetic in
 * the same order (the dense and sparse paths read the same points). */
static int teval_point(const tctx *x, int i, int j, int k, float pc, int validate, tstencil *s)
{
    const hv_extender *e = x->e;
    stencil_self(s, i, j, k);
    if (!e->o.closest_point)
        return 0;
    const int nx = e->n[0], ny = e->n[1], nz = e->n[2];
    const int nn[3] = {nx, ny, nz};
    if (i > 0 && j > 0 && k > 0 && i + 1 < nx && j + 1 < ny && k + 1 < nz) {
        const double nb[6] = {tphi(x, i - 1, j, k, pc), tphi(x, i + 1, j, k, pc),
                              tphi(x, i, j - 1, k, pc), tphi(x, i, j + 1, k, pc),
                              tphi(x, i, j, k - 1, pc), tphi(x, i, j, k + 1, pc)};
        double p[3];
        if (!hv__ext_closest_point(pc, nb, e->h, i, j, k, p))
            return 0;
        int f[3];
        tstencil t = {8, {0, 0, 0}, {1, 1, 1}, {0}};
        if (!hv__ext_trilinear(p, nn, f, t.wt))
            return 0;
        memcpy(t.c, f, sizeof f);
        double v = 0;
        for (int q = 0; q < 8; q++) {
            int c[3];
            corner(&t, q, c);
            v += t.wt[q] * tphi(x, c[0], c[1], c[2], pc);
        }
        if (validate && fabs(v) > 0.5 * fmax(e->o.band, 1.0) * e->h)
            return 0;
        *s = t;
        return 1;
    }
    /* At the block's walls: one-sided differences (grad_phi) and a clamped
     * stencil (stencil), as extend_eval.c. */
    const int ijk[3] = {i, j, k};
    double g[3] = {0, 0, 0}, gn = 0;
    for (int up = 0; up < 2; up++) { /* central, then upwind (phi_diff2) */
        for (int a = 0; a < 3; a++) {
            int lo = ijk[a] > 0, hi = ijk[a] + 1 < nn[a];
            g[a] = 0;
            if (!lo && !hi)
                continue;
            int pp[3] = {i, j, k}, pm[3] = {i, j, k};
            pp[a] += 1;
            pm[a] -= 1;
            double vp = hi ? tphi(x, pp[0], pp[1], pp[2], pc) : pc,
                   vm = lo ? tphi(x, pm[0], pm[1], pm[2], pc) : pc;
            g[a] = lo && hi ? phi_diff2(pc, vm, vp, up) / (2 * e->h) : (vp - vm) / e->h;
        }
        gn = 0;
        for (int a = 0; a < 3; a++)
            gn += g[a] * g[a];
        gn = sqrt(gn);
        if (gn >= GRAD_MIN && gn <= GRAD_MAX)
            break;
    }
    if (!(gn >= GRAD_MIN && gn <= GRAD_MAX))
        return 0;
    double sv = pc / (gn * e->h), p[3] = {i, j, k};
    for (int a = 0; a < 3; a++) {
        p[a] -= sv * g[a];
        if (p[a] < -0.5 || p[a] > nn[a] - 0.5)
            return 0;
    }
    tstencil t = {8, {0, 0, 0}, {0, 0, 0}, {0}};
    double fr[3];
    hv__ext_clamped(3, nn, p, t.c, t.d, fr);
    double v = 0;
    for (int q = 0; q < 8; q++) {
        t.wt[q] = ((q & 1) ? fr[0] : 1 - fr[0]) * ((q & 2) ? fr[1] : 1 - fr[1]) *
                  ((q & 4) ? fr[2] : 1 - fr[2]);
    }
    for (int q = 0; q < 8; q++) {
        int c[3];
        corner(&t, q, c);
        v += t.wt[q] * tphi(x, c[0], c[1], c[2], pc);
    }
    if (validate && fabs(v) > 0.5 * fmax(e->o.band, 1.0) * e->h)
        return 0;
    *s = t;
    return 1;
}

/* The weight of a cell of value v, as hv__extend_classify stores it. */
static inline float weight_of(const tctx *x, float v)
{
    const double s = v / x->bh;
    return fabs(s) < 1 ? (float)((1 - s * s) * (1 - s * s)) : 0.0f;
}

/* ---- classification --------------------------------------------------------- */

static int cmp_tiles(const void *pa, const void *pb)
{
    const int32_t *a = pa, *b = pb;
    for (int d = 2; d >= 0; d--)
        if (a[d] != b[d])
            return a[d] < b[d] ? -1 : 1;
    return 0;
}

/* The marked tiles: the level set's and their neighbours within D tiles (a
 * closest point lies |phi| / h voxels from its cell, its stencil one more),
 * sorted by (k, j, i), with their slots in sp->cmap. */
static hv_status make_candidates(tctx *x, int D)
{
    struct hv_extend_sparse *sp = x->sp;
    const hv_tiles *P = x->P;
    const size_t side = 2 * (size_t)D + 1;
    size_t cap = side * side * side * P->count, nc = 0;
    int32_t *cand = hv_malloc((cap ? cap : 1) * 3 * sizeof *cand);
    if (!cand)
        return hv__error(HV_ERR_NOMEM, "extend: out of memory for the tiles' marks");
    for (size_t t = 0; t < P->count; t++) {
        const int ti = P->ijk[3 * t] / TS, tj = P->ijk[3 * t + 1] / TS, tk = P->ijk[3 * t + 2] / TS;
        for (int dk = -D; dk <= D; dk++)
            for (int dj = -D; dj <= D; dj++)
                for (int di = -D; di <= D; di++) {
                    const int a = ti + di, b = tj + dj, c = tk + dk;
                    if (a < 0 || b < 0 || c < 0 || a >= sp->tn[0] || b >= sp->tn[1] ||
                        c >= sp->tn[2])
                        continue;
                    int32_t *s = &sp->cmap[tile_id(sp, a, b, c)];
                    if (*s)
                        continue;
                    *s = -1;
                    cand[3 * nc] = a;
                    cand[3 * nc + 1] = b;
                    cand[3 * nc + 2] = c;
                    nc++;
                }
    }
    qsort(cand, nc, 3 * sizeof *cand, cmp_tiles);
    for (size_t q = 0; q < nc; q++)
        sp->cmap[tile_id(sp, cand[3 * q], cand[3 * q + 1], cand[3 * q + 2])] = (int32_t)(q + 1);
    x->cand = cand;
    x->ncand = nc;
    if (!(x->mark = hv_calloc(nc ? 8 * nc : 1, sizeof *x->mark)))
        return hv__error(HV_ERR_NOMEM, "extend: out of memory for the tiles' marks");
    return HV_OK;
}

/* The marked cells as runs per row: the marked tiles of one row of tiles are
 * consecutive, so each of its 64 cell rows is read tile by tile. */
static hv_status marks_to_rows(const tctx *x, int m, rowset *out)
{
    const hv_extender *e = x->e;
    memset(out, 0, sizeof *out);
    /* The planes the marks can grow into. */
    int kmin = x->ncand ? TS * x->cand[2] : 0, kmax = x->ncand ? TS * x->cand[3 * x->ncand - 1] : 0;
    out->k0 = kmin - m < 0 ? 0 : kmin - m;
    out->k1 = kmax + TS + m > e->n[2] ? e->n[2] : kmax + TS + m;
    const size_t rows = (size_t)e->n[1] * (out->k1 - out->k0);
    /* Rows of tiles: runs of candidates with the same (tj, tk). */
    size_t ng = 0;
    size_t *gstart = hv_malloc((x->ncand + 1) * sizeof *gstart);
    if (!gstart || !(out->first = hv_calloc(rows + 1, sizeof *out->first))) {
        hv_free(gstart);
        return hv__error(HV_ERR_NOMEM, "extend: out of memory for the band's rows");
    }
    for (size_t q = 0; q < x->ncand; q++)
        if (!q || x->cand[3 * q + 1] != x->cand[3 * (q - 1) + 1] ||
            x->cand[3 * q + 2] != x->cand[3 * (q - 1) + 2])
            gstart[ng++] = q;
    gstart[ng] = x->ncand;
    for (int pass = 0; pass < 2; pass++) {
#pragma omp parallel for schedule(dynamic, 16)
        for (size_t g = 0; g < ng; g++) {
            const int tj = x->cand[3 * gstart[g] + 1], tk = x->cand[3 * gstart[g] + 2];
            for (int kk = 0; kk < TS; kk++)
                for (int jj = 0; jj < TS; jj++) {
                    const int j = TS * tj + jj, k = TS * tk + kk;
                    if (j >= e->n[1] || k >= e->n[2])
                        continue;
                    const size_t r = (size_t)j + (size_t)e->n[1] * (k - out->k0);
                    size_t cnt = 0;
                    int32_t *dst = pass ? out->x + 2 * out->first[r] : NULL;
                    int open = 0;
                    int32_t x0 = 0, x1 = 0;
                    for (size_t q = gstart[g]; q < gstart[g + 1]; q++) {
                        const unsigned byte = (unsigned)(x->mark[8 * q + kk] >> (TS * jj)) & 0xffu;
                        if (!byte)
                            continue;
                        const int base = TS * x->cand[3 * q];
                        for (int b = 0; b < TS; b++) {
                            if (!(byte >> b & 1))
                                continue;
                            const int xc = base + b;
                            if (open && xc == x1) {
                                x1++;
                                continue;
                            }
                            if (open) {
                                if (dst) {
                                    dst[2 * cnt] = x0;
                                    dst[2 * cnt + 1] = x1;
                                }
                                cnt++;
                            }
                            open = 1;
                            x0 = xc;
                            x1 = xc + 1;
                        }
                    }
                    if (open) {
                        if (dst) {
                            dst[2 * cnt] = x0;
                            dst[2 * cnt + 1] = x1;
                        }
                        cnt++;
                    }
                    if (!pass)
                        out->first[r + 1] = cnt;
                }
        }
        if (!pass) {
            for (size_t r = 0; r < rows; r++)
                out->first[r + 1] += out->first[r];
            out->nruns = out->first[rows];
            if (!(out->x = hv_malloc((2 * out->nruns + 2) * sizeof *out->x))) {
                hv_free(gstart);
                rowset_free(out);
                return hv__error(HV_ERR_NOMEM, "extend: out of memory for the band's rows");
            }
        }
    }
    hv_free(gstart);
    return HV_OK;
}

/* Block cell of tile t's cell o. */
static inline void cell_of(const hv_tiles *P, size_t t, int o, int *i, int *j, int *k)
{
    *i = P->ijk[3 * t] + (o & 7);
    *j = P->ijk[3 * t + 1] + ((o >> 3) & 7);
    *k = P->ijk[3 * t + 2] + (o >> 6);
}

/* hv__extend_classify on the tiles: pend, the marks of level 0, the counts.
 * HV_ERR_NUMERIC for a non-finite field value where it is read. */
static hv_status classify(tctx *x, size_t *nsrc_out, size_t *npend_out)
{
    const hv_extender *e = x->e;
    const hv_tiles *P = x->P;
    size_t nsrc = 0, npend = 0, badf = SIZE_MAX;
#pragma omp parallel for reduction(+ : nsrc, npend) reduction(min : badf)                    \
    schedule(dynamic, 8) if (P->count >= PAR_MIN_TILES)
    for (size_t t = 0; t < P->count; t++) {
        const float *pv = P->v + t * TCELLS;
        uint8_t *pd = x->pend + t * TCELLS;
        for (int o = 0; o < TCELLS; o++) {
            int i, j, k;
            cell_of(P, t, o, &i, &j, &k);
            pd[o] = 0;
            if (i >= e->n[0] || j >= e->n[1] || k >= e->n[2])
                continue;
            const float v = pv[o];
            if (fabs(v / x->bh) < 1) {
                nsrc++;
                for (int fi = 0; fi < x->nfields; fi++)
                    for (int q = 0; q < x->f[fi].ncomp; q++)
                        if (!isfinite(x->f[fi].v[q]->v[t * TCELLS + o]) && t * TCELLS + o < badf)
                            badf = t * TCELLS + o;
                mark_cell(x, i, j, k);
                if (weight_of(x, v) > 0)
                    x->smask[8 * t + (o >> 6)] |= (uint64_t)1 << (o & 63);
            }
            const int on = (int)(P->on[8 * t + (o >> 6)] >> (o & 63) & 1);
            if (!on || (x->ob > 0 && !(fabs(v) < x->ob)))
                continue;
            tstencil s;
            pd[o] = teval_point(x, i, j, k, v, 1, &s) ? 1 : 2;
            npend++;
            for (int q = 0; q < s.m; q++) {
                int c[3];
                corner(&s, q, c);
                mark_cell(x, c[0], c[1], c[2]);
            }
        }
    }
    if (badf != SIZE_MAX) {
        int i, j, k;
        cell_of(P, badf / TCELLS, (int)(badf % TCELLS), &i, &j, &k);
        for (int fi = 0; fi < x->nfields; fi++)
            for (int q = 0; q < x->f[fi].ncomp; q++)
                if (!isfinite(x->f[fi].v[q]->v[badf]))
                    return hv__error(HV_ERR_NUMERIC,
                                     "extend: field %d component %d is NaN/Inf at cell (%d, %d, "
                                     "%d), inside the source band",
                                     fi, q, i, j, k);
    }
    *nsrc_out = nsrc;
    *npend_out = npend;
    return HV_OK;
}

/* ---- one level ---------------------------------------------------------------- */

/* The right-hand sides of cells x0 .. x1 - 1 of row (j, k), side by side, as
 * build_rhs_band (extend_band.c) makes them from the dense arrays
 * (hv_extend_rhs_fn). */
static void row_rhs(const void *ctx, int j, int k, int x0, int x1, float *dst)
{
    const tctx *x = ctx;
    const struct hv_extend_sparse *sp = x->sp;
    int r = 0;
    for (int i = x0; i < x1; i++) {
        const int32_t t = sp->map[tile_id(sp, i >> 3, j >> 3, k >> 3)];
        const int o = (i & 7) + TS * (j & 7) + TS * TS * (k & 7);
        const uint64_t word = t ? x->smask[8 * (size_t)(t - 1) + (o >> 6)] : 0;
        if (!(word >> (o & 63) & 1)) {
            for (int q = 0; q < x->R; q++)
                dst[r++] = 0;
            continue;
        }
        const size_t tt = (size_t)(t - 1);
        size_t rank = x->sbase[tt];
        for (int q = 0; q < (o >> 6); q++)
            rank += (size_t)__builtin_popcountll(x->smask[8 * tt + q]);
        rank += (size_t)__builtin_popcountll(word & (((uint64_t)1 << (o & 63)) - 1));
        const float *in = x->sval + rank * x->nfc;
        const double w = weight_of(x, x->P->v[tt * TCELLS + o]);
        dst[r++] = (float)w;
        for (int fi = 0; fi < x->nfields; fi++) {
            const int nc = x->f[fi].ncomp;
            if (nc == 1) {
                dst[r++] = (float)(w * in[0]);
                in++;
                continue;
            }
            double m = 0;
            for (int p = 0; p < nc; p++)
                m += (double)in[p] * in[p];
            dst[r++] = (float)(w * sqrt(m));
            for (int p = 0; p < nc; p++)
                dst[r++] = (float)(w * in[p]);
            in += nc;
        }
    }
}

/* The fields' values at the weighted cells, compact (tctx), then the fields
 * reset to the background, inactive, for the outputs. */
static hv_status gather_sources(tctx *x)
{
    const hv_tiles *P = x->P;
    x->sbase = hv_malloc((P->count + 1) * sizeof *x->sbase);
    if (!x->sbase)
        return hv__error(HV_ERR_NOMEM, "extend: out of memory");
    size_t n = 0;
    for (size_t t = 0; t < P->count; t++) {
        x->sbase[t] = n;
        for (int q = 0; q < 8; q++)
            n += (size_t)__builtin_popcountll(x->smask[8 * t + q]);
    }
    x->sbase[P->count] = n;
    if (!(x->sval = hv_malloc((n ? n : 1) * (size_t)x->nfc * sizeof *x->sval)))
        return hv__error(HV_ERR_NOMEM, "extend: out of memory for the fields at %zu cells", n);
    const float bg = x->e->o.background;
#pragma omp parallel for schedule(dynamic, 16) if (P->count >= PAR_MIN_TILES)
    for (size_t t = 0; t < P->count; t++) {
        float *dst = x->sval + x->sbase[t] * x->nfc;
        for (int o = 0; o < TCELLS; o++) {
            if (!(x->smask[8 * t + (o >> 6)] >> (o & 63) & 1))
                continue;
            for (int fi = 0; fi < x->nfields; fi++)
                for (int q = 0; q < x->f[fi].ncomp; q++)
                    *dst++ = x->f[fi].v[q]->v[t * TCELLS + o];
        }
        for (int fi = 0; fi < x->nfields; fi++)
            for (int q = 0; q < x->f[fi].ncomp; q++) {
                hv_tiles *F = x->f[fi].v[q];
                for (int o = 0; o < TCELLS; o++)
                    F->v[t * TCELLS + o] = bg;
                memset(F->on + 8 * t, 0, 8 * sizeof *F->on);
            }
    }
    return HV_OK;
}

/* sample_all (extend_eval.c) from the solutions at need's cells (sol, R per
 * cell from nprefix[q] for need's run q): corners off need read 0. */
static void tsample(const tctx *x, const rowset *need, const size_t *nprefix, const float *sol,
                    const tstencil *s, double *out)
{
    const int R = x->R;
    for (int r = 0; r < R; r++)
        out[r] = 0;
    for (int q = 0; q < s->m; q++) {
        int c[3];
        corner(s, q, c);
        const long run = hv__xrows_find(need, x->e->n[1], c[1], c[2], c[0]);
        if (run < 0)
            continue;
        const float *v = sol + (nprefix[run] + (size_t)(c[0] - need->x[2 * run])) * R;
        for (int r = 0; r < R; r++)
            out[r] += s->wt[q] * v[r];
    }
}

/* write_cell (extend_eval.c) into tile cell tc. */
static void twrite(const tctx *x, size_t tc, const double *val)
{
    const double W = val[0];
    int r = 1;
    for (int i = 0; i < x->nfields; i++) {
        const hv_extend_tiles_field *F = &x->f[i];
        if (F->ncomp == 1) {
            F->v[0]->v[tc] = (float)(val[r] / W);
            r++;
            continue;
        }
        double mag = val[r] / W, v[3] = {0, 0, 0}, vn = 0;
        for (int q = 0; q < F->ncomp; q++) {
            v[q] = val[r + 1 + q];
            vn += v[q] * v[q];
        }
        vn = sqrt(vn);
        for (int q = 0; q < F->ncomp; q++)
            F->v[q]->v[tc] = vn > 0 ? (float)(mag * v[q] / vn) : 0.0f;
        r += F->ncomp + 1;
    }
}

/* hv__extend_eval_level on the tiles; the cells left are marked for the next
 * level (the marks must be clear on entry). */
static void eval_level(tctx *x, const rowset *need, const size_t *nprefix, const float *sol,
                       int trusted, double thr, int last, hv_extend_counts *n)
{
    const hv_tiles *P = x->P;
    const hv_extender *e = x->e;
    size_t left = 0, cp = 0, ratio = 0, weak = 0;
#pragma omp parallel for reduction(+ : left, cp, ratio, weak) schedule(dynamic, 8)          \
    if (P->count >= PAR_MIN_TILES)
    for (size_t t = 0; t < P->count; t++) {
        uint8_t *pd = x->pend + t * TCELLS;
        for (int o = 0; o < TCELLS; o++) {
            if (!pd[o])
                continue;
            int i, j, k;
            cell_of(P, t, o, &i, &j, &k);
            const float pc = P->v[t * TCELLS + o];
            tstencil s;
            stencil_self(&s, i, j, k);
            int at_cp = 0;
            if (pd[o] == 1)
                at_cp = teval_point(x, i, j, k, pc, 0, &s);
            double val[1 + 4 * MAX_FIELDS_PER_CALL];
            tsample(x, need, nprefix, sol, &s, val);
            double W = val[0];
            if (!(W > thr) && at_cp) {
                at_cp = 0;
                pd[o] = 2;
                stencil_self(&s, i, j, k);
                if (trusted && hv__xrows_find(need, e->n[1], j, k, i) < 0) {
                    W = 0;
                } else {
                    tsample(x, need, nprefix, sol, &s, val);
                    W = val[0];
                }
            }
            if (!(W > thr) && !last) {
                left++;
                mark_cell(x, i, j, k);
                continue;
            }
            const size_t tc = t * TCELLS + o;
            if (!(W > 0)) {
                for (int fi = 0; fi < x->nfields; fi++)
                    for (int q = 0; q < x->f[fi].ncomp; q++)
                        x->f[fi].v[q]->v[tc] = e->o.background;
            } else {
                twrite(x, tc, val);
            }
            for (int fi = 0; fi < x->nfields; fi++)
                for (int q = 0; q < x->f[fi].ncomp; q++)
                    x->f[fi].v[q]->on[8 * t + (o >> 6)] |= (uint64_t)1 << (o & 63);
            weak += !(W > thr);
            cp += at_cp;
            ratio += !at_cp;
            pd[o] = 0;
        }
    }
    n->left = left;
    n->cp = cp;
    n->ratio = ratio;
    n->weak = weak;
}

/* Level l: the marked cells grown into a band, solved as a wave, read. */
static hv_status run_level(tctx *x, int l, int last, hv_extend_stats *S, hv_extend_counts *cnt)
{
    hv_extender *e = x->e;
    const double s = e->o.t_scale * pow(LEVEL_FACTOR, l);
    const int m = (int)lround(BOX_MARGIN * sqrt(s));
    double t0 = hv_now();
    rowset need, g1, g2, dom;
    memset(&g1, 0, sizeof g1);
    memset(&g2, 0, sizeof g2);
    memset(&dom, 0, sizeof dom);
    size_t *nprefix = NULL;
    float *sol = NULL;
    hv_status st = marks_to_rows(x, m, &need);
    if (!st)
        st = rowset_grow(e->n, &need, &g1, 0, m);
    if (!st)
        st = rowset_grow(e->n, &g1, &g2, 1, m);
    rowset_free(&g1);
    if (!st)
        st = rowset_grow(e->n, &g2, &dom, 2, m);
    rowset_free(&g2);
    if (st)
        goto done;
    /* The solutions are kept at need's cells only: the cells read. */
    const size_t ncells = rowset_cells(&need);
    nprefix = hv_malloc((need.nruns ? need.nruns : 1) * sizeof *nprefix);
    sol = hv_malloc((ncells ? ncells : 1) * (size_t)x->R * sizeof *sol);
    if (!nprefix || !sol) {
        st =
            hv__error(HV_ERR_NOMEM, "extend: out of memory for the solutions at %zu cells", ncells);
        goto done;
    }
    for (size_t q = 0, c = 0; q < need.nruns; q++) {
        nprefix[q] = c;
        c += (size_t)(need.x[2 * q + 1] - need.x[2 * q]);
    }
    if (l == 0)
        S->solve_cells = rowset_cells(&dom);
    double thr;
    size_t work = 0;
    {
        hv_extend_stats W;
        memset(&W, 0, sizeof W);
        if ((st = hv__extend_wave_solve(e, &dom, &need, s, x->R, row_rhs, x, sol, &thr, &W)))
            goto done;
        S->solves += W.solves;
        S->relres = fmax(S->relres, W.relres);
        work = W.work_bytes + ncells * (size_t)x->R * sizeof *sol +
               (need.nruns + dom.nruns) * 2 * sizeof(int32_t) +
               2 * ((size_t)e->n[1] * (dom.k1 - dom.k0) + 1) * sizeof(size_t);
        if (work > S->work_bytes)
            S->work_bytes = work;
    }
    rowset_free(&dom);
    S->t_solve += hv_now() - t0;
    t0 = hv_now();
    memset(x->mark, 0, 8 * x->ncand * sizeof *x->mark);
    eval_level(x, &need, nprefix, sol, l == 0, thr, last, cnt);
    S->t_eval += hv_now() - t0;
done:
    hv_free(nprefix);
    hv_free(sol);
    rowset_free(&need);
    rowset_free(&dom);
    return st;
}

/* ---- the call ------------------------------------------------------------------- */

static hv_status check_tiles(const hv_extender *e, const hv_tiles *t, const char *what)
{
    if (!t || (t->count && (!t->ijk || !t->v || !t->on)))
        return hv__error(HV_ERR_INVALID_ARG, "extend: %s: tiles are NULL", what);
    if (t->n[0] != e->n[0] || t->n[1] != e->n[1] || t->n[2] != e->n[2] ||
        fabs(t->h - e->h) > 1e-9 * e->h)
        return hv__error(HV_ERR_INVALID_ARG,
                         "extend: %s is a %d x %d x %d block with h = %g; the extender was made "
                         "for %d x %d x %d with h = %g",
                         what, t->n[0], t->n[1], t->n[2], t->h, e->n[0], e->n[1], e->n[2], e->h);
    return HV_OK;
}

static hv_status sparse_state(hv_extender *e)
{
    if (e->sp)
        return HV_OK;
    struct hv_extend_sparse *sp = calloc(1, sizeof *sp);
    if (!sp)
        return hv__error(HV_ERR_NOMEM, "extend: out of memory");
    size_t nt = 1;
    for (int a = 0; a < 3; a++) {
        sp->tn[a] = (e->n[a] + TS - 1) / TS;
        nt *= (size_t)sp->tn[a];
    }
    /* calloc: the pages of the maps that no tile touches stay unmapped. */
    sp->map = calloc(nt, sizeof *sp->map);
    sp->cmap = calloc(nt, sizeof *sp->cmap);
    if (!sp->map || !sp->cmap) {
        hv__extend_sparse_destroy(&sp);
        return hv__error(HV_ERR_NOMEM, "extend: out of memory for the map of %zu tiles", nt);
    }
    e->sp = sp;
    return HV_OK;
}

/* Clears the maps' entries of this call's tiles (the maps stay allocated). */
static void unmap(tctx *x, size_t mapped)
{
    struct hv_extend_sparse *sp = x->sp;
    for (size_t t = 0; t < mapped; t++)
        sp->map[tile_id(sp, x->P->ijk[3 * t] / TS, x->P->ijk[3 * t + 1] / TS,
                        x->P->ijk[3 * t + 2] / TS)] = 0;
    for (size_t q = 0; q < x->ncand; q++)
        sp->cmap[tile_id(sp, x->cand[3 * q], x->cand[3 * q + 1], x->cand[3 * q + 2])] = 0;
    hv_free(x->cand);
    hv_free(x->mark);
    hv_free(x->pend);
    hv_free(x->smask);
    hv_free(x->sbase);
    hv_free(x->sval);
}

/* The fields' active voxels, counted. */
static void count_active(int nfields, hv_extend_tiles_field *f)
{
    for (int i = 0; i < nfields; i++)
        for (int q = 0; q < f[i].ncomp; q++) {
            hv_tiles *F = f[i].v[q];
            size_t a = 0;
            for (size_t w = 0; w < 8 * F->count; w++)
                a += (size_t)__builtin_popcountll(F->on[w]);
            F->active = a;
        }
}

/* Whether auto takes the device: where the device's maps of the block's
 * tiles (HV_EXTEND_TILES_CL_BYTES a tile) are not far larger than the band
 * and its fields (a small band on a huge block stays on the host). */
static int device_pays(const hv_extender *e, const hv_tiles *phi, int nfields,
                       const hv_extend_tiles_field *f)
{
    double nt = 1, nfc = 0;
    for (int a = 0; a < 3; a++)
        nt *= (double)((e->n[a] + TS - 1) / TS);
    for (int i = 0; i < nfields; i++)
        nfc += f[i].ncomp;
    const double band = (double)phi->count * TCELLS * sizeof(float) * (1 + 2 * nfc);
    return nt * HV_EXTEND_TILES_CL_BYTES <= 8 * band + 256e6;
}

hv_status hv__extend_tiles_check(const hv_extender *e)
{
    if (e->dim != 3)
        return hv__error(HV_ERR_INVALID_ARG, "extend: tiles are 3D; the extender is %dD", e->dim);
    if (e->solid)
        return hv__error(HV_ERR_INVALID_ARG,
                         "extend: the extender has solid cells; tiles take none (use "
                         "hv_extend_many)");
    return HV_OK;
}

hv_status hv_extend_tiles(hv_extender *e, const hv_tiles *phi, int nfields,
                          hv_extend_tiles_field *f, hv_extend_stats *stats)
{
    const double t_start = hv_now();
    hv_extend_stats lst;
    hv_extend_stats *S = stats ? stats : &lst;
    memset(S, 0, sizeof *S);
    if (!e || !phi || nfields < 0 || (nfields > 0 && !f))
        return hv__error(HV_ERR_INVALID_ARG, "hv_extend_tiles: bad arguments");
    hv_status st = hv__extend_tiles_check(e);
    if (st)
        return st;
    if (nfields > MAX_FIELDS_PER_CALL)
        return hv__error(HV_ERR_INVALID_ARG, "extend: %d fields in one call, at most %d", nfields,
                         MAX_FIELDS_PER_CALL);
    if ((st = check_tiles(e, phi, "the level set")))
        return st;
    int nrhs = 1;
    for (int i = 0; i < nfields; i++) {
        if (f[i].ncomp != 1 && f[i].ncomp != 3)
            return hv__error(HV_ERR_INVALID_ARG, "extend: field %d has %d components (1 or 3)", i,
                             f[i].ncomp);
        for (int q = 0; q < f[i].ncomp; q++) {
            if ((st = check_tiles(e, f[i].v[q], "a field")))
                return st;
            if (f[i].v[q]->count != phi->count ||
                (phi->count && memcmp(f[i].v[q]->ijk, phi->ijk, 3 * phi->count * sizeof *phi->ijk)))
                return hv__error(HV_ERR_INVALID_ARG,
                                 "extend: field %d component %d is not on the level set's tiles", i,
                                 q);
        }
        nrhs += f[i].ncomp == 1 ? 1 : f[i].ncomp + 1;
    }
    S->tiles = phi->count;
    for (size_t t = 0; t < phi->count; t++)
        for (int a = 0; a < 3; a++) {
            const int32_t c = phi->ijk[3 * t + a];
            if (c < 0 || c >= e->n[a] || c % TS)
                return hv__error(HV_ERR_INVALID_ARG,
                                 "extend: tile %zu of the level set is not on the block's 8^3 "
                                 "lattice",
                                 t);
        }
    hv__extend_resolve_backend(e);
    if (e->o.backend == HV_BACKEND_OPENCL &&
        (!e->auto_backend || device_pays(e, phi, nfields, f))) {
        st = hv__extend_tiles_cl_run(e, phi, nfields, f, S);
        const int fell = st == HV_ERR_UNSUPPORTED || st == HV_ERR_NOMEM || st == HV_ERR_BACKEND;
        if (!(fell && e->auto_backend)) {
            S->on_device = 1;
            if (!st)
                count_active(nfields, f);
            S->t_total = hv_now() - t_start;
            return st;
        }
        hv_clear_error();
        memset(S, 0, sizeof *S);
        S->tiles = phi->count;
    }
    /* The level set: finite, and its background. */
    float bg = 0;
    size_t bad = SIZE_MAX;
    const size_t cells = phi->count * TCELLS;
#pragma omp parallel for reduction(max : bg) reduction(min : bad) schedule(static)
    for (size_t c = 0; c < cells; c++) {
        const float v = phi->v[c];
        if (!isfinite(v)) {
            if (c < bad)
                bad = c;
        } else if (fabsf(v) > bg) {
            bg = fabsf(v);
        }
    }
    if (bad != SIZE_MAX) {
        int i, j, k;
        cell_of(phi, bad / TCELLS, (int)(bad % TCELLS), &i, &j, &k);
        return hv__error(HV_ERR_NUMERIC,
                         "extend: the level set holds a non-finite value (%g) at cell (%d, %d, %d)",
                         (double)phi->v[bad], i, j, k);
    }
    if ((st = sparse_state(e)))
        return st;
    tctx x;
    memset(&x, 0, sizeof x);
    x.e = e;
    x.sp = e->sp;
    x.P = phi;
    x.nfields = nfields;
    x.R = nrhs;
    x.f = f;
    x.bg = bg;
    x.bh = e->o.band * e->h;
    x.ob = e->o.out_band > 0 ? e->o.out_band * e->h : 0;
    size_t mapped = 0;
    for (; mapped < phi->count; mapped++) {
        int32_t *m =
            &x.sp->map[tile_id(x.sp, phi->ijk[3 * mapped] / TS, phi->ijk[3 * mapped + 1] / TS,
                               phi->ijk[3 * mapped + 2] / TS)];
        if (*m) {
            st =
                hv__error(HV_ERR_INVALID_ARG, "extend: the level set lists tile %zu twice", mapped);
            break;
        }
        *m = (int32_t)(mapped + 1);
    }
    for (int i = 0; i < nfields; i++)
        x.nfc += f[i].ncomp;
    if (!st && (!(x.pend = hv_malloc(cells ? cells : 1)) ||
                !(x.smask = hv_calloc(8 * phi->count + 1, sizeof *x.smask))))
        st = hv__error(HV_ERR_NOMEM, "extend: out of memory");
    /* The output band's width (every active voxel: the level set's band, its
     * background) decides how far closest points lie and the last level. */
    const double ob_vox = x.ob > 0 ? e->o.out_band : bg / e->h;
    if (!st)
        st = make_candidates(&x, 1 + (int)(ob_vox / TS));
    size_t nsrc = 0, npend = 0;
    double t0 = hv_now();
    if (!st)
        st = classify(&x, &nsrc, &npend);
    S->source_cells = nsrc;
    if (!st && !nsrc)
        st = hv__error(HV_ERR_INVALID_ARG,
                       "extend: no cell has |phi| < band * h = %g (the level set has no zero "
                       "crossing in the tiles, or the band is too thin)",
                       e->o.band * e->h);
    if (!st)
        st = gather_sources(&x);
    S->t_weights = hv_now() - t0;
    const int last = hv__extend_last_level(e, ob_vox);
    for (int l = 0; !st && l <= last && npend > 0; l++) {
        if ((st = hv__progress(l ? 0.5 + 0.5 * l / (last + 1) : 0.1, "extend")))
            break;
        hv_extend_counts k = {0, 0, 0, 0};
        if ((st = run_level(&x, l, l == last, S, &k)))
            break;
        S->levels = l + 1;
        S->cp_cells += k.cp;
        S->ratio_cells += k.ratio;
        S->weak_cells += k.weak;
        npend = k.left;
    }
    if (!st)
        count_active(nfields, f);
    S->work_bytes += cells + 8 * (x.ncand + phi->count) * sizeof(uint64_t) +
                     (x.sbase ? x.sbase[phi->count] * x.nfc * sizeof(float) : 0);
    unmap(&x, mapped);
    S->t_total = hv_now() - t_start;
    return st;
}
