/*
 * The CPU multigrid backend (docs/METHOD.md, "Multigrid"): matrix-free
 * geometric multigrid for (alpha I - beta Laplacian) u = f on cell-centred
 * grids with Neumann walls and solid cells. This file holds the backend's
 * entry points (hv__backend_mg_ops) and its steps of the outer iterations
 * (iterate.h): the double-precision fine-level passes and the V-cycle as
 * preconditioner.
 *
 * Float V-cycles (mg_cycle.c) run inside a double-precision defect
 * correction, so tolerances reach 1e-10 although the hierarchy is float. With
 * solid cells the cycle preconditions CG instead (thin walls can stall plain
 * geometric MG), and the smoother order is then made symmetric. Solves from a
 * zero guess start with full multigrid, which saves one cycle of five for the
 * heat step at 1e-6.
 */
#include "mg_internal.h"
#include "solve/iterate.h"
#include "core/error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

/* Most V-cycles per double correction in the automatic mode (3D; one less in 2D). */
#define MG_AUTO_CYCLES 3

/* y = A x in double on a level (fine residuals, PCG). */
static void level_apply_d(const mg_state *m, const mg_level *L, const double *x, double *y)
{
    hv__mg_level_apply_d(L, m->dim, m->alpha, x, y);
}

/* ---------- backend state ---------- */

/* Frees a level's coefficients, vectors, regions and bottom work. */
static void level_free(mg_level *L)
{
    hv__mg_level_free_coeffs(L);
    hv_free(L->u);
    hv_free(L->f);
    hv_free(L->r);
    hv_free(L->d);
    free(L->region);
    free(L->bwork);
    memset(L, 0, sizeof *L);
}

static void mg_destroy(void *state)
{
    mg_state *m = state;
    if (!m)
        return;
    for (int l = 0; l < m->nlev; l++) {
        hv_free(m->pnorm[l]);
        level_free(&m->lv[l]);
    }
    hv__mg_agg_free(m->agg);
    hv_free(m->rt_work);
    hv_free(m->rd);
    hv_free(m->p);
    free(m->zsum);
    hv_free(m->q);
    free(m);
}

/* Frees the geometric levels under the fine one and what only they use. */
static void drop_geometric(mg_state *m)
{
    for (int l = 0; l < m->nlev; l++) {
        hv_free(m->pnorm[l]);
        m->pnorm[l] = NULL;
    }
    hv_free(m->rt_work);
    m->rt_work = NULL;
    for (int l = 1; l < m->nlev; l++)
        level_free(&m->lv[l]);
    m->nlev = 1;
}

/* Coarse levels by smoothed aggregation under the fine level (mg_agg.h), in
 * place of the geometric ones; where aggregation does not apply (or, when
 * `soft`, does not fit in memory) the geometric levels stay. */
static hv_status use_aggregation(mg_state *m, int soft)
{
    m->agg_tried = 1;
    if (!m->use_pcg || (m->nlev < 2 && !m->fine_only))
        return HV_OK;
    hv_status st = hv__mg_agg_build(&m->agg, &m->lv[0], m->dim, m->alpha);
    if (st == HV_ERR_NOMEM && soft)
        return HV_OK;
    if (st || !m->agg)
        return st;
    hv__mg_agg_pack(m->agg);
    drop_geometric(m);
    hv__mg_model_stats_cpu(m->lv, m->nlev, m->dim, m->smoother, m->pre, m->post, m->use_pcg,
                           &m->model);
    m->model.memory_bytes += m->agg->bytes;
    return HV_OK;
}

/* The geometric levels (mg_setup.c), at most max_levels of them, with their
 * work vectors, PCG's prolongation weights and restriction work, and, when
 * they go all the way down, the bottom's CG work. */
static hv_status geometric_levels(mg_state *m, const hv_setup *s, int max_levels)
{
    mg_hierarchy H;
    hv_status st = hv__mg_hierarchy_build_to(&H, s, m->smoother == HV_SMOOTH_CHEBYSHEV, max_levels);
    if (st)
        return st;
    m->nlev = H.nlev;
    m->fine_only = max_levels == 1;
    memcpy(m->lv, H.lv, (size_t)H.nlev * sizeof H.lv[0]);
    for (int l = 0; l < m->nlev; l++) {
        mg_level *L = &m->lv[l];
        L->u = hv_calloc(L->count, sizeof(float));
        L->f = hv_calloc(L->count, sizeof(float));
        L->r = hv_calloc(L->count, sizeof(float));
        if (m->smoother != HV_SMOOTH_RBGS)
            L->d = hv_calloc(L->count, sizeof(float));
        if (!L->u || !L->f || !L->r || (m->smoother != HV_SMOOTH_RBGS && !L->d))
            return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for level %d (%zu cells)", l,
                             L->count);
    }
    /* PCG restricts with P^T; renormalized prolongation needs its weight sums. */
    for (int l = 0; m->use_pcg && l + 1 < m->nlev; l++) {
        const mg_level *F = &m->lv[l], *C = &m->lv[l + 1];
        if (C->plain)
            continue;
        float *pn = m->pnorm[l] = hv_malloc(F->count * sizeof(float));
        if (!pn)
            return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for level %d weights", l);
        hv__mg_prolong_norm(F, C, pn);
    }
    if (m->use_pcg && m->nlev > 1) {
        size_t per = 0;
        for (int l = 0; l + 1 < m->nlev; l++) {
            size_t w = mg_restrict_transpose_work(&m->lv[l], &m->lv[l + 1]);
            per = w > per ? w : per;
        }
        m->rt_threads = 1;
#ifdef _OPENMP
        m->rt_threads = omp_get_max_threads();
#endif
        if (!(m->rt_work = hv_malloc((size_t)m->rt_threads * per * sizeof(float))))
            return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for the restriction's work");
    }
    if (m->fine_only)
        return HV_OK;
    mg_level *L = &m->lv[m->nlev - 1];
    if (!(L->bwork = malloc(MG_BOTTOM_WORK * L->count * sizeof(double))))
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for the bottom solver");
    return HV_OK;
}

/* The outer iterations' work on the fine grid: double residuals, and PCG's
 * direction, product and per-region sums. */
static hv_status fine_work(mg_state *m, const hv_setup *s)
{
    size_t n0 = s->count;
    m->rd = hv_malloc(n0 * sizeof(double));
    if (m->use_pcg) {
        m->p = hv_malloc(n0 * sizeof(float));
        m->zsum_threads = 1;
#ifdef _OPENMP
        m->zsum_threads = omp_get_max_threads();
#endif
        m->zsum_per = ((size_t)3 * (s->region ? s->nregion : 1) + 1 + 7) & ~(size_t)7;
        m->zsum =
            m->alpha == 0 ? calloc(m->zsum_per * (size_t)m->zsum_threads, sizeof(double)) : NULL;
        m->q = hv_malloc(n0 * sizeof(double));
    }
    if (!m->rd || (m->use_pcg && (!m->p || (m->alpha == 0 && !m->zsum) || !m->q)))
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory for %zu-cell work vectors", n0);
    return HV_OK;
}

/* With aggregation asked for, the geometric levels below the fine one are
 * built only where aggregation does not apply. */
static hv_status mg_create(void **state, const hv_setup *s)
{
    mg_state *m = calloc(1, sizeof *m);
    if (!m)
        return hv__error(HV_ERR_NOMEM, "multigrid: out of memory");
    m->s = s;
    m->dim = s->p.dim;
    m->alpha = s->p.alpha;
    m->smoother = s->o.smoother;
    m->pre = s->o.pre_smooth;
    m->post = s->o.post_smooth;
    m->use_pcg = s->p.solid != NULL;
    m->stat_masked = m->use_pcg && m->alpha > 0 && m->smoother == HV_SMOOTH_RBGS;
    const int agg_first =
        s->o.coarse == HV_COARSE_AGGREGATION && m->use_pcg && s->count > MG_BOTTOM_CELLS;
    hv_status st = geometric_levels(m, s, agg_first ? 1 : MG_MAX_LEVELS);
    if (!st)
        st = fine_work(m, s);
    if (st)
        goto fail;
    hv__mg_model_stats_cpu(m->lv, m->nlev, m->dim, m->smoother, m->pre, m->post,
                           m->use_pcg && !m->stat_masked, &m->model);
    if (s->o.coarse == HV_COARSE_AGGREGATION && (st = use_aggregation(m, 0)))
        goto fail;
    if (m->fine_only && !m->agg) {
        level_free(&m->lv[0]);
        if ((st = geometric_levels(m, s, MG_MAX_LEVELS)))
            goto fail;
        hv__mg_model_stats_cpu(m->lv, m->nlev, m->dim, m->smoother, m->pre, m->post,
                               m->use_pcg && !m->stat_masked, &m->model);
    }
    *state = m;
    return HV_OK;
fail:
    mg_destroy(m);
    return st;
}

/* ---------- fine-level passes in double ---------- */

/* Level-0 float right-hand side = f - A x computed in double; returns its norm.
 * Weighted (masked) levels also keep the double residual in rd for PCG. */
static double fine_residual(const mg_state *m, const double *f, const double *x)
{
    const mg_level *L = &m->lv[0];
    double *rd = m->rd;
    double nn = 0;
    if (L->plain) {
        /* One pass: the residual in double, stored as the cycle's float input. */
#pragma omp parallel for collapse(2) reduction(+ : nn) schedule(static) if (L->count > MG_PAR_MIN)
        for (int k = 0; k < L->n[2]; k++)
            for (int j = 0; j < L->n[1]; j++) {
                mg_plain_row R = mg_plain_row_at(m, L, j, k);
                MG_PLAIN_ROW_RESIDUAL(double, float, L, R, x, f, L->f + R.base, nn);
            }
        return sqrt(nn);
    }
    level_apply_d(m, L, x, rd);
#pragma omp parallel for reduction(+ : nn) schedule(static) if (L->count > MG_PAR_MIN)
    for (size_t c = 0; c < L->count; c++) {
        double r = (L->plain || L->a[c] != 0.0f) ? f[c] - rd[c] : 0.0;
        rd[c] = r;
        L->f[c] = (float)r;
        nn += r * r;
    }
    return sqrt(nn);
}

/* One row of the fused outer pass: xo = x + e (x == NULL: a zero x), and the
 * cycle's next float right-hand side fo = f - A xo in double; returns the sum
 * of squares of the residual. Neighbour values are formed on the fly from x and
 * e, so xo may not alias x. */
#define UPDATE_ROW_BODY(HASX)                                                                       \
    do {                                                                                            \
        const int nx = L->n[0];                                                                     \
        const double *f_ = f + R.base;                                                              \
        const float *e_ = e + R.base;                                                               \
        double *xo_ = xo + R.base;                                                                  \
        float *fo_ = fo + R.base;                                                                   \
        const double cx = L->c[0], cy = L->c[1], cz = L->c[2];                                      \
        const double wym = R.wym, wyp = R.wyp, wzm = R.wzm, wzp = R.wzp;                            \
        const ptrdiff_t ym = R.ym, yp = R.yp, zm = R.zm, zp = R.zp;                                 \
        const double din = R.dyz + 2 * cx;                                                          \
        double rb[MG_ROW_BUF];                                                                      \
        double acc[8] = {0, 0, 0, 0, 0, 0, 0, 0};                                                   \
        /* the interior in chunks of MG_ROW_BUF: the residual per cell into rb without            \
         * branches (vectorizes), then its squares in 8 partial sums (a serial sum does not) */ \
        for (int c0 = 1; c0 < nx - 1; c0 += MG_ROW_BUF) {                                           \
            const int c1 = nx - 1 - c0 < MG_ROW_BUF ? nx - 1 : c0 + MG_ROW_BUF;                     \
            for (int i = c0; i < c1; i++) {                                                         \
                double v = XE(i);                                                                   \
                double s = cy * (wym * XE(i + ym) + wyp * XE(i + yp)) +                             \
                           cz * (wzm * XE(i + zm) + wzp * XE(i + zp)) +                             \
                           cx * (XE(i - 1) + XE(i + 1));                                            \
                double r = f_[i] - (din * v - s);                                                   \
                xo_[i] = v;                                                                         \
                fo_[i] = (float)r;                                                                  \
                rb[i - c0] = r;                                                                     \
            }                                                                                       \
            int q0 = 0;                                                                             \
            for (; q0 + 8 <= c1 - c0; q0 += 8)                                                      \
                for (int q = 0; q < 8; q++)                                                         \
                    acc[q] += rb[q0 + q] * rb[q0 + q];                                              \
            for (; q0 < c1 - c0; q0++)                                                              \
                acc[0] += rb[q0] * rb[q0];                                                          \
        }                                                                                           \
        for (int i = 0; i < nx; i += (nx > 1 ? nx - 1 : 1)) {                                       \
            double v = XE(i);                                                                       \
            double s = cy * (wym * XE(i + ym) + wyp * XE(i + yp)) +                                 \
                       cz * (wzm * XE(i + zm) + wzp * XE(i + zp));                                  \
            double d = R.dyz;                                                                       \
            if (i > 0) {                                                                            \
                s += cx * XE(i - 1);                                                                \
                d += cx;                                                                            \
            }                                                                                       \
            if (i < nx - 1) {                                                                       \
                s += cx * XE(i + 1);                                                                \
                d += cx;                                                                            \
            }                                                                                       \
            double r = f_[i] - (d * v - s);                                                         \
            xo_[i] = v;                                                                             \
            fo_[i] = (float)r;                                                                      \
            acc[1] += r * r;                                                                        \
        }                                                                                           \
        return ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]));   \
    } while (0)

MG_KERNEL static double update_row_x(const mg_level *L, mg_plain_row R, const double *x,
                                     const float *e, const double *f, double *xo, float *fo)
{
    const double *x_ = x + R.base;
#define XE(p) (x_[p] + (double)e_[p])
    UPDATE_ROW_BODY(1);
#undef XE
}

MG_KERNEL static double update_row_0(const mg_level *L, mg_plain_row R, const double *x,
                                     const float *e, const double *f, double *xo, float *fo)
{
#define XE(p) ((double)e_[p])
    (void)x;
    UPDATE_ROW_BODY(0);
#undef XE
}

/* Weighted fine level (solid cells): xo = x + e on fluid cells and 0 on solid
 * ones, then row by row level 0's f = f - A xo (0 on solid cells), the row of
 * A xo in a buffer on the stack (rows of more than MG_ROW_BUF cells in q, which
 * the stationary solve leaves free). Returns ||f - A xo||. */
static double update_residual_masked(const mg_state *m, const double *x, const double *f,
                                     double *xo)
{
    const mg_level *L = &m->lv[0];
    const float *e = L->u, *a = L->a;
    float *fo = L->f;
#pragma omp parallel for schedule(static) if (L->count > MG_PAR_MIN)
    for (size_t c = 0; c < L->count; c++)
        xo[c] = a[c] != 0.0f ? (x ? x[c] : 0.0) + e[c] : 0.0;
    double nn = 0;
#pragma omp parallel for collapse(2) reduction(+ : nn) schedule(static) if (L->count > MG_PAR_MIN)
    for (int k = 0; k < L->n[2]; k++)
        for (int j = 0; j < L->n[1]; j++) {
            const size_t b = L->sy * (size_t)j + L->sz * (size_t)k;
            double buf[MG_ROW_BUF], *y = L->n[0] <= MG_ROW_BUF ? buf : m->q + b;
            hv__mg_level_apply_row_d(L, m->dim, m->alpha, xo, y, j, k);
            for (int i = 0; i < L->n[0]; i++) {
                const double r = a[b + i] != 0.0f ? f[b + i] - y[i] : 0.0;
                fo[b + i] = (float)r;
                nn += r * r;
            }
        }
    return sqrt(nn);
}

/* Fine level, one pass where it is plain: xo = x + e with e the cycle's
 * correction (level 0's u), and level 0's f = f - A xo (double arithmetic,
 * float storage). Returns ||f - A xo||. */
static double update_residual(const mg_state *m, const double *x, const double *f, double *xo)
{
    const mg_level *L = &m->lv[0];
    if (!L->plain)
        return update_residual_masked(m, x, f, xo);
    const float *e = L->u;
    float *fo = L->f;
    double nn = 0;
#pragma omp parallel for collapse(2) reduction(+ : nn) schedule(static) if (L->count > MG_PAR_MIN)
    for (int k = 0; k < L->n[2]; k++)
        for (int j = 0; j < L->n[1]; j++) {
            mg_plain_row R = mg_plain_row_at(m, L, j, k);
            nn += x ? update_row_x(L, R, x, e, f, xo, fo) : update_row_0(L, R, x, e, f, xo, fo);
        }
    return sqrt(nn);
}

/* Level 0's f = (float) f, returning ||f|| (the residual of a zero guess). */
static double load_rhs(const mg_state *m, const double *f)
{
    const mg_level *L = &m->lv[0];
    double nn = 0;
#pragma omp parallel for reduction(+ : nn) schedule(static) if (L->count > MG_PAR_MIN)
    for (size_t c = 0; c < L->count; c++) {
        L->f[c] = (float)f[c];
        nn += f[c] * f[c];
    }
    return sqrt(nn);
}

/* z = M r: one symmetric V-cycle from zero on level 0's f, which holds r in
 * float (fine_residual and it_pcg_step leave it there); z is left in level
 * 0's u (Poisson: before its projection, pcg_direction's). */
static void precondition(mg_state *m) { hv__mg_vcycle(m, 0, 0, 1); }

/* ---------- the outer iterations' steps (iterate.h) ---------- */

/* A solve's place in the outer iterations. The stationary iterate alternates
 * between u and the work vector rd (the fused update reads one and writes the
 * other). */
typedef struct mg_iter {
    mg_state *m;
    const double *f;
    double fn;       /* ||f|| */
    double *x, *alt; /* the iterate; stationary: the other buffer */
    int have_x;      /* x holds an iterate; else it is zero and r = f */
    int fixed;       /* stationary: V-cycles per correction, 0: automatic */
    double rho;      /* stationary: per-cycle factor measured so far */
    double rz;       /* PCG: r.z */
} mg_iter;

static hv_status it_residual(void *ctx, double *norm)
{
    mg_iter *c = ctx;
    *norm = c->have_x ? fine_residual(c->m, c->f, c->x) : c->fn;
    return HV_OK;
}

/* Cycles per correction: fixed, or (auto, RBGS) as many as the per-cycle
 * factor measured so far says the tolerance needs, at most 3 in 3D and 2 in
 * 2D. Float cycles in a row reduce the residual as much as corrections do
 * until about 1e-4 per correction (measured: Poisson 256^3 gives the same
 * residuals either way; 2048^2 Poisson drifts after 3), so the double pass
 * runs once per few cycles. Chebyshev and Jacobi keep one cycle per
 * iteration, cycle for cycle like the OpenCL backend. The correction and the
 * next residual are one pass (update_residual). */
static hv_status it_correct(void *ctx, int it, double rel, hv_solve_info *info, double *norm)
{
    mg_iter *c = ctx;
    mg_state *m = c->m;
    const hv_setup *s = m->s;
    const size_t n = s->count;
    int nc = c->fixed;
    if (!nc) {
        /* 25% margin: the first factor includes the better FMG cycle */
        double need = ceil(1.25 * log(s->o.tol / rel) / log(c->rho));
        int mx = MG_AUTO_CYCLES - (m->dim == 2);
        nc = !(need > 1) ? 1 : need > mx ? mx : (int)need;
    }
    for (int q = 0; q < nc; q++) {
        if (q == 0 && it == 0 && !s->o.nonzero_guess) {
            hv__mg_fmg(m);
            continue;
        }
        double t0 = hv_now();
        hv__mg_vcycle(m, 0, q > 0, 0);
        info->cycle_seconds += hv_now() - t0;
        info->cycles_timed++;
        /* a cycle from a guess sweeps u instead of setting it: + 4 B per cell */
        info->cycle_bytes += m->model.bytes_per_cycle + (q > 0 ? 4.0 * (double)n : 0.0);
    }
    info->cycles += nc;
    *norm = update_residual(m, c->have_x ? c->x : NULL, c->f, c->alt);
    double r = *norm / c->fn;
    if (r > 0 && rel > 0) {
        c->rho = pow(r / rel, 1.0 / nc);
        c->rho = c->rho < 1e-3 ? 1e-3 : c->rho > 0.9 ? 0.9 : c->rho;
    }
    double *t = c->x;
    c->x = c->alt;
    c->alt = t;
    c->have_x = 1;
    return HV_OK;
}

static int thread_id(void)
{
#ifdef _OPENMP
    return omp_get_thread_num();
#else
    return 0;
#endif
}

/* Poisson: z = level 0's u made mean-free in each region (as hv__project_mean),
 * never stored: one pass sums u and r per region and r.u, per thread, added
 * in thread order (the same on every run). Leaves the regions' means in
 * zsum[1 + 3 g] and returns r.z = r.u - sum_g mean_g (sum of r over g). */
static double poisson_rz(mg_state *m)
{
    const hv_setup *s = m->s;
    const float *u = m->lv[0].u;
    const double *r = m->rd;
    const int32_t *reg = s->region;
    const int ng = reg ? s->nregion : 1;
    const size_t per = m->zsum_per;
    double *acc = m->zsum;
    memset(acc, 0, per * (size_t)m->zsum_threads * sizeof *acc);
#pragma omp parallel num_threads(m->zsum_threads) if (s->count > MG_PAR_MIN)
    {
        double *a = acc + per * (size_t)thread_id();
        if (ng == 1) { /* in registers: no store per cell */
            double ru = 0, su = 0, sr = 0, cnt = 0;
#pragma omp for schedule(static)
            for (size_t c = 0; c < s->count; c++) {
                const double in = !reg || reg[c] >= 0;
                ru += in * r[c] * (double)u[c];
                su += in * (double)u[c];
                sr += in * r[c];
                cnt += in;
            }
            a[0] = ru;
            a[1] = su;
            a[2] = sr;
            a[3] = cnt;
        } else {
#pragma omp for schedule(static)
            for (size_t c = 0; c < s->count; c++) {
                int g = reg[c];
                if (g < 0)
                    continue;
                a[0] += r[c] * (double)u[c];
                a[1 + 3 * g] += u[c];
                a[2 + 3 * g] += r[c];
                a[3 + 3 * g] += 1;
            }
        }
    }
    for (int t = 1; t < m->zsum_threads; t++)
        for (size_t q = 0; q < 1 + 3 * (size_t)ng; q++)
            acc[q] += acc[per * (size_t)t + q];
    double rz = acc[0];
    for (int g = 0; g < ng; g++) {
        double mean = acc[3 + 3 * g] > 0 ? acc[1 + 3 * g] / acc[3 + 3 * g] : 0.0;
        acc[1 + 3 * g] = mean;
        rz -= mean * acc[2 + 3 * g];
    }
    return rz;
}

/* PCG's next direction from z = M r (precondition): p = z + be p, with
 * be = (r.z) / rz and rz = r.z after; be = 0 on the first (p = z). z is
 * level 0's float u, for Poisson less its region's mean; two passes (r.z,
 * then p). */
static void pcg_direction(mg_iter *c, int first)
{
    mg_state *m = c->m;
    const size_t n = m->s->count;
    const double *r = m->rd;
    const float *z = m->lv[0].u;
    float *p = m->p;
    double rz2 = 0, be;
    if (m->alpha == 0) {
        const int32_t *reg = m->s->region;
        const double *mean = m->zsum + 1;
        rz2 = poisson_rz(m);
        be = first ? 0.0 : rz2 / c->rz;
#pragma omp parallel for schedule(static) if (n > MG_PAR_MIN)
        for (size_t i = 0; i < n; i++) {
            int g = reg ? reg[i] : 0;
            double zi = g >= 0 ? (double)z[i] - mean[3 * (g > 0 ? g : 0)] : 0.0;
            p[i] = (float)(first ? zi : zi + be * p[i]);
        }
    } else {
#pragma omp parallel for reduction(+ : rz2) schedule(static) if (n > MG_PAR_MIN)
        for (size_t i = 0; i < n; i++)
            rz2 += r[i] * (double)z[i];
        be = first ? 0.0 : rz2 / c->rz;
#pragma omp parallel for schedule(static) if (n > MG_PAR_MIN)
        for (size_t i = 0; i < n; i++)
            p[i] = first ? z[i] : (float)((double)z[i] + be * p[i]);
    }
    c->rz = rz2;
}

static hv_status it_pcg_start(void *ctx, hv_solve_info *info)
{
    mg_iter *c = ctx;
    precondition(c->m);
    info->cycles = 1;
    pcg_direction(c, 1);
    return HV_OK;
}

/* q = A p and p.q on the fine level, row by row while the row is in cache. */
static double pcg_pq(const mg_state *m)
{
    const mg_level *L = &m->lv[0];
    const int nx = L->n[0];
    double s = 0;
#pragma omp parallel for collapse(2) reduction(+ : s) schedule(static) if (L->count > MG_PAR_MIN)
    for (int k = 0; k < L->n[2]; k++)
        for (int j = 0; j < L->n[1]; j++) {
            const size_t b = L->sy * (size_t)j + L->sz * (size_t)k;
            const float *p = m->p + b;
            double *q = m->q + b;
            hv__mg_level_apply_row_f(L, m->dim, m->alpha, m->p, q, j, k);
            double part[4] = {0, 0, 0, 0}; /* partial sums: the loop vectorizes */
            int i = 0;
            for (; i + 4 <= nx; i += 4)
                for (int e = 0; e < 4; e++)
                    part[e] += (double)p[i + e] * q[i + e];
            for (; i < nx; i++)
                part[0] += (double)p[i] * q[i];
            s += (part[0] + part[1]) + (part[2] + part[3]);
        }
    return s;
}

/* x += al p, r -= al q, level 0's f = (float) r (the next cycle's input);
 * returns ||r||^2. */
static double pcg_update(const mg_state *m, double *x, double al)
{
    const size_t n = m->s->count;
    const float *p = m->p;
    const double *q = m->q;
    double *r = m->rd;
    float *f = m->lv[0].f;
    double nn = 0;
#pragma omp parallel for reduction(+ : nn) schedule(static) if (n > MG_PAR_MIN)
    for (size_t i = 0; i < n; i++) {
        x[i] += al * (double)p[i];
        r[i] -= al * q[i];
        f[i] = (float)r[i];
        nn += r[i] * r[i];
    }
    return nn;
}

/* q = A p and *pq = p.q; when positive, x += a p, r -= a q with a = rz / pq,
 * level 0's f = (float) r, and ||r||. */
static hv_status it_pcg_step(void *ctx, double *pq_out, double *norm)
{
    mg_iter *c = ctx;
    mg_state *m = c->m;
    double pq = pcg_pq(m);
    *pq_out = pq;
    if (!(pq > 0))
        return HV_OK;
    *norm = sqrt(pcg_update(m, c->x, c->rz / pq));
    return HV_OK;
}

static hv_status it_pcg_next(void *ctx, hv_solve_info *info)
{
    mg_iter *c = ctx;
    precondition(c->m);
    info->cycles++;
    pcg_direction(c, 0);
    return HV_OK;
}

static void it_project(void *ctx)
{
    mg_iter *c = ctx;
    if (c->m->alpha == 0)
        hv__project_mean(c->m->s, c->x);
}

static const hv_iter_ops mg_iter_ops = {"",          it_residual, it_correct, it_pcg_start,
                                        it_pcg_step, it_pcg_next, it_project};

/* ---------- solves ---------- */

/* Defect correction: on a plain fine level, where Poisson's mean, to which
 * the residual is blind, is removed once at the end; and for heat steps with
 * solid cells while each cycle reduces the residual by MG_STAT_SLOW or more
 * (slow > 0: else *slowed is set and u holds the iterate reached). */
static hv_status mg_solve_stationary(mg_state *m, const double *f, double *u, hv_solve_info *info,
                                     double slow, int *slowed)
{
    const hv_setup *s = m->s;
    const size_t n = s->count;
    mg_iter c = {.m = m, .f = f, .x = u, .alt = m->rd, .have_x = s->o.nonzero_guess, .rho = 0.1};
    c.fn = c.have_x ? hv__norm2(s, f) : load_rhs(m, f);
    if (c.fn == 0) {
        memset(u, 0, n * sizeof *u);
        hv_info_push(info, 0.0);
        info->reason = HV_STOP_CONVERGED;
        return HV_OK;
    }
    c.fixed = s->o.cycles_per_iteration;
    if (!c.fixed && m->smoother != HV_SMOOTH_RBGS)
        c.fixed = 1;
    hv_status st = hv__iterate_stationary(&mg_iter_ops, &c, &s->o, c.fn, slow, info, slowed);
    double *cur = c.x;
    if (!c.have_x) { /* converged before any cycle: the zero guess */
        memset(u, 0, n * sizeof *u);
        return st;
    }
    if (m->alpha == 0) {
        double sum = 0;
#pragma omp parallel for reduction(+ : sum) schedule(static) if (n > MG_PAR_MIN)
        for (size_t i = 0; i < n; i++)
            sum += cur[i];
        double mean = sum / (double)n;
#pragma omp parallel for schedule(static) if (n > MG_PAR_MIN)
        for (size_t i = 0; i < n; i++)
            u[i] = cur[i] - mean;
    } else if (cur != u) {
#pragma omp parallel for schedule(static) if (n > MG_PAR_MIN)
        for (size_t i = 0; i < n; i++)
            u[i] = cur[i];
    }
    return st;
}

/* Preconditioned CG in double with a symmetric V-cycle (masked grids). */
static hv_status mg_solve_pcg(mg_state *m, const double *f, double *u, hv_solve_info *info,
                              double fn)
{
    mg_iter c = {.m = m, .f = f, .fn = fn, .x = u, .have_x = 1};
    return hv__iterate_pcg(&mg_iter_ops, &c, &m->s->o, fn, info);
}

/* HV_COARSE_AUTO after the probe of a solve's first iterations: aggregation
 * levels when the geometric ones stall (mg_agg_stalls). */
static hv_status mg_decide(void *user, const hv_solve_info *probe, int *changed)
{
    mg_state *m = user;
    if (!mg_agg_probe_stalls(probe, m->s->o.tol))
        return HV_OK;
    hv_status st = use_aggregation(m, 1);
    *changed = m->agg != NULL;
    return st;
}

/* HV_COARSE_AUTO before any aggregation: a slow solve pays the set-up once,
 * after MG_AGG_PROBE iterations, instead of finishing on the levels that lose
 * the walls; a stall that shows only later asks for it before the next solve. */
static hv_status mg_solve_probed(mg_state *m, const double *f, double *u, hv_solve_info *info,
                                 double fn)
{
    mg_iter c = {.m = m, .f = f, .fn = fn, .x = u, .have_x = 1};
    hv_status st =
        hv__iterate_pcg_probed(&mg_iter_ops, &c, &m->s->o, fn, MG_AGG_PROBE, mg_decide, m, info);
    if (!st && !m->agg_tried && mg_agg_slow(info->iterations, info->relres))
        m->agg_pending = 1;
    return st;
}

/* A heat step with solid cells: defect correction, which needs no CG vectors
 * and with the identity term converges as fast as on a plain box (t = 4h^2:
 * about 0.05 per cycle); PCG from where it got when a cycle is slower than
 * MG_STAT_SLOW. When that happens within the first two corrections (the first
 * starts with the FMG cycle) the operator is to blame (large t, where the heat
 * step nears Poisson and the geometric levels lose the walls) and every later
 * solve starts with PCG; later (what the cycle reduces worst left of a
 * right-hand side) it hands over only the solve it is in. info counts both
 * parts. */
static hv_status mg_solve_masked_heat(mg_state *m, const double *f, double *u, hv_solve_info *info)
{
    const hv_setup *s = m->s;
    int slowed = 0;
    hv_status st = mg_solve_stationary(m, f, u, info, MG_STAT_SLOW, &slowed);
    if (st || !slowed)
        return st;
    if (info->iterations <= 2) {
        m->stat_masked = 0;
        hv__mg_model_stats_cpu(m->lv, m->nlev, m->dim, m->smoother, m->pre, m->post, 1, &m->model);
    }
    hv_solve_info p = {0};
    st = mg_solve_pcg(m, f, u, &p, hv__norm2(s, f));
    if (st)
        return st;
    /* AUTO: a stalling solve asks for aggregation levels, as in mg_solve (the
     * corrections' cycles counted as iterations) */
    if (s->o.coarse == HV_COARSE_AUTO && !m->agg_tried &&
        mg_agg_slow(info->cycles + p.iterations, p.relres))
        m->agg_pending = 1;
    hv__info_append(info, &p);
    return HV_OK;
}

/* u = 0 on solid cells (a guess that converged as it was may hold values there). */
static void zero_solid(const hv_setup *s, double *u)
{
    for (size_t c = 0; c < s->count; c++)
        if (s->p.solid[c])
            u[c] = 0;
}

static hv_status mg_solve(void *state, const double *f, double *u, hv_solve_info *info)
{
    mg_state *m = state;
    const hv_setup *s = m->s;
    hv_status st0;
    if (!m->use_pcg)
        return mg_solve_stationary(m, f, u, info, 0, NULL);
    if (m->stat_masked && !m->agg && !m->agg_pending) {
        hv_status st = mg_solve_masked_heat(m, f, u, info);
        if (st == HV_OK)
            zero_solid(s, u);
        return st;
    }
    if (!s->o.nonzero_guess)
        memset(u, 0, s->count * sizeof *u);
    double fn = hv__norm2(s, f);
    if (fn == 0) {
        memset(u, 0, s->count * sizeof *u);
        hv_info_push(info, 0.0);
        info->reason = HV_STOP_CONVERGED;
        return HV_OK;
    }
    if (m->agg_pending && (st0 = use_aggregation(m, 1)))
        return st0;
    m->agg_pending = 0;
    hv_status st = s->o.coarse == HV_COARSE_AUTO && !m->agg_tried && m->nlev > 1
                       ? mg_solve_probed(m, f, u, info, fn)
                       : mg_solve_pcg(m, f, u, info, fn);
    if (st == HV_OK && s->p.solid)
        zero_solid(s, u);
    return st;
}

static void mg_stats(const void *state, hv_solver_stats *st)
{
    const mg_state *m = state;
    *st = m->model;
    st->aggregation_levels = m->agg ? m->agg->nlev : 0;
}

const hv_backend_ops hv__backend_mg_ops = {"mg",       mg_create, mg_solve, NULL,
                                           mg_destroy, mg_stats,  NULL};
