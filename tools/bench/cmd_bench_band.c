/* heatvox bench band: a narrow-band level set from a mesh as whole commands,
 * `heatvox sdf MESH -o OUT.vdb` against OpenVDB's meshToLevelSet plus its
 * .vdb write on the same lattice, each in its own process, so that the times
 * and the peak RSS (from wait4) are those a user sees. */
#include "bench_device.h"
#include "bench_ref.h"
#include "../cli.h"
#include "../commands.h"
#include "heatvox/heatvox.h"

#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

static int usage(FILE *out)
{
    fprintf(out, "usage: heatvox bench band MESH --n N [--band W] [--repeat R] [--dense]\n"
                 "                         [--backend auto|mg|opencl]\n"
                 "\n"
                 "Times `heatvox sdf MESH --res N --band W -o OUT.vdb` (the narrow band in\n"
                 "tiles) and OpenVDB's meshToLevelSet with its .vdb write on the same lattice,\n"
                 "each as its own process, best of R runs (default 1). Prints one JSON line:\n"
                 "seconds, peak_rss_mb, active_voxels, ref \"openvdb\", ref_seconds,\n"
                 "ref_rss_mb, ref_active_voxels, ratio = seconds / ref_seconds, rss_ratio; up to\n"
                 "512^3 also band_sign_agreement and band_mean_abs_diff (of the distances, in\n"
                 "voxels) over the voxels in both bands; with --dense also dense_seconds and "
                 "dense_rss_mb of the same\n"
                 "band on the dense block (--no-tiles). With --backend opencl the command\n"
                 "runs on the device, and one more run in this process adds the device's\n"
                 "figures: device, device_seconds, stage_device_seconds (trust, bin, scan,\n"
                 "sign, compact), host_bytes_in (host to device), host_bytes_out (device to\n"
                 "host), launches, and copy_gbs, the device's own copy bandwidth. Files go to\n"
                 "$TMPDIR (default /tmp).\n");
    return out == stdout ? HV_EXIT_OK : HV_EXIT_USAGE;
}

/* The reference as its own process: heatvox bench band --ref MESH H X Y Z W OUT. */
static int run_ref(int argc, char **argv)
{
    if (argc != 9)
        return cli_usage_error("bench band", "--ref needs MESH H X Y Z W OUT");
    double h, x[3], w;
    if (cli_parse_double(argv[3], &h) || cli_parse_double(argv[4], &x[0]) ||
        cli_parse_double(argv[5], &x[1]) || cli_parse_double(argv[6], &x[2]) ||
        cli_parse_double(argv[7], &w))
        return cli_usage_error("bench band", "--ref: bad number");
    hv_mesh *m = NULL;
    hv_status st = hv_mesh_read(argv[2], &m);
    if (st)
        return cli_fail("bench band", argv[2], st);
    st = ref_vdb_mesh_to_vdb_file(m->verts, m->nverts, m->tris, m->ntris, h, x, w, argv[8]);
    hv_mesh_destroy(&m);
    return st ? ref_vdb_fail("bench band", argv[8], st) : HV_EXIT_OK;
}

/* Over the voxels in both bands: the fraction whose signs agree and the mean
 * difference of the distances (magnitudes) in voxels. */
static int compare(const char *mine, const char *ref, double band, double *agree, double *diff)
{
    hv_grid *a = NULL, *b = NULL;
    if (hv_vdb_read_float(mine, "sdf", NULL, &a, NULL))
        return -1;
    hv_vdb_read_opts ro = {1, {0, 0, 0}, {a->n[0] - 1, a->n[1] - 1, a->n[2] - 1}};
    if (hv_vdb_read_float(ref, "sdf", &ro, &b, NULL)) {
        hv_grid_destroy(&a);
        return -1;
    }
    const float bg = (float)(band * a->h);
    size_t both = 0, same = 0;
    double sum = 0;
    for (size_t c = 0; c < hv_grid_count(a); c++)
        if (fabsf(a->v[c]) < bg && fabsf(b->v[c]) < bg) {
            both++;
            same += (a->v[c] < 0) == (b->v[c] < 0);
            sum += fabs(fabs((double)a->v[c]) - fabs((double)b->v[c]));
        }
    *agree = both ? (double)same / both : 0;
    *diff = both ? sum / both / a->h : 0;
    hv_grid_destroy(&a);
    hv_grid_destroy(&b);
    return 0;
}

/* The device's figures of one more run, in this process. */
static int device_figures(const char *path, int n, double band, bench_device_run *d)
{
    static const char *const prefixes[] = {"tiles_trust", "tiles_count",  "tiles_fill",
                                           "scan_",       "tiles_flag",   "tiles_list",
                                           "tiles_sign",  "tiles_compact"};
    static const char *const names[] = {"trust", "bin", "bin",  "scan",
                                        "bin",   "bin", "sign", "compact"};
    hv_mesh *m = NULL;
    hv_status st = hv_mesh_read(path, &m);
    if (st)
        return cli_fail("bench band", path, st);
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = n;
    o.backend = HV_BACKEND_OPENCL;
    hv_tiles *T = NULL;
    hv_sdf_stats S;
    bench_device_run_begin();
    st = hv_sdf_compute_tiles(m, &o, band, &T, &S);
    size_t bytes = T ? T->count * (size_t)(HV_TILE * HV_TILE * HV_TILE) * sizeof(float) : 0;
    hv_tiles_destroy(&T);
    hv_mesh_destroy(&m);
    if (!st)
        st = bench_device_run_end(d, prefixes, names, 8, bytes);
    if (st)
        return cli_fail("bench band", path, st);
    bench_device_run_merge(d);
    return HV_EXIT_OK;
}

static void help(void) { usage(stdout); }

int cmd_bench_band(int argc, char **argv)
{
    if (argc > 1 && !strcmp(argv[1], "--ref"))
        return run_ref(argc, argv);
    const char *path = NULL;
    int n = 0, repeat = 1, dense = 0;
    hv_backend backend = HV_BACKEND_AUTO;
    double band = 3;
    const cli_opt opts[] = {
        CLI_ROW_QUIET,
        {.names = "MESH", .kind = CLI_WORDS, .files = CLI_FILES_TRIMESH},
        {.names = "--n",
         .kind = CLI_INT,
         .dst = &n,
         .min = 16,
         .max = INT_MAX,
         .needs = "an integer >= 16"},
        {.names = "--band",
         .kind = CLI_DOUBLE,
         .dst = &band,
         .min = 1,
         .max = 16,
         .needs = "1..16 voxels"},
        CLI_ROW_REPEAT(&repeat),
        CLI_ROW_DENSE(&dense),
        CLI_ROW_BACKEND(&backend, CLI_BACKENDS_LOCAL),
        {.names = NULL},
    };
    int rc = cli_parse("bench band", argc, argv, opts, "mesh", &path, help);
    if (rc >= 0)
        return rc;
    if (!path || !n)
        return usage(stderr);
    const char *dir = getenv("TMPDIR");
    dir = dir && *dir ? dir : "/tmp";
    char mine[4096], ref[4096], ns[32], bs[32];
    snprintf(mine, sizeof mine, "%s/heatvox-bench-band-%d.vdb", dir, (int)getpid());
    snprintf(ref, sizeof ref, "%s/heatvox-bench-band-ref-%d.vdb", dir, (int)getpid());
    snprintf(ns, sizeof ns, "%d", n);
    snprintf(bs, sizeof bs, "%.17g", band);

    double sec = INFINITY, rss = 0, dsec = INFINITY, drss = 0, rsec = INFINITY, rrss = 0, t, r;
    char *hv_argv[] = {"heatvox", "sdf",    (char *)path, "--res",
                       ns,        "--band", bs,           "-o",
                       mine,      "-q",     "--backend",  (char *)hv_backend_name(backend),
                       NULL,      NULL};
    for (int k = 0; k < repeat; k++) {
        if (bench_run_self(hv_argv, &t, &r)) {
            fprintf(stderr, "heatvox bench band: heatvox sdf %s --res %d failed\n", path, n);
            return HV_EXIT_FAIL;
        }
        if (t < sec)
            sec = t, rss = r;
    }
    for (int k = 0; dense && k < repeat; k++) {
        hv_argv[12] = "--no-tiles";
        if (bench_run_self(hv_argv, &t, &r)) {
            fprintf(stderr, "heatvox bench band: heatvox sdf %s --res %d --no-tiles failed\n", path,
                    n);
            return HV_EXIT_FAIL;
        }
        hv_argv[12] = NULL;
        if (t < dsec)
            dsec = t, drss = r;
    }
    hv_vdb_grid_info gi;
    size_t count = 0;
    if (hv_vdb_list(mine, &gi, 1, &count) || count < 1) {
        fprintf(stderr, "heatvox bench band: %s\n", hv_last_error());
        remove(mine);
        return HV_EXIT_FAIL;
    }
    char hs[40], xs[3][40];
    snprintf(hs, sizeof hs, "%.17g", gi.voxel_size[0]);
    for (int a = 0; a < 3; a++)
        snprintf(xs[a], sizeof xs[a], "%.17g", gi.index0_world[a]);
    char *ref_argv[] = {"heatvox", "bench", "band", "--ref", (char *)path, hs,
                        xs[0],     xs[1],   xs[2],  bs,      ref,          NULL};
    for (int k = 0; k < repeat; k++) {
        if (bench_run_self(ref_argv, &t, &r)) {
            fprintf(stderr, "heatvox bench band: the OpenVDB reference failed on %s\n", path);
            remove(mine);
            return HV_EXIT_FAIL;
        }
        if (t < rsec)
            rsec = t, rrss = r;
    }
    hv_vdb_grid_info ri;
    if (hv_vdb_list(ref, &ri, 1, &count) || count < 1) {
        fprintf(stderr, "heatvox bench band: %s\n", hv_last_error());
        remove(mine);
        remove(ref);
        return HV_EXIT_FAIL;
    }
    bench_device_run dev;
    if (backend == HV_BACKEND_OPENCL && device_figures(path, n, band, &dev)) {
        remove(mine);
        remove(ref);
        return HV_EXIT_FAIL;
    }
    printf("{\"bench\":\"sdf_band\",\"mesh\":\"%s\",\"n\":%d,\"band\":%g,\"backend\":\"%s\","
           "\"threads\":%d,\"seconds\":%.4f,\"peak_rss_mb\":%.1f,\"active_voxels\":%lld,"
           "\"ref\":\"openvdb\",\"ref_seconds\":%.4f,\"ref_rss_mb\":%.1f,"
           "\"ref_active_voxels\":%lld,\"ratio\":%.3f,\"rss_ratio\":%.3f",
           path, n, band, backend == HV_BACKEND_OPENCL ? "opencl" : "tiles", hv_get_threads(), sec,
           rss, (long long)gi.active_voxels, rsec, rrss, (long long)ri.active_voxels, sec / rsec,
           rss / rrss);
    if (dense)
        printf(",\"dense_seconds\":%.4f,\"dense_rss_mb\":%.1f", dsec, drss);
    if (backend == HV_BACKEND_OPENCL)
        bench_device_run_json(&dev, stdout);
    double agree, diff;
    if (n <= 512 && !compare(mine, ref, band, &agree, &diff))
        printf(",\"band_sign_agreement\":%.5f,\"band_mean_abs_diff\":%.5f", agree, diff);
    printf("}\n");
    fflush(stdout);
    remove(mine);
    remove(ref);
    return HV_EXIT_OK;
}
