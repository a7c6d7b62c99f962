/*
 * The sparse narrow band (hv_sdf_compute_tiles): on every voxel of every tile
 * it equals the dense band (hv_sdf_compute with band_only and the winding
 * sign), bit for bit, on closed, defective, open and shared meshes and in
 * windows through a mesh; blocks far too large for the dense path run in
 * memory that follows the surface; the .vdb built from tiles reads back in
 * OpenVDB's own reader with the tiles' values, and equals the dense writer's
 * file voxel for voxel; the command uses tiles for a narrow band alone.
 */
#include "heatvox/heatvox.h"
#include "sdf_testutil.h"
#include "testlib.h"

#include <check.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Compares the tiles of m with the dense band under options o (band
 * half width `band`); fails on any difference. Returns the active voxels. */
static size_t check_against_dense(const hv_mesh *m, const hv_sdf_opts *o, double band,
                                  const char *what)
{
    hv_tiles *T = NULL;
    hv_sdf_stats S;
    hv_status st = hv_sdf_compute_tiles(m, o, band, &T, &S);
    ck_assert_msg(st == HV_OK, "%s: tiles: %s", what, hv_last_error());
    hv_sdf_opts d = *o;
    d.band_only = band;
    if (!d.unsigned_distance)
        d.sign = HV_SDF_SIGN_WINDING;
    hv_grid *g = NULL;
    st = hv_sdf_compute(m, &d, &g, NULL);
    ck_assert_msg(st == HV_OK, "%s: dense: %s", what, hv_last_error());
    for (int a = 0; a < 3; a++) {
        ck_assert_int_eq(T->n[a], g->n[a]);
        ck_assert_double_eq(T->origin[a], g->origin[a]);
    }
    ck_assert_double_eq(T->h, g->h);
    const float bg = (float)(band * g->h);
    size_t dense_active = 0;
    for (size_t c = 0; c < hv_grid_count(g); c++)
        dense_active += fabsf(g->v[c]) < bg;
    size_t active = 0, wrong = 0, first = SIZE_MAX;
    for (size_t q = 0; q < T->count; q++) {
        const int32_t *o3 = T->ijk + 3 * q;
        ck_assert(o3[0] % 8 == 0 && o3[1] % 8 == 0 && o3[2] % 8 == 0);
        /* Each tile once: the dense band counts every active voxel once. */
        for (int k = 0; k < 8; k++)
            for (int j = 0; j < 8; j++)
                for (int i = 0; i < 8; i++) {
                    const int o = i + 8 * (j + 8 * k);
                    const int on = (int)(T->on[8 * q + k] >> (i + 8 * j) & 1);
                    const float tv = T->v[512 * q + o];
                    const int x = o3[0] + i, y = o3[1] + j, z = o3[2] + k;
                    if (x >= g->n[0] || y >= g->n[1] || z >= g->n[2]) {
                        ck_assert_msg(!on && tv == bg, "%s: a voxel beyond the block", what);
                        continue;
                    }
                    const float dv = g->v[(size_t)x + (size_t)g->n[0] * (y + (size_t)g->n[1] * z)];
                    const int don = fabsf(dv) < bg;
                    active += on;
                    if (on != don || (on && tv != dv) || (!on && tv != bg)) {
                        if (first == SIZE_MAX)
                            first = (size_t)x + 100000 * ((size_t)y + 100000 * z);
                        wrong++;
                    }
                }
    }
    ck_assert_msg(wrong == 0, "%s: %zu voxels differ from the dense band (first at %zu)", what,
                  wrong, first);
    ck_assert_msg(active == dense_active && active == T->active && active == S.active_voxels,
                  "%s: %zu active voxels in tiles (%zu counted), %zu in the dense band", what,
                  active, T->active, dense_active);
    ck_assert_uint_eq(S.tiles, T->count);
    ck_assert_uint_gt(active, 0);
    hv_tiles_destroy(&T);
    hv_grid_destroy(&g);
    return active;
}

START_TEST(closed_and_defective_meshes_should_equal_the_dense_band)
{
    const double c[3] = {0.1, -0.2, 0.05};
    hv_mesh *sphere = NULL, *torus = NULL, *broken = NULL;
    TL_ASSERT_OK(hv_mesh_make_sphere(&sphere, c, 1.0, 4));
    TL_ASSERT_OK(hv_mesh_make_torus(&torus, c, 1.0, 0.35, 64, 24));
    TL_ASSERT_OK(hv_mesh_make_sphere(&broken, c, 1.0, 4));
    TL_ASSERT_OK(hv_mesh_defect_holes(broken, 3, 0.15, 7));
    TL_ASSERT_OK(hv_mesh_defect_flip(broken, 0.3, 8));
    TL_ASSERT_OK(hv_mesh_defect_duplicate(broken, 0.1, 9));
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    const double bands[3] = {3, 1.5, 4};
    const int res[3] = {48, 61, 80};
    for (int b = 0; b < 3; b++) {
        o.res = res[b];
        check_against_dense(sphere, &o, bands[b], "sphere");
        check_against_dense(torus, &o, bands[b], "torus");
        check_against_dense(broken, &o, bands[b], "sphere with holes, flips and duplicates");
    }
    /* Unsigned: the same distances, no sign. */
    o.res = 56;
    o.unsigned_distance = 1;
    check_against_dense(torus, &o, 3, "torus, unsigned");
    hv_mesh_destroy(&sphere);
    hv_mesh_destroy(&torus);
    hv_mesh_destroy(&broken);
}
END_TEST

START_TEST(open_meshes_and_windows_should_equal_the_dense_band)
{
    const double up[3] = {0, 0, 1};
    hv_mesh *cap = tu_open_sphere(up, 45), *cyl = tu_open_cylinder();
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = 64;
    check_against_dense(cap, &o, 3, "sphere with a cap cut off");
    check_against_dense(cyl, &o, 3, "open cylinder");
    /* A window through the middle of the mesh, on the lattice of a full run. */
    o.use_bbox = 1;
    const double box[6] = {-0.3, -1.2, -0.4, 1.2, 1.2, 0.5};
    memcpy(o.bbox, box, sizeof box);
    o.voxel_size = 1.0 / 24;
    check_against_dense(cap, &o, 3, "window through the open sphere");
    hv_mesh_destroy(&cap);
    hv_mesh_destroy(&cyl);
}
END_TEST

START_TEST(shared_meshes_should_equal_the_dense_band)
{
    const char *names[] = {"stanford-bunny.obj",
                           "bun_zipper_res4.ply",
                           "bunny_small.obj",
                           "armadillo_bad.obj",
                           "chair.obj",
                           "cow.obj",
                           "igea.ply",
                           "knot.obj",
                           "polygon-bear.obj",
                           "rocker.obj",
                           "spot.obj"};
    /* Under the sanitizers three small ones: holed, non-manifold and with
     * duplicate faces; closed; open with line records. The tiles take one
     * path whatever the mesh, and the tests above take it on closed,
     * defective and open meshes there too. */
    const int sanitized[] = {0, 1, 1, 0, 1, 0, 0, 0, 0, 0, 0};
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = 64;
    for (size_t k = 0; k < sizeof names / sizeof names[0]; k++) {
        if (tl_sanitized() && !sanitized[k])
            continue;
        hv_mesh *m = tu_load_shared(names[k]);
        if (!m)
            return;
        check_against_dense(m, &o, 3, names[k]);
        hv_mesh_destroy(&m);
    }
}
END_TEST

/* Three small spheres at the corners of a block of 2048^3 cells: the dense
 * path refuses it (hundreds of GB); the tiles hold only the spheres' bands. */
START_TEST(block_far_too_large_for_the_dense_grid_should_run_in_tiles)
{
    double *V = NULL;
    uint32_t *T = NULL;
    size_t nv = 0, nt = 0;
    const double at[3][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 1}};
    for (int s = 0; s < 3; s++) {
        hv_mesh *b = NULL;
        TL_ASSERT_OK(hv_mesh_make_sphere(&b, at[s], 0.004, 2));
        V = realloc(V, 3 * (nv + b->nverts) * sizeof *V);
        T = realloc(T, 3 * (nt + b->ntris) * sizeof *T);
        memcpy(V + 3 * nv, b->verts, 3 * b->nverts * sizeof *V);
        for (size_t i = 0; i < 3 * b->ntris; i++)
            T[3 * nt + i] = b->tris[i] + (uint32_t)nv;
        nv += b->nverts;
        nt += b->ntris;
        hv_mesh_destroy(&b);
    }
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_from_arrays(&m, V, nv, T, nt));
    free(V);
    free(T);
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = 2048;
    hv_grid *g = NULL;
    ck_assert_int_eq(hv_sdf_compute(m, &o, &g, NULL), HV_ERR_NOMEM);
    size_t before = hv_peak_rss();
    hv_tiles *tiles = NULL;
    hv_sdf_stats S;
    TL_ASSERT_OK(hv_sdf_compute_tiles(m, &o, 3, &tiles, &S));
    ck_assert_int_ge(S.n[0], 2048);
    /* Each sphere, 8 voxels across, with its band fits in a few 8^3 tiles. */
    ck_assert_uint_le(tiles->count, 3 * 27);
    ck_assert_uint_gt(tiles->active, 3 * 200);
    ck_assert_msg(hv_peak_rss() < before + ((size_t)64 << 20),
                  "peak RSS grew by %zu MB for %zu tiles", (hv_peak_rss() - before) >> 20,
                  tiles->count);
    /* Inside the first sphere: its centre's voxel is negative. */
    int found = 0;
    for (size_t q = 0; q < tiles->count; q++)
        for (int c = 0; c < 512; c++)
            found |= tiles->v[512 * q + c] < -(float)(2 * S.h);
    ck_assert_msg(found, "no voxel two voxels deep inside a sphere");
    hv_tiles_destroy(&tiles);
    hv_mesh_destroy(&m);
}
END_TEST

START_TEST(tiles_should_refuse_what_needs_the_dense_grid)
{
    const double c[3] = {0, 0, 0};
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_make_sphere(&m, c, 1.0, 2));
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = 32;
    hv_tiles *T = NULL;
    ck_assert_int_eq(hv_sdf_compute_tiles(m, &o, 3, NULL, NULL), HV_ERR_INVALID_ARG);
    ck_assert_int_eq(hv_sdf_compute_tiles(m, &o, 0, &T, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_null(T);
    o.magnitude = HV_SDF_HEAT;
    ck_assert_int_eq(hv_sdf_compute_tiles(m, &o, 3, &T, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "dense"));
    o.magnitude = HV_SDF_EXACT;
    o.sign = HV_SDF_SIGN_HEAT;
    ck_assert_int_eq(hv_sdf_compute_tiles(m, &o, 3, &T, NULL), HV_ERR_INVALID_ARG);
    o.sign = HV_SDF_SIGN_AUTO;
    o.repair = 0;
    ck_assert_int_eq(hv_sdf_compute_tiles(m, &o, 3, &T, NULL), HV_ERR_INVALID_ARG);
    o.repair = HV_SDF_REPAIR_ALL;
    /* A block that misses the mesh and its band. */
    o.use_bbox = 1;
    const double far[6] = {5, 5, 5, 6, 6, 6};
    memcpy(o.bbox, far, sizeof far);
    ck_assert_int_eq(hv_sdf_compute_tiles(m, &o, 3, &T, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "block"));
    ck_assert_ptr_null(T);
    hv_tiles_destroy(&T);
    hv_tiles_destroy(NULL);
    hv_mesh_destroy(&m);
}
END_TEST

/* The one rule (hv_sdf_tiles_refusal) is what the library does: the tiles
 * refuse exactly the options it names, and accept the rest; as a level set
 * (the command's and batch's .vdb) it also names an unsigned distance. */
START_TEST(the_tile_rule_should_be_what_the_library_does)
{
    const double c[3] = {0, 0, 0};
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_make_sphere(&m, c, 1.0, 2));
    for (int v = 0; v < 9; v++) {
        hv_sdf_opts o;
        hv_sdf_opts_default(&o);
        o.res = 24;
        int refused = 1, levelset_refused = 1;
        switch (v) {
        case 0: refused = levelset_refused = 0; break;
        case 1: o.magnitude = HV_SDF_HEAT; break;
        case 2: o.sign = HV_SDF_SIGN_HEAT; break;
        case 3: o.repair = HV_SDF_REPAIR_ORIENT; break;
        case 4: o.close = 0.1; break;
        case 5: o.open = 0.1; break;
        case 6: o.unsigned_distance = 1, refused = 0; break;
        case 7: o.unsigned_distance = 1, o.sign = HV_SDF_SIGN_HEAT, refused = 0; break;
        case 8:
            o.sign = HV_SDF_SIGN_WINDING, o.offset = 0.05, refused = levelset_refused = 0;
            break;
        }
        const char *why = hv_sdf_tiles_refusal(&o, 0), *why_ls = hv_sdf_tiles_refusal(&o, 1);
        ck_assert_msg((why != NULL) == refused, "case %d: %s", v, why ? why : "accepted");
        ck_assert_msg((why_ls != NULL) == levelset_refused, "case %d (level set): %s", v,
                      why_ls ? why_ls : "accepted");
        hv_tiles *T = NULL;
        hv_status st = hv_sdf_compute_tiles(m, &o, 3, &T, NULL);
        ck_assert_msg(st == (refused ? HV_ERR_INVALID_ARG : HV_OK), "case %d: status %d: %s", v,
                      (int)st, hv_last_error());
        if (refused)
            ck_assert_msg(strstr(hv_last_error(), why), "case %d: %s", v, hv_last_error());
        hv_tiles_destroy(&T);
    }
    hv_mesh_destroy(&m);
}
END_TEST

/* The whole of a text file (malloc'd), or NULL. */
static char *read_text(const char *path)
{
    FILE *f = fopen(path, "rb");
    if (!f)
        return NULL;
    char *s = malloc(1 << 16);
    size_t n = s ? fread(s, 1, (1 << 16) - 1, f) : 0;
    fclose(f);
    if (s)
        s[n] = 0;
    return s;
}

/* The command and batch ask the same rule: a signed band goes to tiles, an
 * unsigned one (a dense grid of class unknown) does not. */
START_TEST(command_and_batch_should_share_the_tile_rule)
{
    char dir[] = "/tmp/hv_tiles_rule_XXXXXX", cmd[4096], err[8192];
    ck_assert_ptr_nonnull(mkdtemp(dir));
    const double c[3] = {0, 0, 0};
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_make_sphere(&m, c, 1.0, 3));
    char mesh[256];
    snprintf(mesh, sizeof mesh, "%s/s.obj", dir);
    TL_ASSERT_OK(hv_mesh_write_obj(m, mesh));
    hv_mesh_destroy(&m);
    const char *flags[2] = {"", "--unsigned"};
    for (int u = 0; u < 2; u++) {
        snprintf(cmd, sizeof cmd, "cd %s && %s sdf s.obj --res 32 -o s%d.vdb -v %s", dir,
                 tl_heatvox_bin(), u, flags[u]);
        ck_assert_msg(tl_run_cmd(cmd, dir, err, sizeof err) == 0, "%s: %s", cmd, err);
        ck_assert_msg(!strstr(err, "tiles of 8^3") == u, "%s: %s", cmd, err);
        snprintf(cmd, sizeof cmd,
                 "cd %s && %s batch s.obj -o out%d --res 32 --report r%d.json -q %s", dir,
                 tl_heatvox_bin(), u, u, flags[u]);
        ck_assert_msg(tl_run_cmd(cmd, dir, err, sizeof err) == 0, "%s: %s", cmd, err);
        char rep[512], *text = NULL;
        snprintf(rep, sizeof rep, "%s/r%d.json", dir, u);
        text = read_text(rep);
        ck_assert_ptr_nonnull(text);
        ck_assert_msg(!strstr(text, "\"tiles\":") == u, "batch %s: %s", flags[u], text);
        free(text);
    }
    tl_rm_rf(dir);
}
END_TEST

/* The .vdb from tiles: OpenVDB's Python reader finds exactly the tiles'
 * active voxels and values, -background at the centre and +background far
 * out; heatvox's reader gives the dense writer's values on every voxel of
 * the block, flood-filled signs included. */
START_TEST(vdb_from_tiles_should_read_back_and_equal_the_dense_file)
{
    ck_assert_msg(system("/usr/bin/python3 -c 'import pyopenvdb' >/dev/null 2>&1") == 0,
                  "pyopenvdb does not import in /usr/bin/python3 (package python3-openvdb)");
    const double c[3] = {0, 0, 0};
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_make_torus(&m, c, 1.0, 0.4, 48, 20));
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = 40;
    hv_tiles *T = NULL;
    TL_ASSERT_OK(hv_sdf_compute_tiles(m, &o, 3, &T, NULL));
    hv_grid *g = NULL;
    o.band_only = 3;
    o.sign = HV_SDF_SIGN_WINDING;
    TL_ASSERT_OK(hv_sdf_compute(m, &o, &g, NULL));
    char dir[] = "/tmp/hv_tiles_XXXXXX", pt[256], pd[256], cmd[2048];
    ck_assert_ptr_nonnull(mkdtemp(dir));
    snprintf(pt, sizeof pt, "%s/tiles.vdb", dir);
    snprintf(pd, sizeof pd, "%s/dense.vdb", dir);
    hv_vdb_writer *w = NULL;
    TL_ASSERT_OK(hv_vdb_writer_create(&w));
    TL_ASSERT_OK(hv_vdb_writer_add_levelset_tiles(w, T, "sdf", 3));
    ck_assert_int_eq(hv_vdb_writer_add_levelset_tiles(w, T, "sdf", 3), HV_ERR_INVALID_ARG);
    ck_assert_int_eq(hv_vdb_writer_add_levelset_tiles(w, NULL, "t2", 3), HV_ERR_INVALID_ARG);
    ck_assert_int_eq(hv_vdb_writer_add_levelset_tiles(w, T, "t3", 0), HV_ERR_INVALID_ARG);
    TL_ASSERT_OK(hv_vdb_writer_write(w, pt));
    hv_vdb_writer_destroy(&w);
    TL_ASSERT_OK(hv_vdb_writer_create(&w));
    TL_ASSERT_OK(hv_vdb_writer_add_levelset(w, g, "sdf", 3, 0));
    TL_ASSERT_OK(hv_vdb_writer_write(w, pd));
    hv_vdb_writer_destroy(&w);

    /* OpenVDB's reader: every active voxel, then two inactive ones. */
    const int mid[3] = {g->n[0] / 2, g->n[1] / 2, g->n[2] / 2};
    int ring[3] = {0, mid[1], mid[2]};
    for (int i = 0; i < g->n[0]; i++) {
        float v = g->v[(size_t)i + (size_t)g->n[0] * (mid[1] + (size_t)g->n[1] * mid[2])];
        if (v < -(float)(3 * g->h)) {
            ring[0] = i; /* deep inside the tube, beyond the band */
            break;
        }
    }
    snprintf(cmd, sizeof cmd,
             "/usr/bin/python3 -c 'import sys, pyopenvdb as vdb\n"
             "g = vdb.read(sys.argv[1], \"sdf\")\n"
             "print(g.gridClass, repr(g.background))\n"
             "n = 0\n"
             "for it in g.citerOnValues():\n"
             "    assert it.count == 1\n"
             "    print(it.min[0], it.min[1], it.min[2], repr(it.value))\n"
             "a = g.getConstAccessor()\n"
             "print(\"inside\", repr(a.getValue((%d, %d, %d))))\n"
             "print(\"outside\", repr(a.getValue((0, 0, 0))))\n"
             "' %s",
             ring[0], ring[1], ring[2], pt);
    FILE *pp = popen(cmd, "r");
    ck_assert_ptr_nonnull(pp);
    char line[256];
    ck_assert_ptr_nonnull(fgets(line, sizeof line, pp));
    const float bg = (float)(3 * g->h);
    double back;
    ck_assert_int_eq(sscanf(line, "level set %lf", &back), 1);
    ck_assert_float_eq((float)back, bg);
    size_t seen = 0, wrong = 0;
    while (fgets(line, sizeof line, pp)) {
        int x, y, z;
        double v;
        if (sscanf(line, "%d %d %d %lf", &x, &y, &z, &v) == 4) {
            seen++;
            float want = g->v[(size_t)x + (size_t)g->n[0] * (y + (size_t)g->n[1] * z)];
            wrong += !(fabsf(want) < bg) || (float)v != want;
        } else if (sscanf(line, "inside %lf", &v) == 1) {
            ck_assert_float_eq((float)v, -bg);
        } else if (sscanf(line, "outside %lf", &v) == 1) {
            ck_assert_float_eq((float)v, bg);
        }
    }
    ck_assert_int_eq(pclose(pp), 0);
    ck_assert_msg(wrong == 0, "%zu of %zu voxels read by pyopenvdb differ", wrong, seen);
    ck_assert_uint_eq(seen, T->active);

    /* heatvox's reader: the whole block of both files. */
    hv_grid *a = NULL, *b = NULL;
    TL_ASSERT_OK(hv_vdb_read_float(pt, "sdf", NULL, &a, NULL));
    TL_ASSERT_OK(hv_vdb_read_float(pd, "sdf", NULL, &b, NULL));
    ck_assert_int_eq(hv_grid_count(a), hv_grid_count(b));
    size_t diff = 0;
    for (size_t q = 0; q < hv_grid_count(a); q++)
        diff += a->v[q] != b->v[q];
    ck_assert_msg(diff == 0, "%zu voxels of the block differ between the tiles' and the dense file",
                  diff);
    hv_grid_destroy(&a);
    hv_grid_destroy(&b);
    hv_tiles_destroy(&T);
    hv_grid_destroy(&g);
    hv_mesh_destroy(&m);
    tl_rm_rf(dir);
}
END_TEST

/* heatvox sdf: a narrow band goes through tiles (-v says so), and
 * --no-tiles writes the same values from the dense block, and the same
 * preview. */
START_TEST(command_should_use_tiles_for_a_narrow_band)
{
    char dir[] = "/tmp/hv_tiles_cli_XXXXXX", cmd[4096], err[4096];
    ck_assert_ptr_nonnull(mkdtemp(dir));
    const double c[3] = {0, 0, 0};
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_make_torus(&m, c, 1.0, 0.3, 48, 20));
    char mesh[256];
    snprintf(mesh, sizeof mesh, "%s/torus.obj", dir);
    TL_ASSERT_OK(hv_mesh_write_obj(m, mesh));
    hv_mesh_destroy(&m);
    snprintf(cmd, sizeof cmd, "cd %s && %s sdf torus.obj --res 48 -o t.vdb --preview t.png -v", dir,
             tl_heatvox_bin());
    ck_assert_msg(tl_run_cmd(cmd, dir, err, sizeof err) == 0, "%s: %s", cmd, err);
    ck_assert_msg(strstr(err, "tiles of 8^3"), "-v does not report the tiles: %s", err);
    snprintf(
        cmd, sizeof cmd,
        "cd %s && %s sdf torus.obj --res 48 -o d.vdb --preview d.png --no-tiles --sign winding "
        "-q",
        dir, tl_heatvox_bin());
    ck_assert_msg(tl_run_cmd(cmd, dir, err, sizeof err) == 0, "%s: %s", cmd, err);
    char pt[512], pd[512];
    snprintf(pt, sizeof pt, "%s/t.vdb", dir);
    snprintf(pd, sizeof pd, "%s/d.vdb", dir);
    hv_grid *a = NULL, *b = NULL;
    TL_ASSERT_OK(hv_vdb_read_float(pt, "sdf", NULL, &a, NULL));
    TL_ASSERT_OK(hv_vdb_read_float(pd, "sdf", NULL, &b, NULL));
    ck_assert_int_eq(hv_grid_count(a), hv_grid_count(b));
    size_t diff = 0, band = 0;
    for (size_t q = 0; q < hv_grid_count(a); q++) {
        diff += a->v[q] != b->v[q];
        band += fabsf(a->v[q]) < (float)(3 * a->h);
    }
    ck_assert_uint_eq(diff, 0);
    ck_assert_uint_gt(band, 1000);
    hv_grid_destroy(&a);
    hv_grid_destroy(&b);
    /* The preview of the tiles' run (three slices computed alone) shows what
     * the dense block holds. */
    uint8_t *pa = NULL, *pb = NULL;
    int wa, ha, wb, hb;
    snprintf(pt, sizeof pt, "%s/t.png", dir);
    snprintf(pd, sizeof pd, "%s/d.png", dir);
    TL_ASSERT_OK(hv_png_read_rgb(pt, &pa, &wa, &ha));
    TL_ASSERT_OK(hv_png_read_rgb(pd, &pb, &wb, &hb));
    ck_assert_int_eq(wa, wb);
    ck_assert_int_eq(ha, hb);
    int worst = 0;
    for (size_t q = 0; q < 3 * (size_t)wa * ha; q++)
        worst = abs(pa[q] - pb[q]) > worst ? abs(pa[q] - pb[q]) : worst;
    ck_assert_msg(worst <= 2, "previews differ by up to %d levels", worst);
    free(pa);
    free(pb);
    tl_rm_rf(dir);
}
END_TEST

int main(void)
{
    Suite *s = suite_create("sdf_tiles");
    TCase *tc = tcase_create("core");
    tcase_set_timeout(tc, 300);
    tcase_add_test(tc, closed_and_defective_meshes_should_equal_the_dense_band);
    tcase_add_test(tc, open_meshes_and_windows_should_equal_the_dense_band);
    tcase_add_test(tc, shared_meshes_should_equal_the_dense_band);
    tcase_add_test(tc, block_far_too_large_for_the_dense_grid_should_run_in_tiles);
    tcase_add_test(tc, tiles_should_refuse_what_needs_the_dense_grid);
    tcase_add_test(tc, the_tile_rule_should_be_what_the_library_does);
    tcase_add_test(tc, command_and_batch_should_share_the_tile_rule);
    tcase_add_test(tc, vdb_from_tiles_should_read_back_and_equal_the_dense_file);
    tcase_add_test(tc, command_should_use_tiles_for_a_narrow_band);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
