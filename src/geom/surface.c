/*
 * Surface quadrature and grid transfer for the signed heat method. Each
 * triangle is cut into k^2 congruent sub-triangles by a k x k barycentric
 * grid, with k chosen so that every sub-edge is at most h (QUAD_EDGE h); each
 * sub-triangle contributes its centroid with its vector area, and points are
 * spread to the eight nearest cell centres with trilinear weights. Centroids
 * are then at most 0.6 h apart along the surface, closer than the splat
 * kernel's half width h, so large triangles do not alias; splitting further,
 * down to h/2, gives 4-8 times as many points and no more accuracy. Triangles much
 * larger than a voxel are first split 1-to-4 with culling against the block,
 * so that a huge triangle mostly outside it costs little.
 */
#include "exact.h"
#include "surface.h"
#include "core/error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

#define QUAD_MAX_DEPTH 24
/* Sub-edges at most this many h. */
#define QUAD_EDGE 1.0
/* Triangles with an edge above this many h are split 1-to-4 (with culling) first. */
#define QUAD_SPLIT 16.0

static hv_status quad_reserve(hv_quad *q, size_t *cap, size_t more)
{
    if (q->count + more <= *cap)
        return HV_OK;
    size_t nc = *cap ? 2 * *cap : 4096;
    while (nc < q->count + more)
        nc *= 2;
    double *nx = realloc(q->x, 3 * nc * sizeof *nx);
    if (nx)
        q->x = nx;
    double *nw = nx ? realloc(q->w, 3 * nc * sizeof *nw) : NULL;
    if (nw)
        q->w = nw;
    double *na = nw ? realloc(q->area, nc * sizeof *na) : NULL;
    if (!na)
        return hv__error(HV_ERR_NOMEM, "surface quadrature: out of memory for %zu points", nc);
    q->area = na;
    *cap = nc;
    return HV_OK;
}

static double dist2(const double *a, const double *b)
{
    return (a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
           (a[2] - b[2]) * (a[2] - b[2]);
}

/* Centroids of the k x k barycentric subdivision of T (vector area N, area A
 * of this piece), those inside [lo, hi]. */
static hv_status leaf_points(hv_quad *q, size_t *cap, const double T[9], const double N[3],
                             double A, double h, const double lo[3], const double hi[3])
{
    double e2 = fmax(dist2(T, T + 3), fmax(dist2(T + 3, T + 6), dist2(T, T + 6)));
    int k = (int)ceil(sqrt(e2) / (QUAD_EDGE * h) - 1e-9);
    if (k < 1)
        k = 1;
    size_t np = (size_t)k * k;
    hv_status st = quad_reserve(q, cap, np);
    if (st)
        return st;
    const double inv = 1.0 / k, share = 1.0 / (double)np;
    double u[3], v[3], w[3] = {N[0] * share, N[1] * share, N[2] * share};
    for (int a = 0; a < 3; a++) {
        u[a] = (T[3 + a] - T[a]) * inv;
        v[a] = (T[6 + a] - T[a]) * inv;
    }
    for (int i = 0; i < k; i++)
        for (int j = 0; i + j < k; j++)
            for (int down = 0; down < 2; down++) {
                if (down && i + j > k - 2)
                    continue;
                double bi = i + (down ? 2.0 / 3 : 1.0 / 3), bj = j + (down ? 2.0 / 3 : 1.0 / 3);
                double *x = q->x + 3 * q->count;
                int in = 1;
                for (int a = 0; a < 3; a++) {
                    x[a] = T[a] + bi * u[a] + bj * v[a];
                    in &= x[a] >= lo[a] && x[a] <= hi[a];
                }
                if (!in)
                    continue;
                memcpy(q->w + 3 * q->count, w, sizeof w);
                q->area[q->count++] = A * share;
            }
    return HV_OK;
}

/* The points of triangles [f0, f1) into q. */
static hv_status quad_range(const hv_mesh *m, double h, const double lo[3], const double hi[3],
                            size_t f0, size_t f1, hv_quad *q)
{
    size_t cap = 0;
    const double split2 = QUAD_SPLIT * QUAD_SPLIT * h * h;
    double stack[QUAD_MAX_DEPTH * 3 + 4][9];
    int depth[QUAD_MAX_DEPTH * 3 + 4];
    for (size_t f = f0; f < f1; f++) {
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
        memcpy(stack[0], a, 3 * sizeof *a);
        memcpy(stack[0] + 3, b, 3 * sizeof *b);
        memcpy(stack[0] + 6, c, 3 * sizeof *c);
        depth[0] = 0;
        int top = 1;
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
            if (e2 <= split2 || d >= QUAD_MAX_DEPTH) {
                double s = ldexp(1.0, -2 * d); /* area share of this sub-triangle */
                double Ns[3] = {N[0] * s, N[1] * s, N[2] * s};
                hv_status st = leaf_points(q, &cap, T, Ns, A * s, h, lo, hi);
                if (st)
                    return st;
                continue;
            }
            double M[9]; /* midpoints ab, bc, ca */
            for (int ax = 0; ax < 3; ax++) {
                M[ax] = 0.5 * (T[ax] + T[3 + ax]);
                M[3 + ax] = 0.5 * (T[3 + ax] + T[6 + ax]);
                M[6 + ax] = 0.5 * (T[6 + ax] + T[ax]);
            }
            const double *sub[4][3] = {
                {T, M, M + 6}, {M, T + 3, M + 3}, {M + 6, M + 3, T + 6}, {M, M + 3, M + 6}};
            for (int s = 0; s < 4; s++) {
                for (int k = 0; k < 3; k++)
                    memcpy(stack[top] + 3 * k, sub[s][k], 3 * sizeof(double));
                depth[top++] = d + 1;
            }
        }
    }
    return HV_OK;
}

hv_status hv__quad_build(const hv_mesh *m, double h, const double lo[3], const double hi[3],
                         hv_quad *q)
{
    memset(q, 0, sizeof *q);
    /* Contiguous triangle ranges per thread, joined in order: the points come
     * out in triangle order whatever the thread count. */
    int nth = 1;
#ifdef _OPENMP
    nth = omp_get_max_threads();
#endif
    if ((size_t)nth > m->ntris / 256 + 1)
        nth = (int)(m->ntris / 256 + 1);
    hv_quad *part = calloc((size_t)nth, sizeof *part);
    if (!part)
        return hv__error(HV_ERR_NOMEM, "surface quadrature: out of memory");
    hv_status err = HV_OK;
#pragma omp parallel for schedule(static, 1) num_threads(nth)
    for (int p = 0; p < nth; p++) {
        size_t f0 = m->ntris * (size_t)p / nth, f1 = m->ntris * (size_t)(p + 1) / nth;
        hv_status st = quad_range(m, h, lo, hi, f0, f1, &part[p]);
        if (st) {
#pragma omp critical(hv_quad_err)
            err = st;
        }
    }
    size_t total = 0;
    for (int p = 0; p < nth; p++)
        total += part[p].count;
    if (err) /* the message was recorded in a worker thread */
        err = hv__error(HV_ERR_NOMEM,
                        "surface quadrature: out of memory for the points of %zu triangles",
                        m->ntris);
    if (!err && total) {
        q->x = malloc(3 * total * sizeof *q->x);
        q->w = malloc(3 * total * sizeof *q->w);
        q->area = malloc(total * sizeof *q->area);
        if (!q->x || !q->w || !q->area) {
            err =
                hv__error(HV_ERR_NOMEM, "surface quadrature: out of memory for %zu points", total);
        } else {
            for (int p = 0; p < nth; p++) {
                memcpy(q->x + 3 * q->count, part[p].x, 3 * part[p].count * sizeof *q->x);
                memcpy(q->w + 3 * q->count, part[p].w, 3 * part[p].count * sizeof *q->w);
                memcpy(q->area + q->count, part[p].area, part[p].count * sizeof *q->area);
                q->count += part[p].count;
            }
        }
    }
    for (int p = 0; p < nth; p++)
        hv__quad_free(&part[p]);
    free(part);
    if (err)
        hv__quad_free(q);
    return err;
}

void hv__quad_free(hv_quad *q)
{
    free(q->x);
    free(q->w);
    free(q->area);
    memset(q, 0, sizeof *q);
}

void hv__trilinear(const hv_grid *g, const double x[3], size_t *c0, size_t step[3], double w[8])
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

double hv__point_triangle_d2(const double p[3], const double a[3], const double b[3],
                             const double c[3])
{
    double q[3];
    int region;
    return hv_closest(p, a, b, c, q, &region);
}

double hv__point_triangle_region(const double p[3], const double a[3], const double b[3],
                                 const double c[3], double diff[3], int *region)
{
    return hv_closest(p, a, b, c, diff, region);
}
