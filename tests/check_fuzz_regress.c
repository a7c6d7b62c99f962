/* Replays every input kept in tests/fuzz/regress/NAME/ (crashers the fuzz
 * targets found, and reproducers of parser defects) through the reader of
 * that target: each must come back with a status, HV_OK or an error with a
 * message, never a crash. `make sanitize` runs this under ASan and UBSan.
 * The directory is $HEATVOX_FUZZ_REGRESS, else tests/fuzz/regress (make check
 * runs from the repository root). */
#include "fuzz/fuzz_assimp.h"
#include "testlib.h"

#include <dirent.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static const char *regress_root(void)
{
    const char *d = getenv("HEATVOX_FUZZ_REGRESS");
    return d && *d ? d : "tests/fuzz/regress";
}

static char *slurp(const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    ck_assert_msg(f != NULL, "%s: cannot open", path);
    size_t cap = 4096, n = 0;
    char *b = malloc(cap);
    for (;;) {
        ck_assert_ptr_nonnull(b);
        n += fread(b + n, 1, cap - n, f);
        if (n < cap)
            break;
        cap *= 2;
        b = realloc(b, cap);
    }
    fclose(f);
    *len = n;
    return b;
}

/* A copy of src under a name with the extension the mesh reader dispatches
 * on; the assimp target's inputs start with the byte that picks it
 * (fuzz/fuzz_assimp.h), which is left out of the copy. */
static const char *with_ext(const char *src, const char *ext)
{
    static char path[512];
    size_t n;
    char *b = slurp(src, &n), *data = b;
    if (!ext) {
        ck_assert_msg(n > 0, "%s: empty (the first byte picks the extension)", src);
        ext = fz_assimp_ext((uint8_t)b[0]);
        data++;
        n--;
    }
    snprintf(path, sizeof path, "%s/hv_regress_%ld%s", getenv("TMPDIR") ? getenv("TMPDIR") : "/tmp",
             (long)getpid(), ext);
    FILE *f = fopen(path, "wb");
    ck_assert_msg(f && fwrite(data, 1, n, f) == n && fclose(f) == 0, "%s: cannot write", path);
    free(b);
    return path;
}

static void check_status(hv_status st, const char *file)
{
    ck_assert_msg(st >= HV_OK && st <= HV_ERR_INTERNAL, "%s: status %d", file, (int)st);
    ck_assert_msg(st != HV_ERR_INTERNAL, "%s: internal error: %s", file, hv_last_error());
    ck_assert_msg(st == HV_OK || *hv_last_error(), "%s: %s without a message", file,
                  hv_status_str(st));
}

static void replay(const char *target, const char *file)
{
    hv_clear_error();
    if (!strcmp(target, "obj") || !strcmp(target, "ply") || !strcmp(target, "stl") ||
        !strcmp(target, "off") || !strcmp(target, "mesh") || !strcmp(target, "assimp")) {
        char ext[264] = ""; /* mesh: no extension, the format by content */
        if (strcmp(target, "mesh"))
            snprintf(ext, sizeof ext, ".%s", target);
        const char *p = with_ext(file, strcmp(target, "assimp") ? ext : NULL);
        hv_mesh *m = NULL;
        hv_status st = hv_mesh_read(p, &m);
        check_status(st, file);
        if (st == HV_OK) {
            hv_mesh_report r;
            double lo[3], hi[3];
            check_status(hv_mesh_report_compute(m, &r), file);
            hv_mesh_bounds(m, lo, hi);
        }
        hv_mesh_destroy(&m);
        unlink(p);
    } else if (!strcmp(target, "points")) {
        const char *p = with_ext(file, ".xyz");
        hv_points *P = NULL;
        check_status(hv_points_read(p, &P), file);
        hv_points_destroy(&P);
        unlink(p);
    } else if (!strcmp(target, "svg") || !strcmp(target, "curves")) {
        size_t n;
        char *b = slurp(file, &n);
        hv_curves *c = NULL;
        hv_status st = hv_curves_parse(b, n, !strcmp(target, "svg"), file, &c);
        check_status(st, file);
        if (st == HV_OK) {
            double lo[2], hi[2];
            hv_curves_segments(c);
            check_status(hv_curves_bounds(c, lo, hi), file);
        }
        hv_curves_destroy(&c);
        free(b);
    } else if (!strcmp(target, "npy")) {
        hv_grid *g = NULL;
        check_status(hv_read_npy(file, &g), file);
        hv_grid_destroy(&g);
    } else if (!strcmp(target, "exr")) {
        hv_grid *g = NULL;
        check_status(hv_exr_read(file, NULL, &g), file);
        hv_grid_destroy(&g);
    } else if (!strcmp(target, "vdb")) {
        hv_vdb_grid_info info[4];
        size_t count = 0;
        hv_status st = hv_vdb_list(file, info, 4, &count);
        check_status(st, file);
        for (size_t i = 0; st == HV_OK && i < count && i < 4; i++) {
            hv_grid *g = NULL;
            hv_vdb_read_opts o = {1,
                                  {info[i].bbox_lo[0], info[i].bbox_lo[1], info[i].bbox_lo[2]},
                                  {info[i].bbox_lo[0], info[i].bbox_lo[1], info[i].bbox_lo[2]}};
            check_status(hv_vdb_read_mask(file, info[i].name, &o, &g), file);
            hv_grid_destroy(&g);
        }
    } else {
        ck_abort_msg("%s: no reader for the directory '%s'", file, target);
    }
}

START_TEST(every_regression_input_should_give_a_status_without_crashing)
{
    const char *root = regress_root();
    DIR *d = opendir(root);
    if (!d)
        TL_SKIP("%s not found (run from the repository root or set HEATVOX_FUZZ_REGRESS)", root);
    size_t files = 0;
    struct dirent *e;
    while ((e = readdir(d))) {
        if (e->d_name[0] == '.')
            continue;
        char sub[1024];
        snprintf(sub, sizeof sub, "%s/%s", root, e->d_name);
        DIR *s = opendir(sub);
        if (!s)
            continue;
        struct dirent *f;
        while ((f = readdir(s))) {
            char path[2048];
            snprintf(path, sizeof path, "%s/%s", sub, f->d_name);
            struct stat sb;
            if (f->d_name[0] == '.' || stat(path, &sb) != 0 || !S_ISREG(sb.st_mode))
                continue;
            replay(e->d_name, path);
            files++;
        }
        closedir(s);
    }
    closedir(d);
    printf("replayed %zu regression inputs from %s\n", files, root);
    ck_assert_msg(files > 0, "%s holds no inputs", root);
}
END_TEST

int main(void)
{
    Suite *s = suite_create("fuzz_regress");
    TCase *tc = tcase_create("replay");
    tcase_set_timeout(tc, 120);
    tcase_add_test(tc, every_regression_input_should_give_a_status_without_crashing);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
