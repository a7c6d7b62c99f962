/*
 * Stages 2-6 of the signed heat method (sdf.c) with every field on one OpenCL
 * device: splat, diffusion, face normalization with the divergence, Poisson,
 * zero-set shift. Same quadrature, weights, noise bounds, face rule and
 * correction as the host path; the host reads back residual norms, the
 * dead-face count, phi at the surface samples (for the area-weighted sums)
 * and phi once. The steps of its own (the splat, the right-hand side, the
 * shift) come first, with their kernels (kernels/heat.cl), which this file
 * registers and builds (hv_cl_module, src/cl/cl_core.h).
 */
#include "sdf_cl.h"
#include "core/error.h"
#include "cl/cl_ops.h"
#include "solve/cl/solve_cl.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* ---------- the device steps and their kernels ---------- */

extern const char hv__kernel_heat[]; /* kernels/heat.cl, embedded by the Makefile */

static const char *const heat_sources[] = {hv__kernel_heat, NULL};
enum { K_SPLAT, K_SDF_RHS, K_SAMPLE, K_SHIFT };
static const char *const heat_kernels[] = {"heat_splat", "heat_sdf_rhs", "heat_sample",
                                           "heat_shift", NULL};
static const hv_cl_module heat_module = {"heat", heat_sources, heat_kernels, 0, 0};

void hv__cl_splat_destroy(hv_cl_splat *S)
{
    free(S->order);
    free(S->stage);
    hv__cl_free(&S->base);
    hv__cl_free(&S->start);
    hv__cl_free(&S->frac);
    hv__cl_free(&S->val);
    memset(S, 0, sizeof *S);
}

/* Inclusive prefix sum of v[0..n) in place, in blocks across the threads. */
static void prefix_sum(uint32_t *v, size_t n)
{
    enum { BLOCK = 1 << 20 };
    const size_t nb = (n + BLOCK - 1) / BLOCK;
    uint32_t *tot = malloc((nb + 1) * sizeof *tot);
    if (!tot) {
        for (size_t c = 1; c < n; c++)
            v[c] += v[c - 1];
        return;
    }
#pragma omp parallel for schedule(static)
    for (size_t b = 0; b < nb; b++) {
        size_t end = (b + 1) * BLOCK < n ? (b + 1) * BLOCK : n;
        for (size_t c = b * BLOCK + 1; c < end; c++)
            v[c] += v[c - 1];
        tot[b] = v[end - 1];
    }
    for (size_t b = 1; b < nb; b++)
        tot[b] += tot[b - 1];
#pragma omp parallel for schedule(static)
    for (size_t b = 1; b < nb; b++) {
        size_t end = (b + 1) * BLOCK < n ? (b + 1) * BLOCK : n;
        for (size_t c = b * BLOCK; c < end; c++)
            v[c] += tot[b - 1];
    }
    free(tot);
}

hv_status hv__cl_splat_create(hv_cl *cl, hv_cl_splat *S, int dim, const int n[3], double h,
                              const double origin[3], size_t npts, const double *x)
{
    memset(S, 0, sizeof *S);
    if ((dim != 2 && dim != 3) || !(h > 0) || !n || !origin || (npts && !x))
        return hv__error(HV_ERR_INVALID_ARG,
                         "OpenCL splat: bad grid (dim %d, h %g) or NULL argument", dim, h);
    const int nn[3] = {n[0], n[1], dim == 3 ? n[2] : 1};
    const size_t count = (size_t)nn[0] * nn[1] * nn[2];
    if (nn[0] < 1 || nn[1] < 1 || nn[2] < 1 || count >= UINT32_MAX || npts >= UINT32_MAX)
        return hv__error(HV_ERR_INVALID_ARG, "OpenCL splat: %zu samples on %d x %d x %d cells",
                         npts, nn[0], nn[1], nn[2]);
    hv_status st = hv__cl_module_open(cl, &heat_module);
    if (!st)
        st = hv__cl_ops_open(cl);
    if (st)
        return st;
    for (int a = 0; a < 3; a++)
        S->N[a] = nn[a];
    S->N[3] = dim;
    S->count = count;
    S->npts = npts;
    uint32_t *start = calloc(count + 3, sizeof *start), *base = malloc((npts + 1) * sizeof *base);
    uint32_t *sbase = malloc((npts + 1) * sizeof *sbase);
    float *frac = malloc((npts + 1) * 4 * sizeof *frac), *f = malloc((npts + 1) * 4 * sizeof *f);
    S->order = malloc((npts + 1) * sizeof *S->order);
    S->stage = malloc((npts + 1) * sizeof *S->stage);
    if (!start || !base || !sbase || !frac || !f || !S->order || !S->stage) {
        st = hv__error(HV_ERR_NOMEM, "OpenCL splat: out of memory for %zu samples", npts);
        goto done;
    }
    const size_t stride[3] = {1, (size_t)nn[0], (size_t)nn[0] * nn[1]};
    /* base cell and fractions exactly as hv__trilinear (src/geom/surface.c) */
    for (size_t p = 0; p < npts; p++) {
        size_t b = 0;
        for (int a = 0; a < 3; a++) {
            double s = a < dim ? (x[3 * p + a] - origin[a]) / h - 0.5 : 0.0, fa = 0.0;
            int i0 = 0;
            if (nn[a] == 1 || !(s > 0)) {
                i0 = 0;
            } else if (s >= nn[a] - 1) {
                i0 = nn[a] - 1;
            } else {
                i0 = (int)floor(s);
                fa = s - i0;
            }
            f[4 * p + a] = (float)fa;
            b += (size_t)i0 * stride[a];
        }
        f[4 * p + 3] = 0.0f;
        base[p] = (uint32_t)b;
        start[b + 2]++;
    }
    prefix_sum(start + 2, count);
    /* Stable counting sort, last sample first: start[c + 2] ends cell c and
     * falls to where it begins, so start + 2 is the cells' starts with the
     * end of the last one after them. */
    for (size_t p = npts; p-- > 0;) {
        uint32_t q = --start[base[p] + 2];
        S->order[q] = (uint32_t)p;
        sbase[q] = base[p];
        memcpy(frac + 4 * (size_t)q, f + 4 * p, 4 * sizeof *f);
    }
    start[count + 2] = (uint32_t)npts;
    if ((st = hv__cl_alloc(cl, (count + 1) * sizeof *start, start + 2, &S->start)) ||
        (st = hv__cl_alloc(cl, npts * 4 * sizeof *frac, npts ? frac : NULL, &S->frac)) ||
        (st = hv__cl_alloc(cl, npts * sizeof *sbase, npts ? sbase : NULL, &S->base)) ||
        (st = hv__cl_alloc(cl, npts * sizeof(float), NULL, &S->val)))
        goto done;
done:
    free(start);
    free(base);
    free(sbase);
    free(frac);
    free(f);
    if (st)
        hv__cl_splat_destroy(S);
    return st;
}

hv_status hv__cl_splat_run(hv_cl *cl, hv_cl_splat *S, const double *val, size_t stride,
                           double scale, cl_mem out)
{
    if (!S->start || !out)
        return hv__error(HV_ERR_INVALID_ARG, "hv__cl_splat_run: no binned samples or no output");
    for (size_t q = 0; q < S->npts; q++)
        S->stage[q] = (float)(val ? scale * val[(size_t)S->order[q] * stride] : scale);
    hv__cl_write(cl, S->val, 0, S->npts * sizeof(float), S->stage);
    size_t g[2], l[2];
    hv__cl_range2((size_t)S->N[0], (size_t)S->N[1] * S->N[2], g, l);
    hv__cl_args(cl, &heat_module, K_SPLAT, "Immmm", S->N, S->start, S->frac, S->val, out);
    hv__cl_run(cl, &heat_module, K_SPLAT, 2, g, l);
    return hv__cl_check(cl);
}

void hv__cl_sdf_rhs(hv_cl *cl, const int n[3], double h, cl_mem Y, int nlev, int ncomp, cl_mem tau,
                    cl_mem rhs, cl_mem dead)
{
    const cl_int N[4] = {n[0], n[1], n[2], 3};
    const size_t count = (size_t)n[0] * n[1] * n[2];
    size_t g[2], l[2];
    hv__cl_range2((size_t)n[0], (size_t)n[1] * n[2], g, l);
    hv__cl_args(cl, &heat_module, K_SDF_RHS, "Imliimamm", N, Y, count, nlev, ncomp, tau, 1.0 / h,
                rhs, dead);
    hv__cl_run(cl, &heat_module, K_SDF_RHS, 2, g, l);
}

void hv__cl_splat_sample(hv_cl *cl, hv_cl_splat *S, cl_mem v, cl_mem out)
{
    size_t g[1], l[1];
    hv__cl_range1(S->npts, g, l);
    hv__cl_args(cl, &heat_module, K_SAMPLE, "Immmml", S->N, S->base, S->frac, v, out, S->npts);
    hv__cl_run(cl, &heat_module, K_SAMPLE, 1, g, l);
}

void hv__cl_sdf_shift(hv_cl *cl, size_t n, cl_mem phi, cl_mem num, cl_mem den, double shift,
                      double tau, int local_shift)
{
    size_t g[1], l[1];
    hv__cl_range1(n, g, l);
    hv__cl_args(cl, &heat_module, K_SHIFT, "mmmfail", phi, num, den, shift, tau, local_shift, n);
    hv__cl_run(cl, &heat_module, K_SHIFT, 1, g, l);
}

/* ---------- the stages ---------- */

/* As sdf.c. */
#define SDF_NOISE_FACTOR 4.0

typedef struct sdf_cl_work {
    hv_cl *cl;
    hv_cl_splat sp;
    cl_mem Y0[3], Y, tmp, tau, rhs, phi, dead, sums, samp;
    float *vals;
    double *res;
    hv_solver *solver;
} sdf_cl_work;

static void work_free(sdf_cl_work *w)
{
    hv_solver_destroy(&w->solver);
    hv__cl_splat_destroy(&w->sp);
    for (int b = 0; b < 3; b++)
        hv__cl_free(&w->Y0[b]);
    hv__cl_free(&w->Y);
    hv__cl_free(&w->tmp);
    hv__cl_free(&w->tau);
    hv__cl_free(&w->rhs);
    hv__cl_free(&w->phi);
    hv__cl_free(&w->dead);
    hv__cl_free(&w->sums);
    hv__cl_free(&w->samp);
    free(w->vals);
    free(w->res);
    hv__cl_close(&w->cl);
}

static hv_status opencl_solver(hv_solver **s, const hv_grid *g, double alpha, double beta,
                               double tol)
{
    hv_solver_opts so;
    hv_solver_opts_default(&so);
    so.backend = HV_BACKEND_OPENCL;
    so.tol = tol;
    so.max_iter = 100;
    hv_problem pb = {3, {g->n[0], g->n[1], g->n[2]}, g->h, NULL, alpha, beta};
    return hv_solver_create(s, &pb, &so);
}

/* phi at the samples (w->vals, sorted order) and its area-weighted sums. */
static hv_status sample_sums(sdf_cl_work *w, const hv_quad *q, double *num, double *den,
                             double *rms)
{
    const size_t np = q->count;
    hv_status st;
    if (!w->samp && (st = hv__cl_alloc(w->cl, np * sizeof(float), NULL, &w->samp)))
        return st;
    if (!w->vals && !(w->vals = malloc(np * sizeof *w->vals)))
        return hv__error(HV_ERR_NOMEM, "sdf: out of memory for %zu surface samples", np);
    if (!w->res && !(w->res = malloc(np * sizeof *w->res)))
        return hv__error(HV_ERR_NOMEM, "sdf: out of memory for %zu surface samples", np);
    hv__cl_splat_sample(w->cl, &w->sp, w->phi, w->samp);
    hv__cl_read(w->cl, w->samp, 0, np * sizeof(float), w->vals);
    if ((st = hv__cl_check(w->cl)))
        return st;
    double a = 0, b = 0, c = 0;
#pragma omp parallel for reduction(+ : a, b, c) schedule(static)
    for (size_t k = 0; k < np; k++) {
        const double ar = q->area[w->sp.order[k]], v = w->vals[k];
        a += ar * v;
        b += ar;
        c += ar * v * v;
    }
    *num = a, *den = b, *rms = c;
    return HV_OK;
}

/* 2. Splat: bin the samples once, one gather per component; *f2 the sum of
 * the components' squared norms. */
static hv_status cl_splat(sdf_cl_work *w, const hv_quad *q, const hv_grid *g, int unsig, double *f2)
{
    hv_cl *cl = w->cl;
    const double h = g->h;
    const size_t count = hv_grid_count(g), bytes = count * sizeof(float);
    const int ncomp = unsig ? 1 : 3;
    hv_status st;
    if ((st = hv__cl_splat_create(cl, &w->sp, 3, g->n, h, g->origin, q->count, q->x)))
        return st;
    const double inv_h3 = 1.0 / (h * h * h);
    for (int b = 0; b < ncomp; b++)
        if ((st = hv__cl_alloc(cl, bytes, NULL, &w->Y0[b])) ||
            (st = hv__cl_splat_run(cl, &w->sp, unsig ? q->area : q->w + b, unsig ? 1 : 3, inv_h3,
                                   w->Y0[b])))
            return st;
    if ((st = hv__cl_alloc(cl, 4 * sizeof(double), NULL, &w->sums)))
        return st;
    for (int b = 0; b < ncomp; b++)
        hv__cl_dot_f(cl, w->Y0[b], w->Y0[b], count, w->sums, b);
    double sq[3] = {0, 0, 0};
    hv__cl_read_acc(cl, w->sums, 0, ncomp, sq);
    if ((st = hv__cl_check(cl)))
        return st;
    for (int b = 0; b < ncomp; b++)
        *f2 += sq[b];
    return HV_OK;
}

/* 3. Diffuse: one backward-Euler step per level, straight into Y; tau[k]
 * the noise threshold of level k. The splat is freed. */
static hv_status cl_diffuse(sdf_cl_work *w, const hv_grid *g, int nlev, int unsig,
                            const hv_sdf_opts *o, double f2, double tau[9], hv_sdf_stats *S)
{
    double tt = hv_now();
    hv_cl *cl = w->cl;
    const size_t bytes = hv_grid_count(g) * sizeof(float);
    const int ncomp = unsig ? 1 : 3;
    hv_status st;
    if ((st = hv__cl_alloc(cl, (size_t)nlev * ncomp * bytes, NULL, &w->Y)) ||
        (st = hv__cl_alloc(cl, bytes, NULL, &w->tmp)) || (st = hv__cl_finish(cl)))
        return st;
    for (int k = 0; k < nlev; k++) {
        if ((st = hv__progress(0.1 + 0.5 * k / nlev, "diffuse")))
            return st;
        if ((st = opencl_solver(&w->solver, g, 1.0, S->t * pow(16.0, k), o->diffuse_tol)))
            return st;
        for (int b = 0; b < ncomp; b++) {
            hv_solve_info info;
            if ((st = hv__cl_solver_solve(w->solver, w->Y0[b], w->tmp, &info)))
                return st;
            S->diffuse_iterations += info.iterations;
            S->diffuse_relres = fmax(S->diffuse_relres, info.relres);
            hv__cl_fail(cl,
                        clEnqueueCopyBuffer(cl->q, w->tmp, w->Y, 0, ((size_t)k * ncomp + b) * bytes,
                                            bytes, 0, NULL, NULL),
                        "clEnqueueCopyBuffer");
            if ((st = hv__cl_finish(cl)))
                return st;
        }
        hv_solver_destroy(&w->solver);
        /* as sdf.c: ||e||_2 <= relres ||f||_2, grown by 2/h per component for the gradient */
        double bound = fmax(S->diffuse_relres, o->diffuse_tol) * sqrt(f2);
        tau[k] = SDF_NOISE_FACTOR * bound * (unsig ? 2.0 * sqrt(3.0) / g->h : 1.0);
    }
    S->backend = HV_BACKEND_OPENCL;
    for (int b = 0; b < ncomp; b++)
        hv__cl_free(&w->Y0[b]);
    S->t_diffuse = hv_now() - tt;
    return HV_OK;
}

/* 4. Normalize on faces, divergence into rhs; the diffused fields are freed. */
static hv_status cl_normalize(sdf_cl_work *w, const hv_grid *g, int nlev, int unsig, double tau[9],
                              hv_sdf_stats *S)
{
    hv_status st;
    if ((st = hv__progress(0.6, "normalize")))
        return st;
    double tt = hv_now();
    hv_cl *cl = w->cl;
    const size_t bytes = hv_grid_count(g) * sizeof(float);
    float tauf[9];
    for (int k = 0; k < nlev; k++)
        tauf[k] = (float)tau[k];
    const uint32_t zero = 0;
    if ((st = hv__cl_alloc(cl, (size_t)nlev * cl->acc, cl->fp64 ? (void *)tau : (void *)tauf,
                           &w->tau)) ||
        (st = hv__cl_alloc(cl, sizeof zero, &zero, &w->dead)) ||
        (st = hv__cl_alloc(cl, bytes, NULL, &w->rhs)))
        return st;
    hv__cl_sdf_rhs(cl, g->n, g->h, w->Y, nlev, unsig ? 1 : 3, w->tau, w->rhs, w->dead);
    uint32_t dead = 0;
    hv__cl_read(cl, w->dead, 0, sizeof dead, &dead);
    if ((st = hv__cl_check(cl)))
        return st;
    S->dead_faces = dead;
    hv__cl_free(&w->Y);
    S->t_normalize = hv_now() - tt;
    return HV_OK;
}

/* 5. Poisson: phi on the device; the divergence is freed. */
static hv_status cl_poisson(sdf_cl_work *w, const hv_grid *g, const hv_sdf_opts *o, hv_sdf_stats *S)
{
    hv_status st;
    if ((st = hv__progress(0.65, "poisson")))
        return st;
    double tt = hv_now();
    if ((st = opencl_solver(&w->solver, g, 0.0, 1.0, o->poisson_tol)) ||
        (st = hv__cl_alloc(w->cl, hv_grid_count(g) * sizeof(float), NULL, &w->phi)))
        return st;
    hv_solve_info info;
    if ((st = hv__cl_solver_solve(w->solver, w->rhs, w->phi, &info)))
        return st;
    S->poisson_iterations = info.iterations;
    S->poisson_relres = info.relres;
    if ((st = hv__cl_check(w->cl)))
        return st;
    hv_solver_destroy(&w->solver);
    hv__cl_free(&w->rhs);
    S->t_poisson = hv_now() - tt;
    return HV_OK;
}

/* The local zero-set correction, as sdf.c: c = K*(a r) / K*(a),
 * K = (I - t Lap)^-1, r = phi at the samples. */
static hv_status cl_local_shift(sdf_cl_work *w, const hv_quad *q, const hv_grid *g,
                                const hv_sdf_opts *o, hv_sdf_stats *S)
{
    hv_cl *cl = w->cl;
    const double h = g->h;
    const size_t count = hv_grid_count(g), bytes = count * sizeof(float);
    const double inv_h3 = 1.0 / (h * h * h);
    double num, den, rms;
    hv_status st;
    if ((st = sample_sums(w, q, &num, &den, &rms)))
        return st;
    for (size_t k = 0; k < q->count; k++)
        w->res[w->sp.order[k]] = q->area[w->sp.order[k]] * w->vals[k];
    if ((st = hv__cl_alloc(cl, bytes, NULL, &w->Y0[0])) ||
        (st = hv__cl_alloc(cl, bytes, NULL, &w->Y0[1])) ||
        (st = hv__cl_alloc(cl, bytes, NULL, &w->Y0[2])) ||
        (st = hv__cl_splat_run(cl, &w->sp, w->res, 1, inv_h3, w->Y0[0])) ||
        (st = hv__cl_splat_run(cl, &w->sp, q->area, 1, inv_h3, w->Y0[1])))
        return st;
    hv__cl_dot_f(cl, w->Y0[1], w->Y0[1], count, w->sums, 0);
    double f1sq = 0;
    hv__cl_read_acc(cl, w->sums, 0, 1, &f1sq);
    if ((st = hv__cl_finish(cl)) || (st = opencl_solver(&w->solver, g, 1.0, S->t, o->diffuse_tol)))
        return st;
    hv_solve_info info;
    if ((st = hv__cl_solver_solve(w->solver, w->Y0[0], w->Y0[2], &info)))
        return st;
    S->diffuse_iterations += info.iterations;
    if ((st = hv__cl_solver_solve(w->solver, w->Y0[1], w->tmp, &info)))
        return st;
    S->diffuse_iterations += info.iterations;
    hv_solver_destroy(&w->solver);
    const double tau_den = fmax(info.relres, o->diffuse_tol) * sqrt(f1sq);
    hv__cl_sdf_shift(cl, count, w->phi, w->Y0[2], w->tmp, 0.0, tau_den, 1);
    if ((st = sample_sums(w, q, &num, &den, &rms)))
        return st;
    S->surface_rms_after = sqrt(rms / den) / h;
    return HV_OK;
}

/* 6. Shift: area-weighted mean of phi at the samples to zero, then the
 * local zero-set correction, as sdf.c; then phi to the host, the one read of
 * a field. */
static hv_status cl_shift(sdf_cl_work *w, const hv_quad *q, hv_grid *g, int unsig,
                          const hv_sdf_opts *o, hv_sdf_stats *S)
{
    hv_status st;
    if ((st = hv__progress(0.8, "shift")))
        return st;
    double tt = hv_now();
    hv_cl *cl = w->cl;
    const size_t count = hv_grid_count(g), bytes = count * sizeof(float);
    double num, den, rms;
    if ((st = sample_sums(w, q, &num, &den, &rms)))
        return st;
    S->shift = den > 0 ? num / den : 0;
    S->surface_rms_before = sqrt(fmax(0.0, rms / den - S->shift * S->shift)) / g->h;
    S->surface_rms_after = S->surface_rms_before;
    hv__cl_sdf_shift(cl, count, w->phi, NULL, NULL, (float)S->shift, 0.0, 0);
    if (o->local_shift && !unsig && (st = cl_local_shift(w, q, g, o, S)))
        return st;
    hv__cl_read(cl, w->phi, 0, bytes, g->v);
    st = hv__cl_check(cl);
    S->t_shift = hv_now() - tt;
    return st;
}

hv_status hv__sdf_heat_cl(const hv_quad *q, hv_grid *g, int nlev, int unsig, const hv_sdf_opts *o,
                          hv_sdf_stats *S)
{
    sdf_cl_work w;
    memset(&w, 0, sizeof w);
    hv_status st;
    double tt = hv_now();
    if ((st = hv__cl_open(&w.cl)))
        return st;
    double f2 = 0;
    if ((st = cl_splat(&w, q, g, unsig, &f2)))
        goto done;
    S->t_splat += hv_now() - tt;
    double tau[9] = {0};
    if ((st = cl_diffuse(&w, g, nlev, unsig, o, f2, tau, S)) ||
        (st = cl_normalize(&w, g, nlev, unsig, tau, S)) || (st = cl_poisson(&w, g, o, S)))
        goto done;
    st = cl_shift(&w, q, g, unsig, o, S);
done:
    work_free(&w);
    return st;
}
