/* Meshes out: the OBJ/PLY/STL writers (round trips, an independent NumPy
 * reader, failures that leave nothing), the zero level set extraction
 * (hv_grid_to_mesh: closed, manifold, outward; within a voxel of the input
 * surface; volume; capped at the walls; exact zeros and noise; errors), the
 * shared broken meshes, and the command line (sdf --mesh-out, info, batch
 * --mesh-out-format with resume). */
#include "heatvox/heatvox.h"
#include "testlib.h"

#include <check.h>
#include <dirent.h>
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

/* ---- files ---- */

static char tmpdir[256];

static void make_tmpdir(void)
{
    snprintf(tmpdir, sizeof tmpdir, "/tmp/hv_check_mesh_out_XXXXXX");
    ck_assert_ptr_nonnull(mkdtemp(tmpdir));
}

static const char *tmp_path(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
static const char *tmp_path(const char *fmt, ...)
{
    static char buf[8][700];
    static int which;
    which = (which + 1) % 8;
    char rel[400];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(rel, sizeof rel, fmt, ap);
    va_end(ap);
    snprintf(buf[which], sizeof buf[which], "%s/%s", tmpdir, rel);
    return buf[which];
}

/* Entries of a directory, "." and ".." left out. */
static int count_entries(const char *d)
{
    DIR *dd = opendir(d);
    ck_assert_ptr_nonnull(dd);
    struct dirent *e;
    int n = 0;
    while ((e = readdir(dd)))
        n += strcmp(e->d_name, ".") && strcmp(e->d_name, "..");
    closedir(dd);
    return n;
}

static int exists(const char *p)
{
    struct stat sb;
    return stat(p, &sb) == 0;
}

/* Runs a shell command; its stdout (up to size - 1 bytes) in out, stderr
 * merged into it. Returns the exit code (-1: no exit). */
static int run_capture(const char *cmd, char *out, size_t size)
{
    char full[4200];
    snprintf(full, sizeof full, "%s 2>&1", cmd);
    FILE *p = popen(full, "r");
    ck_assert_ptr_nonnull(p);
    size_t n = fread(out, 1, size - 1, p);
    out[n] = '\0';
    int rc = pclose(p);
    return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

/* ---- mesh checks ---- */

static hv_mesh_report report_of(const hv_mesh *m)
{
    hv_mesh_report r;
    TL_ASSERT_OK(hv_mesh_report_compute(m, &r));
    return r;
}

/* Closed (no boundary edge), manifold, consistently oriented, outward. */
static void assert_watertight(const hv_mesh *m, const char *what)
{
    hv_mesh_report r = report_of(m);
    ck_assert_msg(r.boundary_edges == 0 && r.nonmanifold_edges == 0 && r.inconsistent_edges == 0,
                  "%s: %zu boundary, %zu non-manifold, %zu inconsistent edges", what,
                  r.boundary_edges, r.nonmanifold_edges, r.inconsistent_edges);
    ck_assert_msg(r.signed_volume > 0, "%s: signed volume %g", what, r.signed_volume);
    ck_assert_msg(r.nonfinite_vertices == 0, "%s: %zu non-finite vertices", what,
                  r.nonfinite_vertices);
}

/* Volume the grid puts inside: cells below 0 times h^3. */
static double inside_volume(const hv_grid *g)
{
    size_t n = hv_grid_count(g), in = 0;
    for (size_t i = 0; i < n; i++)
        in += g->v[i] < 0;
    return (double)in * g->h * g->h * g->h;
}

/* ---- distance to a triangle mesh: a uniform grid of buckets ---- */

static void closest_on_triangle(const double p[3], const double a[3], const double b[3],
                                const double c[3], double q[3])
{
    /* Ericson, Real-Time Collision Detection, 5.1.5 */
    double ab[3], ac[3], ap[3], bp[3], cp[3];
    for (int k = 0; k < 3; k++) {
        ab[k] = b[k] - a[k];
        ac[k] = c[k] - a[k];
        ap[k] = p[k] - a[k];
        bp[k] = p[k] - b[k];
        cp[k] = p[k] - c[k];
    }
#define DOT(u, v) ((u)[0] * (v)[0] + (u)[1] * (v)[1] + (u)[2] * (v)[2])
    double d1 = DOT(ab, ap), d2 = DOT(ac, ap), d3 = DOT(ab, bp), d4 = DOT(ac, bp);
    double d5 = DOT(ab, cp), d6 = DOT(ac, cp);
#undef DOT
    double s = 0, t = 0;
    if (d1 <= 0 && d2 <= 0) {
        s = t = 0;
    } else if (d3 >= 0 && d4 <= d3) {
        s = 1, t = 0;
    } else if (d6 >= 0 && d5 <= d6) {
        s = 0, t = 1;
    } else {
        double vc = d1 * d4 - d3 * d2, vb = d5 * d2 - d1 * d6, va = d3 * d6 - d5 * d4;
        if (vc <= 0 && d1 >= 0 && d3 <= 0) {
            s = d1 / (d1 - d3), t = 0;
        } else if (vb <= 0 && d2 >= 0 && d6 <= 0) {
            s = 0, t = d2 / (d2 - d6);
        } else if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
            t = (d4 - d3) / ((d4 - d3) + (d5 - d6)), s = 1 - t;
        } else {
            double den = 1 / (va + vb + vc);
            s = vb * den, t = vc * den;
        }
    }
    for (int k = 0; k < 3; k++)
        q[k] = a[k] + s * ab[k] + t * ac[k];
}

typedef struct tri_buckets {
    const hv_mesh *m;
    double lo[3], cell;
    int n[3];
    size_t *start; /* n0*n1*n2 + 1 offsets into items */
    uint32_t *items;
} tri_buckets;

static void cell_range(const tri_buckets *b, const double lo[3], const double hi[3], int c0[3],
                       int c1[3])
{
    for (int a = 0; a < 3; a++) {
        c0[a] = (int)floor((lo[a] - b->lo[a]) / b->cell);
        c1[a] = (int)floor((hi[a] - b->lo[a]) / b->cell);
        c0[a] = c0[a] < 0 ? 0 : c0[a] >= b->n[a] ? b->n[a] - 1 : c0[a];
        c1[a] = c1[a] < 0 ? 0 : c1[a] >= b->n[a] ? b->n[a] - 1 : c1[a];
    }
}

static void tri_bounds(const hv_mesh *m, size_t t, double lo[3], double hi[3])
{
    for (int a = 0; a < 3; a++) {
        lo[a] = INFINITY;
        hi[a] = -INFINITY;
    }
    for (int k = 0; k < 3; k++)
        for (int a = 0; a < 3; a++) {
            double x = m->verts[3 * m->tris[3 * t + k] + a];
            lo[a] = fmin(lo[a], x);
            hi[a] = fmax(hi[a], x);
        }
}

static void buckets_build(tri_buckets *b, const hv_mesh *m, double cell)
{
    double hi[3];
    TL_ASSERT_OK(hv_mesh_bounds(m, b->lo, hi));
    b->m = m;
    b->cell = cell;
    size_t cells = 1;
    for (int a = 0; a < 3; a++) {
        b->n[a] = (int)((hi[a] - b->lo[a]) / cell) + 1;
        cells *= (size_t)b->n[a];
    }
    b->start = calloc(cells + 1, sizeof *b->start);
    ck_assert_ptr_nonnull(b->start);
    for (int pass = 0; pass < 2; pass++) {
        for (size_t t = 0; t < m->ntris; t++) {
            double tlo[3], thi[3];
            int c0[3], c1[3];
            tri_bounds(m, t, tlo, thi);
            cell_range(b, tlo, thi, c0, c1);
            for (int z = c0[2]; z <= c1[2]; z++)
                for (int y = c0[1]; y <= c1[1]; y++)
                    for (int x = c0[0]; x <= c1[0]; x++) {
                        size_t c = (size_t)x + (size_t)b->n[0] * ((size_t)y + (size_t)b->n[1] * z);
                        if (pass == 0)
                            b->start[c + 1]++;
                        else
                            b->items[b->start[c]++] = (uint32_t)t;
                    }
        }
        if (pass == 0) {
            for (size_t c = 0; c < cells; c++)
                b->start[c + 1] += b->start[c];
            b->items = malloc((b->start[cells] + 1) * sizeof *b->items);
            ck_assert_ptr_nonnull(b->items);
        } else {
            for (size_t c = cells; c > 0; c--) /* the fill moved each start to the next */
                b->start[c] = b->start[c - 1];
            b->start[0] = 0;
        }
    }
}

static void buckets_free(tri_buckets *b)
{
    free(b->start);
    free(b->items);
}

/* Distance from p to the mesh when it is at most rmax; otherwise some value
 * above rmax. */
static double buckets_dist(const tri_buckets *b, const double p[3], double rmax)
{
    double lo[3], hi[3], best = INFINITY;
    int c0[3], c1[3];
    for (int a = 0; a < 3; a++) {
        lo[a] = p[a] - rmax;
        hi[a] = p[a] + rmax;
    }
    cell_range(b, lo, hi, c0, c1);
    for (int z = c0[2]; z <= c1[2]; z++)
        for (int y = c0[1]; y <= c1[1]; y++)
            for (int x = c0[0]; x <= c1[0]; x++) {
                size_t c = (size_t)x + (size_t)b->n[0] * ((size_t)y + (size_t)b->n[1] * z);
                for (size_t i = b->start[c]; i < b->start[c + 1]; i++) {
                    const uint32_t *t = b->m->tris + 3 * b->items[i];
                    double q[3];
                    closest_on_triangle(p, b->m->verts + 3 * t[0], b->m->verts + 3 * t[1],
                                        b->m->verts + 3 * t[2], q);
                    double d = sqrt((p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]) +
                                    (p[2] - q[2]) * (p[2] - q[2]));
                    if (d < best)
                        best = d;
                }
            }
    return best;
}

/* One-sided Hausdorff distance, in voxels, from `out` (its vertices, centroids
 * and three more points on each triangle) to the surface in b; values above
 * 1.25 are reported as they are found, which is at least 1.25. */
static double hausdorff_voxels(const hv_mesh *out, const tri_buckets *b, double h)
{
    double worst = 0, rmax = 1.25 * h;
    for (size_t i = 0; i < out->nverts; i++)
        worst = fmax(worst, buckets_dist(b, out->verts + 3 * i, rmax));
    static const double w[4][3] = {{1 / 3.0, 1 / 3.0, 1 / 3.0},
                                   {4 / 6.0, 1 / 6.0, 1 / 6.0},
                                   {1 / 6.0, 4 / 6.0, 1 / 6.0},
                                   {1 / 6.0, 1 / 6.0, 4 / 6.0}};
    for (size_t t = 0; t < out->ntris; t++)
        for (int s = 0; s < 4; s++) {
            double p[3] = {0, 0, 0};
            for (int k = 0; k < 3; k++)
                for (int a = 0; a < 3; a++)
                    p[a] += w[s][k] * out->verts[3 * out->tris[3 * t + k] + a];
            worst = fmax(worst, buckets_dist(b, p, rmax));
        }
    return worst / h;
}

static hv_grid *sdf_of(const hv_mesh *m, int res, const double *bbox)
{
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = res;
    if (bbox) {
        o.use_bbox = 1;
        memcpy(o.bbox, bbox, sizeof o.bbox);
    }
    hv_grid *g = NULL;
    hv_sdf_stats st;
    TL_ASSERT_OK(hv_sdf_compute(m, &o, &g, &st));
    return g;
}

/* Checks the extraction of g at each adaptivity: watertight, also once written
 * as STL (float32, no shared vertices) and read back; with `truth`, within
 * max_haus voxels of it; enclosing the grid's inside volume within vol_tol
 * (relative) when vol_tol > 0. Prints the figures. */
static void check_extraction(const char *what, const hv_grid *g, const hv_mesh *truth,
                             double max_haus, double vol_tol)
{
    tri_buckets b;
    if (truth)
        buckets_build(&b, truth, 1.25 * g->h);
    const double vin = inside_volume(g);
    const double ads[2] = {0.0, 0.5};
    char dir[64] = "/tmp/hv_check_mesh_out_XXXXXX", stl[128];
    ck_assert_ptr_nonnull(mkdtemp(dir));
    snprintf(stl, sizeof stl, "%s/out.stl", dir);
    for (int a = 0; a < 2; a++) {
        hv_mesh *out = NULL;
        double t0 = hv_now();
        TL_ASSERT_OK(hv_grid_to_mesh(g, 0.0, ads[a], &out));
        double secs = hv_now() - t0;
        char name[200];
        snprintf(name, sizeof name, "%s at adaptivity %g", what, ads[a]);
        assert_watertight(out, name);
        TL_ASSERT_OK(hv_mesh_write(out, stl));
        hv_mesh *back = NULL;
        TL_ASSERT_OK(hv_mesh_read(stl, &back));
        ck_assert_msg(back->nverts == out->nverts && back->ntris == out->ntris,
                      "%s: the STL reads back as %zu vertices for %zu", name, back->nverts,
                      out->nverts);
        assert_watertight(back, stl);
        hv_mesh_destroy(&back);
        hv_mesh_report r = report_of(out);
        double verr = r.signed_volume / vin - 1;
        double haus = truth ? hausdorff_voxels(out, &b, g->h) : NAN;
        char hs[48] = "none (no reference mesh)";
        if (truth)
            snprintf(hs, sizeof hs, "%.3f voxels", haus);
        printf("MEASURE: %s: grid %dx%dx%d, %zu triangles, hausdorff %s, volume %+.3f%% "
               "against %zu-cell count, %.3f s\n",
               name, g->n[0], g->n[1], g->n[2], out->ntris, hs, 100 * verr,
               (size_t)(vin / (g->h * g->h * g->h) + 0.5), secs);
        if (truth)
            ck_assert_msg(haus <= max_haus, "%s: one-sided Hausdorff %.3f voxels (max %.2f)", name,
                          haus, max_haus);
        if (vol_tol > 0)
            ck_assert_msg(fabs(verr) <= vol_tol, "%s: volume %g against %g inside (%+.2f%%)", name,
                          r.signed_volume, vin, 100 * verr);
        hv_mesh_destroy(&out);
    }
    if (truth)
        buckets_free(&b);
    tl_rm_rf(dir);
}

/* ---- writers ---- */

static void assert_same_triangles(const hv_mesh *m, const hv_mesh *back, int f32, const char *what)
{
    ck_assert_msg(back->nverts == m->nverts && back->ntris == m->ntris,
                  "%s: %zu vertices, %zu triangles back for %zu, %zu", what, back->nverts,
                  back->ntris, m->nverts, m->ntris);
    for (size_t t = 0; t < m->ntris; t++)
        for (int k = 0; k < 3; k++)
            for (int a = 0; a < 3; a++) {
                double want = m->verts[3 * m->tris[3 * t + k] + a];
                if (f32)
                    want = (double)(float)want;
                double got = back->verts[3 * back->tris[3 * t + k] + a];
                ck_assert_msg(got == want, "%s: triangle %zu corner %d axis %d: %.17g for %.17g",
                              what, t, k, a, got, want);
            }
}

START_TEST(written_meshes_should_read_back_with_the_same_triangles_in_every_format)
{
    make_tmpdir();
    const double c[3] = {0.1, 1.0 / 3.0, -7e-5};
    hv_mesh *meshes[2] = {NULL, NULL};
    TL_ASSERT_OK(hv_mesh_make_sphere(&meshes[0], c, 0.7, 3));
    TL_ASSERT_OK(hv_mesh_make_torus(&meshes[1], c, 1.3, 0.45, 24, 12));
    const char *exts[] = {"obj", "ply", "stl", "PLY", "Stl"};
    for (int i = 0; i < 2; i++)
        for (int e = 0; e < 5; e++) {
            const char *p = tmp_path("m%d.%s", i, exts[e]);
            hv_status st = e < 3 && e == 1   ? hv_mesh_write_ply(meshes[i], p)
                           : e < 3 && e == 2 ? hv_mesh_write_stl(meshes[i], p)
                                             : hv_mesh_write(meshes[i], p);
            ck_assert_msg(st == HV_OK, "%s: %s", p, hv_last_error());
            hv_mesh *back = NULL;
            TL_ASSERT_OK(hv_mesh_read(p, &back));
            int stl = !strcasecmp(exts[e], "stl");
            const char *fmt = back->format ? back->format : "";
            ck_assert_msg(!strncasecmp(fmt, exts[e], 3) || (stl && !strncmp(fmt, "STL", 3)),
                          "%s read as %s", p, fmt);
            assert_same_triangles(meshes[i], back, stl, p);
            hv_mesh_report r = report_of(back);
            ck_assert_uint_eq(r.boundary_edges + r.nonmanifold_edges + r.inconsistent_edges, 0);
            ck_assert(r.signed_volume > 0);
            hv_mesh_destroy(&back);
        }
    ck_assert_int_eq(count_entries(tmpdir), 10); /* no temporary left */
    hv_mesh_destroy(&meshes[0]);
    hv_mesh_destroy(&meshes[1]);
    tl_rm_rf(tmpdir);
}
END_TEST

/* Reads a binary PLY or STL with NumPy alone and dumps its vertices (float64)
 * and, for PLY, faces (uint32) for the test to compare; asserts the layout
 * (header, sizes, list counts, STL facet normals and attribute bytes). */
static const char numpy_reader[] =
    "import sys\n"
    "import numpy as np\n"
    "kind, path, vout, fout = sys.argv[1:5]\n"
    "data = open(path, 'rb').read()\n"
    "if kind == 'ply':\n"
    "    end = data.index(b'end_header\\n') + len(b'end_header\\n')\n"
    "    head = data[:end].decode('ascii').split('\\n')\n"
    "    assert head[0] == 'ply' and head[1] == 'format binary_little_endian 1.0', head[:2]\n"
    "    for want in ('property double x', 'property double y', 'property double z',\n"
    "                 'property list uchar uint vertex_indices'):\n"
    "        assert want in head, want\n"
    "    nv = nf = None\n"
    "    for line in head:\n"
    "        w = line.split()\n"
    "        if w[:2] == ['element', 'vertex']: nv = int(w[2])\n"
    "        if w[:2] == ['element', 'face']: nf = int(w[2])\n"
    "    assert len(data) == end + 24 * nv + 13 * nf, (len(data), nv, nf)\n"
    "    v = np.frombuffer(data, dtype='<f8', count=3 * nv, offset=end)\n"
    "    f = np.frombuffer(data, dtype=np.dtype([('n', 'u1'), ('i', '<u4', (3,))]), count=nf,\n"
    "                      offset=end + 24 * nv)\n"
    "    assert (f['n'] == 3).all()\n"
    "    v.astype('<f8').tofile(vout)\n"
    "    f['i'].astype('<u4').tofile(fout)\n"
    "else:\n"
    "    assert not data[:5].lower().startswith(b'solid')\n"
    "    n = int(np.frombuffer(data, '<u4', 1, 80)[0])\n"
    "    assert len(data) == 84 + 50 * n, (len(data), n)\n"
    "    r = np.frombuffer(data, np.dtype([('n', '<f4', (3,)), ('v', '<f4', (3, 3)),\n"
    "                                      ('a', '<u2')]), n, 84)\n"
    "    v = r['v'].astype(np.float64)\n"
    "    c = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])\n"
    "    ln = np.linalg.norm(c, axis=1)\n"
    "    ok = ln > 0\n"
    "    dots = (r['n'][ok] * (c[ok] / ln[ok, None])).sum(axis=1)\n"
    "    assert ok.sum() > 0.9 * n and (dots > 0.999).all(), dots.min()\n"
    "    assert np.allclose(np.linalg.norm(r['n'][ok], axis=1), 1, atol=1e-6)\n"
    "    assert (r['a'] == 0).all()\n"
    "    v.reshape(-1, 3).astype('<f8').tofile(vout)\n";

static void *read_all(const char *p, size_t *len)
{
    FILE *f = fopen(p, "rb");
    ck_assert_msg(f != NULL, "%s: %s", p, strerror(errno));
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    void *b = malloc((size_t)n + 1);
    ck_assert_uint_eq(fread(b, 1, (size_t)n, f), (size_t)n);
    fclose(f);
    *len = (size_t)n;
    return b;
}

START_TEST(ply_and_stl_should_match_an_independent_numpy_reader)
{
    if (access("/usr/bin/python3", X_OK) != 0)
        TL_SKIP("no /usr/bin/python3 for the NumPy reader");
    make_tmpdir();
    const double c[3] = {-2.5, 0.125, 1e3};
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_make_torus(&m, c, 1.7, 0.3, 30, 9));
    FILE *f = fopen(tmp_path("reader.py"), "w");
    ck_assert_ptr_nonnull(f);
    fputs(numpy_reader, f);
    ck_assert_int_eq(fclose(f), 0);
    TL_ASSERT_OK(hv_mesh_write(m, tmp_path("t.ply")));
    TL_ASSERT_OK(hv_mesh_write(m, tmp_path("t.stl")));
    char cmd[3000], err[2000];
    for (int stl = 0; stl < 2; stl++) {
        snprintf(cmd, sizeof cmd, "/usr/bin/python3 %s %s %s %s %s", tmp_path("reader.py"),
                 stl ? "stl" : "ply", tmp_path("t.%s", stl ? "stl" : "ply"), tmp_path("v.bin"),
                 tmp_path("f.bin"));
        int rc = tl_run_cmd(cmd, tmpdir, err, sizeof err);
        ck_assert_msg(rc == 0, "NumPy reader on the %s file: exit %d: %s", stl ? "STL" : "PLY", rc,
                      err);
        size_t vlen;
        double *v = read_all(tmp_path("v.bin"), &vlen);
        if (!stl) {
            ck_assert_uint_eq(vlen, 3 * m->nverts * sizeof(double));
            ck_assert_mem_eq(v, m->verts, vlen);
            size_t flen;
            uint32_t *fi = read_all(tmp_path("f.bin"), &flen);
            ck_assert_uint_eq(flen, 3 * m->ntris * sizeof(uint32_t));
            ck_assert_mem_eq(fi, m->tris, flen);
            free(fi);
        } else {
            ck_assert_uint_eq(vlen, 9 * m->ntris * sizeof(double));
            for (size_t t = 0; t < m->ntris; t++)
                for (int k = 0; k < 3; k++)
                    for (int a = 0; a < 3; a++)
                        ck_assert(v[9 * t + 3 * k + a] ==
                                  (double)(float)m->verts[3 * m->tris[3 * t + k] + a]);
        }
        free(v);
    }
    hv_mesh_destroy(&m);
    tl_rm_rf(tmpdir);
}
END_TEST

START_TEST(failed_writes_should_leave_no_file_and_unknown_extensions_should_be_refused)
{
    make_tmpdir();
    const double c[3] = {0, 0, 0};
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_make_sphere(&m, c, 1, 3));
    const char *exts[] = {"obj", "ply", "stl"};
    /* a missing directory */
    for (int e = 0; e < 3; e++) {
        const char *p = tmp_path("no/such/dir/x.%s", exts[e]);
        ck_assert_int_eq(hv_mesh_write(m, p), HV_ERR_IO);
        ck_assert_msg(strstr(hv_last_error(), "x."), "message '%s'", hv_last_error());
    }
    /* a target that is a directory */
    ck_assert_int_eq(mkdir(tmp_path("d.ply"), 0777), 0);
    ck_assert_int_eq(hv_mesh_write(m, tmp_path("d.ply")), HV_ERR_IO);
    ck_assert_int_eq(count_entries(tmpdir), 1);
    /* a write that fails midway (the file size limit: EFBIG, as on a full disk) */
    struct rlimit old, low;
    ck_assert_int_eq(getrlimit(RLIMIT_FSIZE, &old), 0);
    low = old;
    low.rlim_cur = 4096;
    void (*prev)(int) = signal(SIGXFSZ, SIG_IGN);
    ck_assert_int_eq(setrlimit(RLIMIT_FSIZE, &low), 0);
    hv_status st[3];
    for (int e = 0; e < 3; e++)
        st[e] = hv_mesh_write(m, tmp_path("big.%s", exts[e]));
    ck_assert_int_eq(setrlimit(RLIMIT_FSIZE, &old), 0);
    signal(SIGXFSZ, prev);
    for (int e = 0; e < 3; e++)
        ck_assert_msg(st[e] == HV_ERR_IO, "%s: %s", exts[e], hv_status_str(st[e]));
    ck_assert_int_eq(count_entries(tmpdir), 1);
    /* the same files write once the limit is gone */
    for (int e = 0; e < 3; e++)
        TL_ASSERT_OK(hv_mesh_write(m, tmp_path("big.%s", exts[e])));
    ck_assert_int_eq(count_entries(tmpdir), 4);
    /* extensions */
    const char *bad[] = {"x.off", "x", "x.obj.gz", "dir.obj/x"};
    for (int i = 0; i < 4; i++) {
        const char *p = tmp_path("%s", bad[i]);
        ck_assert_int_eq(hv_mesh_write(m, p), HV_ERR_INVALID_ARG);
        ck_assert_msg(strstr(hv_last_error(), p), "message '%s' does not name %s", hv_last_error(),
                      p);
    }
    ck_assert_int_eq(count_entries(tmpdir), 4);
    hv_mesh_destroy(&m);
    tl_rm_rf(tmpdir);
}
END_TEST

/* ---- extraction ---- */

START_TEST(sphere_and_torus_should_give_closed_outward_meshes_within_a_voxel_of_the_input)
{
    const double c[3] = {0.05, -0.1, 0.2};
    hv_mesh *sphere = NULL, *torus = NULL;
    TL_ASSERT_OK(hv_mesh_make_sphere(&sphere, c, 1.0, 5));
    TL_ASSERT_OK(hv_mesh_make_torus(&torus, c, 1.0, 0.4, 192, 96));
    hv_grid *g = sdf_of(sphere, 64, NULL);
    check_extraction("sphere", g, sphere, 1.0, 0.01);
    hv_grid_destroy(&g);
    /* The tube is 0.4 across 0.8: 96 cells along the torus give it 27. */
    g = sdf_of(torus, 96, NULL);
    check_extraction("torus", g, torus, 1.0, 0.01);
    hv_mesh_report r;
    hv_mesh *out = NULL;
    TL_ASSERT_OK(hv_grid_to_mesh(g, 0, 0, &out));
    r = report_of(out);
    ck_assert_uint_eq(r.components, 1);
    ck_assert_int_eq((int)r.vertices - (int)(r.edges) + (int)r.triangles, 0); /* genus 1 */
    hv_mesh_destroy(&out);
    hv_grid_destroy(&g);
    hv_mesh_destroy(&sphere);
    hv_mesh_destroy(&torus);
}
END_TEST

START_TEST(surfaces_reaching_the_walls_should_be_capped_on_the_walls)
{
    /* A sphere of radius 1 cut through its middle by the block's x0 wall and
     * near its top by z1. */
    const double c[3] = {0, 0, 0};
    hv_mesh *sphere = NULL;
    TL_ASSERT_OK(hv_mesh_make_sphere(&sphere, c, 1.0, 5));
    const double bbox[6] = {0.0, -1.3, -1.3, 1.3, 1.3, 0.7};
    hv_grid *g = sdf_of(sphere, 64, bbox);
    check_extraction("sphere cut by two walls", g, NULL, 0, 0.01);
    for (int a = 0; a < 2; a++) {
        hv_mesh *out = NULL;
        TL_ASSERT_OK(hv_grid_to_mesh(g, 0, a * 0.5, &out));
        double lo[3], hi[3];
        TL_ASSERT_OK(hv_mesh_bounds(out, lo, hi));
        /* the caps lie on the walls: the block's outer faces (z1 is bbox[5]
         * rounded up to whole voxels) */
        const double x0 = g->origin[0], z1 = g->origin[2] + g->n[2] * g->h;
        ck_assert(fabs(x0 - bbox[0]) < 1e-12 && z1 >= bbox[5] && z1 < 1.0);
        ck_assert_msg(fabs(lo[0] - x0) < 1e-9 && fabs(hi[2] - z1) < 1e-9,
                      "caps at x %.17g, z %.17g; walls at %.17g, %.17g", lo[0], hi[2], x0, z1);
        size_t on_wall = 0;
        for (size_t i = 0; i < out->nverts; i++)
            on_wall += fabs(out->verts[3 * i] - x0) < 1e-9;
        ck_assert_msg(on_wall > 100, "%zu vertices on the x0 wall", on_wall);
        hv_mesh_destroy(&out);
    }
    hv_grid_destroy(&g);
    hv_mesh_destroy(&sphere);

    /* Everything inside: the block's box, its edges bevelled by half a voxel. */
    const int n[3] = {40, 24, 16};
    const double origin[3] = {-1, 2, 0.5};
    TL_ASSERT_OK(hv_grid_create(&g, 3, n, 0.05, origin));
    for (size_t i = 0; i < hv_grid_count(g); i++)
        g->v[i] = -0.3f;
    check_extraction("all-inside block", g, NULL, 0, 0.02);
    hv_mesh *out = NULL;
    TL_ASSERT_OK(hv_grid_to_mesh(g, 0, 0, &out));
    double lo[3], hi[3];
    TL_ASSERT_OK(hv_mesh_bounds(out, lo, hi));
    for (int a = 0; a < 3; a++)
        ck_assert(fabs(lo[a] - origin[a]) < 1e-9 && fabs(hi[a] - origin[a] - n[a] * 0.05) < 1e-9);
    hv_mesh_destroy(&out);
    hv_grid_destroy(&g);
}
END_TEST

static uint64_t rng = 0x9e3779b97f4a7c15ull;

START_TEST(exact_zeros_and_noise_should_still_give_closed_manifold_meshes_with_distinct_vertices)
{
    make_tmpdir();
    const int n[3] = {14, 13, 12};
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_grid_create(&g, 3, n, 0.1, NULL));
    const double ads[3] = {0, 0.5, 1};
    for (int trial = 0; trial < 6; trial++) {
        /* Trials 0-2: values in {-1, 0, 1}, so that many samples sit exactly on
         * the isovalue and neighbouring voxels put points on the same spot;
         * 3-5: uniform noise (every ambiguous voxel configuration). */
        for (size_t i = 0; i < hv_grid_count(g); i++) {
            double u = tl_rand(&rng) + 0.5;
            g->v[i] = trial < 3 ? (float)((int)(u * 3) - 1) : (float)(u - 0.5 + 0.1 * (trial - 4));
        }
        /* Under the sanitizers one trial of each kind (drawn as in make
         * check): the others are other draws through the same paths. */
        if (tl_sanitized() && trial != 0 && trial != 3)
            continue;
        for (int a = 0; a < 3; a++) {
            char what[64];
            snprintf(what, sizeof what, "trial %d at adaptivity %g", trial, ads[a]);
            hv_mesh *out = NULL;
            TL_ASSERT_OK(hv_grid_to_mesh(g, 0, ads[a], &out));
            hv_mesh_report r = report_of(out);
            ck_assert_msg(r.boundary_edges == 0 && r.nonmanifold_edges == 0 &&
                              r.inconsistent_edges == 0 && r.signed_volume > 0,
                          "%s: %zu boundary, %zu non-manifold, %zu inconsistent, volume %g", what,
                          r.boundary_edges, r.nonmanifold_edges, r.inconsistent_edges,
                          r.signed_volume);
            ck_assert_uint_gt(r.components, 10);
            /* every vertex has a position of its own, also in float32: the
             * files read back (welding by position) with the same topology */
            const char *exts[2] = {"ply", "stl"};
            for (int e = 0; e < 2; e++) {
                const char *p = tmp_path("noise.%s", exts[e]);
                TL_ASSERT_OK(hv_mesh_write(out, p));
                hv_mesh *back = NULL;
                TL_ASSERT_OK(hv_mesh_read(p, &back));
                assert_same_triangles(out, back, e == 1, what);
                hv_mesh_destroy(&back);
            }
            hv_mesh_destroy(&out);
        }
    }
    hv_grid_destroy(&g);
    tl_rm_rf(tmpdir);
}
END_TEST

START_TEST(isovalue_should_select_the_level_set)
{
    /* An analytic distance to a sphere of radius 0.6: the isovalue 0.2 level set
     * is the sphere of radius 0.8. */
    const int n[3] = {48, 48, 48};
    const double origin[3] = {-1.2, -1.2, -1.2};
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_grid_create(&g, 3, n, 2.4 / 48, origin));
    for (int k = 0; k < n[2]; k++)
        for (int j = 0; j < n[1]; j++)
            for (int i = 0; i < n[0]; i++) {
                double x[3];
                hv_grid_cell_center(g, i, j, k, x);
                g->v[i + n[0] * (j + n[1] * k)] =
                    (float)(sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) - 0.6);
            }
    for (int a = 0; a < 2; a++) {
        hv_mesh *out = NULL;
        TL_ASSERT_OK(hv_grid_to_mesh(g, 0.2, a * 0.5, &out));
        assert_watertight(out, "isovalue 0.2");
        double rmin = INFINITY, rmax = 0;
        for (size_t i = 0; i < out->nverts; i++) {
            const double *p = out->verts + 3 * i;
            double r = sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
            rmin = fmin(rmin, r);
            rmax = fmax(rmax, r);
        }
        ck_assert_msg(rmin > 0.8 - 0.5 * g->h && rmax < 0.8 + 0.1 * g->h,
                      "vertices at radii %g..%g", rmin, rmax);
        hv_mesh_report r = report_of(out);
        double v = 4.0 / 3 * M_PI * 0.8 * 0.8 * 0.8;
        ck_assert_msg(fabs(r.signed_volume / v - 1) < 0.02, "volume %g for %g", r.signed_volume, v);
        hv_mesh_destroy(&out);
    }
    hv_grid_destroy(&g);
}
END_TEST

START_TEST(bad_grids_and_arguments_should_be_refused)
{
    const int n[3] = {8, 8, 8};
    hv_grid *g = NULL, *g2 = NULL;
    hv_mesh *out = NULL;
    TL_ASSERT_OK(hv_grid_create(&g, 3, n, 0.1, NULL));
    for (size_t i = 0; i < hv_grid_count(g); i++)
        g->v[i] = i == 300 ? -1.0f : 1.0f;
    TL_ASSERT_OK(hv_grid_to_mesh(g, 0, 0, &out));
    ck_assert_uint_gt(out->ntris, 0);
    hv_mesh_destroy(&out);

    const double bad_ad[] = {-0.01, 1.01, NAN, INFINITY};
    for (int i = 0; i < 4; i++) {
        ck_assert_int_eq(hv_grid_to_mesh(g, 0, bad_ad[i], &out), HV_ERR_INVALID_ARG);
        ck_assert_ptr_null(out);
        ck_assert_msg(strstr(hv_last_error(), "adaptivity"), "%s", hv_last_error());
    }
    ck_assert_int_eq(hv_grid_to_mesh(g, NAN, 0, &out), HV_ERR_INVALID_ARG);
    ck_assert_int_eq(hv_grid_to_mesh(g, 0, 0, NULL), HV_ERR_INVALID_ARG);
    ck_assert_int_eq(hv_grid_to_mesh(NULL, 0, 0, &out), HV_ERR_INVALID_ARG);
    /* no value below the isovalue: no surface */
    ck_assert_int_eq(hv_grid_to_mesh(g, -1.0, 0, &out), HV_ERR_INVALID_ARG);
    ck_assert_msg(strstr(hv_last_error(), "no surface"), "%s", hv_last_error());
    ck_assert_ptr_null(out);
    /* NaN and Inf values */
    g->v[17] = NAN;
    ck_assert_int_eq(hv_grid_to_mesh(g, 0, 0, &out), HV_ERR_NUMERIC);
    g->v[17] = -INFINITY;
    ck_assert_int_eq(hv_grid_to_mesh(g, 0, 0.5, &out), HV_ERR_NUMERIC);
    ck_assert_ptr_null(out);
    /* a 2D grid */
    TL_ASSERT_OK(hv_grid_create(&g2, 2, n, 0.1, NULL));
    g2->v[3] = -1;
    ck_assert_int_eq(hv_grid_to_mesh(g2, 0, 0, &out), HV_ERR_INVALID_ARG);
    ck_assert_msg(strstr(hv_last_error(), "3D"), "%s", hv_last_error());
    ck_assert_ptr_null(out);
    hv_grid_destroy(&g);
    hv_grid_destroy(&g2);
}
END_TEST

/* ---- the shared meshes ---- */

/* The meshes SOURCES.md lists with no defect ("none" in its defects column). */
static int listed_as_clean(const char *dir, const char *name)
{
    char p[1200], line[1024];
    snprintf(p, sizeof p, "%s/SOURCES.md", dir);
    FILE *f = fopen(p, "r");
    int clean = 0;
    while (f && !clean && fgets(line, sizeof line, f)) {
        char cell[3][256];
        if (sscanf(line, "| %255[^|]| %255[^|]| %255[^|]|", cell[0], cell[1], cell[2]) == 3) {
            size_t n = strlen(cell[0]);
            while (n && cell[0][n - 1] == ' ')
                cell[0][--n] = '\0';
            clean = !strcmp(cell[0], name) && !strncmp(cell[2], "none", 4);
        }
    }
    if (f)
        fclose(f);
    return clean;
}

static int is_mesh_file(const char *name)
{
    const char *dot = strrchr(name, '.');
    return dot && (!strcasecmp(dot, ".obj") || !strcasecmp(dot, ".ply") ||
                   !strcasecmp(dot, ".stl") || !strcasecmp(dot, ".off"));
}

START_TEST(shared_meshes_should_give_closed_oriented_meshes_and_clean_ones_stay_within_a_voxel)
{
    const char *d = tl_test_data();
    if (!d)
        TL_SKIP("no test meshes directory (set HEATVOX_TEST_DATA)");
    DIR *dd = opendir(d);
    ck_assert_ptr_nonnull(dd);
    struct dirent *e;
    static char names[64][256];
    int count = 0;
    while ((e = readdir(dd)) && count < 64)
        if (e->d_name[0] != '.' && is_mesh_file(e->d_name))
            snprintf(names[count++], sizeof names[0], "%s", e->d_name);
    closedir(dd);
    ck_assert_int_gt(count, 0);
    static hv_mesh *meshes[64];
    int intact[64], clean = 0;
    size_t fewest[2] = {SIZE_MAX, SIZE_MAX}; /* triangles of the smallest broken, intact mesh */
    for (int i = 0; i < count; i++) {
        char p[5000];
        snprintf(p, sizeof p, "%.4000s/%.256s", d, names[i]);
        meshes[i] = NULL;
        hv_status st = hv_mesh_read(p, &meshes[i]);
        ck_assert_msg(st == HV_OK, "%s exists but does not load: %s", p, hv_last_error());
        hv_mesh_report in = report_of(meshes[i]);
        /* intact: listed as such and closed, manifold, consistently oriented */
        intact[i] = listed_as_clean(d, names[i]) && in.boundary_edges == 0 &&
                    in.nonmanifold_edges == 0 && in.inconsistent_edges == 0;
        if (meshes[i]->ntris < fewest[intact[i]])
            fewest[intact[i]] = meshes[i]->ntris;
        clean += intact[i];
    }
    for (int i = 0; i < count; i++) {
        hv_mesh *m = meshes[i];
        /* Under the sanitizers every mesh is read and reported, and the
         * smallest intact one and the smallest broken one are extracted: the
         * extraction takes one path whatever the shape, and every mesh's SDF
         * runs there in check_batch. */
        if (!tl_sanitized() || m->ntris == fewest[intact[i]]) {
            hv_grid *g = sdf_of(m, intact[i] ? 80 : 48, NULL);
            check_extraction(names[i], g, intact[i] ? m : NULL, 1.0, intact[i] ? 0.01 : 0);
            hv_grid_destroy(&g);
        }
        hv_mesh_destroy(&meshes[i]);
    }
    char sources[1200];
    snprintf(sources, sizeof sources, "%s/SOURCES.md", d);
    ck_assert_msg(clean >= 1 || !exists(sources), "no intact mesh among the shared ones");
}
END_TEST

/* ---- the command line ---- */

/* `heatvox make-scenes` into the temporary directory, once per test; returns
 * its meshes directory. */
static const char *scenes(const char *hv)
{
    static char meshes[700];
    char cmd[1200], err[1000];
    snprintf(cmd, sizeof cmd, "%s make-scenes -q %s", hv, tmp_path("scenes"));
    ck_assert_msg(tl_run_cmd(cmd, tmpdir, err, sizeof err) == 0, "make-scenes: %s", err);
    snprintf(meshes, sizeof meshes, "%s", tmp_path("scenes/meshes"));
    return meshes;
}

/* `heatvox info --json FILE` must find the file closed and consistent. */
static void assert_info_clean(const char *hv, const char *file)
{
    char cmd[1500], out[8192];
    snprintf(cmd, sizeof cmd, "%s info --json %s", hv, file);
    int rc = run_capture(cmd, out, sizeof out);
    ck_assert_msg(rc == 0, "%s: exit %d: %s", cmd, rc, out);
    const char *keys[] = {"\"boundary_edges\":0,", "\"nonmanifold_edges\":0,",
                          "\"inconsistent_edges\":0,"};
    for (int k = 0; k < 3; k++)
        ck_assert_msg(strstr(out, keys[k]), "%s: no %s in %s", file, keys[k], out);
}

START_TEST(sdf_mesh_out_should_write_obj_ply_stl_that_info_finds_closed_and_consistent)
{
    const char *hv = tl_heatvox_bin();
    ck_assert_msg(hv != NULL, "no heatvox binary beside the tests (set HEATVOX_BIN)");
    make_tmpdir();
    const char *meshes = scenes(hv);
    /* every mesh make-scenes writes (but truncated.obj, malformed on purpose) */
    const char *inputs[] = {"sphere_holes_flips.obj", "torus_soup.obj", "sphere_half_flipped.obj",
                            "torus_holes.obj"};
    const char *exts[] = {"obj", "PLY", "stl"};
    char cmd[3000], out[8192];
    for (int i = 0; i < 4; i++)
        for (int e = 0; e < 3; e++) {
            /* Under the sanitizers each input once, in turn through each
             * writer (and adaptivity 0.5 with PLY). */
            if (tl_sanitized() && e != i % 3)
                continue;
            const char *mo = tmp_path("out%d.%s", i, exts[e]);
            snprintf(cmd, sizeof cmd, "%s sdf %s/%s --mesh-out %s --res 40 --adaptivity %s", hv,
                     meshes, inputs[i], mo, e == 1 ? "0.5" : "0");
            int rc = run_capture(cmd, out, sizeof out);
            ck_assert_msg(rc == 0, "%s: exit %d: %s", cmd, rc, out);
            ck_assert_msg(strstr(out, "triangles, adaptivity"), "summary: %s", out);
            assert_info_clean(hv, mo);
        }
    /* with -o and --npy: all three land */
    snprintf(cmd, sizeof cmd, "%s sdf %s/torus_holes.obj -o %s --npy %s --mesh-out %s --res 32 -q",
             hv, meshes, tmp_path("t.vdb"), tmp_path("t.npy"), tmp_path("t.stl"));
    ck_assert_msg(run_capture(cmd, out, sizeof out) == 0, "%s: %s", cmd, out);
    ck_assert(exists(tmp_path("t.vdb")) && exists(tmp_path("t.npy")) && exists(tmp_path("t.stl")));
    assert_info_clean(hv, tmp_path("t.stl"));
    /* --npy alone is an output too */
    snprintf(cmd, sizeof cmd, "%s sdf %s/torus_holes.obj --npy %s --res 24 -q", hv, meshes,
             tmp_path("only.npy"));
    ck_assert_msg(run_capture(cmd, out, sizeof out) == 0, "%s: %s", cmd, out);
    tl_rm_rf(tmpdir);
}
END_TEST

START_TEST(sdf_mesh_out_usage_errors_should_exit_2_before_computing)
{
    const char *hv = tl_heatvox_bin();
    ck_assert_msg(hv != NULL, "no heatvox binary beside the tests (set HEATVOX_BIN)");
    make_tmpdir();
    const char *meshes = scenes(hv);
    struct {
        const char *args, *message;
    } cases[] = {
        {"--mesh-out %s/u.obj --unsigned", "unsigned"},
        {"--mesh-out %s/u.off", "u.off"},
        {"--mesh-out %s/u", "extension"},
        {"--res 16 --adaptivity 0.5 -o %s/u.vdb", "--adaptivity"},
        {"--mesh-out %s/u.obj --adaptivity 1.5", "--adaptivity"},
        {"--res 16", "no output"},
    };
    char cmd[3000], out[8192], args[1000];
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        snprintf(args, sizeof args, cases[i].args, tmpdir);
        snprintf(cmd, sizeof cmd, "%s sdf %s/torus_holes.obj %s", hv, meshes, args);
        int rc = run_capture(cmd, out, sizeof out);
        ck_assert_msg(rc == 2, "%s: exit %d: %s", cmd, rc, out);
        ck_assert_msg(strstr(out, cases[i].message), "%s: message lacks '%s': %s", cmd,
                      cases[i].message, out);
    }
    ck_assert_int_eq(count_entries(tmpdir), 2); /* scenes and stderr.txt: nothing written */
    tl_rm_rf(tmpdir);
}
END_TEST

START_TEST(sdf_mesh_write_failure_after_the_vdb_should_replace_no_output)
{
    const char *hv = tl_heatvox_bin();
    ck_assert_msg(hv != NULL, "no heatvox binary beside the tests (set HEATVOX_BIN)");
    make_tmpdir();
    const char *meshes = scenes(hv);
    /* Files of at most 64 KiB (ulimit -f counts 512-byte blocks; SIGXFSZ
     * ignored, so a write fails with EFBIG as on a full disk): the .vdb fits,
     * the .obj written after it does not. */
    char cmd[3000], out[8192];
    snprintf(cmd, sizeof cmd,
             "sh -c \"trap '' XFSZ; ulimit -f 128; exec %s sdf %s/torus_holes.obj -o %s "
             "--mesh-out %s --res 40\"",
             hv, meshes, tmp_path("cap.vdb"), tmp_path("cap.obj"));
    int rc = run_capture(cmd, out, sizeof out);
    ck_assert_msg(rc == 1, "%s: exit %d: %s", cmd, rc, out);
    ck_assert_msg(strstr(out, "cap.obj: ") && strstr(out, "write failed") &&
                      strstr(out, "no output was written"),
                  "message: %s", out);
    ck_assert(!exists(tmp_path("cap.vdb")) && !exists(tmp_path("cap.obj")));
    /* the same without the limit: both land */
    snprintf(cmd, sizeof cmd, "%s sdf %s/torus_holes.obj -o %s --mesh-out %s --res 40 -q", hv,
             meshes, tmp_path("cap.vdb"), tmp_path("cap.obj"));
    rc = run_capture(cmd, out, sizeof out);
    ck_assert_msg(rc == 0 && exists(tmp_path("cap.vdb")) && exists(tmp_path("cap.obj")),
                  "%s: exit %d: %s", cmd, rc, out);
    struct stat sv, sm;
    ck_assert(stat(tmp_path("cap.vdb"), &sv) == 0 && stat(tmp_path("cap.obj"), &sm) == 0);
    ck_assert_msg(sv.st_size < 65536 && sm.st_size > 65536, "vdb %ld, obj %ld bytes",
                  (long)sv.st_size, (long)sm.st_size);
    unlink(tmp_path("cap.vdb"));
    unlink(tmp_path("cap.obj"));
    ck_assert_int_eq(count_entries(tmpdir), 2); /* scenes and stderr.txt: no temporary either */
    tl_rm_rf(tmpdir);
}
END_TEST

/* A cloud's mesh beside its batch volume is the cloud's own surface, as
 * heatvox sdf --mesh-out writes it (the same bytes), the band in tiles;
 * with --adaptivity the grid's zero set again. */
START_TEST(batch_mesh_of_a_cloud_should_be_its_own_surface)
{
    const char *hv = tl_heatvox_bin();
    ck_assert_msg(hv != NULL, "no heatvox binary beside the tests (set HEATVOX_BIN)");
    make_tmpdir();
    scenes(hv);
    const char *cloud = tmp_path("scenes/points/torus_scan_bare.xyz");
    char cmd[3000], out[8192];
    snprintf(cmd, sizeof cmd,
             "%s batch %s -o %s --res 32 --mesh-out-format ply --report %s/report.jsonl -q", hv,
             cloud, tmp_path("b"), tmpdir);
    int rc = run_capture(cmd, out, sizeof out);
    ck_assert_msg(rc == 0, "%s: exit %d: %s", cmd, rc, out);
    snprintf(cmd, sizeof cmd, "%s sdf %s -o %s --mesh-out %s --res 32 -q", hv, cloud,
             tmp_path("s.vdb"), tmp_path("s.ply"));
    rc = run_capture(cmd, out, sizeof out);
    ck_assert_msg(rc == 0, "%s: exit %d: %s", cmd, rc, out);
    snprintf(cmd, sizeof cmd, "cmp %s %s", tmp_path("b/torus_scan_bare.ply"), tmp_path("s.ply"));
    rc = run_capture(cmd, out, sizeof out);
    ck_assert_msg(rc == 0, "%s: %s", cmd, out);
    snprintf(cmd, sizeof cmd, "cat %s/report.jsonl", tmpdir);
    run_capture(cmd, out, sizeof out);
    ck_assert_msg(strstr(out, "\"tiles\":") && strstr(out, "\"orient_lines\":false"), "report: %s",
                  out);
    /* with adaptivity: the grid's zero set, not the same file */
    snprintf(cmd, sizeof cmd,
             "%s batch %s -o %s --res 32 --mesh-out-format ply --adaptivity 0.5 -q", hv, cloud,
             tmp_path("a"));
    rc = run_capture(cmd, out, sizeof out);
    ck_assert_msg(rc == 0, "%s: exit %d: %s", cmd, rc, out);
    snprintf(cmd, sizeof cmd, "cmp -s %s %s", tmp_path("a/torus_scan_bare.ply"), tmp_path("s.ply"));
    ck_assert_int_ne(run_capture(cmd, out, sizeof out), 0);
    assert_info_clean(hv, tmp_path("a/torus_scan_bare.ply"));
    assert_info_clean(hv, tmp_path("b/torus_scan_bare.ply"));
    tl_rm_rf(tmpdir);
}
END_TEST

START_TEST(batch_mesh_out_format_should_write_beside_the_volume_report_it_and_resume)
{
    const char *hv = tl_heatvox_bin();
    ck_assert_msg(hv != NULL, "no heatvox binary beside the tests (set HEATVOX_BIN)");
    make_tmpdir();
    const char *meshes = scenes(hv);
    char cmd[3000], out[8192];
    const char *formats[] = {"vdb", "exr"};
    for (int f = 0; f < 2; f++) {
        const char *od = tmp_path("batch_%s", formats[f]);
        snprintf(cmd, sizeof cmd,
                 "%s batch %s/torus_holes.obj %s/sphere_holes_flips.obj -o %s -j 2 --res 32 "
                 "--format %s --mesh-out-format stl --adaptivity 0.5 --report %s/report.jsonl",
                 hv, meshes, meshes, od, formats[f], tmpdir);
        int rc = run_capture(cmd, out, sizeof out);
        ck_assert_msg(rc == 0, "%s: exit %d: %s", cmd, rc, out);
        ck_assert_msg(strstr(out, "2 written, 0 up to date"), "%s", out);
        const char *names[] = {"torus_holes", "sphere_holes_flips"};
        for (int i = 0; i < 2; i++) {
            char p[800];
            snprintf(p, sizeof p, "%s/%s.%s", od, names[i], formats[f]);
            ck_assert_msg(exists(p), "%s missing", p);
            snprintf(p, sizeof p, "%s/%s.stl", od, names[i]);
            assert_info_clean(hv, p);
        }
        /* the report names the mesh and its triangle count */
        snprintf(cmd, sizeof cmd, "cat %s/report.jsonl", tmpdir);
        run_capture(cmd, out, sizeof out);
        ck_assert_msg(strstr(out, "\"mesh\":{\"output\":") && strstr(out, ".stl\",\"triangles\":"),
                      "report: %s", out);
        /* resume: all up to date; a deleted mesh is made again */
        snprintf(cmd, sizeof cmd,
                 "%s batch %s/torus_holes.obj %s/sphere_holes_flips.obj -o %s -j 2 --res 32 "
                 "--format %s --mesh-out-format stl --adaptivity 0.5",
                 hv, meshes, meshes, od, formats[f]);
        rc = run_capture(cmd, out, sizeof out);
        ck_assert_msg(rc == 0 && strstr(out, "0 written, 2 up to date"), "%s: %s", cmd, out);
        char gone[800];
        snprintf(gone, sizeof gone, "%s/torus_holes.stl", od);
        ck_assert_int_eq(unlink(gone), 0);
        rc = run_capture(cmd, out, sizeof out);
        ck_assert_msg(rc == 0 && strstr(out, "1 written, 1 up to date"), "%s: %s", cmd, out);
        assert_info_clean(hv, gone);
    }
    /* usage errors */
    const char *bad[] = {"--mesh-out-format off", "--mesh-out-format stl --unsigned",
                         "--mesh-out-format obj --adaptivity 2"};
    for (int i = 0; i < 3; i++) {
        snprintf(cmd, sizeof cmd, "%s batch %s/torus_holes.obj -o %s %s", hv, meshes,
                 tmp_path("bad"), bad[i]);
        int rc = run_capture(cmd, out, sizeof out);
        ck_assert_msg(rc == 2, "%s: exit %d: %s", cmd, rc, out);
    }
    ck_assert(!exists(tmp_path("bad")));
    /* a mesh output that would replace an input fails that input */
    snprintf(cmd, sizeof cmd, "%s batch %s -o %s --res 16 --mesh-out-format obj --dry-run", hv,
             meshes, meshes);
    int rc = run_capture(cmd, out, sizeof out);
    ck_assert_msg(rc == 1 && strstr(out, "would replace the input"), "%s: exit %d: %s", cmd, rc,
                  out);
    tl_rm_rf(tmpdir);
}
END_TEST

static Suite *mesh_out_suite(void)
{
    Suite *s = suite_create("mesh_out");
    TCase *tc = tcase_create("writers");
    tcase_set_timeout(tc, 120);
    tcase_add_test(tc, written_meshes_should_read_back_with_the_same_triangles_in_every_format);
    tcase_add_test(tc, ply_and_stl_should_match_an_independent_numpy_reader);
    tcase_add_test(tc, failed_writes_should_leave_no_file_and_unknown_extensions_should_be_refused);
    suite_add_tcase(s, tc);

    tc = tcase_create("extraction");
    tcase_set_timeout(tc, 300);
    tcase_add_test(tc,
                   sphere_and_torus_should_give_closed_outward_meshes_within_a_voxel_of_the_input);
    tcase_add_test(tc, surfaces_reaching_the_walls_should_be_capped_on_the_walls);
    tcase_add_test(
        tc, exact_zeros_and_noise_should_still_give_closed_manifold_meshes_with_distinct_vertices);
    tcase_add_test(tc, isovalue_should_select_the_level_set);
    tcase_add_test(tc, bad_grids_and_arguments_should_be_refused);
    suite_add_tcase(s, tc);

    tc = tcase_create("shared");
    tcase_set_timeout(tc, 300);
    tcase_add_test(
        tc, shared_meshes_should_give_closed_oriented_meshes_and_clean_ones_stay_within_a_voxel);
    suite_add_tcase(s, tc);

    tc = tcase_create("cli");
    tcase_set_timeout(tc, 300);
    tcase_add_test(tc, sdf_mesh_out_should_write_obj_ply_stl_that_info_finds_closed_and_consistent);
    tcase_add_test(tc, sdf_mesh_out_usage_errors_should_exit_2_before_computing);
    tcase_add_test(tc, sdf_mesh_write_failure_after_the_vdb_should_replace_no_output);
    tcase_add_test(tc, batch_mesh_out_format_should_write_beside_the_volume_report_it_and_resume);
    tcase_add_test(tc, batch_mesh_of_a_cloud_should_be_its_own_surface);
    suite_add_tcase(s, tc);
    return s;
}

int main(void) { return tl_run(mesh_out_suite()); }
