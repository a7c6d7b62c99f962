/* heatvox batch: signed distance volumes for many meshes with a pool of worker
 * processes. Each mesh runs in its own process (`heatvox batch --job ...`,
 * exec'd from /proc/self/exe), so a crash, a hang killed by the user or a bad
 * file costs only that file, and no process forks after OpenVDB or OpenCL has
 * started threads (docs/METHOD.md, "Testing notes"). This file holds the
 * command's options and its top-level flow: inputs (batch_inputs.c), plan
 * (batch_plan.c), pool (batch_pool.c), report (batch_report.c). */
#include "batch.h"

#include <errno.h>
#include <limits.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static void help(void)
{
    printf("usage: heatvox batch INPUT... -o OUTDIR [-j N] [--report FILE] [--dry-run] [--force]\n"
           "                     [-q|-v] [job options]\n"
           "\n"
           "Computes a signed distance volume for every mesh, each in its own worker process.\n"
           "\n"
           "INPUT is a mesh file (.obj .ply .stl .off; .gltf .glb .fbx .3mf .dae .x through\n"
           "assimp) or an oriented point cloud (.xyz .pts .xyzn, or a PLY of points with\n"
           "normals: see heatvox sdf --help), a directory (searched recursively for those\n"
           "extensions, hidden entries skipped; the output keeps the sub-directory), or\n"
           "a manifest (.txt or .list): one mesh path per line, relative to the manifest's\n"
           "directory, optionally followed by job options for that mesh alone (they come\n"
           "after the global ones, so they win); '#' starts a comment; quote paths with\n"
           "spaces (\"...\" or '...'). Outputs are OUTDIR/<name>.vdb (or .exr); when two inputs\n"
           "would write the same name, later ones get _2, _3, ...\n"
           "\n"
           "  -o DIR          output directory (created when missing)\n"
           "  -j N            worker processes (default: the number of CPUs); each worker runs\n"
           "                  with CPUs/N threads unless --threads is given\n"
           "  --report FILE   JSON lines, one per input, written as inputs finish: file,\n"
           "                  output, status (ok, failed, skipped, interrupted), error, stage,\n"
           "                  grid, voxel_size, seconds per stage, defects (mesh report before\n"
           "                  repair), repair and solver counts, options and options_hash,\n"
           "                  mesh (output and triangles; null without --mesh-out-format)\n"
           "  --dry-run       list what would run or be skipped; compute nothing\n"
           "  --force         recompute outputs that are up to date\n"
           "  -q / -v         quiet (failures and the summary only) / one line per file\n"
           "\n"
           "job options (global, or per manifest line):\n"
           "  --res N            cells along the longest axis (default 128)\n"
           "  --voxel-size H     voxel size instead of --res\n"
           "  --pad N            cells between the mesh bounds and the block (default 4)\n"
           "  --bbox X0 Y0 Z0 X1 Y1 Z1   block bounds instead of --pad\n"
           "  --round-to N       round cell counts up to a multiple of N (default 8)\n"
           "  --unsigned         unsigned distance\n"
           "  --heat | --exact   magnitude from the heat method, or exact distance with the\n"
           "                     heat method's sign (default)\n"
           "  --t-scale S        diffusion time (S h)^2 (default 1)\n"
           "  --far-levels N     extra diffusion levels (-1 automatic)\n"
           "  --orient O         a point cloud's normals: auto (recovered when the file\n"
           "                     has none), given, or recover\n"
           "  --no-repair        no mesh repair before the heat method\n"
           "  --backend B        auto, mg, fftw, opencl\n"
           "  --diffuse-tol T, --poisson-tol T   solver tolerances\n"
           "  --threads N        threads per worker\n"
           "  --format vdb|exr   output format (default vdb: a level set grid \"sdf\", file\n"
           "                     metadata \"source\" and \"heatvox_options\"; exr: the\n"
           "                     multi-part layout of heatvox/image.h, channel \"distance\")\n"
           "  --band N           VDB narrow band half width in voxels (default 3)\n"
           "  --dense            VDB: every voxel active\n"
           "  --preview          also write OUTDIR/<name>.png: middle x, y, z slices\n"
           "  --mesh-out-format obj|ply|stl\n"
           "                     also write the zero level set as a closed, outward-oriented\n"
           "                     triangle mesh OUTDIR/<name>.obj (.ply, .stl) beside the volume\n"
           "                     (not with --unsigned); a mesh output that is one of the\n"
           "                     inputs fails that input\n"
           "  --adaptivity A     that mesh's adaptivity in [0, 1] (default 0: one vertex per\n"
           "                     crossed voxel; larger: fewer triangles where the surface is\n"
           "                     flat, none straying more than A/2 voxels)\n"
           "\n"
           "Resume: an output is skipped when it exists, is not older than its input, and\n"
           "its sidecar <output>.heatvox.json records the same input and options hash (the\n"
           "options above except --threads), and its preview and mesh, when asked for,\n"
           "exist and are not older than the input; --force recomputes. Outputs, previews,\n"
           "meshes and sidecars are written to temporary names and renamed when complete;\n"
           "the sidecar comes last, so an output whose mesh failed is recomputed. Ctrl-C stops\n"
           "the workers and removes their temporaries. The report is appended line by line\n"
           "as files finish.\n"
           "\n"
           "Progress: a bar with rate and ETA when stderr is a terminal, else one line per\n"
           "file on stderr. The summary goes to stdout.\n"
           "\n"
           "exit: 0 every input written or up to date, 1 some input failed (each named on\n"
           "stderr with its error), 2 usage error; killed by the signal on Ctrl-C\n"
           "\n"
           "Workers run `heatvox batch --job INPUT OUTPUT [job options]`, which computes one\n"
           "output and prints its report line on stdout (exit 0 ok, 1 failed).\n");
}

/* ---- command ---- */

/* The command line: the batch command's own options, the job options it
 * passes on to every worker (gargv), and the inputs. */
typedef struct batch_args {
    const char *outdir, *report;
    int nworkers, dry, force;
    const char **inputs;
    int ninputs;
    char **gargv;
    int gargc;
} batch_args;

/* A job option and its values, kept for the workers. */
static int forward(const char *cmd, const char *opt, char **v, int nv, void *dst)
{
    batch_args *A = dst;
    const int k = batch_opt_arity(opt);
    if (nv < k)
        return -cli_usage_error(cmd, "%s needs %d value%s", opt, k, k > 1 ? "s" : "");
    A->gargv[A->gargc++] = (char *)opt;
    for (int t = 0; t < k; t++)
        A->gargv[A->gargc++] = v[t];
    return k;
}

/* Reads the command line into A (whose arrays hold argc words): -1 to go
 * on, else the exit code. */
static int parse_args(int argc, char **argv, batch_args *A)
{
    cli_opt t[7 + BATCH_JOB_OPTS + 1] = {
        CLI_ROW_QUIET,
        {.names = "INPUT",
         .kind = CLI_WORDS,
         .files = CLI_FILES_DIR " " CLI_FILES_MESH " .txt .list"},
        {.names = "-o", .kind = CLI_STR, .dst = &A->outdir, .files = CLI_FILES_DIR},
        {.names = "--report", .kind = CLI_STR, .dst = &A->report, .files = CLI_FILES_ANY},
        {.names = "-j",
         .kind = CLI_INT,
         .dst = &A->nworkers,
         .min = 1,
         .max = BATCH_MAX_WORKERS,
         .needs = "an integer in 1.." BATCH_STR(BATCH_MAX_WORKERS)},
        {.names = "--dry-run", .kind = CLI_FLAG, .dst = &A->dry, .val = 1},
        {.names = "--force", .kind = CLI_FLAG, .dst = &A->force, .val = 1},
    };
    t[7 + batch_opts_forward(t + 7, forward, A)] = (cli_opt){.names = NULL};
    int rc = cli_parse_words("batch", argc, argv, t, "input", A->inputs, argc, &A->ninputs, help);
    if (rc >= 0)
        return rc;
    if (!A->ninputs || !A->outdir)
        return cli_usage_error("batch",
                               A->ninputs ? "no output directory (-o DIR)" : "no input given");
    batch_opts check;
    batch_opts_default(&check);
    char err[512];
    if (batch_opts_parse(A->gargc, A->gargv, &check, err, sizeof err) ||
        batch_opts_check(&check, err, sizeof err))
        return cli_usage_error("batch", "%s", err);
    return -1;
}

/* Plans the jobs and runs them on the pool (or lists them with --dry-run). */
static int run(const batch_args *A)
{
    int rc = HV_EXIT_OK;
    char exe[PATH_MAX];
    ssize_t el = readlink("/proc/self/exe", exe, sizeof exe - 1);
    if (el <= 0) {
        fprintf(stderr, "heatvox batch: cannot find my own executable: %s\n", strerror(errno));
        return HV_EXIT_FAIL;
    }
    exe[el] = '\0';

    /* Strip trailing slashes from OUTDIR so output names stay clean. */
    char *od = batch_xstrdup(A->outdir);
    for (size_t n = strlen(od); n > 1 && od[n - 1] == '/'; n--)
        od[n - 1] = '\0';
    batch_joblist l = {0};
    batch_inputs_find(&l, A->inputs, A->ninputs, od);
    batch_plan(&l, A->gargc, A->gargv, A->force);

    if (A->dry) {
        rc = batch_plan_print(&l);
        goto done;
    }

    batch_progress p;
    batch_progress_start(&p, &l);
    if (batch_mkdirs(od) != 0) {
        fprintf(stderr, "heatvox batch: %s: cannot create the output directory: %s\n", od,
                strerror(errno));
        rc = HV_EXIT_FAIL;
        goto done;
    }
    if (A->report) {
        p.report = fopen(A->report, "we");
        if (!p.report) {
            fprintf(stderr, "heatvox batch: %s: cannot write the report: %s\n", A->report,
                    strerror(errno));
            rc = HV_EXIT_FAIL;
            goto done;
        }
    }
    int sig = batch_pool_run(&l, &p, exe, A->nworkers, A->gargc, A->gargv);
    batch_bar_clear(&p);
    if (p.report)
        fclose(p.report);
    batch_report_summary(&p, sig);
    if (sig) {
        hv_tmp_cleanup_all();
        batch_jobs_free(&l);
        free(od);
        signal(sig, SIG_DFL);
        raise(sig);
        return 128 + sig;
    }
    rc = p.failed ? HV_EXIT_FAIL : HV_EXIT_OK;
done:
    batch_jobs_free(&l);
    free(od);
    return rc;
}

int cmd_batch(int argc, char **argv)
{
    if (argc >= 2 && !strcmp(argv[1], "--job"))
        return batch_job_main(argc - 2, argv + 2);
    batch_args A = {.nworkers = batch_ncpus()};
    A.inputs = malloc(sizeof(char *) * (size_t)argc);
    A.gargv = malloc(sizeof(char *) * (size_t)argc);
    int rc = A.inputs && A.gargv ? parse_args(argc, argv, &A)
                                 : cli_fail("batch", "reading the command line", HV_ERR_NOMEM);
    if (rc < 0)
        rc = run(&A);
    free(A.inputs);
    free(A.gargv);
    return rc;
}
