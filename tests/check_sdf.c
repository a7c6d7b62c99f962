/*
 * The signed heat method on grids (hv_sdf_compute) on analytic shapes, the
 * mesh repair it relies on, grid placement and argument checking.
 *
 * Truth: the exact SDF of a sphere and of a torus, meshed finely enough that
 * the polyhedron's SDF differs from the smooth one by less than 0.005 voxel
 * everywhere (icosphere level 5: sagitta 1.8e-4 R; torus 256 x 96 segments:
 * 1.1e-4 r), so the analytic SDF stands in for the polyhedron's. Errors are
 * measured in voxels (docs/METHOD.md, "Measuring accuracy").
 */
#include "heatvox/heatvox.h"

#include <check.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const double C0[3] = {0.013, -0.021, 0.007};
#define SPHERE_R 0.5
#define TORUS_R 0.55
#define TORUS_r 0.2

typedef double (*sdf_fn)(const double p[3]);

static double sphere_sdf(const double p[3])
{
    double x = p[0] - C0[0], y = p[1] - C0[1], z = p[2] - C0[2];
    return sqrt(x * x + y * y + z * z) - SPHERE_R;
}

static double torus_sdf(const double p[3])
{
    double x = p[0] - C0[0], y = p[1] - C0[1], z = p[2] - C0[2];
    double q = sqrt(x * x + y * y) - TORUS_R;
    return sqrt(q * q + z * z) - TORUS_r;
}

static hv_mesh *make_sphere(void)
{
    hv_mesh *m = NULL;
    ck_assert_int_eq(hv_mesh_make_sphere(&m, C0, SPHERE_R, 5), HV_OK);
    return m;
}

static hv_mesh *make_torus(void)
{
    hv_mesh *m = NULL;
    ck_assert_int_eq(hv_mesh_make_torus(&m, C0, TORUS_R, TORUS_r, 256, 96), HV_OK);
    return m;
}

/* Options for the block [-1,1]^3 with n cells per axis. */
static hv_sdf_opts box_opts(int n)
{
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = n;
    o.use_bbox = 1;
    double b[6] = {-1, -1, -1, 1, 1, 1};
    memcpy(o.bbox, b, sizeof b);
    return o;
}

typedef struct errs {
    double band_mean; /* mean |phi - truth| over |truth| < 3h, voxels */
    double band_max;
    double max_all;  /* over the whole grid */
    double far_max;  /* over |truth| > 10 h */
    size_t sign_bad; /* cells with |truth| > h and the wrong sign */
    size_t sign_cells;
} errs;

static errs measure(const hv_grid *g, sdf_fn truth, int unsig)
{
    errs e;
    memset(&e, 0, sizeof e);
    size_t nb = 0;
    for (int k = 0; k < g->n[2]; k++)
        for (int j = 0; j < g->n[1]; j++)
            for (int i = 0; i < g->n[0]; i++) {
                double p[3];
                hv_grid_cell_center(g, i, j, k, p);
                double t = truth(p), v = g->v[i + (size_t)g->n[0] * (j + (size_t)g->n[1] * k)];
                if (unsig)
                    t = fabs(t);
                double err = fabs(v - t) / g->h;
                e.max_all = fmax(e.max_all, err);
                if (fabs(t) < 3 * g->h) {
                    e.band_mean += err;
                    e.band_max = fmax(e.band_max, err);
                    nb++;
                }
                if (fabs(t) > 10 * g->h)
                    e.far_max = fmax(e.far_max, err);
                if (fabs(t) > g->h) {
                    e.sign_cells++;
                    e.sign_bad += (v < 0) != (t < 0);
                }
            }
    e.band_mean /= (double)(nb ? nb : 1);
    return e;
}

static errs run(const hv_mesh *m, hv_sdf_opts o, sdf_fn truth, hv_sdf_stats *stats)
{
    hv_grid *g = NULL;
    hv_sdf_stats S;
    hv_status st = hv_sdf_compute(m, &o, &g, &S);
    ck_assert_msg(st == HV_OK, "hv_sdf_compute: %s: %s", hv_status_str(st), hv_last_error());
    errs e = measure(g, truth, o.unsigned_distance);
    printf("  %-6s n=%d %s%s: band mean %.4f max %.3f | whole grid max %.3f | far max %.3f | "
           "sign %zu/%zu wrong | %.2f s\n",
           truth == sphere_sdf ? "sphere" : "torus", g->n[0],
           o.unsigned_distance ? "unsigned " : "", o.magnitude == HV_SDF_EXACT ? "exact" : "heat",
           e.band_mean, e.band_max, e.max_all, e.far_max, e.sign_bad, e.sign_cells, S.t_total);
    if (stats)
        *stats = S;
    hv_grid_destroy(&g);
    return e;
}

static void check_targets(sdf_fn truth, hv_mesh *(*make)(void))
{
    hv_mesh *m = make();
    for (int n = 32; n <= 64; n *= 2) {
        errs e = run(m, box_opts(n), truth, NULL);
        ck_assert_msg(e.sign_bad == 0, "n=%d: %zu cells beyond 1 voxel have the wrong sign", n,
                      e.sign_bad);
        ck_assert_msg(e.band_mean <= 0.1, "n=%d: mean error %.4f voxel within 3 voxels", n,
                      e.band_mean);
        ck_assert_msg(e.max_all <= 1.5, "n=%d: max error %.3f voxels over the grid", n, e.max_all);
    }
    hv_mesh_destroy(&m);
}

START_TEST(sphere_should_meet_the_voxel_targets) { check_targets(sphere_sdf, make_sphere); }
END_TEST

START_TEST(torus_should_meet_the_voxel_targets) { check_targets(torus_sdf, make_torus); }
END_TEST

/* Large grids run the heat method (which then only decides the sign) on a
 * grid twice as coarse; forced here on small grids, the targets still hold
 * and the stats say so. */
START_TEST(coarse_heat_grid_should_meet_the_voxel_targets)
{
    sdf_fn truths[2] = {sphere_sdf, torus_sdf};
    hv_mesh *(*makes[2])(void) = {make_sphere, make_torus};
    for (int s = 0; s < 2; s++) {
        hv_mesh *m = makes[s]();
        hv_sdf_opts o = box_opts(64);
        o.heat_coarsen = 2;
        hv_sdf_stats S;
        errs e = run(m, o, truths[s], &S);
        ck_assert_int_eq(S.heat_coarsen, 2);
        ck_assert_msg(e.sign_bad == 0, "%zu cells beyond 1 voxel have the wrong sign", e.sign_bad);
        ck_assert_msg(e.band_mean <= 0.1, "mean error %.4f voxel within 3 voxels", e.band_mean);
        ck_assert_msg(e.max_all <= 1.5, "max error %.3f voxels over the grid", e.max_all);
        hv_mesh_destroy(&m);
    }
}
END_TEST

/* The heat method's own phi (no exact magnitude) converges: its band error
 * in world units shrinks from 32^3 to 64^3, and its sign is right. */
START_TEST(heat_phi_error_should_shrink_under_refinement)
{
    sdf_fn truths[2] = {sphere_sdf, torus_sdf};
    hv_mesh *(*makes[2])(void) = {make_sphere, make_torus};
    for (int s = 0; s < 2; s++) {
        hv_mesh *m = makes[s]();
        double world[2];
        for (int q = 0; q < 2; q++) {
            hv_sdf_opts o = box_opts(32 << q);
            o.magnitude = HV_SDF_HEAT;
            errs e = run(m, o, truths[s], NULL);
            ck_assert_uint_eq(e.sign_bad, 0);
            ck_assert_msg(e.band_mean <= 0.1, "heat phi band error %.4f voxel", e.band_mean);
            world[q] = e.band_mean * 2.0 / (32 << q);
        }
        ck_assert_msg(world[1] < 0.7 * world[0], "band error %.3g -> %.3g under refinement",
                      world[0], world[1]);
        hv_mesh_destroy(&m);
    }
}
END_TEST

START_TEST(unsigned_distance_should_match_the_absolute_sdf)
{
    hv_mesh *m = make_torus();
    hv_sdf_opts o = box_opts(48);
    o.unsigned_distance = 1;
    errs e = run(m, o, torus_sdf, NULL);
    ck_assert_msg(e.max_all <= 0.05, "exact unsigned distance off by %.3f voxel", e.max_all);
    double world[2];
    for (int q = 0; q < 2; q++) {
        o = box_opts(32 << q);
        o.unsigned_distance = 1;
        o.magnitude = HV_SDF_HEAT;
        e = run(m, o, torus_sdf, NULL);
        ck_assert_msg(e.band_mean <= 0.3, "heat unsigned distance: band error %.3f voxel",
                      e.band_mean);
        world[q] = e.band_mean * 2.0 / (32 << q);
    }
    ck_assert_msg(world[1] < 0.8 * world[0], "unsigned band error %.3g -> %.3g under refinement",
                  world[0], world[1]);
    hv_mesh_destroy(&m);
}
END_TEST

/* Far from the surface the diffused normals decay below solver accuracy;
 * the sign must survive (phi is harmonic there) on a grid large against t. */
START_TEST(far_field_should_keep_sign_and_distance)
{
    hv_mesh *m = NULL;
    const double c[3] = {-0.6, 0.55, -0.5};
    ck_assert_int_eq(hv_mesh_make_sphere(&m, c, 0.12, 4), HV_OK);
    hv_sdf_opts o = box_opts(96);
    hv_grid *g = NULL;
    hv_sdf_stats S;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, &S), HV_OK);
    double worst = 0;
    size_t bad = 0;
    for (int k = 0; k < g->n[2]; k++)
        for (int j = 0; j < g->n[1]; j++)
            for (int i = 0; i < g->n[0]; i++) {
                double p[3];
                hv_grid_cell_center(g, i, j, k, p);
                double t = sqrt((p[0] - c[0]) * (p[0] - c[0]) + (p[1] - c[1]) * (p[1] - c[1]) +
                                (p[2] - c[2]) * (p[2] - c[2])) -
                           0.12;
                double v = g->v[i + (size_t)g->n[0] * (j + (size_t)g->n[1] * k)];
                if (t > 20 * g->h) {
                    bad += v <= 0;
                    worst = fmax(worst, fabs(v - t) / g->h);
                }
            }
    printf("  far field (> 20 voxels, up to %.0f): max error %.3f voxel, %zu wrong signs, %zu dead "
           "faces\n",
           (sqrt(3.0) * 2 - 0.2) / g->h, worst, bad, S.dead_faces);
    ck_assert_uint_gt(S.dead_faces, 0); /* the test does reach beyond the diffusion */
    ck_assert_uint_eq(bad, 0);
    ck_assert_double_le(worst, 0.5);
    hv_grid_destroy(&g);
    hv_mesh_destroy(&m);
}
END_TEST

/* ---------- repair ---------- */

static double phi_at(const hv_grid *g, const double x[3])
{
    int idx[3];
    for (int a = 0; a < 3; a++) {
        idx[a] = (int)floor((x[a] - g->origin[a]) / g->h);
        idx[a] = idx[a] < 0 ? 0 : idx[a] >= g->n[a] ? g->n[a] - 1 : idx[a];
    }
    return g->v[idx[0] + (size_t)g->n[0] * (idx[1] + (size_t)g->n[1] * idx[2])];
}

static void flip_all(hv_mesh *m)
{
    for (size_t f = 0; f < m->ntris; f++) {
        uint32_t t = m->tris[3 * f + 1];
        m->tris[3 * f + 1] = m->tris[3 * f + 2];
        m->tris[3 * f + 2] = t;
    }
}

/* Concatenates two meshes. */
static hv_mesh *join(const hv_mesh *a, const hv_mesh *b)
{
    size_t nv = a->nverts + b->nverts, nt = a->ntris + b->ntris;
    double *V = malloc(3 * nv * sizeof *V);
    uint32_t *T = malloc(3 * nt * sizeof *T);
    memcpy(V, a->verts, 3 * a->nverts * sizeof *V);
    memcpy(V + 3 * a->nverts, b->verts, 3 * b->nverts * sizeof *V);
    memcpy(T, a->tris, 3 * a->ntris * sizeof *T);
    for (size_t i = 0; i < 3 * b->ntris; i++)
        T[3 * a->ntris + i] = b->tris[i] + (uint32_t)a->nverts;
    hv_mesh *m = NULL;
    ck_assert_int_eq(hv_mesh_from_arrays(&m, V, nv, T, nt), HV_OK);
    free(V);
    free(T);
    return m;
}

START_TEST(repair_should_drop_duplicates_weld_soups_and_fix_orientation)
{
    hv_mesh *m = NULL;
    ck_assert_int_eq(hv_mesh_make_sphere(&m, C0, 0.5, 2), HV_OK);
    size_t nt = m->ntris;
    ck_assert_int_eq(hv_mesh_defect_duplicate(m, 0.2, 5), HV_OK);
    ck_assert_int_eq(hv_mesh_defect_flip(m, 0.4, 6), HV_OK);
    ck_assert_int_eq(hv_mesh_defect_soup(m, 0, 7), HV_OK);
    hv_mesh *r = NULL;
    hv_sdf_repair_report R;
    ck_assert_int_eq(hv_sdf_repair(m, HV_SDF_REPAIR_ALL, 0.5, &r, &R), HV_OK);
    ck_assert_uint_eq(R.triangles_out, nt);
    ck_assert_uint_eq(R.duplicates_removed, m->ntris - nt);
    ck_assert_uint_gt(R.vertices_welded, 0);
    ck_assert_uint_gt(R.inconsistent_before, 0);
    ck_assert_uint_eq(R.inconsistent_after, 0);
    ck_assert_uint_eq(R.boundary_edges, 0);
    hv_mesh_report mr;
    ck_assert_int_eq(hv_mesh_report_compute(r, &mr), HV_OK);
    ck_assert_uint_eq(mr.inconsistent_edges, 0);
    ck_assert_double_gt(mr.signed_volume, 0);
    hv_mesh_destroy(&r);
    /* Without the orientation steps the inconsistency stays. */
    ck_assert_int_eq(hv_sdf_repair(m, HV_SDF_REPAIR_WELD | HV_SDF_REPAIR_DUPLICATES, 0.5, &r, &R),
                     HV_OK);
    ck_assert_uint_gt(R.inconsistent_after, 0);
    hv_mesh_destroy(&r);
    hv_mesh_destroy(&m);
}
END_TEST

START_TEST(inside_out_mesh_should_come_out_negative_inside)
{
    hv_mesh *m = make_sphere();
    flip_all(m);
    hv_sdf_opts o = box_opts(32);
    hv_grid *g = NULL;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, NULL), HV_OK);
    ck_assert_double_lt(phi_at(g, C0), -0.4);
    hv_grid_destroy(&g);
    /* Without repair the heat method follows the given orientation. */
    o.repair = 0;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, NULL), HV_OK);
    ck_assert_double_gt(phi_at(g, C0), 0.4);
    hv_grid_destroy(&g);
    hv_mesh_destroy(&m);
}
END_TEST

/* A hollow ball: the inner shell bounds a cavity, outside the solid. */
START_TEST(nested_shell_should_stay_a_cavity)
{
    hv_mesh *outer = NULL;
    ck_assert_int_eq(hv_mesh_make_sphere(&outer, C0, 0.7, 3), HV_OK);
    for (int variant = 0; variant < 2; variant++) {
        /* variant 0: the cavity's shell faces inward (consistent); 1: outward. */
        hv_mesh *inner = NULL;
        ck_assert_int_eq(hv_mesh_make_sphere(&inner, C0, 0.35, 3), HV_OK);
        if (variant == 0)
            flip_all(inner);
        hv_mesh *m = join(outer, inner);
        hv_sdf_opts o = box_opts(48);
        hv_grid *g = NULL;
        ck_assert_int_eq(hv_sdf_compute(m, &o, &g, NULL), HV_OK);
        double shell[3] = {C0[0] + 0.52, C0[1], C0[2]}, out[3] = {C0[0], C0[1], C0[2] + 0.9};
        ck_assert_msg(phi_at(g, C0) > 0.25, "variant %d: cavity centre %g", variant, phi_at(g, C0));
        ck_assert_msg(phi_at(g, shell) < -0.1, "variant %d: shell %g", variant, phi_at(g, shell));
        ck_assert_double_gt(phi_at(g, out), 0.1);
        hv_grid_destroy(&g);
        hv_mesh_destroy(&m);
        hv_mesh_destroy(&inner);
    }
    hv_mesh_destroy(&outer);
}
END_TEST

/* An open tube: without caps the heat method would carry the tube to the
 * grid boundary; hole filling closes it at its rims. */
START_TEST(open_tube_should_be_capped_at_its_rims)
{
    const int nu = 32, nz = 16;
    double *V = malloc(3 * (size_t)nu * (nz + 1) * sizeof *V);
    uint32_t *T = malloc(6 * (size_t)nu * nz * sizeof *T);
    size_t t = 0;
    for (int k = 0; k <= nz; k++)
        for (int i = 0; i < nu; i++) {
            double a = 2 * M_PI * i / nu, *x = V + 3 * ((size_t)k * nu + i);
            x[0] = 0.2 * cos(a), x[1] = 0.2 * sin(a), x[2] = -0.5 + (double)k / nz;
        }
    for (int k = 0; k < nz; k++)
        for (int i = 0; i < nu; i++) {
            uint32_t a = k * nu + i, b = k * nu + (i + 1) % nu, c = (k + 1) * nu + (i + 1) % nu,
                     d = (k + 1) * nu + i;
            uint32_t q[6] = {a, b, c, a, c, d};
            memcpy(T + 3 * t, q, sizeof q);
            t += 2;
        }
    hv_mesh *m = NULL;
    ck_assert_int_eq(hv_mesh_from_arrays(&m, V, (size_t)nu * (nz + 1), T, t), HV_OK);
    free(V);
    free(T);
    hv_sdf_opts o = box_opts(48);
    hv_grid *g = NULL;
    hv_sdf_stats S;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, &S), HV_OK);
    ck_assert_uint_eq(S.repair.holes_filled, 2);
    double mid[3] = {0, 0, 0}, beyond[3] = {0, 0, 0.8};
    ck_assert_double_lt(phi_at(g, mid), -0.15);
    ck_assert_double_gt(phi_at(g, beyond), 0.2);
    hv_grid_destroy(&g);
    o.repair &= ~(unsigned)HV_SDF_REPAIR_FILL_HOLES;
    /* With the default sign-only tolerance (1e-6) the field along the open
     * tube decays into dead faces before the probe, which hides the failure;
     * at tight tolerances it reaches it. */
    o.diffuse_tol = 1e-10;
    o.poisson_tol = 1e-8;
    o.sign = HV_SDF_SIGN_HEAT;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, NULL), HV_OK);
    ck_assert_double_lt(phi_at(g, beyond), 0); /* the failure the caps prevent */
    hv_grid_destroy(&g);
    /* Left open, the tube is signed by its winding number by default, which
     * does not leak either (tests/check_sdf_box.c). */
    o.sign = HV_SDF_SIGN_AUTO;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, &S), HV_OK);
    ck_assert_int_eq(S.sign, HV_SDF_SIGN_WINDING);
    ck_assert_double_lt(phi_at(g, mid), -0.15);
    ck_assert_double_gt(phi_at(g, beyond), 0.2);
    hv_grid_destroy(&g);
    hv_mesh_destroy(&m);
}
END_TEST

/* ---------- placement and arguments ---------- */

START_TEST(placement_should_follow_res_pad_and_bbox)
{
    hv_mesh *m = make_torus();
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = 64;
    o.pad = 4;
    int n[3];
    double h, org[3], lo[3], hi[3];
    ck_assert_int_eq(hv_sdf_grid_for_mesh(m, &o, n, &h, org), HV_OK);
    ck_assert_int_eq(hv_mesh_bounds(m, lo, hi), HV_OK);
    ck_assert_int_eq(n[0] > n[2] ? n[0] : n[2], 64);
    ck_assert_double_eq_tol(h, (hi[0] - lo[0]) / 56, 1e-12);
    ck_assert_int_eq(n[2] % 8, 0);
    for (int a = 0; a < 3; a++) {
        ck_assert_double_ge(lo[a] - org[a], 4 * h - 1e-9);
        ck_assert_double_ge(org[a] + n[a] * h - hi[a], 4 * h - 1e-9);
    }
    o.voxel_size = 0.05;
    ck_assert_int_eq(hv_sdf_grid_for_mesh(m, &o, n, &h, org), HV_OK);
    ck_assert_double_eq(h, 0.05);
    o = box_opts(40);
    o.bbox[5] = 0.5; /* 2 x 2 x 1.5 */
    ck_assert_int_eq(hv_sdf_grid_for_mesh(m, &o, n, &h, org), HV_OK);
    ck_assert_double_eq_tol(h, 0.05, 1e-15);
    ck_assert_int_eq(n[0], 40);
    ck_assert_int_eq(n[2], 30);
    ck_assert_double_eq(org[0], -1);
    hv_mesh_destroy(&m);
}
END_TEST

START_TEST(bad_input_should_fail_with_clear_errors)
{
    hv_mesh *m = make_sphere();
    hv_grid *g = NULL;
    hv_sdf_opts o = box_opts(16);
    ck_assert_int_eq(hv_sdf_compute(m, &o, NULL, NULL), HV_ERR_INVALID_ARG);
    o.res = 0;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, NULL), HV_ERR_INVALID_ARG);
    o = box_opts(16);
    o.bbox[3] = -2;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "bounding box"));
    /* A block that misses the mesh: the exact distance with the winding
     * number's sign, outside and at least as far as the mesh's bounds; the
     * heat method, which needs the surface in the block, refuses it. */
    o = box_opts(16);
    double far[6] = {5, 5, 5, 6, 6, 6};
    memcpy(o.bbox, far, sizeof far);
    hv_sdf_stats fs;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, &fs), HV_OK);
    ck_assert_int_eq(fs.sign, HV_SDF_SIGN_WINDING);
    double mlo[3], mhi[3];
    ck_assert_int_eq(hv_mesh_bounds(m, mlo, mhi), HV_OK);
    double gap = 0;
    for (int a = 0; a < 3; a++)
        gap += (5 - mhi[a]) * (5 - mhi[a]);
    for (size_t c = 0; c < hv_grid_count(g); c++)
        ck_assert_msg(g->v[c] >= sqrt(gap) * (1 - 1e-6), "cell %zu: %g nearer than the bounds", c,
                      g->v[c]);
    hv_grid_destroy(&g);
    o.sign = HV_SDF_SIGN_HEAT;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "no part of the mesh"));
    ck_assert_ptr_null(g);
    /* Absurd grids are refused before allocating. */
    hv_sdf_opts_default(&o);
    o.res = 2000000;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, NULL), HV_ERR_NOMEM);
    o.res = 8;
    o.pad = 4;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, NULL), HV_ERR_INVALID_ARG);
    /* NaN coordinates, bad indices, empty meshes. */
    hv_sdf_opts_default(&o);
    o.res = 16;
    double keep = m->verts[4];
    m->verts[4] = NAN;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, NULL), HV_ERR_NUMERIC);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "non-finite"));
    m->verts[4] = keep;
    uint32_t ki = m->tris[5];
    m->tris[5] = (uint32_t)m->nverts;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, NULL), HV_ERR_INVALID_ARG);
    m->tris[5] = ki;
    size_t nt = m->ntris;
    m->ntris = 0;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "empty"));
    m->ntris = nt;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, NULL), HV_OK);
    hv_grid_destroy(&g);
    hv_mesh_destroy(&m);
}
END_TEST

static int cancel_at_poisson(double fraction, const char *stage, void *user)
{
    (void)fraction;
    ++*(int *)user;
    return !strcmp(stage, "poisson");
}

START_TEST(progress_should_report_stages_and_cancel)
{
    hv_mesh *m = make_sphere();
    hv_sdf_opts o = box_opts(24);
    hv_grid *g = NULL;
    int calls = 0;
    hv_set_progress(cancel_at_poisson, &calls);
    hv_status st = hv_sdf_compute(m, &o, &g, NULL);
    hv_set_progress(NULL, NULL);
    ck_assert_int_eq(st, HV_ERR_CANCELLED);
    ck_assert_ptr_null(g);
    ck_assert_int_ge(calls, 4);
    hv_sdf_stats S;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, &S), HV_OK);
    ck_assert_int_gt(S.diffuse_iterations, 0);
    ck_assert_int_gt(S.poisson_iterations, 0);
    ck_assert_double_ge(S.t_total, S.t_diffuse + S.t_poisson);
    ck_assert_uint_gt(S.surface_samples, m->ntris / 2);
    hv_grid_destroy(&g);
    hv_mesh_destroy(&m);
}
END_TEST

int main(void)
{
    Suite *s = suite_create("sdf");
    TCase *tc = tcase_create("analytic");
    tcase_set_timeout(tc, 300);
    tcase_add_test(tc, sphere_should_meet_the_voxel_targets);
    tcase_add_test(tc, torus_should_meet_the_voxel_targets);
    tcase_add_test(tc, coarse_heat_grid_should_meet_the_voxel_targets);
    tcase_add_test(tc, heat_phi_error_should_shrink_under_refinement);
    tcase_add_test(tc, unsigned_distance_should_match_the_absolute_sdf);
    tcase_add_test(tc, far_field_should_keep_sign_and_distance);
    suite_add_tcase(s, tc);
    tc = tcase_create("repair");
    tcase_set_timeout(tc, 120);
    tcase_add_test(tc, repair_should_drop_duplicates_weld_soups_and_fix_orientation);
    tcase_add_test(tc, inside_out_mesh_should_come_out_negative_inside);
    tcase_add_test(tc, nested_shell_should_stay_a_cavity);
    tcase_add_test(tc, open_tube_should_be_capped_at_its_rims);
    suite_add_tcase(s, tc);
    tc = tcase_create("api");
    tcase_set_timeout(tc, 60);
    tcase_add_test(tc, placement_should_follow_res_pad_and_bbox);
    tcase_add_test(tc, bad_input_should_fail_with_clear_errors);
    tcase_add_test(tc, progress_should_report_stages_and_cancel);
    suite_add_tcase(s, tc);
    SRunner *sr = srunner_create(s);
    /* No fork, whatever CK_FORK says: the library links PoCL and OpenVDB/TBB,
     * whose worker threads do not survive fork: a forked test hangs
     * (docs/METHOD.md, "Testing notes"). */
    srunner_set_fork_status(sr, CK_NOFORK);
    srunner_run_all(sr, CK_NORMAL);
    int failed = srunner_ntests_failed(sr);
    srunner_free(sr);
    return failed ? EXIT_FAILURE : EXIT_SUCCESS;
}
