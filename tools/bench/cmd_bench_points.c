/* heatvox bench points: surfaces reconstructed from oriented points, heatvox
 * (`heatvox sdf POINTS.xyz --mesh-out`) against CGAL's Poisson surface
 * reconstruction (bench_ref_cgal, built by make bench) on the same points in
 * the same run, each as its own process so that the times and the peak RSS
 * (from wait4) are those a user sees. The points are drawn from a closed mesh,
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

enum { NSCEN = 6, HOLE_SEED = 3 };
static const scenario SCENARIOS[NSCEN] = {
    {"clean", 1, 0, 0, 0},       {"uneven", 10, 0, 0, 0},      {"noise-0.25", 1, 0.25, 0, 0},
    {"noise-0.5", 1, 0.5, 0, 0}, {"flipped-10", 1, 0, 0.1, 0}, {"hole", 1, 0, 0, 0.1},
};

typedef struct args {
    const char *mesh, *keep, *cgal, *heatvox;
    int n, count, nonly, band, unoriented;
    const char *only[NSCEN];
} args;

/* One program's run on one scenario. */
typedef struct run {
    int code;               /* exit status (0: ran; -1: a signal; 127: could not start) */
    double seconds, rss_mb; /* wall time and peak RSS of the process */
    double compute_seconds; /* bench_ref_cgal's own: the reconstruction alone */
} run;

typedef struct bench {
    args A;
    hv_mesh *m;
    double h;              /* the voxel size of heatvox sdf MESH --res N */
    double hole_center[3]; /* and the hole's radius, world units */
    double hole_radius;
    char dir[4096], heatvox[4096], cgal[4096];
    int have_cgal;
    int asked[NSCEN];
    run hv[NSCEN], cg[NSCEN];
    run rec[NSCEN];        /* --unoriented: heatvox sdf PTS.xyz --orient recover */
    double rec_iou[NSCEN]; /* and the iou of the given normals' surface beside it */
    run mesh_band;         /* --band: heatvox sdf MESH -o X.vdb --res N */
} bench;

static int usage(FILE *out)
{
    fprintf(out, "usage: heatvox bench points MESH --n N [--count K] [--scenario NAME]...\n"
                 "                            [--keep DIR] [--cgal BIN] [--heatvox BIN]\n"
                 "\n"
                 "Draws K oriented points (default 100000) on MESH, closed by heatvox sdf's\n"
                 "repair, area-uniform with the true face normals, in each scenario: clean;\n"
                 "uneven (the density falling 10:1 along x); noise-0.25 and noise-0.5\n"
                 "(Gaussian noise along the normal, sigma in voxels); flipped-10 (10%% of the\n"
                 "normals reversed); hole (no point within a tenth of the mesh's longest side\n"
                 "of one surface point). Each set is written to an .xyz file and reconstructed\n"
                 "by two processes, timed with their peak RSS:\n"
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
                 "                   ref \"heatvox\" with the true normals, iou_gap = its iou\n"
                 "                   minus theirs, orient_agree: the fraction of the points\n"
                 "                   whose recovered normal is on their true normal's side)\n"
                 "  --band           time the narrow band alone instead: heatvox sdf PTS.xyz\n"
                 "                   -o X.vdb --res N (tiles), against the same command on\n"
                 "                   MESH itself in the same run (ref \"mesh-band\"); no cgal\n"
                 "                   rows, no scores\n"
                 "Prints one JSON line per scenario and program: bench, mesh, n, backend\n"
                 "(\"heatvox\" or \"cgal-poisson\"), scenario, points, threads, seconds,\n"
                 "peak_rss_mb, triangles, iou, mean_dist_vox, max_dist_vox, dist_samples; cgal\n"
                 "also compute_seconds (its reconstruction without reading and writing);\n"
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
            return cli_usage_error(CMD,
                                   "--scenario '%s': one of clean, uneven, noise-0.25, "
                                   "noise-0.5, flipped-10, hole",
                                   B->A.only[q]);
        B->asked[s] = 1;
    }
    return -1;
}

/* heatvox: --heatvox or this executable; the reference: --cgal or
 * bench_ref_cgal in this executable's directory, skipped when absent. */
static int find_programs(bench *B)
{
    char self[4096];
    ssize_t len = readlink("/proc/self/exe", self, sizeof self - 1);
    if (len <= 0) {
        fprintf(stderr, "heatvox %s: cannot find this executable: %s\n", CMD, strerror(errno));
        return HV_EXIT_FAIL;
    }
    self[len] = '\0';
    snprintf(B->heatvox, sizeof B->heatvox, "%s", B->A.heatvox ? B->A.heatvox : self);
    if (B->A.cgal)
        snprintf(B->cgal, sizeof B->cgal, "%s", B->A.cgal);
    else
        snprintf(B->cgal, sizeof B->cgal, "%.*s/bench_ref_cgal", (int)(strrchr(self, '/') - self),
                 self);
    B->have_cgal = access(B->cgal, X_OK) == 0;
    if (!B->have_cgal)
        fprintf(stderr, "heatvox %s: no %s (make bench builds it), cgal rows skipped\n", CMD,
                B->cgal);
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

/* ---- phase 1: the points and the two programs ---- */

static void file_of(const bench *B, int s, const char *suffix, char *out, size_t size)
{
    snprintf(out, size, "%s/%s%s", B->dir, SCENARIOS[s].name, suffix);
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

/* Runs argv as exe; says on stderr when it fails. */
static void run_program(const char *exe, char **argv, const char *out, run *R)
{
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

/* heatvox sdf on scenario s's points, with their normals or (recover) from
 * the points alone. */
static void run_heatvox(bench *B, int s, int recover)
{
    char xyz[4096 + 64], npy[4096 + 64], ply[4096 + 64], out[4096 + 64], ns[16];
    const char *who = recover ? "-recover" : "-heatvox";
    char tail[32];
    file_of(B, s, ".xyz", xyz, sizeof xyz);
    snprintf(tail, sizeof tail, "%s.npy", who);
    file_of(B, s, tail, npy, sizeof npy);
    snprintf(tail, sizeof tail, "%s.ply", who);
    file_of(B, s, tail, ply, sizeof ply);
    snprintf(tail, sizeof tail, "%s.out", who);
    file_of(B, s, tail, out, sizeof out);
    snprintf(ns, sizeof ns, "%d", B->A.n);
    char *argv[] = {"heatvox", "sdf",        xyz, "--res", ns,   "--npy",
                    npy,       "--mesh-out", ply, NULL,    NULL, NULL};
    if (recover) {
        argv[9] = "--orient";
        argv[10] = "recover";
    }
    if (B->A.band) { /* the narrow band alone, in tiles */
        snprintf(tail, sizeof tail, "%s.vdb", who);
        file_of(B, s, tail, npy, sizeof npy);
        argv[5] = "-o";
        argv[7] = NULL;
    }
    run_program(B->heatvox, argv, out, recover ? &B->rec[s] : &B->hv[s]);
}

/* compute_seconds from the reference's JSON line; -1 when absent. */
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

static void run_cgal(bench *B, int s)
{
    char xyz[4096 + 64], ply[4096 + 64], out[4096 + 64], hs[40];
    file_of(B, s, ".xyz", xyz, sizeof xyz);
    file_of(B, s, "-cgal.ply", ply, sizeof ply);
    file_of(B, s, "-cgal.out", out, sizeof out);
    snprintf(hs, sizeof hs, "%.17g", B->h);
    char *argv[] = {"bench_ref_cgal", xyz, ply, "--h", hs, NULL};
    run_program(B->cgal, argv, out, &B->cg[s]);
    B->cg[s].compute_seconds = B->cg[s].code ? -1 : read_compute_seconds(out);
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

static void print_run(bench *B, int s, const points_truth *T, int cgal)
{
    const run *R = cgal ? &B->cg[s] : &B->hv[s];
    print_head(B, s, cgal ? "cgal-poisson" : "heatvox");
    if (R->code) {
        printf(",\"error\":\"%s %s\"}\n", cgal ? "bench_ref_cgal" : "heatvox sdf",
               R->code < 0 ? "was killed by a signal" : "failed");
        fflush(stdout);
        return;
    }
    printf(",\"threads\":%d,\"seconds\":%.4f,\"peak_rss_mb\":%.1f", cgal ? 1 : hv_get_threads(),
           R->seconds, R->rss_mb);
    if (cgal && R->compute_seconds >= 0)
        printf(",\"compute_seconds\":%.4f", R->compute_seconds);
    else if (B->have_cgal && !B->cg[s].code)
        printf(",\"ref\":\"cgal-poisson\",\"ref_seconds\":%.4f,\"ratio\":%.3f", B->cg[s].seconds,
               R->seconds / B->cg[s].seconds);
    char ply[4096 + 64];
    file_of(B, s, cgal ? "-cgal.ply" : "-heatvox.ply", ply, sizeof ply);
    const double iou = print_scores(T, ply, "");
    if (!cgal)
        B->rec_iou[s] = iou;
    fflush(stdout);
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

/* --unoriented: the row of the points' recovered orientation. */
static void print_recovered(bench *B, int s, const points_truth *T)
{
    const run *R = &B->rec[s];
    print_head(B, s, "heatvox-recover");
    if (R->code) {
        printf(",\"error\":\"heatvox sdf --orient recover %s\"}\n",
               R->code < 0 ? "was killed by a signal" : "failed");
        fflush(stdout);
        return;
    }
    printf(",\"threads\":%d,\"seconds\":%.4f,\"peak_rss_mb\":%.1f", hv_get_threads(), R->seconds,
           R->rss_mb);
    if (!B->hv[s].code)
        printf(",\"ref\":\"heatvox\",\"ref_seconds\":%.4f,\"ratio\":%.3f", B->hv[s].seconds,
               R->seconds / B->hv[s].seconds);
    char ply[4096 + 64], more[160] = "";
    const double agree = orient_agreement(B, s);
    file_of(B, s, "-recover.ply", ply, sizeof ply);
    int k = snprintf(more, sizeof more, ",\"orient_agree\":%.5f", agree);
    if (B->rec_iou[s] >= 0)
        snprintf(more + k, sizeof more - (size_t)k, ",\"ref_iou\":%.5f", B->rec_iou[s]);
    const double iou = print_scores(T, ply, more);
    if (iou >= 0 && B->rec_iou[s] >= 0)
        fprintf(stderr,
                "heatvox %s: %s: recovered orientation: iou %.4f (%+.4f against the true "
                "normals), %.3f%% of the points on their true side\n",
                CMD, SCENARIOS[s].name, iou, iou - B->rec_iou[s], 100 * agree);
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
        run_heatvox(B, s, 0);
        if (B->A.unoriented)
            run_heatvox(B, s, 1);
        if (B->have_cgal)
            run_cgal(B, s);
    }
    points_truth T;
    char err[512];
    if (points_truth_init(&T, B->m, B->A.n, err, sizeof err)) {
        fprintf(stderr, "heatvox %s: %s: %s\n", CMD, B->A.mesh, err);
        return HV_EXIT_FAIL;
    }
    for (int s = 0; s < NSCEN; s++) {
        if (!B->asked[s])
            continue;
        print_run(B, s, &T, 0);
        if (B->A.unoriented)
            print_recovered(B, s, &T);
        if (B->have_cgal)
            print_run(B, s, &T, 1);
    }
    points_truth_free(&T);
    return HV_EXIT_OK;
}

/* --band: the narrow band of MESH itself, the reference of every row. */
static void run_mesh_band(bench *B)
{
    char vdb[4096 + 64], out[4096 + 64], ns[16];
    snprintf(vdb, sizeof vdb, "%s/mesh-band.vdb", B->dir);
    snprintf(out, sizeof out, "%s/mesh-band.out", B->dir);
    snprintf(ns, sizeof ns, "%d", B->A.n);
    char *argv[] = {"heatvox", "sdf", (char *)B->A.mesh, "--res", ns, "-o", vdb, NULL};
    run_program(B->heatvox, argv, out, &B->mesh_band);
}

/* --band's rows: time and memory against the mesh's own band. */
static int band_rows(bench *B)
{
    run_mesh_band(B);
    for (int s = 0; s < NSCEN; s++) {
        if (!B->asked[s])
            continue;
        if (write_points(B, s))
            return HV_EXIT_FAIL;
        run_heatvox(B, s, 0);
        const run *R = &B->hv[s], *M = &B->mesh_band;
        print_head(B, s, "heatvox-band");
        if (R->code)
            printf(",\"error\":\"heatvox sdf failed\"}\n");
        else
            printf(",\"threads\":%d,\"band\":3,\"seconds\":%.4f,\"peak_rss_mb\":%.1f",
                   hv_get_threads(), R->seconds, R->rss_mb);
        if (!R->code && !M->code)
            printf(",\"ref\":\"mesh-band\",\"ref_seconds\":%.4f,\"ref_peak_rss_mb\":%.1f,"
                   "\"ratio\":%.3f}\n",
                   M->seconds, M->rss_mb, R->seconds / M->seconds);
        else if (!R->code)
            printf("}\n");
        fflush(stdout);
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
