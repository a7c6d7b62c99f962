/* Helpers shared by the commands of heatvox (tools/cli.c): each command lives
 * in tools/cmd_<name>.c and uses only the public headers. */
#ifndef HV_TOOLS_CLI_H
#define HV_TOOLS_CLI_H

#include "heatvox/heatvox.h"

#include <limits.h>
#include <math.h>
#include <stdio.h>

/* Exit codes (documented in README.md). */
enum { HV_EXIT_OK = 0, HV_EXIT_FAIL = 1, HV_EXIT_USAGE = 2 };

extern int cli_verbose; /* -1 quiet (-q), 0 default, 1 verbose (-v) */

/* With -v: what the reader made of a mesh file (format, triangles, points and
 * lines left out, the unit the file declares) on stderr. */
void cli_mesh_note(const char *cmd, const char *path, const hv_mesh *m);
/* --units m on a mesh read from path (m may be NULL: a point cloud, which
 * states no unit): its coordinates times the metres per unit the file
 * states (m->unit_meters becomes 1), said under -v; a file that states none
 * keeps its coordinates, said on stderr unless -q. cmd NULL: nothing said
 * (a batch worker). Returns the factor applied (1 when none). */
double cli_mesh_units(const char *cmd, const char *path, hv_mesh *m, int units);
/* Prints "heatvox <cmd>: <what>: <status>: <hv_last_error()>" on stderr and
 * returns HV_EXIT_FAIL. */
int cli_fail(const char *cmd, const char *what, hv_status st);
/* Prints "heatvox <cmd>: <message>" and a hint to --help; returns HV_EXIT_USAGE. */
int cli_usage_error(const char *cmd, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* Whether out names an HDF5 output (ends in ".h5"): *is_h5 = 1, or 0. In a
 * build without PETSc an HDF5 output is a usage error (returns
 * HV_EXIT_USAGE, having said so); else returns 0. */
int cli_h5_output(const char *cmd, const char *out, int *is_h5);
/* A usage error (printed, HV_EXIT_USAGE) unless path (option opt) ends in one
 * of exts (space-separated, such as ".vdb .h5"; any case); 0 for NULL. */
int cli_check_ext(const char *cmd, const char *opt, const char *path, const char *exts);
/* Parses numbers strictly (whole string, finite); 0 on success. */
int cli_parse_int(const char *s, int *out);
/* Checks the outputs of a command before it computes anything: an output that
 * exists and is not a regular file (a device, a FIFO, a directory) is never
 * replaced, and no output may be one of the inputs or another output. NULL
 * entries are skipped. Prints the reason and returns HV_EXIT_FAIL, else 0. */
int cli_check_outputs(const char *cmd, const char *const *outs, int nout, const char *const *ins,
                      int nin);
/* Outputs of one command that land together or not at all: each is written
 * under the temporary name cli_stage gives (registered for the SIGINT/SIGTERM
 * cleanup), and cli_commit renames them all into place once every one is
 * complete; cli_discard removes them. A failed second output then never
 * leaves the first one replaced. */
#define CLI_MAX_OUTPUTS 4
typedef struct cli_outputs {
    int n;
    const char *final[CLI_MAX_OUTPUTS];
    char tmp[CLI_MAX_OUTPUTS][4096];
} cli_outputs;
/* The name to write `final` under, or NULL (the error is printed). */
const char *cli_stage(const char *cmd, cli_outputs *o, const char *final);
/* Renames every staged output into place; HV_EXIT_FAIL (printed) or 0. */
int cli_commit(const char *cmd, cli_outputs *o);
void cli_discard(cli_outputs *o);
/* Parses a --threads value: an integer in [lo, HV_MAX_THREADS]; 0 on success. */
int cli_parse_threads(const char *s, int lo, int *out);
/* --sign's values: "auto", "heat", "winding" (hv_sdf_sign). Returns 0 on success. */
int cli_parse_sign(const char *s, hv_sdf_sign *out);
/* The name of a sign source as the commands print it ("none" for AUTO). */
const char *cli_sign_name(hv_sdf_sign s);
int cli_parse_double(const char *s, double *out);
/* The arguments of the mesh benchmarks (bench sdf, bench mesh): MESH --n N
 * [--backend B] [--repeat R] [--threads T], -q and -v ignored. Returns -1 when
 * the command should go on, else the exit code (after --help, printed by
 * usage, or a usage error naming cmd). */
typedef struct cli_bench_mesh_args {
    const char *path;
    int n, repeat, threads;
    hv_backend backend;
    hv_sdf_sign sign; /* --sign */
} cli_bench_mesh_args;
int cli_bench_mesh_args_parse(const char *cmd, int argc, char **argv, int (*usage)(FILE *),
                              cli_bench_mesh_args *out);
/* With -v: prints the message on stderr (no newline added). Returns 0. */
/* Prints ,"device":"NAME","device_gpu":BOOL into a JSON line being written
 * when b is the opencl backend (the device it runs on); nothing otherwise. */
void cli_json_device(hv_backend b);

/* ---- options as tables ----
 * A command lists its options as cli_opt rows and cli_parse reads argv
 * against them: every value checked as its kind says, the same messages for
 * every command. */
typedef enum cli_kind {
    CLI_FLAG,    /* *(int *)dst = val */
    CLI_OR,      /* *(int *)dst |= val */
    CLI_STR,     /* *(const char **)dst = the value; min 1: not empty */
    CLI_INT,     /* *(int *)dst, an integer in [min, max] */
    CLI_DOUBLE,  /* *(double *)dst, a number in [min, max] (> min with CLI_ABOVE) */
    CLI_DOUBLES, /* *(double *)dst[0..val), finite numbers */
    CLI_BACKEND, /* *(hv_backend *)dst, one of the backends in val (CLI_BACKEND mask) */
    CLI_THREADS, /* *(int *)dst, 1..HV_MAX_THREADS */
    CLI_SIGN,    /* *(hv_sdf_sign *)dst */
    CLI_CHOICE,  /* *(int *)dst = val + the index of the value in choices ("vdb|exr") */
    CLI_LIST,    /* appended to (const char **)dst, at most val, counted in *given;
                    the same value twice is an error */
    CLI_IGNORE,  /* taken by the driver (-q, -v) */
    CLI_FN,      /* fn(cmd, option, values, how many follow, dst): the values it took
                    (>= 0), or minus the exit code; val: how many it takes, where fixed */
    CLI_WORDS    /* no option: describes the words that are no option (names: how the
                    synopsis calls them, "MESH"; files), for cli_describe alone */
} cli_kind;

#define CLI_ABOVE 1 /* cli_opt.flags: a number must exceed min */

typedef struct cli_opt {
    const char *names; /* "--res", or aliases split by '|': "-o|--output" */
    cli_kind kind;
    void *dst;
    int val;           /* CLI_FLAG, CLI_OR: the value; CLI_DOUBLES: how many; CLI_BACKEND: mask */
    double min, max;   /* CLI_INT, CLI_DOUBLE, CLI_STR (min 1: not empty) */
    const char *needs; /* the message's "--x needs <needs>, got '...'" */
    int *given;        /* set to 1 when the option is given (may be NULL); CLI_LIST: the count */
    int flags;
    int (*fn)(const char *cmd, const char *opt, char **v, int nv, void *dst);
    const char *choices; /* CLI_CHOICE: the values, split by '|'; other kinds: the
                            words the value may be, for the man page and completion */
    const char *files;   /* the value names a file: the extensions it takes as
                            cli_check_ext does (".vdb .h5"), CLI_FILES_ANY or
                            CLI_FILES_DIR (either may lead an extension list) */
} cli_opt;

#define CLI_FILES_ANY "*"
#define CLI_FILES_DIR "/"
/* What the mesh readers take (hv_mesh_read, and the point clouds of
 * cli_read_shape). */
#define CLI_FILES_TRIMESH ".obj .ply .stl .off .gltf .glb .fbx .3mf .dae .x"
#define CLI_FILES_MESH CLI_FILES_TRIMESH " .xyz .pts .xyzn"

/* The rows several commands share, declared once so that an option reads
 * and fails the same wherever it is taken. to is where its value goes. */
#define CLI_ROW_QUIET                                                                              \
    {                                                                                              \
        .names = "-q|-v", .kind = CLI_IGNORE                                                       \
    }
/* exts: the extensions the output takes (cli_opt.files). */
#define CLI_ROW_OUTPUT(to, exts)                                                                   \
    {                                                                                              \
        .names = "-o|--output", .kind = CLI_STR, .dst = (to), .files = (exts)                      \
    }
#define CLI_ROW_THREADS(to)                                                                        \
    {                                                                                              \
        .names = "--threads", .kind = CLI_THREADS, .dst = (to)                                     \
    }
#define CLI_ROW_BACKEND(to, allowed)                                                               \
    {                                                                                              \
        .names = "--backend", .kind = CLI_BACKEND, .dst = (to), .val = (allowed)                   \
    }
/* --res with at least lo cells (given: set when the option is given, or NULL). */
#define CLI_ROW_RES(to, lo, given_)                                                                \
    {                                                                                              \
        .names = "--res", .kind = CLI_INT, .dst = (to), .min = (lo), .max = INT_MAX,               \
        .needs = (lo) == 1 ? "a positive integer" : "an integer >= " #lo, .given = (given_)        \
    }
#define CLI_ROW_VOXEL_SIZE(to, given_)                                                             \
    {                                                                                              \
        .names = "--voxel-size", .kind = CLI_DOUBLE, .dst = (to), .max = INFINITY,                 \
        .flags = CLI_ABOVE, .needs = "a positive number", .given = (given_)                        \
    }
#define CLI_ROW_PAD(to)                                                                            \
    {                                                                                              \
        .names = "--pad", .kind = CLI_INT, .dst = (to), .max = INT_MAX, .needs = "an integer >= 0" \
    }
#define CLI_ROW_T_SCALE(to)                                                                        \
    {                                                                                              \
        .names = "--t-scale", .kind = CLI_DOUBLE, .dst = (to), .max = INFINITY,                    \
        .flags = CLI_ABOVE, .needs = "a positive number"                                           \
    }
/* A band's half width in voxels (name: "--band", "--out-band"). */
#define CLI_ROW_BAND(name, to)                                                                     \
    {                                                                                              \
        .names = (name), .kind = CLI_DOUBLE, .dst = (to), .max = INFINITY, .flags = CLI_ABOVE,     \
        .needs = "a positive number of voxels"                                                     \
    }
#define CLI_ROW_DENSE(to)                                                                          \
    {                                                                                              \
        .names = "--dense", .kind = CLI_FLAG, .dst = (to), .val = 1                                \
    }
#define CLI_ROW_NO_REPAIR(to)                                                                      \
    {                                                                                              \
        .names = "--no-repair", .kind = CLI_FLAG, .dst = (to), .val = 0                            \
    }
#define CLI_ROW_SIGN(to)                                                                           \
    {                                                                                              \
        .names = "--sign", .kind = CLI_SIGN, .dst = (to)                                           \
    }
/* --units: file (CLI_UNITS_FILE, the default) keeps a mesh's coordinates as
 * the file has them; m (CLI_UNITS_M) scales them to metres where the file
 * states its unit (cli_mesh_units). */
enum { CLI_UNITS_FILE = 0, CLI_UNITS_M };
#define CLI_ROW_UNITS(to)                                                                          \
    {                                                                                              \
        .names = "--units", .kind = CLI_CHOICE, .dst = (to), .choices = "file|m",                  \
        .needs = "file or m"                                                                       \
    }
#define CLI_ROW_REPEAT(to)                                                                         \
    {                                                                                              \
        .names = "--repeat", .kind = CLI_INT, .dst = (to), .min = 1, .max = INT_MAX,               \
        .needs = "an integer >= 1"                                                                 \
    }

/* Reads argv[1..argc) against the options (a row with names NULL ends
 * them); words that are no option go to *positional (one at most: a second
 * is a usage error naming both as `noun`s). --help and -h call help and
 * return 0. Returns -1 when every word was taken, else the exit code. */
int cli_parse(const char *cmd, int argc, char **argv, const cli_opt *opts, const char *noun,
              const char **positional, void (*help)(void));
/* The same with up to max words that are no option, in words[0..*nwords). */
int cli_parse_words(const char *cmd, int argc, char **argv, const cli_opt *opts, const char *noun,
                    const char **words, int max, int *nwords, void (*help)(void));
/* `heatvox CMD --describe-options` (the first word after the command): the
 * parsers print the command's rows instead of reading them (cli_describe),
 * which tools/man_completion.py turns into man pages and bash completion. */
#define CLI_DESCRIBE "--describe-options"
/* Prints the rows of opts on stdout as lines of tab-separated fields, for a
 * program to read:
 *   command  CMD
 *   words    NOUN  MAX  FILES                       (the words that are no option)
 *   option   NAMES  KIND  ARITY  CHOICES  FILES  NEEDS
 * NAMES and CHOICES split by '|', FILES by ' ', empty fields as "-". Returns 0. */
int cli_describe(const char *cmd, const cli_opt *opts, const char *noun, int max);
/* The words an option's value may be, split by '|' (CLI_CHOICE, CLI_SIGN,
 * CLI_BACKEND, or the row's choices); NULL for any. */
const char *cli_opt_choices(const cli_opt *o);
/* Options only, argv[0..argc) (a manifest line's): nothing printed; 0, or
 * -1 with the message in err. */
int cli_parse_quiet(int argc, char **argv, const cli_opt *opts, char *err, size_t size);
/* The row of opts that takes the option name, or NULL. */
const cli_opt *cli_find_opt(const cli_opt *opts, const char *name);
/* How many values the row's option takes. */
int cli_opt_arity(const cli_opt *o);

/* The backends a command takes, for cli_parse_backend: a mask of
 * CLI_BACKEND(HV_BACKEND_...). */
#define CLI_BACKEND(b) (1u << (b))
#define CLI_BACKENDS_LOCAL                                                                         \
    (CLI_BACKEND(HV_BACKEND_AUTO) | CLI_BACKEND(HV_BACKEND_MG) | CLI_BACKEND(HV_BACKEND_FFTW) |    \
     CLI_BACKEND(HV_BACKEND_OPENCL))
#define CLI_BACKENDS_ALL (CLI_BACKENDS_LOCAL | CLI_BACKEND(HV_BACKEND_PETSC))
/* --backend V, one of the backends in `allowed`: 0 with *out set, else -1
 * with msg saying which backends the option takes (for a manifest's errors). */
int cli_backend_value(const char *v, unsigned allowed, hv_backend *out, char *msg, size_t size);
/* The same for a command's option: 0, or the usage error's exit code. */
int cli_parse_backend(const char *cmd, const char *v, unsigned allowed, hv_backend *out);
int cli_info(const char *fmt, ...) __attribute__((format(printf, 1, 2)));

/* The shape an sdf reads from path (tools/shape.c): a mesh, or the closed
 * surface of an oriented point cloud (hv_points_surface with o), whose
 * report goes to *pr (pr->points is 0 for a mesh). Errors as the library's. */
hv_status cli_read_shape(const char *path, const hv_sdf_opts *o, hv_mesh **m, hv_points_report *pr);
/* With -v, a line on stderr about a cloud read by cli_read_shape. */
void cli_points_note(const char *cmd, const char *path, const hv_points_report *pr);
/* 1 when a cloud's mesh beside its volume is the cloud's own surface (pr:
 * its report, points > 0 for a cloud): the volume's zero set as it is,
 * unless adaptivity, an offset, a shell, closing or opening asks for the
 * zero set of the grid again. */
int cli_own_surface(const hv_points_report *pr, const hv_sdf_opts *o, double adaptivity);

#endif
