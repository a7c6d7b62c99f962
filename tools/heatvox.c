/* heatvox: the command-line driver, a thin layer over libheatvox. */
#include "bench/bench_device.h"
#include "cli.h"
#include "commands.h"

#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <math.h>
#include <unistd.h>

struct command {
    const char *name;
    int (*run)(int argc, char **argv);
    const char *summary;
};

static const struct command commands[] = {
    {"sdf", cmd_sdf, "signed (or unsigned) distance volume from a triangle mesh"},
    {"batch", cmd_batch, "signed distance volumes for many meshes, in parallel, resumable"},
    {"sdf2d", cmd_sdf2d, "2D signed distance from (broken) curves, SVG or text, to EXR/PNG"},
    {"slice", cmd_slice, "one slice of a volume as EXR data or a PNG preview"},
    {"make-scenes", cmd_make_scenes,
     "write the generated inputs (broken meshes, a level set, distance scenes)"},
    {"info", cmd_info, "read a mesh and print its defect report"},
    {"distance", cmd_distance, "geodesic distance around obstacles (heat method)"},
    {"extend", cmd_extend, "extend fields off a level set (VDB in, VDB out)"},
    {"bench", cmd_bench, "benchmarks; prints one JSON object per line"},
    {"devices", cmd_devices, "list OpenCL devices for --backend opencl"},
};

static void usage(FILE *out)
{
    fprintf(out, "usage: heatvox <command> [options]   (heatvox <command> --help)\n\ncommands:\n");
    for (size_t i = 0; i < sizeof commands / sizeof commands[0]; i++)
        fprintf(out, "  %-12s %s\n", commands[i].name, commands[i].summary);
    fprintf(out, "\nexit codes: 0 success, 1 failure (bad input, I/O, solver), 2 usage error\n");
}

/* heatvox --describe-options: the commands, for tools/man_completion.py. */
static int describe_commands(void)
{
    for (size_t i = 0; i < sizeof commands / sizeof commands[0]; i++)
        printf("subcommand\t%s\t%s\n", commands[i].name, commands[i].summary);
    return HV_EXIT_OK;
}

static void log_to_stderr(hv_log_level level, const char *msg, void *user)
{
    (void)user;
    if (level == HV_LOG_ERROR || (level == HV_LOG_WARN && cli_verbose >= 0) ||
        (level == HV_LOG_INFO && cli_verbose >= 1) || cli_verbose >= 2)
        fprintf(stderr, "heatvox: %s%s\n", level == HV_LOG_WARN ? "warning: " : "", msg);
}

static void on_signal(int sig)
{
    hv_tmp_cleanup_all();
    signal(sig, SIG_DFL);
    raise(sig);
}

/* libgomp spins 300,000 times at every barrier before it sleeps; on a shared or
 * oversubscribed machine a spinning thread holds the core its partner needs, and a
 * multigrid solve with a few hundred barriers per cycle took 56 s instead of
 * 0.3 s (48^3 heat distance, load 3 on 2 cores). libgomp reads its settings when
 * it loads, so the command sets a short spin and runs itself again, once, unless
 * the user chose a policy. */
static void tame_openmp_spinning(char **argv)
{
    if (getenv("OMP_WAIT_POLICY") || getenv("GOMP_SPINCOUNT"))
        return;
    if (setenv("GOMP_SPINCOUNT", "1000", 1) != 0)
        return;
    execv("/proc/self/exe", argv);
    /* exec failed: carry on with the default policy */
}

/* --backend petsc: MPI is started before the command runs, so that ranks
 * other than 0 know to stay quiet (the JSON summaries and reports come from
 * rank 0; every rank still reports its own errors). */
static int mpi_start(int argc, char **argv)
{
    int petsc = 0;
    for (int i = 2; i + 1 < argc; i++)
        if (!strcmp(argv[i], "--backend") && !strcmp(argv[i + 1], "petsc"))
            petsc = 1;
    if (!petsc || !hv_petsc_available())
        return 0; /* the backend's own error says what is missing */
    hv_status st = hv_petsc_init();
    if (st) {
        fprintf(stderr, "heatvox: %s\n", hv_last_error());
        return 1;
    }
    if (hv_mpi_rank() > 0) {
        cli_verbose = -1;
        if (!freopen("/dev/null", "w", stdout))
            return 1;
    }
    return 0;
}

int main(int argc, char **argv)
{
    tame_openmp_spinning(argv);
    if (argc < 2) {
        usage(stderr);
        return HV_EXIT_USAGE;
    }
    if (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h") || !strcmp(argv[1], "help")) {
        usage(stdout);
        return HV_EXIT_OK;
    }
    if (!strcmp(argv[1], CLI_DESCRIBE))
        return describe_commands();
    if (!strcmp(argv[1], "--version")) {
        printf("heatvox %s\n", hv_version());
        return HV_EXIT_OK;
    }
    for (int i = 2; i < argc; i++) {
        if (!strcmp(argv[i], "-q"))
            cli_verbose = -1;
        else if (!strcmp(argv[i], "-v"))
            cli_verbose = cli_verbose > 0 ? cli_verbose + 1 : 1;
    }
    hv_set_log(log_to_stderr, NULL);
    signal(SIGINT, on_signal);
    signal(SIGTERM, on_signal);
    for (size_t i = 0; i < sizeof commands / sizeof commands[0]; i++)
        if (!strcmp(argv[1], commands[i].name)) {
            if (mpi_start(argc, argv))
                return HV_EXIT_FAIL;
            const int rc = commands[i].run(argc - 1, argv + 1);
            if (strcmp(argv[1], "bench") != 0)
                bench_device_profile(argv[1], stderr); /* HEATVOX_OPENCL_PROFILE=1 */
            hv_petsc_finalize(); /* ends MPI where a petsc solver started it */
            return rc;
        }
    fprintf(stderr, "heatvox: unknown command '%s'\n", argv[1]);
    usage(stderr);
    return HV_EXIT_USAGE;
}
