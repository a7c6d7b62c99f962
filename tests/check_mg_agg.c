/* The CPU multigrid's coarse levels by smoothed aggregation (agg_*.c): walls
 * one cell thick, mazes, regions cut apart, odd sizes, 2D, heat steps, the
 * AUTO change after a slow solve, and agreement with the geometric levels. */
#include "solve/backend.h"
#include "solve/mg/mg_agg.h"
#include "testlib.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Walls one cell thick across x at n/3 and 2n/3, with gaps of n/8 at
 * opposite ends in y (bench solve's baffles), in a dim-D box. */
static uint8_t *baffles(int dim, const int n[3])
{
    int nz = dim == 3 ? n[2] : 1;
    uint8_t *m = calloc((size_t)n[0] * n[1] * nz, 1);
    int w1 = n[0] / 3, w2 = 2 * n[0] / 3, gap = n[1] / 8 > 1 ? n[1] / 8 : 1;
    for (int k = 0; k < nz; k++)
        for (int j = 0; j < n[1]; j++) {
            size_t row = (size_t)n[0] * (j + (size_t)n[1] * k);
            if (j < n[1] - gap)
                m[row + w1] = 1;
            if (j >= gap)
                m[row + w2] = 1;
        }
    return m;
}

/* Walls across x and y every `pitch` cells, each panel with one square gap. */
static uint8_t *maze(const int n[3], int pitch)
{
    uint8_t *m = calloc((size_t)n[0] * n[1] * n[2], 1);
    uint64_t seed = 7;
    int g = pitch / 4 > 1 ? pitch / 4 : 1;
    for (int axis = 0; axis < 2; axis++)
        for (int x = pitch / 2; x < n[axis]; x += pitch)
            for (int y0 = 0; y0 < n[1 - axis]; y0 += pitch)
                for (int z0 = 0; z0 < n[2]; z0 += pitch) {
                    int gy = y0 + (int)((tl_rand(&seed) + 0.5) * (pitch - g));
                    int gz = z0 + (int)((tl_rand(&seed) + 0.5) * (pitch - g));
                    for (int z = z0; z < z0 + pitch && z < n[2]; z++)
                        for (int y = y0; y < y0 + pitch && y < n[1 - axis]; y++) {
                            if (y >= gy && y < gy + g && z >= gz && z < gz + g)
                                continue;
                            int i = axis == 0 ? x : y, j = axis == 0 ? y : x;
                            m[i + (size_t)n[0] * (j + (size_t)n[1] * z)] = 1;
                        }
                }
    return m;
}

typedef struct run {
    hv_solve_info info;
    hv_solver_stats stats;
    float *u;
} run;

/* Solves p for f to tol with the given coarse levels; r->u is malloc'ed. */
static void solve(const hv_problem *p, hv_coarse coarse, double tol, const float *f, run *r)
{
    size_t n = (size_t)p->n[0] * p->n[1] * (p->dim == 3 ? p->n[2] : 1);
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.backend = HV_BACKEND_MG;
    o.coarse = coarse;
    o.tol = tol;
    o.max_iter = 300;
    hv_solver *s = NULL;
    TL_ASSERT_OK(hv_solver_create(&s, p, &o));
    r->u = calloc(n, sizeof *r->u);
    TL_ASSERT_OK(hv_solver_solve(s, f, r->u, &r->info));
    TL_ASSERT_OK(hv_solver_get_stats(s, &r->stats));
    ck_assert_msg(r->info.reason == HV_STOP_CONVERGED, "%s after %d iterations at %g",
                  hv_stop_reason_str(r->info.reason), r->info.iterations, r->info.relres);
    for (size_t c = 0; c < n; c++)
        ck_assert(isfinite(r->u[c]) && (!p->solid || !p->solid[c] || r->u[c] == 0));
    hv_solver_destroy(&s);
}

/* max |a - b| over max |b|. */
static double rel_diff(const float *a, const float *b, size_t n)
{
    double d = 0, m = 0;
    for (size_t c = 0; c < n; c++) {
        d = fmax(d, fabs((double)a[c] - b[c]));
        m = fmax(m, fabs((double)b[c]));
    }
    return m > 0 ? d / m : d;
}

static float *random_rhs(size_t n, uint64_t seed)
{
    float *f = malloc(n * sizeof *f);
    tl_fill_random(f, n, seed);
    return f;
}

/* Baffles and a maze, Poisson to 1e-9: aggregation takes few iterations where
 * the geometric levels take many, and both give the same solution. */
START_TEST(aggregation_should_see_thin_walls)
{
    const int n[3] = {48, 48, 48};
    size_t N = (size_t)n[0] * n[1] * n[2];
    uint8_t *masks[2] = {baffles(3, n), maze(n, 8)};
    const char *names[2] = {"baffles", "maze"};
    float *f = random_rhs(N, 11);
    for (int q = 0; q < 2; q++) {
        hv_problem p = {3, {n[0], n[1], n[2]}, 1.0 / n[0], masks[q], 0.0, 1.0};
        run a, g;
        solve(&p, HV_COARSE_AGGREGATION, 1e-9, f, &a);
        solve(&p, HV_COARSE_GEOMETRIC, 1e-9, f, &g);
        ck_assert_msg(a.stats.aggregation_levels >= 3, "%s: %d aggregation levels", names[q],
                      a.stats.aggregation_levels);
        ck_assert_int_eq(g.stats.aggregation_levels, 0);
        /* To 1e-9 (1e-6 takes about two thirds of these). */
        ck_assert_msg(a.info.iterations <= (q ? 14 : 10) &&
                          g.info.iterations >= a.info.iterations + 5,
                      "%s: %d iterations with aggregation, %d geometric", names[q],
                      a.info.iterations, g.info.iterations);
        double d = rel_diff(a.u, g.u, N);
        ck_assert_msg(d < 1e-5, "%s: solutions differ by %g", names[q], d);
        free(a.u);
        free(g.u);
        free(masks[q]);
    }
    free(f);
}
END_TEST

/* Iterations do not grow with the grid: baffles at 32^3 and 64^3. */
START_TEST(aggregation_iterations_should_not_grow_with_n)
{
    int its[2];
    for (int q = 0; q < 2; q++) {
        int m = q ? 64 : 32;
        const int n[3] = {m, m, m};
        size_t N = (size_t)m * m * m;
        uint8_t *mask = baffles(3, n);
        float *f = random_rhs(N, 3);
        hv_problem p = {3, {m, m, m}, 1.0 / m, mask, 0.0, 1.0};
        run a;
        solve(&p, HV_COARSE_AGGREGATION, 1e-6, f, &a);
        its[q] = a.info.iterations;
        free(a.u);
        free(f);
        free(mask);
    }
    ck_assert_msg(its[0] <= 9 && its[1] <= its[0] + 1, "iterations %d (32^3), %d (64^3)", its[0],
                  its[1]);
}
END_TEST

/* A wall across the whole box, a sealed pocket and a lone cell: each fluid
 * region keeps its own null space on every level, so incompatible data is
 * projected per region and the solution is mean-free in each. */
START_TEST(regions_cut_apart_should_each_stay_mean_free)
{
    const int n[3] = {40, 36, 30};
    size_t N = (size_t)n[0] * n[1] * n[2];
    uint8_t *mask = calloc(N, 1);
    int32_t *region = malloc(N * sizeof *region);
    for (int k = 0; k < n[2]; k++)
        for (int j = 0; j < n[1]; j++)
            for (int i = 0; i < n[0]; i++) {
                size_t c = i + (size_t)n[0] * (j + (size_t)n[1] * k);
                int pocket = i >= 26 && i <= 32 && j >= 4 && j <= 10 && k >= 4 && k <= 10;
                int inside = i >= 27 && i <= 31 && j >= 5 && j <= 9 && k >= 5 && k <= 9;
                int lone = i >= 5 && i <= 7 && j >= 5 && j <= 7 && k >= 5 && k <= 7;
                mask[c] = i == 17 || (pocket && !inside) || (lone && !(i == 6 && j == 6 && k == 6));
                region[c] = mask[c] ? -1 : inside ? 2 : (i == 6 && j == 6 && k == 6) ? 3 : i > 17;
            }
    float *f = random_rhs(N, 17);
    for (size_t c = 0; c < N; c++)
        f[c] += region[c] == 1 ? 2.0f : region[c] == 2 ? -5.0f : 0.0f;
    hv_problem p = {3, {n[0], n[1], n[2]}, 1.0 / n[0], mask, 0.0, 1.0};
    run a;
    solve(&p, HV_COARSE_AGGREGATION, 1e-8, f, &a);
    ck_assert_int_gt(a.stats.aggregation_levels, 1);
    ck_assert_int_le(a.info.iterations, 12);
    double sum[4] = {0}, cnt[4] = {0};
    for (size_t c = 0; c < N; c++)
        if (region[c] >= 0) {
            sum[region[c]] += a.u[c];
            cnt[region[c]] += 1;
        }
    for (int r = 0; r < 4; r++)
        ck_assert_msg(fabs(sum[r]) / cnt[r] < 1e-5, "region %d: mean %g over %g cells", r,
                      sum[r] / cnt[r], cnt[r]);
    free(a.u);
    free(f);
    free(region);
    free(mask);
}
END_TEST

/* 2D (a serpentine corridor, odd sizes) and an odd 3D box with baffles, as
 * heat steps and Poisson. */
START_TEST(aggregation_should_solve_2d_odd_sizes_and_heat_steps)
{
    const int n2[3] = {101, 77, 1};
    size_t N2 = (size_t)n2[0] * n2[1];
    uint8_t *m2 = calloc(N2, 1);
    for (int j = 0; j < n2[1]; j++)
        for (int i = 0; i < n2[0]; i++)
            if (j % 8 == 7 && j < n2[1] - 2 && !((j / 8) % 2 ? i < 3 : i >= n2[0] - 3))
                m2[i + (size_t)n2[0] * j] = 1;
    const int n3[3] = {37, 29, 23};
    size_t N3 = (size_t)n3[0] * n3[1] * n3[2];
    uint8_t *m3 = baffles(3, n3);
    float *f = random_rhs(N3, 5);
    for (int heat = 0; heat < 2; heat++) {
        double h2 = 1.0 / n2[0], h3 = 1.0 / n3[0];
        hv_problem p2 = {2, {n2[0], n2[1], 1}, h2, m2, heat ? 1.0 : 0.0, heat ? 4 * h2 * h2 : 1.0};
        hv_problem p3 = {3,  {n3[0], n3[1], n3[2]}, h3,
                         m3, heat ? 1.0 : 0.0,      heat ? 4 * h3 * h3 : 1.0};
        run a, g;
        solve(&p2, HV_COARSE_AGGREGATION, 1e-9, f, &a);
        solve(&p2, HV_COARSE_GEOMETRIC, 1e-9, f, &g);
        ck_assert_int_gt(a.stats.aggregation_levels, 1);
        ck_assert_msg(a.info.iterations <= (heat ? 8 : 14), "2D: %d iterations", a.info.iterations);
        ck_assert_msg(rel_diff(a.u, g.u, N2) < 1e-5, "2D: solutions differ");
        free(a.u);
        free(g.u);
        solve(&p3, HV_COARSE_AGGREGATION, 1e-9, f, &a);
        solve(&p3, HV_COARSE_GEOMETRIC, 1e-9, f, &g);
        ck_assert_msg(a.info.iterations <= (heat ? 8 : 12), "3D odd: %d iterations",
                      a.info.iterations);
        ck_assert_msg(rel_diff(a.u, g.u, N3) < 1e-5, "3D odd: solutions differ");
        free(a.u);
        free(g.u);
    }
    free(f);
    free(m2);
    free(m3);
}
END_TEST

/* AUTO starts on the geometric levels and, when its first iterations stall
 * at the walls, builds the aggregation within that first solve and goes on
 * with it (the later solves take it from the start); a solve whose geometric
 * levels do well keeps them, with the same iterates as GEOMETRIC. A grid too
 * small to aggregate keeps the geometric levels even when aggregation is
 * asked. */
START_TEST(auto_should_change_to_aggregation_within_a_slow_solve)
{
    const int n[3] = {48, 48, 48};
    size_t N = (size_t)n[0] * n[1] * n[2];
    uint8_t *mask = baffles(3, n);
    float *f = random_rhs(N, 23);
    hv_problem p = {3, {n[0], n[1], n[2]}, 1.0 / n[0], mask, 0.0, 1.0};
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.backend = HV_BACKEND_MG;
    hv_solver *s = NULL;
    TL_ASSERT_OK(hv_solver_create(&s, &p, &o));
    float *u0 = calloc(N, sizeof *u0), *u1 = calloc(N, sizeof *u1);
    hv_solve_info i0, i1;
    hv_solver_stats s0, s1;
    TL_ASSERT_OK(hv_solver_solve(s, f, u0, &i0));
    TL_ASSERT_OK(hv_solver_get_stats(s, &s0));
    TL_ASSERT_OK(hv_solver_solve(s, f, u1, &i1));
    TL_ASSERT_OK(hv_solver_get_stats(s, &s1));
    run g;
    solve(&p, HV_COARSE_GEOMETRIC, 1e-6, f, &g);
    ck_assert_msg(g.info.iterations > 16, "geometric: %d iterations", g.info.iterations);
    ck_assert_int_gt(s0.aggregation_levels, 1);
    ck_assert_msg(i0.iterations <= 12 && i0.iterations < g.info.iterations - 8,
                  "first solve: %d iterations, geometric %d", i0.iterations, g.info.iterations);
    ck_assert_int_eq(i0.nhistory, i0.iterations + 1);
    ck_assert(i0.relres <= 1e-6 && i0.reason == HV_STOP_CONVERGED);
    ck_assert_int_eq(s1.aggregation_levels, s0.aggregation_levels);
    ck_assert_msg(i1.iterations <= 8, "second solve: %d iterations", i1.iterations);
    ck_assert(i1.relres <= 1e-6);
    ck_assert_msg(rel_diff(u1, u0, N) < 1e-4, "solutions differ by %g", rel_diff(u1, u0, N));
    ck_assert_msg(rel_diff(g.u, u0, N) < 1e-4, "solutions differ by %g", rel_diff(g.u, u0, N));
    hv_solver_destroy(&s);
    free(g.u);
    free(mask);

    /* A heat step at 4 h^2 around the same walls converges on the geometric
     * levels: AUTO keeps them, iterate for iterate. */
    mask = baffles(3, n);
    hv_problem heat = {3, {n[0], n[1], n[2]}, 1.0 / n[0], mask, 1.0, 4.0 / (n[0] * n[0])};
    run ah, gh;
    solve(&heat, HV_COARSE_AUTO, 1e-6, f, &ah);
    solve(&heat, HV_COARSE_GEOMETRIC, 1e-6, f, &gh);
    ck_assert_int_eq(ah.stats.aggregation_levels, 0);
    ck_assert_int_eq(ah.info.iterations, gh.info.iterations);
    ck_assert(memcmp(ah.u, gh.u, N * sizeof *ah.u) == 0);
    free(ah.u);
    free(gh.u);
    /* So does Poisson around a solid ball, through the probe of its PCG. */
    for (int k = 0; k < n[2]; k++)
        for (int j = 0; j < n[1]; j++)
            for (int i = 0; i < n[0]; i++) {
                double x = i + 0.5 - n[0] / 2.0, y = j + 0.5 - n[1] / 2.0, z = k + 0.5 - n[2] / 2.0;
                mask[i + n[0] * ((size_t)j + n[1] * k)] =
                    x * x + y * y + z * z < n[0] * n[0] / 16.0;
            }
    hv_problem ball = {3, {n[0], n[1], n[2]}, 1.0 / n[0], mask, 0.0, 1.0};
    solve(&ball, HV_COARSE_AUTO, 1e-6, f, &ah);
    solve(&ball, HV_COARSE_GEOMETRIC, 1e-6, f, &gh);
    ck_assert_int_eq(ah.stats.aggregation_levels, 0);
    ck_assert_msg(gh.info.iterations > MG_AGG_PROBE, "ball: %d iterations", gh.info.iterations);
    ck_assert_int_eq(ah.info.iterations, gh.info.iterations);
    ck_assert_int_eq(ah.info.cycles, gh.info.cycles);
    ck_assert(memcmp(ah.u, gh.u, N * sizeof *ah.u) == 0);
    free(ah.u);
    free(gh.u);
    free(mask);
    free(f);

    const int m[3] = {8, 8, 8};
    mask = baffles(3, m);
    f = random_rhs(512, 2);
    hv_problem small = {3, {8, 8, 8}, 1.0 / 8, mask, 0.0, 1.0};
    run a;
    solve(&small, HV_COARSE_AGGREGATION, 1e-8, f, &a);
    ck_assert_int_eq(a.stats.aggregation_levels, 0);
    free(a.u);
    free(mask);
    free(f);
    free(u0);
    free(u1);
}
END_TEST

/* The geometric hierarchy (*H) of an n[0] x n[1] x n[2] box with solid cells
 * `mask`, Poisson or a heat step at 4h^2, and the aggregation levels under
 * its fine level. */
static mg_agg *build_levels(const int n[3], const uint8_t *mask, int heat, hv_setup *s,
                            mg_hierarchy *H)
{
    memset(s, 0, sizeof *s);
    double h = 1.0 / n[0];
    s->p = (hv_problem){3, {n[0], n[1], n[2]}, h, mask, heat ? 1.0 : 0.0, heat ? 4 * h * h : 1.0};
    hv_solver_opts_default(&s->o);
    s->count = (size_t)n[0] * n[1] * n[2];
    s->nregion = 1;
    TL_ASSERT_OK(hv__mg_hierarchy_build(H, s, 0));
    mg_agg *g = NULL;
    TL_ASSERT_OK(hv__mg_agg_build(&g, &H->lv[0], 3, s->p.alpha));
    ck_assert_ptr_nonnull(g);
    return g;
}

/* Level 1's operator against P^T A P computed from its definition with the
 * fine level's own apply (double): columns of plain rows (the template) and
 * of rows next to the walls and the box's faces (the hash-table path, most
 * of them copies of their class's row), heat and Poisson, on the baffles and
 * on a maze of odd size. */
#define WALL_ROWS 40
START_TEST(galerkin_rows_should_be_p_transpose_a_p)
{
    const int sizes[2][3] = {{40, 38, 36}, {37, 35, 33}};
    for (int scene = 0; scene < 4; scene++) {
        const int *n = sizes[scene / 2], heat = scene % 2;
        size_t N = (size_t)n[0] * n[1] * n[2];
        uint8_t *mask = scene < 2 ? baffles(3, n) : maze(n, 8);
        {
            hv_setup s;
            mg_hierarchy H;
            mg_agg *g = build_levels(n, mask, heat, &s, &H);
            const mg_alevel *L0 = &g->lv[0], *L1 = &g->lv[1];
            int nplain = 0;
            for (int32_t J = 0; J < L1->n; J++)
                nplain += L1->tn && L1->plain[J];
            const int want_plain = scene < 2 ? 6 : 0; /* the maze's walls leave no plain row */
            ck_assert_msg(!want_plain || (L1->tn > 0 && nplain > 50), "%d plain rows of %d", nplain,
                          L1->n);
            double wp = 4.0 / 3.0 / L0->lmax;
            double *v = calloc(N, sizeof *v), *w = calloc(N, sizeof *w), *t = calloc(N, sizeof *t);
            double *col = calloc((size_t)L1->n, sizeof *col);
            int checked[2] = {0, 0};
            for (int32_t J = 0; J < L1->n && (checked[0] < WALL_ROWS || checked[1] < want_plain);
                 J += 7) {
                if (L0->mrp[J] == L0->mrp[J + 1])
                    continue; /* a block without fluid */
                int plain = L1->tn && L1->plain[J];
                if (checked[plain] >= (plain ? want_plain : WALL_ROWS))
                    continue;
                checked[plain]++;
                /* v = P e_J = (I - wp D^-1 A) P0 e_J */
                memset(t, 0, N * sizeof *t);
                for (size_t q = L0->mrp[J]; q < L0->mrp[J + 1]; q++)
                    t[L0->mem[q]] = 1;
                hv__mg_level_apply_d(&H.lv[0], 3, s.p.alpha, t, w);
                for (size_t c = 0; c < N; c++)
                    v[c] = t[c] - wp * H.lv[0].dinv[c] * w[c];
                /* column J of P^T A P = P0^T (I - wp A D^-1) A v */
                hv__mg_level_apply_d(&H.lv[0], 3, s.p.alpha, v, w);
                for (size_t c = 0; c < N; c++)
                    t[c] = H.lv[0].dinv[c] * w[c];
                hv__mg_level_apply_d(&H.lv[0], 3, s.p.alpha, t, v);
                memset(col, 0, (size_t)L1->n * sizeof *col);
                for (size_t c = 0; c < N; c++)
                    if (L0->agg[c] >= 0)
                        col[L0->agg[c]] += w[c] - wp * v[c];
                /* against row J as stored (symmetric) */
                double *row = calloc((size_t)L1->n, sizeof *row), scale = fabs(col[J]);
                if (plain)
                    for (int e = 0; e < L1->tn; e++)
                        row[J + L1->toff[e]] += L1->tval[e];
                else
                    for (size_t q = L1->A.rp[J]; q < L1->A.rp[J + 1]; q++)
                        row[L1->A.ci[q]] += L1->A.v[q];
                for (int32_t I = 0; I < L1->n; I++)
                    ck_assert_msg(fabs(row[I] - col[I]) <= 1e-5 * scale,
                                  "%s, %s row %d, column %d: %g stored, %g from P^T A P",
                                  heat ? "heat" : "Poisson", plain ? "plain" : "wall", J, I, row[I],
                                  col[I]);
                free(row);
            }
            ck_assert_msg(checked[0] == WALL_ROWS && checked[1] == want_plain,
                          "rows checked: %d next to walls, %d plain", checked[0], checked[1]);
            free(v);
            free(w);
            free(t);
            free(col);
            hv__mg_agg_free(g);
            hv__mg_hierarchy_free(&H);
        }
        free(mask);
    }
}
END_TEST

/* Whether two builds of the levels hold the same operators, bit for bit. */
static void assert_same_levels(const mg_agg *a, const mg_agg *b, const char *what)
{
    ck_assert_int_eq(a->nlev, b->nlev);
    for (int l = 1; l < a->nlev; l++) {
        const mg_alevel *A = &a->lv[l], *B = &b->lv[l];
        ck_assert_msg(A->n == B->n && A->tn == B->tn, "%s, level %d: %d and %d unknowns", what, l,
                      A->n, B->n);
        ck_assert(!memcmp(A->toff, B->toff, sizeof A->toff));
        ck_assert(!memcmp(A->tval, B->tval, sizeof A->tval));
        ck_assert(!memcmp(A->A.rp, B->A.rp, ((size_t)A->n + 1) * sizeof *A->A.rp));
        size_t nnz = A->A.rp[A->n];
        ck_assert_msg(!memcmp(A->A.ci, B->A.ci, nnz * sizeof *A->A.ci) &&
                          !memcmp(A->A.v, B->A.v, nnz * sizeof *A->A.v),
                      "%s, level %d: the entries differ", what, l);
    }
}

/* Rows copied from their class (agg_classes.c) against every row computed:
 * the same levels bit for bit, on the baffles (rows that repeat along the
 * walls and the faces on levels 1 and 2), a maze of odd size and a ball. */
START_TEST(row_classes_should_change_no_bit)
{
    const int big[3] = {64, 60, 56}, odd[3] = {37, 35, 33};
    for (int scene = 0; scene < 3; scene++) {
        const int *n = scene == 0 ? big : odd;
        size_t N = (size_t)n[0] * n[1] * n[2];
        uint8_t *mask = scene == 0 ? baffles(3, n) : scene == 1 ? maze(n, 8) : calloc(N, 1);
        for (size_t c = 0; scene == 2 && c < N; c++) {
            int i = (int)(c % n[0]), j = (int)(c / n[0] % n[1]),
                k = (int)(c / ((size_t)n[0] * n[1]));
            double x = i - n[0] / 2.0, y = j - n[1] / 2.0, z = k - n[2] / 2.0;
            mask[c] = x * x + y * y + z * z < 100;
        }
        for (int heat = 0; heat < 2; heat++) {
            hv_setup s;
            mg_hierarchy H;
            mg_agg *with = build_levels(n, mask, heat, &s, &H);
            setenv("HV_AGG_NOCLASS", "1", 1);
            mg_agg *without = NULL;
            TL_ASSERT_OK(hv__mg_agg_build(&without, &H.lv[0], 3, s.p.alpha));
            unsetenv("HV_AGG_NOCLASS");
            ck_assert_ptr_nonnull(without);
            ck_assert_msg(with->class_copies > 0 && without->class_copies == 0,
                          "scene %d: %zu rows copied with classes, %zu without", scene,
                          with->class_copies, without->class_copies);
            assert_same_levels(with, without,
                               scene == 0   ? "baffles"
                               : scene == 1 ? "maze"
                                            : "ball");
            hv__mg_agg_free(with);
            hv__mg_agg_free(without);
            hv__mg_hierarchy_free(&H);
        }
        free(mask);
    }
}
END_TEST

/* The coarse cycle once the hierarchy is packed (hv__mg_agg_pack): level 1's
 * rows that repeat along the faces and walls served by row classes (in runs
 * along x, or in groups of MG_GROUP rows: the rows beside walls across x),
 * the deeper levels' columns as 16-bit offsets. The same correction as before,
 * to float rounding (the classes sum in another order), for a maze and
 * baffles. */
START_TEST(packed_levels_should_give_the_same_cycle)
{
    const int n[3] = {56, 44, 40};
    size_t N = (size_t)n[0] * n[1] * n[2];
    for (int obstacle = 0; obstacle < 2; obstacle++) {
        uint8_t *mask = obstacle ? maze(n, 12) : baffles(3, n);
        hv_setup s;
        mg_hierarchy H;
        mg_agg *g = build_levels(n, mask, 0, &s, &H);
        ck_assert_int_ge(g->nlev, 4);
        float *r = random_rhs(N, 11), *u0 = calloc(N, sizeof *u0), *u1 = calloc(N, sizeof *u1);
        for (size_t c = 0; c < N; c++)
            r[c] = mask[c] ? 0.0f : r[c];
        hv__mg_agg_correct(g, r, u0);
        size_t bytes = g->bytes, stored = g->lv[1].A.rp[g->lv[1].n];
        hv__mg_agg_pack(g);
        for (int l = 2; l < g->nlev; l++) {
            const mg_alevel *L = &g->lv[l];
            ck_assert_msg(L->A.co && !L->A.ci, "level %d's A not packed", l);
            ck_assert_msg(!L->P.rp || (L->P.co && !L->P.ci), "level %d's P not packed", l);
            ck_assert_msg(!L->R.rp || (L->R.co && !L->R.ci), "level %d's R not packed", l);
        }
        const mg_alevel *L1 = &g->lv[1];
        int served = 0, grouped = 0;
        for (int32_t c = 0; L1->cls && c < L1->n; c++) {
            served += L1->cls[c] > 1;
            grouped += L1->cls[c] == MG_CLS_GROUP;
        }
        ck_assert_msg(L1->ncls > 0 && served > 200 && L1->A.rp[L1->n] < stored,
                      "%d row classes serve %d rows, %zu of %zu entries left", L1->ncls, served,
                      L1->A.rp[L1->n], stored);
        /* the rows beside walls across x, in groups: each grouped row in one
         * group of its class, each group's rows of one class */
        if (obstacle)
            ck_assert_msg(grouped > 200 && L1->ngrp > 0, "%d rows in %d groups", grouped, L1->ngrp);
        int *seen = calloc((size_t)L1->n, sizeof *seen), in_groups = 0;
        for (int32_t q = 0; q < L1->ngrp; q++) {
            const int32_t *gr = L1->grow + (size_t)MG_GROUP * q;
            for (int i = 0; i < MG_GROUP; i++) {
                ck_assert_msg(gr[i] >= 0 && gr[i] < L1->n && L1->cls[gr[i]] == MG_CLS_GROUP,
                              "group %d's row %d", q, gr[i]);
                ck_assert_msg(L1->gcls[q] >= 0 && L1->gcls[q] < L1->ncls, "group %d", q);
                in_groups += !seen[gr[i]]++;
            }
        }
        ck_assert_int_eq(in_groups, grouped);
        free(seen);
        ck_assert_msg(g->bytes < bytes, "%zu bytes before, %zu after", bytes, g->bytes);
        hv__mg_agg_correct(g, r, u1);
        ck_assert_msg(rel_diff(u1, u0, N) < 1e-5, "%s: packed cycle differs by %g",
                      obstacle ? "maze" : "baffles", rel_diff(u1, u0, N));
        free(r);
        free(u0);
        free(u1);
        hv__mg_agg_free(g);
        hv__mg_hierarchy_free(&H);
        free(mask);
    }
}
END_TEST

int main(void)
{
    Suite *s = suite_create("mg_agg");
    TCase *tc = tcase_create("core");
    tcase_set_timeout(tc, 240);
    tcase_add_test(tc, galerkin_rows_should_be_p_transpose_a_p);
    tcase_add_test(tc, row_classes_should_change_no_bit);
    tcase_add_test(tc, packed_levels_should_give_the_same_cycle);
    tcase_add_test(tc, aggregation_should_see_thin_walls);
    tcase_add_test(tc, aggregation_iterations_should_not_grow_with_n);
    tcase_add_test(tc, regions_cut_apart_should_each_stay_mean_free);
    tcase_add_test(tc, aggregation_should_solve_2d_odd_sizes_and_heat_steps);
    tcase_add_test(tc, auto_should_change_to_aggregation_within_a_slow_solve);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
