/*
 * The Python package (python/heatvox): runs the tests of tests/python/ once,
 * through tests/python/runner.py and Debian's /usr/bin/python3 ($HEATVOX_PYTHON
 * to use another), against the build this suite belongs to
 * (HEATVOX_LIBRARY=BUILD/libheatvox.so, HEATVOX_BIN=BUILD/heatvox,
 * HEATVOX_STAGE=BUILD/stage, which make check installs first), and reports each
 * Python test as one Check test: a pass, a failure with its traceback, or a
 * SKIP with its reason, so that make check's summary counts them one by one.
 * No python3 or no NumPy is a skip, never a pass.
 *
 * Under make sanitize the library carries AddressSanitizer, whose runtime must
 * come first in a process: Python is started with LD_PRELOAD of the compiler's
 * libasan and ASAN_OPTIONS=detect_leaks=0 (the interpreter keeps memory to
 * exit, which LeakSanitizer would report).
 *
 * Run from the repository root (make check does); the Python run's own output
 * is kept in BUILD/tests/check_python.pylog.
 */
#include "testlib.h"

#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#define MAX_TESTS 1024

typedef struct py_test {
    char *id;
    char status; /* 'P' pass, 'S' skip, 'F' fail, 0 no result */
    char *msg;
} py_test;

static py_test g_tests[MAX_TESTS];
static int g_ntests;
static char g_build[PATH_MAX];
static char g_log[PATH_MAX + 32];
static char g_why[1024];      /* set when nothing can run: the reason to skip or fail */
static int g_why_skip;        /* g_why is a skip (python3 or NumPy missing), else a failure */
static int g_rc;              /* exit status of the Python run */
static char g_orphans[16384]; /* failures of no listed test (a setUpClass error) */

/* BUILD from /proc/self/exe = BUILD/tests/check_python. */
static void find_build(void)
{
    ssize_t n = readlink("/proc/self/exe", g_build, sizeof g_build - 1);
    g_build[n > 0 ? n : 0] = '\0';
    for (int up = 0; up < 2; up++) {
        char *slash = strrchr(g_build, '/');
        if (slash)
            *slash = '\0';
    }
}

/* Undoes runner.py's escaping (\\, \t, \n) in place. */
static void unescape(char *s)
{
    char *w = s;
    for (const char *r = s; *r; r++) {
        if (*r == '\\' && r[1]) {
            r++;
            *w++ = *r == 'n' ? '\n' : *r == 't' ? '\t' : *r;
        } else {
            *w++ = *r;
        }
    }
    *w = '\0';
}

/* msg with every line after the first indented, so that no line of a
 * traceback starts with make check's "SKIP: " or "NOT RUN: ". The result
 * lives until the next call (a failed check does not return to free it). */
static char *indent(const char *msg)
{
    static char *out;
    size_t lines = 1;
    for (const char *p = msg; *p; p++)
        lines += *p == '\n';
    free(out);
    out = malloc(strlen(msg) + 4 * lines + 1);
    char *w = out;
    if (!out)
        return NULL;
    for (const char *p = msg; *p; p++) {
        *w++ = *p;
        if (*p == '\n' && p[1]) {
            memcpy(w, "    ", 4);
            w += 4;
        }
    }
    *w = '\0';
    return out;
}

static py_test *find_test(const char *id)
{
    for (int i = 0; i < g_ntests; i++)
        if (!strcmp(g_tests[i].id, id))
            return &g_tests[i];
    return NULL;
}

/* Reads runner.py's results: ID lines, then PASS/SKIP/FAIL lines. */
static void read_results(const char *path)
{
    FILE *f = fopen(path, "r");
    if (!f)
        return;
    size_t cap = 0;
    char *line = NULL;
    ssize_t len;
    while ((len = getline(&line, &cap, f)) > 0) {
        if (line[len - 1] == '\n')
            line[len - 1] = '\0';
        char *fields[3] = {line, NULL, NULL};
        for (int k = 1; k < 3; k++) {
            char *tab = fields[k - 1] ? strchr(fields[k - 1], '\t') : NULL;
            if (tab) {
                *tab = '\0';
                fields[k] = tab + 1;
            }
        }
        if (!fields[1])
            continue;
        unescape(fields[1]);
        if (fields[2])
            unescape(fields[2]);
        if (!strcmp(fields[0], "ID")) {
            if (g_ntests < MAX_TESTS)
                g_tests[g_ntests++].id = strdup(fields[1]);
            continue;
        }
        py_test *t = find_test(fields[1]);
        char status = !strcmp(fields[0], "PASS") ? 'P' : !strcmp(fields[0], "SKIP") ? 'S' : 'F';
        if (!t) {
            size_t used = strlen(g_orphans);
            snprintf(g_orphans + used, sizeof g_orphans - used, "%s: %s\n", fields[1],
                     fields[2] ? fields[2] : "");
            continue;
        }
        /* a test that fails in tearDown after passing reports twice: keep the failure */
        if (t->status != 'F') {
            t->status = status;
            free(t->msg);
            t->msg = strdup(fields[2] ? fields[2] : "");
        }
    }
    free(line);
    fclose(f);
}

/* The last `max` bytes of the Python run's log. */
static char *log_tail(size_t max)
{
    static char buf[8192];
    buf[0] = '\0';
    FILE *f = fopen(g_log, "r");
    if (!f)
        return buf;
    fseek(f, 0, SEEK_END);
    long size = ftell(f);
    if (max > sizeof buf - 1)
        max = sizeof buf - 1;
    fseek(f, size > (long)max ? size - (long)max : 0, SEEK_SET);
    size_t n = fread(buf, 1, max, f);
    buf[n] = '\0';
    fclose(f);
    return buf;
}

static void run_python(void)
{
    const char *python = getenv("HEATVOX_PYTHON");
    if (!python || !*python)
        python = "/usr/bin/python3";
    g_why_skip = 1;
    if (access(python, X_OK) != 0) {
        snprintf(g_why, sizeof g_why, "no %s: the Python package is not tested", python);
        return;
    }
    char cmd[16 * PATH_MAX];
    snprintf(cmd, sizeof cmd, "'%s' -c 'import numpy' > /dev/null 2>&1", python);
    if (system(cmd) != 0) {
        snprintf(g_why, sizeof g_why, "%s has no NumPy (python3-numpy): the package needs it",
                 python);
        return;
    }
    g_why_skip = 0;
    char cwd[PATH_MAX];
    if (!getcwd(cwd, sizeof cwd) || access("python/heatvox/__init__.py", R_OK) != 0 ||
        access("tests/python/runner.py", R_OK) != 0) {
        snprintf(g_why, sizeof g_why,
                 "python/heatvox and tests/python not found from the working directory (run "
                 "from the repository root)");
        return;
    }
    const char *preload = "";
#ifdef __SANITIZE_ADDRESS__
    static char asan[2 * PATH_MAX];
    /* The sanitized library needs the ASan runtime loaded first. */
    FILE *p = popen("cc -print-file-name=libasan.so", "r");
    char lib[PATH_MAX] = "";
    if (p) {
        if (fgets(lib, sizeof lib, p))
            lib[strcspn(lib, "\n")] = '\0';
        pclose(p);
    }
    if (lib[0] != '/' || access(lib, R_OK) != 0) {
        g_why_skip = 1;
        snprintf(g_why, sizeof g_why,
                 "sanitized build: no libasan.so from `cc -print-file-name` to preload into "
                 "python3");
        return;
    }
    /* libstdc++ too: python3 does not link it, and ASan, loaded first, finds
     * no __cxa_throw to intercept; the library's OpenVDB shim then aborts in
     * ASan's CHECK at its first C++ exception. */
    snprintf(asan, sizeof asan,
             "LD_PRELOAD='%s libstdc++.so.6' ASAN_OPTIONS=\"$ASAN_OPTIONS:detect_leaks=0\" ", lib);
    preload = asan;
#endif
    char results[PATH_MAX + 32];
    snprintf(results, sizeof results, "%s/tests/check_python.results", g_build);
    snprintf(g_log, sizeof g_log, "%s/tests/check_python.pylog", g_build);
    unlink(results);
    snprintf(cmd, sizeof cmd,
             "PYTHONPATH='%s/python:%s/tests/python' HEATVOX_LIBRARY='%s/libheatvox.so' "
             "HEATVOX_BIN='%s/heatvox' HEATVOX_STAGE='%s/stage' %stimeout 600 '%s' "
             "tests/python/runner.py '%s' > '%s' 2>&1",
             cwd, cwd, g_build, g_build, g_build, preload, python, results, g_log);
    double t0 = hv_now();
    int rc = system(cmd);
    g_rc = WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
    read_results(results);
    printf("python: %d tests in %.1f s, exit %d (output in %s)\n", g_ntests, hv_now() - t0, g_rc,
           g_log);
    fflush(stdout);
    if (!g_ntests)
        snprintf(g_why, sizeof g_why, "tests/python/runner.py listed no test (exit %d)", g_rc);
}

START_TEST(python_test)
{
    const py_test *t = &g_tests[_i];
    if (t->status == 'P')
        return;
    if (t->status == 'S')
        TL_SKIP("python %s: %s", t->id, t->msg);
    char *msg = indent(t->status == 'F' ? t->msg : g_orphans[0] ? g_orphans : log_tail(3000));
    ck_assert_ptr_nonnull(msg);
    if (t->status == 'F')
        ck_abort_msg("python %s failed:\n%s", t->id, msg);
    ck_abort_msg("python %s: no result (the Python run exited %d; %s):\n%s", t->id, g_rc, g_log,
                 msg);
}
END_TEST

START_TEST(python_suite)
{
    if (g_why_skip)
        TL_SKIP("%s", g_why);
    char *msg = indent(log_tail(3000));
    ck_abort_msg("%s; log %s:\n%s", g_why, g_log[0] ? g_log : "(none)", msg ? msg : "");
}
END_TEST

int main(int argc, char **argv)
{
    (void)argc;
    find_build();
    tl_pocl_cache(argv[0]);
    run_python();
    Suite *s = suite_create("python");
    TCase *tc = tcase_create("python");
    if (g_why[0] || !g_ntests)
        tcase_add_test(tc, python_suite);
    else
        tcase_add_loop_test(tc, python_test, 0, g_ntests);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
