/* Morphology on the signed distance (hv_sdf_opts close, open, offset,
 * shell): a sphere offset by +-D is the sphere of radius r +- D, dense and in
 * tiles; a shell's wall on a box has the thickness asked for; closing fills a
 * gap narrower than twice its radius and keeps the faces away from it;
 * opening removes a fin thinner than twice its radius; the refusals. Errors
 * in voxels of the grid. */
#include "heatvox/heatvox.h"
#include "testlib.h"

#include <check.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Axis-aligned boxes lo..hi, each a closed mesh of 12 triangles, outward. */
static hv_mesh *boxes(int nb, const double (*lo)[3], const double (*hi)[3])
{
    static const int quad[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                                   {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
    double *V = malloc(24 * (size_t)nb * sizeof *V);
    uint32_t *T = malloc(36 * (size_t)nb * sizeof *T);
    for (int b = 0; b < nb; b++) {
        for (int c = 0; c < 8; c++)
            for (int a = 0; a < 3; a++)
                V[24 * b + 3 * c + a] = (c >> a & 1) ? hi[b][a] : lo[b][a];
        for (int f = 0; f < 6; f++) {
            const int *q = quad[f];
            const uint32_t o = 8 * (uint32_t)b;
            const uint32_t t[6] = {o + q[0], o + q[1], o + q[2], o + q[0], o + q[2], o + q[3]};
            memcpy(T + 36 * b + 6 * f, t, sizeof t);
        }
    }
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_from_arrays(&m, V, 8 * (size_t)nb, T, 12 * (size_t)nb));
    free(V);
    free(T);
    return m;
}

static hv_grid *run(const hv_mesh *m, int res, double close, double open, double offset,
                    double shell)
{
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = res;
    o.close = close;
    o.open = open;
    o.offset = offset;
    o.shell = shell;
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_sdf_compute(m, &o, &g, NULL));
    return g;
}

/* phi at the cell nearest to world point p (trilinear between centres). */
static double sample(const hv_grid *g, const double p[3])
{
    double f[3];
    int i0[3];
    for (int a = 0; a < 3; a++) {
        double x = (p[a] - g->origin[a]) / g->h - 0.5;
        i0[a] = (int)floor(x);
        if (i0[a] < 0)
            i0[a] = 0;
        if (i0[a] > g->n[a] - 2)
            i0[a] = g->n[a] - 2;
        f[a] = x - i0[a];
    }
    double s = 0;
    for (int c = 0; c < 8; c++) {
        double w = 1;
        int ix[3];
        for (int a = 0; a < 3; a++) {
            ix[a] = i0[a] + (c >> a & 1);
            w *= (c >> a & 1) ? f[a] : 1 - f[a];
        }
        s += w * g->v[(size_t)ix[0] + (size_t)g->n[0] * ((size_t)ix[1] + (size_t)g->n[1] * ix[2])];
    }
    return s;
}

/* The zero crossing of phi along x on the line (y, z), searched from x0
 * towards x1 between cell centres, by linear interpolation. */
static double crossing_x(const hv_grid *g, double y, double z, double x0, double x1)
{
    const double step = g->h * (x1 > x0 ? 1 : -1) / 8;
    double p[3] = {x0, y, z}, prev = sample(g, p);
    for (double x = x0 + step; (x1 - x) * step > 0; x += step) {
        p[0] = x;
        double v = sample(g, p);
        if ((v < 0) != (prev < 0))
            return x - step * v / (v - prev);
        prev = v;
    }
    return NAN;
}

START_TEST(sphere_offset_should_be_the_sphere_of_radius_r_plus_d)
{
    const double c[3] = {0, 0, 0}, r = 0.5;
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_make_sphere(&m, c, r, 5));
    for (int s = -1; s <= 1; s += 2) {
        const double D = s * 0.06;
        hv_grid *g = run(m, 64, 0, 0, D, 0);
        double worst = 0;
        for (int k = 0; k < g->n[2]; k++)
            for (int j = 0; j < g->n[1]; j++)
                for (int i = 0; i < g->n[0]; i++) {
                    double x[3];
                    hv_grid_cell_center(g, i, j, k, x);
                    const double truth = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) - (r + D);
                    if (fabs(truth) > 2 * g->h)
                        continue;
                    const float v = g->v[(size_t)i + (size_t)g->n[0] * (j + (size_t)g->n[1] * k)];
                    worst = fmax(worst, fabs(v - truth) / g->h);
                }
        printf("offset %+g: largest error within 2 voxels of the surface %.4f voxel\n", D, worst);
        ck_assert_msg(worst <= 0.05, "offset %g: %.4f voxel", D, worst);
        /* The block holds the grown sphere with the usual padding. */
        if (D > 0)
            ck_assert(g->origin[0] < -(r + D) - 3 * g->h);
        hv_grid_destroy(&g);
    }
    hv_mesh_destroy(&m);
}
END_TEST

START_TEST(offset_in_tiles_should_equal_the_dense_band)
{
    const double c[3] = {0, 0, 0};
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_make_sphere(&m, c, 0.5, 4));
    for (int s = -1; s <= 1; s += 2) {
        hv_sdf_opts o;
        hv_sdf_opts_default(&o);
        o.res = 64;
        o.offset = s * 0.07;
        hv_grid *g = NULL;
        hv_tiles *T = NULL;
        hv_sdf_stats S;
        TL_ASSERT_OK(hv_sdf_compute(m, &o, &g, NULL));
        TL_ASSERT_OK(hv_sdf_compute_tiles(m, &o, 3.0, &T, &S));
        ck_assert_int_eq(T->n[0], g->n[0]);
        size_t active = 0;
        double worst = 0;
        for (size_t q = 0; q < T->count; q++)
            for (int v = 0; v < 512; v++) {
                const int i = v % 8, j = v / 8 % 8, k = v / 64;
                if (!(T->on[8 * q + k] >> (i + 8 * j) & 1))
                    continue;
                active++;
                const int *t = T->ijk + 3 * q;
                const float d = g->v[(size_t)(t[0] + i) +
                                     (size_t)g->n[0] * ((size_t)(t[1] + j) +
                                                        (size_t)g->n[1] * (size_t)(t[2] + k))];
                ck_assert(fabsf(T->v[512 * q + v]) < 3 * T->h);
                worst = fmax(worst, fabs(T->v[512 * q + v] - d) / T->h);
            }
        /* Every dense voxel within the band is active in the tiles. */
        size_t dense_band = 0;
        for (size_t cc = 0; cc < hv_grid_count(g); cc++)
            dense_band += fabsf(g->v[cc]) < 3 * g->h;
        printf("offset %+g in tiles: %zu active voxels (dense band %zu), largest difference "
               "%.2e voxel\n",
               o.offset, active, dense_band, worst);
        ck_assert_uint_eq(active, T->active);
        ck_assert_uint_eq(active, S.active_voxels);
        ck_assert_uint_eq(active, dense_band);
        ck_assert_msg(worst < 1e-5, "%g voxel", worst);
        hv_tiles_destroy(&T);
        hv_grid_destroy(&g);
    }
    hv_mesh_destroy(&m);
}
END_TEST

START_TEST(shell_wall_should_have_the_thickness_asked_for)
{
    const double lo[1][3] = {{-0.5, -0.5, -0.5}}, hi[1][3] = {{0.5, 0.5, 0.5}};
    hv_mesh *m = boxes(1, lo, hi);
    const double T = 0.1;
    hv_grid *g = run(m, 64, 0, 0, 0, T);
    /* Through the middle of the faces: out at 0.5, in at 0.5 - T, the box's
     * middle outside the shell. */
    const double y = 0.013, z = -0.021;
    const double outer = crossing_x(g, y, z, 0.7, 0.2), inner = crossing_x(g, y, z, 0.2, 0.7);
    const double p[3] = {0, y, z};
    printf("shell %g: wall from %.5f to %.5f, thickness error %.4f voxel\n", T, inner, outer,
           fabs(outer - inner - T) / g->h);
    ck_assert(fabs(outer - inner - T) / g->h <= 0.1);
    ck_assert(fabs(outer - 0.5) / g->h <= 0.1);
    ck_assert(sample(g, p) > 0);
    hv_grid_destroy(&g);
    hv_mesh_destroy(&m);
}
END_TEST

START_TEST(close_should_fill_a_narrow_gap_and_keep_the_faces)
{
    /* Two boxes 0.1 apart; closing by 0.08 bridges them. */
    const double lo[2][3] = {{-0.5, -0.3, -0.3}, {0.05, -0.3, -0.3}};
    const double hi[2][3] = {{-0.05, 0.3, 0.3}, {0.5, 0.3, 0.3}};
    hv_mesh *m = boxes(2, lo, hi);
    hv_grid *plain = run(m, 64, 0, 0, 0, 0), *g = run(m, 64, 0.08, 0, 0, 0);
    const double mid[3] = {0, 0.01, -0.02};
    printf("close: phi at the gap's middle %.4f before, %.4f after (h %.4f)\n", sample(plain, mid),
           sample(g, mid), g->h);
    ck_assert(sample(plain, mid) > 0);
    ck_assert(sample(g, mid) < 0);
    /* The outer faces stay where they were. */
    const double x = crossing_x(g, 0.01, -0.02, 0.7, 0.3);
    printf("close: outer face at %.5f (error %.4f voxel)\n", x, fabs(x - 0.5) / g->h);
    ck_assert(fabs(x - 0.5) / g->h <= 0.1);
    hv_grid_destroy(&plain);
    hv_grid_destroy(&g);
    hv_mesh_destroy(&m);
}
END_TEST

START_TEST(open_should_remove_a_thin_fin_and_keep_the_body)
{
    /* A box with a fin 0.04 thick; opening by 0.05 removes the fin. */
    const double lo[2][3] = {{-0.5, -0.5, -0.5}, {0.4, -0.02, -0.3}};
    const double hi[2][3] = {{0.5, 0.5, 0.5}, {0.8, 0.02, 0.3}};
    hv_mesh *m = boxes(2, lo, hi);
    hv_grid *plain = run(m, 64, 0, 0, 0, 0), *g = run(m, 64, 0, 0.05, 0, 0);
    const double fin[3] = {0.65, 0.003, 0.01};
    printf("open: phi in the fin %.4f before, %.4f after\n", sample(plain, fin), sample(g, fin));
    ck_assert(sample(plain, fin) < 0);
    ck_assert(sample(g, fin) > 0);
    const double x = crossing_x(g, 0.3, -0.02, 0.0, 0.7);
    printf("open: body face at %.5f (error %.4f voxel)\n", x, fabs(x - 0.5) / g->h);
    ck_assert(fabs(x - 0.5) / g->h <= 0.1);
    hv_grid_destroy(&plain);
    hv_grid_destroy(&g);
    hv_mesh_destroy(&m);
}
END_TEST

START_TEST(refusals_should_name_the_problem)
{
    const double c[3] = {0, 0, 0};
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_make_sphere(&m, c, 0.5, 2));
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = 32;
    hv_grid *g = NULL;
    hv_tiles *T = NULL;
    o.close = 0.1;
    ck_assert_int_eq(hv_sdf_compute_tiles(m, &o, 3.0, &T, NULL), HV_ERR_INVALID_ARG);
    ck_assert(strstr(hv_last_error(), "dense grid"));
    o.close = -1;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, NULL), HV_ERR_INVALID_ARG);
    o.close = 0;
    o.offset = NAN;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, NULL), HV_ERR_INVALID_ARG);
    o.offset = 0.1;
    o.unsigned_distance = 1;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, NULL), HV_ERR_INVALID_ARG);
    ck_assert(strstr(hv_last_error(), "unsigned"));
    ck_assert_ptr_null(g);
    ck_assert_ptr_null(T);
    hv_mesh_destroy(&m);
}
END_TEST

int main(void)
{
    Suite *s = suite_create("sdf_morph");
    TCase *tc = tcase_create("morph");
    tcase_set_timeout(tc, 600);
    tcase_add_test(tc, sphere_offset_should_be_the_sphere_of_radius_r_plus_d);
    tcase_add_test(tc, offset_in_tiles_should_equal_the_dense_band);
    tcase_add_test(tc, shell_wall_should_have_the_thickness_asked_for);
    tcase_add_test(tc, close_should_fill_a_narrow_gap_and_keep_the_faces);
    tcase_add_test(tc, open_should_remove_a_thin_fin_and_keep_the_body);
    tcase_add_test(tc, refusals_should_name_the_problem);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
