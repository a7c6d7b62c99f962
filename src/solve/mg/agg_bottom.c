/* Smoothed aggregation (agg_internal.h): the bottom level's factor and solve. */
#include "agg_internal.h"

/* Connected regions of the bottom operator (Poisson: each its own null space). */
static hv_status bottom_regions(mg_agg *g, const agg_op *o)
{
    int32_t n = o->n, *stack = malloc((size_t)n * sizeof *stack);
    g->region = malloc((size_t)n * sizeof *g->region);
    if (!stack || !g->region) {
        free(stack);
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for the bottom level");
    }
    for (int32_t c = 0; c < n; c++)
        g->region[c] = -1;
    g->nregion = 0;
    for (int32_t c0 = 0; c0 < n; c0++) {
        if (g->region[c0] >= 0 || !(o->dinv[c0] > 0))
            continue;
        int32_t top = 0;
        stack[top++] = c0;
        g->region[c0] = g->nregion;
        while (top) {
            int32_t c = stack[--top];
            int32_t bc[ROW_MAX];
            float bv[ROW_MAX];
            const int32_t *col;
            const float *val;
            int k = hv__agg_op_row(o, c, bc, bv, &col, &val);
            for (int e = 0; e < k; e++)
                if (g->region[col[e]] < 0 && o->dinv[col[e]] > 0 && val[e] != 0) {
                    g->region[col[e]] = g->nregion;
                    stack[top++] = col[e];
                }
        }
        g->nregion++;
    }
    free(stack);
    return HV_OK;
}

/* The bottom level's dense Cholesky factor. Poisson adds sigma/|R| on every
 * pair of a region R (sigma: the mean diagonal), which leaves the mean-free
 * solution of a mean-free right-hand side unchanged and makes the matrix
 * definite; empty rows get a one on the diagonal. */
hv_status hv__agg_bottom_factor(mg_agg *g)
{
    int l = g->nlev - 1;
    agg_op o = level_op(g, l);
    int32_t n = g->nb = o.n;
    hv_status st = bottom_regions(g, &o);
    if (st)
        return st;
    g->chol = calloc((size_t)n * n, sizeof *g->chol);
    g->bx = malloc(((size_t)n + 1) * sizeof *g->bx);
    double *cnt = calloc((size_t)g->nregion + 1, sizeof *cnt);
    if (!g->chol || !g->bx || !cnt) {
        free(cnt);
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for the bottom level");
    }
    double *M = g->chol, dsum = 0;
    for (int32_t c = 0; c < n; c++) {
        int32_t bc[ROW_MAX];
        float bv[ROW_MAX];
        const int32_t *col;
        const float *val;
        int k = hv__agg_op_row(&o, c, bc, bv, &col, &val);
        for (int e = 0; e < k; e++)
            M[(size_t)c * n + col[e]] += val[e];
        if (g->region[c] >= 0) {
            cnt[g->region[c]] += 1;
            dsum += M[(size_t)c * n + c];
        }
    }
    double sigma = n ? dsum / n : 1.0;
    for (int32_t i = 0; i < n; i++) {
        if (g->region[i] < 0) {
            for (int32_t j = 0; j < n; j++)
                M[(size_t)i * n + j] = M[(size_t)j * n + i] = 0;
            M[(size_t)i * n + i] = 1;
            continue;
        }
        for (int32_t j = 0; g->alpha == 0 && j < n; j++)
            if (g->region[j] == g->region[i])
                M[(size_t)i * n + j] += sigma / cnt[g->region[i]];
    }
    free(cnt);
    /* Symmetrize (float coarse rows), then factor in place (lower). */
    for (int32_t i = 0; i < n; i++)
        for (int32_t j = 0; j < i; j++) {
            double v = 0.5 * (M[(size_t)i * n + j] + M[(size_t)j * n + i]);
            M[(size_t)i * n + j] = M[(size_t)j * n + i] = v;
        }
    for (int32_t j = 0; j < n; j++) {
        double d = M[(size_t)j * n + j];
        for (int32_t k = 0; k < j; k++)
            d -= M[(size_t)j * n + k] * M[(size_t)j * n + k];
        if (!(d > 1e-12 * sigma))
            d = sigma; /* a direction float rounding left singular: damp it */
        d = sqrt(d);
        M[(size_t)j * n + j] = d;
#pragma omp parallel for schedule(static) if (n - j > 256)
        for (int32_t i = j + 1; i < n; i++) {
            double s = M[(size_t)i * n + j];
            for (int32_t k = 0; k < j; k++)
                s -= M[(size_t)i * n + k] * M[(size_t)j * n + k];
            M[(size_t)i * n + j] = s / d;
        }
    }
    return HV_OK;
}

/* u = A^-1 f on the bottom level (Poisson: mean-free per region). */
void hv__mg_agg_bottom(mg_agg *g, const float *f, float *u)
{
    int32_t n = g->nb;
    const double *M = g->chol;
    double *x = g->bx;
    for (int32_t i = 0; i < n; i++) {
        double s = g->region[i] >= 0 ? f[i] : 0.0;
        for (int32_t k = 0; k < i; k++)
            s -= M[(size_t)i * n + k] * x[k];
        x[i] = s / M[(size_t)i * n + i];
    }
    for (int32_t i = n - 1; i >= 0; i--) {
        double s = x[i];
        for (int32_t k = i + 1; k < n; k++)
            s -= M[(size_t)k * n + i] * x[k];
        x[i] = s / M[(size_t)i * n + i];
    }
    for (int32_t i = 0; i < n; i++)
        u[i] = g->region[i] >= 0 ? (float)x[i] : 0.0f;
}
