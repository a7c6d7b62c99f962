/* OpenVDB grids as 8^3 tiles of a block, without a dense grid: read tiles
 * equal the dense reader on every cell they hold and hold every active voxel
 * of the block, on blocks aligned and not aligned with OpenVDB's leaves and
 * through active tree tiles; other grids read on the same tiles equal their
 * dense reads; tiles written back hold exactly their active voxels in
 * OpenVDB's own reader (pyopenvdb) and read back densely in place; mismatched
 * grids, types, transforms and tiles are refused naming the grid.
 * Links OpenVDB: run with CK_FORK=no (docs/METHOD.md, "Testing notes"). */
#include "heatvox/vdb.h"
#include "testlib.h"

#include <check.h>
#include <dirent.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define CELLS (HV_TILE * HV_TILE * HV_TILE)

static char dir[64];

static void make_dir(void)
{
    snprintf(dir, sizeof dir, "/tmp/hv-vdbt-XXXXXX");
    ck_assert_ptr_nonnull(mkdtemp(dir));
}

static void remove_dir(void) { tl_rm_rf(dir); }

static void path_in_dir(char *buf, size_t size, const char *name)
{
    snprintf(buf, size, "%s/%s", dir, name);
}

/* The test sphere on a 37 x 41 x 29 block (no side a multiple of 8), a
 * non-zero origin, written with a band of 3 voxels. */
static const int N[3] = {37, 41, 29};
static const double O[3] = {-0.93, -1.02, 0.27};
static const double C[3] = {-0.005, 0.005, 0.995};
static const double R = 0.55;
static const double BAND = 3.0;
static const double H = 0.05;

/* Block offsets in index space: on the leaf lattice, and off it on every axis. */
static const int ALIGNED[3] = {0, 0, 0};
static const int SHIFTED[3] = {3, -5, 11};

static size_t idx(const hv_grid *g, int i, int j, int k)
{
    return (size_t)i + (size_t)g->n[0] * ((size_t)j + (size_t)g->n[1] * (size_t)k);
}

static hv_grid *sphere(double h)
{
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_grid_create(&g, 3, N, h, O));
    for (int k = 0; k < N[2]; k++)
        for (int j = 0; j < N[1]; j++)
            for (int i = 0; i < N[0]; i++) {
                double x[3];
                hv_grid_cell_center(g, i, j, k, x);
                g->v[idx(g, i, j, k)] =
                    (float)(sqrt((x[0] - C[0]) * (x[0] - C[0]) + (x[1] - C[1]) * (x[1] - C[1]) +
                                 (x[2] - C[2]) * (x[2] - C[2])) -
                            R);
            }
    return g;
}

/* Component c of a field that is zero except within two voxels of the
 * sphere's surface. */
static hv_grid *surface_field(const hv_grid *sdf, int c)
{
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_grid_create(&g, 3, N, sdf->h, O));
    for (int k = 0; k < N[2]; k++)
        for (int j = 0; j < N[1]; j++)
            for (int i = 0; i < N[0]; i++) {
                const size_t q = idx(g, i, j, k);
                double x[3];
                hv_grid_cell_center(g, i, j, k, x);
                if (fabsf(sdf->v[q]) < 2 * sdf->h)
                    g->v[q] = (float)((c + 1) * (x[c] - C[c]) + 0.25 * c);
            }
    return g;
}

/* Writes the sphere's level set "sdf" and the vec3s field "vel" (every voxel
 * active) with the block's first voxel at index off, voxel size h. */
static void write_sphere(const char *path, const int off[3], double h)
{
    hv_grid *g = sphere(h), *f[3];
    for (int c = 0; c < 3; c++)
        f[c] = surface_field(g, c);
    double index0[3];
    for (int a = 0; a < 3; a++)
        index0[a] = O[a] + (0.5 - off[a]) * h;
    hv_vdb_writer *w = NULL;
    TL_ASSERT_OK(hv_vdb_writer_create(&w));
    TL_ASSERT_OK(hv_vdb_writer_set_index_origin(w, index0));
    TL_ASSERT_OK(hv_vdb_writer_add_levelset(w, g, "sdf", BAND, 0));
    TL_ASSERT_OK(hv_vdb_writer_add_vec3(w, f[0], f[1], f[2], "vel"));
    TL_ASSERT_OK(hv_vdb_writer_write(w, path));
    hv_vdb_writer_destroy(&w);
    for (int c = 0; c < 3; c++)
        hv_grid_destroy(&f[c]);
    hv_grid_destroy(&g);
}

static float tile_value(const hv_tiles *t, size_t q, int i, int j, int k)
{
    return t->v[q * CELLS + (size_t)(i + HV_TILE * (j + HV_TILE * k))];
}

static int tile_on(const hv_tiles *t, size_t q, int i, int j, int k)
{
    return (int)(t->on[HV_TILE * q + k] >> (i + HV_TILE * j) & 1);
}

static int in_block(const hv_tiles *t, size_t q, int i, int j, int k)
{
    const int32_t *c = t->ijk + 3 * q;
    return c[0] + i < t->n[0] && c[1] + j < t->n[1] && c[2] + k < t->n[2];
}

/* Tiles on the block's 8^3 lattice, each once, in order of (k, j, i), each
 * with an active voxel; `active` counts their active voxels. */
static void check_layout(const hv_tiles *t)
{
    size_t active = 0;
    for (size_t q = 0; q < t->count; q++) {
        const int32_t *c = t->ijk + 3 * q;
        for (int a = 0; a < 3; a++) {
            ck_assert_int_eq(c[a] % HV_TILE, 0);
            ck_assert_int_ge(c[a], 0);
            ck_assert_int_lt(c[a], t->n[a]);
        }
        if (q > 0) {
            const int32_t *p = c - 3;
            const int later = c[2] != p[2] ? c[2] > p[2] : c[1] != p[1] ? c[1] > p[1] : c[0] > p[0];
            ck_assert_msg(later, "tile %zu is not after tile %zu in (k, j, i) order", q, q - 1);
        }
        size_t here = 0;
        for (int k = 0; k < HV_TILE; k++)
            here += (size_t)__builtin_popcountll(t->on[HV_TILE * q + k]);
        ck_assert_msg(here > 0, "tile %zu holds no active voxel", q);
        active += here;
    }
    ck_assert_uint_eq(active, t->active);
}

/* The block of t equals the dense read's block shifted by `from` voxels. */
static void check_block(const hv_tiles *t, const hv_grid *d, const int from[3], const int n[3])
{
    ck_assert_double_eq(t->h, d->h);
    for (int a = 0; a < 3; a++) {
        ck_assert_int_eq(t->n[a], n[a]);
        ck_assert_double_eq_tol(t->origin[a], d->origin[a] + from[a] * d->h, 1e-12);
    }
}

static hv_grid *read_dense(const char *p, const char *name, const int lo[3], const int hi[3])
{
    hv_vdb_read_opts o = {1, {lo[0], lo[1], lo[2]}, {hi[0], hi[1], hi[2]}};
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_vdb_read_float(p, name, &o, &g, NULL));
    return g;
}

START_TEST(tiles_should_equal_the_dense_read_and_hold_every_active_voxel)
{
    const int *offs[2] = {ALIGNED, SHIFTED};
    hv_grid *g = sphere(H);
    const float bg = (float)(BAND * H);
    for (int o = 0; o < 2; o++) {
        char p[256];
        path_in_dir(p, sizeof p, "ls.vdb");
        write_sphere(p, offs[o], H);
        const char *names[] = {"sdf"};
        int lo[3], hi[3], wide[3];
        TL_ASSERT_OK(hv_vdb_common_box(p, names, 1, lo, hi));
        for (int a = 0; a < 3; a++) {
            ck_assert_int_eq(lo[a], offs[o][a]);
            ck_assert_int_eq(hi[a], offs[o][a] + N[a] - 1);
            wide[a] = hi[a] + HV_TILE - 1;
        }
        /* the box itself, and a box reaching over every tile's last cell */
        hv_grid *d = read_dense(p, "sdf", lo, hi), *e = read_dense(p, "sdf", lo, wide);
        /* the whole block, and one cropped on every side whose last tiles
         * along x and z reach past it (33 and 25 cells), along z into the band */
        for (int crop = 0; crop < 2; crop++) {
            const int c0[3] = {1, 3, 1}, c1[3] = {3, 2, 3};
            int blo[3], bhi[3], from[3], n[3];
            for (int a = 0; a < 3; a++) {
                blo[a] = lo[a] + (crop ? c0[a] : 0);
                bhi[a] = hi[a] - (crop ? c1[a] : 0);
                from[a] = blo[a] - lo[a];
                n[a] = bhi[a] - blo[a] + 1;
            }
            hv_tiles *t = NULL;
            int cls = -1;
            TL_ASSERT_OK(hv_vdb_read_float_tiles(p, "sdf", blo, bhi, &t, &cls));
            ck_assert_int_eq(cls, HV_VDB_LEVEL_SET);
            check_block(t, d, from, n);
            check_layout(t);
            /* Every cell of every tile reads as the tree holds it; a voxel is
             * active where the block holds a voxel of the band. */
            for (size_t q = 0; q < t->count; q++)
                for (int k = 0; k < HV_TILE; k++)
                    for (int j = 0; j < HV_TILE; j++)
                        for (int i = 0; i < HV_TILE; i++) {
                            const int x = from[0] + t->ijk[3 * q] + i,
                                      y = from[1] + t->ijk[3 * q + 1] + j,
                                      z = from[2] + t->ijk[3 * q + 2] + k;
                            ck_assert_msg(tile_value(t, q, i, j, k) == e->v[idx(e, x, y, z)],
                                          "offset %d crop %d: cell (%d,%d,%d): %g, dense %g", o,
                                          crop, x, y, z, tile_value(t, q, i, j, k),
                                          e->v[idx(e, x, y, z)]);
                            const int want =
                                in_block(t, q, i, j, k) && fabsf(g->v[idx(g, x, y, z)]) < bg;
                            ck_assert_int_eq(tile_on(t, q, i, j, k), want);
                        }
            /* so no tile holds a voxel outside the band; none of the band is missed */
            size_t band = 0;
            for (int k = 0; k < n[2]; k++)
                for (int j = 0; j < n[1]; j++)
                    for (int i = 0; i < n[0]; i++)
                        band += fabsf(g->v[idx(g, from[0] + i, from[1] + j, from[2] + k)]) < bg;
            ck_assert_uint_gt(band, 2000);
            ck_assert_uint_eq(t->active, band);
            hv_tiles_destroy(&t);
            ck_assert_ptr_null(t);
        }
        hv_grid_destroy(&d);
        hv_grid_destroy(&e);
    }
    hv_grid_destroy(&g);
}
END_TEST

/* hv_vdb_writer_add_float makes every voxel active, and OpenVDB's prune turns
 * its constant 8^3 regions into active tiles of the tree: each of their
 * voxels is active. */
START_TEST(active_tree_tiles_should_make_every_voxel_of_theirs_active)
{
    char p[256];
    path_in_dir(p, sizeof p, "const.vdb");
    const int n[3] = {40, 24, 24};
    const double o[3] = {1, 2, 3};
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_grid_create(&g, 3, n, 0.1, o));
    for (int k = 0; k < n[2]; k++)
        for (int j = 0; j < n[1]; j++)
            for (int i = 0; i < n[0]; i++)
                g->v[idx(g, i, j, k)] = i < 32 ? 1.5f : (float)(0.25 * i + j);
    hv_vdb_writer *w = NULL;
    TL_ASSERT_OK(hv_vdb_writer_create(&w));
    TL_ASSERT_OK(hv_vdb_writer_add_float(w, g, "c"));
    TL_ASSERT_OK(hv_vdb_writer_write(w, p));
    hv_vdb_writer_destroy(&w);

    const int lo[3] = {2, 1, 3}, hi[3] = {37, 22, 20}, zero[3] = {0, 0, 0};
    int wide[3], bn[3];
    for (int a = 0; a < 3; a++) {
        wide[a] = hi[a] + HV_TILE - 1;
        bn[a] = hi[a] - lo[a] + 1;
    }
    hv_grid *e = read_dense(p, "c", lo, wide);
    hv_tiles *t = NULL;
    int cls = -1;
    TL_ASSERT_OK(hv_vdb_read_float_tiles(p, "c", lo, hi, &t, &cls));
    ck_assert_int_eq(cls, HV_VDB_UNKNOWN);
    check_block(t, e, zero, bn);
    check_layout(t);
    /* every tile of the block: ceil(36/8) * ceil(22/8) * ceil(18/8) */
    ck_assert_uint_eq(t->count, 5 * 3 * 3);
    ck_assert_uint_eq(t->active, (size_t)bn[0] * bn[1] * bn[2]);
    for (size_t q = 0; q < t->count; q++)
        for (int k = 0; k < HV_TILE; k++)
            for (int j = 0; j < HV_TILE; j++)
                for (int i = 0; i < HV_TILE; i++) {
                    const int x = t->ijk[3 * q] + i, y = t->ijk[3 * q + 1] + j,
                              z = t->ijk[3 * q + 2] + k;
                    ck_assert_float_eq(tile_value(t, q, i, j, k), e->v[idx(e, x, y, z)]);
                    ck_assert_int_eq(tile_on(t, q, i, j, k), in_block(t, q, i, j, k));
                }
    hv_tiles_destroy(&t);
    hv_grid_destroy(&e);
    hv_grid_destroy(&g);
}
END_TEST

START_TEST(tiles_like_should_read_other_grids_as_the_dense_reader_does)
{
    char p[256];
    path_in_dir(p, sizeof p, "ls.vdb");
    write_sphere(p, SHIFTED, H);
    const char *names[] = {"sdf", "vel"};
    int lo[3], hi[3], wide[3];
    TL_ASSERT_OK(hv_vdb_common_box(p, names, 2, lo, hi));
    for (int a = 0; a < 3; a++)
        wide[a] = hi[a] + HV_TILE - 1;
    hv_tiles *t = NULL, *out[3] = {NULL, NULL, NULL};
    TL_ASSERT_OK(hv_vdb_read_float_tiles(p, "sdf", lo, hi, &t, NULL));

    int nc = 0;
    TL_ASSERT_OK(hv_vdb_read_tiles_like(p, "vel", t, out, &nc));
    ck_assert_int_eq(nc, 3);
    hv_vdb_read_opts o = {1, {lo[0], lo[1], lo[2]}, {wide[0], wide[1], wide[2]}};
    hv_grid *d[3] = {NULL, NULL, NULL};
    TL_ASSERT_OK(hv_vdb_read_vec3(p, "vel", &o, &d[0], &d[1], &d[2]));
    size_t in = 0;
    for (size_t q = 0; q < t->count; q++)
        for (int k = 0; k < HV_TILE; k++)
            for (int j = 0; j < HV_TILE; j++)
                for (int i = 0; i < HV_TILE; i++)
                    in += in_block(t, q, i, j, k);
    for (int c = 0; c < 3; c++) {
        const hv_tiles *v = out[c];
        ck_assert_uint_eq(v->count, t->count);
        ck_assert_mem_eq(v->ijk, t->ijk, 3 * t->count * sizeof *t->ijk);
        ck_assert_double_eq(v->h, t->h);
        for (int a = 0; a < 3; a++) {
            ck_assert_int_eq(v->n[a], t->n[a]);
            ck_assert_double_eq(v->origin[a], t->origin[a]);
        }
        /* "vel" is active on its whole block */
        ck_assert_uint_eq(v->active, in);
        size_t nonzero = 0;
        for (size_t q = 0; q < t->count; q++)
            for (int k = 0; k < HV_TILE; k++)
                for (int j = 0; j < HV_TILE; j++)
                    for (int i = 0; i < HV_TILE; i++) {
                        const int x = t->ijk[3 * q] + i, y = t->ijk[3 * q + 1] + j,
                                  z = t->ijk[3 * q + 2] + k;
                        const float want = d[c]->v[idx(d[c], x, y, z)];
                        ck_assert_msg(tile_value(v, q, i, j, k) == want,
                                      "component %d, cell (%d,%d,%d): %g, dense %g", c, x, y, z,
                                      tile_value(v, q, i, j, k), want);
                        ck_assert_int_eq(tile_on(v, q, i, j, k), in_block(t, q, i, j, k));
                        nonzero += want != 0;
                    }
        ck_assert_uint_gt(nonzero, 1000);
        hv_tiles_destroy(&out[c]);
        hv_grid_destroy(&d[c]);
    }

    /* the level set read on its own tiles is those tiles */
    TL_ASSERT_OK(hv_vdb_read_tiles_like(p, "sdf", t, out, &nc));
    ck_assert_int_eq(nc, 1);
    ck_assert_ptr_null(out[1]);
    ck_assert_uint_eq(out[0]->active, t->active);
    ck_assert_mem_eq(out[0]->v, t->v, t->count * CELLS * sizeof(float));
    ck_assert_mem_eq(out[0]->on, t->on, t->count * HV_TILE * sizeof(uint64_t));
    hv_tiles_destroy(&out[0]);
    hv_tiles_destroy(&t);
}
END_TEST

/* The tile holding block cell (x, y, z) of t, or -1. */
static long find_tile(const hv_tiles *t, const long *lookup, int x, int y, int z)
{
    if (x < 0 || y < 0 || z < 0 || x >= t->n[0] || y >= t->n[1] || z >= t->n[2])
        return -1;
    const int nt[2] = {(t->n[0] + 7) / 8, (t->n[1] + 7) / 8};
    return lookup[x / 8 + nt[0] * (y / 8 + (long)nt[1] * (z / 8))];
}

START_TEST(tiles_written_should_hold_their_active_voxels_in_openvdb_and_in_heatvox)
{
    ck_assert_msg(system("/usr/bin/python3 -c 'import pyopenvdb' >/dev/null 2>&1") == 0,
                  "pyopenvdb does not import in /usr/bin/python3 (package python3-openvdb)");
    char src[256], p[256];
    path_in_dir(src, sizeof src, "src.vdb");
    path_in_dir(p, sizeof p, "out.vdb");
    write_sphere(src, SHIFTED, H);
    const char *names[] = {"sdf", "vel"};
    int lo[3], hi[3];
    TL_ASSERT_OK(hv_vdb_common_box(src, names, 2, lo, hi));
    hv_tiles *t = NULL, *v[3] = {NULL, NULL, NULL};
    int nc = 0;
    TL_ASSERT_OK(hv_vdb_read_float_tiles(src, "sdf", lo, hi, &t, NULL));
    TL_ASSERT_OK(hv_vdb_read_tiles_like(src, "vel", t, v, &nc));
    /* The vector's active voxels are the level set's band (those of x count);
     * values on inactive voxels must not reach the file. */
    memcpy(v[0]->on, t->on, t->count * HV_TILE * sizeof(uint64_t));
    v[0]->active = t->active;
    for (size_t q = 0; q < t->count; q++)
        for (int k = 0; k < HV_TILE; k++)
            for (int j = 0; j < HV_TILE; j++)
                for (int i = 0; i < HV_TILE; i++)
                    if (!tile_on(t, q, i, j, k)) {
                        const size_t c = q * CELLS + (size_t)(i + HV_TILE * (j + HV_TILE * k));
                        t->v[c] = 99;
                        for (int a = 0; a < 3; a++)
                            v[a]->v[c] = -99;
                    }
    const int nt[3] = {(t->n[0] + 7) / 8, (t->n[1] + 7) / 8, (t->n[2] + 7) / 8};
    long *lookup = malloc(sizeof(long) * (size_t)nt[0] * nt[1] * nt[2]);
    ck_assert_ptr_nonnull(lookup);
    for (long q = 0; q < (long)nt[0] * nt[1] * nt[2]; q++)
        lookup[q] = -1;
    for (size_t q = 0; q < t->count; q++)
        lookup[t->ijk[3 * q] / 8 +
               nt[0] * (t->ijk[3 * q + 1] / 8 + (long)nt[1] * (t->ijk[3 * q + 2] / 8))] = (long)q;
    hv_vdb_grid_info info[2];
    size_t count = 0;
    TL_ASSERT_OK(hv_vdb_list(src, info, 2, &count));

    /* by default the block starts at index 0; placed, at the source's index */
    for (int placed = 0; placed < 2; placed++) {
        hv_vdb_writer *w = NULL;
        TL_ASSERT_OK(hv_vdb_writer_create(&w));
        if (placed)
            TL_ASSERT_OK(hv_vdb_writer_set_index_origin(w, info[0].index0_world));
        TL_ASSERT_OK(hv_vdb_writer_add_float_tiles(w, t, "phi"));
        TL_ASSERT_OK(hv_vdb_writer_add_vec3_tiles(w, v[0], v[1], v[2], "vel"));
        ck_assert_int_eq(hv_vdb_writer_add_float_tiles(w, t, "phi"), HV_ERR_INVALID_ARG);
        TL_ASSERT_OK(hv_vdb_writer_write(w, p));
        hv_vdb_writer_destroy(&w);
        int off[3];
        for (int a = 0; a < 3; a++)
            off[a] = placed ? lo[a] : 0;

        /* OpenVDB's reader: every active value (tiles of the tree by their
         * box), nothing else */
        char cmd[1024], line[512];
        snprintf(cmd, sizeof cmd,
                 "/usr/bin/python3 -c 'import sys, pyopenvdb as vdb\n"
                 "for name in (\"phi\", \"vel\"):\n"
                 "    g = vdb.read(sys.argv[1], name)\n"
                 "    b = g.background\n"
                 "    print(\"grid\", name, g.gridClass, *(b if name == \"vel\" else (b,)))\n"
                 "    for it in g.citerOnValues():\n"
                 "        x = it.value if name == \"vel\" else (it.value,)\n"
                 "        print(*it.min, *it.max, *[repr(c) for c in x])\n"
                 "' %s",
                 p);
        FILE *pp = popen(cmd, "r");
        ck_assert_ptr_nonnull(pp);
        int vec = -1;
        size_t seen[2] = {0, 0}, wrong = 0;
        while (fgets(line, sizeof line, pp)) {
            char name[16], cls[32];
            double b[3] = {1, 1, 1}, x[3];
            int m0[3], m1[3];
            if (sscanf(line, "grid %15s %31s %lf %lf %lf", name, cls, &b[0], &b[1], &b[2]) >= 3) {
                vec = strcmp(name, "vel") == 0;
                ck_assert_str_eq(cls, "unknown");
                for (int a = 0; a < (vec ? 3 : 1); a++)
                    ck_assert_double_eq(b[a], 0);
                continue;
            }
            const int got = sscanf(line, "%d %d %d %d %d %d %lf %lf %lf", &m0[0], &m0[1], &m0[2],
                                   &m1[0], &m1[1], &m1[2], &x[0], &x[1], &x[2]);
            ck_assert_msg(vec >= 0 && got == (vec ? 9 : 7), "pyopenvdb printed: %s", line);
            for (int z = m0[2]; z <= m1[2]; z++)
                for (int y = m0[1]; y <= m1[1]; y++)
                    for (int xx = m0[0]; xx <= m1[0]; xx++) {
                        const int i = xx - off[0], j = y - off[1], k = z - off[2];
                        const long q = find_tile(t, lookup, i, j, k);
                        seen[vec]++;
                        if (q < 0 || !tile_on(t, (size_t)q, i % 8, j % 8, k % 8)) {
                            wrong++;
                            continue;
                        }
                        for (int a = 0; a < (vec ? 3 : 1); a++) {
                            const hv_tiles *s = vec ? v[a] : t;
                            wrong += (float)x[a] != tile_value(s, (size_t)q, i % 8, j % 8, k % 8);
                        }
                    }
        }
        ck_assert_int_eq(pclose(pp), 0);
        ck_assert_msg(wrong == 0, "placed %d: %zu active voxels read by pyopenvdb are wrong",
                      placed, wrong);
        ck_assert_uint_eq(seen[0], t->active);
        ck_assert_uint_eq(seen[1], t->active);

        /* heatvox's dense reader: the block in place, the active voxels with
         * their values, every other voxel 0 */
        hv_grid *d = NULL, *dv[3] = {NULL, NULL, NULL};
        TL_ASSERT_OK(hv_vdb_read_float(p, "phi", NULL, &d, NULL));
        TL_ASSERT_OK(hv_vdb_read_vec3(p, "vel", NULL, &dv[0], &dv[1], &dv[2]));
        ck_assert_double_eq_tol(d->h, t->h, 1e-12);
        for (int a = 0; a < 3; a++) {
            ck_assert_int_eq(d->n[a], t->n[a]);
            ck_assert_int_eq(dv[0]->n[a], t->n[a]);
            ck_assert_double_eq_tol(d->origin[a], t->origin[a], 1e-9);
            ck_assert_double_eq_tol(dv[0]->origin[a], t->origin[a], 1e-9);
        }
        size_t bad = 0;
        for (int k = 0; k < t->n[2]; k++)
            for (int j = 0; j < t->n[1]; j++)
                for (int i = 0; i < t->n[0]; i++) {
                    const long q = find_tile(t, lookup, i, j, k);
                    const int on = q >= 0 && tile_on(t, (size_t)q, i % 8, j % 8, k % 8);
                    for (int a = 0; a < 4; a++) {
                        const hv_tiles *s = a == 0 ? t : v[a - 1];
                        const hv_grid *r = a == 0 ? d : dv[a - 1];
                        const float want = on ? tile_value(s, (size_t)q, i % 8, j % 8, k % 8) : 0;
                        bad += r->v[idx(r, i, j, k)] != want;
                    }
                }
        ck_assert_msg(bad == 0, "placed %d: %zu dense values differ", placed, bad);
        hv_grid_destroy(&d);
        for (int a = 0; a < 3; a++)
            hv_grid_destroy(&dv[a]);
    }
    free(lookup);
    hv_tiles_destroy(&t);
    for (int a = 0; a < 3; a++)
        hv_tiles_destroy(&v[a]);
}
END_TEST

START_TEST(tiles_create_like_should_copy_the_block_and_tiles_with_one_value)
{
    hv_tiles like = {{20, 9, 17}, 0.5, {1, 2, 3}, 2, NULL, NULL, NULL, 7};
    int32_t ijk[6] = {16, 8, 0, 0, 0, 16};
    like.ijk = ijk;
    hv_tiles *t = NULL;
    TL_ASSERT_OK(hv_tiles_create_like(&t, &like, -2.5f));
    ck_assert_uint_eq(t->count, 2);
    ck_assert_uint_eq(t->active, 0);
    ck_assert_mem_eq(t->ijk, ijk, sizeof ijk);
    ck_assert_ptr_ne(t->ijk, ijk);
    for (int a = 0; a < 3; a++) {
        ck_assert_int_eq(t->n[a], like.n[a]);
        ck_assert_double_eq(t->origin[a], like.origin[a]);
    }
    ck_assert_double_eq(t->h, 0.5);
    for (size_t c = 0; c < 2 * CELLS; c++)
        ck_assert_float_eq(t->v[c], -2.5f);
    for (size_t w = 0; w < 2 * HV_TILE; w++)
        ck_assert_uint_eq(t->on[w], 0);
    hv_tiles_destroy(&t);
    like.count = 0;
    like.ijk = NULL;
    TL_ASSERT_OK(hv_tiles_create_like(&t, &like, 0));
    ck_assert_uint_eq(t->count, 0);
    hv_tiles_destroy(&t);
    ck_assert_int_eq(hv_tiles_create_like(&t, NULL, 0), HV_ERR_INVALID_ARG);
    ck_assert_ptr_null(t);
}
END_TEST

static void assert_error_names(hv_status st, hv_status want, const char *what)
{
    ck_assert_msg(st == want, "%s: got %s (%s)", what, hv_status_str(st), hv_last_error());
    ck_assert_msg(strstr(hv_last_error(), what), "'%s' not named in: %s", what, hv_last_error());
}

START_TEST(tile_reads_and_writes_should_refuse_missing_grids_wrong_types_and_mismatches)
{
    char p[256], q[256];
    path_in_dir(p, sizeof p, "ls.vdb");
    path_in_dir(q, sizeof q, "coarse.vdb");
    write_sphere(p, SHIFTED, H);
    write_sphere(q, SHIFTED, 0.04);
    const char *names[] = {"sdf"};
    int lo[3], hi[3];
    TL_ASSERT_OK(hv_vdb_common_box(p, names, 1, lo, hi));
    hv_tiles *t = NULL, *out[3] = {NULL, NULL, NULL};
    int nc = -1;

    assert_error_names(hv_vdb_read_float_tiles(p, "nope", lo, hi, &t, NULL), HV_ERR_INVALID_ARG,
                       "'nope'");
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "'sdf'")); /* what the file has */
    ck_assert_ptr_null(t);
    assert_error_names(hv_vdb_read_float_tiles(p, "vel", lo, hi, &t, NULL), HV_ERR_INVALID_ARG,
                       "vec3s");
    ck_assert_ptr_null(t);
    const int empty_hi[3] = {hi[0], lo[1] - 1, hi[2]};
    assert_error_names(hv_vdb_read_float_tiles(p, "sdf", lo, empty_hi, &t, NULL),
                       HV_ERR_INVALID_ARG, "empty");
    ck_assert_int_eq(hv_vdb_read_float_tiles(p, "sdf", lo, hi, NULL, NULL), HV_ERR_INVALID_ARG);

    TL_ASSERT_OK(hv_vdb_read_float_tiles(p, "sdf", lo, hi, &t, NULL));
    assert_error_names(hv_vdb_read_tiles_like(p, "nope", t, out, &nc), HV_ERR_INVALID_ARG,
                       "'nope'");
    ck_assert_int_eq(nc, 0);
    /* another voxel size, and a block a third of a voxel off the lattice */
    assert_error_names(hv_vdb_read_tiles_like(q, "vel", t, out, &nc), HV_ERR_INVALID_ARG, "'vel'");
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "transform"));
    ck_assert_ptr_null(out[0]);
    hv_tiles shifted = *t;
    shifted.origin[1] += t->h / 3;
    assert_error_names(hv_vdb_read_tiles_like(p, "vel", &shifted, out, &nc), HV_ERR_INVALID_ARG,
                       "'vel'");
    ck_assert_int_eq(nc, 0);
    /* a whole voxel off is another block of the same lattice */
    shifted.origin[1] += t->h * 2 / 3;
    TL_ASSERT_OK(hv_vdb_read_tiles_like(p, "sdf", &shifted, out, &nc));
    hv_tiles_destroy(&out[0]);

    /* vec3 tiles: the same tiles in the same order */
    hv_vdb_writer *w = NULL;
    TL_ASSERT_OK(hv_vdb_writer_create(&w));
    ck_assert_uint_ge(t->count, 2);
    hv_tiles fewer = *t, swapped = *t;
    fewer.count--;
    swapped.ijk = malloc(3 * t->count * sizeof *t->ijk);
    ck_assert_ptr_nonnull(swapped.ijk);
    memcpy(swapped.ijk, t->ijk, 3 * t->count * sizeof *t->ijk);
    for (int a = 0; a < 3; a++) {
        swapped.ijk[a] = t->ijk[3 + a];
        swapped.ijk[3 + a] = t->ijk[a];
    }
    assert_error_names(hv_vdb_writer_add_vec3_tiles(w, t, &fewer, t, "v"), HV_ERR_INVALID_ARG,
                       "'v'");
    assert_error_names(hv_vdb_writer_add_vec3_tiles(w, t, t, &swapped, "v"), HV_ERR_INVALID_ARG,
                       "same tiles");
    hv_tiles coarse = *t;
    coarse.h *= 2;
    assert_error_names(hv_vdb_writer_add_vec3_tiles(w, t, &coarse, t, "v"), HV_ERR_INVALID_ARG,
                       "voxel size");
    swapped.ijk[0] += 3;
    assert_error_names(hv_vdb_writer_add_float_tiles(w, &swapped, "s"), HV_ERR_INVALID_ARG,
                       "lattice");
    free(swapped.ijk);
    assert_error_names(hv_vdb_writer_add_float_tiles(w, NULL, "s"), HV_ERR_INVALID_ARG, "'s'");

    /* NaN: refused on an active voxel, of no concern on an inactive one */
    size_t on = SIZE_MAX, off = SIZE_MAX;
    for (size_t c = 0; c < t->count * CELLS && (on == SIZE_MAX || off == SIZE_MAX); c++) {
        const int bit = (int)(t->on[c / 64] >> (c % 64) & 1);
        if (bit && on == SIZE_MAX)
            on = c;
        if (!bit && off == SIZE_MAX)
            off = c;
    }
    ck_assert_uint_ne(on, SIZE_MAX);
    ck_assert_uint_ne(off, SIZE_MAX);
    const float keep = t->v[off];
    t->v[off] = NAN;
    TL_ASSERT_OK(hv_vdb_writer_add_float_tiles(w, t, "inactive_nan"));
    TL_ASSERT_OK(hv_vdb_writer_add_vec3_tiles(w, t, t, t, "inactive_nan3"));
    t->v[off] = keep;
    t->v[on] = INFINITY;
    assert_error_names(hv_vdb_writer_add_float_tiles(w, t, "active_inf"), HV_ERR_NUMERIC,
                       "'active_inf'");
    assert_error_names(hv_vdb_writer_add_vec3_tiles(w, t, t, t, "active_inf3"), HV_ERR_NUMERIC,
                       "'active_inf3'");
    hv_vdb_writer_destroy(&w);
    hv_tiles_destroy(&t);
}
END_TEST

int main(void)
{
    Suite *s = suite_create("vdb_tiles");
    TCase *tc = tcase_create("vdb_tiles");
    /* a scratch directory per test, removed even when the test fails */
    tcase_add_checked_fixture(tc, make_dir, remove_dir);
    tcase_set_timeout(tc, 120);
    tcase_add_test(tc, tiles_should_equal_the_dense_read_and_hold_every_active_voxel);
    tcase_add_test(tc, active_tree_tiles_should_make_every_voxel_of_theirs_active);
    tcase_add_test(tc, tiles_like_should_read_other_grids_as_the_dense_reader_does);
    tcase_add_test(tc, tiles_written_should_hold_their_active_voxels_in_openvdb_and_in_heatvox);
    tcase_add_test(tc, tiles_create_like_should_copy_the_block_and_tiles_with_one_value);
    tcase_add_test(tc,
                   tile_reads_and_writes_should_refuse_missing_grids_wrong_types_and_mismatches);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
