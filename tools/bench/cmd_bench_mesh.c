/* heatvox bench mesh: extracting the zero level set as a mesh (hv_grid_to_mesh,
 * what `heatvox sdf --mesh-out` runs) at adaptivity 0 and 0.5, against the
 * signed distance computation that produced the grid, in the same run. */
#include "../cli.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int usage(FILE *out)
{
    fprintf(out,
            "usage: heatvox bench mesh MESH --n N [--backend auto|mg|fftw|opencl] [--repeat R]\n"
            "                          [--threads T] [--sign auto|heat|winding]\n"
            "Computes the signed distance of MESH at N voxels along the longest axis (the\n"
            "3-voxel narrow band that heatvox sdf --mesh-out computes), then extracts its zero\n"
            "level set as a triangle mesh at adaptivity 0 and 0.5 (best of R runs after a\n"
            "warm-up each), and prints one JSON line: bench, n, grid, backend, threads,\n"
            "seconds and triangles (adaptivity 0), seconds_adaptive and triangles_adaptive\n"
            "(0.5), peak_rss_mb, ref \"sdf\", ref_seconds (the distance computation),\n"
            "ratio = seconds / ref_seconds and ratio_adaptive.\n");
    return out == stdout ? HV_EXIT_OK : HV_EXIT_USAGE;
}

int cmd_bench_mesh(int argc, char **argv)
{
    cli_bench_mesh_args A;
    int rc = cli_bench_mesh_args_parse("bench mesh", argc, argv, usage, &A);
    if (rc >= 0)
        return rc;
    const char *path = A.path;
    const int n = A.n, repeat = A.repeat, threads = A.threads;
    const hv_backend backend = A.backend;
    hv_set_threads(threads);

    hv_mesh *m = NULL;
    hv_status st = hv_mesh_read(path, &m);
    if (st)
        return cli_fail("bench mesh", path, st);
    hv_sdf_opts o;
    hv_sdf_opts_default(&o);
    o.res = n;
    o.backend = backend;
    o.sign = A.sign;
    o.band_only = 3.0;
    hv_grid *phi = NULL;
    hv_sdf_stats stt;
    double ref_seconds = 1e30;
    hv_backend ran = backend;
    for (int r = 0; r <= repeat; r++) {
        hv_grid *g = NULL;
        if ((st = hv_sdf_compute(m, &o, &g, &stt))) {
            hv_grid_destroy(&phi);
            hv_mesh_destroy(&m);
            return cli_fail("bench mesh", path, st);
        }
        ran = stt.backend;
        if (r > 0 && stt.t_total < ref_seconds)
            ref_seconds = stt.t_total;
        hv_grid_destroy(&phi);
        phi = g;
    }
    size_t ntris = m->ntris;
    hv_mesh_destroy(&m);

    const double adaptivity[2] = {0.0, 0.5};
    double seconds[2] = {1e30, 1e30};
    size_t triangles[2] = {0, 0};
    for (int a = 0; a < 2; a++)
        for (int r = 0; r <= repeat; r++) {
            hv_mesh *iso = NULL;
            double t0 = hv_now();
            st = hv_grid_to_mesh(phi, 0.0, adaptivity[a], &iso);
            double t = hv_now() - t0;
            if (st) {
                hv_grid_destroy(&phi);
                return cli_fail("bench mesh", path, st);
            }
            triangles[a] = iso->ntris;
            hv_mesh_destroy(&iso);
            if (r > 0 && t < seconds[a])
                seconds[a] = t;
        }
    printf(
        "{\"bench\":\"mesh\",\"mesh\":\"%s\",\"n\":%d,\"grid\":[%d,%d,%d],\"input_triangles\":%zu,"
        "\"backend\":\"%s\",\"threads\":%d,\"seconds\":%.4f,\"triangles\":%zu,"
        "\"seconds_adaptive\":%.4f,\"triangles_adaptive\":%zu,\"adaptivity\":%.1f,"
        "\"peak_rss_mb\":%.1f,\"ref\":\"sdf\",\"ref_seconds\":%.4f,\"ratio\":%.4f,"
        "\"ratio_adaptive\":%.4f}\n",
        path, n, phi->n[0], phi->n[1], phi->n[2], ntris, hv_backend_name(ran), hv_get_threads(),
        seconds[0], triangles[0], seconds[1], triangles[1], adaptivity[1],
        hv_peak_rss() / 1048576.0, ref_seconds, seconds[0] / ref_seconds, seconds[1] / ref_seconds);
    hv_grid_destroy(&phi);
    return HV_EXIT_OK;
}
