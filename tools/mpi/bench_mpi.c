/* bench_mpi: the distributed distance and extension (builds made with make
 * mpi), one JSON line per run on rank 0, with the single-process answer on
 * the same grid in the same run as the reference.
 *
 *   mpirun -n P build-mpi/bench_mpi extend --n N [--repeat R] [--out-band W] [--corner]
 *   mpirun -n P build-mpi/bench_mpi distance --n N [--calls C] [-hv_distance_keep_solvers true]
 *
 * extend: a velocity g(closest point) given within 1.5 voxels of a sphere
 * (radius 0.3 in the unit box) extended to |phi| < W voxels (--out-band,
 * default 3; 0: every cell, closest points past a rank's ghost layer read
 * from the ranks that own them) on a DMDA
 * (hv_dmda_extend; every rank fills only its own cells, so peak_rss_mb, the
 * largest over the ranks, is the distributed run's: the caller's four double
 * Vecs, phi and the velocity, and the extender's). seconds: best of R calls
 * after the first (setup_seconds: the extender's creation and the first
 * call, which makes the levels' solvers). ref "mg-one-process": rank 0 then
 * spawns `bench_mpi extend-ref`, a fresh process that runs hv_extend_many
 * (the band solve) on the whole grid, best of R, and reports its own peak
 * memory (hv_peak_rss, VmHWM: ref_peak_rss_mb); err and ref_err are the largest errors against the
 * exact extension on the output cells (every cell: but those within 3
 * voxels of the centre, which has no closest point); remote_cells, over
 * all ranks, the cells read at closest points past their rank's ghost layer.
 *
 * distance: the heat-method distance from a point in an N^3 box with two
 * baffles (walls one cell thick with gaps at opposite ends) on a DMDA
 * (hv_dmda_distance_compute: every rank holds its own box; setup_seconds is
 * the object's creation, its solvers and region labels, seconds the last of
 * C calls of the distance and first_seconds the first, keep_solvers the
 * PETSc option; ratio takes setup and the last call). ref "mg-one-process": rank 0 then spawns
 * `bench_mpi distance-ref`, hv_distance_compute with mg on the whole grid in
 * a fresh process with its own peak memory, which writes its distance to a
 * temporary file; max_diff_voxels is the largest difference over all cells. */
#include <heatvox/heatvox.h>
#include <petscdmda.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

extern char **environ;

static int rank, ranks;

/* The largest peak resident memory over the ranks. */
static double peak_mb(void)
{
    double mb = hv_peak_rss() / 1048576.0, all = mb;
    MPI_Allreduce(&mb, &all, 1, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
    return all;
}

static void velocity(const double p[3], double v[3])
{
    v[0] = sin(3 * p[0]) + p[2];
    v[1] = cos(2 * p[1]);
    v[2] = p[0] * p[1] - 0.5 * p[2];
}

/* phi, the exact extension and the input (exact near the surface, 5 off it)
 * at cell c of an n^3 unit box. */
/* The sphere: radius 0.3 at the box's centre, or with --corner radius 0.15
 * at (0.25, 0.25, 0.25), whose closest points the far ranks' cells read
 * past their ghost layers. */
static double sph_c = 0.5, sph_r = 0.3;

static double sphere_at(int n, PetscInt i, PetscInt j, PetscInt k, double ex[3], double in[3])
{
    const double h = 1.0 / n,
                 x[3] = {(i + 0.5) * h - sph_c, (j + 0.5) * h - sph_c, (k + 0.5) * h - sph_c};
    const double r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]), R = sph_r;
    double cp[3];
    for (int a = 0; a < 3; a++)
        cp[a] = sph_c + x[a] * R / fmax(r, 1e-12);
    velocity(cp, ex);
    for (int a = 0; a < 3; a++)
        in[a] = fabs(r - R) < 1.5 * h ? ex[a] : 5.0;
    return r - R;
}

/* The cells whose error the benchmark reports: |phi| < ob voxels, or with
 * ob = 0 every cell but those within 3 voxels of the sphere's centre (no
 * closest point there). */
static int scored(int n, double phi, double ob)
{
    return ob > 0 ? fabs(phi) < ob / n : phi + sph_r >= 3.0 / n;
}

/* The single-process reference, run as `bench_mpi extend-ref`: the whole
 * grid, hv_extend_many with mg (the band solve), best of R calls after the
 * first; prints "seconds err" on stdout. */
static int extend_reference(int n, int repeat, double ob)
{
    const double h = 1.0 / n;
    const size_t count = (size_t)n * n * n;
    float *phi = malloc(count * sizeof *phi), *in[3], *out[3];
    for (int a = 0; a < 3; a++) {
        in[a] = malloc(count * sizeof **in);
        out[a] = malloc(count * sizeof **out);
        if (!phi || !in[a] || !out[a])
            return 1;
    }
    for (size_t c = 0; c < count; c++) {
        double ex[3], v[3];
        phi[c] = (float)sphere_at(n, c % n, c / n % n, c / n / n, ex, v);
        for (int a = 0; a < 3; a++)
            in[a][c] = (float)v[a];
    }
    const int n3[3] = {n, n, n};
    hv_extend_opts o;
    hv_extend_opts_default(&o);
    o.out_band = ob;
    o.backend = HV_BACKEND_MG;
    hv_extender *e = NULL;
    hv_extend_field ef = {3, {in[0], in[1], in[2]}, {out[0], out[1], out[2]}};
    double best = INFINITY;
    if (hv_extender_create(&e, 3, n3, h, NULL, &o)) {
        fprintf(stderr, "bench_mpi: %s\n", hv_last_error());
        return 1;
    }
    for (int r = 0; r <= repeat; r++) {
        const double t0 = hv_now();
        if (hv_extend_many(e, phi, 1, &ef, NULL)) {
            fprintf(stderr, "bench_mpi: %s\n", hv_last_error());
            return 1;
        }
        if (r)
            best = fmin(best, hv_now() - t0);
    }
    hv_extender_destroy(&e);
    double err = 0;
    for (size_t c = 0; c < count; c++) {
        double ex[3], v[3];
        if (scored(n, sphere_at(n, c % n, c / n % n, c / n / n, ex, v), ob))
            for (int a = 0; a < 3; a++)
                err = fmax(err, fabs(out[a][c] - ex[a]));
    }
    printf("%.6f %.6f %.1f\n", best, err, hv_peak_rss() / 1048576.0);
    return 0;
}

static char self_path[4096];

/* Runs `bench_mpi args...` as a fresh process (so that its peak memory is
 * its own) and reads nv numbers from its standard output into v. */
static int spawn_reference(char *const args[], int nv, double *v)
{
    int fd[2];
    if (pipe(fd))
        return 1;
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_adddup2(&fa, fd[1], 1);
    posix_spawn_file_actions_addclose(&fa, fd[0]);
    pid_t pid;
    const int bad = posix_spawn(&pid, self_path, &fa, NULL, args, environ);
    posix_spawn_file_actions_destroy(&fa);
    close(fd[1]);
    if (bad) {
        close(fd[0]);
        fprintf(stderr, "bench_mpi: cannot run %s\n", self_path);
        return 1;
    }
    char buf[512] = {0};
    size_t got = 0;
    ssize_t k;
    while (got + 1 < sizeof buf && (k = read(fd[0], buf + got, sizeof buf - 1 - got)) > 0)
        got += (size_t)k;
    close(fd[0]);
    int status = 0, n = 0;
    const char *p = buf;
    for (int off = 0; n < nv && sscanf(p, "%lf%n", &v[n], &off) == 1; n++)
        p += off;
    if (waitpid(pid, &status, 0) != pid || !WIFEXITED(status) || WEXITSTATUS(status) || n != nv) {
        fprintf(stderr, "bench_mpi: the single-process reference failed\n");
        return 1;
    }
    return 0;
}

/* phi and the input velocity on this rank's cells (the input again before
 * every call: the extension works in place). */
static void extend_fill(DM da, int n, Vec phi, Vec v[3])
{
    PetscInt xs, ys, zs, xm, ym, zm;
    DMDAGetCorners(da, &xs, &ys, &zs, &xm, &ym, &zm);
    PetscScalar ***P, ***V[3];
    DMDAVecGetArray(da, phi, &P);
    for (int a = 0; a < 3; a++)
        DMDAVecGetArray(da, v[a], &V[a]);
    for (PetscInt k = zs; k < zs + zm; k++)
        for (PetscInt j = ys; j < ys + ym; j++)
            for (PetscInt i = xs; i < xs + xm; i++) {
                double ex[3], in[3];
                P[k][j][i] = sphere_at(n, i, j, k, ex, in);
                for (int a = 0; a < 3; a++)
                    V[a][k][j][i] = in[a];
            }
    DMDAVecRestoreArray(da, phi, &P);
    for (int a = 0; a < 3; a++)
        DMDAVecRestoreArray(da, v[a], &V[a]);
}

static int bench_extend(int n, int repeat, double ob)
{
    const double h = 1.0 / n;
    DM da;
    DMDACreate3d(PETSC_COMM_WORLD, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE,
                 DMDA_STENCIL_STAR, n, n, n, PETSC_DECIDE, PETSC_DECIDE, PETSC_DECIDE, 1, 1, NULL,
                 NULL, NULL, &da);
    DMSetUp(da);
    Vec phi, v[3];
    DMCreateGlobalVector(da, &phi);
    for (int a = 0; a < 3; a++)
        VecDuplicate(phi, &v[a]);
    PetscInt xs, ys, zs, xm, ym, zm;
    DMDAGetCorners(da, &xs, &ys, &zs, &xm, &ym, &zm);

    hv_extend_opts o;
    hv_extend_opts_default(&o);
    o.out_band = ob;
    hv_dmda_extender *X = NULL;
    hv_dmda_field f = {3, {v[0], v[1], v[2]}};
    hv_extend_stats S;
    MPI_Barrier(PETSC_COMM_WORLD);
    double t0 = MPI_Wtime(), best = INFINITY, setup = 0;
    for (int r = 0; r <= repeat; r++) {
        extend_fill(da, n, phi, v);
        MPI_Barrier(PETSC_COMM_WORLD);
        const double t1 = MPI_Wtime();
        if ((!X && hv_dmda_extender_create(&X, da, h, &o)) || hv_dmda_extend(X, phi, 1, &f, &S)) {
            fprintf(stderr, "bench_mpi: %s\n", hv_last_error());
            return 1;
        }
        MPI_Barrier(PETSC_COMM_WORLD);
        if (r == 0)
            setup = MPI_Wtime() - t0;
        else
            best = fmin(best, MPI_Wtime() - t1);
    }
    /* The error on the band. */
    double err = 0;
    const PetscScalar ***R[3];
    for (int a = 0; a < 3; a++)
        DMDAVecGetArrayRead(da, v[a], &R[a]);
    for (PetscInt k = zs; k < zs + zm; k++)
        for (PetscInt j = ys; j < ys + ym; j++)
            for (PetscInt i = xs; i < xs + xm; i++) {
                double ex[3], in[3];
                if (scored(n, sphere_at(n, i, j, k, ex, in), ob))
                    for (int a = 0; a < 3; a++)
                        err = fmax(err, fabs(R[a][k][j][i] - ex[a]));
            }
    for (int a = 0; a < 3; a++)
        DMDAVecRestoreArrayRead(da, v[a], &R[a]);
    double errall = 0;
    MPI_Allreduce(&err, &errall, 1, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
    unsigned long long rem = S.remote_cells, remote = 0;
    MPI_Allreduce(&rem, &remote, 1, MPI_UNSIGNED_LONG_LONG, MPI_SUM, PETSC_COMM_WORLD);
    const double peak = peak_mb();
    hv_dmda_extender_destroy(&X);

    /* The reference: one process on the whole grid, spawned by rank 0 (a
     * fresh process, so that its peak memory is its own). */
    if (rank == 0) {
        char ns[32], rs[32], bs[32];
        snprintf(ns, sizeof ns, "%d", n);
        snprintf(rs, sizeof rs, "%d", repeat);
        snprintf(bs, sizeof bs, "%g", ob);
        char *const args[] = {self_path, "extend-ref", "--n", ns, "--repeat", rs, "--out-band", bs,
                              sph_r < 0.3 ? "--corner" : NULL, NULL};
        double R[3]; /* seconds, err, peak */
        if (spawn_reference(args, 3, R))
            return 1;
        printf("{\"bench\":\"extend-dmda\",\"n\":%d,\"ranks\":%d,\"backend\":\"petsc\",\"out_band\":%g,"
               "\"sphere\":\"%s\",\"seconds\":%.4f,\"setup_seconds\":%.4f,\"levels\":%d,\"solves\":%d,"
               "\"remote_cells\":%llu,\"err\":%.5f,"
               "\"peak_rss_mb\":%.1f,\"ref\":\"mg-one-process\",\"ref_seconds\":%.4f,"
               "\"ref_err\":%.5f,\"ref_peak_rss_mb\":%.1f,\"ratio\":%.3f}\n",
               n, ranks, ob, sph_r < 0.3 ? "corner" : "centre", best, setup, S.levels, S.solves, remote, errall, peak, R[0], R[1], R[2],
               best / R[0]);
        fflush(stdout);
    }
    for (int a = 0; a < 3; a++)
        VecDestroy(&v[a]);
    VecDestroy(&phi);
    DMDestroy(&da);
    return 0;
}

/* The baffles: walls one cell thick across x = n/3 and 2n/3, with gaps at
 * opposite ends of y. */
static int baffle_at(int n, PetscInt i, PetscInt j)
{
    return (i == n / 3 && j < n - n / 8) || (i == 2 * n / 3 && j >= n / 8);
}

static const double dist_src[3] = {0.1, 0.5, 0.5};

/* The single-process reference, run as `bench_mpi distance-ref --n N --out
 * FILE`: mg on the whole grid; writes the distance (n^3 floats, x fastest)
 * to FILE and prints "seconds stages peak_mb". */
static int distance_reference(int n, const char *out)
{
    const int nn[3] = {n, n, n};
    const double org[3] = {0, 0, 0};
    hv_grid *g = NULL;
    if (hv_grid_create(&g, 3, nn, 1.0 / n, org) || hv_grid_add_mask(g))
        return 1;
    for (int k = 0; k < n; k++)
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++)
                g->solid[i + (size_t)n * (j + (size_t)n * k)] = (uint8_t)baffle_at(n, i, j);
    hv_distance_sources s = {NULL, 0, dist_src, 1, NULL};
    hv_distance_opts o;
    hv_distance_opts_default(&o);
    o.backend = HV_BACKEND_MG;
    hv_distance_stats S;
    const double t0 = hv_now();
    if (hv_distance_compute(g, &s, &o, &S)) {
        fprintf(stderr, "bench_mpi: %s\n", hv_last_error());
        return 1;
    }
    const double seconds = hv_now() - t0;
    FILE *f = fopen(out, "wb");
    const size_t count = (size_t)n * n * n;
    if (!f || fwrite(g->v, sizeof(float), count, f) != count || fclose(f)) {
        fprintf(stderr, "bench_mpi: cannot write %s\n", out);
        return 1;
    }
    printf("%.6f %d %.1f\n", seconds, S.stages, hv_peak_rss() / 1048576.0);
    hv_grid_destroy(&g);
    return 0;
}

static int bench_distance(int n, int calls)
{
    const double h = 1.0 / n;
    DM da;
    DMDACreate3d(PETSC_COMM_WORLD, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE,
                 DMDA_STENCIL_STAR, n, n, n, PETSC_DECIDE, PETSC_DECIDE, PETSC_DECIDE, 1, 1, NULL,
                 NULL, NULL, &da);
    DMSetUp(da);
    Vec solid, dist;
    DMCreateGlobalVector(da, &solid);
    VecDuplicate(solid, &dist);
    PetscInt xs, ys, zs, xm, ym, zm;
    DMDAGetCorners(da, &xs, &ys, &zs, &xm, &ym, &zm);
    PetscScalar ***M;
    DMDAVecGetArray(da, solid, &M);
    for (PetscInt k = zs; k < zs + zm; k++)
        for (PetscInt j = ys; j < ys + ym; j++)
            for (PetscInt i = xs; i < xs + xm; i++)
                M[k][j][i] = baffle_at(n, i, j);
    DMDAVecRestoreArray(da, solid, &M);
    hv_distance_sources s = {NULL, 0, dist_src, 1, NULL};
    hv_dmda_distance *D = NULL;
    hv_distance_stats S;
    MPI_Barrier(PETSC_COMM_WORLD);
    const double t0 = MPI_Wtime();
    if (hv_dmda_distance_create(&D, da, h, NULL, solid, NULL)) {
        fprintf(stderr, "bench_mpi: %s\n", hv_last_error());
        return 1;
    }
    MPI_Barrier(PETSC_COMM_WORLD);
    const double t1 = MPI_Wtime();
    double first = 0, seconds = 0;
    for (int c = 0; c < calls; c++) {
        const double tc = MPI_Wtime();
        if (hv_dmda_distance_compute(D, &s, dist, &S)) {
            fprintf(stderr, "bench_mpi: %s\n", hv_last_error());
            return 1;
        }
        MPI_Barrier(PETSC_COMM_WORLD);
        seconds = MPI_Wtime() - tc;
        if (c == 0)
            first = seconds;
    }
    PetscBool keep = PETSC_FALSE;
    PetscOptionsGetBool(NULL, NULL, "-hv_distance_keep_solvers", &keep, NULL);
    const double setup = t1 - t0, peak = peak_mb();
    hv_dmda_distance_destroy(&D);

    /* The reference, spawned by rank 0; every rank compares its own cells. */
    char path[64];
    snprintf(path, sizeof path, "/tmp/bench_mpi_distance_%d.f32", (int)getpid());
    (void)MPI_Bcast(path, (int)sizeof path, MPI_CHAR, 0, PETSC_COMM_WORLD);
    double R[3] = {0, 0, 0}; /* seconds, stages, peak */
    int fail = 0;
    if (rank == 0) {
        char ns[32];
        snprintf(ns, sizeof ns, "%d", n);
        char *const args[] = {self_path, "distance-ref", "--n", ns, "--out", path, NULL};
        fail = spawn_reference(args, 3, R);
    }
    (void)MPI_Bcast(&fail, 1, MPI_INT, 0, PETSC_COMM_WORLD);
    if (fail)
        return 1;
    double d = 0;
    FILE *f = fopen(path, "rb");
    float *row = malloc((size_t)xm * sizeof *row);
    const PetscScalar ***A;
    DMDAVecGetArrayRead(da, dist, &A);
    for (PetscInt k = zs; f && row && k < zs + zm; k++)
        for (PetscInt j = ys; j < ys + ym; j++) {
            if (fseek(f, (long)(sizeof(float) * (xs + (size_t)n * (j + (size_t)n * k))), SEEK_SET) ||
                fread(row, sizeof *row, (size_t)xm, f) != (size_t)xm) {
                d = INFINITY;
                break;
            }
            for (PetscInt i = 0; i < xm; i++)
                if (isfinite(row[i]) && isfinite(A[k][j][xs + i]))
                    d = fmax(d, fabs(row[i] - A[k][j][xs + i]) * n);
        }
    DMDAVecRestoreArrayRead(da, dist, &A);
    if (!f || !row)
        d = INFINITY;
    if (f)
        fclose(f);
    free(row);
    MPI_Allreduce(MPI_IN_PLACE, &d, 1, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
    MPI_Barrier(PETSC_COMM_WORLD);
    if (rank == 0) {
        unlink(path);
        printf("{\"bench\":\"distance-dmda\",\"n\":%d,\"ranks\":%d,\"backend\":\"petsc\","
               "\"obstacle\":\"baffles\",\"keep_solvers\":%s,\"calls\":%d,\"first_seconds\":%.3f,"
               "\"seconds\":%.3f,\"setup_seconds\":%.3f,\"stages\":%d,"
               "\"diffuse_iterations\":%d,\"diffuse_seconds\":%.3f,\"normalize_seconds\":%.3f,"
               "\"poisson_iterations\":%d,\"poisson_seconds\":%.3f,\"peak_rss_mb\":%.1f,"
               "\"ref\":\"mg-one-process\",\"ref_seconds\":%.3f,\"ref_stages\":%d,"
               "\"ref_peak_rss_mb\":%.1f,\"max_diff_voxels\":%.2e,\"ratio\":%.3f}\n",
               n, ranks, keep ? "true" : "false", calls, first, seconds, setup, S.stages, S.diffuse_iterations, S.t_diffuse,
               S.t_normalize, S.poisson_iterations, S.t_poisson, peak, R[0], (int)R[1], R[2], d, (seconds + setup) / R[0]);
        fflush(stdout);
    }
    VecDestroy(&solid);
    VecDestroy(&dist);
    DMDestroy(&da);
    return 0;
}

int main(int argc, char **argv)
{
    int n = 0, repeat = 3, calls = 1;
    double ob = 3;
    const char *what = argc > 1 ? argv[1] : "", *out = NULL;
    int bad = 0;
    for (int i = 2; i < argc; i++) {
        if (!strcmp(argv[i], "--corner")) {
            sph_c = 0.25;
            sph_r = 0.15;
        } else if (i + 1 >= argc) {
            bad = 1;
        } else if (!strcmp(argv[i], "--n")) {
            n = atoi(argv[++i]);
        } else if (!strcmp(argv[i], "--repeat")) {
            repeat = atoi(argv[++i]);
        } else if (!strcmp(argv[i], "--calls")) {
            calls = atoi(argv[++i]);
        } else if (!strcmp(argv[i], "--out")) {
            out = argv[++i];
        } else if (!strcmp(argv[i], "--out-band")) {
            ob = atof(argv[++i]);
        } else {
            i++; /* a PETSc option and its value */
        }
    }
    if ((strcmp(what, "extend") && strcmp(what, "distance") && strcmp(what, "extend-ref") &&
         (strcmp(what, "distance-ref") || !out)) ||
        n < 16 || repeat < 1 || calls < 1 || !(ob >= 0) || bad) {
        fprintf(stderr, "usage: mpirun -n P bench_mpi extend|distance --n N (>= 16) [--repeat R] "
                        "[--out-band W (extend; 0: every cell)] [--corner (extend)] [--calls C (distance)]\n");
        return 2;
    }
    if (!strcmp(what, "extend-ref")) /* the spawned references: no MPI */
        return extend_reference(n, repeat, ob);
    if (!strcmp(what, "distance-ref"))
        return distance_reference(n, out);
    if (!realpath("/proc/self/exe", self_path)) {
        fprintf(stderr, "bench_mpi: cannot find its own executable\n");
        return 1;
    }
    PetscInitialize(&argc, &argv, NULL, NULL);
    MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
    MPI_Comm_size(PETSC_COMM_WORLD, &ranks);
    const int rc = !strcmp(what, "extend") ? bench_extend(n, repeat, ob) : bench_distance(n, calls);
    PetscFinalize();
    return rc;
}
