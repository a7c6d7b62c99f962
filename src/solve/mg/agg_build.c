/* Smoothed aggregation (agg_internal.h): building the levels and freeing them. */
#include "agg_internal.h"

static hv_status level_work(mg_agg *g, int l)
{
    mg_alevel *L = &g->lv[l];
    size_t n = (size_t)L->n + 1;
    if (l > 0) {
        L->dinv = malloc(n * sizeof(float));
        L->u = calloc(n, sizeof(float));
        L->f = calloc(n, sizeof(float));
        L->r = calloc(n, sizeof(float));
        L->d = calloc(n, sizeof(float));
        if (!L->dinv || !L->u || !L->f || !L->r || !L->d)
            return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for level %d", l);
        for (int32_t c = 0; c < L->n; c++) {
            int32_t bc[ROW_MAX];
            float bv[ROW_MAX];
            const int32_t *col;
            const float *val;
            int k = hv__agg_level_row(L, c, bc, bv, &col, &val);
            double d = 0;
            for (int q = 0; q < k; q++)
                if (col[q] == c)
                    d += val[q];
            L->dinv[c] = d > 0 ? (float)(1.0 / d) : 0.0f;
        }
        g->bytes += 5 * n * sizeof(float) + 3 * n * sizeof(int32_t) + n * sizeof(size_t) +
                    L->A.rp[L->n] * (sizeof(int32_t) + sizeof(float));
    }
    L->t = calloc(n, sizeof(float));
    L->s = calloc(n, sizeof(float));
    if (!L->t || !L->s)
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for level %d", l);
    g->bytes += 2 * n * sizeof(float);
    return HV_OK;
}

void hv__mg_agg_keep_bottom(mg_agg *g)
{
    for (int l = 0; l < MG_AGG_MAX_LEVELS; l++) {
        mg_alevel *L = &g->lv[l];
        void *all[] = {L->dinv, L->agg, L->mrp, L->mem, L->xyz, L->u, L->f, L->r, L->d, L->t, L->s};
        for (size_t i = 0; i < sizeof all / sizeof all[0]; i++)
            free(all[i]);
        hv__agg_csr_free(&L->A);
        hv__agg_csr_free(&L->P);
        hv__agg_csr_free(&L->R);
        free(L->plain);
        free(L->cls);
        free(L->cn);
        free(L->coff);
        free(L->cval);
        free(L->grow);
        free(L->gcls);
        int32_t n = L->n;
        memset(L, 0, sizeof *L);
        L->n = n;
    }
    free(g->faces);
    g->faces = NULL;
    g->fine = NULL;
}

void hv__mg_agg_free(mg_agg *g)
{
    if (!g)
        return;
    for (int l = 0; l < MG_AGG_MAX_LEVELS; l++) {
        mg_alevel *L = &g->lv[l];
        hv__agg_csr_free(&L->A);
        hv__agg_csr_free(&L->P);
        hv__agg_csr_free(&L->R);
        free(L->plain);
        free(L->cls);
        free(L->cn);
        free(L->coff);
        free(L->cval);
        free(L->grow);
        free(L->gcls);
        free(L->dinv);
        free(L->agg);
        free(L->mrp);
        free(L->mem);
        free(L->xyz);
        free(L->u);
        free(L->f);
        free(L->r);
        free(L->d);
        free(L->t);
        free(L->s);
    }
    free(g->faces);
    free(g->chol);
    free(g->region);
    free(g->bx);
    free(g);
}

/* The open faces of each fine cell, for op_row without index arithmetic
 * (binary levels only: their open faces all weigh one). */
static hv_status fine_faces(mg_agg *g)
{
    const mg_level *L = g->fine;
    if (!L->binary)
        return HV_OK;
    if (!(g->faces = malloc(L->count)))
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for the fine level's faces");
#pragma omp parallel for collapse(2) schedule(static) if (L->count > AGG_PAR_MIN)
    for (int k = 0; k < L->n[2]; k++)
        for (int j = 0; j < L->n[1]; j++)
            for (int i = 0; i < L->n[0]; i++) {
                unsigned f = 0;
                for (int b = 0; b < g->dim; b++)
                    for (int hi = 0; hi < 2; hi++) {
                        int x[3] = {i, j, k};
                        x[b] += hi;
                        if (x[b] > 0 && x[b] < L->n[b] &&
                            L->w[b][mg_face_index(L, b, x[0], x[1], x[2])] != 0.0f)
                            f |= 1u << (2 * b + hi);
                    }
                g->faces[(size_t)i + L->sy * j + L->sz * k] = (uint8_t)f;
            }
    g->bytes += L->count;
    return HV_OK;
}

hv_status hv__mg_agg_build(mg_agg **out, const mg_level *F, int dim, double alpha)
{
    *out = NULL;
    if (F->plain || !F->dinv || F->count >= (size_t)INT32_MAX)
        return HV_OK;
    mg_agg *g = calloc(1, sizeof *g);
    if (!g)
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory");
    g->dim = dim;
    g->alpha = alpha;
    g->fine = F;
    g->lv[0].n = (int32_t)F->count;
    for (int b = 0; b < 3; b++)
        g->lv[0].ext[b] = F->n[b];
    hv_status st = fine_faces(g);
    if (st)
        goto fail;
    int l = 0;
    for (;; l++) {
        mg_alevel *L = &g->lv[l];
        if ((st = level_work(g, l)))
            goto fail;
        agg_op o = level_op(g, l);
        /* The fine level's bound is Gershgorin's (its rows are diagonally
         * dominant); the coarse levels' by power iteration. */
        L->lmax = l == 0 ? 2.0 : hv__agg_op_lmax(&o, L->t, L->s);
        if (L->n <= AGG_BOTTOM || l + 1 == MG_AGG_MAX_LEVELS)
            break;
        if ((st = hv__agg_aggregate(g, l)))
            goto fail;
        if ((double)L->nagg > 0.8 * L->live) {
            if (L->n > AGG_STALL || l == 0)
                goto none; /* not coarsening: keep the geometric levels */
            free(L->agg);
            free(L->mrp);
            free(L->mem);
            L->agg = NULL;
            L->mrp = NULL;
            L->mem = NULL;
            break;
        }
        g->bytes += (size_t)L->n * 2 * sizeof(int32_t) + (size_t)g->lv[l + 1].n * sizeof(size_t);
        if ((st = l == 0 ? hv__agg_galerkin0(g, AGG_OMEGA / L->lmax)
                         : hv__agg_galerkin_csr(g, l, AGG_OMEGA / L->lmax)))
            goto fail;
    }
    g->nlev = l + 1;
    if (g->nlev < 2)
        goto none;
    if ((st = hv__agg_bottom_factor(g)))
        goto fail;
    g->bytes += (size_t)g->nb * g->nb * sizeof(double);
    *out = g;
    return HV_OK;
none:
    hv__mg_agg_free(g);
    return HV_OK;
fail:
    hv__mg_agg_free(g);
    return st;
}
