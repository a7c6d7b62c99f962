/* heatvox bench extend-band: velocity extension on a narrow band as whole
 * commands, `heatvox extend IN.vdb --out-band W -o OUT.vdb` against a program
 * that does the same with OpenVDB's tools::sdfToExt (read, extend, write),
 * each in its own process so that the times and the peak RSS (from wait4) are
 * those a user sees; both are compared with the exact closest-point extension
 * of a smooth field on the mesh.
 *
 * heatvox bench extend-loop: the same extension in a simulation's loop (a
 * sphere moving across the box, its level set as tiles each step), one
 * extender for all steps against sdfToExt per step, in this process. */
#include "bench_device.h"
#include "bench_ref.h"
#include "tri_buckets.h"
#include "../cli.h"

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#define TILE_CELLS (HV_TILE * HV_TILE * HV_TILE)

static const char *CMD = "bench extend-band";

static int usage(FILE *out)
{
    fprintf(out,
            "usage: heatvox bench extend-band MESH --n N [--out-band W] [--field vector|scalar]\n"
            "                                 [--backend auto|mg|opencl] [--keep DIR]\n"
            "\n"
            "Writes IN.vdb (not timed): the level set \"sdf\" of MESH (heatvox sdf --res N,\n"
            "band 3 voxels, in tiles) and a field \"v\" = g(closest point on the mesh), g\n"
            "smooth, active only where |phi| < 1.5 voxels. Then times, each as its own\n"
            "process with its peak RSS:\n"
            "  heatvox extend IN.vdb --levelset sdf --field v --out-band W -o HV.vdb -q\n"
            "  OpenVDB: read both grids, tools::sdfToExt (field sampled trilinearly on\n"
            "           the surface, 1 iteration) over the level set's band, write REF.vdb\n"
            "and compares both outputs with the exact extension g(closest point): mean\n"
            "relative error |f - f_exact| / |f_exact| (vectors: Euclidean norms) over the\n"
            "cells 1 <= |phi|/h < W active in both (err, ref_err) and over each output's\n"
            "cells with |phi| < W voxels (err_all, ref_err_all).\n"
            "  --out-band W   output band of heatvox extend, voxels (default 3)\n"
            "  --field F      vector (vec3s, default) or scalar (float)\n"
            "  --backend B    heatvox extend's --backend; opencl: the band on the device, and\n"
            "                 one more extension of IN.vdb's tiles in this process for the\n"
            "                 device's figures (device, kernel_seconds and each stage's\n"
            "                 device time, host_bytes_in, host_bytes_out, launches, and\n"
            "                 copy_gbs, the device's copy bandwidth in the same run)\n"
            "  --keep DIR     write the files to DIR (made if missing) and keep them;\n"
            "                 else a temporary directory under $TMPDIR (default /tmp),\n"
            "                 removed at the end\n"
            "Prints one JSON line: bench, n, mesh, field, out_band, path (heatvox extend's\n"
            "output: sparse or dense), seconds, peak_rss_mb, ref \"openvdb-sdfToExt\",\n"
            "ref_seconds, ref_peak_rss_mb, ratio = seconds / ref_seconds, mem_ratio, err,\n"
            "ref_err, err_all, ref_err_all, cells, ref_cells (active voxels of each\n"
            "output field), tiles (of the level set).\n"
            "Exit codes: 0 success, 1 failure, 2 usage error.\n");
    return out == stdout ? HV_EXIT_OK : HV_EXIT_USAGE;
}

/* g at world point x: ncomp values. */
static void g_at(int ncomp, const double center[3], double scale, const double x[3], double v[3])
{
    double p[3];
    for (int a = 0; a < 3; a++)
        p[a] = (x[a] - center[a]) / scale;
    if (ncomp == 3)
        bench_field_at(p, v);
    else
        v[0] = bench_scalar_at(p);
}

static inline int tile_on(const hv_tiles *t, size_t q, int c)
{
    return (int)(t->on[q * HV_TILE + c / 64] >> (c % 64) & 1);
}

static inline void tile_set_on(hv_tiles *t, size_t q, int c)
{
    t->on[q * HV_TILE + c / 64] |= 1ull << (c % 64);
}

/* Centre of cell c (i + 8 j + 64 k) of tile q. */
static void tile_cell_center(const hv_tiles *t, size_t q, int c, double x[3])
{
    const int ijk[3] = {c % HV_TILE, c / HV_TILE % HV_TILE, c / (HV_TILE * HV_TILE)};
    for (int a = 0; a < 3; a++)
        x[a] = t->origin[a] + (t->ijk[3 * q + a] + ijk[a] + 0.5) * t->h;
}

static void recount_active(hv_tiles *t)
{
    size_t n = 0;
    for (size_t w = 0; w < HV_TILE * t->count; w++)
        n += (size_t)__builtin_popcountll(t->on[w]);
    t->active = n;
}

/* The mesh as the level set sees it: the repair hv_sdf_compute_tiles applies
 * (its zero set follows the repaired triangles, e.g. the caps over the
 * bunny's holes), bucketed; g's placement from the mesh's bounds. */
typedef struct exact_field {
    hv_mesh *repaired;
    tri_buckets b;
    double center[3], scale;
    int ncomp;
} exact_field;

static void exact_field_free(exact_field *x)
{
    tri_buckets_free(&x->b);
    hv_mesh_destroy(&x->repaired);
}

static hv_status exact_field_init(exact_field *x, const hv_mesh *m, const hv_sdf_opts *so, double h,
                                  int ncomp)
{
    memset(x, 0, sizeof *x);
    x->ncomp = ncomp;
    double lo[3], hi[3];
    hv_status st = hv_mesh_bounds(m, lo, hi);
    if (st)
        return st;
    double ext = fmax(hi[0] - lo[0], fmax(hi[1] - lo[1], hi[2] - lo[2]));
    for (int a = 0; a < 3; a++)
        x->center[a] = 0.5 * (lo[a] + hi[a]);
    x->scale = 0.5 * ext;
    if ((st = hv_sdf_repair(m, so->repair, so->max_hole, &x->repaired, NULL)))
        return st;
    if ((st = tri_buckets_build(&x->b, x->repaired, 4 * h)))
        exact_field_free(x);
    return st;
}

/* f_exact at cell centre x with level set value phi: g at the closest point. */
static int exact_at(const exact_field *x, const double p[3], double phi, double h, double v[3])
{
    double cp[3];
    if (tri_buckets_closest(&x->b, p, fabs(phi) + 0.5 * h, cp))
        return -1;
    g_at(x->ncomp, x->center, x->scale, cp, v);
    return 0;
}

/* ---- The input file (a child process, so that the parent stays small) ---- */

static void mesh_sdf_opts(hv_sdf_opts *o, int n)
{
    /* As `heatvox sdf MESH --res N -o OUT.vdb` sets them for its tiles path. */
    hv_sdf_opts_default(o);
    o->res = n;
    o->voxel_size = 0;
    o->band_only = 3;
}

/* heatvox bench extend-band --input MESH N FIELD IN.vdb */
static int make_input(int argc, char **argv)
{
    if (argc != 6)
        return cli_usage_error(CMD, "--input needs MESH N FIELD OUT");
    const char *mesh = argv[2], *out = argv[5];
    int n, ncomp = !strcmp(argv[4], "scalar") ? 1 : 3;
    if (cli_parse_int(argv[3], &n))
        return cli_usage_error(CMD, "--input: bad N '%s'", argv[3]);
    hv_mesh *m = NULL;
    hv_status st = hv_mesh_read(mesh, &m);
    if (st)
        return cli_fail(CMD, mesh, st);
    hv_sdf_opts so;
    mesh_sdf_opts(&so, n);
    hv_tiles *T = NULL, *f[3] = {NULL, NULL, NULL};
    exact_field ex = {0};
    hv_vdb_writer *w = NULL;
    const char *what = mesh;
    if (!(st = hv_sdf_compute_tiles(m, &so, 3, &T, NULL)) &&
        !(st = exact_field_init(&ex, m, &so, T->h, ncomp)))
        for (int c = 0; c < ncomp && !st; c++)
            st = hv_tiles_create_like(&f[c], T, 0.0f);
    hv_mesh_destroy(&m);
    size_t missed = 0;
    if (!st) {
        const float near = (float)(1.5 * T->h);
#pragma omp parallel for schedule(dynamic, 16) reduction(+ : missed)
        for (size_t q = 0; q < T->count; q++)
            for (int c = 0; c < TILE_CELLS; c++) {
                const float p = T->v[q * TILE_CELLS + c];
                if (!tile_on(T, q, c) || !(fabsf(p) < near))
                    continue;
                double x[3], v[3];
                tile_cell_center(T, q, c, x);
                if (exact_at(&ex, x, p, T->h, v)) {
                    missed++;
                    continue;
                }
                for (int k = 0; k < ncomp; k++) {
                    f[k]->v[q * TILE_CELLS + c] = (float)v[k];
                    tile_set_on(f[k], q, c);
                }
            }
        for (int k = 0; k < ncomp; k++)
            recount_active(f[k]);
        what = out;
        if (!(st = hv_vdb_writer_create(&w)) &&
            !(st = hv_vdb_writer_add_levelset_tiles(w, T, "sdf", 3)))
            st = ncomp == 3 ? hv_vdb_writer_add_vec3_tiles(w, f[0], f[1], f[2], "v")
                            : hv_vdb_writer_add_float_tiles(w, f[0], "v");
        if (!st)
            st = hv_vdb_writer_write(w, out);
    }
    hv_vdb_writer_destroy(&w);
    exact_field_free(&ex);
    hv_tiles_destroy(&T);
    for (int k = 0; k < 3; k++)
        hv_tiles_destroy(&f[k]);
    if (missed)
        fprintf(stderr, "heatvox %s: %zu band cells found no triangle of %s\n", CMD, missed, mesh);
    return st ? cli_fail(CMD, what, st) : HV_EXIT_OK;
}

/* heatvox bench extend-band --ref IN.vdb LEVELSET FIELD OUT.vdb */
static int run_ref(int argc, char **argv)
{
    if (argc != 6)
        return cli_usage_error(CMD, "--ref needs IN LEVELSET FIELD OUT");
    hv_status st = ref_vdb_ext_file(argv[2], argv[3], argv[4], argv[5]);
    return st ? ref_vdb_fail(CMD, argv[5], st) : HV_EXIT_OK;
}

/* ---- Accuracy of the outputs ---------------------------------------------- */

typedef struct ext_errors {
    double err, ref_err, err_all, ref_err_all; /* means, NaN when no cell */
    size_t tiles;
} ext_errors;

static double rel_err(const hv_tiles *const f[3], int ncomp, size_t i, const double v[3])
{
    double d2 = 0, e2 = 0;
    for (int k = 0; k < ncomp; k++) {
        double d = f[k]->v[i] - v[k];
        d2 += d * d;
        e2 += v[k] * v[k];
    }
    return sqrt(d2 / e2);
}

/* The level set and both outputs on the input's tiles; f_exact from the mesh. */
static hv_status measure(const char *in, const char *mine, const char *ref, const char *mesh, int n,
                         int ncomp, double band, ext_errors *e)
{
    const char *names[1] = {"sdf"};
    int lo[3], hi[3], na = 0, nb = 0;
    hv_tiles *phi = NULL, *a[3] = {NULL, NULL, NULL}, *b[3] = {NULL, NULL, NULL};
    hv_mesh *m = NULL;
    exact_field ex = {0};
    hv_status st;
    if ((st = hv_vdb_common_box(in, names, 1, lo, hi)) ||
        (st = hv_vdb_read_float_tiles(in, "sdf", lo, hi, &phi, NULL)) ||
        (st = hv_vdb_read_tiles_like(mine, "v", phi, a, &na)) ||
        (st = hv_vdb_read_tiles_like(ref, "v", phi, b, &nb)) || (st = hv_mesh_read(mesh, &m)))
        goto done;
    if (na != ncomp || nb != ncomp) {
        st = HV_ERR_INVALID_ARG;
        fprintf(stderr, "heatvox %s: grid v has %d and %d components, expected %d\n", CMD, na, nb,
                ncomp);
        goto done;
    }
    hv_sdf_opts so;
    mesh_sdf_opts(&so, n);
    if ((st = exact_field_init(&ex, m, &so, phi->h, ncomp)))
        goto done;
    const double h = phi->h;
    double s = 0, rs = 0, sa = 0, rsa = 0;
    size_t c2 = 0, ca = 0, rca = 0;
#pragma omp parallel for schedule(dynamic, 16) reduction(+ : s, rs, sa, rsa, c2, ca, rca)
    for (size_t q = 0; q < phi->count; q++)
        for (int c = 0; c < TILE_CELLS; c++) {
            const size_t i = q * TILE_CELLS + c;
            const double p = phi->v[i], r = fabs(p) / h;
            const int on_a = tile_on(a[0], q, c), on_b = tile_on(b[0], q, c);
            if (!(r < band) || !(on_a || on_b))
                continue;
            double x[3], v[3];
            tile_cell_center(phi, q, c, x);
            if (exact_at(&ex, x, p, h, v))
                continue;
            const double ea = on_a ? rel_err((const hv_tiles *const *)a, ncomp, i, v) : 0;
            const double eb = on_b ? rel_err((const hv_tiles *const *)b, ncomp, i, v) : 0;
            sa += ea;
            ca += on_a;
            rsa += eb;
            rca += on_b;
            if (on_a && on_b && r >= 1) {
                s += ea;
                rs += eb;
                c2++;
            }
        }
    e->err = c2 ? s / c2 : NAN;
    e->ref_err = c2 ? rs / c2 : NAN;
    e->err_all = ca ? sa / ca : NAN;
    e->ref_err_all = rca ? rsa / rca : NAN;
    e->tiles = phi->count;
done:
    exact_field_free(&ex);
    hv_mesh_destroy(&m);
    hv_tiles_destroy(&phi);
    for (int k = 0; k < 3; k++) {
        hv_tiles_destroy(&a[k]);
        hv_tiles_destroy(&b[k]);
    }
    return st;
}

/* Active voxels of grid `name` in a file, -1 when it cannot be listed. */
static long long active_voxels(const char *path, const char *name)
{
    hv_vdb_grid_info info[8];
    size_t count = 0;
    if (hv_vdb_list(path, info, 8, &count))
        return -1;
    for (size_t i = 0; i < count && i < 8; i++)
        if (!strcmp(info[i].name, name))
            return (long long)info[i].active_voxels;
    return -1;
}

static void remove_files(const char *dir, char (*files)[4096], int nfiles, int keep)
{
    if (keep)
        return;
    for (int i = 0; i < nfiles; i++)
        remove(files[i]);
    rmdir(dir);
}

/* The stages of the device's tile extension (kernels/bandext.cl), by kernel
 * name prefix. */
static const char *const dev_prefixes[] = {"bx_scan_phi", "bx_map",      "bx_classify", "bx_count",
                                           "bx_grow",     "scan_",       "bx_build",    "bx_first",
                                           "bx_sweep",    "bx_residual", "bx_eval"};
static const char *const dev_names[] = {"check",  "check",    "classify", "domain",
                                        "domain", "domain",   "build",    "sweeps",
                                        "sweeps", "residual", "eval"};
#define DEV_STAGES ((int)(sizeof dev_names / sizeof dev_names[0]))

/* The device's figures of one more extension of IN.vdb's tiles, in this
 * process (the tiles read first, not counted). */
static int device_figures(const char *in, double band, bench_device_run *d)
{
    const char *names[2] = {"sdf", "v"};
    int lo[3], hi[3], cls = 0, ncomp = 0;
    hv_tiles *P = NULL, *F[3] = {NULL, NULL, NULL};
    hv_extender *e = NULL;
    hv_status st = hv_vdb_common_box(in, names, 2, lo, hi);
    if (!st)
        st = hv_vdb_read_float_tiles(in, "sdf", lo, hi, &P, &cls);
    if (!st)
        st = hv_vdb_read_tiles_like(in, "v", P, F, &ncomp);
    hv_extend_opts o;
    hv_extend_opts_default(&o);
    o.backend = HV_BACKEND_OPENCL;
    o.out_band = band;
    if (!st)
        st = hv_extender_create(&e, 3, P->n, P->h, NULL, &o);
    if (!st) {
        hv_extend_tiles_field f = {ncomp, {F[0], F[1], F[2]}};
        bench_device_run_begin();
        st = hv_extend_tiles(e, P, 1, &f, NULL);
        hv_extender_destroy(&e);
        if (!st)
            st = bench_device_run_end(d, dev_prefixes, dev_names, DEV_STAGES,
                                      P->count * 512 * sizeof(float));
    }
    hv_extender_destroy(&e);
    hv_tiles_destroy(&P);
    for (int c = 0; c < 3; c++)
        hv_tiles_destroy(&F[c]);
    if (st)
        return cli_fail(CMD, in, st);
    bench_device_run_merge(d);
    return HV_EXIT_OK;
}

static void help(void) { usage(stdout); }

int cmd_bench_extend_band(int argc, char **argv)
{
    if (argc > 1 && !strcmp(argv[1], "--input"))
        return make_input(argc, argv);
    if (argc > 1 && !strcmp(argv[1], "--ref"))
        return run_ref(argc, argv);
    const char *mesh = NULL, *keep = NULL;
    int n = 0, vec = 1;
    double band = 3;
    hv_backend backend = HV_BACKEND_AUTO;
    const cli_opt opts[] = {
        CLI_ROW_QUIET,
        {.names = "MESH", .kind = CLI_WORDS, .files = CLI_FILES_TRIMESH},
        {.names = "--n",
         .kind = CLI_INT,
         .dst = &n,
         .min = 16,
         .max = INT_MAX,
         .needs = "an integer >= 16"},
        {.names = "--out-band",
         .kind = CLI_DOUBLE,
         .dst = &band,
         .min = 1,
         .max = 3,
         .needs = "1..3 voxels (the input band)"},
        {.names = "--field",
         .kind = CLI_CHOICE,
         .dst = &vec,
         .choices = "scalar|vector",
         .needs = "vector or scalar"},
        {.names = "--keep", .kind = CLI_STR, .dst = &keep, .files = CLI_FILES_DIR},
        CLI_ROW_BACKEND(&backend, CLI_BACKENDS_LOCAL),
        {.names = NULL},
    };
    int prc = cli_parse(CMD, argc, argv, opts, "mesh", &mesh, help);
    if (prc >= 0)
        return prc;
    const char *field = vec ? "vector" : "scalar";
    if (!mesh || !n)
        return usage(stderr);
    if (access(mesh, R_OK)) {
        fprintf(stderr, "heatvox %s: %s: %s\n", CMD, mesh, strerror(errno));
        return HV_EXIT_FAIL;
    }
    const int ncomp = !strcmp(field, "vector") ? 3 : 1;
    char dir[3800];
    if (keep) {
        snprintf(dir, sizeof dir, "%s", keep);
        if (mkdir(dir, 0777) && errno != EEXIST) {
            fprintf(stderr, "heatvox %s: %s: %s\n", CMD, dir, strerror(errno));
            return HV_EXIT_FAIL;
        }
    } else {
        const char *tmp = getenv("TMPDIR");
        snprintf(dir, sizeof dir, "%s/heatvox-bench-extend-band-XXXXXX",
                 tmp && *tmp ? tmp : "/tmp");
        if (!mkdtemp(dir)) {
            fprintf(stderr, "heatvox %s: %s: %s\n", CMD, dir, strerror(errno));
            return HV_EXIT_FAIL;
        }
    }
    char files[3][4096], ns[32], ws[32];
    const char *leaf[3] = {"IN.vdb", "HV.vdb", "REF.vdb"};
    for (int k = 0; k < 3; k++)
        snprintf(files[k], sizeof files[k], "%s/%s", dir, leaf[k]);
    char *in = files[0], *mine = files[1], *ref = files[2];
    snprintf(ns, sizeof ns, "%d", n);
    snprintf(ws, sizeof ws, "%.17g", band);

    double t, r, sec, rss, rsec, rrss;
    char *in_argv[] = {"heatvox",     "bench", "extend-band", "--input", (char *)mesh, ns,
                       (char *)field, in,      NULL};
    char *hv_argv[] = {"heatvox",   "extend",
                       in,          "--levelset",
                       "sdf",       "--field",
                       "v",         "--out-band",
                       ws,          "-o",
                       mine,        "-q",
                       "--backend", (char *)hv_backend_name(backend),
                       NULL};
    char *ref_argv[] = {"heatvox", "bench", "extend-band", "--ref", in, "sdf", "v", ref, NULL};
    int rc = HV_EXIT_FAIL;
    if (bench_run_self(in_argv, &t, &r)) {
        fprintf(stderr, "heatvox %s: making the input %s from %s failed\n", CMD, in, mesh);
        goto done;
    }
    if (bench_run_self(hv_argv, &sec, &rss)) {
        fprintf(stderr, "heatvox %s: heatvox extend %s --out-band %s failed\n", CMD, in, ws);
        goto done;
    }
    if (bench_run_self(ref_argv, &rsec, &rrss)) {
        fprintf(stderr, "heatvox %s: the OpenVDB reference failed on %s\n", CMD, in);
        goto done;
    }
    bench_device_run dev;
    if (backend == HV_BACKEND_OPENCL && device_figures(in, band, &dev))
        goto done;
    ext_errors e = {NAN, NAN, NAN, NAN, 0};
    hv_status st = measure(in, mine, ref, mesh, n, ncomp, band, &e);
    if (st) {
        cli_fail(CMD, "reading the outputs", st);
        goto done;
    }
    const long long cells = active_voxels(mine, "v"), ref_cells = active_voxels(ref, "v");
    const long long band_cells = active_voxels(in, "sdf");
    printf("{\"bench\":\"extend_band\",\"n\":%d,\"mesh\":\"%s\",\"field\":\"%s\",\"out_band\":%g,"
           "\"backend\":\"%s\",\"threads\":%d,\"path\":\"%s\",\"seconds\":%.4f,"
           "\"peak_rss_mb\":%.1f,\"ref\":\"openvdb-sdfToExt\",\"ref_seconds\":%.4f,"
           "\"ref_peak_rss_mb\":%.1f,\"ratio\":%.3f,\"mem_ratio\":%.3f,\"err\":%.3e,"
           "\"ref_err\":%.3e,\"err_all\":%.3e,\"ref_err_all\":%.3e,\"cells\":%lld,"
           "\"ref_cells\":%lld,\"tiles\":%zu",
           n, mesh, field, band, backend == HV_BACKEND_OPENCL ? "opencl" : "cpu", hv_get_threads(),
           cells <= band_cells ? "sparse" : "dense", sec, rss, rsec, rrss, sec / rsec, rss / rrss,
           e.err, e.ref_err, e.err_all, e.ref_err_all, cells, ref_cells, e.tiles);
    if (backend == HV_BACKEND_OPENCL)
        bench_device_run_json(&dev, stdout);
    printf("}\n");
    fflush(stdout);
    rc = HV_EXIT_OK;
done:
    remove_files(dir, files, 3, keep != NULL);
    return rc;
}

/* ---- heatvox bench extend-loop -------------------------------------------- */

static int usage_loop(FILE *out)
{
    fprintf(out, "usage: heatvox bench extend-loop --n N [--steps S] [--backend auto|mg|opencl]\n"
                 "\n"
                 "A sphere of radius 0.25 moving across the box [-1,1]^3 (N cells per axis) in\n"
                 "S steps (default 20). Each step (not timed) its level set as tiles within 3\n"
                 "voxels of the surface, never a dense grid, and a vector field g(closest\n"
                 "point) known within 1.5 voxels; then, timed: heatvox hv_extend_tiles with\n"
                 "out_band 3 on ONE extender made before the loop (its creation:\n"
                 "setup_seconds), and OpenVDB sdfToExt on grids built from the same tiles\n"
                 "(the time of sdfToExt alone). Prints one JSON line: seconds and ref_seconds\n"
                 "(means per step), first_seconds (heatvox's first step), ratio, setup_seconds,\n"
                 "and mean relative errors against the exact extension: err, ref_err over the\n"
                 "cells 1 <= |phi|/h < 3 in both outputs, err_all, ref_err_all over each\n"
                 "output's cells with |phi| < 3 voxels; peak_rss_mb, the process's (both\n"
                 "methods run in it). --backend opencl: every step on the device (the tiles\n"
                 "cross each way), with the device's figures over the steps after the first\n"
                 "(kernel_seconds, each stage's device time, host_bytes_in, host_bytes_out,\n"
                 "launches, per step) and copy_gbs, its copy bandwidth in the same run.\n");
    return out == stdout ? HV_EXIT_OK : HV_EXIT_USAGE;
}

/* The sphere (centre c0, radius R) on the block [-1,1]^3 of n^3 cells: phi
 * (active where |phi| < 3h, the rest of each tile the signed band), the field
 * in (active within 1.5 voxels) and the exact extension ex, on the tiles
 * within reach of the band. */
static hv_status sphere_tiles(int n, const double c0[3], double R, hv_tiles **phi, hv_tiles *in[3],
                              hv_tiles *ex[3])
{
    const double h = 2.0 / n, reach = 3 * h + 4 * sqrt(3.0) * h;
    int lo[3], hi[3];
    for (int a = 0; a < 3; a++) {
        lo[a] = (int)fmax(0, floor((c0[a] - R - reach + 1) / h / HV_TILE));
        hi[a] = (int)fmin((n - 1) / HV_TILE, floor((c0[a] + R + reach + 1) / h / HV_TILE));
    }
    size_t cap = (size_t)(hi[0] - lo[0] + 1) * (hi[1] - lo[1] + 1) * (hi[2] - lo[2] + 1);
    hv_tiles like = {{n, n, n}, h, {-1, -1, -1}, 0, malloc(3 * cap * sizeof(int32_t)), NULL,
                     NULL,      0};
    if (!like.ijk)
        return HV_ERR_NOMEM;
    for (int k = lo[2]; k <= hi[2]; k++)
        for (int j = lo[1]; j <= hi[1]; j++)
            for (int i = lo[0]; i <= hi[0]; i++) {
                double r = 0;
                const int t[3] = {i, j, k};
                for (int a = 0; a < 3; a++) {
                    double x = -1 + (t[a] * HV_TILE + 0.5 * HV_TILE) * h - c0[a];
                    r += x * x;
                }
                if (fabs(sqrt(r) - R) > reach)
                    continue;
                for (int a = 0; a < 3; a++)
                    like.ijk[3 * like.count + a] = t[a] * HV_TILE;
                like.count++;
            }
    hv_status st = hv_tiles_create_like(phi, &like, 0.0f);
    for (int k = 0; k < 3 && !st; k++)
        if (!(st = hv_tiles_create_like(&in[k], &like, 0.0f)))
            st = hv_tiles_create_like(&ex[k], &like, 0.0f);
    free(like.ijk);
    if (st)
        return st;
    hv_tiles *P = *phi;
#pragma omp parallel for schedule(static)
    for (size_t q = 0; q < P->count; q++)
        for (int c = 0; c < TILE_CELLS; c++) {
            const size_t i = q * TILE_CELLS + c;
            double x[3], d[3], r = 0, cp[3], v[3];
            tile_cell_center(P, q, c, x);
            for (int a = 0; a < 3; a++) {
                d[a] = x[a] - c0[a];
                r += d[a] * d[a];
            }
            r = sqrt(r);
            const double p = r - R;
            int inside = 1;
            for (int a = 0; a < 3; a++)
                inside &= P->ijk[3 * q + a] + (a == 0 ? c % 8 : a == 1 ? c / 8 % 8 : c / 64) < n;
            const int act = inside && fabs(p) < 3 * h;
            P->v[i] = (float)(act ? p : copysign(3 * h, p));
            if (!act)
                continue;
            tile_set_on(P, q, c);
            for (int a = 0; a < 3; a++)
                cp[a] = c0[a] + R * d[a] / r;
            bench_field_at(cp, v);
            for (int k = 0; k < 3; k++) {
                ex[k]->v[i] = (float)v[k];
                tile_set_on(ex[k], q, c);
                if (fabs(p) < 1.5 * h) {
                    in[k]->v[i] = (float)v[k];
                    tile_set_on(in[k], q, c);
                }
            }
        }
    recount_active(P);
    for (int k = 0; k < 3; k++) {
        recount_active(in[k]);
        recount_active(ex[k]);
    }
    return HV_OK;
}

/* Sums of relative errors of a and b against ex (vectors) over the cells of
 * |phi| < 3h: s[0], s[1] on 1 <= |phi|/h active in both (count m[0]); s[2],
 * s[3] on each one's own cells (m[1], m[2]). */
static void loop_errors(const hv_tiles *phi, hv_tiles *const ex[3], hv_tiles *const a[3],
                        hv_tiles *const b[3], double s[4], size_t m[3])
{
    const double h = phi->h;
    double s0 = 0, s1 = 0, s2 = 0, s3 = 0;
    size_t m0 = 0, m1 = 0, m2 = 0;
#pragma omp parallel for schedule(static) reduction(+ : s0, s1, s2, s3, m0, m1, m2)
    for (size_t q = 0; q < phi->count; q++)
        for (int c = 0; c < TILE_CELLS; c++) {
            const size_t i = q * TILE_CELLS + c;
            const double r = fabs(phi->v[i]) / h;
            if (!tile_on(phi, q, c) || !(r < 3))
                continue;
            const int on_a = tile_on(a[0], q, c), on_b = tile_on(b[0], q, c);
            double v[3] = {ex[0]->v[i], ex[1]->v[i], ex[2]->v[i]};
            const double ea = on_a ? rel_err((const hv_tiles *const *)a, 3, i, v) : 0;
            const double eb = on_b ? rel_err((const hv_tiles *const *)b, 3, i, v) : 0;
            s2 += ea;
            m1 += on_a;
            s3 += eb;
            m2 += on_b;
            if (on_a && on_b && r >= 1) {
                s0 += ea;
                s1 += eb;
                m0++;
            }
        }
    s[0] += s0, s[1] += s1, s[2] += s2, s[3] += s3;
    m[0] += m0, m[1] += m1, m[2] += m2;
}

static void help_loop(void) { usage_loop(stdout); }

int cmd_bench_extend_loop(int argc, char **argv)
{
    const char *cmd = "bench extend-loop";
    int n = 0, steps = 20;
    hv_backend backend = HV_BACKEND_AUTO;
    const cli_opt opts[] = {
        CLI_ROW_QUIET,
        {.names = "--n",
         .kind = CLI_INT,
         .dst = &n,
         .min = 32,
         .max = INT_MAX,
         .needs = "an integer >= 32"},
        {.names = "--steps",
         .kind = CLI_INT,
         .dst = &steps,
         .min = 1,
         .max = INT_MAX,
         .needs = "a positive integer"},
        CLI_ROW_BACKEND(&backend, CLI_BACKENDS_LOCAL),
        {.names = NULL},
    };
    const char *stray = NULL;
    int rc = cli_parse(cmd, argc, argv, opts, "argument", &stray, help_loop);
    if (rc >= 0)
        return rc;
    if (stray)
        return cli_usage_error(cmd, "unexpected argument '%s'", stray);
    if (!n)
        return usage_loop(stderr);
    const double R = 0.25, from[3] = {-0.55, -0.45, -0.5}, to[3] = {0.55, 0.45, 0.5};
    const int ns[3] = {n, n, n};
    hv_extend_opts o;
    hv_extend_opts_default(&o);
    o.out_band = 3;
    o.backend = backend;
    if (backend == HV_BACKEND_OPENCL)
        bench_device_run_begin(); /* before the first OpenCL call */
    hv_extender *e = NULL;
    double t0 = hv_now();
    hv_status st = hv_extender_create(&e, 3, ns, 2.0 / n, NULL, &o);
    const double setup = hv_now() - t0;
    if (st)
        return cli_fail(cmd, "creating the extender", st);
    double sec = 0, first = 0, rsec = 0, s[4] = {0, 0, 0, 0}, tiles = 0, cells = 0;
    size_t m[3] = {0, 0, 0};
    for (int step = 0; step < steps && !st; step++) {
        const double f = steps > 1 ? (double)step / (steps - 1) : 0.5;
        double c0[3];
        for (int a = 0; a < 3; a++)
            c0[a] = from[a] + f * (to[a] - from[a]);
        hv_tiles *phi = NULL, *in[3] = {NULL, NULL, NULL}, *ex[3] = {NULL, NULL, NULL};
        hv_tiles *ro[3] = {NULL, NULL, NULL};
        hv_extend_tiles_field fld = {3, {NULL, NULL, NULL}};
        const char *what = "building the sphere's tiles";
        st = sphere_tiles(n, c0, R, &phi, in, ex);
        /* OpenVDB first: heatvox extends the field in place. */
        for (int k = 0; k < 3 && !st; k++)
            st = hv_tiles_create_like(&ro[k], phi, 0.0f);
        double rs = 0;
        if (!st && (st = ref_vdb_sdf_to_ext_tiles(phi, 3, (const hv_tiles *const *)in, ro, &rs))) {
            ref_vdb_fail(cmd, "OpenVDB sdfToExt", st);
            st = HV_ERR_BACKEND;
            what = NULL;
        }
        rsec += rs;
        if (!st) {
            for (int k = 0; k < 3; k++)
                fld.v[k] = in[k];
            what = "hv_extend_tiles";
            hv_extend_stats es;
            t0 = hv_now();
            st = hv_extend_tiles(e, phi, 1, &fld, &es);
            const double t = hv_now() - t0;
            sec += t;
            if (!step) {
                first = t;
                if (backend == HV_BACKEND_OPENCL)
                    bench_device_run_begin(); /* the first step's counts dropped */
            }
            tiles += (double)phi->count;
        }
        if (!st) {
            cells += (double)fld.v[0]->active;
            loop_errors(phi, ex, fld.v, ro, s, m);
        } else if (what) {
            cli_fail(cmd, what, st);
        }
        hv_tiles_destroy(&phi);
        for (int k = 0; k < 3; k++) {
            hv_tiles_destroy(&in[k]);
            hv_tiles_destroy(&ex[k]);
            hv_tiles_destroy(&ro[k]);
        }
    }
    hv_extender_destroy(&e);
    bench_device_run dev;
    if (!st && backend == HV_BACKEND_OPENCL) {
        const size_t bytes = (size_t)(tiles / steps) * 512 * sizeof(float);
        if ((st = bench_device_run_end(&dev, dev_prefixes, dev_names, DEV_STAGES, bytes)))
            cli_fail(cmd, "the device's figures", st);
        bench_device_run_merge(&dev);
        /* per step, the first (the program's build) left out */
        const double k = steps > 1 ? 1.0 / (steps - 1) : 1;
        dev.kernel_seconds *= k;
        dev.host_bytes_in *= k;
        dev.host_bytes_out *= k;
        dev.launches *= k;
        for (int q = 0; q < dev.nstages; q++)
            dev.stage_seconds[q] *= k;
    }
    if (st)
        return HV_EXIT_FAIL;
    printf("{\"bench\":\"extend_loop\",\"n\":%d,\"steps\":%d,\"field\":\"vector\",\"out_band\":3,"
           "\"backend\":\"%s\",\"threads\":%d,\"setup_seconds\":%.4f,\"seconds\":%.4f,"
           "\"first_seconds\":%.4f,\"ref\":\"openvdb-sdfToExt\",\"ref_seconds\":%.4f,"
           "\"ratio\":%.3f,\"err\":%.3e,\"ref_err\":%.3e,\"err_all\":%.3e,\"ref_err_all\":%.3e,"
           "\"tiles\":%.0f,\"cells\":%.0f,\"peak_rss_mb\":%.1f",
           n, steps, backend == HV_BACKEND_OPENCL ? "opencl" : "cpu", hv_get_threads(), setup,
           sec / steps, first, rsec / steps, sec / rsec, m[0] ? s[0] / m[0] : NAN,
           m[0] ? s[1] / m[0] : NAN, m[1] ? s[2] / m[1] : NAN, m[2] ? s[3] / m[2] : NAN,
           tiles / steps, cells / steps, hv_peak_rss() / 1e6);
    if (backend == HV_BACKEND_OPENCL)
        bench_device_run_json(&dev, stdout);
    printf("}\n");
    fflush(stdout);
    return HV_EXIT_OK;
}
