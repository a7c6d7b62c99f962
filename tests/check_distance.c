/* Heat-method distance around obstacles against exact geodesic distances:
 * rectangles aligned with cell faces, exact distance by a visibility graph
 * over their corners (2D), extruded along z for 3D (where the geodesic length
 * is sqrt(d_xy^2 + dz^2)). */
#include "testlib.h"
#include "heatvox/petsc.h"
#include "heatvox/heat.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

typedef struct {
    double x0, y0, x1, y1;
} rect;

typedef struct {
    int nrect;
    rect r[4];
    double s[2]; /* source */
} scene;

/* A wall at x in [0.5, 0.53125] with a gap for y in [0.625, 0.75]. Obstacles
 * run past the unit square so that no path grazes along its edge around them;
 * corners outside the square are not graph vertices. */
static const scene wall_gap = {
    2, {{0.5, -1.0, 0.53125, 0.625}, {0.5, 0.75, 0.53125, 2.0}}, {0.25, 0.3}};
/* An L-shaped room: the top-right quarter is solid. */
static const scene l_room = {1, {{0.5, 0.5, 2.0, 2.0}}, {0.8, 0.2}};
/* A serpentine corridor: four walls from alternate sides, eight corners to turn. */
static const scene serpentine = {4,
                                 {{0.1875, -1, 0.21875, 0.8125},
                                  {0.40625, 0.1875, 0.4375, 2},
                                  {0.625, -1, 0.65625, 0.8125},
                                  {0.84375, 0.1875, 0.875, 2}},
                                 {0.08, 0.1}};

/* Does segment p-q cross the open interior of rectangle r? (Liang-Barsky on
 * the rectangle shrunk by a hair, so grazing a corner or an edge is allowed.) */
static int crosses(const rect *r, const double p[2], const double q[2])
{
    const double eps = 1e-9;
    double lo[2] = {r->x0 + eps, r->y0 + eps}, hi[2] = {r->x1 - eps, r->y1 - eps};
    double t0 = 0, t1 = 1;
    for (int a = 0; a < 2; a++) {
        double d = q[a] - p[a];
        if (fabs(d) < 1e-300) {
            if (p[a] <= lo[a] || p[a] >= hi[a])
                return 0;
            continue;
        }
        double ta = (lo[a] - p[a]) / d, tb = (hi[a] - p[a]) / d;
        if (ta > tb) {
            double x = ta;
            ta = tb;
            tb = x;
        }
        t0 = fmax(t0, ta);
        t1 = fmin(t1, tb);
    }
    return t0 < t1;
}

static int visible(const scene *sc, const double p[2], const double q[2])
{
    for (int i = 0; i < sc->nrect; i++)
        if (crosses(&sc->r[i], p, q))
            return 0;
    return 1;
}

typedef struct {
    int nv;
    double v[17][2];
    double D[17]; /* geodesic distance from the source to vertex */
} vgraph;

static void build_graph(const scene *sc, vgraph *g)
{
    g->nv = 0;
    for (int i = 0; i < sc->nrect; i++) {
        const rect *r = &sc->r[i];
        double c[4][2] = {{r->x0, r->y0}, {r->x1, r->y0}, {r->x0, r->y1}, {r->x1, r->y1}};
        for (int q = 0; q < 4; q++) {
            if (c[q][0] < 0 || c[q][0] > 1 || c[q][1] < 0 || c[q][1] > 1)
                continue;
            g->v[g->nv][0] = c[q][0];
            g->v[g->nv][1] = c[q][1];
            g->nv++;
        }
    }
    int done[17] = {0};
    for (int i = 0; i < g->nv; i++)
        g->D[i] = visible(sc, sc->s, g->v[i]) ? hypot(g->v[i][0] - sc->s[0], g->v[i][1] - sc->s[1])
                                              : INFINITY;
    for (int it = 0; it < g->nv; it++) { /* Dijkstra, O(V^2) */
        int b = -1;
        for (int i = 0; i < g->nv; i++)
            if (!done[i] && (b < 0 || g->D[i] < g->D[b]))
                b = i;
        done[b] = 1;
        for (int i = 0; i < g->nv; i++)
            if (!done[i] && visible(sc, g->v[b], g->v[i]))
                g->D[i] = fmin(g->D[i],
                               g->D[b] + hypot(g->v[i][0] - g->v[b][0], g->v[i][1] - g->v[b][1]));
    }
}

static double exact2(const scene *sc, const vgraph *g, const double x[2])
{
    if (visible(sc, sc->s, x))
        return hypot(x[0] - sc->s[0], x[1] - sc->s[1]);
    double best = INFINITY;
    for (int i = 0; i < g->nv; i++)
        if (isfinite(g->D[i]) && visible(sc, g->v[i], x))
            best = fmin(best, g->D[i] + hypot(x[0] - g->v[i][0], x[1] - g->v[i][1]));
    return best;
}

static int in_rect(const scene *sc, const double x[2])
{
    for (int i = 0; i < sc->nrect; i++)
        if (x[0] > sc->r[i].x0 && x[0] < sc->r[i].x1 && x[1] > sc->r[i].y0 && x[1] < sc->r[i].y1)
            return 1;
    return 0;
}

typedef struct {
    double mean, max, p99; /* |phi - exact| in voxels over fluid cells */
    double src;            /* distance interpolated at the source point, voxels */
    hv_distance_stats st;
} dist_err;

/* Distance on the unit square (dim 2) or cube (dim 3, extruded scene, source at
 * z = 0.4) with n cells per axis. */
static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* run_scene, keeping the grid in *keep (NULL: destroyed). */
static dist_err run_scene_grid(const scene *sc, int dim, int n, const hv_distance_opts *o,
                               hv_grid **keep);

static dist_err run_scene(const scene *sc, int dim, int n, const hv_distance_opts *o)
{
    return run_scene_grid(sc, dim, n, o, NULL);
}

static dist_err run_scene_grid(const scene *sc, int dim, int n, const hv_distance_opts *o,
                               hv_grid **keep)
{
    int ns[3] = {n, n, dim == 3 ? n : 1};
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_grid_create(&g, dim, ns, 1.0 / n, NULL));
    TL_ASSERT_OK(hv_grid_add_mask(g));
    for (int k = 0; k < ns[2]; k++)
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++) {
                double x[3];
                hv_grid_cell_center(g, i, j, k, x);
                g->solid[i + (size_t)n * (j + (size_t)n * k)] = (uint8_t)in_rect(sc, x);
            }
    double pt[3] = {sc->s[0], sc->s[1], 0.4};
    hv_distance_sources src = {0};
    src.points = pt;
    src.npoints = 1;
    dist_err e = {0};
    TL_ASSERT_OK(hv_distance_compute(g, &src, o, &e.st));
    vgraph vg;
    build_graph(sc, &vg);
    size_t m = 0;
    double *errs = malloc((size_t)n * n * ns[2] * sizeof *errs);
    ck_assert_ptr_nonnull(errs);
    for (int k = 0; k < ns[2]; k++)
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++) {
                size_t c = i + (size_t)n * (j + (size_t)n * k);
                double x[3];
                hv_grid_cell_center(g, i, j, k, x);
                if (g->solid[c]) {
                    ck_assert(isinf(g->v[c]));
                    continue;
                }
                double ex = exact2(sc, &vg, x);
                if (dim == 3)
                    ex = sqrt(ex * ex + (x[2] - pt[2]) * (x[2] - pt[2]));
                double err = fabs(g->v[c] - ex) * n;
                errs[m] = err;
                e.mean += err;
                e.max = fmax(e.max, err);
                m++;
            }
    e.mean /= (double)m;
    qsort(errs, m, sizeof *errs, cmp_double);
    e.p99 = errs[(size_t)(0.99 * (double)(m - 1))];
    free(errs);
    /* Bilinear value at the source point (2D scenes put it inside fluid cells). */
    double p = sc->s[0] * n - 0.5, q = sc->s[1] * n - 0.5;
    int i0 = (int)floor(p), j0 = (int)floor(q);
    double fp = p - i0, fq = q - j0, v = 0;
    int k0 = dim == 3 ? (int)floor(pt[2] * n - 0.5) : 0;
    double fr = dim == 3 ? pt[2] * n - 0.5 - k0 : 0;
    for (int c = 0; c < (dim == 3 ? 8 : 4); c++) {
        int a = c & 1, b = (c >> 1) & 1, z = (c >> 2) & 1;
        double wgt = (a ? fp : 1 - fp) * (b ? fq : 1 - fq) * (dim == 3 ? (z ? fr : 1 - fr) : 1);
        v += wgt * g->v[(i0 + a) + (size_t)n * ((j0 + b) + (size_t)n * (k0 + z))];
    }
    e.src = v * n;
    if (keep)
        *keep = g;
    else
        hv_grid_destroy(&g);
    return e;
}

static void report(const char *name, int dim, int n, const dist_err *e)
{
    printf("  %s %dD n=%d: mean %.3f max %.3f voxels, at source %.3f; stages %d, dead faces %zu, "
           "Poisson %d iterations (%d restarts) to %.1e; %.2f s\n",
           name, dim, n, e->mean, e->max, e->src, e->st.stages, e->st.dead_faces,
           e->st.poisson_iterations, e->st.poisson_restarts, e->st.poisson_relres, e->st.t_total);
    /* The masked Poisson solve (PCG with a symmetric V-cycle) converges in one
     * go, long corridors included: the restart guard must stay idle. */
    ck_assert_msg(e->st.poisson_restarts == 0, "%s: %d Poisson restarts", name,
                  e->st.poisson_restarts);
}

START_TEST(wall_with_gap_2d_should_be_within_one_voxel_at_128)
{
    dist_err e = run_scene(&wall_gap, 2, 128, NULL);
    report("wall-gap", 2, 128, &e);
    ck_assert_msg(e.mean <= 1.0, "mean error %.3f voxels", e.mean);
    ck_assert_int_eq(e.st.dead_faces, 0);
    ck_assert_msg(fabs(e.src) < 0.5, "distance at the source %.3f voxels", e.src);
}
END_TEST

START_TEST(l_room_2d_should_be_within_one_voxel_at_128)
{
    dist_err e = run_scene(&l_room, 2, 128, NULL);
    report("L-room", 2, 128, &e);
    ck_assert_msg(e.mean <= 1.0, "mean error %.3f voxels", e.mean);
    ck_assert_int_eq(e.st.dead_faces, 0);
}
END_TEST

START_TEST(serpentine_corridor_distance_should_follow_the_corridor)
{
    dist_err e = run_scene(&serpentine, 2, 128, NULL);
    report("serpentine", 2, 128, &e);
    ck_assert_int_eq(e.st.dead_faces, 0);
    ck_assert_msg(e.st.poisson_relres <= 1e-8, "Poisson residual %.2e", e.st.poisson_relres);
    /* About half a voxel per corner turned (5.7 at the far end, ~420 voxels away). */
    ck_assert_msg(e.mean <= 3.0, "mean error %.3f voxels", e.mean);
}
END_TEST

START_TEST(error_should_shrink_under_refinement_2d)
{
    /* Under the sanitizers a step coarser (the finest run is most of it). */
    const int ns[] = {32, 64, 128, 256};
    const int q0 = tl_sanitized() ? 0 : 1, q1 = q0 + 3;
    double prev = INFINITY;
    for (int q = q0; q < q1; q++) {
        dist_err e = run_scene(&wall_gap, 2, ns[q], NULL);
        report("wall-gap", 2, ns[q], &e);
        double world = e.mean / ns[q];
        ck_assert_msg(world < prev, "world error %.3g at n=%d not below %.3g", world, ns[q], prev);
        prev = world;
    }
}
END_TEST

START_TEST(wall_with_gap_3d_should_be_within_one_voxel_at_48)
{
    dist_err e = run_scene(&wall_gap, 3, 48, NULL);
    report("wall-gap", 3, 48, &e);
    ck_assert_msg(e.mean <= 1.0, "mean error %.3f voxels", e.mean);
    ck_assert_int_eq(e.st.dead_faces, 0);
}
END_TEST

/* The solves' coarse levels by aggregation (hv_distance_opts.coarse): the same
 * distances as with the geometric levels, to the solves' tolerances, in fewer
 * Poisson iterations around the serpentine's walls. */
START_TEST(aggregation_coarse_levels_should_give_the_same_distances)
{
    const hv_coarse co[2] = {HV_COARSE_GEOMETRIC, HV_COARSE_AGGREGATION};
    /* 32^3 under the sanitizers: 48^3 takes minutes under ThreadSanitizer. */
    const int n = tl_sanitized() ? 32 : 48;
    dist_err e[2];
    for (int q = 0; q < 2; q++) {
        hv_distance_opts o;
        hv_distance_opts_default(&o);
        o.backend = HV_BACKEND_MG;
        o.coarse = co[q];
        e[q] = run_scene(&serpentine, 3, n, &o);
        report(q ? "serpentine, aggregation" : "serpentine, geometric", 3, n, &e[q]);
    }
    ck_assert_msg(fabs(e[0].mean - e[1].mean) < 1e-4 && fabs(e[0].max - e[1].max) < 1e-3,
                  "errors differ: mean %.6f/%.6f, max %.6f/%.6f voxels", e[0].mean, e[1].mean,
                  e[0].max, e[1].max);
    ck_assert_msg(2 * e[1].st.poisson_iterations <= e[0].st.poisson_iterations,
                  "Poisson iterations: %d geometric, %d aggregation", e[0].st.poisson_iterations,
                  e[1].st.poisson_iterations);
}
END_TEST

START_TEST(l_room_3d_error_should_shrink_from_32_to_64)
{
    dist_err a = run_scene(&l_room, 3, 32, NULL), b = run_scene(&l_room, 3, 64, NULL);
    report("L-room", 3, 32, &a);
    report("L-room", 3, 64, &b);
    ck_assert_msg(b.mean <= 1.0, "mean error %.3f voxels", b.mean);
    ck_assert_msg(b.mean / 64 < a.mean / 32, "world error %.3g at 64 not below %.3g at 32",
                  b.mean / 64, a.mean / 32);
}
END_TEST

START_TEST(sealed_room_should_be_unreachable_unless_it_has_a_source)
{
    const int n = 64;
    int ns[3] = {n, n, 1};
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_grid_create(&g, 2, ns, 1.0 / n, NULL));
    TL_ASSERT_OK(hv_grid_add_mask(g));
    /* Walls of the room [40,56)^2, two cells thick; its inside is [42,54)^2. */
    size_t inside = 0;
    for (int j = 0; j < n; j++)
        for (int i = 0; i < n; i++) {
            int in_box = i >= 40 && i < 56 && j >= 40 && j < 56;
            int in_room = i >= 42 && i < 54 && j >= 42 && j < 54;
            g->solid[i + n * j] = (uint8_t)(in_box && !in_room);
            inside += in_room;
        }
    int vox[6] = {10, 10, 0, 47, 48, 0};
    hv_distance_sources src = {0};
    src.voxels = vox;
    src.nvoxels = 1;
    hv_distance_stats st;
    TL_ASSERT_OK(hv_distance_compute(g, &src, NULL, &st));
    ck_assert_int_eq(st.unreachable_cells, inside);
    ck_assert_int_eq(st.regions, 1);
    for (int j = 0; j < n; j++)
        for (int i = 0; i < n; i++) {
            float v = g->v[i + n * j];
            if (i >= 42 && i < 54 && j >= 42 && j < 54)
                ck_assert(isinf(v) && v > 0);
            else if (!g->solid[i + n * j])
                ck_assert(isfinite(v) && v >= 0);
        }
    /* With a source in the room too, both regions get distances, each zero at its source. */
    src.nvoxels = 2;
    hv_distance_opts o;
    hv_distance_opts_default(&o);
    o.unreachable = -1;
    TL_ASSERT_OK(hv_distance_compute(g, &src, &o, &st));
    ck_assert_int_eq(st.unreachable_cells, 0);
    ck_assert_int_eq(st.regions, 2);
    /* Outside, the room's walls are one rectangular obstacle. */
    const scene outer = {1, {{40.0 / n, 40.0 / n, 56.0 / n, 56.0 / n}}, {10.5 / n, 10.5 / n}};
    vgraph vg;
    build_graph(&outer, &vg);
    double worst = 0;
    for (int j = 0; j < n; j++)
        for (int i = 0; i < n; i++) {
            if (g->solid[i + n * j])
                continue;
            int room = i >= 42 && i < 54 && j >= 42 && j < 54;
            double x[2] = {(i + 0.5) / n, (j + 0.5) / n};
            double ex = room ? hypot(i - vox[3], j - vox[4]) / n : exact2(&outer, &vg, x);
            worst = fmax(worst, fabs(g->v[i + n * j] - ex) * n);
        }
    ck_assert_msg(worst < 1.5, "worst error %.3f voxels with a source in each room", worst);
    hv_grid_destroy(&g);
}
END_TEST

/* Geodesic distance from point s around a ball (centre 0, radius R) to x, both outside it. */
static double around_ball(const double s[3], const double x[3], double R)
{
    double ls = sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]);
    double lx = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
    double cosg = (s[0] * x[0] + s[1] * x[1] + s[2] * x[2]) / (ls * lx);
    double gam = acos(fmax(-1, fmin(1, cosg)));
    double arc = gam - acos(R / ls) - acos(R / lx);
    if (arc <= 0) /* visible */
        return sqrt((s[0] - x[0]) * (s[0] - x[0]) + (s[1] - x[1]) * (s[1] - x[1]) +
                    (s[2] - x[2]) * (s[2] - x[2]));
    return sqrt(ls * ls - R * R) + R * arc + sqrt(lx * lx - R * R);
}

START_TEST(distance_should_go_around_a_mesh_obstacle)
{
    const int n = 48;
    const double R = 0.25;
    int ns[3] = {n, n, n};
    double org[3] = {-0.5, -0.5, -0.5}, c[3] = {0, 0, 0};
    hv_grid *g = NULL;
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_grid_create(&g, 3, ns, 1.0 / n, org));
    TL_ASSERT_OK(hv_mesh_make_sphere(&m, c, R, 4));
    size_t nsolid = 0;
    TL_ASSERT_OK(hv_mask_from_mesh(g, m, &nsolid));
    ck_assert(nsolid > 0);
    double pt[3] = {-0.4, 0.05, 0.03};
    hv_distance_sources src = {0};
    src.points = pt;
    src.npoints = 1;
    hv_distance_stats st;
    TL_ASSERT_OK(hv_distance_compute(g, &src, NULL, &st));
    ck_assert_int_eq(st.regions, 1);
    ck_assert(st.unreachable_cells > 0); /* the shell's inside */
    double mean = 0, behind = 0;
    size_t cnt = 0, nb = 0;
    for (int k = 0; k < n; k++)
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++) {
                size_t q = i + (size_t)n * (j + (size_t)n * k);
                double x[3];
                hv_grid_cell_center(g, i, j, k, x);
                double r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
                if (g->solid[q] || r < R)
                    continue;
                double err = fabs(g->v[q] - around_ball(pt, x, R)) * n;
                mean += err;
                cnt++;
                if (x[0] > R) {
                    behind += err;
                    nb++;
                }
            }
    mean /= cnt;
    behind /= nb;
    printf("  around a ball (mesh shell) 48^3: mean %.3f voxels, behind it %.3f; %zu shell cells\n",
           mean, behind, nsolid);
    ck_assert_msg(mean <= 1.0, "mean error %.3f voxels", mean);
    ck_assert_msg(behind <= 1.5, "error behind the ball %.3f voxels", behind);
    hv_mesh_destroy(&m);
    hv_grid_destroy(&g);
}
END_TEST

START_TEST(mesh_source_should_give_unsigned_distance_to_its_surface)
{
    const int n = 48;
    const double R = 0.3;
    int ns[3] = {n, n, n};
    double org[3] = {-0.5, -0.5, -0.5}, c[3] = {0.02, -0.01, 0.015};
    hv_grid *g = NULL;
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_grid_create(&g, 3, ns, 1.0 / n, org));
    TL_ASSERT_OK(hv_mesh_make_sphere(&m, c, R, 5));
    hv_distance_sources src = {0};
    src.mesh = m;
    hv_distance_stats st;
    TL_ASSERT_OK(hv_distance_compute(g, &src, NULL, &st));
    ck_assert_int_eq(st.dead_faces, 0);
    double mean = 0, near = 0;
    size_t nn = 0;
    for (int k = 0; k < n; k++)
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++) {
                double x[3];
                hv_grid_cell_center(g, i, j, k, x);
                double ex =
                    fabs(sqrt((x[0] - c[0]) * (x[0] - c[0]) + (x[1] - c[1]) * (x[1] - c[1]) +
                              (x[2] - c[2]) * (x[2] - c[2])) -
                         R);
                double err = fabs(g->v[i + (size_t)n * (j + (size_t)n * k)] - ex) * n;
                mean += err;
                if (ex < 3.0 / n) {
                    near += err;
                    nn++;
                }
            }
    mean /= hv_grid_count(g);
    near /= nn;
    printf("  unsigned distance to a sphere mesh 48^3: mean %.3f voxels, within 3 voxels %.3f\n",
           mean, near);
    ck_assert_msg(mean <= 0.5, "mean error %.3f voxels", mean);
    ck_assert_msg(near <= 0.5, "error near the surface %.3f voxels", near);
    hv_mesh_destroy(&m);
    hv_grid_destroy(&g);
}
END_TEST

START_TEST(bad_sources_should_fail_clearly)
{
    const int n = 16;
    int ns[3] = {n, n, 1};
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_grid_create(&g, 2, ns, 1.0 / n, NULL));
    hv_distance_sources src = {0};
    ck_assert_int_eq(hv_distance_compute(g, &src, NULL, NULL), HV_ERR_INVALID_ARG);
    int vox[3] = {n, 0, 0};
    src.voxels = vox;
    src.nvoxels = 1;
    ck_assert_int_eq(hv_distance_compute(g, &src, NULL, NULL), HV_ERR_INVALID_ARG);
    ck_assert(strstr(hv_last_error(), "outside") != NULL);
    double pt[3] = {2, 0.5, 0};
    src.nvoxels = 0;
    src.points = pt;
    src.npoints = 1;
    ck_assert_int_eq(hv_distance_compute(g, &src, NULL, NULL), HV_ERR_INVALID_ARG);
    /* A source inside an obstacle only. */
    TL_ASSERT_OK(hv_grid_add_mask(g));
    for (int j = 4; j < 12; j++)
        for (int i = 4; i < 12; i++)
            g->solid[i + n * j] = 1;
    pt[0] = 0.5;
    ck_assert_int_eq(hv_distance_compute(g, &src, NULL, NULL), HV_ERR_INVALID_ARG);
    ck_assert(strstr(hv_last_error(), "solid") != NULL);
    hv_grid_destroy(&g);
}
END_TEST

/* ---- heatvox distance ------------------------------------------------------ */

START_TEST(heatvox_distance_should_go_around_a_vdb_mask)
{
    const char *bin = tl_heatvox_bin();
    if (!bin)
        TL_SKIP("no heatvox binary (build/heatvox or $HEATVOX_BIN)");
    char dir[] = "/tmp/hv_distance_XXXXXX";
    ck_assert_ptr_nonnull(mkdtemp(dir));
    char path[512], cmd[2048], err[4096];
    /* The wall with a gap, extruded, as a bool mask on the unit cube, 32^3. */
    const int n = 32;
    int ns[3] = {n, n, n};
    hv_grid *m = NULL;
    TL_ASSERT_OK(hv_grid_create(&m, 3, ns, 1.0 / n, NULL));
    TL_ASSERT_OK(hv_grid_add_mask(m));
    for (int k = 0; k < n; k++)
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++) {
                double x[3];
                hv_grid_cell_center(m, i, j, k, x);
                m->solid[i + (size_t)n * (j + (size_t)n * k)] = (uint8_t)in_rect(&wall_gap, x);
            }
    hv_vdb_writer *w = NULL;
    snprintf(path, sizeof path, "%s/mask.vdb", dir);
    TL_ASSERT_OK(hv_vdb_writer_create(&w));
    TL_ASSERT_OK(hv_vdb_writer_add_mask(w, m, "walls"));
    TL_ASSERT_OK(hv_vdb_writer_write(w, path));
    hv_vdb_writer_destroy(&w);
    snprintf(path, sizeof path, "%s/src.txt", dir);
    FILE *f = fopen(path, "w");
    ck_assert_ptr_nonnull(f);
    fprintf(f, "# the source\npoint %.17g %.17g 0.4\n", wall_gap.s[0], wall_gap.s[1]);
    fclose(f);
    snprintf(cmd, sizeof cmd,
             "%s distance --sources %s/src.txt --obstacles %s/mask.vdb --bbox 0 0 0 1 1 1 "
             "-o %s/d.vdb -q",
             bin, dir, dir, dir);
    ck_assert_msg(tl_run_cmd(cmd, dir, err, sizeof err) == 0, "heatvox distance failed: %s", err);

    snprintf(path, sizeof path, "%s/d.vdb", dir);
    hv_grid *d = NULL;
    TL_ASSERT_OK(hv_vdb_read_float(path, "distance", NULL, &d, NULL));
    ck_assert_int_eq(d->n[0], n);
    ck_assert_int_eq(d->n[2], n);
    vgraph vg;
    build_graph(&wall_gap, &vg);
    double mean = 0;
    size_t cnt = 0;
    for (int k = 0; k < n; k++)
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++) {
                size_t c = i + (size_t)n * (j + (size_t)n * k);
                double x[3];
                hv_grid_cell_center(d, i, j, k, x);
                ck_assert(fabs(x[0] - (i + 0.5) / n) < 1e-9); /* same placement */
                if (m->solid[c]) {
                    ck_assert(isinf(d->v[c]));
                    continue;
                }
                double ex = exact2(&wall_gap, &vg, x);
                ex = sqrt(ex * ex + (x[2] - 0.4) * (x[2] - 0.4));
                mean += fabs(d->v[c] - ex) * n;
                cnt++;
            }
    mean /= cnt;
    printf("  heatvox distance around a VDB wall mask 32^3: mean error %.3f voxels\n", mean);
    ck_assert_msg(mean <= 1.0, "mean error %.3f voxels", mean);
    hv_grid_destroy(&d);
    hv_grid_destroy(&m);

    /* A box that starts inside the mask's block: the output keeps the mask's
     * transform, and its voxels their index coordinates (x from index 8). */
    snprintf(cmd, sizeof cmd,
             "%s distance --sources %s/src.txt --obstacles %s/mask.vdb --bbox 0.25 0 0 1 1 1 "
             "-o %s/d2.vdb -q",
             bin, dir, dir, dir);
    ck_assert_msg(tl_run_cmd(cmd, dir, err, sizeof err) == 0, "heatvox distance failed: %s", err);
    hv_vdb_grid_info gi[2];
    size_t gcount = 0;
    snprintf(path, sizeof path, "%s/d2.vdb", dir);
    TL_ASSERT_OK(hv_vdb_list(path, gi, 2, &gcount));
    ck_assert_uint_eq(gcount, 2);
    for (size_t q = 0; q < gcount; q++)
        ck_assert_msg(fabs(gi[q].index0_world[0] - 0.5 / n) < 1e-9, "%s: index 0 at x = %g",
                      gi[q].name, gi[q].index0_world[0]);
    ck_assert_int_eq(gi[0].bbox_lo[0], n / 4);
    ck_assert_int_eq(gi[0].bbox_hi[0], n - 1);

    /* Errors: a source file with a bad line, a missing mask grid. */
    snprintf(path, sizeof path, "%s/bad.txt", dir);
    f = fopen(path, "w");
    ck_assert_ptr_nonnull(f);
    fprintf(f, "0.5 0.5 0.5\nvoxel 1 2\n");
    fclose(f);
    snprintf(cmd, sizeof cmd, "%s distance --sources %s --bbox 0 0 0 1 1 1 -o %s/e.vdb", bin, path,
             dir);
    ck_assert_int_eq(tl_run_cmd(cmd, dir, err, sizeof err), 1);
    ck_assert_msg(strstr(err, "bad.txt:2") != NULL, "message: %s", err);
    snprintf(
        cmd, sizeof cmd,
        "%s distance --sources %s/src.txt --obstacles %s/mask.vdb --obstacle-grid nope -o %s/e.vdb",
        bin, dir, dir, dir);
    ck_assert_int_eq(tl_run_cmd(cmd, dir, err, sizeof err), 1);
    ck_assert_msg(strstr(err, "nope") && strstr(err, "walls"), "message: %s", err);
    snprintf(cmd, sizeof cmd, "%s distance --sources %s/src.txt -o %s/e.vdb --res 2", bin, dir,
             dir);
    ck_assert_int_eq(tl_run_cmd(cmd, dir, err, sizeof err), 2);
    /* HDF5 output is in builds with PETSc (tests/mpi/pipelines.py reads it
     * back with h5py): here one process writes it and its sidecar; a build
     * without says so and writes nothing. */
    snprintf(cmd, sizeof cmd,
             "%s distance --sources %s/src.txt --bbox 0 0 0 1 1 1 --res 16 -o %s/e.h5 -q", bin, dir,
             dir);
    snprintf(path, sizeof path, "%s/e.h5", dir);
    if (!hv_petsc_available()) {
        ck_assert_int_eq(tl_run_cmd(cmd, dir, err, sizeof err), 2);
        ck_assert_msg(strstr(err, "e.h5") && strstr(err, "make mpi"), "message: %s", err);
        ck_assert_int_ne(access(path, F_OK), 0);
    } else {
        ck_assert_int_eq(tl_run_cmd(cmd, dir, err, sizeof err), 0);
        ck_assert_int_eq(access(path, F_OK), 0);
        snprintf(path, sizeof path, "%s/e.xmf", dir);
        ck_assert_int_eq(access(path, F_OK), 0);
    }
    snprintf(cmd, sizeof cmd, "rm -rf %s", dir);
    ck_assert_int_eq(system(cmd), 0);
}
END_TEST

/* The stages on tiles near the front (the default) against the stages on the
 * whole grid: the same distances to a fraction of a voxel (the band's tighter
 * tolerance lets each stage reach further, so the fronts sit elsewhere), as
 * accurate, on far fewer cells. */
START_TEST(stages_on_tiles_should_match_the_whole_grid_on_fewer_cells)
{
    const int n = tl_sanitized() ? 128 : 256;
    hv_distance_opts o[2];
    dist_err e[2];
    hv_grid *g[2];
    for (int q = 0; q < 2; q++) {
        hv_distance_opts_default(&o[q]);
        o[q].backend = HV_BACKEND_MG;
        o[q].whole_stages = q;
        e[q] = run_scene_grid(&wall_gap, 2, n, &o[q], &g[q]);
        report(q ? "wall-gap, whole stages" : "wall-gap, stages on tiles", 2, n, &e[q]);
    }
    double sum = 0, worst = 0;
    size_t m = 0;
    for (size_t c = 0; c < (size_t)n * n; c++)
        if (!g[0]->solid[c]) {
            double d = fabs(g[0]->v[c] - g[1]->v[c]) * n;
            sum += d;
            worst = fmax(worst, d);
            m++;
        }
    printf("  tiles vs whole: mean %.3f max %.3f voxels apart; cells solved %zu vs %zu\n",
           sum / (double)m, worst, e[0].st.cells_solved, e[1].st.cells_solved);
    ck_assert_msg(sum / (double)m < 0.15 && worst < 1.5, "apart: mean %.3f, max %.3f voxels",
                  sum / (double)m, worst);
    ck_assert_msg(e[0].mean <= e[1].mean + 0.1, "mean error %.3f on tiles, %.3f whole", e[0].mean,
                  e[1].mean);
    ck_assert_msg(2 * e[0].st.cells_solved < e[1].st.cells_solved, "cells solved %zu vs %zu",
                  e[0].st.cells_solved, e[1].st.cells_solved);
    ck_assert_int_eq(e[1].st.cells_solved, (size_t)e[1].st.stages * n * n);
    ck_assert_int_eq(e[0].st.dead_faces, 0);
    for (int q = 0; q < 2; q++)
        hv_grid_destroy(&g[q]);
}
END_TEST

/* Against the exact geodesic distance around vertical prisms (the 2D
 * visibility-graph distance combined with the height difference): mean error
 * at most half a voxel, 99th percentile at most 2 voxels. */
START_TEST(prisms_should_be_within_half_a_voxel_on_average)
{
    const scene *sc[2] = {&wall_gap, &l_room};
    const char *name[2] = {"wall-gap prisms", "L-room prisms"};
    for (int q = 0; q < 2; q++) {
        dist_err e = run_scene(sc[q], 3, 48, NULL);
        report(name[q], 3, 48, &e);
        printf("  %s: p99 %.3f voxels\n", name[q], e.p99);
        ck_assert_msg(e.mean <= 0.5 && e.p99 <= 2.0, "%s: mean %.3f, p99 %.3f voxels", name[q],
                      e.mean, e.p99);
    }
}
END_TEST

/* One hv_distance for many queries: the set-up is paid at create and
 * reported by the first query only; a query gives what hv_distance_compute
 * gives, bit for bit, whatever came before; a grid of another shape is an
 * error that says so. */
START_TEST(an_object_should_answer_many_queries_without_set_up)
{
    const int n = 32, ns[3] = {n, n, n};
    hv_grid *g = NULL, *ref = NULL, *other = NULL;
    TL_ASSERT_OK(hv_grid_create(&g, 3, ns, 1.0 / n, NULL));
    TL_ASSERT_OK(hv_grid_add_mask(g));
    for (int k = 0; k < n; k++)
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++) {
                double x[3];
                hv_grid_cell_center(g, i, j, k, x);
                g->solid[i + (size_t)n * (j + (size_t)n * k)] = (uint8_t)in_rect(&wall_gap, x);
            }
    TL_ASSERT_OK(hv_grid_create(&ref, 3, ns, 1.0 / n, NULL));
    TL_ASSERT_OK(hv_grid_add_mask(ref));
    memcpy(ref->solid, g->solid, (size_t)n * n * n);
    double pa[3] = {0.2, 0.2, 0.4}, pb[3] = {0.8, 0.8, 0.6};
    hv_distance_sources a = {NULL, 0, pa, 1, NULL}, b = {NULL, 0, pb, 1, NULL};
    hv_distance *D = NULL;
    hv_distance_stats s[3];
    TL_ASSERT_OK(hv_distance_create(&D, g, NULL));
    TL_ASSERT_OK(hv_distance_query(D, &a, g, &s[0]));
    float *first = malloc((size_t)n * n * n * sizeof *first);
    ck_assert_ptr_nonnull(first);
    memcpy(first, g->v, (size_t)n * n * n * sizeof *first);
    TL_ASSERT_OK(hv_distance_query(D, &b, g, &s[1]));
    TL_ASSERT_OK(hv_distance_query(D, &a, g, &s[2]));
    TL_ASSERT_OK(hv_distance_compute(ref, &a, NULL, NULL));
    ck_assert_msg(s[0].t_setup > 0 && s[1].t_setup == 0 && s[2].t_setup == 0, "set-up %g, %g, %g s",
                  s[0].t_setup, s[1].t_setup, s[2].t_setup);
    ck_assert_int_eq(memcmp(first, g->v, (size_t)n * n * n * sizeof *first), 0);
    ck_assert_int_eq(memcmp(ref->v, g->v, (size_t)n * n * n * sizeof *first), 0);
    const int small[3] = {n, n, n / 2};
    TL_ASSERT_OK(hv_grid_create(&other, 3, small, 1.0 / n, NULL));
    ck_assert_int_eq(hv_distance_query(D, &a, other, NULL), HV_ERR_INVALID_ARG);
    ck_assert_msg(strstr(hv_last_error(), "the object's"), "message: %s", hv_last_error());
    hv_distance_destroy(&D);
    ck_assert_ptr_null(D);
    hv_distance_destroy(&D);
    free(first);
    hv_grid_destroy(&g);
    hv_grid_destroy(&ref);
    hv_grid_destroy(&other);
}
END_TEST

int main(void)
{
    Suite *s = suite_create("distance");
    TCase *tc = tcase_create("geodesic");
    tcase_set_timeout(tc, 120);
    tcase_add_test(tc, wall_with_gap_2d_should_be_within_one_voxel_at_128);
    tcase_add_test(tc, l_room_2d_should_be_within_one_voxel_at_128);
    tcase_add_test(tc, serpentine_corridor_distance_should_follow_the_corridor);
    tcase_add_test(tc, error_should_shrink_under_refinement_2d);
    tcase_add_test(tc, wall_with_gap_3d_should_be_within_one_voxel_at_48);
    tcase_add_test(tc, aggregation_coarse_levels_should_give_the_same_distances);
    tcase_add_test(tc, l_room_3d_error_should_shrink_from_32_to_64);
    tcase_add_test(tc, sealed_room_should_be_unreachable_unless_it_has_a_source);
    tcase_add_test(tc, distance_should_go_around_a_mesh_obstacle);
    tcase_add_test(tc, mesh_source_should_give_unsigned_distance_to_its_surface);
    tcase_add_test(tc, bad_sources_should_fail_clearly);
    tcase_add_test(tc, heatvox_distance_should_go_around_a_vdb_mask);
    tcase_add_test(tc, stages_on_tiles_should_match_the_whole_grid_on_fewer_cells);
    tcase_add_test(tc, prisms_should_be_within_half_a_voxel_on_average);
    tcase_add_test(tc, an_object_should_answer_many_queries_without_set_up);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
