/* One level of the multigrid hierarchy on an OpenCL device (cl_mg.h): the
 * operator, the residual, the smoothers, the transfers and the bottom solve. */
#include "cl_mg.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void hv__clmg_apply(hv_clmg *m, int l, cl_mem u, cl_mem y)
{
    hv_clmg_level *L = &m->lv[l];
    hv__cl_args(m->cl, HV_CLSOLVE, HV_K_MG_APPLY, "IFmmmmmm", L->N, L->C, L->a, L->w[0], L->w[1],
                L->w[2], u, y);
    hv__cl_run(m->cl, HV_CLSOLVE, HV_K_MG_APPLY, 2, L->g, L->l);
}

void hv__clmg_residual(hv_clmg *m, int l, cl_mem u, cl_mem f, cl_mem r)
{
    hv_clmg_level *L = &m->lv[l];
    hv__cl_args(m->cl, HV_CLSOLVE, HV_K_MG_RESIDUAL, "IFmmmmmmm", L->N, L->C, L->a, L->w[0],
                L->w[1], L->w[2], u, f, r);
    hv__cl_run(m->cl, HV_CLSOLVE, HV_K_MG_RESIDUAL, 2, L->g, L->l);
}

static void rbgs(hv_clmg *m, hv_clmg_level *L, int col)
{
    size_t g[2], lw[2];
    hv__cl_range2(((size_t)L->n[0] + 1) / 2, (size_t)L->n[1] * L->n[2], g, lw);
    hv__cl_args(m->cl, HV_CLSOLVE, HV_K_MG_RBGS, "IFmmmmmmi", L->N, L->C, L->a, L->w[0], L->w[1],
                L->w[2], L->u[L->cur], L->f, col);
    hv__cl_run(m->cl, HV_CLSOLVE, HV_K_MG_RBGS, 2, g, lw);
}

/* d = cd d + cr D^-1 (f - A u);  u += d  (ping-pong); cd == 0 runs the
 * kernel that does not read d, zero the one that reads neither d nor u (the
 * step from u = 0, whose contents are then ignored). */
static void cheb_step(hv_clmg *m, hv_clmg_level *L, double cd, double cr, int zero)
{
    if (zero) {
        hv__cl_args(m->cl, HV_CLSOLVE, HV_K_MG_JACOBI0, "IFmmmmmmmf", L->N, L->C, L->a, L->w[0],
                    L->w[1], L->w[2], L->u[1 - L->cur], L->f, L->d, cr);
        hv__cl_run(m->cl, HV_CLSOLVE, HV_K_MG_JACOBI0, 2, L->g, L->l);
    } else if (cd == 0) {
        hv__cl_args(m->cl, HV_CLSOLVE, HV_K_MG_JACOBI, "IFmmmmmmmmf", L->N, L->C, L->a, L->w[0],
                    L->w[1], L->w[2], L->u[L->cur], L->u[1 - L->cur], L->f, L->d, cr);
        hv__cl_run(m->cl, HV_CLSOLVE, HV_K_MG_JACOBI, 2, L->g, L->l);
    } else {
        hv__cl_args(m->cl, HV_CLSOLVE, HV_K_MG_CHEB, "IFmmmmmmmmff", L->N, L->C, L->a, L->w[0],
                    L->w[1], L->w[2], L->u[L->cur], L->u[1 - L->cur], L->f, L->d, cd, cr);
        hv__cl_run(m->cl, HV_CLSOLVE, HV_K_MG_CHEB, 2, L->g, L->l);
    }
    L->cur = 1 - L->cur;
}

/* steps sweeps on level l (RBGS: forward and back; Chebyshev: degree
 * 2*steps); zero: from u = 0, whatever the iterate holds. */
void hv__clmg_smooth(hv_clmg *m, int l, int steps, int reverse, int zero)
{
    hv_clmg_level *L = &m->lv[l];
    if (zero && (steps <= 0 || m->smoother == HV_SMOOTH_RBGS))
        hv__cl_zero(m->cl, L->u[L->cur], L->count * sizeof(float));
    if (steps <= 0)
        return;
    if (m->smoother == HV_SMOOTH_RBGS) {
        for (int s = 0; s < steps; s++) {
            rbgs(m, L, reverse ? 1 : 0);
            rbgs(m, L, reverse ? 0 : 1);
        }
    } else if (m->smoother == HV_SMOOTH_JACOBI) {
        double omega = m->dim == 3 ? 6.0 / 7.0 : 4.0 / 5.0;
        for (int s = 0; s < steps; s++)
            cheb_step(m, L, 0.0, omega, zero && s == 0);
    } else {
        /* Chebyshev of degree 2*steps on [lmax/8, lmax], as the CPU (mg_cycle.c). */
        double lmax = L->lmax, lmin = lmax / 8;
        double theta = 0.5 * (lmax + lmin), delta = 0.5 * (lmax - lmin);
        double sigma = theta / delta, rho_old = 1.0 / sigma;
        cheb_step(m, L, 0.0, 1.0 / theta, zero);
        for (int s = 1; s < 2 * steps; s++) {
            double rho = 1.0 / (2 * sigma - rho_old);
            cheb_step(m, L, rho * rho_old, 2 * rho / delta, 0);
            rho_old = rho;
        }
    }
}

static void coarsen_flags(const hv_clmg_level *F, cl_int co[4])
{
    co[3] = 1;
    for (int b = 0; b < 3; b++) {
        co[b] = F->coarsen[b];
        co[3] *= F->coarsen[b] ? 2 : 1;
    }
}

void hv__clmg_restrict_residual(hv_clmg *m, int l)
{
    hv_clmg_level *F = &m->lv[l], *C = &m->lv[l + 1];
    cl_int co[4];
    coarsen_flags(F, co);
    hv__cl_args(m->cl, HV_CLSOLVE, HV_K_MG_RESTRICT_RESIDUAL, "IFmmmmmmIIm", F->N, F->C, F->a,
                F->w[0], F->w[1], F->w[2], F->u[F->cur], F->f, C->N, co, C->f);
    hv__cl_run(m->cl, HV_CLSOLVE, HV_K_MG_RESTRICT_RESIDUAL, 2, C->g, C->l);
}

void hv__clmg_restrict_transpose(hv_clmg *m, int l)
{
    hv_clmg_level *F = &m->lv[l], *C = &m->lv[l + 1];
    cl_int co[4];
    coarsen_flags(F, co);
    hv__cl_args(m->cl, HV_CLSOLVE, HV_K_MG_RESTRICT_TRANSPOSE, "ImmImIm", F->N, F->r, F->pn, C->N,
                C->a, co, C->f);
    hv__cl_run(m->cl, HV_CLSOLVE, HV_K_MG_RESTRICT_TRANSPOSE, 2, C->g, C->l);
}

void hv__clmg_restrict(hv_clmg *m, int l, cl_mem src, cl_mem dst)
{
    hv_clmg_level *F = &m->lv[l], *C = &m->lv[l + 1];
    cl_int co[4];
    coarsen_flags(F, co);
    hv__cl_args(m->cl, HV_CLSOLVE, HV_K_MG_RESTRICT, "ImIIm", F->N, src, C->N, co, dst);
    hv__cl_run(m->cl, HV_CLSOLVE, HV_K_MG_RESTRICT, 2, C->g, C->l);
}

void hv__clmg_prolong(hv_clmg *m, int l)
{
    hv_clmg_level *F = &m->lv[l], *C = &m->lv[l + 1];
    cl_int co[4];
    coarsen_flags(F, co);
    if (C->plain) {
        size_t g[2], lw[2];
        hv__cl_range2((size_t)C->n[0], (size_t)F->n[1] * F->n[2], g, lw);
        if (F->plain && co[0]) {
            hv__cl_args(m->cl, HV_CLSOLVE, HV_K_MG_PROLONG_X2, "IIImm", F->N, C->N, co,
                        C->u[C->cur], F->u[F->cur]);
            hv__cl_run(m->cl, HV_CLSOLVE, HV_K_MG_PROLONG_X2, 2, g, lw);
        } else {
            hv__cl_args(m->cl, HV_CLSOLVE, HV_K_MG_PROLONG, "ImIImm", F->N, F->a, C->N, co,
                        C->u[C->cur], F->u[F->cur]);
            hv__cl_run(m->cl, HV_CLSOLVE, HV_K_MG_PROLONG, 2, g, lw);
        }
    } else {
        hv__cl_args(m->cl, HV_CLSOLVE, HV_K_MG_PROLONG_W, "ImImImm", F->N, F->a, C->N, C->a, co,
                    C->u[C->cur], F->u[F->cur]);
        hv__cl_run(m->cl, HV_CLSOLVE, HV_K_MG_PROLONG_W, 2, F->g, F->l);
    }
}

/* Devices without fp64: the bottom level on the host in double (a float CG
 * stalls near 1e-5 there, and the coarse correction's error then caps the
 * cycle). */
static void bottom_host(hv_clmg *m)
{
    hv_clmg_level *L = &m->lv[m->nlev - 1];
    const size_t n = m->hb.count;
    hv__cl_read(m->cl, L->f, 0, n * sizeof(float), m->hf);
    if (m->cl->err)
        return;
    hv__mg_bottom_cg(&m->hb, m->dim, m->alpha, m->hf, m->hf, m->hw);
    hv__cl_write(m->cl, L->u[L->cur], 0, n * sizeof(float), m->hf);
}

void hv__clmg_bottom(hv_clmg *m)
{
    if (m->host_bottom) {
        bottom_host(m);
        return;
    }
    hv_clmg_level *L = &m->lv[m->nlev - 1];
    double C[4] = {L->c[0], L->c[1], L->c[2], m->alpha};
    hv__cl_args(m->cl, HV_CLSOLVE, HV_K_MG_BOTTOM_CG, "IAmmmmmmmmim", L->N, C, L->a, L->w[0],
                L->w[1], L->w[2], L->f, L->u[L->cur], m->bregion, m->brinv, m->bnregion, m->bscr);
    hv__cl_run(m->cl, HV_CLSOLVE, HV_K_MG_BOTTOM_CG, 1, &m->bl, &m->bl);
}
