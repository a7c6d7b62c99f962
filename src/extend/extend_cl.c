/*
 * The extension off a level set (extend_vhm.c) with its fields on one OpenCL
 * device (kernels/extend.cl): weights, the choice of where each cell is read,
 * the right-hand sides, every solve (device-resident, hv__cl_solver_solve(_d)),
 * the closest-point evaluation and the later levels for the cells the first
 * did not reach. Same boxes, levels, trust bound and rules as the host path's
 * box solve, so both give the same fields to the solves' tolerance. The host
 * reads back the counters once per call (source cells, boxes, NaN checks),
 * per level the weights' norm, the residual norms and the level's counts, and
 * the outputs once. Its kernels are registered and built here (hv_cl_module,
 * src/cl/cl_core.h).
 */
#include "extend_cl.h"
#include "core/error.h"
#include "cl/cl_ops.h"
#include "solve/cl/solve_cl.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

extern const char hv__kernel_extend[]; /* kernels/extend.cl, embedded by the Makefile */

static const char *const extend_sources[] = {hv__kernel_extend, NULL};
enum { EK_SETUP, EK_CHECK, EK_RHS, EK_SCATTER, EK_EVAL };
static const char *const extend_kernels[] = {"ext_setup",   "ext_check", "ext_rhs",
                                             "ext_scatter", "ext_eval",  NULL};
static const hv_cl_module extend_module = {"extend", extend_sources, extend_kernels, 0, 0};

/* Counters on the device (int32), as EXT_* in kernels/extend.cl. */
enum {
    K_NSRC = 0,
    K_NPEND = 1,
    K_WBOX = 2, /* lo xyz, hi xyz */
    K_RBOX = 8,
    K_LEFT = 14,
    K_CP = 15,
    K_RATIO = 16,
    K_WEAK = 17,
    K_BAD = 18, /* one per field component */
    K_COUNT = K_BAD + 3 * MAX_FIELDS_PER_CALL
};
#define K_EMPTY (1 << 30)
#define K_NONE INT32_MAX

struct hv_extend_cl {
    hv_cl *cl;
    cl_mem solid, phi, w, pending, ncomp, K, S;
    cl_mem in, out, sol; /* planes of count floats */
    cl_mem f, u, part;   /* a level's right-hand side and solution on its box (acc_t) */
    size_t cap_in, cap_out, cap_sol, cap_f, cap_u, cap_part;
    hv_solver *sv[MAX_LEVELS]; /* level l: t * 16^l on the box blo, bn */
    int blo[MAX_LEVELS][3], bn[MAX_LEVELS][3];
};

void hv__extend_cl_destroy(hv_extend_cl **state)
{
    if (!state || !*state)
        return;
    hv_extend_cl *x = *state;
    for (int l = 0; l < MAX_LEVELS; l++)
        hv_solver_destroy(&x->sv[l]);
    cl_mem *m[] = {&x->solid, &x->phi, &x->w,   &x->pending, &x->ncomp, &x->K,   &x->S,
                   &x->in,    &x->out, &x->sol, &x->f,       &x->u,     &x->part};
    for (size_t i = 0; i < sizeof m / sizeof m[0]; i++)
        hv__cl_free(m[i]);
    hv__cl_close(&x->cl);
    free(x);
    *state = NULL;
}

/* *m holds at least want units (want 0: one). */
static hv_status ensure(hv_cl *cl, cl_mem *m, size_t *cap, size_t want, size_t unit)
{
    if (want == 0)
        want = 1;
    if (*m && *cap >= want)
        return HV_OK;
    hv__cl_free(m);
    *cap = 0;
    hv_status st = hv__cl_alloc(cl, want * unit, NULL, m);
    if (!st)
        *cap = want;
    return st;
}

static hv_status state_create(hv_extend_cl **out, const hv_extend_grid *g)
{
    hv_extend_cl *x = calloc(1, sizeof *x);
    if (!x)
        return hv__error(HV_ERR_NOMEM, "extend: out of memory");
    hv_status st = hv__cl_open(&x->cl);
    hv_cl *cl = x->cl;
    if (st || (st = hv__cl_module_open(cl, &extend_module)) || (st = hv__cl_ops_open(cl)) ||
        (st = hv__cl_alloc(cl, MAX_FIELDS_PER_CALL * sizeof(cl_int), NULL, &x->ncomp)) ||
        (st = hv__cl_alloc(cl, K_COUNT * sizeof(cl_int), NULL, &x->K)) ||
        (st = hv__cl_alloc(cl, sizeof(double), NULL, &x->S))) {
        hv__extend_cl_destroy(&x);
        return st;
    }
    *out = x;
    return HV_OK;
}

/* The right-hand side r of the layout of extend_internal.h (0: the weights;
 * per field a scalar's values, or a vector's magnitude then its components)
 * as ext_rhs's mode, first input plane and component count. */
static void rhs_source(int r, int nfields, const hv_extend_field *f, int *mode, size_t *plane,
                       int *ncomp)
{
    *mode = 0;
    *plane = 0;
    *ncomp = 0;
    int base = 1;
    size_t p0 = 0;
    for (int i = 0; i < nfields && r > 0; i++) {
        const int k = f[i].ncomp == 1 ? 1 : f[i].ncomp + 1;
        if (r < base + k) {
            const int part = r - base;
            *ncomp = f[i].ncomp;
            *mode = f[i].ncomp > 1 && part == 0 ? 2 : 1;
            *plane = p0 + (f[i].ncomp > 1 && part > 0 ? (size_t)part - 1 : 0);
            return;
        }
        base += k;
        p0 += (size_t)f[i].ncomp;
    }
}

/* ||v||_2^2 of n acc_t values on the device (a host synchronization). */
static hv_status norm2sq(hv_extend_cl *x, cl_mem v, size_t n, double *out)
{
    hv_cl *cl = x->cl;
    *out = 0;
    if (!cl->fp64) {
        hv__cl_dot_f(cl, v, v, n, x->S, 0);
    } else {
        size_t g, l, groups = hv__cl_range_red(n, &g, &l);
        hv_status st = ensure(cl, &x->part, &x->cap_part, groups, sizeof(double));
        if (st)
            return st;
        hv__cl_dot_parts_d(cl, v, v, n, x->part);
        hv__cl_finish_sum(cl, x->part, groups, x->S, 0);
    }
    hv__cl_read_acc(cl, x->S, 0, 1, out);
    return hv__cl_check(cl);
}

/* hv__extend_solve_level (extend_levels.c) on the device: every right-hand
 * side of level l solved on the box [lo, lo + bn) and stored in the solution
 * planes, 0 outside the box; *thr the level's trust bound. */
static hv_status solve_level(hv_extend_cl *x, const hv_extend_grid *g, int l, const int lo[3],
                             const int bn[3], int nrhs, int nfields, const hv_extend_field *f,
                             double *thr, hv_extend_stats *S)
{
    hv_cl *cl = x->cl;
    /* The level's solver on the extender's context and queue, which may be a
     * caller's (hv_opencl_extender_create). */
    hv__cl_adopt(cl->ctx, cl->dev, cl->q);
    hv_status st = hv__extend_level_solver(g->dim, g->n, g->h, g->solid, g->o, HV_BACKEND_OPENCL, l,
                                           lo, bn, &x->sv[l], x->blo[l], x->bn[l]);
    hv__cl_adopt(NULL, NULL, NULL);
    if (st)
        return st;
    const size_t bcount = (size_t)bn[0] * bn[1] * bn[2];
    if ((st = ensure(cl, &x->f, &x->cap_f, bcount, cl->acc)) ||
        (st = ensure(cl, &x->u, &x->cap_u, bcount, cl->acc)))
        return st;
    const size_t count = g->count;
    if (bcount != count)
        hv__cl_zero(cl, x->sol, (size_t)nrhs * count * sizeof(float));
    const cl_int N[4] = {g->n[0], g->n[1], g->n[2], g->dim};
    const cl_int B[4] = {bn[0], bn[1], bn[2], 0}, L[4] = {lo[0], lo[1], lo[2], 0};
    size_t g2[2], l2[2];
    hv__cl_range2((size_t)bn[0], (size_t)bn[1] * bn[2], g2, l2);
    double relmax = 0, wn2 = 0;
    for (int r = 0; r < nrhs; r++) {
        int mode, ncomp;
        size_t plane;
        rhs_source(r, nfields, f, &mode, &plane, &ncomp);
        hv__cl_args(cl, &extend_module, EK_RHS, "IIImmililm", N, B, L, x->w, x->in, mode,
                    plane * count, ncomp, count, x->f);
        hv__cl_run(cl, &extend_module, EK_RHS, 2, g2, l2);
        if (r == 0 && (st = norm2sq(x, x->f, bcount, &wn2)))
            return st;
        /* the solver has its own queue: f must be complete */
        if ((st = hv__cl_finish(cl)))
            return st;
        hv_solve_info info;
        st = cl->fp64 ? hv__cl_solver_solve_d(x->sv[l], x->f, x->u, &info)
                      : hv__cl_solver_solve(x->sv[l], x->f, x->u, &info);
        if (st)
            return st;
        relmax = fmax(relmax, info.relres);
        hv__cl_args(cl, &extend_module, EK_SCATTER, "IIImml", N, B, L, x->u, x->sol,
                    (size_t)r * count);
        hv__cl_run(cl, &extend_module, EK_SCATTER, 2, g2, l2);
        S->solves++;
    }
    S->relres = fmax(S->relres, relmax);
    if (l == 0)
        S->solve_cells = bcount;
    *thr = fmax(RELIABLE * fmax(relmax, 1e-14) * sqrt(wn2), 1e-30);
    return hv__cl_check(cl);
}

hv_status hv__extend_cl_prepare(hv_extend_cl **state, const hv_extend_grid *g, cl_context ctx,
                                cl_device_id dev, cl_command_queue queue)
{
    if (*state)
        return HV_OK;
    if (ctx)
        hv__cl_adopt(ctx, dev, queue);
    hv_status st = state_create(state, g);
    hv__cl_adopt(NULL, NULL, NULL);
    return st;
}

/* Room for the fields' input and output planes and the solutions. */
static hv_status io_planes(hv_extend_cl *x, const hv_extend_grid *g, int nfields,
                           const hv_extend_field *f, int nrhs)
{
    int nout = 0;
    for (int i = 0; i < nfields; i++)
        nout += f[i].ncomp;
    const size_t fb = g->count * sizeof(float);
    hv_status st = HV_OK;
    if (g->count > (size_t)INT32_MAX) /* dense grids only: tiles have their own limits */
        return hv__error(HV_ERR_UNSUPPORTED,
                         "extend: %zu cells exceed the OpenCL path's 2^31 limit", g->count);
    /* The grid's planes, on first use (an extender of tiles never needs them). */
    if ((!x->phi && (st = hv__cl_alloc(x->cl, fb, NULL, &x->phi))) ||
        (!x->w && (st = hv__cl_alloc(x->cl, fb, NULL, &x->w))) ||
        (!x->pending && (st = hv__cl_alloc(x->cl, g->count, NULL, &x->pending))) ||
        (g->solid && !x->solid && (st = hv__cl_alloc(x->cl, g->count, g->solid, &x->solid))))
        return st;
    if ((st = ensure(x->cl, &x->in, &x->cap_in, (size_t)nout, fb)) ||
        (st = ensure(x->cl, &x->out, &x->cap_out, (size_t)nout, fb)))
        return st;
    return ensure(x->cl, &x->sol, &x->cap_sol, (size_t)nrhs, fb);
}

/* The extension once phi is in x->phi and the fields' components in the
 * planes of x->in (only f[i].ncomp is read): the outputs in x->out. */
static hv_status run_loaded(hv_extend_cl *x, const hv_extend_grid *g, int nfields,
                            const hv_extend_field *f, int nrhs, hv_extend_stats *S)
{
    hv_cl *cl = x->cl;
    const hv_extend_opts *o = g->o;
    const size_t count = g->count;
    hv_status st;
    int nout = 0;
    cl_int nc[MAX_FIELDS_PER_CALL];
    for (int i = 0; i < nfields; i++) {
        nc[i] = f[i].ncomp;
        nout += f[i].ncomp;
    }
    double t0 = hv_now();
    hv__cl_write(cl, x->ncomp, 0, (size_t)nfields * sizeof(cl_int), nc);
    cl_int K[K_COUNT];
    for (int q = 0; q < K_COUNT; q++)
        K[q] = q >= K_BAD ? K_NONE : 0;
    for (int a = 0; a < 3; a++) {
        K[K_WBOX + a] = K[K_RBOX + a] = K_EMPTY;
        K[K_WBOX + 3 + a] = K[K_RBOX + 3 + a] = -K_EMPTY;
    }
    hv__cl_write(cl, x->K, 0, sizeof K, K);

    /* Weights, where each output cell is read, the background, the checks. */
    const cl_int N[4] = {g->n[0], g->n[1], g->n[2], g->dim};
    const double P[4] = {o->band, g->h, GRAD_MIN, GRAD_MAX};
    const double Q[4] = {o->band * g->h, o->out_band * g->h, 0, 0};
    size_t gc[2], lc[2], g1[1], l1[1];
    hv__cl_range2((size_t)N[0], (size_t)N[1] * N[2], gc, lc);
    hv__cl_range1(count, g1, l1);
    hv__cl_args(cl, &extend_module, EK_SETUP, "IAAimmmmmilfm", N, P, Q, o->closest_point, x->phi,
                x->solid, x->w, x->pending, x->out, nout, count, (double)o->background, x->K);
    hv__cl_run(cl, &extend_module, EK_SETUP, 2, gc, lc);
    for (int q = 0; q < nout; q++) {
        hv__cl_args(cl, &extend_module, EK_CHECK, "mmllmi", x->w, x->in, (size_t)q * count, count,
                    x->K, q);
        hv__cl_run(cl, &extend_module, EK_CHECK, 1, g1, l1);
    }
    hv__cl_read(cl, x->K, 0, sizeof K, K);
    if ((st = hv__cl_check(cl)))
        return st;
    S->source_cells = (size_t)K[K_NSRC];
    if (!K[K_NSRC])
        return hv__error(HV_ERR_INVALID_ARG,
                         "extend: no fluid cell has |phi| < band * h = %g (the level set has no "
                         "zero crossing in the grid, or the band is too thin)",
                         o->band * g->h);
    for (int i = 0, q0 = 0; i < nfields; q0 += f[i].ncomp, i++)
        for (int q = 0; q < f[i].ncomp; q++)
            if (K[K_BAD + q0 + q] != K_NONE)
                return hv__error(HV_ERR_NUMERIC,
                                 "extend: field %d component %d is NaN/Inf at cell %d, inside "
                                 "the source band",
                                 i, q, K[K_BAD + q0 + q]);
    size_t npend = (size_t)K[K_NPEND];
    int wlo[3], whi[3], rlo[3], rhi[3];
    for (int a = 0; a < 3; a++) {
        wlo[a] = K[K_WBOX + a];
        whi[a] = K[K_WBOX + 3 + a];
        rlo[a] = K[K_RBOX + a];
        rhi[a] = K[K_RBOX + 3 + a];
    }
    S->t_weights = hv_now() - t0;

    /* The levels, as hv_extend_many. */
    for (int l = 0; l < o->max_levels && npend > 0; l++) {
        int lo[3], bn[3];
        hv__extend_level_box(g->e, wlo, whi, rlo, rhi, l, lo, bn);
        t0 = hv_now();
        double thr = 0;
        if ((st = solve_level(x, g, l, lo, bn, nrhs, nfields, f, &thr, S)))
            break;
        S->t_solve += hv_now() - t0;
        S->levels = l + 1;
        t0 = hv_now();
        cl_int *Kl = K + K_RBOX;
        for (int a = 0; a < 3; a++) {
            Kl[a] = K_EMPTY;
            Kl[3 + a] = -K_EMPTY;
        }
        for (int q = K_LEFT; q <= K_WEAK; q++)
            K[q] = 0;
        hv__cl_write(cl, x->K, K_RBOX * sizeof(cl_int), (K_WEAK + 1 - K_RBOX) * sizeof(cl_int), Kl);
        hv__cl_args(cl, &extend_module, EK_EVAL, "IAmmmlmimaifm", N, P, x->phi, x->pending, x->sol,
                    count, x->ncomp, nfields, x->out, thr, l + 1 == o->max_levels,
                    (double)o->background, x->K);
        hv__cl_run(cl, &extend_module, EK_EVAL, 2, gc, lc);
        hv__cl_read(cl, x->K, K_RBOX * sizeof(cl_int), (K_WEAK + 1 - K_RBOX) * sizeof(cl_int), Kl);
        if ((st = hv__cl_check(cl)))
            break;
        S->cp_cells += (size_t)K[K_CP];
        S->ratio_cells += (size_t)K[K_RATIO];
        S->weak_cells += (size_t)K[K_WEAK];
        npend = (size_t)K[K_LEFT];
        for (int a = 0; a < 3; a++) {
            rlo[a] = K[K_RBOX + a];
            rhi[a] = K[K_RBOX + 3 + a];
        }
        S->t_eval += hv_now() - t0;
    }
    return st;
}

hv_status hv__extend_cl_run(hv_extend_cl **state, const hv_extend_grid *g, const float *phi,
                            int nfields, const hv_extend_field *f, int nrhs, hv_extend_stats *S)
{
    hv_status st;
    if ((st = hv__extend_cl_prepare(state, g, NULL, NULL, NULL)) ||
        (st = io_planes(*state, g, nfields, f, nrhs)))
        return st;
    hv_extend_cl *x = *state;
    hv_cl *cl = x->cl;
    const size_t fb = g->count * sizeof(float);
    double t0 = hv_now();
    hv__cl_write(cl, x->phi, 0, fb, phi);
    for (int i = 0, q0 = 0; i < nfields; q0 += f[i].ncomp, i++)
        for (int q = 0; q < f[i].ncomp; q++)
            hv__cl_write(cl, x->in, (size_t)(q0 + q) * fb, fb, f[i].in[q]);
    double t_load = hv_now() - t0;
    if ((st = run_loaded(x, g, nfields, f, nrhs, S)))
        return st;
    S->t_weights += t_load;
    t0 = hv_now();
    for (int i = 0, q0 = 0; i < nfields; q0 += f[i].ncomp, i++)
        for (int q = 0; q < f[i].ncomp; q++)
            hv__cl_read(cl, x->out, (size_t)(q0 + q) * fb, fb, f[i].out[q]);
    st = hv__cl_check(cl);
    S->t_eval += hv_now() - t0;
    return st;
}

/* A float buffer of the extender's cells on its context ("in 0.2": field 0's
 * component 2), or the reason not. */
static hv_status check_buffer(const hv_extend_cl *x, cl_mem m, size_t count, const char *what,
                              int i, int q)
{
    char name[64];
    if (i < 0)
        snprintf(name, sizeof name, "%s", what);
    else
        snprintf(name, sizeof name, "%s (field %d component %d)", what, i, q);
    return hv__cl_check_floats(x->cl, m, count, "hv_opencl_extend", name);
}

hv_status hv__extend_cl_run_dev(hv_extend_cl *x, const hv_extend_grid *g, cl_mem phi, int nfields,
                                const hv_opencl_field *fd, int nrhs, hv_extend_stats *S)
{
    hv_extend_field f[MAX_FIELDS_PER_CALL];
    memset(f, 0, sizeof f);
    hv_status st = check_buffer(x, phi, g->count, "phi", -1, 0);
    for (int i = 0; i < nfields && !st; i++) {
        f[i].ncomp = fd[i].ncomp;
        for (int q = 0; q < fd[i].ncomp && !st; q++)
            if (!(st = check_buffer(x, fd[i].in[q], g->count, "in", i, q)))
                st = check_buffer(x, fd[i].out[q], g->count, "out", i, q);
    }
    if (st || (st = io_planes(x, g, nfields, f, nrhs)))
        return st;
    hv_cl *cl = x->cl;
    const size_t fb = g->count * sizeof(float);
    hv__cl_copy(cl, phi, x->phi, fb);
    for (int i = 0, q0 = 0; i < nfields; q0 += f[i].ncomp, i++)
        for (int q = 0; q < f[i].ncomp; q++)
            hv__cl_copy_at(cl, fd[i].in[q], 0, x->in, (size_t)(q0 + q) * fb, fb);
    if ((st = run_loaded(x, g, nfields, f, nrhs, S)))
        return st;
    for (int i = 0, q0 = 0; i < nfields; q0 += f[i].ncomp, i++)
        for (int q = 0; q < f[i].ncomp; q++)
            hv__cl_copy_at(cl, x->out, (size_t)(q0 + q) * fb, fd[i].out[q], 0, fb);
    return hv__cl_finish(cl);
}

struct hv_cl *hv__extend_cl_handle(hv_extend_cl *x) { return x->cl; }

void hv__extend_cl_queue(const hv_extend_cl *x, cl_context *ctx, cl_device_id *dev,
                         cl_command_queue *queue)
{
    if (ctx)
        *ctx = x->cl->ctx;
    if (dev)
        *dev = x->cl->dev;
    if (queue)
        *queue = x->cl->q;
}
