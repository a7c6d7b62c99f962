/*
 * The same signed distance from every solver backend: the mg and opencl
 * backends must agree to 1e-4 voxel, and both with the
 * FFTW solve of the same plain box. The heat method's own magnitude is compared
 * (HV_SDF_HEAT), where the solves decide every value, as well as the default
 * exact magnitude, where they decide the sign.
 */
#include "heatvox/heatvox.h"
#include "testlib.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

static hv_grid *run(hv_backend b, hv_sdf_magnitude mag, const hv_mesh *m)
{
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = 40;
    o.use_bbox = 1;
    double box[6] = {-1, -1, -1, 1, 1, 1};
    for (int i = 0; i < 6; i++)
        o.bbox[i] = box[i];
    o.backend = b;
    o.magnitude = mag;
    hv_grid *g = NULL;
    hv_sdf_stats st;
    TL_ASSERT_OK(hv_sdf_compute(m, &o, &g, &st));
    ck_assert_int_eq(st.backend, b);
    return g;
}

static double max_diff_voxels(const hv_grid *a, const hv_grid *b)
{
    double d = 0;
    for (size_t c = 0; c < hv_grid_count(a); c++)
        d = fmax(d, fabs((double)a->v[c] - b->v[c]));
    return d / a->h;
}

START_TEST(mg_and_opencl_should_give_the_same_sdf)
{
    hv_opencl_device dev;
    if (hv_opencl_probe(&dev) != HV_OK) {
        TL_SKIP("no OpenCL device (%s)", hv_last_error());
    }
    const double c[3] = {0.02, -0.03, 0.01};
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_make_torus(&m, c, 0.55, 0.2, 96, 48));
    TL_ASSERT_OK(hv_mesh_defect_flip(m, 0.3, 7)); /* broken: 30% flipped faces */
    for (int mag = HV_SDF_EXACT; mag <= HV_SDF_HEAT; mag++) {
        hv_grid *g_mg = run(HV_BACKEND_MG, (hv_sdf_magnitude)mag, m);
        hv_grid *g_cl = run(HV_BACKEND_OPENCL, (hv_sdf_magnitude)mag, m);
        hv_grid *g_ff = run(HV_BACKEND_FFTW, (hv_sdf_magnitude)mag, m);
        double d_cl = max_diff_voxels(g_mg, g_cl), d_ff = max_diff_voxels(g_mg, g_ff);
        printf("check_sdf_backends: magnitude %s: max |mg - opencl| %.2e voxel, |mg - fftw| %.2e "
               "voxel\n",
               mag == HV_SDF_EXACT ? "exact" : "heat", d_cl, d_ff);
        ck_assert_msg(d_cl <= 1e-4, "mg vs opencl: %g voxel", d_cl);
        ck_assert_msg(d_ff <= 1e-3, "mg vs fftw: %g voxel", d_ff);
        hv_grid_destroy(&g_mg);
        hv_grid_destroy(&g_cl);
        hv_grid_destroy(&g_ff);
    }
    hv_mesh_destroy(&m);
}
END_TEST

/* band_only (what heatvox sdf computes for a narrow-band .vdb) must give the
 * whole-grid values inside the band and the same sign everywhere. */
START_TEST(narrow_band_should_match_the_whole_grid_in_the_band)
{
    const double c[3] = {0.02, -0.03, 0.01};
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_make_torus(&m, c, 0.55, 0.2, 96, 48));
    TL_ASSERT_OK(hv_mesh_defect_holes(m, 4, 0.03, 3));
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = 48;
    hv_grid *full = NULL, *band = NULL;
    hv_sdf_stats sf, sb;
    TL_ASSERT_OK(hv_sdf_compute(m, &o, &full, &sf));
    o.band_only = 3;
    TL_ASSERT_OK(hv_sdf_compute(m, &o, &band, &sb));
    double h = full->h, worst = 0;
    size_t sign_diff = 0;
    for (size_t q = 0; q < hv_grid_count(full); q++) {
        if ((full->v[q] < 0) != (band->v[q] < 0))
            sign_diff++;
        if (fabs(full->v[q]) < 3 * h)
            worst = fmax(worst, fabs((double)full->v[q] - band->v[q]) / h);
        else
            ck_assert(fabs(band->v[q]) >= 3 * h);
    }
    printf("check_sdf_backends: band_only 3: max diff in the band %.2e voxel, redistance %.3f s vs "
           "%.3f s\n",
           worst, sb.t_redistance, sf.t_redistance);
    ck_assert_uint_eq(sign_diff, 0);
    ck_assert_msg(worst <= 0.01, "band differs by %g voxel", worst);
    hv_grid_destroy(&full);
    hv_grid_destroy(&band);
    hv_mesh_destroy(&m);
}
END_TEST

int main(void)
{
    Suite *s = suite_create("sdf_backends");
    TCase *tc = tcase_create("backends");
    tcase_set_timeout(tc, 300);
    tcase_add_test(tc, mg_and_opencl_should_give_the_same_sdf);
    tcase_add_test(tc, narrow_band_should_match_the_whole_grid_in_the_band);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
