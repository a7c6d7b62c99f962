/*
 * The signed heat method for 2D curves on a cell-centred grid (Feng & Crane
 * 2024), the 2D sibling of sdf.c with the same grid choices (docs/METHOD.md,
 * "Discretization", "Signed heat method"):
 * segment normals splatted bilinearly onto cell centres, one backward-Euler
 * diffusion per level (t = (t_scale h)^2, x16 per level until the field reaches
 * across the block), the diffused vectors averaged and normalized on cell faces
 * (MAC), div X, the Neumann Poisson solve whose Laplacian is exactly div(grad),
 * and a shift that puts the length-weighted mean of phi on the curves to zero.
 * By default |phi| is then replaced by the exact distance to the segments.
 *
 * Curve repair (see heatvox/curves.h) plays the part of the mesh repair:
 * without it, two copies of a segment drawn in opposite directions cancel,
 * and a flipped piece turns the sign around it. It lives in sdf2d_repair.c
 * (welding, overlaps, duplicates, chains) and sdf2d_orient.c (which way each
 * chain runs); the exact distance in sdf2d_exact.c. This file holds the
 * options, the grid and the method itself.
 */
#include "heatvox/sdf2d.h"
#include "core/error.h"
#include "sdf2d_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Faces whose diffused vector is below this many times the solver's error
 * bound count as decayed (as in sdf.c). */
#define SDF2_NOISE_FACTOR 4.0
#define SDF2_MAX_LEVELS 9

void hv_sdf2d_opts_default(hv_sdf2d_opts *o)
{
    memset(o, 0, sizeof *o);
    o->res = 256;
    o->pad = 8;
    o->t_scale = 1.0;
    o->repair = 1;
    o->weld_tol = 1e-3;
    o->backend = HV_BACKEND_AUTO;
    o->tol = 1e-10;
}

static hv_status check_opts(const hv_sdf2d_opts *o)
{
    if (!(o->voxel_size >= 0) || !isfinite(o->voxel_size))
        return hv__error(HV_ERR_INVALID_ARG,
                         "sdf2d: voxel size must be positive and finite, got %g", o->voxel_size);
    if (o->voxel_size == 0 && !o->use_bbox && o->res <= 2 * o->pad)
        return hv__error(HV_ERR_INVALID_ARG,
                         "sdf2d: resolution %d leaves no cells inside a padding of %d on each side",
                         o->res, o->pad);
    if (o->voxel_size == 0 && o->res < 2)
        return hv__error(HV_ERR_INVALID_ARG, "sdf2d: resolution must be at least 2, got %d",
                         o->res);
    if (o->pad < 0)
        return hv__error(HV_ERR_INVALID_ARG, "sdf2d: padding must be >= 0 cells, got %d", o->pad);
    if (!(o->t_scale > 0) || !(o->t_scale <= 1e4))
        return hv__error(HV_ERR_INVALID_ARG, "sdf2d: t scale must be in (0, 1e4], got %g",
                         o->t_scale);
    if (!(o->weld_tol >= 0) || !(o->weld_tol < 1))
        return hv__error(HV_ERR_INVALID_ARG, "sdf2d: weld tolerance must be in [0, 1), got %g",
                         o->weld_tol);
    if (o->sign < 0 || o->sign > 2)
        return hv__error(HV_ERR_INVALID_ARG, "sdf2d: unknown sign source %d", o->sign);
    if (o->sign == 2 && !o->repair && !o->heat_magnitude)
        return hv__error(HV_ERR_INVALID_ARG,
                         "sdf2d: the winding-number sign needs the repair's orientation "
                         "(curves as given may run any way)");
    if (!(o->tol >= 1e-12 && o->tol < 1))
        return hv__error(HV_ERR_INVALID_ARG, "sdf2d: tolerance must be in [1e-12, 1), got %g",
                         o->tol);
    if (o->use_bbox)
        for (int a = 0; a < 2; a++)
            if (!isfinite(o->bbox[a]) || !isfinite(o->bbox[a + 2]) ||
                !(o->bbox[a + 2] > o->bbox[a]))
                return hv__error(HV_ERR_INVALID_ARG, "sdf2d: bounding box is empty along %c",
                                 "xy"[a]);
    return HV_OK;
}

/* ---- grid ---- */

static hv_status place_grid(const double *P, size_t np, const hv_sdf2d_opts *o, int n[2], double *h,
                            double origin[2])
{
    double lo[2] = {INFINITY, INFINITY}, hi[2] = {-INFINITY, -INFINITY};
    for (size_t i = 0; i < np; i++)
        for (int a = 0; a < 2; a++) {
            double v = P[2 * i + a];
            if (!isfinite(v))
                return hv__error(HV_ERR_NUMERIC, "sdf2d: point %zu has a non-finite coordinate", i);
            lo[a] = fmin(lo[a], v);
            hi[a] = fmax(hi[a], v);
        }
    if (o->use_bbox) {
        const double *b = o->bbox;
        double L = fmax(b[2] - b[0], b[3] - b[1]);
        *h = o->voxel_size > 0 ? o->voxel_size : L / o->res;
        for (int a = 0; a < 2; a++) {
            double c = ceil((b[a + 2] - b[a]) / *h - 1e-9);
            if (!(c < 1e8))
                return hv__error(HV_ERR_INVALID_ARG, "sdf2d: %g cells along %c", c, "xy"[a]);
            n[a] = c < 1 ? 1 : (int)c;
            origin[a] = b[a];
        }
    } else {
        double L = fmax(hi[0] - lo[0], hi[1] - lo[1]);
        if (o->voxel_size > 0)
            *h = o->voxel_size;
        else if (L > 0)
            *h = L / (o->res - 2 * o->pad);
        else
            return hv__error(HV_ERR_INVALID_ARG,
                             "sdf2d: the curves have no extent (one point); give a voxel size");
        for (int a = 0; a < 2; a++) {
            double c = ceil((hi[a] - lo[a]) / *h - 1e-9) + 2.0 * o->pad;
            if (!(c < 1e8))
                return hv__error(HV_ERR_INVALID_ARG, "sdf2d: %g cells along %c", c, "xy"[a]);
            n[a] = c < 1 ? 1 : (int)c;
            origin[a] = 0.5 * (lo[a] + hi[a]) - 0.5 * n[a] * *h;
        }
    }
    int n3[3] = {n[0], n[1], 1};
    return hv_check_dims(2, n3, *h, 8 * sizeof(double) * 3);
}

/* Bilinear weights of world point (x, y) on the cell centres (clamped). */
static void bilinear(const int n[2], double h, const double org[2], double x, double y,
                     size_t idx[4], double w[4])
{
    double u = (x - org[0]) / h - 0.5, v = (y - org[1]) / h - 0.5;
    int i = (int)floor(u), j = (int)floor(v);
    double fu = u - i, fv = v - j;
    if (i < 0) {
        i = 0;
        fu = 0;
    } else if (i >= n[0] - 1) {
        i = n[0] > 1 ? n[0] - 2 : 0;
        fu = n[0] > 1 ? 1 : 0;
    }
    if (j < 0) {
        j = 0;
        fv = 0;
    } else if (j >= n[1] - 1) {
        j = n[1] > 1 ? n[1] - 2 : 0;
        fv = n[1] > 1 ? 1 : 0;
    }
    int i1 = n[0] > 1 ? i + 1 : i, j1 = n[1] > 1 ? j + 1 : j;
    idx[0] = (size_t)i + (size_t)n[0] * j;
    idx[1] = (size_t)i1 + (size_t)n[0] * j;
    idx[2] = (size_t)i + (size_t)n[0] * j1;
    idx[3] = (size_t)i1 + (size_t)n[0] * j1;
    w[0] = (1 - fu) * (1 - fv);
    w[1] = fu * (1 - fv);
    w[2] = (1 - fu) * fv;
    w[3] = fu * fv;
}

static hv_status solver_create(hv_solver **s, const hv_problem *p, const hv_solver_opts *so)
{
    hv_status st = hv_solver_create(s, p, so);
    if (st == HV_ERR_UNSUPPORTED && so->backend == HV_BACKEND_AUTO) {
        hv_solver_opts mg = *so;
        mg.backend = HV_BACKEND_MG;
        st = hv_solver_create(s, p, &mg);
    }
    return st;
}

/* ---- the method ---- */

/* Points at the end of an open chain: used by exactly one segment. */
static hv_status open_ends(size_t np, const sdf2d_seg *S, size_t ns, size_t *ends)
{
    uint8_t *deg = calloc(np ? np : 1, 1);
    if (!deg)
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for %zu points", np);
    for (size_t k = 0; k < ns; k++) {
        deg[S[k].a] += deg[S[k].a] < 2;
        deg[S[k].b] += deg[S[k].b] < 2;
    }
    size_t e = 0;
    for (size_t k = 0; k < np; k++)
        e += deg[k] == 1;
    free(deg);
    *ends = e;
    return HV_OK;
}

/* What the stages of hv_curves_sdf share: the grid, the segments and the
 * fields, all owned here (run_free). */
typedef struct sdf2d_run {
    const double *P;
    int n[2];
    double h, org[2];
    size_t count;
    sdf2d_seg *Sg;
    size_t ns;
    double *samp; /* x, y, length of each sample of the curves */
    size_t nsamp;
    double *Y;    /* the splatted normals, x then y */
    double f2;    /* |Y|^2 */
    double *Ylev; /* the diffused normals of each level */
    int nlev;
    double tau[SDF2_MAX_LEVELS];
    double *rhs, *phi;
    hv_solver *solver;
    hv_solver_opts so;
    hv_sdf2d_stats *S;
} sdf2d_run;

static void run_free(sdf2d_run *r)
{
    hv_solver_destroy(&r->solver);
    free(r->Sg);
    free(r->Y);
    free(r->Ylev);
    free(r->rhs);
    free(r->phi);
    free(r->samp);
}

/* The segments of the polylines, each closed one with its closing segment. */
static hv_status curve_segments(const hv_curves *c, sdf2d_run *r)
{
    r->Sg = malloc((hv_curves_segments(c) + 1) * sizeof *r->Sg);
    if (!r->Sg)
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the segments");
    size_t ns = 0;
    for (size_t k = 0; k < c->nlines; k++) {
        size_t a = c->start[k], b = c->start[k + 1];
        if (b > c->npoints || b < a + 2)
            return hv__error(HV_ERR_INVALID_ARG, "sdf2d: polyline %zu has a bad point range", k);
        for (size_t i = a; i + 1 < b; i++)
            r->Sg[ns++] = (sdf2d_seg){(uint32_t)i, (uint32_t)(i + 1)};
        if (c->closed[k] && b - a > 2)
            r->Sg[ns++] = (sdf2d_seg){(uint32_t)(b - 1), (uint32_t)a};
    }
    r->ns = ns;
    return HV_OK;
}

/* The sign: the winding number of the repaired curves where the heat
 * method's would depend on the block (open chains, or curves beyond the
 * block); sdf2d_winding.c. */
static hv_status choose_sign(const hv_curves *c, const hv_sdf2d_opts *o, sdf2d_run *r, int *wn_sign)
{
    *wn_sign = 0;
    if (!o->heat_magnitude) {
        hv_status st = open_ends(c->npoints, r->Sg, r->ns, &r->S->open_ends);
        if (st)
            return st;
        int cut = 0;
        for (size_t k = 0; k < c->npoints && !cut; k++)
            for (int a = 0; a < 2; a++)
                cut |= r->P[2 * k + a] < r->org[a] || r->P[2 * k + a] > r->org[a] + r->n[a] * r->h;
        *wn_sign = o->sign == 2 || (o->sign == 0 && o->repair && (r->S->open_ends > 0 || cut));
    }
    r->S->sign = *wn_sign ? 2 : 1;
    return HV_OK;
}

/* 2. Length-weighted normals (right-hand side of each segment), splatted
 * from samples at most h/2 apart that the shift reuses. */
static hv_status splat_normals(sdf2d_run *r)
{
    hv_status st = hv__progress(0.05, "splat");
    if (st)
        return st;
    double tt = hv_now();
    const double *P = r->P, h = r->h;
    const size_t count = r->count;
    size_t cap = 0;
    for (size_t k = 0; k < r->ns; k++)
        cap += (size_t)ceil(sdf2d_seg_len(P, r->Sg[k]) / (0.5 * h)) + 1;
    r->samp = malloc(3 * cap * sizeof *r->samp); /* x, y, length */
    r->Y = calloc(2 * count, sizeof *r->Y);
    if (!r->samp || !r->Y)
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the surface field");
    double *Y = r->Y, *samp = r->samp;
    size_t nsamp = 0;
    for (size_t k = 0; k < r->ns; k++) {
        const double *p = P + 2 * r->Sg[k].a, *q = P + 2 * r->Sg[k].b;
        double L = sdf2d_seg_len(P, r->Sg[k]);
        int pieces = (int)ceil(L / (0.5 * h));
        pieces = pieces < 1 ? 1 : pieces;
        double nx = (q[1] - p[1]) / L, ny = -(q[0] - p[0]) / L, w = L / pieces;
        for (int m = 0; m < pieces; m++) {
            double t = (m + 0.5) / pieces;
            double x = p[0] + t * (q[0] - p[0]), y = p[1] + t * (q[1] - p[1]);
            size_t idx[4];
            double wt[4];
            bilinear(r->n, h, r->org, x, y, idx, wt);
            for (int b = 0; b < 4; b++) {
                Y[idx[b]] += wt[b] * w * nx / (h * h);
                Y[count + idx[b]] += wt[b] * w * ny / (h * h);
            }
            samp[3 * nsamp] = x;
            samp[3 * nsamp + 1] = y;
            samp[3 * nsamp + 2] = w;
            nsamp++;
        }
    }
    r->nsamp = nsamp;
    double f2 = 0;
    for (size_t i = 0; i < 2 * count; i++)
        f2 += Y[i] * Y[i];
    r->f2 = f2;
    r->S->t_splat = hv_now() - tt;
    return HV_OK;
}

/* 3. Diffuse: levels t, 16t, ... until the field reaches across the block;
 * tau[k], the length below which level k's vectors are the solver's noise. */
static hv_status diffuse(sdf2d_run *r, const hv_sdf2d_opts *o)
{
    double tt = hv_now();
    const size_t count = r->count;
    const double h = r->h;
    double diag = hypot(r->n[0], r->n[1]);
    double reach = o->t_scale * 0.5 * log(1.0 / o->tol);
    int nlev = 1;
    while (reach < diag && nlev < SDF2_MAX_LEVELS) {
        reach *= 4;
        nlev++;
    }
    r->S->levels = r->nlev = nlev;
    r->Ylev = malloc((size_t)nlev * 2 * count * sizeof *r->Ylev);
    if (!r->Ylev)
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for %d diffused fields", 2 * nlev);
    hv_solver_opts_default(&r->so);
    r->so.backend = o->backend;
    r->so.tol = o->tol;
    r->so.max_iter = 200;
    hv_status st;
    for (int k = 0; k < nlev; k++) {
        if ((st = hv__progress(0.1 + 0.5 * k / nlev, "diffuse")))
            return st;
        double t = (o->t_scale * h) * (o->t_scale * h) * pow(16.0, k);
        hv_problem pb = {2, {r->n[0], r->n[1], 1}, h, NULL, 1.0, t};
        if ((st = solver_create(&r->solver, &pb, &r->so)))
            return st;
        double relres = 0;
        for (int b = 0; b < 2; b++) {
            hv_solve_info info;
            if ((st = hv_solver_solve_d(r->solver, r->Y + b * count,
                                        r->Ylev + ((size_t)k * 2 + b) * count, &info)))
                return st;
            relres = fmax(relres, info.relres);
            r->S->backend = info.backend;
        }
        hv_solver_destroy(&r->solver);
        r->tau[k] = SDF2_NOISE_FACTOR * fmax(relres, 1e-15) * sqrt(r->f2);
    }
    r->S->t_diffuse = hv_now() - tt;
    return HV_OK;
}

/* 4. Normalize on faces, the first level not decayed there; rhs = -div X. */
static hv_status face_divergence(sdf2d_run *r)
{
    hv_status st = hv__progress(0.6, "normalize");
    if (st)
        return st;
    double tt = hv_now();
    const size_t count = r->count;
    const int *n = r->n, nlev = r->nlev;
    const double h = r->h;
    r->rhs = calloc(count, sizeof *r->rhs);
    r->phi = calloc(count, sizeof *r->phi);
    if (!r->rhs || !r->phi)
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the divergence");
    double *rhs = r->rhs;
    const double *Ylev = r->Ylev;
    size_t dead_faces = 0;
    const size_t step[2] = {1, (size_t)n[0]};
    for (int a = 0; a < 2; a++)
        for (int j = a == 1 ? 1 : 0; j < n[1]; j++)
            for (int i = a == 0 ? 1 : 0; i < n[0]; i++) {
                /* the interior face between cells lo and hi along axis a */
                size_t hi = (size_t)i + step[1] * j, lo = hi - step[a];
                double flux = 0;
                int dead = 1;
                for (int k = 0; k < nlev && dead; k++) {
                    const double *Yx = Ylev + (size_t)k * 2 * count, *Yy = Yx + count;
                    double vx = 0.5 * (Yx[lo] + Yx[hi]), vy = 0.5 * (Yy[lo] + Yy[hi]);
                    double len = hypot(vx, vy);
                    if (len > r->tau[k]) {
                        flux = (a == 0 ? vx : vy) / len;
                        dead = 0;
                    }
                }
                dead_faces += (size_t)dead;
                rhs[hi] += flux / h; /* -div: the face adds -flux/h to hi's div */
                rhs[lo] -= flux / h;
            }
    r->S->dead_faces += dead_faces;
    free(r->Ylev);
    r->Ylev = NULL;
    r->S->t_normalize = hv_now() - tt;
    return HV_OK;
}

/* 6. Shift: the length-weighted mean of phi on the curves goes to zero. */
static void shift_to_curves(sdf2d_run *r)
{
    double num = 0, den = 0;
    const double *samp = r->samp;
    for (size_t s = 0; s < r->nsamp; s++) {
        size_t idx[4];
        double wt[4], v = 0;
        bilinear(r->n, r->h, r->org, samp[3 * s], samp[3 * s + 1], idx, wt);
        for (int b = 0; b < 4; b++)
            v += wt[b] * r->phi[idx[b]];
        num += samp[3 * s + 2] * v;
        den += samp[3 * s + 2];
    }
    double shift = den > 0 ? num / den : 0;
    for (size_t i = 0; i < r->count; i++)
        r->phi[i] -= shift;
}

/* 5. Poisson: -Lap phi = -div X, Neumann walls, mean-free; then the shift. */
static hv_status solve_poisson(sdf2d_run *r)
{
    hv_status st = hv__progress(0.65, "poisson");
    if (st)
        return st;
    double tt = hv_now();
    hv_problem pb = {2, {r->n[0], r->n[1], 1}, r->h, NULL, 0.0, 1.0};
    if ((st = solver_create(&r->solver, &pb, &r->so)))
        return st;
    hv_solve_info info;
    if ((st = hv_solver_solve_d(r->solver, r->rhs, r->phi, &info)))
        return st;
    hv_solver_destroy(&r->solver);
    shift_to_curves(r);
    r->S->t_poisson = hv_now() - tt;
    return HV_OK;
}

/* g = the exact distance, signed by the winding number (wn_sign) or by phi. */
static hv_status exact_signed(sdf2d_run *r, int wn_sign, hv_grid *g)
{
    hv_status st = hv__progress(0.85, "distance");
    if (st)
        return st;
    double tt = hv_now();
    const size_t count = r->count;
    if (!r->rhs && !(r->rhs = malloc(count * sizeof *r->rhs)))
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the distance");
    double *dist = r->rhs; /* rhs is spent: it holds the distance */
    if ((st = hv__sdf2d_exact_distance(r->P, r->Sg, r->ns, r->n, r->h, r->org, dist)))
        return st;
    if (wn_sign) {
        int8_t *sg = malloc(count);
        if (!sg)
            return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the sign");
        st = hv__sdf2d_winding_sign(r->P, r->Sg, r->ns, r->n, r->h, r->org, dist, sg,
                                    &r->S->winding_evals);
        for (size_t i = 0; i < count && !st; i++)
            g->v[i] = (float)(sg[i] < 0 ? -dist[i] : dist[i]);
        free(sg);
        if (st)
            return st;
    } else {
        for (size_t i = 0; i < count; i++)
            g->v[i] = (float)(r->phi[i] < 0 ? -dist[i] : dist[i]);
    }
    r->S->t_distance = hv_now() - tt;
    return HV_OK;
}

/* 7. Output, with the exact distance unless asked for the heat magnitude.
 * *g is the caller's, to destroy also on failure. */
static hv_status make_output(sdf2d_run *r, const hv_sdf2d_opts *o, int wn_sign, hv_grid **g)
{
    double org3[3] = {r->org[0], r->org[1], 0};
    int n3[3] = {r->n[0], r->n[1], 1};
    hv_status st = hv_grid_create(g, 2, n3, r->h, org3);
    if (st)
        return st;
    if (!o->heat_magnitude)
        return exact_signed(r, wn_sign, *g);
    for (size_t i = 0; i < r->count; i++)
        (*g)->v[i] = (float)r->phi[i];
    return HV_OK;
}

hv_status hv_curves_sdf(const hv_curves *c, const hv_sdf2d_opts *opts, hv_grid **out,
                        hv_sdf2d_stats *stats)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_curves_sdf: out is NULL");
    *out = NULL;
    if (!c || !c->pts || !c->start || c->nlines == 0)
        return hv__error(HV_ERR_INVALID_ARG, "hv_curves_sdf: no curves");
    hv_sdf2d_opts o;
    if (opts)
        o = *opts;
    else
        hv_sdf2d_opts_default(&o);
    hv_status st = check_opts(&o);
    if (st)
        return st;
    if (c->npoints >= UINT32_MAX)
        return hv__error(HV_ERR_INVALID_ARG, "sdf2d: too many points (%zu)", c->npoints);
    hv_sdf2d_stats S;
    memset(&S, 0, sizeof S);
    double t0 = hv_now();

    sdf2d_run r;
    memset(&r, 0, sizeof r);
    r.P = c->pts;
    r.S = &S;
    if ((st = place_grid(c->pts, c->npoints, &o, r.n, &r.h, r.org)))
        return st;
    S.n[0] = r.n[0];
    S.n[1] = r.n[1];
    S.h = r.h;
    S.origin[0] = r.org[0];
    S.origin[1] = r.org[1];
    r.count = (size_t)r.n[0] * r.n[1];
    hv_grid *g = NULL;
    int wn_sign = 0;
    if ((st = curve_segments(c, &r)))
        goto done;
    S.segments_in = r.ns;

    /* 1. Repair. */
    if ((st = hv__progress(0.0, "repair")))
        goto done;
    if (o.repair &&
        (st = hv__sdf2d_repair(r.P, c->npoints, &r.Sg, &r.ns, o.weld_tol * r.h, r.h, &S)))
        goto done;
    S.segments_out = r.ns;
    S.t_repair = hv_now() - t0;
    if (r.ns == 0) {
        st = hv__error(HV_ERR_INVALID_ARG, "sdf2d: no segment of non-zero length");
        goto done;
    }
    if ((st = choose_sign(c, &o, &r, &wn_sign)))
        goto done;
    /* The winding-number sign needs no heat method. */
    if (!wn_sign && ((st = splat_normals(&r)) || (st = diffuse(&r, &o)) ||
                     (st = face_divergence(&r)) || (st = solve_poisson(&r))))
        goto done;
    if ((st = make_output(&r, &o, wn_sign, &g)))
        goto done;
    if ((st = hv__progress(1.0, "done")))
        goto done;
    S.t_total = hv_now() - t0;
    *out = g;
    g = NULL;
done:
    run_free(&r);
    hv_grid_destroy(&g);
    if (stats)
        *stats = S;
    return st;
}
