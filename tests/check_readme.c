/* The user's manual runs as written: every `build/heatvox` command of
 * README.md's ```sh blocks, in order, in a fresh directory with the generated
 * scenes (a `# exits N: ...` comment names the exit code a command is meant
 * to have), and the ```c example of the Library section compiled against an
 * installed copy (make check stages `make install PREFIX=BUILD/stage`) and
 * run. README.md is read from the working directory (make check runs from the
 * repository root) or from $HEATVOX_README; HEATVOX_README_TIMES=1 prints
 * each command's time (every example should take a few seconds at most). */
#include "heatvox/heatvox.h"
#include "testlib.h"

#include <check.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* BUILD, the directory of the binaries under test: BUILD/tests/check_readme
 * sits beside BUILD/heatvox. */
static char build_dir[PATH_MAX];

static const char *readme_path(void)
{
    const char *p = getenv("HEATVOX_README");
    return p && *p ? p : "README.md";
}

/* The repository's scenes/ directory, beside README.md (absolute). */
static const char *scenes_dir(void)
{
    static char dir[PATH_MAX];
    char readme[PATH_MAX];
    if (!realpath(readme_path(), readme))
        return "scenes";
    char *slash = strrchr(readme, '/');
    *slash = 0;
    snprintf(dir, sizeof dir, "%.*s/scenes", PATH_MAX - 16, readme);
    return dir;
}

/* The whole file, NUL-terminated; the caller frees it. */
static char *slurp(const char *path)
{
    FILE *f = fopen(path, "rb");
    if (!f)
        return NULL;
    size_t cap = 1 << 16, n = 0;
    char *buf = malloc(cap);
    size_t got;
    while (buf && (got = fread(buf + n, 1, cap - n - 1, f)) > 0) {
        n += got;
        if (n + 1 == cap) {
            char *b = realloc(buf, cap *= 2);
            if (!b) {
                free(buf);
                buf = NULL;
            }
            buf = b;
        }
    }
    fclose(f);
    if (buf)
        buf[n] = 0;
    return buf;
}

typedef struct {
    char *text;   /* the command as written, continuation lines joined by newlines */
    int expected; /* exit code */
    int line;     /* its first line in README.md */
} readme_cmd;

/* Cuts the next line off *p (NUL-terminating it in place); NULL at the end. */
static char *next_line(char **p)
{
    if (!**p)
        return NULL;
    char *ln = *p, *nl = strchr(ln, '\n');
    if (nl) {
        *nl = 0;
        *p = nl + 1;
    } else {
        *p = ln + strlen(ln);
    }
    return ln;
}

/* The `build/heatvox` commands of the ```sh blocks, in order. */
static int extract_commands(char *readme, readme_cmd *cmds, int cap)
{
    int n = 0, in_sh = 0, lineno = 0;
    char *p = readme, *ln;
    while ((ln = next_line(&p))) {
        lineno++;
        if (!strncmp(ln, "```", 3)) {
            in_sh = !in_sh && !strcmp(ln, "```sh");
            continue;
        }
        if (!in_sh || strncmp(ln, "build/heatvox ", 14))
            continue;
        ck_assert_msg(n < cap, "more than %d commands in the README", cap);
        size_t len = strlen(ln);
        char *text = malloc(len + 1);
        ck_assert_ptr_nonnull(text);
        memcpy(text, ln, len + 1);
        cmds[n].line = lineno;
        /* A trailing backslash continues the command on the next line. */
        while (len && text[len - 1] == '\\') {
            char *next = next_line(&p);
            ck_assert_msg(next != NULL, "README.md:%d: continuation at the end", lineno);
            lineno++;
            size_t m = strlen(next);
            text = realloc(text, len + m + 2);
            ck_assert_ptr_nonnull(text);
            text[len] = '\n';
            memcpy(text + len + 1, next, m + 1);
            len += m + 1;
        }
        cmds[n].text = text;
        cmds[n].expected = 0;
        const char *c = strstr(text, "# exits ");
        if (c) {
            char *end;
            long e = strtol(c + 8, &end, 10);
            ck_assert_msg(end != c + 8 && *end == ':' && e >= 0 && e < 256,
                          "README.md:%d: write '# exits N: why'", cmds[n].line);
            cmds[n].expected = (int)e;
        }
        n++;
    }
    return n;
}

/* A fresh directory with `build` linked to the binaries under test and an
 * empty out/. */
static void make_workdir(char *dir, size_t size)
{
    char bin[PATH_MAX + 16];
    snprintf(bin, sizeof bin, "%s/heatvox", build_dir);
    ck_assert_msg(access(bin, X_OK) == 0, "%s not built", bin);
    snprintf(dir, size, "/tmp/hv_check_readme_XXXXXX");
    ck_assert_ptr_nonnull(mkdtemp(dir));
    char p[PATH_MAX + 64];
    snprintf(p, sizeof p, "%s/build", dir);
    ck_assert_int_eq(symlink(build_dir, p), 0);
    snprintf(p, sizeof p, "%s/out", dir);
    ck_assert_int_eq(mkdir(p, 0700), 0);
    snprintf(p, sizeof p, "%s/.log", dir);
    ck_assert_int_eq(mkdir(p, 0700), 0);
}

/* Runs `text` with /bin/sh in dir; its stderr lands in err. The command
 * stands alone in a subshell, so a trailing comment comments out nothing. */
static int run_in(const char *dir, const char *text, char *err, size_t errsize)
{
    size_t size = strlen(text) + 2 * strlen(dir) + 64;
    char *cmd = malloc(size), log[PATH_MAX];
    ck_assert_ptr_nonnull(cmd);
    snprintf(cmd, size, "( cd '%s' && %s\n)", dir, text);
    snprintf(log, sizeof log, "%s/.log", dir);
    int rc = tl_run_cmd(cmd, log, err, errsize);
    free(cmd);
    return rc;
}

START_TEST(every_readme_command_should_exit_as_documented)
{
    char *readme = slurp(readme_path());
    ck_assert_msg(readme != NULL,
                  "%s: cannot read (run from the repository root or set "
                  "HEATVOX_README)",
                  readme_path());
    static readme_cmd cmds[256];
    int n = extract_commands(readme, cmds, 256);
    ck_assert_msg(n >= 10, "only %d build/heatvox commands found in %s", n, readme_path());
    char dir[256];
    make_workdir(dir, sizeof dir);
    /* The repository's scenes/ holds the hand-written inputs (curves, the
     * batch manifest); make-scenes adds the generated ones. Generated files
     * left in the checkout are dropped first, so only make-scenes makes them. */
    static char err[16384];
    char setup[3 * PATH_MAX];
    snprintf(setup, sizeof setup,
             "cp -RL '%s' scenes && rm -f scenes/meshes/*.obj scenes/levelset/*.vdb "
             "scenes/distance/*.txt scenes/distance/*.vdb scenes/distance/*.obj && "
             "build/heatvox make-scenes scenes -q",
             scenes_dir());
    int rc = run_in(dir, setup, err, sizeof err);
    ck_assert_msg(rc == 0, "copying %s and make-scenes: exit %d: %s", scenes_dir(), rc, err);
    static char report[65536];
    size_t used = 0;
    int failed = 0;
    for (int i = 0; i < n; i++) {
        double t0 = hv_now();
        rc = run_in(dir, cmds[i].text, err, sizeof err);
        double dt = hv_now() - t0;
        /* A failure on purpose must also say why. */
        int silent = rc != 0 && rc == cmds[i].expected && !err[0];
        if (rc != cmds[i].expected || silent) {
            failed++;
            int w = snprintf(report + used, sizeof report - used,
                             "\nREADME.md:%d: exit %d, expected %d (%.1f s)%s:\n  %s\n  stderr: %s",
                             cmds[i].line, rc, cmds[i].expected, dt,
                             silent ? ", nothing on stderr" : "", cmds[i].text, err);
            if (w > 0)
                used = used + (size_t)w < sizeof report ? used + (size_t)w : sizeof report - 1;
        }
        if (getenv("HEATVOX_README_TIMES"))
            printf("README.md:%d: %.2f s, exit %d\n", cmds[i].line, dt, rc);
        free(cmds[i].text);
    }
    free(readme);
    if (!failed)
        tl_rm_rf(dir);
    ck_assert_msg(failed == 0, "%d of %d README commands failed (work directory %s kept):%s",
                  failed, n, dir, report);
}
END_TEST

/* Builds the ```c block that starts at `start` (after its fence) in a new
 * work directory against the staged install, runs it there, and checks that
 * it ran against the staged library. How long it takes is not checked here:
 * a wall-clock bound fails on a loaded machine or under the sanitizers. */
static void build_and_run(const char *start, int k)
{
    const char *end = strstr(start, "\n```");
    ck_assert_ptr_nonnull(end);
    char dir[256];
    make_workdir(dir, sizeof dir);
    char src[PATH_MAX];
    snprintf(src, sizeof src, "%s/prog.c", dir);
    FILE *f = fopen(src, "w");
    ck_assert_ptr_nonnull(f);
    fwrite(start, 1, (size_t)(end - start) + 1, f);
    ck_assert_int_eq(fclose(f), 0);

    /* A sanitized library (make sanitize) needs its runtime in the program. */
    const char *san = "";
#if defined(__SANITIZE_ADDRESS__)
    san = " -fsanitize=address,undefined";
#endif
    char cmd[4 * PATH_MAX], err[16384];
    snprintf(
        cmd, sizeof cmd,
        "export PKG_CONFIG_PATH='%s/stage/lib/pkgconfig'; "
        "libdir=$(pkg-config --variable=libdir heatvox) && "
        "cc -std=c11 -Wall -Wextra -Werror%s prog.c -o prog $(pkg-config --cflags --libs heatvox) "
        "-Wl,-rpath,\"$libdir\"",
        build_dir, san);
    int rc = run_in(dir, cmd, err, sizeof err);
    ck_assert_msg(rc == 0, "compiling the README's C example %d (%s/prog.c): exit %d: %s", k, dir,
                  rc, err);
    rc = run_in(dir, "./prog", err, sizeof err);
    ck_assert_msg(rc == 0, "the README's C example %d exited %d: %s", k, rc, err);
    /* It must have run against the staged library, not another copy. */
    rc = run_in(dir, "ldd ./prog | grep -q '/stage/lib/libheatvox\\.so'", err, sizeof err);
    ck_assert_msg(rc == 0, "prog is not linked against %s/stage/lib", build_dir);
    tl_rm_rf(dir);
}

START_TEST(the_library_examples_should_build_against_an_installed_copy_and_run)
{
    char *readme = slurp(readme_path());
    ck_assert_msg(readme != NULL, "%s: cannot read", readme_path());
    char pc[PATH_MAX + 64];
    snprintf(pc, sizeof pc, "%s/stage/lib/pkgconfig/heatvox.pc", build_dir);
    ck_assert_msg(access(pc, R_OK) == 0,
                  "%s missing: make check stages `make install PREFIX=BUILD/stage` first", pc);
    int k = 0;
    for (const char *at = strstr(readme, "\n```c\n"); at; at = strstr(at + 6, "\n```c\n"))
        build_and_run(at + 6, ++k);
    ck_assert_msg(k >= 2, "%s has %d ```c blocks, expected the library's examples", readme_path(),
                  k);
    free(readme);
}
END_TEST

int main(int argc, char **argv)
{
    (void)argc;
    char self[PATH_MAX];
    if (!realpath(argv[0], self)) {
        perror(argv[0]);
        return EXIT_FAILURE;
    }
    /* BUILD/tests/check_readme -> BUILD */
    for (int up = 0; up < 2; up++) {
        char *slash = strrchr(self, '/');
        if (slash)
            *slash = 0;
    }
    snprintf(build_dir, sizeof build_dir, "%s", self);
    /* PoCL's kernel cache with the build (the commands run elsewhere). */
    char cache[PATH_MAX + 16];
    snprintf(cache, sizeof cache, "%s/pocl-cache", build_dir);
    setenv("POCL_CACHE_DIR", cache, 0);
    Suite *s = suite_create("readme");
    TCase *tc = tcase_create("readme");
    tcase_set_timeout(tc, 600);
    tcase_add_test(tc, every_readme_command_should_exit_as_documented);
    tcase_add_test(tc, the_library_examples_should_build_against_an_installed_copy_and_run);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
