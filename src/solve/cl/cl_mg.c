/* The multigrid hierarchy on an OpenCL device, uploaded and freed, and its
 * cycles (cl_mg.h); one level's kernels are cl_level.c's. */
#include "cl_mg.h"
#include "core/error.h"
#include "cl/cl_ops.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define BOTTOM_WG 64

static hv_status upload_level(hv_clmg *m, const mg_hierarchy *H, int l)
{
    hv_cl *cl = m->cl;
    const mg_level *S = &H->lv[l];
    hv_clmg_level *L = &m->lv[l];
    memcpy(L->n, S->n, sizeof L->n);
    memcpy(L->coarsen, S->coarsen, sizeof L->coarsen);
    memcpy(L->c, S->c, sizeof L->c);
    L->count = S->count;
    L->plain = S->plain;
    L->lmax = S->lmax;
    for (int b = 0; b < 3; b++) {
        L->N[b] = S->n[b];
        L->C[b] = (cl_float)S->c[b];
    }
    L->N[3] = S->plain;
    L->C[3] = (cl_float)H->alpha;
    hv__cl_range2((size_t)S->n[0], (size_t)S->n[1] * S->n[2], L->g, L->l);
    const size_t bytes = S->count * sizeof(float);
    hv_status st = HV_OK;
    if (!S->plain) {
        if ((st = hv__cl_alloc(cl, bytes, S->a, &L->a)))
            return st;
        for (int b = 0; b < H->dim; b++) {
            size_t nf = (S->count / S->n[b]) * (size_t)(S->n[b] + 1);
            if ((st = hv__cl_alloc(cl, nf * sizeof(float), S->w[b], &L->w[b])))
                return st;
        }
    }
    const int jac = m->smoother != HV_SMOOTH_RBGS;
    if ((st = hv__cl_alloc(cl, bytes, NULL, &L->u[0])) ||
        (st = hv__cl_alloc(cl, bytes, NULL, &L->f)) ||
        (jac && ((st = hv__cl_alloc(cl, bytes, NULL, &L->u[1])) ||
                 (st = hv__cl_alloc(cl, bytes, NULL, &L->d)))))
        return st;
    hv__cl_zero(cl, L->u[0], bytes);
    hv__cl_zero(cl, L->f, bytes);
    if (jac) {
        hv__cl_zero(cl, L->u[1], bytes);
        hv__cl_zero(cl, L->d, bytes);
    }
    return HV_OK;
}

/* The symmetric cycle's residual vector and prolongation renormalization on
 * level l (not the bottom). */
static hv_status upload_sym(hv_clmg *m, const mg_hierarchy *H, int l)
{
    const mg_level *F = &H->lv[l], *C = &H->lv[l + 1];
    hv_clmg_level *L = &m->lv[l];
    hv_status st = hv__cl_alloc(m->cl, F->count * sizeof(float), NULL, &L->r);
    if (st || C->plain)
        return st;
    float *pn = hv_malloc(F->count * sizeof(float));
    if (!pn)
        return hv__error(HV_ERR_NOMEM, "OpenCL multigrid: out of memory for level %d weights", l);
    hv__mg_prolong_norm(F, C, pn);
    st = hv__cl_alloc(m->cl, F->count * sizeof(float), pn, &L->pn); /* copies pn */
    hv_free(pn);
    return st;
}

static hv_status upload_bottom(hv_clmg *m, const mg_hierarchy *H)
{
    hv_cl *cl = m->cl;
    const mg_level *S = &H->lv[H->nlev - 1];
    hv_status st;
    m->bnregion = 0;
    if (H->alpha == 0 && S->region && S->nregion > 0) {
        m->bnregion = S->nregion;
        double *cnt = calloc((size_t)S->nregion, sizeof *cnt);
        float *cntf = calloc((size_t)S->nregion, sizeof *cntf);
        if (!cnt || !cntf) {
            free(cnt);
            free(cntf);
            return hv__error(HV_ERR_NOMEM, "OpenCL multigrid: out of memory");
        }
        for (size_t c = 0; c < S->count; c++)
            if (S->region[c] >= 0)
                cnt[S->region[c]] += 1;
        for (int r = 0; r < S->nregion; r++) {
            cnt[r] = 1.0 / cnt[r];
            cntf[r] = (float)cnt[r];
        }
        st = hv__cl_alloc(cl, S->count * sizeof(int32_t), S->region, &m->bregion);
        if (!st)
            st = hv__cl_alloc(cl, (size_t)S->nregion * cl->acc,
                              cl->fp64 ? (void *)cnt : (void *)cntf, &m->brinv);
        free(cnt);
        free(cntf);
        if (st)
            return st;
    }
    if ((st = hv__cl_alloc(cl, (5 * S->count + (size_t)m->bnregion) * cl->acc, NULL, &m->bscr)))
        return st;
    m->bl = hv__cl_group_limit(cl, HV_CLSOLVE, HV_K_MG_BOTTOM_CG, BOTTOM_WG);
    return HV_OK;
}

/* Devices without fp64: the bottom level's coefficients and regions copied
 * for the host solve. A float CG on the bottom (up to MG_BOTTOM_CELLS cells,
 * long and thin or singular) stalls near 1e-5 relative in its true residual,
 * where mg.c's double CG reaches 1e-12: the inexact coarse solve cost the
 * PCG of a 2D serpentine 174 iterations instead of mg's 97 and stalled the
 * defect correction on a 1000x2x2 Poisson grid. */
static hv_status copy_bottom(hv_clmg *m, const mg_hierarchy *H)
{
    const mg_level *S = &H->lv[H->nlev - 1];
    mg_level *B = &m->hb;
    memset(B, 0, sizeof *B);
    memcpy(B->n, S->n, sizeof B->n);
    B->count = S->count;
    B->sy = S->sy;
    B->sz = S->sz;
    memcpy(B->c, S->c, sizeof B->c);
    B->plain = S->plain;
    m->host_bottom = 1;
    const size_t n = S->count;
    int bad = !(m->hf = malloc(n * sizeof *m->hf)) ||
              !(m->hw = malloc(MG_BOTTOM_WORK * n * sizeof *m->hw));
    if (!S->plain) {
        bad |= !(B->a = malloc(n * sizeof(float)));
        if (B->a)
            memcpy(B->a, S->a, n * sizeof(float));
        for (int b = 0; b < H->dim; b++) {
            const size_t nf = (n / S->n[b]) * (size_t)(S->n[b] + 1);
            bad |= !(B->w[b] = malloc(nf * sizeof(float)));
            if (B->w[b])
                memcpy(B->w[b], S->w[b], nf * sizeof(float));
        }
    }
    if (H->alpha == 0 && S->region && S->nregion > 0) {
        B->nregion = S->nregion;
        bad |= !(B->region = malloc(n * sizeof(int32_t)));
        if (B->region)
            memcpy(B->region, S->region, n * sizeof(int32_t));
    }
    return bad ? hv__error(HV_ERR_NOMEM, "OpenCL multigrid: out of memory for the bottom level")
               : HV_OK;
}

static void free_bottom(hv_clmg *m)
{
    if (!m->host_bottom)
        return;
    free(m->hb.a);
    for (int b = 0; b < 3; b++)
        free(m->hb.w[b]);
    free(m->hb.region);
    free(m->hf);
    free(m->hw);
    memset(&m->hb, 0, sizeof m->hb);
    m->hf = NULL;
    m->hw = NULL;
    m->host_bottom = 0;
}

hv_status hv__clmg_create(hv_clmg *m, hv_cl *cl, const mg_hierarchy *H, hv_smoother smoother,
                          int pre, int post, int sym)
{
    memset(m, 0, sizeof *m);
    m->cl = cl;
    m->dim = H->dim;
    m->alpha = H->alpha;
    m->smoother = smoother;
    m->pre = pre;
    m->post = post;
    hv_status st = hv__cl_module_open(cl, HV_CLSOLVE);
    if (!st)
        st = hv__cl_ops_open(cl);
    for (int l = 0; l < H->nlev && !st; l++) {
        m->nlev = l + 1;
        st = upload_level(m, H, l);
    }
    for (int l = 0; sym && l + 1 < m->nlev && !st; l++)
        st = upload_sym(m, H, l);
    m->sym = sym && !st;
    if (!st)
        st = cl->fp64 ? upload_bottom(m, H) : copy_bottom(m, H);
    if (!st)
        st = hv__cl_finish(cl);
    if (st)
        hv__clmg_destroy(m);
    return st;
}

void hv__clmg_destroy(hv_clmg *m)
{
    hv__clagg_destroy(m);
    for (int l = 0; l < m->nlev; l++) {
        hv_clmg_level *L = &m->lv[l];
        hv__cl_free(&L->a);
        for (int b = 0; b < 3; b++)
            hv__cl_free(&L->w[b]);
        hv__cl_free(&L->u[0]);
        hv__cl_free(&L->u[1]);
        hv__cl_free(&L->f);
        hv__cl_free(&L->d);
        hv__cl_free(&L->r);
        hv__cl_free(&L->pn);
    }
    hv__cl_free(&m->bregion);
    hv__cl_free(&m->brinv);
    hv__cl_free(&m->bscr);
    free_bottom(m);
    m->nlev = 0;
}

/* ---------- cycles ---------- */

void hv__clmg_vcycle(hv_clmg *m, int l, int guess, int sym)
{
    hv_clmg_level *L = &m->lv[l];
    if (m->agg && l == 0) {
        /* The fine level smooths as below; the aggregation levels correct. */
        hv__clmg_smooth(m, 0, m->pre, 0, !guess);
        hv__clmg_residual(m, 0, L->u[L->cur], L->f, m->agg->r0);
        hv__clagg_correct(m);
        hv__clmg_smooth(m, 0, m->post, sym, 0);
        return;
    }
    if (l == m->nlev - 1) {
        hv__clmg_bottom(m);
        return;
    }
    hv__clmg_smooth(m, l, m->pre, 0, !guess);
    if (sym && m->sym) {
        hv__clmg_residual(m, l, L->u[L->cur], L->f, L->r);
        hv__clmg_restrict_transpose(m, l);
    } else {
        hv__clmg_restrict_residual(m, l);
    }
    hv__clmg_vcycle(m, l + 1, 0, sym);
    hv__clmg_prolong(m, l);
    hv__clmg_smooth(m, l, m->post, sym, 0);
}

void hv__clmg_fmg(hv_clmg *m)
{
    for (int l = 0; l + 1 < m->nlev; l++)
        hv__clmg_restrict(m, l, m->lv[l].f, m->lv[l + 1].f);
    hv__clmg_bottom(m);
    for (int l = m->nlev - 2; l >= 0; l--) {
        hv_clmg_level *L = &m->lv[l];
        hv__cl_zero(m->cl, L->u[L->cur], L->count * sizeof(float));
        hv__clmg_prolong(m, l);
        hv__clmg_vcycle(m, l, 1, 0);
    }
}
