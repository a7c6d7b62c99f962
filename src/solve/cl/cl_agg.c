/*
 * The coarse levels by smoothed aggregation on an OpenCL device (cl_mg.h):
 * built on the host as for the CPU backend (src/solve/mg/agg_*.c), uploaded once, and
 * cycled with kernels/agg.cl on the same in-order queue as the fine level.
 * The bottom level (at most a few hundred unknowns) is solved on the host by
 * its Cholesky factor: one read and one write per cycle.
 */
#include "cl_mg.h"
#include "core/error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define AGG_DEGREE 2 /* Chebyshev degree on the coarse levels, as agg_cycle.c */

/* A CSR matrix on the device, row starts as uint. */
static hv_status upload_csr(hv_cl *cl, const mg_csr *M, cl_mem *rp, cl_mem *ci, cl_mem *v)
{
    size_t nnz = M->rp[M->n];
    if (nnz > 0xffffffffu)
        return hv__error(HV_ERR_UNSUPPORTED,
                         "OpenCL multigrid: a coarse level of %zu entries exceeds 2^32", nnz);
    cl_uint *r = malloc(((size_t)M->n + 1) * sizeof *r);
    if (!r)
        return hv__error(HV_ERR_NOMEM, "OpenCL multigrid: out of memory for a coarse level");
    for (int32_t i = 0; i <= M->n; i++)
        r[i] = (cl_uint)M->rp[i];
    hv_status st = hv__cl_alloc(cl, ((size_t)M->n + 1) * sizeof *r, r, rp);
    free(r);
    if (!st)
        st = hv__cl_alloc(cl, (nnz ? nnz : 1) * sizeof(cl_int), M->ci, ci);
    if (!st)
        st = hv__cl_alloc(cl, (nnz ? nnz : 1) * sizeof(float), M->v, v);
    return st;
}

/* Work vectors of n floats, zeroed. */
static hv_status work(hv_cl *cl, size_t n, cl_mem *const *out, int count)
{
    for (int i = 0; i < count; i++) {
        hv_status st = hv__cl_alloc(cl, (n ? n : 1) * sizeof(float), NULL, out[i]);
        if (st)
            return st;
        hv__cl_zero(cl, *out[i], (n ? n : 1) * sizeof(float));
    }
    return HV_OK;
}

/* A level's aggregates (agg) and the next level's members (mrp, mem). */
static hv_status upload_members(hv_cl *cl, const mg_alevel *L, int32_t nc, cl_mem *agg,
                                cl_mem *mrp_out, cl_mem *mem)
{
    size_t members = L->mrp[nc];
    cl_uint *mrp = malloc(((size_t)nc + 1) * sizeof *mrp);
    if (!mrp)
        return hv__error(HV_ERR_NOMEM, "OpenCL multigrid: out of memory for the aggregates");
    for (int32_t I = 0; I <= nc; I++)
        mrp[I] = (cl_uint)L->mrp[I];
    hv_status st = hv__cl_alloc(cl, ((size_t)nc + 1) * sizeof *mrp, mrp, mrp_out);
    free(mrp);
    if (!st)
        st = hv__cl_alloc(cl, (members ? members : 1) * sizeof(cl_int), L->mem, mem);
    if (!st)
        st = hv__cl_alloc(cl, (size_t)L->n * sizeof(cl_int), L->agg, agg);
    return st;
}

static hv_status upload_fine(hv_cl *cl, hv_clagg *G, const mg_agg *g)
{
    const mg_alevel *L = &g->lv[0];
    G->n0 = L->n;
    G->n1 = g->lv[1].n;
    G->wp0 = 4.0 / 3.0 / L->lmax;
    hv_status st = upload_members(cl, L, G->n1, &G->agg0, &G->mrp0, &G->mem0);
    if (!st)
        st = hv__cl_alloc(cl, (size_t)G->n0 * sizeof(float), g->fine->dinv, &G->dinv0);
    cl_mem *w[] = {&G->r0, &G->t0, &G->s0};
    if (!st)
        st = work(cl, (size_t)G->n0, w, 3);
    return st;
}

static hv_status upload_level(hv_cl *cl, hv_clagg *G, const mg_agg *g, int l)
{
    const mg_alevel *S = &g->lv[l];
    hv_clagg_level *L = &G->lv[l];
    L->n = S->n;
    L->lmax = S->lmax;
    hv_status st = upload_csr(cl, &S->A, &L->rp, &L->ci, &L->v);
    if (!st && l + 1 < g->nlev && S->P.rp) {
        st = upload_csr(cl, &S->P, &L->prp, &L->pci, &L->pv);
        if (!st)
            st = upload_csr(cl, &S->R, &L->rrp, &L->rci, &L->rv);
    } else if (!st && l + 1 < g->nlev) {
        st = upload_members(cl, S, g->lv[l + 1].n, &L->agg, &L->mrp, &L->mem);
        cl_mem *w[] = {&L->t, &L->s};
        if (!st)
            st = work(cl, (size_t)S->n, w, 2);
        L->wp = 4.0 / 3.0 / S->lmax;
    }
    if (!st)
        st = hv__cl_alloc(cl, (size_t)S->n * sizeof(float), S->dinv, &L->dinv);
    if (!st && S->tn) {
        L->tn = S->tn;
        st = hv__cl_alloc(cl, (size_t)S->n, S->plain, &L->plain);
        if (!st)
            st = hv__cl_alloc(cl, (size_t)S->tn * sizeof(cl_int), S->toff, &L->toff);
        if (!st)
            st = hv__cl_alloc(cl, (size_t)S->tn * sizeof(float), S->tval, &L->tval);
    }
    cl_mem *w[] = {&L->u, &L->f, &L->r, &L->d};
    if (!st)
        st = work(cl, (size_t)S->n, w, 4);
    return st;
}

void hv__clagg_destroy(hv_clmg *m)
{
    hv_clagg *G = m->agg;
    if (!G)
        return;
    for (int l = 0; l < MG_AGG_MAX_LEVELS; l++) {
        hv_clagg_level *L = &G->lv[l];
        cl_mem *all[] = {&L->rp,   &L->ci,   &L->v,   &L->prp, &L->pci, &L->pv, &L->rrp,   &L->rci,
                         &L->rv,   &L->dinv, &L->u,   &L->f,   &L->r,   &L->d,  &L->plain, &L->toff,
                         &L->tval, &L->agg,  &L->mrp, &L->mem, &L->t,   &L->s};
        for (size_t i = 0; i < sizeof all / sizeof all[0]; i++)
            hv__cl_free(all[i]);
    }
    cl_mem *fine[] = {&G->agg0, &G->mrp0, &G->mem0, &G->dinv0, &G->r0, &G->t0, &G->s0};
    for (size_t i = 0; i < sizeof fine / sizeof fine[0]; i++)
        hv__cl_free(fine[i]);
    hv__mg_agg_free(G->host);
    free(G->bf);
    free(G->bu);
    free(G);
    m->agg = NULL;
}

hv_status hv__clagg_create(hv_clmg *m, const mg_level *F, int dim, double alpha)
{
    mg_agg *g = NULL;
    hv_status st = hv__mg_agg_build(&g, F, dim, alpha);
    if (st || !g)
        return st;
    hv_clagg *G = calloc(1, sizeof *G);
    if (!G) {
        hv__mg_agg_free(g);
        return hv__error(HV_ERR_NOMEM, "OpenCL multigrid: out of memory");
    }
    m->agg = G;
    G->host = g;
    G->nlev = g->nlev;
    st = upload_fine(m->cl, G, g);
    for (int l = 1; l < g->nlev && !st; l++)
        st = upload_level(m->cl, G, g, l);
    if (!st) {
        G->bf = malloc(((size_t)g->nb + 1) * sizeof *G->bf);
        G->bu = malloc(((size_t)g->nb + 1) * sizeof *G->bu);
        if (!G->bf || !G->bu)
            st = hv__error(HV_ERR_NOMEM, "OpenCL multigrid: out of memory for the bottom level");
    }
    if (!st)
        st = hv__cl_finish(m->cl);
    if (st)
        hv__clagg_destroy(m);
    else
        hv__mg_agg_keep_bottom(g);
    return st;
}

/* ---------- the cycle ---------- */

static void range(int n, size_t g[1], size_t l[1]) { hv__cl_range1((size_t)(n > 0 ? n : 1), g, l); }

static void residual(hv_cl *cl, hv_clagg_level *L)
{
    size_t g[1], lw[1];
    range(L->n, g, lw);
    hv__cl_args(cl, HV_CLSOLVE, HV_K_AGG_RESIDUAL, "immmmimmmmm", L->n, L->rp, L->ci, L->v,
                L->plain, L->tn, L->toff, L->tval, L->u, L->f, L->r);
    hv__cl_run(cl, HV_CLSOLVE, HV_K_AGG_RESIDUAL, 1, g, lw);
}

static void cheb(hv_cl *cl, hv_clagg_level *L, cl_mem r, double cd, double cr, int zero)
{
    size_t g[1], lw[1];
    range(L->n, g, lw);
    hv__cl_args(cl, HV_CLSOLVE, HV_K_AGG_CHEB, "immmmffi", L->n, L->dinv, r, L->d, L->u, cd, cr,
                zero);
    hv__cl_run(cl, HV_CLSOLVE, HV_K_AGG_CHEB, 1, g, lw);
}

/* Chebyshev of degree AGG_DEGREE on [lmax/8, lmax], as agg_cycle.c's
 * level_smooth; from u = 0 when `zero` (its first step needs no residual). */
static void smooth(hv_cl *cl, hv_clagg_level *L, int zero)
{
    double lmax = L->lmax, lmin = lmax / 8;
    double theta = 0.5 * (lmax + lmin), delta = 0.5 * (lmax - lmin);
    double sigma = theta / delta, rho_old = 1.0 / sigma;
    for (int s = 0; s < AGG_DEGREE; s++) {
        double cd = 0, cr = 1.0 / theta;
        if (s > 0) {
            double rho = 1.0 / (2 * sigma - rho_old);
            cd = rho * rho_old;
            cr = 2 * rho / delta;
            rho_old = rho;
        }
        if (s == 0 && zero) {
            cheb(cl, L, L->f, 0.0, cr, 1);
            continue;
        }
        residual(cl, L);
        cheb(cl, L, L->r, cd, cr, 0);
    }
}

static void spmv(hv_cl *cl, int n, cl_mem rp, cl_mem ci, cl_mem v, cl_mem x, cl_mem y)
{
    size_t g[1], lw[1];
    range(n, g, lw);
    hv__cl_args(cl, HV_CLSOLVE, HV_K_AGG_SPMV, "immmmm", n, rp, ci, v, x, y);
    hv__cl_run(cl, HV_CLSOLVE, HV_K_AGG_SPMV, 1, g, lw);
}

static void bottom(hv_cl *cl, hv_clagg *G)
{
    hv_clagg_level *L = &G->lv[G->nlev - 1];
    size_t bytes = (size_t)L->n * sizeof(float);
    hv__cl_read(cl, L->f, 0, bytes, G->bf);
    if (cl->err)
        return;
    hv__mg_agg_bottom(G->host, G->bf, G->bu);
    hv__cl_write(cl, L->u, 0, bytes, G->bu);
}

/* y = A x on coarse level L (template rows included) */
static void apply(hv_cl *cl, hv_clagg_level *L, cl_mem x, cl_mem y)
{
    size_t g[1], lw[1];
    range(L->n, g, lw);
    hv__cl_args(cl, HV_CLSOLVE, HV_K_AGG_APPLY, "immmmimmmm", L->n, L->rp, L->ci, L->v, L->plain,
                L->tn, L->toff, L->tval, x, y);
    hv__cl_run(cl, HV_CLSOLVE, HV_K_AGG_APPLY, 1, g, lw);
}

/* C->f = P^T L->r: from P and P^T where the level keeps them, else as the
 * fine level does, P0^T (r - wp A D^-1 r). */
static void restrict_to(hv_cl *cl, hv_clagg_level *L, hv_clagg_level *C)
{
    if (!L->agg) {
        spmv(cl, C->n, L->rrp, L->rci, L->rv, L->r, C->f);
        return;
    }
    size_t g[1], lw[1], gc[1], lc[1];
    range(L->n, g, lw);
    range(C->n, gc, lc);
    hv__cl_args(cl, HV_CLSOLVE, HV_K_AGG_SCALE, "immm", L->n, L->dinv, L->r, L->t);
    hv__cl_run(cl, HV_CLSOLVE, HV_K_AGG_SCALE, 1, g, lw);
    apply(cl, L, L->t, L->s);
    hv__cl_args(cl, HV_CLSOLVE, HV_K_AGG_RESTRICT0, "immmmfm", C->n, L->mrp, L->mem, L->r, L->s,
                L->wp, C->f);
    hv__cl_run(cl, HV_CLSOLVE, HV_K_AGG_RESTRICT0, 1, gc, lc);
}

/* L->u += P C->u, as restrict_to. */
static void prolong(hv_cl *cl, hv_clagg_level *L, hv_clagg_level *C)
{
    size_t g[1], lw[1];
    range(L->n, g, lw);
    if (!L->agg) {
        hv__cl_args(cl, HV_CLSOLVE, HV_K_AGG_PROLONG, "immmmm", L->n, L->prp, L->pci, L->pv, C->u,
                    L->u);
        hv__cl_run(cl, HV_CLSOLVE, HV_K_AGG_PROLONG, 1, g, lw);
        return;
    }
    hv__cl_args(cl, HV_CLSOLVE, HV_K_AGG_INJECT0, "immm", L->n, L->agg, C->u, L->t);
    hv__cl_run(cl, HV_CLSOLVE, HV_K_AGG_INJECT0, 1, g, lw);
    apply(cl, L, L->t, L->s);
    hv__cl_args(cl, HV_CLSOLVE, HV_K_AGG_PROLONG0, "immmfm", L->n, L->t, L->s, L->dinv, L->wp,
                L->u);
    hv__cl_run(cl, HV_CLSOLVE, HV_K_AGG_PROLONG0, 1, g, lw);
}

/* One symmetric V-cycle from zero on level l >= 1 for lv[l].f into lv[l].u. */
static void cycle(hv_cl *cl, hv_clagg *G, int l)
{
    hv_clagg_level *L = &G->lv[l], *C = &G->lv[l + 1];
    if (l == G->nlev - 1) {
        bottom(cl, G);
        return;
    }
    smooth(cl, L, 1);
    residual(cl, L);
    restrict_to(cl, L, C);
    cycle(cl, G, l + 1);
    prolong(cl, L, C);
    smooth(cl, L, 0);
}

void hv__clagg_correct(hv_clmg *m)
{
    hv_cl *cl = m->cl;
    hv_clagg *G = m->agg;
    hv_clmg_level *F = &m->lv[0];
    size_t g0[1], l0[1], g1[1], l1[1];
    range(G->n0, g0, l0);
    range(G->n1, g1, l1);
    /* f_1 = P0^T (r - wp A D^-1 r) */
    hv__cl_args(cl, HV_CLSOLVE, HV_K_AGG_SCALE, "immm", G->n0, G->dinv0, G->r0, G->t0);
    hv__cl_run(cl, HV_CLSOLVE, HV_K_AGG_SCALE, 1, g0, l0);
    hv__clmg_apply(m, 0, G->t0, G->s0);
    hv__cl_args(cl, HV_CLSOLVE, HV_K_AGG_RESTRICT0, "immmmfm", G->n1, G->mrp0, G->mem0, G->r0,
                G->s0, G->wp0, G->lv[1].f);
    hv__cl_run(cl, HV_CLSOLVE, HV_K_AGG_RESTRICT0, 1, g1, l1);
    cycle(cl, G, 1);
    /* u_0 += t - wp D^-1 A t, t = P0 u_1 */
    hv__cl_args(cl, HV_CLSOLVE, HV_K_AGG_INJECT0, "immm", G->n0, G->agg0, G->lv[1].u, G->t0);
    hv__cl_run(cl, HV_CLSOLVE, HV_K_AGG_INJECT0, 1, g0, l0);
    hv__clmg_apply(m, 0, G->t0, G->s0);
    hv__cl_args(cl, HV_CLSOLVE, HV_K_AGG_PROLONG0, "immmfm", G->n0, G->t0, G->s0, G->dinv0, G->wp0,
                F->u[F->cur]);
    hv__cl_run(cl, HV_CLSOLVE, HV_K_AGG_PROLONG0, 1, g0, l0);
}
