/* NumPy .npy writer and reader: round trips, the header layout of format 1.0,
 * the variants the reader accepts and the inputs it must refuse, and numpy
 * (/usr/bin/python3) as the independent reader and writer, both directions. */
#include "heatvox/io.h"

#include <check.h>
#include <dirent.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static char dir[64];

static void make_dir(void)
{
    snprintf(dir, sizeof dir, "/tmp/hv-npy-XXXXXX");
    ck_assert_ptr_nonnull(mkdtemp(dir));
}

static void remove_dir(void)
{
    DIR *d = opendir(dir);
    if (!d)
        return;
    struct dirent *e;
    char p[512];
    while ((e = readdir(d)))
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

static hv_grid *ramp(int dim, int nx, int ny, int nz)
{
    hv_grid *g = NULL;
    int n[3] = {nx, ny, nz};
    ck_assert_int_eq(hv_grid_create(&g, dim, n, 0.25, NULL), HV_OK);
    for (size_t i = 0; i < hv_grid_count(g); i++)
        g->v[i] = (float)i * 0.5f - 7.25f + (i % 3 ? 1e-3f : -1e30f);
    return g;
}

static long file_size(const char *p)
{
    FILE *f = fopen(p, "rb");
    ck_assert_ptr_nonnull(f);
    fseek(f, 0, SEEK_END);
    long s = ftell(f);
    fclose(f);
    return s;
}

static void write_bytes(const char *p, const void *data, size_t len)
{
    FILE *f = fopen(p, "wb");
    ck_assert_ptr_nonnull(f);
    ck_assert_uint_eq(fwrite(data, 1, len, f), len);
    fclose(f);
}

/* Writes an .npy by hand: version major.0, the given dict (padded to 64),
 * then `data_bytes` bytes from data. */
static void write_npy_raw(const char *p, int major, const char *dict, const void *data,
                          size_t data_bytes)
{
    size_t pre = major == 1 ? 10 : 12, dlen = strlen(dict);
    size_t total = (pre + dlen + 1 + 63) / 64 * 64, hlen = total - pre;
    unsigned char *buf = calloc(1, total + data_bytes);
    memcpy(buf, "\x93NUMPY", 6);
    buf[6] = (unsigned char)major;
    buf[7] = 0;
    for (size_t b = 0; b < pre - 8; b++)
        buf[8 + b] = (unsigned char)(hlen >> (8 * b));
    memcpy(buf + pre, dict, dlen);
    memset(buf + pre + dlen, ' ', hlen - dlen - 1);
    buf[total - 1] = '\n';
    memcpy(buf + total, data, data_bytes);
    write_bytes(p, buf, total + data_bytes);
    free(buf);
}

/* numpy (python3-numpy, which make installs) is the independent reader and
 * writer these files are checked against: its absence fails the test. */
static void require_numpy(void)
{
    ck_assert_msg(system("/usr/bin/python3 -c 'import numpy' >/dev/null 2>&1") == 0,
                  "numpy does not import in /usr/bin/python3 (package python3-numpy)");
}

static void assert_same(const hv_grid *a, const hv_grid *b)
{
    ck_assert_int_eq(a->dim, b->dim);
    for (int d = 0; d < 3; d++)
        ck_assert_int_eq(a->n[d], b->n[d]);
    ck_assert_mem_eq(a->v, b->v, hv_grid_count(a) * sizeof(float));
}

START_TEST(npy_3d_round_trip_should_keep_shape_and_every_value)
{
    char p[256];
    path_in_dir(p, sizeof p, "a.npy");
    hv_grid *g = ramp(3, 5, 4, 3), *r = NULL;
    ck_assert_int_eq(hv_write_npy(p, g), HV_OK);
    ck_assert_int_eq(hv_read_npy(p, &r), HV_OK);
    assert_same(g, r);
    ck_assert_double_eq(r->h, 1.0);
    hv_grid_destroy(&g);
    hv_grid_destroy(&r);
}
END_TEST

START_TEST(npy_2d_round_trip_should_give_a_2d_grid)
{
    char p[256];
    path_in_dir(p, sizeof p, "b.npy");
    hv_grid *g = ramp(2, 7, 3, 1), *r = NULL;
    ck_assert_int_eq(hv_write_npy(p, g), HV_OK);
    ck_assert_int_eq(hv_read_npy(p, &r), HV_OK);
    ck_assert_int_eq(r->dim, 2);
    assert_same(g, r);
    hv_grid_destroy(&g);
    hv_grid_destroy(&r);
}
END_TEST

START_TEST(npy_header_should_follow_format_1_0_padded_to_64)
{
    char p[256];
    path_in_dir(p, sizeof p, "c.npy");
    hv_grid *g = ramp(3, 5, 4, 3);
    ck_assert_int_eq(hv_write_npy(p, g), HV_OK);
    unsigned char buf[256];
    FILE *f = fopen(p, "rb");
    ck_assert_uint_eq(fread(buf, 1, sizeof buf, f), sizeof buf);
    fclose(f);
    ck_assert_mem_eq(buf, "\x93NUMPY\x01\x00", 8);
    size_t hlen = buf[8] | (size_t)buf[9] << 8;
    size_t data_off = 10 + hlen;
    ck_assert_uint_eq(data_off % 64, 0);
    ck_assert_int_eq(buf[data_off - 1], '\n');
    char hdr[256];
    memcpy(hdr, buf + 10, hlen);
    hdr[hlen] = '\0';
    ck_assert_ptr_nonnull(strstr(hdr, "'descr': '<f4'"));
    ck_assert_ptr_nonnull(strstr(hdr, "'fortran_order': False"));
    ck_assert_ptr_nonnull(strstr(hdr, "'shape': (3, 4, 5)"));
    ck_assert_int_eq(file_size(p), (long)(data_off + hv_grid_count(g) * 4));
    /* the data is little-endian float32, x fastest */
    float v1;
    unsigned char *b = buf + data_off + 4;
    uint32_t u = (uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16 | (uint32_t)b[3] << 24;
    memcpy(&v1, &u, 4);
    ck_assert_float_eq(v1, g->v[1]);
    hv_grid_destroy(&g);
}
END_TEST

START_TEST(npy_reader_should_accept_float64_and_version_2_headers)
{
    char p[256];
    double d[6] = {1.5, -2.25, 3e-3, 4e10, -5, 6};
    path_in_dir(p, sizeof p, "f8.npy");
    write_npy_raw(p, 1, "{'descr': '<f8', 'fortran_order': False, 'shape': (2, 3), }", d, sizeof d);
    hv_grid *r = NULL;
    ck_assert_int_eq(hv_read_npy(p, &r), HV_OK);
    ck_assert_int_eq(r->dim, 2);
    ck_assert_int_eq(r->n[0], 3);
    ck_assert_int_eq(r->n[1], 2);
    for (int i = 0; i < 6; i++)
        ck_assert_float_eq(r->v[i], (float)d[i]);
    hv_grid_destroy(&r);

    float s[8] = {1, 2, 3, 4, 5, 6, 7, 8};
    path_in_dir(p, sizeof p, "v2.npy");
    write_npy_raw(p, 2, "{\"descr\": \"<f4\", \"fortran_order\": False, \"shape\": (2, 2, 2)}", s,
                  sizeof s);
    ck_assert_int_eq(hv_read_npy(p, &r), HV_OK);
    ck_assert_int_eq(r->dim, 3);
    ck_assert_mem_eq(r->v, s, sizeof s);
    hv_grid_destroy(&r);
}
END_TEST

static void expect_error(const char *p, hv_status want, const char *fragment)
{
    hv_grid *r = NULL;
    hv_status st = hv_read_npy(p, &r);
    ck_assert_msg(st == want, "%s: status %s, wanted %s (%s)", p, hv_status_str(st),
                  hv_status_str(want), hv_last_error());
    ck_assert_ptr_null(r);
    ck_assert_msg(strstr(hv_last_error(), p), "message does not name the file: %s",
                  hv_last_error());
    ck_assert_msg(strstr(hv_last_error(), fragment), "message lacks '%s': %s", fragment,
                  hv_last_error());
}

START_TEST(npy_reader_should_refuse_truncated_data_naming_the_file)
{
    char p[256];
    path_in_dir(p, sizeof p, "t.npy");
    hv_grid *g = ramp(3, 5, 4, 3);
    ck_assert_int_eq(hv_write_npy(p, g), HV_OK);
    ck_assert_int_eq(truncate(p, file_size(p) - 5), 0);
    expect_error(p, HV_ERR_PARSE, "truncated");
    ck_assert_int_eq(truncate(p, 30), 0);
    expect_error(p, HV_ERR_PARSE, "truncated");
    ck_assert_int_eq(truncate(p, 4), 0);
    expect_error(p, HV_ERR_PARSE, "not a NumPy");
    hv_grid_destroy(&g);
}
END_TEST

START_TEST(npy_reader_should_refuse_other_dtypes_fortran_order_and_1d)
{
    char p[256];
    int32_t iv[4] = {1, 2, 3, 4};
    path_in_dir(p, sizeof p, "i4.npy");
    write_npy_raw(p, 1, "{'descr': '<i4', 'fortran_order': False, 'shape': (2, 2), }", iv,
                  sizeof iv);
    expect_error(p, HV_ERR_UNSUPPORTED, "<i4");
    path_in_dir(p, sizeof p, "be.npy");
    write_npy_raw(p, 1, "{'descr': '>f4', 'fortran_order': False, 'shape': (2, 2), }", iv,
                  sizeof iv);
    expect_error(p, HV_ERR_UNSUPPORTED, ">f4");
    path_in_dir(p, sizeof p, "fo.npy");
    write_npy_raw(p, 1, "{'descr': '<f4', 'fortran_order': True, 'shape': (2, 2), }", iv,
                  sizeof iv);
    expect_error(p, HV_ERR_UNSUPPORTED, "Fortran");
    path_in_dir(p, sizeof p, "1d.npy");
    write_npy_raw(p, 1, "{'descr': '<f4', 'fortran_order': False, 'shape': (4,), }", iv, sizeof iv);
    expect_error(p, HV_ERR_UNSUPPORTED, "1 dimension");
    path_in_dir(p, sizeof p, "missing.npy");
    expect_error(p, HV_ERR_IO, "cannot open");
}
END_TEST

START_TEST(npy_reader_should_refuse_devices_directories_and_pipes)
{
    /* The data size is checked against the file's size, which only a regular
     * file has; /dev/zero is refused, not read as a (malformed) array. */
    expect_error("/dev/zero", HV_ERR_IO, "character device");
    expect_error(dir, HV_ERR_IO, "directory");
    char p[256];
    path_in_dir(p, sizeof p, "pipe.npy");
    ck_assert_int_eq(mkfifo(p, 0600), 0);
    /* held open for writing with bytes waiting, so that a reader that does
     * open it cannot block */
    int fd = open(p, O_RDWR);
    ck_assert_int_ge(fd, 0);
    ck_assert_int_eq(write(fd, "\x93NUMPY\x01\x00\x10\x00", 10), 10);
    expect_error(p, HV_ERR_IO, "pipe");
    close(fd);
}
END_TEST

START_TEST(npy_writer_should_fail_cleanly_in_a_missing_directory)
{
    char p[256];
    path_in_dir(p, sizeof p, "nodir/x.npy");
    hv_grid *g = ramp(2, 3, 3, 1);
    ck_assert_int_eq(hv_write_npy(p, g), HV_ERR_IO);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), p));
    /* only the directory's own entries remain: no temporary file anywhere */
    DIR *d = opendir(dir);
    int entries = 0;
    for (struct dirent *e; (e = readdir(d));)
        entries += strcmp(e->d_name, ".") && strcmp(e->d_name, "..");
    closedir(d);
    ck_assert_int_eq(entries, 0);
    hv_grid_destroy(&g);
}
END_TEST

START_TEST(npy_files_should_agree_with_numpy)
{
    require_numpy();
    char p[256], q[256], cmd[1024];
    path_in_dir(p, sizeof p, "ours.npy");
    hv_grid *g = ramp(3, 5, 4, 3);
    ck_assert_int_eq(hv_write_npy(p, g), HV_OK);
    /* numpy reads ours: shape, dtype and one value at (z,y,x) = (2,1,3) */
    snprintf(cmd, sizeof cmd,
             "/usr/bin/python3 -c 'import numpy as np,sys; a=np.load(sys.argv[1]); "
             "print(a.shape, a.dtype.str, repr(float(a[2,1,3])))' %s",
             p);
    FILE *pp = popen(cmd, "r");
    char line[256] = "";
    ck_assert_ptr_nonnull(fgets(line, sizeof line, pp));
    ck_assert_int_eq(pclose(pp), 0);
    char want[256];
    int tail = snprintf(want, sizeof want, "(3, 4, 5) <f4 ");
    (void)tail;
    ck_assert_msg(strncmp(line, want, strlen(want)) == 0, "numpy says: %s", line);
    double v = strtod(line + strlen(want), NULL);
    ck_assert_float_eq((float)v, g->v[3 + 5 * (1 + 4 * 2)]);

    /* ours reads numpy's: float64, C order, and a version 2.0 header */
    path_in_dir(q, sizeof q, "theirs.npy");
    snprintf(cmd, sizeof cmd,
             "/usr/bin/python3 -c 'import numpy as np,sys; "
             "a=np.arange(24,dtype=np.float64).reshape(2,3,4)*0.5-3; np.save(sys.argv[1],a); "
             "f=open(sys.argv[2],\"wb\"); np.lib.format.write_array(f,a.astype(np.float32),"
             "version=(2,0)); f.close()' %s %s",
             q, p);
    ck_assert_int_eq(system(cmd), 0);
    hv_grid *r = NULL;
    ck_assert_int_eq(hv_read_npy(q, &r), HV_OK);
    ck_assert_int_eq(r->n[0], 4);
    ck_assert_int_eq(r->n[1], 3);
    ck_assert_int_eq(r->n[2], 2);
    for (int i = 0; i < 24; i++)
        ck_assert_float_eq(r->v[i], (float)(i * 0.5 - 3));
    hv_grid_destroy(&r);
    ck_assert_int_eq(hv_read_npy(p, &r), HV_OK);
    for (int i = 0; i < 24; i++)
        ck_assert_float_eq(r->v[i], (float)(i * 0.5 - 3));
    hv_grid_destroy(&r);
    hv_grid_destroy(&g);
}
END_TEST

int main(void)
{
    Suite *s = suite_create("npy");
    TCase *tc = tcase_create("npy");
    /* a scratch directory per test, removed even when the test fails */
    tcase_add_checked_fixture(tc, make_dir, remove_dir);
    tcase_add_test(tc, npy_3d_round_trip_should_keep_shape_and_every_value);
    tcase_add_test(tc, npy_2d_round_trip_should_give_a_2d_grid);
    tcase_add_test(tc, npy_header_should_follow_format_1_0_padded_to_64);
    tcase_add_test(tc, npy_reader_should_accept_float64_and_version_2_headers);
    tcase_add_test(tc, npy_reader_should_refuse_truncated_data_naming_the_file);
    tcase_add_test(tc, npy_reader_should_refuse_other_dtypes_fortran_order_and_1d);
    tcase_add_test(tc, npy_reader_should_refuse_devices_directories_and_pipes);
    tcase_add_test(tc, npy_writer_should_fail_cleanly_in_a_missing_directory);
    tcase_add_test(tc, npy_files_should_agree_with_numpy);
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
