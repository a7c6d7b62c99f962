/* Grids and finite-volume operators: the properties the solvers rely on. */
#include "testlib.h"

#include <math.h>
#include <string.h>
#include <sys/mman.h>

static hv_grid *make(int dim, int nx, int ny, int nz, int with_mask)
{
    hv_grid *g = NULL;
    int n[3] = {nx, ny, nz};
    TL_ASSERT_OK(hv_grid_create(&g, dim, n, 0.1, NULL));
    if (with_mask) {
        TL_ASSERT_OK(hv_grid_add_mask(g));
        /* A bulky block and a thin wall with a gap. */
        for (int k = 0; k < g->n[2]; k++)
            for (int j = 0; j < g->n[1]; j++)
                for (int i = 0; i < g->n[0]; i++) {
                    size_t c = i + (size_t)g->n[0] * (j + (size_t)g->n[1] * k);
                    if ((i > nx / 4 && i < nx / 2 && j > ny / 4 && j < ny / 2) ||
                        (i == 3 * nx / 4 && j > 2))
                        g->solid[c] = 1;
                }
    }
    return g;
}

static double dot_fluid(const hv_grid *g, const float *a, const float *b)
{
    double s = 0;
    for (size_t c = 0; c < hv_grid_count(g); c++)
        if (!g->solid || !g->solid[c])
            s += (double)a[c] * b[c];
    return s;
}

static void check_symmetry(int dim, int nx, int ny, int nz)
{
    hv_grid *u = make(dim, nx, ny, nz, 1), *v = make(dim, nx, ny, nz, 1);
    hv_grid *Lu = make(dim, nx, ny, nz, 1), *Lv = make(dim, nx, ny, nz, 1);
    size_t n = hv_grid_count(u);
    tl_fill_random(u->v, n, 1);
    tl_fill_random(v->v, n, 2);
    TL_ASSERT_OK(hv_laplacian(u, Lu));
    TL_ASSERT_OK(hv_laplacian(v, Lv));
    double a = dot_fluid(u, Lu->v, v->v), b = dot_fluid(u, u->v, Lv->v);
    ck_assert_msg(fabs(a - b) <= 1e-5 * (fabs(a) + fabs(b)), "<Lu,v>=%g <u,Lv>=%g", a, b);
    /* Negative semi-definite: <Lu,u> <= 0. */
    ck_assert(dot_fluid(u, Lu->v, u->v) <= 0);
    hv_grid_destroy(&u);
    hv_grid_destroy(&v);
    hv_grid_destroy(&Lu);
    hv_grid_destroy(&Lv);
}

START_TEST(masked_laplacian_should_be_symmetric)
{
    check_symmetry(2, 33, 20, 1);
    check_symmetry(3, 17, 12, 9);
}
END_TEST

START_TEST(constants_should_lie_in_the_laplacian_null_space)
{
    for (int dim = 2; dim <= 3; dim++) {
        hv_grid *u = make(dim, 19, 14, 11, 1), *Lu = make(dim, 19, 14, 11, 1);
        for (size_t c = 0; c < hv_grid_count(u); c++)
            u->v[c] = u->solid[c] ? 123.0f : 2.5f; /* solid values must not leak in */
        TL_ASSERT_OK(hv_laplacian(u, Lu));
        for (size_t c = 0; c < hv_grid_count(u); c++)
            ck_assert_msg(Lu->v[c] == 0.0f, "L(const) = %g at %zu", Lu->v[c], c);
        hv_grid_destroy(&u);
        hv_grid_destroy(&Lu);
    }
}
END_TEST

START_TEST(divergence_of_gradient_should_equal_laplacian)
{
    for (int dim = 2; dim <= 3; dim++)
        for (int masked = 0; masked <= 1; masked++) {
            hv_grid *u = make(dim, 23, 16, 13, masked), *L1 = make(dim, 23, 16, 13, masked),
                    *L2 = make(dim, 23, 16, 13, masked);
            tl_fill_random(u->v, hv_grid_count(u), 7);
            hv_faces *F = NULL;
            TL_ASSERT_OK(hv_faces_create(&F, u));
            TL_ASSERT_OK(hv_face_gradient(u, F));
            TL_ASSERT_OK(hv_face_divergence(F, L1));
            TL_ASSERT_OK(hv_laplacian(u, L2));
            double maxd = 0, maxv = 0;
            for (size_t c = 0; c < hv_grid_count(u); c++) {
                maxd = fmax(maxd, fabs(L1->v[c] - L2->v[c]));
                maxv = fmax(maxv, fabs(L2->v[c]));
            }
            ck_assert_msg(maxd <= 1e-5 * maxv, "dim %d mask %d: |div grad - lap| = %g of %g", dim,
                          masked, maxd, maxv);
            /* Compatibility: the divergence sums to zero over the domain. */
            double sum = 0;
            for (size_t c = 0; c < hv_grid_count(u); c++)
                sum += L1->v[c];
            ck_assert_msg(fabs(sum) <= 1e-4 * maxv, "sum of div = %g", sum);
            hv_faces_destroy(&F);
            ck_assert_ptr_null(F);
            hv_grid_destroy(&u);
            hv_grid_destroy(&L1);
            hv_grid_destroy(&L2);
        }
}
END_TEST

START_TEST(laplacian_should_converge_at_second_order)
{
    /* u = cos(pi x) cos(2 pi y) [cos(pi z)] satisfies the Neumann walls of the unit box. */
    for (int dim = 2; dim <= 3; dim++) {
        double err[3];
        for (int r = 0; r < 3; r++) {
            int n = 16 << r;
            int sz[3] = {n, n, n};
            hv_grid *u = NULL, *L = NULL;
            TL_ASSERT_OK(hv_grid_create(&u, dim, sz, 1.0 / n, NULL));
            TL_ASSERT_OK(hv_grid_create(&L, dim, sz, 1.0 / n, NULL));
            double lam = M_PI * M_PI * (1 + 4 + (dim == 3));
            for (int k = 0; k < u->n[2]; k++)
                for (int j = 0; j < n; j++)
                    for (int i = 0; i < n; i++) {
                        double x[3];
                        hv_grid_cell_center(u, i, j, k, x);
                        u->v[i + (size_t)n * (j + (size_t)n * k)] =
                            (float)(cos(M_PI * x[0]) * cos(2 * M_PI * x[1]) *
                                    (dim == 3 ? cos(M_PI * x[2]) : 1));
                    }
            TL_ASSERT_OK(hv_laplacian(u, L));
            double e = 0;
            for (size_t c = 0; c < hv_grid_count(u); c++)
                e = fmax(e, fabs(L->v[c] + lam * u->v[c]));
            err[r] = e / lam;
            hv_grid_destroy(&u);
            hv_grid_destroy(&L);
        }
        /* Second order: halving h quarters the error (first order would halve it). */
        ck_assert_msg(err[0] / err[1] > 3.5 && err[1] / err[2] > 3.5, "dim %d: errors %g %g %g",
                      dim, err[0], err[1], err[2]);
    }
}
END_TEST

START_TEST(grid_create_should_reject_bad_sizes)
{
    hv_grid *g = (hv_grid *)0x1;
    int zero[3] = {0, 4, 4}, neg[3] = {4, -1, 4}, huge[3] = {100000, 100000, 100000};
    ck_assert_int_eq(hv_grid_create(&g, 3, zero, 1.0, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_null(g);
    ck_assert(strstr(hv_last_error(), "positive") != NULL);
    ck_assert_int_eq(hv_grid_create(&g, 3, neg, 1.0, NULL), HV_ERR_INVALID_ARG);
    int ok[3] = {4, 4, 4};
    ck_assert_int_eq(hv_grid_create(&g, 3, ok, 0.0, NULL), HV_ERR_INVALID_ARG);
    ck_assert_int_eq(hv_grid_create(&g, 3, ok, NAN, NULL), HV_ERR_INVALID_ARG);
    ck_assert_int_eq(hv_grid_create(&g, 4, ok, 1.0, NULL), HV_ERR_INVALID_ARG);
    ck_assert_int_eq(hv_grid_create(&g, 3, huge, 1.0, NULL), HV_ERR_NOMEM);
    ck_assert_msg(strstr(hv_last_error(), "GB") != NULL, "message: %s", hv_last_error());
    /* A 2D grid ignores n[2] and is not a stack of layers. */
    int two[3] = {5, 7, -3};
    TL_ASSERT_OK(hv_grid_create(&g, 2, two, 1.0, NULL));
    ck_assert_int_eq(g->n[2], 1);
    ck_assert_uint_eq(hv_grid_count(g), 35);
    ck_assert_uint_eq((uintptr_t)g->v % 64, 0);
    hv_grid_destroy(&g);
    ck_assert_ptr_null(g);
    hv_grid_destroy(&g); /* NULL is fine */
}
END_TEST

START_TEST(check_finite_should_name_the_bad_cell)
{
    float v[5] = {0, 1, NAN, 3, INFINITY};
    ck_assert_int_eq(hv_check_finite(v, 5, "test field"), HV_ERR_NUMERIC);
    ck_assert(strstr(hv_last_error(), "test field") && strstr(hv_last_error(), "cell 2"));
    ck_assert_int_eq(hv_check_finite(v, 2, "x"), HV_OK);
}
END_TEST

/* The peak memory sees a buffer once touched, and a reset forgets it once
 * it is gone (mmap: no allocator keeps it). */
START_TEST(peak_rss_should_see_a_buffer_and_forget_it_after_a_reset)
{
    const size_t bytes = (size_t)128 << 20;
    const size_t before = hv_peak_rss();
    ck_assert_uint_gt(before, 0);
    char *b = mmap(NULL, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    ck_assert_ptr_ne(b, MAP_FAILED);
    memset(b, 1, bytes);
    const size_t high = hv_peak_rss();
    ck_assert_msg(high >= before + bytes * 3 / 4 || high >= bytes, "peak %zu MB, before %zu MB",
                  high >> 20, before >> 20);
    munmap(b, bytes);
    /* (Linux counts resident pages per thread and folds them in lazily: the
     * mark may read a few pages apart from one call to the next.) */
    ck_assert_uint_ge(hv_peak_rss(), high - bytes / 16);
    TL_ASSERT_OK(hv_peak_rss_reset());
    ck_assert_msg(hv_peak_rss() + bytes / 2 < high, "after the reset %zu MB, peak was %zu MB",
                  hv_peak_rss() >> 20, high >> 20);
}
END_TEST

int main(void)
{
    Suite *s = suite_create("ops");
    TCase *tc = tcase_create("operators");
    tcase_set_timeout(tc, 60);
    tcase_add_test(tc, masked_laplacian_should_be_symmetric);
    tcase_add_test(tc, constants_should_lie_in_the_laplacian_null_space);
    tcase_add_test(tc, divergence_of_gradient_should_equal_laplacian);
    tcase_add_test(tc, laplacian_should_converge_at_second_order);
    tcase_add_test(tc, grid_create_should_reject_bad_sizes);
    tcase_add_test(tc, check_finite_should_name_the_bad_cell);
    tcase_add_test(tc, peak_rss_should_see_a_buffer_and_forget_it_after_a_reset);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
