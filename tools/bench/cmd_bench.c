/* heatvox bench: benchmarks that print one JSON object per line. Ratios are
 * taken against references measured in the same process (a plain memory copy,
 * FFTW), because absolute times drift on shared machines. */
#include "bench_device.h"
#include "bench_ref.h"
#include "../cli.h"
#include "../commands.h"

#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef _OPENMP
#include <omp.h>
#endif

/* The reference: a threaded streaming copy b = a, counting read + write.
 * Trials run between the timed solves, so that the copy and the cycles are
 * measured over the same stretch of time on a shared machine (its memory
 * bandwidth drifts by up to 2x between seconds), and the best trial is kept,
 * as the best solve is. */
typedef struct copy_ref {
    float *a, *b;
    size_t n;
    double gbs;  /* best so far, all threads */
    double gbs1; /* best so far, one thread: a copy on 2 threads runs at 1.2x this where
                    both cores share one path to memory, 2x where they do not */
} copy_ref;

static int copy_ref_init(copy_ref *c, size_t bytes)
{
    c->n = bytes / sizeof(float);
    c->gbs = c->gbs1 = 0;
    c->a = hv_malloc(c->n * sizeof(float));
    c->b = hv_malloc(c->n * sizeof(float));
    if (!c->a || !c->b)
        return -1;
    float *a = c->a, *b = c->b;
#pragma omp parallel for schedule(static)
    for (size_t i = 0; i < c->n; i++) {
        a[i] = (float)i;
        b[i] = 0;
    }
    return 0;
}

static void copy_ref_trial(copy_ref *c, int passes)
{
    const float *a = c->a;
    float *b = c->b;
    const size_t n = c->n;
    for (int r = 0; r < passes + 1; r++) {
        int one = r == passes; /* the last pass on one thread */
        double t0 = hv_now();
#pragma omp parallel for schedule(static) if (!one)
        for (size_t i = 0; i < n; i++)
            b[i] = a[i];
        double t = hv_now() - t0;
        double gbs = t > 0 ? 2.0 * (double)n * sizeof(float) / t / 1e9 : 0;
        double *best = one ? &c->gbs1 : &c->gbs;
        if (gbs > *best)
            *best = gbs;
    }
    volatile float sink = b[n / 2];
    (void)sink;
}

static void copy_ref_free(copy_ref *c)
{
    hv_free(c->a);
    hv_free(c->b);
    c->a = c->b = NULL;
}

static void fill_rhs(float *f, size_t n)
{
    uint64_t s = 0x9e3779b97f4a7c15ull;
#pragma omp parallel for schedule(static)
    for (size_t i = 0; i < n; i++) {
        uint64_t x = (s ^ (i * 0xbf58476d1ce4e5b9ull)) * 0x94d049bb133111ebull;
        f[i] = (float)((double)(x >> 40) / (double)(1ull << 24)) - 0.5f;
    }
}

/* A maze's walls (--obstacle maze): planes one cell thick across x and
 * across y every `pitch` cells (pitch = max(N/8, 4), the first at pitch/2),
 * each panel of pitch x pitch cells of a wall with one square gap of side
 * pitch/4 at a place drawn from a fixed seed: every room opens into its
 * neighbours, through holes that geometric coarsening loses. */
static int maze_wall(int n, int dim, int i, int j, int k)
{
    const int pitch = n / 8 > 4 ? n / 8 : 4, g = pitch / 4 > 1 ? pitch / 4 : 1;
    const int across[2] = {i, j}, along[2] = {j, i};
    for (int a = 0; a < 2; a++) {
        const int x = across[a];
        if (x < pitch / 2 || (x - pitch / 2) % pitch)
            continue;
        const int y = along[a], z = dim == 3 ? k : 0;
        /* The panel (wall, y / pitch, z / pitch) and its gap. */
        uint64_t key = ((uint64_t)a << 60) ^ ((uint64_t)x << 40) ^ ((uint64_t)(y / pitch) << 20) ^
                       (uint64_t)(z / pitch);
        key = (key ^ (key >> 31)) * 0x94d049bb133111ebull;
        key = (key ^ (key >> 29)) * 0xbf58476d1ce4e5b9ull;
        const int span = pitch - g > 1 ? pitch - g : 1;
        const int gy = (int)(key % (uint64_t)span), gz = (int)(key / 1024 % (uint64_t)span);
        const int in_gap = y % pitch >= gy && y % pitch < gy + g &&
                           (dim == 2 || (z % pitch >= gz && z % pitch < gz + g));
        if (!in_gap)
            return 1;
    }
    return 0;
}

/* Solid cells of an n^dim box for --obstacle (dim 2: one layer). */
static uint8_t *make_obstacle(const char *kind, int dim, int n)
{
    const int nz = dim == 3 ? n : 1;
    uint8_t *solid = calloc((size_t)n * n * nz, 1);
    if (!solid)
        return NULL;
    const int w1 = n / 3, w2 = 2 * n / 3, gap = n / 8 > 1 ? n / 8 : 1;
    for (int k = 0; k < nz; k++)
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++) {
                size_t c = (size_t)i + (size_t)n * ((size_t)j + (size_t)n * k);
                if (!strcmp(kind, "ball")) {
                    double x = i + 0.5 - 0.5 * n, y = j + 0.5 - 0.5 * n,
                           z = dim == 3 ? k + 0.5 - 0.5 * n : 0;
                    solid[c] = x * x + y * y + z * z < 0.0625 * n * n;
                } else if (!strcmp(kind, "maze")) {
                    solid[c] = (uint8_t)maze_wall(n, dim, i, j, k);
                } else { /* baffles: wall at w1 open at high y, wall at w2 open at low y */
                    solid[c] = (i == w1 && j < n - gap) || (i == w2 && j >= gap);
                }
            }
    return solid;
}

/* The first solve of a solver (the warm-up of time_solve): its time and
 * iterations, what a single solve costs after the set-up. */
typedef struct first_solve {
    double seconds;
    int iterations;
} first_solve;

/* Times `repeat` solves after one warm-up; returns the best time and its info,
 * and in *cycle_gbs the best V-cycle bandwidth of any timed solve (cycle_bytes /
 * cycle_seconds; 0 where the backend does not time its cycles). With `ref`, a
 * copy trial runs before each solve; with `first`, the first solve's figures. */
static hv_status time_solve(hv_solver *s, const float *f, float *u, int repeat, copy_ref *ref,
                            double *best, hv_solve_info *info, double *cycle_gbs,
                            first_solve *first)
{
    *best = 1e30;
    *cycle_gbs = 0;
    memset(info, 0, sizeof *info);
    for (int r = 0; r <= repeat; r++) {
        if (ref)
            copy_ref_trial(ref, 3);
        hv_solve_info run;
        double t0 = hv_now();
        hv_status st = hv_solver_solve(s, f, u, &run);
        double t = hv_now() - t0;
        if (st)
            return st;
        if (r == 0 && first)
            *first = (first_solve){t, run.iterations};
        if (r == 0 && repeat > 0)
            continue;    /* warm-up */
        if (t < *best) { /* the info of the fastest run */
            *best = t;
            *info = run;
        }
        if (run.cycles_timed > 0 && run.cycle_seconds > 0 &&
            run.cycle_bytes / run.cycle_seconds / 1e9 > *cycle_gbs)
            *cycle_gbs = run.cycle_bytes / run.cycle_seconds / 1e9;
    }
    return HV_OK;
}

/* The device's own figures (tools/bench/bench_device.c) as JSON fields: the solve
 * with the fields on the device, the transfers apart, the device's copy
 * bandwidth and the modelled traffic against it. */
static void print_device(const hv_problem *p, hv_solver_opts *o, const float *f, int repeat,
                         double traffic, double host_seconds)
{
    bench_device d;
    o->backend = HV_BACKEND_OPENCL;
    hv_status st = bench_device_solve(p, o, f, repeat, &d);
    if (st) {
        printf(",\"device_error\":\"%s\"", hv_status_str(st));
        return;
    }
    const double gbs = d.seconds > 0 ? traffic / d.seconds / 1e9 : 0;
    printf(",\"device\":\"%s\",\"device_setup_seconds\":%.4f,\"device_seconds\":%.5f,"
           "\"device_event_seconds\":%.5f,\"device_iterations\":%d,\"device_relres\":%.3e,"
           "\"transfer_seconds\":%.6g,\"host_vs_device\":%.3f,\"dev_copy_gbs\":%.2f,"
           "\"dev_solve_gbs\":%.2f,\"dev_solve_vs_copy\":%.3f",
           d.name, d.setup_seconds, d.seconds, d.event_seconds, d.iterations, d.relres,
           d.transfer_seconds, d.seconds > 0 ? host_seconds / d.seconds : 0, d.copy_gbs, gbs,
           d.copy_gbs > 0 ? gbs / d.copy_gbs : 0);
    const double kgbs = d.kernel_seconds > 0 ? traffic / d.kernel_seconds / 1e9 : 0;
    printf(",\"dev_kernel_seconds\":%.5f,\"dev_launches\":%.0f,\"dev_kernel_gbs\":%.2f,"
           "\"dev_kernel_vs_copy\":%.3f",
           d.kernel_seconds, d.launches, kgbs, d.copy_gbs > 0 ? kgbs / d.copy_gbs : 0);
}

static int usage_solve(FILE *out)
{
    fprintf(out,
            "usage: heatvox bench solve --n N [--dim 2|3] [--t-scale K] [--poisson]\n"
            "                           [--backend mg|fftw|opencl|petsc]\n"
            "                           [--smoother rbgs|jacobi|chebyshev] [--pc "
            "auto|boomeramg|pfmg|gamg]\n"
            "                           [--tol 1e-6] [--threads T] [--repeat R] [--wisdom FILE]\n"
            "                           [--obstacle none|ball|baffles|maze]\n"
            "                           [--coarse auto|geometric|aggregation]\n"
            "Solves (I - t Lap) u = f with t = K h^2 (default K = 4), or Neumann Poisson with\n"
            "--poisson, on an N^dim box with a random right-hand side, and prints one JSON line:\n"
            "bench, n, dim, problem, backend, seconds (best of R after a warm-up), iterations,\n"
            "cycles (V-cycles; mg may run several per iteration), relres, reduction (the\n"
            "residual's mean factor per iteration, relres^(1/iterations)), copy_gbs (threaded\n"
            "streaming copy in the same process, best of trials run between the timed solves;\n"
            "copy1_gbs the same on one thread), cycle_gbs (modelled bytes of the timed V-cycles /\n"
            "their wall time, best of the timed solves; mg times every cycle but the FMG start,\n"
            "cycles_timed of them),\n"
            "solve_gbs (modelled bytes of the whole solve / its time), peak_rss_mb (the\n"
            "process's peak resident memory after the timed solves: the problem's arrays, the\n"
            "solver's and the copy reference's two buffers, copy_ref_mb), and for mg/opencl ref "
            "\"fftw\",\n"
            "ref_seconds (float DCT solve, FFTW_MEASURE) and ratio = seconds / ref_seconds.\n"
            "--backend petsc (builds with PETSc: make mpi) runs under mpirun: every rank solves,\n"
            "rank 0 prints, with ranks, and ref \"mg\" (the same grid on one process, the same\n"
            "run, solved first: ref_seconds, ref_iterations, ref_peak_rss_mb; each peak counts\n"
            "from a reset high-water mark; mem_ratio); peak_rss_mb is rank 0's (every rank holds "
            "the whole grid's f and\n"
            "u, as the solver interface takes them; no copy reference); --pc its preconditioner "
            "(smoother in the JSON):\n"
            "auto (default: hypre's PFMG in 3D, BoomerAMG in 2D), hypre's BoomerAMG or PFMG\n"
            "(3D), or PETSc's GAMG.\n"
            "--obstacle: solid cells (mg and opencl then run PCG with the V-cycle inside): ball,\n"
            "a solid ball of radius N/4 in the middle; baffles, walls one cell thick across x at\n"
            "N/3 and 2N/3, each with a gap of N/8 at opposite ends (a corridor); maze, walls one\n"
            "cell thick across x and across y every max(N/8, 4) cells, each panel of the walls\n"
            "with one square gap of a quarter of that at a fixed random place. The reference\n"
            "is then FFTW on the same box without the obstacle (\"ref\": \"fftw-plain-box\").\n"
            "--coarse: the coarse levels of mg and opencl with solid cells: aggregation\n"
            "(Galerkin operators that keep the walls; auto changes to it within a solve whose\n"
            "first iterations stall, as the warm-up of most --poisson rows does) or geometric\n"
            "(halved grids, averaged coefficients). first_seconds and first_iterations: the\n"
            "solver's first solve (the warm-up, where auto decides); one_solve_seconds =\n"
            "setup_seconds + first_seconds, what one solve costs from nothing.\n"
            "--backend opencl adds the device's own figures, from a context and profiling\n"
            "queue of the benchmark's: device, device_setup_seconds, device_seconds (best\n"
            "solve with f and u already on the device, hv_opencl_solve), device_event_seconds\n"
            "(the same between two profiled markers), transfer_seconds (f in and u out as\n"
            "floats, which the host-array interface adds), host_vs_device (seconds /\n"
            "device_seconds), dev_copy_gbs (clEnqueueCopyBuffer, read + write, best of five),\n"
            "dev_solve_gbs (the solve's modelled traffic / device_seconds) and\n"
            "dev_solve_vs_copy; dev_kernel_seconds (the solve's kernels and transfers\n"
            "summed from their profiling events: the solve without the host's share),\n"
            "dev_launches (commands per solve), dev_kernel_gbs and dev_kernel_vs_copy\n"
            "(the modelled traffic over the kernels' time, against the device's copy).\n");
    return out == stdout ? HV_EXIT_OK : HV_EXIT_USAGE;
}

/* bench solve's command line. */
typedef struct solve_args {
    int n, dim, poisson, threads, repeat;
    double tscale, tol;
    hv_backend backend;
    int smoother, smoother_set; /* hv_smoother */
    int pc;                     /* index in PCS: backend petsc's preconditioner */
    int obstacle;               /* index in OBSTACLES */
    int coarse;                 /* hv_coarse */
    const char *wisdom;
} solve_args;

static const char *const PCS[] = {"auto", "boomeramg", "pfmg", "gamg"};
static const char *const OBSTACLES[] = {"none", "ball", "baffles", "maze"};
static const char *const COARSE[] = {"auto", "geometric", "aggregation"};

static void help_solve(void) { usage_solve(stdout); }

/* -1 to go on, else the exit code. */
static int parse_solve(int argc, char **argv, solve_args *A)
{
    const cli_opt opts[] = {
        CLI_ROW_QUIET,
        {.names = "--poisson", .kind = CLI_FLAG, .dst = &A->poisson, .val = 1},
        {.names = "--n",
         .kind = CLI_INT,
         .dst = &A->n,
         .min = 2,
         .max = INT_MAX,
         .needs = "an integer >= 2"},
        {.names = "--dim", .kind = CLI_INT, .dst = &A->dim, .min = 2, .max = 3, .needs = "2 or 3"},
        CLI_ROW_T_SCALE(&A->tscale),
        {.names = "--tol",
         .kind = CLI_DOUBLE,
         .dst = &A->tol,
         .min = 1e-12,
         .max = 1 - 0x1p-53,
         .needs = "a number in [1e-12, 1)"},
        CLI_ROW_THREADS(&A->threads),
        CLI_ROW_REPEAT(&A->repeat),
        CLI_ROW_BACKEND(&A->backend, CLI_BACKENDS_ALL & ~CLI_BACKEND(HV_BACKEND_AUTO)),
        {.names = "--smoother",
         .kind = CLI_CHOICE,
         .dst = &A->smoother,
         .val = HV_SMOOTH_RBGS,
         .choices = "rbgs|jacobi|chebyshev",
         .needs = "rbgs, jacobi or chebyshev",
         .given = &A->smoother_set},
        {.names = "--pc",
         .kind = CLI_CHOICE,
         .dst = &A->pc,
         .choices = "auto|boomeramg|pfmg|gamg",
         .needs = "auto, boomeramg, pfmg or gamg"},
        {.names = "--wisdom", .kind = CLI_STR, .dst = &A->wisdom, .files = CLI_FILES_ANY},
        {.names = "--obstacle",
         .kind = CLI_CHOICE,
         .dst = &A->obstacle,
         .choices = "none|ball|baffles|maze",
         .needs = "none, ball, baffles or maze"},
        {.names = "--coarse",
         .kind = CLI_CHOICE,
         .dst = &A->coarse,
         .choices = "auto|geometric|aggregation",
         .needs = "auto, geometric or aggregation"},
        {.names = NULL},
    };
    const char *stray = NULL;
    int rc = cli_parse("bench solve", argc, argv, opts, "argument", &stray, help_solve);
    if (rc >= 0)
        return rc;
    if (stray)
        return cli_usage_error("bench solve", "unexpected argument '%s'", stray);
    if (!A->n)
        return cli_usage_error("bench solve", "--n is required");
    if (A->backend == HV_BACKEND_OPENCL && !A->smoother_set)
        A->smoother = HV_SMOOTH_CHEBYSHEV;
    if (A->pc && A->backend != HV_BACKEND_PETSC)
        return cli_usage_error("bench solve", "--pc needs --backend petsc");
    return -1;
}

/* The problem of a run: the box, its random right-hand side, the solution
 * and the obstacle's solid cells. */
typedef struct solve_problem {
    hv_problem p;
    size_t count;
    float *f, *u;
    uint8_t *solid;
} solve_problem;

static void problem_free(solve_problem *P)
{
    free(P->solid);
    hv_free(P->f);
    hv_free(P->u);
}

static int make_problem(const solve_args *A, solve_problem *P)
{
    const int n = A->n, dim = A->dim;
    const double h = 1.0 / n;
    const hv_problem p = {dim,  {n, n, dim == 3 ? n : 1}, h,
                          NULL, A->poisson ? 0.0 : 1.0,   A->poisson ? 1.0 : A->tscale * h * h};
    P->p = p;
    P->count = (size_t)n * n * (dim == 3 ? n : 1);
    hv_status st = hv_check_dims(dim, P->p.n, h, 24);
    if (st)
        return cli_fail("bench solve", "grid", st);
    P->f = hv_malloc(P->count * sizeof(float));
    P->u = hv_calloc(P->count, sizeof(float));
    if (!P->f || !P->u)
        return cli_fail("bench solve", "allocating the problem", HV_ERR_NOMEM);
    fill_rhs(P->f, P->count);
    if (A->obstacle) {
        if (!(P->solid = make_obstacle(OBSTACLES[A->obstacle], dim, n)))
            return cli_fail("bench solve", "allocating the obstacle", HV_ERR_NOMEM);
        P->p.solid = P->solid;
    }
    return 0;
}

/* What the timed solves measured. */
typedef struct solve_row {
    double setup, seconds, cycle_gbs, solve_gbs, traffic, peak_mb;
    double copy_gbs, copy1_gbs, copy_mb;
    hv_solve_info info;
    first_solve first;
    int levels;
} solve_row;

/* Creates the solver and times its solves, the copy reference's trials run
 * between them (not under mpirun: ranks would share the memory bandwidth it
 * measures, and its buffers would blur the peak memory). */
static int time_row(const solve_args *A, const solve_problem *P, const hv_solver_opts *o,
                    solve_row *R)
{
    copy_ref ref = {0};
    const int copy = A->backend != HV_BACKEND_PETSC;
    const size_t bytes = P->count * sizeof(float);
    if (copy && copy_ref_init(&ref, bytes > (256u << 20) ? bytes : (256u << 20))) {
        copy_ref_free(&ref);
        return cli_fail("bench solve", "allocating the copy reference", HV_ERR_NOMEM);
    }
    hv_solver *s = NULL;
    double t0 = hv_now(), best_cycle_gbs;
    hv_status st = hv_solver_create(&s, &P->p, o);
    if (st) {
        copy_ref_free(&ref);
        return cli_fail("bench solve", "creating the solver", st);
    }
    R->setup = hv_now() - t0;
    st = time_solve(s, P->f, P->u, A->repeat, copy ? &ref : NULL, &R->seconds, &R->info,
                    &best_cycle_gbs, &R->first);
    R->copy_gbs = ref.gbs;
    R->copy1_gbs = ref.gbs1;
    R->copy_mb = 2.0 * ref.n * sizeof(float) / 1048576;
    copy_ref_free(&ref);
    if (st) {
        hv_solver_destroy(&s);
        return cli_fail("bench solve", "solving", st);
    }
    hv_solver_stats stats;
    hv_solver_get_stats(s, &stats);
    R->levels = stats.levels;
    /* Each iteration runs one cycle plus its correction; further cycles in an
     * iteration (mg: info.cycles > iterations) add bytes_per_cycle each. */
    const hv_solve_info *info = &R->info;
    R->traffic = stats.bytes_per_iteration * info->iterations;
    if (info->cycles > info->iterations && stats.bytes_per_cycle > 0)
        R->traffic += stats.bytes_per_cycle * (info->cycles - info->iterations);
    R->solve_gbs =
        info->iterations > 0 && A->backend != HV_BACKEND_FFTW ? R->traffic / R->seconds / 1e9 : 0;
    /* The V-cycle's own bandwidth where the backend times its cycles (mg);
     * otherwise the whole solve's. */
    R->cycle_gbs = best_cycle_gbs > 0 ? best_cycle_gbs : R->solve_gbs;
    hv_solver_destroy(&s);
    R->peak_mb = hv_peak_rss() / 1048576.0;
    return 0;
}

/* Under mpirun (backend petsc): mg on the same grid in the same run, first,
 * so that each peak memory counts from a high-water mark reset after the
 * other (PETSc keeps what it freed resident; mg hands its arrays back). */
typedef struct mg_ref {
    double seconds, peak_mb;
    hv_solve_info info;
} mg_ref;

static int time_mg_ref(const solve_args *A, const solve_problem *P, hv_solver_opts o, mg_ref *M)
{
    hv_solver *s = NULL;
    double unused_gbs;
    o.backend = HV_BACKEND_MG;
    o.smoother = HV_SMOOTH_AUTO;
    M->peak_mb = -1;
    const int reset = hv_peak_rss_reset() == HV_OK;
    hv_status st = hv_solver_create(&s, &P->p, &o);
    if (!st)
        st = time_solve(s, P->f, P->u, A->repeat, NULL, &M->seconds, &M->info, &unused_gbs, NULL);
    hv_solver_destroy(&s);
    if (st)
        return cli_fail("bench solve", "the mg reference", st);
    if (reset)
        M->peak_mb = hv_peak_rss() / 1048576.0;
    hv_peak_rss_reset();
    return 0;
}

static const char *smoother_name(const solve_args *A)
{
    if (A->backend == HV_BACKEND_PETSC)
        return A->pc         ? PCS[A->pc]
               : A->dim == 3 ? "auto:pfmg" /* one fluid region */
                             : "auto:boomeramg";
    return A->smoother == HV_SMOOTH_RBGS     ? "rbgs"
           : A->smoother == HV_SMOOTH_JACOBI ? "jacobi"
                                             : "chebyshev";
}

/* The reference's fields: mg in the same run under mpirun, else FFTW on the
 * same box (without the obstacle: FFTW solves plain boxes). */
static void print_reference(const solve_args *A, const solve_problem *P, hv_solver_opts o,
                            const solve_row *R, const mg_ref *M)
{
    if (A->backend == HV_BACKEND_PETSC) {
        printf(",\"ref\":\"mg\",\"ref_seconds\":%.5f,\"ref_iterations\":%d,\"ref_relres\":%.3e,"
               "\"ratio\":%.3f",
               M->seconds, M->info.iterations, M->info.relres, R->seconds / M->seconds);
        if (M->peak_mb >= 0)
            printf(",\"ref_peak_rss_mb\":%.1f,\"mem_ratio\":%.3f", M->peak_mb,
                   R->peak_mb / M->peak_mb);
        return;
    }
    if (A->backend == HV_BACKEND_FFTW)
        return;
    hv_problem plain = P->p;
    plain.solid = NULL;
    o.backend = HV_BACKEND_FFTW;
    hv_solver *s = NULL;
    double ref_seconds = 0, unused;
    hv_solve_info rinfo;
    if (hv_solver_create(&s, &plain, &o) == HV_OK &&
        time_solve(s, P->f, P->u, A->repeat, NULL, &ref_seconds, &rinfo, &unused, NULL) == HV_OK)
        printf(",\"ref\":\"%s\",\"ref_seconds\":%.5f,\"ref_relres\":%.3e,\"ratio\":%.3f",
               P->solid ? "fftw-plain-box" : "fftw", ref_seconds, rinfo.relres,
               R->seconds / ref_seconds);
    hv_solver_destroy(&s);
}

static void print_row(const solve_args *A, const solve_problem *P, hv_solver_opts *o,
                      const solve_row *R, const mg_ref *M)
{
    const hv_solve_info *info = &R->info;
    printf(
        "{\"bench\":\"solve\",\"n\":%d,\"ranks\":%d,\"dim\":%d,\"problem\":\"%s\",\"t_scale\":%g,"
        "\"backend\":\"%s\",\"smoother\":\"%s\",\"threads\":%d,\"tol\":%g,\"setup_seconds\":%.4f,"
        "\"seconds\":%.5f,\"peak_rss_mb\":%.1f,\"iterations\":%d,\"cycles\":%d,\"relres\":%.3e,"
        "\"reduction\":%.4f,\"reason\":\"%s\","
        "\"levels\":%d,"
        "\"copy_gbs\":%.2f,\"cycle_gbs\":%.2f,\"cycles_timed\":%d,\"solve_gbs\":%.2f,"
        "\"obstacle\":\"%s\",\"coarse\":\"%s\",\"first_seconds\":%.5f,\"first_iterations\":%d,"
        "\"one_solve_seconds\":%.5f",
        A->n, hv_mpi_size(), A->dim, A->poisson ? "poisson" : "heat", A->poisson ? 0.0 : A->tscale,
        hv_backend_name(A->backend), smoother_name(A), A->threads, A->tol, R->setup, R->seconds,
        R->peak_mb, info->iterations, info->cycles, info->relres,
        info->iterations > 0 && info->relres > 0 ? pow(info->relres, 1.0 / info->iterations) : 0.0,
        hv_stop_reason_str(info->reason), R->levels, R->copy_gbs, R->cycle_gbs, info->cycles_timed,
        R->solve_gbs, OBSTACLES[A->obstacle], COARSE[A->coarse], R->first.seconds,
        R->first.iterations, R->setup + R->first.seconds);
    print_reference(A, P, *o, R, M);
    if (A->backend != HV_BACKEND_PETSC)
        printf(",\"copy1_gbs\":%.2f,\"copy_ref_mb\":%.1f", R->copy1_gbs, R->copy_mb);
    if (A->backend == HV_BACKEND_OPENCL)
        print_device(&P->p, o, P->f, A->repeat, R->traffic, R->seconds);
    if (R->copy_gbs > 0 && R->cycle_gbs > 0)
        printf(",\"cycle_vs_copy\":%.3f,\"solve_vs_copy\":%.3f", R->cycle_gbs / R->copy_gbs,
               R->solve_gbs / R->copy_gbs);
    printf("}\n");
    fflush(stdout);
}

static int bench_solve(int argc, char **argv)
{
    solve_args A = {.dim = 3, .repeat = 3, .tscale = 4, .tol = 1e-6, .backend = HV_BACKEND_MG};
    int rc = parse_solve(argc, argv, &A);
    if (rc >= 0)
        return rc;
    if (A.backend == HV_BACKEND_PETSC) {
        hv_status pst = hv_petsc_option("-hv_petsc_pc", PCS[A.pc]);
        if (pst)
            return cli_fail("bench solve", "--pc", pst);
    }
    hv_set_threads(A.threads);
    A.threads = hv_get_threads();
    solve_problem P = {0};
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.backend = A.backend;
    o.smoother = (hv_smoother)A.smoother;
    o.coarse = (hv_coarse)A.coarse;
    o.tol = A.tol;
    o.fftw_double = 0;
    o.fftw_measure = 1;
    o.wisdom_file = A.wisdom;
    mg_ref M = {0};
    solve_row R = {0};
    if (!(rc = make_problem(&A, &P)) &&
        !(rc = A.backend == HV_BACKEND_PETSC ? time_mg_ref(&A, &P, o, &M) : 0) &&
        !(rc = time_row(&A, &P, &o, &R)) && hv_mpi_rank() == 0)
        print_row(&A, &P, &o, &R, &M); /* every rank solves, rank 0 reports */
    problem_free(&P);
    return rc;
}

static const struct benchmark {
    const char *name;
    int (*run)(int argc, char **argv);
    const char *summary;
} benchmarks[] = {
    {"solve", bench_solve, "one solver's solves on a box, against a memory copy and FFTW"},
    {"sdf", cmd_bench_sdf, "heatvox sdf on a mesh, stage by stage, against OpenVDB"},
    {"band", cmd_bench_band, "a narrow band in tiles against OpenVDB's meshToLevelSet"},
    {"mesh", cmd_bench_mesh, "the zero level set of a mesh's distance as a triangle mesh"},
    {"points", cmd_bench_points, "surfaces of oriented point clouds against CGAL's Poisson"},
    {"sdf2d", cmd_bench_sdf2d, "heatvox sdf2d on generated SVG curves"},
    {"extend", bench_extend, "the extension off a level set against OpenVDB's sdfToExt"},
    {"extend-band", cmd_bench_extend_band, "heatvox extend on a band against OpenVDB's sdfToExt"},
    {"extend-loop", cmd_bench_extend_loop, "one extender over the steps of a moving sphere"},
};

/* heatvox bench --describe-options: the benchmarks, one line each. */
static int describe_benchmarks(void)
{
    printf("command\tbench\n");
    for (size_t i = 0; i < sizeof benchmarks / sizeof benchmarks[0]; i++)
        printf("subcommand\tbench %s\t%s\n", benchmarks[i].name, benchmarks[i].summary);
    return HV_EXIT_OK;
}

static int bench_run(int argc, char **argv)
{
    if (!strcmp(argv[1], CLI_DESCRIBE))
        return describe_benchmarks();
    for (size_t i = 0; i < sizeof benchmarks / sizeof benchmarks[0]; i++)
        if (!strcmp(argv[1], benchmarks[i].name))
            return benchmarks[i].run(argc - 1, argv + 1);
    return cli_usage_error("bench", "unknown benchmark '%s'", argv[1]);
}

int cmd_bench(int argc, char **argv)
{
    if (argc < 2 || !strcmp(argv[1], "--help") || !strcmp(argv[1], "-h")) {
        FILE *out = argc < 2 ? stderr : stdout;
        fprintf(out,
                "usage: heatvox bench "
                "<solve|sdf|band|mesh|points|sdf2d|extend|extend-band|extend-loop> "
                "[options]   (heatvox "
                "bench <name> --help)\n"
                "With HEATVOX_OPENCL_PROFILE=1, one more JSON line per OpenCL kernel and transfer\n"
                "follows: bench \"kernel\", of (the benchmark), name, launches, seconds (device\n"
                "time over every run, warm-ups included) and share of the summed time.\n");
        return argc < 2 ? HV_EXIT_USAGE : HV_EXIT_OK;
    }
    int rc = bench_run(argc, argv);
    bench_device_profile(argv[1], stdout);
    return rc;
}
