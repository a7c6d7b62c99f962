/* Unsigned geodesic distance by the heat method on grids with obstacles
 * (heat.h). One backward-Euler step decays like e^{-r/sqrt t} (docs/METHOD.md,
 * "Heat method"), so a double solve is trusted only ~30 sqrt(t) out; a larger
 * t reaches further but bends directions near walls (Neumann reflections) and
 * corners (6 voxels mean error at 128^2 with t = 512 h^2). Instead the
 * diffusion marches: each stage starts from a wavefront of the previous one,
 * with t kept small. The lattice and front rules are in distance_front.c; on
 * an fp64 OpenCL device the stages run in distance_cl.c. */
#include "distance_internal.h"
#include "distance_cl.h"
#include "core/error.h"
#include "heatvox/ops.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void hv_distance_opts_default(hv_distance_opts *o)
{
    memset(o, 0, sizeof *o);
    o->t_scale = 2;
    o->max_stages = 1000;
    o->diffuse_tol = 1e-11;
    o->poisson_tol = 1e-9;
    o->backend = HV_BACKEND_AUTO;
    o->unreachable = INFINITY;
    o->solid_value = INFINITY;
}

typedef hv_dist_box dist_ctx;

/* ---- one process, the whole grid ------------------------------------------ */

struct hv_distance {
    hv_distance_opts o; /* the backend resolved */
    hv_grid shape;      /* dim, n, h, origin; solid: the object's copy (NULL: none) */
    size_t count;
    int band;         /* the stages on tiles (distance_band.c) */
    hv_solver *sv[3]; /* the two heat steps (whole stages only), then Poisson */
    double t_setup;   /* seconds spent making them, not yet reported */
};

typedef struct local_solves {
    const dist_ctx *d;
    hv_distance *D;
    int restarts; /* of the Poisson solve */
} local_solves;

/* Poisson, with restarts (defect correction) on the residual, a guard: CG
 * with a preconditioner that is not symmetric stalls near 3e-2 in long
 * corridors; with the symmetric cycle (P^T restriction, reversed
 * post-smoothing) every test scene (serpentine and maze included) converges
 * without one, and check_distance asserts that. */
static hv_status local_poisson(local_solves *L, const double *rhs, double *u, hv_solve_info *info)
{
    const dist_ctx *d = L->d;
    const hv_distance_opts *o = &L->D->o;
    hv_solver *sv = L->D->sv[2];
    hv_status st = hv_solver_solve_d(sv, rhs, u, info);
    if (st)
        return st;
    double fn = hv__dist_norm2(d, rhs), rel = info->relres;
    int its = info->iterations, restarts = 0;
    double *Au = NULL;
    for (int rs = 0; rel > o->poisson_tol && rs < 30; rs++) {
        if (!Au && !(Au = hv_malloc(2 * d->count * sizeof *Au)))
            return hv__error(HV_ERR_NOMEM, "distance: out of memory for the Poisson restarts");
        double *r = Au + d->count;
        hv_apply_helmholtz_d(d->dim, d->n, d->h, d->solid, 0.0, 1.0, u, Au);
#pragma omp parallel for schedule(static)
        for (size_t c = 0; c < d->count; c++)
            r[c] = d->region[c] >= 0 ? rhs[c] - Au[c] : 0.0;
        rel = fn > 0 ? hv__dist_norm2(d, r) / fn : 0;
        if (rel <= o->poisson_tol)
            break;
        if ((st = hv_solver_solve_d(sv, r, Au, info)))
            break;
#pragma omp parallel for schedule(static)
        for (size_t c = 0; c < d->count; c++)
            u[c] += Au[c];
        its += info->iterations;
        restarts++;
    }
    hv_free(Au);
    info->iterations = its;
    L->restarts = restarts;
    info->relres = rel;
    return st;
}

static hv_status local_solve(void *user, int q, const double *f, double *u, hv_solve_info *info)
{
    local_solves *L = user;
    return q == 2 ? local_poisson(L, f, u, info) : hv_solver_solve_d(L->D->sv[q], f, u, info);
}

/* The solvers the object keeps: Poisson (on a device too, where the device
 * path solves with it), and for the host's whole stages the heat steps. */
static hv_status make_poisson(hv_distance *D)
{
    const hv_grid *g = &D->shape;
    const hv_distance_opts *o = &D->o;
    return hv__dist_solver(&D->sv[2], g->dim, g->n, g->h, g->solid, 0.0, 1.0, o->poisson_tol,
                           o->backend, hv__dist_poisson_coarse(o, g->solid));
}

static hv_status make_heat_steps(hv_distance *D)
{
    const hv_grid *g = &D->shape;
    const hv_distance_opts *o = &D->o;
    const double t = o->t_scale * g->h * g->h;
    hv_status st = HV_OK;
    for (int q = 0; !st && q < 2; q++)
        st = hv__dist_solver(&D->sv[q], g->dim, g->n, g->h, g->solid, 1.0, t * (q ? T_RATIO : 1),
                             o->diffuse_tol, o->backend, o->coarse);
    return st;
}

static int any_fluid(const hv_grid *g, size_t count)
{
    if (!g->solid)
        return 1;
    for (size_t c = 0; c < count; c++)
        if (!g->solid[c])
            return 1;
    return 0;
}

hv_status hv_distance_create(hv_distance **out, const hv_grid *g, const hv_distance_opts *opts)
{
    const double t0 = hv_now();
    if (!out || !g)
        return hv__error(HV_ERR_INVALID_ARG, "hv_distance_create: NULL argument");
    *out = NULL;
    hv_distance_opts o;
    if (opts)
        o = *opts;
    else
        hv_distance_opts_default(&o);
    const hv_distance_sources none = {0};
    hv_status st = hv__dist_check_opts(&o, &none);
    if (st || (st = hv_check_dims(g->dim, g->n, g->h,
                                  2 * sizeof(double) + 3 * sizeof(float) + 4 + sizeof(int32_t))))
        return st;
    hv_distance *D = calloc(1, sizeof *D);
    if (!D)
        return hv__error(HV_ERR_NOMEM, "distance: out of memory");
    D->shape.dim = g->dim;
    memcpy(D->shape.n, g->n, sizeof D->shape.n);
    memcpy(D->shape.origin, g->origin, sizeof D->shape.origin);
    D->shape.h = g->h;
    D->count = (size_t)g->n[0] * g->n[1] * g->n[2];
    /* The backend, chosen here once for every solve: AUTO on a GPU runs the
     * pipeline on the device, as an explicit opencl does. */
    o.backend = hv_backend_resolve(o.backend, D->count, g->solid != NULL);
    D->o = o;
    /* the device path's stages (and, without an fp64 device, the device's
     * solvers) run on the whole grid */
    D->band = !o.whole_stages && o.backend != HV_BACKEND_OPENCL;
    if (g->solid && !(D->shape.solid = malloc(D->count)))
        st = hv__error(HV_ERR_NOMEM, "distance: out of memory for the obstacle mask");
    else if (g->solid)
        memcpy(D->shape.solid, g->solid, D->count);
    /* the device path makes its whole stages' heat steps itself; with no fluid
     * cell every query fails on its sources (no source lands on a fluid cell) */
    if (!st && any_fluid(&D->shape, D->count)) {
        st = make_poisson(D);
        if (!st && !D->band && o.backend != HV_BACKEND_OPENCL)
            st = make_heat_steps(D);
    }
    if (st) {
        hv_distance_destroy(&D);
        return st;
    }
    D->t_setup = hv_now() - t0;
    *out = D;
    return HV_OK;
}

void hv_distance_destroy(hv_distance **d)
{
    if (!d || !*d)
        return;
    for (int q = 0; q < 3; q++)
        hv_solver_destroy(&(*d)->sv[q]);
    free((*d)->shape.solid);
    free(*d);
    *d = NULL;
}

/* The query's work arrays. */
typedef struct query_arrays {
    double *w, *u, *u2;
    uint8_t *inside, *ok;
    float *ref;
} query_arrays;

static void arrays_free(query_arrays *A, dist_ctx *d)
{
    hv_free(A->w);
    hv_free(A->u);
    hv_free(A->u2);
    free(A->inside);
    free(A->ok);
    hv_free(A->ref);
    for (int a = 0; a < 3; a++)
        hv_free(d->X[a]);
    free(d->region);
}

static hv_status arrays_alloc(query_arrays *A, dist_ctx *d)
{
    A->w = hv_calloc(d->count, sizeof *A->w);
    A->u = hv_malloc(d->count * sizeof *A->u);
    A->u2 = hv_malloc(d->count * sizeof *A->u2);
    A->inside = calloc(d->count, 1);
    A->ok = calloc(d->count, 1);
    A->ref = hv_malloc(d->count * sizeof *A->ref);
    int bad = !A->w || !A->u || !A->u2 || !A->inside || !A->ok || !A->ref;
    for (int a = 0; !bad && a < d->dim; a++)
        bad = !(d->X[a] = hv_malloc(d->nface[a] * sizeof(float)));
    if (bad)
        return hv__error(HV_ERR_NOMEM, "distance: out of memory for a %d x %d x %d grid", d->n[0],
                         d->n[1], d->n[2]);
    return HV_OK;
}

/* dist has the object's shape. */
static hv_status check_shape(const hv_distance *D, const hv_grid *g)
{
    const hv_grid *s = &D->shape;
    if (g->dim != s->dim || g->n[0] != s->n[0] || g->n[1] != s->n[1] || g->n[2] != s->n[2] ||
        g->h != s->h)
        return hv__error(HV_ERR_INVALID_ARG,
                         "hv_distance_query: the grid is %d x %d x %d (h = %g), the object's "
                         "%d x %d x %d (h = %g)",
                         g->n[0], g->n[1], g->n[2], g->h, s->n[0], s->n[1], s->n[2], s->h);
    return HV_OK;
}

/* Splats the sources and labels the regions that hold one. */
static hv_status query_sources(hv_distance *D, dist_ctx *d, const hv_distance_sources *src,
                               query_arrays *A, hv_distance_stats *S)
{
    for (size_t c = 0; c < d->count; c++)
        A->ref[c] = INFINITY;
    hv_status st = hv__dist_splat(&D->shape, NULL, src, A->w, A->ref, &S->sources_in_solid);
    if (st)
        return st;
    for (size_t c = 0; c < d->count; c++)
        S->source_cells += A->w[c] > 0;
    if ((st = hv__dist_no_source(S)))
        return st;
    return hv__dist_label_regions(d, A->w, &S->regions, &S->unreachable_cells);
}

hv_status hv_distance_query(hv_distance *D, const hv_distance_sources *src, hv_grid *g,
                            hv_distance_stats *stats)
{
    const double t_start = hv_now();
    if (!D || !src || !g)
        return hv__error(HV_ERR_INVALID_ARG, "hv_distance_query: NULL argument");
    hv_status st = hv__dist_check_opts(&D->o, src);
    if (st || (st = check_shape(D, g)))
        return st;
    hv_distance_stats lst;
    hv_distance_stats *S = stats ? stats : &lst;
    memset(S, 0, sizeof *S);
    S->t_setup = D->t_setup;
    D->t_setup = 0;

    dist_ctx d = {0};
    hv__dist_box_init(&d, D->shape.dim, D->shape.n, D->shape.h, D->shape.solid);
    d.whole = 1;
    d.band = D->band;
    query_arrays A = {0};
    local_solves L = {&d, D, 0};
    const hv_dist_hooks hk = {&L, NULL, local_solve};
    d.hk = &hk;
    double t0 = hv_now();
    if ((st = arrays_alloc(&A, &d)) || (st = query_sources(D, &d, src, &A, S)))
        goto done;
    S->t = D->o.t_scale * d.h * d.h;
    S->t_splat = hv_now() - t0;
    if (D->o.backend == HV_BACKEND_OPENCL) { /* the rest on the device (fp64 devices) */
        int handled = 0;
        hv_grid dev = D->shape;
        dev.v = g->v;
        st = hv__distance_heat_cl(&dev, &D->o, D->sv[2], d.region, S->regions, A.w, A.ref, S,
                                  &handled);
        if (st || handled)
            goto done;
        /* no fp64 device: the host's whole stages, with the device's solvers,
         * made by the first query */
        if (!D->sv[0]) {
            const double t1 = hv_now();
            if ((st = make_heat_steps(D)))
                goto done;
            S->t_setup += hv_now() - t1;
        }
    }
    st = hv__dist_march(&d, &D->o, A.w, A.u, A.u2, A.inside, A.ok, A.ref, g->v, S);
    S->poisson_restarts = L.restarts;
done:
    arrays_free(&A, &d);
    S->t_total = hv_now() - t_start + S->t_setup;
    return st;
}

hv_status hv_distance_compute(hv_grid *g, const hv_distance_sources *src,
                              const hv_distance_opts *opts, hv_distance_stats *stats)
{
    if (!g || !src)
        return hv__error(HV_ERR_INVALID_ARG, "hv_distance_compute: NULL argument");
    hv_distance *D = NULL;
    hv_status st = hv_distance_create(&D, g, opts);
    if (!st)
        st = hv_distance_query(D, src, g, stats);
    hv_distance_destroy(&D);
    return st;
}

hv_status hv__dist_check_opts(const hv_distance_opts *o, const hv_distance_sources *src)
{
    if (!(o->t_scale > 0) || !isfinite(o->t_scale))
        return hv__error(HV_ERR_INVALID_ARG, "distance: t_scale must be positive, got %g",
                         o->t_scale);
    if (o->max_stages < 1)
        return hv__error(HV_ERR_INVALID_ARG, "distance: max_stages must be >= 1, got %d",
                         o->max_stages);
    if ((src->nvoxels && !src->voxels) || (src->npoints && !src->points))
        return hv__error(HV_ERR_INVALID_ARG, "distance: source counts given without arrays");
    return HV_OK;
}

hv_status hv__dist_no_source(const hv_distance_stats *S)
{
    if (S->source_cells)
        return HV_OK;
    return hv__error(HV_ERR_INVALID_ARG,
                     "distance: no source lands on a fluid cell (%zu in solid cells)",
                     S->sources_in_solid);
}
