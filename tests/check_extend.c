/* Extension off a level set against the exact closest-point extension on
 * analytic shapes (sphere, torus, circle): scalar and vector fields, constant
 * fields, output bands, repeated calls on one extender. */
#include "testlib.h"
#include "heatvox/heat.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

typedef enum { SPHERE, TORUS, CIRCLE } shape_kind;

static const double C0[3] = {0.05, -0.03, 0.02};

/* Signed distance and closest point of the shape. Returns 0 where the closest
 * point is not unique (centre, axis, core circle). */
static int closest(shape_kind s, const double x[3], double *phi, double cp[3])
{
    double q[3] = {x[0] - C0[0], x[1] - C0[1], x[2] - C0[2]};
    if (s == CIRCLE)
        q[2] = 0;
    if (s == SPHERE || s == CIRCLE) {
        const double R = 0.5;
        double r = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
        *phi = r - R;
        if (r < 1e-12)
            return 0;
        for (int a = 0; a < 3; a++)
            cp[a] = C0[a] + R * q[a] / r;
        if (s == CIRCLE)
            cp[2] = x[2];
        return 1;
    }
    const double R = 0.5, rt = 0.2;
    double rho = hypot(q[0], q[1]);
    if (rho < 1e-12) {
        *phi = hypot(R, q[2]) - rt;
        return 0;
    }
    double m[3] = {R * q[0] / rho, R * q[1] / rho, 0};
    double d[3] = {q[0] - m[0], q[1] - m[1], q[2]},
           dn = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    *phi = dn - rt;
    if (dn < 1e-12)
        return 0;
    for (int a = 0; a < 3; a++)
        cp[a] = C0[a] + m[a] + rt * d[a] / dn;
    return 1;
}

static double g_scalar(const double p[3]) { return 2 + sin(3 * p[0]) * cos(2 * p[1]) + 0.5 * p[2]; }

static void g_vector(const double p[3], double v[3])
{
    v[0] = -p[1] + 0.3;
    v[1] = p[0] + 0.2;
    v[2] = 0.5 + 0.2 * p[2];
}

typedef struct {
    double near, all; /* mean relative error within 5 voxels / over every cell */
    hv_extend_stats st;
} ext_err;

/* Grid on [-1,1]^dim with n cells per axis. */
static hv_grid *make_grid(int dim, int n)
{
    int ns[3] = {n, n, dim == 3 ? n : 1};
    double org[3] = {-1, -1, dim == 3 ? -1 : 0};
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_grid_create(&g, dim, ns, 2.0 / n, org));
    return g;
}

/* Extends g(cp) (scalar, or vector when vec) given only in the source band
 * (garbage elsewhere) and compares with the exact closest-point extension. */
static ext_err run_shape(shape_kind s, int n, int vec, const hv_extend_opts *o)
{
    int dim = s == CIRCLE ? 2 : 3;
    hv_grid *phi = make_grid(dim, n);
    hv_grid *in[3], *out[3];
    for (int q = 0; q < 3; q++) {
        in[q] = make_grid(dim, n);
        out[q] = make_grid(dim, n);
    }
    size_t count = hv_grid_count(phi);
    double *ex = malloc(4 * count * sizeof *ex);
    uint8_t *valid = malloc(count);
    double band = o ? o->band : 1.5;
    for (int k = 0; k < phi->n[2]; k++)
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++) {
                size_t c = i + (size_t)n * (j + (size_t)n * k);
                double x[3], cp[3], ph;
                hv_grid_cell_center(phi, i, j, k, x);
                valid[c] = (uint8_t)closest(s, x, &ph, cp);
                phi->v[c] = (float)ph;
                double v[3];
                if (valid[c]) {
                    ex[4 * c] = g_scalar(cp);
                    g_vector(cp, v);
                    memcpy(ex + 4 * c + 1, v, sizeof v);
                }
                int in_band = fabs(ph) < band * phi->h;
                for (int q = 0; q < 3; q++)
                    in[q]->v[c] = in_band ? (float)(vec ? ex[4 * c + 1 + q] : ex[4 * c]) : 1e6f;
            }
    hv_extender *e = NULL;
    TL_ASSERT_OK(hv_extender_create(&e, dim, phi->n, phi->h, NULL, o));
    ext_err r = {0};
    if (vec)
        TL_ASSERT_OK(hv_extend_vec3(e, phi, (const hv_grid *const *)in, out, &r.st));
    else
        TL_ASSERT_OK(hv_extend_scalar(e, phi, in[0], out[0], &r.st));
    size_t nn = 0, na = 0;
    for (size_t c = 0; c < count; c++) {
        if (!valid[c])
            continue;
        double err;
        if (vec) {
            double d2 = 0, e2 = 0;
            for (int q = 0; q < 3; q++) {
                d2 += (out[q]->v[c] - ex[4 * c + 1 + q]) * (out[q]->v[c] - ex[4 * c + 1 + q]);
                e2 += ex[4 * c + 1 + q] * ex[4 * c + 1 + q];
            }
            err = sqrt(d2 / e2);
        } else {
            err = fabs(out[0]->v[c] - ex[4 * c]) / fabs(ex[4 * c]);
        }
        r.all += err;
        na++;
        if (fabs(phi->v[c]) <= 5 * phi->h) {
            r.near += err;
            nn++;
        }
    }
    r.near /= (double)nn;
    r.all /= (double)na;
    hv_extender_destroy(&e);
    ck_assert_ptr_null(e);
    for (int q = 0; q < 3; q++) {
        hv_grid_destroy(&in[q]);
        hv_grid_destroy(&out[q]);
    }
    hv_grid_destroy(&phi);
    free(ex);
    free(valid);
    return r;
}

static void report(const char *name, int n, int vec, const ext_err *r)
{
    printf("  %s n=%d %s: mean relative error %.2e within 5 voxels, %.2e everywhere; "
           "%zu closest-point / %zu ratio cells, %d levels, %d solves, %.2f s\n",
           name, n, vec ? "vector" : "scalar", r->near, r->all, r->st.cp_cells, r->st.ratio_cells,
           r->st.levels, r->st.solves, r->st.t_total);
}

START_TEST(sphere_scalar_should_match_closest_point_extension)
{
    ext_err r = run_shape(SPHERE, 64, 0, NULL);
    report("sphere", 64, 0, &r);
    ck_assert_msg(r.near <= 0.01, "near error %.3g", r.near);
    ck_assert_msg(r.all <= 0.03, "overall error %.3g", r.all);
}
END_TEST

START_TEST(sphere_vector_should_match_closest_point_extension)
{
    ext_err r = run_shape(SPHERE, 64, 1, NULL);
    report("sphere", 64, 1, &r);
    ck_assert_msg(r.near <= 0.01, "near error %.3g", r.near);
    ck_assert_msg(r.all <= 0.03, "overall error %.3g", r.all);
}
END_TEST

START_TEST(torus_scalar_and_vector_should_match_closest_point_extension)
{
    for (int vec = 0; vec < 2; vec++) {
        ext_err r = run_shape(TORUS, 64, vec, NULL);
        report("torus", 64, vec, &r);
        ck_assert_msg(r.near <= 0.01, "near error %.3g", r.near);
        ck_assert_msg(r.all <= 0.03, "overall error %.3g", r.all);
    }
}
END_TEST

START_TEST(circle_2d_should_match_closest_point_extension)
{
    for (int vec = 0; vec < 2; vec++) {
        ext_err r = run_shape(CIRCLE, 128, vec, NULL);
        report("circle", 128, vec, &r);
        ck_assert_msg(r.near <= 0.01, "near error %.3g", r.near);
        ck_assert_msg(r.all <= 0.03, "overall error %.3g", r.all);
    }
}
END_TEST

START_TEST(plain_diffusion_ratio_should_blur_more_than_closest_point)
{
    hv_extend_opts o;
    hv_extend_opts_default(&o);
    o.closest_point = 0;
    ext_err plain = run_shape(SPHERE, 48, 0, &o), cp = run_shape(SPHERE, 48, 0, NULL);
    report("sphere (plain ratio)", 48, 0, &plain);
    ck_assert_int_eq(plain.st.cp_cells, 0);
    ck_assert(cp.all < plain.all);
}
END_TEST

/* A constant field, on shape s, with the given options: every output cell
 * must hold the constant to float rounding. */
static void check_constant(shape_kind s, int n, const hv_extend_opts *o)
{
    int dim = s == CIRCLE ? 2 : 3;
    hv_grid *phi = make_grid(dim, n), *f = make_grid(dim, n), *fo = make_grid(dim, n);
    hv_grid *vin[3], *vout[3];
    const float cv[3] = {0.3f, -1.2f, 0.7f}, cs = 3.25f;
    size_t count = hv_grid_count(phi);
    for (int q = 0; q < 3; q++) {
        vin[q] = make_grid(dim, n);
        vout[q] = make_grid(dim, n);
    }
    for (int k = 0; k < phi->n[2]; k++)
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++) {
                size_t c = i + (size_t)n * (j + (size_t)n * k);
                double x[3], cp[3], ph;
                hv_grid_cell_center(phi, i, j, k, x);
                closest(s, x, &ph, cp);
                phi->v[c] = (float)ph;
                f->v[c] = cs;
                for (int q = 0; q < 3; q++)
                    vin[q]->v[c] = cv[q];
            }
    hv_extender *e = NULL;
    TL_ASSERT_OK(hv_extender_create(&e, dim, phi->n, phi->h, NULL, o));
    hv_extend_field fl[2] = {
        {1, {f->v, NULL, NULL}, {fo->v, NULL, NULL}},
        {3, {vin[0]->v, vin[1]->v, vin[2]->v}, {vout[0]->v, vout[1]->v, vout[2]->v}}};
    hv_extend_stats st;
    TL_ASSERT_OK(hv_extend_many(e, phi->v, 2, fl, &st));
    ck_assert_int_eq(st.solves, st.levels * 6);
    double ob = o ? o->out_band * phi->h : 0;
    double worst = 0;
    for (size_t c = 0; c < count; c++) {
        int inside = ob == 0 || fabs(phi->v[c]) < ob;
        if (!inside) {
            ck_assert(fo->v[c] == (o ? o->background : 0.0f));
            continue;
        }
        worst = fmax(worst, fabs(fo->v[c] - cs) / cs);
        for (int q = 0; q < 3; q++)
            worst = fmax(worst, fabs(vout[q]->v[c] - cv[q]) / 1.2);
    }
    ck_assert_msg(worst <= 4e-6, "constant reproduced to %.3g only", worst);
    hv_extender_destroy(&e);
    for (int q = 0; q < 3; q++) {
        hv_grid_destroy(&vin[q]);
        hv_grid_destroy(&vout[q]);
    }
    hv_grid_destroy(&phi);
    hv_grid_destroy(&f);
    hv_grid_destroy(&fo);
}

START_TEST(constant_fields_should_be_reproduced_exactly)
{
    check_constant(SPHERE, 48, NULL);
    check_constant(TORUS, 48, NULL);
    check_constant(CIRCLE, 96, NULL);
    hv_extend_opts o;
    hv_extend_opts_default(&o);
    o.closest_point = 0;
    check_constant(TORUS, 40, &o);
}
END_TEST

START_TEST(solid_cells_should_not_break_extension)
{
    /* A solid slab cutting through the sphere: multigrid backend, constant and
     * smooth fields still right on the fluid side. */
    const int n = 40;
    hv_grid *phi = make_grid(3, n), *f = make_grid(3, n), *o = make_grid(3, n);
    uint8_t *solid = calloc(hv_grid_count(phi), 1);
    for (int k = 0; k < n; k++)
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++) {
                size_t c = i + (size_t)n * (j + (size_t)n * k);
                double x[3], cp[3], ph;
                hv_grid_cell_center(phi, i, j, k, x);
                closest(SPHERE, x, &ph, cp);
                phi->v[c] = (float)ph;
                f->v[c] = 1.75f;
                solid[c] = (uint8_t)(x[0] > 0.3 && x[0] < 0.45);
            }
    hv_extender *e = NULL;
    TL_ASSERT_OK(hv_extender_create(&e, 3, phi->n, phi->h, solid, NULL));
    hv_extend_stats st;
    TL_ASSERT_OK(hv_extend_scalar(e, phi, f, o, &st));
    double worst = 0;
    for (size_t c = 0; c < hv_grid_count(phi); c++)
        if (!solid[c])
            worst = fmax(worst, fabs(o->v[c] - 1.75) / 1.75);
        else
            ck_assert(o->v[c] == 0.0f);
    ck_assert_msg(worst <= 4e-6, "constant reproduced to %.3g with solid cells", worst);
    hv_extender_destroy(&e);
    free(solid);
    hv_grid_destroy(&phi);
    hv_grid_destroy(&f);
    hv_grid_destroy(&o);
}
END_TEST

START_TEST(out_band_should_leave_background_outside)
{
    hv_extend_opts o;
    hv_extend_opts_default(&o);
    o.out_band = 4;
    o.background = -7;
    check_constant(SPHERE, 40, &o);
    ext_err r = run_shape(SPHERE, 48, 0, &o);
    ck_assert_int_eq(r.st.levels, 1);
    ck_assert_int_eq(r.st.ratio_cells, 0);
}
END_TEST

START_TEST(band_solve_should_agree_with_the_box_solve)
{
    /* A thin band around a sphere (out_band 3): the band solve covers a part of
     * the box and gives the box solve's extension. */
    const int n = 64;
    hv_grid *phi = make_grid(3, n), *f = make_grid(3, n), *a = make_grid(3, n),
            *b = make_grid(3, n);
    for (int k = 0; k < n; k++)
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++) {
                size_t c = i + (size_t)n * (j + (size_t)n * k);
                double x[3], cp[3], ph;
                hv_grid_cell_center(phi, i, j, k, x);
                closest(SPHERE, x, &ph, cp);
                phi->v[c] = (float)ph;
                f->v[c] = fabs(ph) < 3 * phi->h ? (float)g_scalar(cp) : 0.0f;
            }
    hv_extend_opts o;
    hv_extend_opts_default(&o);
    o.out_band = 3;
    hv_extend_stats sb, sx;
    hv_extender *e = NULL;
    TL_ASSERT_OK(hv_extender_create(&e, 3, phi->n, phi->h, NULL, &o));
    TL_ASSERT_OK(hv_extend_scalar(e, phi, f, a, &sb));
    hv_extender_destroy(&e);
    o.box_only = 1;
    TL_ASSERT_OK(hv_extender_create(&e, 3, phi->n, phi->h, NULL, &o));
    TL_ASSERT_OK(hv_extend_scalar(e, phi, f, b, &sx));
    hv_extender_destroy(&e);
    double worst = 0;
    for (size_t c = 0; c < hv_grid_count(a); c++)
        worst = fmax(worst, fabs(a->v[c] - b->v[c]) / fmax(fabs(b->v[c]), 1e-3));
    printf(
        "  band solve vs box solve, sphere 64^3: %zu vs %zu cells, max relative difference %.2e, "
        "%.3f vs %.3f s\n",
        sb.solve_cells, sx.solve_cells, worst, sb.t_solve, sx.t_solve);
    ck_assert_msg(sb.solve_cells < sx.solve_cells / 2, "band %zu cells, box %zu", sb.solve_cells,
                  sx.solve_cells);
    ck_assert_msg(worst <= 2e-5, "band and box differ by %.3g", worst);
    ck_assert_int_eq(sb.cp_cells, sx.cp_cells);
    hv_grid_destroy(&phi);
    hv_grid_destroy(&f);
    hv_grid_destroy(&a);
    hv_grid_destroy(&b);
}
END_TEST

START_TEST(extender_should_be_reusable_across_steps)
{
    const int n = 40;
    hv_grid *phi = make_grid(3, n), *f = make_grid(3, n), *a = make_grid(3, n),
            *b = make_grid(3, n);
    hv_extender *e = NULL;
    TL_ASSERT_OK(hv_extender_create(&e, 3, phi->n, phi->h, NULL, NULL));
    for (int step = 0; step < 3; step++) {
        /* A sphere that moves and a field that changes each step. */
        for (int k = 0; k < n; k++)
            for (int j = 0; j < n; j++)
                for (int i = 0; i < n; i++) {
                    size_t c = i + (size_t)n * (j + (size_t)n * k);
                    double x[3];
                    hv_grid_cell_center(phi, i, j, k, x);
                    x[0] -= 0.05 * step;
                    double cp[3], ph;
                    closest(SPHERE, x, &ph, cp);
                    phi->v[c] = (float)ph;
                    f->v[c] = (float)(g_scalar(cp) + step);
                }
        hv_extend_stats st;
        TL_ASSERT_OK(hv_extend_scalar(e, phi, f, a, &st));
        hv_extender *fresh = NULL;
        TL_ASSERT_OK(hv_extender_create(&fresh, 3, phi->n, phi->h, NULL, NULL));
        TL_ASSERT_OK(hv_extend_scalar(fresh, phi, f, b, NULL));
        hv_extender_destroy(&fresh);
        ck_assert(memcmp(a->v, b->v, hv_grid_count(a) * sizeof(float)) == 0);
    }
    hv_extender_destroy(&e);
    hv_grid_destroy(&phi);
    hv_grid_destroy(&f);
    hv_grid_destroy(&a);
    hv_grid_destroy(&b);
}
END_TEST

START_TEST(bad_input_should_fail_clearly)
{
    const int n = 16;
    hv_grid *phi = make_grid(3, n), *f = make_grid(3, n), *o = make_grid(3, n);
    hv_extender *e = NULL;
    TL_ASSERT_OK(hv_extender_create(&e, 3, phi->n, phi->h, NULL, NULL));
    for (size_t c = 0; c < hv_grid_count(phi); c++)
        phi->v[c] = 1; /* no zero crossing */
    ck_assert_int_eq(hv_extend_scalar(e, phi, f, o, NULL), HV_ERR_INVALID_ARG);
    ck_assert(strstr(hv_last_error(), "band") != NULL);
    phi->v[5] = NAN;
    ck_assert_int_eq(hv_extend_scalar(e, phi, f, o, NULL), HV_ERR_NUMERIC);
    ck_assert(strstr(hv_last_error(), "level set") != NULL);

    /* A sphere: the field is read only in the source band. A NaN there fails
     * and leaves the output as it was (outputs may alias inputs); a NaN
     * elsewhere is never read. */
    size_t inside = SIZE_MAX, far = SIZE_MAX;
    for (int k = 0; k < n; k++)
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++) {
                size_t c = i + (size_t)n * (j + (size_t)n * k);
                double x[3];
                hv_grid_cell_center(phi, i, j, k, x);
                phi->v[c] = (float)(sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) - 0.5);
                f->v[c] = 1;
                o->v[c] = -7;
                if (fabs(phi->v[c]) < 0.5 * phi->h && inside == SIZE_MAX)
                    inside = c;
                if (phi->v[c] > 0.3)
                    far = c;
            }
    ck_assert(inside != SIZE_MAX && far != SIZE_MAX);
    f->v[inside] = NAN;
    hv_extend_opts ob;
    hv_extend_opts_default(&ob);
    ob.out_band = 2; /* cells beyond would get the background */
    hv_extender *eb = NULL;
    TL_ASSERT_OK(hv_extender_create(&eb, 3, phi->n, phi->h, NULL, &ob));
    ck_assert_int_eq(hv_extend_scalar(eb, phi, f, o, NULL), HV_ERR_NUMERIC);
    ck_assert_msg(strstr(hv_last_error(), "field 0") != NULL, "message: %s", hv_last_error());
    for (size_t c = 0; c < hv_grid_count(o); c++)
        ck_assert_msg(o->v[c] == -7, "cell %zu written before the error", c);
    hv_extender_destroy(&eb);
    f->v[inside] = 1;
    f->v[far] = NAN;
    TL_ASSERT_OK(hv_extend_scalar(e, phi, f, o, NULL));
    for (size_t c = 0; c < hv_grid_count(o); c++)
        ck_assert_msg(fabsf(o->v[c] - 1) < 1e-6f, "cell %zu: %g", c, o->v[c]);
    hv_grid *small = make_grid(3, 8);
    ck_assert_int_eq(hv_extend_scalar(e, small, small, small, NULL), HV_ERR_INVALID_ARG);
    hv_extender *bad = NULL;
    hv_extend_opts opt;
    hv_extend_opts_default(&opt);
    opt.band = 0;
    ck_assert_int_eq(hv_extender_create(&bad, 3, phi->n, phi->h, NULL, &opt), HV_ERR_INVALID_ARG);
    ck_assert_ptr_null(bad);
    hv_extender_destroy(&e);
    hv_grid_destroy(&phi);
    hv_grid_destroy(&f);
    hv_grid_destroy(&o);
    hv_grid_destroy(&small);
}
END_TEST

/* ---- heatvox extend, VDB in and out ---------------------------------------- */

/* Where write_input puts its block in index space (not at 0, not leaf-aligned,
 * as in a file another tool made). */
static const int IN_OFF[3] = {-7, 2, 5};

/* A narrow-band sphere level set 'surface', a velocity 'v' and a scalar 'temp'
 * (both given within 3 voxels of the surface, 0 elsewhere) on n^3 cells of
 * [-1,1]^3, the block at index IN_OFF; temp_h != 0 writes 'temp' with that voxel
 * size instead (and the block at index 0). */
static void write_input(const char *path, int n, double temp_h)
{
    int ns[3] = {n, n, n};
    double h = 2.0 / n, org[3] = {-1, -1, -1};
    hv_grid *phi = NULL, *t = NULL, *v[3];
    TL_ASSERT_OK(hv_grid_create(&phi, 3, ns, h, org));
    TL_ASSERT_OK(hv_grid_create(&t, 3, ns, temp_h ? temp_h : h, org));
    for (int q = 0; q < 3; q++)
        TL_ASSERT_OK(hv_grid_create(&v[q], 3, ns, h, org));
    for (int k = 0; k < n; k++)
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++) {
                size_t c = i + (size_t)n * (j + (size_t)n * k);
                double x[3], cp[3], ph, g[3];
                hv_grid_cell_center(phi, i, j, k, x);
                closest(SPHERE, x, &ph, cp);
                phi->v[c] = (float)ph;
                int band = fabs(ph) < 3 * h;
                g_vector(cp, g);
                for (int q = 0; q < 3; q++)
                    v[q]->v[c] = band ? (float)g[q] : 0.0f;
                t->v[c] = band ? (float)g_scalar(cp) : 0.0f;
            }
    hv_vdb_writer *w = NULL;
    TL_ASSERT_OK(hv_vdb_writer_create(&w));
    if (!temp_h) {
        double i0[3];
        for (int a = 0; a < 3; a++)
            i0[a] = org[a] + (0.5 - IN_OFF[a]) * h;
        TL_ASSERT_OK(hv_vdb_writer_set_index_origin(w, i0));
    }
    TL_ASSERT_OK(hv_vdb_writer_add_levelset(w, phi, "surface", 3, 0));
    TL_ASSERT_OK(hv_vdb_writer_add_vec3(w, v[0], v[1], v[2], "v"));
    TL_ASSERT_OK(hv_vdb_writer_add_float(w, t, "temp"));
    TL_ASSERT_OK(hv_vdb_writer_write(w, path));
    hv_vdb_writer_destroy(&w);
    hv_grid_destroy(&phi);
    hv_grid_destroy(&t);
    for (int q = 0; q < 3; q++)
        hv_grid_destroy(&v[q]);
}

START_TEST(heatvox_extend_should_round_trip_levelset_and_velocity_through_vdb)
{
    const char *bin = tl_heatvox_bin();
    if (!bin)
        TL_SKIP("no heatvox binary (build/heatvox or $HEATVOX_BIN)");
    char dir[] = "/tmp/hv_extend_XXXXXX";
    ck_assert_ptr_nonnull(mkdtemp(dir));
    char in[256], out[256], cmd[2048], err[4096];
    snprintf(in, sizeof in, "%s/in.vdb", dir);
    snprintf(out, sizeof out, "%s/out.vdb", dir);
    const int n = 48;
    write_input(in, n, 0);
    snprintf(cmd, sizeof cmd,
             "%s extend %s --levelset surface --field v --field temp -o %s -q --dense", bin, in,
             out);
    ck_assert_msg(tl_run_cmd(cmd, dir, err, sizeof err) == 0, "heatvox extend failed: %s", err);

    /* Names, value types, classes, and the input's index space. */
    hv_vdb_grid_info info[8], info_in;
    size_t count = 0;
    TL_ASSERT_OK(hv_vdb_list(in, &info_in, 1, &count));
    TL_ASSERT_OK(hv_vdb_list(out, info, 8, &count));
    ck_assert_int_eq(count, 3);
    for (size_t i = 0; i < count; i++)
        for (int a = 0; a < 3; a++) {
            ck_assert_msg(fabs(info[i].index0_world[a] - info_in.index0_world[a]) < 1e-9,
                          "grid %s: index (0,0,0) moved", info[i].name);
            if (strcmp(info[i].name, "surface")) {
                ck_assert_int_eq(info[i].bbox_lo[a], IN_OFF[a]);
                ck_assert_int_eq(info[i].bbox_hi[a], IN_OFF[a] + n - 1);
            }
        }
    int seen = 0;
    for (size_t i = 0; i < count; i++) {
        if (!strcmp(info[i].name, "surface")) {
            ck_assert_int_eq(info[i].grid_class, HV_VDB_LEVEL_SET);
            ck_assert_str_eq(info[i].value_type, "float");
            seen |= 1;
        } else if (!strcmp(info[i].name, "v")) {
            ck_assert_str_eq(info[i].value_type, "vec3s");
            seen |= 2;
        } else if (!strcmp(info[i].name, "temp")) {
            ck_assert_str_eq(info[i].value_type, "float");
            seen |= 4;
        }
        ck_assert(fabs(info[i].voxel_size[0] - 2.0 / n) < 1e-9);
    }
    ck_assert_int_eq(seen, 7);

    /* Same world placement, the level set unchanged, the fields extended. */
    hv_grid *phi = NULL, *v[3] = {NULL, NULL, NULL}, *t = NULL, *phi0 = NULL;
    int cls;
    TL_ASSERT_OK(hv_vdb_read_float(out, "surface", NULL, &phi, &cls));
    TL_ASSERT_OK(hv_vdb_read_float(in, "surface", NULL, &phi0, NULL));
    ck_assert_int_eq(cls, HV_VDB_LEVEL_SET);
    hv_vdb_read_opts ro = {1,
                           {IN_OFF[0], IN_OFF[1], IN_OFF[2]},
                           {IN_OFF[0] + n - 1, IN_OFF[1] + n - 1, IN_OFF[2] + n - 1}};
    TL_ASSERT_OK(hv_vdb_read_vec3(out, "v", &ro, &v[0], &v[1], &v[2]));
    TL_ASSERT_OK(hv_vdb_read_float(out, "temp", &ro, &t, NULL));
    for (int a = 0; a < 3; a++) {
        ck_assert(fabs(v[0]->origin[a] + 1) < 1e-6);
        ck_assert_int_eq(v[0]->n[a], n);
        ck_assert(fabs(phi->origin[a] - phi0->origin[a]) < 1e-6);
    }
    ck_assert(memcmp(phi->v, phi0->v, hv_grid_count(phi) * sizeof(float)) == 0);
    double ev = 0, et = 0, evn = 0, etn = 0;
    size_t m = 0, mn = 0;
    for (int k = 0; k < n; k++)
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++) {
                size_t c = i + (size_t)n * (j + (size_t)n * k);
                double x[3], cp[3], ph, g[3];
                hv_grid_cell_center(v[0], i, j, k, x);
                if (!closest(SPHERE, x, &ph, cp))
                    continue;
                g_vector(cp, g);
                double d2 = 0, g2 = 0;
                for (int q = 0; q < 3; q++) {
                    d2 += (v[q]->v[c] - g[q]) * (v[q]->v[c] - g[q]);
                    g2 += g[q] * g[q];
                }
                double e1 = sqrt(d2 / g2), e2 = fabs(t->v[c] - g_scalar(cp)) / g_scalar(cp);
                ev += e1;
                et += e2;
                m++;
                if (fabs(ph) < 3 * v[0]->h) {
                    evn += e1;
                    etn += e2;
                    mn++;
                }
            }
    printf("  heatvox extend round trip (narrow-band level set, 48^3): velocity %.2e within 3 "
           "voxels, %.2e everywhere; temp %.2e / %.2e\n",
           evn / mn, ev / m, etn / mn, et / m);
    ck_assert_msg(evn / mn <= 0.01 && etn / mn <= 0.01, "near errors %.3g %.3g", evn / mn,
                  etn / mn);
    /* Beyond the level set's band phi is clamped: plain diffusion there, coarser. */
    ck_assert_msg(ev / m <= 0.1 && et / m <= 0.1, "overall errors %.3g %.3g", ev / m, et / m);
    hv_grid_destroy(&phi);
    hv_grid_destroy(&phi0);
    hv_grid_destroy(&t);
    for (int q = 0; q < 3; q++)
        hv_grid_destroy(&v[q]);

    /* Missing grids and mismatched transforms fail with the names. */
    snprintf(cmd, sizeof cmd, "%s extend %s --levelset surface --field nothere -o %s/x.vdb", bin,
             in, dir);
    ck_assert_int_eq(tl_run_cmd(cmd, dir, err, sizeof err), 1);
    ck_assert_msg(strstr(err, "nothere") && strstr(err, "'v'"), "message: %s", err);
    snprintf(cmd, sizeof cmd, "%s extend %s --levelset nosurface --field v -o %s/x.vdb", bin, in,
             dir);
    ck_assert_int_eq(tl_run_cmd(cmd, dir, err, sizeof err), 1);
    ck_assert_msg(strstr(err, "nosurface") != NULL, "message: %s", err);
    write_input(in, n, 1.5 * 2.0 / n);
    snprintf(cmd, sizeof cmd, "%s extend %s --levelset surface --field v --field temp -o %s/x.vdb",
             bin, in, dir);
    ck_assert_int_eq(tl_run_cmd(cmd, dir, err, sizeof err), 1);
    ck_assert_msg(strstr(err, "temp") != NULL, "message: %s", err);
    snprintf(cmd, sizeof cmd, "%s extend %s --levelset surface -o %s/x.vdb", bin, in, dir);
    ck_assert_int_eq(tl_run_cmd(cmd, dir, err, sizeof err), 2);
    ck_assert(access(dir, F_OK) == 0);
    snprintf(cmd, sizeof cmd, "rm -rf %s", dir);
    ck_assert_int_eq(system(cmd), 0);
}
END_TEST

int main(void)
{
    Suite *s = suite_create("extend");
    TCase *tc = tcase_create("closest-point");
    tcase_set_timeout(tc, 120);
    tcase_add_test(tc, sphere_scalar_should_match_closest_point_extension);
    tcase_add_test(tc, sphere_vector_should_match_closest_point_extension);
    tcase_add_test(tc, torus_scalar_and_vector_should_match_closest_point_extension);
    tcase_add_test(tc, circle_2d_should_match_closest_point_extension);
    tcase_add_test(tc, plain_diffusion_ratio_should_blur_more_than_closest_point);
    tcase_add_test(tc, constant_fields_should_be_reproduced_exactly);
    tcase_add_test(tc, solid_cells_should_not_break_extension);
    tcase_add_test(tc, out_band_should_leave_background_outside);
    tcase_add_test(tc, band_solve_should_agree_with_the_box_solve);
    tcase_add_test(tc, extender_should_be_reusable_across_steps);
    tcase_add_test(tc, bad_input_should_fail_clearly);
    tcase_add_test(tc, heatvox_extend_should_round_trip_levelset_and_velocity_through_vdb);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
