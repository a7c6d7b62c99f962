/*
 * The narrow band in tiles on an OpenCL device (src/sdf/tiles_cl.c) against
 * the host path (sdf_tiles.c, itself equal to the dense band): the same
 * tiles in the same order, the same active voxels, the same sign on every
 * one, distances within 1e-4 voxel, on closed, defective, open and shared
 * meshes, signed and unsigned, in windows and in many batches; what crosses
 * between host and device is the mesh, its sign data and the tiles, plus a
 * few scalars (HEATVOX_OPENCL_PROFILE's byte counts); the command writes the
 * same .vdb with --backend opencl. On PoCL in CI; skipped without a device.
 */
#include "heatvox/heatvox.h"
#include "heatvox/opencl.h"
#include "sdf_testutil.h"
#include "testlib.h"

#include <check.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Whether an OpenCL device with fp64 is here; skips the test otherwise. */
static int have_device(void)
{
    hv_opencl_device d;
    if (hv_opencl_probe(&d) != HV_OK) {
        tl_skip("no OpenCL device: %s", hv_last_error());
        return 0;
    }
    if (!d.fp64) {
        tl_skip("the OpenCL device '%s' has no fp64", d.name);
        return 0;
    }
    return 1;
}

static hv_tiles *tiles_of(const hv_mesh *m, const hv_sdf_opts *o, hv_backend b, double band,
                          hv_sdf_stats *S, const char *what)
{
    hv_sdf_opts x = *o;
    x.backend = b;
    hv_tiles *T = NULL;
    hv_status st = hv_sdf_compute_tiles(m, &x, band, &T, S);
    ck_assert_msg(st == HV_OK, "%s (%s): %s", what, hv_backend_name(b), hv_last_error());
    return T;
}

/* Compares the device's tiles of m with the host's; returns the active
 * voxels. */
static size_t check_against_host(const hv_mesh *m, const hv_sdf_opts *o, double band,
                                 const char *what)
{
    hv_sdf_stats Sh, Sd;
    hv_tiles *H = tiles_of(m, o, HV_BACKEND_MG, band, &Sh, what);
    hv_tiles *D = tiles_of(m, o, HV_BACKEND_OPENCL, band, &Sd, what);
    ck_assert_msg(Sd.backend == HV_BACKEND_OPENCL, "%s: the device path did not run", what);
    ck_assert_msg(D->count == H->count, "%s: %zu tiles on the device, %zu on the host", what,
                  D->count, H->count);
    ck_assert_msg(D->active == H->active && Sd.active_voxels == Sh.active_voxels,
                  "%s: %zu active voxels on the device, %zu on the host", what, D->active,
                  H->active);
    /* The same work: cells rasterized, signed by pseudonormals, winding
     * numbers evaluated (the flood seeds where the host's does). */
    ck_assert_msg(Sd.band_cells == Sh.band_cells && Sd.near_sign_cells == Sh.near_sign_cells &&
                      Sd.winding_evals == Sh.winding_evals,
                  "%s: device %zu cells, %zu by pseudonormals, %zu evaluations; host %zu, %zu, "
                  "%zu",
                  what, Sd.band_cells, Sd.near_sign_cells, Sd.winding_evals, Sh.band_cells,
                  Sh.near_sign_cells, Sh.winding_evals);
    const float tol = (float)(1e-4 * H->h);
    size_t signs = 0, far = 0;
    float worst = 0;
    for (size_t q = 0; q < H->count; q++) {
        ck_assert_msg(memcmp(D->ijk + 3 * q, H->ijk + 3 * q, 3 * sizeof *H->ijk) == 0,
                      "%s: tile %zu at (%d %d %d) on the device, (%d %d %d) on the host", what, q,
                      D->ijk[3 * q], D->ijk[3 * q + 1], D->ijk[3 * q + 2], H->ijk[3 * q],
                      H->ijk[3 * q + 1], H->ijk[3 * q + 2]);
        ck_assert_msg(memcmp(D->on + 8 * q, H->on + 8 * q, 8 * sizeof *H->on) == 0,
                      "%s: tile %zu: other active voxels", what, q);
        for (int o3 = 0; o3 < 512; o3++) {
            const float dv = D->v[512 * q + o3], hv = H->v[512 * q + o3];
            signs += (dv < 0) != (hv < 0);
            far += !(fabsf(dv - hv) <= tol);
            worst = fmaxf(worst, fabsf(dv - hv));
        }
    }
    ck_assert_msg(signs == 0 && far == 0,
                  "%s: %zu voxels of other sign, %zu farther than 1e-4 voxel apart (worst %.3g "
                  "voxel)",
                  what, signs, far, (double)(worst / H->h));
    ck_assert_uint_gt(H->active, 0);
    const size_t active = H->active;
    hv_tiles_destroy(&H);
    hv_tiles_destroy(&D);
    return active;
}

START_TEST(closed_and_defective_meshes_should_equal_the_host_tiles)
{
    if (!have_device())
        return;
    const double c[3] = {0.1, -0.2, 0.05};
    hv_mesh *sphere = NULL, *torus = NULL, *broken = NULL;
    TL_ASSERT_OK(hv_mesh_make_sphere(&sphere, c, 1.0, 4));
    TL_ASSERT_OK(hv_mesh_make_torus(&torus, c, 1.0, 0.35, 64, 24));
    TL_ASSERT_OK(hv_mesh_make_sphere(&broken, c, 1.0, 4));
    TL_ASSERT_OK(hv_mesh_defect_holes(broken, 3, 0.15, 7));
    TL_ASSERT_OK(hv_mesh_defect_flip(broken, 0.3, 8));
    TL_ASSERT_OK(hv_mesh_defect_duplicate(broken, 0.1, 9));
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    const double bands[3] = {3, 1.5, 4};
    const int res[3] = {48, 61, 80};
    for (int b = 0; b < 3; b++) {
        o.res = res[b];
        check_against_host(sphere, &o, bands[b], "sphere");
        check_against_host(torus, &o, bands[b], "torus");
        check_against_host(broken, &o, bands[b], "sphere with holes, flips and duplicates");
    }
    o.res = 56;
    o.unsigned_distance = 1;
    check_against_host(torus, &o, 3, "torus, unsigned");
    hv_mesh_destroy(&sphere);
    hv_mesh_destroy(&torus);
    hv_mesh_destroy(&broken);
}
END_TEST

START_TEST(open_meshes_windows_and_batches_should_equal_the_host_tiles)
{
    if (!have_device())
        return;
    const double up[3] = {0, 0, 1};
    hv_mesh *cap = tu_open_sphere(up, 45), *cyl = tu_open_cylinder();
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = 64;
    check_against_host(cap, &o, 3, "sphere with a cap cut off");
    check_against_host(cyl, &o, 3, "open cylinder");
    /* Many batches: the tiles come back in pieces, in order. */
    setenv("HEATVOX_TILE_BATCH", "37", 1);
    check_against_host(cyl, &o, 3, "open cylinder, batches of 37 tiles");
    unsetenv("HEATVOX_TILE_BATCH");
    o.use_bbox = 1;
    const double box[6] = {-0.3, -1.2, -0.4, 1.2, 1.2, 0.5};
    memcpy(o.bbox, box, sizeof box);
    o.voxel_size = 1.0 / 24;
    check_against_host(cap, &o, 3, "window through the open sphere");
    hv_mesh_destroy(&cap);
    hv_mesh_destroy(&cyl);
}
END_TEST

START_TEST(shared_meshes_should_equal_the_host_tiles)
{
    if (!have_device())
        return;
    const char *names[] = {"bunny_small.obj", "armadillo_bad.obj", "chair.obj", "knot.obj",
                           "spot.obj"};
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = 64;
    for (size_t k = 0; k < sizeof names / sizeof names[0]; k++) {
        if (tl_sanitized() && k > 0)
            break;
        hv_mesh *m = tu_load_shared(names[k]);
        if (!m)
            return;
        check_against_host(m, &o, 3, names[k]);
        hv_mesh_destroy(&m);
    }
}
END_TEST

/* What crosses in a device run: the mesh and its sign data in (vertices,
 * triangles, face and vertex normals, edge neighbours, the tree of at most
 * 2 nodes a face), the kept tiles out in batches, and eight scalars. */
static void check_traffic(const hv_mesh *m, const hv_sdf_opts *o, const char *what)
{
    double in, out;
    long reads;
    tl_cl_traffic(&in, &out, &reads);
    hv_sdf_stats S;
    hv_tiles *D = tiles_of(m, o, HV_BACKEND_OPENCL, 3, &S, what);
    tl_cl_traffic(&in, &out, &reads);
    const double nv = (double)m->nverts, nt = (double)m->ntris;
    const double inputs =
        24 * nv + 12 * nt + 24 * nt + 24 * nv + 12 * nt + nv + 5 * nt + 2 * nt * 80;
    const double tiles = (double)D->count * (512 * 4 + 8 * 8 + 3 * 4);
    const size_t batch = S.tiles_in_flight, batches = (D->count + batch - 1) / batch;
    printf("check_sdf_tiles_cl: %s: %.0f bytes in (bound %.0f), %.0f out (%zu tiles: %.0f), "
           "%ld reads in %zu batches\n",
           what, in, inputs, out, D->count, tiles, reads, batches);
    ck_assert_msg(in >= 24 * nv + 12 * nt && in <= inputs, "%s: %.0f bytes to the device", what,
                  in);
    ck_assert_msg(out >= tiles && out <= tiles + 8 * 4, "%s: %.0f bytes to the host for %.0f", what,
                  out, tiles);
    ck_assert_msg(reads <= 3 * (long)batches + 5, "%s: %ld reads", what, reads);
    hv_tiles_destroy(&D);
}

START_TEST(device_runs_should_move_their_inputs_and_tiles_only)
{
    if (!have_device())
        return;
    const double c[3] = {0.1, -0.2, 0.05}, up[3] = {0, 0, 1};
    hv_mesh *torus = NULL, *cap = tu_open_sphere(up, 45);
    TL_ASSERT_OK(hv_mesh_make_torus(&torus, c, 1.0, 0.35, 64, 24));
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = 96;
    check_traffic(torus, &o, "torus");
    check_traffic(cap, &o, "open sphere");
    setenv("HEATVOX_TILE_BATCH", "50", 1);
    check_traffic(torus, &o, "torus, batches of 50");
    unsetenv("HEATVOX_TILE_BATCH");
    o.unsigned_distance = 1;
    check_traffic(torus, &o, "torus, unsigned");
    hv_mesh_destroy(&torus);
    hv_mesh_destroy(&cap);
}
END_TEST

/* auto takes the device where a solve would (HEATVOX_AUTO_OPENCL=1 on a CPU
 * device), mg keeps the host. */
START_TEST(auto_should_take_the_device_where_solves_do)
{
    if (!have_device())
        return;
    const double c[3] = {0, 0, 0};
    hv_mesh *sphere = NULL;
    TL_ASSERT_OK(hv_mesh_make_sphere(&sphere, c, 1.0, 3));
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = 40;
    hv_sdf_stats S;
    setenv("HEATVOX_AUTO_OPENCL", "1", 1);
    hv_tiles *T = tiles_of(sphere, &o, HV_BACKEND_AUTO, 3, &S, "auto, device asked for");
    ck_assert_int_eq(S.backend, HV_BACKEND_OPENCL);
    hv_tiles_destroy(&T);
    setenv("HEATVOX_AUTO_OPENCL", "0", 1);
    T = tiles_of(sphere, &o, HV_BACKEND_AUTO, 3, &S, "auto, host asked for");
    ck_assert_int_ne(S.backend, HV_BACKEND_OPENCL);
    hv_tiles_destroy(&T);
    unsetenv("HEATVOX_AUTO_OPENCL");
    T = tiles_of(sphere, &o, HV_BACKEND_MG, 3, &S, "mg");
    ck_assert_int_ne(S.backend, HV_BACKEND_OPENCL);
    hv_tiles_destroy(&T);
    hv_mesh_destroy(&sphere);
}
END_TEST

/* The command with --backend opencl writes the host's .vdb, read back by
 * OpenVDB: the same active voxels and signs, values within 1e-4 voxel. */
START_TEST(command_should_write_the_same_vdb_from_the_device)
{
    if (!have_device())
        return;
    char dir[256], bin[512], err[4096];
    tl_scratch_scenes("sdf_tiles_cl", dir, sizeof dir, bin, sizeof bin);
    ck_assert_msg(tl_hv(dir, bin, err, sizeof err,
                        "sdf sc/meshes/torus_holes.obj --res 72 -o h.vdb --backend mg") == 0,
                  "host run: %s", err);
    ck_assert_msg(tl_hv(dir, bin, err, sizeof err,
                        "sdf sc/meshes/torus_holes.obj --res 72 -o d.vdb --backend opencl -v") == 0,
                  "device run: %s", err);
    ck_assert_msg(strstr(err, "on the device"), "the device run does not say so: %s", err);
    char ph[512], pd[512];
    snprintf(ph, sizeof ph, "%s/h.vdb", dir);
    snprintf(pd, sizeof pd, "%s/d.vdb", dir);
    hv_grid *a = NULL, *b = NULL;
    TL_ASSERT_OK(hv_vdb_read_float(ph, "sdf", NULL, &a, NULL));
    TL_ASSERT_OK(hv_vdb_read_float(pd, "sdf", NULL, &b, NULL));
    ck_assert_int_eq(hv_grid_count(a), hv_grid_count(b));
    size_t signs = 0, far = 0, band = 0;
    for (size_t q = 0; q < hv_grid_count(a); q++) {
        signs += (a->v[q] < 0) != (b->v[q] < 0);
        far += !(fabsf(a->v[q] - b->v[q]) <= (float)(1e-4 * a->h));
        band += fabsf(a->v[q]) < (float)(3 * a->h);
    }
    ck_assert_msg(signs == 0 && far == 0, "%zu voxels of other sign, %zu apart", signs, far);
    ck_assert_uint_gt(band, 1000);
    hv_grid_destroy(&a);
    hv_grid_destroy(&b);
    tl_rm_rf(dir);
}
END_TEST

int main(int argc, char **argv)
{
    (void)argc;
    /* Every queue counts its traffic (before the first OpenCL call). */
    setenv("HEATVOX_OPENCL_PROFILE", "1", 1);
    tl_pocl_cache(argv[0]);
    Suite *s = suite_create("sdf_tiles_cl");
    TCase *tc = tcase_create("core");
    tcase_set_timeout(tc, 600);
    tcase_add_test(tc, closed_and_defective_meshes_should_equal_the_host_tiles);
    tcase_add_test(tc, open_meshes_windows_and_batches_should_equal_the_host_tiles);
    tcase_add_test(tc, shared_meshes_should_equal_the_host_tiles);
    tcase_add_test(tc, device_runs_should_move_their_inputs_and_tiles_only);
    tcase_add_test(tc, auto_should_take_the_device_where_solves_do);
    tcase_add_test(tc, command_should_write_the_same_vdb_from_the_device);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
