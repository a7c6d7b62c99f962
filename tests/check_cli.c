/* The command as a new user meets it: a resolution too large for the machine
 * is a usage error naming the option, a broken vertex is named by its line,
 * messages name a file once, outputs are checked by their extension, progress
 * appears on a terminal alone and advances through the long stages, --units
 * m scales to metres. */
#include "heatvox/heatvox.h"
#include "testlib.h"

#include <check.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static char dir[256];
static char bin[PATH_MAX];

static void setup(void) { tl_scratch_scenes("check_cli", dir, sizeof dir, bin, sizeof bin); }

static void teardown(void)
{
    tl_rm_rf(dir);
    *dir = '\0';
}

/* Runs `heatvox ARGS` in dir; stderr lands in err. Returns the exit code. */
#define hv(err, errsize, ...) tl_hv(dir, bin, err, errsize, __VA_ARGS__)

static int exists(const char *name)
{
    char p[600];
    snprintf(p, sizeof p, "%s/%s", dir, name);
    return access(p, F_OK) == 0;
}

static int count(const char *hay, const char *needle)
{
    int n = 0;
    for (const char *p = strstr(hay, needle); p; p = strstr(p + 1, needle))
        n++;
    return n;
}

/* The narrow band's own check refuses --res 20000 on machines under 64 GB
 * (its tree), after the binning (5 s); the others fail before any work. */
START_TEST(a_resolution_too_large_should_be_a_usage_error_naming_the_option)
{
    const char *cases[] = {
        "sdf sc/meshes/torus_holes.obj -o t.vdb --res 100000",
        "sdf sc/meshes/torus_holes.obj -o t.vdb --res 20000",
        "sdf sc/meshes/torus_holes.obj -o t.vdb --res 100000 --dense",
        "sdf sc/meshes/torus_holes.obj -o t.vdb --voxel-size 1e-6",
    };
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        char err[4096];
        int rc = hv(err, sizeof err, "%s", cases[c]);
        ck_assert_msg(rc == 2, "%s: exit %d (%s)", cases[c], rc, err);
        ck_assert_msg(strstr(err, strstr(cases[c], "--res") ? "--res " : "--voxel-size "),
                      "%s: the option is not named: %s", cases[c], err);
        ck_assert_msg(strstr(err, " GB, more than "), "%s: %s", cases[c], err);
        ck_assert_msg(!strstr(err, "tiles") && !strstr(err, "2^32"), "%s: jargon: %s", cases[c],
                      err);
        ck_assert_msg(!strstr(err, "torus_holes.obj:"), "%s: blames the mesh: %s", cases[c], err);
        ck_assert(!exists("t.vdb"));
    }
}
END_TEST

/* Options read from tables (cli_parse): the same words for the same mistake
 * in every command, exit 2, nothing written. */
START_TEST(option_errors_should_read_alike_in_every_command)
{
    const struct {
        const char *args, *says;
    } cases[] = {
        {"sdf sc/meshes/torus_holes.obj -o t.vdb --band 0",
         "sdf: --band needs a positive number of voxels, got '0'"},
        {"extend sc/levelset/sphere_velocity.vdb --levelset s --field v -o t.vdb --band 0",
         "extend: --band needs a positive number of voxels, got '0'"},
        {"sdf sc/meshes/torus_holes.obj -o t.vdb --res", "sdf: --res needs 1 value"},
        {"extend sc/levelset/sphere_velocity.vdb --levelset", "extend: --levelset needs 1 value"},
        {"sdf sc/meshes/torus_holes.obj -o t.vdb --frob", "sdf: unknown option '--frob'"},
        {"extend sc/levelset/sphere_velocity.vdb --frob", "extend: unknown option '--frob'"},
        {"extend sc/levelset/sphere_velocity.vdb --field v --field v",
         "extend: --field 'v' given twice"},
        {"sdf a.obj b.obj -o t.vdb", "sdf: more than one mesh given ('a.obj' and 'b.obj')"},
        {"extend a.vdb b.vdb", "extend: more than one input file given ('a.vdb' and 'b.vdb')"},
        {"sdf sc/meshes/torus_holes.obj -o t.vdb --backend petsc",
         "sdf: --backend must be auto, mg, fftw or opencl, got 'petsc'"},
        {"sdf sc/meshes/torus_holes.obj -o t.vdb --bbox 0 0 0 1 1", "sdf: --bbox needs 6 values"},
        {"distance --sources sc/distance/sources.txt -o t.vdb --res 2",
         "distance: --res needs an integer >= 4, got '2'"},
        {"distance --sources sc/distance/sources.txt -o t.vdb --frob",
         "distance: unknown option '--frob'"},
        {"distance --sources sc/distance/sources.txt -o t.vdb --obstacles",
         "distance: --obstacles needs 1 value"},
        {"sdf2d x.txt -o t.exr --res 1", "sdf2d: --res needs an integer >= 2, got '1'"},
        {"sdf2d x.txt y.txt -o t.exr",
         "sdf2d: more than one curves file given ('x.txt' and 'y.txt')"},
        {"slice x.vdb -o t.png --axis w", "slice: --axis needs x, y or z, got 'w'"},
        {"slice x.vdb -o t.png --index -1", "slice: --index needs an integer >= 0, got '-1'"},
        {"info --frob", "info: unknown option '--frob'"},
        {"batch sc/meshes -o t --res 1", "batch: --res needs an integer >= 2, got '1'"},
        {"batch sc/meshes -o t --format png", "batch: --format needs vdb or exr, got 'png'"},
        {"batch sc/meshes -o t -j 0", "batch: -j needs an integer in 1..256, got '0'"},
        {"bench solve --n 8 --smoother sor",
         "bench solve: --smoother needs rbgs, jacobi or chebyshev, got 'sor'"},
        {"bench solve --n 8 --backend auto",
         "bench solve: --backend must be mg, fftw, opencl or petsc, got 'auto'"},
        {"bench extend --n 8", "bench extend: --n needs an integer >= 16, got '8'"},
        {"bench band a.obj b.obj --n 64",
         "bench band: more than one mesh given ('a.obj' and 'b.obj')"},
        {"bench points x.obj --n 8", "bench points: --n needs an integer in 16..4096, got '8'"},
        {"bench points x.obj --n 64 --scenario dusty",
         "bench points: --scenario 'dusty': one of clean, uneven, density-4, noise-0.25, "
         "noise-0.5, flipped-10, hole, all"},
    };
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        char err[4096];
        int rc = hv(err, sizeof err, "%s", cases[c].args);
        ck_assert_msg(rc == 2, "%s: exit %d (%s)", cases[c].args, rc, err);
        ck_assert_msg(strstr(err, cases[c].says), "%s: says\n%s\nnot\n%s", cases[c].args, err,
                      cases[c].says);
        ck_assert(!exists("t.vdb"));
    }
}
END_TEST

START_TEST(a_non_finite_vertex_should_be_named_by_its_line)
{
    char path[600];
    snprintf(path, sizeof path, "%s/nan.obj", dir);
    FILE *f = fopen(path, "w");
    ck_assert_ptr_nonnull(f);
    fputs("# a tetrahedron with one broken vertex\n"
          "v 0 0 0\nv 1 0 0\nv 0 1 0\n\n"
          "v 0 0 nan\n"
          "f 1 2 3\nf 1 2 4\nf 2 3 4\nf 3 1 4\n",
          f);
    fclose(f);
    /* The same in binary STL: the 1-based place among the file's vertices. */
    snprintf(path, sizeof path, "%s/nan.stl", dir);
    f = fopen(path, "wb");
    ck_assert_ptr_nonnull(f);
    char header[80] = "binary";
    fwrite(header, 1, 80, f);
    uint32_t nt = 2;
    fwrite(&nt, 4, 1, f);
    const float tri[2][12] = {{0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 1, 0},
                              {0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, NAN}};
    for (int t = 0; t < 2; t++) {
        fwrite(tri[t], 4, 12, f);
        fwrite("\0\0", 1, 2, f);
    }
    fclose(f);
    char err[4096];
    int rc = hv(err, sizeof err, "sdf nan.obj -o n.vdb --res 16");
    ck_assert_msg(rc == 1, "exit %d (%s)", rc, err);
    ck_assert_msg(strstr(err, "nan.obj") && strstr(err, "line 6: vertex 4 "), "%s", err);
    rc = hv(err, sizeof err, "sdf nan.obj -o n.vdb --res 16 --no-repair --sign heat");
    ck_assert_msg(rc == 1 && strstr(err, "line 6: vertex 4 "), "exit %d: %s", rc, err);
    rc = hv(err, sizeof err, "sdf nan.stl -o n.vdb --res 16");
    ck_assert_msg(rc == 1, "exit %d (%s)", rc, err);
    ck_assert_msg(strstr(err, "vertex 6 of the file"), "%s", err);
}
END_TEST

START_TEST(messages_should_name_a_file_once)
{
    char err[4096];
    ck_assert_int_eq(hv(err, sizeof err, "sdf sc/meshes/torus_holes.obj -o t.vdb --res 16 -q"), 0);
    int rc = hv(err, sizeof err, "slice t.vdb --grid nosuch -o s.exr");
    ck_assert_msg(rc == 1, "exit %d (%s)", rc, err);
    ck_assert_msg(count(err, "t.vdb") == 1 && strstr(err, "no grid named 'nosuch'"), "%s", err);
    ck_assert(!exists("s.exr"));
}
END_TEST

START_TEST(outputs_should_be_checked_by_their_extension)
{
    const char *cases[] = {
        "sdf sc/meshes/torus_holes.obj -o x.txt --res 16",
        "sdf sc/meshes/torus_holes.obj -o x.vdb --npy x.txt --res 16",
        "sdf sc/meshes/torus_holes.obj -o x.vdb --preview x.txt --res 16",
        "extend sc/levelset/sphere_velocity.vdb --levelset sdf --field v -o x.txt",
        "distance --sources sc/distance/sources.txt --obstacles none --res 16 -o x.txt",
        "distance --sources sc/distance/sources.txt --obstacles none --res 16 --npy x.txt",
        "sdf2d sc/distance/sources_2d.txt -o x.txt",
        "slice sc/levelset/sphere_velocity.vdb --grid sdf -o x.txt",
    };
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        char err[4096];
        int rc = hv(err, sizeof err, "%s", cases[c]);
        ck_assert_msg(rc == 2, "%s: exit %d (%s)", cases[c], rc, err);
        ck_assert_msg(strstr(err, "x.txt"), "%s: %s", cases[c], err);
        ck_assert_msg(!exists("x.txt") && !exists("x.vdb"), "%s: wrote a file", cases[c]);
    }
    /* Any case of the right extension is taken. */
    char err[4096];
    int rc = hv(err, sizeof err, "sdf sc/meshes/torus_holes.obj -o X.VDB --res 16 -q");
    ck_assert_msg(rc == 0, "exit %d (%s)", rc, err);
}
END_TEST

START_TEST(progress_should_not_reach_a_log_even_with_v)
{
    char err[8192];
    int rc = hv(err, sizeof err, "sdf sc/meshes/torus_holes.obj -o t.vdb --res 48 --dense -v");
    ck_assert_msg(rc == 0, "exit %d (%s)", rc, err);
    ck_assert_msg(!strstr(err, "%  peak"), "progress in a log: %s", err);
    ck_assert_msg(strstr(err, "repair") != NULL, "-v gave no details: %s", err);
}
END_TEST

/* The fractions a run reports, and whether they only grow. */
typedef struct {
    double f[4096];
    char stage[4096][16];
    int n;
} seen;

static int record(double fraction, const char *stage, void *user)
{
    seen *s = user;
    if (s->n < 4096) {
        s->f[s->n] = fraction;
        snprintf(s->stage[s->n], sizeof s->stage[0], "%s", stage);
        s->n++;
    }
    return 0;
}

static int distinct_in(const seen *s, const char *stage, double lo, double hi)
{
    int n = 0;
    for (int i = 0; i < s->n; i++)
        n += !strcmp(s->stage[i], stage) && s->f[i] > lo && s->f[i] < hi &&
             (i == 0 || s->f[i] != s->f[i - 1]);
    return n;
}

START_TEST(long_stages_should_advance)
{
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_make_torus(&m, (double[3]){0, 0, 0}, 1.0, 0.35, 96, 48));
    static seen s;
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = 96;
    /* Dense: the redistance between 85% and 95% reports as it goes. */
    s.n = 0;
    hv_set_progress(record, &s);
    hv_grid *g = NULL;
    hv_sdf_stats S;
    hv_status st = hv_sdf_compute(m, &o, &g, &S);
    hv_set_progress(NULL, NULL);
    TL_ASSERT_OK(st);
    hv_grid_destroy(&g);
    for (int i = 1; i < s.n; i++)
        ck_assert_msg(s.f[i] >= s.f[i - 1], "%s %g after %g", s.stage[i], s.f[i], s.f[i - 1]);
    ck_assert_msg(distinct_in(&s, "redistance", 0.85, 0.95) >= 3, "redistance reported %d times",
                  distinct_in(&s, "redistance", 0.85, 0.95));
    /* Tiles: the raster between 30% and 90%. */
    s.n = 0;
    hv_set_progress(record, &s);
    hv_tiles *T = NULL;
    o.res = 400;
    st = hv_sdf_compute_tiles(m, &o, 3.0, &T, &S);
    hv_set_progress(NULL, NULL);
    TL_ASSERT_OK(st);
    hv_tiles_destroy(&T);
    for (int i = 1; i < s.n; i++)
        ck_assert_msg(s.f[i] >= s.f[i - 1], "%s %g after %g", s.stage[i], s.f[i], s.f[i - 1]);
    ck_assert_msg(distinct_in(&s, "tiles", 0.3, 0.9) >= 3, "tiles reported %d times",
                  distinct_in(&s, "tiles", 0.3, 0.9));
    hv_mesh_destroy(&m);
}
END_TEST

/* dir/name's text into buf ("" when it cannot be read). */
static void read_text(const char *name, char *buf, size_t size)
{
    char p[600];
    snprintf(p, sizeof p, "%s/%s", dir, name);
    FILE *f = fopen(p, "r");
    size_t n = f ? fread(buf, 1, size - 1, f) : 0;
    buf[n] = 0;
    if (f)
        fclose(f);
}

/* The h= of the summary line in dir/name (0 when there is none). */
static double summary_h(const char *name)
{
    char line[4096];
    read_text(name, line, sizeof line);
    const char *h = strstr(line, " h=");
    return h ? atof(h + 3) : 0;
}

/* --units m takes a file's stated unit (the spider of assimp's test models,
 * an FBX in centimetres) to metres: the same cells, h a hundredth; a file
 * that states none keeps its coordinates and says so; --units cm is a usage
 * error. */
START_TEST(units_m_should_scale_to_metres_where_the_file_states_a_unit)
{
    const char *fbx = "/usr/share/assimp/models/FBX/spider.fbx";
    if (access(fbx, R_OK))
        TL_SKIP("units: no %s (Debian's assimp-testmodels)", fbx);
    char err[4096];
    /* stdout to a file: the redirections come before tl_run_cmd's, which then
     * apply to `exit` alone */
    ck_assert_int_eq(hv(err, sizeof err, "sdf %s -o a.vdb --res 24 > a.txt; exit $?", fbx), 0);
    int rc =
        hv(err, sizeof err, "sdf %s -o b.vdb --res 24 --units m -v > b.txt 2> b.err; exit $?", fbx);
    read_text("b.err", err, sizeof err);
    ck_assert_msg(rc == 0, "exit %d (%s)", rc, err);
    ck_assert_msg(strstr(err, "length unit 0.01 m, from the file") &&
                      strstr(err, "coordinates times 0.01, in metres (--units m)"),
                  "%s", err);
    double ha = summary_h("a.txt"), hb = summary_h("b.txt");
    ck_assert_msg(ha > 0 && fabs(hb / ha - 0.01) < 1e-9, "h %g and %g", ha, hb);

    rc = hv(err, sizeof err, "sdf sc/meshes/torus_holes.obj -o t.vdb --res 16 --units m");
    ck_assert_msg(rc == 0 && strstr(err, "torus_holes.obj states no length unit: --units m keeps "
                                         "its coordinates"),
                  "exit %d (%s)", rc, err);
    rc = hv(err, sizeof err, "sdf sc/meshes/torus_holes.obj -o u.vdb --res 16 --units cm");
    ck_assert_msg(rc == 2 && strstr(err, "--units needs file or m, got 'cm'"), "exit %d (%s)", rc,
                  err);
    ck_assert(!exists("u.vdb"));
}
END_TEST

int main(void)
{
    Suite *s = suite_create("cli");
    TCase *tc = tcase_create("cli");
    tcase_set_timeout(tc, 300);
    tcase_add_checked_fixture(tc, setup, teardown);
    tcase_add_test(tc, a_resolution_too_large_should_be_a_usage_error_naming_the_option);
    tcase_add_test(tc, option_errors_should_read_alike_in_every_command);
    tcase_add_test(tc, a_non_finite_vertex_should_be_named_by_its_line);
    tcase_add_test(tc, messages_should_name_a_file_once);
    tcase_add_test(tc, outputs_should_be_checked_by_their_extension);
    tcase_add_test(tc, progress_should_not_reach_a_log_even_with_v);
    tcase_add_test(tc, long_stages_should_advance);
    tcase_add_test(tc, units_m_should_scale_to_metres_where_the_file_states_a_unit);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
