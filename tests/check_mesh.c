/* Mesh input: readers on every shared file and on hand-written cubes in each
 * format, the defect report on generated meshes with known defects, writers. */
#include "heatvox/heatvox.h"
#include "testlib.h"

#include <check.h>
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <float.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

/* ---- helpers ---- */

/* The test meshes ($HEATVOX_TEST_DATA); NULL, with the test counted as
 * skipped, when the directory is absent. The caller returns at once. */
static const char *shared_meshes(void)
{
    const char *d = tl_test_data();
    if (!d)
        tl_skip("no test meshes directory (set HEATVOX_TEST_DATA)");
    return d;
}

static char tmpdir[256];

static void make_tmpdir(void)
{
    snprintf(tmpdir, sizeof tmpdir, "/tmp/hv_check_mesh_XXXXXX");
    ck_assert_ptr_nonnull(mkdtemp(tmpdir));
}

static void remove_tmpdir(void)
{
    DIR *d = opendir(tmpdir);
    if (!d)
        return;
    struct dirent *e;
    char p[600];
    while ((e = readdir(d)))
        if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) {
            snprintf(p, sizeof p, "%s/%s", tmpdir, e->d_name);
            unlink(p);
        }
    closedir(d);
    rmdir(tmpdir);
}

static const char *tmp_path(const char *name)
{
    static char p[600];
    snprintf(p, sizeof p, "%s/%s", tmpdir, name);
    return p;
}

static const char *tmp_write(const char *name, const void *data, size_t len)
{
    const char *p = tmp_path(name);
    FILE *f = fopen(p, "wb");
    ck_assert_ptr_nonnull(f);
    ck_assert_uint_eq(fwrite(data, 1, len, f), len);
    ck_assert_int_eq(fclose(f), 0);
    return p;
}

static const char *tmp_write_str(const char *name, const char *text)
{
    return tmp_write(name, text, strlen(text));
}

static hv_mesh_report report(const hv_mesh *m)
{
    hv_mesh_report r;
    ck_assert_int_eq(hv_mesh_report_compute(m, &r), HV_OK);
    return r;
}

static void assert_closed_consistent(const hv_mesh_report *r, const char *what)
{
    ck_assert_msg(r->boundary_edges == 0 && r->nonmanifold_edges == 0 &&
                      r->inconsistent_edges == 0 && r->components == 1,
                  "%s: boundary %zu, non-manifold %zu, inconsistent %zu, components %zu", what,
                  r->boundary_edges, r->nonmanifold_edges, r->inconsistent_edges, r->components);
}

/* A unit cube [0,1]^3 must come back as 12 triangles on 8 welded vertices,
 * closed, consistent and outward (volume +1). */
static void assert_unit_cube(const char *path, const char *what)
{
    hv_mesh *m = NULL;
    hv_status st = hv_mesh_read(path, &m);
    ck_assert_msg(st == HV_OK, "%s: %s", what, hv_last_error());
    ck_assert_msg(m->ntris == 12 && m->nverts == 8, "%s: %zu triangles, %zu vertices", what,
                  m->ntris, m->nverts);
    hv_mesh_report r = report(m);
    assert_closed_consistent(&r, what);
    ck_assert_msg(fabs(r.signed_volume - 1) < 1e-12, "%s: volume %g", what, r.signed_volume);
    ck_assert_uint_eq(r.degenerate_faces, 0);
    ck_assert_uint_eq(r.duplicate_faces, 0);
    double lo[3], hi[3];
    ck_assert_int_eq(hv_mesh_bounds(m, lo, hi), HV_OK);
    for (int a = 0; a < 3; a++)
        ck_assert(lo[a] == 0 && hi[a] == 1);
    hv_mesh_destroy(&m);
    ck_assert_ptr_null(m);
}

/* Expects a parse/IO failure whose message names the file and contains `part`. */
static void assert_fails(const char *path, const char *part)
{
    hv_mesh *m = NULL;
    hv_status st = hv_mesh_read(path, &m);
    ck_assert_msg(st == HV_ERR_PARSE || st == HV_ERR_IO, "%s: status %s (%s)", path,
                  hv_status_str(st), hv_last_error());
    ck_assert_ptr_null(m);
    ck_assert_msg(strstr(hv_last_error(), path), "message '%s' does not name %s", hv_last_error(),
                  path);
    ck_assert_msg(!part || strstr(hv_last_error(), part), "message '%s' lacks '%s'",
                  hv_last_error(), part);
}

/* ---- cube in every format ---- */

static const double cube_v[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                    {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
/* outward quads, counter-clockwise from outside */
static const int cube_q[6][4] = {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 1, 5, 4},
                                 {1, 2, 6, 5}, {2, 3, 7, 6}, {3, 0, 4, 7}};

typedef struct bytes {
    unsigned char b[4096];
    size_t n;
} bytes;

/* Appends n bytes of a host value, reversed for big endian output when the
 * host is little endian (x86-64, arm64). */
static void put(bytes *o, const void *p, size_t n, int big)
{
    ck_assert(o->n + n <= sizeof o->b);
    const unsigned char *s = p;
    for (size_t i = 0; i < n; i++)
        o->b[o->n + i] = s[big ? n - 1 - i : i];
    o->n += n;
}

static void put_text(bytes *o, const char *s) { put(o, s, strlen(s), 0); }

static const char *write_binary_ply(const char *name, int big)
{
    bytes o = {.n = 0};
    put_text(&o, "ply\n");
    put_text(&o, big ? "format binary_big_endian 1.0\n" : "format binary_little_endian 1.0\n");
    put_text(&o, "comment extra properties and elements to skip\n"
                 "element camera 1\nproperty double focal\nproperty list uint8 int16 junk\n"
                 "element vertex 8\nproperty uint8 flags\nproperty float32 x\n"
                 "property double y\nproperty float z\nproperty list uchar float normals\n"
                 "element face 6\nproperty list uchar uint vertex_indices\nproperty short tag\n"
                 "end_header\n");
    double focal = 35;
    unsigned char cnt = 2;
    short junk[2] = {7, -7};
    put(&o, &focal, 8, big);
    put(&o, &cnt, 1, big);
    put(&o, &junk[0], 2, big);
    put(&o, &junk[1], 2, big);
    for (int i = 0; i < 8; i++) {
        unsigned char flags = 0xff, three = 3;
        float x = (float)cube_v[i][0], z = (float)cube_v[i][2], n = 0.5f;
        double y = cube_v[i][1];
        put(&o, &flags, 1, big);
        put(&o, &x, 4, big);
        put(&o, &y, 8, big);
        put(&o, &z, 4, big);
        put(&o, &three, 1, big);
        for (int k = 0; k < 3; k++)
            put(&o, &n, 4, big);
    }
    for (int f = 0; f < 6; f++) {
        unsigned char four = 4;
        put(&o, &four, 1, big);
        for (int k = 0; k < 4; k++) {
            uint32_t v = (uint32_t)cube_q[f][k];
            put(&o, &v, 4, big);
        }
        short tag = 1;
        put(&o, &tag, 2, big);
    }
    return tmp_write(name, o.b, o.n);
}

static const char *write_binary_stl(const char *name)
{
    bytes o = {.n = 0};
    char header[80] = "solid this header says solid but the file is binary";
    put(&o, header, 80, 0);
    uint32_t n = 12;
    put(&o, &n, 4, 0);
    for (int f = 0; f < 6; f++)
        for (int t = 0; t < 2; t++) {
            float normal[3] = {0, 0, 0};
            put(&o, normal, 12, 0);
            int c[3] = {cube_q[f][0], cube_q[f][1 + t], cube_q[f][2 + t]};
            for (int k = 0; k < 3; k++)
                for (int a = 0; a < 3; a++) {
                    float x = (float)cube_v[c[k]][a];
                    put(&o, &x, 4, 0);
                }
            uint16_t attr = 0;
            put(&o, &attr, 2, 0);
        }
    ck_assert_uint_eq(o.n, 84 + 50 * 12);
    return tmp_write(name, o.b, o.n);
}

/* Two solids (the second after an empty one), a tab after "solid", CRLF in
 * places, no final newline. */
static const char *write_ascii_stl(const char *name)
{
    char s[8192];
    size_t n = 0;
    n += (size_t)snprintf(s + n, sizeof s - n, "solid\tcube part one\n");
    for (int f = 0; f < 6; f++) {
        if (f == 3)
            n += (size_t)snprintf(s + n, sizeof s - n,
                                  "endsolid cube part one\nsolid empty\nendsolid empty\n"
                                  "solid second\r\n");
        for (int t = 0; t < 2; t++) {
            int c[3] = {cube_q[f][0], cube_q[f][1 + t], cube_q[f][2 + t]};
            n += (size_t)snprintf(s + n, sizeof s - n, "  facet normal 0 0 0\r\n    outer loop\n");
            for (int k = 0; k < 3; k++)
                n += (size_t)snprintf(s + n, sizeof s - n, "      vertex %g %g %.1e\n",
                                      cube_v[c[k]][0], cube_v[c[k]][1], cube_v[c[k]][2]);
            n += (size_t)snprintf(s + n, sizeof s - n, "    endloop\n  endfacet\n");
        }
    }
    snprintf(s + n, sizeof s - n, "endsolid second");
    return tmp_write_str(name, s);
}

/* OBJ: quads, negative indices, v/vt/vn variants, CRLF, records to skip,
 * numbers like "1." "+1e0", a trailing w, no final newline. */
static const char cube_obj[] = "# cube\r\nmtllib x.mtl\r\no cube\r\ng g1\r\ns off\r\nusemtl m\r\n"
                               "v 0 0 0\r\nv 1. 0 0\r\nv +1e0 1 0\r\nv 0 1.0 0\r\n"
                               "vt 0 0\r\nvn 0 0 1\r\nvp 0.5\r\n"
                               "f -4/1/1 -1/1/1 -2/1/1 -3/1/1\r\n"
                               "v 0 0 1\r\nv 1 0 +1.\r\nv 1 1 1\r\nv 0 1 1 1.0\r\n"
                               "f 5//1 6//1 7//1 8//1\r\n"
                               "l 1 2\r\np 3\r\n"
                               "f 1/1 2/1 6/1 5/1\r\nf 2 3 7 6\r\nf 3 4 8 7\r\nf\t4 1 5 8";

START_TEST(cube_written_in_every_format_should_load_to_12_triangles_on_8_vertices)
{
    make_tmpdir();
    assert_unit_cube(tmp_write_str("cube.obj", cube_obj), "OBJ");

    char ply[4096];
    size_t n = (size_t)snprintf(ply, sizeof ply,
                                "ply\nformat ascii 1.0\ncomment hello\nelement vertex 8\n"
                                "property float32 x\nproperty float y\nproperty double z\n"
                                "property uchar red\nelement face 6\n"
                                "property list uint8 int32 vertex_index\nend_header\n");
    for (int i = 0; i < 8; i++)
        n += (size_t)snprintf(ply + n, sizeof ply - n, "%g %g %g 255\n", cube_v[i][0], cube_v[i][1],
                              cube_v[i][2]);
    for (int f = 0; f < 6; f++)
        n += (size_t)snprintf(ply + n, sizeof ply - n, "4 %d %d %d %d\n", cube_q[f][0],
                              cube_q[f][1], cube_q[f][2], cube_q[f][3]);
    assert_unit_cube(tmp_write_str("cube_ascii.PLY", ply), "PLY ascii");
    assert_unit_cube(write_binary_ply("cube_le.ply", 0), "PLY binary_little_endian");
    assert_unit_cube(write_binary_ply("cube_be.ply", 1), "PLY binary_big_endian");
    assert_unit_cube(write_ascii_stl("cube_ascii.stl"), "STL ascii");
    assert_unit_cube(write_binary_stl("cube_binary.Stl"), "STL binary with a 'solid' header");

    char off[2048];
    n = (size_t)snprintf(off, sizeof off, "# a comment first\nCOFF 8 6 0 # counts here\n\n");
    for (int i = 0; i < 8; i++)
        n += (size_t)snprintf(off + n, sizeof off - n, "%g %g %g 0.5 0.5 0.5 1 # colour\n",
                              cube_v[i][0], cube_v[i][1], cube_v[i][2]);
    for (int f = 0; f < 6; f++)
        n += (size_t)snprintf(off + n, sizeof off - n, "4  %d %d %d %d 255 0 0\n", cube_q[f][0],
                              cube_q[f][1], cube_q[f][2], cube_q[f][3]);
    assert_unit_cube(tmp_write_str("cube.off", off), "OFF");

    /* without a known extension the content decides */
    assert_unit_cube(tmp_write_str("cube_off_noext", off), "OFF by content");
    assert_unit_cube(tmp_write_str("cube_ply.dat", ply), "PLY by content");
    assert_unit_cube(tmp_write_str("cube_obj_noext", cube_obj), "OBJ by content");
    assert_unit_cube(write_binary_stl("cube_stl_noext"), "binary STL by content");
    remove_tmpdir();
}
END_TEST

START_TEST(fanned_polygons_should_be_counted)
{
    make_tmpdir();
    hv_mesh *m = NULL;
    const char *p = tmp_write_str("penta.obj", "v 0 0 0\nv 1 0 0\nv 1.5 1 0\nv 0.5 2 0\n"
                                               "v -0.5 1 0\nf 1 2 3 4 5\nf 1 2 3\n");
    ck_assert_int_eq(hv_mesh_read(p, &m), HV_OK);
    ck_assert_uint_eq(m->ntris, 4);
    hv_mesh_report r = report(m);
    ck_assert_uint_eq(r.polygons_fanned, 1);
    ck_assert_uint_eq(r.duplicate_faces, 1);
    hv_mesh_destroy(&m);
    remove_tmpdir();
}
END_TEST

START_TEST(long_lines_without_final_newline_should_load)
{
    make_tmpdir();
    /* a 100 000-corner polygon on one line (no fixed line buffer), no newline at the end */
    size_t nv = 100000, cap = nv * 40 + 64, n = 0;
    char *s = malloc(cap);
    ck_assert_ptr_nonnull(s);
    for (size_t i = 0; i < nv; i++) {
        double a = 2 * M_PI * (double)i / (double)nv;
        n += (size_t)snprintf(s + n, cap - n, "v %.9f %.9f 0\n", cos(a), sin(a));
    }
    n += (size_t)snprintf(s + n, cap - n, "f");
    for (size_t i = 0; i < nv; i++)
        n += (size_t)snprintf(s + n, cap - n, " %zu", i + 1);
    hv_mesh *m = NULL;
    ck_assert_int_eq(hv_mesh_read(tmp_write("disc.obj", s, n), &m), HV_OK);
    ck_assert_uint_eq(m->ntris, nv - 2);
    ck_assert_uint_eq(m->polygons_fanned, 1);
    ck_assert_uint_eq(report(m).boundary_edges, nv);
    hv_mesh_destroy(&m);
    free(s);
    remove_tmpdir();
}
END_TEST

/* ---- shared files ---- */

typedef struct expect {
    const char *name; /* path under meshes/ */
    long tris;        /* > 0: loads to this many; 0: loads; -1: must fail */
    const char *part; /* for failures: text the message must contain */
} expect;

static const expect expected[] = {
    /* SOURCES.md */
    {"bunny_small.obj", 2856, NULL},
    {"spot.obj", 5856, NULL},
    {"chair.obj", 7859, NULL},
    {"knot.obj", 30504, NULL},
    {"rocker.obj", 13819, NULL},
    {"polygon-bear.obj", 4214, NULL},
    {"stanford-bunny.obj", 69451, NULL},
    {"bun_zipper_res4.ply", 948, NULL},
    {"armadillo_bad.obj", 86482, NULL},
    {"cow.obj", 5804, NULL},
    {"igea.ply", 0, NULL},
    /* formats/ (cubes are 6 quads = 12 triangles; binary STL counts from their headers) */
    {"formats/OBJ/box.obj", 12, NULL},
    {"formats/OBJ/box_longline.obj", 0, NULL},
    {"formats/OBJ/box_without_lineending.obj", 12, NULL},
    {"formats/OBJ/box_mat_with_spaces.obj", 12, NULL},
    {"formats/OBJ/cube_mtllib_after_g.obj", 12, NULL},
    {"formats/OBJ/cube_usemtl.obj", 12, NULL},
    {"formats/OBJ/cube_with_vertexcolors.obj", 12, NULL},
    {"formats/OBJ/cube_with_vertexcolors_uni.obj", 12, NULL},
    {"formats/OBJ/testmixed.obj", 12, NULL},
    {"formats/OBJ/multiple_spaces.obj", 1, NULL},
    {"formats/OBJ/regr_3429812.obj", 4, NULL},
    {"formats/OBJ/box_UTF16BE.obj", -1, "UTF-16"},
    {"formats/OBJ/point_cloud.obj", -1, "no triangles"},
    {"formats/OBJ/testline.obj", -1, "no triangles"},
    {"formats/OBJ/testpoints.obj", -1, "no triangles"},
    {"formats/OBJ/number_formats.obj", -1, "line 11"}, /* "3.1+e2" is not a number */
    {"formats/OBJ/box_spaces.mtl", -1, "not a mesh format"},
    {"formats/OFF/Cube.off", 12, NULL},
    {"formats/OFF/formatDetection", 12, NULL},
    {"formats/OFF/Wuson.off", 3732, NULL},
    {"formats/OFF/invalid.off", -1, NULL},
    {"formats/PLY/cube.ply", 12, NULL},
    {"formats/PLY/cube_binary.ply", 12, NULL},
    {"formats/PLY/cube_uv.ply", 12, NULL},
    {"formats/PLY/float-color.ply", 1, NULL},
    {"formats/PLY/Wuson.ply", 3732, NULL},
    {"formats/PLY/points.ply", -1, "no triangles"},
    {"formats/PLY/issue623.ply", -1, NULL}, /* header lists a property the data lacks */
    {"formats/PLY/pond.0.ply", -1, NULL},   /* truncated: 69 bytes short */
    {"formats/STL/3DSMaxExport.STL", 2000, NULL},
    {"formats/STL/Spider_binary.stl", 1368, NULL},
    {"formats/STL/Spider_ascii.stl", 1368, NULL},
    {"formats/STL/Wuson.stl", 3732, NULL},
    {"formats/STL/formatDetection", 1, NULL},
    {"formats/STL/triangle.stl", 1, NULL},
    {"formats/STL/triangle_with_two_solids.stl", 2, NULL},
    {"formats/STL/triangle_with_empty_solid.stl", 1, NULL},
    {"formats/STL/sphereWithHole.stl", 0, NULL},
    {"formats/invalid/OutOfMemory.off", -1, "353535235358"},
    {"formats/invalid/malformed.obj", -1, "line"},
    {"formats/invalid/malformed2.obj", -1, "line"},
    {"formats/invalid/empty.3ds", -1, "empty"},
    {"formats/invalid/empty.obj", -1, "empty"},
    {"formats/invalid/emptyIrrMesh.xml", -1, "not a mesh format"},
};

static const expect *find_expect(const char *rel)
{
    for (size_t i = 0; i < sizeof expected / sizeof expected[0]; i++)
        if (!strcmp(expected[i].name, rel))
            return &expected[i];
    return NULL;
}

static int has_ext(const char *name, const char *ext)
{
    size_t n = strlen(name), e = strlen(ext);
    return n > e && !strcasecmp(name + n - e, ext);
}

static size_t files_seen, files_loaded, expectations_met;

static void check_one(const char *root, const char *rel)
{
    char path[8192];
    snprintf(path, sizeof path, "%s/%s", root, rel);
    const expect *x = find_expect(rel);
    hv_mesh *m = NULL;
    hv_status st = hv_mesh_read(path, &m);
    files_seen++;
    if (st == HV_OK) {
        files_loaded++;
        ck_assert_msg(!x || x->tris >= 0, "%s should fail but loaded %zu triangles", rel, m->ntris);
        ck_assert_msg(m->ntris > 0 && m->nverts > 0, "%s: empty mesh returned", rel);
        ck_assert_msg(!x || x->tris == 0 || (size_t)x->tris == m->ntris,
                      "%s: %zu triangles, expected %ld", rel, m->ntris, x ? x->tris : 0L);
        for (size_t i = 0; i < 3 * m->ntris; i++)
            ck_assert_msg(m->tris[i] < m->nverts, "%s: index out of range", rel);
        ck_assert_msg(m->nverts <= m->input_vertices, "%s: welding added vertices", rel);
        hv_mesh_report r = report(m);
        ck_assert_uint_eq(r.triangles, m->ntris);
        hv_mesh_destroy(&m);
    } else {
        ck_assert_msg(!x || x->tris < 0, "%s should load but failed: %s", rel, hv_last_error());
        ck_assert_msg(st == HV_ERR_PARSE || st == HV_ERR_IO, "%s: status %s (%s)", rel,
                      hv_status_str(st), hv_last_error());
        ck_assert_ptr_null(m);
        ck_assert_msg(strstr(hv_last_error(), path), "%s: message '%s' does not name the file", rel,
                      hv_last_error());
        ck_assert_msg(!x || !x->part || strstr(hv_last_error(), x->part),
                      "%s: message '%s' lacks '%s'", rel, hv_last_error(), x ? x->part : "");
    }
    if (x)
        expectations_met++;
}

static void walk(const char *root, const char *rel, int recurse)
{
    char dir[4096];
    snprintf(dir, sizeof dir, "%s%s%s", root, *rel ? "/" : "", rel);
    DIR *d = opendir(dir);
    ck_assert_msg(d != NULL, "cannot list %s", dir);
    struct dirent *e;
    static char names[8][256][256]; /* per depth */
    static int depth = -1;
    depth++;
    ck_assert_int_lt(depth, 8);
    size_t n = 0;
    while ((e = readdir(d)) && n < 256)
        if (e->d_name[0] != '.')
            snprintf(names[depth][n++], sizeof names[0][0], "%s", e->d_name);
    closedir(d);
    for (size_t i = 0; i < n; i++) {
        char sub[4096], full[8192];
        snprintf(sub, sizeof sub, "%s%s%s", rel, *rel ? "/" : "", names[depth][i]);
        snprintf(full, sizeof full, "%s/%s", root, sub);
        struct stat sb;
        ck_assert_int_eq(stat(full, &sb), 0);
        if (S_ISDIR(sb.st_mode)) {
            if (recurse)
                walk(root, sub, 1);
        } else if (recurse || has_ext(names[depth][i], ".obj") ||
                   has_ext(names[depth][i], ".ply")) {
            check_one(root, sub);
        }
    }
    depth--;
}

START_TEST(every_shared_file_should_load_or_fail_with_a_message_naming_it)
{
    const char *root = shared_meshes();
    if (!root)
        return;
    size_t rss0 = hv_peak_rss();
    files_seen = files_loaded = expectations_met = 0;
    walk(root, "", 0);        /* meshes/ *.obj, *.ply */
    walk(root, "formats", 1); /* meshes/formats, every file whatever its extension */
    printf("shared meshes: %zu files, %zu loaded, %zu checked against expectations\n", files_seen,
           files_loaded, expectations_met);
    ck_assert_uint_eq(expectations_met, sizeof expected / sizeof expected[0]);
    /* nothing allocated from a header the file cannot back (OutOfMemory.off) */
    size_t rss1 = hv_peak_rss();
    ck_assert_msg(rss1 < rss0 + ((size_t)512 << 20), "peak RSS grew by %zu MB",
                  (rss1 - rss0) >> 20);
}
END_TEST

static hv_mesh *read_shared(const char *name, hv_mesh_report *r)
{
    const char *root = shared_meshes();
    if (!root)
        return NULL;
    char path[4096];
    snprintf(path, sizeof path, "%s/%s", root, name);
    hv_mesh *m = NULL;
    ck_assert_msg(hv_mesh_read(path, &m) == HV_OK, "%s", hv_last_error());
    *r = report(m);
    return m;
}

START_TEST(clean_shared_meshes_should_be_closed_and_consistent)
{
    const char *names[] = {"spot.obj", "bunny_small.obj", "cow.obj"};
    for (int i = 0; i < 3; i++) {
        hv_mesh_report r;
        hv_mesh *m = read_shared(names[i], &r);
        if (!m)
            return;
        assert_closed_consistent(&r, names[i]);
        ck_assert_msg(r.signed_volume > 0, "%s: inside out", names[i]);
        ck_assert_uint_eq(r.duplicate_faces + r.degenerate_faces + r.nonfinite_vertices, 0);
        hv_mesh_destroy(&m);
    }
}
END_TEST

/* Defect counts that SOURCES.md states (measured there with another tool). */
START_TEST(broken_shared_meshes_should_report_the_defects_sources_md_lists)
{
    hv_mesh_report r;
    hv_mesh *m = read_shared("chair.obj", &r);
    if (!m)
        return;
    ck_assert_uint_eq(r.boundary_edges, 2701);
    hv_mesh_destroy(&m);

    m = read_shared("armadillo_bad.obj", &r);
    ck_assert_uint_eq(r.inconsistent_edges, 108264);
    ck_assert_uint_eq(r.boundary_edges, 0);
    hv_mesh_destroy(&m);

    m = read_shared("bun_zipper_res4.ply", &r);
    ck_assert_uint_eq(r.boundary_edges, 26);
    ck_assert_uint_eq(r.nonmanifold_edges, 70);
    ck_assert_uint_eq(r.duplicate_faces, 40);
    hv_mesh_destroy(&m);

    m = read_shared("stanford-bunny.obj", &r);
    ck_assert_uint_eq(r.boundary_edges, 223);
    hv_mesh_destroy(&m);

    /* SOURCES.md counts components through shared vertices */
    m = read_shared("knot.obj", &r);
    ck_assert_uint_eq(r.boundary_edges, 5620);
    ck_assert_uint_eq(r.vertex_components, 4);
    ck_assert_uint_ge(r.components, r.vertex_components);
    hv_mesh_destroy(&m);

    m = read_shared("rocker.obj", &r);
    ck_assert_uint_eq(r.boundary_edges, 4223);
    ck_assert_uint_eq(r.vertex_components, 19);
    hv_mesh_destroy(&m);

    m = read_shared("polygon-bear.obj", &r);
    ck_assert_uint_eq(r.nonmanifold_edges, 1);
    ck_assert_uint_eq(r.polygons_fanned, 1031);
    hv_mesh_destroy(&m);
}
END_TEST

START_TEST(igea_tristrips_should_become_a_consistent_surface)
{
    hv_mesh_report r;
    hv_mesh *m = read_shared("igea.ply", &r);
    if (!m)
        return;
    ck_assert_uint_gt(m->ntris, 100000);
    ck_assert_uint_eq(r.inconsistent_edges, 0);
    ck_assert_uint_eq(r.degenerate_faces, 0);
    printf("igea.ply: %zu triangles from strips, %zu boundary edges, %zu components\n", m->ntris,
           r.boundary_edges, r.components);
    hv_mesh_destroy(&m);
}
END_TEST

/* Its times are printed for the log; `heatvox bench` measures speed. */
START_TEST(stanford_bunny_should_load_and_report)
{
    const char *root = shared_meshes();
    if (!root)
        return;
    char path[4096];
    snprintf(path, sizeof path, "%s/stanford-bunny.obj", root);
    hv_mesh *m = NULL;
    double t0 = hv_now();
    ck_assert_int_eq(hv_mesh_read(path, &m), HV_OK);
    double t1 = hv_now();
    hv_mesh_report r = report(m);
    double t2 = hv_now();
    printf("stanford-bunny.obj: read %.3f s, report %.3f s (%zu triangles)\n", t1 - t0, t2 - t1,
           r.triangles);
    /* SOURCES.md: 69,451 triangles, 223 boundary edges (holes in the base). */
    ck_assert_uint_eq(r.triangles, 69451);
    ck_assert_uint_eq(r.boundary_edges, 223);
    hv_mesh_destroy(&m);
}
END_TEST

/* ---- malformed input ---- */

START_TEST(malformed_files_should_fail_with_the_line_or_byte)
{
    make_tmpdir();
    assert_fails(tmp_write_str("range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 4\n"), "line 5");
    assert_fails(tmp_write_str("neg.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n"), "line 4");
    assert_fails(tmp_write_str("zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n"), "line 4");
    assert_fails(tmp_write_str("two.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n"), "line 4");
    assert_fails(tmp_write_str("num.obj", "v 0 0 0\nv 1 0 0\nv 0 1x 0\nf 1 2 3\n"), "line 3");
    assert_fails(tmp_write_str("short.obj", "v 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"), "line 1");
    assert_fails(tmp_write("utf16le.obj",
                           "\xff\xfev\0 \0"
                           "0\0",
                           8),
                 "UTF-16");
    assert_fails(tmp_write_str("empty.obj", ""), "empty");
    assert_fails(tmp_write_str("comments.obj", "# nothing\n"), "no triangles");
    assert_fails(tmp_write_str("range.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n"),
                 "line 6");
    assert_fails(tmp_write_str("trunc.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n"), NULL);
    assert_fails(tmp_write_str("huge.off", "OFF 4000000000 4000000000 0\n0 0 0\n3 0 0 0\n"),
                 "4000000000");
    assert_fails(tmp_write_str("range.ply", "ply\nformat ascii 1.0\nelement vertex 3\n"
                                            "property float x\nproperty float y\n"
                                            "property float z\nelement face 1\n"
                                            "property list uchar int vertex_indices\n"
                                            "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n"),
                 "line 13");
    assert_fails(tmp_write_str("nox.ply", "ply\nformat ascii 1.0\nelement vertex 1\n"
                                          "property float y\nend_header\n0\n"),
                 "no property x");
    assert_fails(tmp_write_str("hugecount.ply",
                               "ply\nformat binary_little_endian 1.0\nelement vertex 3\n"
                               "property float x\nproperty float y\nproperty float z\n"
                               "element face 1000000000\n"
                               "property list uint int vertex_indices\nend_header\n"),
                 "bytes");
    {
        /* binary PLY: index 9 of 3 vertices, named by byte offset */
        bytes o = {.n = 0};
        put_text(&o, "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
                     "property float y\nproperty float z\nelement face 1\n"
                     "property list uchar int vertex_indices\nend_header\n");
        float v[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
        put(&o, v, sizeof v, 0);
        unsigned char three = 3;
        int idx[3] = {0, 1, 9};
        put(&o, &three, 1, 0);
        put(&o, idx, sizeof idx, 0);
        assert_fails(tmp_write("badidx.ply", o.b, o.n), "byte");
        /* truncated inside the face list */
        assert_fails(tmp_write("cut.ply", o.b, o.n - 3), "byte");
        /* a list length the file cannot hold */
        o.n -= 13;
        uint32_t big = 0xfffffff0u;
        o.b[o.n] = 0xff;
        o.n++;
        put(&o, &big, 4, 0);
        assert_fails(tmp_write("biglist.ply", o.b, o.n), NULL);
    }
    assert_fails(tmp_write_str("bad.stl", "solid x\n facet normal 0 0 1\n outer loop\n"
                                          "vertex 0 0 0\nvertex 1 0 0\nendloop\nendfacet\n"
                                          "endsolid\n"),
                 "2 vertices");
    assert_fails(tmp_write_str("garbage.stl", "hello"), NULL);
    {
        unsigned char b[84 + 50 + 7] = {0};
        b[80] = 1;
        assert_fails(tmp_write("size.stl", b, sizeof b), "declares 1 triangles");
    }
    assert_fails(tmp_write_str("notes.txt", "just some text\n"), "not a mesh format");
    assert_fails(tmp_path("missing.obj"), "cannot open");
    hv_mesh *m = NULL;
    ck_assert_int_eq(hv_mesh_read(tmpdir, &m), HV_ERR_IO);
    ck_assert_int_eq(hv_mesh_read(NULL, &m), HV_ERR_INVALID_ARG);
    remove_tmpdir();
}
END_TEST

START_TEST(huge_declared_counts_should_fail_without_allocating)
{
    const char *root = shared_meshes();
    if (!root)
        return;
    char path[4096];
    snprintf(path, sizeof path, "%s/formats/invalid/OutOfMemory.off", root);
    size_t rss0 = hv_peak_rss();
    assert_fails(path, "353535235358");
    ck_assert_msg(hv_peak_rss() < rss0 + ((size_t)16 << 20), "peak RSS grew");
}
END_TEST

START_TEST(nonfinite_coordinates_should_be_loaded_and_counted)
{
    make_tmpdir();
    hv_mesh *m = NULL;
    const char *p = tmp_write_str("nan.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv nan 0 0\nv 0 inf 0\n"
                                             "v 0 0 -Infinity\nf 1 2 3\nf 1 4 5\nf 6 2 3\n");
    ck_assert_int_eq(hv_mesh_read(p, &m), HV_OK);
    ck_assert_uint_eq(m->ntris, 3);
    ck_assert_uint_eq(m->nverts, 6);
    hv_mesh_report r = report(m);
    ck_assert_uint_eq(r.nonfinite_vertices, 3);
    double lo[3], hi[3];
    ck_assert_int_eq(hv_mesh_bounds(m, lo, hi), HV_OK);
    for (int a = 0; a < 3; a++)
        ck_assert(lo[a] == 0 && hi[a] == (a < 2 ? 1 : 0));
    hv_mesh_destroy(&m);
    remove_tmpdir();
}
END_TEST

static int bare_normal_notes;
static void count_bare_normals(hv_log_level level, const char *msg, void *user)
{
    (void)user;
    bare_normal_notes += level == HV_LOG_INFO && strstr(msg, "'facet normal' without numbers") &&
                         strstr(msg, "line 2");
}

/* 'facet normal' without its numbers (a public STL test file has them):
 * read, since STL normals are never used, and said once at info level. */
START_TEST(stl_facet_normals_without_numbers_should_read_with_a_note)
{
    make_tmpdir();
    const char *path = tmp_write_str("bare.stl", "solid t\nfacet normal\nouter loop\nvertex 0 0 0\n"
                                                 "vertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\n"
                                                 "facet normal\nouter loop\nvertex 0 0 0\n"
                                                 "vertex 0 1 0\nvertex 0 0 1\nendloop\nendfacet\n"
                                                 "endsolid t\n");
    bare_normal_notes = 0;
    hv_set_log(count_bare_normals, NULL);
    hv_mesh *m = NULL;
    hv_status st = hv_mesh_read(path, &m);
    hv_set_log(NULL, NULL);
    TL_ASSERT_OK(st);
    ck_assert_uint_eq(m->ntris, 2);
    ck_assert_uint_eq(m->nverts, 4);
    ck_assert_int_eq(bare_normal_notes, 1);
    hv_mesh_destroy(&m);
    assert_fails(tmp_write_str("half.stl", "solid t\nfacet normal 0 1\nouter loop\nvertex 0 0 0\n"
                                           "vertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\n"
                                           "endsolid t\n"),
                 "malformed normal coordinate 'outer'");
    remove_tmpdir();
}
END_TEST

START_TEST(tristrips_should_alternate_winding_and_restart_at_minus_one)
{
    make_tmpdir();
    /* Two 2x2 ladders in one strip, joined by repeated indices (writers' zero-area
     * stitches, dropped) that keep the parity: every triangle must wind the same
     * way. Vertices 4 and 5 are unused. */
    const char *ply = "ply\nformat ascii 1.0\nelement vertex 10\nproperty float x\n"
                      "property float y\nproperty float z\nelement tristrips 1\n"
                      "property list int int vertex_indices\nend_header\n"
                      "0 0 0\n0 1 0\n1 0 0\n1 1 0\n9 9 9\n9 9 9\n5 0 0\n5 1 0\n6 0 0\n6 1 0\n"
                      "10 0 1 2 3 3 6 6 7 8 9\n";
    hv_mesh *m = NULL;
    ck_assert_int_eq(hv_mesh_read(tmp_write_str("strip.ply", ply), &m), HV_OK);
    ck_assert_uint_eq(m->ntris, 4);
    ck_assert_uint_eq(m->nverts, 8);
    hv_mesh_report r = report(m);
    ck_assert_uint_eq(r.degenerate_faces, 0);
    for (size_t t = 0; t < m->ntris; t++) {
        const double *a = m->verts + 3 * m->tris[3 * t], *b = m->verts + 3 * m->tris[3 * t + 1],
                     *c = m->verts + 3 * m->tris[3 * t + 2];
        double nz = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
        ck_assert_msg(nz < 0, "triangle %zu winds the other way", t);
    }
    hv_mesh_destroy(&m);

    const char *ply2 = "ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\n"
                       "property float y\nproperty float z\nelement tristrips 1\n"
                       "property list int int vertex_indices\nend_header\n"
                       "0 0 0\n0 1 0\n1 0 0\n1 1 0\n2 0 0\n2 1 0\n"
                       "9 0 1 2 3 -1 2 3 4 5\n";
    ck_assert_int_eq(hv_mesh_read(tmp_write_str("strip2.ply", ply2), &m), HV_OK);
    ck_assert_uint_eq(m->ntris, 4);
    r = report(m);
    ck_assert_uint_eq(r.inconsistent_edges, 0);
    ck_assert_uint_eq(r.boundary_edges, 6);
    ck_assert_uint_eq(r.components, 1);
    hv_mesh_destroy(&m);
    remove_tmpdir();
}
END_TEST

/* ---- input limits ---- */

static const char *ply_with_lines(const char *name, const char *vertices, const char *face)
{
    char text[512];
    snprintf(text, sizeof text,
             "ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\n"
             "property double z\nelement face 1\nproperty list uchar int vertex_indices\n"
             "end_header\n%s%s\n",
             vertices, face);
    return tmp_write_str(name, text);
}

static const char *ply_face_line(const char *name, const char *face)
{
    return ply_with_lines(name, "0 0 0\n1 0 0\n0 1 0\n", face);
}

START_TEST(ply_integers_beyond_int64_should_fail_naming_the_file_and_line)
{
    /* Integral values written as reals ("3.0") are accepted; one outside the
     * range of int64 is refused, not converted (undefined behaviour). */
    make_tmpdir();
    hv_mesh *m = NULL;
    ck_assert_int_eq(hv_mesh_read(ply_face_line("real.ply", "3.0 0 1 2.0"), &m), HV_OK);
    ck_assert_uint_eq(m->ntris, 1);
    hv_mesh_destroy(&m);
    assert_fails(ply_face_line("count.ply", "1e300 0 1 2"),
                 "line 13: list count '1e300' is out of range");
    assert_fails(ply_face_line("index.ply", "3 0 1 -1e300"),
                 "line 13: a vertex index '-1e300' is out of range");
    assert_fails(ply_face_line("edge.ply", "3 0 1 9223372036854775808.0"), "out of range");
    assert_fails(ply_face_line("inf.ply", "inf 0 1 2"), "out of range");
    assert_fails(ply_face_line("nan.ply", "3 0 1 nan"), "line 13");
    remove_tmpdir();
}
END_TEST

/* Expects HV_ERR_NUMERIC with a message naming the file, the bound and `part`. */
static void assert_absurd(const char *path, const char *part)
{
    hv_mesh *m = NULL;
    hv_status st = hv_mesh_read(path, &m);
    ck_assert_msg(st == HV_ERR_NUMERIC, "%s: status %s (%s)", path, hv_status_str(st),
                  hv_last_error());
    ck_assert_ptr_null(m);
    ck_assert_msg(strstr(hv_last_error(), path) && strstr(hv_last_error(), part) &&
                      strstr(hv_last_error(), "+-1e+100"),
                  "message '%s' should name %s, '%s' and the bound", hv_last_error(), path, part);
}

START_TEST(coordinates_beyond_1e100_should_fail_naming_the_file_and_the_bound)
{
    /* 1e308 loads but the bounding box's extent overflows to inf: refused at
     * once, not much later as "voxel size inf gives -nan cells". */
    make_tmpdir();
    assert_absurd(tmp_write_str("big.obj", "v 0 0 0\nv 1e308 0 0\nv -1e308 1 0\nf 1 2 3\n"),
                  "line 2: vertex 2: coordinate x = 1e+308");
    assert_absurd(tmp_write_str("big.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 -2e100 0\n3 0 1 2\n"),
                  "line 5: vertex 3: coordinate y = -2e+100");
    assert_absurd(tmp_write_str("big.stl", "solid s\nfacet normal 0 0 1\nouter loop\n"
                                           "vertex 0 0 0\nvertex 1 0 0\nvertex 0 1 1e101\n"
                                           "endloop\nendfacet\nendsolid s\n"),
                  "line 6: vertex 3: coordinate z = 1e+101");
    assert_absurd(ply_with_lines("big.ply", "0 0 0\n1e300 0 0\n0 1 0\n", "3 0 1 2"),
                  "line 11: vertex 2: coordinate x = 1e+300");
    {
        /* binary: no line, the vertex number */
        bytes o = {.n = 0};
        put_text(&o, "ply\nformat binary_little_endian 1.0\nelement vertex 3\n"
                     "property double x\nproperty double y\nproperty double z\n"
                     "element face 1\nproperty list uchar int vertex_indices\nend_header\n");
        double v[9] = {0, 0, 0, 1, 0, 0, 0, 1, -DBL_MAX};
        put(&o, v, sizeof v, 0);
        unsigned char three = 3;
        int idx[3] = {0, 1, 2};
        put(&o, &three, 1, 0);
        put(&o, idx, sizeof idx, 0);
        assert_absurd(tmp_write("big_binary.ply", o.b, o.n), ": vertex 3: coordinate z");
    }
    /* the bound itself is accepted, and the extent stays finite */
    hv_mesh *m = NULL;
    ck_assert_int_eq(hv_mesh_read(tmp_write_str("edge.obj", "v -1e100 0 0\nv 1e100 0 0\n"
                                                            "v 0 1e100 -1e100\nf 1 2 3\n"),
                                  &m),
                     HV_OK);
    double lo[3], hi[3];
    ck_assert_int_eq(hv_mesh_bounds(m, lo, hi), HV_OK);
    for (int a = 0; a < 3; a++)
        ck_assert(isfinite(hi[a] - lo[a]));
    hv_mesh_destroy(&m);
    /* arrays are held to the same bound */
    const double v[9] = {0, 0, 0, 1, 0, 0, 0, 1e200, 0};
    const uint32_t t[3] = {0, 1, 2};
    ck_assert_int_eq(hv_mesh_from_arrays(&m, v, 3, t, 1), HV_ERR_NUMERIC);
    ck_assert_ptr_null(m);
    ck_assert_msg(strstr(hv_last_error(), "vertex 2: coordinate y"), "%s", hv_last_error());
    remove_tmpdir();
}
END_TEST

/* Writes text into a FIFO once a reader opens it; gives up after ~5 s. */
typedef struct fifo_job {
    const char *path, *text;
    int ok;
} fifo_job;

static void *fifo_writer(void *arg)
{
    fifo_job *j = arg;
    for (int tries = 0; tries < 500; tries++) {
        int fd = open(j->path, O_WRONLY | O_NONBLOCK);
        if (fd >= 0) {
            size_t n = strlen(j->text);
            j->ok = write(fd, j->text, n) == (ssize_t)n;
            close(fd);
            return NULL;
        }
        if (errno != ENXIO)
            return NULL;
        struct timespec ts = {0, 10 * 1000 * 1000};
        nanosleep(&ts, NULL);
    }
    return NULL;
}

START_TEST(non_regular_inputs_should_be_refused_naming_the_file)
{
    /* /dev/zero is refused, not read until memory runs out. */
    make_tmpdir();
    hv_mesh *m = NULL;
    ck_assert_int_eq(hv_mesh_read("/dev/zero", &m), HV_ERR_IO);
    ck_assert_ptr_null(m);
    ck_assert_msg(strstr(hv_last_error(), "/dev/zero") &&
                      strstr(hv_last_error(), "character device"),
                  "%s", hv_last_error());
    ck_assert_int_eq(hv_mesh_read(tmpdir, &m), HV_ERR_IO);
    ck_assert_msg(strstr(hv_last_error(), tmpdir) && strstr(hv_last_error(), "directory"), "%s",
                  hv_last_error());

    hv_curves *c = NULL;
    ck_assert_int_eq(hv_curves_read("/dev/zero", &c), HV_ERR_IO);
    ck_assert_ptr_null(c);
    ck_assert_msg(strstr(hv_last_error(), "/dev/zero") &&
                      strstr(hv_last_error(), "character device"),
                  "%s", hv_last_error());
    ck_assert_int_eq(hv_curves_read(tmpdir, &c), HV_ERR_IO);
    ck_assert_msg(strstr(hv_last_error(), "directory"), "%s", hv_last_error());

    /* a pipe (a shell's <(...)) is still read, by content */
    const char *fifo = tmp_path("pipe");
    ck_assert_int_eq(mkfifo(fifo, 0600), 0);
    fifo_job job = {fifo, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", 0};
    pthread_t th;
    ck_assert_int_eq(pthread_create(&th, NULL, fifo_writer, &job), 0);
    hv_status st = hv_mesh_read(fifo, &m);
    pthread_join(th, NULL);
    ck_assert_msg(job.ok && st == HV_OK, "%s: %s", hv_status_str(st), hv_last_error());
    ck_assert_uint_eq(m->ntris, 1);
    hv_mesh_destroy(&m);
    remove_tmpdir();
}
END_TEST

START_TEST(curve_coordinates_beyond_1e100_should_fail_naming_the_line_or_byte)
{
    hv_curves *c = NULL;
    const char *text = "M 0 0\nL 1 0\nL 0 1e300\n";
    ck_assert_int_eq(hv_curves_parse(text, strlen(text), 0, "t.txt", &c), HV_ERR_NUMERIC);
    ck_assert_msg(strstr(hv_last_error(), "t.txt: line 3") && strstr(hv_last_error(), "1e+100"),
                  "%s", hv_last_error());
    /* relative SVG commands add up past the bound (and then to inf) */
    const char *svg = "<svg><path d=\"M 0 0 l 1e100 0 l 1e100 0 l 1e308 0 l 1e308 0\"/></svg>";
    ck_assert_int_eq(hv_curves_parse(svg, strlen(svg), 1, "s.svg", &c), HV_ERR_NUMERIC);
    char at[64];
    snprintf(at, sizeof at, "s.svg: byte %ld:", (long)(strstr(svg, "1e100 0 l 1e308") - svg));
    ck_assert_msg(strstr(hv_last_error(), at), "'%s' lacks '%s'", hv_last_error(), at);
    ck_assert_ptr_null(c);
    const char *ok = "<svg><path d=\"M 0 0 l 1e100 0 L 0 -1e100 z\"/></svg>";
    ck_assert_int_eq(hv_curves_parse(ok, strlen(ok), 1, "ok.svg", &c), HV_OK);
    hv_curves_destroy(&c);
}
END_TEST

/* ---- arrays, welding ---- */

START_TEST(from_arrays_should_weld_exact_positions_only)
{
    /* two triangles sharing an edge given as a soup (-0 == +0); a NaN vertex
     * repeated is not merged; an unused vertex is dropped */
    const double v[] = {0,   0,    0, 1,   0, 0, 0, 1, 0, /* t0 */
                        1,   -0.0, 0, 1,   1, 0, 0, 1, 0, /* t1 */
                        NAN, 0,    0, NAN, 0, 0, 5, 5, 5, /* t2 */
                        9,   9,    9};                    /* unused */
    const uint32_t t[] = {0, 1, 4, 3, 5, 4, 6, 7, 8};
    hv_mesh *m = NULL;
    ck_assert_int_eq(hv_mesh_from_arrays(&m, v, 10, t, 3), HV_OK);
    ck_assert_uint_eq(m->nverts, 4 + 3);
    ck_assert_uint_eq(m->unreferenced_vertices, 2); /* v2 and v9; v3 merges into v1 */
    hv_mesh_report r = report(m);
    ck_assert_uint_eq(r.nonfinite_vertices, 2);
    ck_assert_uint_eq(r.edges, 5 + 3);
    ck_assert_uint_eq(r.boundary_edges, 4 + 3);
    ck_assert_uint_eq(r.inconsistent_edges, 0);
    ck_assert_uint_eq(r.components, 2);
    hv_mesh_destroy(&m);

    const uint32_t bad[] = {0, 1, 10};
    ck_assert_int_eq(hv_mesh_from_arrays(&m, v, 10, bad, 1), HV_ERR_INVALID_ARG);
    ck_assert_ptr_null(m);
    ck_assert_int_eq(hv_mesh_from_arrays(&m, v, 10, t, 0), HV_ERR_INVALID_ARG);
    hv_mesh_destroy(&m);
    hv_mesh_destroy(NULL);
}
END_TEST

START_TEST(degenerate_and_duplicate_faces_should_be_kept_and_counted)
{
    const double v[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 2, 0, 0};
    const uint32_t t[] = {0, 1, 2, 2, 1, 0, 1, 2, 0, 0, 0, 1, 0, 1, 3};
    hv_mesh *m = NULL;
    ck_assert_int_eq(hv_mesh_from_arrays(&m, v, 4, t, 5), HV_OK);
    ck_assert_uint_eq(m->ntris, 5);
    hv_mesh_report r = report(m);
    ck_assert_uint_eq(r.duplicate_faces, 2);   /* (2 1 0) and (1 2 0) repeat (0 1 2) */
    ck_assert_uint_eq(r.degenerate_faces, 2);  /* (0 0 1) repeats a vertex, (0 1 3) is flat */
    ck_assert_uint_eq(r.nonmanifold_edges, 3); /* 0-1 (4 uses), 1-2 and 0-2 (3 uses) */
    hv_mesh_destroy(&m);
}
END_TEST

/* ---- generators ---- */

START_TEST(icosphere_should_be_closed_consistent_and_outward)
{
    const double c[3] = {1, -2, 3};
    for (int s = 0; s <= 4; s++) {
        hv_mesh *m = NULL;
        ck_assert_int_eq(hv_mesh_make_sphere(&m, c, 2.0, s), HV_OK);
        size_t f = (size_t)20 << (2 * s);
        ck_assert_uint_eq(m->ntris, f);
        ck_assert_uint_eq(m->nverts, f / 2 + 2); /* Euler: V = F/2 + 2 */
        hv_mesh_report r = report(m);
        assert_closed_consistent(&r, "icosphere");
        ck_assert_uint_eq(r.edges, 3 * f / 2);
        ck_assert_uint_eq(r.duplicate_faces + r.degenerate_faces, 0);
        double exact = 4.0 / 3.0 * M_PI * 8.0;
        ck_assert_msg(r.signed_volume > 0 && r.signed_volume < exact, "volume %g", r.signed_volume);
        if (s == 4)
            ck_assert_msg(exact - r.signed_volume < 0.01 * exact, "volume %g", r.signed_volume);
        for (size_t i = 0; i < m->nverts; i++) {
            const double *p = m->verts + 3 * i;
            double d = sqrt((p[0] - c[0]) * (p[0] - c[0]) + (p[1] - c[1]) * (p[1] - c[1]) +
                            (p[2] - c[2]) * (p[2] - c[2]));
            ck_assert(fabs(d - 2.0) < 1e-12);
        }
        hv_mesh_destroy(&m);
    }
    hv_mesh *m = NULL;
    ck_assert_int_eq(hv_mesh_make_sphere(&m, c, -1, 2), HV_ERR_INVALID_ARG);
    ck_assert_int_eq(hv_mesh_make_sphere(&m, c, 1, 12), HV_ERR_INVALID_ARG);
    ck_assert_ptr_null(m);
}
END_TEST

START_TEST(torus_should_be_closed_outward_with_euler_characteristic_zero)
{
    const double c[3] = {0, 0, 0};
    hv_mesh *m = NULL;
    ck_assert_int_eq(hv_mesh_make_torus(&m, c, 2.0, 0.5, 96, 48), HV_OK);
    hv_mesh_report r = report(m);
    assert_closed_consistent(&r, "torus");
    ck_assert_int_eq((long)r.vertices - (long)r.edges + (long)r.triangles, 0);
    double exact = 2 * M_PI * M_PI * 2.0 * 0.25;
    ck_assert_msg(fabs(r.signed_volume - exact) < 0.01 * exact, "volume %g vs %g", r.signed_volume,
                  exact);
    hv_mesh_destroy(&m);
    ck_assert_int_eq(hv_mesh_make_torus(&m, c, 1.0, 2.0, 8, 8), HV_ERR_INVALID_ARG);
}
END_TEST

/* ---- defect makers ---- */

static hv_mesh *sphere(int s)
{
    const double c[3] = {0, 0, 0};
    hv_mesh *m = NULL;
    ck_assert_int_eq(hv_mesh_make_sphere(&m, c, 1.0, s), HV_OK);
    return m;
}

START_TEST(holes_should_open_boundaries_deterministically)
{
    hv_mesh *m = sphere(3), *m2 = NULL;
    size_t n0 = m->ntris;
    ck_assert_int_eq(hv_mesh_clone(m, &m2), HV_OK);
    ck_assert_int_eq(hv_mesh_defect_holes(m, 3, 0.05, 7), HV_OK);
    ck_assert_int_eq(hv_mesh_defect_holes(m2, 3, 0.05, 7), HV_OK);
    ck_assert_uint_eq(m->ntris, m2->ntris);
    ck_assert_mem_eq(m->tris, m2->tris, 3 * m->ntris * sizeof *m->tris);
    ck_assert_uint_lt(m->ntris, n0);
    hv_mesh_report r = report(m);
    ck_assert_uint_gt(r.boundary_edges, 0);
    ck_assert_uint_eq(r.nonmanifold_edges, 0);
    ck_assert_uint_eq(r.inconsistent_edges, 0);
    ck_assert_uint_eq(r.unreferenced_vertices, 0);
    for (size_t i = 0; i < 3 * m->ntris; i++)
        ck_assert_uint_lt(m->tris[i], m->nverts);
    hv_mesh_destroy(&m2);
    /* radius 0 still removes the fan around the chosen vertex: 5 or 6 triangles,
     * leaving as many boundary edges */
    m2 = sphere(2);
    ck_assert_int_eq(hv_mesh_defect_holes(m2, 1, 0.0, 1), HV_OK);
    r = report(m2);
    ck_assert_uint_eq(320 - m2->ntris, r.boundary_edges);
    ck_assert(r.boundary_edges == 5 || r.boundary_edges == 6);
    ck_assert_int_eq(hv_mesh_defect_holes(m2, 1, 10.0, 1), HV_ERR_INVALID_ARG);
    hv_mesh_destroy(&m);
    hv_mesh_destroy(&m2);
}
END_TEST

START_TEST(flips_should_make_inconsistent_edges_and_flipping_all_should_invert)
{
    hv_mesh *m = sphere(3);
    hv_mesh_report r0 = report(m);
    ck_assert_int_eq(hv_mesh_defect_flip(m, 0.3, 5), HV_OK);
    hv_mesh_report r = report(m);
    ck_assert_uint_gt(r.inconsistent_edges, r0.edges / 10);
    ck_assert_uint_eq(r.boundary_edges, 0);
    ck_assert_uint_eq(r.nonmanifold_edges, 0);
    hv_mesh_destroy(&m);

    m = sphere(3);
    ck_assert_int_eq(hv_mesh_defect_flip(m, 1.0, 5), HV_OK);
    r = report(m);
    ck_assert_uint_eq(r.inconsistent_edges, 0);
    ck_assert(fabs(r.signed_volume + r0.signed_volume) < 1e-12);
    ck_assert_int_eq(hv_mesh_defect_flip(m, 1.5, 5), HV_ERR_INVALID_ARG);
    hv_mesh_destroy(&m);

    m = sphere(3);
    ck_assert_int_eq(hv_mesh_defect_flip(m, 0.0, 5), HV_OK);
    ck_assert_uint_eq(report(m).inconsistent_edges, 0);
    hv_mesh_destroy(&m);
}
END_TEST

START_TEST(flip_half_should_invert_one_side_only)
{
    for (int axis = 0; axis < 3; axis++) {
        hv_mesh *m = sphere(3);
        hv_mesh_report r0 = report(m);
        ck_assert_int_eq(hv_mesh_defect_flip_half(m, axis), HV_OK);
        hv_mesh_report r = report(m);
        /* the flipped half meets the rest along one loop of edges */
        ck_assert_uint_gt(r.inconsistent_edges, 0);
        ck_assert_uint_lt(r.inconsistent_edges, r0.edges / 10);
        ck_assert(fabs(r.signed_volume) < 0.1 * r0.signed_volume);
        hv_mesh_destroy(&m);
    }
    hv_mesh *m = sphere(1);
    ck_assert_int_eq(hv_mesh_defect_flip_half(m, 3), HV_ERR_INVALID_ARG);
    hv_mesh_destroy(&m);
}
END_TEST

START_TEST(duplicates_should_be_counted_and_make_edges_nonmanifold)
{
    hv_mesh *m = sphere(3);
    size_t n0 = m->ntris;
    double v0 = report(m).signed_volume;
    ck_assert_int_eq(hv_mesh_defect_duplicate(m, 0.1, 3), HV_OK);
    size_t k = (size_t)llround(0.1 * (double)n0);
    ck_assert_uint_eq(m->ntris, n0 + k);
    hv_mesh_report r = report(m);
    ck_assert_uint_eq(r.duplicate_faces, k);
    ck_assert_uint_gt(r.nonmanifold_edges, 0);
    ck_assert_uint_eq(r.boundary_edges, 0);
    ck_assert_uint_eq(r.components, 1);
    /* half the copies are reversed, so the copies' volumes nearly cancel */
    ck_assert(fabs(r.signed_volume - v0) < 0.05 * v0);
    hv_mesh_destroy(&m);
}
END_TEST

START_TEST(soup_should_unweld_every_triangle_and_welding_should_restore_it)
{
    hv_mesh *m = sphere(2);
    size_t nv = m->nverts, nt = m->ntris;
    ck_assert_int_eq(hv_mesh_defect_soup(m, 0.0, 1), HV_OK);
    ck_assert_uint_eq(m->nverts, 3 * nt);
    hv_mesh_report r = report(m);
    ck_assert_uint_eq(r.boundary_edges, 3 * nt);
    ck_assert_uint_eq(r.components, nt);
    hv_mesh *w = NULL;
    ck_assert_int_eq(hv_mesh_from_arrays(&w, m->verts, m->nverts, m->tris, m->ntris), HV_OK);
    ck_assert_uint_eq(w->nverts, nv);
    r = report(w);
    assert_closed_consistent(&r, "rewelded soup");
    hv_mesh_destroy(&w);
    hv_mesh_destroy(&m);

    m = sphere(2);
    ck_assert_int_eq(hv_mesh_defect_soup(m, 1e-6, 1), HV_OK);
    ck_assert_int_eq(hv_mesh_from_arrays(&w, m->verts, m->nverts, m->tris, m->ntris), HV_OK);
    ck_assert_uint_eq(w->nverts, 3 * nt); /* jittered: nothing welds */
    hv_mesh_destroy(&w);
    hv_mesh_destroy(&m);
}
END_TEST

/* ---- writer ---- */

START_TEST(written_obj_should_read_back_bit_for_bit)
{
    make_tmpdir();
    const double c[3] = {0.1, 1.0 / 3.0, -7e-5};
    hv_mesh *m = NULL, *back = NULL;
    ck_assert_int_eq(hv_mesh_make_sphere(&m, c, 0.7, 3), HV_OK);
    char path[600];
    snprintf(path, sizeof path, "%s/sphere.obj", tmpdir);
    ck_assert_int_eq(hv_mesh_write_obj(m, path), HV_OK);
    ck_assert_int_eq(hv_mesh_read(path, &back), HV_OK);
    ck_assert_uint_eq(back->nverts, m->nverts);
    ck_assert_uint_eq(back->ntris, m->ntris);
    ck_assert_mem_eq(back->verts, m->verts, 3 * m->nverts * sizeof *m->verts);
    ck_assert_mem_eq(back->tris, m->tris, 3 * m->ntris * sizeof *m->tris);
    /* nothing but the file itself is left in the directory */
    DIR *d = opendir(tmpdir);
    struct dirent *e;
    int files = 0;
    while ((e = readdir(d)))
        files += strcmp(e->d_name, ".") && strcmp(e->d_name, "..");
    closedir(d);
    ck_assert_int_eq(files, 1);
    char bad[700];
    snprintf(bad, sizeof bad, "%s/no/such/dir/x.obj", tmpdir);
    ck_assert_int_eq(hv_mesh_write_obj(m, bad), HV_ERR_IO);
    hv_mesh_destroy(&m);
    hv_mesh_destroy(&back);
    remove_tmpdir();
}
END_TEST

static Suite *mesh_suite(void)
{
    Suite *s = suite_create("mesh");
    TCase *tc = tcase_create("readers");
    tcase_set_timeout(tc, 60);
    tcase_add_test(tc, cube_written_in_every_format_should_load_to_12_triangles_on_8_vertices);
    tcase_add_test(tc, fanned_polygons_should_be_counted);
    tcase_add_test(tc, long_lines_without_final_newline_should_load);
    tcase_add_test(tc, malformed_files_should_fail_with_the_line_or_byte);
    tcase_add_test(tc, nonfinite_coordinates_should_be_loaded_and_counted);
    tcase_add_test(tc, tristrips_should_alternate_winding_and_restart_at_minus_one);
    tcase_add_test(tc, stl_facet_normals_without_numbers_should_read_with_a_note);
    tcase_add_test(tc, ply_integers_beyond_int64_should_fail_naming_the_file_and_line);
    tcase_add_test(tc, coordinates_beyond_1e100_should_fail_naming_the_file_and_the_bound);
    tcase_add_test(tc, non_regular_inputs_should_be_refused_naming_the_file);
    tcase_add_test(tc, curve_coordinates_beyond_1e100_should_fail_naming_the_line_or_byte);
    tcase_add_test(tc, from_arrays_should_weld_exact_positions_only);
    tcase_add_test(tc, degenerate_and_duplicate_faces_should_be_kept_and_counted);
    tcase_add_test(tc, written_obj_should_read_back_bit_for_bit);
    suite_add_tcase(s, tc);

    tc = tcase_create("shared");
    tcase_set_timeout(tc, 120);
    tcase_add_test(tc, every_shared_file_should_load_or_fail_with_a_message_naming_it);
    tcase_add_test(tc, huge_declared_counts_should_fail_without_allocating);
    tcase_add_test(tc, clean_shared_meshes_should_be_closed_and_consistent);
    tcase_add_test(tc, broken_shared_meshes_should_report_the_defects_sources_md_lists);
    tcase_add_test(tc, igea_tristrips_should_become_a_consistent_surface);
    tcase_add_test(tc, stanford_bunny_should_load_and_report);
    suite_add_tcase(s, tc);

    tc = tcase_create("generators and defects");
    tcase_set_timeout(tc, 60);
    tcase_add_test(tc, icosphere_should_be_closed_consistent_and_outward);
    tcase_add_test(tc, torus_should_be_closed_outward_with_euler_characteristic_zero);
    tcase_add_test(tc, holes_should_open_boundaries_deterministically);
    tcase_add_test(tc, flips_should_make_inconsistent_edges_and_flipping_all_should_invert);
    tcase_add_test(tc, flip_half_should_invert_one_side_only);
    tcase_add_test(tc, duplicates_should_be_counted_and_make_edges_nonmanifold);
    tcase_add_test(tc, soup_should_unweld_every_triangle_and_welding_should_restore_it);
    suite_add_tcase(s, tc);
    return s;
}

int main(void)
{
    SRunner *sr = srunner_create(mesh_suite());
    /* No fork, whatever CK_FORK says: the library links PoCL and OpenVDB/TBB,
     * whose worker threads do not survive fork: a forked test hangs
     * (docs/METHOD.md, "Testing notes"). */
    srunner_set_fork_status(sr, CK_NOFORK);
    srunner_run_all(sr, CK_NORMAL);
    int failed = srunner_ntests_failed(sr);
    srunner_free(sr);
    return failed ? EXIT_FAILURE : EXIT_SUCCESS;
}
