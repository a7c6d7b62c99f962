/* Multigrid and the solver interface: convergence factors, exactness against
 * analytic solutions and the FFTW oracle, null spaces, and bad input. */
#include "heatvox/petsc.h"
#include "solve/backend.h"
#include "solve/mg/mg_internal.h"
#include "solve/mg/mg_level.h"
#include "testlib.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

typedef struct {
    int dim, n[3];
    int mask; /* 0 none, 1 bulky ball, 2 two rooms split by a wall */
} shape;

static uint8_t *make_mask(const shape *s)
{
    if (!s->mask)
        return NULL;
    int nz = s->dim == 3 ? s->n[2] : 1;
    uint8_t *m = calloc((size_t)s->n[0] * s->n[1] * nz, 1);
    for (int k = 0; k < nz; k++)
        for (int j = 0; j < s->n[1]; j++)
            for (int i = 0; i < s->n[0]; i++) {
                double x = (i + 0.5) / s->n[0] - 0.5, y = (j + 0.5) / s->n[1] - 0.5,
                       z = s->dim == 3 ? (k + 0.5) / nz - 0.5 : 0;
                size_t c = i + (size_t)s->n[0] * (j + (size_t)s->n[1] * k);
                if (s->mask == 1)
                    m[c] = x * x + y * y + z * z < 0.09;
                else
                    m[c] = i == s->n[0] / 2 || i == s->n[0] / 2 + 1;
            }
    return m;
}

/* Solves a random right-hand side; returns the worst per-iteration residual
 * factor over the iterations above 1e-9 (past that float/double rounding rules). */
static double worst_factor(const shape *sh, double t_over_h2, int poisson, hv_smoother sm,
                           hv_solve_info *out)
{
    double h = 1.0 / sh->n[0];
    uint8_t *mask = make_mask(sh);
    hv_problem p = {sh->dim,
                    {sh->n[0], sh->n[1], sh->n[2]},
                    h,
                    mask,
                    poisson ? 0.0 : 1.0,
                    poisson ? 1.0 : t_over_h2 * h * h};
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.backend = HV_BACKEND_MG;
    o.smoother = sm;
    o.tol = 1e-9;
    o.cycles_per_iteration = 1; /* each history step is then one V-cycle */
    hv_solver *s = NULL;
    TL_ASSERT_OK(hv_solver_create(&s, &p, &o));
    size_t n = (size_t)sh->n[0] * sh->n[1] * (sh->dim == 3 ? sh->n[2] : 1);
    float *f = malloc(n * sizeof *f), *u = calloc(n, sizeof *u);
    tl_fill_random(f, n, 42);
    hv_solve_info info;
    TL_ASSERT_OK(hv_solver_solve(s, f, u, &info));
    ck_assert_int_eq(info.reason, HV_STOP_CONVERGED);
    ck_assert(info.relres <= 1e-9);
    ck_assert_int_eq(info.nhistory, info.iterations + 1);
    ck_assert_int_eq(info.cycles, info.iterations);
    double worst = 0;
    for (int i = 1; i < info.nhistory; i++)
        if (info.history[i - 1] > 1e-9)
            worst = fmax(worst, info.history[i] / info.history[i - 1]);
    if (out)
        *out = info;
    free(f);
    free(u);
    free(mask);
    hv_solver_destroy(&s);
    ck_assert_ptr_null(s);
    return worst;
}

static const shape shapes[] = {
    {3, {48, 48, 48}, 0},  {3, {37, 64, 80}, 0}, {3, {100, 100, 100}, 0}, {3, {48, 48, 48}, 1},
    {2, {128, 128, 1}, 0}, {2, {101, 77, 1}, 0}, {2, {96, 96, 1}, 1},
};
#define NSHAPES (int)(sizeof shapes / sizeof shapes[0])

START_TEST(vcycle_should_reduce_heat_residual_below_0_12_per_cycle)
{
    const double ts[] = {0.1, 4, 100};
    for (int t = 0; t < 3; t++) {
        double w = worst_factor(&shapes[_i], ts[t], 0, HV_SMOOTH_RBGS, NULL);
        ck_assert_msg(w <= 0.12, "shape %d (%dD %dx%dx%d mask %d) t/h2=%g: factor %.3f", _i,
                      shapes[_i].dim, shapes[_i].n[0], shapes[_i].n[1], shapes[_i].n[2],
                      shapes[_i].mask, ts[t], w);
    }
}
END_TEST

START_TEST(vcycle_should_reduce_poisson_residual_below_0_15_per_cycle)
{
    double w = worst_factor(&shapes[_i], 0, 1, HV_SMOOTH_RBGS, NULL);
    ck_assert_msg(w <= 0.15, "shape %d: Poisson factor %.3f", _i, w);
}
END_TEST

START_TEST(gpu_smoothers_should_converge)
{
    shape sh = {3, {40, 40, 40}, 0};
    hv_solve_info info;
    double wj = worst_factor(&sh, 4, 0, HV_SMOOTH_JACOBI, &info);
    ck_assert_msg(wj <= 0.3, "Jacobi factor %.3f", wj);
    double wc = worst_factor(&sh, 4, 0, HV_SMOOTH_CHEBYSHEV, &info);
    ck_assert_msg(wc <= 0.12, "Chebyshev factor %.3f", wc);
    double wp = worst_factor(&sh, 0, 1, HV_SMOOTH_CHEBYSHEV, &info);
    ck_assert_msg(wp <= 0.15, "Chebyshev Poisson factor %.3f", wp);
}
END_TEST

/* u = cos(pi x) cos(pi y) [cos(pi z)] on the unit box solves both problems with
 * f = (alpha + beta lambda) u, lambda = d pi^2. */
static double analytic_error(int dim, int n, int poisson, hv_backend b)
{
    double h = 1.0 / n, lam = dim * M_PI * M_PI, t = 4 * h * h;
    double alpha = poisson ? 0 : 1, beta = poisson ? 1 : t;
    hv_problem p = {dim, {n, n, n}, h, NULL, alpha, beta};
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.backend = b;
    o.tol = 1e-10;
    hv_solver *s = NULL;
    TL_ASSERT_OK(hv_solver_create(&s, &p, &o));
    size_t cnt = (size_t)n * n * (dim == 3 ? n : 1);
    double *f = malloc(cnt * sizeof *f), *u = calloc(cnt, sizeof *u),
           *ex = malloc(cnt * sizeof *ex);
    for (size_t c = 0; c < cnt; c++) {
        int i = c % n, j = (c / n) % n, k = (int)(c / ((size_t)n * n));
        double v = cos(M_PI * (i + 0.5) * h) * cos(M_PI * (j + 0.5) * h) *
                   (dim == 3 ? cos(M_PI * (k + 0.5) * h) : 1);
        ex[c] = v;
        f[c] = (alpha + beta * lam) * v;
    }
    hv_solve_info info;
    TL_ASSERT_OK(hv_solver_solve_d(s, f, u, &info));
    ck_assert_msg(info.relres <= 1e-10, "relres %g", info.relres);
    double e = 0;
    for (size_t c = 0; c < cnt; c++)
        e = fmax(e, fabs(u[c] - ex[c]));
    free(f);
    free(u);
    free(ex);
    hv_solver_destroy(&s);
    return e;
}

START_TEST(solutions_should_converge_at_second_order)
{
    for (int dim = 2; dim <= 3; dim++)
        for (int poisson = 0; poisson <= 1; poisson++) {
            double e1 = analytic_error(dim, 16, poisson, HV_BACKEND_MG);
            double e2 = analytic_error(dim, 32, poisson, HV_BACKEND_MG);
            double e3 = analytic_error(dim, 64, poisson, HV_BACKEND_MG);
            ck_assert_msg(e1 / e2 > 3.5 && e2 / e3 > 3.5, "dim %d poisson %d: %g %g %g", dim,
                          poisson, e1, e2, e3);
        }
}
END_TEST

/* The petsc backend is in builds with PETSc (make mpi, or make where
 * petsc-dev is installed; tested under mpirun by make mpi-check). Without
 * it, it says so and fails cleanly; with it, one process (MPI's singleton)
 * solves as mg does and computes the distance as hv_distance_compute. */
static void petsc_without_it(void)
{
    const int n[3] = {8, 8, 8};
    hv_problem p = {3, {n[0], n[1], n[2]}, 1.0 / 8, NULL, 1, 0.01};
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.backend = HV_BACKEND_PETSC;
    hv_solver *s = NULL;
    ck_assert_int_eq(hv_solver_create(&s, &p, &o), HV_ERR_UNSUPPORTED);
    ck_assert_ptr_null(s);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "make mpi"));
    ck_assert_int_eq(hv_mpi_rank(), 0);
    ck_assert_int_eq(hv_mpi_size(), 1);
    /* The distributed pipelines likewise. */
    hv_dmda_distance *D = (hv_dmda_distance *)&s; /* not NULL: the call must clear it */
    ck_assert_int_eq(hv_dmda_distance_create(&D, NULL, 0.1, NULL, NULL, NULL), HV_ERR_UNSUPPORTED);
    ck_assert_ptr_null(D);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "make mpi"));
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_grid_create(&g, 3, n, 1.0 / 8, NULL));
    const int vox[3] = {1, 1, 1};
    hv_distance_sources src = {vox, 1, NULL, 0, NULL};
    ck_assert_int_eq(hv_petsc_distance_block(g, &src, NULL, NULL), HV_ERR_UNSUPPORTED);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "make mpi"));
    hv_grid_destroy(&g);
    hv_petsc_finalize(); /* nothing to end */
}

static void petsc_with_it(void)
{
    const int n[3] = {19, 14, 11};
    const size_t count = (size_t)n[0] * n[1] * n[2];
    shape sh = {3, {n[0], n[1], n[2]}, 1};
    uint8_t *mask = make_mask(&sh);
    double *f = malloc(count * sizeof *f),
           *u[2] = {malloc(count * sizeof(double)), malloc(count * sizeof(double))};
    uint64_t seed = 5;
    for (size_t c = 0; c < count; c++)
        f[c] = tl_rand(&seed);
    hv_problem p = {3, {n[0], n[1], n[2]}, 1.0 / 19, mask, 1, 0.01};
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.tol = 1e-10;
    double umax = 0, dmax = 0;
    for (int q = 0; q < 2; q++) {
        o.backend = q ? HV_BACKEND_PETSC : HV_BACKEND_MG;
        hv_solver *s = NULL;
        hv_solve_info info;
        TL_ASSERT_OK(hv_solver_create(&s, &p, &o));
        TL_ASSERT_OK(hv_solver_solve_d(s, f, u[q], &info));
        ck_assert_int_eq(info.backend, o.backend);
        ck_assert_int_eq(info.reason, HV_STOP_CONVERGED);
        hv_solver_destroy(&s);
    }
    for (size_t c = 0; c < count; c++) {
        umax = fmax(umax, fabs(u[0][c]));
        dmax = fmax(dmax, fabs(u[0][c] - u[1][c]));
    }
    ck_assert_msg(dmax <= 1e-7 * umax, "petsc against mg: %g of %g", dmax, umax);
    const double srel = dmax / umax;
    ck_assert_int_eq(hv_mpi_size(), 1);
    /* The distance on one rank's "distributed" grid: hv_distance_compute's. */
    hv_grid *g[2] = {NULL, NULL};
    const double org[3] = {-0.2, 0.1, 0.3}, pt[3] = {-0.12, 0.2, 0.4};
    hv_distance_sources src = {NULL, 0, pt, 1, NULL};
    hv_distance_opts dopt;
    hv_distance_opts_default(&dopt);
    dopt.backend = HV_BACKEND_MG;
    dopt.whole_stages = 1; /* the DMDA's stages run on the whole box */
    hv_distance_stats S[2];
    for (int q = 0; q < 2; q++) {
        TL_ASSERT_OK(hv_grid_create(&g[q], 3, n, 1.0 / 19, org));
        TL_ASSERT_OK(hv_grid_add_mask(g[q]));
        memcpy(g[q]->solid, mask, count);
    }
    TL_ASSERT_OK(hv_distance_compute(g[0], &src, &dopt, &S[0]));
    TL_ASSERT_OK(hv_petsc_distance_block(g[1], &src, &dopt, &S[1]));
    ck_assert_int_eq(S[1].stages, S[0].stages);
    ck_assert_int_eq(S[1].backend, HV_BACKEND_PETSC);
    dmax = 0;
    for (size_t c = 0; c < count; c++) {
        ck_assert_int_eq(isfinite(g[0]->v[c]), isfinite(g[1]->v[c]));
        if (isfinite(g[0]->v[c]))
            dmax = fmax(dmax, fabs(g[0]->v[c] - g[1]->v[c]) * 19);
    }
    ck_assert_msg(dmax <= 1e-3, "distance, petsc against mg: %g voxels", dmax);
    printf("  petsc in one process: solve %.1e relative to mg, distance %.1e voxels\n", srel, dmax);
    for (int q = 0; q < 2; q++) {
        hv_grid_destroy(&g[q]);
        free(u[q]);
    }
    free(f);
    free(mask);
    hv_petsc_finalize();
}

START_TEST(petsc_backend_should_work_or_fail_clearly)
{
    hv_backend b;
    TL_ASSERT_OK(hv_backend_parse("petsc", &b));
    ck_assert_int_eq(b, HV_BACKEND_PETSC);
    ck_assert_str_eq(hv_backend_name(b), "petsc");
    if (hv_petsc_available())
        petsc_with_it();
    else
        petsc_without_it();
}
END_TEST

START_TEST(multigrid_and_fftw_should_agree)
{
    /* 4500 x 7: rows wider than the kernels' row buffers (MG_ROW_BUF) */
    const shape plain[] = {
        {3, {48, 48, 48}, 0}, {3, {37, 64, 80}, 0}, {2, {101, 77, 1}, 0}, {2, {4500, 7, 1}, 0}};
    for (int q = 0; q < (int)(sizeof plain / sizeof plain[0]); q++)
        for (int poisson = 0; poisson <= 1; poisson++) {
            const shape *sh = &plain[q];
            double h = 1.0 / sh->n[0];
            hv_problem p = {sh->dim,         {sh->n[0], sh->n[1], sh->n[2]}, h, NULL,
                            poisson ? 0 : 1, poisson ? 1 : 4 * h * h};
            size_t n = (size_t)sh->n[0] * sh->n[1] * (sh->dim == 3 ? sh->n[2] : 1);
            float *f = malloc(n * sizeof *f), *u1 = calloc(n, sizeof *u1),
                  *u2 = calloc(n, sizeof *u2);
            tl_fill_random(f, n, 9);
            hv_solver_opts o;
            hv_solver_opts_default(&o);
            o.tol = 1e-9;
            hv_solver *mg = NULL, *ff = NULL;
            o.backend = HV_BACKEND_MG;
            TL_ASSERT_OK(hv_solver_create(&mg, &p, &o));
            o.backend = HV_BACKEND_AUTO;
            TL_ASSERT_OK(hv_solver_create(&ff, &p, &o));
            ck_assert_int_eq(hv_solver_backend(ff), HV_BACKEND_FFTW);
            TL_ASSERT_OK(hv_solver_solve(mg, f, u1, NULL));
            hv_solve_info info;
            TL_ASSERT_OK(hv_solver_solve(ff, f, u2, &info));
            ck_assert_int_eq(info.reason, HV_STOP_EXACT);
            double num = 0, den = 0;
            for (size_t c = 0; c < n; c++) {
                num += (double)(u1[c] - u2[c]) * (u1[c] - u2[c]);
                den += (double)u2[c] * u2[c];
            }
            ck_assert_msg(sqrt(num / den) <= 1e-5, "shape %d poisson %d: rel diff %g", q, poisson,
                          sqrt(num / den));
            free(f);
            free(u1);
            free(u2);
            hv_solver_destroy(&mg);
            hv_solver_destroy(&ff);
        }
}
END_TEST

/* Rows wider than the kernels' row buffers, with solid cells: the weighted
 * levels' fallbacks (fine rows of 8300, coarse rows of 4150). */
START_TEST(wide_rows_with_solid_cells_should_converge)
{
    shape sh = {2, {8300, 5, 1}, 2};
    uint8_t *mask = make_mask(&sh);
    size_t n = (size_t)sh.n[0] * sh.n[1];
    double h = 1.0 / 64;
    hv_problem p = {2, {sh.n[0], sh.n[1], 1}, h, mask, 1, 4 * h * h};
    float *f = malloc(n * sizeof *f), *u = calloc(n, sizeof *u);
    tl_fill_random(f, n, 5);
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.backend = HV_BACKEND_MG;
    o.tol = 1e-8;
    hv_solver *s = NULL;
    TL_ASSERT_OK(hv_solver_create(&s, &p, &o));
    hv_solve_info info;
    TL_ASSERT_OK(hv_solver_solve(s, f, u, &info));
    ck_assert_msg(info.reason == HV_STOP_CONVERGED && info.iterations <= 20,
                  "reason %d after %d iterations at %g", (int)info.reason, info.iterations,
                  info.relres);
    for (size_t c = 0; c < n; c++)
        ck_assert(isfinite(u[c]) && (!mask[c] || u[c] == 0));
    hv_solver_destroy(&s);
    free(f);
    free(u);
    free(mask);
}
END_TEST

/* Region labels by a walk over single cells, the reference for the runs'
 * union-find: the same numbering (regions in the order of their first cell). */
static int flood_labels(const int n[3], const uint8_t *solid, int32_t *lab)
{
    size_t sy = (size_t)n[0], sz = sy * n[1], N = sz * n[2];
    size_t *stack = malloc(N * sizeof *stack);
    int nr = 0;
    for (size_t c = 0; c < N; c++)
        lab[c] = -1;
    for (size_t seed = 0; seed < N; seed++) {
        if (solid[seed] || lab[seed] >= 0)
            continue;
        size_t top = 0;
        stack[top++] = seed;
        lab[seed] = nr;
        while (top) {
            size_t c = stack[--top], i = c % sy, j = c / sy % n[1], k = c / sz;
            size_t nb[6];
            int m = 0;
            if (i > 0)
                nb[m++] = c - 1;
            if (i + 1 < sy)
                nb[m++] = c + 1;
            if (j > 0)
                nb[m++] = c - sy;
            if (j + 1 < (size_t)n[1])
                nb[m++] = c + sy;
            if (k > 0)
                nb[m++] = c - sz;
            if (k + 1 < (size_t)n[2])
                nb[m++] = c + sz;
            for (int q = 0; q < m; q++)
                if (!solid[nb[q]] && lab[nb[q]] < 0) {
                    lab[nb[q]] = nr;
                    stack[top++] = nb[q];
                }
        }
        nr++;
    }
    free(stack);
    return nr;
}

/* The solver's fluid regions (runs along x joined by a union-find) against a
 * flood fill: random masks near the percolation threshold, where regions
 * are many and wind, in 3D and 2D, and a comb whose teeth meet only at the
 * far end (a region that the runs join late). */
START_TEST(fluid_regions_should_match_a_flood_fill)
{
    const int sizes[3][3] = {{23, 19, 17}, {41, 37, 1}, {30, 8, 6}};
    uint64_t seed = 11;
    for (int t = 0; t < 7; t++) {
        const int *n = sizes[t < 3 ? 0 : t < 6 ? 1 : 2];
        size_t N = (size_t)n[0] * n[1] * n[2];
        uint8_t *m = malloc(N);
        int32_t *a = malloc(N * sizeof *a), *b = malloc(N * sizeof *b);
        double p = t < 6 ? 0.55 + 0.1 * (t % 3) : 0;
        for (size_t c = 0; c < N; c++) {
            int i = (int)(c % n[0]), j = (int)(c / n[0] % n[1]);
            m[c] = t < 6 ? (tl_rand(&seed) + 0.5) < p : (j < n[1] - 1 && i % 2 == 1);
        }
        int na = hv__label_regions(n, m, a), nb = flood_labels(n, m, b);
        ck_assert_msg(na == nb, "mask %d: %d regions, the flood fill finds %d", t, na, nb);
        for (size_t c = 0; c < N; c++)
            ck_assert_msg(a[c] == b[c], "mask %d, cell %zu: region %d, the flood fill's %d", t, c,
                          a[c], b[c]);
        ck_assert_int_ge(na, t < 6 ? 2 : 1);
        free(m);
        free(a);
        free(b);
    }
}
END_TEST

START_TEST(poisson_solution_should_be_mean_free_in_each_region)
{
    shape sh = {2, {64, 48, 1}, 2};
    uint8_t *mask = make_mask(&sh);
    double h = 1.0 / 64;
    hv_problem p = {2, {64, 48, 1}, h, mask, 0.0, 1.0};
    hv_solver *s = NULL;
    TL_ASSERT_OK(hv_solver_create(&s, &p, NULL));
    ck_assert_int_eq(hv_solver_backend(s), HV_BACKEND_MG);
    size_t n = 64 * 48;
    float *f = malloc(n * sizeof *f), *u = calloc(n, sizeof *u);
    /* Incompatible data: a different mean in each room. The solver projects it. */
    for (size_t c = 0; c < n; c++)
        f[c] = (c % 64) < 32 ? 1.0f + 0.1f * (float)((c * 7) % 5)
                             : -3.0f + 0.2f * (float)((c * 3) % 4);
    hv_solve_info info;
    TL_ASSERT_OK(hv_solver_solve(s, f, u, &info));
    ck_assert_int_eq(info.reason, HV_STOP_CONVERGED);
    double sum[2] = {0, 0};
    for (size_t c = 0; c < n; c++) {
        if (mask[c]) {
            ck_assert(u[c] == 0.0f);
            continue;
        }
        sum[(c % 64) >= 32] += u[c];
    }
    ck_assert_msg(fabs(sum[0]) < 1e-3 && fabs(sum[1]) < 1e-3, "region sums %g %g", sum[0], sum[1]);
    free(f);
    free(u);
    free(mask);
    hv_solver_destroy(&s);
}
END_TEST

/* A serpentine corridor (walls every 8 cells with a gap at alternate ends):
 * coarse levels cannot see the walls, so the V-cycle is a weak preconditioner
 * here, but it is a symmetric one (P^T restriction, symmetric smoothing) and CG
 * must keep converging rather than stall. */
START_TEST(pcg_should_converge_in_a_serpentine_corridor)
{
    const int n = 96;
    size_t N = (size_t)n * n;
    uint8_t *mask = calloc(N, 1);
    for (int j = 0; j < n; j++)
        for (int i = 0; i < n; i++) {
            int wall = (j % 8 == 7) && j < n - 2, gap_left = (j / 8) % 2;
            if (wall && !(gap_left ? i < 3 : i >= n - 3))
                mask[i + (size_t)n * j] = 1;
        }
    hv_problem p = {2, {n, n, 1}, 1.0 / n, mask, 0.0, 1.0};
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.backend = HV_BACKEND_MG;
    o.tol = 1e-10;
    o.max_iter = 300;
    hv_solver *s = NULL;
    TL_ASSERT_OK(hv_solver_create(&s, &p, &o));
    float *f = calloc(N, sizeof *f), *u = calloc(N, sizeof *u);
    f[5 + 2 * n] = 1;
    f[N - 10 - 2 * n] = -1;
    hv_solve_info info;
    TL_ASSERT_OK(hv_solver_solve(s, f, u, &info));
    ck_assert_msg(info.reason == HV_STOP_CONVERGED, "%s after %d iterations at %g",
                  hv_stop_reason_str(info.reason), info.iterations, info.relres);
    free(f);
    free(u);
    free(mask);
    hv_solver_destroy(&s);
}
END_TEST

START_TEST(solver_should_report_max_iterations_not_fail)
{
    hv_problem p = {3, {32, 32, 32}, 1.0 / 32, NULL, 0.0, 1.0};
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.backend = HV_BACKEND_MG;
    o.max_iter = 2;
    o.tol = 1e-12;
    hv_solver *s = NULL;
    TL_ASSERT_OK(hv_solver_create(&s, &p, &o));
    size_t n = 32 * 32 * 32;
    float *f = malloc(n * sizeof *f), *u = calloc(n, sizeof *u);
    tl_fill_random(f, n, 3);
    hv_solve_info info;
    TL_ASSERT_OK(hv_solver_solve(s, f, u, &info));
    ck_assert_int_eq(info.reason, HV_STOP_MAX_ITER);
    ck_assert_int_eq(info.iterations, 2);
    ck_assert(info.relres > 1e-12 && info.relres < 0.1);
    ck_assert(info.history[0] > info.history[1] && info.history[1] > info.history[2]);
    free(f);
    free(u);
    hv_solver_destroy(&s);
}
END_TEST

START_TEST(solver_should_reject_bad_input)
{
    hv_solver *s = NULL;
    hv_problem p = {3, {16, 16, 16}, 0.1, NULL, 1.0, 0.01};
    hv_problem bad = p;
    bad.n[1] = 0;
    ck_assert_int_eq(hv_solver_create(&s, &bad, NULL), HV_ERR_INVALID_ARG);
    bad = p;
    bad.n[0] = -5;
    ck_assert_int_eq(hv_solver_create(&s, &bad, NULL), HV_ERR_INVALID_ARG);
    bad = p;
    bad.beta = 0;
    ck_assert_int_eq(hv_solver_create(&s, &bad, NULL), HV_ERR_INVALID_ARG);
    bad = p;
    bad.alpha = -1;
    ck_assert_int_eq(hv_solver_create(&s, &bad, NULL), HV_ERR_INVALID_ARG);
    bad = p;
    bad.n[0] = bad.n[1] = bad.n[2] = 200000;
    ck_assert_int_eq(hv_solver_create(&s, &bad, NULL), HV_ERR_NOMEM);
    ck_assert_ptr_null(s);
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.tol = 0;
    ck_assert_int_eq(hv_solver_create(&s, &p, &o), HV_ERR_INVALID_ARG);
    /* FFTW cannot take obstacles. */
    uint8_t *mask = calloc(16 * 16 * 16, 1);
    mask[100] = 1;
    bad = p;
    bad.solid = mask;
    hv_solver_opts_default(&o);
    o.backend = HV_BACKEND_FFTW;
    ck_assert_int_eq(hv_solver_create(&s, &bad, &o), HV_ERR_UNSUPPORTED);
    free(mask);
    /* NaN in the right-hand side is an error, not a silent NaN solution. */
    TL_ASSERT_OK(hv_solver_create(&s, &p, NULL));
    size_t n = 16 * 16 * 16;
    float *f = calloc(n, sizeof *f), *u = calloc(n, sizeof *u);
    f[77] = NAN;
    ck_assert_int_eq(hv_solver_solve(s, f, u, NULL), HV_ERR_NUMERIC);
    ck_assert(strstr(hv_last_error(), "right-hand side") != NULL);
    f[77] = INFINITY;
    ck_assert_int_eq(hv_solver_solve(s, f, u, NULL), HV_ERR_NUMERIC);
    free(f);
    free(u);
    hv_solver_destroy(&s);
}
END_TEST

START_TEST(solve_many_should_match_single_solves)
{
    hv_problem p = {3, {24, 20, 16}, 0.05, NULL, 1.0, 0.01};
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.backend = HV_BACKEND_MG;
    hv_solver *s = NULL;
    TL_ASSERT_OK(hv_solver_create(&s, &p, &o));
    size_t n = 24 * 20 * 16;
    float *f[3], *u[3], *v = calloc(n, sizeof *v);
    for (int i = 0; i < 3; i++) {
        f[i] = malloc(n * sizeof(float));
        u[i] = calloc(n, sizeof(float));
        tl_fill_random(f[i], n, 100 + i);
    }
    hv_solve_info info[3];
    TL_ASSERT_OK(hv_solver_solve_many(s, 3, (const float *const *)f, u, info));
    for (int i = 0; i < 3; i++) {
        ck_assert_int_eq(info[i].reason, HV_STOP_CONVERGED);
        TL_ASSERT_OK(hv_solver_solve(s, f[i], v, NULL));
        for (size_t c = 0; c < n; c++)
            ck_assert_float_eq(u[i][c], v[c]);
        free(f[i]);
        free(u[i]);
    }
    free(v);
    hv_solver_destroy(&s);
}
END_TEST

/* Several float V-cycles per double correction (the default): fewer corrections
 * than one cycle each, no more cycles than one extra, every cycle counted, and
 * the reported residual is the true one of the returned solution. */
START_TEST(auto_cycles_should_save_corrections_and_report_the_true_residual)
{
    const shape cases[] = {{3, {48, 40, 36}, 0}, {2, {128, 96, 1}, 0}};
    const double tols[] = {1e-6, 1e-10};
    for (int c = 0; c < 2; c++)
        for (int poisson = 0; poisson < 2; poisson++)
            for (int t = 0; t < 2; t++) {
                const shape *sh = &cases[c];
                double h = 1.0 / sh->n[0];
                hv_problem p = {sh->dim,
                                {sh->n[0], sh->n[1], sh->n[2]},
                                h,
                                NULL,
                                poisson ? 0.0 : 1.0,
                                poisson ? 1.0 : 4 * h * h};
                size_t n = (size_t)sh->n[0] * sh->n[1] * (sh->dim == 3 ? sh->n[2] : 1);
                float *f = malloc(n * sizeof *f), *u = calloc(n, sizeof *u);
                double *fd = malloc(n * sizeof *fd), *ud = malloc(n * sizeof *ud),
                       *au = malloc(n * sizeof *au);
                tl_fill_random(f, n, 7 + c);
                double mean = 0;
                for (size_t i = 0; i < n; i++)
                    mean += f[i];
                mean /= (double)n;
                for (size_t i = 0; i < n; i++)
                    fd[i] = poisson ? f[i] - mean : f[i];
                hv_solve_info info[2];
                for (int one = 0; one < 2; one++) {
                    hv_solver_opts o;
                    hv_solver_opts_default(&o);
                    o.backend = HV_BACKEND_MG;
                    o.tol = tols[t];
                    o.cycles_per_iteration = one;
                    hv_solver *s = NULL;
                    TL_ASSERT_OK(hv_solver_create(&s, &p, &o));
                    TL_ASSERT_OK(hv_solver_solve_d(s, fd, ud, &info[one]));
                    hv_solver_destroy(&s);
                    /* the reported residual is the true one of the returned solution */
                    TL_ASSERT_OK(
                        hv_apply_helmholtz_d(p.dim, p.n, h, NULL, p.alpha, p.beta, ud, au));
                    double rr = 0, ff = 0;
                    for (size_t i = 0; i < n; i++) {
                        rr += (fd[i] - au[i]) * (fd[i] - au[i]);
                        ff += fd[i] * fd[i];
                    }
                    double rel = sqrt(rr / ff);
                    ck_assert_msg(fabs(rel - info[one].relres) <= 1e-6 * rel + 1e-14,
                                  "case %d poisson %d tol %g: relres %.9g, true %.9g", c, poisson,
                                  tols[t], info[one].relres, rel);
                }
                hv_solve_info *a = &info[0], *b = &info[1];
                ck_assert_int_eq(a->reason, HV_STOP_CONVERGED);
                ck_assert(a->relres <= tols[t]);
                ck_assert_int_eq(b->cycles, b->iterations);
                ck_assert_int_ge(a->cycles, a->iterations);
                ck_assert_msg(a->iterations < b->iterations && a->cycles <= b->cycles + 1,
                              "case %d poisson %d tol %g: auto %d/%d cycles, one per iteration %d",
                              c, poisson, tols[t], a->iterations, a->cycles, b->iterations);
                free(f);
                free(u);
                free(fd);
                free(ud);
                free(au);
            }
}
END_TEST

/* Two walls across x with a gap at opposite ends (a corridor), 3D. */
static uint8_t *make_baffles(int n)
{
    uint8_t *m = calloc((size_t)n * n * n, 1);
    for (int k = 0; k < n; k++)
        for (int j = 0; j < n; j++) {
            m[n / 3 + (size_t)n * (j + (size_t)n * k)] = j >= n / 8;
            m[2 * n / 3 + (size_t)n * (j + (size_t)n * k)] = j < n - n / 8;
        }
    return m;
}

/* Heat steps with solid cells correct by V-cycles as plain boxes do (several
 * cycles per correction) while a cycle gains 0.3 or more; with t large enough
 * to be nearly Poisson they hand over to PCG within the solve, and later
 * solves start with PCG. Either way the reported residual is the true one
 * and solid cells hold 0. */
START_TEST(masked_heat_steps_should_correct_then_hand_slow_solves_to_pcg)
{
    const int N = 40;
    const size_t n = (size_t)N * N * N;
    const double h = 1.0 / N, tscale[2] = {4, 4096};
    uint8_t *mask = make_baffles(N);
    double *fd = malloc(n * sizeof *fd), *ud = malloc(n * sizeof *ud), *au = malloc(n * sizeof *au);
    float *f = malloc(n * sizeof *f);
    tl_fill_random(f, n, 21);
    for (size_t c = 0; c < n; c++)
        fd[c] = f[c];
    for (int t = 0; t < 2; t++) {
        hv_problem p = {3, {N, N, N}, h, mask, 1.0, tscale[t] * h * h};
        hv_solver_opts o;
        hv_solver_opts_default(&o);
        o.backend = HV_BACKEND_MG;
        o.coarse = HV_COARSE_GEOMETRIC;
        o.tol = 1e-9;
        hv_solver *s = NULL;
        TL_ASSERT_OK(hv_solver_create(&s, &p, &o));
        hv_solve_info info[2];
        for (int rep = 0; rep < 2; rep++) {
            TL_ASSERT_OK(hv_solver_solve_d(s, fd, ud, &info[rep]));
            ck_assert_msg(info[rep].reason == HV_STOP_CONVERGED && info[rep].relres <= o.tol,
                          "t %g h^2, solve %d: %s at %g", tscale[t], rep,
                          hv_stop_reason_str(info[rep].reason), info[rep].relres);
            TL_ASSERT_OK(hv_apply_helmholtz_d(3, p.n, h, mask, p.alpha, p.beta, ud, au));
            double rr = 0, ff = 0;
            for (size_t c = 0; c < n; c++) {
                ck_assert(!mask[c] || ud[c] == 0.0);
                double r = mask[c] ? 0.0 : fd[c] - au[c];
                rr += r * r;
                ff += mask[c] ? 0.0 : fd[c] * fd[c];
            }
            double rel = sqrt(rr / ff);
            ck_assert_msg(fabs(rel - info[rep].relres) <= 1e-6 * rel + 1e-14,
                          "t %g h^2, solve %d: relres %.9g, true %.9g", tscale[t], rep,
                          info[rep].relres, rel);
        }
        if (t == 0) /* corrections of several cycles, the second solve as the first */
            ck_assert_msg(info[0].cycles > info[0].iterations && info[0].iterations <= 4 &&
                              info[1].iterations == info[0].iterations,
                          "t = 4 h^2: %d corrections, %d cycles; then %d", info[0].iterations,
                          info[0].cycles, info[1].iterations);
        else /* the first solve handed over after a slow correction; the next is PCG */
            ck_assert_msg(info[0].cycles > info[0].iterations &&
                              info[1].cycles == info[1].iterations,
                          "t = 4096 h^2: %d/%d, then %d/%d iterations/cycles", info[0].iterations,
                          info[0].cycles, info[1].iterations, info[1].cycles);
        hv_solver_destroy(&s);
    }
    free(mask);
    free(f);
    free(fd);
    free(ud);
    free(au);
}
END_TEST

/* The fused passes split a level into slabs of planes, one per thread, and
 * order the work at slab edges so that a sweep, its residual and the
 * restriction come out as on one thread: the same cycles on 1, 2, 3 and 5
 * threads must give the same bits (sizes with odd and short last slabs). */
START_TEST(cycles_should_not_depend_on_the_thread_count)
{
#ifdef _OPENMP
    const shape cases[] = {{3, {40, 33, 26}, 0},
                           {3, {64, 48, 13}, 0},
                           {3, {45, 20, 64}, 0},
                           {3, {37, 20, 29}, 1},
                           {3, {61, 24, 30}, 2}};
    const int threads[] = {1, 2, 3, 5};
    const int saved = omp_get_max_threads();
    for (int c = 0; c < 5; c++) {
        const shape *sh = &cases[c];
        double h = 1.0 / sh->n[0];
        uint8_t *mask = make_mask(sh);
        hv_problem p = {3, {sh->n[0], sh->n[1], sh->n[2]}, h, mask, 1.0, 4 * h * h};
        size_t n = (size_t)sh->n[0] * sh->n[1] * sh->n[2];
        float *f = malloc(n * sizeof *f), *u = malloc(n * sizeof *u), *u1 = malloc(n * sizeof *u1);
        tl_fill_random(f, n, 11 + c);
        for (int t = 0; t < 4; t++) {
            omp_set_num_threads(threads[t]);
            hv_solver_opts o;
            hv_solver_opts_default(&o);
            o.backend = HV_BACKEND_MG;
            o.tol = 1e-12; /* three iterations of one cycle each: not reached */
            o.max_iter = 3;
            o.cycles_per_iteration = 1;
            hv_solver *s = NULL;
            TL_ASSERT_OK(hv_solver_create(&s, &p, &o));
            hv_solve_info info;
            TL_ASSERT_OK(hv_solver_solve(s, f, t ? u : u1, &info));
            ck_assert_int_eq(info.reason, HV_STOP_MAX_ITER);
            hv_solver_destroy(&s);
            if (!t)
                continue;
            size_t bad = 0, first = 0;
            for (size_t i = 0; i < n; i++)
                if (memcmp(&u[i], &u1[i], sizeof(float)) && !bad++)
                    first = i;
            ck_assert_msg(
                !bad,
                "%dx%dx%d on %d threads: %zu cells differ from one thread, first at plane %zu",
                sh->n[0], sh->n[1], sh->n[2], threads[t], bad,
                first / ((size_t)sh->n[0] * sh->n[1]));
        }
        free(f);
        free(u);
        free(u1);
        free(mask);
    }
    omp_set_num_threads(saved);
#endif
}
END_TEST

#if MG_MULTIVERSION
/* A mask's fine level smooths in the fused pass with the AVX2 row or the C
 * row (both compute every cell of a row and write it back whole) where the
 * CPU has no AVX-512: the same cycles to float rounding, on rows whose length
 * is a multiple of 8, is not, and is under 8 (the masked chunk alone). */
START_TEST(binary_rows_should_agree_across_kernels)
{
    if (!hv__mg_avx2_probe())
        TL_SKIP("binary rows: no AVX2 and FMA on this CPU, the C row alone runs");
    const shape cases[] = {{3, {40, 24, 20}, 1}, {3, {37, 20, 29}, 2}, {3, {5, 24, 16}, 2}};
    const int saved512 = hv__mg_avx512_state, saved2 = hv__mg_avx2_state;
    for (int c = 0; c < 3; c++) {
        const shape *sh = &cases[c];
        double h = 1.0 / sh->n[0];
        uint8_t *mask = make_mask(sh);
        hv_problem p = {3, {sh->n[0], sh->n[1], sh->n[2]}, h, mask, 1.0, 5.3 * h * h};
        size_t n = (size_t)sh->n[0] * sh->n[1] * sh->n[2];
        float *f = malloc(n * sizeof *f), *u[2];
        tl_fill_random(f, n, 5 + c);
        for (int k = 0; k < 2; k++) {
            hv__mg_avx512_state = 0;
            hv__mg_avx2_state = k; /* 0: the C row, 1: AVX2 */
            hv_solver_opts o;
            hv_solver_opts_default(&o);
            o.backend = HV_BACKEND_MG;
            o.coarse = HV_COARSE_GEOMETRIC;
            o.tol = 1e-12; /* two iterations: not reached */
            o.max_iter = 2;
            hv_solver *s = NULL;
            TL_ASSERT_OK(hv_solver_create(&s, &p, &o));
            hv_solve_info info;
            u[k] = calloc(n, sizeof *u[k]);
            TL_ASSERT_OK(hv_solver_solve(s, f, u[k], &info));
            hv_solver_destroy(&s);
        }
        double d = 0, m = 0;
        for (size_t i = 0; i < n; i++) {
            d = fmax(d, fabs((double)u[1][i] - u[0][i]));
            m = fmax(m, fabs((double)u[0][i]));
        }
        printf("  binary rows %dx%dx%d: AVX2 against C %.2e of %.2e\n", sh->n[0], sh->n[1],
               sh->n[2], d, m);
        ck_assert_msg(m > 0 && d <= 1e-5 * m, "%dx%dx%d: AVX2 and C rows differ by %g (max %g)",
                      sh->n[0], sh->n[1], sh->n[2], d, m);
        free(u[0]);
        free(u[1]);
        free(f);
        free(mask);
    }
    hv__mg_avx512_state = saved512;
    hv__mg_avx2_state = saved2;
}
END_TEST
#endif

/* One axis of the cell-centred prolongation, written out independently of
 * mg_transfer.c: weight of coarse index I for fine index i among nc coarse cells. */
static double p_axis(int coarsen, int nc, int i, int I)
{
    if (!coarsen)
        return i == I;
    int I0 = i / 2, nb = (i & 1) ? I0 + 1 : I0 - 1;
    if (nb < 0 || nb >= nc)
        return I == I0;
    return I == I0 ? 0.75 : I == nb ? 0.25 : 0.0;
}

/* The PCG restriction must be the transpose of the renormalized prolongation
 * (else CG loses conjugacy): <R r, v>_C 2^d = <r, P v>_F for random r and v, on
 * odd and even sizes with solid cells, 2D and 3D, on 1 and 3 threads (grids
 * above MG_PAR_MIN cells run threaded). */
START_TEST(restriction_should_be_the_transpose_of_prolongation)
{
    const shape shapes[] = {
        {3, {13, 10, 7}, 1},  {3, {16, 9, 12}, 2},  {3, {21, 18, 16}, 1},
        {2, {45, 38, 1}, 1},  {2, {60, 61, 1}, 2},  {3, {12, 12, 12}, 0},
        {3, {40, 33, 27}, 1}, {2, {250, 141, 1}, 2}}; /* the last two run threaded */
    for (size_t q = 0; q < sizeof shapes / sizeof shapes[0]; q++) {
        const shape *sh = &shapes[q];
        uint8_t *solid = make_mask(sh);
        hv_setup st;
        memset(&st, 0, sizeof st);
        st.p = (hv_problem){sh->dim, {sh->n[0], sh->n[1], sh->n[2]}, 1.0, solid, 1.0, 2.0};
        hv_solver_opts_default(&st.o);
        st.count = (size_t)sh->n[0] * sh->n[1] * sh->n[2];
        st.nregion = 1;
        mg_hierarchy H;
        ck_assert_int_eq(hv__mg_hierarchy_build(&H, &st, 0), HV_OK);
        ck_assert_msg(H.nlev >= 2, "shape %zu: one level", q);
        for (int l = 0; l + 1 < H.nlev; l++) {
            const mg_level *F = &H.lv[l], *C = &H.lv[l + 1];
            float *r = malloc(F->count * sizeof(float)), *pn = malloc(F->count * sizeof(float));
            float *fc = malloc(C->count * sizeof(float)), *v = malloc(C->count * sizeof(float));
            const int nt = 3;
            float *work = malloc((size_t)nt * mg_restrict_transpose_work(F, C) * sizeof(float));
            ck_assert(r && pn && fc && v && work);
            tl_fill_random(r, F->count, 1000 + 77 * q + l);
            tl_fill_random(v, C->count, 2000 + 77 * q + l);
            const float *pnp = NULL;
            if (!C->plain) {
                hv__mg_prolong_norm(F, C, pn);
                pnp = pn;
            }
            int nchild = 1;
            for (int b = 0; b < sh->dim; b++)
                nchild *= F->coarsen[b] ? 2 : 1;
            double rhs = 0, mag = 0;
            for (int k = 0; k < F->n[2]; k++)
                for (int j = 0; j < F->n[1]; j++)
                    for (int i = 0; i < F->n[0]; i++) {
                        size_t fcell = i + F->sy * j + F->sz * k;
                        double pv = 0, ws = 0;
                        /* coarse cells within one of i/2 (p_axis is 0 further out) */
                        int lo[3], hi[3], fi[3] = {i, j, k};
                        for (int b = 0; b < 3; b++) {
                            lo[b] = F->coarsen[b] ? fi[b] / 2 - 1 : fi[b];
                            hi[b] = F->coarsen[b] ? fi[b] / 2 + 1 : fi[b];
                            lo[b] = lo[b] < 0 ? 0 : lo[b];
                            hi[b] = hi[b] > C->n[b] - 1 ? C->n[b] - 1 : hi[b];
                        }
                        for (int K = lo[2]; K <= hi[2]; K++)
                            for (int J = lo[1]; J <= hi[1]; J++)
                                for (int I = lo[0]; I <= hi[0]; I++) {
                                    double w = p_axis(F->coarsen[0], C->n[0], i, I) *
                                               p_axis(F->coarsen[1], C->n[1], j, J) *
                                               p_axis(F->coarsen[2], C->n[2], k, K);
                                    size_t cc = I + C->sy * J + C->sz * K;
                                    if (w == 0 || (!C->plain && C->a[cc] == 0))
                                        continue;
                                    pv += w * v[cc];
                                    ws += w;
                                }
                        if (!C->plain)
                            pv = (F->plain || F->a[fcell] != 0) && ws > 0 ? pv / ws : 0;
                        rhs += (double)r[fcell] * pv;
                        mag += fabs((double)r[fcell] * pv);
                    }
            for (int threads = 1; threads <= nt; threads += nt - 1) {
                hv__mg_restrict_transpose(F, C, sh->dim, pnp, r, fc, work, threads);
                double lhs = 0;
                for (size_t c = 0; c < C->count; c++)
                    lhs += (double)fc[c] * v[c] * nchild;
                ck_assert_msg(fabs(lhs - rhs) <= 1e-5 * mag,
                              "shape %zu level %d, %d threads: <Rr,v> 2^d = %.9g, <r,Pv> = %.9g", q,
                              l, threads, lhs, rhs);
            }
            free(r), free(pn), free(fc), free(v), free(work);
        }
        hv__mg_hierarchy_free(&H);
        free(solid);
    }
}
END_TEST

int main(void)
{
    Suite *s = suite_create("mg");
    TCase *tc = tcase_create("multigrid");
    tcase_set_timeout(tc, 120);
    tcase_add_loop_test(tc, vcycle_should_reduce_heat_residual_below_0_12_per_cycle, 0, NSHAPES);
    tcase_add_loop_test(tc, vcycle_should_reduce_poisson_residual_below_0_15_per_cycle, 0, NSHAPES);
    tcase_add_test(tc, cycles_should_not_depend_on_the_thread_count);
#if MG_MULTIVERSION
    tcase_add_test(tc, binary_rows_should_agree_across_kernels);
#endif
    tcase_add_test(tc, restriction_should_be_the_transpose_of_prolongation);
    tcase_add_test(tc, wide_rows_with_solid_cells_should_converge);
    tcase_add_test(tc, masked_heat_steps_should_correct_then_hand_slow_solves_to_pcg);
    tcase_add_test(tc, gpu_smoothers_should_converge);
    tcase_add_test(tc, auto_cycles_should_save_corrections_and_report_the_true_residual);
    tcase_add_test(tc, solutions_should_converge_at_second_order);
    tcase_add_test(tc, multigrid_and_fftw_should_agree);
    tcase_add_test(tc, petsc_backend_should_work_or_fail_clearly);
    tcase_add_test(tc, poisson_solution_should_be_mean_free_in_each_region);
    tcase_add_test(tc, fluid_regions_should_match_a_flood_fill);
    tcase_add_test(tc, pcg_should_converge_in_a_serpentine_corridor);
    tcase_add_test(tc, solver_should_report_max_iterations_not_fail);
    tcase_add_test(tc, solver_should_reject_bad_input);
    tcase_add_test(tc, solve_many_should_match_single_solves);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
