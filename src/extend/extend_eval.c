/* The per-cell passes of the extension off a level set (extend_internal.h):
 * where each output cell is read (its closest point on the zero set, or the
 * cell itself: stencils, evaluation points), the first pass's weights and
 * checks, the background, and the reading of a level's ratios into the
 * outputs (write_cell). */
#include "extend_internal.h"
#include "core/error.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

static int is_solid(const hv_extender *e, size_t c) { return e->solid && e->solid[c]; }

/* Trilinear (bilinear in 2D) stencil at index-space point p (cell centres at
 * integers) of a grid of n cells, clamped to it. Returns the number of
 * corners. */
static int stencil_in(int dim, const int n[3], const double p[3], size_t idx[8], double wt[8])
{
    int i0[3], d[3], i1[3];
    double fr[3];
    hv__ext_clamped(dim, n, p, i0, d, fr);
    for (int a = 0; a < 3; a++)
        i1[a] = i0[a] + d[a];
    int m = dim == 3 ? 8 : 4;
    for (int q = 0; q < m; q++) {
        int ii = (q & 1) ? i1[0] : i0[0], jj = (q & 2) ? i1[1] : i0[1],
            kk = (q & 4) ? i1[2] : i0[2];
        idx[q] = ii + (size_t)n[0] * (jj + (size_t)n[1] * kk);
        wt[q] = ((q & 1) ? fr[0] : 1 - fr[0]) * ((q & 2) ? fr[1] : 1 - fr[1]) *
                (dim == 3 ? ((q & 4) ? fr[2] : 1 - fr[2]) : 1.0);
    }
    return m;
}

static int stencil(const hv_extender *e, const double p[3], size_t idx[8], double wt[8])
{
    return stencil_in(e->dim, e->n, p, idx, wt);
}

/* Distributed: whether the stencil of box point p needs cells past what the
 * box holds of level 0 (rem->lo, rem->hi) on a face that borders another
 * rank (the same cells as the whole grid's stencil otherwise, clamped alike
 * at the grid's own faces). */
static int past_box(const hv_extender *e, const double p[3])
{
    const hv_extend_remote *R = e->dist ? e->dist->rem : NULL;
    if (!R)
        return 0;
    for (int a = 0; a < e->dim; a++)
        if ((R->cut[a][0] && p[a] < R->lo[a]) || (R->cut[a][1] && p[a] > R->hi[a]))
            return 1;
    return 0;
}

/* A closest point past the box at box point p: 3 with pg = p in the whole
 * grid's index space, or 0 where that lies outside the grid (read at the
 * cell, as in one process). */
static int past_point(const hv_extender *e, const double p[3], double pg[3])
{
    const hv_extend_remote *R = e->dist->rem;
    double q[3] = {0, 0, 0};
    for (int a = 0; a < e->dim; a++) {
        q[a] = p[a] + R->go[a];
        if (q[a] < -0.5 || q[a] > R->gn[a] - 0.5)
            return 0;
    }
    if (pg)
        memcpy(pg, q, sizeof q);
    return 3;
}

static double sample(const float *v, const size_t idx[8], const double wt[8], int m)
{
    double s = 0;
    for (int q = 0; q < m; q++)
        s += wt[q] * v[idx[q]];
    return s;
}

/* All nsol solutions at once from the interleaved array. */
static void sample_all(const hv_extender *e, const size_t idx[8], const double wt[8], int m,
                       double *out)
{
    const int k = e->nsol;
    out[0] = 0;
    for (int r = 1; r < k; r++)
        out[r] = 0;
    for (int q = 0; q < m; q++) {
        const float *v = e->sol + idx[q] * (size_t)k;
        for (int r = 0; r < k; r++)
            out[r] += wt[q] * v[r];
    }
}

/* Central-difference gradient of phi at cell (i,j,k) (upwind: phi_diff2's),
 * one-sided at walls, in world units. */
static void grad_phi(const hv_extender *e, const float *phi, int i, int j, int k, int upwind,
                     double g[3])
{
    const int ijk[3] = {i, j, k};
    const size_t st[3] = {1, (size_t)e->n[0], (size_t)e->n[0] * e->n[1]};
    size_t c = i + st[1] * j + st[2] * k;
    g[0] = g[1] = g[2] = 0;
    for (int a = 0; a < e->dim; a++) {
        int lo = ijk[a] > 0, hi = ijk[a] + 1 < e->n[a];
        if (!lo && !hi)
            continue;
        double vp = hi ? phi[c + st[a]] : phi[c], vm = lo ? phi[c - st[a]] : phi[c];
        g[a] = lo && hi ? phi_diff2(phi[c], vm, vp, upwind) / (2 * e->h) : (vp - vm) / e->h;
    }
}

/* Where the extension of cell c is read: its closest point on the zero set
 * when phi is a distance there (|grad phi| near 1, and phi interpolated at the
 * point is within half the band of 0), else the cell itself. Fills the
 * interpolation stencil and returns 1 for a closest point. Distributed, a
 * closest point whose stencil lies partly past the box is not checked here
 * (its phi is other ranks'): 3, with pg (may be NULL) the point in the whole
 * grid's index space. */
static int evaluation_point(const hv_extender *e, const float *phi, int i, int j, int k,
                            int validate, size_t idx[8], double wt[8], int *m, double pg[3])
{
    size_t c = i + (size_t)e->n[0] * (j + (size_t)e->n[1] * k);
    idx[0] = c;
    wt[0] = 1;
    *m = 1;
    if (!e->o.closest_point)
        return 0;
    const int nx = e->n[0], ny = e->n[1], nz = e->n[2];
    if (e->dim == 3 && i > 0 && j > 0 && k > 0 && i + 1 < nx && j + 1 < ny && k + 1 < nz) {
        /* Inside the grid, straight-line: the same central differences and
         * trilinear stencil as below (this runs once or twice per output cell). */
        const size_t sy = (size_t)nx, sz = (size_t)nx * ny;
        const double nb[6] = {phi[c - 1],  phi[c + 1],  phi[c - sy],
                              phi[c + sy], phi[c - sz], phi[c + sz]};
        double p[3];
        if (!hv__ext_closest_point(phi[c], nb, e->h, i, j, k, p))
            return 0;
        if (past_box(e, p))
            return past_point(e, p, pg);
        const int nn[3] = {nx, ny, nz};
        int f[3];
        double cw[8], v = 0;
        if (!hv__ext_trilinear(p, nn, f, cw))
            return 0;
        const size_t b = f[0] + sy * f[1] + sz * f[2];
        const size_t ci[8] = {b,      b + 1,      b + sy,      b + sy + 1,
                              b + sz, b + sz + 1, b + sy + sz, b + sy + sz + 1};
        for (int q = 0; q < 8; q++)
            v += cw[q] * phi[ci[q]];
        if (validate && fabs(v) > 0.5 * fmax(e->o.band, 1.0) * e->h)
            return 0;
        memcpy(idx, ci, sizeof ci);
        memcpy(wt, cw, sizeof cw);
        *m = 8;
        return 1;
    }
    double g[3], gn = 0;
    for (int up = 0; up < 2; up++) { /* central, then upwind (phi_diff2) */
        grad_phi(e, phi, i, j, k, up, g);
        gn = 0;
        for (int a = 0; a < e->dim; a++)
            gn += g[a] * g[a];
        gn = sqrt(gn);
        if (gn >= GRAD_MIN && gn <= GRAD_MAX)
            break;
    }
    if (!(gn >= GRAD_MIN && gn <= GRAD_MAX))
        return 0;
    double s = phi[c] / (gn * e->h), p[3] = {i, j, k};
    for (int a = 0; a < e->dim; a++)
        p[a] -= s * g[a];
    if (past_box(e, p))
        return past_point(e, p, pg);
    for (int a = 0; a < e->dim; a++)
        if (p[a] < -0.5 || p[a] > e->n[a] - 0.5)
            return 0;
    size_t ci[8];
    double cw[8];
    int cm = stencil(e, p, ci, cw);
    if (validate && fabs(sample(phi, ci, cw, cm)) > 0.5 * fmax(e->o.band, 1.0) * e->h)
        return 0;
    memcpy(idx, ci, sizeof ci);
    memcpy(wt, cw, sizeof cw);
    *m = cm;
    return 1;
}

/* ---- closest points past a distributed extender's box ---------------------- */

static size_t key_hash(size_t g, size_t cap)
{
    return (size_t)(((uint64_t)g * 0x9E3779B97F4A7C15ull) >> 17) & (cap - 1);
}

/* The slot of global cell g: its own, or the empty one it would take. */
static size_t key_slot(const hv_extend_remote *R, size_t g)
{
    size_t s = key_hash(g, R->cap);
    while (R->key[s] && R->key[s] != g + 1)
        s = (s + 1) & (R->cap - 1);
    return s;
}

static hv_status key_grow(hv_extend_remote *R)
{
    const size_t cap = R->cap ? 2 * R->cap : 4096, old = R->cap;
    size_t *key = calloc(cap, sizeof *key), *ok = R->key;
    if (!key)
        return hv__error(HV_ERR_NOMEM, "extend: out of memory for %zu closest-point cells", cap);
    R->key = key;
    R->cap = cap;
    for (size_t s = 0; s < old; s++)
        if (ok[s])
            R->key[key_slot(R, ok[s] - 1)] = ok[s];
    free(ok);
    return HV_OK;
}

/* The whole grid's stencil of the closest point of box cell (i, j, k), of
 * pending 3: its corners as slots of the table. */
static int remote_stencil(const hv_extender *e, const float *phi, int i, int j, int k,
                          size_t slot[8], double wt[8])
{
    const hv_extend_remote *R = e->dist->rem;
    size_t idx[8];
    double pg[3];
    int m;
    evaluation_point(e, phi, i, j, k, 0, idx, wt, &m, pg);
    m = stencil_in(e->dim, R->gn, pg, idx, wt);
    for (int q = 0; q < m; q++)
        slot[q] = key_slot(R, idx[q]);
    return m;
}

static void remote_sample(const hv_extender *e, const float *phi, int i, int j, int k, double *out)
{
    const hv_extend_remote *R = e->dist->rem;
    size_t slot[8];
    double wt[8];
    const int m = remote_stencil(e, phi, i, j, k, slot, wt), n = e->nsol;
    for (int r = 0; r < n; r++)
        out[r] = 0;
    for (int q = 0; q < m; q++) {
        const float *v = R->sol + slot[q] * (size_t)n;
        for (int r = 0; r < n; r++)
            out[r] += wt[q] * v[r];
    }
}

/* Each of this rank's cells of pending 3, in order. */
#define FOR_PAST(e, ...)                                                                           \
    for (int k = (e)->dist->own_lo[2]; k <= (e)->dist->own_hi[2]; k++)                             \
        for (int j = (e)->dist->own_lo[1]; j <= (e)->dist->own_hi[1]; j++)                         \
            for (int i = (e)->dist->own_lo[0]; i <= (e)->dist->own_hi[0]; i++) {                   \
                const size_t c = i + (size_t)(e)->n[0] * (j + (size_t)(e)->n[1] * k);              \
                if ((e)->pending[c] == 3)                                                          \
                    __VA_ARGS__                                                                    \
            }

hv_status hv__extend_remote_collect(hv_extender *e, const float *phi)
{
    hv_extend_remote *R = e->dist->rem;
    if (R->key)
        memset(R->key, 0, R->cap * sizeof *R->key);
    R->used = 0;
    hv_status st = HV_OK;
    size_t last = SIZE_MAX; /* neighbours along a row mostly share a stencil */
    FOR_PAST(e, {
        size_t idx[8];
        double wt[8], pg[3];
        int m;
        evaluation_point(e, phi, i, j, k, 0, idx, wt, &m, pg);
        m = stencil_in(e->dim, R->gn, pg, idx, wt);
        if (idx[0] == last)
            continue;
        last = idx[0];
        for (int q = 0; q < m && !st; q++) {
            if (2 * (R->used + 1) > R->cap && (st = key_grow(R)))
                break;
            const size_t s = key_slot(R, idx[q]);
            if (!R->key[s]) {
                R->key[s] = idx[q] + 1;
                R->used++;
            }
        }
        if (st)
            return st;
    })
    return HV_OK;
}

void hv__extend_remote_check(hv_extender *e, const float *phi, uint8_t *need)
{
    hv_extend_remote *R = e->dist->rem;
    const double lim = 0.5 * fmax(e->o.band, 1.0) * e->h;
    memset(R->read, 0, R->cap);
    R->cells = 0;
    FOR_PAST(e, {
        size_t slot[8];
        double wt[8], v = 0;
        const int m = remote_stencil(e, phi, i, j, k, slot, wt);
        for (int q = 0; q < m; q++)
            v += wt[q] * R->phi[slot[q]];
        if (fabs(v) > lim) {
            e->pending[c] = 2;
            if (need)
                need[c] = 1;
            continue;
        }
        for (int q = 0; q < m; q++)
            R->read[slot[q]] = 1;
        R->cells++;
    })
}

/* Writes the extension of every field at cell c from the current level's
 * solutions sampled at p. */
static void write_cell(const hv_extender *e, int nfields, const hv_extend_field *f, size_t c,
                       const double *val)
{
    const double W = val[0];
    int r = 1;
    for (int i = 0; i < nfields; i++) {
        if (f[i].ncomp == 1) {
            f[i].out[0][c] = (float)(val[r] / W);
            r++;
            continue;
        }
        double mag = val[r] / W, v[3] = {0, 0, 0}, vn = 0;
        for (int q = 0; q < f[i].ncomp; q++) {
            v[q] = val[r + 1 + q];
            vn += v[q] * v[q];
        }
        vn = sqrt(vn);
        for (int q = 0; q < f[i].ncomp; q++)
            f[i].out[q][c] = vn > 0 ? (float)(mag * v[q] / vn) : 0.0f;
        r += f[i].ncomp + 1;
    }
}

hv_status hv__extend_classify(hv_extender *e, const float *phi, int nfields,
                              const hv_extend_field *f, uint8_t *need, size_t *nsrc_out,
                              size_t *npend_out, ibox *wbox, ibox *rbox)
{
    uint8_t *pending = e->pending;
    /* need is only ever set in this pass, so that the stencils' marks from
     * other rows cannot be lost. */
    if (need)
        memset(need, 0, e->count);
    const double bh = e->o.band * e->h, ob = e->o.out_band * e->h;
    size_t nsrc = 0, npend = 0, badphi = SIZE_MAX, badf = SIZE_MAX;
    ibox band_box, ratio_box;
    box_empty(&band_box);
    box_empty(&ratio_box);
#pragma omp parallel reduction(+ : nsrc, npend) reduction(min : badphi, badf)
    {
        ibox lb, lr;
        box_empty(&lb);
        box_empty(&lr);
#pragma omp for collapse(2) schedule(static)
        for (int k = 0; k < e->n[2]; k++)
            for (int j = 0; j < e->n[1]; j++)
                for (int i = 0; i < e->n[0]; i++) {
                    const size_t c = i + (size_t)e->n[0] * (j + (size_t)e->n[1] * k);
                    const double s = phi[c] / bh;
                    const int solid = is_solid(e, c);
                    double v = 0;
                    pending[c] = 0;
                    if (!isfinite(s)) {
                        if (c < badphi)
                            badphi = c;
                        e->w[c] = 0;
                        continue;
                    }
                    if (fabs(s) < 1 && !solid) {
                        v = (1 - s * s) * (1 - s * s);
                        nsrc++;
                        box_add(&lb, i, j, k);
                        for (int fi = 0; fi < nfields; fi++)
                            for (int q = 0; q < f[fi].ncomp; q++)
                                if (!isfinite(f[fi].in[q][c]) && c < badf)
                                    badf = c;
                        if (need) {
#pragma omp atomic write
                            need[c] = 1;
                        }
                    }
                    e->w[c] = (float)v;
                    if (solid || (ob > 0 && !(fabs(phi[c]) < ob)))
                        continue;
                    size_t idx[8];
                    double wt[8];
                    int m;
                    const int at = evaluation_point(e, phi, i, j, k, 1, idx, wt, &m, NULL);
                    if (at == 3) {
                        /* Past the box: read from the owners (hv_extend_remote) where the
                         * cell is this rank's; the ghost layer's cells are other ranks'
                         * outputs. */
                        const hv_extend_dist *D = e->dist;
                        const int own = i >= D->own_lo[0] && i <= D->own_hi[0] &&
                                        j >= D->own_lo[1] && j <= D->own_hi[1] &&
                                        k >= D->own_lo[2] && k <= D->own_hi[2];
                        pending[c] = own ? 3 : 0;
                        npend += own;
                        continue;
                    }
                    pending[c] = at ? 1 : 2;
                    npend++;
                    if (pending[c] == 2)
                        box_add(&lr, i, j, k);
                    if (need)
                        for (int q = 0; q < m; q++) {
#pragma omp atomic write
                            need[idx[q]] = 1;
                        }
                }
#pragma omp critical(hv_extend_box)
        {
            box_union(&band_box, &lb);
            box_union(&ratio_box, &lr);
        }
    }
    if (badphi != SIZE_MAX)
        return hv__error(HV_ERR_NUMERIC,
                         "extend: the level set holds a non-finite value (%g) at cell %zu",
                         (double)phi[badphi], badphi);
    for (int i = 0; i < nfields && badf != SIZE_MAX; i++)
        for (int q = 0; q < f[i].ncomp; q++)
            if (!isfinite(f[i].in[q][badf]))
                return hv__error(HV_ERR_NUMERIC,
                                 "extend: field %d component %d is NaN/Inf at cell %zu, inside "
                                 "the source band",
                                 i, q, badf);
    *nsrc_out = nsrc;
    *npend_out = npend;
    *wbox = band_box;
    *rbox = ratio_box;
    return HV_OK;
}

void hv__extend_fill_background(const hv_extender *e, int nfields, const hv_extend_field *f)
{
    const uint8_t *pending = e->pending;
    const size_t rows = (size_t)e->n[1] * e->n[2], nx = (size_t)e->n[0];
    const float bg = e->o.background;
#pragma omp parallel for schedule(static)
    for (size_t r = 0; r < rows; r++) {
        const uint8_t *pr = pending + r * nx;
        for (size_t x = 0; x < nx;) {
            if (pr[x]) {
                x++;
                continue;
            }
            size_t x1 = x + 1;
            while (x1 < nx && !pr[x1])
                x1++;
            for (int fi = 0; fi < nfields; fi++)
                for (int q = 0; q < f[fi].ncomp; q++) {
                    float *o = f[fi].out[q] + r * nx;
                    for (size_t y = x; y < x1; y++)
                        o[y] = bg;
                }
            x = x1;
        }
    }
}

void hv__extend_eval_level(hv_extender *e, const float *phi, int nfields, const hv_extend_field *f,
                           double thr, int last, const uint8_t *trusted, ibox *rbox,
                           hv_extend_counts *n)
{
    uint8_t *pending = e->pending;
    size_t left = 0, cp = 0, ratio = 0, weak = 0;
    /* The cells left for the next level are boxed as they are met. */
    box_empty(rbox);
#pragma omp parallel reduction(+ : left, cp, ratio, weak)
    {
        ibox lr;
        box_empty(&lr);
#pragma omp for collapse(2) schedule(static)
        for (int k = 0; k < e->n[2]; k++)
            for (int j = 0; j < e->n[1]; j++)
                for (int i = 0; i < e->n[0]; i++) {
                    size_t c = i + (size_t)e->n[0] * (j + (size_t)e->n[1] * k);
                    if (!pending[c])
                        continue;
                    size_t idx[8] = {c};
                    double wt[8] = {1};
                    int m = 1, at_cp = 0;
                    double val[1 + 4 * MAX_FIELDS_PER_CALL];
                    if (pending[c] == 3) {
                        remote_sample(e, phi, i, j, k, val);
                        at_cp = 1;
                    } else {
                        if (pending[c] == 1)
                            at_cp = evaluation_point(e, phi, i, j, k, 0, idx, wt, &m, NULL);
                        sample_all(e, idx, wt, m, val);
                    }
                    double W = val[0];
                    if (!(W > thr) && at_cp) {
                        /* Closest point but no weight there: read at the cell from now on. */
                        at_cp = 0;
                        pending[c] = 2;
                        idx[0] = c;
                        wt[0] = 1;
                        m = 1;
                        if (trusted && !trusted[c]) {
                            /* Off the cells the band solve was made for: not at this level. */
                            W = 0;
                        } else {
                            sample_all(e, idx, wt, m, val);
                            W = val[0];
                        }
                    }
                    if (!(W > thr) && !last) {
                        left++;
                        box_add(&lr, i, j, k);
                        continue;
                    }
                    if (!(W > 0)) {
                        for (int fi = 0; fi < nfields; fi++)
                            for (int q = 0; q < f[fi].ncomp; q++)
                                f[fi].out[q][c] = e->o.background;
                    } else {
                        write_cell(e, nfields, f, c, val);
                    }
                    weak += !(W > thr);
                    cp += at_cp;
                    ratio += !at_cp;
                    pending[c] = 0;
                }
#pragma omp critical(hv_extend_box)
        box_union(rbox, &lr);
    }
    n->left = left;
    n->cp = cp;
    n->ratio = ratio;
    n->weak = weak;
}
