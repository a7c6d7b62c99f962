/*
 * The library's public face: every public header compiles on its own as C11
 * and as C++17, the shared library exports exactly the functions the headers
 * declare HV_API (nothing internal, no C++ template instances), its soname
 * carries the major version, hv_version() returns the headers' version, and
 * an installed copy links statically through `pkg-config --static`.
 *
 * Run from the repository root (make check does): the headers are read from
 * include/heatvox/, the libraries from the build directory that holds this
 * test (BUILD/tests/check_api), the installed copy from BUILD/stage, which
 * make check installs first.
 */
#include "testlib.h"

#include <dirent.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define MAX_NAMES 512

static char g_build[1024];

/* BUILD from /proc/self/exe = BUILD/tests/check_api. */
static void find_build(void)
{
    ssize_t n = readlink("/proc/self/exe", g_build, sizeof g_build - 1);
    g_build[n > 0 ? n : 0] = '\0'; /* a longer path fails the tests below, naming it */
    for (int up = 0; up < 2; up++) {
        char *slash = strrchr(g_build, '/');
        if (slash)
            *slash = '\0';
    }
}

static int cmp_str(const void *a, const void *b)
{
    return strcmp(*(const char *const *)a, *(const char *const *)b);
}

static int header_names(char ***out)
{
    static char *names[MAX_NAMES];
    int count = 0;
    DIR *d = opendir("include/heatvox");
    ck_assert_msg(d != NULL, "include/heatvox not found from %s (run from the repository root)",
                  getcwd((char[PATH_MAX]){0}, PATH_MAX));
    struct dirent *e;
    while ((e = readdir(d)) != NULL) {
        size_t len = strlen(e->d_name);
        if (len < 3 || strcmp(e->d_name + len - 2, ".h") != 0)
            continue;
        char path[PATH_MAX];
        snprintf(path, sizeof path, "include/heatvox/%s", e->d_name);
        FILE *f = fopen(path, "r");
        ck_assert_msg(f != NULL, "cannot open %s", path);
        char line[1024];
        while (fgets(line, sizeof line, f)) {
            if (strncmp(line, "HV_API ", 7) != 0)
                continue;
            char *paren = strchr(line, '(');
            ck_assert_msg(paren != NULL, "%s: HV_API line without '(': %s", path, line);
            char *end = paren;
            while (end > line && end[-1] == ' ')
                end--;
            char *start = end;
            while (start > line && (start[-1] == '_' || (start[-1] >= 'a' && start[-1] <= 'z') ||
                                    (start[-1] >= '0' && start[-1] <= '9')))
                start--;
            ck_assert_int_lt(count, MAX_NAMES);
            names[count++] = strndup(start, (size_t)(end - start));
        }
        fclose(f);
    }
    closedir(d);
    qsort(names, (size_t)count, sizeof *names, cmp_str);
    *out = names;
    return count;
}

/* Each header alone, as C and as C++, warnings as errors. */
START_TEST(test_headers_compile_alone)
{
    char dir[] = "/tmp/hv-api-XXXXXX";
    ck_assert_ptr_nonnull(mkdtemp(dir));
    DIR *d = opendir("include/heatvox");
    ck_assert_ptr_nonnull(d);
    struct dirent *e;
    int headers = 0;
    while ((e = readdir(d)) != NULL) {
        size_t len = strlen(e->d_name);
        if (len < 3 || strcmp(e->d_name + len - 2, ".h") != 0)
            continue;
        static const char *const lang[2][2] = {
            {"c", "cc -std=c11 -pedantic -Wall -Wextra -Werror"},
            {"cpp", "c++ -std=c++17 -pedantic -Wall -Wextra -Werror"}};
        for (int l = 0; l < 2; l++) {
            char src[PATH_MAX], cmd[3 * PATH_MAX], err[2048];
            snprintf(src, sizeof src, "%s/one.%s", dir, lang[l][0]);
            FILE *f = fopen(src, "w");
            ck_assert_ptr_nonnull(f);
            /* twice: include guards */
            fprintf(f,
                    "#include <heatvox/%s>\n#include <heatvox/%s>\nint main(void) { return 0; }\n",
                    e->d_name, e->d_name);
            ck_assert_int_eq(fclose(f), 0);
            snprintf(cmd, sizeof cmd, "%s -I'%s/include' -c '%s' -o '%s/one.o'", lang[l][1],
                     getcwd((char[PATH_MAX]){0}, PATH_MAX), src, dir);
            int rc = tl_run_cmd(cmd, dir, err, sizeof err);
            ck_assert_msg(rc == 0, "heatvox/%s does not compile as %s:\n%s", e->d_name,
                          l ? "C++17" : "C11", err);
        }
        headers++;
    }
    closedir(d);
    ck_assert_int_ge(headers, 10);
    tl_rm_rf(dir);
}
END_TEST

/* Exported beside the public API on purpose: assimp's assertion handler,
 * which libassimp must find in libheatvox before its own aborting one
 * (src/mesh/mesh_assimp_guard.cpp). */
static const char *const exported_on_purpose[] = {"_ZN6Assimp17aiAssertViolationEPKcS1_i"};

/* nm -D of the shared library against the HV_API declarations. */
START_TEST(test_exports_are_the_public_api)
{
    char **names;
    int count = header_names(&names);
    ck_assert_int_ge(count, 100);

    char cmd[PATH_MAX + 64];
    snprintf(cmd, sizeof cmd, "nm -D --defined-only '%s/libheatvox.so'", g_build);
    FILE *p = popen(cmd, "r");
    ck_assert_ptr_nonnull(p);
    char line[4096];
    int exported = 0, missing_from_headers = 0;
    char *seen = calloc((size_t)count, 1);
    while (fgets(line, sizeof line, p)) {
        char addr[64], type[8], name[3000];
        if (sscanf(line, "%63s %7s %2999s", addr, type, name) != 3)
            continue;
        char *at = strchr(name, '@');
        if (at)
            *at = '\0';
        int on_purpose = 0;
        for (size_t i = 0; i < sizeof exported_on_purpose / sizeof *exported_on_purpose; i++)
            on_purpose |= !strcmp(name, exported_on_purpose[i]);
        if (on_purpose)
            continue;
        exported++;
        const char *key = name;
        char **hit = bsearch(&key, names, (size_t)count, sizeof *names, cmp_str);
        if (!hit) {
            fprintf(stderr, "exported but not declared HV_API: %s (%s)\n", name, type);
            missing_from_headers++;
        } else {
            seen[hit - names] = 1;
        }
    }
    int rc = pclose(p);
    ck_assert_msg(rc == 0 && exported > 0, "'%s' failed", cmd);
    int not_exported = 0;
    for (int i = 0; i < count; i++)
        if (!seen[i]) {
            fprintf(stderr, "declared HV_API but not exported: %s\n", names[i]);
            not_exported++;
        }
    free(seen);
    ck_assert_msg(missing_from_headers == 0 && not_exported == 0,
                  "%d symbols exported beyond the public API, %d public functions missing "
                  "(listed above)",
                  missing_from_headers, not_exported);
    ck_assert_int_eq(exported, count);
}
END_TEST

START_TEST(test_soname_and_version)
{
    char expect[64];
    snprintf(expect, sizeof expect, "%d.%d.%d", HV_VERSION_MAJOR, HV_VERSION_MINOR,
             HV_VERSION_PATCH);
    ck_assert_str_eq(HV_VERSION_STRING, expect);
    ck_assert_str_eq(hv_version(), HV_VERSION_STRING);

    char cmd[PATH_MAX + 64], line[1024], soname[128] = "";
    snprintf(cmd, sizeof cmd, "readelf -d '%s/libheatvox.so'", g_build);
    FILE *p = popen(cmd, "r");
    ck_assert_ptr_nonnull(p);
    while (fgets(line, sizeof line, p)) {
        char *s = strstr(line, "Library soname: [");
        if (s)
            sscanf(s + 17, "%127[^]]", soname);
    }
    pclose(p);
    char want[64];
    snprintf(want, sizeof want, "libheatvox.so.%d", HV_VERSION_MAJOR);
    ck_assert_str_eq(soname, want);

    /* libheatvox.so and libheatvox.so.MAJOR both lead to libheatvox.so.X.Y.Z */
    char path[PATH_MAX], real[PATH_MAX], target[PATH_MAX];
    snprintf(path, sizeof path, "%s/libheatvox.so.%s", g_build, HV_VERSION_STRING);
    ck_assert_ptr_nonnull(realpath(path, target));
    snprintf(path, sizeof path, "%s/%s", g_build, want);
    ck_assert_ptr_nonnull(realpath(path, real));
    ck_assert_str_eq(real, target);
    snprintf(path, sizeof path, "%s/libheatvox.so", g_build);
    ck_assert_ptr_nonnull(realpath(path, real));
    ck_assert_str_eq(real, target);
}
END_TEST

/* A program against the copy `make check` installed into BUILD/stage: linked
 * through pkg-config --static it carries libheatvox.a (no libheatvox.so in
 * its NEEDED list) and runs without a library path; linked through
 * pkg-config with an rpath it loads libheatvox.so.MAJOR from the prefix. */
START_TEST(test_installed_copy_links)
{
    char stage[PATH_MAX];
    snprintf(stage, sizeof stage, "%s/stage", g_build);
    char pc[PATH_MAX + 64];
    snprintf(pc, sizeof pc, "%s/lib/pkgconfig/heatvox.pc", stage);
    ck_assert_msg(access(pc, R_OK) == 0, "%s missing: make check installs it first", pc);

    char dir[] = "/tmp/hv-api-XXXXXX";
    ck_assert_ptr_nonnull(mkdtemp(dir));
    char src[PATH_MAX];
    snprintf(src, sizeof src, "%s/prog.c", dir);
    FILE *f = fopen(src, "w");
    ck_assert_ptr_nonnull(f);
    /* a grid through OpenVDB and back (the C++ shim inside the library), an
     * error path, and the version */
    fputs("#include <heatvox/heatvox.h>\n"
          "#include <stdio.h>\n#include <string.h>\n"
          "#define OK(x) do { if ((x) != HV_OK) { fprintf(stderr, \"%s: %s\\n\", #x, "
          "hv_last_error()); return 1; } } while (0)\n"
          "int main(void)\n{\n"
          "    hv_grid *g = NULL, *back = NULL;\n"
          "    hv_vdb_writer *w = NULL;\n"
          "    OK(hv_grid_create(&g, 3, (int[3]){8, 8, 8}, 0.5, NULL));\n"
          "    for (size_t i = 0; i < hv_grid_count(g); i++) g->v[i] = (float)i;\n"
          "    OK(hv_vdb_writer_create(&w));\n"
          "    OK(hv_vdb_writer_add_float(w, g, \"f\"));\n"
          "    OK(hv_vdb_writer_write(w, \"prog.vdb\"));\n"
          "    hv_vdb_writer_destroy(&w);\n"
          "    OK(hv_vdb_read_float(\"prog.vdb\", \"f\", NULL, &back, NULL));\n"
          "    if (hv_grid_count(back) != hv_grid_count(g) ||\n"
          "        memcmp(back->v, g->v, hv_grid_count(g) * sizeof(float)) != 0) return 3;\n"
          "    hv_grid_destroy(&back);\n"
          "    hv_grid_destroy(&g);\n"
          "    if (hv_grid_create(&g, 3, (int[3]){0, 8, 8}, 0.5, NULL) == HV_OK)\n"
          "        return 2;\n"
          "    return strcmp(hv_version(), HV_VERSION_STRING) != 0;\n}\n",
          f);
    ck_assert_int_eq(fclose(f), 0);

#ifdef __SANITIZE_ADDRESS__
#define SAN " -fsanitize=address,undefined" /* make sanitize installs an instrumented copy */
#else
#define SAN ""
#endif
    static const char *const how[2] = {
        /* static: the archive first, then what it needs */
        "cc" SAN
        " prog.c -o prog $(pkg-config --cflags heatvox) -Wl,-Bstatic -lheatvox -Wl,-Bdynamic "
        "-Wl,--as-needed $(pkg-config --static --libs heatvox)",
        /* shared, found through the rpath */
        "cc" SAN " prog.c -o prog $(pkg-config --cflags --libs heatvox) "
        "-Wl,-rpath,$(pkg-config --variable=libdir heatvox)"};
    for (int k = 0; k < 2; k++) {
        char cmd[4 * PATH_MAX], err[4096];
        snprintf(
            cmd, sizeof cmd,
            "(cd '%s' && export PKG_CONFIG_PATH='%s/lib/pkgconfig' && unset LD_LIBRARY_PATH && "
            "%s && ./prog && if readelf -d prog | grep -q 'NEEDED.*libheatvox'; then echo "
            "shared; else echo static; fi > kind.txt)",
            dir, stage, how[k]);
        int rc = tl_run_cmd(cmd, dir, err, sizeof err);
        ck_assert_msg(rc == 0, "%s\nexit %d:\n%s", how[k], rc, err);
        char kindpath[PATH_MAX + 16], kind[32] = "";
        snprintf(kindpath, sizeof kindpath, "%s/kind.txt", dir);
        FILE *kf = fopen(kindpath, "r");
        ck_assert_ptr_nonnull(kf);
        ck_assert_ptr_nonnull(fgets(kind, sizeof kind, kf));
        fclose(kf);
        ck_assert_str_eq(kind, k == 0 ? "static\n" : "shared\n");
    }
    tl_rm_rf(dir);
}
END_TEST

int main(void)
{
    find_build();
    Suite *s = suite_create("api");
    TCase *tc = tcase_create("api");
    tcase_set_timeout(tc, 300);
    tcase_add_test(tc, test_headers_compile_alone);
    tcase_add_test(tc, test_exports_are_the_public_api);
    tcase_add_test(tc, test_soname_and_version);
    tcase_add_test(tc, test_installed_copy_links);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
