/*
 * The diffused line field of a point cloud (docs/METHOD.md, "Point clouds
 * without normals"): directions without a sign, each splatted with its
 * point's area as the tensor a d d^T and diffused by one heat step per
 * component with the solver the signed heat method uses. Where sheets of
 * points lie, the field's principal eigenvector is their common line and
 * the gap to the second eigenvalue says how clearly; noise in the points'
 * own directions averages out over the heat kernel's width.
 */
#include "sdf_internal.h"
#include "core/error.h"
#include "heatvox/solve.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define LINES_TOL 1e-6 /* the heat steps' relative residual, as the pipeline's */

void hv__lines_free(pt_lines *L)
{
    for (int b = 0; b < 6; b++) {
        hv_free(L->T[b]);
        L->T[b] = NULL;
    }
}

/* The six products a d d^T of each point into vals (6 a point). */
static void tensors(const hv_points *P, const double *area, const double *dir, double *vals)
{
#pragma omp parallel for schedule(static)
    for (size_t i = 0; i < P->count; i++) {
        const double *d = dir + 3 * i, a = area[i];
        double *v = vals + 6 * i;
        v[0] = a * d[0] * d[0], v[1] = a * d[1] * d[1], v[2] = a * d[2] * d[2];
        v[3] = a * d[0] * d[1], v[4] = a * d[0] * d[2], v[5] = a * d[1] * d[2];
    }
}

/* One heat step (I - t Lap) per component, in place, sharing a solver (FFTW
 * on the box where this build has it, else multigrid). */
static hv_status lines_diffuse(pt_lines *L, double t, hv_backend backend)
{
    const hv_grid *g = L->g;
    hv_problem pb = {3, {g->n[0], g->n[1], g->n[2]}, g->h, NULL, 1.0, t};
    hv_solver_opts so;
    hv_solver_opts_default(&so);
    so.backend = backend == HV_BACKEND_OPENCL ? HV_BACKEND_AUTO : backend;
    so.tol = LINES_TOL;
    so.max_iter = 100;
    hv_solver *s = NULL;
    hv_status st = hv_solver_create(&s, &pb, &so);
    if (st == HV_ERR_UNSUPPORTED && so.backend == HV_BACKEND_AUTO) {
        so.backend = HV_BACKEND_MG;
        st = hv_solver_create(&s, &pb, &so);
    }
    const size_t count = hv_grid_count(g);
    float *u = st ? NULL : hv_malloc(count * sizeof *u);
    if (!st && !u)
        st = hv__error(HV_ERR_NOMEM, "points: out of memory for the line field (%zu cells)", count);
    for (int b = 0; b < 6 && !st; b++) {
        hv_solve_info info;
        if (!(st = hv_solver_solve(s, L->T[b], u, &info))) {
            memcpy(L->T[b], u, count * sizeof *u);
            L->iterations += info.iterations;
        }
    }
    hv_free(u);
    hv_solver_destroy(&s);
    return st;
}

hv_status hv__lines_build(pt_lines *L, const hv_points *P, const double *area, const double *dir,
                          const hv_grid *g, double t, hv_backend backend)
{
    memset(L, 0, sizeof *L);
    L->g = g;
    const size_t count = hv_grid_count(g);
    double *vals = malloc(6 * P->count * sizeof *vals);
    int ok = vals != NULL;
    for (int b = 0; b < 6 && ok; b++)
        ok = (L->T[b] = hv_calloc(count, sizeof(float))) != NULL;
    if (!ok) {
        free(vals);
        hv__lines_free(L);
        return hv__error(HV_ERR_NOMEM, "points: out of memory for the line field (%zu cells)",
                         count);
    }
    tensors(P, area, dir, vals);
    hv_quad q = {P->count, P->xyz, NULL, (double *)area};
    hv__sdf_splat(g, &q, 6, vals, 6, L->T);
    free(vals);
    hv_status st = lines_diffuse(L, t, backend);
    if (st)
        hv__lines_free(L);
    return st;
}

/* The principal direction of the tensor m and its anisotropy. */
static double principal(const double m[6], const double *along, double v[3])
{
    double lam[3], e[3][3];
    hv__sym3_axes(m, lam, e);
    int j = lam[0] >= lam[1] && lam[0] >= lam[2] ? 0 : lam[1] >= lam[2] ? 1 : 2;
    const double l1 = lam[j], l2 = fmax(lam[(j + 1) % 3], lam[(j + 2) % 3]);
    double len = sqrt(e[0][j] * e[0][j] + e[1][j] * e[1][j] + e[2][j] * e[2][j]);
    if (along && e[0][j] * along[0] + e[1][j] * along[1] + e[2][j] * along[2] < 0)
        len = -len;
    for (int k = 0; k < 3; k++)
        v[k] = e[k][j] / len;
    return l1 > 0 ? (l1 - l2) / l1 : 0;
}

double hv__lines_at(const pt_lines *L, const double x[3], const double *along, double v[3])
{
    size_t c0, step[3];
    double wt[8], m[6] = {0, 0, 0, 0, 0, 0};
    hv__trilinear(L->g, x, &c0, step, wt);
    for (int q = 0; q < 8; q++) {
        const size_t c = c0 + (q & 1 ? step[0] : 0) + (q & 2 ? step[1] : 0) + (q & 4 ? step[2] : 0);
        for (int b = 0; b < 6; b++)
            m[b] += wt[q] * L->T[b][c];
    }
    return principal(m, along, v);
}

double hv__lines_cell(const pt_lines *L, size_t c, double v[3])
{
    double m[6];
    for (int b = 0; b < 6; b++)
        m[b] = L->T[b][c];
    return principal(m, NULL, v);
}
