/*
 * Test helpers for the signed-distance tests (header-only, static): truths
 * computed independently of the library:
 * ray parity along grid rows (exact for closed meshes, whatever their
 * orientation) and a fast generalized winding number (Barill et al. 2018,
 * first-order dipole far field), which closes holes.
 */
#ifndef HV_TESTS_SDF_TESTUTIL_H
#define HV_TESTS_SDF_TESTUTIL_H

#include "heatvox/heatvox.h"
#include "heatvox/sdf.h"
#include "testlib.h"

#include <check.h>
#include <math.h>
#include <sys/stat.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Reads <test data>/<name> (tl_test_data: $HEATVOX_TEST_DATA, default
 * ../shared/meshes). A mesh that is not there skips the test (NULL); one that
 * is there and does not read fails it. */
__attribute__((unused)) static hv_mesh *tu_load_shared(const char *name)
{
    const char *dir = tl_test_data();
    char path[4096];
    snprintf(path, sizeof path, "%s/%s", dir ? dir : "(no test data directory)", name);
    struct stat sb;
    if (!dir || stat(path, &sb) != 0) {
        tl_skip("%s not found (set HEATVOX_TEST_DATA)", path);
        return NULL;
    }
    hv_mesh *m = NULL;
    hv_status st = hv_mesh_read(path, &m);
    ck_assert_msg(st == HV_OK, "%s: %s", path, hv_last_error());
    return m;
}

__attribute__((unused)) static void tu_centroid(const hv_mesh *m, size_t f, double c[3])
{
    for (int d = 0; d < 3; d++)
        c[d] = (m->verts[3 * (size_t)m->tris[3 * f] + d] +
                m->verts[3 * (size_t)m->tris[3 * f + 1] + d] +
                m->verts[3 * (size_t)m->tris[3 * f + 2] + d]) /
               3;
}

/* ---------- truths ---------- */

/* 2D edge sign with symbolic perturbation p + (eps, eps^2): never zero for a
 * non-degenerate edge, and the same for every triangle sharing the edge. */
__attribute__((unused)) static int tu_edge_sign(double au, double av, double bu, double bv,
                                                double pu, double pv)
{
    double e = (bu - au) * (pv - av) - (bv - av) * (pu - au);
    if (e != 0)
        return e > 0 ? 1 : -1;
    if (bv != av)
        return -(bv - av) > 0 ? 1 : -1;
    return (bu - au) > 0 ? 1 : -1;
}

typedef struct tu_hit {
    size_t row;
    double x;
} tu_hit;

__attribute__((unused)) static int tu_cmp_hit(const void *pa, const void *pb)
{
    const tu_hit *a = pa, *b = pb;
    if (a->row != b->row)
        return a->row < b->row ? -1 : 1;
    return a->x < b->x ? -1 : a->x > b->x;
}

/* inside[c] = 1 where a ray along +x from the cell centre crosses the mesh an
 * odd number of times (exact for closed meshes of any orientation). */
__attribute__((unused)) static void tu_ray_parity(const hv_mesh *m, const hv_grid *g,
                                                  uint8_t *inside)
{
    size_t cap = 1 << 16, nh = 0;
    tu_hit *H = malloc(cap * sizeof *H);
    for (size_t f = 0; f < m->ntris; f++) {
        const double *P[3];
        for (int k = 0; k < 3; k++)
            P[k] = m->verts + 3 * (size_t)m->tris[3 * f + k];
        double area =
            (P[1][1] - P[0][1]) * (P[2][2] - P[0][2]) - (P[1][2] - P[0][2]) * (P[2][1] - P[0][1]);
        if (area == 0)
            continue;
        int orient = area > 0 ? 1 : -1;
        double ylo = fmin(P[0][1], fmin(P[1][1], P[2][1])),
               yhi = fmax(P[0][1], fmax(P[1][1], P[2][1]));
        double zlo = fmin(P[0][2], fmin(P[1][2], P[2][2])),
               zhi = fmax(P[0][2], fmax(P[1][2], P[2][2]));
        int j0 = (int)ceil((ylo - g->origin[1]) / g->h - 0.5),
            j1 = (int)floor((yhi - g->origin[1]) / g->h - 0.5);
        int k0 = (int)ceil((zlo - g->origin[2]) / g->h - 0.5),
            k1 = (int)floor((zhi - g->origin[2]) / g->h - 0.5);
        if (j0 < 0)
            j0 = 0;
        if (k0 < 0)
            k0 = 0;
        if (j1 > g->n[1] - 1)
            j1 = g->n[1] - 1;
        if (k1 > g->n[2] - 1)
            k1 = g->n[2] - 1;
        for (int k = k0; k <= k1; k++)
            for (int j = j0; j <= j1; j++) {
                double pu = g->origin[1] + (j + 0.5) * g->h, pv = g->origin[2] + (k + 0.5) * g->h;
                int s0 = tu_edge_sign(P[0][1], P[0][2], P[1][1], P[1][2], pu, pv);
                int s1 = tu_edge_sign(P[1][1], P[1][2], P[2][1], P[2][2], pu, pv);
                int s2 = tu_edge_sign(P[2][1], P[2][2], P[0][1], P[0][2], pu, pv);
                if (s0 != orient || s1 != orient || s2 != orient)
                    continue;
                /* Barycentric x of the crossing. */
                double l0 =
                    ((P[1][1] - pu) * (P[2][2] - pv) - (P[1][2] - pv) * (P[2][1] - pu)) / area;
                double l1 =
                    ((P[2][1] - pu) * (P[0][2] - pv) - (P[2][2] - pv) * (P[0][1] - pu)) / area;
                double x = l0 * P[0][0] + l1 * P[1][0] + (1 - l0 - l1) * P[2][0];
                if (nh == cap)
                    H = realloc(H, (cap *= 2) * sizeof *H);
                H[nh].row = (size_t)j + (size_t)g->n[1] * k;
                H[nh++].x = x;
            }
    }
    qsort(H, nh, sizeof *H, tu_cmp_hit);
    size_t rows = (size_t)g->n[1] * g->n[2], h0 = 0;
    for (size_t r = 0; r < rows; r++) {
        size_t h1 = h0;
        while (h1 < nh && H[h1].row == r)
            h1++;
        size_t q = h0;
        for (int i = 0; i < g->n[0]; i++) {
            double x = g->origin[0] + (i + 0.5) * g->h;
            while (q < h1 && H[q].x < x)
                q++;
            inside[i + (size_t)g->n[0] * r] = (uint8_t)((q - h0) & 1);
        }
        h0 = h1;
    }
    free(H);
}

/* Fast generalized winding number. */
typedef struct tu_node {
    double c[3], N[3], r;
    int left, right; /* children, or -1 */
    size_t first, count;
} tu_node;

typedef struct tu_wn {
    const hv_mesh *m;
    size_t *order;
    tu_node *nodes;
    int nn, cap;
    double beta;
} tu_wn;

__attribute__((unused)) static double tu_solid_angle(const double *p, const double *a,
                                                     const double *b, const double *c)
{
    double A[3], B[3], C[3];
    for (int d = 0; d < 3; d++)
        A[d] = a[d] - p[d], B[d] = b[d] - p[d], C[d] = c[d] - p[d];
    double la = sqrt(A[0] * A[0] + A[1] * A[1] + A[2] * A[2]),
           lb = sqrt(B[0] * B[0] + B[1] * B[1] + B[2] * B[2]),
           lc = sqrt(C[0] * C[0] + C[1] * C[1] + C[2] * C[2]);
    double det = A[0] * (B[1] * C[2] - B[2] * C[1]) - A[1] * (B[0] * C[2] - B[2] * C[0]) +
                 A[2] * (B[0] * C[1] - B[1] * C[0]);
    double den = la * lb * lc + (A[0] * B[0] + A[1] * B[1] + A[2] * B[2]) * lc +
                 (A[0] * C[0] + A[1] * C[1] + A[2] * C[2]) * lb +
                 (B[0] * C[0] + B[1] * C[1] + B[2] * C[2]) * la;
    return 2 * atan2(det, den);
}

__attribute__((unused)) static int tu_wn_build(tu_wn *W, size_t first, size_t count, int axis_hint)
{
    if (W->nn == W->cap)
        W->nodes = realloc(W->nodes, (W->cap = W->cap ? 2 * W->cap : 1024) * sizeof *W->nodes);
    int id = W->nn++;
    tu_node nd;
    memset(&nd, 0, sizeof nd);
    nd.first = first, nd.count = count, nd.left = nd.right = -1;
    double asum = 0, lo[3] = {INFINITY, INFINITY, INFINITY},
           hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (size_t q = first; q < first + count; q++) {
        size_t f = W->order[q];
        const double *a = W->m->verts + 3 * (size_t)W->m->tris[3 * f],
                     *b = W->m->verts + 3 * (size_t)W->m->tris[3 * f + 1],
                     *c = W->m->verts + 3 * (size_t)W->m->tris[3 * f + 2];
        double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]},
               v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        double n[3] = {0.5 * (u[1] * v[2] - u[2] * v[1]), 0.5 * (u[2] * v[0] - u[0] * v[2]),
                       0.5 * (u[0] * v[1] - u[1] * v[0])};
        double A = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        for (int d = 0; d < 3; d++) {
            nd.N[d] += n[d];
            nd.c[d] += A * (a[d] + b[d] + c[d]) / 3;
            double cc = (a[d] + b[d] + c[d]) / 3;
            lo[d] = fmin(lo[d], cc), hi[d] = fmax(hi[d], cc);
        }
        asum += A;
    }
    for (int d = 0; d < 3; d++)
        nd.c[d] = asum > 0 ? nd.c[d] / asum : 0.5 * (lo[d] + hi[d]);
    for (size_t q = first; q < first + count; q++)
        for (int k = 0; k < 3; k++) {
            const double *x = W->m->verts + 3 * (size_t)W->m->tris[3 * W->order[q] + k];
            double r =
                sqrt((x[0] - nd.c[0]) * (x[0] - nd.c[0]) + (x[1] - nd.c[1]) * (x[1] - nd.c[1]) +
                     (x[2] - nd.c[2]) * (x[2] - nd.c[2]));
            nd.r = fmax(nd.r, r);
        }
    if (count > 8) {
        int ax = 0;
        for (int d = 1; d < 3; d++)
            if (hi[d] - lo[d] > hi[ax] - lo[ax])
                ax = d;
        double mid = 0.5 * (lo[ax] + hi[ax]);
        size_t i = first, j = first + count;
        while (i < j) {
            double c[3];
            tu_centroid(W->m, W->order[i], c);
            if (c[ax] < mid)
                i++;
            else {
                size_t t = W->order[i];
                W->order[i] = W->order[--j];
                W->order[j] = t;
            }
        }
        if (i == first || i == first + count)
            i = first + count / 2;
        W->nodes[id] = nd;
        int l = tu_wn_build(W, first, i - first, ax);
        int r = tu_wn_build(W, i, first + count - i, ax);
        W->nodes[id].left = l, W->nodes[id].right = r;
        return id;
    }
    (void)axis_hint;
    W->nodes[id] = nd;
    return id;
}

__attribute__((unused)) static double tu_wn_eval(const tu_wn *W, int id, const double p[3])
{
    const tu_node *nd = &W->nodes[id];
    double d[3] = {nd->c[0] - p[0], nd->c[1] - p[1], nd->c[2] - p[2]};
    double dist = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    if (dist > W->beta * nd->r)
        return (nd->N[0] * d[0] + nd->N[1] * d[1] + nd->N[2] * d[2]) /
               (4 * M_PI * dist * dist * dist);
    if (nd->left < 0) {
        double w = 0;
        for (size_t q = nd->first; q < nd->first + nd->count; q++) {
            const uint32_t *t = W->m->tris + 3 * W->order[q];
            w += tu_solid_angle(p, W->m->verts + 3 * (size_t)t[0], W->m->verts + 3 * (size_t)t[1],
                                W->m->verts + 3 * (size_t)t[2]);
        }
        return w / (4 * M_PI);
    }
    return tu_wn_eval(W, nd->left, p) + tu_wn_eval(W, nd->right, p);
}

/* inside[c] = 1 where the generalized winding number of the raw mesh exceeds 1/2. */
__attribute__((unused)) static void tu_winding(const hv_mesh *m, const hv_grid *g, uint8_t *inside)
{
    tu_wn W;
    memset(&W, 0, sizeof W);
    W.m = m;
    W.beta = 3.0;
    W.order = malloc(m->ntris * sizeof *W.order);
    for (size_t f = 0; f < m->ntris; f++)
        W.order[f] = f;
    tu_wn_build(&W, 0, m->ntris, 0);
#pragma omp parallel for collapse(2) schedule(dynamic, 4)
    for (int k = 0; k < g->n[2]; k++)
        for (int j = 0; j < g->n[1]; j++)
            for (int i = 0; i < g->n[0]; i++) {
                double p[3];
                hv_grid_cell_center(g, i, j, k, p);
                inside[i + (size_t)g->n[0] * (j + (size_t)g->n[1] * k)] =
                    tu_wn_eval(&W, 0, p) > 0.5;
            }
    free(W.order);
    free(W.nodes);
}

/* IoU of {phi < 0} against truth. */
__attribute__((unused)) static double tu_iou(const hv_grid *phi, const uint8_t *inside)
{
    size_t I = 0, U = 0, n = hv_grid_count(phi);
    for (size_t c = 0; c < n; c++) {
        int a = phi->v[c] < 0, b = inside[c] != 0;
        I += a && b;
        U += a || b;
    }
    return U ? (double)I / (double)U : 1.0;
}

/* ---- generated open meshes ---- */

/* An icosphere (radius 1 at the origin, 4 subdivisions) without the faces
 * whose centroid lies within cap_deg of direction d. */
__attribute__((unused)) static hv_mesh *tu_open_sphere(const double d[3], double cap_deg)
{
    const double c[3] = {0, 0, 0};
    hv_mesh *s = NULL;
    TL_ASSERT_OK(hv_mesh_make_sphere(&s, c, 1.0, 4));
    double dl = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), cosc = cos(cap_deg * M_PI / 180);
    uint32_t *T = malloc(3 * s->ntris * sizeof *T);
    size_t nt = 0;
    for (size_t f = 0; f < s->ntris; f++) {
        double m[3];
        tu_centroid(s, f, m);
        double ml = sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]);
        if ((m[0] * d[0] + m[1] * d[1] + m[2] * d[2]) / (ml * dl) > cosc)
            continue;
        memcpy(T + 3 * nt++, s->tris + 3 * f, 3 * sizeof *T);
    }
    hv_mesh *o = NULL;
    TL_ASSERT_OK(hv_mesh_from_arrays(&o, s->verts, s->nverts, T, nt));
    free(T);
    hv_mesh_destroy(&s);
    return o;
}

/* Appends an open tube of radius r around the z axis from z0 to z1 (nu
 * segments around, nz along), outward, to (V, nv, T, nt). */
__attribute__((unused)) static void tu_tube(double *V, size_t *nv, uint32_t *T, size_t *nt,
                                            double r, double z0, double z1, int nu, int nz)
{
    size_t b = *nv;
    for (int i = 0; i <= nz; i++)
        for (int j = 0; j < nu; j++) {
            double a = 2 * M_PI * j / nu;
            double *x = V + 3 * (*nv)++;
            x[0] = r * cos(a), x[1] = r * sin(a), x[2] = z0 + (z1 - z0) * i / nz;
        }
    for (int i = 0; i < nz; i++)
        for (int j = 0; j < nu; j++) {
            uint32_t p = (uint32_t)(b + (size_t)i * nu + j),
                     q = (uint32_t)(b + (size_t)i * nu + (j + 1) % nu), u = p + (uint32_t)nu,
                     w = q + (uint32_t)nu;
            uint32_t *t = T + 3 * *nt;
            t[0] = p, t[1] = q, t[2] = u, t[3] = q, t[4] = w, t[5] = u;
            *nt += 2;
        }
}

__attribute__((unused)) static hv_mesh *tu_open_cylinder(void)
{
    double *V = malloc(3 * 64 * 33 * sizeof *V);
    uint32_t *T = malloc(3 * 2 * 64 * 32 * sizeof *T);
    size_t nv = 0, nt = 0;
    tu_tube(V, &nv, T, &nt, 0.5, -1.0, 1.0, 64, 32);
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_from_arrays(&m, V, nv, T, nt));
    free(V);
    free(T);
    return m;
}

#endif
