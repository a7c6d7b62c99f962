/* Extension of scalar and vector fields off a level set by diffusion (heat.h):
 * the vector heat method's split (Sharp, Soliman & Crane 2019) in flat space,
 * where the connection Laplacian acts on each component, evaluated at the
 * closest point where phi is a distance. This file holds the extender's
 * lifecycle and the pipeline of hv_extend_many: the per-cell passes are in
 * extend_eval.c, the levels in extend_levels.c, the band solve in
 * extend_band.c and the whole extension on a device in extend_cl.c. */
#include "heatvox/heat.h"
#include "core/error.h"
#include "extend_cl.h"
#include "extend_internal.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

void hv_extend_opts_default(hv_extend_opts *o)
{
    memset(o, 0, sizeof *o);
    o->band = 1.5;
    o->t_scale = 0.25;
    o->closest_point = 1;
    o->out_band = 0;
    o->background = 0;
    o->max_levels = 6;
    o->backend = HV_BACKEND_AUTO;
    o->tol = 1e-10;
}

hv_status hv_extender_create(hv_extender **out, int dim, const int n[3], double h,
                             const uint8_t *solid, const hv_extend_opts *opts)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_extender_create: out is NULL");
    *out = NULL;
    /* The dense arrays come with the first hv_extend_many (dense_arrays): an
     * extender for hv_extend_tiles allocates nothing of the block's size. */
    if (dim != 2 && dim != 3)
        return hv__error(HV_ERR_INVALID_ARG, "extend: grid dimension must be 2 or 3, got %d", dim);
    for (int a = 0; a < dim; a++)
        if (!n || n[a] <= 0)
            return hv__error(HV_ERR_INVALID_ARG, "extend: grid size along %c must be positive",
                             "xyz"[a]);
    if (!(h > 0) || !isfinite(h))
        return hv__error(HV_ERR_INVALID_ARG, "extend: voxel size must be positive, got %g", h);
    hv_extend_opts o;
    if (opts)
        o = *opts;
    else
        hv_extend_opts_default(&o);
    if (!(o.band > 0) || !isfinite(o.band))
        return hv__error(HV_ERR_INVALID_ARG, "extend: band must be positive (voxels), got %g",
                         o.band);
    if (!(o.t_scale > 0) || !isfinite(o.t_scale))
        return hv__error(HV_ERR_INVALID_ARG, "extend: t_scale must be positive, got %g", o.t_scale);
    if (!(o.out_band >= 0) || !isfinite(o.out_band))
        return hv__error(HV_ERR_INVALID_ARG,
                         "extend: out_band must be >= 0 (0 = every cell), got %g", o.out_band);
    if (o.max_levels < 1 || o.max_levels > MAX_LEVELS)
        return hv__error(HV_ERR_INVALID_ARG, "extend: max_levels must be in 1..%d, got %d",
                         MAX_LEVELS, o.max_levels);
    if (!(o.tol >= 1e-12) || !(o.tol < 1))
        return hv__error(HV_ERR_INVALID_ARG, "extend: tol must be in [1e-12, 1), got %g", o.tol);
    hv_extender *e = calloc(1, sizeof *e);
    if (!e)
        return hv__error(HV_ERR_NOMEM, "extend: out of memory");
    e->dim = dim;
    e->n[0] = n[0];
    e->n[1] = n[1];
    e->n[2] = dim == 3 ? n[2] : 1;
    e->h = h;
    e->count = (size_t)e->n[0] * e->n[1] * e->n[2];
    e->o = o;
    if (solid) {
        e->solid = malloc(e->count);
        if (e->solid)
            memcpy(e->solid, solid, e->count);
    }
    if (solid && !e->solid) {
        hv_extender_destroy(&e);
        return hv__error(HV_ERR_NOMEM, "extend: out of memory for a %d x %d x %d grid", e->n[0],
                         e->n[1], e->n[2]);
    }
    *out = e;
    return HV_OK;
}

void hv_extender_destroy(hv_extender **ep)
{
    if (!ep || !*ep)
        return;
    hv_extender *e = *ep;
    for (int l = 0; l < MAX_LEVELS; l++)
        hv_solver_destroy(&e->sv[l]);
    hv_free(e->sol);
    hv_free(e->fd);
    hv_free(e->ud);
    hv_free(e->w);
    hv_free(e->bf);
    hv_free(e->bu0);
    hv_free(e->bu1);
    hv_free(e->bneed);
    hv_free(e->pending);
    hv_free(e->bg0);
    hv_free(e->bg1);
    hv__extend_tiles_cl_destroy(&e->tcl);
    hv__extend_cl_destroy(&e->cl);
    hv__extend_sparse_destroy(&e->sp);
    free(e->solid);
    free(e);
    *ep = NULL;
}

/* The dense path's per-cell arrays, on first use: the weights, the box
 * solves' right-hand side and solution (double). */
static hv_status dense_arrays(hv_extender *e)
{
    if (e->w && e->fd && e->ud)
        return HV_OK;
    hv_status st = hv_check_dims(e->dim, e->n, e->h, 2 * sizeof(double) + 6 * sizeof(float));
    if (st)
        return st;
    if (!e->fd)
        e->fd = hv_malloc(e->count * sizeof(double));
    if (!e->ud)
        e->ud = hv_malloc(e->count * sizeof(double));
    if (!e->w)
        e->w = hv_malloc(e->count * sizeof(float));
    if (!e->fd || !e->ud || !e->w)
        return hv__error(HV_ERR_NOMEM, "extend: out of memory for a %d x %d x %d grid", e->n[0],
                         e->n[1], e->n[2]);
    return HV_OK;
}

static hv_status ensure_solutions(hv_extender *e, int k)
{
    if (k > e->capsol) {
        hv_free(e->sol);
        e->capsol = 0;
        if (!(e->sol = hv_malloc(e->count * (size_t)k * sizeof(float))))
            return hv__error(HV_ERR_NOMEM, "extend: out of memory for %d solutions", k);
        e->capsol = k;
    }
    e->nsol = k;
    return HV_OK;
}

/* The box a band solve is weighed against (hv__extend_band_build takes the
 * band when it is under half of it). An output band always takes the band:
 * its cells are what the output needs, and hv_extend_tiles solves the same
 * cells, so that both paths give the same values. */
static size_t band_box_cells(const hv_extender *e, const int bn[3])
{
    if (e->o.out_band > 0 || e->dist) /* distributed: level 0 is every rank's band */
        return SIZE_MAX / 4;
    return (size_t)bn[0] * bn[1] * (e->dim == 3 ? bn[2] : 1);
}

/* Distributed: st, or when another rank failed, an error saying so; every
 * rank calls it at the same points (not distributed: st). */
static hv_status agree(const hv_extend_dist *D, hv_status st)
{
    if (D && D->sum(D->user, st != HV_OK) && !st)
        return hv__error(HV_ERR_NUMERIC, "extend: another rank's part of the grid failed");
    return st;
}

/* Distributed: the output cells left on this rank's own cells, over all ranks. */
static size_t left_everywhere(const hv_extender *e, const hv_extend_dist *D)
{
    size_t left = 0;
    for (int k = D->own_lo[2]; k <= D->own_hi[2]; k++)
        for (int j = D->own_lo[1]; j <= D->own_hi[1]; j++) {
            const uint8_t *p = e->pending + (size_t)e->n[0] * (j + (size_t)e->n[1] * k);
            for (int i = D->own_lo[0]; i <= D->own_hi[0]; i++)
                left += p[i] != 0;
        }
    return D->sum(D->user, left);
}

/* Whether the extender runs on the device, decided once: AUTO on a GPU runs
 * the whole extension there (extend_cl.c), as an explicit opencl does. AUTO
 * stays AUTO otherwise: with mg it takes the band solves where they apply
 * (hv__extend_band_allowed), which an explicit fftw does not. Decided on the
 * first dense call:
 * looking for a device loads the OpenCL platforms, which hv_extend_tiles
 * never needs. */
void hv__extend_resolve_backend(hv_extender *e)
{
    if (!e->resolved) {
        e->auto_backend = e->o.backend == HV_BACKEND_AUTO;
        if (hv_backend_resolve(e->o.backend, e->count, e->solid != NULL) == HV_BACKEND_OPENCL)
            e->o.backend = HV_BACKEND_OPENCL;
        e->resolved = 1;
    }
}

/* What the stages of hv_extend_many share. The band's arrays are this call's
 * (hv__extend_band_free at the end); need is e->bneed when the band solve
 * applies, NULL otherwise. */
typedef struct extend_run {
    hv_extender *e;
    const hv_extend_dist *D; /* distributed: every rank runs the same stages */
    const float *phi;
    int nfields, nrhs;
    const hv_extend_field *f;
    hv_extend_stats *S;
    uint8_t *need;
    hv_extend_band band;
    ibox band_box, ratio_box;
    size_t npend, npend_all; /* output cells left here, and over all ranks */
} extend_run;

/* The right-hand sides the fields take (*nrhs), the fields checked. */
static hv_status count_rhs(int nfields, const hv_extend_field *f, int *nrhs)
{
    *nrhs = 1;
    if (nfields > MAX_FIELDS_PER_CALL)
        return hv__error(HV_ERR_INVALID_ARG, "extend: %d fields in one call, at most %d", nfields,
                         MAX_FIELDS_PER_CALL);
    for (int i = 0; i < nfields; i++) {
        if (f[i].ncomp < 1 || f[i].ncomp > 3)
            return hv__error(HV_ERR_INVALID_ARG, "extend: field %d has %d components (1 to 3)", i,
                             f[i].ncomp);
        for (int q = 0; q < f[i].ncomp; q++)
            if (!f[i].in[q] || !f[i].out[q])
                return hv__error(HV_ERR_INVALID_ARG, "extend: field %d component %d has no array",
                                 i, q);
        *nrhs += f[i].ncomp == 1 ? 1 : f[i].ncomp + 1;
    }
    return HV_OK;
}

/* The band solve's cell mask (short times, no obstacles; CPU backends only: an
 * explicit fftw or opencl backend gets its own solver) and the output cells'
 * states. Without memory for the mask a single process does without the band
 * solve; a distributed one cannot, its band solve being every rank's level 0. */
static hv_status work_masks(extend_run *r)
{
    hv_extender *e = r->e;
    if (hv__extend_band_allowed(e) && (!r->D || r->D->band0)) {
        if (e->bneed || (e->bneed = hv_malloc(e->count)))
            r->need = e->bneed;
        else if (r->D)
            return hv__error(HV_ERR_NOMEM, "extend: out of memory for the band solve");
    }
    if (!e->pending && !(e->pending = hv_malloc(e->count)))
        return hv__error(HV_ERR_NOMEM, "extend: out of memory");
    return HV_OK;
}

/* One pass over the grid: the weights, the checks, where each output cell is
 * read, the boxes, the band solve's cells; then the sources counted over all
 * ranks. A rank that fails tells the others before the next collective call,
 * and every rank returns (agree). */
static hv_status classify_cells(extend_run *r)
{
    hv_extender *e = r->e;
    const hv_extend_dist *D = r->D;
    hv_extend_stats *S = r->S;
    hv_status st = dense_arrays(e);
    double t0 = hv_now();
    if (!st)
        st = work_masks(r);
    size_t nsrc = 0;
    r->npend = 0;
    if (!st)
        st = hv__extend_classify(e, r->phi, r->nfields, r->f, r->need, &nsrc, &r->npend,
                                 &r->band_box, &r->ratio_box);
    if (!st)
        st = ensure_solutions(e, r->nrhs);
    if ((st = agree(D, st)))
        return st;
    /* Distributed: the closest points past the box, checked against their
     * owners' phi, their stencils marked in the owners' band. */
    if (D && D->rem && (st = agree(D, D->remote(D->user, e, r->phi, r->need, 0))))
        return st;
    S->remote_cells = D && D->rem ? D->rem->cells : 0;
    S->source_cells = nsrc;
    r->npend_all = D ? left_everywhere(e, D) : r->npend;
    if (D ? !D->sum(D->user, nsrc) : !nsrc)
        return hv__error(HV_ERR_INVALID_ARG,
                         "extend: no fluid cell has |phi| < band * h = %g (the level set has no "
                         "zero crossing in the grid, or the band is too thin)",
                         e->o.band * e->h);
    S->t_weights = hv_now() - t0;
    return HV_OK;
}

/* The background on the cells no level will write, then level 0's band: its
 * cells start from the weights, the closest points' stencils and the cells
 * read at themselves. */
static hv_status first_band(extend_run *r)
{
    hv_extender *e = r->e;
    hv_extend_stats *S = r->S;
    hv_status st = HV_OK;
    double t0 = hv_now();
    if (r->npend < e->count)
        hv__extend_fill_background(e, r->nfields, r->f);
    S->t_eval = hv_now() - t0;
    t0 = hv_now();
    if (r->need) {
        int lo[3], bn[3];
        hv__extend_level_box(e, r->band_box.lo, r->band_box.hi, r->ratio_box.lo, r->ratio_box.hi, 0,
                             lo, bn);
        r->band.need = r->need;
        int built =
            hv__extend_band_build(e, &r->band, band_box_cells(e, bn), r->nrhs, e->o.t_scale);
        if (built < 0)
            st = hv__error(HV_ERR_NOMEM, "extend: out of memory for the band solve");
        if (built <= 0)
            hv__extend_band_free(&r->band);
    }
    if ((st = agree(r->D, st)))
        return st;
    S->t_solve = hv_now() - t0;
    return HV_OK;
}

/* Later levels answer for the cells left, read at themselves: on a band around
 * them too when it is small. */
static hv_status level_band(extend_run *r, int l, const int bn[3])
{
    hv_extender *e = r->e;
    uint8_t *need = r->need;
    hv__extend_band_free(&r->band);
#pragma omp parallel for schedule(static)
    for (size_t c = 0; c < e->count; c++)
        need[c] = e->pending[c] != 0;
    r->band.need = need;
    int built = hv__extend_band_build(e, &r->band, band_box_cells(e, bn), r->nrhs,
                                      e->o.t_scale * pow(LEVEL_FACTOR, l));
    if (built < 0)
        return hv__error(HV_ERR_NOMEM, "extend: out of memory for the band solve");
    if (!built)
        hv__extend_band_free(&r->band);
    return HV_OK;
}

/* Level l's solutions into e->sol and its trust bound *thr: on the band, on
 * the ranks (distributed), or on the box [lo, lo + bn). */
static hv_status solve_level(extend_run *r, int l, int band_l, int on_band, const int lo[3],
                             const int bn[3], double *thr)
{
    hv_extender *e = r->e;
    const hv_extend_dist *D = r->D;
    if (D && band_l) {
        /* A rank without band cells reads nothing at this level; the
         * bound is the worst rank's residual's, as one process's. */
        *thr = 0;
        hv_status st =
            on_band ? hv__extend_band_solve(e, &r->band, r->nfields, r->f, thr, r->S) : HV_OK;
        *thr = D->max(D->user, *thr);
        return agree(D, st);
    }
    return on_band ? hv__extend_band_solve(e, &r->band, r->nfields, r->f, thr, r->S)
           : D     ? D->solve(D->user, e, l, r->nrhs, r->nfields, r->f, thr, r->S)
                   : hv__extend_solve_level(e, l, lo, bn, r->nrhs, r->nfields, r->f, thr, r->S);
}

/* The levels: each solves, then reads the cells it can answer for; with an
 * output band they stop at the first that reaches across it. */
static hv_status run_levels(extend_run *r)
{
    hv_extender *e = r->e;
    const hv_extend_dist *D = r->D;
    hv_extend_stats *S = r->S;
    hv_status st = HV_OK;
    const int last =
        e->o.out_band > 0 ? hv__extend_last_level(e, e->o.out_band) : e->o.max_levels - 1;
    for (int l = 0; l <= last && r->npend_all > 0; l++) {
        /* most calls need one level; later ones only reach the far cells */
        if (!D && (st = hv__progress(l ? 0.5 + 0.5 * l / e->o.max_levels : 0.1, "extend")))
            break;
        double thr;
        int lo[3], bn[3];
        hv__extend_level_box(e, r->band_box.lo, r->band_box.hi, r->ratio_box.lo, r->ratio_box.hi, l,
                             lo, bn);
        double t0 = hv_now();
        /* Distributed: the band solve on level 0 only (its reach is what the
         * ghost layer holds); later levels over all ranks. */
        const int band_l = D ? l == 0 && D->band0 : l == 0 || hv__extend_band_level_allowed(e, l);
        if (l > 0 && r->need && band_l && (st = level_band(r, l, bn)))
            break;
        const int on_band = r->band.runs && band_l;
        const uint8_t *trusted = on_band ? r->band.need : NULL;
        if ((st = solve_level(r, l, band_l, on_band, lo, bn, &thr)))
            break;
        /* ... and the owners' solutions there, once level 0 is solved. */
        if (D && D->rem && l == 0 && (st = agree(D, D->remote(D->user, e, r->phi, NULL, 1))))
            break;
        S->t_solve += hv_now() - t0;
        S->levels = l + 1;
        t0 = hv_now();
        hv_extend_counts k;
        hv__extend_eval_level(e, r->phi, r->nfields, r->f, thr, l == last, trusted, &r->ratio_box,
                              &k);
        S->cp_cells += k.cp;
        S->ratio_cells += k.ratio;
        S->weak_cells += k.weak;
        r->npend = k.left;
        r->npend_all = D ? left_everywhere(e, D) : r->npend;
        S->t_eval += hv_now() - t0;
    }
    return st;
}

hv_status hv_extend_many(hv_extender *e, const float *phi, int nfields, const hv_extend_field *f,
                         hv_extend_stats *stats)
{
    double t_start = hv_now();
    if (!e || !phi || nfields < 0 || (nfields > 0 && !f))
        return hv__error(HV_ERR_INVALID_ARG, "hv_extend_many: bad arguments");
    hv_extend_stats lst;
    hv_extend_stats *S = stats ? stats : &lst;
    memset(S, 0, sizeof *S);
    int nrhs;
    hv_status st = count_rhs(nfields, f, &nrhs);
    if (st)
        return st;
    hv__extend_resolve_backend(e);
    if (e->o.backend == HV_BACKEND_OPENCL) {
        if ((st = hv_check_finite(phi, e->count, "the level set")))
            return st;
        const hv_extend_grid g = {e,        e->dim, {e->n[0], e->n[1], e->n[2]}, e->h, e->count,
                                  e->solid, &e->o};
        st = hv__extend_cl_run(&e->cl, &g, phi, nfields, f, nrhs, S);
        S->t_total = hv_now() - t_start;
        return st;
    }
    extend_run r;
    memset(&r, 0, sizeof r);
    r.e = e;
    r.D = e->dist;
    r.phi = phi;
    r.nfields = nfields;
    r.nrhs = nrhs;
    r.f = f;
    r.S = S;
    if ((st = classify_cells(&r)))
        return st;
    if ((st = first_band(&r))) {
        hv__extend_band_free(&r.band);
        return st;
    }
    st = run_levels(&r);
    hv__extend_band_free(&r.band);
    S->t_total = hv_now() - t_start;
    return st;
}

static hv_status check_grid(const hv_extender *e, const hv_grid *g, const hv_grid *phi,
                            const char *what)
{
    if (!g)
        return hv__error(HV_ERR_INVALID_ARG, "extend: %s is NULL", what);
    if (g->dim != e->dim || g->n[0] != e->n[0] || g->n[1] != e->n[1] || g->n[2] != e->n[2] ||
        fabs(g->h - e->h) > 1e-9 * e->h)
        return hv__error(
            HV_ERR_INVALID_ARG,
            "extend: %s is %dD %d x %d x %d with h = %g; the extender was made for %dD "
            "%d x %d x %d with h = %g",
            what, g->dim, g->n[0], g->n[1], g->n[2], g->h, e->dim, e->n[0], e->n[1], e->n[2], e->h);
    for (int a = 0; a < 3; a++)
        if (fabs(g->origin[a] - phi->origin[a]) > 1e-6 * e->h)
            return hv__error(HV_ERR_INVALID_ARG,
                             "extend: %s has origin (%g %g %g), the level set (%g %g %g)", what,
                             g->origin[0], g->origin[1], g->origin[2], phi->origin[0],
                             phi->origin[1], phi->origin[2]);
    return HV_OK;
}

hv_status hv_extend_scalar(hv_extender *e, const hv_grid *phi, const hv_grid *field, hv_grid *out,
                           hv_extend_stats *stats)
{
    if (!e || !phi)
        return hv__error(HV_ERR_INVALID_ARG, "hv_extend_scalar: NULL argument");
    hv_status st;
    if ((st = check_grid(e, phi, phi, "the level set")) ||
        (st = check_grid(e, field, phi, "the field")) ||
        (st = check_grid(e, out, phi, "the output")))
        return st;
    hv_extend_field f = {1, {field->v, NULL, NULL}, {out->v, NULL, NULL}};
    return hv_extend_many(e, phi->v, 1, &f, stats);
}

hv_status hv_extend_vec3(hv_extender *e, const hv_grid *phi, const hv_grid *const in[3],
                         hv_grid *const out[3], hv_extend_stats *stats)
{
    if (!e || !phi || !in || !out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_extend_vec3: NULL argument");
    hv_status st;
    if ((st = check_grid(e, phi, phi, "the level set")))
        return st;
    hv_extend_field f = {3, {NULL, NULL, NULL}, {NULL, NULL, NULL}};
    static const char *names[3] = {"the x component", "the y component", "the z component"};
    for (int q = 0; q < 3; q++) {
        if ((st = check_grid(e, in[q], phi, names[q])) ||
            (st = check_grid(e, out[q], phi, "an output")))
            return st;
        f.in[q] = in[q]->v;
        f.out[q] = out[q]->v;
    }
    return hv_extend_many(e, phi->v, 1, &f, stats);
}

/* ---------- fields on the device (heat.h, opencl.h) ---------- */

static hv_extend_grid device_grid(const hv_extender *e)
{
    const hv_extend_grid g = {e,        e->dim, {e->n[0], e->n[1], e->n[2]}, e->h, e->count,
                              e->solid, &e->o};
    return g;
}

hv_status hv_opencl_extender_create(hv_extender **out, int dim, const int n[3], double h,
                                    const uint8_t *solid, const hv_extend_opts *opts,
                                    cl_context ctx, cl_device_id dev, cl_command_queue queue)
{
    if (out)
        *out = NULL;
    if (!ctx || !dev || !queue)
        return hv__error(HV_ERR_INVALID_ARG,
                         "hv_opencl_extender_create: the context, device and queue are required");
    hv_extend_opts o;
    if (opts)
        o = *opts;
    else
        hv_extend_opts_default(&o);
    o.backend = HV_BACKEND_OPENCL;
    hv_status st = hv_extender_create(out, dim, n, h, solid, &o);
    if (st)
        return st;
    hv_extender *e = *out;
    e->resolved = 1;
    const hv_extend_grid g = device_grid(e);
    st = hv__extend_cl_prepare(&e->cl, &g, ctx, dev, queue);
    if (st)
        hv_extender_destroy(out);
    return st;
}

/* An extender whose work runs on the device, with its state made. */
static hv_status device_extender(hv_extender *e, const char *who)
{
    if (!e)
        return hv__error(HV_ERR_INVALID_ARG, "%s: the extender is NULL", who);
    hv__extend_resolve_backend(e);
    if (e->o.backend != HV_BACKEND_OPENCL)
        return hv__error(HV_ERR_UNSUPPORTED, "%s: the extender runs on the %s backend, not opencl",
                         who, hv_backend_name(e->o.backend));
    const hv_extend_grid g = device_grid(e);
    return hv__extend_cl_prepare(&e->cl, &g, NULL, NULL, NULL);
}

hv_status hv_opencl_extend(hv_extender *e, cl_mem phi, int nfields, const hv_opencl_field *f,
                           hv_extend_stats *stats)
{
    double t_start = hv_now();
    hv_extend_stats lst;
    hv_extend_stats *S = stats ? stats : &lst;
    memset(S, 0, sizeof *S);
    hv_status st = device_extender(e, "hv_opencl_extend");
    if (st)
        return st;
    if (nfields < 0 || nfields > MAX_FIELDS_PER_CALL || (nfields > 0 && !f))
        return hv__error(HV_ERR_INVALID_ARG, "hv_opencl_extend: %d fields (0 to %d, with an array)",
                         nfields, MAX_FIELDS_PER_CALL);
    int nrhs = 1;
    for (int i = 0; i < nfields; i++) {
        if (f[i].ncomp < 1 || f[i].ncomp > 3)
            return hv__error(HV_ERR_INVALID_ARG, "extend: field %d has %d components (1 to 3)", i,
                             f[i].ncomp);
        nrhs += f[i].ncomp == 1 ? 1 : f[i].ncomp + 1;
    }
    const hv_extend_grid g = device_grid(e);
    st = hv__extend_cl_run_dev(e->cl, &g, phi, nfields, f, nrhs, S);
    S->t_total = hv_now() - t_start;
    return st;
}

hv_status hv_opencl_extend_tiles(hv_extender *e, const hv_opencl_tiles *phi, int nfields,
                                 const hv_opencl_tiles_field *f, hv_extend_stats *stats)
{
    const double t_start = hv_now();
    hv_extend_stats lst;
    hv_extend_stats *S = stats ? stats : &lst;
    memset(S, 0, sizeof *S);
    hv_status st = device_extender(e, "hv_opencl_extend_tiles");
    if (st)
        return st;
    if (!phi || nfields < 0 || nfields > MAX_FIELDS_PER_CALL || (nfields > 0 && !f))
        return hv__error(HV_ERR_INVALID_ARG, "hv_opencl_extend_tiles: bad arguments");
    if ((st = hv__extend_tiles_check(e)))
        return st;
    for (int i = 0; i < nfields; i++)
        if (f[i].ncomp != 1 && f[i].ncomp != 3)
            return hv__error(HV_ERR_INVALID_ARG, "extend: field %d has %d components (1 or 3)", i,
                             f[i].ncomp);
    S->tiles = phi->count;
    S->on_device = 1;
    st = hv__extend_tiles_cl_run_dev(e, phi, nfields, f, S);
    S->t_total = hv_now() - t_start;
    return st;
}

hv_status hv_opencl_extender_queue(hv_extender *e, cl_context *ctx, cl_device_id *dev,
                                   cl_command_queue *queue)
{
    hv_status st = device_extender(e, "hv_opencl_extender_queue");
    if (!st)
        hv__extend_cl_queue(e->cl, ctx, dev, queue);
    return st;
}
