/* Smoothed aggregation (agg_internal.h): the cycle on the coarse levels. */
#include "agg_internal.h"

/* r = f - A u on a coarse level. */
static void level_residual(const agg_op *o, const float *f, const float *u, float *r)
{
    hv__agg_op_apply(o, u, r);
#pragma omp parallel for schedule(static) if (o->n > AGG_PAR_MIN)
    for (int32_t c = 0; c < o->n; c++)
        r[c] = f[c] - r[c];
}

/* Chebyshev smoothing of degree AGG_DEGREE on [lmax/8, lmax] (u from zero
 * when `zero`): the same polynomial before and after, so the cycle is
 * symmetric. */
static void level_smooth(const agg_op *o, mg_alevel *L, int zero)
{
    double lmax = L->lmax, lmin = lmax / 8;
    double theta = 0.5 * (lmax + lmin), delta = 0.5 * (lmax - lmin);
    double sigma = theta / delta, rho_old = 1.0 / sigma;
    int32_t n = o->n;
    for (int s = 0; s < AGG_DEGREE; s++) {
        double cd = 0, cr = 1.0 / theta;
        if (s > 0) {
            double rho = 1.0 / (2 * sigma - rho_old);
            cd = rho * rho_old;
            cr = 2 * rho / delta;
            rho_old = rho;
        }
        if (s == 0 && zero) {
#pragma omp parallel for schedule(static) if (n > AGG_PAR_MIN)
            for (int32_t c = 0; c < n; c++)
                L->r[c] = L->f[c];
        } else {
            level_residual(o, L->f, L->u, L->r);
        }
#pragma omp parallel for schedule(static) if (n > AGG_PAR_MIN)
        for (int32_t c = 0; c < n; c++) {
            float d = (float)((s ? cd * L->d[c] : 0.0) + cr * o->dinv[c] * L->r[c]);
            L->d[c] = d;
            L->u[c] = (s == 0 && zero ? 0.0f : L->u[c]) + d;
        }
    }
}

/* f_{l+1} = P^T r = P0^T (r - wp A D^-1 r) from level l's residual r. */

/* Coefficients of the y-, y+, z-, z+ faces of row R of fine level F: c_b, or 0
 * at the box's faces (where R's neighbour offset is 0, the row itself). */
static void fine_cyz(const mg_level *F, const mg_wrow *R, float c[4])
{
    const float cy = (float)F->c[1], cz = (float)F->c[2];
    c[0] = R->ym ? cy : 0;
    c[1] = R->yp ? cy : 0;
    c[2] = R->zm ? cz : 0;
    c[3] = R->zp ? cz : 0;
}

/* sum_b c_b sum_nb x_nb s_nb (s NULL: 1) over the faces of cell i of a binary
 * fine row that the box has: the row's first and last cells, which the
 * interior loops leave out. */
static float fine_nb_sum(const mg_wrow *R, const float c[4], float cx, int nx, const float *x,
                         const float *s, int i)
{
    const size_t q = R->base + (size_t)i;
    const ptrdiff_t o[4] = {R->ym, R->yp, R->zm, R->zp};
    float v = 0;
    if (i > 0)
        v += cx * x[q - 1] * (s ? s[q - 1] : 1.0f);
    if (i < nx - 1)
        v += cx * x[q + 1] * (s ? s[q + 1] : 1.0f);
    for (int e = 0; e < 4; e++)
        v += c[e] * x[q + o[e]] * (s ? s[q + o[e]] : 1.0f);
    return v;
}

/* Row (j,k) of v = r - wp A D^-1 r on a binary fine level, without forming
 * D^-1 r: A D^-1 r = D dinv r - sum c_b dinv_nb r_nb, where D dinv is 1 on
 * rows with dinv > 0 and 0 on empty ones (solid cells; for Poisson, fluid
 * cells without an open face); dinv is 0 on solid cells, which closes their
 * faces. Neither the cell weights nor D are read. */
static void restrict0_row(const mg_level *F, int dim, double wp, const float *r, float *v, int j,
                          int k)
{
    const mg_wrow R = mg_wrow_at(F, dim, j, k);
    float c[4];
    fine_cyz(F, &R, c);
    const int nx = F->n[0];
    const float cx = (float)F->c[0], w = (float)wp;
    const float *d0 = F->dinv + R.base, *r0 = r + R.base;
    float *vr = v + R.base;
    for (int i = 0; i<nx; i += nx> 1 ? nx - 1 : 1)
        vr[i] = r0[i] - (d0[i] > 0 ? w : 0) * (r0[i] - fine_nb_sum(&R, c, cx, nx, r, F->dinv, i));
    const float *dm = d0 + R.ym, *dp = d0 + R.yp, *dzm = d0 + R.zm, *dzp = d0 + R.zp;
    const float *rm = r0 + R.ym, *rp = r0 + R.yp, *rzm = r0 + R.zm, *rzp = r0 + R.zp;
#pragma omp simd
    for (int i = 1; i < nx - 1; i++) {
        float sn = cx * (d0[i - 1] * r0[i - 1] + d0[i + 1] * r0[i + 1]) + c[0] * dm[i] * rm[i] +
                   c[1] * dp[i] * rp[i] + c[2] * dzm[i] * rzm[i] + c[3] * dzp[i] * rzp[i];
        vr[i] = r0[i] - (d0[i] > 0 ? w : 0) * (r0[i] - sn);
    }
}

/* Row (j,k) of u += t - wp D^-1 A t on a binary fine level, t = P0 u_1 (0 on
 * solid cells): D^-1 A t = t - dinv sum c_b t_nb on rows with dinv > 0, 0 on
 * empty ones. */
static void prolong0_row(const mg_level *F, int dim, double wp, const float *t, float *u, int j,
                         int k)
{
    const mg_wrow R = mg_wrow_at(F, dim, j, k);
    float c[4];
    fine_cyz(F, &R, c);
    const int nx = F->n[0];
    const float cx = (float)F->c[0], w = (float)wp;
    const float *dv = F->dinv + R.base, *t0 = t + R.base;
    float *ur = u + R.base;
    for (int i = 0; i<nx; i += nx> 1 ? nx - 1 : 1)
        ur[i] +=
            t0[i] - (dv[i] > 0 ? w : 0) * (t0[i] - dv[i] * fine_nb_sum(&R, c, cx, nx, t, NULL, i));
    const float *tm = t0 + R.ym, *tp = t0 + R.yp, *tzm = t0 + R.zm, *tzp = t0 + R.zp;
#pragma omp simd
    for (int i = 1; i < nx - 1; i++) {
        float sn = cx * (t0[i - 1] + t0[i + 1]) + c[0] * tm[i] + c[1] * tp[i] + c[2] * tzm[i] +
                   c[3] * tzp[i];
        ur[i] += t0[i] - (dv[i] > 0 ? w : 0) * (t0[i] - dv[i] * sn);
    }
}

/* f_1 = P^T r on a binary fine level: v = r - wp A D^-1 r row by row (D^-1 r
 * never stored), then summed over each aggregate's members. */
static void restrict0_binary(mg_agg *g, const float *r)
{
    const mg_level *F = g->fine;
    mg_alevel *L = &g->lv[0], *C = &g->lv[1];
    const double wp = AGG_OMEGA / L->lmax;
#pragma omp parallel for collapse(2) schedule(static) if (F->count > AGG_PAR_MIN)
    for (int k = 0; k < F->n[2]; k++)
        for (int j = 0; j < F->n[1]; j++)
            restrict0_row(F, g->dim, wp, r, L->t, j, k);
#pragma omp parallel for schedule(static) if (C->n > AGG_PAR_MIN)
    for (int32_t I = 0; I < C->n; I++) {
        double s = 0;
        for (size_t q = L->mrp[I]; q < L->mrp[I + 1]; q++)
            s += L->t[L->mem[q]];
        C->f[I] = (float)s;
    }
}

/* u += P u_1 on a binary fine level: t = P0 u_1, then u += t - wp D^-1 A t
 * row by row. */
static void prolong0_binary(mg_agg *g, float *u)
{
    const mg_level *F = g->fine;
    mg_alevel *L = &g->lv[0], *C = &g->lv[1];
    const double wp = AGG_OMEGA / L->lmax;
#pragma omp parallel for schedule(static) if (L->n > AGG_PAR_MIN)
    for (int32_t c = 0; c < L->n; c++)
        L->t[c] = L->agg[c] >= 0 ? C->u[L->agg[c]] : 0.0f;
#pragma omp parallel for collapse(2) schedule(static) if (F->count > AGG_PAR_MIN)
    for (int k = 0; k < F->n[2]; k++)
        for (int j = 0; j < F->n[1]; j++)
            prolong0_row(F, g->dim, wp, L->t, u, j, k);
}

static void restrict_to(mg_agg *g, int l, const float *r)
{
    mg_alevel *L = &g->lv[l], *C = &g->lv[l + 1];
    if (L->R.rp) {
        hv__agg_csr_apply(&L->R, r, C->f);
        return;
    }
    if (l == 0 && g->fine->binary) {
        restrict0_binary(g, r);
        return;
    }
    agg_op o = level_op(g, l);
    double wp = AGG_OMEGA / L->lmax;
#pragma omp parallel for schedule(static) if (o.n > AGG_PAR_MIN)
    for (int32_t c = 0; c < o.n; c++)
        L->t[c] = o.dinv[c] * r[c];
    hv__agg_op_apply(&o, L->t, L->s);
#pragma omp parallel for schedule(static) if (C->n > AGG_PAR_MIN)
    for (int32_t I = 0; I < C->n; I++) {
        double s = 0;
        for (size_t q = L->mrp[I]; q < L->mrp[I + 1]; q++) {
            int32_t c = L->mem[q];
            s += r[c] - wp * L->s[c];
        }
        C->f[I] = (float)s;
    }
}

/* u_l += P u_{l+1} = v - wp D^-1 A v with v = P0 u_{l+1}. */
static void prolong_add(mg_agg *g, int l, float *u)
{
    mg_alevel *L = &g->lv[l], *C = &g->lv[l + 1];
    if (l == 0 && g->fine->binary) {
        prolong0_binary(g, u);
        return;
    }
    if (L->P.rp) {
        hv__agg_csr_apply(&L->P, C->u, L->t);
#pragma omp parallel for schedule(static) if (L->n > AGG_PAR_MIN)
        for (int32_t c = 0; c < L->n; c++)
            u[c] += L->t[c];
        return;
    }
    agg_op o = level_op(g, l);
    double wp = AGG_OMEGA / L->lmax;
#pragma omp parallel for schedule(static) if (o.n > AGG_PAR_MIN)
    for (int32_t c = 0; c < o.n; c++)
        L->t[c] = L->agg[c] >= 0 ? C->u[L->agg[c]] : 0.0f;
    hv__agg_op_apply(&o, L->t, L->s);
#pragma omp parallel for schedule(static) if (o.n > AGG_PAR_MIN)
    for (int32_t c = 0; c < o.n; c++)
        u[c] += (float)(L->t[c] - wp * o.dinv[c] * L->s[c]);
}

/* One symmetric V-cycle from zero on level l >= 1 for lv[l].f into lv[l].u. */
static void cycle(mg_agg *g, int l)
{
    mg_alevel *L = &g->lv[l];
    if (l == g->nlev - 1) {
        hv__mg_agg_bottom(g, L->f, L->u);
        return;
    }
    agg_op o = level_op(g, l);
    level_smooth(&o, L, 1);
    level_residual(&o, L->f, L->u, L->r);
    restrict_to(g, l, L->r);
    cycle(g, l + 1);
    prolong_add(g, l, L->u);
    level_smooth(&o, L, 0);
}

void hv__mg_agg_correct(mg_agg *g, const float *r, float *u)
{
    restrict_to(g, 0, r);
    cycle(g, 1);
    prolong_add(g, 0, u);
}
