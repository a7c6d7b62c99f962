/* heatvox batch: pieces shared by the files of the batch command: the driver
 * (cmd_batch.c: options and top-level flow), the inputs (batch_inputs.c), the
 * plan (batch_plan.c), the worker pool (batch_pool.c), progress and report
 * (batch_report.c), and the job that each worker process runs (batch_job.c). */
#ifndef HV_TOOLS_BATCH_H
#define HV_TOOLS_BATCH_H

#include "cli.h"

#include <stddef.h>
#include <stdio.h>

enum { BATCH_VDB = 0, BATCH_EXR = 1 };
/* Formats of the zero level set mesh beside the volume (--mesh-out-format). */
enum { BATCH_MESH_NONE = 0, BATCH_MESH_OBJ, BATCH_MESH_PLY, BATCH_MESH_STL };

/* The options of one job: the signed-distance options plus output choices. */
typedef struct batch_opts {
    hv_sdf_opts sdf;
    int format;        /* BATCH_VDB or BATCH_EXR */
    int preview;       /* also write <output>.png: the three middle slices */
    double band;       /* VDB narrow band half width in voxels */
    int dense;         /* VDB: every voxel active */
    int mesh_format;   /* BATCH_MESH_*: also write the zero level set as a mesh */
    double adaptivity; /* of that mesh (hv_grid_to_mesh), 0..1 */
    int units;         /* --units: CLI_UNITS_FILE or CLI_UNITS_M */
} batch_opts;

void batch_opts_default(batch_opts *o);

/* Number of arguments option `name` takes, or -1 when it is not a job option. */
int batch_opt_arity(const char *name);
/* The job options as BATCH_JOB_OPTS rows t[0..) of kind CLI_FN, each with fn
 * and dst and its arity in val (the batch command passes them on to its
 * workers); returns BATCH_JOB_OPTS. */
#define BATCH_JOB_OPTS 23
int batch_opts_forward(cli_opt *t, int (*fn)(const char *, const char *, char **, int, void *),
                       void *dst);
#define BATCH_STR_(x) #x
#define BATCH_STR(x) BATCH_STR_(x)

/* Applies argv[0..argc) (job options only) to o; on error writes a message to
 * err and returns -1. */
int batch_opts_parse(int argc, char **argv, batch_opts *o, char *err, size_t errsize);
/* Checks the combination of options once all are parsed (a mesh needs a signed
 * distance); on error writes a message to err and returns -1. */
int batch_opts_check(const batch_opts *o, char *err, size_t errsize);

/* The options that change the output, as text ("res=128 pad=4 ..."), and its
 * 64-bit FNV-1a hash as 16 hex digits. threads is left out. */
void batch_opts_canonical(const batch_opts *o, char *buf, size_t size);
void batch_hash(const char *text, char hex[17]);

/* Output file extension for the format (".vdb" or ".exr"). */
const char *batch_ext(int format);

/* Sidecar next to an output: "<output>.heatvox.json". */
void batch_sidecar_path(const char *output, char *buf, size_t size);
/* Preview next to an output: "<output without extension>.png". */
void batch_preview_path(const char *output, char *buf, size_t size);
/* Mesh next to an output: "<output without extension>.obj" (.ply, .stl). */
void batch_mesh_path(const char *output, int mesh_format, char *buf, size_t size);

/* True when output exists, is not older than input, and its sidecar records the
 * same input path and options hash (and the preview and mesh exist, not older
 * than the input, when asked for). */
int batch_up_to_date(const char *input, const char *output, const batch_opts *o, const char *hash);

/* mkdir -p; 0 or -1 with errno. */
int batch_mkdirs(const char *dir);

/* The worker: `heatvox batch --job INPUT OUTPUT [job options]`. Prints one
 * JSON object on stdout (the report line) and returns the exit code. */
int batch_job_main(int argc, char **argv);

/* Appends s to a growing buffer as a JSON string literal. */
typedef struct batch_buf {
    char *s;
    size_t len, cap;
} batch_buf;
void bb_printf(batch_buf *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
void bb_json_string(batch_buf *b, const char *s);
void bb_free(batch_buf *b);

/* strdup and asprintf for the driver: on out of memory they print a message
 * and exit with HV_EXIT_FAIL. The caller frees the result. (batch_job.c) */
char *batch_xstrdup(const char *s);
char *batch_xprintf(const char *fmt, ...) __attribute__((format(printf, 1, 2)));

/* ---- the driver ---- */

/* Most worker processes (-j). */
#define BATCH_MAX_WORKERS 256

/* One input of the driver. */
typedef struct batch_job {
    char *input;
    char *stem; /* output path without extension */
    char *output;
    char **args; /* per-line options, owned */
    int nargs;
    batch_opts opts;
    char hash[17];
    char *error; /* planning error: the job fails without running */
    int skip;
    int state; /* 0 pending, 1 running, 2 done */
    int again; /* its worker was killed beside others: it runs once more, alone */
} batch_job;

typedef struct batch_joblist {
    batch_job *v;
    size_t n, cap;
} batch_joblist;

/* batch_inputs.c. Appends a job for input whose output is stem + extension;
 * the strings are copied. */
batch_job *batch_jobs_add(batch_joblist *l, const char *input, const char *stem);
/* Frees every job and the list's array. */
void batch_jobs_free(batch_joblist *l);
/* Appends the jobs of each input: a mesh file, a directory (searched
 * recursively for meshes; outputs keep the sub-directory under outdir) or a
 * manifest. Inputs that cannot be read become jobs with an error. */
void batch_inputs_find(batch_joblist *l, const char *const *inputs, int ninputs,
                       const char *outdir);

/* batch_plan.c. Parses the options of every job (the global ones gargv, then
 * its own), names its output and marks the jobs that are up to date (unless
 * force) or cannot run. */
void batch_plan(batch_joblist *l, int gargc, char **gargv, int force);
/* The dry run: one line per job and a count on stdout; returns the exit code. */
int batch_plan_print(const batch_joblist *l);

/* batch_report.c. Counts, the progress bar and the report file of a run. */
typedef struct batch_progress {
    size_t total, done, ok, failed, skipped, to_run, ran;
    double t0, drawn;
    int tty, bar_shown;
    const char *current;
    FILE *report; /* --report, or NULL */
} batch_progress;

/* Zeroes p and starts the clock for the jobs of l (report NULL). */
void batch_progress_start(batch_progress *p, const batch_joblist *l);
/* Erases the bar if shown. */
void batch_bar_clear(batch_progress *p);
/* Redraws the bar (a terminal only), at most ten times a second unless forced. */
void batch_bar_draw(batch_progress *p, int force);
/* Appends one JSON line to the report, if any. */
void batch_report_line(batch_progress *p, const char *line);
/* A report line written by the driver itself (no worker report). */
void batch_report_simple(batch_progress *p, const batch_job *j, const char *status,
                         const char *error, const char *stage);
/* One finished input: counts, a line on stderr, the bar. */
void batch_finish(batch_progress *p, batch_job *j, int ok, int skipped, const char *error,
                  double seconds);
/* The summary line on stdout. */
void batch_report_summary(const batch_progress *p, int sig);

/* batch_pool.c. Number of CPUs online (at least 1). */
int batch_ncpus(void);
/* Runs every job of l, at most nworkers at once, exe being this program;
 * returns the stop signal (0 when all finished). */
int batch_pool_run(batch_joblist *l, batch_progress *p, const char *exe, int nworkers, int gargc,
                   char **gargv);

#endif
