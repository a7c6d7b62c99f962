/* Sources of the heat-method distance (voxels, points, mesh surfaces) and
 * obstacle shells rasterized from meshes. */
#include "distance_internal.h"
#include "core/error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Spreads weight wt trilinearly over the fluid cells among the 8 (4 in 2D)
 * cells around world point x; returns 0 when none is fluid. */
/* ref = min(ref, |centre - x|) on the fluid cells within HV_DIST_REF_RADIUS
 * voxels of x. */
static void note_near(const hv_grid *g, const double x[3], float *ref)
{
    int lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};
    const double R = HV_DIST_REF_RADIUS;
    for (int a = 0; a < g->dim; a++) {
        double p = (x[a] - g->origin[a]) / g->h - 0.5;
        lo[a] = (int)ceil(p - R);
        hi[a] = (int)floor(p + R);
        if (lo[a] < 0)
            lo[a] = 0;
        if (hi[a] > g->n[a] - 1)
            hi[a] = g->n[a] - 1;
    }
    for (int k = lo[2]; k <= hi[2]; k++)
        for (int j = lo[1]; j <= hi[1]; j++)
            for (int i = lo[0]; i <= hi[0]; i++) {
                size_t c = i + (size_t)g->n[0] * (j + (size_t)g->n[1] * k);
                if (g->solid && g->solid[c])
                    continue;
                double y[3], s = 0;
                hv_grid_cell_center(g, i, j, k, y);
                for (int a = 0; a < g->dim; a++)
                    s += (x[a] - y[a]) * (x[a] - y[a]);
                if (s <= R * R * g->h * g->h && sqrt(s) < ref[c])
                    ref[c] = (float)sqrt(s);
            }
}

static int splat_point(const hv_grid *g, const double x[3], double wt, double *w, float *ref)
{
    int i0[3] = {0, 0, 0};
    double fr[3] = {0, 0, 0};
    for (int a = 0; a < g->dim; a++) {
        double p = (x[a] - g->origin[a]) / g->h - 0.5;
        double f = floor(p);
        i0[a] = (int)f;
        fr[a] = p - f;
    }
    size_t idx[8];
    double cw[8], sum = 0;
    int nc = g->dim == 3 ? 8 : 4;
    for (int q = 0; q < nc; q++) {
        int ii[3] = {0, 0, 0};
        double c = 1;
        for (int a = 0; a < g->dim; a++) {
            int hi = (q >> a) & 1;
            ii[a] = i0[a] + hi;
            if (ii[a] < 0)
                ii[a] = 0;
            if (ii[a] >= g->n[a])
                ii[a] = g->n[a] - 1;
            c *= hi ? fr[a] : 1 - fr[a];
        }
        idx[q] = ii[0] + (size_t)g->n[0] * (ii[1] + (size_t)g->n[1] * ii[2]);
        if (g->solid && g->solid[idx[q]])
            c = 0;
        cw[q] = c;
        sum += c;
    }
    if (!(sum > 1e-12)) {
        /* The point sits on a solid corner of its stencil: fall back to any fluid neighbour. */
        for (int q = 0; q < nc; q++)
            if (!g->solid || !g->solid[idx[q]]) {
                w[idx[q]] += wt;
                note_near(g, x, ref);
                return 1;
            }
        return 0;
    }
    for (int q = 0; q < nc; q++)
        if (cw[q] > 0)
            w[idx[q]] += wt * cw[q] / sum;
    note_near(g, x, ref);
    return 1;
}

static int inside_block(const hv_grid *g, const double x[3])
{
    for (int a = 0; a < g->dim; a++) {
        double lo = g->origin[a], hi = g->origin[a] + g->n[a] * g->h;
        if (!(x[a] >= lo && x[a] <= hi))
            return 0;
    }
    return 1;
}

/* Whether this rank counts a source at x as lost: its nearest cell of the
 * whole grid (clamped to it) is owned; always without a window. */
static int counts_here(const hv_dist_window *win, const double x[3])
{
    if (!win)
        return 1;
    const hv_grid *f = win->full;
    for (int a = 0; a < f->dim; a++) {
        double p = floor((x[a] - f->origin[a]) / f->h);
        p = p < 0 ? 0 : p > f->n[a] - 1 ? f->n[a] - 1 : p;
        if (p < win->own_lo[a] || p >= win->own_hi[a])
            return 0;
    }
    return 1;
}

/* Splats a point of the whole grid's block; one outside the window is left
 * to the rank whose window holds it. */
static void splat_in(const hv_grid *g, const hv_dist_window *win, const double x[3], double wt,
                     double *w, float *ref, size_t *in_solid)
{
    if (win && !inside_block(g, x))
        return;
    if (!splat_point(g, x, wt, w, ref) && counts_here(win, x))
        (*in_solid)++;
}

static hv_status splat_mesh(const hv_grid *g, const hv_dist_window *win, const hv_mesh *m,
                            double *w, float *ref, size_t *in_solid)
{
    const hv_grid *full = win ? win->full : g;
    const double h = g->h;
    for (size_t t = 0; t < m->ntris; t++) {
        const double *p[3];
        for (int c = 0; c < 3; c++) {
            uint32_t v = m->tris[3 * t + c];
            if (v >= m->nverts)
                return hv__error(HV_ERR_INVALID_ARG,
                                 "source mesh: triangle %zu uses vertex %u of %zu", t, v,
                                 m->nverts);
            p[c] = m->verts + 3 * (size_t)v;
        }
        double e1[3], e2[3], cr[3], lmax = 0;
        for (int a = 0; a < 3; a++) {
            e1[a] = p[1][a] - p[0][a];
            e2[a] = p[2][a] - p[0][a];
        }
        cr[0] = e1[1] * e2[2] - e1[2] * e2[1];
        cr[1] = e1[2] * e2[0] - e1[0] * e2[2];
        cr[2] = e1[0] * e2[1] - e1[1] * e2[0];
        double area = 0.5 * sqrt(cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]);
        for (int c = 0; c < 3; c++) {
            const double *a = p[c], *b = p[(c + 1) % 3];
            double d = sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                            (a[2] - b[2]) * (a[2] - b[2]));
            lmax = fmax(lmax, d);
        }
        if (!isfinite(area) || !isfinite(lmax))
            return hv__error(HV_ERR_NUMERIC, "source mesh: triangle %zu has a NaN/Inf vertex", t);
        /* m x m sub-triangles, each sampled at its centroid: spacing <= h/2. A
         * degenerate triangle still marks its centroid (weight floor) so that a
         * sliver-only mesh is not silently empty. */
        int sub = (int)ceil(lmax / (0.5 * h));
        if (sub < 1)
            sub = 1;
        if (sub > 4096)
            return hv__error(HV_ERR_INVALID_ARG,
                             "source mesh: triangle %zu is %.3g voxels long; use a coarser grid", t,
                             lmax / h);
        double wt = fmax(area / ((double)sub * sub * h * h), 1e-6);
        for (int a = 0; a < sub; a++)
            for (int b = 0; a + b < sub; b++)
                for (int up = 0; up < 2; up++) {
                    if (up && a + b + 1 >= sub)
                        continue;
                    /* Barycentric centroid of the lower (up = 0) or upper sub-triangle. */
                    double ua = up ? (a + 2.0 / 3) / sub : (a + 1.0 / 3) / sub;
                    double ub = up ? (b + 2.0 / 3) / sub : (b + 1.0 / 3) / sub;
                    double x[3];
                    for (int d = 0; d < 3; d++)
                        x[d] = p[0][d] + ua * e1[d] + ub * e2[d];
                    if (!inside_block(full, x))
                        *in_solid += counts_here(win, x);
                    else
                        splat_in(g, win, x, wt, w, ref, in_solid);
                }
    }
    return HV_OK;
}

hv_status hv__dist_splat(const hv_grid *g, const hv_dist_window *win,
                         const hv_distance_sources *src, double *w, float *ref, size_t *in_solid)
{
    *in_solid = 0;
    const hv_grid *full = win ? win->full : g;
    const int *n = full->n;
    const int zero[3] = {0, 0, 0}, *off = win ? win->off : zero;
    for (size_t s = 0; s < src->nvoxels; s++) {
        const int *v = src->voxels + 3 * s;
        int k = g->dim == 3 ? v[2] : 0;
        if (v[0] < 0 || v[0] >= n[0] || v[1] < 0 || v[1] >= n[1] || k < 0 || k >= n[2] ||
            (g->dim == 2 && v[2] != 0))
            return hv__error(HV_ERR_INVALID_ARG,
                             "source voxel %zu (%d %d %d) lies outside the %d x %d x %d grid", s,
                             v[0], v[1], v[2], n[0], n[1], n[2]);
        const int l[3] = {v[0] - off[0], v[1] - off[1], k - off[2]};
        if (l[0] < 0 || l[0] >= g->n[0] || l[1] < 0 || l[1] >= g->n[1] || l[2] < 0 ||
            l[2] >= g->n[2])
            continue; /* another rank's */
        size_t c = l[0] + (size_t)g->n[0] * (l[1] + (size_t)g->n[1] * l[2]);
        double x[3];
        hv_grid_cell_center(g, l[0], l[1], l[2], x);
        if (g->solid && g->solid[c])
            *in_solid += counts_here(win, x);
        else {
            w[c] += 1.0;
            note_near(g, x, ref);
        }
    }
    for (size_t s = 0; s < src->npoints; s++) {
        const double *x = src->points + 3 * s;
        if (!isfinite(x[0]) || !isfinite(x[1]) || (g->dim == 3 && !isfinite(x[2])))
            return hv__error(HV_ERR_NUMERIC, "source point %zu has a NaN/Inf coordinate", s);
        if (!inside_block(full, x))
            return hv__error(HV_ERR_INVALID_ARG,
                             "source point %zu (%g %g %g) lies outside the grid's block", s, x[0],
                             x[1], g->dim == 3 ? x[2] : 0.0);
        splat_in(g, win, x, 1.0, w, ref, in_solid);
    }
    if (src->mesh) {
        if (g->dim != 3)
            return hv__error(HV_ERR_INVALID_ARG, "a mesh source needs a 3D grid");
        hv_status st = splat_mesh(g, win, src->mesh, w, ref, in_solid);
        if (st)
            return st;
    }
    return HV_OK;
}

/* ---- Obstacle shells ----------------------------------------------------- */

/* Separating-axis test of a triangle against an axis-aligned box (centre c,
 * half sizes e), after Akenine-Moeller, "Fast 3D Triangle-Box Overlap Testing"
 * (2001): box axes, triangle normal, and the nine edge cross products. */
static int tri_box_overlap(const double c[3], const double e[3], const double *p0, const double *p1,
                           const double *p2)
{
    double v[3][3], f[3][3];
    for (int a = 0; a < 3; a++) {
        v[0][a] = p0[a] - c[a];
        v[1][a] = p1[a] - c[a];
        v[2][a] = p2[a] - c[a];
    }
    for (int a = 0; a < 3; a++) {
        double lo = fmin(v[0][a], fmin(v[1][a], v[2][a]));
        double hi = fmax(v[0][a], fmax(v[1][a], v[2][a]));
        if (lo > e[a] || hi < -e[a])
            return 0;
    }
    for (int a = 0; a < 3; a++) {
        f[0][a] = v[1][a] - v[0][a];
        f[1][a] = v[2][a] - v[1][a];
        f[2][a] = v[0][a] - v[2][a];
    }
    for (int i = 0; i < 3; i++)       /* box axis i */
        for (int j = 0; j < 3; j++) { /* triangle edge j */
            double ax[3] = {0, 0, 0};
            /* axis = e_i x f_j */
            int i1 = (i + 1) % 3, i2 = (i + 2) % 3;
            ax[i1] = -f[j][i2];
            ax[i2] = f[j][i1];
            double p[3], lo = INFINITY, hi = -INFINITY;
            for (int q = 0; q < 3; q++) {
                p[q] = ax[0] * v[q][0] + ax[1] * v[q][1] + ax[2] * v[q][2];
                lo = fmin(lo, p[q]);
                hi = fmax(hi, p[q]);
            }
            double r = e[0] * fabs(ax[0]) + e[1] * fabs(ax[1]) + e[2] * fabs(ax[2]);
            if (lo > r || hi < -r)
                return 0;
        }
    double nrm[3] = {f[0][1] * f[1][2] - f[0][2] * f[1][1], f[0][2] * f[1][0] - f[0][0] * f[1][2],
                     f[0][0] * f[1][1] - f[0][1] * f[1][0]};
    double d = nrm[0] * v[0][0] + nrm[1] * v[0][1] + nrm[2] * v[0][2];
    double r = e[0] * fabs(nrm[0]) + e[1] * fabs(nrm[1]) + e[2] * fabs(nrm[2]);
    return fabs(d) <= r;
}

hv_status hv_mask_from_mesh(hv_grid *g, const hv_mesh *m, size_t *nsolid)
{
    if (!g || !m)
        return hv__error(HV_ERR_INVALID_ARG, "hv_mask_from_mesh: NULL argument");
    if (g->dim != 3)
        return hv__error(HV_ERR_INVALID_ARG, "an obstacle mesh needs a 3D grid");
    hv_status st = hv_grid_add_mask(g);
    if (st)
        return st;
    const double h = g->h;
    /* Closed boxes, grown by a hair so that a triangle lying exactly on a face
     * marks the cells on both sides (no gap for heat to leak through). */
    const double e[3] = {0.5 * h * (1 + 1e-9), 0.5 * h * (1 + 1e-9), 0.5 * h * (1 + 1e-9)};
    size_t count = 0;
    for (size_t t = 0; t < m->ntris; t++) {
        const double *p[3];
        int lo[3], hi[3];
        for (int c = 0; c < 3; c++) {
            uint32_t v = m->tris[3 * t + c];
            if (v >= m->nverts)
                return hv__error(HV_ERR_INVALID_ARG,
                                 "obstacle mesh: triangle %zu uses vertex %u of %zu", t, v,
                                 m->nverts);
            p[c] = m->verts + 3 * (size_t)v;
            if (!isfinite(p[c][0]) || !isfinite(p[c][1]) || !isfinite(p[c][2]))
                return hv__error(HV_ERR_NUMERIC, "obstacle mesh: triangle %zu has a NaN/Inf vertex",
                                 t);
        }
        int skip = 0;
        for (int a = 0; a < 3; a++) {
            double mn = fmin(p[0][a], fmin(p[1][a], p[2][a])),
                   mx = fmax(p[0][a], fmax(p[1][a], p[2][a]));
            double l = floor((mn - g->origin[a]) / h - 1e-9),
                   u = floor((mx - g->origin[a]) / h + 1e-9);
            if (u < 0 || l >= g->n[a]) {
                skip = 1;
                break;
            }
            lo[a] = l < 0 ? 0 : (int)l;
            hi[a] = u >= g->n[a] ? g->n[a] - 1 : (int)u;
        }
        if (skip)
            continue;
        for (int k = lo[2]; k <= hi[2]; k++)
            for (int j = lo[1]; j <= hi[1]; j++)
                for (int i = lo[0]; i <= hi[0]; i++) {
                    size_t c = i + (size_t)g->n[0] * (j + (size_t)g->n[1] * k);
                    if (g->solid[c])
                        continue;
                    double ctr[3];
                    hv_grid_cell_center(g, i, j, k, ctr);
                    if (tri_box_overlap(ctr, e, p[0], p[1], p[2])) {
                        g->solid[c] = 1;
                        count++;
                    }
                }
    }
    if (nsolid)
        *nsolid = count;
    return HV_OK;
}
