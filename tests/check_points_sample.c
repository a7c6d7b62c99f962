/* The point sampler of the point-cloud benchmark (tools/bench/points_sample.c)
 * on a unit sphere, where every property has a closed form: points on the
 * surface with outward unit normals, reproducible for a seed, and each
 * defect as asked. */
#include "../tools/bench/points_sample.h"
#include "testlib.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* The icosphere at subdivision 4 stays within 0.002 of the unit sphere. */
#define FACETING 0.002

static hv_mesh *sphere(void)
{
    hv_mesh *m = NULL;
    const double c[3] = {0, 0, 0};
    TL_ASSERT_OK(hv_mesh_make_sphere(&m, c, 1.0, 4));
    return m;
}

static void sample(const hv_mesh *m, const points_sample_opts *o, points_set *P)
{
    char err[256] = "";
    ck_assert_msg(points_sample(m, o, P, err, sizeof err) == 0, "points_sample: %s", err);
    ck_assert_uint_eq(P->count, o->count);
}

static double norm(const double *v) { return sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }
static double dot(const double *a, const double *b)
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

START_TEST(points_should_lie_on_the_surface_with_outward_unit_normals)
{
    hv_mesh *m = sphere();
    points_sample_opts o;
    points_sample_opts_default(&o);
    o.count = 20000;
    points_set P;
    sample(m, &o, &P);
    double mean[3] = {0, 0, 0};
    for (size_t i = 0; i < P.count; i++) {
        const double *p = P.xyz + 3 * i, *n = P.normal + 3 * i;
        ck_assert_double_le(fabs(norm(p) - 1), FACETING);
        ck_assert_double_le(fabs(norm(n) - 1), 1e-12);
        ck_assert_double_gt(dot(n, p), 0.99);
        for (int a = 0; a < 3; a++)
            mean[a] += p[a] / (double)P.count;
    }
    /* Area-uniform: the mean of 20000 points lies within a few 1/sqrt(3 n). */
    ck_assert_double_lt(norm(mean), 0.02);
    points_set_free(&P);
    /* Turned inside out, the mesh still gives outward normals. */
    TL_ASSERT_OK(hv_mesh_defect_flip(m, 1.0, 1));
    sample(m, &o, &P);
    for (size_t i = 0; i < P.count; i++)
        ck_assert_double_gt(dot(P.normal + 3 * i, P.xyz + 3 * i), 0.99);
    points_set_free(&P);
    hv_mesh_destroy(&m);
}
END_TEST

START_TEST(the_same_seed_should_give_the_same_points)
{
    hv_mesh *m = sphere();
    points_sample_opts o;
    points_sample_opts_default(&o);
    o.count = 1000;
    o.noise = 0.01;
    o.flip_fraction = 0.1;
    points_set A, B, C;
    sample(m, &o, &A);
    sample(m, &o, &B);
    o.seed = 2;
    sample(m, &o, &C);
    ck_assert(!memcmp(A.xyz, B.xyz, 3 * A.count * sizeof *A.xyz));
    ck_assert(!memcmp(A.normal, B.normal, 3 * A.count * sizeof *A.normal));
    ck_assert(memcmp(A.xyz, C.xyz, 3 * A.count * sizeof *A.xyz));
    points_set_free(&A);
    points_set_free(&B);
    points_set_free(&C);
    hv_mesh_destroy(&m);
}
END_TEST

START_TEST(density_should_fall_along_x_as_asked)
{
    hv_mesh *m = sphere();
    points_sample_opts o;
    points_sample_opts_default(&o);
    o.count = 40000;
    o.density_ratio = 10;
    points_set P;
    sample(m, &o, &P);
    size_t low = 0, high = 0; /* the caps x < -0.8 and x > 0.8, of equal area */
    for (size_t i = 0; i < P.count; i++) {
        low += P.xyz[3 * i] < -0.8;
        high += P.xyz[3 * i] > 0.8;
    }
    /* Kept with 1 - 0.9 (x + 1) / 2, uniform in x over each cap: a mean of
     * 0.955 on the low cap and 0.145 on the high one, a ratio of 6.6. */
    const double ratio = (double)low / (double)high;
    ck_assert_msg(ratio > 5.8 && ratio < 7.5, "low cap %zu, high cap %zu points", low, high);
    points_set_free(&P);
    hv_mesh_destroy(&m);
}
END_TEST

/* The standard deviation of the distance to the sphere. */
static double radial_sigma(const points_set *P)
{
    double s = 0;
    for (size_t i = 0; i < P->count; i++)
        s += (norm(P->xyz + 3 * i) - 1) * (norm(P->xyz + 3 * i) - 1);
    return sqrt(s / (double)P->count);
}

START_TEST(noise_should_have_the_sigma_asked)
{
    hv_mesh *m = sphere();
    points_sample_opts o;
    points_sample_opts_default(&o);
    o.count = 20000;
    o.noise = 0.02;
    points_set P;
    sample(m, &o, &P);
    ck_assert_double_lt(fabs(radial_sigma(&P) / 0.02 - 1), 0.05);
    for (size_t i = 0; i < P.count; i++) /* along the normal: still radial */
        ck_assert_double_gt(dot(P.normal + 3 * i, P.xyz + 3 * i) / norm(P.xyz + 3 * i), 0.99);
    points_set_free(&P);
    o.noise_isotropic = 1; /* the radial part of isotropic noise has the same sigma */
    sample(m, &o, &P);
    ck_assert_double_lt(fabs(radial_sigma(&P) / 0.02 - 1), 0.05);
    points_set_free(&P);
    hv_mesh_destroy(&m);
}
END_TEST

START_TEST(flips_and_the_hole_should_be_exact)
{
    hv_mesh *m = sphere();
    points_sample_opts o;
    points_sample_opts_default(&o);
    o.count = 10001;
    o.flip_fraction = 0.1;
    o.hole_radius = 0.5;
    ck_assert_int_eq(points_surface_point(m, 7, o.hole_center), 0);
    ck_assert_double_le(fabs(norm(o.hole_center) - 1), FACETING);
    points_set P;
    sample(m, &o, &P);
    size_t flipped = 0;
    double nearest = INFINITY;
    for (size_t i = 0; i < P.count; i++) {
        const double *p = P.xyz + 3 * i;
        flipped += dot(P.normal + 3 * i, p) < 0;
        const double d[3] = {p[0] - o.hole_center[0], p[1] - o.hole_center[1],
                             p[2] - o.hole_center[2]};
        nearest = fmin(nearest, norm(d));
    }
    ck_assert_uint_eq(flipped, 1000);
    ck_assert_double_ge(nearest, 0.5);
    ck_assert_double_lt(nearest, 0.55);
    points_set_free(&P);
    hv_mesh_destroy(&m);
}
END_TEST

START_TEST(xyz_file_should_read_back_the_points)
{
    hv_mesh *m = sphere();
    points_sample_opts o;
    points_sample_opts_default(&o);
    o.count = 500;
    points_set P;
    sample(m, &o, &P);
    char dir[] = "/tmp/hv_points_XXXXXX", path[256], err[256] = "";
    ck_assert_ptr_nonnull(mkdtemp(dir));
    snprintf(path, sizeof path, "%s/p.xyz", dir);
    ck_assert_msg(points_write_xyz(&P, path, err, sizeof err) == 0, "%s", err);
    FILE *f = fopen(path, "r");
    ck_assert_ptr_nonnull(f);
    char line[512];
    size_t n = 0;
    while (fgets(line, sizeof line, f)) {
        if (line[0] == '#')
            continue;
        double v[6];
        ck_assert_int_eq(
            sscanf(line, "%lf %lf %lf %lf %lf %lf", v, v + 1, v + 2, v + 3, v + 4, v + 5), 6);
        ck_assert_uint_lt(n, P.count);
        for (int a = 0; a < 3; a++) {
            ck_assert_double_le(fabs(v[a] - P.xyz[3 * n + a]), 1e-8);
            ck_assert_double_le(fabs(v[3 + a] - P.normal[3 * n + a]), 1e-6);
        }
        n++;
    }
    fclose(f);
    ck_assert_uint_eq(n, P.count);
    /* A directory that does not exist: the error names the file. */
    snprintf(path, sizeof path, "%s/no/p.xyz", dir);
    ck_assert_int_eq(points_write_xyz(&P, path, err, sizeof err), -1);
    ck_assert_ptr_nonnull(strstr(err, "no/p.xyz"));
    tl_rm_rf(dir);
    points_set_free(&P);
    hv_mesh_destroy(&m);
}
END_TEST

int main(void)
{
    Suite *s = suite_create("points_sample");
    TCase *tc = tcase_create("sampler");
    tcase_set_timeout(tc, 60);
    tcase_add_test(tc, points_should_lie_on_the_surface_with_outward_unit_normals);
    tcase_add_test(tc, the_same_seed_should_give_the_same_points);
    tcase_add_test(tc, density_should_fall_along_x_as_asked);
    tcase_add_test(tc, noise_should_have_the_sigma_asked);
    tcase_add_test(tc, flips_and_the_hole_should_be_exact);
    tcase_add_test(tc, xyz_file_should_read_back_the_points);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
