/* The diffusion levels of the extension off a level set (extend_internal.h):
 * level l diffuses for t_scale h^2 16^l on a box around the cells it must
 * answer for. The boxes and the solvers are shared by the host path and the
 * OpenCL path (extend_cl.c); the box solve of every right-hand side is the
 * host's. */
#include "extend_internal.h"
#include "core/error.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

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

void hv__extend_level_box(const hv_extender *e, const int wlo[3], const int whi[3],
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
    if (wlo[0] > whi[0] && rlo[0] > rhi[0]) {
        /* Nothing to solve for (a rank of a distributed extension whose box
         * holds no weight and no cell read at itself): one cell. */
        for (int a = 0; a < 3; a++) {
            lo[a] = 0;
            bn[a] = 1;
        }
        return;
    }
    box_grow(e, &need, (int)ceil(BOX_MARGIN * sqrt(e->o.t_scale) * pow(sqrt(LEVEL_FACTOR), l)), lo,
             bn);
    if (e->dim == 2) {
        lo[2] = 0;
        bn[2] = 1;
    }
}

hv_status hv__extend_level_solver(int dim, const int n[3], double h, const uint8_t *solid,
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
            return hv__error(HV_ERR_NOMEM, "extend: out of memory");
        for (size_t b = 0; b < bcount; b++) {
            size_t bi = b % (size_t)bn[0], bj = (b / (size_t)bn[0]) % (size_t)bn[1];
            size_t bk = b / ((size_t)bn[0] * bn[1]);
            sub[b] =
                solid[(lo[0] + bi) + (size_t)n[0] * ((lo[1] + bj) + (size_t)n[1] * (lo[2] + bk))];
        }
    }
    hv_problem p = {
        dim, {bn[0], bn[1], bn[2]}, h, sub, 1.0, o->t_scale * h * h * pow(LEVEL_FACTOR, l)};
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

hv_status hv__extend_solve_level(hv_extender *e, int l, const int lo[3], const int bn[3], int nrhs,
                                 int nfields, const hv_extend_field *f, double *thr,
                                 hv_extend_stats *S)
{
    hv_status st = hv__extend_level_solver(e->dim, e->n, e->h, e->solid, &e->o, e->o.backend, l, lo,
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
            size_t c =
                (lo[0] + bi) + (size_t)e->n[0] * ((lo[1] + bj) + (size_t)e->n[1] * (lo[2] + bk));
            out[c * k + r] = (float)ud[b];
        }
        S->solves++;
    }
    S->relres = fmax(S->relres, relmax);
    if (l == 0)
        S->solve_cells = bcount;
    /* The bound is the larger of the achieved residual and the requested one,
     * so that every backend (and the extension on a DMDA, on any number of
     * ranks) trusts the same cells. Float storage caps the range too: trust
     * W only well above float's smallest normal. */
    *thr = fmax(RELIABLE * fmax(fmax(relmax, e->o.tol), 1e-14) * wn, 1e-30);
    return HV_OK;
}
