/* heatvox bench points: surfaces reconstructed from oriented points, heatvox
 * (`heatvox sdf POINTS.xyz --mesh-out`) against CGAL's Poisson surface
 * reconstruction (bench_ref_cgal, built by make bench) on the same points in
 * the same run, and from the points alone (--unoriented: heatvox's recovered
 * orientation against CGAL's and Open3D's normal estimation, orientation and
 * Poisson reconstruction, bench_ref_open3d.py), each as its own process so
 * that the times and the peak RSS (from wait4) are those a user sees. The points are drawn from a closed mesh,
 * clean and with the defects of scanned data, and each surface is scored
 * against that mesh. */
#include "bench_ref.h"
#include "points_sample.h"
#include "points_score.h"
#include "../cli.h"
#include "../commands.h"

#include <dirent.h>
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static const char *CMD = "bench points";

/* The points of one row: drawn from the mesh, then spoiled as scans are. */
typedef struct scenario {
    const char *name;
    double density_ratio; /* kept with a probability falling 1 to 1/ratio along x */
    double noise_vox;     /* Gaussian noise along the normal, sigma in voxels */
    double flip;          /* fraction of the normals reversed */
    double hole;          /* no point within this fraction of the mesh's longest side
                             of a surface point drawn with seed HOLE_SEED */
} scenario;

enum { NSCEN = 8, HOLE_SEED = 3 };
static const scenario SCENARIOS[NSCEN] = {
    {"clean", 1, 0, 0, 0},         {"uneven", 10, 0, 0, 0},     {"density-4", 4, 0, 0, 0},
    {"noise-0.25", 1, 0.25, 0, 0}, {"noise-0.5", 1, 0.5, 0, 0}, {"flipped-10", 1, 0, 0.1, 0},
    {"hole", 1, 0, 0, 0.1},        {"all", 4, 0.25, 0, 0.1},
};
#define SCENARIO_NAMES "clean, uneven, density-4, noise-0.25, noise-0.5, flipped-10, hole, all"

/* The programs that reconstruct a scenario's points, each a row. */
enum { P_HEATVOX, P_RECOVER, P_CGAL, P_CGAL_UNORIENTED, P_OPEN3D, NPROG };
static const char *const PROG_NAME[NPROG] = {"heatvox", "heatvox-recover", "cgal-poisson",
                                             "cgal-unoriented", "open3d-unoriented"};
static const char *const PROG_SUFFIX[NPROG] = {"-heatvox", "-recover", "-cgal", "-cgal-unoriented",
                                               "-open3d"};

typedef struct args {
    const char *mesh, *keep, *cgal, *open3d, *heatvox;
    int n, count, nonly, band, unoriented;
    const char *only[NSCEN];
} args;

/* One program's run on one scenario. */
typedef struct run {
    int code;               /* exit status (0: ran; -1: a signal; 127: could not start) */
    double seconds, rss_mb; /* wall time and peak RSS of the process */
    double compute_seconds; /* a reference's own: the reconstruction alone */
    double iou;             /* its score, -1 until scored or when it has none */
} run;

typedef struct bench {
    args A;
    hv_mesh *m;
    double h;              /* the voxel size of heatvox sdf MESH --res N */
    double hole_center[3]; /* and the hole's radius, world units */
    double hole_radius;
    char dir[4096], heatvox[4096], cgal[4096], open3d[4096];
    int have_cgal, have_open3d;
    int asked[NSCEN];
    int runs[NPROG];     /* which programs run on every scenario */
    run r[NSCEN][NPROG]; /* P_RECOVER: heatvox sdf PTS.xyz --orient recover */
    run mesh_band;       /* --band: heatvox sdf MESH -o X.vdb --res N */
} bench;

static int usage(FILE *out)
{
    fprintf(out, "usage: heatvox bench points MESH --n N [--count K] [--scenario NAME]...\n"
                 "                            [--keep DIR] [--cgal BIN] [--heatvox BIN]\n"
                 "                            [--unoriented [--open3d SCRIPT]] [--band]\n"
                 "\n"
                 "Draws K oriented points (default 100000) on MESH, closed by heatvox sdf's\n"
                 "repair, area-uniform with the true face normals, in each scenario: clean;\n"
                 "uneven and density-4 (the density falling 10:1 and 4:1 along x); noise-0.25\n"
                 "and noise-0.5 (Gaussian noise along the normal, sigma in voxels); flipped-10\n"
                 "(10%% of the normals reversed); hole (no point within a tenth of the mesh's\n"
                 "longest side of one surface point); all (density 4:1, noise 0.25 and the\n"
                 "hole at once). Each set is written to an .xyz file and reconstructed by\n"
                 "these processes, timed with their peak RSS:\n"
                 "  heatvox sdf PTS.xyz --res N --npy X.npy --mesh-out S.ply\n"
                 "  bench_ref_cgal PTS.xyz C.ply --h H   (CGAL's Poisson reconstruction, meshed\n"
                 "                 at the voxel size H of heatvox sdf MESH --res N; make bench)\n"
                 "then each surface is scored against MESH: iou, of the cells inside MESH and\n"
                 "inside the surface (winding-number sign) on the block of heatvox sdf MESH\n"
                 "--res N; mean_dist_vox and max_dist_vox, the exact distance of area-uniform\n"
                 "samples of the surface (4 a square voxel) to MESH, in voxels.\n"
                 "  --scenario NAME  run only the scenarios named (repeatable)\n"
                 "  --keep DIR       write the files to DIR (made if missing) and keep them;\n"
                 "                   else a temporary directory under $TMPDIR (default /tmp)\n"
                 "  --cgal BIN       the reference program (default: bench_ref_cgal beside\n"
                 "                   this heatvox); without it the cgal rows are skipped\n"
                 "  --heatvox BIN    the heatvox that reconstructs (default: this one)\n"
                 "  --unoriented     also reconstruct each set without its normals (heatvox sdf\n"
                 "                   PTS.xyz --orient recover ...: backend \"heatvox-recover\",\n"
                 "                   ref \"heatvox\" with the true normals, ref_iou: theirs,\n"
                 "                   orient_agree: the fraction of the points whose recovered\n"
                 "                   normal is on their true normal's side), and so do the\n"
                 "                   peers from the points alone, ref \"heatvox-recover\":\n"
                 "                   \"cgal-unoriented\" (bench_ref_cgal --unoriented: jet\n"
                 "                   normals, mst_orient_normals, Poisson) and\n"
                 "                   \"open3d-unoriented\" (estimate_normals,\n"
                 "                   orient_normals_consistent_tangent_plane(15), Poisson);\n"
                 "                   a last row per program, scenario \"mean\", has mean_iou\n"
                 "                   and min_iou over the scenarios and the summed seconds\n"
                 "  --open3d SCRIPT  bench_ref_open3d.py (default: tools/bench/ beside this\n"
                 "                   build's directory), run by /usr/bin/python3; without it\n"
                 "                   or Python's open3d the open3d rows are skipped\n"
                 "  --band           time the narrow band alone instead: heatvox sdf PTS.xyz\n"
                 "                   -o X.vdb --mesh-out S.ply --res N (tiles; with\n"
                 "                   --unoriented --orient recover too), against the same\n"
                 "                   command on MESH itself in the same run (ref\n"
                 "                   \"mesh-band\"); no reference rows, no scores\n"
                 "Prints one JSON line per scenario and program: bench, mesh, n, backend\n"
                 "(\"heatvox\", \"cgal-poisson\", ...), scenario, points, threads, seconds,\n"
                 "peak_rss_mb, triangles, iou, mean_dist_vox, max_dist_vox, dist_samples; the\n"
                 "references also compute_seconds (without reading, writing or start-up);\n"
                 "heatvox also ref \"cgal-poisson\", ref_seconds and ratio = seconds /\n"
                 "ref_seconds. A run that fails gives a row with its error instead.\n"
                 "Exit codes: 0 success, 1 failure, 2 usage error.\n");
    return out == stdout ? HV_EXIT_OK : HV_EXIT_USAGE;
}

static void help(void) { usage(stdout); }

static int parse(int argc, char **argv, args *A)
{
    memset(A, 0, sizeof *A);
    A->count = 100000;
    const cli_opt opts[] = {
        CLI_ROW_QUIET,
        {.names = "--n",
         .kind = CLI_INT,
         .dst = &A->n,
         .min = 16,
         .max = 4096,
         .needs = "an integer in 16..4096"},
        {.names = "--count",
         .kind = CLI_INT,
         .dst = &A->count,
         .min = 100,
         .max = INT_MAX,
         .needs = "an integer >= 100"},
        {.names = "MESH", .kind = CLI_WORDS, .files = CLI_FILES_TRIMESH},
        {.names = "--scenario", .kind = CLI_LIST, .dst = A->only, .val = NSCEN, .given = &A->nonly},
        {.names = "--keep", .kind = CLI_STR, .dst = &A->keep, .min = 1, .files = CLI_FILES_DIR},
        {.names = "--cgal", .kind = CLI_STR, .dst = &A->cgal, .min = 1, .files = CLI_FILES_ANY},
        {.names = "--open3d", .kind = CLI_STR, .dst = &A->open3d, .min = 1, .files = CLI_FILES_ANY},
        {.names = "--heatvox",
         .kind = CLI_STR,
         .dst = &A->heatvox,
         .min = 1,
         .files = CLI_FILES_ANY},
        {.names = "--band", .kind = CLI_FLAG, .dst = &A->band, .val = 1},
        {.names = "--unoriented", .kind = CLI_FLAG, .dst = &A->unoriented, .val = 1},
        {.names = NULL},
    };
    int rc = cli_parse(CMD, argc, argv, opts, "mesh", &A->mesh, help);
    if (rc >= 0)
        return rc;
    if (!A->mesh || !A->n)
        return usage(stderr);
    return -1;
}

/* ---- setting up: scenarios, programs, the directory ---- */

static int pick_scenarios(bench *B)
{
    for (int s = 0; s < NSCEN; s++)
        B->asked[s] = B->A.nonly == 0;
    for (int q = 0; q < B->A.nonly; q++) {
        int s = 0;
        while (s < NSCEN && strcmp(SCENARIOS[s].name, B->A.only[q]))
            s++;
        if (s == NSCEN)
            return cli_usage_error(CMD, "--scenario '%s': one of " SCENARIO_NAMES, B->A.only[q]);
        B->asked[s] = 1;
    }
    return -1;
}

/* Whether /usr/bin/python3 runs SCRIPT --check (Python's open3d imports). */
static int open3d_runs(const char *script)
{
    char *argv[] = {"python3", (char *)script, "--check", NULL};
    double seconds, rss;
    int code = 1;
    return access(script, R_OK) == 0 &&
           !bench_run_exe("/usr/bin/python3", argv, "/dev/null", &seconds, &rss, &code) && !code;
}

/* heatvox: --heatvox or this executable; the references: --cgal or
 * bench_ref_cgal in this executable's directory, --open3d or
 * tools/bench/bench_ref_open3d.py beside that directory; each skipped when
 * absent. */
static int find_programs(bench *B)
{
    char self[4096];
    ssize_t len = readlink("/proc/self/exe", self, sizeof self - 1);
    if (len <= 0) {
        fprintf(stderr, "heatvox %s: cannot find this executable: %s\n", CMD, strerror(errno));
        return HV_EXIT_FAIL;
    }
    self[len] = '\0';
    const int dir = (int)(strrchr(self, '/') - self);
    snprintf(B->heatvox, sizeof B->heatvox, "%s", B->A.heatvox ? B->A.heatvox : self);
    if (B->A.cgal)
        snprintf(B->cgal, sizeof B->cgal, "%s", B->A.cgal);
    else
        snprintf(B->cgal, sizeof B->cgal, "%.*s/bench_ref_cgal", dir, self);
    if (B->A.open3d)
        snprintf(B->open3d, sizeof B->open3d, "%s", B->A.open3d);
    else
        snprintf(B->open3d, sizeof B->open3d, "%.*s/../tools/bench/bench_ref_open3d.py", dir, self);
    B->have_cgal = access(B->cgal, X_OK) == 0;
    if (!B->have_cgal)
        fprintf(stderr, "heatvox %s: no %s (make bench builds it), cgal rows skipped\n", CMD,
                B->cgal);
    B->have_open3d = B->A.unoriented && open3d_runs(B->open3d);
    if (B->A.unoriented && !B->have_open3d)
        fprintf(stderr,
                "heatvox %s: /usr/bin/python3 %s --check failed (no script, or no "
                "python3-open3d): open3d rows skipped\n",
                CMD, B->open3d);
    const int on[NPROG] = {1, B->A.unoriented, B->have_cgal, B->A.unoriented && B->have_cgal,
                           B->have_open3d};
    memcpy(B->runs, on, sizeof on);
    return -1;
}

static int make_dir(bench *B)
{
    if (B->A.keep) {
        snprintf(B->dir, sizeof B->dir, "%s", B->A.keep);
        if (mkdir(B->dir, 0755) && errno != EEXIST) {
            fprintf(stderr, "heatvox %s: --keep %s: %s\n", CMD, B->dir, strerror(errno));
            return HV_EXIT_FAIL;
        }
        return -1;
    }
    const char *tmp = getenv("TMPDIR");
    snprintf(B->dir, sizeof B->dir, "%s/heatvox-bench-points-XXXXXX", tmp && *tmp ? tmp : "/tmp");
    if (!mkdtemp(B->dir)) {
        fprintf(stderr, "heatvox %s: %s: %s\n", CMD, B->dir, strerror(errno));
        return HV_EXIT_FAIL;
    }
    return -1;
}

/* The temporary directory and everything in it (not a --keep one). */
static void remove_dir(const bench *B)
{
    if (B->A.keep || !B->dir[0])
        return;
    DIR *d = opendir(B->dir);
    struct dirent *e;
    char path[4096 + 256];
    while (d && (e = readdir(d)))
        if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) {
            snprintf(path, sizeof path, "%s/%s", B->dir, e->d_name);
            remove(path);
        }
    if (d)
        closedir(d);
    rmdir(B->dir);
}

/* The block of heatvox sdf MESH --res N (its voxel size is the cgal
 * reference's) and the place of the hole. */
static int place(bench *B)
{
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = B->A.n;
    int n[3];
    double origin[3], lo[3], hi[3];
    hv_status st = hv_sdf_grid_for_mesh(B->m, &o, n, &B->h, origin);
    if (!st)
        st = hv_mesh_bounds(B->m, lo, hi);
    if (st)
        return cli_fail(CMD, B->A.mesh, st);
    B->hole_radius = 0.1 * fmax(hi[0] - lo[0], fmax(hi[1] - lo[1], hi[2] - lo[2]));
    if (points_surface_point(B->m, HOLE_SEED, B->hole_center)) {
        fprintf(stderr, "heatvox %s: %s: the mesh has no area\n", CMD, B->A.mesh);
        return HV_EXIT_FAIL;
    }
    return -1;
}

/* ---- phase 1: the points and the programs ---- */

static void file_of(const bench *B, int s, const char *suffix, char *out, size_t size)
{
    snprintf(out, size, "%s/%s%s", B->dir, SCENARIOS[s].name, suffix);
}

/* Program p's file of scenario s with the extension ext (".ply", ".out"). */
static void file_of_run(const bench *B, int s, int p, const char *ext, char *out, size_t size)
{
    char tail[64];
    snprintf(tail, sizeof tail, "%s%s", PROG_SUFFIX[p], ext);
    file_of(B, s, tail, out, size);
}

static int write_points(const bench *B, int s)
{
    const scenario *S = &SCENARIOS[s];
    points_sample_opts o;
    points_sample_opts_default(&o);
    o.count = (size_t)B->A.count;
    o.seed = 1 + (uint64_t)s;
    o.density_ratio = S->density_ratio;
    o.noise = S->noise_vox * B->h;
    o.flip_fraction = S->flip;
    if (S->hole > 0) {
        o.hole_radius = B->hole_radius;
        memcpy(o.hole_center, B->hole_center, sizeof o.hole_center);
    }
    points_set P;
    char path[4096 + 64], err[512];
    file_of(B, s, ".xyz", path, sizeof path);
    int rc = points_sample(B->m, &o, &P, err, sizeof err);
    if (!rc) {
        rc = points_write_xyz(&P, path, err, sizeof err);
        points_set_free(&P);
    }
    if (rc)
        fprintf(stderr, "heatvox %s: %s: %s\n", CMD, S->name, err);
    return rc;
}

/* compute_seconds from a reference's JSON line; -1 when absent. */
static double read_compute_seconds(const char *path)
{
    FILE *f = fopen(path, "r");
    char line[1024];
    double v = -1;
    if (f && fgets(line, sizeof line, f)) {
        const char *k = strstr(line, "\"compute_seconds\":");
        if (k)
            v = strtod(k + strlen("\"compute_seconds\":"), NULL);
    }
    if (f)
        fclose(f);
    return v;
}

/* Runs argv as exe, its stdout to out; says on stderr when it fails. */
static void run_program(const char *exe, char **argv, const char *out, run *R)
{
    R->iou = -1;
    R->compute_seconds = -1;
    if (bench_run_exe(exe, argv, out, &R->seconds, &R->rss_mb, &R->code)) {
        R->code = 127;
        fprintf(stderr, "heatvox %s: cannot start %s: %s\n", CMD, exe, strerror(errno));
        return;
    }
    if (R->code < 0)
        fprintf(stderr, "heatvox %s: %s %s ... was killed by a signal\n", CMD, exe, argv[1]);
    else if (R->code)
        fprintf(stderr, "heatvox %s: %s %s ... failed (exit %d)\n", CMD, exe, argv[1], R->code);
}

/* heatvox sdf on scenario s's points, with their normals or (P_RECOVER)
 * from the points alone. */
static void run_heatvox(bench *B, int s, int p)
{
    char xyz[4096 + 64], grid[4096 + 64], ply[4096 + 64], out[4096 + 64], ns[16];
    file_of(B, s, ".xyz", xyz, sizeof xyz);
    file_of_run(B, s, p, B->A.band ? ".vdb" : ".npy", grid, sizeof grid);
    file_of_run(B, s, p, ".ply", ply, sizeof ply);
    file_of_run(B, s, p, ".out", out, sizeof out);
    snprintf(ns, sizeof ns, "%d", B->A.n);
    /* --band: the narrow band alone, in tiles (-o X.vdb), and its mesh */
    char *argv[] = {"heatvox", "sdf",        xyz, "--res", ns,        B->A.band ? "-o" : "--npy",
                    grid,      "--mesh-out", ply, NULL,    "recover", NULL};
    if (p == P_RECOVER)
        argv[9] = "--orient";
    run_program(B->heatvox, argv, out, &B->r[s][p]);
}

/* A reference on scenario s's points: bench_ref_cgal (P_CGAL, with the
 * normals; P_CGAL_UNORIENTED) or bench_ref_open3d.py (P_OPEN3D). */
static void run_reference(bench *B, int s, int p)
{
    char xyz[4096 + 64], ply[4096 + 64], out[4096 + 64], hs[40];
    file_of(B, s, ".xyz", xyz, sizeof xyz);
    file_of_run(B, s, p, ".ply", ply, sizeof ply);
    file_of_run(B, s, p, ".out", out, sizeof out);
    snprintf(hs, sizeof hs, "%.17g", B->h);
    char *cgal[] = {"bench_ref_cgal", xyz, ply, "--h", hs, "--unoriented", NULL};
    char *o3d[] = {"python3", B->open3d, xyz, ply, "--h", hs, "--unoriented", NULL};
    if (p == P_CGAL)
        cgal[5] = NULL;
    run *R = &B->r[s][p];
    if (p == P_OPEN3D)
        run_program("/usr/bin/python3", o3d, out, R);
    else
        run_program(B->cgal, cgal, out, R);
    if (!R->code)
        R->compute_seconds = read_compute_seconds(out);
}

static void run_scenario(bench *B, int s)
{
    for (int p = 0; p < NPROG; p++)
        if (B->runs[p] && (p == P_HEATVOX || p == P_RECOVER))
            run_heatvox(B, s, p);
        else if (B->runs[p])
            run_reference(B, s, p);
}

/* ---- phase 2: scores and rows ---- */

static void print_head(const bench *B, int s, const char *backend)
{
    printf("{\"bench\":\"points\",\"mesh\":\"%s\",\"n\":%d,\"backend\":\"%s\",\"scenario\":\"%s\","
           "\"points\":%d",
           B->A.mesh, B->A.n, backend, SCENARIOS[s].name, B->A.count);
}

/* The scores of the surface a run wrote; the row's end. Its iou, -1 when
 * it has none. */
static double print_scores(const points_truth *T, const char *ply, const char *more)
{
    hv_mesh *r = NULL;
    hv_status st = hv_mesh_read(ply, &r);
    if (st) {
        printf(",\"error\":\"reading the surface: %s\"}\n", hv_status_str(st));
        fprintf(stderr, "heatvox %s: %s\n", CMD, hv_last_error());
        return -1;
    }
    double iou = -1;
    points_score sc;
    char err[512];
    if (points_score_mesh(T, r, &sc, err, sizeof err)) {
        printf(",\"triangles\":%zu,\"error\":\"scoring the surface\"}\n", r->ntris);
        fprintf(stderr, "heatvox %s: %s: %s\n", CMD, ply, err);
    } else {
        printf(",\"triangles\":%zu,\"iou\":%.5f,\"mean_dist_vox\":%.4f,\"max_dist_vox\":%.4f,"
               "\"dist_samples\":%zu%s}\n",
               r->ntris, sc.iou, sc.mean_dist_vox, sc.max_dist_vox, sc.samples, more);
        iou = sc.iou;
    }
    hv_mesh_destroy(&r);
    return iou;
}

/* The fraction of scenario s's points whose recovered normal lies on their
 * true normal's side: the library's own recovery (hv_points_surface with
 * HV_ORIENT_RECOVER) in this process, after the timed runs. -1 on failure. */
static double orient_agreement(const bench *B, int s)
{
    char xyz[4096 + 64];
    file_of(B, s, ".xyz", xyz, sizeof xyz);
    hv_points *P = NULL;
    hv_mesh *M = NULL;
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = B->A.n;
    o.orient = HV_ORIENT_RECOVER;
    hv_points_report R;
    hv_status st = hv_points_read(xyz, &P);
    if (!st)
        st = hv_points_surface(P, &o, &M, &R);
    const double agree = st ? -1 : 1 - (double)R.orient_disagree / (double)P->count;
    if (st)
        fprintf(stderr, "heatvox %s: %s\n", CMD, hv_last_error());
    hv_mesh_destroy(&M);
    hv_points_destroy(&P);
    return agree;
}

/* The program a row of p is measured against: heatvox's true normals for
 * heatvox-recover and cgal-poisson (the latter the other way: heatvox's row
 * names cgal), heatvox-recover for the peers without normals. -1: none. */
static int ref_of(int p)
{
    static const int REF[NPROG] = {P_CGAL, P_HEATVOX, -1, P_RECOVER, P_RECOVER};
    return REF[p];
}

/* Program p's row of scenario s (the programs in order, so that a row's
 * ref_iou is known when it is its reference's). */
static void print_run(bench *B, int s, int p, const points_truth *T)
{
    run *R = &B->r[s][p];
    const int q = ref_of(p);
    const run *Q = q >= 0 && B->runs[q] && !B->r[s][q].code ? &B->r[s][q] : NULL;
    print_head(B, s, PROG_NAME[p]);
    if (R->code) {
        printf(",\"error\":\"%s %s\"}\n", PROG_NAME[p],
               R->code < 0 ? "was killed by a signal" : "failed");
        fflush(stdout);
        return;
    }
    const int threads = p == P_HEATVOX || p == P_RECOVER ? hv_get_threads() : 1;
    printf(",\"threads\":%d,\"seconds\":%.4f,\"peak_rss_mb\":%.1f", threads, R->seconds, R->rss_mb);
    if (R->compute_seconds >= 0)
        printf(",\"compute_seconds\":%.4f", R->compute_seconds);
    if (Q)
        printf(",\"ref\":\"%s\",\"ref_seconds\":%.4f,\"ratio\":%.3f", PROG_NAME[q], Q->seconds,
               R->seconds / Q->seconds);
    char ply[4096 + 64], more[160] = "";
    int k = 0;
    if (p == P_RECOVER)
        k = snprintf(more, sizeof more, ",\"orient_agree\":%.5f", orient_agreement(B, s));
    if (Q && Q->iou >= 0 && p != P_HEATVOX)
        snprintf(more + k, sizeof more - (size_t)k, ",\"ref_iou\":%.5f", Q->iou);
    file_of_run(B, s, p, ".ply", ply, sizeof ply);
    R->iou = print_scores(T, ply, more);
    if (p != P_HEATVOX && p != P_CGAL && R->iou >= 0 && Q && Q->iou >= 0)
        fprintf(stderr, "heatvox %s: %s: %s: iou %.4f (%+.4f against %s)\n", CMD, SCENARIOS[s].name,
                PROG_NAME[p], R->iou, R->iou - Q->iou, PROG_NAME[q]);
    fflush(stdout);
}

/* The last row of each program: its mean and least iou over the scenarios
 * it scored, and its summed time. */
static void print_means(const bench *B)
{
    for (int p = 0; p < NPROG; p++) {
        if (!B->runs[p])
            continue;
        int scored = 0, asked = 0;
        double sum = 0, least = 1, seconds = 0, rss = 0;
        for (int s = 0; s < NSCEN; s++) {
            if (!B->asked[s])
                continue;
            const run *R = &B->r[s][p];
            asked++;
            if (R->code || R->iou < 0)
                continue;
            scored++;
            sum += R->iou;
            least = fmin(least, R->iou);
            seconds += R->seconds;
            rss = fmax(rss, R->rss_mb);
        }
        printf("{\"bench\":\"points\",\"mesh\":\"%s\",\"n\":%d,\"backend\":\"%s\",\"scenario\":"
               "\"mean\",\"points\":%d,\"scenarios\":%d,\"scored\":%d",
               B->A.mesh, B->A.n, PROG_NAME[p], B->A.count, asked, scored);
        if (scored)
            printf(",\"seconds\":%.4f,\"peak_rss_mb\":%.1f,\"mean_iou\":%.5f,\"min_iou\":%.5f",
                   seconds, rss, sum / scored, least);
        printf("}\n");
    }
    fflush(stdout);
}

/* Every asked scenario's points and runs first, while this process is small
 * (its resident memory at each fork counts in the child's peak), then the
 * truth and the rows. */
static int run_all(bench *B)
{
    for (int s = 0; s < NSCEN; s++) {
        if (!B->asked[s])
            continue;
        if (write_points(B, s))
            return HV_EXIT_FAIL;
        run_scenario(B, s);
    }
    points_truth T;
    char err[512];
    if (points_truth_init(&T, B->m, B->A.n, err, sizeof err)) {
        fprintf(stderr, "heatvox %s: %s: %s\n", CMD, B->A.mesh, err);
        return HV_EXIT_FAIL;
    }
    for (int s = 0; s < NSCEN; s++)
        for (int p = 0; p < NPROG; p++)
            if (B->asked[s] && B->runs[p])
                print_run(B, s, p, &T);
    points_truth_free(&T);
    if (B->A.unoriented)
        print_means(B);
    return HV_EXIT_OK;
}

/* --band: the narrow band of MESH itself, the reference of every row. */
static void run_mesh_band(bench *B)
{
    char vdb[4096 + 64], out[4096 + 64], ns[16];
    char ply[4096 + 64];
    snprintf(vdb, sizeof vdb, "%s/mesh-band.vdb", B->dir);
    snprintf(ply, sizeof ply, "%s/mesh-band.ply", B->dir);
    snprintf(out, sizeof out, "%s/mesh-band.out", B->dir);
    snprintf(ns, sizeof ns, "%d", B->A.n);
    char *argv[] = {"heatvox", "sdf", (char *)B->A.mesh, "--res", ns,
                    "-o",      vdb,   "--mesh-out",      ply,     NULL};
    run_program(B->heatvox, argv, out, &B->mesh_band);
}

/* --band's rows: time and memory against the mesh's own band. */
static int band_rows(bench *B)
{
    run_mesh_band(B);
    const run *M = &B->mesh_band;
    for (int s = 0; s < NSCEN; s++) {
        if (!B->asked[s])
            continue;
        if (write_points(B, s))
            return HV_EXIT_FAIL;
        for (int p = P_HEATVOX; p <= (B->A.unoriented ? P_RECOVER : P_HEATVOX); p++) {
            run_heatvox(B, s, p);
            const run *R = &B->r[s][p];
            print_head(B, s, p == P_RECOVER ? "heatvox-recover-band" : "heatvox-band");
            if (R->code)
                printf(",\"error\":\"heatvox sdf failed\"}\n");
            else
                printf(",\"threads\":%d,\"band\":3,\"mesh_out\":true,\"seconds\":%.4f,"
                       "\"peak_rss_mb\":%.1f",
                       hv_get_threads(), R->seconds, R->rss_mb);
            if (!R->code && !M->code)
                printf(",\"ref\":\"mesh-band\",\"ref_seconds\":%.4f,\"ref_peak_rss_mb\":%.1f,"
                       "\"ratio\":%.3f}\n",
                       M->seconds, M->rss_mb, R->seconds / M->seconds);
            else if (!R->code)
                printf("}\n");
            fflush(stdout);
        }
    }
    return HV_EXIT_OK;
}

/* MESH as heatvox sdf's repair closes it (the Stanford bunny's holes in its
 * base capped): the surface the points are drawn from and scored against. */
static int read_truth(bench *B)
{
    hv_mesh *m = NULL;
    hv_sdf_repair_report rep;
    hv_status st = hv_mesh_read(B->A.mesh, &m);
    if (!st)
        st = hv_sdf_repair(m, HV_SDF_REPAIR_ALL, 0.5, &B->m, &rep);
    hv_mesh_destroy(&m);
    if (st)
        return cli_fail(CMD, B->A.mesh, st);
    if (rep.boundary_edges || rep.nonmanifold_edges)
        fprintf(stderr,
                "heatvox %s: %s is not closed after the repair (%zu boundary, %zu non-manifold "
                "edges): its inside is the winding number's\n",
                CMD, B->A.mesh, rep.boundary_edges, rep.nonmanifold_edges);
    return -1;
}

int cmd_bench_points(int argc, char **argv)
{
    bench B;
    memset(&B, 0, sizeof B);
    int rc = parse(argc, argv, &B.A);
    if (rc >= 0 || (rc = pick_scenarios(&B)) >= 0 || (rc = read_truth(&B)) >= 0)
        return rc;
    if ((rc = place(&B)) < 0 && (rc = find_programs(&B)) < 0 && (rc = make_dir(&B)) < 0)
        rc = B.A.band ? band_rows(&B) : run_all(&B);
    remove_dir(&B);
    hv_mesh_destroy(&B.m);
    return rc;
}
