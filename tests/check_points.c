/* Oriented point clouds: the readers (text and PLY, their errors), and the
 * surface hv_points_surface finds against known truth: points on a sphere
 * (analytic distance) and on the shared meshes (the intact mesh's solid),
 * clean and with uneven density, noise, flipped normals and a missing
 * patch. Errors in voxels of the grid. */
#include "heatvox/heatvox.h"
#include "sdf/sdf_internal.h"
#include "testlib.h"

#include <check.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static char dir[64];

static void setup(void)
{
    snprintf(dir, sizeof dir, "/tmp/hv_points_XXXXXX");
    ck_assert_ptr_nonnull(mkdtemp(dir));
}

static void teardown(void) { tl_rm_rf(dir); }

static const char *write_file(const char *name, const char *text, size_t len)
{
    static char path[128];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    FILE *f = fopen(path, "wb");
    ck_assert_ptr_nonnull(f);
    ck_assert_uint_eq(fwrite(text, 1, len, f), len);
    fclose(f);
    return path;
}

/* Reads path expecting failure with status want and a message containing
 * each of the NULL-terminated words. */
static void expect_error(const char *path, hv_status want, const char *const *words)
{
    hv_points *P = NULL;
    hv_status st = hv_points_read(path, &P);
    ck_assert_msg(st == want, "%s: got %s (%s)", path, hv_status_str(st), hv_last_error());
    ck_assert_ptr_null(P);
    for (; *words; words++)
        ck_assert_msg(strstr(hv_last_error(), *words), "'%s' lacks '%s'", hv_last_error(), *words);
}

START_TEST(text_reader)
{
    const char *t = "# a comment\r\n1 2 3 0 0 2\r\n\r\n  4 5 6  -3 0 4 0.5 0.5  # more columns\n";
    const char *path = write_file("a.xyz", t, strlen(t));
    ck_assert_int_eq(hv_points_file(path), 1);
    hv_points *P = NULL;
    TL_ASSERT_OK(hv_points_read(path, &P));
    ck_assert_uint_eq(P->count, 2);
    ck_assert_double_eq(P->xyz[3], 4);
    ck_assert_double_eq_tol(P->normals[2], 1, 1e-15);
    ck_assert_double_eq_tol(P->normals[3], -0.6, 1e-15);
    ck_assert_double_eq_tol(P->normals[5], 0.8, 1e-15);
    hv_points_destroy(&P);
    ck_assert_ptr_null(P);
}
END_TEST

/* Clouds without normals: x y z per line, the normals NULL. */
START_TEST(text_unoriented)
{
    const char *t = "# x y z\n0 0 0\n1 2 3 # a comment\n\n4 5 6\n";
    hv_points *P = NULL;
    TL_ASSERT_OK(hv_points_read(write_file("u.xyz", t, strlen(t)), &P));
    ck_assert_uint_eq(P->count, 3);
    ck_assert_ptr_null(P->normals);
    ck_assert_double_eq(P->xyz[8], 6);
    hv_points_destroy(&P);
    const double x[6] = {0, 0, 0, 1, 1, 1};
    TL_ASSERT_OK(hv_points_from_arrays(&P, x, NULL, 2));
    ck_assert_ptr_null(P->normals);
    hv_points_destroy(&P);
    const char *nan = "0 0 0\n1 nan 3\n";
    expect_error(write_file("n.xyz", nan, strlen(nan)), HV_ERR_NUMERIC,
                 (const char *[]){"n.xyz", "line 2", "coordinate y", NULL});
}
END_TEST

START_TEST(text_errors)
{
    const char *t1 = "0 0 0 1 0 0\n1 2 3\n";
    expect_error(write_file("u.xyz", t1, strlen(t1)), HV_ERR_PARSE,
                 (const char *[]){"u.xyz", "line 2",
                                  "x y z without a normal, where the points "
                                  "before have normals",
                                  NULL});
    const char *t0 = "# bare\n0 0 0\n1 0 0 1 0 0\n";
    expect_error(
        write_file("v.xyz", t0, strlen(t0)), HV_ERR_PARSE,
        (const char *[]){"v.xyz", "line 3", "a normal, where the points before have none", NULL});
    const char *t2 = "0 0 0 1 0 0\n\n0 0 x 1 0 0\n";
    expect_error(write_file("b.xyz", t2, strlen(t2)), HV_ERR_PARSE,
                 (const char *[]){"b.xyz", "line 3", "column 3 is not a number (x)", NULL});
    const char *t3 = "0 0 0 1 0 0\n0 0 0 0 0 0\n";
    expect_error(write_file("z.xyz", t3, strlen(t3)), HV_ERR_NUMERIC,
                 (const char *[]){"line 2", "no direction", NULL});
    const char *t4 = "0 0 nan 1 0 0\n";
    expect_error(write_file("n.xyz", t4, strlen(t4)), HV_ERR_NUMERIC,
                 (const char *[]){"line 1", "coordinate z", NULL});
    const char *t5 = "0 0 0 1 0\n";
    expect_error(write_file("f.xyz", t5, strlen(t5)), HV_ERR_PARSE,
                 (const char *[]){"line 1", "5 numbers", NULL});
    expect_error(write_file("e.xyz", "# nothing\n", 10), HV_ERR_PARSE,
                 (const char *[]){"no points", NULL});
    char colours[512] = "";
    for (int i = 0; i < 10; i++)
        snprintf(colours + strlen(colours), sizeof colours - strlen(colours), "%d 0 0 255 %d 0\n",
                 i, 20 * i);
    expect_error(write_file("c.xyz", colours, strlen(colours)), HV_ERR_INVALID_ARG,
                 (const char *[]){"colours", NULL});
}
END_TEST

static const char ply_head[] = "ply\nformat %s 1.0\ncomment points\nelement vertex 2\n"
                               "property float x\nproperty float y\nproperty float z\n"
                               "property uchar red\nproperty float nx\nproperty float ny\n"
                               "property float nz\n%send_header\n";

START_TEST(ply_reader)
{
    char text[1024];
    int n = snprintf(text, sizeof text, ply_head, "ascii", "");
    n += snprintf(text + n, sizeof text - n, "1 2 3 255 0 0 1\n4 5 6 0 0 -2 0\n");
    const char *path = write_file("a.ply", text, (size_t)n);
    ck_assert_int_eq(hv_points_file(path), 1);
    hv_points *P = NULL;
    TL_ASSERT_OK(hv_points_read(path, &P));
    ck_assert_uint_eq(P->count, 2);
    ck_assert_double_eq(P->xyz[5], 6);
    ck_assert_double_eq(P->normals[4], -1);
    hv_points_destroy(&P);
    /* Binary little endian: records of 3 floats, a byte, 3 floats. */
    n = snprintf(text, sizeof text, ply_head, "binary_little_endian", "");
    const float rec[2][7] = {{1, 2, 3, 0, 0, 0, 1}, {4, 5, 6, 0, 0, 3, 0}};
    for (int r = 0; r < 2; r++) {
        memcpy(text + n, rec[r], 12);
        text[n + 12] = 7;
        memcpy(text + n + 13, rec[r] + 4, 12);
        n += 25;
    }
    path = write_file("b.ply", text, (size_t)n);
    TL_ASSERT_OK(hv_points_read(path, &P));
    ck_assert_double_eq(P->xyz[3], 4);
    ck_assert_double_eq(P->normals[4], 1);
    hv_points_destroy(&P);
    /* Faces make it a mesh; no normals make it unoriented. */
    n = snprintf(text, sizeof text, ply_head, "ascii",
                 "element face 1\nproperty list uchar int vertex_indices\n");
    ck_assert_int_eq(hv_points_file(write_file("m.ply", text, (size_t)n)), 0);
    const char *bare = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\n"
                       "property float y\nproperty float nx\nproperty float z\nend_header\n"
                       "0 0 5 0\n1 2 7 3\n";
    TL_ASSERT_OK(hv_points_read(write_file("u.ply", bare, strlen(bare)), &P));
    ck_assert_uint_eq(P->count, 2);
    ck_assert_ptr_null(P->normals); /* nx alone is no normal */
    ck_assert_double_eq(P->xyz[5], 3);
    hv_points_destroy(&P);
}
END_TEST

/* ---- surfaces against known truth ---- */

static double rnd(uint64_t *s) { return tl_rand(s) + 0.5; }

static double gauss(uint64_t *s)
{
    double u = rnd(s), v = rnd(s);
    return sqrt(-2 * log(u + 1e-300)) * cos(2 * M_PI * v);
}

/* How a cloud departs from clean, uniform samples of the surface. */
typedef struct defects {
    double noise; /* Gaussian offset along the normal, voxels (sd) */
    double flip;  /* fraction of normals turned around */
    int uneven;   /* density 10:1 from low x to high x */
    double hole;  /* radius of a missing patch around the first vertex, in
                      units of the bounding box's width (0: none) */
} defects;

static void add_point(double *xyz, double *nrm, size_t i, const double p[3], const double n[3],
                      double off, int flip)
{
    for (int a = 0; a < 3; a++) {
        xyz[3 * i + a] = p[a] + off * n[a];
        nrm[3 * i + a] = flip ? -n[a] : n[a];
    }
}

/* A point uniform on triangle t of m, its unit normal, and its area. */
static double on_triangle(const hv_mesh *m, size_t t, uint64_t *s, double p[3], double n[3])
{
    const double *a = m->verts + 3 * (size_t)m->tris[3 * t],
                 *b = m->verts + 3 * (size_t)m->tris[3 * t + 1],
                 *c = m->verts + 3 * (size_t)m->tris[3 * t + 2];
    double r1 = sqrt(rnd(s)), r2 = rnd(s), u[3], v[3];
    for (int k = 0; k < 3; k++) {
        p[k] = (1 - r1) * a[k] + r1 * (1 - r2) * b[k] + r1 * r2 * c[k];
        u[k] = b[k] - a[k];
        v[k] = c[k] - a[k];
    }
    n[0] = u[1] * v[2] - u[2] * v[1];
    n[1] = u[2] * v[0] - u[0] * v[2];
    n[2] = u[0] * v[1] - u[1] * v[0];
    double l = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (int k = 0; k < 3; k++)
        n[k] = l > 0 ? n[k] / l : 0;
    return 0.5 * l;
}

/* count points sampled from m's surface with defects D; h: the voxel. */
static hv_points *sample(const hv_mesh *m, size_t count, const defects *D, double h, uint64_t seed)
{
    double *cdf = malloc(m->ntris * sizeof *cdf), A = 0, p[3], n[3], lo[3], hi[3];
    uint64_t s = seed;
    for (size_t t = 0; t < m->ntris; t++)
        cdf[t] = A += on_triangle(m, t, &s, p, n);
    TL_ASSERT_OK(hv_mesh_bounds(m, lo, hi));
    const double *c = m->verts, R = D->hole * (hi[0] - lo[0]);
    double *xyz = malloc(3 * count * sizeof *xyz), *nrm = malloc(3 * count * sizeof *nrm);
    size_t k = 0;
    while (k < count) {
        double r = rnd(&s) * A;
        size_t L = 0, U = m->ntris - 1;
        while (L < U) {
            size_t M = (L + U) / 2;
            if (cdf[M] < r)
                L = M + 1;
            else
                U = M;
        }
        on_triangle(m, L, &s, p, n);
        double d2 = (p[0] - c[0]) * (p[0] - c[0]) + (p[1] - c[1]) * (p[1] - c[1]) +
                    (p[2] - c[2]) * (p[2] - c[2]);
        if ((D->uneven && rnd(&s) > 0.1 + 0.9 * (p[0] - lo[0]) / (hi[0] - lo[0])) || d2 < R * R ||
            n[0] * n[0] + n[1] * n[1] + n[2] * n[2] == 0)
            continue;
        add_point(xyz, nrm, k++, p, n, D->noise * h * gauss(&s), rnd(&s) < D->flip);
    }
    hv_points *P = NULL;
    TL_ASSERT_OK(hv_points_from_arrays(&P, xyz, nrm, count));
    free(cdf);
    free(xyz);
    free(nrm);
    return P;
}

/* The options of a run at res with the block of g (NULL: placed around the
 * shape). */
static hv_sdf_opts opts_on(int res, const hv_grid *g)
{
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = res;
    if (g) {
        o.use_bbox = 1;
        o.voxel_size = g->h;
        o.round_to = 1;
        for (int a = 0; a < 3; a++) {
            o.bbox[a] = g->origin[a];
            o.bbox[3 + a] = g->origin[a] + g->n[a] * g->h;
        }
    }
    return o;
}

static double sample_grid(const hv_grid *g, const double x[3])
{
    double f[3], v = 0;
    int i0[3];
    for (int a = 0; a < 3; a++) {
        double t = fmin(fmax((x[a] - g->origin[a]) / g->h - 0.5, 0), g->n[a] - 1.000001);
        i0[a] = (int)t;
        f[a] = t - i0[a];
    }
    for (int q = 0; q < 8; q++) {
        int i = i0[0] + (q & 1), j = i0[1] + (q >> 1 & 1), k = i0[2] + (q >> 2 & 1);
        v += (q & 1 ? f[0] : 1 - f[0]) * (q & 2 ? f[1] : 1 - f[1]) * (q & 4 ? f[2] : 1 - f[2]) *
             g->v[i + (size_t)g->n[0] * (j + (size_t)g->n[1] * k)];
    }
    return v;
}

/* Mean (area-weighted, at triangle centroids) and largest distance of S to
 * the zero set of the signed distance truth, voxels. */
static void surface_error(const hv_mesh *S, const hv_grid *truth, double *mean, double *max)
{
    double sum = 0, area = 0, mx = 0, p[3], n[3];
    uint64_t s = 1;
    for (size_t t = 0; t < S->ntris; t++) {
        double a = on_triangle(S, t, &s, p, n);
        double d = fabs(sample_grid(truth, p)) / truth->h;
        sum += a * d;
        area += a;
        mx = fmax(mx, d);
    }
    *mean = sum / area;
    *max = mx;
}

/* Inside-IoU of the cells where a and b are negative. */
static double iou(const hv_grid *a, const hv_grid *b)
{
    size_t I = 0, U = 0;
    for (size_t c = 0; c < hv_grid_count(a); c++) {
        int x = a->v[c] < 0, y = b->v[c] < 0;
        I += x && y;
        U += x || y;
    }
    return (double)I / (double)U;
}

/* The surface of P and its signed distance on truth's block: IoU and
 * surface error against truth. */
static void score(const hv_points *P, const hv_grid *truth, double *j, double *mean, double *max,
                  hv_points_report *R)
{
    hv_sdf_opts o = opts_on(0, truth);
    hv_mesh *S = NULL;
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_points_surface(P, &o, &S, R));
    TL_ASSERT_OK(hv_sdf_compute(S, &o, &g, NULL));
    ck_assert_int_eq(g->n[0], truth->n[0]);
    *j = iou(g, truth);
    surface_error(S, truth, mean, max);
    hv_mesh_destroy(&S);
    hv_grid_destroy(&g);
}

/* The analytic signed distance of the sphere |x| = r on a block n^3 over
 * [-L, L]^3. */
static hv_grid *sphere_truth(int n, double L, double r)
{
    hv_grid *g = NULL;
    const int dims[3] = {n, n, n};
    const double org[3] = {-L, -L, -L};
    TL_ASSERT_OK(hv_grid_create(&g, 3, dims, 2 * L / n, org));
    for (int k = 0; k < n; k++)
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++) {
                double x[3];
                hv_grid_cell_center(g, i, j, k, x);
                g->v[i + (size_t)n * (j + (size_t)n * k)] =
                    (float)(sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) - r);
            }
    return g;
}

/* Points on a unit sphere (a fine icosphere, faceting < 1e-3 voxel) at 64^3,
 * 49 voxels across: clean and with every defect. The surface's mean error
 * is bounded per case (measured 0.004, 0.041, 0.064, 0.004, 0.005, 0.020);
 * the inside-IoU of so small a sphere moves by 0.012 per 0.1 voxel of
 * error, so it is held to 0.988. */
START_TEST(sphere_defects)
{
    static const defects cases[] = {{0, 0, 0, 0},   {0.25, 0, 0, 0}, {0.5, 0, 0, 0},
                                    {0, 0.1, 0, 0}, {0, 0, 1, 0},    {0, 0, 0, 0.3}};
    static const double mean_max[] = {0.01, 0.06, 0.09, 0.01, 0.01, 0.04};
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_make_sphere(&m, (const double[3]){0, 0, 0}, 1.0, 6));
    hv_grid *truth = sphere_truth(64, 1.3, 1.0);
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        hv_points *P = sample(m, 40000, &cases[c], truth->h, 7 + c);
        hv_points_report R;
        double j, mean, max;
        score(P, truth, &j, &mean, &max, &R);
        printf("points: sphere case %zu: IoU %.5f, surface error mean %.3f max %.3f voxels; "
               "%zu normals turned, agreement %.3f, %zu vertices without points, noise %.3f "
               "voxels\n",
               c, j, mean, max, R.normals_against, R.normal_agreement, R.vertices_unsupported,
               R.noise / truth->h);
        ck_assert_msg(j >= 0.988 && mean <= mean_max[c], "case %zu: IoU %g, mean error %g", c, j,
                      mean);
        ck_assert_uint_eq(R.points, 40000);
        if (cases[c].flip > 0)
            ck_assert_msg(fabs(R.normals_against - 4000.0) < 300, "%zu turned", R.normals_against);
        else
            ck_assert_uint_le(R.normals_against, 40);
        if (cases[c].hole > 0)
            ck_assert_uint_gt(R.vertices_unsupported, 0);
        /* The noise the projection measures: none on clean points (a fit's
         * residual stays under its floor), within a third of what was
         * added on noisy ones. */
        if (cases[c].noise > 0)
            ck_assert_msg(fabs(R.noise / truth->h - cases[c].noise) < cases[c].noise / 3,
                          "case %zu: noise %g voxels", c, R.noise / truth->h);
        else
            ck_assert_double_eq(R.noise, 0);
        hv_points_destroy(&P);
    }
    hv_grid_destroy(&truth);
    hv_mesh_destroy(&m);
}
END_TEST

/* The shared meshes' file name into path; NULL, or why it is absent. */
static const char *mesh_path(const char *name, char *path, size_t size)
{
    const char *data = tl_test_data();
    if (!data)
        return "no test meshes (HEATVOX_TEST_DATA)";
    snprintf(path, size, "%s/%s", data, name);
    return access(path, R_OK) ? "the mesh is absent" : NULL;
}

/* The shared meshes' intact bunny into path; NULL, or why it is absent. */
static const char *bunny_path(char *path, size_t size)
{
    return mesh_path("stanford-bunny.obj", path, size);
}

/* The mesh at path into *m, and its signed distance at 128^3 (the winding
 * number's sign): the truth its clouds are scored against. */
static hv_grid *bunny_truth(const char *path, hv_mesh **m)
{
    TL_ASSERT_OK(hv_mesh_read(path, m));
    hv_sdf_opts o = opts_on(128, NULL);
    o.sign = HV_SDF_SIGN_WINDING;
    hv_grid *truth = NULL;
    TL_ASSERT_OK(hv_sdf_compute(*m, &o, &truth, NULL));
    return truth;
}

/* Points sampled from the intact bunny (shared meshes) at 128^3: inside-IoU
 * against its solid and the surface's distance to it, bounded per case
 * (measured 0.018, 0.019, 0.047, 0.074, 0.018, 0.058 voxel). */
START_TEST(bunny_defects)
{
    char path[512];
    const char *why = bunny_path(path, sizeof path);
    if (why)
        TL_SKIP("bunny_defects: %s", why);
    hv_mesh *m = NULL;
    hv_grid *truth = bunny_truth(path, &m);
    static const defects cases[] = {{0, 0, 0, 0},   {0, 0, 1, 0},   {0.25, 0, 0, 0},
                                    {0.5, 0, 0, 0}, {0, 0.1, 0, 0}, {0, 0, 0, 0.15}};
    static const double mean_max[] = {0.025, 0.025, 0.065, 0.1, 0.025, 0.08};
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        /* Under the sanitizers the clean cloud alone, the bunny's size at
         * 128^3: the sphere above goes through every kind of defect there,
         * holes included. */
        if (tl_sanitized() && c != 0)
            continue;
        hv_points *P = sample(m, 200000, &cases[c], truth->h, 11 + c);
        hv_points_report R;
        double j, mean, max;
        score(P, truth, &j, &mean, &max, &R);
        printf("points: bunny case %zu: IoU %.5f, surface error mean %.3f max %.3f voxels; "
               "%zu normals turned; %.2f s\n",
               c, j, mean, max, R.normals_against, R.t_total);
        ck_assert_msg(j >= 0.99 && mean <= mean_max[c], "case %zu: IoU %g, mean error %g", c, j,
                      mean);
        hv_points_destroy(&P);
    }
    hv_grid_destroy(&truth);
    hv_mesh_destroy(&m);
}
END_TEST

/* The points of P without their normals (an unoriented cloud). */
static hv_points *bare(const hv_points *P)
{
    hv_points *Q = NULL;
    TL_ASSERT_OK(hv_points_from_arrays(&Q, P->xyz, NULL, P->count));
    return Q;
}

/* The fraction of P's points whose recovered normal (the surface's
 * orientation from the points alone, HV_ORIENT_RECOVER) is on the side of
 * their true normal, from the report. */
static double agreement(const hv_points *P, const hv_points_report *R)
{
    ck_assert_int_eq(R->recovered, 1);
    return 1 - (double)R->orient_disagree / (double)P->count;
}

/* The inside-IoU against truth of P's surface with its orientation
 * recovered from the points alone (HV_ORIENT_RECOVER, P's normals only
 * counted against), its report into R. */
static double score_recovered(const hv_points *P, const hv_grid *truth, hv_points_report *R)
{
    hv_sdf_opts o = opts_on(0, truth);
    o.orient = HV_ORIENT_RECOVER;
    hv_mesh *S = NULL;
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_points_surface(P, &o, &S, R));
    TL_ASSERT_OK(hv_sdf_compute(S, &o, &g, NULL));
    const double j = iou(g, truth);
    hv_mesh_destroy(&S);
    hv_grid_destroy(&g);
    return j;
}

/* The sphere's clouds of sphere_defects without their normals: the inside-IoU
 * within 0.01 of the true normals' and at least 99% of the points on their
 * true side. The cloud read as unoriented (normals NULL, HV_ORIENT_AUTO)
 * gives the same surface as HV_ORIENT_RECOVER on the cloud with normals. */
START_TEST(sphere_recovered)
{
    static const defects cases[] = {
        {0, 0, 0, 0}, {0.25, 0, 0, 0}, {0.5, 0, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 0.3}};
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_make_sphere(&m, (const double[3]){0, 0, 0}, 1.0, 6));
    hv_grid *truth = sphere_truth(64, 1.3, 1.0);
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        if (tl_sanitized() && c != 2)
            continue;
        hv_points *P = sample(m, 40000, &cases[c], truth->h, 7 + c), *Q = bare(P);
        hv_points_report R, G, U;
        double j, jg, ju, mean, max;
        score(P, truth, &jg, &mean, &max, &G);
        j = score_recovered(P, truth, &R);
        score(Q, truth, &ju, &mean, &max, &U);
        printf("points: sphere case %zu recovered: IoU %.5f (true normals %.5f, read bare "
               "%.5f), %.3f%% on their true side, %zu components, %d rounds, spread %.3f%s, "
               "%.2f s\n",
               c, j, jg, ju, 100 * agreement(P, &R), R.orient_components, R.orient_rounds,
               R.orient_spread, R.orient_lines ? " (line field)" : "", R.t_orient);
        ck_assert_msg(j >= jg - 0.01, "case %zu: IoU %g, %g with the true normals", c, j, jg);
        ck_assert_msg(agreement(P, &R) >= 0.99, "case %zu: %g on their side", c, agreement(P, &R));
        /* The diffused line field gives the directions of the noisiest
         * cloud alone (its spread about 0.4, 0.25 voxel of noise about
         * 0.14, clean ones under 0.05). */
        ck_assert_int_eq(R.orient_lines, cases[c].noise >= 0.5);
        ck_assert(R.orient_lines ? R.orient_line_iterations > 0 : R.orient_line_iterations == 0);
        ck_assert_int_eq(U.recovered, 1);
        ck_assert_uint_eq(U.orient_disagree, 0); /* nothing to disagree with */
        ck_assert_double_eq_tol(ju, j, 1e-12);
        ck_assert_int_eq(G.recovered, 0);
        hv_points_destroy(&P);
        hv_points_destroy(&Q);
    }
    hv_grid_destroy(&truth);
    hv_mesh_destroy(&m);
}
END_TEST

/* The angle in degrees between the lines of unit vectors a and b. */
static double line_angle(const double a[3], const double b[3])
{
    return acos(fmin(1, fabs(a[0] * b[0] + a[1] * b[1] + a[2] * b[2]))) * 180 / M_PI;
}

/* The diffused line field (points_lines.c) of points on a sphere whose
 * directions are the radial lines tilted at random by up to 40 degrees,
 * signs at random: at the points the field's direction is nearer the true
 * line than the directions splatted, the cells near the sphere hold the
 * radial line with a clear gap to the second eigenvalue, and cells 0.3
 * radius off hold next to nothing (the pipeline's t, h^2 / 4). */
START_TEST(line_field)
{
    const size_t n = 20000;
    double *xyz = malloc(3 * n * sizeof *xyz), *dir = malloc(3 * n * sizeof *dir);
    double *area = malloc(n * sizeof *area);
    uint64_t s = 5;
    double in = 0;
    for (size_t i = 0; i < n; i++) {
        double p[3], len = 0, q[3];
        for (int a = 0; a < 3; a++) {
            p[a] = gauss(&s);
            len += p[a] * p[a];
        }
        for (int a = 0; a < 3; a++)
            xyz[3 * i + a] = p[a] /= sqrt(len);
        len = 0;
        for (int a = 0; a < 3; a++) {
            q[a] = p[a] + 0.35 * gauss(&s);
            len += q[a] * q[a];
        }
        const double sign = rnd(&s) < 0.5 ? -1 : 1;
        for (int a = 0; a < 3; a++)
            dir[3 * i + a] = sign * q[a] / sqrt(len);
        area[i] = 4 * M_PI / n;
        in += line_angle(dir + 3 * i, p) / n;
    }
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_grid_create(&g, 3, (const int[3]){48, 48, 48}, 3.0 / 48,
                                (const double[3]){-1.5, -1.5, -1.5}));
    hv_points P = {n, xyz, NULL, NULL};
    pt_lines L;
    TL_ASSERT_OK(hv__lines_build(&L, &P, area, dir, g, 0.25 * g->h * g->h, HV_BACKEND_AUTO));
    ck_assert_int_gt(L.iterations, 0);
    double out = 0, cell_max = 0, cell_mean = 0, v[3];
    for (size_t i = 0; i < n; i++) {
        const double a = hv__lines_at(&L, xyz + 3 * i, dir + 3 * i, v);
        ck_assert(a > 0 && a <= 1);
        ck_assert(v[0] * dir[3 * i] + v[1] * dir[3 * i + 1] + v[2] * dir[3 * i + 2] >= 0);
        out += line_angle(v, xyz + 3 * i) / n;
    }
    size_t near = 0;
    double tr_near = 0, tr_far = 0;
    for (int k = 0; k < 48; k++)
        for (int j = 0; j < 48; j++)
            for (int i = 0; i < 48; i++) {
                const size_t c = ((size_t)k * 48 + j) * 48 + i;
                const double x[3] = {-1.5 + (i + 0.5) * g->h, -1.5 + (j + 0.5) * g->h,
                                     -1.5 + (k + 0.5) * g->h};
                const double r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
                const double a = hv__lines_cell(&L, c, v);
                const double tr = L.T[0][c] + L.T[1][c] + L.T[2][c];
                if (fabs(r - 1) < g->h) {
                    tr_near = fmax(tr_near, tr);
                    const double u[3] = {x[0] / r, x[1] / r, x[2] / r};
                    ck_assert_msg(a > 0.5, "cell at r %g: anisotropy %g", r, a);
                    cell_max = fmax(cell_max, line_angle(v, u));
                    cell_mean += line_angle(v, u);
                    near++;
                } else if (r > 1.3) {
                    tr_far = fmax(tr_far, tr);
                }
            }
    printf("points: line field: mean angle %.2f deg splatted, %.2f deg at the points; "
           "%zu cells near the sphere, %.2f deg off radial (at most %.2f); trace far off %.3g "
           "of the sphere's; %d iterations\n",
           in, out, near, cell_mean / near, cell_max, tr_far / tr_near, L.iterations);
    ck_assert_msg(tr_far < 1e-3 * tr_near, "far cells hold %g of the sphere's", tr_far / tr_near);
    ck_assert_msg(out < 0.25 * in, "line field %g deg, directions %g deg", out, in);
    ck_assert_msg(cell_mean < 0.25 * in * near && cell_max < 45,
                  "cells %g deg off radial (at most %g)", cell_mean / near, cell_max);
    hv__lines_free(&L);
    hv_grid_destroy(&g);
    free(xyz), free(dir), free(area);
}
END_TEST

/* Two spheres in one scan, without normals: each is oriented outward (both
 * centres inside), whatever the propagation's start. */
START_TEST(two_objects)
{
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_make_sphere(&m, (const double[3]){0, 0, 0}, 1.0, 5));
    const defects clean = {0, 0, 0, 0};
    hv_points *A = sample(m, 20000, &clean, 0.05, 3), *B = sample(m, 10000, &clean, 0.05, 4);
    const size_t n = A->count + B->count;
    double *xyz = malloc(3 * n * sizeof *xyz);
    memcpy(xyz, A->xyz, 3 * A->count * sizeof *xyz);
    for (size_t i = 0; i < 3 * B->count; i++) /* radius 0.6 at (3, 0, 0) */
        xyz[3 * A->count + i] = 0.6 * B->xyz[i] + (i % 3 == 0 ? 3 : 0);
    hv_points *P = NULL;
    TL_ASSERT_OK(hv_points_from_arrays(&P, xyz, NULL, n));
    hv_sdf_opts o = opts_on(96, NULL);
    hv_mesh *S = NULL;
    hv_points_report R;
    TL_ASSERT_OK(hv_points_surface(P, &o, &S, &R));
    hv_grid *g = NULL;
    o.sign = HV_SDF_SIGN_WINDING;
    TL_ASSERT_OK(hv_sdf_compute(S, &o, &g, NULL));
    printf("points: two spheres recovered: %zu components (%zu turned), %d rounds turned %zu\n",
           R.orient_components, R.orient_components_flipped, R.orient_rounds, R.orient_turned);
    ck_assert_uint_ge(R.orient_components, 2);
    ck_assert_double_lt(sample_grid(g, (const double[3]){0, 0, 0}), -0.9);
    ck_assert_double_lt(sample_grid(g, (const double[3]){3, 0, 0}), -0.5);
    ck_assert_double_gt(sample_grid(g, (const double[3]){1.8, 0, 0}), 0.3);
    hv_grid_destroy(&g);
    hv_mesh_destroy(&S);
    hv_points_destroy(&P);
    hv_points_destroy(&A);
    hv_points_destroy(&B);
    free(xyz);
    hv_mesh_destroy(&m);
}
END_TEST

/* The bunny's clouds of bunny_defects without their normals (shared
 * meshes): the inside-IoU within 0.01 of the true normals', at least 99%
 * of the points on their true side. */
START_TEST(bunny_recovered)
{
    char path[512];
    const char *why = bunny_path(path, sizeof path);
    if (why)
        TL_SKIP("bunny_recovered: %s", why);
    hv_mesh *m = NULL;
    hv_grid *truth = bunny_truth(path, &m);
    static const defects cases[] = {{0, 0, 0, 0}, {0.5, 0, 0, 0}, {0, 0, 0, 0.15}};
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        if (tl_sanitized() && c != 0)
            continue;
        hv_points *P = sample(m, 200000, &cases[c], truth->h, 11 + c);
        hv_points_report G, R;
        double jg, j, mean, max;
        score(P, truth, &jg, &mean, &max, &G);
        j = score_recovered(P, truth, &R);
        printf("points: bunny case %zu recovered: IoU %.5f (true normals %.5f), %.3f%% on their "
               "true side; %.2f s (orientation %.2f s), %.2f s with the true normals\n",
               c, j, jg, 100 * agreement(P, &R), R.t_total, R.t_orient, G.t_total);
        ck_assert_msg(j >= jg - 0.01, "case %zu: IoU %g, %g with the true normals", c, j, jg);
        ck_assert_msg(agreement(P, &R) >= 0.99, "case %zu: %g on their side", c, agreement(P, &R));
        hv_points_destroy(&P);
    }
    hv_grid_destroy(&truth);
    hv_mesh_destroy(&m);
}
END_TEST

/* The cow's clouds without normals (shared meshes): its ears, tail and
 * horns are a voxel thick or less at 128^3, where the tree's signs cross
 * from one face to the other and the heat rounds cannot tell the faces
 * apart; the rays' votes and the labelling set them. */
START_TEST(cow_recovered)
{
    char path[512];
    const char *why = mesh_path("cow.obj", path, sizeof path);
    if (why)
        TL_SKIP("cow_recovered: cow.obj: %s", why);
    hv_mesh *m = NULL;
    hv_grid *truth = bunny_truth(path, &m);
    static const defects cases[] = {{0, 0, 0, 0}, {0.25, 0, 0, 0}};
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        if (tl_sanitized() && c != 0)
            continue;
        hv_points *P = sample(m, 200000, &cases[c], truth->h, 31 + c);
        hv_points_report G, R;
        double jg, j, mean, max;
        score(P, truth, &jg, &mean, &max, &G);
        j = score_recovered(P, truth, &R);
        printf("points: cow case %zu recovered: IoU %.5f (true normals %.5f), %.3f%% on their "
               "true side; thin parts: %zu points voted, %zu turned; %.2f s (orientation "
               "%.2f s)\n",
               c, j, jg, 100 * agreement(P, &R), R.orient_thin_votes, R.orient_thin_turned,
               R.t_total, R.t_orient);
        ck_assert_msg(j >= jg - 0.01, "case %zu: IoU %g, %g with the true normals", c, j, jg);
        ck_assert_msg(agreement(P, &R) >= 0.99, "case %zu: %g on their side", c, agreement(P, &R));
        ck_assert_uint_gt(R.orient_thin_votes, 1000);
        ck_assert_uint_gt(R.orient_thin_turned, 0);
        hv_points_destroy(&P);
    }
    hv_grid_destroy(&truth);
    hv_mesh_destroy(&m);
}
END_TEST

START_TEST(refusals)
{
    hv_mesh *S = NULL;
    ck_assert_int_eq(hv_points_surface(NULL, NULL, &S, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "empty"));
    hv_points *P = NULL;
    const double x[3] = {0, 0, 0}, n[3] = {1, 0, 0};
    TL_ASSERT_OK(hv_points_from_arrays(&P, x, n, 1));
    /* One point has no extent to place a block around. */
    ck_assert_int_eq(hv_points_surface(P, NULL, &S, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_null(S);
    hv_points_destroy(&P);
    ck_assert_int_eq(hv_points_from_arrays(&P, x, (const double[3]){0, 0, 0}, 1), HV_ERR_NUMERIC);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "point 1"));
    /* Without normals: too few points to orient, normals asked for that are
     * not there, points on a plane (no inside). */
    const double three[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    TL_ASSERT_OK(hv_points_from_arrays(&P, three, NULL, 3));
    ck_assert_int_eq(hv_points_surface(P, NULL, &S, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "at least 4"));
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.orient = HV_ORIENT_GIVEN;
    ck_assert_int_eq(hv_points_surface(P, &o, &S, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "no normals"));
    hv_points_destroy(&P);
    enum { NPLANE = 2500 };
    double *plane = malloc(3 * NPLANE * sizeof *plane);
    for (int i = 0; i < NPLANE; i++) {
        plane[3 * i] = i % 50 * 0.02;
        plane[3 * i + 1] = i / 50 * 0.02;
        plane[3 * i + 2] = 0.5;
    }
    TL_ASSERT_OK(hv_points_from_arrays(&P, plane, NULL, NPLANE));
    hv_sdf_opts_default(&o);
    o.res = 32;
    ck_assert_int_eq(hv_points_surface(P, &o, &S, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_null(S);
    ck_assert_msg(strstr(hv_last_error(), "no inside"), "%s", hv_last_error());
    hv_points_destroy(&P);
    free(plane);
    o.orient = (hv_points_orient)7;
    ck_assert_int_eq(hv_points_surface(P, &o, &S, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "orientation source"));
}
END_TEST

/* A cloud larger than the memory it may take (100M points on 24 GB; here
 * 6M points, binary PLY, under an address-space cap of 1.5 GB) is refused
 * before the work, with what it would need, naming the file; nothing is
 * written. The command runs under ulimit -v, whose cap ends with it. */
START_TEST(too_large)
{
    if (tl_sanitized())
        TL_SKIP("too_large: the sanitizers' shadow memory is outside any address-space cap");
    const char *bin = tl_heatvox_bin();
    ck_assert_msg(bin != NULL, "no heatvox command to run");
    enum { N = 6000000 };
    char path[128], err[2048], cmd[1024];
    snprintf(path, sizeof path, "%s/big.ply", dir);
    FILE *f = fopen(path, "wb");
    ck_assert_ptr_nonnull(f);
    fprintf(f,
            "ply\nformat binary_little_endian 1.0\nelement vertex %d\nproperty float x\n"
            "property float y\nproperty float z\nend_header\n",
            (int)N);
    float *x = malloc(3 * (size_t)N * sizeof *x);
    ck_assert_ptr_nonnull(x);
    for (size_t i = 0; i < N; i++) { /* a sphere's spiral */
        const double z = 1 - (2 * i + 1.0) / N, r = sqrt(1 - z * z), t = 2.39996 * i;
        x[3 * i] = (float)(r * cos(t));
        x[3 * i + 1] = (float)(r * sin(t));
        x[3 * i + 2] = (float)z;
    }
    ck_assert_uint_eq(fwrite(x, sizeof *x, 3 * (size_t)N, f), 3 * (size_t)N);
    free(x);
    ck_assert_int_eq(fclose(f), 0);
    snprintf(
        cmd, sizeof cmd,
        "cd '%s' && ulimit -v 1572864 && MALLOC_ARENA_MAX=2 OMP_NUM_THREADS=2 '%s' sdf big.ply "
        "-o big.vdb --res 128",
        dir, bin);
    ck_assert_int_eq(tl_run_cmd(cmd, dir, err, sizeof err), 1);
    ck_assert_msg(strstr(err, "big.ply") &&
                      strstr(err, "6000000 points without normals need about") &&
                      strstr(err, "ulimit -v"),
                  "stderr: %s", err);
    snprintf(path, sizeof path, "%s/big.vdb", dir);
    ck_assert_int_ne(access(path, F_OK), 0);
}
END_TEST

/* Writes P as a text cloud at path. */
static void write_xyz(const char *path, const hv_points *P)
{
    FILE *f = fopen(path, "w");
    ck_assert_ptr_nonnull(f);
    fprintf(f, "# x y z nx ny nz\n");
    for (size_t i = 0; i < P->count; i++) {
        const double *x = P->xyz + 3 * i, *n = P->normals + 3 * i;
        fprintf(f, "%.17g %.17g %.17g %.17g %.17g %.17g\n", x[0], x[1], x[2], n[0], n[1], n[2]);
    }
    ck_assert_int_eq(fclose(f), 0);
}

/* Writes P's points alone (x y z) at path. */
static void write_xyz_bare(const char *path, const hv_points *P)
{
    FILE *f = fopen(path, "w");
    ck_assert_ptr_nonnull(f);
    for (size_t i = 0; i < P->count; i++)
        fprintf(f, "%.17g %.17g %.17g\n", P->xyz[3 * i], P->xyz[3 * i + 1], P->xyz[3 * i + 2]);
    ck_assert_int_eq(fclose(f), 0);
}

/* heatvox sdf on a cloud: a level set of the sphere read back from the
 * .vdb, with the normals and without; a cloud too small to orient, and
 * normals asked for that the file lacks, fail naming the file and write
 * nothing. */
START_TEST(command)
{
    const char *bin = tl_heatvox_bin();
    ck_assert_msg(bin != NULL, "no heatvox command to run");
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_make_sphere(&m, (const double[3]){0, 0, 0}, 1.0, 5));
    const defects clean = {0, 0.1, 0, 0};
    hv_points *P = sample(m, 20000, &clean, 0.05, 5);
    char path[128], err[2048];
    snprintf(path, sizeof path, "%s/s.xyz", dir);
    write_xyz(path, P);
    ck_assert_int_eq(tl_hv(dir, bin, err, sizeof err, "sdf s.xyz -o s.vdb --res 48 -q"), 0);
    snprintf(path, sizeof path, "%s/s.vdb", dir);
    hv_grid *g = NULL;
    int cls = 0;
    TL_ASSERT_OK(hv_vdb_read_float(path, "sdf", NULL, &g, &cls));
    ck_assert_int_eq(cls, HV_VDB_LEVEL_SET);
    double worst = 0;
    for (int a = 0; a < 3; a++) {
        double x[3] = {0, 0, 0};
        x[a] = 1; /* on the sphere */
        worst = fmax(worst, fabs(sample_grid(g, x)) / g->h);
    }
    ck_assert_msg(worst < 0.05, "|phi| on the sphere up to %g voxels", worst);
    ck_assert_double_lt(sample_grid(g, (const double[3]){0, 0, 0}), 0);
    hv_grid_destroy(&g);
    /* The same points without normals: recovered, the same sphere. */
    snprintf(path, sizeof path, "%s/b.xyz", dir);
    write_xyz_bare(path, P);
    ck_assert_int_eq(tl_hv(dir, bin, err, sizeof err, "sdf b.xyz -o b.vdb --res 48 -v"), 0);
    ck_assert_msg(strstr(err, "b.xyz: orientation recovered"), "stderr: %s", err);
    snprintf(path, sizeof path, "%s/b.vdb", dir);
    TL_ASSERT_OK(hv_vdb_read_float(path, "sdf", NULL, &g, &cls));
    ck_assert_double_lt(fabs(sample_grid(g, (const double[3]){0, 1, 0})) / g->h, 0.1);
    ck_assert_double_lt(sample_grid(g, (const double[3]){0, 0, 0}), 0);
    hv_grid_destroy(&g);
    /* A band and the cloud's own surface beside it: the band in tiles. */
    ck_assert_int_eq(
        tl_hv(dir, bin, err, sizeof err, "sdf b.xyz -o m.vdb --mesh-out m.ply --res 48 -v"), 0);
    ck_assert_msg(strstr(err, "the band went into the .vdb's tree as it was computed"),
                  "stderr: %s", err);
    snprintf(path, sizeof path, "%s/m.vdb", dir);
    TL_ASSERT_OK(hv_vdb_read_float(path, "sdf", NULL, &g, &cls));
    ck_assert_int_eq(cls, HV_VDB_LEVEL_SET);
    ck_assert_double_lt(fabs(sample_grid(g, (const double[3]){1, 0, 0})) / g->h, 0.1);
    const double hm = g->h;
    hv_grid_destroy(&g);
    snprintf(path, sizeof path, "%s/m.ply", dir);
    hv_mesh *own = NULL;
    TL_ASSERT_OK(hv_mesh_read(path, &own));
    ck_assert_uint_gt(own->ntris, 1000);
    for (size_t v = 0; v < own->nverts; v += 97) {
        const double *p = own->verts + 3 * v;
        ck_assert_double_lt(fabs(sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]) - 1), 0.1 * hm);
    }
    hv_mesh_destroy(&own);
    ck_assert_int_eq(tl_hv(dir, bin, err, sizeof err, "sdf b.xyz -o g.vdb --orient given"), 1);
    ck_assert_msg(strstr(err, "b.xyz") && strstr(err, "no normals"), "stderr: %s", err);
    ck_assert_int_eq(tl_hv(dir, bin, err, sizeof err, "sdf b.xyz -o g.vdb --orient maybe"), 2);
    snprintf(path, sizeof path, "%s/g.vdb", dir);
    ck_assert_int_ne(access(path, F_OK), 0);
    write_file("u.xyz", "0 0 0\n1 0 0\n", 12);
    ck_assert_int_eq(tl_hv(dir, bin, err, sizeof err, "sdf u.xyz -o u.vdb"), 1);
    ck_assert_msg(strstr(err, "u.xyz") && strstr(err, "at least 4"), "stderr: %s", err);
    snprintf(path, sizeof path, "%s/u.vdb", dir);
    ck_assert_int_ne(access(path, F_OK), 0);
    hv_points_destroy(&P);
    hv_mesh_destroy(&m);
}
END_TEST

int main(void)
{
    Suite *s = suite_create("points");
    TCase *tc = tcase_create("readers");
    tcase_add_checked_fixture(tc, setup, teardown);
    tcase_add_test(tc, text_reader);
    tcase_add_test(tc, text_unoriented);
    tcase_add_test(tc, text_errors);
    tcase_add_test(tc, ply_reader);
    tcase_add_test(tc, command);
    tcase_add_test(tc, too_large);
    suite_add_tcase(s, tc);
    tc = tcase_create("surfaces");
    tcase_set_timeout(tc, 300);
    tcase_add_test(tc, sphere_defects);
    tcase_add_test(tc, bunny_defects);
    tcase_add_test(tc, sphere_recovered);
    tcase_add_test(tc, line_field);
    tcase_add_test(tc, two_objects);
    tcase_add_test(tc, bunny_recovered);
    tcase_add_test(tc, cow_recovered);
    tcase_add_test(tc, refusals);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
