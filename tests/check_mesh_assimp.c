/* Meshes through assimp: every format hv_mesh_read hands to assimp reads the
 * triangles of the same scene saved as OBJ. The files are made here with
 * assimp's own exporters from an OBJ that heatvox writes (float coordinates,
 * so that no format rounds them), with node transforms set on the imported
 * scene; a 3MF with placed build items is written by hand. Rejected files
 * fail naming the file, nothing is printed, the assimp test models corpus
 * (Debian's assimp-testmodels) loads or fails cleanly, and `heatvox sdf` of a
 * .glb equals that of the .obj bit for bit. */
#include "heatvox/heatvox.h"
#include "testlib.h"

#include <assimp/cexport.h>
#include <assimp/cimport.h>
#include <assimp/scene.h>

#include <check.h>
#include <errno.h>
#include <fcntl.h>
#include <ftw.h>
#include <malloc.h>
#if defined(__SANITIZE_ADDRESS__)
/* AddressSanitizer's count of the bytes its allocator holds for the program
 * (sanitizer/allocator_interface.h, which GCC does not install). */
size_t __sanitizer_get_current_allocated_bytes(void);
#endif
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>
#include <zlib.h>

/* ---- scratch files ---- */

static char tmpdir[256];

static void make_tmpdir(void)
{
    snprintf(tmpdir, sizeof tmpdir, "/tmp/hv_check_mesh_assimp_XXXXXX");
    ck_assert_ptr_nonnull(mkdtemp(tmpdir));
}

static void remove_tmpdir(void) { tl_rm_rf(tmpdir); }

static const char *tmp_path(const char *name)
{
    static char p[4][600];
    static int k;
    k = (k + 1) % 4;
    snprintf(p[k], sizeof p[k], "%s/%s", tmpdir, name);
    return p[k];
}

static void write_bytes(const char *path, const void *data, size_t len)
{
    FILE *f = fopen(path, "wb");
    ck_assert_msg(f != NULL, "%s: %s", path, strerror(errno));
    ck_assert_uint_eq(fwrite(data, 1, len, f), len);
    ck_assert_int_eq(fclose(f), 0);
}

static char *read_text(const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    ck_assert_msg(f != NULL, "%s: %s", path, strerror(errno));
    ck_assert_int_eq(fseek(f, 0, SEEK_END), 0);
    long n = ftell(f);
    ck_assert_int_ge(n, 0);
    rewind(f);
    char *s = malloc((size_t)n + 1);
    ck_assert_ptr_nonnull(s);
    ck_assert_uint_eq(fread(s, 1, (size_t)n, f), (size_t)n);
    fclose(f);
    s[n] = '\0';
    if (len)
        *len = (size_t)n;
    return s;
}

/* Replaces the first `from` in the text file at src by `to`, into dst. */
static void edit_copy(const char *src, const char *dst, const char *from, const char *to)
{
    size_t n;
    char *s = read_text(src, &n);
    char *at = strstr(s, from);
    ck_assert_msg(at != NULL, "%s: no '%s' to replace", src, from);
    FILE *f = fopen(dst, "wb");
    ck_assert_ptr_nonnull(f);
    fwrite(s, 1, (size_t)(at - s), f);
    fputs(to, f);
    fputs(at + strlen(from), f);
    ck_assert_int_eq(fclose(f), 0);
    free(s);
}

/* ---- meshes and their triangles ---- */

/* The mesh with its coordinates on a grid of 1/32 (below 10 in magnitude):
 * exact in float32, which every format here stores, in the six decimals
 * assimp's ASCII FBX writer prints and in the six significant digits of its
 * 3MF writer. Its vertices come in the order triangles first use them: a
 * reader that welds per-corner vertices back (as hv_mesh_read does) builds
 * the same arrays. */
static hv_mesh *grid_mesh(hv_mesh *m)
{
    double *v = malloc(m->ntris * 9 * sizeof *v);
    uint32_t *t = malloc(m->ntris * 3 * sizeof *t);
    ck_assert(v && t);
    for (size_t i = 0; i < 3 * m->ntris; i++) {
        for (int a = 0; a < 3; a++)
            v[3 * i + a] = round(m->verts[3 * (size_t)m->tris[i] + a] * 32) / 32;
        t[i] = (uint32_t)i;
    }
    hv_mesh *f = NULL;
    TL_ASSERT_OK(hv_mesh_from_arrays(&f, v, 3 * m->ntris, t, m->ntris));
    free(v);
    free(t);
    hv_mesh_destroy(&m);
    return f;
}

static hv_mesh *test_sphere(double cx, double r, int subdiv)
{
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_make_sphere(&m, (const double[3]){cx, 0.25, -0.5}, r, subdiv));
    return grid_mesh(m);
}

static hv_mesh *test_torus(void)
{
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_make_torus(&m, (const double[3]){0.5, -1, 0.75}, 1.0, 0.3, 16, 8));
    return grid_mesh(m);
}

static hv_mesh *read_ok(const char *path)
{
    hv_mesh *m = NULL;
    hv_status st = hv_mesh_read(path, &m);
    ck_assert_msg(st == HV_OK, "%s: %s: %s", path, hv_status_str(st), hv_last_error());
    return m;
}

/* One object per mesh ("o NAME"), so that assimp's OBJ importer gives each
 * its own node under the root. */
static void write_objects(const char *path, hv_mesh *const *ms, int n)
{
    FILE *f = fopen(path, "w");
    ck_assert_ptr_nonnull(f);
    size_t base = 1;
    for (int k = 0; k < n; k++) {
        fprintf(f, "o part%d\n", k);
        for (size_t i = 0; i < ms[k]->nverts; i++)
            fprintf(f, "v %.17g %.17g %.17g\n", ms[k]->verts[3 * i], ms[k]->verts[3 * i + 1],
                    ms[k]->verts[3 * i + 2]);
        for (size_t i = 0; i < ms[k]->ntris; i++)
            fprintf(f, "f %zu %zu %zu\n", base + ms[k]->tris[3 * i], base + ms[k]->tris[3 * i + 1],
                    base + ms[k]->tris[3 * i + 2]);
        base += ms[k]->nverts;
    }
    ck_assert_int_eq(fclose(f), 0);
}

static double bbox_diag(const hv_mesh *m)
{
    double lo[3], hi[3];
    TL_ASSERT_OK(hv_mesh_bounds(m, lo, hi));
    return sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                (hi[2] - lo[2]) * (hi[2] - lo[2]));
}

/* Whether corners (a0 a1 a2) of a and (b0 b1 b2) of b agree within tol, in
 * the same cyclic order starting anywhere (the orientation kept). */
static int same_tri(const hv_mesh *a, size_t ta, const hv_mesh *b, size_t tb, double tol, int rev)
{
    for (int s = 0; s < 3; s++) {
        int ok = 1;
        for (int c = 0; c < 3 && ok; c++) {
            int cb = rev ? (s + 3 - c) % 3 : (s + c) % 3;
            const double *p = a->verts + 3 * (size_t)a->tris[3 * ta + c];
            const double *q = b->verts + 3 * (size_t)b->tris[3 * tb + cb];
            for (int d = 0; d < 3 && ok; d++)
                ok = fabs(p[d] - q[d]) <= tol;
        }
        if (ok)
            return 1;
    }
    return 0;
}

/* Every triangle of got matches one of want (each used once), corner for
 * corner within tol (0: the same doubles), in want's orientation (reversed
 * with rev). Triangle order may differ. */
static void assert_same_triangles(const char *what, const hv_mesh *got, const hv_mesh *want,
                                  double tol, int rev)
{
    ck_assert_msg(got->ntris == want->ntris, "%s: %zu triangles, the OBJ has %zu", what, got->ntris,
                  want->ntris);
    ck_assert_msg(got->nverts == want->nverts, "%s: %zu vertices, the OBJ has %zu", what,
                  got->nverts, want->nverts);
    char *used = calloc(want->ntris, 1);
    ck_assert_ptr_nonnull(used);
    size_t unmatched = 0, first = 0;
    for (size_t i = 0; i < got->ntris; i++) {
        size_t j = 0;
        while (j < want->ntris && (used[j] || !same_tri(got, i, want, j, tol, rev)))
            j++;
        if (j < want->ntris)
            used[j] = 1;
        else if (!unmatched++)
            first = i;
    }
    free(used);
    if (unmatched) {
        const double *p = got->verts + 3 * (size_t)got->tris[3 * first];
        ck_abort_msg("%s: %zu of %zu triangles match none of the OBJ's within %g (the first: "
                     "%zu, corner (%.9g %.9g %.9g))",
                     what, unmatched, got->ntris, tol, first, p[0], p[1], p[2]);
    }
}

/* ---- assimp's side: scenes and exports ---- */

typedef struct {
    const char *id, *ext; /* assimp exporter, file extension */
    int transforms;       /* which transforms the exporter writes */
} exporter;
enum { NO_TRANSFORMS, BELOW_THE_ROOT, ALL_TRANSFORMS };

/* The exporters of assimp 5.2 whose files its importers read back. The
 * binary FBX exporter writes files its own importer rejects ("block offset
 * is out of range", assimp's GitHub report 4686): FBX is made as ASCII here,
 * and binary FBX from other tools is in the corpus test. The FBX writer
 * leaves out the root node's transform (the root becomes FBX's implicit
 * RootNode), and D3MFExporter writes no transforms at all: a 3MF with them
 * is written by hand. */
static const exporter exporters[] = {
    {"gltf2", ".gltf", ALL_TRANSFORMS},  {"glb2", ".glb", ALL_TRANSFORMS},
    {"collada", ".dae", ALL_TRANSFORMS}, {"fbxa", ".fbx", BELOW_THE_ROOT},
    {"x", ".x", ALL_TRANSFORMS},         {"3mf", ".3mf", NO_TRANSFORMS},
};
#define NEXPORTERS (sizeof exporters / sizeof exporters[0])

static const struct aiScene *import_obj(const char *path)
{
    const struct aiScene *sc = aiImportFile(path, 0);
    ck_assert_msg(sc != NULL, "assimp cannot read %s: %s", path, aiGetErrorString());
    ck_assert_ptr_nonnull(sc->mRootNode);
    return sc;
}

static const char *export_as(const struct aiScene *sc, const exporter *e, const char *stem)
{
    char name[128];
    snprintf(name, sizeof name, "%s_%s%s", stem, e->id, e->ext);
    const char *path = tmp_path(name);
    ck_assert_msg(aiExportScene(sc, e->id, path, 0) == aiReturn_SUCCESS, "export %s: %s", e->id,
                  aiGetErrorString());
    return path;
}

static struct aiMatrix4x4 affine(const double m[12])
{
    struct aiMatrix4x4 t = {(float)m[0],
                            (float)m[1],
                            (float)m[2],
                            (float)m[3],
                            (float)m[4],
                            (float)m[5],
                            (float)m[6],
                            (float)m[7],
                            (float)m[8],
                            (float)m[9],
                            (float)m[10],
                            (float)m[11],
                            0,
                            0,
                            0,
                            1};
    return t;
}

/* A binary glTF 2.0 container around a JSON text (padded to 4 bytes), no
 * binary chunk. */
static void write_glb(const char *path, const char *json)
{
    size_t n = strlen(json), padded = (n + 3) / 4 * 4, total = 20 + padded;
    unsigned char *b = malloc(total);
    ck_assert_ptr_nonnull(b);
    const uint32_t head[5] = {0x46546c67u, 2, (uint32_t)total, (uint32_t)padded, 0x4e4f534au};
    for (int i = 0; i < 5; i++)
        for (int k = 0; k < 4; k++)
            b[4 * i + k] = (unsigned char)(head[i] >> (8 * k));
    memcpy(b + 20, json, n);
    memset(b + 20 + n, ' ', padded - n);
    write_bytes(path, b, total);
    free(b);
}

/* ---- nothing printed ---- */

/* stdout and stderr into a file while a reader runs: the library prints
 * nothing (assimp has no logger attached and must not write on its own). */
typedef struct {
    int saved[2];
    char path[600];
} quiet;

static void quiet_begin(quiet *q, const char *path)
{
    snprintf(q->path, sizeof q->path, "%s", path);
    fflush(stdout);
    fflush(stderr);
    int fd = open(path, O_WRONLY | O_CREAT | O_TRUNC, 0600);
    ck_assert_int_ge(fd, 0);
    for (int k = 0; k < 2; k++) {
        q->saved[k] = dup(k + 1);
        ck_assert_int_ge(q->saved[k], 0);
        ck_assert_int_ge(dup2(fd, k + 1), 0);
    }
    close(fd);
}

/* Restores the streams; returns how many bytes were written meanwhile. */
static long quiet_end(quiet *q)
{
    fflush(stdout);
    fflush(stderr);
    for (int k = 0; k < 2; k++) {
        dup2(q->saved[k], k + 1);
        close(q->saved[k]);
    }
    struct stat sb;
    long n = stat(q->path, &sb) == 0 ? (long)sb.st_size : -1;
    unlink(q->path);
    return n;
}

/* ---- tests ---- */

START_TEST(extensions_should_pick_the_hand_written_readers_or_assimp)
{
    ck_assert_str_eq(hv_mesh_format_by_extension("a/b.OBJ"), "OBJ");
    ck_assert_str_eq(hv_mesh_format_by_extension("x.ply"), "PLY");
    ck_assert_str_eq(hv_mesh_format_by_extension("x.stl"), "STL");
    ck_assert_str_eq(hv_mesh_format_by_extension("x.off"), "OFF");
    ck_assert_str_eq(hv_mesh_format_by_extension("x.gltf"), "glTF 2.0 via assimp");
    ck_assert_str_eq(hv_mesh_format_by_extension("x.GLB"), "glTF 2.0 binary via assimp");
    ck_assert_str_eq(hv_mesh_format_by_extension("x.fbx"), "FBX via assimp");
    ck_assert_str_eq(hv_mesh_format_by_extension("x.3mf"), "3MF via assimp");
    ck_assert_str_eq(hv_mesh_format_by_extension("x.dae"), "COLLADA via assimp");
    ck_assert_str_eq(hv_mesh_format_by_extension("x.X"), "DirectX X via assimp");
    ck_assert_ptr_null(hv_mesh_format_by_extension("x.3ds"));
    ck_assert_ptr_null(hv_mesh_format_by_extension("x.glb/mesh"));
    ck_assert_ptr_null(hv_mesh_format_by_extension("noext"));
    ck_assert_ptr_null(hv_mesh_format_by_extension(NULL));
}
END_TEST

/* One mesh, no transform: every format gives the OBJ's doubles exactly. */
START_TEST(every_format_should_read_the_same_triangles_as_the_obj)
{
    make_tmpdir();
    hv_mesh *ref = test_sphere(0.125, 1.5, 2);
    const char *obj = tmp_path("sphere.obj");
    TL_ASSERT_OK(hv_mesh_write_obj(ref, obj));
    hv_mesh *want = read_ok(obj);
    const struct aiScene *sc = import_obj(obj);
    quiet q;
    for (size_t k = 0; k < NEXPORTERS; k++) {
        const char *path = export_as(sc, &exporters[k], "sphere");
        quiet_begin(&q, tmp_path("out.txt"));
        hv_mesh *m = NULL;
        hv_status st = hv_mesh_read(path, &m);
        long printed = quiet_end(&q);
        ck_assert_msg(st == HV_OK, "%s: %s", path, hv_last_error());
        ck_assert_msg(printed == 0, "%s: reading it printed %ld bytes", path, printed);
        ck_assert_str_eq(m->format, hv_mesh_format_by_extension(path));
        assert_same_triangles(path, m, want, 0.0, 0);
        ck_assert_uint_eq(m->skipped_primitives, 0);
        hv_mesh_destroy(&m);
    }
    aiReleaseImport(sc);
    hv_mesh_destroy(&want);
    hv_mesh_destroy(&ref);
    remove_tmpdir();
}
END_TEST

/* Two objects under a root, each node with its own transform (rotation,
 * non-uniform scale, translation): the formats that keep node transforms give
 * the triangles of assimp's OBJ export of the same scene, which applies them
 * (in float, hence the tolerance). */
START_TEST(a_node_hierarchy_should_be_flattened_with_its_transforms)
{
    make_tmpdir();
    hv_mesh *parts[2] = {test_sphere(0, 1, 2), test_torus()};
    const char *obj = tmp_path("parts.obj");
    write_objects(obj, parts, 2);
    const struct aiScene *sc = import_obj(obj);
    struct aiNode *root = sc->mRootNode;
    ck_assert_uint_eq(root->mNumChildren, 2);
    const double c = cos(0.5), s = sin(0.5);
    /* the root: a uniform scale and a shift; part 0: a quarter turn about z
     * and a shift; part 1: a non-uniform scale then half a radian about x */
    root->mTransformation = affine((const double[12]){2, 0, 0, 1, 0, 2, 0, -3, 0, 0, 2, 0.5});
    root->mChildren[0]->mTransformation =
        affine((const double[12]){0, -1, 0, 4, 1, 0, 0, 0, 0, 0, 1, -2});
    root->mChildren[1]->mTransformation =
        affine((const double[12]){1.5, 0, 0, 0, 0, 0.5 * c, -0.25 * s, 1, 0, 0.5 * s, 0.25 * c, 0});
    /* the references: every transform, and those below the root */
    hv_mesh *want[2];
    for (int r = 0; r < 2; r++) {
        const struct aiMatrix4x4 keep = root->mTransformation;
        if (r)
            root->mTransformation = affine((const double[12]){1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0});
        const char *ref = tmp_path(r ? "parts_below_root.obj" : "parts_all.obj");
        ck_assert_int_eq(aiExportScene(sc, "objnomtl", ref, 0), aiReturn_SUCCESS);
        root->mTransformation = keep;
        want[r] = read_ok(ref);
        ck_assert_uint_eq(want[r]->ntris, parts[0]->ntris + parts[1]->ntris);
    }
    const double tol = 1e-6 * bbox_diag(want[0]);
    for (size_t k = 0; k < NEXPORTERS; k++) {
        if (exporters[k].transforms == NO_TRANSFORMS)
            continue;
        const char *path = export_as(sc, &exporters[k], "parts");
        hv_mesh *m = read_ok(path);
        assert_same_triangles(path, m, want[exporters[k].transforms == BELOW_THE_ROOT], tol, 0);
        hv_mesh_report r;
        TL_ASSERT_OK(hv_mesh_report_compute(m, &r));
        ck_assert_msg(r.components == 2 && r.boundary_edges == 0 && r.signed_volume > 0,
                      "%s: %zu components, %zu boundary edges, volume %g", path, r.components,
                      r.boundary_edges, r.signed_volume);
        hv_mesh_destroy(&m);
    }
    aiReleaseImport(sc);
    hv_mesh_destroy(&want[0]);
    hv_mesh_destroy(&want[1]);
    hv_mesh_destroy(&parts[0]);
    hv_mesh_destroy(&parts[1]);
    remove_tmpdir();
}
END_TEST

/* A transform with a negative determinant turns a surface inside out unless
 * its faces are reversed (glTF 2.0 says so, assimp's PreTransformVertices
 * does it): the triangles are the OBJ export's (which moves vertices only)
 * reversed, and the volume stays positive. */
START_TEST(a_mirroring_transform_should_keep_the_faces_outward)
{
    make_tmpdir();
    hv_mesh *part = test_sphere(0.5, 1, 2);
    const char *obj = tmp_path("mirror.obj");
    write_objects(obj, &part, 1);
    const struct aiScene *sc = import_obj(obj);
    ck_assert_uint_eq(sc->mRootNode->mNumChildren, 1);
    sc->mRootNode->mChildren[0]->mTransformation =
        affine((const double[12]){-1, 0, 0, 0.25, 0, 1, 0, 0, 0, 0, 1, 0});
    const char *ref = tmp_path("mirror_ref.obj");
    ck_assert_int_eq(aiExportScene(sc, "objnomtl", ref, 0), aiReturn_SUCCESS);
    hv_mesh *want = read_ok(ref);
    hv_mesh_report r;
    TL_ASSERT_OK(hv_mesh_report_compute(want, &r));
    ck_assert_double_lt(r.signed_volume, 0); /* the OBJ: inside out */
    for (size_t k = 0; k < NEXPORTERS; k++) {
        if (exporters[k].transforms == NO_TRANSFORMS)
            continue;
        const char *path = export_as(sc, &exporters[k], "mirror");
        hv_mesh *m = read_ok(path);
        assert_same_triangles(path, m, want, 1e-6, 1);
        TL_ASSERT_OK(hv_mesh_report_compute(m, &r));
        ck_assert_msg(r.signed_volume > 0 && r.inconsistent_edges == 0, "%s: volume %g", path,
                      r.signed_volume);
        hv_mesh_destroy(&m);
    }
    aiReleaseImport(sc);
    hv_mesh_destroy(&want);
    hv_mesh_destroy(&part);
    remove_tmpdir();
}
END_TEST

/* ---- 3MF by hand: a zip archive with stored (uncompressed) entries ---- */

typedef struct {
    const char *name, *data;
} zip_entry;

static void put16(FILE *f, unsigned v)
{
    fputc((int)(v & 0xff), f);
    fputc((int)(v >> 8 & 0xff), f);
}

static void put32(FILE *f, unsigned long v)
{
    put16(f, (unsigned)(v & 0xffff));
    put16(f, (unsigned)(v >> 16 & 0xffff));
}

static void write_zip(const char *path, const zip_entry *e, int n)
{
    FILE *f = fopen(path, "wb");
    ck_assert_ptr_nonnull(f);
    unsigned long offs[8], crcs[8];
    ck_assert_int_le(n, 8);
    for (int i = 0; i < n; i++) {
        size_t len = strlen(e[i].data);
        crcs[i] = crc32(0L, (const Bytef *)e[i].data, (uInt)len);
        offs[i] = (unsigned long)ftell(f);
        put32(f, 0x04034b50);
        put16(f, 20), put16(f, 0), put16(f, 0), put16(f, 0), put16(f, 0);
        put32(f, crcs[i]), put32(f, len), put32(f, len);
        put16(f, (unsigned)strlen(e[i].name)), put16(f, 0);
        fputs(e[i].name, f);
        fwrite(e[i].data, 1, len, f);
    }
    unsigned long cd = (unsigned long)ftell(f);
    for (int i = 0; i < n; i++) {
        size_t len = strlen(e[i].data);
        put32(f, 0x02014b50);
        put16(f, 20), put16(f, 20), put16(f, 0), put16(f, 0), put16(f, 0), put16(f, 0);
        put32(f, crcs[i]), put32(f, len), put32(f, len);
        put16(f, (unsigned)strlen(e[i].name)), put16(f, 0), put16(f, 0), put16(f, 0), put16(f, 0);
        put32(f, 0), put32(f, offs[i]);
        fputs(e[i].name, f);
    }
    unsigned long cdlen = (unsigned long)ftell(f) - cd;
    put32(f, 0x06054b50);
    put16(f, 0), put16(f, 0), put16(f, (unsigned)n), put16(f, (unsigned)n);
    put32(f, cdlen), put32(f, cd), put16(f, 0);
    ck_assert_int_eq(fclose(f), 0);
}

/* 3MF places objects with build items, each with a 3x4 transform of row
 * vectors ("m00 m01 m02 m10 ... m32": p' = p M); the same object placed twice
 * is two copies. */
START_TEST(a_3mf_build_should_place_each_item_with_its_transform)
{
    make_tmpdir();
    /* a tetrahedron, outward */
    static const double tv[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    static const uint32_t tt[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
    char model[4096];
    int n = snprintf(model, sizeof model,
                     "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
                     "<model unit=\"millimeter\" "
                     "xmlns=\"http://schemas.microsoft.com/3dmanufacturing/core/2015/02\">\n"
                     "<resources><object id=\"1\" type=\"model\"><mesh><vertices>\n");
    for (int i = 0; i < 4; i++)
        n += snprintf(model + n, sizeof model - (size_t)n, "<vertex x=\"%g\" y=\"%g\" z=\"%g\"/>\n",
                      tv[i][0], tv[i][1], tv[i][2]);
    n += snprintf(model + n, sizeof model - (size_t)n, "</vertices><triangles>\n");
    for (int i = 0; i < 4; i++)
        n += snprintf(model + n, sizeof model - (size_t)n,
                      "<triangle v1=\"%u\" v2=\"%u\" v3=\"%u\"/>\n", tt[i][0], tt[i][1], tt[i][2]);
    /* the second item: x -> y, y -> -x (a quarter turn), z doubled, shifted */
    static const double M[4][3] = {{0, 1, 0}, {-1, 0, 0}, {0, 0, 2}, {5, 6, 7}};
    n += snprintf(model + n, sizeof model - (size_t)n,
                  "</triangles></mesh></object></resources>\n<build><item objectid=\"1\"/>"
                  "<item objectid=\"1\" transform=\"%g %g %g %g %g %g %g %g %g %g %g %g\"/>"
                  "</build></model>\n",
                  M[0][0], M[0][1], M[0][2], M[1][0], M[1][1], M[1][2], M[2][0], M[2][1], M[2][2],
                  M[3][0], M[3][1], M[3][2]);
    ck_assert_int_lt(n, (int)sizeof model);
    const zip_entry e[] = {
        {"[Content_Types].xml",
         "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<Types "
         "xmlns=\"http://schemas.openxmlformats.org/package/2006/content-types\">"
         "<Default Extension=\"rels\" "
         "ContentType=\"application/vnd.openxmlformats-package.relationships+xml\"/>"
         "<Default Extension=\"model\" "
         "ContentType=\"application/vnd.ms-package.3dmanufacturing-3dmodel+xml\"/></Types>\n"},
        {"_rels/.rels", "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<Relationships "
                        "xmlns=\"http://schemas.openxmlformats.org/package/2006/relationships\">"
                        "<Relationship Target=\"/3D/3DModel.model\" Id=\"rel0\" "
                        "Type=\"http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel\"/>"
                        "</Relationships>\n"},
        {"3D/3DModel.model", model},
    };
    const char *path = tmp_path("placed.3mf");
    write_zip(path, e, 3);
    hv_mesh *m = read_ok(path);

    double v[8][3];
    uint32_t t[8][3];
    for (int i = 0; i < 4; i++)
        for (int a = 0; a < 3; a++) {
            v[i][a] = tv[i][a];
            v[4 + i][a] = tv[i][0] * M[0][a] + tv[i][1] * M[1][a] + tv[i][2] * M[2][a] + M[3][a];
            t[i][a] = tt[i][a];
            t[4 + i][a] = tt[i][a] + 4;
        }
    hv_mesh *want = NULL;
    TL_ASSERT_OK(hv_mesh_from_arrays(&want, &v[0][0], 8, &t[0][0], 8));
    assert_same_triangles(path, m, want, 1e-6, 0);
    ck_assert_double_eq(m->unit_meters, 0); /* assimp 5.2 does not read 3MF's unit */
    hv_mesh_destroy(&want);
    hv_mesh_destroy(&m);
    remove_tmpdir();
}
END_TEST

START_TEST(points_and_lines_should_be_left_out_and_counted)
{
    make_tmpdir();
    const char *obj = tmp_path("lines.obj");
    FILE *f = fopen(obj, "w");
    ck_assert_ptr_nonnull(f);
    fputs("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
          "l 1 2\nl 2 3\np 4\n",
          f);
    fclose(f);
    const struct aiScene *sc = import_obj(obj);
    const char *glb = export_as(sc, &exporters[1], "lines");
    hv_mesh *m = read_ok(glb);
    ck_assert_uint_eq(m->ntris, 4);
    ck_assert_uint_eq(m->skipped_primitives, 3);
    hv_mesh_destroy(&m);
    aiReleaseImport(sc);

    f = fopen(obj, "w");
    ck_assert_ptr_nonnull(f);
    fputs("v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2\nl 2 3\n", f);
    fclose(f);
    sc = import_obj(obj);
    glb = export_as(sc, &exporters[1], "only_lines");
    ck_assert_int_eq(hv_mesh_read(glb, &m), HV_ERR_PARSE);
    ck_assert_ptr_null(m);
    char want[700];
    snprintf(want, sizeof want, "%s: no triangles (2 points and lines: not a surface)", glb);
    ck_assert_str_eq(hv_last_error(), want);
    aiReleaseImport(sc);
    remove_tmpdir();
}
END_TEST

/* The unit each format declares is reported and the coordinates are not
 * rescaled for it, except COLLADA's, which assimp applies to the root. */
START_TEST(units_should_be_reported_as_the_file_declares_them)
{
    make_tmpdir();
    hv_mesh *part = test_sphere(0, 1, 1);
    const char *obj = tmp_path("unit.obj");
    TL_ASSERT_OK(hv_mesh_write_obj(part, obj));
    hv_mesh *want = read_ok(obj);
    const struct aiScene *sc = import_obj(obj);
    const double units[NEXPORTERS] = {1, 1, 1, 0.01, 0, 0}; /* FBX: centimetres unless told */
    char path[NEXPORTERS][600];
    for (size_t k = 0; k < NEXPORTERS; k++) {
        snprintf(path[k], sizeof path[k], "%s", export_as(sc, &exporters[k], "unit"));
        hv_mesh *m = read_ok(path[k]);
        ck_assert_msg(m->unit_meters == units[k], "%s: unit %g m, want %g", path[k], m->unit_meters,
                      units[k]);
        hv_mesh_destroy(&m);
    }
    aiReleaseImport(sc);

    /* FBX in inches: reported, the coordinates as they are */
    const char *inch = tmp_path("inch.fbx");
    edit_copy(path[3], inch, "\"UnitScaleFactor\", \"double\", \"Number\", \"\", 1",
              "\"UnitScaleFactor\", \"double\", \"Number\", \"\", 2.54");
    hv_mesh *m = read_ok(inch);
    ck_assert_double_eq_tol(m->unit_meters, 0.0254, 1e-9);
    assert_same_triangles(inch, m, want, 0, 0);
    hv_mesh_destroy(&m);

    /* COLLADA in centimetres: assimp scales the scene to metres */
    const char *cm = tmp_path("cm.dae");
    edit_copy(path[2], cm, "meter=\"1\"", "meter=\"0.01\"");
    m = read_ok(cm);
    ck_assert_double_eq(m->unit_meters, 1);
    for (size_t i = 0; i < want->nverts; i++)
        for (int a = 0; a < 3; a++)
            want->verts[3 * i + a] *= (double)0.01f;
    assert_same_triangles(cm, m, want, 1e-7, 0);
    hv_mesh_destroy(&m);

    /* COLLADA z-up: the coordinates as the file has them, not turned y-up */
    const char *zup = tmp_path("zup.dae");
    edit_copy(path[2], zup, "<up_axis>Y_UP</up_axis>", "<up_axis>Z_UP</up_axis>");
    hv_mesh *y = read_ok(path[2]);
    m = read_ok(zup);
    assert_same_triangles(zup, m, y, 0, 0);
    hv_mesh_destroy(&m);
    hv_mesh_destroy(&y);
    hv_mesh_destroy(&want);
    hv_mesh_destroy(&part);
    remove_tmpdir();
}
END_TEST

static long printed_by_readers;

static void assert_fails(const char *path, hv_status want, const char *after_path)
{
    hv_mesh *m = (hv_mesh *)&m; /* set to NULL on failure */
    quiet q;
    quiet_begin(&q, tmp_path("out.txt"));
    hv_status st = hv_mesh_read(path, &m);
    printed_by_readers += quiet_end(&q);
    ck_assert_msg(st == want, "%s: %s, want %s (%s)", path, hv_status_str(st), hv_status_str(want),
                  hv_last_error());
    ck_assert_ptr_null(m);
    const char *e = hv_last_error();
    size_t n = strlen(path);
    ck_assert_msg(!strncmp(e, path, n) && e[n] == ':', "'%s' does not start with the file '%s'", e,
                  path);
    ck_assert_msg(strstr(e + n, after_path) != NULL, "'%s' does not say '%s'", e, after_path);
}

START_TEST(files_assimp_rejects_should_fail_naming_the_file)
{
    make_tmpdir();
    printed_by_readers = 0;
    unsigned char junk[4096];
    uint64_t s = 7;
    for (size_t i = 0; i < sizeof junk; i++)
        junk[i] = (unsigned char)(tl_rand(&s) * 256 + 128);
    for (size_t k = 0; k < NEXPORTERS; k++) {
        char name[64];
        snprintf(name, sizeof name, "junk%s", exporters[k].ext);
        const char *p = tmp_path(name);
        write_bytes(p, junk, sizeof junk);
        /* a .glb's container is checked ahead of assimp */
        assert_fails(p, HV_ERR_PARSE, strcmp(exporters[k].ext, ".glb") ? ": assimp: " : "glTF");
        snprintf(name, sizeof name, "empty%s", exporters[k].ext);
        p = tmp_path(name);
        write_bytes(p, "", 0);
        assert_fails(p, HV_ERR_PARSE, "empty file");
    }
    /* a GLB cut short, a glTF without its buffer, no meshes at all */
    hv_mesh *part = test_sphere(0, 1, 1);
    const char *obj = tmp_path("cut.obj");
    TL_ASSERT_OK(hv_mesh_write_obj(part, obj));
    const struct aiScene *sc = import_obj(obj);
    size_t len;
    char *glb = read_text(export_as(sc, &exporters[1], "cut"), &len);
    write_bytes(tmp_path("half.glb"), glb, len / 2);
    assert_fails(tmp_path("half.glb"), HV_ERR_PARSE, "binary glTF of");
    /* chunks longer than the file: refused before assimp allocates them */
    glb[12] = (char)0xff, glb[13] = (char)0xff, glb[14] = (char)0xff, glb[15] = 0x0f;
    write_bytes(tmp_path("long_json.glb"), glb, len);
    assert_fails(tmp_path("long_json.glb"), HV_ERR_PARSE, "the first chunk is not JSON");
    free(glb);
    /* junk JSON in a sound container reaches assimp, which says why */
    write_glb(tmp_path("bad_json.glb"), "{\"asset\": not json");
    assert_fails(tmp_path("bad_json.glb"), HV_ERR_PARSE, ": assimp: ");
    const char *gltf = export_as(sc, &exporters[0], "nobin");
    char bin[600];
    snprintf(bin, sizeof bin, "%.*s.bin", (int)(strlen(gltf) - 5), gltf);
    ck_assert_int_eq(unlink(bin), 0);
    assert_fails(gltf, HV_ERR_PARSE, ": assimp: ");
    aiReleaseImport(sc);
    hv_mesh_destroy(&part);
    const char *empty = tmp_path("nothing.gltf");
    const char *json = "{\"asset\":{\"version\":\"2.0\"},\"scene\":0,\"scenes\":[{\"nodes\":[]}]}";
    write_bytes(empty, json, strlen(json));
    assert_fails(empty, HV_ERR_PARSE, "no triangles");
    /* not there, a directory */
    assert_fails(tmp_path("missing.fbx"), HV_ERR_IO, "cannot open");
    ck_assert_int_eq(mkdir(tmp_path("dir.glb"), 0700), 0);
    assert_fails(tmp_path("dir.glb"), HV_ERR_IO, "directory");
    ck_assert_msg(printed_by_readers == 0, "the readers printed %ld bytes", printed_by_readers);
    remove_tmpdir();
}
END_TEST

typedef struct {
    const char *path;
    const char *data;
    size_t len;
} fifo_writer;

static void *write_fifo(void *arg)
{
    fifo_writer *w = arg;
    int fd = open(w->path, O_WRONLY);
    if (fd >= 0) {
        size_t done = 0;
        while (done < w->len) {
            ssize_t k = write(fd, w->data + done, w->len - done);
            if (k <= 0)
                break;
            done += (size_t)k;
        }
        close(fd);
    }
    return NULL;
}

/* A pipe (a shell's <(...)) is read whole, then handed to assimp from memory
 * with the format its name gives. */
START_TEST(a_pipe_should_be_read_like_the_file)
{
    make_tmpdir();
    hv_mesh *part = test_sphere(0, 1, 1);
    const char *obj = tmp_path("pipe.obj");
    TL_ASSERT_OK(hv_mesh_write_obj(part, obj));
    hv_mesh *want = read_ok(obj);
    const struct aiScene *sc = import_obj(obj);
    size_t len;
    char *glb = read_text(export_as(sc, &exporters[1], "pipe"), &len);
    aiReleaseImport(sc);
    const char *fifo = tmp_path("fifo.glb");
    ck_assert_int_eq(mkfifo(fifo, 0600), 0);
    fifo_writer w = {fifo, glb, len};
    pthread_t th;
    ck_assert_int_eq(pthread_create(&th, NULL, write_fifo, &w), 0);
    hv_mesh *m = read_ok(fifo);
    pthread_join(th, NULL);
    assert_same_triangles(fifo, m, want, 0, 0);
    hv_mesh_destroy(&m);
    hv_mesh_destroy(&want);
    hv_mesh_destroy(&part);
    free(glb);
    remove_tmpdir();
}
END_TEST

typedef struct {
    const char *good, *bad;
    size_t ntris;
    int failures;
} thread_case;

static void *read_many(void *arg)
{
    thread_case *c = arg;
    size_t n = strlen(c->bad);
    for (int i = 0; i < 25; i++) {
        hv_mesh *m = NULL;
        if (hv_mesh_read(c->good, &m) != HV_OK || m->ntris != c->ntris)
            c->failures++;
        hv_mesh_destroy(&m);
        const char *e = hv_mesh_read(c->bad, &m) == HV_ERR_PARSE ? hv_last_error() : "";
        if (strncmp(e, c->bad, n) || !strstr(e, ": assimp: "))
            c->failures++;
    }
    return NULL;
}

/* Readers on several threads at once each get their own result and message
 * (assimp keeps its last error in one global string). */
START_TEST(threads_reading_at_once_should_each_get_their_own_result)
{
    make_tmpdir();
    hv_mesh *part = test_sphere(0, 1, 1);
    const char *obj = tmp_path("threads.obj");
    TL_ASSERT_OK(hv_mesh_write_obj(part, obj));
    const struct aiScene *sc = import_obj(obj);
    char good[600], bad[4][600];
    snprintf(good, sizeof good, "%s", export_as(sc, &exporters[1], "threads"));
    aiReleaseImport(sc);
    thread_case c[4];
    pthread_t th[4];
    for (int k = 0; k < 4; k++) {
        char name[32];
        snprintf(name, sizeof name, "bad%d.glb", k);
        snprintf(bad[k], sizeof bad[k], "%s", tmp_path(name));
        write_glb(bad[k], "{\"asset\": {\"version\": \"2.0\"}, not json");
        c[k] = (thread_case){good, bad[k], part->ntris, 0};
        ck_assert_int_eq(pthread_create(&th[k], NULL, read_many, &c[k]), 0);
    }
    for (int k = 0; k < 4; k++) {
        pthread_join(th[k], NULL);
        ck_assert_msg(c[k].failures == 0, "thread %d: %d wrong results", k, c[k].failures);
    }
    hv_mesh_destroy(&part);
    remove_tmpdir();
}
END_TEST

/* Every scene is released: the heap holds as much after 20 more reads of
 * each format (and of a file assimp rejects) as after the first. The
 * LeakSanitizer suppressions cover libassimp as a whole (it leaks on some
 * failed reads, and names none of its functions), so this is what watches
 * heatvox's own aiReleaseImport. Under AddressSanitizer, whose allocator
 * glibc's mallinfo2 does not see, the sanitizer's own count is read. */
static size_t heap_in_use(void)
{
#if defined(__SANITIZE_ADDRESS__)
    return __sanitizer_get_current_allocated_bytes();
#else
    return mallinfo2().uordblks;
#endif
}

START_TEST(reading_should_release_every_scene)
{
    make_tmpdir();
    hv_mesh *part = test_sphere(0, 1, 1);
    const char *obj = tmp_path("release.obj");
    TL_ASSERT_OK(hv_mesh_write_obj(part, obj));
    const struct aiScene *sc = import_obj(obj);
    char path[NEXPORTERS + 1][600];
    for (size_t k = 0; k < NEXPORTERS; k++)
        snprintf(path[k], sizeof path[k], "%s", export_as(sc, &exporters[k], "release"));
    aiReleaseImport(sc);
    snprintf(path[NEXPORTERS], sizeof path[NEXPORTERS], "%s", tmp_path("junk.glb"));
    write_glb(path[NEXPORTERS], "{\"asset\": {\"version\": \"2.0\"}, not json");
    size_t before = 0;
    for (int round = 0; round < 21; round++) {
        if (round == 1)
            before = heap_in_use();
        for (size_t k = 0; k <= NEXPORTERS; k++) {
            hv_mesh *m = NULL;
            hv_status st = hv_mesh_read(path[k], &m);
            ck_assert_int_eq(st, k < NEXPORTERS ? HV_OK : HV_ERR_PARSE);
            hv_mesh_destroy(&m);
        }
    }
    size_t after = heap_in_use();
    ck_assert_msg(after <= before + 4096, "the heap grew from %zu to %zu bytes over 20 rounds",
                  before, after);
    hv_mesh_destroy(&part);
    remove_tmpdir();
}
END_TEST

/* `heatvox sdf` of a .glb and of the .obj it was made from: the same arrays,
 * so the same level set, voxel for voxel. */
START_TEST(sdf_of_a_glb_should_equal_that_of_the_obj_bit_for_bit)
{
    const char *bin = tl_heatvox_bin();
    ck_assert_msg(bin != NULL, "build/heatvox not found (set HEATVOX_BIN)");
    make_tmpdir();
    hv_mesh *a = test_sphere(0, 1, 2), *b = test_torus();
    const double shift[3] = {0.25, 1.5, 0.5}; /* stays on the grid */
    for (size_t i = 0; i < b->nverts; i++)
        for (int k = 0; k < 3; k++)
            b->verts[3 * i + k] += shift[k];
    hv_mesh *parts[2] = {a, b};
    const char *obj = tmp_path("scene.obj");
    write_objects(obj, parts, 2);
    const struct aiScene *sc = import_obj(obj);
    const char *glb = export_as(sc, &exporters[1], "scene");
    aiReleaseImport(sc);
    hv_mesh *mo = read_ok(obj), *mg = read_ok(glb);
    ck_assert_uint_eq(mo->nverts, mg->nverts);
    ck_assert_uint_eq(mo->ntris, mg->ntris);
    ck_assert_msg(!memcmp(mo->verts, mg->verts, mo->nverts * 3 * sizeof *mo->verts) &&
                      !memcmp(mo->tris, mg->tris, mo->ntris * 3 * sizeof *mo->tris),
                  "the .glb's arrays differ from the .obj's");
    hv_mesh_destroy(&mo);
    hv_mesh_destroy(&mg);
    char err[2048];
    int rc = tl_hv(tmpdir, bin, err, sizeof err, "sdf scene.obj -o obj.vdb --res 48 -q");
    ck_assert_msg(rc == 0, "sdf scene.obj: exit %d: %s", rc, err);
    rc = tl_hv(tmpdir, bin, err, sizeof err, "sdf scene_glb2.glb -o glb.vdb --res 48 -v");
    ck_assert_msg(rc == 0, "sdf scene_glb2.glb: exit %d: %s", rc, err);
    ck_assert_msg(strstr(err, "scene_glb2.glb: glTF 2.0 binary via assimp") &&
                      strstr(err, "length unit 1 m, from the file"),
                  "-v does not say the format and unit: %s", err);
    hv_grid *go = NULL, *gg = NULL;
    TL_ASSERT_OK(hv_vdb_read_float(tmp_path("obj.vdb"), "sdf", NULL, &go, NULL));
    TL_ASSERT_OK(hv_vdb_read_float(tmp_path("glb.vdb"), "sdf", NULL, &gg, NULL));
    ck_assert(go->n[0] == gg->n[0] && go->n[1] == gg->n[1] && go->n[2] == gg->n[2]);
    ck_assert(go->h == gg->h && !memcmp(go->origin, gg->origin, sizeof go->origin));
    size_t cells = (size_t)go->n[0] * (size_t)go->n[1] * (size_t)go->n[2];
    ck_assert_msg(!memcmp(go->v, gg->v, cells * sizeof *go->v), "the level sets differ (%zu cells)",
                  cells);
    char po[512], pg[512];
    TL_ASSERT_OK(hv_vdb_read_meta(tmp_path("obj.vdb"), NULL, "parameters", po, sizeof po));
    TL_ASSERT_OK(hv_vdb_read_meta(tmp_path("glb.vdb"), NULL, "parameters", pg, sizeof pg));
    ck_assert_str_eq(po, pg);
    hv_grid_destroy(&go);
    hv_grid_destroy(&gg);
    hv_mesh_destroy(&a);
    hv_mesh_destroy(&b);
    remove_tmpdir();
}
END_TEST

/* Runs `cd tmpdir && heatvox ARGS` with stdout (stderr merged) in out;
 * returns the exit code (-1: no exit). */
static int hv_capture(const char *bin, char *out, size_t size, const char *args)
{
    char cmd[4096];
    snprintf(cmd, sizeof cmd, "cd '%s' && '%s' %s 2>&1", tmpdir, bin, args);
    FILE *p = popen(cmd, "r");
    ck_assert_ptr_nonnull(p);
    size_t n = fread(out, 1, size - 1, p);
    out[n] = '\0';
    int rc = pclose(p);
    return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

/* The command takes these files wherever it takes a mesh by its extension:
 * info (with the points and lines left out and the unit), batch's directory
 * scan, and distance's sources, which say with -v what the reader made. */
START_TEST(the_command_should_take_these_formats_wherever_it_takes_a_mesh)
{
    const char *bin = tl_heatvox_bin();
    ck_assert_msg(bin != NULL, "build/heatvox not found (set HEATVOX_BIN)");
    make_tmpdir();
    char obj[600]; /* kept: tmp_path's strings are reused */
    snprintf(obj, sizeof obj, "%s", tmp_path("lines.obj"));
    FILE *f = fopen(obj, "w");
    ck_assert_ptr_nonnull(f);
    fputs("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
          "l 1 2\nl 2 3\np 4\n",
          f);
    fclose(f);
    const struct aiScene *sc = import_obj(obj);
    ck_assert_int_eq(mkdir(tmp_path("in"), 0700), 0);
    for (size_t k = 0; k < NEXPORTERS; k++)
        export_as(sc, &exporters[k], "in/tet");
    aiReleaseImport(sc);
    ck_assert_int_eq(unlink(obj), 0);
    write_bytes(tmp_path("in/notes.md"), "not a mesh\n", 11);

    char out[8192];
    int rc = hv_capture(bin, out, sizeof out, "info --json in/tet_glb2.glb");
    ck_assert_msg(rc == 0, "info --json: exit %d: %s", rc, out);
    ck_assert_msg(strstr(out, "\"format\":\"glTF 2.0 binary via assimp\"") &&
                      strstr(out, "\"triangles\":4,") &&
                      strstr(out, "\"skipped_primitives\":3,\"unit_meters\":1,"),
                  "info --json: %s", out);
    rc = hv_capture(bin, out, sizeof out, "info in/tet_fbxa.fbx in/tet_x.x");
    ck_assert_msg(rc == 0, "info: exit %d: %s", rc, out);
    const char *x = strstr(out, "tet_x.x");
    ck_assert_msg(x && strstr(out, "length unit         0.01 m, from the file") < x &&
                      strstr(x, "length unit         none in the file") &&
                      !strstr(strstr(x, "length unit") + 1, "length unit"),
                  "info: the FBX's unit, none for the X file: %s", out);

    rc = hv_capture(bin, out, sizeof out, "batch in -o out --dry-run");
    ck_assert_msg(rc == 0, "batch --dry-run: exit %d: %s", rc, out);
    for (size_t k = 0; k < NEXPORTERS; k++) {
        char want[128];
        snprintf(want, sizeof want, "in/tet_%s%s -> ", exporters[k].id, exporters[k].ext);
        ck_assert_msg(strstr(out, want), "batch --dry-run does not list %s: %s", want, out);
    }
    ck_assert_msg(strstr(out, "6 to run") && !strstr(out, ".bin") && !strstr(out, "notes.md"),
                  "batch --dry-run: %s", out);

    rc = hv_capture(bin, out, sizeof out,
                    "distance --sources in/tet_gltf2.gltf -o d.vdb --res 16 -v");
    ck_assert_msg(rc == 0, "distance: exit %d: %s", rc, out);
    ck_assert_msg(strstr(out, "in/tet_gltf2.gltf: glTF 2.0 via assimp, 4 triangles on 4 vertices, "
                              "3 points and lines left out; length unit 1 m, from the file"),
                  "distance -v: %s", out);
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_vdb_read_float(tmp_path("d.vdb"), "distance", NULL, &g, NULL));
    hv_grid_destroy(&g);
    remove_tmpdir();
}
END_TEST

/* ---- the assimp test models ---- */

static struct {
    int files, loaded, failed, bad;
    char first_bad[1024];
} corpus;

static int corpus_file(const char *path, const struct stat *sb, int type, struct FTW *ftw)
{
    if (type != FTW_F || !hv_mesh_format_by_extension(path))
        return 0;
    corpus.files++;
    hv_mesh *m = NULL;
    hv_status st = hv_mesh_read(path, &m);
    const char *e = hv_last_error();
    size_t n = strlen(path);
    if (st == HV_OK && m && m->ntris > 0)
        corpus.loaded++;
    else if (st != HV_OK && !m && !strncmp(e, path, n) && e[n] == ':' && e[n + 1])
        corpus.failed++;
    else if (!corpus.bad++)
        snprintf(corpus.first_bad, sizeof corpus.first_bad, "%s: %s: '%s'", path, hv_status_str(st),
                 e);
    hv_mesh_destroy(&m);
    return 0;
}

/* Every file of Debian's assimp-testmodels in a format hv_mesh_read knows
 * loads, or fails with a message naming it; none crashes, none prints. */
START_TEST(the_assimp_test_models_should_load_or_fail_naming_the_file)
{
    const char *dir = getenv("HEATVOX_ASSIMP_MODELS");
    if (!dir || !*dir)
        dir = "/usr/share/assimp/models";
    struct stat sb;
    if (stat(dir, &sb) != 0 || !S_ISDIR(sb.st_mode))
        TL_SKIP("no assimp test models in %s (Debian package assimp-testmodels)", dir);
    make_tmpdir();
    memset(&corpus, 0, sizeof corpus);
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    quiet q;
    quiet_begin(&q, tmp_path("out.txt"));
    int rc = nftw(dir, corpus_file, 16, FTW_PHYS);
    long printed = quiet_end(&q);
    clock_gettime(CLOCK_MONOTONIC, &t1);
    double secs = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
    printf("assimp test models: %d files in formats heatvox reads, %d loaded, %d failed naming "
           "the file, %.2f s\n",
           corpus.files, corpus.loaded, corpus.failed, secs);
    fflush(stdout);
    ck_assert_int_eq(rc, 0);
    ck_assert_msg(corpus.bad == 0, "%d files neither loaded nor failed cleanly; the first: %s",
                  corpus.bad, corpus.first_bad);
    ck_assert_msg(printed == 0, "reading them printed %ld bytes", printed);
    ck_assert_int_gt(corpus.loaded, 0);
    remove_tmpdir();
}
END_TEST

static Suite *mesh_assimp_suite(void)
{
    Suite *s = suite_create("mesh_assimp");
    TCase *tc = tcase_create("formats");
    tcase_set_timeout(tc, 300);
    tcase_add_test(tc, extensions_should_pick_the_hand_written_readers_or_assimp);
    tcase_add_test(tc, every_format_should_read_the_same_triangles_as_the_obj);
    tcase_add_test(tc, a_node_hierarchy_should_be_flattened_with_its_transforms);
    tcase_add_test(tc, a_mirroring_transform_should_keep_the_faces_outward);
    tcase_add_test(tc, a_3mf_build_should_place_each_item_with_its_transform);
    tcase_add_test(tc, points_and_lines_should_be_left_out_and_counted);
    tcase_add_test(tc, units_should_be_reported_as_the_file_declares_them);
    tcase_add_test(tc, files_assimp_rejects_should_fail_naming_the_file);
    tcase_add_test(tc, a_pipe_should_be_read_like_the_file);
    tcase_add_test(tc, threads_reading_at_once_should_each_get_their_own_result);
    tcase_add_test(tc, reading_should_release_every_scene);
    tcase_add_test(tc, sdf_of_a_glb_should_equal_that_of_the_obj_bit_for_bit);
    tcase_add_test(tc, the_command_should_take_these_formats_wherever_it_takes_a_mesh);
    tcase_add_test(tc, the_assimp_test_models_should_load_or_fail_naming_the_file);
    suite_add_tcase(s, tc);
    return s;
}

int main(void) { return tl_run(mesh_assimp_suite()); }
