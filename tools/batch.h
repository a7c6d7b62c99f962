/* heatvox batch: pieces shared by the batch driver (cmd_batch.c) and the job
 * that each worker process runs (batch_job.c). */
#ifndef HV_TOOLS_BATCH_H
#define HV_TOOLS_BATCH_H

#include "cli.h"

#include <stddef.h>

enum { BATCH_VDB = 0, BATCH_EXR = 1 };

/* The options of one job: the signed-distance options plus output choices. */
typedef struct batch_opts {
    hv_sdf_opts sdf;
    int format;        /* BATCH_VDB or BATCH_EXR */
    int preview;       /* also write <output>.png: the three middle slices */
    double band;       /* VDB narrow band half width in voxels */
    int dense;         /* VDB: every voxel active */
} batch_opts;

void batch_opts_default(batch_opts *o);

/* Number of arguments option `name` takes, or -1 when it is not a job option. */
int batch_opt_arity(const char *name);

/* Applies argv[0..argc) (job options only) to o; on error writes a message to
 * err and returns -1. */
int batch_opts_parse(int argc, char **argv, batch_opts *o, char *err, size_t errsize);

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

/* True when output exists, is not older than input, and its sidecar records the
 * same input path and options hash (and the preview exists when asked for). */
int batch_up_to_date(const char *input, const char *output, const batch_opts *o,
                     const char *hash);

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

#endif
