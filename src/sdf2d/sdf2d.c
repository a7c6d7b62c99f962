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
    double t0 = hv_now(), tt = t0;

    int n[2] = {0, 0};
    double h = 0, org[2] = {0, 0};
    if ((st = place_grid(c->pts, c->npoints, &o, n, &h, org)))
        return st;
    S.n[0] = n[0];
    S.n[1] = n[1];
    S.h = h;
    S.origin[0] = org[0];
    S.origin[1] = org[1];
    const size_t count = (size_t)n[0] * n[1];
    const double *P = c->pts;

    size_t ns = 0, nsamp = 0;
    sdf2d_seg *Sg = malloc((hv_curves_segments(c) + 1) * sizeof *Sg);
    double *Y = NULL, *Ylev = NULL, *rhs = NULL, *phi = NULL, *samp = NULL;
    hv_solver *solver = NULL;
    hv_grid *g = NULL;
    if (!Sg) {
        st = hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the segments");
        goto done;
    }
    for (size_t k = 0; k < c->nlines; k++) {
        size_t a = c->start[k], b = c->start[k + 1];
        if (b > c->npoints || b < a + 2) {
            st = hv__error(HV_ERR_INVALID_ARG, "sdf2d: polyline %zu has a bad point range", k);
            goto done;
        }
        for (size_t i = a; i + 1 < b; i++)
            Sg[ns++] = (sdf2d_seg){(uint32_t)i, (uint32_t)(i + 1)};
        if (c->closed[k] && b - a > 2)
            Sg[ns++] = (sdf2d_seg){(uint32_t)(b - 1), (uint32_t)a};
    }
    S.segments_in = ns;

    /* 1. Repair. */
    if ((st = hv__progress(0.0, "repair")))
        goto done;
    if (o.repair && (st = hv__sdf2d_repair(P, c->npoints, &Sg, &ns, o.weld_tol * h, h, &S)))
        goto done;
    S.segments_out = ns;
    S.t_repair = hv_now() - tt;
    if (ns == 0) {
        st = hv__error(HV_ERR_INVALID_ARG, "sdf2d: no segment of non-zero length");
        goto done;
    }

    /* The sign: the winding number of the repaired curves where the heat
     * method's would depend on the block (open chains, or curves beyond the
     * block); sdf2d_winding.c. */
    int wn_sign = 0;
    if (!o.heat_magnitude) {
        if ((st = open_ends(c->npoints, Sg, ns, &S.open_ends)))
            goto done;
        int cut = 0;
        for (size_t k = 0; k < c->npoints && !cut; k++)
            for (int a = 0; a < 2; a++)
                cut |= P[2 * k + a] < org[a] || P[2 * k + a] > org[a] + n[a] * h;
        wn_sign = o.sign == 2 || (o.sign == 0 && o.repair && (S.open_ends > 0 || cut));
    }
    S.sign = wn_sign ? 2 : 1;
    if (wn_sign)
        goto output;

    /* 2. Splat length-weighted normals (right-hand side of each segment). */
    if ((st = hv__progress(0.05, "splat")))
        goto done;
    tt = hv_now();
    size_t cap = 0;
    for (size_t k = 0; k < ns; k++)
        cap += (size_t)ceil(sdf2d_seg_len(P, Sg[k]) / (0.5 * h)) + 1;
    samp = malloc(3 * cap * sizeof *samp); /* x, y, length */
    Y = calloc(2 * count, sizeof *Y);
    if (!samp || !Y) {
        st = hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the surface field");
        goto done;
    }
    double f2 = 0;
    for (size_t k = 0; k < ns; k++) {
        const double *p = P + 2 * Sg[k].a, *q = P + 2 * Sg[k].b;
        double L = sdf2d_seg_len(P, Sg[k]);
        int pieces = (int)ceil(L / (0.5 * h));
        pieces = pieces < 1 ? 1 : pieces;
        double nx = (q[1] - p[1]) / L, ny = -(q[0] - p[0]) / L, w = L / pieces;
        for (int m = 0; m < pieces; m++) {
            double t = (m + 0.5) / pieces;
            double x = p[0] + t * (q[0] - p[0]), y = p[1] + t * (q[1] - p[1]);
            size_t idx[4];
            double wt[4];
            bilinear(n, h, org, x, y, idx, wt);
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
    for (size_t i = 0; i < 2 * count; i++)
        f2 += Y[i] * Y[i];
    S.t_splat = hv_now() - tt;

    /* 3. Diffuse: levels t, 16t, ... until the field reaches across the block. */
    tt = hv_now();
    double diag = hypot(n[0], n[1]);
    double reach = o.t_scale * 0.5 * log(1.0 / o.tol);
    int nlev = 1;
    while (reach < diag && nlev < SDF2_MAX_LEVELS) {
        reach *= 4;
        nlev++;
    }
    S.levels = nlev;
    Ylev = malloc((size_t)nlev * 2 * count * sizeof *Ylev);
    if (!Ylev) {
        st = hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for %d diffused fields", 2 * nlev);
        goto done;
    }
    double tau[SDF2_MAX_LEVELS];
    hv_solver_opts so;
    hv_solver_opts_default(&so);
    so.backend = o.backend;
    so.tol = o.tol;
    so.max_iter = 200;
    for (int k = 0; k < nlev; k++) {
        if ((st = hv__progress(0.1 + 0.5 * k / nlev, "diffuse")))
            goto done;
        double t = (o.t_scale * h) * (o.t_scale * h) * pow(16.0, k);
        hv_problem pb = {2, {n[0], n[1], 1}, h, NULL, 1.0, t};
        if ((st = solver_create(&solver, &pb, &so)))
            goto done;
        double relres = 0;
        for (int b = 0; b < 2; b++) {
            hv_solve_info info;
            if ((st = hv_solver_solve_d(solver, Y + b * count, Ylev + ((size_t)k * 2 + b) * count,
                                        &info)))
                goto done;
            relres = fmax(relres, info.relres);
            S.backend = info.backend;
        }
        hv_solver_destroy(&solver);
        tau[k] = SDF2_NOISE_FACTOR * fmax(relres, 1e-15) * sqrt(f2);
    }
    S.t_diffuse = hv_now() - tt;

    /* 4. Normalize on faces, rhs = -div X. */
    if ((st = hv__progress(0.6, "normalize")))
        goto done;
    tt = hv_now();
    rhs = calloc(count, sizeof *rhs);
    phi = calloc(count, sizeof *phi);
    if (!rhs || !phi) {
        st = hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the divergence");
        goto done;
    }
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
                    if (len > tau[k]) {
                        flux = (a == 0 ? vx : vy) / len;
                        dead = 0;
                    }
                }
                S.dead_faces += (size_t)dead;
                rhs[hi] += flux / h; /* -div: the face adds -flux/h to hi's div */
                rhs[lo] -= flux / h;
            }
    free(Ylev);
    Ylev = NULL;
    S.t_normalize = hv_now() - tt;

    /* 5. Poisson: -Lap phi = -div X, Neumann walls, mean-free. */
    if ((st = hv__progress(0.65, "poisson")))
        goto done;
    tt = hv_now();
    {
        hv_problem pb = {2, {n[0], n[1], 1}, h, NULL, 0.0, 1.0};
        if ((st = solver_create(&solver, &pb, &so)))
            goto done;
        hv_solve_info info;
        if ((st = hv_solver_solve_d(solver, rhs, phi, &info)))
            goto done;
        hv_solver_destroy(&solver);
    }
    /* 6. Shift: the length-weighted mean of phi on the curves goes to zero. */
    {
        double num = 0, den = 0;
        for (size_t s = 0; s < nsamp; s++) {
            size_t idx[4];
            double wt[4], v = 0;
            bilinear(n, h, org, samp[3 * s], samp[3 * s + 1], idx, wt);
            for (int b = 0; b < 4; b++)
                v += wt[b] * phi[idx[b]];
            num += samp[3 * s + 2] * v;
            den += samp[3 * s + 2];
        }
        double shift = den > 0 ? num / den : 0;
        for (size_t i = 0; i < count; i++)
            phi[i] -= shift;
    }
    S.t_poisson = hv_now() - tt;

    /* 7. Output, with the exact distance unless asked for the heat magnitude. */
output:;
    double org3[3] = {org[0], org[1], 0};
    int n3[3] = {n[0], n[1], 1};
    if ((st = hv_grid_create(&g, 2, n3, h, org3)))
        goto done;
    if (!o.heat_magnitude) {
        if ((st = hv__progress(0.85, "distance")))
            goto done;
        tt = hv_now();
        if (!rhs && !(rhs = malloc(count * sizeof *rhs))) {
            st = hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the distance");
            goto done;
        }
        if ((st = hv__sdf2d_exact_distance(P, Sg, ns, n, h, org, rhs)))
            goto done;
        if (wn_sign) {
            int8_t *sg = malloc(count);
            if (!sg) {
                st = hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the sign");
                goto done;
            }
            st = hv__sdf2d_winding_sign(P, Sg, ns, n, h, org, rhs, sg, &S.winding_evals);
            for (size_t i = 0; i < count && !st; i++)
                g->v[i] = (float)(sg[i] < 0 ? -rhs[i] : rhs[i]);
            free(sg);
            if (st)
                goto done;
        } else {
            for (size_t i = 0; i < count; i++)
                g->v[i] = (float)(phi[i] < 0 ? -rhs[i] : rhs[i]);
        }
        S.t_distance = hv_now() - tt;
    } else {
        for (size_t i = 0; i < count; i++)
            g->v[i] = (float)phi[i];
    }
    if ((st = hv__progress(1.0, "done")))
        goto done;
    S.t_total = hv_now() - t0;
    *out = g;
    g = NULL;
done:
    hv_solver_destroy(&solver);
    hv_grid_destroy(&g);
    free(Sg);
    free(Y);
    free(Ylev);
    free(rhs);
    free(phi);
    free(samp);
    if (stats)
        *stats = S;
    return st;
}
