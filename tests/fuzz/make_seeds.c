/* Writes small seed inputs for the fuzz targets into DIR/<target>/ (one
 * directory per target, created if missing): hand-built meshes in every
 * format and encoding, curve files, scenes in the formats read through
 * assimp (written by its exporters), and .npy, .exr and .vdb files written by
 * the library itself. `make fuzz` adds the output of `heatvox make-scenes` and
 * the repository's scenes/curves files. Seeds stay small (a few KB) so that
 * the fuzzer's mutations stay cheap. Usage: make_seeds DIR */
#include "fuzz_assimp.h"
#include "heatvox/heatvox.h"

#include <assimp/cexport.h>
#include <assimp/cimport.h>
#include <assimp/scene.h>
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

static const char *root;
static int failures;

static void put(const char *target, const char *name, const void *data, size_t len)
{
    char path[1024];
    snprintf(path, sizeof path, "%s/%s", root, target);
    if (mkdir(path, 0777) != 0 && errno != EEXIST) {
        fprintf(stderr, "make_seeds: %s: %s\n", path, strerror(errno));
        failures++;
        return;
    }
    snprintf(path, sizeof path, "%s/%s/%s", root, target, name);
    FILE *f = fopen(path, "wb");
    if (!f || fwrite(data, 1, len, f) != len || fclose(f) != 0) {
        fprintf(stderr, "make_seeds: %s: cannot write\n", path);
        failures++;
    }
}

static void put_str(const char *target, const char *name, const char *text)
{
    put(target, name, text, strlen(text));
}

/* Grows a byte buffer with printf text or raw bytes. */
typedef struct buf {
    char *p;
    size_t n, cap;
} buf;

static void b_raw(buf *b, const void *d, size_t len)
{
    if (b->n + len + 1 > b->cap) {
        b->cap = 2 * (b->n + len + 1);
        b->p = realloc(b->p, b->cap);
        if (!b->p)
            abort();
    }
    memcpy(b->p + b->n, d, len);
    b->n += len;
}

static void b_printf(buf *b, const char *fmt, ...)
{
    char tmp[512];
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(tmp, sizeof tmp, fmt, ap);
    va_end(ap);
    b_raw(b, tmp, (size_t)n);
}

static void b_num(buf *b, const void *v, size_t size, int big_endian)
{
    unsigned char t[8];
    memcpy(t, v, size);
    if (big_endian)
        for (size_t k = 0; k < size / 2; k++) {
            unsigned char x = t[k];
            t[k] = t[size - 1 - k];
            t[size - 1 - k] = x;
        }
    b_raw(b, t, size);
}

/* ---- meshes: the unit cube, outward quads ---- */

static const double cube_v[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                    {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
static const int cube_q[6][4] = {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 1, 5, 4},
                                 {1, 2, 6, 5}, {2, 3, 7, 6}, {3, 0, 4, 7}};

static void seeds_obj(void)
{
    buf b = {0};
    b_printf(&b, "# cube\nmtllib x.mtl\no cube\n");
    for (int i = 0; i < 8; i++)
        b_printf(&b, "v %g %g %g\n", cube_v[i][0], cube_v[i][1], cube_v[i][2]);
    b_printf(&b, "vt 0 0\nvn 0 0 1\ng side\ns 1\nusemtl m\n");
    for (int f = 0; f < 6; f++)
        b_printf(&b, "f %d/1/1 %d//1 %d/1 %d\n", cube_q[f][0] + 1, cube_q[f][1] + 1,
                 cube_q[f][2] + 1, cube_q[f][3] + 1);
    put("obj", "cube_quads.obj", b.p, b.n);
    b.n = 0;
    /* relative indices, triangles, CRLF, a face before its vertices */
    b_printf(&b, "\xEF\xBB\xBF"
                 "f 1 2 3\r\n");
    for (int i = 0; i < 8; i++)
        b_printf(&b, "v %.17g %.17g %.17g 1.0\r\n", cube_v[i][0], cube_v[i][1], cube_v[i][2]);
    for (int f = 0; f < 6; f++)
        b_printf(&b, "f %d %d %d\r\nfo %d %d %d\r\n", cube_q[f][0] - 8, cube_q[f][1] - 8,
                 cube_q[f][2] - 8, cube_q[f][0] - 8, cube_q[f][2] - 8, cube_q[f][3] - 8);
    put("obj", "cube_relative_crlf.obj", b.p, b.n);
    free(b.p);
    put_str("obj", "nonfinite.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv nan 0 0\nv 0 inf 0\nv 0 0 -1e308\nf 1 2 3\nf 1 4 5\n"
            "f 6 2 3\nl 1 2\np 3\n");
}

static void seeds_ply(void)
{
    const char *names[3] = {"ascii", "binary_little_endian", "binary_big_endian"};
    for (int fmt = 0; fmt < 3; fmt++) {
        buf b = {0};
        b_printf(&b,
                 "ply\nformat %s 1.0\ncomment seed\nelement vertex 8\nproperty float x\n"
                 "property float y\nproperty float z\nproperty uchar red\n"
                 "element face 6\nproperty list uchar int vertex_indices\n"
                 "property int flags\nelement extra 1\nproperty list ushort double data\n"
                 "end_header\n",
                 names[fmt]);
        for (int i = 0; i < 8; i++) {
            if (fmt == 0) {
                b_printf(&b, "%g %g %g 255\n", cube_v[i][0], cube_v[i][1], cube_v[i][2]);
                continue;
            }
            for (int a = 0; a < 3; a++) {
                float x = (float)cube_v[i][a];
                b_num(&b, &x, 4, fmt == 2);
            }
            unsigned char red = 255;
            b_raw(&b, &red, 1);
        }
        for (int f = 0; f < 6; f++) {
            if (fmt == 0) {
                b_printf(&b, "4 %d %d %d %d 0\n", cube_q[f][0], cube_q[f][1], cube_q[f][2],
                         cube_q[f][3]);
                continue;
            }
            unsigned char k = 4;
            b_raw(&b, &k, 1);
            for (int c = 0; c < 4; c++) {
                int32_t v = cube_q[f][c];
                b_num(&b, &v, 4, fmt == 2);
            }
            int32_t flags = 0;
            b_num(&b, &flags, 4, fmt == 2);
        }
        if (fmt == 0)
            b_printf(&b, "2 0.5 1.5\n");
        else {
            uint16_t n = 2;
            double d[2] = {0.5, 1.5};
            b_num(&b, &n, 2, fmt == 2);
            b_num(&b, &d[0], 8, fmt == 2);
            b_num(&b, &d[1], 8, fmt == 2);
        }
        char name[64];
        snprintf(name, sizeof name, "cube_%s.ply", names[fmt]);
        put("ply", name, b.p, b.n);
        free(b.p);
    }
    put_str("ply", "tristrips.ply",
            "ply\nformat ascii 1.0\nelement vertex 6\nproperty double x\nproperty double y\n"
            "property double z\nelement tristrips 1\nproperty list int int vertex_indices\n"
            "end_header\n0 0 0\n0 1 0\n1 0 0\n1 1 0\n2 0 0\n2 1 0\n9 0 1 2 3 -1 2 3 4 5\n");
}

static void seeds_stl(void)
{
    buf a = {0}, b = {0};
    char head[80] = "binary cube";
    b_raw(&b, head, 80);
    uint32_t n = 12;
    b_num(&b, &n, 4, 0);
    b_printf(&a, "solid cube\n");
    for (int f = 0; f < 6; f++)
        for (int t = 0; t < 2; t++) {
            const int c[3] = {cube_q[f][0], cube_q[f][t + 1], cube_q[f][t + 2]};
            b_printf(&a, "  facet normal 0 0 0\n    outer loop\n");
            float zero[3] = {0, 0, 0};
            b_raw(&b, zero, 12);
            for (int k = 0; k < 3; k++) {
                b_printf(&a, "      vertex %g %g %g\n", cube_v[c[k]][0], cube_v[c[k]][1],
                         cube_v[c[k]][2]);
                for (int d = 0; d < 3; d++) {
                    float x = (float)cube_v[c[k]][d];
                    b_num(&b, &x, 4, 0);
                }
            }
            uint16_t attr = 0;
            b_raw(&b, &attr, 2);
            b_printf(&a, "    endloop\n  endfacet\n");
        }
    b_printf(&a, "endsolid cube\n");
    put("stl", "cube_ascii.stl", a.p, a.n);
    put("stl", "cube_binary.stl", b.p, b.n);
    free(a.p);
    free(b.p);
    put_str("stl", "quad_facet.stl",
            "solid q\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 1 1 0\n"
            "vertex 0 1 0\nendloop\nendfacet\nendsolid q\nsolid r\nendsolid\n");
}

static void seeds_off(void)
{
    buf b = {0};
    b_printf(&b, "OFF\n# cube\n8 6 12\n");
    for (int i = 0; i < 8; i++)
        b_printf(&b, "%g %g %g\n", cube_v[i][0], cube_v[i][1], cube_v[i][2]);
    for (int f = 0; f < 6; f++)
        b_printf(&b, "4 %d %d %d %d\n", cube_q[f][0], cube_q[f][1], cube_q[f][2], cube_q[f][3]);
    put("off", "cube.off", b.p, b.n);
    b.n = 0;
    b_printf(&b, "COFF 8 12 0\n");
    for (int i = 0; i < 8; i++)
        b_printf(&b, "%g %g %g 255 0 0 255 # colour\n", cube_v[i][0], cube_v[i][1], cube_v[i][2]);
    for (int f = 0; f < 6; f++)
        b_printf(&b, "3 %d %d %d 1 2 3\n3 %d %d %d\n", cube_q[f][0], cube_q[f][1], cube_q[f][2],
                 cube_q[f][0], cube_q[f][2], cube_q[f][3]);
    put("off", "cube_coff.off", b.p, b.n);
    free(b.p);
}

/* Oriented points: text with comments and extra columns, and PLY point
 * clouds in each encoding (the points target names every file .xyz; the
 * reader takes PLY by content). */
static void seeds_points(void)
{
    put_str("points", "text",
            "# x y z nx ny nz\n0 0 0 1 0 0\r\n1 0 0 0 1 0 0.5 0.5\n"
            "0 1 0 0 0 -1  # end\n\n1 1 1 1e-3 2 3\n");
    put_str("points", "unoriented", "0 0 0\n1 2 3\n");
    const char *names[3] = {"ascii", "binary_little_endian", "binary_big_endian"};
    for (int fmt = 0; fmt < 3; fmt++) {
        buf b = {0};
        b_printf(&b,
                 "ply\nformat %s 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                 "property float z\nproperty uchar red\nproperty double nx\nproperty double ny\n"
                 "property double nz\nend_header\n",
                 names[fmt]);
        for (int i = 0; i < 4; i++) {
            const float x[3] = {(float)(i & 1), (float)(i >> 1), 0.5f};
            const double n[3] = {i & 1 ? 1.0 : -1.0, 0.0, i > 1 ? 1.0 : 0.0};
            const unsigned char red = (unsigned char)(60 * i);
            if (fmt == 0) {
                b_printf(&b, "%g %g %g %u %g %g %g\n", x[0], x[1], x[2], red, n[0], n[1], n[2]);
                continue;
            }
            for (int a = 0; a < 3; a++)
                b_num(&b, &x[a], 4, fmt == 2);
            b_raw(&b, &red, 1);
            for (int a = 0; a < 3; a++)
                b_num(&b, &n[a], 8, fmt == 2);
        }
        char name[64];
        snprintf(name, sizeof name, "ply_%s", names[fmt]);
        put("points", name, b.p, b.n);
        free(b.p);
    }
}

static void seeds_curves(void)
{
    put_str("curves", "square.txt", "# a square\nM 0 0\nL 1 0\nL 1 1\nL 0 1\nZ\n");
    put_str("curves", "polylines.txt",
            "0,0 1,0 1,1\n2 2 3 3 4 2.5e0 -1e-3 .5\n\nM -1 -1 # start\nL -2 -1\n");
    put_str("svg", "commands.svg",
            "<?xml version=\"1.0\"?>\n<!-- all path commands -->\n"
            "<svg xmlns=\"http://www.w3.org/2000/svg\" viewBox=\"0 0 100 100\">\n"
            "<path d=\"M10 10 H 90 V 90 H 10 Z m 5 5 l 10 0 l 0 10 z\"/>\n"
            "<path d='M 20,20 C 30,10 40,10 50,20 S 70,30 80,20 Q 60,60 40,40 T 20,20 "
            "c 1 1 2 2 3 3 s 1 1 2 2 q 1 1 2 2 t 1 1 h 5 v 5 L 1.5.5 10-5'/>\n"
            "<polygon points=\"0,0 10,0 10,10\" /><polyline points='1 1 2 2 3 1'/>\n"
            "<g transform=\"scale(2)\"><path d=\"M0 0 L 5 5\"></path></g>\n</svg>\n");
}

/* ---- scenes for the formats read through assimp, written by its exporters ---- */

static char *slurp(const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    if (!f)
        return NULL;
    buf b = {0};
    char chunk[4096];
    size_t n;
    while ((n = fread(chunk, 1, sizeof chunk, f)) > 0)
        b_raw(&b, chunk, n);
    fclose(f);
    *len = b.n;
    return b.p;
}

/* A .gltf with its buffer in a data: URI, so that the one file is the input. */
static char *gltf_embedded(const char *gltf, const char *bin, size_t *len)
{
    size_t glen, blen;
    char *g = slurp(gltf, &glen), *d = slurp(bin, &blen);
    char *uri = g ? strstr(g, "\"uri\"") : NULL;
    char *q1 = uri ? strchr(uri + 5, '"') : NULL, *q2 = q1 ? strchr(q1 + 1, '"') : NULL;
    if (!d || !q2) {
        free(g);
        free(d);
        return NULL;
    }
    static const char b64[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    buf b = {0};
    b_raw(&b, g, (size_t)(q1 + 1 - g));
    b_printf(&b, "data:application/octet-stream;base64,");
    for (size_t i = 0; i < blen; i += 3) {
        unsigned v = (unsigned char)d[i] << 16;
        if (i + 1 < blen)
            v |= (unsigned char)d[i + 1] << 8;
        if (i + 2 < blen)
            v |= (unsigned char)d[i + 2];
        char out[4] = {b64[v >> 18 & 63], b64[v >> 12 & 63], i + 1 < blen ? b64[v >> 6 & 63] : '=',
                       i + 2 < blen ? b64[v & 63] : '='};
        b_raw(&b, out, 4);
    }
    b_raw(&b, q2, glen - (size_t)(q2 - g));
    free(g);
    free(d);
    *len = b.n;
    return b.p;
}

/* Two objects under the root, a tetrahedron and a cube of quads, one turned
 * and scaled, the other mirrored, with a line and a point; one file per
 * exporter, each prefixed with the byte that picks its extension. */
static void seeds_assimp(void)
{
    static const struct {
        const char *id, *ext;
    } ex[] = {{"gltf2", ".gltf"}, {"glb2", ".glb"},    {"fbxa", ".fbx"}, {"fbx", ".fbx"},
              {"3mf", ".3mf"},    {"collada", ".dae"}, {"x", ".x"}};
    char dir[1024], obj[1100], out[1100], bin[1100];
    snprintf(dir, sizeof dir, "%s/assimp-tmp", root);
    mkdir(dir, 0777);
    snprintf(obj, sizeof obj, "%s/scene.obj", dir);
    buf b = {0};
    b_printf(&b, "o tetra\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n"
                 "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\nl 1 2\np 3\no cube\n");
    for (int i = 0; i < 8; i++)
        b_printf(&b, "v %g %g %g\n", cube_v[i][0] + 2, cube_v[i][1], cube_v[i][2]);
    for (int f = 0; f < 6; f++)
        b_printf(&b, "f %d %d %d %d\n", cube_q[f][0] + 5, cube_q[f][1] + 5, cube_q[f][2] + 5,
                 cube_q[f][3] + 5);
    FILE *fo = fopen(obj, "wb");
    if (!fo || fwrite(b.p, 1, b.n, fo) != b.n || fclose(fo) != 0) {
        fprintf(stderr, "make_seeds: %s: cannot write\n", obj);
        failures++;
        free(b.p);
        return;
    }
    free(b.p);
    const struct aiScene *sc = aiImportFile(obj, 0);
    if (!sc || !sc->mRootNode || sc->mRootNode->mNumChildren != 2) {
        fprintf(stderr, "make_seeds: assimp: %s: %s\n", obj, aiGetErrorString());
        failures++;
        if (sc)
            aiReleaseImport(sc);
        return;
    }
    const struct aiMatrix4x4 turn = {0, -2, 0, 1, 2, 0, 0, 0, 0, 0, 0.5f, -1, 0, 0, 0, 1};
    const struct aiMatrix4x4 mirror = {-1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    sc->mRootNode->mChildren[0]->mTransformation = mirror;
    sc->mRootNode->mChildren[1]->mTransformation = turn;
    for (size_t k = 0; k < sizeof ex / sizeof ex[0]; k++) {
        snprintf(out, sizeof out, "%s/scene_%s%s", dir, ex[k].id, ex[k].ext);
        if (aiExportScene(sc, ex[k].id, out, 0) != aiReturn_SUCCESS) {
            fprintf(stderr, "make_seeds: assimp export %s: %s\n", ex[k].id, aiGetErrorString());
            failures++;
            continue;
        }
        size_t len = 0;
        char *data;
        if (!strcmp(ex[k].ext, ".gltf")) {
            snprintf(bin, sizeof bin, "%s/scene_%s.bin", dir, ex[k].id);
            data = gltf_embedded(out, bin, &len);
            remove(bin);
        } else {
            data = slurp(out, &len);
        }
        remove(out);
        uint8_t sel = 0;
        while (sel < FZ_ASSIMP_NEXT && strcmp(fz_assimp_exts[sel], ex[k].ext))
            sel++;
        if (!data || sel == FZ_ASSIMP_NEXT) {
            fprintf(stderr, "make_seeds: %s: cannot read it back\n", out);
            failures++;
            free(data);
            continue;
        }
        buf s = {0};
        b_raw(&s, &sel, 1);
        b_raw(&s, data, len);
        char name[64];
        snprintf(name, sizeof name, "scene_%s%s", ex[k].id, ex[k].ext);
        put("assimp", name, s.p, s.n);
        free(s.p);
        free(data);
    }
    aiReleaseImport(sc);
    remove(obj);
    remove(dir);
}

/* ---- files the library writes ---- */

static void check(hv_status st, const char *what)
{
    if (st) {
        fprintf(stderr, "make_seeds: %s: %s\n", what, hv_last_error());
        failures++;
    }
}

static hv_grid *ramp(int dim, int nx, int ny, int nz)
{
    hv_grid *g = NULL;
    const int n[3] = {nx, ny, nz};
    const double o[3] = {-0.5, 0.25, 1};
    if (hv_grid_create(&g, dim, n, 0.5, o))
        return NULL;
    for (size_t i = 0; i < hv_grid_count(g); i++)
        g->v[i] = (float)i * 0.25f - 1.0f;
    return g;
}

static void seeds_written(void)
{
    char path[1024];
    hv_grid *g2 = ramp(2, 5, 3, 1), *g3 = ramp(3, 4, 3, 2);
    if (!g2 || !g3) {
        fprintf(stderr, "make_seeds: cannot create grids\n");
        failures++;
        return;
    }
    char dir[1024];
    for (int k = 0; k < 3; k++) {
        const char *t = k == 0 ? "npy" : k == 1 ? "exr" : "vdb";
        snprintf(dir, sizeof dir, "%s/%s", root, t);
        mkdir(dir, 0777);
    }
    snprintf(path, sizeof path, "%s/npy/ramp2d.npy", root);
    check(hv_write_npy(path, g2), path);
    snprintf(path, sizeof path, "%s/npy/ramp3d.npy", root);
    check(hv_write_npy(path, g3), path);
    /* float64, format 2.0, by hand */
    buf b = {0};
    const char *dict = "{'descr': '<f8', 'fortran_order': False, 'shape': (2, 3), }";
    size_t hlen = (12 + strlen(dict) + 1 + 63) / 64 * 64 - 12;
    b_raw(&b, "\x93NUMPY\x02\x00", 8);
    uint32_t hl = (uint32_t)hlen;
    b_num(&b, &hl, 4, 0);
    b_raw(&b, dict, strlen(dict));
    for (size_t i = strlen(dict); i + 1 < hlen; i++)
        b_raw(&b, " ", 1);
    b_raw(&b, "\n", 1);
    for (int i = 0; i < 6; i++) {
        double d = i - 2.5;
        b_num(&b, &d, 8, 0);
    }
    put("npy", "f8_v2.npy", b.p, b.n);
    free(b.p);

    snprintf(path, sizeof path, "%s/exr/ramp2d.exr", root);
    check(hv_exr_write(path, g2, NULL), path);
    snprintf(path, sizeof path, "%s/exr/ramp3d_parts.exr", root);
    check(hv_exr_write(path, g3, "phi"), path);

    hv_vdb_writer *w = NULL;
    hv_grid *ls = ramp(3, 6, 5, 4), *m = ramp(3, 3, 3, 3);
    if (ls && m && !hv_grid_add_mask(m)) {
        m->solid[0] = m->solid[13] = 1;
        check(hv_vdb_writer_create(&w), "vdb writer");
        check(hv_vdb_writer_add_levelset(w, ls, "sdf", 3, 0), "levelset");
        check(hv_vdb_writer_add_float(w, g3, "density"), "float");
        check(hv_vdb_writer_add_vec3(w, g3, g3, g3, "v"), "vec3");
        check(hv_vdb_writer_add_mask(w, m, "solid"), "mask");
        check(hv_vdb_writer_set_meta(w, "source", "make_seeds"), "meta");
        snprintf(path, sizeof path, "%s/vdb/grids.vdb", root);
        check(hv_vdb_writer_write(w, path), path);
        hv_vdb_writer_destroy(&w);
        check(hv_vdb_writer_create(&w), "vdb writer");
        check(hv_vdb_writer_add_levelset(w, ls, "dense", 2, 1), "levelset");
        snprintf(path, sizeof path, "%s/vdb/dense_levelset.vdb", root);
        check(hv_vdb_writer_write(w, path), path);
        hv_vdb_writer_destroy(&w);
    } else {
        failures++;
    }
    hv_grid_destroy(&ls);
    hv_grid_destroy(&m);
    hv_grid_destroy(&g2);
    hv_grid_destroy(&g3);
}

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: make_seeds DIR\n");
        return 2;
    }
    root = argv[1];
    if (mkdir(root, 0777) != 0 && errno != EEXIST) {
        fprintf(stderr, "make_seeds: %s: %s\n", root, strerror(errno));
        return 1;
    }
    seeds_obj();
    seeds_ply();
    seeds_stl();
    seeds_off();
    seeds_curves();
    seeds_points();
    seeds_assimp();
    seeds_written();
    return failures ? 1 : 0;
}
