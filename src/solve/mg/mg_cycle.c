/*
 * The CPU multigrid's cycles (docs/METHOD.md, "The V-cycle"): smoothing by
 * red-black Gauss-Seidel (fused on plain 3D levels), weighted Jacobi or
 * Chebyshev; the V-cycle, with the symmetric variant that preconditions CG;
 * full multigrid; the bottom level solved by hv__mg_bottom_cg (mg_setup.c).
 */
#include "mg_internal.h"

static void smooth(const mg_state *m, mg_level *L, int steps, int reverse)
{
    if (steps <= 0)
        return;
    if (m->smoother == HV_SMOOTH_RBGS) {
        int fused = mg_level_sweep_fusable(m, L);
        for (int s = 0; s < steps; s++) {
            if (fused) {
                hv__mg_fused_pass(m, L, NULL, MG_FS_PLAIN, reverse ? 1 : 0);
                continue;
            }
            hv__mg_rb_sweep(m, L, reverse ? 1 : 0);
            hv__mg_rb_sweep(m, L, reverse ? 0 : 1);
        }
    } else if (m->smoother == HV_SMOOTH_JACOBI) {
        double omega = m->dim == 3 ? 6.0 / 7.0 : 4.0 / 5.0;
        for (int s = 0; s < steps; s++) {
            hv__mg_level_residual(m, L);
            hv__mg_level_jacobi_update(m, L, 0.0, omega);
        }
    } else {
        /* Chebyshev of degree 2*steps on [lmax/8, lmax]. */
        double lmax = L->lmax, lmin = lmax / 8;
        double theta = 0.5 * (lmax + lmin), delta = 0.5 * (lmax - lmin);
        double sigma = theta / delta, rho_old = 1.0 / sigma;
        hv__mg_level_residual(m, L);
        hv__mg_level_jacobi_update(m, L, 0.0, 1.0 / theta);
        for (int s = 1; s < 2 * steps; s++) {
            double rho = 1.0 / (2 * sigma - rho_old);
            hv__mg_level_residual(m, L);
            hv__mg_level_jacobi_update(m, L, rho * rho_old, 2 * rho / delta);
            rho_old = rho;
        }
    }
}

static void restrict_residual(const mg_state *m, const mg_level *F, mg_level *C)
{
    hv__mg_restrict_field(m, F, F->r, C);
}

static void restrict_transpose(const mg_state *m, int l)
{
    hv__mg_restrict_transpose(&m->lv[l], &m->lv[l + 1], m->dim, m->pnorm[l], m->lv[l].r,
                              m->lv[l + 1].f, m->rt_work, m->rt_threads);
}

static void bottom_solve(const mg_state *m, mg_level *L)
{
    hv__mg_bottom_cg(L, m->dim, m->alpha, L->f, L->u, L->bwork);
}

/* The V-cycle of the aggregation hierarchy: the fine level smooths as the
 * geometric cycle does, the coarse levels correct its residual (agg_cycle.c). */
static void vcycle_agg(const mg_state *m, int guess, int sym)
{
    mg_level *L = (mg_level *)&m->lv[0];
    if (!guess)
        mg_zero_f(L->u, L->count);
    if (m->smoother != HV_SMOOTH_RBGS)
        mg_zero_f(L->d, L->count);
    smooth(m, L, m->pre, 0);
    hv__mg_level_residual(m, L);
    hv__mg_agg_correct(m->agg, L->r, L->u);
    if (m->smoother != HV_SMOOTH_RBGS)
        mg_zero_f(L->d, L->count);
    smooth(m, L, m->post, sym);
}

/* One V-cycle on level l for A u_l = f_l; u_l holds the initial guess when
 * `guess`, else starts from zero. `sym` reverses the post-smoothing order. */
void hv__mg_vcycle(const mg_state *m, int l, int guess, int sym)
{
    mg_level *L = (mg_level *)&m->lv[l];
    if (m->agg && l == 0) {
        vcycle_agg(m, guess, sym);
        return;
    }
    if (l == m->nlev - 1) {
        bottom_solve(m, L);
        return;
    }
    mg_level *C = (mg_level *)&m->lv[l + 1];
    if (m->smoother == HV_SMOOTH_RBGS && !sym && m->pre >= 1 && m->post >= 1 &&
        mg_level_fusable(m, L)) {
        /* Same arithmetic as below, fewer passes over the level. */
        int s0 = 0;
        if (!guess) {
            if (m->pre >= 2) {
                hv__mg_fused_pass(m, L, NULL, MG_FS_ZERO, 0);
                s0 = 1;
            } else {
                mg_zero_f(L->u, L->count);
            }
        }
        for (int s = s0; s < m->pre - 1; s++)
            hv__mg_fused_pass(m, L, NULL, MG_FS_PLAIN, 0);
        hv__mg_fused_pass(m, L, C, MG_FS_RESTRICT, 0);
        hv__mg_vcycle(m, l + 1, 0, sym);
        int s1 = 0;
        if (C->plain && C->n[0] <= MG_ROW_BUF) {
            hv__mg_fused_pass(m, L, (mg_level *)C, MG_FS_PROLONG, 0);
            s1 = 1;
        } else {
            hv__mg_prolong_add(m, L, C, 0);
        }
        for (int s = s1; s < m->post; s++)
            hv__mg_fused_pass(m, L, NULL, MG_FS_PLAIN, 0);
        return;
    }
    if (!guess)
        mg_zero_f(L->u, L->count);
    if (m->smoother != HV_SMOOTH_RBGS)
        mg_zero_f(L->d, L->count);
    smooth(m, L, m->pre, 0);
    hv__mg_level_residual(m, L);
    if (sym)
        restrict_transpose(m, l);
    else
        restrict_residual(m, L, (mg_level *)&m->lv[l + 1]);
    hv__mg_vcycle(m, l + 1, 0, sym);
    hv__mg_prolong_add(m, L, &m->lv[l + 1], 0);
    if (m->smoother != HV_SMOOTH_RBGS)
        mg_zero_f(L->d, L->count);
    smooth(m, L, m->post, sym);
}

/* Full multigrid: restrict f down, solve the bottom, then interpolate and
 * V-cycle on each finer level (docs/METHOD.md, "Multigrid": meant for Poisson;
 * measured, it also takes the heat step's first factor from 0.014 to 0.009). */
void hv__mg_fmg(const mg_state *m)
{
    for (int l = 0; l + 1 < m->nlev; l++) {
        mg_level *F = (mg_level *)&m->lv[l];
        hv__mg_restrict_field(m, F, F->f, (mg_level *)&m->lv[l + 1]);
    }
    bottom_solve(m, (mg_level *)&m->lv[m->nlev - 1]);
    for (int l = m->nlev - 2; l >= 0; l--) {
        mg_level *L = (mg_level *)&m->lv[l];
        hv__mg_prolong_add(m, L, &m->lv[l + 1], 1);
        hv__mg_vcycle(m, l, 1, 0);
    }
}
