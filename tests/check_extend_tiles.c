/* Extension on narrow bands given as tiles (hv_extend_tiles): the values of
 * the dense path on the band, scalar and vector fields, a band that moves
 * between calls of one extender, accuracy against the exact closest-point
 * extension, bad input, and the heatvox extend command's sparse path. */
#include "sdf_testutil.h"
#include "testlib.h"
#include "heatvox/heat.h"
#include "heatvox/opencl.h"
#include "heatvox/vdb.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define TCELLS (HV_TILE * HV_TILE * HV_TILE)
#define LS_BAND 3.0 /* the level sets' band, voxels */

typedef enum { SPHERE, TORUS } shape_kind;

/* Signed distance and closest point; 0 where the closest point is not unique. */
static int closest(shape_kind s, const double c0[3], const double x[3], double *phi, double cp[3])
{
    const double q[3] = {x[0] - c0[0], x[1] - c0[1], x[2] - c0[2]};
    if (s == SPHERE) {
        const double R = 0.5, r = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
        *phi = r - R;
        if (r < 1e-12)
            return 0;
        for (int a = 0; a < 3; a++)
            cp[a] = c0[a] + R * q[a] / r;
        return 1;
    }
    const double R = 0.5, rt = 0.2, rho = hypot(q[0], q[1]);
    if (rho < 1e-12) {
        *phi = hypot(R, q[2]) - rt;
        return 0;
    }
    const double m[3] = {R * q[0] / rho, R * q[1] / rho, 0};
    const double d[3] = {q[0] - m[0], q[1] - m[1], q[2]},
                 dn = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    *phi = dn - rt;
    if (dn < 1e-12)
        return 0;
    for (int a = 0; a < 3; a++)
        cp[a] = c0[a] + m[a] + rt * d[a] / dn;
    return 1;
}

static double g_scalar(const double p[3]) { return 2 + sin(3 * p[0]) * cos(2 * p[1]) + 0.5 * p[2]; }

static void g_vector(const double p[3], double v[3])
{
    v[0] = -p[1] + 0.3;
    v[1] = p[0] + 0.2;
    v[2] = 0.5 + 0.2 * p[2];
}

/* A narrow-band case, dense: phi clamped to +-LS_BAND voxels (active where
 * |phi| is below it), the fields given on the source band (garbage beyond),
 * and the exact extension. */
typedef struct {
    int n[3];
    double h, org[3];
    hv_grid *phi, *in[4]; /* in[0]: scalar; in[1..3]: vector */
    double *ex;           /* 4 per cell: scalar, vector */
    uint8_t *valid;
} nb_case;

static void make_case(nb_case *c, shape_kind s, const int n[3], const double c0[3])
{
    memset(c, 0, sizeof *c);
    memcpy(c->n, n, sizeof c->n);
    c->h = 2.0 / n[0];
    for (int a = 0; a < 3; a++)
        c->org[a] = -1;
    TL_ASSERT_OK(hv_grid_create(&c->phi, 3, n, c->h, c->org));
    for (int q = 0; q < 4; q++)
        TL_ASSERT_OK(hv_grid_create(&c->in[q], 3, n, c->h, c->org));
    const size_t count = hv_grid_count(c->phi);
    c->ex = calloc(4 * count, sizeof *c->ex);
    c->valid = calloc(count, 1);
    ck_assert(c->ex && c->valid);
    const double bg = LS_BAND * c->h;
    for (int k = 0; k < n[2]; k++)
        for (int j = 0; j < n[1]; j++)
            for (int i = 0; i < n[0]; i++) {
                const size_t cell = i + (size_t)n[0] * (j + (size_t)n[1] * k);
                double x[3], cp[3] = {0, 0, 0}, ph, v[3];
                hv_grid_cell_center(c->phi, i, j, k, x);
                c->valid[cell] = (uint8_t)closest(s, c0, x, &ph, cp);
                c->phi->v[cell] = (float)(ph > bg ? bg : ph < -bg ? -bg : ph);
                if (c->valid[cell]) {
                    c->ex[4 * cell] = g_scalar(cp);
                    g_vector(cp, v);
                    memcpy(c->ex + 4 * cell + 1, v, sizeof v);
                }
                const int src = fabs(ph) < 1.5 * c->h && c->valid[cell];
                for (int q = 0; q < 4; q++)
                    c->in[q]->v[cell] = src ? (float)c->ex[4 * cell + q] : 1e6f;
            }
}

static void free_case(nb_case *c)
{
    hv_grid_destroy(&c->phi);
    for (int q = 0; q < 4; q++)
        hv_grid_destroy(&c->in[q]);
    free(c->ex);
    free(c->valid);
}

static int is_active(const nb_case *c, size_t cell)
{
    return fabsf(c->phi->v[cell]) < (float)(LS_BAND * c->h);
}

/* Tiles of g on the tiles of the case's active cells (every cell of a tile,
 * active bits where the level set is active). */
static hv_tiles *tiles_of(const nb_case *c, const hv_grid *g)
{
    const int tn[3] = {(c->n[0] + 7) / 8, (c->n[1] + 7) / 8, (c->n[2] + 7) / 8};
    hv_tiles *t = calloc(1, sizeof *t);
    ck_assert_ptr_nonnull(t);
    memcpy(t->n, c->n, sizeof t->n);
    t->h = c->h;
    memcpy(t->origin, c->org, sizeof t->origin);
    const size_t maxt = (size_t)tn[0] * tn[1] * tn[2];
    t->ijk = hv_malloc(3 * maxt * sizeof *t->ijk);
    t->v = hv_malloc(maxt * TCELLS * sizeof *t->v);
    t->on = hv_calloc(8 * maxt, sizeof *t->on);
    ck_assert(t->ijk && t->v && t->on);
    for (int tk = 0; tk < tn[2]; tk++)
        for (int tj = 0; tj < tn[1]; tj++)
            for (int ti = 0; ti < tn[0]; ti++) {
                const size_t q = t->count;
                int any = 0;
                for (int o = 0; o < TCELLS; o++) {
                    const int i = 8 * ti + (o & 7), j = 8 * tj + ((o >> 3) & 7),
                              k = 8 * tk + (o >> 6);
                    if (i >= c->n[0] || j >= c->n[1] || k >= c->n[2]) {
                        t->v[q * TCELLS + o] = (float)(LS_BAND * c->h);
                        continue;
                    }
                    const size_t cell = i + (size_t)c->n[0] * (j + (size_t)c->n[1] * k);
                    t->v[q * TCELLS + o] = g->v[cell];
                    if (is_active(c, cell)) {
                        t->on[8 * q + (o >> 6)] |= (uint64_t)1 << (o & 63);
                        t->active++;
                        any = 1;
                    }
                }
                if (!any)
                    continue;
                t->ijk[3 * q] = 8 * ti;
                t->ijk[3 * q + 1] = 8 * tj;
                t->ijk[3 * q + 2] = 8 * tk;
                t->count++;
            }
    return t;
}

/* Per tile of the block: the index + 1 of t's tile there, 0 none. */
static int32_t *tile_index(const hv_tiles *t)
{
    const int tn[3] = {(t->n[0] + 7) / 8, (t->n[1] + 7) / 8, (t->n[2] + 7) / 8};
    int32_t *map = calloc((size_t)tn[0] * tn[1] * tn[2], sizeof *map);
    ck_assert_ptr_nonnull(map);
    for (size_t q = 0; q < t->count; q++) {
        const int32_t *c = t->ijk + 3 * q;
        map[c[0] / 8 + tn[0] * (c[1] / 8 + (size_t)tn[1] * (c[2] / 8))] = (int32_t)(q + 1);
    }
    return map;
}

/* Value of tiles t at block cell (i, j, k) with its active bit; -1 when no
 * tile holds it (map from tile_index). */
static int tile_value(const hv_tiles *t, const int32_t *map, int i, int j, int k, float *v)
{
    const int tn[2] = {(t->n[0] + 7) / 8, (t->n[1] + 7) / 8};
    const int32_t q = map[i / 8 + tn[0] * (j / 8 + (size_t)tn[1] * (k / 8))];
    if (!q)
        return -1;
    const int o = (i & 7) + 8 * (j & 7) + 64 * (k & 7);
    *v = t->v[(size_t)(q - 1) * TCELLS + o];
    return (int)(t->on[8 * (size_t)(q - 1) + (o >> 6)] >> (o & 63) & 1);
}

typedef struct {
    double worst;            /* largest relative difference to the dense path on the band */
    double err_s, err_v;     /* mean relative error against the exact extension on the band */
    size_t cells, wrong_set; /* band cells; cells active in one output and not the other */
    hv_extend_stats sp, dn;
} cmp_result;

/* Scalar and vector together, sparse (extender e, kept by the caller) and dense. */
static cmp_result compare(const nb_case *c, hv_extender *e, const hv_extend_opts *o)
{
    cmp_result r;
    memset(&r, 0, sizeof r);
    hv_tiles *P = tiles_of(c, c->phi), *F[4];
    for (int q = 0; q < 4; q++)
        F[q] = tiles_of(c, c->in[q]);
    hv_extend_tiles_field tf[2] = {{1, {F[0], NULL, NULL}}, {3, {F[1], F[2], F[3]}}};
    TL_ASSERT_OK(hv_extend_tiles(e, P, 2, tf, &r.sp));
    /* Dense, on a fresh extender. */
    hv_grid *out[4];
    for (int q = 0; q < 4; q++)
        TL_ASSERT_OK(hv_grid_create(&out[q], 3, c->n, c->h, c->org));
    hv_extend_field df[2] = {
        {1, {c->in[0]->v, NULL, NULL}, {out[0]->v, NULL, NULL}},
        {3, {c->in[1]->v, c->in[2]->v, c->in[3]->v}, {out[1]->v, out[2]->v, out[3]->v}}};
    hv_extender *d = NULL;
    TL_ASSERT_OK(hv_extender_create(&d, 3, c->n, c->h, NULL, o));
    TL_ASSERT_OK(hv_extend_many(d, c->phi->v, 2, df, &r.dn));
    hv_extender_destroy(&d);
    hv_tiles *const *T = F; /* extended in place */
    const double ob = (o && o->out_band > 0 ? o->out_band : LS_BAND) * c->h;
    int32_t *map = tile_index(P);
    size_t nerr = 0;
    for (int k = 0; k < c->n[2]; k++)
        for (int j = 0; j < c->n[1]; j++)
            for (int i = 0; i < c->n[0]; i++) {
                const size_t cell = i + (size_t)c->n[0] * (j + (size_t)c->n[1] * k);
                const int want = is_active(c, cell) && fabsf(c->phi->v[cell]) < (float)ob;
                double d2 = 0, e2 = 0;
                for (int q = 0; q < 4; q++) {
                    float v = 0;
                    const int on = tile_value(T[q], map, i, j, k, &v);
                    if (!(on == want || (on < 0 && !want)) && !r.wrong_set++)
                        printf("  cell (%d %d %d): active %d, expected %d\n", i, j, k, on, want);
                    if (!want)
                        continue;
                    const double b = out[q]->v[cell];
                    r.worst = fmax(r.worst, fabs(v - b) / fmax(fabs(b), 1e-3));
                    if (q == 0 && c->valid[cell])
                        r.err_s += fabs(v - c->ex[4 * cell]) / fabs(c->ex[4 * cell]);
                    if (q > 0) {
                        d2 += (v - c->ex[4 * cell + q]) * (v - c->ex[4 * cell + q]);
                        e2 += c->ex[4 * cell + q] * c->ex[4 * cell + q];
                    }
                }
                if (want) {
                    r.cells++;
                    if (c->valid[cell]) {
                        r.err_v += sqrt(d2 / e2);
                        nerr++;
                    }
                }
            }
    free(map);
    r.err_s /= (double)nerr;
    r.err_v /= (double)nerr;
    for (int q = 0; q < 4; q++) {
        ck_assert_uint_eq(T[q]->active, r.cells);
        hv_tiles_destroy(&F[q]);
        hv_grid_destroy(&out[q]);
    }
    hv_tiles_destroy(&P);
    return r;
}

static void report(const char *what, const cmp_result *r)
{
    printf("  %s: %zu band cells, %zu tiles, %zu solve cells, %d levels (dense %d), %zu cp / %zu "
           "ratio cells; sparse vs dense max relative difference %.2e; mean error scalar %.2e "
           "vector %.2e\n",
           what, r->cells, r->sp.tiles, r->sp.solve_cells, r->sp.levels, r->dn.levels,
           r->sp.cp_cells, r->sp.ratio_cells, r->worst, r->err_s, r->err_v);
}

static void expect_same(const cmp_result *r)
{
    ck_assert_uint_eq(r->wrong_set, 0);
    ck_assert_msg(r->worst <= 1e-6, "sparse and dense differ by %.3g", r->worst);
    ck_assert_uint_eq(r->sp.cp_cells, r->dn.cp_cells);
    ck_assert_uint_eq(r->sp.ratio_cells, r->dn.ratio_cells);
    ck_assert_uint_eq(r->sp.source_cells, r->dn.source_cells);
    ck_assert_int_eq(r->sp.levels, r->dn.levels);
}

START_TEST(sparse_should_equal_dense_on_a_sphere_band)
{
    /* Sizes that are not multiples of 8, the sphere off centre. */
    const int n[3] = {61, 57, 54};
    const double c0[3] = {0.05, -0.03, 0.02};
    nb_case c;
    make_case(&c, SPHERE, n, c0);
    for (int pass = 0; pass < 2; pass++) {
        hv_extend_opts o;
        hv_extend_opts_default(&o);
        o.out_band = pass ? 2 : LS_BAND;
        hv_extender *e = NULL;
        TL_ASSERT_OK(hv_extender_create(&e, 3, c.n, c.h, NULL, &o));
        cmp_result r = compare(&c, e, &o);
        report(pass ? "sphere, output band 2" : "sphere, output band 3", &r);
        expect_same(&r);
        ck_assert_msg(r.err_s <= 0.01 && r.err_v <= 0.01, "errors %.3g %.3g", r.err_s, r.err_v);
        ck_assert(r.sp.work_bytes > 0 && r.sp.solve_cells > 0);
        hv_extender_destroy(&e);
    }
    free_case(&c);
}
END_TEST

START_TEST(sparse_should_equal_dense_on_a_torus_band)
{
    const int n[3] = {128, 128, 64}; /* its solve runs threaded (over 131,072 cells) */
    const double c0[3] = {0.02, 0.01, -0.5 + 0.013};
    nb_case c;
    make_case(&c, TORUS, n, c0);
    hv_extend_opts o;
    hv_extend_opts_default(&o);
    o.out_band = LS_BAND;
    hv_extender *e = NULL;
    TL_ASSERT_OK(hv_extender_create(&e, 3, c.n, c.h, NULL, &o));
    cmp_result r = compare(&c, e, &o);
    report("torus, output band 3", &r);
    expect_same(&r);
    ck_assert_msg(r.err_s <= 0.01 && r.err_v <= 0.01, "errors %.3g %.3g", r.err_s, r.err_v);
    hv_extender_destroy(&e);
    free_case(&c);
}
END_TEST

START_TEST(one_extender_should_follow_a_moving_band)
{
    /* A sphere moving across the block, one extender for every step; without
     * an output band the output is every active voxel of the level set. */
    const int n[3] = {48, 48, 48};
    hv_extend_opts o;
    hv_extend_opts_default(&o);
    hv_extender *e = NULL;
    TL_ASSERT_OK(hv_extender_create(&e, 3, n, 2.0 / n[0], NULL, &o));
    for (int step = 0; step < 3; step++) {
        const double c0[3] = {-0.3 + 0.23 * step, 0.1 - 0.07 * step, 0.02};
        nb_case c;
        make_case(&c, SPHERE, n, c0);
        hv_extend_opts od = o;
        od.out_band = LS_BAND; /* the dense path's output cells: the same band */
        cmp_result r = compare(&c, e, &od);
        report("moving sphere", &r);
        expect_same(&r);
        free_case(&c);
    }
    hv_extender_destroy(&e);
}
END_TEST

/* Whether an OpenCL device with fp64 is here (no message). */
static int device_here(void)
{
    hv_opencl_device d;
    const int ok = hv_opencl_probe(&d) == HV_OK && d.fp64;
    hv_clear_error();
    return ok;
}

/* The checks of bad_input_should_fail_without_output on backend b. */
static void bad_input_on(hv_backend b)
{
    const int n[3] = {32, 32, 32};
    const double c0[3] = {0, 0, 0};
    nb_case c;
    make_case(&c, SPHERE, n, c0);
    hv_tiles *P = tiles_of(&c, c.phi), *F = tiles_of(&c, c.in[0]);
    hv_extender *e = NULL;
    hv_extend_opts o;
    hv_extend_opts_default(&o);
    o.backend = b;
    TL_ASSERT_OK(hv_extender_create(&e, 3, n, c.h, NULL, &o));
    hv_extend_tiles_field f = {1, {F, NULL, NULL}};
    float *copy = malloc(F->count * TCELLS * sizeof *copy);
    ck_assert_ptr_nonnull(copy);
    /* NaN in the field where it is read: refused, the field unchanged. */
    size_t at = 0;
    for (size_t q = 0; q < F->count * TCELLS; q++)
        if (fabsf(P->v[q]) < 0.5f * (float)c.h) {
            at = q;
            break;
        }
    const float keep = F->v[at];
    F->v[at] = NAN;
    memcpy(copy, F->v, F->count * TCELLS * sizeof *copy);
    ck_assert_int_eq(hv_extend_tiles(e, P, 1, &f, NULL), HV_ERR_NUMERIC);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "NaN"));
    ck_assert(isnan(F->v[at]));
    F->v[at] = keep;
    copy[at] = keep;
    ck_assert(memcmp(copy, F->v, F->count * TCELLS * sizeof *copy) == 0);
    /* NaN in the level set. */
    const float pk = P->v[at];
    P->v[at] = INFINITY;
    ck_assert_int_eq(hv_extend_tiles(e, P, 1, &f, NULL), HV_ERR_NUMERIC);
    ck_assert(memcmp(copy, F->v, F->count * TCELLS * sizeof *copy) == 0);
    P->v[at] = pk;
    free(copy);
    /* Tiles of another block or voxel size. */
    hv_extender *other = NULL;
    const int n2[3] = {40, 32, 32};
    TL_ASSERT_OK(hv_extender_create(&other, 3, n2, c.h, NULL, NULL));
    ck_assert_int_eq(hv_extend_tiles(other, P, 1, &f, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "block"));
    hv_extender_destroy(&other);
    /* A field on other tiles. */
    F->count--;
    ck_assert_int_eq(hv_extend_tiles(e, P, 1, &f, NULL), HV_ERR_INVALID_ARG);
    F->count++;
    /* A tile listed twice. */
    const int32_t save[3] = {P->ijk[3], P->ijk[4], P->ijk[5]};
    memcpy(P->ijk + 3, P->ijk, 3 * sizeof *P->ijk);
    memcpy(F->ijk + 3, F->ijk, 3 * sizeof *F->ijk);
    ck_assert_int_eq(hv_extend_tiles(e, P, 1, &f, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "twice"));
    memcpy(P->ijk + 3, save, sizeof save);
    memcpy(F->ijk + 3, save, sizeof save);
    /* Solid cells are the dense path's. */
    uint8_t *solid = calloc(hv_grid_count(c.phi), 1);
    hv_extender *se = NULL;
    TL_ASSERT_OK(hv_extender_create(&se, 3, n, c.h, solid, NULL));
    ck_assert_int_eq(hv_extend_tiles(se, P, 1, &f, NULL), HV_ERR_INVALID_ARG);
    hv_extender_destroy(&se);
    free(solid);
    /* After the failures the extender still works. */
    hv_extend_stats st;
    TL_ASSERT_OK(hv_extend_tiles(e, P, 1, &f, &st));
    ck_assert_int_eq(st.on_device, b == HV_BACKEND_OPENCL);
    ck_assert_uint_eq(F->active, st.cp_cells + st.ratio_cells);
    ck_assert_uint_eq(F->active, P->active);
    hv_extender_destroy(&e);
    hv_tiles_destroy(&P);
    hv_tiles_destroy(&F);
    free_case(&c);
}

START_TEST(bad_input_should_fail_without_output)
{
    bad_input_on(HV_BACKEND_AUTO);
    if (device_here())
        bad_input_on(HV_BACKEND_OPENCL);
    else
        printf("  bad input: no OpenCL device with fp64, the device path left out\n");
}
END_TEST

/* The band of a sphere of radius 6 voxels around cell (c + 8.5) per axis of
 * a block of n^3 cells: 27 tiles from cell c on, the distance clamped to 3
 * voxels, active below it. */
static hv_tiles *small_sphere(int nb, int c)
{
    const int n[3] = {nb, nb, nb};
    const double h = 1.0 / nb;
    hv_tiles *P = calloc(1, sizeof *P);
    ck_assert_ptr_nonnull(P);
    memcpy(P->n, n, sizeof P->n);
    P->h = h;
    const int t0 = c, nt = 3;
    const double o0 = c + 8.5;
    P->count = nt * nt * nt;
    P->ijk = hv_malloc(3 * P->count * sizeof *P->ijk);
    P->v = hv_malloc(P->count * TCELLS * sizeof *P->v);
    P->on = hv_calloc(8 * P->count, sizeof *P->on);
    size_t q = 0;
    for (int tk = 0; tk < nt; tk++)
        for (int tj = 0; tj < nt; tj++)
            for (int ti = 0; ti < nt; ti++, q++) {
                P->ijk[3 * q] = t0 + 8 * ti;
                P->ijk[3 * q + 1] = t0 + 8 * tj;
                P->ijk[3 * q + 2] = t0 + 8 * tk;
                for (int o = 0; o < TCELLS; o++) {
                    const double x = t0 + 8 * ti + (o & 7) - o0,
                                 y = t0 + 8 * tj + ((o >> 3) & 7) - o0,
                                 z = t0 + 8 * tk + (o >> 6) - o0;
                    double d = sqrt(x * x + y * y + z * z) - 6;
                    d = d > 3 ? 3 : d < -3 ? -3 : d;
                    P->v[q * TCELLS + o] = (float)(d * h);
                    if (fabs(d) < 3) {
                        P->on[8 * q + (o >> 6)] |= (uint64_t)1 << (o & 63);
                        P->active++;
                    }
                }
            }
    return P;
}

START_TEST(an_extender_for_tiles_should_not_allocate_the_block)
{
    /* A 4096^3 block: 256 GB as one float field. The extender and a call on
     * a small sphere's band cost the tiles, not the block. */
    const int n[3] = {4096, 4096, 4096};
    const double h = 1.0 / 4096;
    hv_extender *e = NULL;
    TL_ASSERT_OK(hv_extender_create(&e, 3, n, h, NULL, NULL));
    hv_tiles *P = small_sphere(n[0], 1992), *F = NULL;
    TL_ASSERT_OK(hv_tiles_create_like(&F, P, 2.5f));
    hv_extend_tiles_field f = {1, {F, NULL, NULL}};
    hv_extend_stats st;
    TL_ASSERT_OK(hv_extend_tiles(e, P, 1, &f, &st));
    printf("  4096^3 block, sphere of 6 voxels: %zu tiles, %zu output cells, work %.1f MB\n",
           st.tiles, F->active, st.work_bytes / 1e6);
    ck_assert_uint_eq(F->active, P->active);
    ck_assert_msg(st.work_bytes < 64u << 20, "work %zu bytes", st.work_bytes);
    /* A constant comes back exactly. */
    double worst = 0;
    for (size_t c = 0; c < F->count * TCELLS; c++)
        if (F->on[8 * (c / TCELLS) + (c % TCELLS >> 6)] >> (c % 64) & 1)
            worst = fmax(worst, fabs(F->v[c] - 2.5));
    ck_assert_msg(worst <= 2e-6, "a constant came back off by %g", worst);
    hv_tiles_destroy(&F);
    hv_tiles_destroy(&P);
    hv_extender_destroy(&e);
}
END_TEST

/* The command's input in dir/in.vdb: a sphere's narrow band (class level
 * set, "surface") with a vector "v" and a scalar "temp" on the source band. */
static void write_band_input(nb_case *c, const char *dir, char *in, size_t size)
{
    const int n[3] = {44, 40, 36};
    const double c0[3] = {0.03, -0.02, 0.01};
    make_case(c, SPHERE, n, c0);
    for (size_t q = 0; q < hv_grid_count(c->phi); q++)
        if (c->in[0]->v[q] > 1e5f)
            for (int k = 0; k < 4; k++)
                c->in[k]->v[q] = 0; /* no garbage in a file */
    snprintf(in, size, "%s/in.vdb", dir);
    hv_vdb_writer *w = NULL;
    TL_ASSERT_OK(hv_vdb_writer_create(&w));
    TL_ASSERT_OK(hv_vdb_writer_add_levelset(w, c->phi, "surface", LS_BAND, 0));
    TL_ASSERT_OK(hv_vdb_writer_add_vec3(w, c->in[1], c->in[2], c->in[3], "v"));
    TL_ASSERT_OK(hv_vdb_writer_add_float(w, c->in[0], "temp"));
    TL_ASSERT_OK(hv_vdb_writer_write(w, in));
    hv_vdb_writer_destroy(&w);
}

/* heatvox extend on a level set: the tiles' path by default, its output
 * read back by OpenVDB's own reader (pyopenvdb): the active voxels are the
 * band's cells, with the values of the --dense path; NaN in the field fails
 * and leaves no file. */
START_TEST(command_should_extend_a_narrow_band_in_tiles)
{
    const char *bin = tl_heatvox_bin();
    if (!bin)
        TL_SKIP("no heatvox binary (build/heatvox or $HEATVOX_BIN)");
    ck_assert_msg(system("/usr/bin/python3 -c 'import pyopenvdb' >/dev/null 2>&1") == 0,
                  "pyopenvdb does not import in /usr/bin/python3 (package python3-openvdb)");
    nb_case c;
    char dir[] = "/tmp/hv_ext_tiles_XXXXXX", in[256], sp[256], dn[256], cmd[4096], err[4096];
    ck_assert_ptr_nonnull(mkdtemp(dir));
    write_band_input(&c, dir, in, sizeof in);
    snprintf(sp, sizeof sp, "%s/sparse.vdb", dir);
    snprintf(dn, sizeof dn, "%s/dense.vdb", dir);
    hv_vdb_writer *w = NULL;
    snprintf(cmd, sizeof cmd,
             "cd %s && %s extend in.vdb --levelset surface --field v --field temp --out-band 2.5 "
             "-o sparse.vdb -v",
             dir, bin);
    ck_assert_msg(tl_run_cmd(cmd, dir, err, sizeof err) == 0, "%s: %s", cmd, err);
    ck_assert_msg(strstr(err, "narrow band in") && strstr(err, "levels"), "-v says: %s", err);
    snprintf(cmd, sizeof cmd,
             "cd %s && %s extend in.vdb --levelset surface --field v --field temp --out-band 2.5 "
             "--dense -o dense.vdb -q",
             dir, bin);
    ck_assert_msg(tl_run_cmd(cmd, dir, err, sizeof err) == 0, "%s: %s", cmd, err);
    size_t want = 0;
    for (size_t q = 0; q < hv_grid_count(c.phi); q++)
        want += fabsf(c.phi->v[q]) < (float)(2.5 * c.h);
    /* OpenVDB's reader: the sparse grids' active voxels against the dense file's values. */
    snprintf(cmd, sizeof cmd,
             "/usr/bin/python3 -c 'import sys, pyopenvdb as vdb\n"
             "for name in (\"v\", \"temp\"):\n"
             "    a = vdb.read(sys.argv[1], name); b = vdb.read(sys.argv[2], name)\n"
             "    acc = b.getConstAccessor(); n = 0; worst = 0.0\n"
             "    for it in a.citerOnValues():\n"
             "        assert it.count == 1\n"
             "        x = it.value; y = acc.getValue(it.min); n += 1\n"
             "        if name == \"temp\": x, y = (x,), (y,)\n"
             "        for p, q in zip(x, y):\n"
             "            worst = max(worst, abs(p - q) / max(abs(q), 1e-3))\n"
             "    g = a.background; g = g if isinstance(g, tuple) else (g,)\n"
             "    print(name, n, worst, sum(abs(t) for t in g))\n"
             "s = vdb.read(sys.argv[1], \"surface\")\n"
             "print(\"surface\", s.activeVoxelCount(), s.gridClass)\n"
             "' %s %s",
             sp, dn);
    FILE *pp = popen(cmd, "r");
    ck_assert_ptr_nonnull(pp);
    char line[512];
    int seen = 0;
    while (fgets(line, sizeof line, pp)) {
        char name[32];
        size_t cnt;
        double worst, bg;
        if (sscanf(line, "%31s %zu %lf %lf", name, &cnt, &worst, &bg) == 4) {
            printf("  %s: %zu active voxels read back, expected %zu; largest difference to the "
                   "dense path %.2e\n",
                   name, cnt, want, worst);
            ck_assert_uint_eq(cnt, want);
            ck_assert_msg(worst <= 1e-6, "%s differs from the dense path by %g", name, worst);
            ck_assert(bg == 0);
            seen++;
        } else if (sscanf(line, "surface %zu", &cnt) == 1) {
            size_t act = 0;
            for (size_t q = 0; q < hv_grid_count(c.phi); q++)
                act += is_active(&c, q);
            ck_assert_uint_eq(cnt, act);
            ck_assert_ptr_nonnull(strstr(line, "level set"));
            seen++;
        }
    }
    ck_assert_int_eq(pclose(pp), 0);
    ck_assert_int_eq(seen, 3);

    /* NaN in the field where it is read: exit 1, the file named, nothing written. */
    for (size_t q = 0; q < hv_grid_count(c.phi); q++)
        if (fabsf(c.phi->v[q]) < 0.3f * (float)c.h) {
            c.in[1]->v[q] = NAN;
            break;
        }
    TL_ASSERT_OK(hv_vdb_writer_create(&w));
    TL_ASSERT_OK(hv_vdb_writer_add_levelset(w, c.phi, "surface", LS_BAND, 0));
    TL_ASSERT_OK(hv_vdb_writer_add_vec3(w, c.in[1], c.in[2], c.in[3], "v"));
    TL_ASSERT_OK(hv_vdb_writer_write(w, in));
    hv_vdb_writer_destroy(&w);
    snprintf(cmd, sizeof cmd, "cd %s && %s extend in.vdb --levelset surface --field v -o nan.vdb",
             dir, bin);
    ck_assert_int_eq(tl_run_cmd(cmd, dir, err, sizeof err), 1);
    ck_assert_msg(strstr(err, "in.vdb") && strstr(err, "NaN"), "message: %s", err);
    snprintf(cmd, sizeof cmd, "%s/nan.vdb", dir);
    ck_assert_int_ne(access(cmd, F_OK), 0);
    free_case(&c);
    tl_rm_rf(dir);
}
END_TEST

/* ---- on a device ------------------------------------------------------------ */

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

/* The case's scalar and vector on tiles, extended by e (fresh tiles). */
static void extend_on(const nb_case *c, hv_extender *e, hv_tiles *F[4], hv_extend_stats *S)
{
    hv_tiles *P = tiles_of(c, c->phi);
    for (int q = 0; q < 4; q++)
        F[q] = tiles_of(c, c->in[q]);
    hv_extend_tiles_field tf[2] = {{1, {F[0], NULL, NULL}}, {3, {F[1], F[2], F[3]}}};
    TL_ASSERT_OK(hv_extend_tiles(e, P, 2, tf, S));
    hv_tiles_destroy(&P);
}

/* The device extender dev gives the host extender's values bit for bit,
 * the same active voxels and the same counts. */
static void expect_device_equal(const nb_case *c, hv_extender *host, hv_extender *dev,
                                const char *what)
{
    hv_tiles *A[4], *B[4];
    hv_extend_stats sa, sb;
    extend_on(c, host, A, &sa);
    extend_on(c, dev, B, &sb);
    size_t diff = 0, ondiff = 0;
    double worst = 0;
    for (int q = 0; q < 4; q++) {
        ck_assert_uint_eq(A[q]->count, B[q]->count);
        for (size_t v = 0; v < A[q]->count * TCELLS; v++) {
            const float a = A[q]->v[v], b = B[q]->v[v];
            if (memcmp(&a, &b, sizeof a)) {
                if (!diff++)
                    printf("  %s: component %d, value %zu: host %.9g, device %.9g\n", what, q, v, a,
                           b);
                worst = fmax(worst, fabs(a - b) / fmax(fabs(a), 1e-3));
            }
        }
        for (size_t w = 0; w < 8 * A[q]->count; w++)
            ondiff += A[q]->on[w] != B[q]->on[w];
        ck_assert_uint_eq(A[q]->active, B[q]->active);
    }
    printf("check_extend_tiles: %s on the device: %zu tiles, %zu active, %zu values apart "
           "(worst %.3g), levels %d/%d, solve cells %zu/%zu, cp %zu/%zu, ratio %zu/%zu, "
           "weak %zu/%zu\n",
           what, A[0]->count, A[0]->active, diff, worst, sa.levels, sb.levels, sa.solve_cells,
           sb.solve_cells, sa.cp_cells, sb.cp_cells, sa.ratio_cells, sb.ratio_cells, sa.weak_cells,
           sb.weak_cells);
    ck_assert_msg(diff == 0 && ondiff == 0, "%s: %zu values and %zu active words differ", what,
                  diff, ondiff);
    ck_assert_int_eq(sa.levels, sb.levels);
    ck_assert_uint_eq(sa.solve_cells, sb.solve_cells);
    ck_assert_uint_eq(sa.source_cells, sb.source_cells);
    ck_assert_uint_eq(sa.cp_cells, sb.cp_cells);
    ck_assert_uint_eq(sa.ratio_cells, sb.ratio_cells);
    ck_assert_uint_eq(sa.weak_cells, sb.weak_cells);
    ck_assert_int_eq(sa.solves, sb.solves);
    ck_assert_msg(fabs(sa.relres - sb.relres) <= 1e-6 * sa.relres + 1e-12, "relres %g %g",
                  sa.relres, sb.relres);
    for (int q = 0; q < 4; q++) {
        hv_tiles_destroy(&A[q]);
        hv_tiles_destroy(&B[q]);
    }
}

START_TEST(device_should_equal_the_host_on_bands)
{
    if (!have_device())
        return;
    hv_extend_opts o;
    hv_extend_opts_default(&o);
    o.backend = HV_BACKEND_MG;
    hv_extend_opts od = o;
    od.backend = HV_BACKEND_OPENCL;
    {
        const int n[3] = {61, 57, 54};
        const double c0[3] = {0.05, -0.03, 0.02};
        nb_case c;
        make_case(&c, SPHERE, n, c0);
        for (int pass = 0; pass < 3; pass++) {
            o.out_band = od.out_band = pass == 0 ? LS_BAND : pass == 1 ? 2 : 0;
            hv_extender *h = NULL, *d = NULL;
            TL_ASSERT_OK(hv_extender_create(&h, 3, c.n, c.h, NULL, &o));
            TL_ASSERT_OK(hv_extender_create(&d, 3, c.n, c.h, NULL, &od));
            expect_device_equal(&c, h, d,
                                pass == 0   ? "sphere, band 3"
                                : pass == 1 ? "sphere, band 2"
                                            : "sphere, every voxel");
            hv_extender_destroy(&h);
            hv_extender_destroy(&d);
        }
        /* Cells read at themselves, and a short first level that leaves
         * cells to the next. */
        o.out_band = od.out_band = LS_BAND;
        o.closest_point = od.closest_point = 0;
        o.t_scale = od.t_scale = 0.02;
        hv_extender *h = NULL, *d = NULL;
        TL_ASSERT_OK(hv_extender_create(&h, 3, c.n, c.h, NULL, &o));
        TL_ASSERT_OK(hv_extender_create(&d, 3, c.n, c.h, NULL, &od));
        expect_device_equal(&c, h, d, "sphere, at the cells, two levels");
        hv_extender_destroy(&h);
        hv_extender_destroy(&d);
        free_case(&c);
    }
    hv_extend_opts_default(&o);
    o.backend = HV_BACKEND_MG;
    od = o;
    od.backend = HV_BACKEND_OPENCL;
    {
        /* Against the block's walls: one-sided differences and clamped
         * stencils; one extender each for three steps of a moving sphere. */
        const int n[3] = {40, 44, 36};
        hv_extender *h = NULL, *d = NULL;
        TL_ASSERT_OK(hv_extender_create(&h, 3, n, 2.0 / n[0], NULL, &o));
        TL_ASSERT_OK(hv_extender_create(&d, 3, n, 2.0 / n[0], NULL, &od));
        for (int step = 0; step < 3; step++) {
            const double c0[3] = {0.45 - 0.2 * step, -0.5 + 0.1 * step, 0.55};
            nb_case c;
            make_case(&c, SPHERE, n, c0);
            expect_device_equal(&c, h, d, "sphere through the walls");
            free_case(&c);
        }
        hv_extender_destroy(&h);
        hv_extender_destroy(&d);
    }
    if (!tl_sanitized()) {
        const int n[3] = {128, 128, 64};
        const double c0[3] = {0.02, 0.01, -0.5 + 0.013};
        nb_case c;
        make_case(&c, TORUS, n, c0);
        o.out_band = od.out_band = LS_BAND;
        hv_extender *h = NULL, *d = NULL;
        TL_ASSERT_OK(hv_extender_create(&h, 3, c.n, c.h, NULL, &o));
        TL_ASSERT_OK(hv_extender_create(&d, 3, c.n, c.h, NULL, &od));
        expect_device_equal(&c, h, d, "torus, band 3");
        hv_extender_destroy(&h);
        hv_extender_destroy(&d);
        free_case(&c);
    }
}
END_TEST

/* Bytes of scalars a device call moves each way at most: the counters and
 * the fields' layout in, per level the domain's size, the residual's 3 R
 * sums and the level's counts out (R = 6: a scalar and a vector). */
#define SCALARS_IN(levels) (96.0 + 8 + 16.0 * (levels))
#define SCALARS_OUT(levels) (2 * 96.0 + (4 + 3 * 6 * 8 + 16.0) * (levels))

/* On host tiles, a device run moves the level set and the fields in, the
 * fields out, and scalars; on device buffers, scalars only. */
START_TEST(device_runs_should_move_their_inputs_and_outputs_only)
{
    if (!have_device())
        return;
    const int n[3] = {96, 96, 96};
    const double c0[3] = {0.02, 0.01, -0.013};
    nb_case c;
    make_case(&c, TORUS, n, c0);
    hv_extend_opts o;
    hv_extend_opts_default(&o);
    o.backend = HV_BACKEND_OPENCL;
    o.out_band = LS_BAND;
    hv_extender *d = NULL;
    TL_ASSERT_OK(hv_extender_create(&d, 3, c.n, c.h, NULL, &o));
    double in, out;
    long reads;
    hv_tiles *F[4];
    hv_extend_stats S;
    extend_on(&c, d, F, &S); /* the first call builds the program */
    for (int q = 0; q < 4; q++)
        hv_tiles_destroy(&F[q]);
    tl_cl_traffic(&in, &out, &reads);
    extend_on(&c, d, F, &S);
    tl_cl_traffic(&in, &out, &reads);
    const double T = (double)F[0]->count, L = S.levels;
    const double want_in = T * (12 + 2048 + 64) + 4 * T * 2048, want_out = 4 * T * (2048 + 64);
    printf("check_extend_tiles: torus 96^3 on the device: %.0f tiles, %d levels; %.0f bytes in "
           "(inputs %.0f), %.0f out (outputs %.0f), %ld reads\n",
           T, S.levels, in, want_in, out, want_out, reads);
    ck_assert_msg(in >= want_in && in <= want_in + SCALARS_IN(L), "%.0f bytes in", in);
    ck_assert_msg(out >= want_out && out <= want_out + SCALARS_OUT(L), "%.0f bytes out", out);
    /* the counters twice, per level 3 reads, each component's values and words */
    ck_assert_msg(reads <= 2 + 3 * (long)S.levels + 2 * 4, "%ld reads", reads);
    /* The same level set and fields as device buffers on the extender's
     * context: only scalars cross, and the values are the host tiles'. */
    cl_context ctx;
    cl_command_queue queue;
    TL_ASSERT_OK(hv_opencl_extender_queue(d, &ctx, NULL, &queue));
    hv_tiles *P = tiles_of(&c, c.phi), *G[4];
    hv_opencl_tiles dp = {P->count, NULL, NULL, NULL};
    cl_int e;
    const size_t vb = P->count * TCELLS * sizeof(float), ob = 8 * P->count * sizeof(uint64_t);
    dp.ijk = clCreateBuffer(ctx, CL_MEM_READ_WRITE | CL_MEM_COPY_HOST_PTR,
                            3 * P->count * sizeof(int32_t), P->ijk, &e);
    dp.v = clCreateBuffer(ctx, CL_MEM_READ_WRITE | CL_MEM_COPY_HOST_PTR, vb, P->v, &e);
    dp.on = clCreateBuffer(ctx, CL_MEM_READ_WRITE | CL_MEM_COPY_HOST_PTR, ob, P->on, &e);
    ck_assert_int_eq(e, CL_SUCCESS);
    cl_mem fv[4], fo[4];
    for (int q = 0; q < 4; q++) {
        G[q] = tiles_of(&c, c.in[q]);
        fv[q] = clCreateBuffer(ctx, CL_MEM_READ_WRITE | CL_MEM_COPY_HOST_PTR, vb, G[q]->v, &e);
        fo[q] = clCreateBuffer(ctx, CL_MEM_READ_WRITE, ob, NULL, &e);
        ck_assert_int_eq(e, CL_SUCCESS);
    }
    hv_opencl_tiles_field df[2] = {{1, {fv[0], NULL, NULL}, {fo[0], NULL, NULL}},
                                   {3, {fv[1], fv[2], fv[3]}, {fo[1], fo[2], fo[3]}}};
    tl_cl_traffic(&in, &out, &reads);
    TL_ASSERT_OK(hv_opencl_extend_tiles(d, &dp, 2, df, &S));
    tl_cl_traffic(&in, &out, &reads);
    printf("check_extend_tiles: the same on device buffers: %.0f bytes in, %.0f out, %ld reads\n",
           in, out, reads);
    ck_assert_msg(in <= SCALARS_IN(S.levels), "%.0f bytes in", in);
    ck_assert_msg(out <= SCALARS_OUT(S.levels), "%.0f bytes out", out);
    ck_assert_msg(reads <= 2 + 3 * (long)S.levels, "%ld reads", reads);
    for (int q = 0; q < 4; q++) {
        ck_assert_int_eq(clEnqueueReadBuffer(queue, fv[q], CL_TRUE, 0, vb, G[q]->v, 0, NULL, NULL),
                         CL_SUCCESS);
        ck_assert_int_eq(clEnqueueReadBuffer(queue, fo[q], CL_TRUE, 0, ob, G[q]->on, 0, NULL, NULL),
                         CL_SUCCESS);
        ck_assert_msg(!memcmp(G[q]->v, F[q]->v, vb) && !memcmp(G[q]->on, F[q]->on, ob),
                      "component %d: the buffers' extension differs from the tiles'", q);
        clReleaseMemObject(fv[q]);
        clReleaseMemObject(fo[q]);
        hv_tiles_destroy(&G[q]);
        hv_tiles_destroy(&F[q]);
    }
    /* A buffer too small is refused, naming it. */
    dp.count = P->count + 1;
    ck_assert_int_eq(hv_opencl_extend_tiles(d, &dp, 2, df, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "hv_opencl_extend_tiles"));
    clReleaseMemObject(dp.ijk);
    clReleaseMemObject(dp.v);
    clReleaseMemObject(dp.on);
    hv_tiles_destroy(&P);
    hv_extender_destroy(&d);
    free_case(&c);
}
END_TEST

/* The command with --backend opencl extends the band on the device and
 * writes the host's file: OpenVDB reads the same active voxels and values;
 * a NaN where the field is read fails the same way, writing nothing. */
START_TEST(command_should_extend_the_band_on_the_device)
{
    if (!have_device())
        return;
    const char *bin = tl_heatvox_bin();
    if (!bin)
        TL_SKIP("no heatvox binary (build/heatvox or $HEATVOX_BIN)");
    nb_case c;
    char dir[] = "/tmp/hv_ext_tiles_cl_XXXXXX", in[256], cmd[4096], err[4096];
    ck_assert_ptr_nonnull(mkdtemp(dir));
    write_band_input(&c, dir, in, sizeof in);
    const char *be[2] = {"mg", "opencl"};
    for (int b = 0; b < 2; b++) {
        snprintf(cmd, sizeof cmd,
                 "cd %s && %s extend in.vdb --levelset surface --field v --field temp "
                 "--out-band 2.5 -o %s.vdb --backend %s -v",
                 dir, bin, be[b], be[b]);
        ck_assert_msg(tl_run_cmd(cmd, dir, err, sizeof err) == 0, "%s: %s", cmd, err);
        ck_assert_msg(!b == !strstr(err, "on the device"), "--backend %s: -v says %s", be[b], err);
    }
    snprintf(
        cmd, sizeof cmd,
        "/usr/bin/python3 -c 'import sys, pyopenvdb as vdb\n"
        "for name in (\"v\", \"temp\", \"surface\"):\n"
        "    a = vdb.read(sys.argv[1], name); b = vdb.read(sys.argv[2], name)\n"
        "    acc = b.getConstAccessor(); n = 0; apart = 0\n"
        "    for it in a.citerOnValues():\n"
        "        n += 1; apart += acc.getValue(it.min) != it.value or not acc.isValueOn(it.min)\n"
        "    print(name, n, b.activeVoxelCount(), apart)\n"
        "' %s/mg.vdb %s/opencl.vdb",
        dir, dir);
    FILE *pp = popen(cmd, "r");
    ck_assert_ptr_nonnull(pp);
    char line[512];
    int seen = 0;
    while (fgets(line, sizeof line, pp)) {
        char name[32];
        size_t na, nb, apart;
        ck_assert_int_eq(sscanf(line, "%31s %zu %zu %zu", name, &na, &nb, &apart), 4);
        printf("  %s: %zu active voxels on the host, %zu on the device, %zu apart\n", name, na, nb,
               apart);
        ck_assert(na > 1000 && na == nb && apart == 0);
        seen++;
    }
    ck_assert_int_eq(pclose(pp), 0);
    ck_assert_int_eq(seen, 3);
    for (size_t q = 0; q < hv_grid_count(c.phi); q++)
        if (fabsf(c.phi->v[q]) < 0.3f * (float)c.h) {
            c.in[0]->v[q] = NAN;
            break;
        }
    hv_vdb_writer *w = NULL;
    TL_ASSERT_OK(hv_vdb_writer_create(&w));
    TL_ASSERT_OK(hv_vdb_writer_add_levelset(w, c.phi, "surface", LS_BAND, 0));
    TL_ASSERT_OK(hv_vdb_writer_add_float(w, c.in[0], "temp"));
    TL_ASSERT_OK(hv_vdb_writer_write(w, in));
    hv_vdb_writer_destroy(&w);
    snprintf(cmd, sizeof cmd,
             "cd %s && %s extend in.vdb --levelset surface --field temp -o nan.vdb --backend "
             "opencl",
             dir, bin);
    ck_assert_int_eq(tl_run_cmd(cmd, dir, err, sizeof err), 1);
    ck_assert_msg(strstr(err, "in.vdb") && strstr(err, "NaN"), "message: %s", err);
    snprintf(cmd, sizeof cmd, "%s/nan.vdb", dir);
    ck_assert_int_ne(access(cmd, F_OK), 0);
    free_case(&c);
    tl_rm_rf(dir);
}
END_TEST

/* The number after "key": in a JSON line, or -1; the text after it in *at. */
static double json_num(const char *line, const char *key, const char **at)
{
    char pat[64];
    snprintf(pat, sizeof pat, "\"%s\":", key);
    const char *p = strstr(line, pat);
    if (at)
        *at = p ? p + strlen(pat) : NULL;
    return p ? atof(p + strlen(pat)) : -1;
}

/* The JSON line of `heatvox ARGS` (the first that starts {"bench":) into
 * line; the rest of its output read to the end. */
static void bench_line(const char *args, char *line, size_t size)
{
    char cmd[8400], buf[8192];
    snprintf(cmd, sizeof cmd, "env -u HEATVOX_OPENCL_PROFILE '%s' %s", tl_heatvox_bin(), args);
    FILE *pp = popen(cmd, "r");
    ck_assert_ptr_nonnull(pp);
    line[0] = 0;
    while (fgets(buf, sizeof buf, pp))
        if (!line[0] && !strncmp(buf, "{\"bench\":", 9))
            snprintf(line, size, "%s", buf);
    ck_assert_int_eq(pclose(pp), 0);
    ck_assert_msg(line[0], "%s printed no JSON line", cmd);
}

/* bench extend-loop and extend-band with --backend opencl: the host's errors
 * (the same values), and the device's figures beside them. */
START_TEST(benches_should_report_the_device_and_its_figures)
{
    if (!have_device())
        return;
    if (!tl_heatvox_bin())
        TL_SKIP("no heatvox binary (build/heatvox or $HEATVOX_BIN)");
    char args[4200], host[8192], dev[8192];
    const char *data = tl_test_data();
    for (int b = 0; b < 2; b++) {
        if (b == 1 && !data) {
            tl_skip("no shared meshes: bench extend-band left out");
            break;
        }
        const char *be[2] = {"mg", "opencl"};
        char *out[2] = {host, dev};
        for (int k = 0; k < 2; k++) {
            if (b == 0)
                snprintf(args, sizeof args, "bench extend-loop --n 48 --steps 3 --backend %s",
                         be[k]);
            else
                snprintf(args, sizeof args,
                         "bench extend-band '%s/bunny_small.obj' --n 48 --backend %s", data, be[k]);
            bench_line(args, out[k], sizeof host);
        }
        printf("  %s", dev);
        const char *keys[] = {"err", "ref_err", "err_all", "cells"};
        for (size_t q = 0; q < sizeof keys / sizeof keys[0]; q++) {
            const char *a, *c;
            json_num(host, keys[q], &a);
            json_num(dev, keys[q], &c);
            ck_assert_msg(a && c && strcspn(a, ",") == strcspn(c, ",") &&
                              !strncmp(a, c, strcspn(a, ",")),
                          "%s: host %s, device %s", keys[q], host, dev);
        }
        ck_assert_ptr_nonnull(strstr(dev, "\"backend\":\"opencl\""));
        ck_assert_ptr_nonnull(strstr(dev, "\"device\":\""));
        const char *pos[] = {
            "device_seconds", "host_bytes_in", "host_bytes_out", "launches", "copy_gbs",
            "sweeps",         "eval"};
        for (size_t q = 0; q < sizeof pos / sizeof pos[0]; q++)
            ck_assert_msg(json_num(dev, pos[q], NULL) > 0, "%s: %s", pos[q], dev);
        ck_assert_ptr_null(strstr(host, "\"device\":"));
    }
}
END_TEST

/* tools/examples/advect_band_cl, beside the command: a sphere's band on the
 * device advected for a few steps, its velocity extended each step with
 * hv_opencl_extend_tiles; the program checks the sphere and the velocity,
 * and heatvox moves only scalars between host and device. */
START_TEST(example_should_advect_a_band_on_the_device)
{
    if (!have_device())
        return;
    const char *bin = tl_heatvox_bin();
    if (!bin)
        TL_SKIP("no heatvox binary (build/heatvox or $HEATVOX_BIN)");
    char ex[4096], cmd[8400], out[8192];
    snprintf(ex, sizeof ex, "%s", bin);
    char *slash = strrchr(ex, '/');
    snprintf(slash ? slash + 1 : ex, sizeof ex - (size_t)(slash ? slash + 1 - ex : 0),
             "examples/advect_band_cl");
    ck_assert_msg(access(ex, X_OK) == 0, "%s not built (make check builds it)", ex);
    snprintf(cmd, sizeof cmd, "HEATVOX_OPENCL_PROFILE=1 '%s' --n 40 --steps 10 2>&1", ex);
    FILE *pp = popen(cmd, "r");
    ck_assert_ptr_nonnull(pp);
    const size_t got = fread(out, 1, sizeof out - 1, pp);
    out[got] = 0;
    const int rc = pclose(pp);
    printf("%s", out);
    ck_assert_msg(rc == 0, "advect_band_cl failed: %s", out);
    const char *m = strstr(out, "heatvox moved ");
    double in = -1, to_host = -1;
    ck_assert_ptr_nonnull(m);
    ck_assert_int_eq(
        sscanf(m, "heatvox moved %lf bytes to the device and %lf to the host", &in, &to_host), 2);
    /* per step: the counters and, per level, the domain's size, the
     * residual's sums and the counts (two levels at most here) */
    ck_assert_msg(in > 0 && in <= SCALARS_IN(2) && to_host > 0 && to_host <= SCALARS_OUT(2),
                  "%.0f bytes in, %.0f out a step", in, to_host);
    ck_assert_ptr_nonnull(strstr(out, "voxels off"));
}
END_TEST

/* auto takes the device where a solve would (HEATVOX_AUTO_OPENCL=1 on a CPU
 * device) and the host where not; past the device's 17 right-hand sides
 * auto falls back to the host, an explicit opencl says why. */
START_TEST(auto_should_take_the_device_where_it_can)
{
    if (!have_device())
        return;
    const int n[3] = {32, 32, 32};
    const double c0[3] = {0.01, 0.02, -0.01};
    nb_case c;
    make_case(&c, SPHERE, n, c0);
    hv_tiles *P = tiles_of(&c, c.phi);
    enum { NF = 5 };
    hv_tiles *F[NF][3];
    hv_extend_tiles_field f[NF];
    for (int i = 0; i < NF; i++) {
        f[i].ncomp = 3;
        for (int q = 0; q < 3; q++)
            f[i].v[q] = F[i][q] = tiles_of(&c, c.in[1 + q]);
    }
    const char *env[3] = {"1", "0", "1"};
    for (int pass = 0; pass < 3; pass++) {
        setenv("HEATVOX_AUTO_OPENCL", env[pass], 1);
        hv_extend_opts o;
        hv_extend_opts_default(&o);
        hv_extender *e = NULL;
        TL_ASSERT_OK(hv_extender_create(&e, 3, n, c.h, NULL, &o));
        hv_extend_stats S;
        /* passes 0, 1: one vector (R = 5); pass 2: five (R = 21) */
        TL_ASSERT_OK(hv_extend_tiles(e, P, pass == 2 ? NF : 1, f, &S));
        ck_assert_int_eq(S.on_device, pass == 0);
        ck_assert_uint_eq(S.cp_cells + S.ratio_cells, P->active);
        hv_extender_destroy(&e);
    }
    unsetenv("HEATVOX_AUTO_OPENCL");
    hv_extend_opts o;
    hv_extend_opts_default(&o);
    o.backend = HV_BACKEND_OPENCL;
    hv_extender *e = NULL;
    TL_ASSERT_OK(hv_extender_create(&e, 3, n, c.h, NULL, &o));
    ck_assert_int_eq(hv_extend_tiles(e, P, NF, f, NULL), HV_ERR_UNSUPPORTED);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "right-hand sides"));
    hv_extender_destroy(&e);
    for (int i = 0; i < NF; i++)
        for (int q = 0; q < 3; q++)
            hv_tiles_destroy(&F[i][q]);
    hv_tiles_destroy(&P);
    free_case(&c);
}
END_TEST

/* A shared mesh's narrow band (hv_sdf_compute_tiles, 3 voxels) with a
 * smooth vector and scalar known within 1.5 voxels: the device's extension
 * is the host's bit for bit. */
static void expect_mesh_equal(const char *name, int res)
{
    hv_mesh *m = tu_load_shared(name);
    if (!m)
        return;
    hv_sdf_opts so;
    hv_sdf_opts_default(&so);
    so.res = res;
    hv_tiles *P = NULL, *A[4], *B[4];
    hv_sdf_stats ss;
    TL_ASSERT_OK(hv_sdf_compute_tiles(m, &so, 3, &P, &ss));
    hv_mesh_destroy(&m);
    for (int q = 0; q < 4; q++) {
        TL_ASSERT_OK(hv_tiles_create_like(&A[q], P, 0.0f));
        TL_ASSERT_OK(hv_tiles_create_like(&B[q], P, 0.0f));
    }
    for (size_t t = 0; t < P->count; t++)
        for (int o = 0; o < TCELLS; o++) {
            double x[3], v[3];
            for (int a = 0; a < 3; a++)
                x[a] = P->origin[a] + (P->ijk[3 * t + a] +
                                       (a == 0   ? o & 7
                                        : a == 1 ? o >> 3 & 7
                                                 : o >> 6) +
                                       0.5) *
                                          P->h;
            g_vector(x, v);
            const size_t c = t * TCELLS + o;
            const int src = fabsf(P->v[c]) < 1.5f * (float)P->h;
            A[0]->v[c] = B[0]->v[c] = src ? (float)g_scalar(x) : 1e6f;
            for (int q = 0; q < 3; q++)
                A[1 + q]->v[c] = B[1 + q]->v[c] = src ? (float)v[q] : 1e6f;
        }
    hv_extend_opts o;
    hv_extend_opts_default(&o);
    o.backend = HV_BACKEND_MG;
    hv_extender *h = NULL, *d = NULL;
    TL_ASSERT_OK(hv_extender_create(&h, 3, P->n, P->h, NULL, &o));
    o.backend = HV_BACKEND_OPENCL;
    TL_ASSERT_OK(hv_extender_create(&d, 3, P->n, P->h, NULL, &o));
    hv_extend_tiles_field fa[2] = {{1, {A[0], NULL, NULL}}, {3, {A[1], A[2], A[3]}}};
    hv_extend_tiles_field fb[2] = {{1, {B[0], NULL, NULL}}, {3, {B[1], B[2], B[3]}}};
    hv_extend_stats sa, sb;
    TL_ASSERT_OK(hv_extend_tiles(h, P, 2, fa, &sa));
    TL_ASSERT_OK(hv_extend_tiles(d, P, 2, fb, &sb));
    size_t diff = 0;
    for (int q = 0; q < 4; q++) {
        diff += memcmp(A[q]->v, B[q]->v, P->count * TCELLS * sizeof(float)) != 0;
        diff += memcmp(A[q]->on, B[q]->on, 8 * P->count * sizeof(uint64_t)) != 0;
    }
    printf("check_extend_tiles: %s at %d on the device: %zu tiles, %zu output voxels, %d levels, "
           "%zu solve cells; %zu of 8 arrays differ\n",
           name, res, P->count, A[0]->active, sb.levels, sb.solve_cells, diff);
    ck_assert_msg(diff == 0, "%s: the device's extension differs from the host's", name);
    ck_assert_int_eq(sa.levels, sb.levels);
    ck_assert_uint_eq(sa.solve_cells, sb.solve_cells);
    ck_assert_uint_gt(A[0]->active, 1000);
    hv_extender_destroy(&h);
    hv_extender_destroy(&d);
    for (int q = 0; q < 4; q++) {
        hv_tiles_destroy(&A[q]);
        hv_tiles_destroy(&B[q]);
    }
    hv_tiles_destroy(&P);
}

START_TEST(device_should_equal_the_host_on_shared_meshes)
{
    if (!have_device())
        return;
    const char *names[] = {"bunny_small.obj", "armadillo_bad.obj", "chair.obj", "knot.obj",
                           "spot.obj"};
    for (size_t k = 0; k < sizeof names / sizeof names[0]; k++) {
        if (tl_sanitized() && k > 0)
            break;
        expect_mesh_equal(names[k], 80);
    }
}
END_TEST

/* A block past 2^31 cells (1296^3): the device's band extension keeps maps
 * of its tiles only (1.1 GB here) and gives the host's values. */
START_TEST(device_should_extend_a_band_on_a_block_past_2_31_cells)
{
    if (!have_device())
        return;
    if (tl_sanitized())
        TL_SKIP("a 1.1 GB device map under the sanitizers: make check runs it");
    const int nb = 1296, n[3] = {nb, nb, nb};
    hv_tiles *P = small_sphere(nb, 1000), *F[2][3];
    hv_extend_stats S[2];
    for (int b = 0; b < 2; b++) {
        hv_extend_opts o;
        hv_extend_opts_default(&o);
        o.backend = b ? HV_BACKEND_OPENCL : HV_BACKEND_MG;
        hv_extender *e = NULL;
        TL_ASSERT_OK(hv_extender_create(&e, 3, n, 1.0 / nb, NULL, &o));
        for (int q = 0; q < 3; q++)
            TL_ASSERT_OK(hv_tiles_create_like(&F[b][q], P, 1.0f + q));
        hv_extend_tiles_field f = {3, {F[b][0], F[b][1], F[b][2]}};
        TL_ASSERT_OK(hv_extend_tiles(e, P, 1, &f, &S[b]));
        hv_extender_destroy(&e);
    }
    ck_assert_int_eq(S[1].on_device, 1);
    for (int q = 0; q < 3; q++) {
        ck_assert_uint_eq(F[1][q]->active, P->active);
        ck_assert(!memcmp(F[0][q]->v, F[1][q]->v, P->count * TCELLS * sizeof(float)));
        ck_assert(!memcmp(F[0][q]->on, F[1][q]->on, 8 * P->count * sizeof(uint64_t)));
        hv_tiles_destroy(&F[0][q]);
        hv_tiles_destroy(&F[1][q]);
    }
    printf("check_extend_tiles: 1296^3 block on the device: %zu tiles, %zu output voxels as the "
           "host's; device memory %.0f MB\n",
           P->count, P->active, S[1].work_bytes / 1e6);
    hv_tiles_destroy(&P);
}
END_TEST

int main(int argc, char **argv)
{
    (void)argc;
    /* Every queue counts its traffic (before the first OpenCL call). */
    setenv("HEATVOX_OPENCL_PROFILE", "1", 1);
    tl_pocl_cache(argv[0]);
    Suite *s = suite_create("extend_tiles");
    TCase *tc = tcase_create("core");
    tcase_set_timeout(tc, 300);
    tcase_add_test(tc, sparse_should_equal_dense_on_a_sphere_band);
    tcase_add_test(tc, sparse_should_equal_dense_on_a_torus_band);
    tcase_add_test(tc, one_extender_should_follow_a_moving_band);
    tcase_add_test(tc, bad_input_should_fail_without_output);
    tcase_add_test(tc, an_extender_for_tiles_should_not_allocate_the_block);
    tcase_add_test(tc, command_should_extend_a_narrow_band_in_tiles);
    tcase_add_test(tc, device_should_equal_the_host_on_bands);
    tcase_add_test(tc, device_should_equal_the_host_on_shared_meshes);
    tcase_add_test(tc, device_runs_should_move_their_inputs_and_outputs_only);
    tcase_add_test(tc, command_should_extend_the_band_on_the_device);
    tcase_add_test(tc, benches_should_report_the_device_and_its_figures);
    tcase_add_test(tc, example_should_advect_a_band_on_the_device);
    tcase_add_test(tc, auto_should_take_the_device_where_it_can);
    tcase_add_test(tc, device_should_extend_a_band_on_a_block_past_2_31_cells);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
