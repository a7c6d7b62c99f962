/* heatvox bench extend: velocity (or scalar) extension off a level set by
 * diffusion against OpenVDB's tools::sdfToExt (fast sweeping) on the same
 * input in the same process; both are compared with the exact closest-point
 * extension. */
#include "bench_ref.h"
#include "../cli.h"

#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int usage_extend(FILE *out)
{
    fprintf(out,
            "usage: heatvox bench extend --n N [--shape sphere|mesh:PATH] [--field vector|scalar]\n"
            "                            [--out-band W] [--band W] [--t-scale K] [--threads T]\n"
            "                            [--repeat R] [--backend auto|mg|fftw|opencl]\n"
            "Extends g(closest point) off a level set, g a smooth field, given only within\n"
            "3 voxels of the surface; heatvox's diffusion extension (hv_extend_many, the\n"
            "extender built once, time = best of R calls after a warm-up) against OpenVDB\n"
            "sdfToExt (time inside OpenVDB, best of R) on the same dense input.\n"
            "  sphere     [-1,1]^3 with N cells per axis, radius 0.5, exact SDF everywhere;\n"
            "             dense output (or --out-band W voxels)\n"
            "  mesh:PATH  the mesh's SDF from heatvox sdf (N cells along the longest axis)\n"
            "             clamped to +-3 voxels like a narrow-band level set; output and\n"
            "             error within 2 voxels (--out-band)\n"
            "Errors: mean relative error |f - f_exact| / |f_exact| over the output cells\n"
            "(err, ref_err; err_near and ref_err_near within 3 voxels of the surface).\n"
            "Prints one JSON line: bench, n, shape, field, backend, seconds, setup_seconds,\n"
            "ref, ref_seconds, ratio = seconds / ref_seconds, err, ref_err, ...\n");
    return out == stdout ? HV_EXIT_OK : HV_EXIT_USAGE;
}

typedef struct {
    hv_grid *phi;
    hv_grid *in[3], *ex[3]; /* input field (band only) and exact extension */
    uint8_t *eval;          /* cells where errors are measured */
    double center[3], scale;
} bench_case;

static void free_case(bench_case *b)
{
    hv_grid_destroy(&b->phi);
    for (int q = 0; q < 3; q++) {
        hv_grid_destroy(&b->in[q]);
        hv_grid_destroy(&b->ex[q]);
    }
    free(b->eval);
}

static hv_status alloc_case(bench_case *b, const int n[3], double h, const double org[3])
{
    hv_status st = hv_grid_create(&b->phi, 3, n, h, org);
    for (int q = 0; q < 3 && !st; q++)
        if (!(st = hv_grid_create(&b->in[q], 3, n, h, org)))
            st = hv_grid_create(&b->ex[q], 3, n, h, org);
    if (!st && !(b->eval = calloc(hv_grid_count(b->phi), 1)))
        st = HV_ERR_NOMEM;
    return st;
}

/* Fills the exact extension at cell c from its closest point cp, and the input
 * where |phi| < 3h. */
static void fill_cell(bench_case *b, size_t c, const double cp[3], int vec)
{
    double p[3], v[3];
    for (int a = 0; a < 3; a++)
        p[a] = (cp[a] - b->center[a]) / b->scale;
    if (vec) {
        bench_field_at(p, v);
    } else {
        v[0] = v[1] = v[2] = bench_scalar_at(p);
    }
    int band = fabs(b->phi->v[c]) < 3 * b->phi->h;
    for (int q = 0; q < 3; q++) {
        b->ex[q]->v[c] = (float)v[q];
        b->in[q]->v[c] = band ? (float)v[q] : 0.0f;
    }
}

static hv_status make_sphere(bench_case *b, int n, int vec)
{
    const double R = 0.5, c0[3] = {0.031, -0.017, 0.023};
    int ns[3] = {n, n, n};
    double org[3] = {-1, -1, -1};
    hv_status st = alloc_case(b, ns, 2.0 / n, org);
    if (st)
        return st;
    memcpy(b->center, c0, sizeof c0);
    b->scale = R;
#pragma omp parallel for collapse(2) schedule(static)
    for (int k = 0; k < n; k++)
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++) {
                size_t c = i + (size_t)n * (j + (size_t)n * k);
                double x[3], q[3], r = 0, cp[3];
                hv_grid_cell_center(b->phi, i, j, k, x);
                for (int a = 0; a < 3; a++) {
                    q[a] = x[a] - c0[a];
                    r += q[a] * q[a];
                }
                r = sqrt(r);
                b->phi->v[c] = (float)(r - R);
                for (int a = 0; a < 3; a++)
                    cp[a] = c0[a] + (r > 0 ? R * q[a] / r : (a == 0 ? R : 0));
                fill_cell(b, c, cp, vec);
                b->eval[c] = r > 0.05; /* the centre has no unique closest point */
            }
    return HV_OK;
}

/* The mesh's signed distance from heatvox sdf (exact distance, heat-method
 * sign: robust to the holes of scanned meshes, where OpenVDB's flood-fill sign
 * breaks), clamped to +-3 voxels like a narrow-band level set; closest points
 * from the unclamped field. */
static hv_status make_mesh(bench_case *b, const char *path, int n, int vec, double *sdf_seconds)
{
    hv_mesh *m = NULL;
    hv_grid *sdf = NULL;
    hv_status st = hv_mesh_read(path, &m);
    if (st)
        return st;
    hv_sdf_opts so;
    hv_sdf_opts_default(&so);
    so.res = n;
    so.pad = 6;
    double t0 = hv_now();
    st = hv_sdf_compute(m, &so, &sdf, NULL);
    *sdf_seconds = hv_now() - t0;
    double lo[3], hi[3];
    if (!st)
        st = hv_mesh_bounds(m, lo, hi);
    hv_mesh_destroy(&m);
    if (!st)
        st = alloc_case(b, sdf->n, sdf->h, sdf->origin);
    if (st) {
        hv_grid_destroy(&sdf);
        return st;
    }
    double ext = fmax(hi[0] - lo[0], fmax(hi[1] - lo[1], hi[2] - lo[2]));
    for (int a = 0; a < 3; a++)
        b->center[a] = 0.5 * (lo[a] + hi[a]);
    b->scale = 0.5 * ext;
    const int *ns = sdf->n;
    const double h = sdf->h;
    const float *p = sdf->v;
#pragma omp parallel for collapse(2) schedule(static)
    for (int k = 0; k < ns[2]; k++)
        for (int j = 0; j < ns[1]; j++)
            for (int i = 0; i < ns[0]; i++) {
                size_t c = i + (size_t)ns[0] * (j + (size_t)ns[1] * k);
                b->phi->v[c] = fmaxf(-3 * (float)h, fminf(3 * (float)h, p[c]));
            }
#pragma omp parallel for collapse(2) schedule(static)
    for (int k = 1; k < ns[2] - 1; k++)
        for (int j = 1; j < ns[1] - 1; j++)
            for (int i = 1; i < ns[0] - 1; i++) {
                size_t c = i + (size_t)ns[0] * (j + (size_t)ns[1] * k);
                const size_t s[3] = {1, (size_t)ns[0], (size_t)ns[0] * ns[1]};
                double g[3], gn = 0, x[3], cp[3];
                for (int a = 0; a < 3; a++) {
                    g[a] = (p[c + s[a]] - p[c - s[a]]) / (2 * h);
                    gn += g[a] * g[a];
                }
                gn = sqrt(gn);
                hv_grid_cell_center(sdf, i, j, k, x);
                int ok = gn > 0.9 && gn < 1.1;
                for (int a = 0; a < 3; a++)
                    cp[a] = ok ? x[a] - p[c] * g[a] / gn : x[a];
                fill_cell(b, c, cp, vec);
                b->eval[c] = (uint8_t)ok;
            }
    hv_grid_destroy(&sdf);
    return HV_OK;
}

/* Mean relative error over the eval cells (and within 3 voxels). */
static void errors(const bench_case *b, hv_grid *const out[3], int vec, double *all, double *near)
{
    double s = 0, sn = 0;
    size_t m = 0, mn = 0;
    size_t count = hv_grid_count(b->phi);
    for (size_t c = 0; c < count; c++) {
        if (!b->eval[c])
            continue;
        double d2 = 0, e2 = 0;
        for (int q = 0; q < (vec ? 3 : 1); q++) {
            double d = out[q]->v[c] - b->ex[q]->v[c];
            d2 += d * d;
            e2 += (double)b->ex[q]->v[c] * b->ex[q]->v[c];
        }
        double e = sqrt(d2 / e2);
        s += e;
        m++;
        if (fabs(b->phi->v[c]) < 3 * b->phi->h) {
            sn += e;
            mn++;
        }
    }
    *all = m ? s / m : NAN;
    *near = mn ? sn / mn : NAN;
}

/* bench extend's command line. */
typedef struct extend_args {
    int n, threads, repeat, vec;
    double out_band, band, tscale;
    const char *shape;
    hv_backend backend;
} extend_args;

/* --shape sphere|mesh:PATH */
static int take_shape(const char *cmd, const char *opt, char **v, int nv, void *dst)
{
    if (nv < 1)
        return -cli_usage_error(cmd, "%s needs 1 value", opt);
    if (strcmp(v[0], "sphere") && strncmp(v[0], "mesh:", 5))
        return -cli_usage_error(cmd, "%s needs sphere or mesh:PATH, got '%s'", opt, v[0]);
    *(const char **)dst = v[0];
    return 1;
}

static void help_extend(void) { usage_extend(stdout); }

/* -1 to go on, else the exit code. */
static int parse_extend(int argc, char **argv, extend_args *A)
{
    const cli_opt opts[] = {
        CLI_ROW_QUIET,
        {.names = "--n",
         .kind = CLI_INT,
         .dst = &A->n,
         .min = 16,
         .max = INT_MAX,
         .needs = "an integer >= 16"},
        {.names = "--shape", .kind = CLI_FN, .dst = &A->shape, .val = 1, .fn = take_shape},
        {.names = "--field",
         .kind = CLI_CHOICE,
         .dst = &A->vec,
         .choices = "scalar|vector",
         .needs = "vector or scalar"},
        CLI_ROW_BAND("--out-band", &A->out_band),
        CLI_ROW_BAND("--band", &A->band),
        CLI_ROW_T_SCALE(&A->tscale),
        CLI_ROW_THREADS(&A->threads),
        CLI_ROW_REPEAT(&A->repeat),
        CLI_ROW_BACKEND(&A->backend, CLI_BACKENDS_LOCAL),
        {.names = NULL},
    };
    const char *stray = NULL;
    int rc = cli_parse("bench extend", argc, argv, opts, "argument", &stray, help_extend);
    if (rc >= 0)
        return rc;
    if (stray)
        return cli_usage_error("bench extend", "unexpected argument '%s'", stray);
    if (!A->n)
        return cli_usage_error("bench extend", "--n is required");
    return -1;
}

/* What heatvox's extension measured: the extender built once (a
 * simulation's set-up), then timed per call. */
typedef struct extend_row {
    double setup, seconds;
    hv_extend_stats es;
} extend_row;

static int time_heatvox(const extend_args *A, const bench_case *b, hv_grid *const out[3],
                        extend_row *R)
{
    hv_extend_opts o;
    hv_extend_opts_default(&o);
    o.band = A->band;
    o.t_scale = A->tscale;
    o.out_band = A->out_band > 0 ? A->out_band : 0;
    o.backend = A->backend;
    hv_extender *e = NULL;
    double t0 = hv_now();
    hv_status st = hv_extender_create(&e, 3, b->phi->n, b->phi->h, NULL, &o);
    if (st)
        return cli_fail("bench extend", "creating the extender", st);
    hv_extend_field f = {
        A->vec ? 3 : 1, {b->in[0]->v, b->in[1]->v, b->in[2]->v}, {out[0]->v, out[1]->v, out[2]->v}};
    st = hv_extend_many(e, b->phi->v, 1, &f, &R->es);
    R->setup = hv_now() - t0;
    R->seconds = 1e30;
    for (int r = 0; r < A->repeat && !st; r++) {
        t0 = hv_now();
        st = hv_extend_many(e, b->phi->v, 1, &f, &R->es);
        R->seconds = fmin(R->seconds, hv_now() - t0);
    }
    R->setup -= R->seconds;
    hv_extender_destroy(&e);
    return st ? cli_fail("bench extend", "extending", st) : 0;
}

/* OpenVDB sdfToExt on the same input: time inside OpenVDB, best of R, and
 * the wall time around it. */
static int time_openvdb(const extend_args *A, const bench_case *b, hv_grid *const ref[3],
                        double *seconds, double *wall)
{
    *seconds = *wall = 1e30;
    const double vb = A->out_band > 0 ? A->out_band + 1 : 0; /* sdfToExt's own band, voxels */
    for (int r = 0; r < A->repeat; r++) {
        double s = 0, t0 = hv_now();
        hv_status st = A->vec ? ref_vdb_sdf_to_ext_vec3(b->phi, b->in[0], b->in[1], b->in[2], vb, 1,
                                                        0.0f, ref[0], ref[1], ref[2], &s)
                              : ref_vdb_sdf_to_ext(b->phi, b->in[0], vb, 1, 0.0f, ref[0], &s);
        if (st)
            return ref_vdb_fail("bench extend", "OpenVDB sdfToExt", st);
        *wall = fmin(*wall, hv_now() - t0);
        *seconds = fmin(*seconds, s);
    }
    return 0;
}

static void print_extend(const extend_args *A, const bench_case *b, hv_grid *const out[3],
                         hv_grid *const ref[3], const extend_row *R, double ref_seconds,
                         double ref_wall, double sdf_seconds)
{
    const int is_mesh = !strncmp(A->shape, "mesh:", 5);
    const hv_extend_stats *es = &R->es;
    double err, err_near, rerr, rerr_near;
    errors(b, out, A->vec, &err, &err_near);
    errors(b, ref, A->vec, &rerr, &rerr_near);
    printf("{\"bench\":\"extend\",\"n\":%d,\"grid\":[%d,%d,%d],\"shape\":\"%s\",\"field\":\"%s\","
           "\"output\":\"%s\",\"backend\":\"%s\",\"threads\":%d,\"band\":%g,\"t_scale\":%g,"
           "\"seconds\":%.4f,\"setup_seconds\":%.4f,\"solves\":%d,\"levels\":%d,"
           "\"weights_seconds\":%.4f,\"solve_seconds\":%.4f,\"eval_seconds\":%.4f,\"solve_cells\":%"
           "zu,\"cp_cells\":%zu,\"ratio_cells\":%zu,"
           "\"ref\":\"openvdb-sdfToExt\",\"ref_seconds\":%.4f,\"ref_wall_seconds\":%.4f,"
           "\"ratio\":%.3f,\"err\":%.3e,\"ref_err\":%.3e,\"err_near\":%.3e,\"ref_err_near\":%.3e",
           A->n, b->phi->n[0], b->phi->n[1], b->phi->n[2], is_mesh ? A->shape + 5 : "sphere",
           A->vec ? "vector" : "scalar", A->out_band > 0 ? "band" : "dense",
           hv_backend_name(A->backend), A->threads, A->band, A->tscale, R->seconds, R->setup,
           es->solves, es->levels, es->t_weights, es->t_solve, es->t_eval, es->solve_cells,
           es->cp_cells, es->ratio_cells, ref_seconds, ref_wall, R->seconds / ref_seconds, err,
           rerr, err_near, rerr_near);
    if (A->out_band > 0)
        printf(",\"out_band\":%g", A->out_band);
    if (is_mesh)
        printf(",\"sdf_seconds\":%.4f", sdf_seconds);
    cli_json_device(A->backend);
    printf("}\n");
    fflush(stdout);
}

int bench_extend(int argc, char **argv)
{
    hv_extend_opts dflt;
    hv_extend_opts_default(&dflt);
    extend_args A = {.repeat = 3,
                     .vec = 1,
                     .out_band = -1,
                     .band = dflt.band,
                     .tscale = dflt.t_scale,
                     .shape = "sphere",
                     .backend = HV_BACKEND_AUTO};
    int rc = parse_extend(argc, argv, &A);
    if (rc >= 0)
        return rc;
    hv_set_threads(A.threads);
    A.threads = hv_get_threads();
    const int is_mesh = !strncmp(A.shape, "mesh:", 5);
    if (is_mesh && A.out_band < 0)
        A.out_band = 2;

    bench_case b = {0};
    hv_grid *out[3] = {NULL, NULL, NULL}, *ref[3] = {NULL, NULL, NULL};
    double sdf_seconds = 0;
    hv_status st = is_mesh ? make_mesh(&b, A.shape + 5, A.n, A.vec, &sdf_seconds)
                           : make_sphere(&b, A.n, A.vec);
    if (st) {
        rc = cli_fail("bench extend", is_mesh ? A.shape + 5 : "building the sphere", st);
        goto done;
    }
    if (A.out_band > 0) {
        size_t count = hv_grid_count(b.phi);
        for (size_t c = 0; c < count; c++)
            if (!(fabs(b.phi->v[c]) < A.out_band * b.phi->h))
                b.eval[c] = 0;
    }
    for (int q = 0; q < 3 && !st; q++)
        if (!(st = hv_grid_create(&out[q], 3, b.phi->n, b.phi->h, b.phi->origin)))
            st = hv_grid_create(&ref[q], 3, b.phi->n, b.phi->h, b.phi->origin);
    if (st) {
        rc = cli_fail("bench extend", "allocating outputs", st);
        goto done;
    }
    extend_row R;
    double ref_seconds, ref_wall;
    if (!(rc = time_heatvox(&A, &b, out, &R)) &&
        !(rc = time_openvdb(&A, &b, ref, &ref_seconds, &ref_wall)))
        print_extend(&A, &b, out, ref, &R, ref_seconds, ref_wall, sdf_seconds);
done:
    for (int q = 0; q < 3; q++) {
        hv_grid_destroy(&out[q]);
        hv_grid_destroy(&ref[q]);
    }
    free_case(&b);
    return rc;
}
