/*
 * A narrow band streamed into the .vdb (hv_sdf_stream_tiles into
 * hv_vdb_writer_levelset_sink): batches of any size give the tiles that
 * hv_sdf_compute_tiles gives, the file equals the one written from all the
 * tiles at once byte for byte (and the bytes of OpenVDB's own serial
 * writer), on the aligned lattice and shifted off it; a failing sink stops
 * the run and is told so once; the writer takes no half-built grid.
 */
#include "heatvox/heatvox.h"
#include "testlib.h"

#include <check.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static hv_mesh *torus(void)
{
    const double c[3] = {0.1, -0.2, 0.05};
    hv_mesh *m = NULL;
    TL_ASSERT_OK(hv_mesh_make_torus(&m, c, 1.0, 0.35, 48, 20));
    return m;
}

static void options(hv_sdf_opts *o)
{
    hv_sdf_opts_default(o);
    o->res = 56;
}

static void set_batch(const char *b)
{
    if (b)
        setenv("HEATVOX_TILE_BATCH", b, 1);
    else
        unsetenv("HEATVOX_TILE_BATCH");
}

static void assert_same_tiles(const hv_tiles *a, const hv_tiles *b, const char *what)
{
    ck_assert_msg(a->count == b->count, "%s: %zu tiles against %zu", what, a->count, b->count);
    ck_assert_uint_eq(a->active, b->active);
    ck_assert_msg(!memcmp(a->ijk, b->ijk, 3 * a->count * sizeof *a->ijk), "%s: tile order", what);
    ck_assert_msg(!memcmp(a->v, b->v, 512 * a->count * sizeof *a->v), "%s: values", what);
    ck_assert_msg(!memcmp(a->on, b->on, 8 * a->count * sizeof *a->on), "%s: active bits", what);
}

/* Batches of 1, 5 and 64 tiles and the default: the same tiles, in the same
 * order, bit for bit (the collected tiles go through the same batches). */
START_TEST(batches_of_any_size_should_give_the_same_tiles)
{
    hv_mesh *m = torus();
    hv_sdf_opts o;
    options(&o);
    hv_tiles *ref = NULL;
    hv_sdf_stats S;
    set_batch("100000000");
    TL_ASSERT_OK(hv_sdf_compute_tiles(m, &o, 3, &ref, &S));
    ck_assert_uint_gt(ref->count, 100);
    const char *sizes[] = {"1", "5", "64", NULL};
    for (int k = 0; k < 4; k++) {
        set_batch(sizes[k]);
        hv_tiles *t = NULL;
        TL_ASSERT_OK(hv_sdf_compute_tiles(m, &o, 3, &t, &S));
        assert_same_tiles(ref, t, sizes[k] ? sizes[k] : "default");
        if (sizes[k])
            ck_assert_uint_le(S.tiles_in_flight, (size_t)atoi(sizes[k]) + 7);
        hv_tiles_destroy(&t);
    }
    set_batch(NULL);
    hv_tiles_destroy(&ref);
    hv_mesh_destroy(&m);
}
END_TEST

/* The file's bytes, the 36-byte UUID of the header (after the magic, the
 * versions and the offsets flag: bytes 21..56) blanked. */
static char *file_bytes(const char *path, size_t *n)
{
    FILE *f = fopen(path, "rb");
    ck_assert_msg(f != NULL, "%s does not open", path);
    fseek(f, 0, SEEK_END);
    *n = (size_t)ftell(f);
    fseek(f, 0, SEEK_SET);
    char *b = malloc(*n);
    ck_assert_ptr_nonnull(b);
    ck_assert_uint_eq(fread(b, 1, *n, f), *n);
    fclose(f);
    ck_assert_uint_gt(*n, 57);
    memset(b + 21, 0, 36);
    return b;
}

static void assert_same_file(const char *a, const char *b)
{
    size_t na, nb;
    char *x = file_bytes(a, &na), *y = file_bytes(b, &nb);
    ck_assert_msg(na == nb, "%s has %zu bytes, %s %zu", a, na, b, nb);
    size_t first = na;
    for (size_t i = 0; i < na && first == na; i++)
        if (x[i] != y[i])
            first = i;
    ck_assert_msg(first == na, "%s and %s differ from byte %zu", a, b, first);
    free(x);
    free(y);
}

/* Writes m's band to path: streamed in batches of `batch` tiles, or from
 * all the tiles at once; index origin shifted by `shift` voxels when not
 * NULL. */
static void write_band(const hv_mesh *m, const char *path, const char *batch, int streamed,
                       const int *shift)
{
    hv_sdf_opts o;
    options(&o);
    set_batch(batch);
    hv_vdb_writer *w = NULL;
    TL_ASSERT_OK(hv_vdb_writer_create(&w));
    if (shift) {
        int n[3];
        double h, origin[3];
        TL_ASSERT_OK(hv_sdf_grid_for_mesh(m, &o, n, &h, origin));
        const double at[3] = {origin[0] + (0.5 - shift[0]) * h, origin[1] + (0.5 - shift[1]) * h,
                              origin[2] + (0.5 - shift[2]) * h};
        TL_ASSERT_OK(hv_vdb_writer_set_index_origin(w, at));
    }
    if (streamed) {
        hv_tiles_sink sink;
        hv_vdb_sink_stats vs;
        hv_sdf_stats S;
        TL_ASSERT_OK(hv_vdb_writer_levelset_sink(w, "sdf", 3, &vs, &sink));
        TL_ASSERT_OK(hv_sdf_stream_tiles(m, &o, 3, &sink, &S));
        ck_assert_uint_eq(vs.tiles, S.tiles);
        if (!shift) {
            ck_assert_uint_eq(vs.leaves, S.tiles); /* one leaf a tile on the lattice */
            const char *serial = getenv("HEATVOX_VDB_SERIAL_WRITE");
            /* packed, each about 1 kB, but with OpenVDB's own writer */
            ck_assert_uint_eq(vs.packed_leaves, serial ? 0 : vs.leaves);
            ck_assert(serial ? vs.packed_bytes == 0
                             : vs.packed_bytes > 100.0 * vs.leaves &&
                                   vs.packed_bytes < 2100.0 * vs.leaves);
        } else {
            ck_assert_uint_eq(vs.packed_leaves, 0); /* a leaf spans batches */
        }
        ck_assert_uint_ge(vs.batches, batch ? S.tiles / (size_t)atoi(batch) / 8 : 1);
        ck_assert(vs.tree_bytes > 0 && vs.tree_bytes <= vs.tree_bytes_bound * 1.25);
    } else {
        hv_tiles *t = NULL;
        TL_ASSERT_OK(hv_sdf_compute_tiles(m, &o, 3, &t, NULL));
        TL_ASSERT_OK(hv_vdb_writer_add_levelset_tiles(w, t, "sdf", 3));
        hv_tiles_destroy(&t);
    }
    TL_ASSERT_OK(hv_vdb_writer_set_meta(w, "source", "torus"));
    TL_ASSERT_OK(hv_vdb_writer_write(w, path));
    hv_vdb_writer_destroy(&w);
    set_batch(NULL);
}

/* Streamed in batches of 3 tiles, or all at once, or all at once through
 * OpenVDB's own flood fill and serial writer (leaves not packed): the same
 * bytes. */
START_TEST(streamed_file_should_equal_the_file_of_all_tiles_byte_for_byte)
{
    char dir[] = "/tmp/hv_vdb_stream_XXXXXX", a[256], b[256], c[256], d[256];
    ck_assert_ptr_nonnull(mkdtemp(dir));
    snprintf(a, sizeof a, "%s/streamed.vdb", dir);
    snprintf(b, sizeof b, "%s/whole.vdb", dir);
    snprintf(c, sizeof c, "%s/serial.vdb", dir);
    snprintf(d, sizeof d, "%s/serial_streamed.vdb", dir);
    hv_mesh *m = torus();
    write_band(m, a, "3", 1, NULL);
    write_band(m, b, NULL, 0, NULL);
    setenv("HEATVOX_VDB_SERIAL_WRITE", "1", 1);
    write_band(m, c, NULL, 0, NULL);
    write_band(m, d, "3", 1, NULL);
    unsetenv("HEATVOX_VDB_SERIAL_WRITE");
    assert_same_file(a, b);
    assert_same_file(b, c);
    assert_same_file(c, d);
    hv_mesh_destroy(&m);
    tl_rm_rf(dir);
}
END_TEST

/* Off the 8^3 lattice a tile meets up to 8 leaves, and a leaf gets voxels
 * from tiles of different batches: the grid is still the one of all the
 * tiles at once. */
START_TEST(streamed_file_off_the_leaf_lattice_should_equal_the_whole_one)
{
    char dir[] = "/tmp/hv_vdb_stream_XXXXXX", a[256], b[256];
    ck_assert_ptr_nonnull(mkdtemp(dir));
    snprintf(a, sizeof a, "%s/streamed.vdb", dir);
    snprintf(b, sizeof b, "%s/whole.vdb", dir);
    hv_mesh *m = torus();
    const int shift[3] = {3, -5, 11};
    write_band(m, a, "2", 1, shift);
    write_band(m, b, NULL, 0, shift);
    hv_grid *ga = NULL, *gb = NULL;
    TL_ASSERT_OK(hv_vdb_read_float(a, "sdf", NULL, &ga, NULL));
    TL_ASSERT_OK(hv_vdb_read_float(b, "sdf", NULL, &gb, NULL));
    ck_assert_int_eq(hv_grid_count(ga), hv_grid_count(gb));
    size_t diff = 0, band = 0;
    for (size_t q = 0; q < hv_grid_count(ga); q++) {
        diff += ga->v[q] != gb->v[q];
        band += ga->v[q] < 0;
    }
    ck_assert_msg(diff == 0, "%zu voxels differ", diff);
    ck_assert_uint_gt(band, 1000);
    for (int k = 0; k < 3; k++)
        ck_assert_double_eq_tol(ga->origin[k], gb->origin[k], 1e-12);
    hv_grid_destroy(&ga);
    hv_grid_destroy(&gb);
    hv_mesh_destroy(&m);
    tl_rm_rf(dir);
}
END_TEST

/* Four hand-made tiles in two columns 8192 voxels apart along z, so in two
 * 4096^3 nodes of the root. Column (0, 0) goes from outside to inside along
 * z at the bottom and back at the top, column (0, 8) the other way round;
 * the voxels 3.5 voxels off the surface are beyond the band and inactive.
 * Packed leaves keep only their signs for the flood fill of the levels
 * above them: the file must be OpenVDB's own (its flood fill from the
 * values, its writer), byte for byte, with the root's inside tile between
 * the columns. */
static void write_columns(const char *path)
{
    enum { NT = 4 };
    int32_t ijk[3 * NT] = {0, 0, 0, 0, 0, 8192, 0, 8, 0, 0, 8, 8192};
    static float v[512 * NT];
    static uint64_t on[8 * NT];
    const double h = 0.01;
    for (int q = 0; q < NT; q++) {
        const double s = (q == 0 || q == 3) ? 1 : -1; /* outside below: +1 */
        for (int c = 0; c < 512; c++)
            v[512 * q + c] = (float)(s * (3.5 - c / 64) * h);
        for (int k = 0; k < 8; k++)
            on[8 * q + k] = ~(uint64_t)0;
    }
    hv_tiles t = {
        .n = {8, 16, 8200}, .h = h, .count = NT, .ijk = ijk, .v = v, .on = on, .active = 512 * NT};
    hv_vdb_writer *w = NULL;
    TL_ASSERT_OK(hv_vdb_writer_create(&w));
    TL_ASSERT_OK(hv_vdb_writer_add_levelset_tiles(w, &t, "sdf", 3));
    TL_ASSERT_OK(hv_vdb_writer_write(w, path));
    hv_vdb_writer_destroy(&w);
}

static float at(const hv_grid *g, int i, int j, int k)
{
    return g->v[i + (size_t)g->n[0] * (j + (size_t)g->n[1] * k)];
}

START_TEST(packed_leaves_should_flood_fill_every_level_as_openvdb_does)
{
    char dir[] = "/tmp/hv_vdb_stream_XXXXXX", a[256], b[256];
    ck_assert_ptr_nonnull(mkdtemp(dir));
    snprintf(a, sizeof a, "%s/packed.vdb", dir);
    snprintf(b, sizeof b, "%s/serial.vdb", dir);
    write_columns(a);
    setenv("HEATVOX_VDB_SERIAL_WRITE", "1", 1);
    write_columns(b);
    unsetenv("HEATVOX_VDB_SERIAL_WRITE");
    assert_same_file(a, b);
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_vdb_read_float(a, "sdf", NULL, &g, NULL));
    ck_assert_int_eq(g->n[2], 8200);
    const float bg = (float)(3 * 0.01);
    ck_assert_float_eq(at(g, 0, 0, 6000), -bg); /* the root's tile */
    ck_assert_float_eq(at(g, 0, 0, 0), bg);     /* beyond the band */
    ck_assert_float_eq(at(g, 0, 8, 0), -bg);
    ck_assert_float_eq(at(g, 0, 0, 2), (float)(1.5 * 0.01)); /* active */
    hv_grid_destroy(&g);
    tl_rm_rf(dir);
}
END_TEST

/* A sink that fails at its third batch, counting its calls and keeping
 * the bound begin was told. */
typedef struct {
    int begins, puts, ends, last_ok;
    size_t bound;
} counting;

static hv_status count_begin(void *u, const hv_tiles *b, size_t max_tiles)
{
    counting *c = u;
    c->begins++;
    c->bound = max_tiles;
    ck_assert_int_eq(b->count, 0);
    return HV_OK;
}

static hv_status count_put(void *u, const hv_tiles *b)
{
    counting *c = u;
    ck_assert_uint_gt(b->count, 0);
    return ++c->puts == 3 ? HV_ERR_IO : HV_OK;
}

static hv_status count_end(void *u, int ok)
{
    counting *c = u;
    c->ends++;
    c->last_ok = ok;
    return HV_OK;
}

/* The sink's failure stops the run with its status, end(0) once; a run
 * that fails before begin (a bad band, a block far from the mesh) still
 * ends the sink once; a second vdb sink is refused while the first is
 * taking tiles; and one whose run failed leaves the writer without the
 * grid, ready for another. */
START_TEST(failing_sink_should_stop_the_run_and_hear_of_it_once)
{
    hv_mesh *m = torus();
    hv_sdf_opts o;
    options(&o);
    set_batch("4");
    counting c = {0};
    hv_tiles_sink sink = {&c, count_begin, count_put, count_end};
    ck_assert_int_eq(hv_sdf_stream_tiles(m, &o, 3, &sink, NULL), HV_ERR_IO);
    ck_assert(c.begins == 1 && c.puts == 3 && c.ends == 1 && c.last_ok == 0);
    ck_assert_uint_gt(c.bound, 3 * 4);
    hv_tiles_sink partial = {&c, count_begin, NULL, count_end};
    ck_assert_int_eq(hv_sdf_stream_tiles(m, &o, 3, &partial, NULL), HV_ERR_INVALID_ARG);
    ck_assert_int_eq(hv_sdf_stream_tiles(m, &o, 0, &sink, NULL), HV_ERR_INVALID_ARG);
    ck_assert(c.begins == 1 && c.ends == 2 && c.last_ok == 0);

    /* A block that a triangle's box and plane reach but its band does not:
     * begun with a bound of 0, no tile put, ended with 0. */
    const double V[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    const uint32_t F[3] = {0, 1, 2};
    hv_mesh *tri = NULL;
    TL_ASSERT_OK(hv_mesh_from_arrays(&tri, V, 3, F, 1));
    hv_sdf_opts t;
    hv_sdf_opts_default(&t);
    t.res = 0;
    t.voxel_size = 0.01;
    t.use_bbox = 1;
    const double corner[6] = {0.8, 0.8, -0.05, 1.0, 1.0, 0.05};
    memcpy(t.bbox, corner, sizeof corner);
    counting d = {0};
    hv_tiles_sink none = {&d, count_begin, count_put, count_end};
    ck_assert_int_eq(hv_sdf_stream_tiles(tri, &t, 3, &none, NULL), HV_ERR_INVALID_ARG);
    ck_assert_msg(strstr(hv_last_error(), "narrow band lies inside the grid block"), "%s",
                  hv_last_error());
    ck_assert(d.begins == 1 && d.bound == 0 && d.puts == 0 && d.ends == 1 && d.last_ok == 0);
    hv_mesh_destroy(&tri);

    hv_vdb_writer *w = NULL;
    TL_ASSERT_OK(hv_vdb_writer_create(&w));
    hv_tiles_sink vs;
    TL_ASSERT_OK(hv_vdb_writer_levelset_sink(w, "sdf", 3, NULL, &vs));
    hv_tiles_sink again;
    ck_assert_int_eq(hv_vdb_writer_levelset_sink(w, "sdf", 0, NULL, &again), HV_ERR_INVALID_ARG);
    ck_assert_int_eq(hv_vdb_writer_levelset_sink(w, "other", 3, NULL, &again), HV_ERR_INVALID_ARG);
    ck_assert_msg(strstr(hv_last_error(), "still taking level set 'sdf'"), "%s", hv_last_error());
    /* A block far from the mesh: no band voxel in it. */
    o.res = 0;
    o.voxel_size = 0.05;
    o.use_bbox = 1;
    const double box[6] = {5, 5, 5, 6, 6, 6};
    memcpy(o.bbox, box, sizeof box);
    hv_status st = hv_sdf_stream_tiles(m, &o, 3, &vs, NULL);
    ck_assert_int_ne(st, HV_OK);
    char path[] = "/tmp/hv_vdb_stream_XXXXXX";
    ck_assert_ptr_nonnull(mkdtemp(path));
    char file[256];
    snprintf(file, sizeof file, "%s/none.vdb", path);
    ck_assert_int_eq(hv_vdb_writer_write(w, file), HV_ERR_INVALID_ARG); /* no grid */
    /* The writer takes a new sink, and that one's grid. */
    options(&o);
    TL_ASSERT_OK(hv_vdb_writer_levelset_sink(w, "sdf", 3, NULL, &vs));
    TL_ASSERT_OK(hv_sdf_stream_tiles(m, &o, 3, &vs, NULL));
    TL_ASSERT_OK(hv_vdb_writer_write(w, file));
    hv_vdb_writer_destroy(&w);
    set_batch(NULL);
    hv_mesh_destroy(&m);
    tl_rm_rf(path);
}
END_TEST

/* The sink's memory check: a bound on the tiles whose tree exceeds the
 * machine is refused at begin with the figure, and nothing is added. */
START_TEST(sink_should_refuse_a_tree_larger_than_the_machine)
{
    hv_vdb_writer *w = NULL;
    TL_ASSERT_OK(hv_vdb_writer_create(&w));
    hv_tiles_sink sink;
    TL_ASSERT_OK(hv_vdb_writer_levelset_sink(w, "sdf", 3, NULL, &sink));
    hv_tiles block = {.n = {1 << 20, 1 << 20, 1 << 20}, .h = 1e-6};
    const size_t tiles = (size_t)1 << 40; /* 2 PB of leaves */
    ck_assert_int_eq(sink.begin(sink.user, &block, tiles), HV_ERR_NOMEM);
    const char *msg = hv_last_error();
    ck_assert_msg(strstr(msg, "level set 'sdf'") && strstr(msg, "GB, more than "), "%s", msg);
    TL_ASSERT_OK(sink.end(sink.user, 0));
    char dir[] = "/tmp/hv_vdb_stream_XXXXXX", file[256];
    ck_assert_ptr_nonnull(mkdtemp(dir));
    snprintf(file, sizeof file, "%s/none.vdb", dir);
    ck_assert_int_eq(hv_vdb_writer_write(w, file), HV_ERR_INVALID_ARG);
    hv_vdb_writer_destroy(&w);
    tl_rm_rf(dir);
}
END_TEST

/* A voxel size OpenVDB's transforms refuse (h^3 below 3e-15) is refused at
 * begin with the figure, not with OpenVDB's bare "Non-zero scale values". */
START_TEST(sink_should_refuse_a_voxel_size_openvdb_cannot_hold)
{
    hv_vdb_writer *w = NULL;
    TL_ASSERT_OK(hv_vdb_writer_create(&w));
    hv_tiles_sink sink;
    TL_ASSERT_OK(hv_vdb_writer_levelset_sink(w, "sdf", 3, NULL, &sink));
    hv_tiles block = {.n = {64, 64, 64}, .h = 1.2e-5};
    ck_assert_int_eq(sink.begin(sink.user, &block, 100), HV_ERR_INVALID_ARG);
    const char *msg = hv_last_error();
    ck_assert_msg(strstr(msg, "voxel size 1.2e-05 is below the smallest") &&
                      strstr(msg, "1.44e-05"),
                  "%s", msg);
    TL_ASSERT_OK(sink.end(sink.user, 0));
    block.h = 1.5e-5;
    TL_ASSERT_OK(hv_vdb_writer_levelset_sink(w, "sdf", 3, NULL, &sink));
    TL_ASSERT_OK(sink.begin(sink.user, &block, 100));
    TL_ASSERT_OK(sink.end(sink.user, 0));
    hv_vdb_writer_destroy(&w);
}
END_TEST

int main(void)
{
    Suite *s = suite_create("vdb_stream");
    TCase *tc = tcase_create("core");
    tcase_set_timeout(tc, 120);
    tcase_add_test(tc, batches_of_any_size_should_give_the_same_tiles);
    tcase_add_test(tc, streamed_file_should_equal_the_file_of_all_tiles_byte_for_byte);
    tcase_add_test(tc, streamed_file_off_the_leaf_lattice_should_equal_the_whole_one);
    tcase_add_test(tc, packed_leaves_should_flood_fill_every_level_as_openvdb_does);
    tcase_add_test(tc, failing_sink_should_stop_the_run_and_hear_of_it_once);
    tcase_add_test(tc, sink_should_refuse_a_tree_larger_than_the_machine);
    tcase_add_test(tc, sink_should_refuse_a_voxel_size_openvdb_cannot_hold);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
