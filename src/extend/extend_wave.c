/* The band solve as a wave through the planes (extend_internal.h,
 * hv__extend_wave_solve), for narrow bands given as tiles (extend_tiles.c).
 *
 * The band solve of extend_band.c holds the right-hand sides and two iterates
 * of every band cell: 12 R bytes a cell, most of the memory of a narrow-band
 * extension. Its sweeps are Jacobi-like (each reads the previous iterate of a
 * cell's six neighbours and the one before it at the cell), so sweep t of
 * plane k can run as soon as sweep t - 1 of planes k - 1, k and k + 1 is
 * done: a wave. At step w the plane w enters (its right-hand sides and the
 * first sweep), sweep t runs on plane w - t + 1 for t = 2 .. iters in that
 * order, and plane w - iters, final, gets its residual and hands its
 * solutions at the cells that are read to the caller. Each plane is held for
 * iters + 2 steps, in a ring of slots, so memory follows a plane's band cells
 * times the sweep count, not the band. Values are the same as the whole
 * band's: the same cells, segments, coefficients and per-cell arithmetic
 * (band_seg), only in another order. */
#include "extend_internal.h"
#include "core/error.h"

#include <math.h>
#include <omp.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define NONE UINT32_MAX
/* Smaller bands run on one thread (a barrier per plane and sweep costs more). */
#define WAVE_PAR_MIN 131072
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define WAVE_KERNEL __attribute__((target_clones("avx2", "default")))
#else
#define WAVE_KERNEL
#endif

/* Cells at..at+len-1 of a plane (local compact offsets) whose neighbour rows
 * j - 1, j + 1 (same plane), k - 1, k + 1 (the planes beside) start at nb[]
 * (NONE: no band cell there), with diagonal d. */
typedef struct {
    uint32_t at, nb[4], len;
    float d;
} wseg;

typedef struct {
    int k; /* plane held, -1 none */
    float *f, *A, *B;
    wseg *seg;
    size_t nseg, capseg;
} wslot;

typedef struct {
    const hv_extender *e;
    const hv_xrows *dom, *need;
    int R, iters;
    double s;
    uint32_t *loc;   /* per run of dom: its first cell's offset in its plane */
    uint32_t *psz;   /* per plane of dom: compact cells (runs with a ghost at each end) */
    size_t *nprefix; /* per run of need: cells of need before it */
    float *zero;     /* (nx + 2) R zeros */
    wslot *slot;
    int W;          /* slots */
    float *ca, *cc; /* per sweep t: the Chebyshev coefficients a, c (float) */
    hv_extend_rhs_fn rhs;
    const void *ctx;
    float *sol;
    double *acc; /* per thread: 3 R doubles (residual sums) */
} wave;

static inline size_t row_of(const wave *w, int j, int k)
{
    return (size_t)j + (size_t)w->e->n[1] * (k - w->dom->k0);
}

static inline int in_dom(const wave *w, int k) { return k >= w->dom->k0 && k < w->dom->k1; }

static wslot *slot_of(const wave *w, int k)
{
    if (!in_dom(w, k))
        return NULL;
    wslot *sl = &w->slot[(k - w->dom->k0) % w->W];
    return sl->k == k ? sl : NULL;
}

/* The segments of plane k, as run_segments (extend_band.c) cuts them. */
static int plane_segments(const wave *w, int k, wslot *sl)
{
    const hv_extender *e = w->e;
    const hv_xrows *d = w->dom;
    const int nx = e->n[0], ny = e->n[1], nz = e->n[2];
    const int dj[4] = {-1, 1, 0, 0}, dk[4] = {0, 0, -1, 1};
    sl->nseg = 0;
    for (int j = 0; j < ny; j++) {
        const size_t r = row_of(w, j, k);
        for (size_t q = d->first[r]; q < d->first[r + 1]; q++) {
            const int x0 = d->x[2 * q], x1 = d->x[2 * q + 1];
            size_t lo[4], hi[4];
            int rc = 0;
            for (int a = 0; a < 4; a++) {
                const int jj = j + dj[a], kk = k + dk[a];
                const int exists = jj >= 0 && jj < ny && kk >= 0 && kk < nz;
                rc += exists;
                lo[a] = hi[a] = 0;
                if (exists && in_dom(w, kk)) {
                    lo[a] = d->first[row_of(w, jj, kk)];
                    hi[a] = d->first[row_of(w, jj, kk) + 1];
                }
            }
            /* Cut points: as run_segments. */
            int cutbuf[64], *cuts = cutbuf, nc = 0;
            size_t needc = 4;
            for (int a = 0; a < 4; a++)
                needc += 2 * (hi[a] - lo[a]);
            if (needc > 64 && !(cuts = malloc(needc * sizeof *cuts)))
                return -1;
            cuts[nc++] = x0;
            cuts[nc++] = x1;
            if (x0 == 0 && x1 > 1)
                cuts[nc++] = 1;
            if (x1 == nx && nx - 1 > x0)
                cuts[nc++] = nx - 1;
            for (int a = 0; a < 4; a++)
                for (size_t p = lo[a]; p < hi[a]; p++) {
                    const int o0 = d->x[2 * p], o1 = d->x[2 * p + 1];
                    if (o1 <= x0 || o0 >= x1)
                        continue;
                    if (o0 > x0)
                        cuts[nc++] = o0;
                    if (o1 < x1)
                        cuts[nc++] = o1;
                }
            for (int a = 1; a < nc; a++) {
                int v = cuts[a], z = a - 1;
                while (z >= 0 && cuts[z] > v) {
                    cuts[z + 1] = cuts[z];
                    z--;
                }
                cuts[z + 1] = v;
            }
            size_t pp[4];
            for (int a = 0; a < 4; a++)
                pp[a] = lo[a];
            for (int c = 0; c + 1 < nc; c++) {
                const int xa = cuts[c], xb = cuts[c + 1];
                if (xb <= xa)
                    continue;
                if (sl->nseg == sl->capseg) {
                    size_t cap = sl->capseg ? 2 * sl->capseg : 1024;
                    wseg *ns = realloc(sl->seg, cap * sizeof *ns);
                    if (!ns) {
                        if (cuts != cutbuf)
                            free(cuts);
                        return -1;
                    }
                    sl->seg = ns;
                    sl->capseg = cap;
                }
                wseg *g = &sl->seg[sl->nseg++];
                g->at = w->loc[q] + (uint32_t)(xa - x0);
                g->len = (uint32_t)(xb - xa);
                g->d = (float)(1 + w->s * (rc + (xa > 0) + (xb < nx)));
                for (int a = 0; a < 4; a++) {
                    while (pp[a] < hi[a] && d->x[2 * pp[a] + 1] <= xa)
                        pp[a]++;
                    g->nb[a] = pp[a] < hi[a] && d->x[2 * pp[a]] <= xa
                                   ? w->loc[pp[a]] + (uint32_t)(xa - d->x[2 * pp[a]])
                                   : NONE;
                }
            }
            if (cuts != cutbuf)
                free(cuts);
        }
    }
    return 0;
}

/* band_seg's update of one segment: out = cur + a (cur - out) + c D^-1 (f - A cur). */
static inline __attribute__((always_inline)) void seg_update(size_t R, float s, const wseg *g,
                                                             const float *F, const float *C,
                                                             const float *Cm, const float *Cp,
                                                             const float *Z, float *O, float a,
                                                             float c)
{
    const size_t n = (size_t)g->len * R;
    const float d = g->d, cd = c / d;
    const float *restrict f = F + (size_t)g->at * R;
    const float *restrict u = C + (size_t)g->at * R;
    const float *restrict n0 = g->nb[0] == NONE ? Z : C + (size_t)g->nb[0] * R;
    const float *restrict n1 = g->nb[1] == NONE ? Z : C + (size_t)g->nb[1] * R;
    const float *restrict n2 = g->nb[2] == NONE || !Cm ? Z : Cm + (size_t)g->nb[2] * R;
    const float *restrict n3 = g->nb[3] == NONE || !Cp ? Z : Cp + (size_t)g->nb[3] * R;
    const float *restrict um = u - R, *restrict up = u + R;
    float *restrict o = O + (size_t)g->at * R;
#pragma omp simd
    for (size_t y = 0; y < n; y++) {
        float sum = n0[y] + n1[y] + n2[y] + n3[y] + um[y] + up[y];
        o[y] = u[y] + a * (u[y] - o[y]) + cd * (f[y] - (d * u[y] - s * sum));
    }
}

WAVE_KERNEL static void segs_update(const wave *w, const wslot *sl, size_t q0, size_t q1,
                                    const float *C, const float *Cm, const float *Cp, float *O,
                                    float a, float c)
{
    const float s = (float)w->s;
    for (size_t q = q0; q < q1; q++)
        seg_update((size_t)w->R, s, &sl->seg[q], sl->f, C, Cm, Cp, w->zero, O, a, c);
}

static inline float *iterate(wslot *sl, int t) { return t & 1 ? sl->A : sl->B; }

/* Sweep t (t >= 2) of plane k: from iterate t - 1 of planes k - 1 .. k + 1
 * into iterate t of plane k, over iterate t - 2 (the same array). */
static void sweep_plane(const wave *w, int k, int t)
{
    wslot *sl = slot_of(w, k), *m = slot_of(w, k - 1), *p = slot_of(w, k + 1);
    const float *C = iterate(sl, t - 1), *Cm = m ? iterate(m, t - 1) : NULL,
                *Cp = p ? iterate(p, t - 1) : NULL;
    float *O = iterate(sl, t);
    const size_t nt = (size_t)omp_get_num_threads(), th = (size_t)omp_get_thread_num();
    segs_update(w, sl, sl->nseg * th / nt, sl->nseg * (th + 1) / nt, C, Cm, Cp, O, w->ca[t],
                w->cc[t]);
#pragma omp barrier
}

/* Plane k enters slot: its segments (one thread), then its right-hand sides,
 * iterate 0 (zero) and iterate 1 = D^-1 f (band_first). */
static int enter_plane(wave *w, int k, int *oom)
{
    wslot *sl = &w->slot[(k - w->dom->k0) % w->W];
    const size_t R = (size_t)w->R, cells = w->psz[k - w->dom->k0];
#pragma omp single
    {
        sl->k = k;
        if (plane_segments(w, k, sl))
            *oom = 1;
    }
    if (*oom)
        return -1;
    const hv_xrows *d = w->dom;
    const size_t r0 = row_of(w, 0, k), r1 = row_of(w, 0, k + 1);
#pragma omp for schedule(static)
    for (size_t y = 0; y < cells * R; y++) {
        sl->A[y] = 0;
        sl->B[y] = 0;
        sl->f[y] = 0;
    }
#pragma omp for schedule(dynamic, 64)
    for (size_t r = r0; r < r1; r++)
        for (size_t q = d->first[r]; q < d->first[r + 1]; q++)
            w->rhs(w->ctx, (int)(r - r0), k, d->x[2 * q], d->x[2 * q + 1],
                   sl->f + (size_t)w->loc[q] * R);
#pragma omp for schedule(static)
    for (size_t q = 0; q < sl->nseg; q++) {
        const wseg *g = &sl->seg[q];
        const size_t n = (size_t)g->len * R;
        const float cd = 1.0f / g->d, *f = sl->f + (size_t)g->at * R;
        float *o = sl->A + (size_t)g->at * R;
        for (size_t y = 0; y < n; y++)
            o[y] = cd * f[y];
    }
    return 0;
}

/* band_residual on plane k's final iterate (acc: this thread's sums), and
 * the solutions at its cells of need into sol. */
static void finish_plane(const wave *w, int k)
{
    const wslot *sl = slot_of(w, k), *m = slot_of(w, k - 1), *p = slot_of(w, k + 1);
    const int R = w->R, T = w->iters;
    const float *u = iterate((wslot *)sl, T), *um = m ? iterate((wslot *)m, T) : NULL,
                *up = p ? iterate((wslot *)p, T) : NULL;
    double *a = w->acc + 3 * (size_t)R * omp_get_thread_num();
    const double s = w->s;
#pragma omp for schedule(static)
    for (size_t q = 0; q < sl->nseg; q++) {
        const wseg *g = &sl->seg[q];
        const float *v = u + (size_t)g->at * R, *f = sl->f + (size_t)g->at * R;
        const float *nb[4] = {
            g->nb[0] == NONE ? w->zero : u + (size_t)g->nb[0] * R,
            g->nb[1] == NONE ? w->zero : u + (size_t)g->nb[1] * R,
            g->nb[2] == NONE || !um ? w->zero : um + (size_t)g->nb[2] * R,
            g->nb[3] == NONE || !up ? w->zero : up + (size_t)g->nb[3] * R,
        };
        hv__band_run_residual(v, f, nb, g->len, R, g->d, s, a);
    }
    /* Solutions at need's cells of this plane: each need run lies in one run of dom. */
    const hv_xrows *n = w->need, *d = w->dom;
    const int ny = w->e->n[1];
    if (k < n->k0 || k >= n->k1)
        return;
#pragma omp for schedule(static)
    for (int j = 0; j < ny; j++) {
        const size_t rn = (size_t)j + (size_t)ny * (k - n->k0), rd = row_of(w, j, k);
        size_t qd = d->first[rd];
        for (size_t q = n->first[rn]; q < n->first[rn + 1]; q++) {
            const int x0 = n->x[2 * q], x1 = n->x[2 * q + 1];
            while (qd < d->first[rd + 1] && d->x[2 * qd + 1] <= x0)
                qd++;
            /* need is inside dom: qd holds x0 .. x1 - 1 */
            memcpy(w->sol + w->nprefix[q] * R,
                   u + ((size_t)w->loc[qd] + (size_t)(x0 - d->x[2 * qd])) * R,
                   (size_t)(x1 - x0) * R * sizeof(float));
        }
    }
}

static void free_wave(wave *w)
{
    free(w->loc);
    free(w->psz);
    free(w->nprefix);
    free(w->zero);
    free(w->ca);
    free(w->cc);
    free(w->acc);
    if (w->slot)
        for (int i = 0; i < w->W; i++) {
            hv_free(w->slot[i].f);
            hv_free(w->slot[i].A);
            hv_free(w->slot[i].B);
            free(w->slot[i].seg);
        }
    free(w->slot);
}

hv_status hv__extend_wave_solve(const hv_extender *e, const hv_xrows *dom, const hv_xrows *need,
                                double s, int R, hv_extend_rhs_fn rhs, const void *ctx, float *sol,
                                double *thr, hv_extend_stats *S)
{
    wave w;
    memset(&w, 0, sizeof w);
    w.e = e;
    w.dom = dom;
    w.need = need;
    w.R = R;
    w.s = s;
    w.rhs = rhs;
    w.ctx = ctx;
    w.sol = sol;
    w.iters = hv__extend_band_iters(e, s);
    const int npl = dom->k1 - dom->k0, ny = e->n[1];
    const int nth = omp_get_max_threads();
    w.W = w.iters + 2;
    w.loc = malloc((dom->nruns ? dom->nruns : 1) * sizeof *w.loc);
    w.psz = calloc(npl ? (size_t)npl : 1, sizeof *w.psz);
    w.nprefix = malloc((need->nruns ? need->nruns : 1) * sizeof *w.nprefix);
    w.zero = calloc(((size_t)e->n[0] + 2) * R, sizeof *w.zero);
    w.ca = calloc((size_t)w.iters + 1, sizeof *w.ca);
    w.cc = calloc((size_t)w.iters + 1, sizeof *w.cc);
    w.acc = calloc(3 * (size_t)R * nth, sizeof *w.acc);
    w.slot = calloc((size_t)w.W, sizeof *w.slot);
    if (!w.loc || !w.psz || !w.nprefix || !w.zero || !w.ca || !w.cc || !w.acc || !w.slot) {
        free_wave(&w);
        return hv__error(HV_ERR_NOMEM, "extend: out of memory for the band solve");
    }
    /* Each plane's compact layout: its runs, each between two ghost cells. */
    size_t cap = 1, cells = 0;
    for (int p = 0; p < npl; p++) {
        size_t at = 0;
        for (size_t q = dom->first[(size_t)ny * p]; q < dom->first[(size_t)ny * (p + 1)]; q++) {
            w.loc[q] = (uint32_t)(at + 1);
            at += (size_t)(dom->x[2 * q + 1] - dom->x[2 * q]) + 2;
            cells += (size_t)(dom->x[2 * q + 1] - dom->x[2 * q]);
        }
        if (at >= NONE) {
            free_wave(&w);
            return hv__error(HV_ERR_INVALID_ARG, "extend: a plane of the band has %zu cells", at);
        }
        w.psz[p] = (uint32_t)at;
        if (at > cap)
            cap = at;
    }
    for (size_t q = 0, c = 0; q < need->nruns; q++) {
        w.nprefix[q] = c;
        c += (size_t)(need->x[2 * q + 1] - need->x[2 * q]);
    }
    for (int i = 0; i < w.W; i++) {
        w.slot[i].k = -1;
        w.slot[i].f = hv_malloc(cap * R * sizeof(float));
        w.slot[i].A = hv_malloc(cap * R * sizeof(float));
        w.slot[i].B = hv_malloc(cap * R * sizeof(float));
        if (!w.slot[i].f || !w.slot[i].A || !w.slot[i].B) {
            free_wave(&w);
            return hv__error(HV_ERR_NOMEM, "extend: out of memory for the band solve");
        }
    }
    const size_t bytes = (size_t)w.W * 3 * cap * R * sizeof(float) + dom->nruns * sizeof *w.loc +
                         need->nruns * sizeof *w.nprefix;
    if (bytes > S->work_bytes)
        S->work_bytes = bytes;
    /* The coefficients of the band solve (extend_band.c), sweep by sweep. */
    const double theta = 1, delta = 1 - 1 / (1 + 2 * e->dim * s), sigma = theta / delta;
    double rho = 1 / sigma;
    for (int t = 2; t <= w.iters; t++) {
        const double rn = 1 / (2 * sigma - rho);
        w.ca[t] = (float)(rn * rho);
        w.cc[t] = (float)(2 * rn / delta);
        rho = rn;
    }
    int oom = 0;
#pragma omp parallel if (cells >= WAVE_PAR_MIN)
    {
        for (int step = 0; step < npl + w.iters && !oom; step++) {
            if (step < npl && enter_plane(&w, dom->k0 + step, &oom))
                break;
            for (int t = 2; t <= w.iters; t++) {
                const int p = step - t + 1;
                if (p >= 0 && p < npl)
                    sweep_plane(&w, dom->k0 + p, t);
            }
            const int pf = step - w.iters;
            if (pf >= 0 && pf < npl) {
                finish_plane(&w, dom->k0 + pf);
            }
        }
    }
    if (oom) {
        free_wave(&w);
        return hv__error(HV_ERR_NOMEM, "extend: out of memory for the band solve");
    }
    /* The sums of the threads (band_residual's norms). */
    double rinf0 = 0, relmax = 0;
    for (int r = 0; r < R; r++) {
        double r2 = 0, ri = 0, f2 = 0;
        for (int t = 0; t < nth; t++) {
            const double *a = w.acc + 3 * (size_t)R * t;
            r2 += a[r];
            ri = fmax(ri, a[R + r]);
            f2 += a[2 * R + r];
        }
        if (!r)
            rinf0 = ri;
        relmax = fmax(relmax, f2 > 0 ? sqrt(r2) / sqrt(f2) : 0);
    }
    free_wave(&w);
    S->solves += R;
    S->relres = fmax(S->relres, relmax);
    *thr = fmax(RELIABLE * rinf0, 1e-30);
    return HV_OK;
}
