/*
 * The heat-method distance with backend opencl (its stages on the device,
 * src/distance/distance_cl.c) against the host path with the same backend
 * (HEATVOX_DISTANCE_CL=0): same field to 1e-4 voxel, same stage counts (and
 * within a voxel of backend mg, whose residuals move the trust bounds), on 2D and 3D grids of odd sizes with
 * obstacles, several sources and a sealed region without a source; and the
 * host fallback on devices without fp64. Without an OpenCL platform the suite
 * only notes it.
 */
#include "heatvox/heatvox.h"
#include "cl/cl_core.h"
#include "testlib.h"

#include <check.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* A grid of n cells with a wall (a gap in it), a block, and a sealed box
 * (solid shell) without a source; points and one voxel as sources. */
static int no_mask;
/* The stages on the whole grid (the comparisons of the device and host paths
 * with the same solvers), or on tiles. */
static int whole_stages = 1;

static hv_grid *scene(int dim, const int n[3])
{
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_grid_create(&g, dim, n, 1.0 / n[0], NULL));
    if (no_mask)
        return g;
    TL_ASSERT_OK(hv_grid_add_mask(g));
    const int nz = dim == 3 ? n[2] : 1;
    for (int k = 0; k < nz; k++)
        for (int j = 0; j < n[1]; j++)
            for (int i = 0; i < n[0]; i++) {
                size_t c = i + (size_t)n[0] * (j + (size_t)n[1] * k);
                int wall = i == n[0] / 2 && !(j > n[1] / 2 && j < n[1] / 2 + 4);
                int block = i > n[0] / 5 && i < n[0] / 3 && j > 2 * n[1] / 3 && j < 4 * n[1] / 5;
                int bi = i - 3 * n[0] / 4, bj = j - n[1] / 6; /* sealed box, 5^dim shell */
                int bk = dim == 3 ? k - nz / 2 : 0;
                int shell = abs(bi) <= 2 && abs(bj) <= 2 && abs(bk) <= 2 &&
                            (abs(bi) == 2 || abs(bj) == 2 || (dim == 3 && abs(bk) == 2));
                g->solid[c] = (uint8_t)(wall || block || shell);
            }
    return g;
}

typedef struct {
    float *v;
    hv_distance_stats st;
} result;

static result run(int dim, const int n[3], hv_backend b)
{
    hv_grid *g = scene(dim, n);
    const double L[3] = {n[0] * g->h, n[1] * g->h, 0};
    double pts[6] = {0.13 * L[0], 0.21 * L[1], 0.37, 0.31 * L[0], 0.77 * L[1], 0.55};
    int vox[3] = {n[0] / 4, n[1] - 3, dim == 3 ? 1 : 0};
    hv_distance_sources src = {0};
    src.points = pts;
    src.npoints = 2;
    src.voxels = vox;
    src.nvoxels = 1;
    hv_distance_opts o;
    hv_distance_opts_default(&o);
    o.backend = b;
    o.whole_stages = whole_stages;
    result r;
    TL_ASSERT_OK(hv_distance_compute(g, &src, &o, &r.st));
    size_t count = hv_grid_count(g);
    r.v = malloc(count * sizeof *r.v);
    memcpy(r.v, g->v, count * sizeof *r.v);
    hv_grid_destroy(&g);
    return r;
}

/* opencl's device path against its host path (HEATVOX_DISTANCE_CL=0): max difference in voxels over finite cells, infinities
 * in the same places, the same stages and face counts. */
static void compare(int dim, const int n[3])
{
    setenv("HEATVOX_DISTANCE_CL", "0", 1);
    result m = run(dim, n, HV_BACKEND_OPENCL);
    unsetenv("HEATVOX_DISTANCE_CL");
    result c = run(dim, n, HV_BACKEND_OPENCL);
    size_t count = (size_t)n[0] * n[1] * (dim == 3 ? n[2] : 1), finite = 0, inf = 0;
    double dmax = 0, vmax = 0;
    for (size_t i = 0; i < count; i++) {
        ck_assert_msg(isinf(m.v[i]) == isinf(c.v[i]), "cell %zu: mg %g, opencl %g", i, m.v[i],
                      c.v[i]);
        if (isinf(m.v[i])) {
            inf++;
            continue;
        }
        finite++;
        dmax = fmax(dmax, fabs((double)m.v[i] - c.v[i]) * n[0]);
        vmax = fmax(vmax, m.v[i] * n[0]);
    }
    printf("  %dD %dx%dx%d: %zu finite cells (max %.1f voxels), %zu infinite; max |device - host "
           "path| "
           "%.2e voxel; stages %d/%d, dead faces %zu/%zu, diffusion %d/%d and Poisson %d/%d "
           "iterations, Poisson restarts %d/%d; %.2f s host, %.2f s device\n",
           dim, n[0], n[1], dim == 3 ? n[2] : 1, finite, vmax, inf, dmax, m.st.stages, c.st.stages,
           m.st.dead_faces, c.st.dead_faces, m.st.diffuse_iterations, c.st.diffuse_iterations,
           m.st.poisson_iterations, c.st.poisson_iterations, m.st.poisson_restarts,
           c.st.poisson_restarts, m.st.t_total, c.st.t_total);
    ck_assert(finite > count / 2 && (inf > 0 || no_mask) && vmax > n[0] / 2);
    ck_assert_int_eq(c.st.backend, HV_BACKEND_OPENCL);
    ck_assert_int_eq(m.st.stages, c.st.stages);
    ck_assert_uint_eq(m.st.dead_faces, c.st.dead_faces);
    ck_assert_uint_eq(m.st.regions, c.st.regions);
    for (int l = 0; l < 8; l++)
        ck_assert_uint_eq(m.st.faces_per_stage[l], c.st.faces_per_stage[l]);
    /* the symmetric cycle keeps PCG converging: the Poisson solve needs no
     * restart of the defect-correction loop (it took one in 2D with
     * mean-of-children restriction) */
    ck_assert_int_eq(m.st.poisson_restarts, 0);
    ck_assert_int_eq(c.st.poisson_restarts, 0);
    ck_assert_msg(dmax <= 1e-4, "device and host paths differ by %g voxel", dmax);
    /* mg solves to the same tolerances but its own residuals move the trust
     * bounds: a fraction of a voxel apart */
    result g = run(dim, n, HV_BACKEND_MG);
    double gmax = 0, gmean = 0;
    for (size_t i = 0; i < count; i++)
        if (!isinf(g.v[i])) {
            gmax = fmax(gmax, fabs((double)g.v[i] - c.v[i]) * n[0]);
            gmean += fabs((double)g.v[i] - c.v[i]) * n[0] / (double)finite;
        }
    printf("    against mg: max %.3f, mean %.4f voxel; mg Poisson %d iterations, %d restarts\n",
           gmax, gmean, g.st.poisson_iterations, g.st.poisson_restarts);
    ck_assert(gmax < 1.0);
    free(g.v);
    free(m.v);
    free(c.v);
}

START_TEST(opencl_distance_should_match_mg_in_2d_with_obstacles)
{
    const int n[3] = {97, 83, 1};
    compare(2, n);
}
END_TEST

START_TEST(opencl_distance_should_match_mg_in_3d_with_obstacles)
{
    const int n[3] = {37, 33, 29};
    compare(3, n);
}
END_TEST

START_TEST(opencl_distance_should_match_mg_over_many_stages)
{
    /* a long thin 2D strip: the march needs many stages */
    const int n[3] = {201, 23, 1};
    compare(2, n);
}
END_TEST

START_TEST(opencl_distance_should_match_on_a_grid_without_mask)
{
    const int n[3] = {31, 27, 25};
    no_mask = 1;
    compare(3, n);
    no_mask = 0;
}
END_TEST

/* The stages on tiles on the device (the tiles chosen on the host from the
 * device's per-tile flags, the band's Chebyshev sweeps on the device) against
 * the host's stages on tiles: the same stages, faces and cells per stage, the
 * same field to the solves' tolerance; and what the stages moved between host
 * and device, a small part of one double field per stage. */
START_TEST(opencl_stages_on_tiles_should_match_the_host_tiles)
{
    const int sizes[2][3] = {{37, 33, 29}, {201, 23, 1}};
    hv_cl *cl = NULL;
    TL_ASSERT_OK(hv__cl_open(&cl));
    const int fp64 = cl->fp64;
    hv__cl_close(&cl);
    whole_stages = 0;
    if (!fp64) { /* the host path with the device's whole-grid solvers */
        const int *n = sizes[1];
        result m = run(2, n, HV_BACKEND_MG), c = run(2, n, HV_BACKEND_OPENCL);
        double dmax = 0;
        for (size_t i = 0; i < (size_t)n[0] * n[1]; i++)
            if (!isinf(m.v[i]))
                dmax = fmax(dmax, fabs((double)m.v[i] - c.v[i]) * n[0]);
        printf("  float device (host path, whole stages): max |opencl - mg tiles| %.3f voxel\n",
               dmax);
        ck_assert_int_eq(c.st.backend, HV_BACKEND_OPENCL);
        ck_assert_uint_eq(c.st.cells_solved, (size_t)c.st.stages * n[0] * n[1]);
        /* whole stages against tiles: the fronts sit elsewhere (as in check_distance) */
        ck_assert_msg(dmax < 1.5, "differ by %g voxel", dmax);
        free(m.v);
        free(c.v);
        whole_stages = 1;
        return;
    }
    for (int q = 0; q < 2; q++) {
        const int *n = sizes[q], dim = n[2] > 1 ? 3 : 2;
        result m = run(dim, n, HV_BACKEND_MG), c = run(dim, n, HV_BACKEND_OPENCL);
        const size_t count = (size_t)n[0] * n[1] * n[2];
        double dmax = 0;
        for (size_t i = 0; i < count; i++) {
            ck_assert_msg(isinf(m.v[i]) == isinf(c.v[i]), "cell %zu: %g, %g", i, m.v[i], c.v[i]);
            if (!isinf(m.v[i]))
                dmax = fmax(dmax, fabs((double)m.v[i] - c.v[i]) * n[0]);
        }
        const double field = (double)count * sizeof(double) * c.st.stages;
        printf("  tiles %dD %dx%dx%d: max |device - host| %.2e voxel; stages %d/%d, cells solved "
               "%zu/%zu; %.0f bytes between host and device, %.3f of a double field per stage\n",
               dim, n[0], n[1], n[2], dmax, m.st.stages, c.st.stages, m.st.cells_solved,
               c.st.cells_solved, c.st.host_bytes, c.st.host_bytes / field);
        ck_assert_int_eq(c.st.backend, HV_BACKEND_OPENCL);
        ck_assert_int_eq(m.st.stages, c.st.stages);
        ck_assert_uint_eq(m.st.cells_solved, c.st.cells_solved);
        for (int l = 0; l < 8; l++) {
            ck_assert_uint_eq(m.st.faces_per_stage[l], c.st.faces_per_stage[l]);
            ck_assert_uint_eq(m.st.stage_cells[l], c.st.stage_cells[l]);
        }
        ck_assert(c.st.cells_solved < (size_t)c.st.stages * count);
        ck_assert_msg(dmax <= 1e-3, "device and host tiles differ by %g voxel", dmax);
        ck_assert_msg(c.st.host_bytes > 0 && c.st.host_bytes < 0.25 * field,
                      "%.0f bytes moved, %.0f in the stages' double fields", c.st.host_bytes,
                      field);
        free(m.v);
        free(c.v);
    }
    whole_stages = 1;
}
END_TEST

static int count_progress(double fraction, const char *stage, void *user)
{
    int *seen = user;
    seen[strcmp(stage, "poisson") == 0]++;
    return fraction < 0 || fraction > 1;
}

/* One hv_distance for many queries on the device: its Poisson solver (the
 * set-up) made at create and kept, the first query reporting the set-up and
 * the others none; a query gives what hv_distance_compute gives, bit for bit,
 * whatever came before; the stages report progress as on the host. */
START_TEST(an_opencl_object_should_answer_many_queries_without_set_up)
{
    hv_cl *cl = NULL;
    TL_ASSERT_OK(hv__cl_open(&cl));
    const int fp64 = cl->fp64;
    hv__cl_close(&cl);
    const int n[3] = {37, 33, 29};
    const size_t count = (size_t)n[0] * n[1] * n[2];
    hv_grid *g = scene(3, n), *ref = scene(3, n);
    hv_distance_opts o;
    hv_distance_opts_default(&o);
    o.backend = HV_BACKEND_OPENCL;
    double pa[3] = {0.2, 0.2, 0.3}, pb[3] = {0.8, 0.7, 0.5};
    hv_distance_sources a = {NULL, 0, pa, 1, NULL}, b = {NULL, 0, pb, 1, NULL};
    hv_distance *D = NULL;
    hv_distance_stats s[3];
    int seen[2] = {0, 0};
    TL_ASSERT_OK(hv_distance_create(&D, g, &o));
    hv_set_progress(count_progress, seen);
    TL_ASSERT_OK(hv_distance_query(D, &a, g, &s[0]));
    hv_set_progress(NULL, NULL);
    float *first = malloc(count * sizeof *first);
    ck_assert_ptr_nonnull(first);
    memcpy(first, g->v, count * sizeof *first);
    TL_ASSERT_OK(hv_distance_query(D, &b, g, &s[1]));
    TL_ASSERT_OK(hv_distance_query(D, &a, g, &s[2]));
    TL_ASSERT_OK(hv_distance_compute(ref, &a, &o, NULL));
    printf("  device object: set-up %.3f, %.3f, %.3f s; Poisson %.3f, %.3f, %.3f s; stages %d, "
           "progress %d diffuse, %d poisson (fp64 %d)\n",
           s[0].t_setup, s[1].t_setup, s[2].t_setup, s[0].t_poisson, s[1].t_poisson, s[2].t_poisson,
           s[0].stages, seen[0], seen[1], fp64);
    ck_assert_msg(s[0].t_setup > 0 && s[1].t_setup == 0 && s[2].t_setup == 0, "set-up %g, %g, %g s",
                  s[0].t_setup, s[1].t_setup, s[2].t_setup);
    ck_assert_int_eq(s[0].backend, HV_BACKEND_OPENCL);
    ck_assert_int_eq(memcmp(first, g->v, count * sizeof *first), 0);
    ck_assert_int_eq(memcmp(ref->v, g->v, count * sizeof *first), 0);
    ck_assert_int_eq(seen[0], s[0].stages);
    ck_assert_int_eq(seen[1], 1);
    hv_distance_destroy(&D);
    free(first);
    hv_grid_destroy(&g);
    hv_grid_destroy(&ref);
}
END_TEST

START_TEST(opencl_distance_without_fp64_should_fall_back_to_the_host)
{
    setenv("HEATVOX_OPENCL_FP64", "0", 1);
    hv_cl *cl = NULL;
    TL_ASSERT_OK(hv__cl_open(&cl));
    int fp64 = cl->fp64;
    hv__cl_close(&cl);
    ck_assert_int_eq(fp64, 0);
    const int n[3] = {41, 39, 1};
    result m = run(2, n, HV_BACKEND_MG), c = run(2, n, HV_BACKEND_OPENCL);
    unsetenv("HEATVOX_OPENCL_FP64");
    double dmax = 0;
    for (size_t i = 0; i < (size_t)n[0] * n[1]; i++)
        if (!isinf(m.v[i]))
            dmax = fmax(dmax, fabs((double)m.v[i] - c.v[i]) * n[0]);
    printf("  float device (host path): max |opencl - mg| %.2e voxel\n", dmax);
    ck_assert_int_eq(c.st.backend, HV_BACKEND_OPENCL);
    ck_assert_msg(dmax < 0.25, "differ by %g voxel", dmax);
    free(m.v);
    free(c.v);
}
END_TEST

int main(int argc, char **argv)
{
    (void)argc;
    tl_pocl_cache(argv[0]);
    Suite *su = suite_create("distance_cl");
    TCase *tc = tcase_create("distance_cl");
    tcase_set_timeout(tc, 600);
    int have_cl = hv_opencl_probe(NULL) == HV_OK;
    char why[512];
    snprintf(why, sizeof why, "no usable OpenCL device (%s)", hv_last_error());
    TL_ADD_IF(tc, opencl_distance_should_match_mg_in_2d_with_obstacles, have_cl, why);
    TL_ADD_IF(tc, opencl_distance_should_match_mg_in_3d_with_obstacles, have_cl, why);
    TL_ADD_IF(tc, opencl_stages_on_tiles_should_match_the_host_tiles, have_cl, why);
    TL_ADD_IF(tc, opencl_distance_should_match_mg_over_many_stages, have_cl, why);
    TL_ADD_IF(tc, opencl_distance_should_match_on_a_grid_without_mask, have_cl, why);
    TL_ADD_IF(tc, an_opencl_object_should_answer_many_queries_without_set_up, have_cl, why);
    TL_ADD_IF(tc, opencl_distance_without_fp64_should_fall_back_to_the_host, have_cl, why);
    suite_add_tcase(su, tc);
    return tl_run(su);
}
