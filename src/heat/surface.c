/*
 * Surface quadrature and grid transfer for the signed heat method: triangles
 * are split 1-to-4 until every sub-edge is at most h/2 (so that large
 * triangles do not alias on the grid), each sub-triangle contributes its
 * centroid with its vector area, and points are spread to the eight nearest
 * cell centres with trilinear weights.
 */
#include "sdf_internal.h"
#include "core/error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define QUAD_MAX_DEPTH 24

static hv_status quad_push(hv_quad *q, size_t *cap, const double x[3], const double w[3], double area)
{
    if (q->count == *cap) {
        size_t nc = *cap ? 2 * *cap : 4096;
        double *nx = realloc(q->x, 3 * nc * sizeof *nx);
        if (nx)
            q->x = nx;
        double *nw = nx ? realloc(q->w, 3 * nc * sizeof *nw) : NULL;
        if (nw)
            q->w = nw;
        double *na = nw ? realloc(q->area, nc * sizeof *na) : NULL;
        if (!na)
            return hv_error(HV_ERR_NOMEM, "surface quadrature: out of memory for %zu points", nc);
        q->area = na;
        *cap = nc;
    }
    memcpy(q->x + 3 * q->count, x, 3 * sizeof *x);
    memcpy(q->w + 3 * q->count, w, 3 * sizeof *w);
    q->area[q->count++] = area;
    return HV_OK;
}

static double dist2(const double *a, const double *b)
{
    return (a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]);
}

hv_status hv_quad_build(const hv_mesh *m, double h, const double lo[3], const double hi[3], hv_quad *q)
{
    memset(q, 0, sizeof *q);
    size_t cap = 0;
    const double lim2 = 0.25 * h * h;
    /* Depth-first 1-to-4 splitting; sub-triangles outside the block are culled. */
    double stack[QUAD_MAX_DEPTH * 3 + 4][9];
    for (size_t f = 0; f < m->ntris; f++) {
        const uint32_t *t = m->tris + 3 * f;
        const double *a = m->verts + 3 * (size_t)t[0], *b = m->verts + 3 * (size_t)t[1],
                     *c = m->verts + 3 * (size_t)t[2];
        double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
        double v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        double N[3] = {0.5 * (u[1] * v[2] - u[2] * v[1]), 0.5 * (u[2] * v[0] - u[0] * v[2]),
                       0.5 * (u[0] * v[1] - u[1] * v[0])};
        double A = sqrt(N[0] * N[0] + N[1] * N[1] + N[2] * N[2]);
        if (!(A > 0))
            continue;
        int top = 0, depth[QUAD_MAX_DEPTH * 3 + 4];
        memcpy(stack[0], a, 3 * sizeof *a);
        memcpy(stack[0] + 3, b, 3 * sizeof *b);
        memcpy(stack[0] + 6, c, 3 * sizeof *c);
        depth[0] = 0;
        top = 1;
        while (top) {
            top--;
            double T[9];
            memcpy(T, stack[top], sizeof T);
            int d = depth[top];
            int out = 0;
            for (int ax = 0; ax < 3 && !out; ax++) {
                double mn = fmin(T[ax], fmin(T[3 + ax], T[6 + ax]));
                double mx = fmax(T[ax], fmax(T[3 + ax], T[6 + ax]));
                out = mx < lo[ax] || mn > hi[ax];
            }
            if (out)
                continue;
            double e2 = fmax(dist2(T, T + 3), fmax(dist2(T + 3, T + 6), dist2(T, T + 6)));
            if (e2 <= lim2 || d >= QUAD_MAX_DEPTH) {
                double s = ldexp(1.0, -2 * d); /* area share of this sub-triangle */
                double x[3], w[3] = {N[0] * s, N[1] * s, N[2] * s};
                for (int ax = 0; ax < 3; ax++)
                    x[ax] = (T[ax] + T[3 + ax] + T[6 + ax]) / 3.0;
                if (x[0] < lo[0] || x[0] > hi[0] || x[1] < lo[1] || x[1] > hi[1] || x[2] < lo[2] ||
                    x[2] > hi[2])
                    continue;
                hv_status st = quad_push(q, &cap, x, w, A * s);
                if (st) {
                    hv_quad_free(q);
                    return st;
                }
                continue;
            }
            double M[9]; /* midpoints ab, bc, ca */
            for (int ax = 0; ax < 3; ax++) {
                M[ax] = 0.5 * (T[ax] + T[3 + ax]);
                M[3 + ax] = 0.5 * (T[3 + ax] + T[6 + ax]);
                M[6 + ax] = 0.5 * (T[6 + ax] + T[ax]);
            }
            const double *sub[4][3] = {{T, M, M + 6}, {M, T + 3, M + 3}, {M + 6, M + 3, T + 6},
                                       {M, M + 3, M + 6}};
            for (int s = 0; s < 4; s++) {
                for (int k = 0; k < 3; k++)
                    memcpy(stack[top] + 3 * k, sub[s][k], 3 * sizeof(double));
                depth[top++] = d + 1;
            }
        }
    }
    return HV_OK;
}

void hv_quad_free(hv_quad *q)
{
    free(q->x);
    free(q->w);
    free(q->area);
    memset(q, 0, sizeof *q);
}

void hv_trilinear(const hv_grid *g, const double x[3], size_t *c0, size_t step[3], double w[8])
{
    size_t stride[3] = {1, (size_t)g->n[0], (size_t)g->n[0] * g->n[1]};
    size_t base = 0;
    double f[3];
    for (int a = 0; a < 3; a++) {
        double s = (x[a] - g->origin[a]) / g->h - 0.5;
        int n = g->n[a];
        int i0 = (int)floor(s);
        if (n == 1 || s <= 0) {
            i0 = 0;
            f[a] = 0;
        } else if (i0 >= n - 1) {
            i0 = n - 1;
            f[a] = 0;
        } else {
            f[a] = s - i0;
        }
        step[a] = (i0 < n - 1) ? stride[a] : 0;
        base += (size_t)i0 * stride[a];
    }
    *c0 = base;
    for (int q = 0; q < 8; q++)
        w[q] = (q & 1 ? f[0] : 1 - f[0]) * (q & 2 ? f[1] : 1 - f[1]) * (q & 4 ? f[2] : 1 - f[2]);
}

/* Ericson, Real-Time Collision Detection, 5.1.5: closest point on a triangle
 * by Voronoi regions. */
double hv_point_triangle_d2(const double p[3], const double a[3], const double b[3],
                            const double c[3])
{
    double ab[3], ac[3], ap[3], q[3];
    for (int i = 0; i < 3; i++) {
        ab[i] = b[i] - a[i];
        ac[i] = c[i] - a[i];
        ap[i] = p[i] - a[i];
    }
#define DOT(u, v) ((u)[0] * (v)[0] + (u)[1] * (v)[1] + (u)[2] * (v)[2])
    double d1 = DOT(ab, ap), d2 = DOT(ac, ap);
    if (d1 <= 0 && d2 <= 0)
        return DOT(ap, ap);
    double bp[3] = {p[0] - b[0], p[1] - b[1], p[2] - b[2]};
    double d3 = DOT(ab, bp), d4 = DOT(ac, bp);
    if (d3 >= 0 && d4 <= d3)
        return DOT(bp, bp);
    double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) {
        double v = d1 / (d1 - d3);
        for (int i = 0; i < 3; i++)
            q[i] = ap[i] - v * ab[i];
        return DOT(q, q);
    }
    double cp[3] = {p[0] - c[0], p[1] - c[1], p[2] - c[2]};
    double d5 = DOT(ab, cp), d6 = DOT(ac, cp);
    if (d6 >= 0 && d5 <= d6)
        return DOT(cp, cp);
    double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) {
        double w = d2 / (d2 - d6);
        for (int i = 0; i < 3; i++)
            q[i] = ap[i] - w * ac[i];
        return DOT(q, q);
    }
    double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
        double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        for (int i = 0; i < 3; i++)
            q[i] = bp[i] - w * (c[i] - b[i]);
        return DOT(q, q);
    }
    double denom = 1.0 / (va + vb + vc);
    double v = vb * denom, w = vc * denom;
    for (int i = 0; i < 3; i++)
        q[i] = ap[i] - ab[i] * v - ac[i] * w;
    return DOT(q, q);
#undef DOT
}
