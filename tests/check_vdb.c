/* OpenVDB files through the C shim: level sets (narrow band and dense), vec3,
 * masks, metadata, common boxes, errors; OpenVDB's own reader (pyopenvdb,
 * vdb_print) as the judge of the files; and the OpenVDB reference tools of the
 * benchmarks (meshToLevelSet, sdfToExt: tools/bench/bench_ref_vdb.cpp, linked in)
 * against analytic answers.
 * Links OpenVDB: run with CK_FORK=no (docs/METHOD.md, "Testing notes"). */
#include "heatvox/vdb.h"
#include "heatvox/io.h"
#include "../tools/bench/bench_ref.h"
#include "testlib.h"

#include <check.h>
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

static char dir[64];

static void make_dir(void)
{
    snprintf(dir, sizeof dir, "/tmp/hv-vdb-XXXXXX");
    ck_assert_ptr_nonnull(mkdtemp(dir));
}

static int count_entries(const char *d_path)
{
    DIR *d = opendir(d_path);
    if (!d)
        return -1;
    int n = 0;
    for (struct dirent *e; (e = readdir(d));)
        n += strcmp(e->d_name, ".") && strcmp(e->d_name, "..");
    closedir(d);
    return n;
}

static void remove_dir(void)
{
    DIR *d = opendir(dir);
    if (!d)
        return;
    char p[512];
    for (struct dirent *e; (e = readdir(d));)
        if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) {
            snprintf(p, sizeof p, "%s/%s", dir, e->d_name);
            unlink(p);
        }
    closedir(d);
    rmdir(dir);
}

static void path_in_dir(char *buf, size_t size, const char *name)
{
    snprintf(buf, size, "%s/%s", dir, name);
}

/* The test sphere: 40 x 36 x 32 voxels, h = 0.05, a non-zero origin. */
static const int SN[3] = {40, 36, 32};
static const double SH = 0.05;
static const double SO[3] = {-1.1, -0.85, 0.3};
static const double SC[3] = {-0.12, 0.07, 1.08};
static const double SR = 0.55;

static hv_grid *sphere_sdf(void)
{
    hv_grid *g = NULL;
    ck_assert_int_eq(hv_grid_create(&g, 3, SN, SH, SO), HV_OK);
    for (int k = 0; k < SN[2]; k++)
        for (int j = 0; j < SN[1]; j++)
            for (int i = 0; i < SN[0]; i++) {
                double x[3];
                hv_grid_cell_center(g, i, j, k, x);
                double r = sqrt((x[0] - SC[0]) * (x[0] - SC[0]) + (x[1] - SC[1]) * (x[1] - SC[1]) +
                                (x[2] - SC[2]) * (x[2] - SC[2]));
                g->v[i + SN[0] * (j + SN[1] * k)] = (float)(r - SR);
            }
    return g;
}

static size_t idx(const hv_grid *g, int i, int j, int k)
{
    return (size_t)i + (size_t)g->n[0] * ((size_t)j + (size_t)g->n[1] * (size_t)k);
}

static void write_sphere(const char *path, double band, int dense)
{
    hv_grid *g = sphere_sdf();
    hv_vdb_writer *w = NULL;
    ck_assert_int_eq(hv_vdb_writer_create(&w), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_add_levelset(w, g, "sphere", band, dense), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_set_meta(w, "source", "check_vdb analytic sphere"), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_set_grid_meta(w, "sphere", "radius", "0.55"), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_write(w, path), HV_OK);
    hv_vdb_writer_destroy(&w);
    ck_assert_ptr_null(w);
    hv_grid_destroy(&g);
}

START_TEST(levelset_round_trip_should_keep_band_values_and_signed_background)
{
    char p[256];
    path_in_dir(p, sizeof p, "sphere.vdb");
    write_sphere(p, 3.0, 0);
    /* nothing but the file is left in the directory (the temporary was renamed) */
    ck_assert_int_eq(count_entries(dir), 1);

    hv_grid *g = sphere_sdf(), *r = NULL;
    int cls = -1;
    ck_assert_int_eq(hv_vdb_read_float(p, "sphere", NULL, &r, &cls), HV_OK);
    ck_assert_int_eq(cls, HV_VDB_LEVEL_SET);
    for (int a = 0; a < 3; a++) {
        ck_assert_int_eq(r->n[a], SN[a]);
        ck_assert_double_eq_tol(r->origin[a], SO[a], 1e-9);
    }
    ck_assert_double_eq_tol(r->h, SH, 1e-12);
    const float bg = (float)(3.0 * SH);
    size_t in_band = 0, inside_far = 0, outside_far = 0;
    for (size_t i = 0; i < hv_grid_count(g); i++) {
        if (fabsf(g->v[i]) < bg) {
            ck_assert_float_eq(r->v[i], g->v[i]);
            in_band++;
        } else if (g->v[i] < 0) {
            ck_assert_float_eq(r->v[i], -bg);
            inside_far++;
        } else {
            ck_assert_float_eq(r->v[i], bg);
            outside_far++;
        }
    }
    /* the sphere has a deep inside and a far outside in this block */
    ck_assert_uint_gt(in_band, 1000);
    ck_assert_uint_gt(inside_far, 1000);
    ck_assert_uint_gt(outside_far, 1000);

    /* the active voxels are exactly the band */
    hv_vdb_grid_info info[4];
    size_t count = 0;
    ck_assert_int_eq(hv_vdb_list(p, info, 4, &count), HV_OK);
    ck_assert_uint_eq(count, 1);
    ck_assert_str_eq(info[0].name, "sphere");
    ck_assert_str_eq(info[0].value_type, "float");
    ck_assert_int_eq(info[0].grid_class, HV_VDB_LEVEL_SET);
    ck_assert_int_eq(info[0].uniform, 1);
    ck_assert_int_eq(info[0].active_voxels, (int64_t)in_band);
    /* index (0,0,0) is the centre of the first cell */
    for (int a = 0; a < 3; a++) {
        ck_assert_double_eq_tol(info[0].voxel_size[a], SH, 1e-12);
        ck_assert_double_eq_tol(info[0].index0_world[a], SO[a] + 0.5 * SH, 1e-9);
    }
    hv_grid_destroy(&r);
    hv_grid_destroy(&g);
}
END_TEST

START_TEST(levelset_read_with_a_larger_box_should_place_the_block_and_keep_signs)
{
    char p[256];
    path_in_dir(p, sizeof p, "sphere.vdb");
    write_sphere(p, 3.0, 0);
    hv_vdb_read_opts o = {1, {-2, -1, 0}, {SN[0] + 1, SN[1] - 1, SN[2] - 1}};
    hv_grid *g = sphere_sdf(), *r = NULL;
    ck_assert_int_eq(hv_vdb_read_float(p, "sphere", &o, &r, NULL), HV_OK);
    ck_assert_int_eq(r->n[0], SN[0] + 4);
    ck_assert_double_eq_tol(r->origin[0], SO[0] - 2 * SH, 1e-9);
    ck_assert_double_eq_tol(r->origin[1], SO[1] - SH, 1e-9);
    const float bg = (float)(3.0 * SH);
    for (int k = 0; k < SN[2]; k++)
        for (int j = 0; j < SN[1]; j++)
            for (int i = 0; i < SN[0]; i++) {
                float want = g->v[idx(g, i, j, k)];
                if (fabsf(want) >= bg)
                    want = want < 0 ? -bg : bg;
                ck_assert_float_eq(r->v[idx(r, i + 2, j + 1, k)], want);
            }
    hv_grid_destroy(&r);
    hv_grid_destroy(&g);
}
END_TEST

START_TEST(dense_levelset_should_keep_every_value_and_activate_every_voxel)
{
    char p[256];
    path_in_dir(p, sizeof p, "dense.vdb");
    write_sphere(p, 3.0, 1);
    hv_grid *g = sphere_sdf(), *r = NULL;
    ck_assert_int_eq(hv_vdb_read_float(p, "sphere", NULL, &r, NULL), HV_OK);
    ck_assert_mem_eq(r->v, g->v, hv_grid_count(g) * sizeof(float));
    hv_vdb_grid_info info;
    size_t count = 0;
    ck_assert_int_eq(hv_vdb_list(p, &info, 1, &count), HV_OK);
    ck_assert_int_eq(info.active_voxels, (int64_t)hv_grid_count(g));
    for (int a = 0; a < 3; a++) {
        ck_assert_int_eq(info.bbox_lo[a], 0);
        ck_assert_int_eq(info.bbox_hi[a], SN[a] - 1);
    }
    hv_grid_destroy(&r);
    hv_grid_destroy(&g);
}
END_TEST

/* OpenVDB's own Python module (python3-openvdb, which make installs): the
 * independent reader these tests compare against, so its absence fails them. */
static void require_pyopenvdb(void)
{
    ck_assert_msg(system("/usr/bin/python3 -c 'import pyopenvdb' >/dev/null 2>&1") == 0,
                  "pyopenvdb does not import in /usr/bin/python3 (package python3-openvdb)");
}

START_TEST(openvdb_own_reader_should_see_the_level_set_we_wrote)
{
    char p[256];
    path_in_dir(p, sizeof p, "sphere.vdb");
    write_sphere(p, 3.0, 0);
    hv_grid *g = sphere_sdf();

    char cmd[2048], line[512];
    snprintf(cmd, sizeof cmd, "vdb_print -l -m %s 2>&1", p);
    FILE *pp = popen(cmd, "r");
    ck_assert_ptr_nonnull(pp);
    int saw_name = 0;
    while (fgets(line, sizeof line, pp)) {
        ck_assert_msg(!strstr(line, "ERROR"), "vdb_print: %s", line);
        saw_name |= strstr(line, "sphere") != NULL;
    }
    int rc = pclose(pp);
    /* vdb_print comes with libopenvdb-tools, which make installs. */
    ck_assert_msg(rc == 0 && saw_name, "vdb_print -l -m %s: exit %d", p, rc);

    require_pyopenvdb();
    /* voxels: deep inside, in the band, far outside */
    const int pts[3][3] = {{17, 22, 16}, {28, 22, 16}, {1, 1, 1}};
    snprintf(cmd, sizeof cmd,
             "/usr/bin/python3 -c 'import sys, pyopenvdb as vdb\n"
             "g = vdb.read(sys.argv[1], \"sphere\")\n"
             "a = g.getConstAccessor()\n"
             "print(g.gridClass)\n"
             "print(repr(g.transform.voxelSize()[0]))\n"
             "print(repr(g.background))\n"
             "w = g.transform.indexToWorld((0, 0, 0))\n"
             "print(repr(w[0]), repr(w[1]), repr(w[2]))\n"
             "c = [int(x) for x in sys.argv[2:]]\n"
             "for i in range(0, len(c), 3): print(repr(a.getValue((c[i], c[i+1], c[i+2]))))\n"
             "' %s %d %d %d %d %d %d %d %d %d",
             p, pts[0][0], pts[0][1], pts[0][2], pts[1][0], pts[1][1], pts[1][2], pts[2][0],
             pts[2][1], pts[2][2]);
    pp = popen(cmd, "r");
    ck_assert_ptr_nonnull(pp);
    ck_assert_ptr_nonnull(fgets(line, sizeof line, pp));
    ck_assert_str_eq(line, "level set\n");
    ck_assert_ptr_nonnull(fgets(line, sizeof line, pp));
    ck_assert_double_eq_tol(strtod(line, NULL), SH, 1e-12);
    ck_assert_ptr_nonnull(fgets(line, sizeof line, pp));
    ck_assert_float_eq((float)strtod(line, NULL), (float)(3 * SH));
    ck_assert_ptr_nonnull(fgets(line, sizeof line, pp));
    double w[3];
    ck_assert_int_eq(sscanf(line, "%lf %lf %lf", &w[0], &w[1], &w[2]), 3);
    for (int a = 0; a < 3; a++)
        ck_assert_double_eq_tol(w[a], SO[a] + 0.5 * SH, 1e-9);
    const float bg = (float)(3 * SH);
    for (int q = 0; q < 3; q++) {
        ck_assert_ptr_nonnull(fgets(line, sizeof line, pp));
        float want = g->v[idx(g, pts[q][0], pts[q][1], pts[q][2])];
        if (fabsf(want) >= bg)
            want = want < 0 ? -bg : bg;
        ck_assert_msg((float)strtod(line, NULL) == want, "voxel %d: pyopenvdb %s, expected %g", q,
                      line, want);
    }
    /* the three voxels cover the three cases */
    ck_assert_float_lt(g->v[idx(g, 17, 22, 16)], -bg);
    ck_assert_float_lt(fabsf(g->v[idx(g, 28, 22, 16)]), bg);
    ck_assert_float_gt(g->v[idx(g, 1, 1, 1)], bg);
    ck_assert_int_eq(pclose(pp), 0);
    hv_grid_destroy(&g);
}
END_TEST

START_TEST(files_made_by_openvdb_should_read_on_their_active_box_and_refuse_nonuniform_voxels)
{
    require_pyopenvdb();
    char p[256], cmd[2048];
    path_in_dir(p, sizeof p, "foreign.vdb");
    /* a level set sphere (radius 1, centre c, voxel 0.1, half width 3), a grid
     * with 0.1 x 0.2 x 0.1 voxels, and a bool mask */
    snprintf(cmd, sizeof cmd,
             "/usr/bin/python3 -c 'import sys, pyopenvdb as vdb\n"
             "ls = vdb.createLevelSetSphere(radius=1.0, center=(0.2,-0.1,0.3), voxelSize=0.1, "
             "halfWidth=3.0)\n"
             "ls.name = \"ls\"\n"
             "ns = vdb.FloatGrid(); ns.name = \"ns\"\n"
             "ns.transform = vdb.createLinearTransform([[0.1,0,0,0],[0,0.2,0,0],[0,0,0.1,0],"
             "[0,0,0,1]])\n"
             "ns.getAccessor().setValueOn((1,2,3), 5.0)\n"
             "m = vdb.BoolGrid(); m.name = \"m\"; a = m.getAccessor()\n"
             "for c in [(0,0,0),(3,1,2),(-2,5,1)]: a.setValueOn(c, True)\n"
             "vdb.write(sys.argv[1], grids=[ls, ns, m])\n"
             "' %s",
             p);
    ck_assert_int_eq(system(cmd), 0);
    const double c[3] = {0.2, -0.1, 0.3}, h = 0.1, bg = 0.3;

    hv_grid *r = NULL;
    int cls = -1;
    ck_assert_int_eq(hv_vdb_read_float(p, "ls", NULL, &r, &cls), HV_OK);
    ck_assert_int_eq(cls, HV_VDB_LEVEL_SET);
    ck_assert_double_eq_tol(r->h, h, 1e-7); /* pyopenvdb passes the voxel size as float */
    /* the box is the active bounding box; the sphere's centre lies inside it */
    ck_assert_int_ge(r->n[0], 20);
    size_t near = 0, far = 0;
    for (int k = 0; k < r->n[2]; k++)
        for (int j = 0; j < r->n[1]; j++)
            for (int i = 0; i < r->n[0]; i++) {
                double x[3];
                hv_grid_cell_center(r, i, j, k, x);
                double d = sqrt((x[0] - c[0]) * (x[0] - c[0]) + (x[1] - c[1]) * (x[1] - c[1]) +
                                (x[2] - c[2]) * (x[2] - c[2])) -
                           1.0;
                float v = r->v[idx(r, i, j, k)];
                if (fabs(d) < 1.5 * h) {
                    /* placement error of one voxel would show as 0.1 here */
                    ck_assert_msg(fabs(v - d) < 0.02, "(%d,%d,%d): %g vs %g", i, j, k, v, d);
                    near++;
                } else if (fabs(d) > bg + h) {
                    ck_assert_double_eq_tol(v, d < 0 ? -bg : bg, 1e-6);
                    far++;
                }
            }
    ck_assert_uint_gt(near, 500);
    ck_assert_uint_gt(far, 100);
    hv_grid_destroy(&r);

    ck_assert_int_eq(hv_vdb_read_float(p, "ns", NULL, &r, NULL), HV_ERR_UNSUPPORTED);
    ck_assert_msg(strstr(hv_last_error(), "'ns'") && strstr(hv_last_error(), p), "%s",
                  hv_last_error());
    hv_vdb_grid_info info[3];
    size_t count = 0;
    ck_assert_int_eq(hv_vdb_list(p, info, 3, &count), HV_OK);
    ck_assert_uint_eq(count, 3);
    for (size_t q = 0; q < count; q++)
        ck_assert_int_eq(info[q].uniform, strcmp(info[q].name, "ns") != 0);

    ck_assert_int_eq(hv_vdb_read_mask(p, "m", NULL, &r), HV_OK);
    ck_assert_int_eq(r->n[0], 6);
    ck_assert_int_eq(r->n[1], 6);
    ck_assert_int_eq(r->n[2], 3);
    size_t solid = 0;
    for (size_t q = 0; q < hv_grid_count(r); q++)
        solid += r->solid[q] != 0;
    ck_assert_uint_eq(solid, 3);
    /* index (3,1,2) is voxel (5,1,2) of the box starting at (-2,0,0) */
    ck_assert_int_eq(r->solid[idx(r, 5, 1, 2)], 1);
    hv_grid_destroy(&r);
}
END_TEST

START_TEST(vec3_round_trip_should_keep_each_component)
{
    char p[256];
    path_in_dir(p, sizeof p, "vel.vdb");
    int n[3] = {9, 7, 5};
    double o[3] = {0.5, -2, 3};
    hv_grid *c[3] = {NULL, NULL, NULL};
    for (int a = 0; a < 3; a++) {
        ck_assert_int_eq(hv_grid_create(&c[a], 3, n, 0.1, o), HV_OK);
        for (size_t i = 0; i < hv_grid_count(c[a]); i++)
            c[a]->v[i] = (float)((a + 1) * 1000 + (double)i * 0.37 - 11);
    }
    hv_vdb_writer *w = NULL;
    ck_assert_int_eq(hv_vdb_writer_create(&w), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_add_vec3(w, c[0], c[1], c[2], "velocity"), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_write(w, p), HV_OK);
    hv_vdb_writer_destroy(&w);
    hv_grid *r[3] = {NULL, NULL, NULL};
    ck_assert_int_eq(hv_vdb_read_vec3(p, "velocity", NULL, &r[0], &r[1], &r[2]), HV_OK);
    for (int a = 0; a < 3; a++) {
        ck_assert_int_eq(r[a]->n[0], 9);
        ck_assert_int_eq(r[a]->n[2], 5);
        ck_assert_double_eq_tol(r[a]->origin[1], -2, 1e-12);
        ck_assert_mem_eq(r[a]->v, c[a]->v, hv_grid_count(c[a]) * sizeof(float));
        hv_grid_destroy(&r[a]);
        hv_grid_destroy(&c[a]);
    }
    hv_vdb_grid_info info;
    size_t count = 0;
    ck_assert_int_eq(hv_vdb_list(p, &info, 1, &count), HV_OK);
    ck_assert_str_eq(info.value_type, "vec3s");
    /* a vec3 grid is not a scalar */
    hv_grid *s = NULL;
    ck_assert_int_eq(hv_vdb_read_float(p, "velocity", NULL, &s, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "vec3s"));
}
END_TEST

START_TEST(index_origin_should_keep_the_input_index_space_and_refuse_off_lattice_blocks)
{
    /* Index (0,0,0) of the input sits at world I0; the block to write starts
     * 5 voxels below it in x, 3 above in y and 13 above in z (offsets that are
     * neither zero nor multiples of a leaf). */
    const double h = 0.1, I0[3] = {0.25, -1.05, 2.0};
    const int off[3] = {-5, 3, 13}, n[3] = {11, 9, 7};
    double o[3];
    for (int a = 0; a < 3; a++)
        o[a] = I0[a] + (off[a] - 0.5) * h;
    hv_grid *g = NULL, *c[3] = {NULL, NULL, NULL};
    ck_assert_int_eq(hv_grid_create(&g, 3, n, h, o), HV_OK);
    for (size_t i = 0; i < hv_grid_count(g); i++)
        g->v[i] = (float)((double)i * 0.01 - 0.3);
    for (int a = 0; a < 3; a++) {
        ck_assert_int_eq(hv_grid_create(&c[a], 3, n, h, o), HV_OK);
        for (size_t i = 0; i < hv_grid_count(g); i++)
            c[a]->v[i] = (float)(a + 0.001 * (double)i);
    }
    char p[256];
    path_in_dir(p, sizeof p, "index0.vdb");
    hv_vdb_writer *w = NULL;
    ck_assert_int_eq(hv_vdb_writer_create(&w), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_set_index_origin(w, I0), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_add_levelset(w, g, "ls", 100, 1), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_add_float(w, g, "f"), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_add_vec3(w, c[0], c[1], c[2], "v"), HV_OK);
    /* a block half a voxel off the lattice cannot share the index space */
    hv_grid *bad = NULL;
    double ob[3] = {o[0] + 0.5 * h, o[1], o[2]};
    ck_assert_int_eq(hv_grid_create(&bad, 3, n, h, ob), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_add_float(w, bad, "bad"), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "'bad'"));
    hv_grid_destroy(&bad);
    ck_assert_int_eq(hv_vdb_writer_write(w, p), HV_OK);
    hv_vdb_writer_destroy(&w);

    hv_vdb_grid_info info[3];
    size_t count = 0;
    ck_assert_int_eq(hv_vdb_list(p, info, 3, &count), HV_OK);
    ck_assert_uint_eq(count, 3);
    for (size_t q = 0; q < count; q++)
        for (int a = 0; a < 3; a++) {
            ck_assert_double_eq_tol(info[q].index0_world[a], I0[a], 1e-9);
            ck_assert_int_eq(info[q].bbox_lo[a], off[a]);
            ck_assert_int_eq(info[q].bbox_hi[a], off[a] + n[a] - 1);
        }
    hv_grid *r = NULL, *rv[3] = {NULL, NULL, NULL};
    const char *names[2] = {"ls", "f"};
    for (int q = 0; q < 2; q++) {
        ck_assert_int_eq(hv_vdb_read_float(p, names[q], NULL, &r, NULL), HV_OK);
        for (int a = 0; a < 3; a++) {
            ck_assert_int_eq(r->n[a], n[a]);
            ck_assert_double_eq_tol(r->origin[a], o[a], 1e-9);
        }
        ck_assert_mem_eq(r->v, g->v, hv_grid_count(g) * sizeof(float));
        hv_grid_destroy(&r);
    }
    ck_assert_int_eq(hv_vdb_read_vec3(p, "v", NULL, &rv[0], &rv[1], &rv[2]), HV_OK);
    for (int a = 0; a < 3; a++) {
        ck_assert_mem_eq(rv[a]->v, c[a]->v, hv_grid_count(g) * sizeof(float));
        hv_grid_destroy(&rv[a]);
        hv_grid_destroy(&c[a]);
    }
    hv_grid_destroy(&g);
}
END_TEST

START_TEST(writing_into_a_missing_directory_should_fail_with_io_and_leave_no_temporary)
{
    char p[256];
    path_in_dir(p, sizeof p, "no/such/dir/out.vdb");
    hv_grid *g = sphere_sdf();
    hv_vdb_writer *w = NULL;
    ck_assert_int_eq(hv_vdb_writer_create(&w), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_add_float(w, g, "phi"), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_write(w, p), HV_ERR_IO);
    ck_assert_msg(strstr(hv_last_error(), p), "message does not name the file: %s",
                  hv_last_error());
    ck_assert_int_eq(count_entries(dir), 0);
    /* the writer is still usable */
    path_in_dir(p, sizeof p, "ok.vdb");
    ck_assert_int_eq(hv_vdb_writer_write(w, p), HV_OK);
    ck_assert_int_eq(count_entries(dir), 1);
    /* an empty writer or a duplicate name is refused */
    ck_assert_int_eq(hv_vdb_writer_add_float(w, g, "phi"), HV_ERR_INVALID_ARG);
    hv_vdb_writer_destroy(&w);
    ck_assert_int_eq(hv_vdb_writer_create(&w), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_write(w, p), HV_ERR_INVALID_ARG);
    hv_vdb_writer_destroy(&w);
    hv_grid_destroy(&g);
}
END_TEST

START_TEST(reading_a_missing_grid_should_name_it_the_file_and_what_is_there)
{
    char p[256];
    path_in_dir(p, sizeof p, "sphere.vdb");
    write_sphere(p, 3.0, 0);
    hv_grid *r = NULL;
    ck_assert_int_eq(hv_vdb_read_float(p, "density", NULL, &r, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_null(r);
    const char *m = hv_last_error();
    ck_assert_msg(strstr(m, "density") && strstr(m, p) && strstr(m, "'sphere'"), "message: %s", m);
}
END_TEST

START_TEST(missing_and_corrupt_files_should_give_io_errors_naming_the_file)
{
    char p[256], q[256];
    hv_grid *r = NULL;
    path_in_dir(p, sizeof p, "absent.vdb");
    ck_assert_int_eq(hv_vdb_read_float(p, "sphere", NULL, &r, NULL), HV_ERR_IO);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), p));

    path_in_dir(q, sizeof q, "garbage.vdb");
    FILE *f = fopen(q, "wb");
    fputs("this is not an OpenVDB file, just some text long enough to look like a header", f);
    fclose(f);
    ck_assert_int_eq(hv_vdb_read_float(q, "sphere", NULL, &r, NULL), HV_ERR_IO);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), q));
    size_t count = 0;
    ck_assert_int_eq(hv_vdb_list(q, NULL, 0, &count), HV_ERR_IO);

    /* a real file cut in the middle of the grid data */
    path_in_dir(p, sizeof p, "cut.vdb");
    write_sphere(p, 3.0, 1);
    f = fopen(p, "rb");
    fseek(f, 0, SEEK_END);
    long size = ftell(f);
    fclose(f);
    ck_assert_int_eq(truncate(p, size / 2), 0);
    hv_status st = hv_vdb_read_float(p, "sphere", NULL, &r, NULL);
    ck_assert_msg(st == HV_ERR_IO, "truncated file: %s (%s)", hv_status_str(st), hv_last_error());
    ck_assert_ptr_null(r);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), p));
}
END_TEST

START_TEST(metadata_should_round_trip_on_file_and_grid)
{
    char p[256], buf[256];
    path_in_dir(p, sizeof p, "sphere.vdb");
    write_sphere(p, 3.0, 0);
    ck_assert_int_eq(hv_vdb_read_meta(p, NULL, "source", buf, sizeof buf), HV_OK);
    ck_assert_str_eq(buf, "check_vdb analytic sphere");
    ck_assert_int_eq(hv_vdb_read_meta(p, NULL, "creator", buf, sizeof buf), HV_OK);
    ck_assert_ptr_nonnull(strstr(buf, hv_version()));
    ck_assert_int_eq(hv_vdb_read_meta(p, "sphere", "radius", buf, sizeof buf), HV_OK);
    ck_assert_str_eq(buf, "0.55");
    ck_assert_int_eq(hv_vdb_read_meta(p, "sphere", "missing_key", buf, sizeof buf),
                     HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "missing_key"));
}
END_TEST

START_TEST(common_box_should_cover_all_grids_and_refuse_mismatched_transforms)
{
    char p[256];
    path_in_dir(p, sizeof p, "two.vdb");
    int na[3] = {10, 10, 10}, nb[3] = {14, 6, 12};
    double o[3] = {1, 2, 3};
    hv_grid *a = NULL, *b = NULL, *c = NULL;
    ck_assert_int_eq(hv_grid_create(&a, 3, na, 0.5, o), HV_OK);
    ck_assert_int_eq(hv_grid_create(&b, 3, nb, 0.5, o), HV_OK);
    ck_assert_int_eq(hv_grid_create(&c, 3, na, 0.25, o), HV_OK);
    for (size_t i = 0; i < hv_grid_count(b); i++)
        b->v[i] = 2.0f;
    for (size_t i = 0; i < hv_grid_count(a); i++)
        a->v[i] = 1.0f;
    hv_vdb_writer *w = NULL;
    ck_assert_int_eq(hv_vdb_writer_create(&w), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_add_float(w, a, "a"), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_add_float(w, b, "b"), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_add_float(w, c, "fine"), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_write(w, p), HV_OK);
    hv_vdb_writer_destroy(&w);

    const char *ab[2] = {"a", "b"};
    int lo[3], hi[3];
    ck_assert_int_eq(hv_vdb_common_box(p, ab, 2, lo, hi), HV_OK);
    for (int d = 0; d < 3; d++) {
        ck_assert_int_eq(lo[d], 0);
        ck_assert_int_eq(hi[d], (na[d] > nb[d] ? na[d] : nb[d]) - 1);
    }
    hv_vdb_read_opts opt = {1, {lo[0], lo[1], lo[2]}, {hi[0], hi[1], hi[2]}};
    hv_grid *ra = NULL, *rb = NULL;
    ck_assert_int_eq(hv_vdb_read_float(p, "a", &opt, &ra, NULL), HV_OK);
    ck_assert_int_eq(hv_vdb_read_float(p, "b", &opt, &rb, NULL), HV_OK);
    for (int d = 0; d < 3; d++) {
        ck_assert_int_eq(ra->n[d], rb->n[d]);
        ck_assert_double_eq(ra->origin[d], rb->origin[d]);
    }
    /* a voxel inside b only: a reads its background 0 there */
    ck_assert_float_eq(ra->v[idx(ra, 12, 1, 11)], 0.0f);
    ck_assert_float_eq(rb->v[idx(rb, 12, 1, 11)], 2.0f);
    ck_assert_float_eq(ra->v[idx(ra, 3, 3, 3)], 1.0f);

    const char *mixed[2] = {"a", "fine"};
    ck_assert_int_eq(hv_vdb_common_box(p, mixed, 2, lo, hi), HV_ERR_INVALID_ARG);
    const char *m = hv_last_error();
    ck_assert_msg(strstr(m, "'a'") && strstr(m, "'fine'") && strstr(m, "transform"), "%s", m);
    const char *missing[2] = {"a", "nope"};
    ck_assert_int_eq(hv_vdb_common_box(p, missing, 2, lo, hi), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "nope"));
    hv_grid_destroy(&ra);
    hv_grid_destroy(&rb);
    hv_grid_destroy(&a);
    hv_grid_destroy(&b);
    hv_grid_destroy(&c);
}
END_TEST

START_TEST(masks_should_round_trip_and_level_sets_should_read_as_their_inside)
{
    char p[256];
    path_in_dir(p, sizeof p, "mask.vdb");
    hv_grid *g = sphere_sdf();
    ck_assert_int_eq(hv_grid_add_mask(g), HV_OK);
    for (size_t i = 0; i < hv_grid_count(g); i++)
        g->solid[i] = (i * 7919u) % 5 == 0;
    hv_vdb_writer *w = NULL;
    ck_assert_int_eq(hv_vdb_writer_create(&w), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_add_mask(w, g, "solid"), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_add_levelset(w, g, "sphere", 2.0, 0), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_write(w, p), HV_OK);
    hv_vdb_writer_destroy(&w);
    hv_grid *r = NULL;
    ck_assert_int_eq(hv_vdb_read_mask(p, "solid", NULL, &r), HV_OK);
    ck_assert_ptr_nonnull(r->solid);
    ck_assert_mem_eq(r->solid, g->solid, hv_grid_count(g));
    hv_grid_destroy(&r);
    ck_assert_int_eq(hv_vdb_read_mask(p, "sphere", NULL, &r), HV_OK);
    for (size_t i = 0; i < hv_grid_count(g); i++) {
        ck_assert_int_eq(r->solid[i], g->v[i] < 0);
        ck_assert_float_eq(r->v[i], g->v[i] < 0 ? 1.0f : 0.0f);
    }
    hv_grid_destroy(&r);
    hv_grid_destroy(&g);
}
END_TEST

/* Signed distance to the axis-aligned box [lo, hi]. */
static double box_sdf(const double x[3], const double lo[3], const double hi[3])
{
    double out2 = 0, in = -1e300;
    for (int a = 0; a < 3; a++) {
        double c = 0.5 * (lo[a] + hi[a]), e = 0.5 * (hi[a] - lo[a]);
        double q = fabs(x[a] - c) - e;
        if (q > 0)
            out2 += q * q;
        if (q > in)
            in = q;
    }
    return out2 > 0 ? sqrt(out2) : in;
}

START_TEST(mesh_to_levelset_reference_should_match_the_box_sdf_near_the_surface)
{
    const double lo[3] = {-0.43, -0.31, -0.27}, hi[3] = {0.38, 0.35, 0.29};
    double v[8][3];
    for (int c = 0; c < 8; c++)
        for (int a = 0; a < 3; a++)
            v[c][a] = (c >> a) & 1 ? hi[a] : lo[a];
    /* 12 outward triangles; corner c has bit a set when at hi along axis a */
    static const uint32_t t[12][3] = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6},
                                      {0, 1, 4}, {1, 5, 4}, {2, 6, 3}, {3, 6, 7},
                                      {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
    int n[3] = {36, 32, 30};
    double o[3] = {-0.9, -0.8, -0.75}, h = 0.05;
    hv_grid *g = NULL;
    ck_assert_int_eq(hv_grid_create(&g, 3, n, h, o), HV_OK);
    double secs = -1;
    ck_assert_int_eq(ref_vdb_mesh_to_levelset(&v[0][0], 8, &t[0][0], 12, 3.0, g, &secs), HV_OK);
    ck_assert_double_ge(secs, 0);
    double max_err1 = 0, max_err2 = 0;
    size_t band = 0, wrong_sign = 0;
    const double bg = 3 * h;
    for (int k = 0; k < n[2]; k++)
        for (int j = 0; j < n[1]; j++)
            for (int i = 0; i < n[0]; i++) {
                double x[3];
                hv_grid_cell_center(g, i, j, k, x);
                double d = box_sdf(x, lo, hi), got = g->v[idx(g, i, j, k)];
                if (fabs(d) < h && fabs(got - d) > max_err1)
                    max_err1 = fabs(got - d);
                if (fabs(d) < 2 * h) {
                    band++;
                    if (fabs(got - d) > max_err2)
                        max_err2 = fabs(got - d);
                }
                if (fabs(d) > 0.5 * h && (got < 0) != (d < 0))
                    wrong_sign++;
                if (fabs(d) > bg + 0.5 * h)
                    ck_assert_double_eq_tol(fabs(got), bg, 1e-6);
            }
    ck_assert_uint_gt(band, 1000);
    ck_assert_uint_eq(wrong_sign, 0);
    /* OpenVDB computes exact distances in the voxels next to the surface and
     * approximates them farther out (band expansion from neighbours' closest
     * triangles, then renormalization): measured 3e-6 h within h, 0.13 h
     * within 2h on this box. */
    ck_assert_msg(max_err1 < 1e-3 * h, "max |phi - box sdf| within h: %g h", max_err1 / h);
    ck_assert_msg(max_err2 < 0.3 * h, "max |phi - box sdf| within 2h: %g h", max_err2 / h);
    printf("check_vdb: meshToLevelSet box %dx%dx%d: max error within h %.2e h, within 2h %.3f h, "
           "%.4f s\n",
           n[0], n[1], n[2], max_err1 / h, max_err2 / h, secs);

    uint32_t bad[3] = {0, 1, 8};
    ck_assert_int_eq(ref_vdb_mesh_to_levelset(&v[0][0], 8, bad, 1, 3.0, g, NULL),
                     HV_ERR_INVALID_ARG);
    hv_grid_destroy(&g);
}
END_TEST

START_TEST(sdf_to_ext_reference_should_extend_a_surface_field_along_normals)
{
    hv_grid *phi = sphere_sdf(), *fx = NULL, *fy = NULL, *fz = NULL, *ox = NULL, *oy = NULL,
            *oz = NULL;
    ck_assert_int_eq(hv_grid_create(&fx, 3, SN, SH, SO), HV_OK);
    ck_assert_int_eq(hv_grid_create(&fy, 3, SN, SH, SO), HV_OK);
    ck_assert_int_eq(hv_grid_create(&fz, 3, SN, SH, SO), HV_OK);
    ck_assert_int_eq(hv_grid_create(&ox, 3, SN, SH, SO), HV_OK);
    ck_assert_int_eq(hv_grid_create(&oy, 3, SN, SH, SO), HV_OK);
    ck_assert_int_eq(hv_grid_create(&oz, 3, SN, SH, SO), HV_OK);
    /* field = position; its extension is the closest point on the sphere */
    for (int k = 0; k < SN[2]; k++)
        for (int j = 0; j < SN[1]; j++)
            for (int i = 0; i < SN[0]; i++) {
                double x[3];
                hv_grid_cell_center(phi, i, j, k, x);
                fx->v[idx(phi, i, j, k)] = (float)x[0];
                fy->v[idx(phi, i, j, k)] = (float)x[1];
                fz->v[idx(phi, i, j, k)] = (float)x[2];
            }
    const float NOVAL = -1000.0f;
    double secs = -1;
    ck_assert_int_eq(ref_vdb_sdf_to_ext(phi, fx, 4.0, 1, NOVAL, ox, &secs), HV_OK);
    double max_err = 0, sum_err = 0;
    size_t cnt = 0;
    for (int k = 0; k < SN[2]; k++)
        for (int j = 0; j < SN[1]; j++)
            for (int i = 0; i < SN[0]; i++) {
                size_t q = idx(phi, i, j, k);
                double x[3];
                hv_grid_cell_center(phi, i, j, k, x);
                double r = SR + phi->v[q];
                double want = SC[0] + SR * (x[0] - SC[0]) / r;
                if (fabs(phi->v[q]) < 3 * SH) {
                    double e = fabs(ox->v[q] - want);
                    max_err = e > max_err ? e : max_err;
                    sum_err += e;
                    cnt++;
                } else if (fabs(phi->v[q]) > 4 * SH) {
                    ck_assert_float_eq(ox->v[q], NOVAL);
                }
            }
    printf("check_vdb: sdfToExt scalar on sphere R=%.0fh: |err| within 3h mean %.3f h, max %.3f h, "
           "%.4f s\n",
           SR / SH, sum_err / cnt / SH, max_err / SH, secs);
    /* first-order sweeping: errors of a fraction of a voxel; a callback fed
     * world coordinates read as index ones would be off by whole voxels */
    ck_assert_double_lt(sum_err / cnt, 0.15 * SH);
    ck_assert_double_lt(max_err, 0.75 * SH);

    /* the vector variant, computed everywhere (band <= 0) */
    ck_assert_int_eq(ref_vdb_sdf_to_ext_vec3(phi, fx, fy, fz, 0.0, 2, NOVAL, ox, oy, oz, NULL),
                     HV_OK);
    double vmax = 0, vsum = 0;
    size_t vcnt = 0, unset = 0;
    for (size_t q = 0; q < hv_grid_count(phi); q++) {
        int i = (int)(q % SN[0]), j = (int)(q / SN[0] % SN[1]), k = (int)(q / SN[0] / SN[1]);
        double x[3];
        hv_grid_cell_center(phi, i, j, k, x);
        double r = SR + phi->v[q];
        unset += ox->v[q] == NOVAL;
        if (fabs(phi->v[q]) >= 3 * SH || r < 2 * SH)
            continue;
        double e2 = 0, o[3] = {ox->v[q], oy->v[q], oz->v[q]};
        for (int a = 0; a < 3; a++) {
            double want = SC[a] + SR * (x[a] - SC[a]) / r;
            e2 += (o[a] - want) * (o[a] - want);
        }
        vmax = sqrt(e2) > vmax ? sqrt(e2) : vmax;
        vsum += sqrt(e2);
        vcnt++;
    }
    ck_assert_uint_eq(unset, 0);
    ck_assert_double_lt(vsum / vcnt, 0.25 * SH);
    ck_assert_double_lt(vmax, 1.0 * SH);
    printf("check_vdb: sdfToExt vec3: |err| within 3h mean %.3f h, max %.3f h\n", vsum / vcnt / SH,
           vmax / SH);

    /* a field without a zero crossing is refused */
    for (size_t q = 0; q < hv_grid_count(phi); q++)
        fx->v[q] = 1.0f;
    ck_assert_int_eq(ref_vdb_sdf_to_ext(fx, fy, 3.0, 1, 0.0f, ox, NULL), HV_ERR_INVALID_ARG);
    hv_grid_destroy(&phi);
    hv_grid_destroy(&fx);
    hv_grid_destroy(&fy);
    hv_grid_destroy(&fz);
    hv_grid_destroy(&ox);
    hv_grid_destroy(&oy);
    hv_grid_destroy(&oz);
}
END_TEST

/* ---- damaged files ------------------------------------------------------------
 * OpenVDB trusts the lengths and counts it reads: a cut or damaged file made it
 * allocate gigabytes. Each damaged file is read by the heatvox command in a
 * child process whose address space is capped, so that a regression fails the
 * test instead of taking the machine down. */

#define CHILD_AS_BYTES (1536ull << 20)
#define CHILD_RSS_MAX_KB (300L * 1024)
#define CHILD_SECONDS 60

extern char **environ;

typedef struct child_result {
    int status;     /* from wait4 */
    long maxrss_kb; /* the child's peak resident size */
    char err[4096]; /* its stderr */
} child_result;

/* The environment for the children: ours, with few threads and malloc arenas
 * so that the address-space cap only bites on real allocations. */
static char **child_env(void)
{
    static char *env[512];
    static char arenas[] = "MALLOC_ARENA_MAX=2", omp[] = "OMP_NUM_THREADS=2";
    size_t n = 0;
    for (char **e = environ; *e && n < 500; e++)
        if (strncmp(*e, "MALLOC_ARENA_MAX=", 17) && strncmp(*e, "OMP_NUM_THREADS=", 16))
            env[n++] = *e;
    env[n++] = arenas;
    env[n++] = omp;
    env[n] = NULL;
    return env;
}

/* Runs argv (argv[0] a path) with stdout discarded, stderr in errfile,
 * CHILD_SECONDS to live and, when capped, its address space capped at
 * CHILD_AS_BYTES. */
static void run_child(char *const argv[], const char *errfile, int capped, child_result *r)
{
    char **env = child_env();
    pid_t pid = fork();
    ck_assert_int_ge(pid, 0);
    if (pid == 0) {
        /* Only async-signal-safe calls until exec: the parent has OpenVDB's threads. */
        struct rlimit rl = {CHILD_AS_BYTES, CHILD_AS_BYTES};
        int out = open("/dev/null", O_WRONLY | O_CLOEXEC);
        int err = open(errfile, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
        if ((capped && setrlimit(RLIMIT_AS, &rl) != 0) || out < 0 || err < 0 || dup2(out, 1) < 0 ||
            dup2(err, 2) < 0)
            _exit(126);
        alarm(CHILD_SECONDS);
        execve(argv[0], argv, env);
        _exit(127);
    }
    struct rusage ru;
    pid_t w;
    while ((w = wait4(pid, &r->status, 0, &ru)) < 0 && errno == EINTR)
        ;
    ck_assert_int_eq(w, pid);
    r->maxrss_kb = ru.ru_maxrss;
    r->err[0] = '\0';
    FILE *f = fopen(errfile, "r");
    if (f) {
        size_t n = fread(r->err, 1, sizeof r->err - 1, f);
        r->err[n] = '\0';
        fclose(f);
    }
}

/* A file with three grids the commands read: level set 'sdf' (narrow band:
 * mask-compressed leaves), Vec3s 'v' and bool 'm'. */
static void write_three_grids(const char *path)
{
    hv_grid *g = sphere_sdf();
    hv_grid *c[3] = {NULL, NULL, NULL};
    for (int a = 0; a < 3; a++) {
        ck_assert_int_eq(hv_grid_create(&c[a], 3, SN, SH, SO), HV_OK);
        for (int k = 0; k < SN[2]; k++)
            for (int j = 0; j < SN[1]; j++)
                for (int i = 0; i < SN[0]; i++) {
                    double x[3];
                    hv_grid_cell_center(g, i, j, k, x);
                    c[a]->v[idx(g, i, j, k)] = (float)x[(a + 1) % 3];
                }
    }
    ck_assert_int_eq(hv_grid_add_mask(g), HV_OK);
    for (size_t i = 0; i < hv_grid_count(g); i++)
        g->solid[i] = g->v[i] < 0;
    hv_vdb_writer *w = NULL;
    ck_assert_int_eq(hv_vdb_writer_create(&w), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_add_levelset(w, g, "sdf", 3.0, 0), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_add_vec3(w, c[0], c[1], c[2], "v"), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_add_mask(w, g, "m"), HV_OK);
    ck_assert_int_eq(hv_vdb_writer_write(w, path), HV_OK);
    hv_vdb_writer_destroy(&w);
    for (int a = 0; a < 3; a++)
        hv_grid_destroy(&c[a]);
    hv_grid_destroy(&g);
}

static unsigned char *slurp(const char *path, size_t *size)
{
    FILE *f = fopen(path, "rb");
    ck_assert_ptr_nonnull(f);
    ck_assert_int_eq(fseek(f, 0, SEEK_END), 0);
    long n = ftell(f);
    ck_assert_int_gt(n, 0);
    rewind(f);
    unsigned char *b = malloc((size_t)n);
    ck_assert_ptr_nonnull(b);
    ck_assert_uint_eq(fread(b, 1, (size_t)n, f), (size_t)n);
    fclose(f);
    *size = (size_t)n;
    return b;
}

static void spill(const char *path, const unsigned char *b, size_t n)
{
    FILE *f = fopen(path, "wb");
    ck_assert_ptr_nonnull(f);
    ck_assert_uint_eq(fwrite(b, 1, n, f), n);
    ck_assert_int_eq(fclose(f), 0);
}

/* Offset of the first occurrence of the n bytes s in b at or after from. */
static size_t find_bytes(const unsigned char *b, size_t size, size_t from, const void *s, size_t n)
{
    for (size_t i = from; i + n <= size; i++)
        if (!memcmp(b + i, s, n))
            return i;
    ck_abort_msg("byte pattern not found in the test file");
    return 0;
}

/* A length field, and what to put there: each is a size or count that OpenVDB
 * would allocate (and fill) before finding that the file cannot back it. */
typedef struct length_patch {
    const char *what;
    size_t at;
    unsigned width; /* 4 or 8 bytes */
    uint64_t value;
} length_patch;

static size_t find_length_patches(const unsigned char *b, size_t size, length_patch *p)
{
    size_t n = 0;
    /* file metadata: the length of the first name, "creator" */
    size_t at = find_bytes(b, size, 0, "\x07\0\0\0creator", 11);
    p[n++] = (length_patch){"file metadata name length", at, 4, 0x40000000u};
    /* the grid count, just before the first descriptor's name "sdf" */
    size_t sdf = find_bytes(b, size, at, "\x03\0\0\0sdf", 7);
    p[n++] = (length_patch){"grid count", sdf - 4, 4, 0x7fffffffu};
    /* descriptor of 'sdf': its type's length, then its end position */
    size_t type = find_bytes(b, size, sdf, "\x10\0\0\0Tree_float_5_4_3", 20);
    p[n++] = (length_patch){"grid type length", type, 4, 0x50000000u};
    p[n++] = (length_patch){"grid end position", type + 20 + 4 + 16, 8, 1ull << 40};
    /* the grid's own metadata: the size of its 'class' string value */
    size_t cls = find_bytes(b, size, type, "\x05\0\0\0class\x06\0\0\0string", 19);
    p[n++] = (length_patch){"metadata value size", cls + 19, 4, 0x40000000u};
    /* OpenVDB's delayed-load metadata: its size, and its leaf count */
    size_t dl = find_bytes(b, size, cls, "__delayedload", 13);
    p[n++] = (length_patch){"delayed-load metadata size", dl + 13, 4, 0x40000000u};
    p[n++] = (length_patch){"delayed-load leaf count", dl + 17, 4, 0x7fffffffu};
    /* the root's child count: after the transform (map type, 144 bytes of
     * ScaleTranslateMap) come the buffer count, background and tile count */
    size_t map = find_bytes(b, size, dl, "\x18\0\0\0UniformScaleTranslateMap", 28);
    p[n++] = (length_patch){"root child count", map + 28 + 144 + 12, 4, 0x00ffffffu};
    /* the second descriptor's type length (grid 'v') */
    size_t vt = find_bytes(b, size, dl, "\x10\0\0\0Tree_vec3s_5_4_3", 20);
    p[n++] = (length_patch){"second grid type length", vt, 4, 0xffffffffu};
    return n;
}

START_TEST(damaged_files_should_fail_with_small_memory_naming_the_file)
{
    const char *bin = tl_heatvox_bin();
    ck_assert_msg(bin != NULL, "no heatvox command (make builds it; or set HEATVOX_BIN)");
    char good[256], bad[256], src[256], errf[256], out_vdb[256], out_exr[256];
    path_in_dir(good, sizeof good, "good.vdb");
    path_in_dir(bad, sizeof bad, "bad.vdb");
    path_in_dir(src, sizeof src, "sources.txt");
    path_in_dir(errf, sizeof errf, "stderr.txt");
    path_in_dir(out_vdb, sizeof out_vdb, "out.vdb");
    path_in_dir(out_exr, sizeof out_exr, "out.exr");
    write_three_grids(good);
    FILE *f = fopen(src, "w");
    ck_assert_ptr_nonnull(f);
    fprintf(f, "point %g %g %g\n", SO[0] + 0.1, SO[1] + 0.1, SO[2] + 0.1); /* outside the sphere */
    fclose(f);
    size_t size = 0;
    unsigned char *data = slurp(good, &size);
    char exe[1024];
    snprintf(exe, sizeof exe, "%s", bin);

    /* Three readers: extend (level set + vec3 through hv_vdb_list, common box,
     * read_float, read_vec3), slice (read_float), distance (list, meta, mask). */
    char *cmds[3][16] = {
        {exe, "extend", bad, "--levelset", "sdf", "--field", "v", "-o", out_vdb, "--backend", "mg",
         "--threads", "2", "-q", NULL},
        {exe, "slice", bad, "--grid", "sdf", "-o", out_exr, NULL},
        {exe, "distance", "--sources", src, "--obstacles", bad, "--obstacle-grid", "m", "-o",
         out_vdb, "--backend", "mg", "--threads", "2", "-q", NULL},
    };
    child_result r;
    /* The intact file reads under the same limits: a failure below is the
     * damage. A binary that cannot start under the cap at all (a sanitizer
     * build reserves terabytes of address space) skips the test. */
    spill(bad, data, size);
    for (int c = 0; c < 3; c++) {
        run_child(cmds[c], errf, 1, &r);
        if (!WIFEXITED(r.status) || WEXITSTATUS(r.status) != 0) {
            child_result u;
            run_child(cmds[c], errf, 0, &u);
            ck_assert_msg(WIFEXITED(u.status) && WEXITSTATUS(u.status) == 0,
                          "%s on the intact file: status 0x%x: %s", cmds[c][1], u.status, u.err);
            r.err[strcspn(r.err, "\n")] = '\0';
            free(data);
            TL_SKIP("%s does not run under a %llu MB address-space cap (%s)", bin,
                    CHILD_AS_BYTES >> 20, r.err);
        }
        unlink(out_vdb);
        unlink(out_exr);
    }
    const int files_before = count_entries(dir);

    /* Cuts: the first bytes only, every length at a stride, all but the last byte. */
    size_t cuts[64];
    size_t ncut = 0;
    const size_t fixed[] = {0, 1, 100, 4000, size - 1};
    for (size_t i = 0; i < sizeof fixed / sizeof *fixed; i++)
        cuts[ncut++] = fixed[i];
    for (size_t k = 1; k < 40; k++)
        cuts[ncut++] = size * k / 40;
    length_patch patches[16];
    const size_t npatch = find_length_patches(data, size, patches);

    /* Every case runs; the failures are listed together at the end. */
    unsigned char *copy = malloc(size);
    ck_assert_ptr_nonnull(copy);
    char report[8192];
    size_t used = 0;
    int failed = 0;
    long worst_kb = 0;
    const size_t ncase = ncut + npatch;
    for (size_t q = 0; q < ncase; q++) {
        char what[128];
        if (q < ncut) {
            spill(bad, data, cuts[q]);
            snprintf(what, sizeof what, "cut to %zu of %zu bytes", cuts[q], size);
        } else {
            const length_patch *p = &patches[q - ncut];
            memcpy(copy, data, size);
            memcpy(copy + p->at, &p->value, p->width); /* little-endian, as OpenVDB writes */
            spill(bad, copy, size);
            snprintf(what, sizeof what, "%s at byte %zu set to %llu", p->what, p->at,
                     (unsigned long long)p->value);
        }
        char *const *argv = cmds[q % 3];
        run_child(argv, errf, 1, &r);
        const char *wrong = NULL;
        if (!WIFEXITED(r.status) || WEXITSTATUS(r.status) != 1)
            wrong = WIFSIGNALED(r.status) ? "killed by a signal" : "exit status not 1";
        else if (r.maxrss_kb >= CHILD_RSS_MAX_KB)
            wrong = "too much memory";
        else if (!strstr(r.err, bad))
            wrong = "the message does not name the file";
        else if (access(out_vdb, F_OK) == 0 || access(out_exr, F_OK) == 0 ||
                 count_entries(dir) != files_before)
            wrong = "an output was written";
        if (r.maxrss_kb > worst_kb)
            worst_kb = r.maxrss_kb;
        unlink(out_vdb);
        unlink(out_exr);
        if (wrong) {
            failed++;
            r.err[strcspn(r.err, "\n")] = '\0';
            int k = snprintf(report + used, sizeof report - used,
                             "\n  %s, %s: %s (status 0x%x, peak %ld kB): %.160s", argv[1], what,
                             wrong, r.status, r.maxrss_kb, r.err);
            if (k > 0 && (size_t)k < sizeof report - used)
                used += (size_t)k;
        }
    }
    printf("check_vdb: %zu damaged files read by heatvox, peak resident size at most %ld kB\n",
           ncase, worst_kb);
    ck_assert_msg(failed == 0, "%d of %zu damaged files were not refused quickly and cheaply:%s",
                  failed, ncase, report);
    free(copy);
    free(data);
}
END_TEST

/* A patched copy of the file at src must be refused by every read of grid
 * `name`: no OK status, no crash, a message naming the copy and holding
 * `expect`. */
static void expect_refused(const char *bad, const unsigned char *b, size_t size, const char *name,
                           int vec3, const hv_vdb_read_opts *opts, const char *expect)
{
    spill(bad, b, size);
    hv_grid *g[3] = {NULL, NULL, NULL};
    hv_status st = vec3 ? hv_vdb_read_vec3(bad, name, opts, &g[0], &g[1], &g[2])
                        : hv_vdb_read_float(bad, name, opts, &g[0], NULL);
    ck_assert_msg(st == HV_ERR_IO, "grid '%s': status %d: %s", name, (int)st, hv_last_error());
    ck_assert_msg(strstr(hv_last_error(), bad) && strstr(hv_last_error(), expect),
                  "grid '%s': %s (expected to name the file and hold '%s')", name, hv_last_error(),
                  expect);
    for (int a = 0; a < 3; a++)
        ck_assert_ptr_null(g[a]);
}

/* OpenVDB reads a tree as half floats when the grid's own metadata says so
 * (is_saved_as_half_float, which replaces the descriptor's "_HalfFloat" flag),
 * and takes every root tile for 4096^3 voxels from its origin. */
START_TEST(half_float_grids_and_root_tiles_should_read_and_their_damage_be_refused)
{
    require_pyopenvdb();
    char p[256], bad[256], cmd[2048];
    path_in_dir(p, sizeof p, "half.vdb");
    path_in_dir(bad, sizeof bad, "bad.vdb");
    /* values exact in half precision; 't' is one active root tile */
    snprintf(cmd, sizeof cmd,
             "/usr/bin/python3 -c 'import sys, pyopenvdb as vdb\n"
             "v = vdb.Vec3SGrid(); v.name = \"v\"; v.saveFloatAsHalf = True; a = v.getAccessor()\n"
             "f = vdb.FloatGrid(); f.name = \"f\"; f.saveFloatAsHalf = True; b = f.getAccessor()\n"
             "for i in range(6):\n"
             " for j in range(5):\n"
             "  for k in range(4):\n"
             "   a.setValueOn((i, j, k), (i + 0.5, j * 0.25, -k))\n"
             "   b.setValueOn((i, j, k), i * 8 + j - k * 0.125)\n"
             "t = vdb.FloatGrid(); t.name = \"t\"\n"
             "t.fill((4096, 8192, 12288), (8191, 12287, 16383), 2.5, True)\n"
             "vdb.write(sys.argv[1], grids=[v, f, t])\n"
             "' %s",
             p);
    ck_assert_int_eq(system(cmd), 0);

    hv_grid *g[3] = {NULL, NULL, NULL};
    ck_assert_int_eq(hv_vdb_read_vec3(p, "v", NULL, &g[0], &g[1], &g[2]), HV_OK);
    ck_assert_int_eq(g[0]->n[0], 6);
    ck_assert_int_eq(g[0]->n[1], 5);
    ck_assert_int_eq(g[0]->n[2], 4);
    for (int k = 0; k < 4; k++)
        for (int j = 0; j < 5; j++)
            for (int i = 0; i < 6; i++) {
                const size_t q = idx(g[0], i, j, k);
                ck_assert_float_eq(g[0]->v[q], i + 0.5f);
                ck_assert_float_eq(g[1]->v[q], j * 0.25f);
                ck_assert_float_eq(g[2]->v[q], (float)-k);
            }
    for (int a = 0; a < 3; a++)
        hv_grid_destroy(&g[a]);
    ck_assert_int_eq(hv_vdb_read_float(p, "f", NULL, &g[0], NULL), HV_OK);
    for (int k = 0; k < 4; k++)
        for (int j = 0; j < 5; j++)
            for (int i = 0; i < 6; i++)
                ck_assert_float_eq(g[0]->v[idx(g[0], i, j, k)], i * 8 + j - k * 0.125f);
    hv_grid_destroy(&g[0]);
    const hv_vdb_read_opts in_tile = {1, {5000, 9000, 13000}, {5001, 9001, 13001}};
    ck_assert_int_eq(hv_vdb_read_float(p, "t", &in_tile, &g[0], NULL), HV_OK);
    for (size_t q = 0; q < hv_grid_count(g[0]); q++)
        ck_assert_float_eq(g[0]->v[q], 2.5f);
    hv_grid_destroy(&g[0]);

    size_t size = 0;
    unsigned char *data = slurp(p, &size);
    unsigned char *copy = malloc(size);
    ck_assert_ptr_nonnull(copy);
    /* 'v' (the first grid) with its half-float flag false: OpenVDB would read
     * its half-float blocks as full floats */
    static const char flag[] = "\x16\0\0\0is_saved_as_half_float\x04\0\0\0bool\x01\0\0\0";
    const size_t fv = find_bytes(data, size, 0, flag, sizeof flag - 1) + sizeof flag - 1;
    ck_assert_int_eq(data[fv], 1);
    memcpy(copy, data, size);
    copy[fv] = 0;
    expect_refused(bad, copy, size, "v", 1, NULL, "grid 'v'");
    /* the root tile of 't' (origin, value, active; file_bbox_min holds the
     * same origin) moved to y = 2^31 - 256: its extent ends past INT_MAX */
    unsigned char tile[17];
    const int32_t origin[3] = {4096, 8192, 12288};
    const float tile_value = 2.5f;
    memcpy(tile, origin, 12);
    memcpy(tile + 12, &tile_value, 4);
    tile[16] = 1;
    const size_t to = find_bytes(data, size, 0, tile, sizeof tile);
    memcpy(copy, data, size);
    const int32_t y = 2147483392;
    memcpy(copy + to + 4, &y, 4);
    expect_refused(bad, copy, size, "t", 0, &in_tile, "int32 coordinate range");
    /* ... or off the 4096-voxel lattice */
    memcpy(copy, data, size);
    const int32_t x = 4096 + 64;
    memcpy(copy + to, &x, 4);
    expect_refused(bad, copy, size, "t", 0, &in_tile, "4096-voxel lattice");
    free(copy);
    free(data);

    /* A full-float file (heatvox's) whose 'v' half-float flag has an unknown
     * type: OpenVDB keeps the raw byte, and a non-empty unknown value reads as
     * true, so it would read 'v' as half floats (the fuzzer's input). */
    write_three_grids(p);
    data = slurp(p, &size);
    const size_t vt = find_bytes(data, size, 0, "\x10\0\0\0Tree_vec3s_5_4_3", 20);
    const size_t fb = find_bytes(data, size, vt, flag, sizeof flag - 1) + sizeof flag - 1 - 8;
    ck_assert_int_eq(memcmp(data + fb, "bool", 4), 0);
    data[fb + 1] = 'O';
    expect_refused(bad, data, size, "v", 1, NULL, "values saved as half floats");
    free(data);
}
END_TEST

int main(int argc, char **argv)
{
    /* The heatvox command of this build (BUILD/tests/check_vdb -> BUILD/heatvox)
     * unless HEATVOX_BIN names one. */
    char bin[4096];
    snprintf(bin, sizeof bin, "%s", argc > 0 ? argv[0] : "");
    char *slash = strrchr(bin, '/');
    if (!getenv("HEATVOX_BIN") && slash) {
        snprintf(slash + 1, sizeof bin - (size_t)(slash + 1 - bin), "../heatvox");
        if (access(bin, X_OK) == 0)
            setenv("HEATVOX_BIN", bin, 0);
    }
    Suite *s = suite_create("vdb");
    TCase *tc = tcase_create("vdb");
    /* a scratch directory per test, removed even when the test fails */
    tcase_add_checked_fixture(tc, make_dir, remove_dir);
    tcase_set_timeout(tc, 120);
    tcase_add_test(tc, levelset_round_trip_should_keep_band_values_and_signed_background);
    tcase_add_test(tc, levelset_read_with_a_larger_box_should_place_the_block_and_keep_signs);
    tcase_add_test(tc, dense_levelset_should_keep_every_value_and_activate_every_voxel);
    tcase_add_test(tc, openvdb_own_reader_should_see_the_level_set_we_wrote);
    tcase_add_test(
        tc, files_made_by_openvdb_should_read_on_their_active_box_and_refuse_nonuniform_voxels);
    tcase_add_test(tc, vec3_round_trip_should_keep_each_component);
    tcase_add_test(tc, writing_into_a_missing_directory_should_fail_with_io_and_leave_no_temporary);
    tcase_add_test(tc, reading_a_missing_grid_should_name_it_the_file_and_what_is_there);
    tcase_add_test(tc, missing_and_corrupt_files_should_give_io_errors_naming_the_file);
    tcase_add_test(tc, metadata_should_round_trip_on_file_and_grid);
    tcase_add_test(tc, common_box_should_cover_all_grids_and_refuse_mismatched_transforms);
    tcase_add_test(tc,
                   index_origin_should_keep_the_input_index_space_and_refuse_off_lattice_blocks);
    tcase_add_test(tc, masks_should_round_trip_and_level_sets_should_read_as_their_inside);
    tcase_add_test(tc, mesh_to_levelset_reference_should_match_the_box_sdf_near_the_surface);
    tcase_add_test(tc, sdf_to_ext_reference_should_extend_a_surface_field_along_normals);
    tcase_add_test(tc, damaged_files_should_fail_with_small_memory_naming_the_file);
    tcase_add_test(tc, half_float_grids_and_root_tiles_should_read_and_their_damage_be_refused);
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
