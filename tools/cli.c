/* Helpers shared by the commands of tools/cmd_*.c (declared in cli.h):
 * messages and exit codes, strict number parsing, and outputs that are
 * checked before anything runs and land together. */
#include "cli.h"

#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

int cli_verbose = 0;

void cli_mesh_note(const char *cmd, const char *path, const hv_mesh *m)
{
    if (cli_verbose < 1 || !m)
        return;
    fprintf(stderr, "heatvox %s: %s: %s, %zu triangles on %zu vertices", cmd, path,
            m->format ? m->format : "mesh", m->ntris, m->nverts);
    if (m->skipped_primitives)
        fprintf(stderr, ", %zu points and lines left out", m->skipped_primitives);
    if (m->unit_meters > 0)
        fprintf(stderr, "; length unit %g m, from the file", m->unit_meters);
    else
        fprintf(stderr, "; no length unit in the file");
    fputc('\n', stderr);
}

double cli_mesh_units(const char *cmd, const char *path, hv_mesh *m, int units)
{
    if (units != CLI_UNITS_M)
        return 1;
    if (!m || !(m->unit_meters > 0)) {
        if (cmd && cli_verbose >= 0)
            fprintf(stderr,
                    "heatvox %s: %s states no length unit: --units m keeps its coordinates\n", cmd,
                    path);
        return 1;
    }
    const double f = m->unit_meters;
    for (size_t i = 0; i < 3 * m->nverts && f != 1; i++)
        m->verts[i] *= f;
    m->unit_meters = 1;
    if (cmd)
        cli_info("heatvox %s: %s: coordinates times %g, in metres (--units m)\n", cmd, path, f);
    return f;
}

int cli_fail(const char *cmd, const char *what, hv_status st)
{
    const char *detail = hv_last_error();
    /* A message that names the file already says it all. */
    size_t n = what ? strlen(what) : 0;
    if (n && !strncmp(detail, what, n) && detail[n] == ':') {
        fprintf(stderr, "heatvox %s: %s\n", cmd, detail);
        return HV_EXIT_FAIL;
    }
    fprintf(stderr, "heatvox %s: %s: %s%s%s\n", cmd, what, hv_status_str(st), *detail ? ": " : "",
            detail);
    return HV_EXIT_FAIL;
}

/* Where cli_parse_quiet keeps the message of a usage error instead of
 * printing it. */
static char *capture;
static size_t capture_size;

int cli_usage_error(const char *cmd, const char *fmt, ...)
{
    va_list ap;
    if (capture) {
        va_start(ap, fmt);
        vsnprintf(capture, capture_size, fmt, ap);
        va_end(ap);
        return HV_EXIT_USAGE;
    }
    fprintf(stderr, "heatvox %s: ", cmd);
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fprintf(stderr, "\n(see heatvox %s --help)\n", cmd);
    return HV_EXIT_USAGE;
}

int cli_h5_output(const char *cmd, const char *out, int *is_h5)
{
    const size_t n = out ? strlen(out) : 0;
    *is_h5 = n > 3 && !strcmp(out + n - 3, ".h5");
    if (*is_h5 && !hv_petsc_available())
        return cli_usage_error(
            cmd, "-o %s: HDF5 output needs heatvox built with MPI and PETSc (make mpi)", out);
    return 0;
}

int cli_check_ext(const char *cmd, const char *opt, const char *path, const char *exts)
{
    if (!path)
        return 0;
    const char *slash = strrchr(path, '/'), *dot = strrchr(path, '.');
    if (dot && (!slash || dot > slash)) {
        size_t n = strlen(dot);
        for (const char *e = exts; *e;) {
            size_t k = strcspn(e, " ");
            if (k == n && !strncasecmp(e, dot, n))
                return 0;
            e += k + (e[k] == ' ');
        }
    }
    char list[64];
    snprintf(list, sizeof list, "%s", exts);
    for (char *c = list; *c; c++)
        if (*c == ' ')
            *c = '/';
    return cli_usage_error(cmd, "%s %s: the file name must end in %s (the format is chosen by it)",
                           opt, path, list);
}

void cli_json_device(hv_backend b)
{
    hv_opencl_device d;
    if (b != HV_BACKEND_OPENCL || hv_opencl_probe(&d) != HV_OK)
        return;
    printf(",\"device\":\"");
    for (const char *s = d.name; *s; s++)
        if (*s == '"' || *s == '\\')
            printf("\\%c", *s);
        else if ((unsigned char)*s >= 0x20)
            putchar(*s);
    printf("\",\"device_gpu\":%s", d.gpu ? "true" : "false");
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
                fprintf(stderr, "heatvox %s: %s and %s are the same file\n", cmd, outs[j], outs[i]);
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

int cli_parse_sign(const char *s, hv_sdf_sign *out)
{
    static const char *names[] = {"auto", "heat", "winding"};
    for (int k = 0; k < 3; k++)
        if (!strcmp(s, names[k])) {
            *out = (hv_sdf_sign)k;
            return 0;
        }
    return -1;
}

const char *cli_sign_name(hv_sdf_sign s)
{
    return s == HV_SDF_SIGN_WINDING ? "winding" : s == HV_SDF_SIGN_HEAT ? "heat" : "none";
}

/* The mesh benchmark's usage, for cli_parse's help. */
static int (*bench_mesh_usage)(FILE *);
static void bench_mesh_help(void) { bench_mesh_usage(stdout); }

int cli_bench_mesh_args_parse(const char *cmd, int argc, char **argv, int (*usage)(FILE *),
                              cli_bench_mesh_args *out)
{
    cli_bench_mesh_args A = {NULL, 0, 1, 0, HV_BACKEND_AUTO, HV_SDF_SIGN_AUTO};
    const cli_opt opts[] = {
        CLI_ROW_QUIET,
        {.names = "MESH", .kind = CLI_WORDS, .files = CLI_FILES_MESH},
        {.names = "--n",
         .kind = CLI_INT,
         .dst = &A.n,
         .min = 8,
         .max = INT_MAX,
         .needs = "an integer >= 8"},
        CLI_ROW_REPEAT(&A.repeat),
        CLI_ROW_THREADS(&A.threads),
        CLI_ROW_BACKEND(&A.backend, CLI_BACKENDS_LOCAL),
        CLI_ROW_SIGN(&A.sign),
        {.names = NULL},
    };
    bench_mesh_usage = usage;
    int rc = cli_parse(cmd, argc, argv, opts, "mesh", &A.path, bench_mesh_help);
    if (rc >= 0)
        return rc;
    if (!A.path || !A.n)
        return cli_usage_error(cmd, "a mesh and --n are required");
    *out = A;
    return -1;
}

int cli_backend_value(const char *v, unsigned allowed, hv_backend *out, char *msg, size_t size)
{
    static const hv_backend order[] = {HV_BACKEND_AUTO, HV_BACKEND_MG, HV_BACKEND_FFTW,
                                       HV_BACKEND_OPENCL, HV_BACKEND_PETSC};
    hv_backend b;
    if (v && hv_backend_parse(v, &b) == HV_OK && (allowed & CLI_BACKEND(b))) {
        *out = b;
        return 0;
    }
    int n = 0, k = 0;
    for (size_t i = 0; i < sizeof order / sizeof order[0]; i++)
        n += (allowed & CLI_BACKEND(order[i])) != 0;
    size_t len = (size_t)snprintf(msg, size, "--backend must be ");
    for (size_t i = 0; i < sizeof order / sizeof order[0] && len < size; i++)
        if (allowed & CLI_BACKEND(order[i])) {
            k++;
            len += (size_t)snprintf(msg + len, size - len, "%s%s",
                                    k == 1   ? ""
                                    : k == n ? " or "
                                             : ", ",
                                    hv_backend_name(order[i]));
        }
    if (len < size)
        snprintf(msg + len, size - len, ", got '%s'", v ? v : "");
    return -1;
}

int cli_parse_backend(const char *cmd, const char *v, unsigned allowed, hv_backend *out)
{
    char msg[160];
    if (cli_backend_value(v, allowed, out, msg, sizeof msg) == 0)
        return 0;
    return cli_usage_error(cmd, "%s", msg);
}

const cli_opt *cli_find_opt(const cli_opt *opts, const char *a)
{
    const size_t n = strlen(a);
    for (const cli_opt *o = opts; o->names; o++)
        for (const char *p = o->kind == CLI_WORDS ? "" : o->names; *p;) {
            const char *e = strchr(p, '|');
            size_t len = e ? (size_t)(e - p) : strlen(p);
            if (len == n && !strncmp(p, a, n))
                return o;
            p += len + (e != NULL);
        }
    return NULL;
}

/* One option's values v[0..): 0, or the usage error's exit code. */
static int take_value(const char *cmd, const char *a, const cli_opt *o, char **v)
{
    switch (o->kind) {
    case CLI_STR:
        if (o->min >= 1 && !*v[0])
            return cli_usage_error(cmd, "%s must not be empty", a);
        *(const char **)o->dst = v[0];
        return 0;
    case CLI_INT: {
        int x;
        if (cli_parse_int(v[0], &x) || x < o->min || x > o->max)
            return cli_usage_error(cmd, "%s needs %s, got '%s'", a, o->needs, v[0]);
        *(int *)o->dst = x;
        return 0;
    }
    case CLI_DOUBLE: {
        double x;
        if (cli_parse_double(v[0], &x) || !(x >= o->min) || !(x <= o->max) ||
            ((o->flags & CLI_ABOVE) && !(x > o->min)))
            return cli_usage_error(cmd, "%s needs %s, got '%s'", a, o->needs, v[0]);
        *(double *)o->dst = x;
        return 0;
    }
    case CLI_DOUBLES:
        for (int k = 0; k < o->val; k++)
            if (cli_parse_double(v[k], (double *)o->dst + k))
                return cli_usage_error(cmd, "%s needs %s, got '%s'", a, o->needs, v[k]);
        return 0;
    case CLI_BACKEND:
        return cli_parse_backend(cmd, v[0], (unsigned)o->val, (hv_backend *)o->dst) ? HV_EXIT_USAGE
                                                                                    : 0;
    case CLI_THREADS:
        if (cli_parse_threads(v[0], 1, (int *)o->dst))
            return cli_usage_error(cmd, "%s must be 1..%d, got '%s'", a, HV_MAX_THREADS, v[0]);
        return 0;
    case CLI_SIGN:
        if (cli_parse_sign(v[0], (hv_sdf_sign *)o->dst))
            return cli_usage_error(cmd, "%s needs auto, heat or winding, got '%s'", a, v[0]);
        return 0;
    case CLI_CHOICE: {
        int k = 0;
        for (const char *p = o->choices; *p; k++) {
            const size_t len = strcspn(p, "|");
            if (strlen(v[0]) == len && !strncmp(p, v[0], len)) {
                *(int *)o->dst = o->val + k;
                return 0;
            }
            p += len + (p[len] == '|');
        }
        return cli_usage_error(cmd, "%s needs %s, got '%s'", a, o->needs, v[0]);
    }
    case CLI_LIST: {
        const char **list = (const char **)o->dst;
        for (int q = 0; q < *o->given; q++)
            if (!strcmp(list[q], v[0]))
                return cli_usage_error(cmd, "%s '%s' given twice", a, v[0]);
        if (*o->given == o->val)
            return cli_usage_error(cmd, "at most %d %s options", o->val, a);
        list[(*o->given)++] = v[0];
        return 0;
    }
    default: return 0;
    }
}

/* argv[first..argc) against opts. */
static int parse_from(const char *cmd, int first, int argc, char **argv, const cli_opt *opts,
                      const char *noun, const char **words, int max, int *nwords,
                      void (*help)(void))
{
    *nwords = 0;
    if (first == 1 && argc > 1 && !strcmp(argv[1], CLI_DESCRIBE))
        return cli_describe(cmd, opts, noun, max);
    for (int i = first; i < argc; i++) {
        const char *a = argv[i];
        if (help && (!strcmp(a, "--help") || !strcmp(a, "-h"))) {
            help();
            return HV_EXIT_OK;
        }
        const cli_opt *o = cli_find_opt(opts, a);
        if (!o && ((a[0] == '-' && a[1]) || !max))
            return cli_usage_error(cmd, "unknown option '%s'", a);
        if (!o) {
            if (*nwords == max)
                return cli_usage_error(cmd, "more than one %s given ('%s' and '%s')", noun,
                                       words[0], a);
            words[(*nwords)++] = a;
            continue;
        }
        if (o->given && o->kind != CLI_LIST)
            *o->given = 1;
        if (o->kind == CLI_FLAG || o->kind == CLI_OR || o->kind == CLI_IGNORE) {
            if (o->kind == CLI_FLAG)
                *(int *)o->dst = o->val;
            else if (o->kind == CLI_OR)
                *(int *)o->dst |= o->val;
            continue;
        }
        if (o->kind == CLI_FN) {
            int took = o->fn(cmd, a, argv + i + 1, argc - i - 1, o->dst);
            if (took < 0)
                return -took;
            i += took;
            continue;
        }
        const int k = o->kind == CLI_DOUBLES ? o->val : 1;
        if (i + k >= argc)
            return cli_usage_error(cmd, "%s needs %d value%s", a, k, k > 1 ? "s" : "");
        int rc = take_value(cmd, a, o, argv + i + 1);
        if (rc)
            return rc;
        i += k;
    }
    return -1;
}

int cli_parse(const char *cmd, int argc, char **argv, const cli_opt *opts, const char *noun,
              const char **positional, void (*help)(void))
{
    const char *words[1] = {*positional};
    int n = 0;
    int rc = parse_from(cmd, 1, argc, argv, opts, noun, words, 1, &n, help);
    if (n)
        *positional = words[0];
    return rc;
}

int cli_parse_words(const char *cmd, int argc, char **argv, const cli_opt *opts, const char *noun,
                    const char **words, int max, int *nwords, void (*help)(void))
{
    return parse_from(cmd, 1, argc, argv, opts, noun, words, max, nwords, help);
}

int cli_parse_quiet(int argc, char **argv, const cli_opt *opts, char *err, size_t size)
{
    int n;
    capture = err;
    capture_size = size;
    const int rc = parse_from("", 0, argc, argv, opts, NULL, NULL, 0, &n, NULL);
    capture = NULL;
    return rc < 0 ? 0 : -1;
}

int cli_opt_arity(const cli_opt *o)
{
    switch (o->kind) {
    case CLI_FLAG:
    case CLI_OR:
    case CLI_IGNORE: return 0;
    case CLI_DOUBLES:
    case CLI_FN: return o->val;
    default: return 1;
    }
}
