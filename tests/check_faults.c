/* Faults around the command's outputs, run as a user would meet them: outputs
 * onto special files and onto inputs, thread counts libgomp cannot start,
 * temporaries left by killed processes, SIGKILL and SIGINT while writing each
 * kind of output, and a full disk (a small tmpfs, when run as root). The rule
 * in every case: a clear error naming the file, the documented exit code, and
 * nothing partial under any requested name. */
#include "heatvox/heatvox.h"
#include "testlib.h"

#include <check.h>
#include <dirent.h>
#include <errno.h>
#include <limits.h>
#include <signal.h>
#include <spawn.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mount.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

extern char **environ;

static char dir[256];
static char full_mnt[300];
static int full_mounted;
static char bin[PATH_MAX];

static const char *at(const char *name)
{
    static char p[8][600];
    static int which;
    which = (which + 1) % 8;
    snprintf(p[which], sizeof p[which], "%s/%s", dir, name);
    return p[which];
}

/* A scratch directory with the generated scenes in it. */
static void setup(void) { tl_scratch_scenes("check_faults", dir, sizeof dir, bin, sizeof bin); }

static void teardown(void) { tl_rm_rf(dir); }

/* Runs `heatvox ARGS` in dir; stderr lands in err. Returns the exit code. */
#define hv(err, errsize, ...) tl_hv(dir, bin, err, errsize, __VA_ARGS__)

/* Names in dir (not recursive) that start with `.` and hold ".tmp-". */
static int temporaries_in(const char *d)
{
    DIR *dd = opendir(d);
    int n = 0;
    struct dirent *e;
    while (dd && (e = readdir(dd)))
        n += e->d_name[0] == '.' && strstr(e->d_name, ".tmp-") != NULL;
    if (dd)
        closedir(dd);
    return n;
}

/* Temporaries of process pid (".NAME.tmp-PID-N"): those a SIGINT must remove.
 * Others may be a SIGKILLed run's, which the next run that stages into the
 * directory removes, unless a signal stops it before it gets there. */
static int temporaries_of(const char *d, pid_t pid)
{
    char tag[32];
    snprintf(tag, sizeof tag, ".tmp-%ld-", (long)pid);
    DIR *dd = opendir(d);
    int n = 0;
    struct dirent *e;
    while (dd && (e = readdir(dd)))
        n += e->d_name[0] == '.' && strstr(e->d_name, tag) != NULL;
    if (dd)
        closedir(dd);
    return n;
}

/* Temporaries anywhere under d (outputs go to sub-directories too). */
static int temporaries_under(const char *d)
{
    DIR *dd = opendir(d);
    int n = 0;
    struct dirent *e;
    while (dd && (e = readdir(dd))) {
        if (!strcmp(e->d_name, ".") || !strcmp(e->d_name, ".."))
            continue;
        char sub[1200];
        snprintf(sub, sizeof sub, "%s/%s", d, e->d_name);
        struct stat sb;
        if (lstat(sub, &sb) == 0 && S_ISDIR(sb.st_mode))
            n += temporaries_under(sub);
        else
            n += e->d_name[0] == '.' && strstr(e->d_name, ".tmp-") != NULL;
    }
    if (dd)
        closedir(dd);
    return n;
}

static int is_regular(const char *p)
{
    struct stat sb;
    return lstat(p, &sb) == 0 && S_ISREG(sb.st_mode);
}

/* ---- special files and inputs as outputs ---- */

START_TEST(outputs_onto_special_files_should_be_refused_and_left_alone)
{
    setup();
    ck_assert_int_eq(mkfifo(at("fifo.vdb"), 0600), 0);
    ck_assert_int_eq(symlink("/dev/null", at("null.npy")), 0);
    ck_assert_int_eq(mkdir(at("dir.png"), 0700), 0);
    ck_assert_int_eq(mkfifo(at("fifo.exr"), 0600), 0);
    struct {
        const char *args, *victim;
    } cases[] = {
        {"sdf sc/meshes/torus_holes.obj -o fifo.vdb --res 24", "fifo.vdb"},
        {"sdf sc/meshes/torus_holes.obj -o a.vdb --npy null.npy --res 24", "null.npy"},
        {"sdf sc/meshes/torus_holes.obj -o a.vdb --preview dir.png --res 24", "dir.png"},
        {"extend sc/levelset/sphere_velocity.vdb --levelset sdf --field v -o fifo.vdb", "fifo.vdb"},
        {"slice sc/levelset/sphere_velocity.vdb --grid sdf -o fifo.exr", "fifo.exr"},
        {"distance --sources src.txt --obstacles none --res 16 -o fifo.vdb", "fifo.vdb"},
        {"distance --sources src.txt --obstacles none --res 16 --npy null.npy", "null.npy"},
    };
    FILE *f = fopen(at("src.txt"), "w");
    fputs("0 0 0\n", f);
    fclose(f);
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        char err[2048];
        int rc = hv(err, sizeof err, "%s", cases[c].args);
        ck_assert_msg(rc == 1, "%s: exit %d (%s)", cases[c].args, rc, err);
        ck_assert_msg(strstr(err, cases[c].victim) && strstr(err, "not replaced"),
                      "%s: message does not name %s: %s", cases[c].args, cases[c].victim, err);
        ck_assert_msg(!is_regular(at(cases[c].victim)), "%s replaced by a file", cases[c].victim);
        ck_assert_msg(!is_regular(at("a.vdb")), "%s: a.vdb written", cases[c].args);
    }
    struct stat sb;
    ck_assert_int_eq(stat(at("null.npy"), &sb), 0);
    ck_assert(S_ISCHR(sb.st_mode)); /* still /dev/null */
    ck_assert_int_eq(temporaries_in(dir), 0);
    /* The library refuses too (a program that skips the command's check). */
    hv_grid *g = NULL;
    int n[3] = {4, 4, 4};
    double o[3] = {0, 0, 0};
    TL_ASSERT_OK(hv_grid_create(&g, 3, n, 1.0, o));
    ck_assert_int_eq(hv_write_npy(at("fifo.vdb"), g), HV_ERR_IO);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "not a regular file"));
    ck_assert_int_eq(hv_exr_write(at("dir.png"), g, NULL), HV_ERR_IO);
    hv_grid_destroy(&g);
    teardown();
}
END_TEST

START_TEST(an_output_that_is_an_input_should_be_refused)
{
    setup();
    const char *ls = at("sc/levelset/sphere_velocity.vdb");
    struct stat before, after;
    ck_assert_int_eq(stat(ls, &before), 0);
    char err[2048];
    int rc = hv(err, sizeof err,
                "extend sc/levelset/sphere_velocity.vdb --levelset sdf --field v "
                "-o sc/levelset/../levelset/sphere_velocity.vdb");
    ck_assert_msg(rc == 1, "exit %d: %s", rc, err);
    ck_assert_ptr_nonnull(strstr(err, "is the input"));
    rc = hv(err, sizeof err,
            "sdf sc/meshes/torus_holes.obj -o a.vdb --mesh-out sc/meshes/torus_holes.obj --res 16");
    ck_assert_msg(rc == 1, "exit %d: %s", rc, err);
    /* Two outputs that are one file: the outputs' extensions differ, so
     * through a link. */
    FILE *f = fopen(at("x.vdb"), "w");
    fputs("keep", f);
    fclose(f);
    ck_assert_int_eq(symlink("x.vdb", at("y.npy")), 0);
    rc = hv(err, sizeof err, "sdf sc/meshes/torus_holes.obj -o x.vdb --npy y.npy --res 16");
    ck_assert_msg(rc == 1, "exit %d: %s", rc, err);
    ck_assert_msg(strstr(err, "the same file"), "%s", err);
    struct stat xs;
    ck_assert_int_eq(stat(at("x.vdb"), &xs), 0);
    ck_assert_int_eq(xs.st_size, 4);
    ck_assert_int_eq(stat(ls, &after), 0);
    ck_assert_int_eq(before.st_ino, after.st_ino);
    ck_assert_int_eq(before.st_mtime, after.st_mtime);
    ck_assert_int_eq(before.st_size, after.st_size);
    ck_assert(!is_regular(at("a.vdb")));
    teardown();
}
END_TEST

/* ---- thread counts ---- */

START_TEST(thread_counts_libgomp_cannot_start_should_be_usage_errors)
{
    setup();
    FILE *f = fopen(at("src.txt"), "w");
    fputs("0 0 0\n", f);
    fclose(f);
    const char *cmds[] = {
        "sdf sc/meshes/torus_holes.obj -o a.vdb --res 16 --threads 100000",
        "extend sc/levelset/sphere_velocity.vdb --levelset sdf --field v -o a.vdb --threads 100000",
        "distance --sources src.txt --obstacles none --res 16 -o a.vdb --threads 100000",
        "batch sc/meshes -o out --res 16 --threads 100000",
        "bench solve --n 16 --threads 100000",
    };
    for (size_t c = 0; c < sizeof cmds / sizeof cmds[0]; c++) {
        char err[2048];
        int rc = hv(err, sizeof err, "%s", cmds[c]);
        ck_assert_msg(rc == 2, "%s: exit %d (%s)", cmds[c], rc, err);
        ck_assert_msg(strstr(err, "--threads") && strstr(err, "1024"), "%s: %s", cmds[c], err);
    }
    ck_assert(!is_regular(at("a.vdb")));
    /* The largest count allowed runs. */
    char err[2048];
    int rc = hv(err, sizeof err, "sdf sc/meshes/torus_holes.obj -o a.vdb --res 16 --threads %d",
                HV_MAX_THREADS);
    ck_assert_msg(rc == 0, "exit %d: %s", rc, err);
    teardown();
}
END_TEST

/* ---- temporaries of killed processes ---- */

static pid_t dead_pid(void)
{
    pid_t p = fork();
    ck_assert_int_ge(p, 0);
    if (p == 0)
        _exit(0);
    waitpid(p, NULL, 0);
    return p;
}

START_TEST(temporaries_of_dead_processes_should_be_removed_by_the_next_write)
{
    setup();
    char stale[600], live[600], other[600];
    snprintf(stale, sizeof stale, "%s/.a.vdb.tmp-%ld-3", dir, (long)dead_pid());
    snprintf(live, sizeof live, "%s/.a.vdb.tmp-%ld-0", dir, (long)getpid());
    snprintf(other, sizeof other, "%s/.b.vdb.tmp-%ld-0", dir, (long)dead_pid());
    const char *names[] = {stale, live, other};
    for (int i = 0; i < 3; i++) {
        FILE *f = fopen(names[i], "w");
        fputs("partial", f);
        fclose(f);
    }
    char err[2048];
    int rc = hv(err, sizeof err, "sdf sc/meshes/torus_holes.obj -o a.vdb --res 16 -q");
    ck_assert_msg(rc == 0, "exit %d: %s", rc, err);
    ck_assert_msg(access(stale, F_OK) != 0, "%s left", stale);
    ck_assert_msg(access(live, F_OK) == 0, "a live process's temporary was removed");
    ck_assert_msg(access(other, F_OK) == 0, "another output's temporary was removed");
    unlink(live);
    unlink(other);
    teardown();
}
END_TEST

/* ---- signals while writing ---- */

static pid_t spawn(const char *args)
{
    char cmd[8000];
    snprintf(cmd, sizeof cmd, "cd '%s' && exec '%s' %s >/dev/null 2>&1", dir, bin, args);
    char *argv[] = {"sh", "-c", cmd, NULL};
    pid_t pid;
    ck_assert_int_eq(posix_spawn(&pid, "/bin/sh", NULL, NULL, argv, environ), 0);
    return pid;
}

static void sleep_ms(int ms)
{
    struct timespec t = {ms / 1000, (long)(ms % 1000) * 1000000L};
    nanosleep(&t, NULL);
}

/* An output under its requested name must be whole: each reads back. */
static void assert_whole_or_absent(const char *const *outs, int n, const char *when)
{
    for (int i = 0; i < n; i++) {
        const char *p = at(outs[i]);
        if (access(p, F_OK) != 0)
            continue;
        const char *ext = strrchr(p, '.');
        hv_status st = HV_OK;
        hv_grid *g = NULL;
        if (!strcmp(ext, ".vdb")) {
            hv_vdb_grid_info info[8];
            size_t count = 0;
            st = hv_vdb_list(p, info, 8, &count);
            for (size_t k = 0; k < count && k < 8 && st == HV_OK; k++) {
                hv_grid *c[3] = {NULL, NULL, NULL};
                if (!strcmp(info[k].value_type, "float"))
                    st = hv_vdb_read_float(p, info[k].name, NULL, &c[0], NULL);
                else if (!strcmp(info[k].value_type, "vec3s"))
                    st = hv_vdb_read_vec3(p, info[k].name, NULL, &c[0], &c[1], &c[2]);
                for (int a = 0; a < 3; a++)
                    hv_grid_destroy(&c[a]);
            }
        } else if (!strcmp(ext, ".npy")) {
            st = hv_read_npy(p, &g);
        } else if (!strcmp(ext, ".exr")) {
            st = hv_exr_read(p, NULL, &g);
        } else if (!strcmp(ext, ".png")) {
            uint8_t *rgb = NULL;
            int w, h;
            st = hv_png_read_rgb(p, &rgb, &w, &h);
            free(rgb);
        } else if (!strcmp(ext, ".obj") || !strcmp(ext, ".ply") || !strcmp(ext, ".stl")) {
            hv_mesh *m = NULL;
            st = hv_mesh_read(p, &m);
            hv_mesh_destroy(&m);
        }
        hv_grid_destroy(&g);
        ck_assert_msg(st == HV_OK, "%s: %s is partial: %s", when, outs[i], hv_last_error());
    }
}

/* One command that writes, and the outputs it writes. */
typedef struct {
    const char *args;
    const char *outs[4];
    int sigint; /* also interrupted by SIGINT, whose handler must clean up */
} writer;

static int count_outs(const writer *w)
{
    int n = 0;
    while (n < 4 && w->outs[n])
        n++;
    return n;
}

static void kill_during_writes(const writer *w, int sig, double run_ms)
{
    const int n = count_outs(w);
    /* Delays spread over a whole run (measured), so that some land while
     * writing, and two fixed early ones for the reading and set-up. */
    const double frac[] = {0.15, 0.35, 0.55, 0.7, 0.8, 0.9, 0.97};
    for (size_t k = 0; k < 2 + sizeof frac / sizeof frac[0]; k++) {
        /* Under the sanitizers (each run several times longer) 30 ms, which
         * lands in the process's start-up as 5 ms does (it takes 0.3 s), and
         * two delays into the run, 0.35 and 0.9. */
        if (tl_sanitized() && k != 1 && k != 3 && k != 7)
            continue;
        int ms = k == 0 ? 5 : k == 1 ? 30 : (int)(frac[k - 2] * run_ms);
        for (int i = 0; i < n; i++)
            unlink(at(w->outs[i]));
        pid_t pid = spawn(w->args);
        sleep_ms(ms);
        kill(pid, sig);
        int status = 0;
        ck_assert_int_eq(waitpid(pid, &status, 0), pid);
        char when[512];
        snprintf(when, sizeof when, "%s after %d ms, signal %d", w->args, ms, sig);
        /* All of a command's outputs land together, or none does. */
        int present = 0;
        for (int i = 0; i < n; i++)
            present += access(at(w->outs[i]), F_OK) == 0;
        ck_assert_msg(present == 0 || present == n, "%s: %d of %d outputs", when, present, n);
        assert_whole_or_absent(w->outs, n, when);
        if (sig == SIGINT && WIFSIGNALED(status))
            ck_assert_msg(temporaries_of(dir, pid) == 0, "%s: temporaries left", when);
    }
}

/* Runs w to completion: it succeeds, writes every output whole, and leaves no
 * temporary anywhere under the scratch directory, also none that a killed run
 * (its own or a writer's inside it) staged. Returns the run's milliseconds. */
static double run_whole(const writer *w, const char *when)
{
    char err[2048];
    double t0 = hv_now();
    int rc = hv(err, sizeof err, "%s", w->args);
    double ms = 1e3 * (hv_now() - t0);
    ck_assert_msg(rc == 0, "%s: %s: exit %d (%s)", when, w->args, rc, err);
    const int n = count_outs(w);
    for (int i = 0; i < n; i++)
        ck_assert_msg(is_regular(at(w->outs[i])), "%s: %s: %s missing", when, w->args, w->outs[i]);
    assert_whole_or_absent(w->outs, n, when);
    ck_assert_msg(temporaries_under(dir) == 0, "%s: %s: %d temporaries left", when, w->args,
                  temporaries_under(dir));
    return ms;
}

/* Every command that writes, every kind of output. */
static const writer writers[] = {
    {"sdf sc/meshes/torus_holes.obj -o o.vdb --npy o.npy --preview o.png --res 112 --dense -q",
     {"o.vdb", "o.npy", "o.png"},
     1},
    {"sdf sc/meshes/torus_holes.obj -o t.vdb --preview t.png --res 160 -q", {"t.vdb", "t.png"}, 0},
    {"sdf sc/meshes/torus_holes.obj -o m.vdb --mesh-out m.obj --res 96 -q", {"m.vdb", "m.obj"}, 0},
    {"sdf sc/meshes/torus_holes.obj --mesh-out m.ply --res 80 -q", {"m.ply"}, 0},
    {"sdf sc/meshes/torus_holes.obj --mesh-out m.stl --npy m.npy --res 64 -q",
     {"m.stl", "m.npy"},
     0},
    {"sdf2d sc/curves.txt -o c.exr --png c.png --res 400 -q", {"c.exr", "c.png"}, 0},
    {"extend sc/levelset/sphere_velocity.vdb --levelset sdf --field v -o e.vdb --dense -q",
     {"e.vdb"},
     1},
    {"slice sc/levelset/sphere_velocity.vdb --grid sdf --axis z -o s.exr -q", {"s.exr"}, 0},
    {"slice sc/levelset/sphere_velocity.vdb --grid sdf --axis y -o s.png -q", {"s.png"}, 0},
    {"distance --sources sc/distance/sources.txt --obstacles sc/distance/walls.vdb -o d.vdb "
     "--npy d.npy -q",
     {"d.vdb", "d.npy"},
     1},
    /* make-scenes writes each scene on its own: one output checked */
    {"make-scenes sc2 -q", {"sc2/meshes/torus_holes.obj"}, 0},
    {"batch sc/meshes/torus_holes.obj sc/meshes/torus_soup.obj -o bo --res 40 --force -j 1 -q",
     {"bo/torus_holes.vdb"},
     0},
};

START_TEST(sigkill_and_sigint_while_writing_should_leave_nothing_partial)
{
    setup();
    FILE *f = fopen(at("sc/curves.txt"), "w");
    fputs("M 0 0\nL 4 0\nL 4 3\nL 0 3\nZ\nM 1 1\nL 2 1\nL 2 2\n", f);
    fclose(f);
    /* HDF5 (with its XDMF sidecar), where the build links PETSc. */
    const writer h5 = {
        "distance --sources sc/distance/sources.txt --obstacles sc/distance/walls.vdb "
        "-o h.h5 -q",
        {"h.h5"},
        1};
    const size_t nw = sizeof writers / sizeof writers[0];
    for (size_t c = 0; c < nw + (hv_petsc_available() != 0); c++) {
        const writer *w = c < nw ? &writers[c] : &h5;
        double ms = run_whole(w, "a first run");
        kill_during_writes(w, SIGKILL, ms);
        run_whole(w, "the run after SIGKILL");
        if (w->sigint) {
            kill_during_writes(w, SIGINT, ms);
            run_whole(w, "the run after SIGINT");
        }
    }
    teardown();
}
END_TEST

/* ---- a full disk ---- */

START_TEST(a_full_disk_should_fail_clearly_and_leave_nothing)
{
    if (geteuid() != 0)
        TL_SKIP("mounting a small tmpfs needs root");
    setup();
    /* The mount point in a buffer of its own: at()'s ring is reused. */
    const char *mnt = full_mnt;
    snprintf(full_mnt, sizeof full_mnt, "%s/full", dir);
    ck_assert_int_eq(mkdir(mnt, 0700), 0);
    if (mount("tmpfs", mnt, "tmpfs", 0, "size=96k") != 0) {
        int e = errno;
        teardown();
        TL_SKIP("cannot mount a tmpfs: %s", strerror(e));
    }
    full_mounted = 1;
    char err[2048];
    /* Each kind of output alone, then a small .vdb with a dense .npy that does
     * not fit: neither lands. */
    const char *cmds[] = {
        "sdf sc/meshes/torus_holes.obj -o full/a.vdb --res 64 --dense",
        "sdf sc/meshes/torus_holes.obj -o a.vdb --npy full/a.npy --res 64",
        "sdf sc/meshes/torus_holes.obj -o a.vdb --preview full/a.png --res 400 --band 1",
        "slice sc/levelset/sphere_velocity.vdb --grid sdf -o full/a.exr",
        "extend sc/levelset/sphere_velocity.vdb --levelset sdf --field v -o full/e.vdb --dense",
        "make-scenes full/sc",
    };
    for (size_t c = 0; c < sizeof cmds / sizeof cmds[0]; c++) {
        /* Fill the disk but for 4 kB, so that even small files fail. */
        static char block[92 * 1024];
        char filler[700];
        snprintf(filler, sizeof filler, "%s/filler", mnt);
        FILE *f = fopen(filler, "w");
        ck_assert_ptr_nonnull(f);
        fwrite(block, 1, 92 * 1024, f);
        fclose(f);
        int rc = hv(err, sizeof err, "%s", cmds[c]);
        ck_assert_msg(rc == 1, "%s: exit %d (%s)", cmds[c], rc, err);
        ck_assert_msg(strstr(err, "full/") || strstr(err, "space"), "%s: %s", cmds[c], err);
        ck_assert_msg(!is_regular(at("a.vdb")), "%s: a.vdb landed without its .npy", cmds[c]);
        ck_assert_int_eq(unlink(filler), 0);
        DIR *d = opendir(mnt);
        ck_assert_msg(d != NULL, "%s: %s", mnt, strerror(errno));
        struct dirent *e;
        int left = 0;
        char names[512] = "";
        while (d && (e = readdir(d)))
            if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) {
                char sub[700];
                snprintf(sub, sizeof sub, "%s/%s", mnt, e->d_name);
                struct stat sb;
                /* make-scenes makes its directories before it writes */
                if (stat(sub, &sb) == 0 && S_ISDIR(sb.st_mode)) {
                    tl_rm_rf(sub);
                    continue;
                }
                left++;
                strncat(names, e->d_name, sizeof names - strlen(names) - 2);
                strcat(names, " ");
            }
        if (d)
            closedir(d);
        ck_assert_msg(left == 0, "%s: left on the full disk: %s", cmds[c], names);
    }
    ck_assert_int_eq(umount(mnt), 0);
    full_mounted = 0;
    teardown();
}
END_TEST

/* Runs after every test, passed or failed: what a failed one left mounted is
 * unmounted, its scratch directory removed. */
static void cleanup(void)
{
    if (full_mounted && umount2(full_mnt, MNT_DETACH) == 0)
        full_mounted = 0;
    struct stat sb;
    if (*dir && stat(dir, &sb) == 0)
        tl_rm_rf(dir);
    *dir = '\0';
}

int main(void)
{
    Suite *s = suite_create("faults");
    TCase *tc = tcase_create("outputs");
    tcase_set_timeout(tc, 300);
    tcase_add_checked_fixture(tc, NULL, cleanup);
    tcase_add_test(tc, outputs_onto_special_files_should_be_refused_and_left_alone);
    tcase_add_test(tc, an_output_that_is_an_input_should_be_refused);
    tcase_add_test(tc, thread_counts_libgomp_cannot_start_should_be_usage_errors);
    tcase_add_test(tc, temporaries_of_dead_processes_should_be_removed_by_the_next_write);
    tcase_add_test(tc, sigkill_and_sigint_while_writing_should_leave_nothing_partial);
    tcase_add_test(tc, a_full_disk_should_fail_clearly_and_leave_nothing);
    suite_add_tcase(s, tc);
    return tl_run(s);
}
