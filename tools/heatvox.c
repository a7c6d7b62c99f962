/* heatvox: the command-line driver, a thin layer over libheatvox. */
#include "cli.h"

#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <math.h>
#include <unistd.h>

int cli_verbose = 0;

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
    {"make-scenes", cmd_make_scenes, "write the generated demo inputs (broken meshes, a level set)"},
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

int cli_fail(const char *cmd, const char *what, hv_status st)
{
    const char *detail = hv_last_error();
    fprintf(stderr, "heatvox %s: %s: %s%s%s\n", cmd, what, hv_status_str(st), *detail ? ": " : "",
            detail);
    return HV_EXIT_FAIL;
}

int cli_usage_error(const char *cmd, const char *fmt, ...)
{
    va_list ap;
    fprintf(stderr, "heatvox %s: ", cmd);
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fprintf(stderr, "\n(see heatvox %s --help)\n", cmd);
    return HV_EXIT_USAGE;
}

int cli_info(const char *fmt, ...)
{
    if (cli_verbose < 1)
        return 0;
    va_list ap;
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    return 0;
}

int cli_parse_int(const char *s, int *out)
{
    char *end;
    long v = strtol(s, &end, 10);
    if (!*s || *end || v < -2147483647L || v > 2147483647L)
        return -1;
    *out = (int)v;
    return 0;
}

static const char *file_kind(mode_t m)
{
    return S_ISDIR(m)    ? "a directory"
           : S_ISCHR(m)  ? "a character device"
           : S_ISBLK(m)  ? "a block device"
           : S_ISFIFO(m) ? "a FIFO"
           : S_ISSOCK(m) ? "a socket"
                         : "not a regular file";
}

int cli_check_outputs(const char *cmd, const char *const *outs, int nout, const char *const *ins,
                      int nin)
{
    for (int i = 0; i < nout; i++) {
        if (!outs[i])
            continue;
        struct stat so;
        if (stat(outs[i], &so) != 0)
            continue; /* a new file; the writer reports a missing directory */
        if (!S_ISREG(so.st_mode)) {
            fprintf(stderr, "heatvox %s: %s: output exists and is %s; it is not replaced\n", cmd,
                    outs[i], file_kind(so.st_mode));
            return HV_EXIT_FAIL;
        }
        for (int j = 0; j < nin; j++) {
            struct stat si;
            if (ins[j] && stat(ins[j], &si) == 0 && si.st_dev == so.st_dev &&
                si.st_ino == so.st_ino) {
                fprintf(stderr, "heatvox %s: %s: output is the input %s; choose another name\n",
                        cmd, outs[i], ins[j]);
                return HV_EXIT_FAIL;
            }
        }
        for (int j = 0; j < i; j++) {
            struct stat sj;
            if (outs[j] && stat(outs[j], &sj) == 0 && sj.st_dev == so.st_dev &&
                sj.st_ino == so.st_ino) {
                fprintf(stderr, "heatvox %s: %s and %s are the same file\n", cmd, outs[j],
                        outs[i]);
                return HV_EXIT_FAIL;
            }
        }
    }
    for (int i = 0; i < nout; i++)
        for (int j = 0; j < i; j++)
            if (outs[i] && outs[j] && !strcmp(outs[i], outs[j])) {
                fprintf(stderr, "heatvox %s: %s is named as two outputs\n", cmd, outs[i]);
                return HV_EXIT_FAIL;
            }
    return 0;
}

const char *cli_stage(const char *cmd, cli_outputs *o, const char *final)
{
    if (o->n >= CLI_MAX_OUTPUTS) {
        fprintf(stderr, "heatvox %s: too many outputs\n", cmd);
        return NULL;
    }
    hv_status st = hv_tmp_name(final, o->tmp[o->n], sizeof o->tmp[0]);
    if (st) {
        cli_fail(cmd, final, st);
        return NULL;
    }
    o->final[o->n] = final;
    return o->tmp[o->n++];
}

int cli_commit(const char *cmd, cli_outputs *o)
{
    for (int i = 0; i < o->n; i++) {
        hv_status st = hv_tmp_commit(o->tmp[i], o->final[i]);
        if (st) {
            for (int j = i + 1; j < o->n; j++)
                hv_tmp_discard(o->tmp[j]);
            o->n = 0;
            return cli_fail(cmd, "output", st);
        }
    }
    o->n = 0;
    return 0;
}

void cli_discard(cli_outputs *o)
{
    for (int i = 0; i < o->n; i++)
        hv_tmp_discard(o->tmp[i]);
    o->n = 0;
}

int cli_parse_threads(const char *s, int lo, int *out)
{
    return cli_parse_int(s, out) || *out < lo || *out > HV_MAX_THREADS;
}

int cli_parse_double(const char *s, double *out)
{
    char *end;
    double v = strtod(s, &end);
    if (!*s || *end || !isfinite(v))
        return -1;
    *out = v;
    return 0;
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
        if (!strcmp(argv[1], commands[i].name))
            return commands[i].run(argc - 1, argv + 1);
    fprintf(stderr, "heatvox: unknown command '%s'\n", argv[1]);
    usage(stderr);
    return HV_EXIT_USAGE;
}
