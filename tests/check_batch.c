/* heatvox batch, run as a program: a mix of good, malformed and missing meshes;
 * outputs, report lines, exit codes, resume, --force, --dry-run, interruption.
 * The binary is $HEATVOX_BIN, else ../heatvox next to this test's directory. */
#include "heatvox/heatvox.h"
#include "testlib.h"

#include <check.h>
#include <dirent.h>
#include <fcntl.h>
#include <limits.h>
#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

static char bin[PATH_MAX];
static char dir[256];

static const char *heatvox_bin(void)
{
    const char *env = getenv("HEATVOX_BIN");
    if (env && *env)
        snprintf(bin, sizeof bin, "%s", env);
    else {
        char self[PATH_MAX];
        ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
        ck_assert_int_gt(n, 0);
        self[n] = '\0';
        char *slash = strrchr(self, '/');
        *slash = '\0';
        snprintf(bin, sizeof bin, "%.4000s/../heatvox", self);
    }
    ck_assert_msg(access(bin, X_OK) == 0, "heatvox binary %s not found (set HEATVOX_BIN)", bin);
    return bin;
}

static const char *path(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
static const char *path(const char *fmt, ...)
{
    static char buf[8][600];
    static int which;
    which = (which + 1) % 8;
    char rel[400];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(rel, sizeof rel, fmt, ap);
    va_end(ap);
    snprintf(buf[which], sizeof buf[which], "%.190s/%.390s", dir, rel);
    return buf[which];
}

static void write_text(const char *p, const char *text)
{
    FILE *f = fopen(p, "w");
    ck_assert_ptr_nonnull(f);
    fputs(text, f);
    fclose(f);
}

static char *read_text(const char *p)
{
    FILE *f = fopen(p, "rb");
    if (!f)
        return calloc(1, 1);
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    char *s = malloc((size_t)n + 1);
    s[fread(s, 1, (size_t)n, f)] = '\0';
    fclose(f);
    return s;
}

/* Runs heatvox with the arguments; stdout and stderr go to files in dir.
 * Returns the exit code (or 128 + signal). */
static int run(const char *args)
{
    char cmd[16384];
    snprintf(cmd, sizeof cmd, "'%s' %.4000s >'%s/stdout.txt' 2>'%s/stderr.txt' </dev/null", bin,
             args, dir, dir);
    int st = system(cmd);
    ck_assert_int_ne(st, -1);
    return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
}

/* The report line for input `file` and output `output` (malloc'd), or NULL. */
static char *report_line(const char *report, const char *file, const char *output)
{
    char key[1400];
    snprintf(key, sizeof key, "\"file\":\"%s\",\"output\":\"%s\"", file, output);
    const char *p = strstr(report, key);
    if (!p)
        return NULL;
    while (p > report && p[-1] != '\n')
        p--;
    const char *e = strchr(p, '\n');
    size_t n = e ? (size_t)(e - p) : strlen(p);
    char *s = malloc(n + 1);
    memcpy(s, p, n);
    s[n] = '\0';
    return s;
}

static double mtime(const char *p)
{
    struct stat sb;
    if (stat(p, &sb) != 0)
        return -1;
    return sb.st_mtim.tv_sec + 1e-9 * sb.st_mtim.tv_nsec;
}

static int count_temps(const char *d)
{
    DIR *dd = opendir(d);
    struct dirent *e;
    int n = 0;
    while (dd && (e = readdir(dd)))
        n += strstr(e->d_name, ".tmp-") != NULL;
    if (dd)
        closedir(dd);
    return n;
}

/* Processes whose command line mentions text (workers of a batch). */
/* Counts the processes whose command line holds text and also, when also is
 * not NULL, that; *first gets the pid of the first (may be NULL). */
static int processes_with(const char *text, const char *also, pid_t *first)
{
    DIR *d = opendir("/proc");
    struct dirent *e;
    int n = 0;
    while (d && (e = readdir(d))) {
        if (e->d_name[0] < '0' || e->d_name[0] > '9')
            continue;
        char p[300], buf[4096];
        snprintf(p, sizeof p, "/proc/%s/cmdline", e->d_name);
        FILE *f = fopen(p, "rb");
        if (!f)
            continue;
        size_t k = fread(buf, 1, sizeof buf - 1, f);
        fclose(f);
        for (size_t i = 0; i < k; i++)
            if (!buf[i])
                buf[i] = ' ';
        buf[k] = '\0';
        if (strstr(buf, text) && (!also || strstr(buf, also))) {
            if (first && n == 0)
                *first = (pid_t)atol(e->d_name);
            n++;
        }
    }
    if (d)
        closedir(d);
    return n;
}

static int processes_mentioning(const char *text) { return processes_with(text, NULL, NULL); }

/* in/sphere.obj, in/sub/torus.obj, in/broken.obj (index out of range),
 * in/empty.obj, and a manifest naming the sphere with its own options, a
 * missing file and a bad option. */
static void make_inputs(void)
{
    snprintf(dir, sizeof dir, "/tmp/hv_check_batch_XXXXXX");
    ck_assert_ptr_nonnull(mkdtemp(dir));
    heatvox_bin();
    ck_assert_int_eq(mkdir(path("in"), 0777), 0);
    ck_assert_int_eq(mkdir(path("in/sub"), 0777), 0);
    hv_mesh *m = NULL;
    double c[3] = {0.1, -0.2, 0.3};
    TL_ASSERT_OK(hv_mesh_make_sphere(&m, c, 1.0, 3));
    TL_ASSERT_OK(hv_mesh_write_obj(m, path("in/sphere.obj")));
    hv_mesh_destroy(&m);
    TL_ASSERT_OK(hv_mesh_make_torus(&m, c, 1.0, 0.35, 32, 16));
    TL_ASSERT_OK(hv_mesh_write_obj(m, path("in/sub/torus.obj")));
    hv_mesh_destroy(&m);
    write_text(path("in/broken.obj"), "v 0 0 0\nv 1 0 0\nf 1 2 7\n");
    write_text(path("in/empty.obj"), "# nothing here\n");
    write_text(path("in/notes.md"), "not a mesh: ignored by the directory walk\n");
    write_text(path("list.txt"), "# manifest\n"
                                 "in/sphere.obj --res 16   # same mesh, its own grid\n"
                                 "\n"
                                 "does/not/exist.obj\n"
                                 "'in/sub/torus.obj' --no-such-option\n");
}

static void remove_inputs(void) { tl_rm_rf(dir); }

static void check_sdf_exr(const char *p, int res, int inside_at_centre)
{
    hv_grid *g = NULL;
    TL_ASSERT_OK(hv_exr_read(p, NULL, &g));
    ck_assert_int_eq(g->dim, 3);
    int longest = g->n[0] > g->n[1] ? g->n[0] : g->n[1];
    longest = longest > g->n[2] ? longest : g->n[2];
    ck_assert_int_ge(longest, res);
    ck_assert_int_lt(longest, res + 8);
    /* The mesh is centred at (0.1, -0.2, 0.3): sample the nearest cell. */
    int ijk[3];
    double c[3] = {0.1, -0.2, 0.3};
    for (int a = 0; a < 3; a++)
        ijk[a] = (int)floor((c[a] - g->origin[a]) / g->h);
    float v = g->v[ijk[0] + (size_t)g->n[0] * (ijk[1] + (size_t)g->n[1] * ijk[2])];
    /* the sampled cell centre is within h sqrt(3)/2 of the mesh centre */
    if (inside_at_centre)
        ck_assert_msg(v < -(1 - g->h), "%s: centre value %g, expected about -1", p, v);
    else
        ck_assert_msg(v > 0.5f, "%s: torus hole value %g, expected about 0.65", p, v);
    hv_grid_destroy(&g);
}

static int run_in_dir(const char *args)
{
    char cwd[PATH_MAX];
    ck_assert_ptr_nonnull(getcwd(cwd, sizeof cwd));
    ck_assert_int_eq(chdir(dir), 0);
    int rc = run(args);
    ck_assert_int_eq(chdir(cwd), 0);
    return rc;
}

START_TEST(mixed_batch_should_isolate_failures_and_resume)
{
    make_inputs();
    const char *args =
        "batch in list.txt -o out -j 2 --res 24 --format exr --preview --report report.jsonl";
    int rc = run_in_dir(args);
    char *err = read_text(path("stderr.txt")), *out = read_text(path("stdout.txt"));
    char *rep = read_text(path("report.jsonl"));
    ck_assert_msg(rc == 1, "exit %d (failures must give 1); stderr:\n%s", rc, err);
    /* good ones written, with previews and sidecars */
    check_sdf_exr(path("out/sphere.exr"), 24, 1);
    check_sdf_exr(path("out/sub/torus.exr"), 24, 0);
    check_sdf_exr(path("out/sphere_2.exr"), 16, 1); /* the manifest's own --res 16 */
    ck_assert(mtime(path("out/sphere.exr.heatvox.json")) > 0);
    uint8_t *rgb = NULL;
    int w, h;
    TL_ASSERT_OK(hv_png_read_rgb(path("out/sphere.png"), &rgb, &w, &h));
    ck_assert_int_gt(w, 3 * 24);
    free(rgb);
    /* bad ones: nothing written, each named with its error on stderr */
    ck_assert(mtime(path("out/broken.exr")) < 0 && mtime(path("out/empty.exr")) < 0);
    ck_assert_msg(strstr(err, "in/broken.obj: line 3") != NULL, "stderr:\n%s", err);
    ck_assert_msg(strstr(err, "in/empty.obj") != NULL, "stderr:\n%s", err);
    ck_assert_msg(strstr(err, "does/not/exist.obj: cannot open") != NULL, "stderr:\n%s", err);
    ck_assert_msg(strstr(err, "--no-such-option") != NULL, "stderr:\n%s", err);
    /* summary on stdout: 3 written, 4 failed */
    ck_assert_msg(strstr(out, "7 inputs: 3 written, 0 up to date, 4 failed") != NULL, "stdout:\n%s",
                  out);
    /* report: one line per input with the documented fields */
    int lines = 0;
    for (const char *p = rep; *p; p++)
        lines += *p == '\n';
    ck_assert_int_eq(lines, 7);
    char *l = report_line(rep, "in/sphere.obj", "out/sphere.exr");
    ck_assert_ptr_nonnull(l);
    ck_assert_ptr_nonnull(strstr(l, "\"status\":\"ok\""));
    ck_assert_ptr_nonnull(strstr(l, "\"grid\":[24,24,24]"));
    ck_assert_ptr_nonnull(strstr(l, "\"seconds\":{\"read\":"));
    ck_assert_ptr_nonnull(strstr(l, "\"poisson\":"));
    ck_assert_ptr_nonnull(strstr(l, "\"defects\":{\"vertices\":642,\"triangles\":1280,"
                                    "\"boundary_edges\":0"));
    free(l);
    l = report_line(rep, "in/broken.obj", "out/broken.exr");
    ck_assert_ptr_nonnull(l);
    ck_assert_ptr_nonnull(strstr(l, "\"status\":\"failed\""));
    ck_assert_ptr_nonnull(strstr(l, "\"stage\":\"read\""));
    ck_assert_ptr_nonnull(strstr(l, "\"error\":\"in/broken.obj: line 3"));
    free(l);
    l = report_line(rep, "does/not/exist.obj", "out/exist.exr");
    ck_assert_ptr_nonnull(l);
    ck_assert_ptr_nonnull(strstr(l, "\"status\":\"failed\""));
    free(l);
    free(err);
    free(out);
    free(rep);

    /* Resume: nothing recomputed, failures still fail. */
    double t_sphere = mtime(path("out/sphere.exr")), t_torus = mtime(path("out/sub/torus.exr"));
    rc = run_in_dir(args);
    out = read_text(path("stdout.txt"));
    rep = read_text(path("report.jsonl"));
    ck_assert_int_eq(rc, 1);
    ck_assert_msg(strstr(out, "7 inputs: 0 written, 3 up to date, 4 failed") != NULL, "stdout:\n%s",
                  out);
    ck_assert(mtime(path("out/sphere.exr")) == t_sphere);
    l = report_line(rep, "in/sphere.obj", "out/sphere.exr");
    ck_assert_ptr_nonnull(strstr(l, "\"status\":\"skipped\""));
    free(l);
    free(out);
    free(rep);

    /* A newer input is recomputed, alone. */
    struct timespec later[2] = {{0, UTIME_NOW}, {0, UTIME_NOW}};
    ck_assert_int_eq(utimensat(AT_FDCWD, path("in/sub/torus.obj"), later, 0), 0);
    rc = run_in_dir(args);
    out = read_text(path("stdout.txt"));
    ck_assert_msg(strstr(out, "1 written, 2 up to date, 4 failed") != NULL, "stdout:\n%s", out);
    ck_assert(mtime(path("out/sub/torus.exr")) > t_torus);
    ck_assert(mtime(path("out/sphere.exr")) == t_sphere);
    free(out);

    /* Other options: recomputed. --force: recomputed. */
    rc = run_in_dir("batch in -o out --res 20 --format exr --preview");
    out = read_text(path("stdout.txt"));
    ck_assert_int_eq(rc, 1); /* broken.obj and empty.obj */
    ck_assert_msg(strstr(out, "4 inputs: 2 written, 0 up to date, 2 failed") != NULL, "stdout:\n%s",
                  out);
    check_sdf_exr(path("out/sphere.exr"), 20, 1);
    free(out);
    rc = run_in_dir("batch in/sphere.obj -o out --res 20 --format exr --preview");
    out = read_text(path("stdout.txt"));
    ck_assert_int_eq(rc, 0);
    ck_assert_msg(strstr(out, "1 input: 0 written, 1 up to date") != NULL, "stdout:\n%s", out);
    free(out);
    rc = run_in_dir("batch in/sphere.obj -o out --res 20 --format exr --preview --force");
    out = read_text(path("stdout.txt"));
    ck_assert_int_eq(rc, 0);
    ck_assert_msg(strstr(out, "1 input: 1 written, 0 up to date") != NULL, "stdout:\n%s", out);
    free(out);
    /* A removed preview makes the output stale when previews are asked for. */
    unlink(path("out/sphere.png"));
    rc = run_in_dir("batch in/sphere.obj -o out --res 20 --format exr --preview --dry-run");
    out = read_text(path("stdout.txt"));
    ck_assert_msg(strstr(out, "run  in/sphere.obj -> out/sphere.exr") != NULL, "stdout:\n%s", out);
    free(out);
    ck_assert_int_eq(count_temps(path("out")), 0);
    remove_inputs();
}
END_TEST

START_TEST(default_output_should_be_a_vdb_level_set_that_slice_can_cut)
{
    make_inputs();
    /* a directory's files land in OUTDIR under their path below that directory */
    int rc = run_in_dir("batch in/sub -o out --res 24 --band 2 --report rep.json");
    ck_assert_int_eq(rc, 0);
    /* a narrow band alone is computed in tiles, which the report counts */
    char *rep = read_text(path("rep.json"));
    ck_assert_ptr_nonnull(rep);
    ck_assert_msg(strstr(rep, "\"tiles\":") && strstr(rep, "\"sign\":\"winding\""),
                  "no tiles in the report: %s", rep);
    free(rep);
    hv_grid *g = NULL;
    int cls = -1;
    TL_ASSERT_OK(hv_vdb_read_float(path("out/torus.vdb"), "sdf", NULL, &g, &cls));
    ck_assert_int_eq(cls, HV_VDB_LEVEL_SET);
    ck_assert_int_eq(g->n[0], 24); /* the torus is widest along x and y */
    ck_assert_int_eq(g->n[1], 24);
    /* narrow band of 2 voxels: values are clamped to +-2h, positive in the hole */
    double x[3] = {0.1, -0.2, 0.3};
    int ijk[3];
    for (int a = 0; a < 3; a++)
        ijk[a] = (int)floor((x[a] - g->origin[a]) / g->h);
    float v = g->v[ijk[0] + (size_t)g->n[0] * (ijk[1] + (size_t)g->n[1] * ijk[2])];
    ck_assert(fabsf(v - (float)(2 * g->h)) < 1e-5f);
    char meta[2048];
    TL_ASSERT_OK(
        hv_vdb_read_meta(path("out/torus.vdb"), NULL, "heatvox_options", meta, sizeof meta));
    ck_assert_ptr_nonnull(strstr(meta, "res=24"));
    ck_assert_ptr_nonnull(strstr(meta, "band=2 dense=0"));
    hv_grid_destroy(&g);
    rc = run_in_dir("slice out/torus.vdb --axis y -o y.png");
    ck_assert_int_eq(rc, 0);
    uint8_t *rgb = NULL;
    int w, h;
    TL_ASSERT_OK(hv_png_read_rgb(path("y.png"), &rgb, &w, &h));
    ck_assert_int_eq(w, 24);
    ck_assert_int_gt(h, 6); /* z extent of the torus block */
    free(rgb);
    ck_assert_int_eq(run_in_dir("slice out/torus.vdb --grid nope -o y.png"), 1);
    ck_assert_int_eq(run_in_dir("slice out/torus.vdb --index 99 -o y.png"), 1);
    remove_inputs();
}
END_TEST

START_TEST(sdf_preview_should_show_the_three_middle_slices)
{
    make_inputs();
    ck_assert_int_eq(run_in_dir("sdf in/sphere.obj -o s.vdb --res 16 --preview s.png -q"), 0);
    uint8_t *rgb = NULL;
    int w, h;
    TL_ASSERT_OK(hv_png_read_rgb(path("s.png"), &rgb, &w, &h));
    /* a sphere: a 16^3 block, three 16 x 16 slices and two gaps */
    ck_assert_int_eq(w, 3 * 16 + 2 * HV_PNG_GAP);
    ck_assert_int_eq(h, 16);
    for (int s = 0; s < 3; s++) {
        const uint8_t *centre = rgb + 3 * ((size_t)8 * w + s * (16 + HV_PNG_GAP) + 8);
        const uint8_t *corner = rgb + 3 * ((size_t)s * (16 + HV_PNG_GAP));
        ck_assert_msg(centre[2] > centre[0], "slice %d: centre not blue", s);
        ck_assert_msg(corner[0] > corner[2], "slice %d: corner not red", s);
    }
    free(rgb);
    ck_assert_int_eq(run_in_dir("sdf in/sphere.obj -o s.vdb --res 16 --preview /nonexistent/p.png"),
                     1);
    remove_inputs();
}
END_TEST

START_TEST(dry_run_should_list_jobs_and_write_nothing)
{
    make_inputs();
    int rc = run_in_dir("batch in list.txt -o out --res 24 --format exr --dry-run");
    char *out = read_text(path("stdout.txt"));
    ck_assert_int_eq(rc, 1); /* the manifest names a missing file and a bad option */
    ck_assert_ptr_nonnull(strstr(out, "run  in/sphere.obj -> out/sphere.exr"));
    ck_assert_ptr_nonnull(strstr(out, "run  in/sub/torus.obj -> out/sub/torus.exr"));
    ck_assert_ptr_nonnull(strstr(out, "run  in/sphere.obj -> out/sphere_2.exr"));
    ck_assert_ptr_nonnull(strstr(out, "fail does/not/exist.obj: cannot open"));
    ck_assert_ptr_null(strstr(out, "notes.md"));
    ck_assert(mtime(path("out")) < 0);
    free(out);
    rc = run_in_dir("batch in/sphere.obj in/sub -o out --dry-run");
    ck_assert_int_eq(rc, 0);
    ck_assert(mtime(path("out")) < 0);
    remove_inputs();
}
END_TEST

START_TEST(usage_errors_should_exit_2)
{
    make_inputs();
    ck_assert_int_eq(run_in_dir("batch in"), 2);                   /* no -o */
    ck_assert_int_eq(run_in_dir("batch -o out"), 2);               /* no input */
    ck_assert_int_eq(run_in_dir("batch in -o out --res zero"), 2); /* bad global option */
    ck_assert_int_eq(run_in_dir("batch in -o out -j 0"), 2);
    ck_assert_int_eq(run_in_dir("batch in -o out --frobnicate"), 2);
    ck_assert_int_eq(run_in_dir("batch --help"), 0);
    ck_assert(mtime(path("out")) < 0);
    remove_inputs();
}
END_TEST

START_TEST(interrupted_batch_should_leave_no_partial_outputs)
{
    make_inputs();
    /* Several copies of the torus at a size that takes a while. */
    ck_assert_int_eq(mkdir(path("many"), 0777), 0);
    char *torus = read_text(path("in/sub/torus.obj"));
    for (int i = 0; i < 6; i++)
        write_text(path("many/t%d.obj", i), torus);
    free(torus);
    ck_assert_int_eq(mkdir(path("out"), 0777), 0);
    pid_t pid = fork();
    if (pid == 0) {
        int fd = open("/dev/null", O_WRONLY);
        dup2(fd, 1);
        dup2(fd, 2);
        execl(bin, "heatvox", "batch", path("many"), "-o", path("out"), "-j", "2", "--res", "64",
              "--format", "exr", "--preview", (char *)NULL);
        _exit(127);
    }
    ck_assert_int_gt(pid, 0);
    /* Interrupt while a worker is writing if we can catch one, else after 20 s. */
    double t0 = hv_now();
    while (hv_now() - t0 < 20 && count_temps(path("out")) == 0)
        usleep(2000);
    ck_assert_int_ge(processes_mentioning("--job"), 1);
    kill(pid, SIGINT);
    int st = 0;
    ck_assert_int_eq(waitpid(pid, &st, 0), pid);
    ck_assert_msg(WIFSIGNALED(st) && WTERMSIG(st) == SIGINT,
                  "the driver should die of SIGINT (status %#x)", st);
    /* the driver waits for its workers before it dies */
    ck_assert_int_eq(processes_mentioning(path("many")), 0);
    ck_assert_int_eq(count_temps(path("out")), 0);
    /* Whatever was finished is whole: every output decodes in full. */
    for (int i = 0; i < 6; i++) {
        const char *o = path("out/t%d.exr", i);
        if (mtime(o) < 0)
            continue;
        hv_grid *g = NULL;
        TL_ASSERT_OK(hv_exr_read(o, NULL, &g));
        hv_grid_destroy(&g);
    }
    remove_inputs();
}
END_TEST

/* A worker killed by SIGKILL beside another (what the OOM killer does when
 * the jobs together pass the memory) costs nothing: its job runs again alone
 * once the other is done, and both outputs are whole. */
START_TEST(worker_killed_beside_others_should_run_again_alone)
{
    make_inputs();
    ck_assert_int_eq(mkdir(path("two"), 0777), 0);
    char *torus = read_text(path("in/sub/torus.obj"));
    write_text(path("two/t0.obj"), torus);
    write_text(path("two/t1.obj"), torus);
    free(torus);
    ck_assert_int_eq(mkdir(path("out"), 0777), 0);
    char errf[700];
    snprintf(errf, sizeof errf, "%s", path("killed.txt"));
    pid_t pid = fork();
    if (pid == 0) {
        int out = open("/dev/null", O_WRONLY);
        int err = open(errf, O_WRONLY | O_CREAT | O_TRUNC, 0644);
        dup2(out, 1);
        dup2(err, 2);
        execl(bin, "heatvox", "batch", path("two"), "-o", path("out"), "-j", "2", "--res", "160",
              "--format", "exr", "--report", path("report.jsonl"), (char *)NULL);
        _exit(127);
    }
    ck_assert_int_gt(pid, 0);
    double t0 = hv_now();
    while (hv_now() - t0 < 20 && processes_mentioning("--job") < 2)
        usleep(2000);
    pid_t victim = 0;
    ck_assert_int_eq(processes_with("--job", "t0.obj", &victim), 1);
    ck_assert_int_eq(processes_mentioning("--job"), 2);
    kill(victim, SIGKILL);
    int st = 0;
    ck_assert_int_eq(waitpid(pid, &st, 0), pid);
    char *err = read_text(errf);
    ck_assert_msg(WIFEXITED(st) && WEXITSTATUS(st) == 0, "status %#x: %s", st, err);
    ck_assert_msg(strstr(err, "t0.obj: its worker was killed (SIGKILL) while 1 other ran, most "
                              "likely for memory; it runs again alone after them"),
                  "%s", err);
    free(err);
    char *report = read_text(path("report.jsonl"));
    for (int i = 0; i < 2; i++) {
        char in[1024], out[1024];
        snprintf(in, sizeof in, "%s", path("two/t%d.obj", i));
        snprintf(out, sizeof out, "%s", path("out/t%d.exr", i));
        char *line = report_line(report, in, out);
        ck_assert_msg(line && strstr(line, "\"status\":\"ok\""), "t%d: %s", i, report);
        free(line);
        hv_grid *g = NULL;
        TL_ASSERT_OK(hv_exr_read(out, NULL, &g));
        const int longest = g->n[0] > g->n[1] ? g->n[0] : g->n[1];
        ck_assert_int_eq(longest > g->n[2] ? longest : g->n[2], 160);
        hv_grid_destroy(&g);
    }
    ck_assert_int_eq(count_temps(path("out")), 0);
    free(report);
    remove_inputs();
}
END_TEST

/* numpy's view of an .npy file against OpenEXR's C++ reader's view of an EXR
 * volume (tests/exr_values.cpp: parts in z order, top image row first): the
 * script prints the number of voxels whose bits differ. */
static const char npy_vs_raw_py[] =
    "import sys, numpy as np\n"
    "a = np.load(sys.argv[1])\n"
    "assert a.dtype == np.float32 and a.ndim == 3, (a.dtype, a.shape)\n"
    "nz, ny, nx = a.shape\n"
    "r = np.fromfile(sys.argv[2], dtype='<f4')\n"
    "assert r.size == a.size, (r.size, a.shape)\n"
    "r = r.reshape(nz, ny, nx)[:, ::-1, :]\n"
    "print(int((a.view(np.uint32) != r.view(np.uint32)).sum()))\n";

static int is_mesh_name(const char *n)
{
    const char *e = strrchr(n, '.');
    return e &&
           (!strcmp(e, ".obj") || !strcmp(e, ".ply") || !strcmp(e, ".stl") || !strcmp(e, ".off"));
}

START_TEST(batch_exr_volumes_should_decode_to_the_npy_of_the_same_grid)
{
    /* OpenEXR 3.1's ZIP encoder corrupted some 16-row chunks of such volumes
     * (see src/io/exr.c): every volume at every resolution must decode, in
     * OpenEXR's C++ reader, to exactly the values numpy reads from the .npy
     * that `heatvox sdf --npy` writes for the same grid. */
    const char *data = tl_test_data();
    if (!data)
        TL_SKIP("no test meshes (set HEATVOX_TEST_DATA)");
    snprintf(dir, sizeof dir, "/tmp/hv_check_batch_XXXXXX");
    ck_assert_ptr_nonnull(mkdtemp(dir));
    heatvox_bin();
    char exe[PATH_MAX];
    ssize_t len = readlink("/proc/self/exe", exe, sizeof exe - 32);
    ck_assert_int_gt(len, 0);
    exe[len] = 0;
    strcpy(strrchr(exe, '/') + 1, "exr_values");
    write_text(path("cmp.py"), npy_vs_raw_py);
    char names[64][256], inputs[8192] = "";
    int nm = 0;
    DIR *d = opendir(data);
    ck_assert_ptr_nonnull(d);
    struct dirent *e;
    while ((e = readdir(d)) && nm < 64)
        if (is_mesh_name(e->d_name)) {
            snprintf(names[nm++], sizeof names[0], "%s", e->d_name);
            size_t l = strlen(inputs);
            snprintf(inputs + l, sizeof inputs - l, " '%s/%s'", data, e->d_name);
        }
    closedir(d);
    if (nm == 0)
        TL_SKIP("no meshes in %s", data);
    /* Two resolutions in make check, all four in make check-long. Under the
     * sanitizers the smallest alone: every mesh still goes through the batch,
     * the EXR writer and its guard once, and the guard's raw-chunk branch is
     * check_image's (a chunk made to deflate to its raw size). */
    const int all_res[] = {32, 64, 96, 128}, quick_res[] = {32, 96};
    const int full = tl_long(), san = tl_sanitized();
    const int *res = full || san ? all_res : quick_res;
    const int nres = full ? 4 : san ? 1 : 2;
    int volumes = 0;
    for (int r = 0; r < nres; r++) {
        char args[16384];
        snprintf(args, sizeof args, "batch%.9000s -o '%s/exr%d' --format exr --res %d -q", inputs,
                 dir, res[r], res[r]);
        int rc = run(args);
        char *err = read_text(path("stderr.txt"));
        ck_assert_msg(rc == 0 || rc == 1, "batch exit %d: %s", rc, err);
        free(err);
        for (int m = 0; m < nm; m++) {
            char stem[256];
            memcpy(stem, names[m], sizeof stem);
            *strrchr(stem, '.') = '\0';
            const char *exr = path("exr%d/%.200s.exr", res[r], stem);
            snprintf(args, sizeof args, "sdf '%.2000s/%.250s' -o '%s' --res %d --npy '%s'", data,
                     names[m], path("v.vdb"), res[r], path("v.npy"));
            ck_assert_int_eq(run(args), 0);
            ck_assert_msg(access(exr, F_OK) == 0, "batch wrote no %s", exr);
            char cmd[8192];
            snprintf(cmd, sizeof cmd,
                     "'%.3000s' '%s' distance '%s' && /usr/bin/python3 '%s' '%s' '%s' > '%s'", exe,
                     exr, path("v.raw"), path("cmp.py"), path("v.npy"), path("v.raw"),
                     path("diff.txt"));
            ck_assert_msg(system(cmd) == 0, "%s: decoding or comparing failed", exr);
            char *diff = read_text(path("diff.txt"));
            ck_assert_msg(atol(diff) == 0, "%s at --res %d: %s voxels differ from the .npy",
                          names[m], res[r], diff);
            free(diff);
            volumes++;
        }
    }
    ck_assert_int_ge(volumes, nm * nres);
    printf("check_batch: %d EXR volumes of %d meshes match their .npy bit for bit\n", volumes, nm);
    tl_rm_rf(dir);
}
END_TEST

int main(void)
{
    Suite *s = suite_create("batch");
    TCase *tc = tcase_create("cli");
    tcase_set_timeout(tc, 240);
    tcase_add_test(tc, mixed_batch_should_isolate_failures_and_resume);
    tcase_add_test(tc, default_output_should_be_a_vdb_level_set_that_slice_can_cut);
    tcase_add_test(tc, sdf_preview_should_show_the_three_middle_slices);
    tcase_add_test(tc, dry_run_should_list_jobs_and_write_nothing);
    tcase_add_test(tc, usage_errors_should_exit_2);
    tcase_add_test(tc, interrupted_batch_should_leave_no_partial_outputs);
    tcase_add_test(tc, worker_killed_beside_others_should_run_again_alone);
    suite_add_tcase(s, tc);
    tc = tcase_create("exr volumes");
    tcase_set_timeout(tc, 600);
    tcase_add_test(tc, batch_exr_volumes_should_decode_to_the_npy_of_the_same_grid);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
