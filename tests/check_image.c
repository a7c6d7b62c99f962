/* Images: EXR round trips with a full pixel decode, truncated and foreign files,
 * slices of 3D grids, PNG previews decoded back with libpng. */
#include "heatvox/heatvox.h"
#include "testlib.h"

#include <OpenEXR/openexr.h>
#include <check.h>
#include <zlib.h>
#include <dirent.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static char tmpdir[256];

static void make_tmpdir(void)
{
    snprintf(tmpdir, sizeof tmpdir, "/tmp/hv_check_image_XXXXXX");
    ck_assert_ptr_nonnull(mkdtemp(tmpdir));
}

static int count_entries(void)
{
    DIR *d = opendir(tmpdir);
    int n = 0;
    struct dirent *e;
    while (d && (e = readdir(d)))
        if (strcmp(e->d_name, ".") && strcmp(e->d_name, ".."))
            n++;
    if (d)
        closedir(d);
    return n;
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
    static char p[2][600];
    static int which;
    which ^= 1;
    snprintf(p[which], sizeof p[which], "%s/%s", tmpdir, name);
    return p[which];
}

static hv_grid *make_grid(int dim, int nx, int ny, int nz, double h)
{
    int n[3] = {nx, ny, nz};
    double org[3] = {-1.25, 0.5, 3.0};
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_grid_create(&g, dim, n, h, org));
    return g;
}

/* Signed distance to a circle (2D) or sphere (3D) through the cell centres. */
static void fill_sphere(hv_grid *g, const double c[3], double r)
{
    for (int k = 0; k < g->n[2]; k++)
        for (int j = 0; j < g->n[1]; j++)
            for (int i = 0; i < g->n[0]; i++) {
                double x[3];
                hv_grid_cell_center(g, i, j, k, x);
                double dz = g->dim == 3 ? x[2] - c[2] : 0;
                g->v[i + (size_t)g->n[0] * (j + (size_t)g->n[1] * k)] =
                    (float)(sqrt((x[0] - c[0]) * (x[0] - c[0]) + (x[1] - c[1]) * (x[1] - c[1]) +
                                 dz * dz) -
                            r);
            }
}

static void assert_same_grid(const hv_grid *a, const hv_grid *b)
{
    ck_assert_int_eq(a->dim, b->dim);
    for (int d = 0; d < 3; d++) {
        ck_assert_int_eq(a->n[d], b->n[d]);
        ck_assert(a->origin[d] == b->origin[d]);
    }
    ck_assert(a->h == b->h);
    ck_assert_int_eq(memcmp(a->v, b->v, sizeof(float) * hv_grid_count(a)), 0);
}

static long file_size(const char *p)
{
    struct stat sb;
    return stat(p, &sb) == 0 ? (long)sb.st_size : -1;
}

static void copy_truncated(const char *from, const char *to, long keep)
{
    FILE *in = fopen(from, "rb"), *out = fopen(to, "wb");
    ck_assert_ptr_nonnull(in);
    ck_assert_ptr_nonnull(out);
    char *buf = malloc((size_t)keep);
    ck_assert_int_eq((long)fread(buf, 1, (size_t)keep, in), keep);
    ck_assert_int_eq((long)fwrite(buf, 1, (size_t)keep, out), keep);
    free(buf);
    fclose(in);
    fclose(out);
}

/* ---- EXR ---- */

START_TEST(exr_2d_round_trip_should_return_every_value_bit_for_bit)
{
    make_tmpdir();
    hv_grid *g = make_grid(2, 37, 23, 1, 0.125); /* 23 lines: a partial last ZIP block */
    tl_fill_random(g->v, hv_grid_count(g), 7);
    g->v[0] = NAN;
    g->v[1] = -0.0f;
    g->v[2] = INFINITY;
    g->v[36] = 1e-40f; /* subnormal */
    const char *p = tmp_path("f.exr");
    TL_ASSERT_OK(hv_exr_write(p, g, "distance"));
    ck_assert_int_eq(count_entries(), 1); /* no temporary left behind */
    hv_grid *r = NULL;
    TL_ASSERT_OK(hv_exr_read(p, NULL, &r));
    ck_assert(isnan(r->v[0]));
    r->v[0] = g->v[0];
    assert_same_grid(g, r);
    ck_assert(signbit(r->v[1]));
    hv_grid_destroy(&r);
    TL_ASSERT_OK(hv_exr_read(p, "distance", &r));
    hv_grid_destroy(&r);
    hv_status st = hv_exr_read(p, "Y", &r);
    ck_assert_int_eq(st, HV_ERR_PARSE);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "distance")); /* lists what there is */
    ck_assert_ptr_null(r);
    hv_grid_destroy(&g);
    remove_tmpdir();
}
END_TEST

/* The zlib level OpenEXR uses for ZIP parts by default. */
static int exr_zip_level(void)
{
    exr_context_t ctx = NULL;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    const char *p = tmp_path("level.exr");
    ck_assert_int_eq(exr_start_write(&ctx, p, EXR_WRITE_FILE_DIRECTLY, &init), EXR_ERR_SUCCESS);
    int part = -1, level = -1;
    ck_assert_int_eq(exr_add_part(ctx, "p", EXR_STORAGE_SCANLINE, &part), EXR_ERR_SUCCESS);
    ck_assert_int_eq(exr_initialize_required_attr_simple(ctx, part, 4, 4, EXR_COMPRESSION_ZIP),
                     EXR_ERR_SUCCESS);
    ck_assert_int_eq(exr_get_zip_compression_level(ctx, part, &level), EXR_ERR_SUCCESS);
    exr_finish(&ctx);
    unlink(p);
    return level;
}

/* OpenEXR's ZIP of a chunk of raw bytes: bytes split into even and odd halves,
 * then differences (+128) of successive bytes, then deflate (the predictor of
 * the OpenEXR file format's ZIP compression). Returns the deflated size; the
 * bytes go to z when it is not NULL (compressBound(n) bytes). */
static size_t exr_zip(const unsigned char *raw, size_t n, int level, unsigned char *z)
{
    unsigned char *t = malloc(n), *zz = z ? z : malloc(compressBound(n));
    ck_assert_ptr_nonnull(t);
    ck_assert_ptr_nonnull(zz);
    size_t h = (n + 1) / 2;
    for (size_t i = 0; i < n; i++)
        t[(i & 1) ? h + i / 2 : i / 2] = raw[i];
    for (size_t i = n - 1; i > 0; i--)
        t[i] = (unsigned char)(t[i] - t[i - 1] + 128);
    uLongf zn = compressBound(n);
    ck_assert_int_eq(compress2(zz, &zn, t, n, level), Z_OK);
    free(t);
    if (!z)
        free(zz);
    return zn;
}

/* Fills a 16-row image (one ZIP chunk) of nx floats whose deflated chunk is
 * exactly as long as the raw chunk: a random prefix, zeros after it, the prefix
 * length searched. Returns 0 when no such prefix was found. */
static int equal_size_chunk(unsigned char *raw, int nx, int level)
{
    size_t n = (size_t)16 * nx * sizeof(float);
    for (uint64_t seed = 1; seed < 64; seed++) {
        uint64_t s = seed;
        for (size_t i = 0; i < n; i++)
            raw[i] = (unsigned char)((tl_rand(&s) + 0.5) * 256.0);
        for (size_t b = n > 600 ? n - 600 : 0; b < n; b++) {
            unsigned char *keep = malloc(n);
            memcpy(keep, raw, n);
            memset(keep + b, 0, n - b);
            size_t zs = exr_zip(keep, n, level, NULL);
            if (zs == n) {
                memcpy(raw, keep, n);
                free(keep);
                return 1;
            }
            free(keep);
            if (zs > n + 64)
                break;
        }
    }
    return 0;
}

/* Decodes p with OpenEXR's C++ library (tests/exr_values.cpp) and compares
 * each part with the grid's slice, rows flipped (image row 0 is the grid's
 * last). */
static void assert_cxx_reader_gives(const char *p, const char *channel, const hv_grid *g)
{
    char exe[4096], cmd[9000];
    ssize_t len = readlink("/proc/self/exe", exe, sizeof exe - 32);
    ck_assert_int_gt(len, 0);
    exe[len] = 0;
    strcpy(strrchr(exe, '/') + 1, "exr_values");
    const char *raw = tmp_path("values.raw");
    snprintf(cmd, sizeof cmd, "'%s' '%s' '%s' '%s'", exe, p, channel, raw);
    ck_assert_int_eq(system(cmd), 0);
    size_t n = hv_grid_count(g), nx = (size_t)g->n[0], ny = (size_t)g->n[1];
    ck_assert_int_eq(file_size(raw), (long)(n * sizeof(float)));
    float *v = malloc(n * sizeof(float));
    FILE *f = fopen(raw, "rb");
    ck_assert_int_eq(fread(v, sizeof(float), n, f), n);
    fclose(f);
    size_t bad = 0;
    for (size_t k = 0; k < n / (nx * ny); k++)
        for (size_t y = 0; y < ny; y++)
            bad += memcmp(v + (k * ny + y) * nx, g->v + (k * ny + ny - 1 - y) * nx,
                          nx * sizeof(float)) != 0;
    ck_assert_msg(bad == 0, "%s: %zu rows differ as OpenEXR's C++ reader decodes them", p, bad);
    free(v);
    unlink(raw);
}

START_TEST(exr_chunk_deflating_to_its_raw_size_should_read_back_exactly)
{
    /* OpenEXR 3.1's Core ZIP encoder kept such a chunk deflated while readers
     * take it as raw: the chunk decoded as garbage. */
    make_tmpdir();
    const int nx = 40, level = exr_zip_level();
    unsigned char *raw = malloc((size_t)16 * nx * sizeof(float));
    ck_assert_msg(equal_size_chunk(raw, nx, level), "no chunk deflates to its raw size");
    hv_grid *g = make_grid(3, nx, 16, 5, 0.5);
    tl_fill_random(g->v, hv_grid_count(g), 11);
    for (int r = 0; r < 16; r++) /* slice 2 holds the chunk, image row r = grid row 15-r */
        memcpy(g->v + (size_t)nx * 16 * 2 + (size_t)(15 - r) * nx, raw + (size_t)r * nx * 4,
               (size_t)nx * 4);
    const char *p = tmp_path("equal.exr");
    TL_ASSERT_OK(hv_exr_write(p, g, "sdf"));
    hv_grid *r = NULL;
    TL_ASSERT_OK(hv_exr_read(p, "sdf", &r));
    assert_same_grid(g, r);
    hv_grid_destroy(&r);
    assert_cxx_reader_gives(p, "sdf", g);
    /* The same chunk as a 2D image. */
    hv_grid *g2 = make_grid(2, nx, 16, 1, 0.5);
    memcpy(g2->v, g->v + (size_t)nx * 16 * 2, (size_t)nx * 16 * 4);
    p = tmp_path("equal2d.exr");
    TL_ASSERT_OK(hv_exr_write(p, g2, NULL));
    TL_ASSERT_OK(hv_exr_read(p, NULL, &r));
    assert_same_grid(g2, r);
    hv_grid_destroy(&r);
    assert_cxx_reader_gives(p, "Y", g2);
    hv_grid_destroy(&g2);
    hv_grid_destroy(&g);
    free(raw);
    remove_tmpdir();
}
END_TEST

START_TEST(exr_chunk_deflated_but_flagged_raw_should_be_recovered_on_reading)
{
    /* The file OpenEXR 3.1's Core encoder wrote without the guard: the deflated
     * chunk, as long as the raw one, stored as it is. */
    make_tmpdir();
    const int nx = 40, level = exr_zip_level();
    size_t n = (size_t)16 * nx * sizeof(float);
    unsigned char *raw = malloc(n), *z = malloc(compressBound(n));
    ck_assert_msg(equal_size_chunk(raw, nx, level), "no chunk deflates to its raw size");
    ck_assert_int_eq(exr_zip(raw, n, level, z), n);
    const char *p = tmp_path("old.exr");
    exr_context_t ctx = NULL;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    int part = -1;
    ck_assert_int_eq(exr_start_write(&ctx, p, EXR_WRITE_FILE_DIRECTLY, &init), EXR_ERR_SUCCESS);
    ck_assert_int_eq(exr_add_part(ctx, "heatvox", EXR_STORAGE_SCANLINE, &part), EXR_ERR_SUCCESS);
    ck_assert_int_eq(exr_initialize_required_attr_simple(ctx, part, nx, 16, EXR_COMPRESSION_ZIP),
                     EXR_ERR_SUCCESS);
    ck_assert_int_eq(
        exr_add_channel(ctx, part, "Y", EXR_PIXEL_FLOAT, EXR_PERCEPTUALLY_LINEAR, 1, 1),
        EXR_ERR_SUCCESS);
    ck_assert_int_eq(exr_write_header(ctx), EXR_ERR_SUCCESS);
    ck_assert_int_eq(exr_write_scanline_chunk(ctx, part, 0, z, n), EXR_ERR_SUCCESS);
    ck_assert_int_eq(exr_finish(&ctx), EXR_ERR_SUCCESS);
    hv_grid *r = NULL;
    TL_ASSERT_OK(hv_exr_read(p, NULL, &r));
    ck_assert_int_eq(r->n[0], nx);
    ck_assert_int_eq(r->n[1], 16);
    for (int y = 0; y < 16; y++) /* image row y is grid row 15-y */
        ck_assert_int_eq(
            memcmp(r->v + (size_t)(15 - y) * nx, raw + (size_t)y * nx * 4, (size_t)nx * 4), 0);
    hv_grid_destroy(&r);
    free(raw);
    free(z);
    remove_tmpdir();
}
END_TEST

START_TEST(exr_header_asking_for_gigabytes_should_fail_before_allocating)
{
    /* Fuzzer finds: headers of a few hundred bytes whose data window asks for
     * 5 to 19 GB; the grid must not be allocated (and touched) first. */
    const char *files[] = {"tests/fuzz/regress/exr/data_window_67109377x46_in_550_bytes.exr",
                           "tests/fuzz/regress/exr/grid_allocated_before_chunk_table_check.exr",
                           "tests/fuzz/regress/exr/grid_of_19GB_in_1126_bytes.exr"};
    for (int i = 0; i < 3; i++) {
        ck_assert_msg(access(files[i], R_OK) == 0, "%s missing (run from the repository root)",
                      files[i]);
        hv_grid *g = NULL;
        ck_assert_int_eq(hv_exr_read(files[i], NULL, &g), HV_ERR_PARSE);
        ck_assert_ptr_null(g);
        ck_assert_ptr_nonnull(strstr(hv_last_error(), files[i]));
        ck_assert_ptr_nonnull(strstr(hv_last_error(), "data window"));
    }
    ck_assert_msg(hv_peak_rss() < 512u << 20, "peak RSS %zu MB", hv_peak_rss() >> 20);
}
END_TEST

START_TEST(exr_files_should_decode_alike_in_openexrs_cxx_reader)
{
    make_tmpdir();
    hv_grid *g = make_grid(3, 33, 21, 4, 0.25);
    const double c[3] = {1.0, 3.0, 3.5};
    fill_sphere(g, c, 1.5);
    const char *p = tmp_path("sphere.exr");
    TL_ASSERT_OK(hv_exr_write(p, g, "sdf"));
    assert_cxx_reader_gives(p, "sdf", g);
    hv_grid_destroy(&g);
    remove_tmpdir();
}
END_TEST

START_TEST(exr_2d_image_should_show_the_second_axis_up)
{
    make_tmpdir();
    hv_grid *g = make_grid(2, 5, 4, 1, 1.0);
    for (int j = 0; j < 4; j++)
        for (int i = 0; i < 5; i++)
            g->v[i + 5 * j] = (float)(10 * j + i);
    const char *p = tmp_path("o.exr");
    TL_ASSERT_OK(hv_exr_write(p, g, NULL));
    /* Read the raw first scanline with the Core API: it must be j = 3. */
    exr_context_t ctx = NULL;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    ck_assert_int_eq(exr_start_read(&ctx, p, &init), EXR_ERR_SUCCESS);
    const exr_attr_chlist_t *chl = NULL;
    ck_assert_int_eq(exr_get_channels(ctx, 0, &chl), EXR_ERR_SUCCESS);
    ck_assert_int_eq(chl->num_channels, 1);
    ck_assert_str_eq(chl->entries[0].name.str, "Y");
    ck_assert_int_eq(chl->entries[0].pixel_type, EXR_PIXEL_FLOAT);
    exr_chunk_info_t ci;
    ck_assert_int_eq(exr_read_scanline_chunk_info(ctx, 0, 0, &ci), EXR_ERR_SUCCESS);
    exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
    ck_assert_int_eq(exr_decoding_initialize(ctx, 0, &ci, &dec), EXR_ERR_SUCCESS);
    float rows[4 * 5];
    dec.channels[0].decode_to_ptr = (uint8_t *)rows;
    dec.channels[0].user_pixel_stride = 4;
    dec.channels[0].user_line_stride = 20;
    dec.channels[0].user_data_type = EXR_PIXEL_FLOAT;
    dec.channels[0].user_bytes_per_element = 4;
    ck_assert_int_eq(exr_decoding_choose_default_routines(ctx, 0, &dec), EXR_ERR_SUCCESS);
    ck_assert_int_eq(exr_decoding_run(ctx, 0, &dec), EXR_ERR_SUCCESS);
    ck_assert_int_eq(ci.height, 4);
    ck_assert(rows[0] == 30.0f && rows[4] == 34.0f && rows[15] == 0.0f);
    exr_decoding_destroy(ctx, &dec);
    exr_finish(&ctx);
    hv_grid_destroy(&g);
    remove_tmpdir();
}
END_TEST

START_TEST(exr_3d_round_trip_should_use_one_named_part_per_z_slice)
{
    make_tmpdir();
    hv_grid *g = make_grid(3, 19, 33, 5, 0.5);
    tl_fill_random(g->v, hv_grid_count(g), 11);
    const char *p = tmp_path("vol.exr");
    TL_ASSERT_OK(hv_exr_write(p, g, NULL));
    exr_context_t ctx = NULL;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    ck_assert_int_eq(exr_start_read(&ctx, p, &init), EXR_ERR_SUCCESS);
    int np = 0;
    ck_assert_int_eq(exr_get_count(ctx, &np), EXR_ERR_SUCCESS);
    ck_assert_int_eq(np, 5);
    for (int k = 0; k < 5; k++) {
        const char *name = NULL;
        char want[32];
        snprintf(want, sizeof want, "slice_%04d", k);
        ck_assert_int_eq(exr_get_name(ctx, k, &name), EXR_ERR_SUCCESS);
        ck_assert_str_eq(name, want);
        int32_t idx = -1;
        ck_assert_int_eq(exr_attr_get_int(ctx, k, "heatvox:sliceIndex", &idx), EXR_ERR_SUCCESS);
        ck_assert_int_eq(idx, k);
    }
    exr_finish(&ctx);
    hv_grid *r = NULL;
    TL_ASSERT_OK(hv_exr_read(p, NULL, &r));
    assert_same_grid(g, r);
    hv_grid_destroy(&r);
    hv_grid_destroy(&g);
    remove_tmpdir();
}
END_TEST

START_TEST(truncated_exr_should_fail_to_decode_naming_the_file)
{
    make_tmpdir();
    hv_grid *g = make_grid(3, 64, 64, 3, 1.0);
    tl_fill_random(g->v, hv_grid_count(g), 3); /* random bits barely compress */
    char p[600];
    snprintf(p, sizeof p, "%s", tmp_path("big.exr"));
    TL_ASSERT_OK(hv_exr_write(p, g, NULL));
    long size = file_size(p);
    ck_assert_int_gt(size, 40000);
    const double keep[] = {0.999, 0.9, 0.5, 0.1};
    int header_only_passes = 0;
    for (size_t t = 0; t < sizeof keep / sizeof keep[0]; t++) {
        const char *cut = tmp_path("cut.exr");
        copy_truncated(p, cut, (long)(size * keep[t]));
        /* What a header-only check (exrheader) sees. */
        exr_context_t ctx = NULL;
        exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
        init.flags = EXR_CONTEXT_FLAG_SILENT_HEADER_PARSE;
        init.error_handler_fn = NULL;
        if (exr_start_read(&ctx, cut, &init) == EXR_ERR_SUCCESS)
            header_only_passes++;
        exr_finish(&ctx);
        hv_grid *r = NULL;
        hv_status st = hv_exr_read(cut, NULL, &r);
        ck_assert_msg(st == HV_ERR_PARSE, "kept %.1f%%: status %s", 100 * keep[t],
                      hv_status_str(st));
        ck_assert_ptr_null(r);
        ck_assert_msg(strstr(hv_last_error(), cut) != NULL, "message '%s' does not name %s",
                      hv_last_error(), cut);
        unlink(cut);
    }
    ck_assert_int_ge(header_only_passes, 1);
    hv_grid_destroy(&g);
    remove_tmpdir();
}
END_TEST

START_TEST(missing_and_foreign_files_should_fail_with_the_path)
{
    make_tmpdir();
    hv_grid *r = NULL;
    const char *missing = tmp_path("nope.exr");
    ck_assert_int_eq(hv_exr_read(missing, NULL, &r), HV_ERR_IO);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), missing));
    const char *text = tmp_path("text.exr");
    FILE *f = fopen(text, "w");
    fputs("this is not an image\n", f);
    fclose(f);
    ck_assert_int_eq(hv_exr_read(text, NULL, &r), HV_ERR_PARSE);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), text));
    uint8_t *rgb = NULL;
    int w, h;
    ck_assert_int_eq(hv_png_read_rgb(text, &rgb, &w, &h), HV_ERR_PARSE);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), text));
    ck_assert_ptr_null(rgb);
    remove_tmpdir();
}
END_TEST

START_TEST(writing_into_a_missing_directory_should_fail_and_leave_nothing)
{
    hv_grid *g = make_grid(2, 4, 4, 1, 1.0);
    ck_assert_int_eq(hv_exr_write("/nonexistent-dir/x.exr", g, NULL), HV_ERR_IO);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "/nonexistent-dir/x.exr"));
    ck_assert_int_eq(hv_png_write("/nonexistent-dir/x.png", g, 0), HV_ERR_IO);
    ck_assert_int_eq(hv_exr_write("/tmp/x.exr", g, ""), HV_ERR_INVALID_ARG);
    hv_grid_destroy(&g);
}
END_TEST

/* ---- slices ---- */

START_TEST(slices_should_copy_the_plane_keeping_the_remaining_axes_in_order)
{
    hv_grid *g = make_grid(3, 4, 5, 6, 0.5);
    for (int k = 0; k < 6; k++)
        for (int j = 0; j < 5; j++)
            for (int i = 0; i < 4; i++)
                g->v[i + 4 * (j + 5 * k)] = (float)(i + 100 * j + 10000 * k);
    for (int axis = 0; axis < 3; axis++) {
        int idx = axis + 1;
        hv_grid *s = NULL;
        TL_ASSERT_OK(hv_grid_slice(g, axis, idx, &s));
        int u = axis == 0 ? 1 : 0, w = axis == 2 ? 1 : 2;
        ck_assert_int_eq(s->dim, 2);
        ck_assert_int_eq(s->n[0], g->n[u]);
        ck_assert_int_eq(s->n[1], g->n[w]);
        ck_assert(s->origin[0] == g->origin[u] && s->origin[1] == g->origin[w]);
        ck_assert(fabs(s->origin[2] - (g->origin[axis] + (idx + 0.5) * g->h)) < 1e-12);
        for (int b = 0; b < s->n[1]; b++)
            for (int a = 0; a < s->n[0]; a++) {
                int c[3];
                c[axis] = idx;
                c[u] = a;
                c[w] = b;
                ck_assert(s->v[a + s->n[0] * b] == (float)(c[0] + 100 * c[1] + 10000 * c[2]));
            }
        hv_grid_destroy(&s);
    }
    hv_grid *s = NULL;
    ck_assert_int_eq(hv_grid_slice(g, 2, 6, &s), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "0..5"));
    ck_assert_int_eq(hv_grid_slice(g, 3, 0, &s), HV_ERR_INVALID_ARG);
    ck_assert_int_eq(hv_grid_slice(g, 0, -1, &s), HV_ERR_INVALID_ARG);
    ck_assert_ptr_null(s);
    hv_grid_destroy(&g);
}
END_TEST

/* ---- PNG ---- */

static void expect_colour(const uint8_t *px, int r, int g, int b, const char *what)
{
    ck_assert_msg(px[0] == r && px[1] == g && px[2] == b, "%s: (%d,%d,%d), expected (%d,%d,%d)",
                  what, px[0], px[1], px[2], r, g, b);
}

START_TEST(png_preview_should_decode_with_blue_inside_red_outside_black_contour)
{
    make_tmpdir();
    /* 64 x 48, h = 1, circle of radius 10 at cell (20, 30): not centred, so a
     * transposed or upside-down image fails. */
    hv_grid *g = make_grid(2, 64, 48, 1, 1.0);
    g->origin[0] = g->origin[1] = g->origin[2] = 0;
    double c[3] = {20.5, 30.5, 0};
    fill_sphere(g, c, 10.0);
    double range = 10.0;
    const char *p = tmp_path("c.png");
    TL_ASSERT_OK(hv_png_write(p, g, range));
    ck_assert_int_eq(count_entries(), 1);
    uint8_t *rgb = NULL;
    int w = 0, h = 0;
    TL_ASSERT_OK(hv_png_read_rgb(p, &rgb, &w, &h));
    ck_assert_int_eq(w, 64);
    ck_assert_int_eq(h, 48);
#define PX(i, j) (rgb + 3 * ((size_t)(h - 1 - (j)) * w + (i)))
    /* centre: v = -10 = -range: the blue end; far corner: clamped red end. */
    expect_colour(PX(20, 30), HV_PNG_BLUE_R, HV_PNG_BLUE_G, HV_PNG_BLUE_B, "centre");
    expect_colour(PX(63, 0), HV_PNG_RED_R, HV_PNG_RED_G, HV_PNG_RED_B, "corner");
    /* halfway inside: half blue. */
    const uint8_t *half = PX(25, 30); /* v = -5 */
    ck_assert(half[2] > half[0] && half[0] > HV_PNG_BLUE_R && half[0] < 255);
    int blacks = 0;
    for (int j = 0; j < h; j++)
        for (int i = 0; i < w; i++) {
            const uint8_t *px = PX(i, j);
            int black = px[0] == 0 && px[1] == 0 && px[2] == 0;
            float v = g->v[i + w * j];
            blacks += black;
            /* Black exactly within a pixel of the circle, never elsewhere. */
            if (black)
                ck_assert_msg(fabsf(v) <= 1.0f, "black at (%d,%d) where v = %g", i, j, v);
            else if (v < 0)
                ck_assert_msg(px[2] > px[0], "inside (%d,%d) not blue", i, j);
            else
                ck_assert_msg(px[0] > px[2] || (px[0] == 255 && px[2] == 255),
                              "outside (%d,%d) not red", i, j);
        }
    /* The contour is closed and one pixel thick: about 2 pi r / (pixels per
     * unit of length along a 4-connected line, between 1 and sqrt 2). */
    ck_assert_int_gt(blacks, (int)(2 * M_PI * 10 * 0.8));
    ck_assert_int_lt(blacks, (int)(2 * M_PI * 10 * 1.5));
    /* Along the row through the centre, the sign changes twice, each marked. */
    for (int i = 1; i < w; i++) {
        float a = g->v[i - 1 + w * 30], b = g->v[i + w * 30];
        if ((a < 0) != (b < 0)) {
            const uint8_t *pa = PX(i - 1, 30), *pb = PX(i, 30);
            ck_assert(pa[0] + pa[1] + pa[2] == 0 || pb[0] + pb[1] + pb[2] == 0);
        }
    }
#undef PX
    free(rgb);
    hv_grid_destroy(&g);
    remove_tmpdir();
}
END_TEST

START_TEST(three_slice_preview_should_place_x_y_z_slices_side_by_side)
{
    make_tmpdir();
    hv_grid *g = make_grid(3, 20, 30, 40, 1.0);
    g->origin[0] = g->origin[1] = g->origin[2] = 0;
    double c[3] = {10, 15, 20}; /* the middle slices cut through the centre */
    fill_sphere(g, c, 6.0);
    const char *p = tmp_path("prev.png");
    TL_ASSERT_OK(hv_png_write_preview(p, g, 6.0));
    uint8_t *rgb = NULL;
    int w = 0, h = 0;
    TL_ASSERT_OK(hv_png_read_rgb(p, &rgb, &w, &h));
    /* x slice (y,z) 30 x 40, y slice (x,z) 20 x 40, z slice (x,y) 20 x 30. */
    ck_assert_int_eq(w, 30 + 20 + 20 + 2 * HV_PNG_GAP);
    ck_assert_int_eq(h, 40);
    int x0[3] = {0, 30 + HV_PNG_GAP, 50 + 2 * HV_PNG_GAP}, cw[3] = {15, 10, 10},
        ch[3] = {20, 20, 15};
    for (int s = 0; s < 3; s++) {
        const uint8_t *px = rgb + 3 * ((size_t)(h - 1 - ch[s]) * w + x0[s] + cw[s]);
        ck_assert_msg(px[2] > px[0] + 50, "slice %d centre is not blue", s);
        const uint8_t *corner = rgb + 3 * ((size_t)(h - 1) * w + x0[s]);
        ck_assert_msg(corner[0] > corner[2] + 50, "slice %d corner is not red", s);
    }
    /* gaps are white, and the z slice (30 tall) leaves white above it */
    expect_colour(rgb + 3 * (size_t)(30 + 1), 255, 255, 255, "gap");
    expect_colour(rgb + 3 * (size_t)(w - 1), 255, 255, 255, "above the z slice");
    free(rgb);
    hv_grid_destroy(&g);
    remove_tmpdir();
}
END_TEST

START_TEST(truncated_png_should_fail_to_decode)
{
    make_tmpdir();
    hv_grid *g = make_grid(2, 64, 64, 1, 1.0);
    tl_fill_random(g->v, hv_grid_count(g), 5);
    const char *p = tmp_path("r.png");
    TL_ASSERT_OK(hv_png_write(p, g, 0));
    const char *cut = tmp_path("cut.png");
    copy_truncated(p, cut, file_size(p) / 2);
    uint8_t *rgb = NULL;
    int w, h;
    ck_assert_int_eq(hv_png_read_rgb(cut, &rgb, &w, &h), HV_ERR_PARSE);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), cut));
    ck_assert_ptr_null(rgb);
    hv_grid_destroy(&g);
    remove_tmpdir();
}
END_TEST

START_TEST(colormap_should_be_symmetric_and_grey_for_nan)
{
    hv_grid *g = make_grid(2, 5, 1, 1, 1.0);
    float vals[5] = {-4, -2, NAN, 2, 4};
    memcpy(g->v, vals, sizeof vals);
    uint8_t rgb[15];
    TL_ASSERT_OK(hv_image_colormap(g, 0, rgb)); /* auto range: 4 */
    expect_colour(rgb + 6, HV_PNG_GREY, HV_PNG_GREY, HV_PNG_GREY, "NaN");
    expect_colour(rgb, HV_PNG_BLUE_R, HV_PNG_BLUE_G, HV_PNG_BLUE_B, "-range");
    expect_colour(rgb + 12, HV_PNG_RED_R, HV_PNG_RED_G, HV_PNG_RED_B, "+range");
    /* half way: half as far from white as the ends (to rounding) */
    for (int k = 0; k < 3; k++) {
        ck_assert_int_le(abs(2 * (255 - rgb[3 + k]) - (255 - rgb[0 + k])), 1);
        ck_assert_int_le(abs(2 * (255 - rgb[9 + k]) - (255 - rgb[12 + k])), 1);
    }
    hv_grid_destroy(&g);
}
END_TEST

int main(void)
{
    Suite *s = suite_create("image");
    TCase *tc = tcase_create("exr");
    tcase_set_timeout(tc, 30);
    tcase_add_test(tc, exr_2d_round_trip_should_return_every_value_bit_for_bit);
    tcase_add_test(tc, exr_2d_image_should_show_the_second_axis_up);
    tcase_add_test(tc, exr_chunk_deflating_to_its_raw_size_should_read_back_exactly);
    tcase_add_test(tc, exr_chunk_deflated_but_flagged_raw_should_be_recovered_on_reading);
    tcase_add_test(tc, exr_files_should_decode_alike_in_openexrs_cxx_reader);
    tcase_add_test(tc, exr_header_asking_for_gigabytes_should_fail_before_allocating);
    tcase_add_test(tc, exr_3d_round_trip_should_use_one_named_part_per_z_slice);
    tcase_add_test(tc, truncated_exr_should_fail_to_decode_naming_the_file);
    tcase_add_test(tc, missing_and_foreign_files_should_fail_with_the_path);
    tcase_add_test(tc, writing_into_a_missing_directory_should_fail_and_leave_nothing);
    suite_add_tcase(s, tc);
    tc = tcase_create("slices and previews");
    tcase_set_timeout(tc, 30);
    tcase_add_test(tc, slices_should_copy_the_plane_keeping_the_remaining_axes_in_order);
    tcase_add_test(tc, png_preview_should_decode_with_blue_inside_red_outside_black_contour);
    tcase_add_test(tc, three_slice_preview_should_place_x_y_z_slices_side_by_side);
    tcase_add_test(tc, truncated_png_should_fail_to_decode);
    tcase_add_test(tc, colormap_should_be_symmetric_and_grey_for_nan);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
