/*
 * The OpenCL solver backend: the multigrid of mg_backend.c on an OpenCL device.
 *
 * The hierarchy is built on the host exactly as for the CPU backend
 * (mg_setup.c) and uploaded once. Each solve runs on one in-order queue: float
 * V-cycles (Chebyshev by default, RBGS and Jacobi too) inside a double-
 * precision defect-correction loop, or, with solid cells, inside preconditioned
 * CG with a symmetric cycle (docs/METHOD.md, "Multigrid"). CG coefficients live
 * in a small device buffer that later kernels read, so the only host
 * synchronization per cycle or CG iteration is reading back the residual
 * norm. On devices without fp64 the double part (residuals, CG vectors) runs
 * on the host and each cycle moves the fine residual and correction across.
 * With solid cells the coarse levels may be the aggregation hierarchy
 * (cl_agg.c), asked for or, with HV_COARSE_AUTO, after a slow solve (mg_backend.c).
 * The outer iterations are iterate.c's, as on the CPU; this file provides
 * their steps. It also tells HV_BACKEND_AUTO whether there is a device to
 * take (hv__opencl_auto_device). The entries that take the front end's solver
 * and device fields are cl_device.c's.
 */
#include "cl_backend.h"
#include "cl_mg.h"
#include "cl/cl_ops.h"
#include "core/error.h"
#include "solve/iterate.h"

#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

enum { VX, VF, VR, VP, VZ, VQ, NVEC };
enum { S_RR, S_PQ, S_RZ0, S_RZ1, NSLOT };

typedef struct ocl_state {
    const hv_setup *s;
    hv_cl *cl;
    hv_clmg mg;
    mg_hierarchy H;        /* host copy; level 0 kept for the host path only */
    hv_solver_stats stats; /* modelled while the whole hierarchy is at hand */
    int dev64;             /* double defect correction on the device */
    int use_pcg;
    int agg_tried, agg_pending; /* AUTO coarse levels: as mg_backend.c */
    /* device path */
    cl_mem v[NVEC];    /* double fine vectors */
    cl_mem S;          /* double scalars */
    cl_mem ff, uf;     /* float f and u of the float interface, made on first use */
    cl_mem part;       /* double partial sums */
    hv_cl_regions reg; /* Poisson projections */
    /* host path */
    double *h[NVEC]; /* h[VX] and h[VF] point at the caller's arrays during a solve */
    float *stage;    /* fine float vector on its way to or from the device */
    double hs[NSLOT];
} ocl_state;

static void ocl_destroy(void *state)
{
    ocl_state *o = state;
    if (!o)
        return;
    for (int i = 0; i < NVEC; i++)
        hv__cl_free(&o->v[i]);
    hv__cl_free(&o->S);
    hv__cl_free(&o->ff);
    hv__cl_free(&o->uf);
    hv__cl_free(&o->part);
    hv__cl_regions_destroy(&o->reg);
    if (o->mg.cl)
        hv__clmg_destroy(&o->mg);
    hv__mg_hierarchy_free(&o->H);
    for (int i = VR; i < NVEC; i++)
        hv_free(o->h[i]);
    hv_free(o->stage);
    hv__cl_close(&o->cl);
    free(o);
}

static hv_status ocl_create(void **state, const hv_setup *s)
{
    if (s->count > (size_t)INT32_MAX)
        return hv__error(HV_ERR_UNSUPPORTED, "OpenCL backend: %zu cells exceed its 2^31 limit",
                         s->count);
    ocl_state *o = calloc(1, sizeof *o);
    if (!o)
        return hv__error(HV_ERR_NOMEM, "OpenCL backend: out of memory");
    o->s = s;
    o->use_pcg = s->p.solid != NULL;
    hv_status st = hv__cl_open(&o->cl);
    if (st) {
        free(o);
        return st;
    }
    hv_cl *cl = o->cl;
    o->dev64 = cl->fp64;
    if ((st = hv__mg_hierarchy_build(&o->H, s, s->o.smoother == HV_SMOOTH_CHEBYSHEV)) ||
        (st = hv__clmg_create(&o->mg, cl, &o->H, s->o.smoother, s->o.pre_smooth, s->o.post_smooth,
                              o->use_pcg)))
        goto fail;
    if (o->use_pcg && s->o.coarse == HV_COARSE_AGGREGATION) {
        o->agg_tried = 1;
        if ((st = hv__clagg_create(&o->mg, &o->H.lv[0], o->H.dim, o->H.alpha)))
            goto fail;
    }
    hv__mg_model_stats(o->H.lv, o->H.nlev, o->H.dim, o->mg.smoother, o->mg.pre, o->mg.post,
                       o->use_pcg, &o->stats);
    const size_t n = s->count;
    if (o->dev64) {
        size_t g, l, np = hv__cl_range_red(n, &g, &l);
        for (int i = 0; i < NVEC && !st; i++)
            if (i <= VR || o->use_pcg)
                st = hv__cl_alloc(cl, n * sizeof(double), NULL, &o->v[i]);
        if (st || (st = hv__cl_alloc(cl, NSLOT * sizeof(double), NULL, &o->S)) ||
            (st = hv__cl_alloc(cl, np * sizeof(double), NULL, &o->part)))
            goto fail;
        if (s->p.alpha == 0 && (st = hv__cl_regions_create(cl, &o->reg, n, s->region, s->nregion)))
            goto fail;
        hv__mg_hierarchy_free(&o->H);
    } else {
        for (int i = VR; i < NVEC && !st; i++)
            if (i == VR || o->use_pcg)
                if (!(o->h[i] = hv_malloc(n * sizeof(double))))
                    st = hv__error(HV_ERR_NOMEM,
                                   "OpenCL backend: out of memory for %zu-cell vectors", n);
        if (!st && !(o->stage = hv_malloc(n * sizeof(float))))
            st = hv__error(HV_ERR_NOMEM, "OpenCL backend: out of memory for %zu-cell vectors", n);
        if (st)
            goto fail;
        /* the host residual needs level 0 only */
        for (int l = 1; l < o->H.nlev; l++) {
            hv__mg_level_free_coeffs(&o->H.lv[l]);
            free(o->H.lv[l].region);
            o->H.lv[l].region = NULL;
        }
    }
    if ((st = hv__cl_finish(cl)))
        goto fail;
    *state = o;
    return HV_OK;
fail:
    ocl_destroy(o);
    return st;
}

/* ---------- fine-level steps, on the device (fp64) or on the host ---------- */

static void fv_dot(ocl_state *o, int a, int b, int slot);

static void host_project(ocl_state *o, double *v)
{
    if (o->s->p.alpha == 0)
        hv__project_mean(o->s, v);
}

/* R = F - A X on fluid cells; level-0 f = (float)R; slot RR = R.R */
static void fv_residual(ocl_state *o)
{
    hv_cl *cl = o->cl;
    hv_clmg_level *L0 = &o->mg.lv[0];
    if (o->dev64) {
        const double C[4] = {L0->c[0], L0->c[1], L0->c[2], o->mg.alpha};
        hv__cl_args(cl, HV_CLSOLVE, HV_K_FINE_RESIDUAL, "IAmmmmmmmm", L0->N, C, L0->a, L0->w[0],
                    L0->w[1], L0->w[2], o->v[VX], o->v[VF], o->v[VR], L0->f);
        hv__cl_run(cl, HV_CLSOLVE, HV_K_FINE_RESIDUAL, 2, L0->g, L0->l);
        fv_dot(o, VR, VR, S_RR);
        return;
    }
    const mg_level *H0 = &o->H.lv[0];
    const double *x = o->h[VX], *f = o->h[VF];
    double *r = o->h[VR], nn = 0;
    hv__mg_level_apply_d(H0, o->H.dim, o->H.alpha, x, r);
#pragma omp parallel for reduction(+ : nn) schedule(static)
    for (size_t c = 0; c < H0->count; c++) {
        double v = (H0->plain || H0->a[c] != 0.0f) ? f[c] - r[c] : 0.0;
        r[c] = v;
        o->stage[c] = (float)v;
        nn += v * v;
    }
    o->hs[S_RR] = nn;
}

/* Host path: level-0 f <- stage, cycle, stage <- level-0 u. */
static void host_cycle(ocl_state *o, int fmg, int sym)
{
    hv_clmg_level *L0 = &o->mg.lv[0];
    hv__cl_write(o->cl, L0->f, 0, L0->count * sizeof(float), o->stage);
    if (fmg)
        hv__clmg_fmg(&o->mg);
    else
        hv__clmg_vcycle(&o->mg, 0, 0, sym);
    hv__cl_read(o->cl, L0->u[L0->cur], 0, L0->count * sizeof(float), o->stage);
}

/* One cycle on the residual in level-0 f, added to X (then projected). */
static void fv_correct(ocl_state *o, int fmg)
{
    hv_cl *cl = o->cl;
    hv_clmg_level *L0 = &o->mg.lv[0];
    const size_t n = o->s->count;
    if (o->dev64) {
        if (fmg)
            hv__clmg_fmg(&o->mg);
        else
            hv__clmg_vcycle(&o->mg, 0, 0, 0);
        size_t g[1], l[1];
        hv__cl_range1(n, g, l);
        hv__cl_args(cl, HV_CLSOLVE, HV_K_FINE_ADD, "mml", o->v[VX], L0->u[L0->cur], n);
        hv__cl_run(cl, HV_CLSOLVE, HV_K_FINE_ADD, 1, g, l);
        if (o->s->p.alpha == 0)
            hv__cl_project_d(cl, &o->reg, o->v[VX]);
        return;
    }
    host_cycle(o, fmg, 0);
    double *x = o->h[VX];
#pragma omp parallel for schedule(static)
    for (size_t c = 0; c < n; c++)
        x[c] += o->stage[c];
    host_project(o, x);
}

/* Z = M R: a symmetric V-cycle on level-0 f (= (float)R), projected. */
static void fv_precondition(ocl_state *o)
{
    hv_cl *cl = o->cl;
    hv_clmg_level *L0 = &o->mg.lv[0];
    const size_t n = o->s->count;
    if (o->dev64) {
        hv__clmg_vcycle(&o->mg, 0, 0, 1);
        size_t g[1], l[1];
        hv__cl_range1(n, g, l);
        hv__cl_args(cl, HV_CLSOLVE, HV_K_FINE_F2D, "mml", L0->u[L0->cur], o->v[VZ], n);
        hv__cl_run(cl, HV_CLSOLVE, HV_K_FINE_F2D, 1, g, l);
        if (o->s->p.alpha == 0)
            hv__cl_project_d(cl, &o->reg, o->v[VZ]);
        return;
    }
    host_cycle(o, 0, 1);
    double *z = o->h[VZ];
#pragma omp parallel for schedule(static)
    for (size_t c = 0; c < n; c++)
        z[c] = o->stage[c];
    host_project(o, z);
}

static double host_dot(const double *a, const double *b, size_t n)
{
    double s = 0;
#pragma omp parallel for reduction(+ : s) schedule(static)
    for (size_t i = 0; i < n; i++)
        s += a[i] * b[i];
    return s;
}

/* slot = a.b */
static void fv_dot(ocl_state *o, int a, int b, int slot)
{
    const size_t n = o->s->count;
    if (!o->dev64) {
        o->hs[slot] = host_dot(o->h[a], o->h[b], n);
        return;
    }
    size_t g, l, groups = hv__cl_range_red(n, &g, &l);
    hv__cl_dot_parts_d(o->cl, o->v[a], o->v[b], n, o->part);
    hv__cl_finish_sum(o->cl, o->part, groups, o->S, slot);
}

/* Q = A P; slot PQ = P.Q */
static void fv_apply_dot(ocl_state *o)
{
    hv_clmg_level *L0 = &o->mg.lv[0];
    if (o->dev64) {
        const double C[4] = {L0->c[0], L0->c[1], L0->c[2], o->mg.alpha};
        hv__cl_args(o->cl, HV_CLSOLVE, HV_K_FINE_APPLY, "IAmmmmmm", L0->N, C, L0->a, L0->w[0],
                    L0->w[1], L0->w[2], o->v[VP], o->v[VQ]);
        hv__cl_run(o->cl, HV_CLSOLVE, HV_K_FINE_APPLY, 2, L0->g, L0->l);
        fv_dot(o, VP, VQ, S_PQ);
        return;
    }
    hv__mg_level_apply_d(&o->H.lv[0], o->H.dim, o->H.alpha, o->h[VP], o->h[VQ]);
    o->hs[S_PQ] = host_dot(o->h[VP], o->h[VQ], o->s->count);
}

/* al = slot irz / slot PQ (0 unless PQ > 0): X += al P, R -= al Q,
 * level-0 f = (float)R, slot RR = R.R */
static void fv_pcg_update(ocl_state *o, int irz)
{
    const size_t n = o->s->count;
    if (o->dev64) {
        size_t g, l, groups = hv__cl_range_red(n, &g, &l);
        hv__cl_args(o->cl, HV_CLSOLVE, HV_K_FINE_PCG_UPDATE, "mmmmmiimlm", o->v[VX], o->v[VR],
                    o->v[VP], o->v[VQ], o->S, irz, (int)S_PQ, o->mg.lv[0].f, n, o->part);
        hv__cl_run(o->cl, HV_CLSOLVE, HV_K_FINE_PCG_UPDATE, 1, &g, &l);
        hv__cl_finish_sum(o->cl, o->part, groups, o->S, S_RR);
        return;
    }
    double pq = o->hs[S_PQ], al = pq > 0 ? o->hs[irz] / pq : 0.0, nn = 0;
    double *x = o->h[VX], *r = o->h[VR];
    const double *p = o->h[VP], *q = o->h[VQ];
#pragma omp parallel for reduction(+ : nn) schedule(static)
    for (size_t c = 0; c < n; c++) {
        x[c] += al * p[c];
        r[c] -= al * q[c];
        o->stage[c] = (float)r[c];
        nn += r[c] * r[c];
    }
    o->hs[S_RR] = nn;
}

/* P = Z + (slot inew / slot iold) P */
static void fv_xpay(ocl_state *o, int inew, int iold)
{
    const size_t n = o->s->count;
    if (o->dev64) {
        size_t g[1], l[1];
        hv__cl_range1(n, g, l);
        hv__cl_args(o->cl, HV_CLSOLVE, HV_K_FINE_XPAY, "mmmiil", o->v[VP], o->v[VZ], o->S, inew,
                    iold, n);
        hv__cl_run(o->cl, HV_CLSOLVE, HV_K_FINE_XPAY, 1, g, l);
        return;
    }
    double be = o->hs[iold] != 0 ? o->hs[inew] / o->hs[iold] : 0.0, *p = o->h[VP];
    const double *z = o->h[VZ];
#pragma omp parallel for schedule(static)
    for (size_t c = 0; c < n; c++)
        p[c] = z[c] + be * p[c];
}

static void fv_copy(ocl_state *o, int dst, int src)
{
    if (o->dev64)
        hv__cl_copy(o->cl, o->v[src], o->v[dst], o->s->count * sizeof(double));
    else
        memcpy(o->h[dst], o->h[src], o->s->count * sizeof(double));
}

/* Waits for the queue and reads the scalars: the one synchronization of a cycle. */
static hv_status fv_sync(ocl_state *o, double out[NSLOT])
{
    if (o->dev64)
        hv__cl_read_acc(o->cl, o->S, 0, NSLOT, out);
    else
        memcpy(out, o->hs, sizeof o->hs);
    return hv__cl_check(o->cl);
}

/* ---------- the outer iterations' steps (iterate.h) ---------- */

typedef struct ocl_iter {
    ocl_state *o;
    int rz; /* PCG: the slot of r.z (S_RZ0 or S_RZ1, alternating) */
} ocl_iter;

/* R = F - A X; the residual norm read back: the one synchronization. */
static hv_status it_residual(void *ctx, double *norm)
{
    ocl_state *o = ((ocl_iter *)ctx)->o;
    double S[NSLOT];
    fv_residual(o);
    hv_status st = fv_sync(o, S);
    if (st)
        return st;
    *norm = sqrt(S[S_RR]);
    return HV_OK;
}

/* One cycle per correction (the FMG start, as mg_backend.c), then the residual. */
static hv_status it_correct(void *ctx, int it, double rel, hv_solve_info *info, double *norm)
{
    ocl_state *o = ((ocl_iter *)ctx)->o;
    fv_correct(o, it == 0 && !o->s->o.nonzero_guess);
    return it_residual(ctx, norm);
}

static hv_status it_pcg_start(void *ctx, hv_solve_info *info)
{
    ocl_iter *c = ctx;
    fv_precondition(c->o);
    fv_copy(c->o, VP, VZ);
    c->rz = S_RZ0;
    fv_dot(c->o, VR, VZ, c->rz);
    return HV_OK;
}

/* The CG coefficient is formed on the device: one synchronization per step. */
static hv_status it_pcg_step(void *ctx, double *pq, double *norm)
{
    ocl_iter *c = ctx;
    double S[NSLOT];
    fv_apply_dot(c->o);
    fv_pcg_update(c->o, c->rz); /* a no-op when p.q <= 0 */
    hv_status st = fv_sync(c->o, S);
    if (st)
        return st;
    *pq = S[S_PQ];
    *norm = sqrt(S[S_RR]);
    return HV_OK;
}

static hv_status it_pcg_next(void *ctx, hv_solve_info *info)
{
    ocl_iter *c = ctx;
    fv_precondition(c->o);
    int rz_new = c->rz == S_RZ0 ? S_RZ1 : S_RZ0;
    fv_dot(c->o, VR, VZ, rz_new);
    fv_xpay(c->o, rz_new, c->rz);
    c->rz = rz_new;
    return HV_OK;
}

static void it_project(void *ctx)
{
    ocl_state *o = ((ocl_iter *)ctx)->o;
    if (o->s->p.alpha == 0) {
        if (o->dev64)
            hv__cl_project_d(o->cl, &o->reg, o->v[VX]);
        else
            host_project(o, o->h[VX]);
    }
}

static const hv_iter_ops ocl_iter_ops = {"OpenCL ",   it_residual, it_correct, it_pcg_start,
                                         it_pcg_step, it_pcg_next, it_project};

/* The solve once X holds the initial guess and F the right-hand side (on the
 * device or, without fp64, on the host); fn = ||F|| > 0. */
/* Aggregation levels under the device's fine level (cl_agg.c), from the host
 * fine level made again; where they do not fit in memory the geometric ones
 * stay (AUTO asked for them, not the caller). */
static hv_status use_aggregation(ocl_state *o)
{
    o->agg_tried = 1;
    o->agg_pending = 0;
    mg_hierarchy H;
    hv_status st = hv__mg_hierarchy_build(&H, o->s, 0);
    if (!st) {
        st = hv__clagg_create(&o->mg, &H.lv[0], H.dim, H.alpha);
        hv__mg_hierarchy_free(&H);
    }
    return st == HV_ERR_NOMEM ? HV_OK : st;
}

/* HV_COARSE_AUTO after the probe of a solve's first iterations, as in
 * mg_backend.c: aggregation levels when the geometric ones stall. */
static hv_status ocl_decide(void *user, const hv_solve_info *probe, int *changed)
{
    ocl_state *o = user;
    if (!mg_agg_probe_stalls(probe, o->s->o.tol))
        return HV_OK;
    hv_status st = use_aggregation(o);
    *changed = o->mg.agg != NULL;
    return st;
}

static hv_status solve_iterate(ocl_state *o, hv_solve_info *info, double fn)
{
    ocl_iter c = {o, S_RZ0};
    const hv_solver_opts *opts = &o->s->o;
    hv_status st;
    if (o->agg_pending && (st = use_aggregation(o)))
        return st;
    if (!o->use_pcg)
        return hv__iterate_stationary(&ocl_iter_ops, &c, opts, fn, 0, info, NULL);
    if (opts->coarse != HV_COARSE_AUTO || o->agg_tried)
        return hv__iterate_pcg(&ocl_iter_ops, &c, opts, fn, info);
    st = hv__iterate_pcg_probed(&ocl_iter_ops, &c, opts, fn, MG_AGG_PROBE, ocl_decide, o, info);
    if (!st && !o->agg_tried && mg_agg_slow(info->iterations, info->relres))
        o->agg_pending = 1;
    return st;
}

static hv_status ocl_solve(void *state, const double *f, double *u, hv_solve_info *info)
{
    ocl_state *o = state;
    const hv_setup *s = o->s;
    const size_t n = s->count;
    if (!s->o.nonzero_guess)
        memset(u, 0, n * sizeof *u);
    double fn = hv__norm2(s, f);
    if (fn == 0) {
        memset(u, 0, n * sizeof *u);
        hv_info_push(info, 0.0);
        info->reason = HV_STOP_CONVERGED;
        return HV_OK;
    }
    hv_status st;
    if (o->dev64) {
        hv__cl_write(o->cl, o->v[VF], 0, n * sizeof(double), f);
        hv__cl_write(o->cl, o->v[VX], 0, n * sizeof(double), u);
    } else {
        o->h[VX] = u;
        o->h[VF] = (double *)f;
    }
    st = solve_iterate(o, info, fn);
    if (o->dev64) {
        hv__cl_read(o->cl, o->v[VX], 0, n * sizeof(double), u);
        hv_status st2 = hv__cl_check(o->cl);
        if (!st)
            st = st2;
    }
    o->h[VX] = o->h[VF] = NULL;
    if (st == HV_OK && s->p.solid)
        for (size_t c = 0; c < n; c++)
            if (s->p.solid[c])
                u[c] = 0;
    return st;
}

static void ocl_stats(const void *state, hv_solver_stats *st)
{
    const ocl_state *o = state;
    *st = o->stats;
    if (o->mg.agg) {
        st->aggregation_levels = o->mg.agg->nlev;
        st->memory_bytes += o->mg.agg->host->bytes;
    }
}

static hv_status ocl_solve_f(void *state, const float *f, float *u, hv_solve_info *info);

const hv_backend_ops hv__backend_opencl_ops = {"opencl",    ocl_create, ocl_solve,  NULL,
                                               ocl_destroy, ocl_stats,  ocl_solve_f};

/* ---------- the device AUTO may take (backend.h) ---------- */

/* What the one probe of the OpenCL devices found: -1 none usable by AUTO,
 * 0 a CPU device, 1 a GPU. */
static int auto_device = -1;
static pthread_once_t auto_once = PTHREAD_ONCE_INIT;

static void auto_probe(void)
{
    hv_opencl_device d;
    if (hv_opencl_probe(&d) == HV_OK)
        auto_device = d.gpu;
    else
        hv__log(HV_LOG_WARN, "backend auto: %s; solving on the CPU", hv_last_error());
    hv_clear_error();
}

int hv__opencl_auto_device(void)
{
    pthread_once(&auto_once, auto_probe);
    return auto_device;
}

/* ---------- solves of device fields ---------- */

static void cl_convert(hv_cl *cl, int k, cl_mem src, cl_mem dst, size_t n)
{
    size_t g[1], l[1];
    hv__cl_range1(n, g, l);
    hv__cl_args(cl, HV_CLSOLVE, k, "mml", src, dst, n);
    hv__cl_run(cl, HV_CLSOLVE, k, 1, g, l);
}

/* The solve of hv__cl_solver_solve(_d) once v[VF] holds f (zero on solid
 * cells) and v[VX] the guess when the options say there is one; the result is
 * left in v[VX]. As the front end: Poisson right-hand sides projected per
 * region, then ||f|| over the fluid. */
static hv_status device_solve(ocl_state *o, hv_solve_info *info)
{
    const hv_setup *s = o->s;
    hv_cl *cl = o->cl;
    double S[NSLOT];
    if (s->p.alpha == 0)
        hv__cl_project_d(cl, &o->reg, o->v[VF]);
    fv_dot(o, VF, VF, S_RR);
    hv_status st = fv_sync(o, S);
    if (st)
        return st;
    const double fn = sqrt(S[S_RR]);
    if (!isfinite(fn))
        return hv__error(HV_ERR_NUMERIC,
                         "the right-hand side on the device holds NaN or Inf (norm %g)", fn);
    if (fn == 0 || !s->o.nonzero_guess)
        hv__cl_zero(cl, o->v[VX], s->count * sizeof(double));
    if (fn == 0) {
        hv_info_push(info, 0.0);
        info->reason = HV_STOP_CONVERGED;
        return HV_OK;
    }
    return solve_iterate(o, info, fn);
}

/* Whether float fields solve on the device as they are: fp64 there. */
static int device_takes_floats(const ocl_state *o) { return o->dev64; }

/* v = 0 on solid cells (level-0 weight a == 0); nothing on plain grids. */
static void fine_mask(ocl_state *o, cl_mem v)
{
    hv_clmg_level *L0 = &o->mg.lv[0];
    if (L0->plain || !L0->a)
        return;
    size_t g[1], l[1];
    hv__cl_range1(o->s->count, g, l);
    hv__cl_args(o->cl, HV_CLSOLVE, HV_K_FINE_MASK, "mml", v, L0->a, o->s->count);
    hv__cl_run(o->cl, HV_CLSOLVE, HV_K_FINE_MASK, 1, g, l);
}

/* The float fields f and u on the device solved there (device_takes_floats). */
static hv_status solve_floats(ocl_state *o, cl_mem f, cl_mem u, hv_solve_info *info)
{
    const hv_setup *s = o->s;
    hv_cl *cl = o->cl;
    const size_t n = s->count;
    cl_convert(cl, HV_K_FINE_F2D, f, o->v[VF], n);
    fine_mask(o, o->v[VF]); /* the front end's f = 0 on solid cells, on the device */
    if (s->o.nonzero_guess)
        cl_convert(cl, HV_K_FINE_F2D, u, o->v[VX], n);
    hv_status st = device_solve(o, info);
    if (!st) {
        fine_mask(o, o->v[VX]);
        cl_convert(cl, HV_K_FINE_D2F, o->v[VX], u, n);
    }
    hv_status st2 = hv__cl_finish(cl);
    return st ? st : st2;
}

/* The host's float interface: f to the device and u back as floats, once
 * each way (half the bytes of the double way), solved as device fields. */
static hv_status ocl_solve_f(void *state, const float *f, float *u, hv_solve_info *info)
{
    ocl_state *o = state;
    if (!device_takes_floats(o))
        return HV_ERR_UNSUPPORTED;
    hv_cl *cl = o->cl;
    const size_t bytes = o->s->count * sizeof(float);
    hv_status st;
    if ((!o->ff && (st = hv__cl_alloc(cl, bytes, NULL, &o->ff))) ||
        (!o->uf && (st = hv__cl_alloc(cl, bytes, NULL, &o->uf))))
        return st;
    hv__cl_write(cl, o->ff, 0, bytes, f);
    if (o->s->o.nonzero_guess)
        hv__cl_write(cl, o->uf, 0, bytes, u);
    if ((st = solve_floats(o, o->ff, o->uf, info)))
        return st;
    hv__cl_read(cl, o->uf, 0, bytes, u);
    return hv__cl_check(cl);
}

/* ---------- the device-resident solves' steps (cl_backend.h) ---------- */

int hv__clsolve_takes_floats(const void *state) { return device_takes_floats(state); }

hv_cl *hv__clsolve_cl(const void *state) { return ((const ocl_state *)state)->cl; }

const hv_setup *hv__clsolve_setup(const void *state) { return ((const ocl_state *)state)->s; }

hv_status hv__clsolve_floats(void *state, cl_mem f, cl_mem u, hv_solve_info *info)
{
    double t0 = hv_now();
    hv_status st = solve_floats(state, f, u, info);
    info->seconds = hv_now() - t0;
    info->backend = HV_BACKEND_OPENCL;
    return st;
}

hv_status hv__clsolve_doubles(void *state, cl_mem f, cl_mem u, hv_solve_info *info)
{
    ocl_state *o = state;
    if (!o->dev64)
        return hv__error(HV_ERR_UNSUPPORTED,
                         "hv__cl_solver_solve_d: the OpenCL device has no fp64");
    hv_cl *cl = o->cl;
    const size_t bytes = o->s->count * sizeof(double);
    double t0 = hv_now();
    hv__cl_copy(cl, f, o->v[VF], bytes);
    fine_mask(o, o->v[VF]);
    if (o->s->o.nonzero_guess)
        hv__cl_copy(cl, u, o->v[VX], bytes);
    hv_status st = device_solve(o, info);
    if (!st) {
        fine_mask(o, o->v[VX]);
        hv__cl_copy(cl, o->v[VX], u, bytes);
    }
    hv_status st2 = hv__cl_finish(cl);
    info->seconds = hv_now() - t0;
    info->backend = HV_BACKEND_OPENCL;
    return st ? st : st2;
}
