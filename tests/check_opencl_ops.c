/*
 * Device steps of the heat pipelines against their CPU twins: the trilinear
 * splat (gather on the device, atomics on the CPU), the signed heat method's
 * right-hand side -div X (levels, noise bounds, the unsigned gradient) and the
 * device-resident solve against the host interface of the same backend.
 * 2D and 3D, odd sizes, masks where the step has them. Without an OpenCL
 * platform the suite only notes it.
 */
#include "sdf/sdf_cl.h"
#include "sdf/sdf_internal.h"
#include "solve/cl/solve_cl.h"
#include "heatvox/heatvox.h"
#include "cl/cl_ops.h"
#include "testlib.h"

#include <check.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static hv_cl *CL;

/* max |a - b| / max |b| */
static double rel_diff(const float *a, const float *b, size_t n)
{
    double d = 0, m = 0;
    for (size_t i = 0; i < n; i++) {
        d = fmax(d, fabs((double)a[i] - b[i]));
        m = fmax(m, fabs((double)b[i]));
    }
    return m > 0 ? d / m : d;
}

static cl_mem dev_alloc(size_t n, const float *init)
{
    cl_mem m = NULL;
    TL_ASSERT_OK(hv__cl_alloc(CL, n * sizeof(float), init, &m));
    return m;
}

static void download(cl_mem m, float *v, size_t n)
{
    hv__cl_read(CL, m, 0, n * sizeof(float), v);
    TL_ASSERT_OK(hv__cl_check(CL));
}

/* ---------- splat ---------- */

/* The CPU splat of src/sdf/sdf.c: hv__trilinear weights, float sums. */
static void cpu_splat(const hv_grid *g, size_t npts, const double *x, const double *val,
                      size_t stride, double scale, float *out)
{
    for (size_t p = 0; p < npts; p++) {
        size_t c0, step[3];
        double wt[8];
        hv__trilinear(g, x + 3 * p, &c0, step, wt);
        for (int q = 0; q < 8; q++) {
            if (wt[q] == 0)
                continue;
            size_t c = c0 + (q & 1 ? step[0] : 0) + (q & 2 ? step[1] : 0) + (q & 4 ? step[2] : 0);
            out[c] += (float)(wt[q] * scale * val[p * stride]);
        }
    }
}

/* Samples spread over the block and a little beyond (clamped stencils), some
 * exactly on cell centres and walls (zero fractions), values of both signs. */
static void random_samples(const hv_grid *g, size_t npts, double *x, double *val, uint64_t seed)
{
    uint64_t s = seed;
    for (size_t p = 0; p < npts; p++) {
        for (int a = 0; a < 3; a++) {
            double L = g->n[a] * g->h, u = tl_rand(&s) + 0.5;
            x[3 * p + a] = g->origin[a] - 0.05 * L + 1.1 * L * u;
            if (p % 7 == 0) /* on a cell centre */
                x[3 * p + a] = g->origin[a] + (floor(u * g->n[a]) + 0.5) * g->h;
        }
        if (p % 11 == 0)
            x[3 * p] = g->origin[0]; /* on the wall */
        for (int b = 0; b < 3; b++)
            val[3 * p + b] = tl_rand(&s) * (b == 2 ? 1e3 : 1.0);
    }
}

static void check_splat(int dim, const int n[3], size_t npts)
{
    const double origin[3] = {-0.3, 0.2, 1.1}, h = 0.037;
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_grid_create(&g, dim, n, h, origin));
    const size_t count = hv_grid_count(g);
    double *x = malloc(3 * npts * sizeof *x), *val = malloc(3 * npts * sizeof *val);
    random_samples(g, npts, x, val, 7 + (uint64_t)dim);
    hv_cl_splat sp;
    TL_ASSERT_OK(hv__cl_splat_create(CL, &sp, dim, n, h, origin, npts, x));
    float *ref = calloc(count, sizeof *ref), *got = malloc(count * sizeof *got);
    cl_mem out = dev_alloc(count, NULL);
    const double scale = 1.0 / (h * h * h);
    for (int b = 0; b < 3; b++) {
        memset(ref, 0, count * sizeof *ref);
        cpu_splat(g, npts, x, val + b, 3, scale, ref);
        TL_ASSERT_OK(hv__cl_splat_run(CL, &sp, val + b, 3, scale, out));
        download(out, got, count);
        double d = rel_diff(got, ref, count);
        printf("splat %dD %dx%dx%d, %zu samples, component %d: max rel diff %.2e\n", dim, n[0],
               n[1], dim == 3 ? n[2] : 1, npts, b, d);
        ck_assert_msg(d < 1e-5, "component %d differs by %g", b, d);
    }
    /* val == NULL splats the scale: the total is npts * scale */
    TL_ASSERT_OK(hv__cl_splat_run(CL, &sp, NULL, 0, 2.0, out));
    download(out, got, count);
    double sum = 0;
    for (size_t c = 0; c < count; c++)
        sum += got[c];
    ck_assert_msg(fabs(sum - 2.0 * npts) < 1e-4 * npts, "unit splat sums to %g, not %g", sum,
                  2.0 * npts);
    hv__cl_free(&out);
    hv__cl_splat_destroy(&sp);
    free(x), free(val), free(ref), free(got);
    hv_grid_destroy(&g);
}

START_TEST(splat_should_match_the_cpu_splat_in_3d)
{
    check_splat(3, (const int[3]){23, 17, 11}, 20000);
    check_splat(3, (const int[3]){1, 9, 5}, 500); /* a one-cell axis */
}
END_TEST

START_TEST(splat_should_match_the_cpu_splat_in_2d)
{
    check_splat(2, (const int[3]){37, 29, 1}, 8000);
}
END_TEST

START_TEST(splat_of_a_mesh_quadrature_should_match_the_cpu)
{
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_make_torus(&m, (const double[3]){0.01, -0.02, 0.03}, 0.6, 0.25, 48, 24));
    const int n[3] = {41, 39, 19};
    const double h = 0.04, origin[3] = {-0.82, -0.8, -0.35};
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_grid_create(&g, 3, n, h, origin));
    double hi[3];
    for (int a = 0; a < 3; a++)
        hi[a] = origin[a] + n[a] * h;
    hv_quad q;
    TL_ASSERT_OK(hv__quad_build(m, h, origin, hi, &q));
    const size_t count = hv_grid_count(g);
    hv_cl_splat sp;
    TL_ASSERT_OK(hv__cl_splat_create(CL, &sp, 3, n, h, origin, q.count, q.x));
    float *ref = malloc(count * sizeof *ref), *got = malloc(count * sizeof *got);
    cl_mem out = dev_alloc(count, NULL);
    for (int b = 0; b < 4; b++) {
        memset(ref, 0, count * sizeof *ref);
        const double *v = b < 3 ? q.w + b : q.area;
        cpu_splat(g, q.count, q.x, v, b < 3 ? 3 : 1, 1.0 / (h * h * h), ref);
        TL_ASSERT_OK(hv__cl_splat_run(CL, &sp, v, b < 3 ? 3 : 1, 1.0 / (h * h * h), out));
        download(out, got, count);
        double d = rel_diff(got, ref, count);
        printf("splat of a torus's %zu samples, %s: max rel diff %.2e\n", q.count,
               b < 3 ? "normal component" : "area", d);
        ck_assert_msg(d < 1e-5, "field %d differs by %g", b, d);
    }
    hv__cl_free(&out);
    hv__cl_splat_destroy(&sp);
    hv__quad_free(&q);
    free(ref), free(got);
    hv_grid_destroy(&g);
    hv_mesh_destroy(&m);
}
END_TEST

/* interp() of src/sdf/sdf.c */
static double cpu_interp(const hv_grid *g, const float *v, const double x[3])
{
    size_t c0, step[3];
    double wt[8], val = 0;
    hv__trilinear(g, x, &c0, step, wt);
    for (int q = 0; q < 8; q++)
        val +=
            wt[q] * v[c0 + (q & 1 ? step[0] : 0) + (q & 2 ? step[1] : 0) + (q & 4 ? step[2] : 0)];
    return val;
}

static void check_sample(int dim, const int n[3], size_t npts)
{
    const double origin[3] = {0.1, -0.2, 0.3}, h = 0.05;
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_grid_create(&g, dim, n, h, origin));
    const size_t count = hv_grid_count(g);
    double *x = malloc(3 * npts * sizeof *x), *val = malloc(3 * npts * sizeof *val);
    random_samples(g, npts, x, val, 3);
    float *v = malloc(count * sizeof *v), *got = malloc(npts * sizeof *got);
    tl_fill_random(v, count, 17);
    hv_cl_splat sp;
    TL_ASSERT_OK(hv__cl_splat_create(CL, &sp, dim, n, h, origin, npts, x));
    cl_mem dv = dev_alloc(count, v), dout = dev_alloc(npts, NULL);
    hv__cl_splat_sample(CL, &sp, dv, dout);
    download(dout, got, npts);
    double d = 0;
    for (size_t k = 0; k < npts; k++)
        d = fmax(d, fabs(got[k] - cpu_interp(g, v, x + 3 * sp.order[k])));
    d /= 0.5; /* max |v| */
    printf("sample %dD %dx%dx%d at %zu points: max rel diff %.2e\n", dim, n[0], n[1],
           dim == 3 ? n[2] : 1, npts, d);
    ck_assert_msg(d < 1e-5, "interpolation differs by %g", d);
    hv__cl_free(&dv), hv__cl_free(&dout);
    hv__cl_splat_destroy(&sp);
    free(x), free(val), free(v), free(got);
    hv_grid_destroy(&g);
}

START_TEST(sample_should_match_cpu_interpolation)
{
    check_sample(3, (const int[3]){19, 14, 9}, 5000);
    check_sample(2, (const int[3]){33, 21, 1}, 3000);
}
END_TEST

START_TEST(shift_should_match_the_cpu_zero_set_correction)
{
    const size_t n = 5001;
    float *phi = malloc(n * sizeof *phi), *num = malloc(n * sizeof *num),
          *den = malloc(n * sizeof *den);
    float *ref = malloc(n * sizeof *ref), *got = malloc(n * sizeof *got);
    tl_fill_random(phi, n, 1);
    tl_fill_random(num, n, 2);
    const double tau = 1e-3;
    for (size_t c = 0; c < n; c++) /* den from 0 to 2000 tau: below, in and above the taper */
        den[c] = (float)(2.0 * tau * (double)c / (double)n * 1000.0);
    const float sh = 0.0625f;
    for (size_t c = 0; c < n; c++) { /* sdf.c: global shift, then local_shift */
        ref[c] = phi[c] - sh;
        double d = den[c];
        if (!(d > 100 * tau))
            continue;
        double taper = d >= 1000 * tau ? 1.0 : (d - 100 * tau) / (900 * tau);
        ref[c] -= (float)(taper * num[c] / d);
    }
    cl_mem dphi = dev_alloc(n, phi), dnum = dev_alloc(n, num), dden = dev_alloc(n, den);
    hv__cl_sdf_shift(CL, n, dphi, NULL, NULL, sh, 0.0, 0);
    hv__cl_sdf_shift(CL, n, dphi, dnum, dden, 0.0, tau, 1);
    download(dphi, got, n);
    double d = rel_diff(got, ref, n);
    printf("zero-set shift: max rel diff %.2e\n", d);
    ck_assert_msg(d < 1e-5, "shift differs by %g", d);
    hv__cl_free(&dphi), hv__cl_free(&dnum), hv__cl_free(&dden);
    free(phi), free(num), free(den), free(ref), free(got);
}
END_TEST

/* ---------- the signed heat method's right-hand side ---------- */

/* build_rhs of src/sdf/sdf.c, serial. */
static void cpu_face_vec(const float *Y, size_t count, int unsig, const int n[3], const size_t s[3],
                         double h, int a, size_t c, const int idx[3], double v[3])
{
    size_t lo = c - s[a];
    if (!unsig) {
        for (int b = 0; b < 3; b++)
            v[b] = 0.5 * ((double)Y[b * count + c] + Y[b * count + lo]);
        return;
    }
    v[a] = ((double)Y[c] - Y[lo]) / h;
    for (int b = 0; b < 3; b++) {
        if (b == a)
            continue;
        double g = 0;
        for (int side = 0; side < 2; side++) {
            size_t cc = side ? c : lo;
            size_t up = idx[b] < n[b] - 1 ? cc + s[b] : cc, dn = idx[b] > 0 ? cc - s[b] : cc;
            g += ((double)Y[up] - Y[dn]) / (2 * h);
        }
        v[b] = 0.5 * g;
    }
}

static double cpu_flux(const float *Y, size_t count, int nlev, const double *tau, int unsig,
                       const int n[3], const size_t s[3], double h, int a, size_t c,
                       const int idx[3], int *dead)
{
    const int ncomp = unsig ? 1 : 3;
    for (int k = 0; k < nlev; k++) {
        double v[3];
        cpu_face_vec(Y + (size_t)k * ncomp * count, count, unsig, n, s, h, a, c, idx, v);
        double len = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
        if (len > tau[k]) {
            *dead = 0;
            return unsig ? -v[a] / len : v[a] / len;
        }
    }
    *dead = 1;
    return 0;
}

static size_t cpu_rhs(const float *Y, size_t count, int nlev, const double *tau, int unsig,
                      const int n[3], double h, float *rhs)
{
    const size_t s[3] = {1, (size_t)n[0], (size_t)n[0] * n[1]};
    size_t dead_total = 0;
    for (int k = 0; k < n[2]; k++)
        for (int j = 0; j < n[1]; j++)
            for (int i = 0; i < n[0]; i++) {
                int idx[3] = {i, j, k}, dead;
                size_t c = (size_t)i + s[1] * j + s[2] * k;
                double div = 0;
                for (int a = 0; a < 3; a++) {
                    if (idx[a] > 0) {
                        div -= cpu_flux(Y, count, nlev, tau, unsig, n, s, h, a, c, idx, &dead);
                        dead_total += dead;
                    }
                    if (idx[a] < n[a] - 1) {
                        int up[3] = {i, j, k};
                        up[a]++;
                        div +=
                            cpu_flux(Y, count, nlev, tau, unsig, n, s, h, a, c + s[a], up, &dead);
                    }
                }
                rhs[c] = (float)(-div / h);
            }
    return dead_total;
}

/* Fields like diffused normals: a smooth radial field decaying away from a
 * point, times e^{-r/w} per level, so that the outer faces are dead on the
 * first level and served by the second. */
static void heat_like_fields(const int n[3], int nlev, int ncomp, float *Y)
{
    const size_t count = (size_t)n[0] * n[1] * n[2];
    for (int l = 0; l < nlev; l++)
        for (int k = 0; k < n[2]; k++)
            for (int j = 0; j < n[1]; j++)
                for (int i = 0; i < n[0]; i++) {
                    size_t c = (size_t)i + (size_t)n[0] * ((size_t)j + (size_t)n[1] * k);
                    double p[3] = {i - 0.4 * n[0], j - 0.55 * n[1], k - 0.5 * n[2]};
                    double r = sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]) + 0.3;
                    double e = exp(-r / (l ? 12.0 : 1.5)) * (1 + 0.1 * sin(i + 2.0 * j));
                    for (int b = 0; b < ncomp; b++)
                        Y[((size_t)l * ncomp + b) * count + c] =
                            (float)(ncomp == 1 ? e : e * p[b] / r);
                }
}

static size_t check_rhs(int unsig, int nlev)
{
    const int n[3] = {25, 19, 13}, ncomp = unsig ? 1 : 3;
    const double h = 0.05;
    const size_t count = (size_t)n[0] * n[1] * n[2];
    float *Y = malloc((size_t)nlev * ncomp * count * sizeof *Y);
    heat_like_fields(n, nlev, ncomp, Y);
    double tau[2] = {unsig ? 1e-3 : 1e-4, unsig ? 0.5 : 0.3};
    float *ref = malloc(count * sizeof *ref), *got = malloc(count * sizeof *got);
    size_t dead_ref = cpu_rhs(Y, count, nlev, tau, unsig, n, h, ref);
    cl_mem dY = dev_alloc((size_t)nlev * ncomp * count, Y), drhs = dev_alloc(count, NULL), dtau,
           ddead;
    float tauf[2] = {(float)tau[0], (float)tau[1]};
    const uint32_t zero = 0;
    TL_ASSERT_OK(hv__cl_alloc(CL, 2 * CL->acc, CL->fp64 ? (void *)tau : (void *)tauf, &dtau));
    TL_ASSERT_OK(hv__cl_alloc(CL, sizeof zero, &zero, &ddead));
    hv__cl_sdf_rhs(CL, n, h, dY, nlev, ncomp, dtau, drhs, ddead);
    download(drhs, got, count);
    uint32_t dead = 0;
    hv__cl_read(CL, ddead, 0, sizeof dead, &dead);
    TL_ASSERT_OK(hv__cl_check(CL));
    double d = rel_diff(got, ref, count);
    size_t faces = (size_t)(n[0] - 1) * n[1] * n[2] + (size_t)n[0] * (n[1] - 1) * n[2] +
                   (size_t)n[0] * n[1] * (n[2] - 1);
    printf("sdf rhs %s, %d level(s): max rel diff %.2e, dead faces %u (cpu %zu) of %zu\n",
           unsig ? "unsigned" : "signed", nlev, d, dead, dead_ref, faces);
    ck_assert_msg(d < 1e-5, "rhs differs by %g", d);
    ck_assert_msg(dead_ref > 0 && dead_ref < faces,
                  "the fields should leave some faces dead, not %zu of %zu", dead_ref, faces);
    /* a face right at a bound may tip either way in float */
    ck_assert_msg(fabs((double)dead - (double)dead_ref) <= 2, "dead faces %u, cpu %zu", dead,
                  dead_ref);
    hv__cl_free(&dY), hv__cl_free(&drhs), hv__cl_free(&dtau), hv__cl_free(&ddead);
    free(Y), free(ref), free(got);
    return dead_ref;
}

START_TEST(sdf_rhs_should_match_the_cpu_with_levels_and_dead_faces)
{
    size_t one = check_rhs(0, 1), two = check_rhs(0, 2);
    ck_assert_msg(two < one, "a second level should serve faces dead on the first (%zu, %zu)", one,
                  two);
}
END_TEST

START_TEST(sdf_rhs_should_match_the_cpu_for_the_unsigned_gradient)
{
    size_t one = check_rhs(1, 1), two = check_rhs(1, 2);
    ck_assert_msg(two < one, "a second level should serve faces dead on the first (%zu, %zu)", one,
                  two);
}
END_TEST

/* ---------- device-resident solve ---------- */

typedef struct scfg {
    int dim, n[3];
    double alpha;
    int mask, guess;
} scfg;

static void check_device_solve(const scfg *c)
{
    const int nz = c->dim == 3 ? c->n[2] : 1;
    const size_t count = (size_t)c->n[0] * c->n[1] * nz;
    uint8_t *solid = NULL;
    if (c->mask) {
        solid = calloc(count, 1);
        for (int k = 0; k < nz; k++)
            for (int j = 0; j < c->n[1]; j++)
                for (int i = 0; i < c->n[0]; i++) {
                    double x = (i + 0.5) / c->n[0] - 0.6, y = (j + 0.5) / c->n[1] - 0.5;
                    double z = c->dim == 3 ? (k + 0.5) / nz - 0.5 : 0;
                    solid[(size_t)i + (size_t)c->n[0] * ((size_t)j + (size_t)c->n[1] * k)] =
                        x * x + y * y + z * z < 0.05 || i == c->n[0] / 4;
                }
    }
    const double h = 1.0 / c->n[0];
    hv_problem p = {c->dim,   {c->n[0], c->n[1], c->n[2]},    h, solid,
                    c->alpha, c->alpha > 0 ? 16 * h * h : 1.0};
    hv_solver_opts so;
    hv_solver_opts_default(&so);
    so.backend = HV_BACKEND_OPENCL;
    so.tol = 1e-8;
    so.max_iter = 100;
    so.nonzero_guess = c->guess;
    hv_solver *sv = NULL;
    TL_ASSERT_OK(hv_solver_create(&sv, &p, &so));
    float *f = malloc(count * sizeof *f), *u0 = malloc(count * sizeof *u0);
    float *ref = malloc(count * sizeof *ref), *got = malloc(count * sizeof *got);
    tl_fill_random(f, count, 99);
    tl_fill_random(u0, count, 5);
    memcpy(ref, u0, count * sizeof *ref);
    hv_solve_info hi, di;
    TL_ASSERT_OK(hv_solver_solve(sv, f, ref, &hi));
    cl_mem df = dev_alloc(count, f), du = dev_alloc(count, u0);
    TL_ASSERT_OK(hv__cl_finish(CL));
    TL_ASSERT_OK(hv__cl_solver_solve(sv, df, du, &di));
    download(du, got, count);
    double d = rel_diff(got, ref, count);
    printf("device solve %dD %dx%dx%d alpha %g%s%s: max rel diff %.2e, %d/%d iterations, relres "
           "%.1e\n",
           c->dim, c->n[0], c->n[1], nz, c->alpha, c->mask ? " masked" : "",
           c->guess ? " guess" : "", d, di.iterations, hi.iterations, di.relres);
    ck_assert_msg(di.reason == HV_STOP_CONVERGED && di.relres <= 1e-8,
                  "device solve stopped: %s at %g", hv_stop_reason_str(di.reason), di.relres);
    ck_assert_int_eq(di.backend, HV_BACKEND_OPENCL);
    ck_assert_msg(d < 1e-5, "device and host solves differ by %g", d);
    for (size_t q = 0; solid && q < count; q++)
        ck_assert_msg(!solid[q] || got[q] == 0.0f, "solid cell %zu holds %g", q, got[q]);
    hv__cl_free(&df), hv__cl_free(&du);
    hv_solver_destroy(&sv);
    free(solid), free(f), free(u0), free(ref), free(got);
}

START_TEST(device_solve_should_match_the_host_interface)
{
    static const scfg C[] = {
        {3, {21, 18, 13}, 1.0, 0, 0}, {3, {21, 18, 13}, 0.0, 0, 0}, {3, {19, 24, 14}, 0.0, 1, 0},
        {3, {24, 20, 16}, 1.0, 1, 0}, {2, {67, 53, 1}, 0.0, 0, 0},  {2, {61, 47, 1}, 1.0, 0, 1},
    };
    for (size_t i = 0; i < sizeof C / sizeof C[0]; i++)
        check_device_solve(&C[i]);
}
END_TEST

START_TEST(device_solve_should_refuse_other_backends_and_zero_rhs_gives_zero)
{
    hv_problem p = {3, {8, 8, 8}, 0.1, NULL, 1.0, 0.01};
    hv_solver_opts so;
    hv_solver_opts_default(&so);
    so.backend = HV_BACKEND_MG;
    hv_solver *sv = NULL;
    TL_ASSERT_OK(hv_solver_create(&sv, &p, &so));
    cl_mem f = dev_alloc(512, NULL), u = dev_alloc(512, NULL);
    hv__cl_zero(CL, f, 512 * sizeof(float));
    TL_ASSERT_OK(hv__cl_finish(CL));
    ck_assert_int_eq(hv__cl_solver_solve(sv, f, u, NULL), HV_ERR_UNSUPPORTED);
    hv_solver_destroy(&sv);
    so.backend = HV_BACKEND_OPENCL;
    TL_ASSERT_OK(hv_solver_create(&sv, &p, &so));
    float *v = malloc(512 * sizeof *v);
    for (int i = 0; i < 512; i++)
        v[i] = 1.0f;
    hv__cl_write(CL, u, 0, 512 * sizeof(float), v);
    TL_ASSERT_OK(hv__cl_finish(CL));
    hv_solve_info info;
    TL_ASSERT_OK(hv__cl_solver_solve(sv, f, u, &info));
    download(u, v, 512);
    for (int i = 0; i < 512; i++)
        ck_assert_msg(v[i] == 0.0f, "cell %d holds %g", i, v[i]);
    ck_assert_int_eq(info.reason, HV_STOP_CONVERGED);
    hv_solver_destroy(&sv);
    hv__cl_free(&f), hv__cl_free(&u);
    free(v);
}
END_TEST

/* The exclusive prefix sums on the device equal the host's, across one,
 * two and three levels of block totals. */
START_TEST(scan_should_give_the_host_prefix_sums)
{
    const size_t sizes[] = {1, 5, 1023, 1024, 1025, 70000, (1u << 20) + 3, (1u << 21) + 17};
    for (size_t z = 0; z < sizeof sizes / sizeof sizes[0]; z++) {
        const size_t n = sizes[z];
        uint32_t *in = malloc(n * sizeof *in), *out = malloc(n * sizeof *out);
        uint64_t seed = 7 + n;
        for (size_t i = 0; i < n; i++)
            in[i] = (uint32_t)((tl_rand(&seed) + 0.5) * 7);
        cl_mem a = NULL, b = NULL;
        TL_ASSERT_OK(hv__cl_alloc(CL, n * sizeof *in, in, &a));
        TL_ASSERT_OK(hv__cl_alloc(CL, n * sizeof *in, NULL, &b));
        TL_ASSERT_OK(hv__cl_scan_u32(CL, a, b, n));
        hv__cl_read(CL, b, 0, n * sizeof *out, out);
        TL_ASSERT_OK(hv__cl_check(CL));
        uint32_t run = 0;
        size_t bad = 0;
        for (size_t i = 0; i < n; i++) {
            bad += out[i] != run;
            run += in[i];
        }
        ck_assert_msg(bad == 0, "%zu of %zu prefix sums differ", bad, n);
        hv__cl_free(&a);
        hv__cl_free(&b);
        free(in);
        free(out);
    }
}
END_TEST

int main(int argc, char **argv)
{
    (void)argc;
    tl_pocl_cache(argv[0]);
    hv_set_threads(1);
    Suite *su = suite_create("opencl_ops");
    TCase *tc = tcase_create("opencl_ops");
    tcase_set_timeout(tc, 600);
    int have_cl = hv_opencl_probe(NULL) == HV_OK;
    char why[512];
    snprintf(why, sizeof why, "no usable OpenCL device (%s)", hv_last_error());
    if (have_cl) {
        if (hv__cl_open(&CL)) {
            fprintf(stderr, "check_opencl_ops: cannot open the OpenCL device: %s\n",
                    hv_last_error());
            return 1;
        }
        printf("OpenCL device: %s (%s), fp64 %s\n", CL->info.name, CL->info.platform_name,
               CL->fp64 ? "yes" : "no");
    }
    TL_ADD_IF(tc, splat_should_match_the_cpu_splat_in_3d, have_cl, why);
    TL_ADD_IF(tc, splat_should_match_the_cpu_splat_in_2d, have_cl, why);
    TL_ADD_IF(tc, splat_of_a_mesh_quadrature_should_match_the_cpu, have_cl, why);
    TL_ADD_IF(tc, sample_should_match_cpu_interpolation, have_cl, why);
    TL_ADD_IF(tc, shift_should_match_the_cpu_zero_set_correction, have_cl, why);
    TL_ADD_IF(tc, sdf_rhs_should_match_the_cpu_with_levels_and_dead_faces, have_cl, why);
    TL_ADD_IF(tc, sdf_rhs_should_match_the_cpu_for_the_unsigned_gradient, have_cl, why);
    TL_ADD_IF(tc, device_solve_should_match_the_host_interface, have_cl, why);
    TL_ADD_IF(tc, device_solve_should_refuse_other_backends_and_zero_rhs_gives_zero, have_cl, why);
    TL_ADD_IF(tc, scan_should_give_the_host_prefix_sums, have_cl, why);
    suite_add_tcase(su, tc);
    int rc = tl_run(su);
    if (CL)
        hv__cl_close(&CL);
    return rc;
}
