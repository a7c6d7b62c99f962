#include "testlib.h"

#include <dirent.h>
#include <limits.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

double tl_rand(uint64_t *s)
{
    *s = *s * 6364136223846793005ull + 1442695040888963407ull;
    return (double)(*s >> 11) / 9007199254740992.0 - 0.5;
}

void tl_fill_random(float *v, size_t n, uint64_t seed)
{
    for (size_t i = 0; i < n; i++)
        v[i] = (float)tl_rand(&seed);
}

const char *tl_test_data(void)
{
    const char *d = getenv("HEATVOX_TEST_DATA");
    if (!d || !*d)
        d = "../shared/meshes";
    struct stat st;
    if (stat(d, &st) != 0 || !S_ISDIR(st.st_mode))
        return NULL;
    return d;
}

int tl_long(void)
{
    const char *longrun = getenv("HEATVOX_TEST_LONG");
    return longrun && *longrun && strcmp(longrun, "0");
}

int tl_sanitized(void)
{
    if (tl_long())
        return 0;
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
    return 1;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
    return 1;
#endif
#endif
    return 0;
}

void tl_skip(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    printf("SKIP: ");
    vprintf(fmt, ap);
    printf("\n");
    va_end(ap);
    fflush(stdout);
}

void tl_not_run(const char *test, const char *why)
{
    printf("NOT RUN: %s: %s\n", test, why);
    fflush(stdout);
}

int tl_run(Suite *s)
{
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

const char *tl_heatvox_bin(void)
{
    /* $HEATVOX_BIN, else the command of the build this suite belongs to
     * (BUILD/tests/check_x -> BUILD/heatvox: make sanitize tests its own);
     * absolute, since suites change directories. */
    static char path[4096];
    const char *b = getenv("HEATVOX_BIN");
    char self[4096];
    if (!b || !*b) {
        ssize_t n = readlink("/proc/self/exe", self, sizeof self - 16);
        if (n <= 0)
            return NULL;
        self[n] = '\0';
        for (int up = 0; up < 2; up++) {
            char *slash = strrchr(self, '/');
            if (slash)
                *slash = '\0';
        }
        strcat(self, "/heatvox");
        b = self;
    }
    if (!realpath(b, path) || access(path, X_OK) != 0)
        return NULL;
    return path;
}

void tl_rm_rf(const char *p)
{
    struct stat sb;
    if (lstat(p, &sb) != 0)
        return;
    if (S_ISDIR(sb.st_mode)) {
        DIR *d = opendir(p);
        struct dirent *e;
        while (d && (e = readdir(d)))
            if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) {
                char sub[4096];
                snprintf(sub, sizeof sub, "%s/%s", p, e->d_name);
                tl_rm_rf(sub);
            }
        if (d)
            closedir(d);
        rmdir(p);
    } else
        unlink(p);
}

int tl_run_cmd(const char *cmd, const char *dir, char *err, size_t errsize)
{
    char full[4096], errfile[1024];
    snprintf(errfile, sizeof errfile, "%s/stderr.txt", dir);
    snprintf(full, sizeof full, "%s > /dev/null 2> %s", cmd, errfile);
    int rc = system(full);
    if (err && errsize > 0) {
        err[0] = 0;
        FILE *f = fopen(errfile, "r");
        if (f) {
            size_t n = fread(err, 1, errsize - 1, f);
            err[n] = 0;
            fclose(f);
        }
    }
    return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

void tl_pocl_cache(const char *argv0)
{
    if (getenv("POCL_CACHE_DIR"))
        return;
    char dir[4096];
    snprintf(dir, sizeof dir, "%s", argv0);
    char *slash = strrchr(dir, '/');
    snprintf(slash ? slash + 1 : dir, sizeof dir - (size_t)(slash ? slash + 1 - dir : 0),
             "../pocl-cache");
    setenv("POCL_CACHE_DIR", dir, 1);
}

void tl_scratch_scenes(const char *name, char *dir, size_t dirsize, char *bin, size_t binsize)
{
    const char *b = tl_heatvox_bin();
    ck_assert_msg(b != NULL, "build/heatvox not found (set HEATVOX_BIN)");
    char full[PATH_MAX];
    ck_assert_ptr_nonnull(realpath(b, full));
    ck_assert_int_lt(snprintf(bin, binsize, "%s", full), (int)binsize);
    ck_assert_int_lt(snprintf(dir, dirsize, "/tmp/hv_%s_XXXXXX", name), (int)dirsize);
    ck_assert_ptr_nonnull(mkdtemp(dir));
    char cmd[2 * PATH_MAX + 64];
    snprintf(cmd, sizeof cmd, "'%s' make-scenes '%s/sc' -q", bin, dir);
    ck_assert_int_eq(tl_run_cmd(cmd, dir, NULL, 0), 0);
}

int tl_hv(const char *dir, const char *bin, char *err, size_t errsize, const char *fmt, ...)
{
    char args[3000], cmd[8000];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(args, sizeof args, fmt, ap);
    va_end(ap);
    snprintf(cmd, sizeof cmd, "cd '%s' && '%s' %s", dir, bin, args);
    return tl_run_cmd(cmd, dir, err, errsize);
}

void tl_cl_traffic(double *to_device, double *to_host, long *reads)
{
    hv_opencl_kernel_time t[256];
    const int n = hv_opencl_profile_take(t, 256);
    *to_device = *to_host = 0;
    *reads = 0;
    for (int i = 0; i < n && i < 256; i++) {
        if (!strcmp(t[i].name, "write"))
            *to_device += t[i].bytes;
        if (!strcmp(t[i].name, "read")) {
            *to_host += t[i].bytes;
            *reads += t[i].launches;
        }
    }
}
