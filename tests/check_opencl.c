/*
 * The OpenCL backend against the CPU: every kernel agrees with the CPU code
 * (2D and 3D, odd sizes, obstacles), whole solves agree with the mg backend
 * and reach the requested tolerance, and device choice and failures are
 * reported clearly. Runs on whatever device HEATVOX_OPENCL_DEVICE picks (PoCL
 * in CI); without any OpenCL platform it only checks that the backend says so.
 */
#include "heatvox/heatvox.h"
#include "solve/cl/cl_mg.h"
#include "cl/cl_ops.h"
#include "testlib.h"

#include <check.h>
#include <fcntl.h>
#include <math.h>
#include <spawn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

extern char **environ;

static hv_cl *CL;        /* opened once in main */
static const char *SELF; /* this binary, for the no-platform child */

/* ---------- problems ---------- */

typedef struct cfg {
    const char *name;
    int dim;
    int n[3];
    double alpha;
    int mask;
} cfg;

static const cfg CFGS[] = {
    {"3d odd plain heat", 3, {21, 18, 13}, 1.0, 0},
    {"3d masked heat", 3, {24, 20, 16}, 1.0, 1},
    {"2d odd plain poisson", 2, {67, 53, 1}, 0.0, 0},
    {"2d masked poisson", 2, {61, 47, 1}, 0.0, 1},
    {"3d masked poisson", 3, {19, 24, 14}, 0.0, 1},
    {"3d even plain heat", 3, {16, 20, 12}, 1.0, 0},   /* plain coarse levels */
    {"3d flat plain poisson", 3, {2, 40, 36}, 0.0, 0}, /* x never coarsened */
};
#define NCFG ((int)(sizeof CFGS / sizeof CFGS[0]))

static size_t cfg_count(const cfg *c)
{
    return (size_t)c->n[0] * c->n[1] * (c->dim == 3 ? c->n[2] : 1);
}

/* A ball and a full wall (two fluid regions), or NULL without mask. */
static uint8_t *make_mask(const cfg *c)
{
    if (!c->mask)
        return NULL;
    const int nz = c->dim == 3 ? c->n[2] : 1;
    size_t n = cfg_count(c);
    uint8_t *s = calloc(n, 1);
    for (int k = 0; k < nz; k++)
        for (int j = 0; j < c->n[1]; j++)
            for (int i = 0; i < c->n[0]; i++) {
                double x = (i + 0.5) / c->n[0] - 0.6, y = (j + 0.5) / c->n[1] - 0.5;
                double z = c->dim == 3 ? (k + 0.5) / nz - 0.5 : 0;
                size_t q = (size_t)i + (size_t)c->n[0] * ((size_t)j + (size_t)c->n[1] * k);
                s[q] = x * x + y * y + z * z < 0.05 || i == c->n[0] / 4;
            }
    return s;
}

static hv_problem make_problem(const cfg *c, const uint8_t *solid)
{
    hv_problem p;
    memset(&p, 0, sizeof p);
    p.dim = c->dim;
    memcpy(p.n, c->n, sizeof p.n);
    p.h = 1.0 / c->n[0];
    p.solid = solid;
    p.alpha = c->alpha;
    p.beta = c->alpha > 0 ? 16 * p.h * p.h : 1.0;
    return p;
}

static unsigned rng = 12345u;
static double rnd(void)
{
    rng = rng * 1664525u + 1013904223u;
    return (double)(rng >> 8) / (1u << 24) - 0.5;
}

static void fill_f(float *v, size_t n)
{
    for (size_t i = 0; i < n; i++)
        v[i] = (float)rnd();
}

static double max_abs_f(const float *v, size_t n)
{
    double m = 0;
    for (size_t i = 0; i < n; i++)
        m = fmax(m, fabs(v[i]));
    return m;
}

/* max |a - b| / max |b| */
static double rel_diff_f(const float *a, const float *b, size_t n)
{
    double d = 0;
    for (size_t i = 0; i < n; i++)
        d = fmax(d, fabs((double)a[i] - b[i]));
    double m = max_abs_f(b, n);
    return m > 0 ? d / m : d;
}

/* A hierarchy on the host and its device copy. */
typedef struct hier {
    hv_setup s;
    uint8_t *solid;
    mg_hierarchy H;
    hv_clmg m;
} hier;

static void hier_make(hier *h, const cfg *c, hv_smoother sm)
{
    memset(h, 0, sizeof *h);
    h->solid = make_mask(c);
    h->s.p = make_problem(c, h->solid);
    if (c->dim == 2)
        h->s.p.n[2] = 1;
    hv_solver_opts_default(&h->s.o);
    h->s.o.smoother = sm;
    h->s.count = cfg_count(c);
    h->s.nregion = 1;
    ck_assert_int_eq(hv__mg_hierarchy_build(&h->H, &h->s, 1), HV_OK);
    ck_assert_msg(hv__clmg_create(&h->m, CL, &h->H, sm, 2, 2, 1) == HV_OK, "%s", hv_last_error());
}

static void hier_free(hier *h)
{
    hv__clmg_destroy(&h->m);
    hv__mg_hierarchy_free(&h->H);
    free(h->solid);
}

static void upload(cl_mem m, const float *v, size_t n)
{
    hv__cl_write(CL, m, 0, n * sizeof(float), v);
}

static void download(cl_mem m, float *v, size_t n)
{
    hv__cl_read(CL, m, 0, n * sizeof(float), v);
    ck_assert_msg(hv__cl_check(CL) == HV_OK, "%s", hv_last_error());
}

/* ---------- CPU references (mg_backend.c semantics) ---------- */

static void ref_residual(const mg_hierarchy *H, const mg_level *L, const float *u, const float *f,
                         float *r)
{
    for (int k = 0; k < L->n[2]; k++)
        for (int j = 0; j < L->n[1]; j++)
            for (int i = 0; i < L->n[0]; i++) {
                size_t c = (size_t)i + L->sy * j + L->sz * k;
                double S, D;
                MG_STENCIL(L, H, u, i, j, k, c, S, D);
                r[c] = (float)((f ? f[c] : 0.0) - (D * u[c] - S));
            }
}

static double ref_diag(const mg_hierarchy *H, const mg_level *L, size_t c)
{
    int i = (int)(c % L->n[0]), j = (int)((c / L->sy) % L->n[1]), k = (int)(c / L->sz);
    return L->plain ? hv__mg_level_diag(L, H->dim, H->alpha, i, j, k)
                    : (L->dinv[c] > 0 ? 1.0 / L->dinv[c] : 0.0);
}

static void ref_rbgs(const mg_hierarchy *H, const mg_level *L, float *u, const float *f, int col)
{
    for (int k = 0; k < L->n[2]; k++)
        for (int j = 0; j < L->n[1]; j++)
            for (int i = (j + k + col) & 1; i < L->n[0]; i += 2) {
                size_t c = (size_t)i + L->sy * j + L->sz * k;
                double S, D;
                MG_STENCIL(L, H, u, i, j, k, c, S, D);
                u[c] = D > 0 ? (float)((f[c] + S) / D) : 0.0f;
            }
}

static void ref_jacobi_update(const mg_hierarchy *H, const mg_level *L, float *u, const float *r,
                              float *d, double cd, double cr)
{
    for (size_t c = 0; c < L->count; c++) {
        double dg = ref_diag(H, L, c), z = dg > 0 ? r[c] / dg : 0.0;
        double dn = cd * d[c] + cr * z;
        d[c] = (float)dn;
        u[c] += (float)dn;
    }
}

static void ref_smooth(const mg_hierarchy *H, const mg_level *L, hv_smoother sm, float *u,
                       const float *f, int steps, int reverse)
{
    float *r = calloc(L->count, sizeof *r), *d = calloc(L->count, sizeof *d);
    if (sm == HV_SMOOTH_RBGS) {
        for (int s = 0; s < steps; s++) {
            ref_rbgs(H, L, u, f, reverse ? 1 : 0);
            ref_rbgs(H, L, u, f, reverse ? 0 : 1);
        }
    } else if (sm == HV_SMOOTH_JACOBI) {
        double omega = H->dim == 3 ? 6.0 / 7.0 : 4.0 / 5.0;
        for (int s = 0; s < steps; s++) {
            ref_residual(H, L, u, f, r);
            ref_jacobi_update(H, L, u, r, d, 0.0, omega);
        }
    } else {
        double lmax = L->lmax, lmin = lmax / 8;
        double theta = 0.5 * (lmax + lmin), delta = 0.5 * (lmax - lmin);
        double sigma = theta / delta, rho_old = 1.0 / sigma;
        ref_residual(H, L, u, f, r);
        ref_jacobi_update(H, L, u, r, d, 0.0, 1.0 / theta);
        for (int s = 1; s < 2 * steps; s++) {
            double rho = 1.0 / (2 * sigma - rho_old);
            ref_residual(H, L, u, f, r);
            ref_jacobi_update(H, L, u, r, d, rho * rho_old, 2 * rho / delta);
            rho_old = rho;
        }
    }
    free(r);
    free(d);
}

static void ref_restrict(const mg_level *F, const mg_level *C, const float *src, float *dst)
{
    const int *co = F->coarsen;
    int nchild = (co[0] ? 2 : 1) * (co[1] ? 2 : 1) * (co[2] ? 2 : 1);
    for (int K = 0; K < C->n[2]; K++)
        for (int J = 0; J < C->n[1]; J++)
            for (int I = 0; I < C->n[0]; I++) {
                double s = 0;
                for (int dk = 0; dk <= co[2]; dk++)
                    for (int dj = 0; dj <= co[1]; dj++)
                        for (int di = 0; di <= co[0]; di++) {
                            int i = co[0] ? 2 * I + di : I, j = co[1] ? 2 * J + dj : J,
                                k = co[2] ? 2 * K + dk : K;
                            if (i < F->n[0] && j < F->n[1] && k < F->n[2])
                                s += src[(size_t)i + F->sy * j + F->sz * k];
                        }
                dst[(size_t)I + C->sy * J + C->sz * K] = (float)(s / nchild);
            }
}

static void ref_axis(int coarsen, int nc, int i, int *I0, int *I1, double *w1)
{
    *I0 = *I1 = coarsen ? i >> 1 : i;
    *w1 = 0;
    if (coarsen) {
        int nb = (i & 1) ? (i >> 1) + 1 : (i >> 1) - 1;
        if (nb >= 0 && nb < nc) {
            *I1 = nb;
            *w1 = 0.25;
        }
    }
}

static void ref_prolong(const mg_level *F, const mg_level *C, const float *uc, float *uf)
{
    const int *co = F->coarsen;
    for (int k = 0; k < F->n[2]; k++)
        for (int j = 0; j < F->n[1]; j++)
            for (int i = 0; i < F->n[0]; i++) {
                size_t fc = (size_t)i + F->sy * j + F->sz * k;
                if (!F->plain && F->a[fc] == 0.0f)
                    continue;
                int I[2], J[2], K[2];
                double wi, wj, wk;
                ref_axis(co[0], C->n[0], i, &I[0], &I[1], &wi);
                ref_axis(co[1], C->n[1], j, &J[0], &J[1], &wj);
                ref_axis(co[2], C->n[2], k, &K[0], &K[1], &wk);
                double Wi[2] = {1 - wi, wi}, Wj[2] = {1 - wj, wj}, Wk[2] = {1 - wk, wk}, s = 0,
                       ws = 0;
                for (int a = 0; a < 2; a++)
                    for (int b = 0; b < 2; b++)
                        for (int e = 0; e < 2; e++) {
                            double w = Wk[a] * Wj[b] * Wi[e];
                            size_t cc = (size_t)I[e] + C->sy * J[b] + C->sz * K[a];
                            if (w == 0 || (!C->plain && C->a[cc] == 0.0f))
                                continue;
                            s += w * uc[cc];
                            ws += w;
                        }
                if (ws > 0)
                    uf[fc] += (float)(C->plain ? s : s / ws);
            }
}

/* ---------- level kernels ---------- */

START_TEST(apply_and_residual_should_match_cpu_on_every_level)
{
    for (int ci = 0; ci < NCFG; ci++) {
        hier h;
        hier_make(&h, &CFGS[ci], HV_SMOOTH_RBGS);
        ck_assert_int_ge(h.H.nlev, 2);
        for (int l = 0; l < h.H.nlev; l++) {
            const mg_level *L = &h.H.lv[l];
            size_t n = L->count;
            float *u = malloc(n * 4), *f = malloc(n * 4), *ref = malloc(n * 4),
                  *got = malloc(n * 4);
            fill_f(u, n);
            fill_f(f, n);
            cl_mem du = h.m.lv[l].u[0], df = h.m.lv[l].f, out;
            ck_assert_int_eq(hv__cl_alloc(CL, n * 4, NULL, &out), HV_OK);
            upload(du, u, n);
            upload(df, f, n);
            hv__clmg_apply(&h.m, l, du, out);
            download(out, got, n);
            ref_residual(&h.H, L, u, NULL, ref);
            for (size_t c = 0; c < n; c++)
                ref[c] = -ref[c];
            ck_assert_msg(rel_diff_f(got, ref, n) < 1e-5, "apply, %s level %d: %g", CFGS[ci].name,
                          l, rel_diff_f(got, ref, n));
            hv__clmg_residual(&h.m, l, du, df, out);
            download(out, got, n);
            ref_residual(&h.H, L, u, f, ref);
            ck_assert_msg(rel_diff_f(got, ref, n) < 1e-5, "residual, %s level %d: %g",
                          CFGS[ci].name, l, rel_diff_f(got, ref, n));
            hv__cl_free(&out);
            free(u);
            free(f);
            free(ref);
            free(got);
        }
        hier_free(&h);
    }
}
END_TEST

START_TEST(smoother_sweeps_should_match_cpu)
{
    const hv_smoother sms[] = {HV_SMOOTH_RBGS, HV_SMOOTH_JACOBI, HV_SMOOTH_CHEBYSHEV};
    for (int si = 0; si < 3; si++)
        for (int ci = 0; ci < NCFG; ci++) {
            hier h;
            hier_make(&h, &CFGS[ci], sms[si]);
            for (int l = 0; l < h.H.nlev; l++)
                for (int rev = 0; rev < 4; rev++) {
                    /* rev & 2: from a zero guess, with garbage in the iterate */
                    const int zero = rev >> 1;
                    const mg_level *L = &h.H.lv[l];
                    hv_clmg_level *D = &h.m.lv[l];
                    size_t n = L->count;
                    float *u = malloc(n * 4), *f = malloc(n * 4), *got = malloc(n * 4);
                    fill_f(u, n);
                    fill_f(f, n);
                    if (!L->plain) /* solid cells hold 0, as in a cycle */
                        for (size_t c = 0; c < n; c++)
                            if (L->a[c] == 0.0f)
                                u[c] = f[c] = 0;
                    upload(D->u[D->cur], u, n);
                    upload(D->f, f, n);
                    hv__clmg_smooth(&h.m, l, 2, rev & 1, zero);
                    download(D->u[D->cur], got, n);
                    if (zero)
                        memset(u, 0, n * sizeof *u);
                    ref_smooth(&h.H, L, sms[si], u, f, 2, rev & 1);
                    double e = rel_diff_f(got, u, n);
                    ck_assert_msg(e < 1e-5, "smoother %d, %s level %d reverse %d zero %d: %g",
                                  sms[si], CFGS[ci].name, l, rev & 1, zero, e);
                    free(u);
                    free(f);
                    free(got);
                }
            hier_free(&h);
        }
}
END_TEST

START_TEST(restriction_should_be_the_mean_of_the_children)
{
    for (int ci = 0; ci < NCFG; ci++) {
        hier h;
        hier_make(&h, &CFGS[ci], HV_SMOOTH_RBGS);
        for (int l = 0; l + 1 < h.H.nlev; l++) {
            const mg_level *F = &h.H.lv[l], *C = &h.H.lv[l + 1];
            float *u = malloc(F->count * 4), *f = malloc(F->count * 4), *r = malloc(F->count * 4);
            float *ref = malloc(C->count * 4), *got = malloc(C->count * 4);
            fill_f(u, F->count);
            fill_f(f, F->count);
            upload(h.m.lv[l].f, f, F->count);
            upload(h.m.lv[l].u[0], u, F->count);
            hv__clmg_restrict(&h.m, l, h.m.lv[l].f, h.m.lv[l + 1].f);
            download(h.m.lv[l + 1].f, got, C->count);
            ref_restrict(F, C, f, ref);
            ck_assert_msg(rel_diff_f(got, ref, C->count) < 1e-5, "restrict, %s level %d",
                          CFGS[ci].name, l);
            hv__clmg_restrict_residual(&h.m, l);
            download(h.m.lv[l + 1].f, got, C->count);
            ref_residual(&h.H, F, u, f, r);
            ref_restrict(F, C, r, ref);
            ck_assert_msg(rel_diff_f(got, ref, C->count) < 1e-5,
                          "restrict residual, %s level %d: %g", CFGS[ci].name, l,
                          rel_diff_f(got, ref, C->count));
            free(u);
            free(f);
            free(r);
            free(ref);
            free(got);
        }
        hier_free(&h);
    }
}
END_TEST

static double dot_f(const float *a, const float *b, size_t n)
{
    double s = 0;
    for (size_t i = 0; i < n; i++)
        s += (double)a[i] * b[i];
    return s;
}

START_TEST(transpose_restriction_should_match_cpu_and_be_the_adjoint_of_prolongation)
{
    int weighted = 0;
    for (int ci = 0; ci < NCFG; ci++) {
        hier h;
        hier_make(&h, &CFGS[ci], HV_SMOOTH_RBGS);
        for (int l = 0; l + 1 < h.H.nlev; l++) {
            const mg_level *F = &h.H.lv[l], *C = &h.H.lv[l + 1];
            float *r = malloc(F->count * 4), *pn = NULL, *ref = malloc(C->count * 4);
            float *got = malloc(C->count * 4), *uc = malloc(C->count * 4),
                  *pu = calloc(F->count, 4);
            fill_f(r, F->count);
            if (!C->plain) {
                weighted++;
                pn = malloc(F->count * 4);
                hv__mg_prolong_norm(F, C, pn);
            }
            ck_assert(h.m.lv[l].r != NULL && (h.m.lv[l].pn != NULL) == !C->plain);
            upload(h.m.lv[l].r, r, F->count);
            hv__clmg_restrict_transpose(&h.m, l);
            download(h.m.lv[l + 1].f, got, C->count);
            float *work = malloc(mg_restrict_transpose_work(F, C) * sizeof(float));
            ck_assert(work != NULL);
            hv__mg_restrict_transpose(F, C, h.H.dim, pn, r, ref, work, 1);
            free(work);
            ck_assert_msg(rel_diff_f(got, ref, C->count) < 1e-5,
                          "restrict transpose, %s level %d: %g", CFGS[ci].name, l,
                          rel_diff_f(got, ref, C->count));
            /* adjoint of the device prolongation: <R r, uc> 2^d = <r, P uc>
             * (P leaves solid fine cells alone, and pn is 0 there) */
            fill_f(uc, C->count);
            upload(h.m.lv[l].u[0], pu, F->count);
            upload(h.m.lv[l + 1].u[0], uc, C->count);
            hv__clmg_prolong(&h.m, l);
            download(h.m.lv[l].u[0], pu, F->count);
            if (!F->plain)
                for (size_t c = 0; c < F->count; c++)
                    if (F->a[c] == 0.0f)
                        r[c] = 0;
            int nchild =
                (F->coarsen[0] ? 2 : 1) * (F->coarsen[1] ? 2 : 1) * (F->coarsen[2] ? 2 : 1);
            double lhs = nchild * dot_f(got, uc, C->count), rhs = dot_f(r, pu, F->count);
            ck_assert_msg(fabs(lhs - rhs) <=
                              1e-5 * sqrt(dot_f(r, r, F->count) * dot_f(pu, pu, F->count)),
                          "adjoint, %s level %d: %g vs %g", CFGS[ci].name, l, lhs, rhs);
            free(r);
            free(pn);
            free(ref);
            free(got);
            free(uc);
            free(pu);
        }
        hier_free(&h);
    }
    ck_assert_int_gt(weighted, 3); /* renormalized levels were covered */
}
END_TEST

/* M x for the PCG preconditioner: one symmetric cycle from zero on f = x. */
static void precondition(hier *h, const float *x, float *y)
{
    hv_clmg_level *L0 = &h->m.lv[0];
    upload(L0->f, x, L0->count);
    hv__clmg_vcycle(&h->m, 0, 0, 1);
    download(L0->u[L0->cur], y, L0->count);
}

START_TEST(symmetric_cycle_should_be_a_symmetric_operator)
{
    /* CG needs <M x, y> = <x, M y>; mean-of-children restriction broke it */
    const hv_smoother sms[] = {HV_SMOOTH_RBGS, HV_SMOOTH_CHEBYSHEV, HV_SMOOTH_JACOBI};
    for (int ci = 0; ci < NCFG; ci++) {
        if (!CFGS[ci].mask)
            continue;
        for (int si = 0; si < 3; si++) {
            hier h;
            hier_make(&h, &CFGS[ci], sms[si]);
            size_t n = h.H.lv[0].count;
            float *x = malloc(n * 4), *y = malloc(n * 4), *mx = malloc(n * 4), *my = malloc(n * 4);
            fill_f(x, n);
            fill_f(y, n);
            for (size_t c = 0; c < n; c++)
                if (h.solid[c])
                    x[c] = y[c] = 0;
            precondition(&h, x, mx);
            precondition(&h, y, my);
            double a = dot_f(mx, y, n), b = dot_f(x, my, n);
            double scale = sqrt(dot_f(mx, mx, n) * dot_f(y, y, n));
            printf("  %s, smoother %d: |<Mx,y> - <x,My>| / |Mx||y| = %.2e\n", CFGS[ci].name, si,
                   fabs(a - b) / scale);
            ck_assert_msg(fabs(a - b) <= 1e-5 * scale, "%s smoother %d: <Mx,y> %g, <x,My> %g",
                          CFGS[ci].name, si, a, b);
            ck_assert(dot_f(mx, x, n) > 0); /* and positive */
            free(x);
            free(y);
            free(mx);
            free(my);
            hier_free(&h);
        }
    }
}
END_TEST

START_TEST(prolongation_should_match_cpu)
{
    for (int ci = 0; ci < NCFG; ci++) {
        hier h;
        hier_make(&h, &CFGS[ci], HV_SMOOTH_RBGS);
        for (int l = 0; l + 1 < h.H.nlev; l++) {
            const mg_level *F = &h.H.lv[l], *C = &h.H.lv[l + 1];
            float *uf = malloc(F->count * 4), *uc = malloc(C->count * 4),
                  *got = malloc(F->count * 4);
            fill_f(uf, F->count);
            fill_f(uc, C->count);
            upload(h.m.lv[l].u[0], uf, F->count);
            upload(h.m.lv[l + 1].u[0], uc, C->count);
            hv__clmg_prolong(&h.m, l);
            download(h.m.lv[l].u[0], got, F->count);
            ref_prolong(F, C, uc, uf);
            ck_assert_msg(rel_diff_f(got, uf, F->count) < 1e-5, "prolong, %s level %d (%s->%s): %g",
                          CFGS[ci].name, l, C->plain ? "plain" : "weighted",
                          F->plain ? "plain" : "weighted", rel_diff_f(got, uf, F->count));
            free(uf);
            free(uc);
            free(got);
        }
        hier_free(&h);
    }
}
END_TEST

START_TEST(bottom_solver_should_solve_the_coarsest_level)
{
    for (int ci = 0; ci < NCFG; ci++) {
        hier h;
        hier_make(&h, &CFGS[ci], HV_SMOOTH_RBGS);
        int b = h.H.nlev - 1;
        const mg_level *L = &h.H.lv[b];
        size_t n = L->count;
        float *f = malloc(n * 4), *u = malloc(n * 4), *r = malloc(n * 4);
        fill_f(f, n);
        for (size_t c = 0; c < n; c++)
            if (!L->plain && L->a[c] == 0.0f)
                f[c] = 0;
        if (L->region) { /* Poisson: a compatible right-hand side, mean-free per region */
            double s[64] = {0}, cnt[64] = {0};
            ck_assert_int_le(L->nregion, 64);
            for (size_t c = 0; c < n; c++)
                if (L->region[c] >= 0) {
                    s[L->region[c]] += f[c];
                    cnt[L->region[c]] += 1;
                }
            for (size_t c = 0; c < n; c++)
                if (L->region[c] >= 0)
                    f[c] -= (float)(s[L->region[c]] / cnt[L->region[c]]);
        }
        upload(h.m.lv[b].f, f, n);
        hv__clmg_bottom(&h.m);
        download(h.m.lv[b].u[0], u, n);
        ref_residual(&h.H, L, u, f, r);
        ck_assert_msg(max_abs_f(r, n) < 1e-5 * max_abs_f(f, n), "bottom residual, %s: %g",
                      CFGS[ci].name, max_abs_f(r, n) / max_abs_f(f, n));
        if (L->region) {
            double s[64] = {0};
            for (size_t c = 0; c < n; c++)
                if (L->region[c] >= 0)
                    s[L->region[c]] += u[c];
            for (int q = 0; q < L->nregion; q++)
                ck_assert_msg(fabs(s[q]) < 1e-4 * max_abs_f(u, n) * n, "region %d not mean-free",
                              q);
        }
        free(f);
        free(u);
        free(r);
        hier_free(&h);
    }
}
END_TEST

/* ---------- face operators, pointwise steps, reductions ---------- */

static hv_grid *make_grid(const cfg *c, const uint8_t *solid)
{
    hv_grid *g;
    ck_assert_int_eq(hv_grid_create(&g, c->dim, c->n, 1.0 / c->n[0], NULL), HV_OK);
    if (solid) {
        ck_assert_int_eq(hv_grid_add_mask(g), HV_OK);
        memcpy(g->solid, solid, cfg_count(c));
    }
    return g;
}

START_TEST(face_gradient_and_divergence_should_match_cpu)
{
    for (int ci = 0; ci < NCFG; ci++) {
        const cfg *c = &CFGS[ci];
        uint8_t *solid = make_mask(c);
        hv_grid *u = make_grid(c, solid), *div = make_grid(c, solid);
        size_t n = cfg_count(c);
        fill_f(u->v, n);
        hv_faces *F;
        ck_assert_int_eq(hv_faces_create(&F, u), HV_OK);
        cl_mem du, ds = NULL, dg[3] = {NULL, NULL, NULL}, dd;
        ck_assert_int_eq(hv__cl_alloc(CL, n * 4, u->v, &du), HV_OK);
        ck_assert_int_eq(hv__cl_alloc(CL, n * 4, NULL, &dd), HV_OK);
        if (solid)
            ck_assert_int_eq(hv__cl_alloc(CL, n, solid, &ds), HV_OK);
        for (int a = 0; a < c->dim; a++)
            ck_assert_int_eq(hv__cl_alloc(CL, hv_faces_count(F, a) * 4, NULL, &dg[a]), HV_OK);
        /* gradient */
        hv__cl_face_gradient(CL, c->dim, c->n, u->h, ds, du, dg);
        ck_assert_int_eq(hv_face_gradient(u, F), HV_OK);
        for (int a = 0; a < c->dim; a++) {
            size_t nf = hv_faces_count(F, a);
            float *got = malloc(nf * 4);
            download(dg[a], got, nf);
            ck_assert_msg(rel_diff_f(got, F->f[a], nf) < 1e-5, "gradient axis %d, %s", a, c->name);
            free(got);
        }
        /* divergence of an arbitrary face field (including wall and solid faces) */
        for (int a = 0; a < c->dim; a++) {
            fill_f(F->f[a], hv_faces_count(F, a));
            upload(dg[a], F->f[a], hv_faces_count(F, a));
        }
        hv__cl_face_divergence(CL, c->dim, c->n, u->h, ds, dg, dd);
        ck_assert_int_eq(hv_face_divergence(F, div), HV_OK);
        float *got = malloc(n * 4);
        download(dd, got, n);
        ck_assert_msg(rel_diff_f(got, div->v, n) < 1e-5, "divergence, %s: %g", c->name,
                      rel_diff_f(got, div->v, n));
        free(got);
        hv__cl_free(&du);
        hv__cl_free(&dd);
        hv__cl_free(&ds);
        for (int a = 0; a < 3; a++)
            hv__cl_free(&dg[a]);
        hv_faces_destroy(&F);
        hv_grid_destroy(&u);
        hv_grid_destroy(&div);
        free(solid);
    }
}
END_TEST

/* The heat methods' face field: normalized mean of the two cells' vectors. */
static double ref_normalize(const cfg *c, const uint8_t *solid, float *const v[3], int a, int i,
                            int j, int k)
{
    int idx[3] = {i, j, k}, nz = c->dim == 3 ? c->n[2] : 1, n[3] = {c->n[0], c->n[1], nz};
    if (idx[a] == 0 || idx[a] == n[a])
        return 0;
    size_t hi = (size_t)i + (size_t)n[0] * ((size_t)j + (size_t)n[1] * k);
    size_t lo = hi - (a == 0 ? 1 : a == 1 ? (size_t)n[0] : (size_t)n[0] * n[1]);
    if (solid && (solid[hi] || solid[lo]))
        return 0;
    double m[3] = {0, 0, 0}, len = 0;
    for (int b = 0; b < c->dim; b++) {
        m[b] = 0.5 * ((double)v[b][lo] + v[b][hi]);
        len += m[b] * m[b];
    }
    return len > 0 ? m[a] / sqrt(len) : 0;
}

START_TEST(face_normalize_should_give_unit_normal_components)
{
    for (int ci = 0; ci < NCFG; ci++) {
        const cfg *c = &CFGS[ci];
        uint8_t *solid = make_mask(c);
        size_t n = cfg_count(c);
        int nz = c->dim == 3 ? c->n[2] : 1;
        float *v[3] = {NULL, NULL, NULL};
        cl_mem dv[3] = {NULL, NULL, NULL}, dout[3] = {NULL, NULL, NULL}, ds = NULL;
        if (solid)
            ck_assert_int_eq(hv__cl_alloc(CL, n, solid, &ds), HV_OK);
        for (int b = 0; b < c->dim; b++) {
            v[b] = malloc(n * 4);
            fill_f(v[b], n);
            /* tiny vectors (far from a heat source) must survive the float math */
            for (size_t q = 0; q < n; q += 7)
                v[b][q] *= 1e-30f;
            ck_assert_int_eq(hv__cl_alloc(CL, n * 4, v[b], &dv[b]), HV_OK);
            size_t nf = n / c->n[b] * (c->n[b] + 1);
            ck_assert_int_eq(hv__cl_alloc(CL, nf * 4, NULL, &dout[b]), HV_OK);
        }
        hv__cl_face_normalize(CL, c->dim, c->n, ds, dv, dout, 0.0);
        for (int a = 0; a < c->dim; a++) {
            int m[3] = {c->n[0] + (a == 0), c->n[1] + (a == 1), nz + (a == 2)};
            size_t nf = (size_t)m[0] * m[1] * m[2];
            float *got = malloc(nf * 4);
            download(dout[a], got, nf);
            double err = 0;
            for (int k = 0; k < m[2]; k++)
                for (int j = 0; j < m[1]; j++)
                    for (int i = 0; i < m[0]; i++) {
                        size_t fi = (size_t)i + (size_t)m[0] * ((size_t)j + (size_t)m[1] * k);
                        err = fmax(err, fabs(got[fi] - ref_normalize(c, solid, v, a, i, j, k)));
                        ck_assert(fabs(got[fi]) <= 1.0f + 1e-6f);
                    }
            ck_assert_msg(err < 1e-5, "normalize axis %d, %s: %g", a, c->name, err);
            free(got);
        }
        for (int b = 0; b < 3; b++) {
            free(v[b]);
            hv__cl_free(&dv[b]);
            hv__cl_free(&dout[b]);
        }
        hv__cl_free(&ds);
        free(solid);
    }
}
END_TEST

START_TEST(ratio_and_axpy_should_match_cpu)
{
    size_t n = 10007;
    float *a = malloc(n * 4), *b = malloc(n * 4), *got = malloc(n * 4), *ref = malloc(n * 4);
    fill_f(a, n);
    fill_f(b, n);
    cl_mem da, db, dout;
    ck_assert_int_eq(hv__cl_alloc(CL, n * 4, a, &da), HV_OK);
    ck_assert_int_eq(hv__cl_alloc(CL, n * 4, b, &db), HV_OK);
    ck_assert_int_eq(hv__cl_alloc(CL, n * 4, NULL, &dout), HV_OK);
    hv__cl_ratio(CL, n, da, db, dout, 0.01);
    download(dout, got, n);
    for (size_t c = 0; c < n; c++)
        ref[c] = b[c] > 0.01f ? a[c] / b[c] : 0.0f;
    ck_assert(rel_diff_f(got, ref, n) < 1e-6);
    hv__cl_axpy(CL, n, -2.5, da, db);
    download(db, got, n);
    for (size_t c = 0; c < n; c++)
        ref[c] = b[c] - 2.5f * a[c];
    ck_assert(rel_diff_f(got, ref, n) < 1e-6);
    hv__cl_free(&da);
    hv__cl_free(&db);
    hv__cl_free(&dout);
    free(a);
    free(b);
    free(got);
    free(ref);
}
END_TEST

START_TEST(reductions_should_match_double_sums)
{
    const size_t sizes[] = {1, 63, 1025, 100003};
    cl_mem S;
    ck_assert_int_eq(hv__cl_alloc(CL, 8 * sizeof(double), NULL, &S), HV_OK);
    for (int si = 0; si < 4; si++) {
        size_t n = sizes[si];
        float *a = malloc(n * 4), *b = malloc(n * 4);
        fill_f(a, n);
        fill_f(b, n);
        double dot = 0, sum = 0, mag = 0, got[2];
        for (size_t c = 0; c < n; c++) {
            dot += (double)a[c] * b[c];
            sum += a[c];
            mag += fabs(a[c]);
        }
        cl_mem da, db;
        ck_assert_int_eq(hv__cl_alloc(CL, n * 4, a, &da), HV_OK);
        ck_assert_int_eq(hv__cl_alloc(CL, n * 4, b, &db), HV_OK);
        hv__cl_dot_f(CL, da, db, n, S, 0);
        hv__cl_dot_f(CL, da, NULL, n, S, 1);
        hv__cl_read_acc(CL, S, 0, 2, got);
        ck_assert_int_eq(hv__cl_check(CL), HV_OK);
        ck_assert_msg(fabs(got[0] - dot) <= 1e-5 * mag, "dot over %zu: %g vs %g", n, got[0], dot);
        ck_assert_msg(fabs(got[1] - sum) <= 1e-5 * mag, "sum over %zu: %g vs %g", n, got[1], sum);
        hv__cl_free(&da);
        hv__cl_free(&db);
        free(a);
        free(b);
    }
    hv__cl_free(&S);

    /* per-region sums and the mean projection, with many small regions and a
     * large one (several chunks) */
    size_t n = 50000;
    int nregion = 37;
    int32_t *region = malloc(n * sizeof *region);
    float *v = malloc(n * 4), *got = malloc(n * 4);
    fill_f(v, n);
    for (size_t c = 0; c < n; c++)
        region[c] = c % 11 == 0 ? -1 : c < 30000 ? 0 : 1 + (int)(c % (nregion - 1));
    double sum[64] = {0}, cnt[64] = {0}, mag = 0;
    for (size_t c = 0; c < n; c++)
        if (region[c] >= 0) {
            sum[region[c]] += v[c];
            cnt[region[c]] += 1;
            mag += fabs(v[c]);
        }
    hv_cl_regions R;
    ck_assert_int_eq(hv__cl_regions_create(CL, &R, n, region, nregion), HV_OK);
    cl_mem dv;
    ck_assert_int_eq(hv__cl_alloc(CL, n * 4, v, &dv), HV_OK);
    hv__cl_region_sums(CL, &R, dv, 0);
    double rs[64];
    hv__cl_read_acc(CL, R.sum, 0, nregion, rs);
    for (int r = 0; r < nregion; r++)
        ck_assert_msg(fabs(rs[r] - sum[r]) <= 1e-6 * mag, "region %d: %g vs %g", r, rs[r], sum[r]);
    hv__cl_project(CL, &R, dv);
    download(dv, got, n);
    double err = 0;
    for (size_t c = 0; c < n; c++) {
        double want = region[c] >= 0 ? v[c] - sum[region[c]] / cnt[region[c]] : 0.0;
        err = fmax(err, fabs(got[c] - want));
    }
    ck_assert_msg(err < 1e-6, "projection error %g", err);
    hv__cl_regions_destroy(&R);
    hv__cl_free(&dv);
    free(region);
    free(v);
    free(got);
}
END_TEST

/* ---------- whole solves ---------- */

/* ||f - A u|| / ||f|| on fluid cells, in double, with the CPU operator. */
static double true_relres(const hv_problem *p, const double *f, const double *u)
{
    hv_setup s;
    memset(&s, 0, sizeof s);
    s.p = *p;
    if (p->dim == 2)
        s.p.n[2] = 1;
    s.count = (size_t)s.p.n[0] * s.p.n[1] * s.p.n[2];
    hv_solver_opts_default(&s.o);
    mg_hierarchy H;
    ck_assert_int_eq(hv__mg_hierarchy_build(&H, &s, 0), HV_OK);
    double *y = malloc(s.count * sizeof *y), rr = 0, ff = 0;
    hv__mg_level_apply_d(&H.lv[0], H.dim, H.alpha, u, y);
    for (size_t c = 0; c < s.count; c++)
        if (!p->solid || !p->solid[c]) {
            rr += (f[c] - y[c]) * (f[c] - y[c]);
            ff += f[c] * f[c];
        }
    free(y);
    hv__mg_hierarchy_free(&H);
    return sqrt(rr / ff);
}

/* Heat: random f. Poisson: f = A v for random v, compatible in every region. */
static double *make_rhs(const hv_problem *p, size_t n)
{
    double *f = malloc(n * sizeof *f), *v = malloc(n * sizeof *v);
    for (size_t c = 0; c < n; c++)
        v[c] = (p->solid && p->solid[c]) ? 0.0 : rnd();
    if (p->alpha > 0) {
        memcpy(f, v, n * sizeof *f);
    } else {
        hv_setup s;
        memset(&s, 0, sizeof s);
        s.p = *p;
        if (p->dim == 2)
            s.p.n[2] = 1;
        s.count = n;
        mg_hierarchy H;
        ck_assert_int_eq(hv__mg_hierarchy_build(&H, &s, 0), HV_OK);
        hv__mg_level_apply_d(&H.lv[0], H.dim, H.alpha, v, f);
        hv__mg_hierarchy_free(&H);
    }
    free(v);
    return f;
}

static void solve_with(const hv_problem *p, hv_backend b, hv_smoother sm, double tol,
                       const double *f, double *u, hv_solve_info *info)
{
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.backend = b;
    o.tol = tol;
    o.smoother = sm;
    hv_solver *s;
    ck_assert_msg(hv_solver_create(&s, p, &o) == HV_OK, "%s", hv_last_error());
    ck_assert_int_eq(hv_solver_backend(s), b);
    ck_assert_msg(hv_solver_solve_d(s, f, u, info) == HV_OK, "%s", hv_last_error());
    hv_solver_destroy(&s);
}

static double rel_diff_d(const double *a, const double *b, size_t n)
{
    double d = 0, m = 0;
    for (size_t i = 0; i < n; i++) {
        d += (a[i] - b[i]) * (a[i] - b[i]);
        m += b[i] * b[i];
    }
    return m > 0 ? sqrt(d / m) : sqrt(d);
}

static void check_solves(hv_smoother sm, const double *tols, int ntol)
{
    for (int ci = 0; ci < NCFG; ci++)
        for (int ti = 0; ti < ntol; ti++) {
            const cfg *c = &CFGS[ci];
            uint8_t *solid = make_mask(c);
            hv_problem p = make_problem(c, solid);
            size_t n = cfg_count(c);
            double *f = make_rhs(&p, n), *ucl = malloc(n * 8), *umg = malloc(n * 8);
            hv_solve_info icl, img;
            solve_with(&p, HV_BACKEND_OPENCL, sm, tols[ti], f, ucl, &icl);
            solve_with(&p, HV_BACKEND_MG, sm == HV_SMOOTH_AUTO ? HV_SMOOTH_CHEBYSHEV : sm, tols[ti],
                       f, umg, &img);
            ck_assert_msg(icl.reason == HV_STOP_CONVERGED && icl.relres <= tols[ti] * 1.0001,
                          "%s tol %g: %s after %d iterations at %g", c->name, tols[ti],
                          hv_stop_reason_str(icl.reason), icl.iterations, icl.relres);
            double tr = true_relres(&p, f, ucl);
            ck_assert_msg(tr <= tols[ti] * 1.01, "%s tol %g: true residual %g", c->name, tols[ti],
                          tr);
            /* agreement with mg: tight where both are accurate; at 1e-6 the
             * solutions differ by up to cond(A) * tol, so only heat is compared */
            double d = rel_diff_d(ucl, umg, n);
            if (tols[ti] <= 1e-10 || c->alpha > 0)
                ck_assert_msg(d < 1e-5, "%s tol %g: opencl and mg differ by %g", c->name, tols[ti],
                              d);
            if (solid)
                for (size_t q = 0; q < n; q++)
                    if (solid[q])
                        ck_assert(ucl[q] == 0.0);
            free(f);
            free(ucl);
            free(umg);
            free(solid);
        }
}

START_TEST(solves_should_agree_with_mg_and_reach_the_tolerance)
{
    const double tols[] = {1e-6, 1e-10};
    check_solves(HV_SMOOTH_AUTO, tols, 2);
}
END_TEST

START_TEST(rbgs_and_jacobi_smoothers_should_converge_on_the_device)
{
    const double tols[] = {1e-8};
    check_solves(HV_SMOOTH_RBGS, tols, 1);
    check_solves(HV_SMOOTH_JACOBI, tols, 1);
}
END_TEST

START_TEST(chebyshev_should_be_the_default_smoother_and_match_mg_iterations)
{
    /* the same hierarchy and smoother: the same number of cycles as mg */
    const cfg c = {"3d plain heat", 3, {32, 32, 32}, 1.0, 0};
    hv_problem p = make_problem(&c, NULL);
    size_t n = cfg_count(&c);
    double *f = make_rhs(&p, n), *u = malloc(n * 8);
    hv_solve_info icl, img;
    solve_with(&p, HV_BACKEND_OPENCL, HV_SMOOTH_AUTO, 1e-10, f, u, &icl);
    solve_with(&p, HV_BACKEND_MG, HV_SMOOTH_CHEBYSHEV, 1e-10, f, u, &img);
    ck_assert_int_eq(icl.iterations, img.iterations);
    for (int i = 0; i < icl.nhistory; i++)
        ck_assert_msg(fabs(icl.history[i] - img.history[i]) <= 1e-3 * img.history[i] + 1e-13,
                      "cycle %d: %g vs %g", i, icl.history[i], img.history[i]);
    free(f);
    free(u);
}
END_TEST

/* A serpentine: one-voxel walls across x every 6 rows, open at alternate ends,
 * so the fluid is one corridor many times the box long (walls off the coarse
 * grid lines: the case where plain geometric MG stalls; docs/METHOD.md,
 * "Multigrid"). */
static uint8_t *make_serpentine(const cfg *c)
{
    const int nz = c->dim == 3 ? c->n[2] : 1;
    uint8_t *s = calloc(cfg_count(c), 1);
    for (int k = 0; k < nz; k++)
        for (int j = 0; j < c->n[1]; j++)
            for (int i = 0; i < c->n[0]; i++) {
                int wall = j % 6 == 5 && ((j / 6) % 2 ? i >= 3 : i < c->n[0] - 3);
                s[(size_t)i + (size_t)c->n[0] * ((size_t)j + (size_t)c->n[1] * k)] = (uint8_t)wall;
            }
    return s;
}

START_TEST(masked_corridor_poisson_should_converge_like_mg)
{
    /* PCG with the symmetric cycle converges (with mean-of-children
     * restriction the device stalled near 2e-5) in about mg's iterations */
    const cfg cs[] = {
        {"2d serpentine poisson", 2, {128, 96, 1}, 0.0, 1},
        {"3d serpentine poisson", 3, {40, 36, 12}, 0.0, 1},
    };
    const hv_smoother sms[] = {HV_SMOOTH_CHEBYSHEV, HV_SMOOTH_RBGS};
    for (int ci = 0; ci < 2; ci++)
        for (int si = 0; si < 2; si++) {
            const cfg *c = &cs[ci];
            uint8_t *solid = make_serpentine(c);
            hv_problem p = make_problem(c, solid);
            size_t n = cfg_count(c);
            double *f = make_rhs(&p, n), *u = malloc(n * 8);
            hv_solve_info info[2];
            const hv_backend bs[2] = {HV_BACKEND_OPENCL, HV_BACKEND_MG};
            for (int b = 1; b >= 0; b--) {
                hv_solver_opts o;
                hv_solver_opts_default(&o);
                o.backend = bs[b];
                o.tol = 1e-8;
                o.smoother = sms[si];
                o.max_iter = 400;
                hv_solver *s;
                ck_assert_msg(hv_solver_create(&s, &p, &o) == HV_OK, "%s", hv_last_error());
                ck_assert_msg(hv_solver_solve_d(s, f, u, &info[b]) == HV_OK, "%s", hv_last_error());
                hv_solver_destroy(&s);
                ck_assert_msg(info[b].reason == HV_STOP_CONVERGED, "%s %s: %s after %d at %g",
                              c->name, b ? "mg" : "opencl", hv_stop_reason_str(info[b].reason),
                              info[b].iterations, info[b].relres);
                ck_assert(true_relres(&p, f, u) <= 1e-8 * 1.01);
            }
            printf("  %s, %s: PCG iterations to 1e-8: opencl %d, mg %d\n", c->name,
                   si ? "rbgs" : "chebyshev", info[0].iterations, info[1].iterations);
            ck_assert_msg(info[0].iterations <= info[1].iterations + 2 + info[1].iterations / 4,
                          "%s: opencl %d iterations, mg %d", c->name, info[0].iterations,
                          info[1].iterations);
            free(f);
            free(u);
            free(solid);
        }
}
END_TEST

/* Walls one cell thick across x at n/3 and 2n/3 with gaps of n/8 at opposite
 * ends in y (bench solve's baffles). */
static uint8_t *make_baffles(const cfg *c)
{
    uint8_t *s = calloc(cfg_count(c), 1);
    int w1 = c->n[0] / 3, w2 = 2 * c->n[0] / 3, gap = c->n[1] / 8;
    for (int k = 0; k < c->n[2]; k++)
        for (int j = 0; j < c->n[1]; j++) {
            size_t row = (size_t)c->n[0] * (j + (size_t)c->n[1] * k);
            s[row + w1] = j < c->n[1] - gap;
            s[row + w2] = j >= gap;
        }
    return s;
}

/* Coarse levels by aggregation on the device (cl_agg.c): the same hierarchy
 * as the CPU's, so about its iterations, far fewer than the geometric levels
 * take in a serpentine corridor, and the same solution; also with float
 * kernels only (double correction on the host). */
START_TEST(aggregation_should_match_mg_on_the_device)
{
    const cfg cs[] = {
        {"2d serpentine poisson", 2, {128, 96, 1}, 0.0, 1},
        {"3d serpentine poisson", 3, {40, 36, 12}, 0.0, 1},
        {"3d serpentine heat", 3, {40, 36, 12}, 1.0, 1},
        {"3d baffles poisson", 3, {40, 38, 36}, 0.0, 1}, /* open space: template rows */
    };
    for (int ci = 0; ci < 4; ci++)
        for (int fp64 = 1; fp64 >= (ci == 1 ? 0 : 1); fp64--) {
            const cfg *c = &cs[ci];
            if (!fp64)
                setenv("HEATVOX_OPENCL_FP64", "0", 1);
            uint8_t *solid = ci < 3 ? make_serpentine(c) : make_baffles(c);
            hv_problem p = make_problem(c, solid);
            size_t n = cfg_count(c);
            double *f = make_rhs(&p, n), *u[3] = {malloc(n * 8), malloc(n * 8), malloc(n * 8)};
            hv_solve_info info[3];
            const hv_backend bs[3] = {HV_BACKEND_OPENCL, HV_BACKEND_MG, HV_BACKEND_OPENCL};
            const hv_coarse co[3] = {HV_COARSE_AGGREGATION, HV_COARSE_AGGREGATION,
                                     HV_COARSE_GEOMETRIC};
            for (int b = 0; b < 3; b++) {
                hv_solver_opts o;
                hv_solver_opts_default(&o);
                o.backend = bs[b];
                o.coarse = co[b];
                o.smoother = HV_SMOOTH_CHEBYSHEV;
                o.tol = 1e-8;
                o.max_iter = 400;
                hv_solver *s;
                ck_assert_msg(hv_solver_create(&s, &p, &o) == HV_OK, "%s", hv_last_error());
                ck_assert_msg(hv_solver_solve_d(s, f, u[b], &info[b]) == HV_OK, "%s",
                              hv_last_error());
                hv_solver_stats st;
                ck_assert_int_eq(hv_solver_get_stats(s, &st), HV_OK);
                ck_assert_msg((st.aggregation_levels > 1) == (b < 2), "%s: %d aggregation levels",
                              c->name, st.aggregation_levels);
                hv_solver_destroy(&s);
                ck_assert_msg(info[b].reason == HV_STOP_CONVERGED, "%s: %s after %d at %g", c->name,
                              hv_stop_reason_str(info[b].reason), info[b].iterations,
                              info[b].relres);
                ck_assert(true_relres(&p, f, u[b]) <= 1e-8 * 1.01);
            }
            printf("  %s%s: PCG iterations to 1e-8: opencl aggregation %d, mg aggregation %d, "
                   "opencl geometric %d\n",
                   c->name, fp64 ? "" : " (float kernels)", info[0].iterations, info[1].iterations,
                   info[2].iterations);
            ck_assert_msg(info[0].iterations <= info[1].iterations + 2, "%s: opencl %d, mg %d",
                          c->name, info[0].iterations, info[1].iterations);
            if (c->alpha == 0)
                ck_assert_msg(2 * info[0].iterations <= info[2].iterations,
                              "%s: aggregation %d, geometric %d", c->name, info[0].iterations,
                              info[2].iterations);
            ck_assert_msg(rel_diff_d(u[0], u[1], n) < 1e-5, "%s: %g", c->name,
                          rel_diff_d(u[0], u[1], n));
            for (int b = 0; b < 3; b++)
                free(u[b]);
            free(f);
            free(solid);
            unsetenv("HEATVOX_OPENCL_FP64");
        }
    /* AUTO: geometric for the first solve, aggregation after its 25 or so. */
    const cfg *c = &cs[1];
    uint8_t *solid = make_serpentine(c);
    hv_problem p = make_problem(c, solid);
    size_t n = cfg_count(c);
    double *f = make_rhs(&p, n), *u = malloc(n * 8);
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.backend = HV_BACKEND_OPENCL;
    o.tol = 1e-8;
    o.max_iter = 400;
    hv_solver *s;
    ck_assert_msg(hv_solver_create(&s, &p, &o) == HV_OK, "%s", hv_last_error());
    hv_solve_info i0, i1;
    hv_solver_stats s0, s1;
    ck_assert_int_eq(hv_solver_solve_d(s, f, u, &i0), HV_OK);
    ck_assert_int_eq(hv_solver_get_stats(s, &s0), HV_OK);
    ck_assert_int_eq(hv_solver_solve_d(s, f, u, &i1), HV_OK);
    ck_assert_int_eq(hv_solver_get_stats(s, &s1), HV_OK);
    ck_assert_msg(s0.aggregation_levels == 0 && i0.iterations > 16 && s1.aggregation_levels > 1 &&
                      i1.iterations <= 8,
                  "AUTO: %d iterations on %d aggregation levels, then %d on %d", i0.iterations,
                  s0.aggregation_levels, i1.iterations, s1.aggregation_levels);
    hv_solver_destroy(&s);
    free(f);
    free(u);
    free(solid);
}
END_TEST

/* A buffer of `bytes` at the start of a larger one filled with a sentinel, so
 * that writes past its end show (on CPU devices they would hit the heap). */
#define GUARD_BYTES 8192
static cl_mem guarded(size_t bytes, cl_mem *parent)
{
    ck_assert_int_le(bytes, GUARD_BYTES / 2);
    ck_assert_int_eq(hv__cl_alloc(CL, GUARD_BYTES, NULL, parent), HV_OK);
    const cl_uchar pattern = 0xab;
    ck_assert_int_eq(
        clEnqueueFillBuffer(CL->q, *parent, &pattern, 1, 0, GUARD_BYTES, 0, NULL, NULL),
        CL_SUCCESS);
    cl_buffer_region reg = {0, bytes};
    cl_int e;
    cl_mem sub =
        clCreateSubBuffer(*parent, CL_MEM_READ_WRITE, CL_BUFFER_CREATE_TYPE_REGION, &reg, &e);
    ck_assert_int_eq(e, CL_SUCCESS);
    return sub;
}

static void check_guard(cl_mem parent, size_t bytes, const char *what)
{
    unsigned char *h = malloc(GUARD_BYTES);
    hv__cl_read(CL, parent, 0, GUARD_BYTES, h);
    ck_assert_int_eq(hv__cl_check(CL), HV_OK);
    for (size_t i = bytes; i < GUARD_BYTES; i++)
        ck_assert_msg(h[i] == 0xab, "%s wrote %zu bytes past its %zu-byte buffer", what, i - bytes,
                      bytes);
    free(h);
}

START_TEST(kernels_should_write_only_inside_tiny_levels)
{
    const cfg tiny[] = {
        {"3d one cell heat", 3, {1, 1, 1}, 1.0, 0},   {"2d one cell poisson", 2, {1, 1, 1}, 0.0, 0},
        {"3d 3x1x1 poisson", 3, {3, 1, 1}, 0.0, 0},   {"2d 2x5 heat", 2, {2, 5, 1}, 1.0, 0},
        {"2d 1x601 poisson", 2, {1, 601, 1}, 0.0, 0}, /* two levels */
        {"3d 9x9x9 heat", 3, {9, 9, 9}, 1.0, 0},      /* odd: weighted coarse level */
        {"3d 9x8x9 masked", 3, {9, 8, 9}, 0.0, 1},
    };
    const hv_smoother sms[] = {HV_SMOOTH_RBGS, HV_SMOOTH_CHEBYSHEV};
    for (int ci = 0; ci < (int)(sizeof tiny / sizeof tiny[0]); ci++)
        for (int si = 0; si < 2; si++) {
            hier h;
            hier_make(&h, &tiny[ci], sms[si]);
            enum { NB = 5 };
            cl_mem parent[MG_MAX_LEVELS][NB];
            memset(parent, 0, sizeof parent);
            for (int l = 0; l < h.m.nlev; l++) {
                hv_clmg_level *L = &h.m.lv[l];
                cl_mem *slot[NB] = {&L->u[0], &L->u[1], &L->f, &L->d, &L->r};
                for (int q = 0; q < NB; q++)
                    if (*slot[q]) {
                        hv__cl_free(slot[q]);
                        *slot[q] = guarded(L->count * sizeof(float), &parent[l][q]);
                    }
            }
            hv_clmg_level *L0 = &h.m.lv[0];
            float *v = malloc(L0->count * sizeof(float));
            fill_f(v, L0->count);
            upload(L0->f, v, L0->count);
            hv__clmg_vcycle(&h.m, 0, 0, 1);
            hv__clmg_fmg(&h.m);
            hv__clmg_smooth(&h.m, 0, 1, 0, 1);
            ck_assert_int_eq(hv__cl_finish(CL), HV_OK);
            for (int l = 0; l < h.m.nlev; l++)
                for (int q = 0; q < NB; q++)
                    if (parent[l][q]) {
                        char what[64];
                        snprintf(what, sizeof what, "%s: level %d buffer %d", tiny[ci].name, l, q);
                        check_guard(parent[l][q], h.m.lv[l].count * sizeof(float), what);
                    }
            hier_free(&h);
            for (int l = 0; l < MG_MAX_LEVELS; l++)
                for (int q = 0; q < NB; q++)
                    hv__cl_free(&parent[l][q]);
            free(v);
        }
}
END_TEST

START_TEST(tiny_and_degenerate_grids_should_solve_like_mg)
{
    /* one-cell and one-row grids: the bottom kernel once wrote past such
     * levels (PoCL), which only a heap checker or a later crash revealed */
    const cfg tiny[] = {
        {"3d one cell heat", 3, {1, 1, 1}, 1.0, 0},
        {"2d one cell heat", 2, {1, 1, 1}, 1.0, 0},
        {"3d 3x1x1 poisson", 3, {3, 1, 1}, 0.0, 0},
        {"2d 1x700 heat", 2, {1, 700, 1}, 1.0, 0},
        {"3d 1000x2x2 poisson", 3, {1000, 2, 2}, 0.0, 0},
        {"3d 5x7x9 poisson", 3, {5, 7, 9}, 0.0, 0},
    };
    for (int ci = 0; ci < (int)(sizeof tiny / sizeof tiny[0]); ci++) {
        hv_problem p = make_problem(&tiny[ci], NULL);
        size_t n = cfg_count(&tiny[ci]);
        double *f = make_rhs(&p, n), *ucl = malloc(n * 8), *umg = malloc(n * 8);
        hv_solve_info icl, img;
        for (int rep = 0; rep < 2; rep++) {
            solve_with(&p, HV_BACKEND_OPENCL, HV_SMOOTH_AUTO, 1e-10, f, ucl, &icl);
            solve_with(&p, HV_BACKEND_MG, HV_SMOOTH_CHEBYSHEV, 1e-10, f, umg, &img);
            ck_assert_msg(icl.reason == HV_STOP_CONVERGED, "%s: %s", tiny[ci].name,
                          hv_stop_reason_str(icl.reason));
            ck_assert_msg(rel_diff_d(ucl, umg, n) < 1e-6, "%s: %g", tiny[ci].name,
                          rel_diff_d(ucl, umg, n));
        }
        free(f);
        free(ucl);
        free(umg);
    }
}
END_TEST

START_TEST(float_interface_and_initial_guess_should_work)
{
    const cfg c = {"2d masked heat", 2, {50, 40, 1}, 1.0, 1};
    uint8_t *solid = make_mask(&c);
    hv_problem p = make_problem(&c, solid);
    size_t n = cfg_count(&c);
    float *f = malloc(n * 4), *u = malloc(n * 4);
    fill_f(f, n);
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.backend = HV_BACKEND_OPENCL;
    hv_solver *s;
    ck_assert_int_eq(hv_solver_create(&s, &p, &o), HV_OK);
    hv_solve_info info;
    ck_assert_int_eq(hv_solver_solve(s, f, u, &info), HV_OK);
    ck_assert_int_eq(info.reason, HV_STOP_CONVERGED);
    ck_assert_int_eq(info.backend, HV_BACKEND_OPENCL);
    ck_assert_int_gt(info.iterations, 0);
    hv_solver_destroy(&s);
    /* starting from the converged solution takes no iteration */
    o.nonzero_guess = 1;
    o.tol = 1e-4; /* above the float rounding of u */
    ck_assert_int_eq(hv_solver_create(&s, &p, &o), HV_OK);
    ck_assert_int_eq(hv_solver_solve(s, f, u, &info), HV_OK);
    ck_assert_int_eq(info.iterations, 0);
    ck_assert_int_eq(info.reason, HV_STOP_CONVERGED);
    hv_solver_destroy(&s);
    free(f);
    free(u);
    free(solid);
}
END_TEST

START_TEST(float_only_devices_should_still_reach_1e10)
{
    /* HEATVOX_OPENCL_FP64=0: float kernels, double defect correction on the host */
    setenv("HEATVOX_OPENCL_FP64", "0", 1);
    const double tols[] = {1e-10};
    for (int ci = 0; ci < NCFG; ci += 2) {
        const cfg *c = &CFGS[ci];
        uint8_t *solid = make_mask(c);
        hv_problem p = make_problem(c, solid);
        size_t n = cfg_count(c);
        double *f = make_rhs(&p, n), *ucl = malloc(n * 8), *umg = malloc(n * 8);
        hv_solve_info icl, img;
        solve_with(&p, HV_BACKEND_OPENCL, HV_SMOOTH_AUTO, tols[0], f, ucl, &icl);
        solve_with(&p, HV_BACKEND_MG, HV_SMOOTH_CHEBYSHEV, tols[0], f, umg, &img);
        ck_assert_msg(icl.reason == HV_STOP_CONVERGED, "%s: %s at %g", c->name,
                      hv_stop_reason_str(icl.reason), icl.relres);
        ck_assert(true_relres(&p, f, ucl) <= tols[0] * 1.01);
        ck_assert_msg(rel_diff_d(ucl, umg, n) < 1e-5, "%s: %g", c->name, rel_diff_d(ucl, umg, n));
        free(f);
        free(ucl);
        free(umg);
        free(solid);
    }
    unsetenv("HEATVOX_OPENCL_FP64");
}
END_TEST

/* ---------- devices and failures ---------- */

START_TEST(invalid_device_choice_should_fail_with_a_clear_message)
{
    const char *bad[] = {"99:0", "0:99", "no-such-device-name"};
    hv_problem p = make_problem(&CFGS[0], NULL);
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.backend = HV_BACKEND_OPENCL;
    for (int i = 0; i < 3; i++) {
        setenv("HEATVOX_OPENCL_DEVICE", bad[i], 1);
        hv_solver *s = NULL;
        ck_assert_int_eq(hv_solver_create(&s, &p, &o), HV_ERR_INVALID_ARG);
        ck_assert_ptr_null(s);
        ck_assert_msg(strstr(hv_last_error(), "HEATVOX_OPENCL_DEVICE") &&
                          strstr(hv_last_error(), bad[i]) && strstr(hv_last_error(), CL->info.name),
                      "message: %s", hv_last_error());
        ck_assert_int_eq(hv_opencl_probe(NULL), HV_ERR_INVALID_ARG);
    }
    /* the selected device by index and by part of its name */
    char spec[64];
    snprintf(spec, sizeof spec, "%d:%d", CL->info.platform, CL->info.device);
    setenv("HEATVOX_OPENCL_DEVICE", spec, 1);
    hv_opencl_device d;
    ck_assert_int_eq(hv_opencl_probe(&d), HV_OK);
    ck_assert_str_eq(d.name, CL->info.name);
    snprintf(spec, sizeof spec, "%.6s", CL->info.name);
    setenv("HEATVOX_OPENCL_DEVICE", spec, 1);
    ck_assert_int_eq(hv_opencl_probe(&d), HV_OK);
    hv_solver *s;
    ck_assert_msg(hv_solver_create(&s, &p, &o) == HV_OK, "%s", hv_last_error());
    hv_solver_destroy(&s);
    unsetenv("HEATVOX_OPENCL_DEVICE");
}
END_TEST

START_TEST(device_list_should_describe_and_mark_the_selected_device)
{
    hv_opencl_device list[16];
    int count = 0, selected = 0;
    ck_assert_int_eq(hv_opencl_list_devices(list, 16, &count), HV_OK);
    ck_assert_int_ge(count, 1);
    for (int i = 0; i < count && i < 16; i++) {
        ck_assert(list[i].name[0] != 0);
        ck_assert_msg(!strncmp(list[i].version, "OpenCL ", 7), "version '%s'", list[i].version);
        ck_assert(list[i].global_mem > 0);
        if (list[i].selected) {
            selected++;
            ck_assert_str_eq(list[i].name, CL->info.name);
            ck_assert_int_eq(list[i].fp64, CL->info.fp64);
        }
    }
    ck_assert_int_eq(selected, 1);
    ck_assert_int_eq(hv_opencl_list_devices(NULL, 0, &count), HV_OK);
    ck_assert_int_ge(count, 1);
}
END_TEST

START_TEST(kernel_build_failure_should_report_the_build_log)
{
    const char *src[] = {"__kernel void broken(__global float *x) { x[0] = undeclared_name; }\n"};
    cl_program prog = NULL;
    /* PoCL's compiler also prints the error on stderr: keep it out of the log */
    fflush(stderr);
    int saved = dup(2), null = open("/dev/null", O_WRONLY);
    if (null >= 0)
        dup2(null, 2);
    hv_status st = hv__cl_build(CL, src, 1, "", &prog);
    if (saved >= 0)
        dup2(saved, 2);
    if (null >= 0)
        close(null);
    if (saved >= 0)
        close(saved);
    ck_assert_int_eq(st, HV_ERR_BACKEND);
    ck_assert_ptr_null(prog);
    ck_assert_msg(strstr(hv_last_error(), "failed to build") &&
                      strstr(hv_last_error(), "undeclared_name"),
                  "message: %s", hv_last_error());
    ck_assert(strlen(hv_last_error()) < 1000);
}
END_TEST

/* A module's kernels on a handle (cl_core.h): opened once, the same kernel
 * objects after; its fp64-only kernels exist exactly on fp64 handles, and a
 * launch of one that does not exist is recorded, naming it, not dropped. A
 * module whose sources do not build reports the build log. */
START_TEST(modules_should_open_once_and_refuse_missing_kernels)
{
    TL_ASSERT_OK(hv__cl_module_open(CL, HV_CLSOLVE));
    TL_ASSERT_OK(hv__cl_module_open(CL, HV_CLSOLVE));
    int opened = 0;
    for (int i = 0; i < CL->nmod; i++)
        opened += CL->mod[i].m == HV_CLSOLVE;
    ck_assert_int_eq(opened, 1);
    cl_mem v = NULL, a = NULL;
    TL_ASSERT_OK(hv__cl_alloc(CL, 64 * sizeof(double), NULL, &v));
    TL_ASSERT_OK(hv__cl_alloc(CL, 64 * sizeof(float), NULL, &a));
    size_t g[1], l[1];
    hv__cl_range1(64, g, l);
    hv__cl_args(CL, HV_CLSOLVE, HV_K_FINE_MASK, "mml", v, a, (size_t)64);
    hv__cl_run(CL, HV_CLSOLVE, HV_K_FINE_MASK, 1, g, l);
    hv_status st = hv__cl_finish(CL);
    if (CL->fp64) {
        ck_assert_int_eq(st, HV_OK);
    } else {
        ck_assert_int_eq(st, HV_ERR_BACKEND);
        ck_assert_msg(strstr(hv_last_error(), "fine_mask"), "message: %s", hv_last_error());
    }
    hv__cl_free(&v);
    hv__cl_free(&a);
    static const char *const bad_sources[] = {
        "__kernel void k(__global float *x) { x[0] = nope; }\n", NULL};
    static const char *const bad_kernels[] = {"k", NULL};
    static const hv_cl_module bad = {"broken", bad_sources, bad_kernels, 0, 0};
    fflush(stderr);
    int saved = dup(2), null = open("/dev/null", O_WRONLY);
    if (null >= 0)
        dup2(null, 2);
    st = hv__cl_module_open(CL, &bad);
    if (saved >= 0)
        dup2(saved, 2);
    if (null >= 0)
        close(null);
    if (saved >= 0)
        close(saved);
    ck_assert_int_eq(st, HV_ERR_BACKEND);
    ck_assert_msg(strstr(hv_last_error(), "nope"), "message: %s", hv_last_error());
}
END_TEST

/* AUTO: the CPU unless a GPU (or HEATVOX_AUTO_OPENCL=1 any device) is there;
 * once resolved to opencl, the solver and the pipelines run on the device. */
START_TEST(auto_should_take_a_gpu_or_the_device_it_is_allowed)
{
    const size_t big = (size_t)1 << 24, small = 4096;
    setenv("HEATVOX_AUTO_OPENCL", "0", 1);
    ck_assert_int_eq(hv_backend_resolve(HV_BACKEND_AUTO, big, 0), HV_BACKEND_FFTW);
    ck_assert_int_eq(hv_backend_resolve(HV_BACKEND_AUTO, big, 1), HV_BACKEND_MG);
    unsetenv("HEATVOX_AUTO_OPENCL");
    hv_opencl_device d;
    ck_assert_int_eq(hv_opencl_probe(&d), HV_OK);
    ck_assert_int_eq(hv_backend_resolve(HV_BACKEND_AUTO, big, 0),
                     d.gpu ? HV_BACKEND_OPENCL : HV_BACKEND_FFTW);
    ck_assert_int_eq(hv_backend_resolve(HV_BACKEND_AUTO, small, 1), HV_BACKEND_MG);
    ck_assert_int_eq(hv_backend_resolve(HV_BACKEND_MG, big, 0), HV_BACKEND_MG);
    ck_assert_int_eq(hv_backend_resolve(HV_BACKEND_FFTW, big, 0), HV_BACKEND_FFTW);
    printf("  auto on '%s' (%s): %s for 2^24 cells, %s for 4096\n", d.name, d.gpu ? "GPU" : "CPU",
           hv_backend_name(hv_backend_resolve(HV_BACKEND_AUTO, big, 0)),
           hv_backend_name(hv_backend_resolve(HV_BACKEND_AUTO, small, 0)));

    setenv("HEATVOX_AUTO_OPENCL", "1", 1);
    ck_assert_int_eq(hv_backend_resolve(HV_BACKEND_AUTO, small, 1), HV_BACKEND_OPENCL);
    hv_problem p;
    memset(&p, 0, sizeof p);
    p.dim = 2;
    p.n[0] = p.n[1] = 32;
    p.h = 1.0 / 32;
    p.alpha = 1;
    p.beta = 4 * p.h * p.h;
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    hv_solver *s = NULL;
    ck_assert_int_eq(hv_solver_create(&s, &p, &o), HV_OK);
    ck_assert_int_eq(hv_solver_backend(s), HV_BACKEND_OPENCL);
    hv_solver_destroy(&s);
    /* The distance pipeline takes its device path (fp64 devices) */
    if (CL->fp64) {
        hv_grid *g = NULL;
        const int n[3] = {32, 32, 1};
        const double org[3] = {0, 0, 0};
        ck_assert_int_eq(hv_grid_create(&g, 2, n, 1.0 / 32, org), HV_OK);
        const int vox[3] = {5, 7, 0};
        hv_distance_sources src = {0};
        src.voxels = vox;
        src.nvoxels = 1;
        hv_distance_stats st;
        ck_assert_int_eq(hv_distance_compute(g, &src, NULL, &st), HV_OK);
        ck_assert_int_eq(st.backend, HV_BACKEND_OPENCL);
        hv_grid_destroy(&g);
    }
    unsetenv("HEATVOX_AUTO_OPENCL");
}
END_TEST

/* Run in a child whose ICD loader finds no platform (OCL_ICD_VENDORS). */
static int child_without_platform(void)
{
    static uint8_t solid[64] = {[9] = 1};
    hv_problem p;
    memset(&p, 0, sizeof p);
    p.dim = 2;
    p.n[0] = p.n[1] = 8;
    p.h = 1;
    p.alpha = 1;
    p.beta = 1;
    p.solid = solid;
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.backend = HV_BACKEND_OPENCL;
    hv_solver *s = NULL;
    int count = -1;
    if (hv_solver_create(&s, &p, &o) != HV_ERR_UNSUPPORTED || s)
        return 1;
    if (!strstr(hv_last_error(), "OpenCL platform"))
        return 2;
    if (hv_opencl_probe(NULL) != HV_ERR_UNSUPPORTED)
        return 3;
    if (hv_opencl_list_devices(NULL, 0, &count) != HV_ERR_UNSUPPORTED || count != 0)
        return 4;
    /* AUTO falls back to the CPU (with a mask, mg), even when asked to take any device */
    setenv("HEATVOX_AUTO_OPENCL", "1", 1);
    o.backend = HV_BACKEND_AUTO;
    if (hv_solver_create(&s, &p, &o) != HV_OK || hv_solver_backend(s) == HV_BACKEND_OPENCL)
        return 5;
    hv_solver_destroy(&s);
    return 0;
}

START_TEST(no_platform_should_make_the_backend_unsupported)
{
    char *argv[] = {(char *)SELF, "--child-no-platform", NULL};
    size_t ne = 0;
    while (environ[ne])
        ne++;
    char **env = calloc(ne + 2, sizeof *env);
    size_t k = 0;
    for (size_t i = 0; i < ne; i++)
        if (strncmp(environ[i], "OCL_ICD_VENDORS=", 16) &&
            strncmp(environ[i], "HEATVOX_OPENCL_DEVICE=", 22))
            env[k++] = environ[i];
    env[k++] = "OCL_ICD_VENDORS=/nonexistent-heatvox-icd-dir";
    env[k] = NULL;
    pid_t pid;
    ck_assert_int_eq(posix_spawn(&pid, SELF, NULL, NULL, argv, env), 0);
    int status = 0;
    ck_assert_int_eq(waitpid(pid, &status, 0), pid);
    ck_assert_msg(WIFEXITED(status) && WEXITSTATUS(status) == 0, "child status %d", status);
    free(env);
}
END_TEST

START_TEST(opencl_should_be_reported_unsupported_without_a_platform)
{
    ck_assert_int_eq(child_without_platform(), 0);
}
END_TEST

int main(int argc, char **argv)
{
    if (argc > 1 && !strcmp(argv[1], "--child-no-platform"))
        return child_without_platform();
    SELF = argv[0];
    tl_pocl_cache(argv[0]);
    /* The CPU references run on one thread: libgomp's spinning workers and
     * PoCL's worker threads interleaved on a busy 2-core machine took minutes. */
    hv_set_threads(1);
    Suite *su = suite_create("opencl");
    TCase *tc = tcase_create("opencl");
    tcase_set_timeout(tc, 600);
    hv_status st = hv_opencl_probe(NULL);
    int have_cl = st != HV_ERR_UNSUPPORTED;
    char why[512];
    snprintf(why, sizeof why, "no OpenCL platform (%s)", hv_last_error());
    if (!have_cl) {
        printf("note: no OpenCL platform (%s); only checking that the backend says so\n",
               hv_last_error());
        tcase_add_test(tc, opencl_should_be_reported_unsupported_without_a_platform);
    } else {
        st = hv__cl_open(&CL);
        if (st) {
            fprintf(stderr, "check_opencl: cannot open the OpenCL device: %s\n", hv_last_error());
            return 1;
        }
        printf("OpenCL device: %s (%s), fp64 %s\n", CL->info.name, CL->info.platform_name,
               CL->fp64 ? "yes" : "no");
    }
    TL_ADD_IF(tc, apply_and_residual_should_match_cpu_on_every_level, have_cl, why);
    TL_ADD_IF(tc, smoother_sweeps_should_match_cpu, have_cl, why);
    TL_ADD_IF(tc, restriction_should_be_the_mean_of_the_children, have_cl, why);
    TL_ADD_IF(tc, prolongation_should_match_cpu, have_cl, why);
    TL_ADD_IF(tc, transpose_restriction_should_match_cpu_and_be_the_adjoint_of_prolongation,
              have_cl, why);
    TL_ADD_IF(tc, symmetric_cycle_should_be_a_symmetric_operator, have_cl, why);
    TL_ADD_IF(tc, bottom_solver_should_solve_the_coarsest_level, have_cl, why);
    TL_ADD_IF(tc, face_gradient_and_divergence_should_match_cpu, have_cl, why);
    TL_ADD_IF(tc, face_normalize_should_give_unit_normal_components, have_cl, why);
    TL_ADD_IF(tc, ratio_and_axpy_should_match_cpu, have_cl, why);
    TL_ADD_IF(tc, reductions_should_match_double_sums, have_cl, why);
    TL_ADD_IF(tc, solves_should_agree_with_mg_and_reach_the_tolerance, have_cl, why);
    TL_ADD_IF(tc, rbgs_and_jacobi_smoothers_should_converge_on_the_device, have_cl, why);
    TL_ADD_IF(tc, chebyshev_should_be_the_default_smoother_and_match_mg_iterations, have_cl, why);
    TL_ADD_IF(tc, aggregation_should_match_mg_on_the_device, have_cl, why);
    TL_ADD_IF(tc, masked_corridor_poisson_should_converge_like_mg, have_cl, why);
    TL_ADD_IF(tc, kernels_should_write_only_inside_tiny_levels, have_cl, why);
    TL_ADD_IF(tc, tiny_and_degenerate_grids_should_solve_like_mg, have_cl, why);
    TL_ADD_IF(tc, float_interface_and_initial_guess_should_work, have_cl, why);
    TL_ADD_IF(tc, float_only_devices_should_still_reach_1e10, have_cl, why);
    TL_ADD_IF(tc, invalid_device_choice_should_fail_with_a_clear_message, have_cl, why);
    TL_ADD_IF(tc, device_list_should_describe_and_mark_the_selected_device, have_cl, why);
    TL_ADD_IF(tc, kernel_build_failure_should_report_the_build_log, have_cl, why);
    TL_ADD_IF(tc, modules_should_open_once_and_refuse_missing_kernels, have_cl, why);
    TL_ADD_IF(tc, no_platform_should_make_the_backend_unsupported, have_cl, why);
    TL_ADD_IF(tc, auto_should_take_a_gpu_or_the_device_it_is_allowed, have_cl, why);
    suite_add_tcase(su, tc);
    SRunner *sr = srunner_create(su);
    /* No fork, whatever CK_FORK says: the library links PoCL and OpenVDB/TBB,
     * whose worker threads do not survive fork: a forked test hangs
     * (docs/METHOD.md, "Testing notes"). */
    srunner_set_fork_status(sr, CK_NOFORK);
    srunner_run_all(sr, CK_NORMAL);
    int failed = srunner_ntests_failed(sr);
    srunner_free(sr);
    if (CL)
        hv__cl_close(&CL);
    return failed ? 1 : 0;
}
