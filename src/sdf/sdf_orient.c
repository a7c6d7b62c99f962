/*
 * The orientation of a point cloud without normals (hv_points_surface, step
 * 0): each point's direction from its neighbourhood, turned consistently
 * along a minimum spanning tree of the neighbour graph, and each of the
 * graph's components turned to face out of the volume it encloses. The heat
 * rounds that follow (sdf_points.c) turn the points that still disagree
 * with the signed field.
 */
#include "sdf_internal.h"
#include "core/error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define OR_K 8               /* neighbours of a point in the graph */
#define OR_OFFSET 1.0        /* weight of a neighbour's offset along the directions */
#define OR_JACOBI_SWEEPS 8   /* of the 3 x 3 eigenproblem (converged after 4-5) */
#define OR_FLAT 1e-6         /* least spread, of the cloud's size, of a cloud that has a volume */
#define OR_MAX_RINGS 3       /* cells searched around a point's own for its direction */
#define OR_AXIS_SAMPLES 1024 /* points of the cells around, at most, a direction weighs */

void hv__sym3_axes(const double m[6], double lam[3], double e[3][3])
{
    double a[3][3] = {{m[0], m[3], m[4]}, {m[3], m[1], m[5]}, {m[4], m[5], m[2]}};
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++)
            e[i][k] = i == k;
    for (int sweep = 0; sweep < OR_JACOBI_SWEEPS; sweep++)
        for (int p = 0; p < 2; p++)
            for (int q = p + 1; q < 3; q++) {
                if (fabs(a[p][q]) < 1e-300)
                    continue;
                const double th = 0.5 * atan2(2 * a[p][q], a[q][q] - a[p][p]);
                const double c = cos(th), s = sin(th);
                for (int k = 0; k < 3; k++) { /* a = a J */
                    const double x = a[k][p], y = a[k][q];
                    a[k][p] = c * x - s * y;
                    a[k][q] = s * x + c * y;
                }
                for (int k = 0; k < 3; k++) { /* a = J^T a */
                    const double x = a[p][k], y = a[q][k];
                    a[p][k] = c * x - s * y;
                    a[q][k] = s * x + c * y;
                }
                for (int k = 0; k < 3; k++) {
                    const double x = e[k][p], y = e[k][q];
                    e[k][p] = c * x - s * y;
                    e[k][q] = s * x + c * y;
                }
            }
    for (int k = 0; k < 3; k++)
        lam[k] = a[k][k];
}

/* The eigenvector of m of its smallest eigenvalue; returns that eigenvalue
 * over the middle one (0 on a plane, 1 for no plane at all). */
static double smallest_axis(const double m[6], double v[3])
{
    double lam[3], e[3][3];
    hv__sym3_axes(m, lam, e);
    int j = lam[0] <= lam[1] && lam[0] <= lam[2] ? 0 : lam[1] <= lam[2] ? 1 : 2;
    const double mid = fmin(lam[(j + 1) % 3], lam[(j + 2) % 3]);
    const double len = sqrt(e[0][j] * e[0][j] + e[1][j] * e[1][j] + e[2][j] * e[2][j]);
    for (int k = 0; k < 3; k++)
        v[k] = e[k][j] / len;
    return mid > 0 ? fmax(lam[j], 0) / mid : 1;
}

/* The runs of points of the cells within `rings` of cell q: up to max
 * (start, len) pairs into run; their number. */
static int block_runs(const pt_bins *B, const long q[3], long rings, uint32_t *run, int max)
{
    int m = 0;
    for (long k = -rings; k <= rings; k++)
        for (long j = -rings; j <= rings; j++)
            for (long i = -rings; i <= rings && m < max; i++)
                if (hv__bins_find(B, hv__cell_key(q[0] + i, q[1] + j, q[2] + k), &run[2 * m],
                                  &run[2 * m + 1]))
                    m++;
    return m;
}

/* The direction of the point at place u of the sorted order: the axis of
 * least spread of the points within rho (runs: the cells around its own;
 * every stride-th of each), weighted (1 - d^2/rho^2)^2 about their
 * weighted mean; returns the spread along it over the least across it. */
static double point_axis(const pt_bins *B, uint32_t u, const uint32_t *run, int nrun,
                         uint32_t stride, double rho, double *v)
{
    const float *x = B->sx + 3 * (size_t)u;
    const double r2 = rho * rho;
    double w0 = 0, m1[3] = {0, 0, 0}, m2[6] = {0, 0, 0, 0, 0, 0};
    for (int r = 0; r < nrun; r++)
        for (uint32_t k = run[2 * r]; k < run[2 * r] + run[2 * r + 1]; k += stride) {
            const float *y = B->sx + 3 * (size_t)k;
            const double d[3] = {y[0] - x[0], y[1] - x[1], y[2] - x[2]};
            const double d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
            if (d2 >= r2)
                continue;
            const double w = (1 - d2 / r2) * (1 - d2 / r2);
            w0 += w;
            for (int a = 0; a < 3; a++)
                m1[a] += w * d[a];
            m2[0] += w * d[0] * d[0], m2[1] += w * d[1] * d[1], m2[2] += w * d[2] * d[2];
            m2[3] += w * d[0] * d[1], m2[4] += w * d[0] * d[2], m2[5] += w * d[1] * d[2];
        }
    const double c[3] = {m1[0] / w0, m1[1] / w0, m1[2] / w0};
    const double cov[6] = {m2[0] / w0 - c[0] * c[0], m2[1] / w0 - c[1] * c[1],
                           m2[2] / w0 - c[2] * c[2], m2[3] / w0 - c[0] * c[1],
                           m2[4] / w0 - c[0] * c[2], m2[5] / w0 - c[1] * c[2]};
    return smallest_axis(cov, v);
}

hv_status hv__points_axes(const pt_bins *B, double rho, double *dir, float *spread)
{
    const long rings = (long)fmin(OR_MAX_RINGS, ceil(rho / B->c));
    const int max = (int)((2 * rings + 1) * (2 * rings + 1) * (2 * rings + 1));
    int failed = 0;
#pragma omp parallel reduction(| : failed)
    {
        uint32_t *run = malloc(2 * (size_t)max * sizeof *run);
        failed |= !run;
#pragma omp for schedule(dynamic, 64)
        for (size_t t = 0; t <= B->mask; t++) {
            if (B->keys[t] == UINT64_MAX || !run)
                continue;
            long q[3];
            hv__slot_cell(B, t, q);
            const int nrun = block_runs(B, q, rings, run, max);
            /* A cloud far denser than the voxels (1M points at 64^3: some
             * 4000 around each) is sampled: every stride-th point of each
             * cell, about OR_AXIS_SAMPLES in all, give the same axis. */
            size_t around = 0;
            for (int r = 0; r < nrun; r++)
                around += run[2 * r + 1];
            const uint32_t stride = (uint32_t)(1 + around / OR_AXIS_SAMPLES);
            for (uint32_t u = B->start[t]; u < B->start[t] + B->len[t]; u++) {
                const uint32_t i = B->order[u];
                spread[i] = (float)point_axis(B, u, run, nrun, stride, rho, dir + 3 * (size_t)i);
            }
        }
        free(run);
    }
    return failed ? hv__error(HV_ERR_NOMEM, "points: out of memory for the directions") : HV_OK;
}

int hv__points_flat(const hv_points *P)
{
    double c[3] = {0, 0, 0}, m[6] = {0, 0, 0, 0, 0, 0};
    const double n = (double)P->count;
    for (size_t i = 0; i < P->count; i++)
        for (int a = 0; a < 3; a++)
            c[a] += P->xyz[3 * i + a] / n;
    for (size_t i = 0; i < P->count; i++) {
        const double *x = P->xyz + 3 * i;
        const double d[3] = {x[0] - c[0], x[1] - c[1], x[2] - c[2]};
        m[0] += d[0] * d[0], m[1] += d[1] * d[1], m[2] += d[2] * d[2];
        m[3] += d[0] * d[1], m[4] += d[0] * d[2], m[5] += d[1] * d[2];
    }
    double v[3];
    smallest_axis(m, v);
    const double least = m[0] * v[0] * v[0] + m[1] * v[1] * v[1] + m[2] * v[2] * v[2] +
                         2 * (m[3] * v[0] * v[1] + m[4] * v[0] * v[2] + m[5] * v[1] * v[2]);
    return !(least > OR_FLAT * OR_FLAT * (m[0] + m[1] + m[2]));
}

/* The graph: each point's OR_K nearest within the 27 cells around its own,
 * both ways, as lists (adj from off[u] to off[u + 1]), points by their
 * place u in the bins' order, so that neighbours lie near in memory. */
static void keep_nearest(uint32_t *nb, double *d2s, int *m, uint32_t j, double d2)
{
    if (*m == OR_K && d2 >= d2s[OR_K - 1])
        return;
    int k = *m < OR_K ? (*m)++ : OR_K - 1;
    while (k > 0 && d2s[k - 1] > d2) {
        d2s[k] = d2s[k - 1];
        nb[k] = nb[k - 1];
        k--;
    }
    d2s[k] = d2;
    nb[k] = j;
}

/* The OR_K nearest of the point at place u of the sorted order among the
 * runs of the cells around its own, as places in that order into nb; how
 * many. */
static int point_neighbours(const pt_bins *B, uint32_t u, const uint32_t *run, int nrun,
                            uint32_t *nb)
{
    const float *x = B->sx + 3 * (size_t)u;
    double d2s[OR_K];
    int m = 0;
    for (int r = 0; r < nrun; r++)
        for (uint32_t k = run[2 * r]; k < run[2 * r] + run[2 * r + 1]; k++) {
            const float *y = B->sx + 3 * (size_t)k;
            const double d0 = y[0] - x[0], d1 = y[1] - x[1], d2 = y[2] - x[2];
            if (k != u)
                keep_nearest(nb, d2s, &m, k, d0 * d0 + d1 * d1 + d2 * d2);
        }
    return m;
}

static hv_status graph_build(const pt_bins *B, const hv_points *P, or_graph *G)
{
    const size_t n = P->count;
    uint32_t *knn = malloc(n * OR_K * sizeof *knn);
    uint8_t *cnt = malloc(n * sizeof *cnt);
    G->off = calloc(n + 1, sizeof *G->off);
    G->adj = NULL;
    if (!knn || !cnt || !G->off) {
        free(knn), free(cnt);
        return hv__error(HV_ERR_NOMEM, "points: out of memory for the neighbour graph");
    }
#pragma omp parallel for schedule(dynamic, 64)
    for (size_t t = 0; t <= B->mask; t++) {
        if (B->keys[t] == UINT64_MAX)
            continue;
        long q[3];
        uint32_t run[2 * 27];
        hv__slot_cell(B, t, q);
        const int nrun = block_runs(B, q, 1, run, 27);
        for (uint32_t u = B->start[t]; u < B->start[t] + B->len[t]; u++)
            cnt[u] = (uint8_t)point_neighbours(B, u, run, nrun, knn + OR_K * (size_t)u);
    }
    for (size_t i = 0; i < n; i++)
        for (int k = 0; k < cnt[i]; k++) {
            G->off[i + 1]++;
            G->off[knn[OR_K * i + k] + 1]++;
        }
    for (size_t i = 0; i < n; i++)
        G->off[i + 1] += G->off[i];
    uint32_t *fill = malloc(n * sizeof *fill);
    G->adj = malloc((size_t)G->off[n] * sizeof *G->adj);
    if (!fill || !G->adj) {
        free(knn), free(cnt), free(fill);
        return hv__error(HV_ERR_NOMEM, "points: out of memory for the neighbour graph");
    }
    memcpy(fill, G->off, n * sizeof *fill);
    for (size_t i = 0; i < n; i++)
        for (int k = 0; k < cnt[i]; k++) {
            const uint32_t j = knn[OR_K * i + k];
            G->adj[fill[i]++] = j;
            G->adj[fill[j]++] = (uint32_t)i;
        }
    free(knn), free(cnt), free(fill);
    return HV_OK;
}

/* How far apart the directions of places i and j are as a step of the
 * propagation: their angle, and how far each lies off the other's plane
 * (the two faces of a thin wall are parallel but lie off each other's). */
static float edge_cost(const pt_bins *B, const double *dir, uint32_t i, uint32_t j)
{
    const double *a = dir + 3 * (size_t)i, *b = dir + 3 * (size_t)j;
    const float *x = B->sx + 3 * (size_t)i, *y = B->sx + 3 * (size_t)j;
    const double u[3] = {y[0] - x[0], y[1] - x[1], y[2] - x[2]};
    const double len = sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
    const double ab = fabs(a[0] * b[0] + a[1] * b[1] + a[2] * b[2]);
    if (!(len > 0))
        return (float)(1 - ab);
    const double off = (fabs(u[0] * a[0] + u[1] * a[1] + u[2] * a[2]) +
                        fabs(u[0] * b[0] + u[1] * b[1] + u[2] * b[2])) /
                       (2 * len);
    return (float)(1 - ab + OR_OFFSET * off);
}

/* A binary heap of (cost, point, parent) for Prim's tree. */
typedef struct or_entry {
    float cost;
    uint32_t to, from;
} or_entry;
typedef struct or_heap {
    or_entry *e;
    size_t n, cap;
} or_heap;

static int heap_push(or_heap *H, or_entry x)
{
    if (H->n == H->cap) {
        size_t c = H->cap ? 2 * H->cap : 4096;
        or_entry *e = realloc(H->e, c * sizeof *e);
        if (!e)
            return -1;
        H->e = e;
        H->cap = c;
    }
    size_t k = H->n++;
    while (k > 0 && H->e[(k - 1) / 2].cost > x.cost) {
        H->e[k] = H->e[(k - 1) / 2];
        k = (k - 1) / 2;
    }
    H->e[k] = x;
    return 0;
}

static or_entry heap_pop(or_heap *H)
{
    or_entry top = H->e[0], last = H->e[--H->n];
    size_t k = 0;
    for (;;) {
        size_t c = 2 * k + 1;
        if (c >= H->n)
            break;
        if (c + 1 < H->n && H->e[c + 1].cost < H->e[c].cost)
            c++;
        if (H->e[c].cost >= last.cost)
            break;
        H->e[k] = H->e[c];
        k = c;
    }
    if (H->n)
        H->e[k] = last;
    return top;
}

/* Prim's tree from seed over its component (places in the bins' order):
 * each point turned to agree with its parent's direction, its component's
 * number into comp; key: the cheapest edge to each point seen so far. */
static hv_status propagate(const pt_bins *B, const or_graph *G, double *dir, uint32_t seed,
                           uint32_t c, uint32_t *comp, float *key, or_heap *H)
{
    H->n = 0;
    if (heap_push(H, (or_entry){0, seed, seed}))
        return hv__error(HV_ERR_NOMEM, "points: out of memory orienting the cloud");
    while (H->n) {
        const or_entry x = heap_pop(H);
        if (comp[x.to] != UINT32_MAX)
            continue;
        comp[x.to] = c;
        double *a = dir + 3 * (size_t)x.from, *b = dir + 3 * (size_t)x.to;
        if (a[0] * b[0] + a[1] * b[1] + a[2] * b[2] < 0)
            b[0] = -b[0], b[1] = -b[1], b[2] = -b[2];
        for (uint32_t k = G->off[x.to]; k < G->off[x.to + 1]; k++) {
            const uint32_t j = G->adj[k];
            if (comp[j] != UINT32_MAX)
                continue;
            const float e = edge_cost(B, dir, x.to, j);
            if (e >= key[j])
                continue;
            key[j] = e;
            if (heap_push(H, (or_entry){e, j, x.to}))
                return hv__error(HV_ERR_NOMEM, "points: out of memory orienting the cloud");
        }
    }
    return HV_OK;
}

/* Each component turned to face out of the volume it bounds: the sum of
 * a_i d_i . (p_i - c) over it (three times that volume, about its centroid
 * c, for a closed surface) positive. */
static hv_status turn_outward(const hv_points *P, const double *area, const uint32_t *comp,
                              size_t ncomp, double *dir, hv_points_report *R)
{
    double *acc = calloc(5 * ncomp, sizeof *acc); /* area, area-weighted x y z, volume */
    if (!acc)
        return hv__error(HV_ERR_NOMEM, "points: out of memory for %zu components", ncomp);
    for (size_t i = 0; i < P->count; i++) {
        double *c = acc + 5 * (size_t)comp[i];
        c[0] += area[i];
        for (int a = 0; a < 3; a++)
            c[1 + a] += area[i] * P->xyz[3 * i + a];
    }
    for (size_t i = 0; i < P->count; i++) {
        double *c = acc + 5 * (size_t)comp[i];
        for (int a = 0; a < 3; a++)
            c[4] += area[i] * dir[3 * i + a] * (P->xyz[3 * i + a] - c[1 + a] / c[0]);
    }
    for (size_t k = 0; k < ncomp; k++)
        R->orient_components_flipped += acc[5 * k + 4] < 0;
    for (size_t i = 0; i < P->count; i++)
        if (acc[5 * (size_t)comp[i] + 4] < 0)
            for (int a = 0; a < 3; a++)
                dir[3 * i + a] = -dir[3 * i + a];
    free(acc);
    return HV_OK;
}

/* The trees over every component, in the bins' order: dir's directions
 * permuted into that order, turned, and back; each point's component into
 * comp (by point); each component turned outward; then (T) the thin
 * parts' labelling, in the bins' order again. */
static hv_status propagate_all(const pt_bins *B, const hv_points *P, const double *area,
                               const pt_thin *T, double *dir, uint32_t *comp, hv_points_report *R)
{
    const size_t n = P->count;
    or_graph G = {NULL, NULL};
    or_heap H = {NULL, 0, 0};
    double *D = malloc(3 * n * sizeof *D);
    uint32_t *cu = malloc(n * sizeof *cu);
    float *key = malloc(n * sizeof *key);
    hv_status st = D && cu && key
                       ? graph_build(B, P, &G)
                       : hv__error(HV_ERR_NOMEM, "points: out of memory orienting the cloud");
    for (size_t u = 0; u < n && !st; u++) {
        memcpy(D + 3 * u, dir + 3 * (size_t)B->order[u], 3 * sizeof *D);
        cu[u] = UINT32_MAX;
        key[u] = INFINITY;
    }
    size_t ncomp = 0;
    for (size_t u = 0; u < n && !st; u++)
        if (cu[u] == UINT32_MAX)
            st = propagate(B, &G, D, (uint32_t)u, (uint32_t)ncomp++, cu, key, &H);
    for (size_t u = 0; u < n && !st; u++) {
        memcpy(dir + 3 * (size_t)B->order[u], D + 3 * u, 3 * sizeof *D);
        comp[B->order[u]] = cu[u];
    }
    R->orient_components = ncomp;
    if (!st)
        st = turn_outward(P, area, comp, ncomp, dir, R);
    if (!st && T) { /* the votes count from the outside: after the turns */
        for (size_t u = 0; u < n; u++)
            memcpy(D + 3 * u, dir + 3 * (size_t)B->order[u], 3 * sizeof *D);
        if (!(st = hv__points_cut(B, &G, P, T, D, R)))
            for (size_t u = 0; u < n; u++)
                memcpy(dir + 3 * (size_t)B->order[u], D + 3 * u, 3 * sizeof *D);
    }
    free(G.off), free(G.adj), free(H.e), free(D), free(cu), free(key);
    return st;
}

hv_status hv__points_propagate(const pt_bins *B, const hv_points *P, const double *area,
                               const pt_thin *T, double *dir, hv_points_report *R)
{
    uint32_t *comp = malloc(P->count * sizeof *comp);
    hv_status st = comp ? propagate_all(B, P, area, T, dir, comp, R)
                        : hv__error(HV_ERR_NOMEM, "points: out of memory orienting the cloud");
    free(comp);
    return st;
}
