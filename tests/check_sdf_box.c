/* The signed distance does not depend on the block it is computed in: open
 * meshes (a sphere with a polar cap cut off, an open-ended cylinder, a ball
 * on an open neck, an opening facing a corner of the block) give the same
 * inside at pads 1, 4 and 32 on one lattice, nothing inside on the block's
 * outer layer, and the inside of the winding number of the repaired mesh;
 * a --bbox window through a mesh gives the values of the same window of a
 * full run; the sign option's errors and the command's report. */
#include "heatvox/heatvox.h"
#include "sdf_testutil.h"
#include "testlib.h"

#include <check.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- generated open meshes ---- */

/* A "bust": a ball of radius 1 centred at z = 1.6 on an open neck (radius
 * 0.4, z from 0 to 1.0, its top inside the ball), cut open at the bottom. */
static hv_mesh *bust(void)
{
    const double c[3] = {0, 0, 1.6};
    hv_mesh *ball = NULL;
    TL_ASSERT_OK(hv_mesh_make_sphere(&ball, c, 1.0, 4));
    size_t nv = ball->nverts, nt = ball->ntris;
    double *V = malloc(3 * (nv + 48 * 21) * sizeof *V);
    uint32_t *T = malloc(3 * (nt + 2 * 48 * 20) * sizeof *T);
    memcpy(V, ball->verts, 3 * nv * sizeof *V);
    memcpy(T, ball->tris, 3 * nt * sizeof *T);
    tu_tube(V, &nv, T, &nt, 0.4, 0.0, 1.0, 48, 20);
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_from_arrays(&m, V, nv, T, nt));
    free(V);
    free(T);
    hv_mesh_destroy(&ball);
    return m;
}

/* ---- the properties ---- */

static hv_grid *run(const hv_mesh *m, double h, int pad, hv_sdf_stats *S)
{
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.voxel_size = h;
    o.pad = pad;
    o.round_to = 1; /* every pad on one lattice */
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_sdf_compute(m, &o, &g, S));
    return g;
}

static float at(const hv_grid *g, int i, int j, int k)
{
    return g->v[(size_t)i + (size_t)g->n[0] * ((size_t)j + (size_t)g->n[1] * k)];
}

/* Index offset of grid a's first cell in grid b (same lattice). */
static void offset(const hv_grid *a, const hv_grid *b, int off[3])
{
    for (int d = 0; d < 3; d++) {
        double s = (a->origin[d] - b->origin[d]) / a->h;
        off[d] = (int)lround(s);
        ck_assert_msg(fabs(s - off[d]) < 1e-6, "grids not on one lattice (%g)", s);
    }
}

/* Inside-IoU of a and b on a's cells. */
static double iou_window(const hv_grid *a, const hv_grid *b)
{
    int off[3];
    offset(a, b, off);
    size_t I = 0, U = 0;
    for (int k = 0; k < a->n[2]; k++)
        for (int j = 0; j < a->n[1]; j++)
            for (int i = 0; i < a->n[0]; i++) {
                int x = at(a, i, j, k) < 0, y = at(b, i + off[0], j + off[1], k + off[2]) < 0;
                I += x && y;
                U += x || y;
            }
    return U ? (double)I / (double)U : 1.0;
}

static size_t outer_inside(const hv_grid *g)
{
    size_t c = 0;
    for (int k = 0; k < g->n[2]; k++)
        for (int j = 0; j < g->n[1]; j++)
            for (int i = 0; i < g->n[0]; i++)
                if (i == 0 || j == 0 || k == 0 || i == g->n[0] - 1 || j == g->n[1] - 1 ||
                    k == g->n[2] - 1)
                    c += at(g, i, j, k) < 0;
    return c;
}

static void check_box_independent(const char *name, hv_mesh *m)
{
    double lo[3], hi[3];
    TL_ASSERT_OK(hv_mesh_bounds(m, lo, hi));
    double L = fmax(hi[0] - lo[0], fmax(hi[1] - lo[1], hi[2] - lo[2]));
    const double h = L / 32;
    hv_mesh *rep = NULL;
    TL_ASSERT_OK(hv_sdf_repair(m, HV_SDF_REPAIR_ALL, 0.5, &rep, NULL));
    const int pads[3] = {1, 4, 32};
    hv_grid *g[3];
    hv_sdf_stats S[3];
    for (int q = 0; q < 3; q++)
        g[q] = run(m, h, pads[q], &S[q]);
    for (int q = 0; q < 3; q++) {
        uint8_t *wn = NULL;
        double wiou = -1;
        if (q < 2) { /* the pad-32 block is checked through the other two */
            wn = malloc(hv_grid_count(g[q]));
            tu_winding(rep, g[q], wn);
            wiou = tu_iou(g[q], wn);
            free(wn);
        }
        double piou = iou_window(g[0], g[q]);
        size_t out = outer_inside(g[q]);
        printf("  %-22s pad %2d: %dx%dx%d, sign from %s (%zu evaluations), inside-IoU %.5f "
               "against pad 1, %zu inside on the outer layer",
               name, pads[q], g[q]->n[0], g[q]->n[1], g[q]->n[2],
               S[q].sign == HV_SDF_SIGN_WINDING ? "winding" : "heat", S[q].winding_evals, piou,
               out);
        if (wiou >= 0)
            printf(", %.5f against the winding number", wiou);
        printf("\n");
        ck_assert_msg(piou >= 0.995, "%s: pad %d against pad 1: IoU %.5f", name, pads[q], piou);
        ck_assert_msg(out == 0, "%s: pad %d: %zu inside cells on the outer layer", name, pads[q],
                      out);
        if (wiou >= 0)
            ck_assert_msg(wiou >= 0.98, "%s: pad %d against the winding number: IoU %.5f", name,
                          pads[q], wiou);
    }
    for (int q = 0; q < 3; q++)
        hv_grid_destroy(&g[q]);
    hv_mesh_destroy(&rep);
}

START_TEST(sphere_with_a_cap_cut_off_should_not_depend_on_the_block)
{
    static const double caps[] = {30, 45, 60};
    const double up[3] = {0, 0, 1};
    char name[64];
    for (int c = 0; c < 3; c++) {
        hv_mesh *m = tu_open_sphere(up, caps[c]);
        snprintf(name, sizeof name, "sphere, %.0f deg cap off", caps[c]);
        check_box_independent(name, m);
        hv_mesh_destroy(&m);
    }
}
END_TEST

START_TEST(open_cylinder_should_not_depend_on_the_block)
{
    hv_mesh *m = tu_open_cylinder();
    check_box_independent("open cylinder", m);
    hv_mesh_destroy(&m);
}
END_TEST

START_TEST(bust_open_at_the_neck_should_not_depend_on_the_block)
{
    hv_mesh *m = bust();
    check_box_independent("bust open at the neck", m);
    hv_mesh_destroy(&m);
}
END_TEST

START_TEST(opening_towards_a_corner_should_not_depend_on_the_block)
{
    const double d[3] = {1, 1, 1};
    hv_mesh *m = tu_open_sphere(d, 50);
    check_box_independent("opening to a corner", m);
    hv_mesh_destroy(&m);
}
END_TEST

/* A window of the block through the middle of the mesh: the same signs as
 * the full run's cells there, and the same values within the narrow band
 * (band_only, as the command computes for a .vdb). */
static void check_window(const char *name, const hv_mesh *m, hv_sdf_sign full_sign)
{
    double lo[3], hi[3];
    TL_ASSERT_OK(hv_mesh_bounds(m, lo, hi));
    double L = fmax(hi[0] - lo[0], fmax(hi[1] - lo[1], hi[2] - lo[2]));
    const double h = L / 40;
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.voxel_size = h;
    o.round_to = 1;
    o.band_only = 3;
    o.sign = full_sign;
    hv_grid *full = NULL, *win = NULL;
    hv_sdf_stats Sf, Sw;
    TL_ASSERT_OK(hv_sdf_compute(m, &o, &full, &Sf));
    /* Lower half along x and the middle half along y, on the same lattice. */
    o.use_bbox = 1;
    o.sign = HV_SDF_SIGN_AUTO;
    for (int d = 0; d < 3; d++) {
        int a = 0, b = full->n[d];
        if (d == 0)
            b = full->n[0] / 2;
        if (d == 1)
            a = full->n[1] / 4, b = 3 * full->n[1] / 4;
        o.bbox[d] = full->origin[d] + a * h;
        o.bbox[3 + d] = full->origin[d] + b * h;
    }
    TL_ASSERT_OK(hv_sdf_compute(m, &o, &win, &Sw));
    ck_assert_int_eq(Sw.sign, HV_SDF_SIGN_WINDING);
    int off[3];
    offset(win, full, off);
    size_t sign_diff = 0, band = 0, inside = 0;
    double worst = 0;
    const float cap = (float)(3 * h);
    for (int k = 0; k < win->n[2]; k++)
        for (int j = 0; j < win->n[1]; j++)
            for (int i = 0; i < win->n[0]; i++) {
                float a = at(win, i, j, k), b = at(full, i + off[0], j + off[1], k + off[2]);
                sign_diff += (a < 0) != (b < 0);
                inside += b < 0;
                if (fabsf(b) <= cap) {
                    band++;
                    worst = fmax(worst, fabs((double)a - b) / h);
                }
            }
    printf("  %-22s window %dx%dx%d of %dx%dx%d (full run's sign from %s): %zu of %zu inside "
           "cells differ in sign, band values within %.2g voxel over %zu cells\n",
           name, win->n[0], win->n[1], win->n[2], full->n[0], full->n[1], full->n[2],
           Sf.sign == HV_SDF_SIGN_WINDING ? "winding" : "heat", sign_diff, inside, worst, band);
    ck_assert_msg(inside > 1000, "%s: the window holds too little of the inside", name);
    ck_assert_msg(sign_diff == 0, "%s: %zu cells change sign in the window", name, sign_diff);
    ck_assert_msg(worst <= 1e-6, "%s: band values differ by %g voxel", name, worst);
    hv_grid_destroy(&full);
    hv_grid_destroy(&win);
}

START_TEST(window_through_a_mesh_should_equal_the_full_run)
{
    const double c[3] = {0.01, -0.02, 0.03};
    hv_mesh *torus = NULL;
    TL_ASSERT_OK(hv_mesh_make_torus(&torus, c, 1.0, 0.4, 96, 48));
    /* Closed: the full run signs by the heat method, the window by the
     * winding number; and both by the winding number. */
    check_window("torus", torus, HV_SDF_SIGN_AUTO);
    check_window("torus", torus, HV_SDF_SIGN_WINDING);
    hv_mesh_destroy(&torus);
    const double up[3] = {0, 0, 1};
    hv_mesh *m = tu_open_sphere(up, 60);
    check_window("sphere, 60 deg cap off", m, HV_SDF_SIGN_AUTO);
    hv_mesh_destroy(&m);
}
END_TEST

/* Choices of the sign, and what AUTO picks. */
START_TEST(sign_option_should_pick_and_check_its_source)
{
    const double c[3] = {0, 0, 0}, up[3] = {0, 0, 1};
    hv_mesh *ball = NULL, *cut = tu_open_sphere(up, 60);
    TL_ASSERT_OK(hv_mesh_make_sphere(&ball, c, 1.0, 3));
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = 32;
    hv_grid *g = NULL;
    hv_sdf_stats S;
    TL_ASSERT_OK(hv_sdf_compute(ball, &o, &g, &S));
    ck_assert_int_eq(S.sign, HV_SDF_SIGN_HEAT);
    ck_assert_uint_eq(S.winding_evals, 0);
    ck_assert_int_gt(S.diffuse_iterations, 0);
    hv_grid_destroy(&g);
    TL_ASSERT_OK(hv_sdf_compute(cut, &o, &g, &S));
    ck_assert_int_eq(S.sign, HV_SDF_SIGN_WINDING);
    ck_assert_uint_gt(S.winding_evals, 0);
    ck_assert_int_eq(S.diffuse_iterations, 0); /* no heat solve ran */
    hv_grid_destroy(&g);
    /* The heat method on request: the open sphere's inside then leaks out
     * of its opening to the walls. */
    o.sign = HV_SDF_SIGN_HEAT;
    TL_ASSERT_OK(hv_sdf_compute(cut, &o, &g, &S));
    ck_assert_int_eq(S.sign, HV_SDF_SIGN_HEAT);
    ck_assert_uint_gt(outer_inside(g), 0);
    hv_grid_destroy(&g);
    /* The winding number on a closed ball: the same inside as the heat method. */
    o.sign = HV_SDF_SIGN_WINDING;
    hv_grid *gw = NULL;
    TL_ASSERT_OK(hv_sdf_compute(ball, &o, &gw, &S));
    o.sign = HV_SDF_SIGN_HEAT;
    TL_ASSERT_OK(hv_sdf_compute(ball, &o, &g, NULL));
    ck_assert_double_eq(iou_window(g, gw), 1.0);
    hv_grid_destroy(&g);
    hv_grid_destroy(&gw);
    /* No orientation, no winding number; unknown sources. */
    o.sign = HV_SDF_SIGN_WINDING;
    o.repair = 0;
    ck_assert_int_eq(hv_sdf_compute(cut, &o, &g, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "orientation"));
    o.repair = HV_SDF_REPAIR_ALL;
    o.sign = (hv_sdf_sign)7;
    ck_assert_int_eq(hv_sdf_compute(cut, &o, &g, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_null(g);
    /* Without orientation AUTO keeps the heat method. */
    o.sign = HV_SDF_SIGN_AUTO;
    o.repair = HV_SDF_REPAIR_WELD;
    TL_ASSERT_OK(hv_sdf_compute(cut, &o, &g, &S));
    ck_assert_int_eq(S.sign, HV_SDF_SIGN_HEAT);
    hv_grid_destroy(&g);
    hv_mesh_destroy(&ball);
    hv_mesh_destroy(&cut);
}
END_TEST

/* The command: --sign, its errors, and -v saying where the sign came from. */
START_TEST(command_should_take_and_report_the_sign)
{
    const char *bin = tl_heatvox_bin();
    ck_assert_msg(bin != NULL, "the heatvox command is not built");
    char dir[] = "/tmp/hv_check_sdf_box_XXXXXX";
    ck_assert_ptr_nonnull(mkdtemp(dir));
    const double up[3] = {0, 0, 1};
    hv_mesh *m = tu_open_sphere(up, 60);
    char path[600], cmd[2400], err[4096];
    snprintf(path, sizeof path, "%s/cut.obj", dir);
    TL_ASSERT_OK(hv_mesh_write_obj(m, path));
    hv_mesh_destroy(&m);
    snprintf(cmd, sizeof cmd, "'%s' sdf '%s' --res 24 --sign sideways -o '%s/a.vdb'", bin, path,
             dir);
    ck_assert_int_eq(tl_run_cmd(cmd, dir, err, sizeof err), 2);
    ck_assert_msg(strstr(err, "--sign needs auto, heat or winding, got 'sideways'"), "%s", err);
    snprintf(cmd, sizeof cmd, "'%s' sdf '%s' --res 24 --sign winding --no-repair -o '%s/a.vdb'",
             bin, path, dir);
    ck_assert_int_eq(tl_run_cmd(cmd, dir, err, sizeof err), 1);
    ck_assert_msg(strstr(err, "orientation"), "%s", err);
    snprintf(cmd, sizeof cmd, "'%s' sdf '%s' --res 24 -v -o '%s/a.vdb'", bin, path, dir);
    ck_assert_int_eq(tl_run_cmd(cmd, dir, err, sizeof err), 0);
    ck_assert_msg(strstr(err, "sign from winding"), "%s", err);
    snprintf(cmd, sizeof cmd, "'%s' sdf '%s' --res 24 -v --sign heat -o '%s/a.vdb'", bin, path,
             dir);
    ck_assert_int_eq(tl_run_cmd(cmd, dir, err, sizeof err), 0);
    ck_assert_msg(strstr(err, "sign from heat"), "%s", err);
    tl_rm_rf(dir);
}
END_TEST

int main(void)
{
    Suite *s = suite_create("sdf_box");
    TCase *tc = tcase_create("open");
    tcase_set_timeout(tc, 600);
    tcase_add_test(tc, sphere_with_a_cap_cut_off_should_not_depend_on_the_block);
    tcase_add_test(tc, open_cylinder_should_not_depend_on_the_block);
    tcase_add_test(tc, bust_open_at_the_neck_should_not_depend_on_the_block);
    tcase_add_test(tc, opening_towards_a_corner_should_not_depend_on_the_block);
    tcase_add_test(tc, window_through_a_mesh_should_equal_the_full_run);
    tcase_add_test(tc, sign_option_should_pick_and_check_its_source);
    tcase_add_test(tc, command_should_take_and_report_the_sign);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
