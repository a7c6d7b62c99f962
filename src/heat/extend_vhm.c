/* Extension of scalar and vector fields off a level set by diffusion (heat.h):
 * the vector heat method's split (Sharp, Soliman & Crane 2019) in flat space,
 * where the connection Laplacian acts on each component, evaluated at the
 * closest point where phi is a distance. */
#include "heatvox/heat.h"
#include "core/error.h"
#include "extend_cl.h"

#include <math.h>
#include <omp.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

struct hv_extender {
    int dim, n[3];
    double h;
    size_t count;
    uint8_t *solid;                /* owned copy or NULL */
    hv_extend_opts o;
    hv_solver *sv[MAX_LEVELS];     /* level l: t * 16^l, built on first use */
    int blo[MAX_LEVELS][3];        /* the box level l's solver was built for */
    int bn[MAX_LEVELS][3];
    double *fd, *ud;               /* one right-hand side and solution (double) */
    float *w;                      /* weights */
    float *sol;                    /* solutions of the current level, interleaved: right-hand
                                      side r of cell c at c * nsol + r (a closest point's 8
                                      corners then cost a few cache lines for all fields) */
    int nsol, capsol;
    float *bf, *bu0, *bu1;         /* band solve: right-hand sides and iterates, compact */
    size_t bcap;                   /* floats each of them holds */
    uint8_t *bneed, *bg0, *bg1;    /* band solve: cells read, growing buffers */
    uint8_t *pending;              /* per cell: 0 done, 1 read at the closest point, 2 at itself */
    hv_extend_cl *cl;              /* backend opencl: the device path's state */
};

void hv_extend_opts_default(hv_extend_opts *o)
{
    memset(o, 0, sizeof *o);
    o->band = 1.5;
    o->t_scale = 0.25;
    o->closest_point = 1;
    o->out_band = 0;
    o->background = 0;
    o->max_levels = 6;
    o->backend = HV_BACKEND_AUTO;
    o->tol = 1e-10;
}

hv_status hv_extender_create(hv_extender **out, int dim, const int n[3], double h,
                             const uint8_t *solid, const hv_extend_opts *opts)
{
    if (!out)
        return hv_error(HV_ERR_INVALID_ARG, "hv_extender_create: out is NULL");
    *out = NULL;
    hv_status st = hv_check_dims(dim, n, h, 2 * sizeof(double) + 6 * sizeof(float));
    if (st)
        return st;
    hv_extend_opts o;
    if (opts)
        o = *opts;
    else
        hv_extend_opts_default(&o);
    if (!(o.band > 0) || !isfinite(o.band))
        return hv_error(HV_ERR_INVALID_ARG, "extend: band must be positive (voxels), got %g", o.band);
    if (!(o.t_scale > 0) || !isfinite(o.t_scale))
        return hv_error(HV_ERR_INVALID_ARG, "extend: t_scale must be positive, got %g", o.t_scale);
    if (!(o.out_band >= 0) || !isfinite(o.out_band))
        return hv_error(HV_ERR_INVALID_ARG, "extend: out_band must be >= 0 (0 = every cell), got %g",
                        o.out_band);
    if (o.max_levels < 1 || o.max_levels > MAX_LEVELS)
        return hv_error(HV_ERR_INVALID_ARG, "extend: max_levels must be in 1..%d, got %d", MAX_LEVELS,
                        o.max_levels);
    if (!(o.tol >= 1e-12) || !(o.tol < 1))
        return hv_error(HV_ERR_INVALID_ARG, "extend: tol must be in [1e-12, 1), got %g", o.tol);
    hv_extender *e = calloc(1, sizeof *e);
    if (!e)
        return hv_error(HV_ERR_NOMEM, "extend: out of memory");
    e->dim = dim;
    e->n[0] = n[0];
    e->n[1] = n[1];
    e->n[2] = dim == 3 ? n[2] : 1;
    e->h = h;
    e->count = (size_t)e->n[0] * e->n[1] * e->n[2];
    /* AUTO on a GPU: the whole extension on the device (extend_cl.c). */
    if (hv_backend_resolve(o.backend, e->count, solid != NULL) == HV_BACKEND_OPENCL)
        o.backend = HV_BACKEND_OPENCL;
    e->o = o;
    e->fd = hv_malloc(e->count * sizeof(double));
    e->ud = hv_malloc(e->count * sizeof(double));
    e->w = hv_malloc(e->count * sizeof(float));
    if (solid) {
        e->solid = malloc(e->count);
        if (e->solid)
            memcpy(e->solid, solid, e->count);
    }
    if (!e->fd || !e->ud || !e->w || (solid && !e->solid)) {
        hv_extender_destroy(&e);
        return hv_error(HV_ERR_NOMEM, "extend: out of memory for a %d x %d x %d grid", e->n[0],
                        e->n[1], e->n[2]);
    }
    *out = e;
    return HV_OK;
}

void hv_extender_destroy(hv_extender **ep)
{
    if (!ep || !*ep)
        return;
    hv_extender *e = *ep;
    for (int l = 0; l < MAX_LEVELS; l++)
        hv_solver_destroy(&e->sv[l]);
    hv_free(e->sol);
    hv_free(e->fd);
    hv_free(e->ud);
    hv_free(e->w);
    hv_free(e->bf);
    hv_free(e->bu0);
    hv_free(e->bu1);
    hv_free(e->bneed);
    hv_free(e->pending);
    hv_free(e->bg0);
    hv_free(e->bg1);
    hv_extend_cl_destroy(&e->cl);
    free(e->solid);
    free(e);
    *ep = NULL;
}

static int is_solid(const hv_extender *e, size_t c) { return e->solid && e->solid[c]; }

static hv_status ensure_solutions(hv_extender *e, int k)
{
    if (k > e->capsol) {
        hv_free(e->sol);
        e->capsol = 0;
        if (!(e->sol = hv_malloc(e->count * (size_t)k * sizeof(float))))
            return hv_error(HV_ERR_NOMEM, "extend: out of memory for %d solutions", k);
        e->capsol = k;
    }
    e->nsol = k;
    return HV_OK;
}

/* Right-hand side r of the layout: 0 = weights; then per field, for a scalar
 * w f, for a vector w |v| followed by w v_c per component. rhs_part finds
 * which (field -1 for the weights; part 0 = |v|, c + 1 = component c). */
typedef struct {
    int field, part;
} rhs_part;

static rhs_part rhs_locate(int r, int nfields, const hv_extend_field *f)
{
    rhs_part p = {-1, 0};
    for (int i = 0, base = 1; i < nfields && r > 0; i++) {
        int k = f[i].ncomp == 1 ? 1 : f[i].ncomp + 1;
        if (r < base + k) {
            p.field = i;
            p.part = r - base;
            break;
        }
        base += k;
    }
    return p;
}

/* Right-hand side p at cell c. */
static inline double rhs_value(const hv_extender *e, const hv_extend_field *f, rhs_part p, size_t c)
{
    const double w = e->w[c];
    if (!(w > 0))
        return 0;
    if (p.field < 0)
        return w;
    const hv_extend_field *F = &f[p.field];
    if (F->ncomp == 1)
        return w * F->in[0][c];
    if (p.part > 0)
        return w * F->in[p.part - 1][c];
    double m = 0;
    for (int q = 0; q < F->ncomp; q++)
        m += (double)F->in[q][c] * F->in[q][c];
    return w * sqrt(m);
}

/* Right-hand side r on the box [lo, lo + bn). */
static void build_rhs(const hv_extender *e, int r, int nfields, const hv_extend_field *f,
                      const int lo[3], const int bn[3], double *out)
{
    const rhs_part p = rhs_locate(r, nfields, f);
    const size_t bcount = (size_t)bn[0] * bn[1] * bn[2];
#pragma omp parallel for schedule(static)
    for (size_t b = 0; b < bcount; b++) {
        size_t bi = b % (size_t)bn[0], bj = (b / (size_t)bn[0]) % (size_t)bn[1];
        size_t bk = b / ((size_t)bn[0] * bn[1]);
        size_t c = (lo[0] + bi) + (size_t)e->n[0] * ((lo[1] + bj) + (size_t)e->n[1] * (lo[2] + bk));
        out[b] = rhs_value(e, f, p, c);
    }
}

static double norm2_d(const double *v, size_t n)
{
    double s = 0;
#pragma omp parallel for reduction(+ : s) schedule(static)
    for (size_t c = 0; c < n; c++)
        s += v[c] * v[c];
    return sqrt(s);
}

/* Trilinear (bilinear in 2D) stencil at index-space point p (cell centres at
 * integers), clamped to the grid. Returns the number of corners. */
static int stencil(const hv_extender *e, const double p[3], size_t idx[8], double wt[8])
{
    int i0[3] = {0, 0, 0}, i1[3] = {0, 0, 0};
    double fr[3] = {0, 0, 0};
    for (int a = 0; a < e->dim; a++) {
        double q = p[a];
        if (q < 0)
            q = 0;
        if (q > e->n[a] - 1)
            q = e->n[a] - 1;
        int f = (int)floor(q);
        if (f > e->n[a] - 2)
            f = e->n[a] - 2;
        if (f < 0)
            f = 0;
        i0[a] = f;
        i1[a] = e->n[a] > 1 ? f + 1 : f;
        fr[a] = e->n[a] > 1 ? q - f : 0;
    }
    int m = e->dim == 3 ? 8 : 4;
    for (int q = 0; q < m; q++) {
        int ii = (q & 1) ? i1[0] : i0[0], jj = (q & 2) ? i1[1] : i0[1], kk = (q & 4) ? i1[2] : i0[2];
        idx[q] = ii + (size_t)e->n[0] * (jj + (size_t)e->n[1] * kk);
        wt[q] = ((q & 1) ? fr[0] : 1 - fr[0]) * ((q & 2) ? fr[1] : 1 - fr[1]) *
                (e->dim == 3 ? ((q & 4) ? fr[2] : 1 - fr[2]) : 1.0);
    }
    return m;
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

/* Central-difference gradient of phi at cell (i,j,k), one-sided at walls, in
 * world units. */
static void grad_phi(const hv_extender *e, const float *phi, int i, int j, int k, double g[3])
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
        g[a] = (vp - vm) / ((lo + hi) * e->h);
    }
}

/* Where the extension of cell c is read: its closest point on the zero set
 * when phi is a distance there (|grad phi| near 1, and phi interpolated at the
 * point is within half the band of 0), else the cell itself. Fills the
 * interpolation stencil and returns 1 for a closest point. */
static int evaluation_point(const hv_extender *e, const float *phi, int i, int j, int k,
                            int validate, size_t idx[8], double wt[8], int *m)
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
        const double gx = (double)phi[c + 1] - phi[c - 1], gy = (double)phi[c + sy] - phi[c - sy],
                     gz = (double)phi[c + sz] - phi[c - sz];
        const double gn = sqrt(gx * gx + gy * gy + gz * gz) * (0.5 / e->h);
        if (!(gn >= GRAD_MIN && gn <= GRAD_MAX))
            return 0;
        const double sc = phi[c] * 0.5 / (gn * e->h * e->h);
        const double p[3] = {i - sc * gx, j - sc * gy, k - sc * gz};
        const int nn[3] = {nx, ny, nz};
        int f[3];
        double fr[3];
        for (int a = 0; a < 3; a++) {
            if (p[a] < -0.5 || p[a] > nn[a] - 0.5)
                return 0;
            double q = p[a] < 0 ? 0 : p[a]; /* comparisons: fmin/fmax are libm calls here */
            if (q > nn[a] - 1)
                q = nn[a] - 1;
            f[a] = (int)q;
            if (f[a] > nn[a] - 2)
                f[a] = nn[a] - 2;
            fr[a] = q - f[a];
        }
        const size_t b = f[0] + sy * f[1] + sz * f[2];
        const size_t ci[8] = {b, b + 1, b + sy, b + sy + 1, b + sz, b + sz + 1, b + sy + sz,
                              b + sy + sz + 1};
        const double wx[2] = {1 - fr[0], fr[0]}, wy[2] = {1 - fr[1], fr[1]},
                     wz[2] = {1 - fr[2], fr[2]};
        double cw[8], v = 0;
        for (int q = 0; q < 8; q++) {
            cw[q] = wx[q & 1] * wy[(q >> 1) & 1] * wz[q >> 2];
            v += cw[q] * phi[ci[q]];
        }
        if (validate && fabs(v) > 0.5 * fmax(e->o.band, 1.0) * e->h)
            return 0;
        memcpy(idx, ci, sizeof ci);
        memcpy(wt, cw, sizeof cw);
        *m = 8;
        return 1;
    }
    double g[3], gn = 0;
    grad_phi(e, phi, i, j, k, g);
    for (int a = 0; a < e->dim; a++)
        gn += g[a] * g[a];
    gn = sqrt(gn);
    if (!(gn >= GRAD_MIN && gn <= GRAD_MAX))
        return 0;
    double s = phi[c] / (gn * e->h), p[3] = {i, j, k};
    for (int a = 0; a < e->dim; a++) {
        p[a] -= s * g[a];
        if (p[a] < -0.5 || p[a] > e->n[a] - 0.5)
            return 0;
    }
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

hv_status hv_extend_level_solver(int dim, const int n[3], double h, const uint8_t *solid,
                                 const hv_extend_opts *o, hv_backend backend, int l,
                                 const int lo[3], const int bn[3], hv_solver **sv, int blo[3],
                                 int bnk[3])
{
    if (*sv && (memcmp(bnk, bn, 3 * sizeof *bn) || (solid && memcmp(blo, lo, 3 * sizeof *lo))))
        hv_solver_destroy(sv);
    if (*sv)
        return HV_OK;
    const size_t bcount = (size_t)bn[0] * bn[1] * bn[2];
    uint8_t *sub = NULL;
    if (solid) {
        if (!(sub = malloc(bcount)))
            return hv_error(HV_ERR_NOMEM, "extend: out of memory");
        for (size_t b = 0; b < bcount; b++) {
            size_t bi = b % (size_t)bn[0], bj = (b / (size_t)bn[0]) % (size_t)bn[1];
            size_t bk = b / ((size_t)bn[0] * bn[1]);
            sub[b] = solid[(lo[0] + bi) + (size_t)n[0] * ((lo[1] + bj) + (size_t)n[1] * (lo[2] + bk))];
        }
    }
    hv_problem p = {dim, {bn[0], bn[1], bn[2]}, h, sub, 1.0, o->t_scale * h * h * pow(LEVEL_FACTOR, l)};
    hv_solver_opts so;
    hv_solver_opts_default(&so);
    so.backend = backend;
    so.tol = o->tol;
    so.max_iter = 200;
    hv_status st = hv_solver_create(sv, &p, &so);
    free(sub);
    if (st)
        return st;
    memcpy(blo, lo, 3 * sizeof *lo);
    memcpy(bnk, bn, 3 * sizeof *bn);
    return HV_OK;
}

/* Solves every right-hand side for level l on the box [lo, lo + bn) (Neumann
 * walls at its faces) and stores the solutions on the full grid, 0 outside. */
static hv_status solve_level(hv_extender *e, int l, const int lo[3], const int bn[3], int nrhs,
                             int nfields, const hv_extend_field *f, double *thr,
                             hv_extend_stats *S)
{
    hv_status st = hv_extend_level_solver(e->dim, e->n, e->h, e->solid, &e->o, e->o.backend, l, lo,
                                          bn, &e->sv[l], e->blo[l], e->bn[l]);
    if (st)
        return st;
    const size_t bcount = (size_t)bn[0] * bn[1] * bn[2];
    const int full = bcount == e->count;
    double relmax = 0, wn = 0;
    for (int r = 0; r < nrhs; r++) {
        build_rhs(e, r, nfields, f, lo, bn, e->fd);
        if (r == 0)
            wn = norm2_d(e->fd, bcount);
        hv_solve_info info;
        if ((st = hv_solver_solve_d(e->sv[l], e->fd, e->ud, &info)))
            return st;
        relmax = fmax(relmax, info.relres);
        float *out = e->sol;
        const double *ud = e->ud;
        const size_t k = (size_t)e->nsol;
        if (!full && r == 0)
            memset(out, 0, e->count * k * sizeof *out);
#pragma omp parallel for schedule(static)
        for (size_t b = 0; b < bcount; b++) {
            size_t bi = b % (size_t)bn[0], bj = (b / (size_t)bn[0]) % (size_t)bn[1];
            size_t bk = b / ((size_t)bn[0] * bn[1]);
            size_t c = (lo[0] + bi) + (size_t)e->n[0] * ((lo[1] + bj) + (size_t)e->n[1] * (lo[2] + bk));
            out[c * k + r] = (float)ud[b];
        }
        S->solves++;
    }
    S->relres = fmax(S->relres, relmax);
    if (l == 0)
        S->solve_cells = bcount;
    /* Float storage caps the range too: trust W only well above float's smallest normal. */
    *thr = fmax(RELIABLE * fmax(relmax, 1e-14) * wn, 1e-30);
    return HV_OK;
}

/* ---- The band solve -------------------------------------------------------
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
#define BAND_MAX_T_SCALE 8.0  /* longer times: the box solve (more sweeps than a V-cycle) */
#define BAND_MAX_FRACTION 0.5 /* a band larger than this part of the box: the box solve */
#define BAND_TOL 3e-5
/* Smaller bands sweep on one thread (a barrier per sweep costs more). */
#define BAND_PAR_MIN 131072
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__SANITIZE_ADDRESS__)
#define BAND_KERNEL __attribute__((target_clones("avx2", "default")))
#else
#define BAND_KERNEL
#endif

typedef struct {
    int j, k, x0, x1; /* row (j, k), cells x0 <= x < x1 */
} xrun;

/* Cells x0 .. x0 + len - 1 of one run (at compact cell `at`), whose neighbours
 * in rows j - 1, j + 1, k - 1, k + 1 start at compact cell nb[0..3] (the zero
 * block where that row has no band cell there or the grid ends), with one
 * diagonal d = 1 + s (neighbour count) for all of them. */
typedef struct {
    size_t at, nb[4];
    uint32_t len;
    float d;
} bseg;

struct band {
    xrun *runs;
    size_t nruns, cells;
    uint8_t *need;   /* the cells read (before growing): trusted at level 0 */
    size_t *roff;    /* compact cell of run q's left ghost; its cells follow */
    bseg *segs;
    size_t nsegs;
    size_t *kstart;  /* segments of plane k: kstart[k] .. kstart[k + 1] - 1 */
    size_t zero;     /* compact cell of the zero block (nx cells) */
    size_t ncompact; /* compact cells in all */
    int R;           /* right-hand sides, side by side */
    float *f, *u0, *u1;
    int iters;
    double s;
};

static void band_free(struct band *b)
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
static size_t run_segments(const hv_extender *e, const struct band *b, const size_t *rfirst,
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
 * built, -1 when out of memory. */
static int band_build(hv_extender *e, struct band *b, size_t box_cells, int R)
{
    const int m = (int)lround(BOX_MARGIN * sqrt(e->o.t_scale));
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
    size_t *sfirst = malloc((nr + 1) * sizeof *sfirst);
    if (!b->runs || !b->roff || !sfirst) {
        free(first);
        free(sfirst);
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
    b->s = e->o.t_scale;
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
        free(first);
        free(sfirst);
        return -1;
    }
#pragma omp parallel for reduction(| : oom) schedule(static)
    for (size_t q = 0; q < nr; q++)
        oom |= run_segments(e, b, first, q, b->segs + sfirst[q]) == (size_t)-1;
    b->nsegs = sfirst[nr];
    if (oom || !(b->kstart = malloc(((size_t)e->n[2] + 1) * sizeof *b->kstart))) {
        free(first);
        free(sfirst);
        return -1;
    }
    for (int k = 0, q = 0; k <= e->n[2]; k++) {
        while ((size_t)q < nr && b->runs[q].k < k)
            q++;
        b->kstart[k] = sfirst[q];
    }
    free(first);
    free(sfirst);
    /* Sweeps for the error bound 2 c^k / (1 + c^2k) <= tol, c = (sqrt(K) - 1) / (sqrt(K) + 1),
     * K = 1 + 4 d s the condition number of D^-1 A. */
    const double K = 1 + 4 * e->dim * b->s, c = (sqrt(K) - 1) / (sqrt(K) + 1);
    const double tol = fmax(e->o.tol, BAND_TOL);
    b->iters = 1;
    while (2 * pow(c, b->iters) / (1 + pow(c, 2 * b->iters)) > tol && b->iters < 1000)
        b->iters++;
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
        const size_t g0 = b->roff[q] * R, g1 = (b->roff[q] + 1 + (b->runs[q].x1 - b->runs[q].x0)) * R;
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
static inline __attribute__((always_inline)) void band_seg(const struct band *b, const bseg *g,
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
BAND_KERNEL static void band_segs(const struct band *b, size_t q0, size_t q1, const float *cur,
                                  float *out, float a, float c)
{
    for (size_t q = q0; q < q1; q++)
        band_seg(b, &b->segs[q], cur, out, a, c);
}

/* One Chebyshev sweep on the band (every segment). */
static void band_sweep(const struct band *b, const float *cur, float *out, float a, float c)
{
#pragma omp parallel if (b->cells >= BAND_PAR_MIN)
    {
        const size_t nt = (size_t)omp_get_num_threads(), t = (size_t)omp_get_thread_num();
        band_segs(b, b->nsegs * t / nt, b->nsegs * (t + 1) / nt, cur, out, a, c);
    }
}

/* The first sweep from x0 = 0: x1 = c D^-1 f, and x0 = 0 (the previous
 * iterate of the second sweep) on the band's cells. */
static void band_first(const struct band *b, float *x0, float *x1, float c)
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

static void band_plane(const struct band *b, int p, const float *cur, float *out, float a, float c)
{
    band_segs(b, b->kstart[p], b->kstart[p + 1], cur, out, a, c);
}

/* Two Chebyshev sweeps in one pass over memory (3D): plane p gets the first
 * (A -> B) and plane p - 1 the second (B -> A) right after, while its
 * neighbours are still in cache. Plane p - 1's old A values are read by the
 * first sweep of planes p - 2 .. p only, all done by then. Threads take slabs
 * of planes; a slab's first and last planes get their second sweep after a
 * barrier, when the neighbouring slabs' first sweeps are done. */
static void band_sweep2(const hv_extender *e, const struct band *b, float *A, float *B, float a1,
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
static void band_residual(const struct band *b, const float *u, double *acc, double *r2,
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
            for (size_t x = 0, y = 0; x < g->len; x++)
                for (int r = 0; r < R; r++, y++) {
                    double sum = (double)nb[0][y] + nb[1][y] + nb[2][y] + nb[3][y] +
                                 v[(ptrdiff_t)y - R] + v[y + R];
                    double res = f[y] - (g->d * (double)v[y] - s * sum);
                    a[r] += res * res;
                    if (fabs(res) > a[R + r])
                        a[R + r] = fabs(res);
                    a[2 * R + r] += (double)f[y] * f[y];
                }
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
static void build_rhs_band(const hv_extender *e, struct band *b, int nfields,
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
 * thr as in solve_level, from the max-norm bound |u - u*| <= |r|_inf (A has
 * unit diagonal excess, ||A^-1||_inf <= 1). */
static hv_status solve_band(hv_extender *e, struct band *b, int nfields, const hv_extend_field *f,
                            double *thr, hv_extend_stats *S)
{
    const int R = b->R;
    const double theta = 1, delta = 1 - 1 / (1 + 2 * e->dim * b->s), sigma = theta / delta;
    build_rhs_band(e, b, nfields, f);
    double *nrm = malloc((3 + 3 * (size_t)omp_get_max_threads()) * R * sizeof *nrm);
    if (!nrm)
        return hv_error(HV_ERR_NOMEM, "extend: out of memory");
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
    /* The compact layout of a run is e->sol's on that run. */
    const int nx = e->n[0];
#pragma omp parallel for if (b->cells >= BAND_PAR_MIN) schedule(static)
    for (size_t q = 0; q < b->nruns; q++) {
        const xrun *r = &b->runs[q];
        const size_t c0 = (size_t)nx * (r->j + (size_t)e->n[1] * r->k) + r->x0;
        memcpy(e->sol + c0 * R, cur + (b->roff[q] + 1) * R,
               (size_t)(r->x1 - r->x0) * R * sizeof(float));
    }
    S->solves += R;
    S->relres = fmax(S->relres, relmax);
    S->solve_cells = b->cells;
    *thr = fmax(RELIABLE * rinf0, 1e-30);
    return HV_OK;
}

typedef struct {
    int lo[3], hi[3]; /* inclusive; lo > hi when empty */
} ibox;

static void box_empty(ibox *b)
{
    for (int a = 0; a < 3; a++) {
        b->lo[a] = 1 << 30;
        b->hi[a] = -(1 << 30);
    }
}

static void box_add(ibox *b, int i, int j, int k)
{
    const int p[3] = {i, j, k};
    for (int a = 0; a < 3; a++) {
        if (p[a] < b->lo[a])
            b->lo[a] = p[a];
        if (p[a] > b->hi[a])
            b->hi[a] = p[a];
    }
}

static void box_union(ibox *b, const ibox *o)
{
    for (int a = 0; a < 3; a++) {
        if (o->lo[a] < b->lo[a])
            b->lo[a] = o->lo[a];
        if (o->hi[a] > b->hi[a])
            b->hi[a] = o->hi[a];
    }
}

/* Smallest size >= m, a multiple of 4 with no prime factor above 7 (fast
 * transforms, even multigrid coarsening), or cap when that is larger. */
static int nice_size(int m, int cap)
{
    for (int s = (m + 3) & ~3; s < cap; s += 4) {
        int r = s;
        for (int p = 2; p <= 7; p++)
            while (r % p == 0)
                r /= p;
        if (r == 1)
            return s;
    }
    return cap;
}

/* Grows b by g cells on every side, then to a nice size, within the grid:
 * lo and size. */
static void box_grow(const hv_extender *e, const ibox *b, int g, int lo[3], int bn[3])
{
    for (int a = 0; a < 3; a++) {
        int l = b->lo[a] - g, h = b->hi[a] + g;
        if (l < 0)
            l = 0;
        if (h > e->n[a] - 1)
            h = e->n[a] - 1;
        int m = nice_size(h - l + 1, e->n[a]);
        l -= (m - (h - l + 1)) / 2;
        if (l < 0)
            l = 0;
        if (l + m > e->n[a])
            l = e->n[a] - m;
        lo[a] = l;
        bn[a] = m;
    }
}

hv_status hv_extend_many(hv_extender *e, const float *phi, int nfields,
                         const hv_extend_field *f, hv_extend_stats *stats)
{
    double t_start = hv_now();
    if (!e || !phi || nfields < 0 || (nfields > 0 && !f))
        return hv_error(HV_ERR_INVALID_ARG, "hv_extend_many: bad arguments");
    hv_extend_stats lst;
    hv_extend_stats *S = stats ? stats : &lst;
    memset(S, 0, sizeof *S);
    int nrhs = 1;
    if (nfields > MAX_FIELDS_PER_CALL)
        return hv_error(HV_ERR_INVALID_ARG, "extend: %d fields in one call, at most %d", nfields,
                        MAX_FIELDS_PER_CALL);
    for (int i = 0; i < nfields; i++) {
        if (f[i].ncomp < 1 || f[i].ncomp > 3)
            return hv_error(HV_ERR_INVALID_ARG, "extend: field %d has %d components (1 to 3)", i,
                            f[i].ncomp);
        for (int q = 0; q < f[i].ncomp; q++)
            if (!f[i].in[q] || !f[i].out[q])
                return hv_error(HV_ERR_INVALID_ARG, "extend: field %d component %d has no array", i, q);
        nrhs += f[i].ncomp == 1 ? 1 : f[i].ncomp + 1;
    }
    hv_status st;
    if (e->o.backend == HV_BACKEND_OPENCL) {
        if ((st = hv_check_finite(phi, e->count, "the level set")))
            return st;
        const hv_extend_grid g = {e, e->dim, {e->n[0], e->n[1], e->n[2]}, e->h, e->count, e->solid, &e->o};
        st = hv_extend_cl_run(&e->cl, &g, phi, nfields, f, nrhs, S);
        S->t_total = hv_now() - t_start;
        return st;
    }
    double t0 = hv_now();
    /* The band solve (short times, no obstacles; CPU backends only: an explicit
     * fftw or opencl backend gets its own solver): its cells start from the
     * weights, the closest points' stencils and the cells read at themselves. */
    struct band band;
    memset(&band, 0, sizeof band);
    uint8_t *need = NULL;
    if (!e->solid && !e->o.box_only && e->o.t_scale <= BAND_MAX_T_SCALE &&
        (e->o.backend == HV_BACKEND_AUTO || e->o.backend == HV_BACKEND_MG) &&
        (e->bneed || (e->bneed = hv_malloc(e->count))))
        need = e->bneed;

    /* One pass over the grid: the weights (a smooth bump of |phi| / (band h) on
     * fluid cells), phi and the fields where they are read (the weighted
     * cells) checked for NaN/Inf, and the output cells classified: pending 0 =
     * background, 1 = read at the closest point, 2 = read at the cell. The
     * weighted cells and the cells read at themselves are boxed; the band
     * solve's cells start from the weights and the closest points' stencils
     * (need is only ever set here, so the stencils' marks from other rows
     * cannot be lost). Nothing is written to the outputs before the checks
     * pass: they may alias the inputs. */
    if (!e->pending && !(e->pending = hv_malloc(e->count)))
        return hv_error(HV_ERR_NOMEM, "extend: out of memory");
    uint8_t *pending = e->pending;
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
                    pending[c] = evaluation_point(e, phi, i, j, k, 1, idx, wt, &m) ? 1 : 2;
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
        return hv_error(HV_ERR_NUMERIC, "extend: the level set holds a non-finite value (%g) at cell %zu",
                        (double)phi[badphi], badphi);
    for (int i = 0; i < nfields && badf != SIZE_MAX; i++)
        for (int q = 0; q < f[i].ncomp; q++)
            if (!isfinite(f[i].in[q][badf]))
                return hv_error(HV_ERR_NUMERIC,
                                "extend: field %d component %d is NaN/Inf at cell %zu, inside "
                                "the source band", i, q, badf);
    S->source_cells = nsrc;
    if (!nsrc)
        return hv_error(HV_ERR_INVALID_ARG,
                        "extend: no fluid cell has |phi| < band * h = %g (the level set has no "
                        "zero crossing in the grid, or the band is too thin)", bh);
    if ((st = ensure_solutions(e, nrhs)))
        return st;
    S->t_weights = hv_now() - t0;

    /* The background, on the cells no level will write: runs of each row. */
    t0 = hv_now();
    if (npend < e->count) {
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
    S->t_eval = hv_now() - t0;
    t0 = hv_now();
    if (need) {
        int lo[3], bn[3];
        hv_extend_level_box(e, band_box.lo, band_box.hi, ratio_box.lo, ratio_box.hi, 0, lo, bn);
        band.need = need;
        int built = band_build(e, &band, (size_t)bn[0] * bn[1] * (e->dim == 3 ? bn[2] : 1), nrhs);
        if (built < 0) {
            band_free(&band);
            return hv_error(HV_ERR_NOMEM, "extend: out of memory for the band solve");
        }
        if (!built)
            band_free(&band);
    }
    S->t_solve = hv_now() - t0;

    for (int l = 0; l < e->o.max_levels && npend > 0; l++) {
        double thr;
        int lo[3], bn[3];
        hv_extend_level_box(e, band_box.lo, band_box.hi, ratio_box.lo, ratio_box.hi, l, lo, bn);
        t0 = hv_now();
        const uint8_t *trusted = l == 0 && band.runs ? band.need : NULL;
        if ((st = trusted ? solve_band(e, &band, nfields, f, &thr, S)
                          : solve_level(e, l, lo, bn, nrhs, nfields, f, &thr, S)))
            break;
        S->t_solve += hv_now() - t0;
        S->levels = l + 1;
        t0 = hv_now();
        const int last = l + 1 == e->o.max_levels;
        size_t left = 0, cp = 0, ratio = 0, weak = 0;
        /* The cells left for the next level are boxed as they are met. */
        box_empty(&ratio_box);
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
                        if (pending[c] == 1)
                            at_cp = evaluation_point(e, phi, i, j, k, 0, idx, wt, &m);
                        double val[1 + 4 * MAX_FIELDS_PER_CALL];
                        sample_all(e, idx, wt, m, val);
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
            box_union(&ratio_box, &lr);
        }
        S->cp_cells += cp;
        S->ratio_cells += ratio;
        S->weak_cells += weak;
        npend = left;
        S->t_eval += hv_now() - t0;
    }
    band_free(&band);
    S->t_total = hv_now() - t_start;
    return st;
}

static hv_status check_grid(const hv_extender *e, const hv_grid *g, const hv_grid *phi,
                            const char *what)
{
    if (!g)
        return hv_error(HV_ERR_INVALID_ARG, "extend: %s is NULL", what);
    if (g->dim != e->dim || g->n[0] != e->n[0] || g->n[1] != e->n[1] || g->n[2] != e->n[2] ||
        fabs(g->h - e->h) > 1e-9 * e->h)
        return hv_error(HV_ERR_INVALID_ARG,
                        "extend: %s is %dD %d x %d x %d with h = %g; the extender was made for %dD "
                        "%d x %d x %d with h = %g", what, g->dim, g->n[0], g->n[1], g->n[2], g->h,
                        e->dim, e->n[0], e->n[1], e->n[2], e->h);
    for (int a = 0; a < 3; a++)
        if (fabs(g->origin[a] - phi->origin[a]) > 1e-6 * e->h)
            return hv_error(HV_ERR_INVALID_ARG,
                            "extend: %s has origin (%g %g %g), the level set (%g %g %g)", what,
                            g->origin[0], g->origin[1], g->origin[2], phi->origin[0],
                            phi->origin[1], phi->origin[2]);
    return HV_OK;
}

hv_status hv_extend_scalar(hv_extender *e, const hv_grid *phi, const hv_grid *field,
                           hv_grid *out, hv_extend_stats *stats)
{
    if (!e || !phi)
        return hv_error(HV_ERR_INVALID_ARG, "hv_extend_scalar: NULL argument");
    hv_status st;
    if ((st = check_grid(e, phi, phi, "the level set")) || (st = check_grid(e, field, phi, "the field")) ||
        (st = check_grid(e, out, phi, "the output")))
        return st;
    hv_extend_field f = {1, {field->v, NULL, NULL}, {out->v, NULL, NULL}};
    return hv_extend_many(e, phi->v, 1, &f, stats);
}

hv_status hv_extend_vec3(hv_extender *e, const hv_grid *phi, const hv_grid *const in[3],
                         hv_grid *const out[3], hv_extend_stats *stats)
{
    if (!e || !phi || !in || !out)
        return hv_error(HV_ERR_INVALID_ARG, "hv_extend_vec3: NULL argument");
    hv_status st;
    if ((st = check_grid(e, phi, phi, "the level set")))
        return st;
    hv_extend_field f = {3, {NULL, NULL, NULL}, {NULL, NULL, NULL}};
    static const char *names[3] = {"the x component", "the y component", "the z component"};
    for (int q = 0; q < 3; q++) {
        if ((st = check_grid(e, in[q], phi, names[q])) || (st = check_grid(e, out[q], phi, "an output")))
            return st;
        f.in[q] = in[q]->v;
        f.out[q] = out[q]->v;
    }
    return hv_extend_many(e, phi->v, 1, &f, stats);
}

void hv_extend_level_box(const hv_extender *e, const int wlo[3], const int whi[3],
                         const int rlo[3], const int rhi[3], int l, int lo[3], int bn[3])
{
    ibox need, r;
    for (int a = 0; a < 3; a++) {
        need.lo[a] = wlo[a] - 2;
        need.hi[a] = whi[a] + 2;
        r.lo[a] = rlo[a];
        r.hi[a] = rhi[a];
    }
    box_union(&need, &r);
    box_grow(e, &need, (int)ceil(BOX_MARGIN * sqrt(e->o.t_scale) * pow(sqrt(LEVEL_FACTOR), l)), lo,
             bn);
    if (e->dim == 2) {
        lo[2] = 0;
        bn[2] = 1;
    }
}
