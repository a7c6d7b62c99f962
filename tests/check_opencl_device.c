/* The public device entry (heatvox/opencl.h): a solver on the caller's
 * context and queue solves float buffers that stay on the device, and gives
 * what the host-array interface gives; wrong queues and buffers are refused. */
#include "heatvox/heatvox.h"
#include "testlib.h"

#include <check.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static cl_platform_id plat;
static cl_device_id dev;
static cl_context ctx;
static cl_command_queue queue;

/* The device heatvox would take, on a context and queue of the test's own. */
static int open_device(void)
{
    hv_opencl_device d;
    if (hv_opencl_probe(&d) != HV_OK)
        return 0;
    cl_platform_id ps[16];
    cl_uint np = 0;
    if (clGetPlatformIDs(16, ps, &np) != CL_SUCCESS || d.platform >= (int)np)
        return 0;
    plat = ps[d.platform];
    cl_device_id ds[16];
    cl_uint nd = 0;
    if (clGetDeviceIDs(plat, CL_DEVICE_TYPE_ALL, 16, ds, &nd) != CL_SUCCESS || d.device >= (int)nd)
        return 0;
    dev = ds[d.device];
    cl_int e;
    ctx = clCreateContext(NULL, 1, &dev, NULL, NULL, &e);
    if (e != CL_SUCCESS)
        return 0;
    queue = clCreateCommandQueue(ctx, dev, 0, &e);
    return e == CL_SUCCESS;
}

static cl_mem buffer(size_t n, const float *init)
{
    cl_int e;
    cl_mem m = clCreateBuffer(ctx, CL_MEM_READ_WRITE | (init ? CL_MEM_COPY_HOST_PTR : 0),
                              n * sizeof(float), (void *)init, &e);
    ck_assert_int_eq(e, CL_SUCCESS);
    return m;
}

/* A 3D problem (kind 0: a heat step; 1: Neumann Poisson around a solid ball;
 * 2: a heat step around the ball). */
static void problem(hv_problem *p, int n, int kind, uint8_t **solid)
{
    const double h = 1.0 / n;
    const int poisson = kind == 1;
    hv_problem q = {3, {n, n, n}, h, NULL, poisson ? 0.0 : 1.0, poisson ? 1.0 : 4 * h * h};
    *solid = NULL;
    if (kind > 0) {
        *solid = calloc((size_t)n * n * n, 1);
        for (int k = 0; k < n; k++)
            for (int j = 0; j < n; j++)
                for (int i = 0; i < n; i++) {
                    double x = i - n / 2 + 0.5, y = j - n / 2 + 0.5, z = k - n / 2 + 0.5;
                    (*solid)[i + (size_t)n * (j + (size_t)n * k)] =
                        x * x + y * y + z * z < n * n / 16.0;
                }
        q.solid = *solid;
    }
    *p = q;
}

static double max_rel_diff(const float *a, const float *b, size_t n)
{
    double d = 0, m = 0;
    for (size_t c = 0; c < n; c++) {
        d = fmax(d, fabs((double)a[c] - b[c]));
        m = fmax(m, fabs((double)b[c]));
    }
    return m > 0 ? d / m : d;
}

static const char *const kind_name[] = {"heat", "poisson", "masked heat"};

START_TEST(device_fields_should_give_what_host_arrays_give)
{
    for (int kind = 0; kind <= 2; kind++) {
        const int n = 32;
        const size_t count = (size_t)n * n * n;
        hv_problem p;
        uint8_t *solid;
        problem(&p, n, kind, &solid);
        float *f = malloc(count * sizeof *f), *u_host = calloc(count, sizeof *u_host),
              *u_dev = calloc(count, sizeof *u_dev);
        tl_fill_random(f, count, 7 + kind); /* nonzero on solid cells too */
        hv_solver_opts o;
        hv_solver_opts_default(&o);
        o.backend = HV_BACKEND_OPENCL;
        o.tol = 1e-8;
        hv_solver *host = NULL, *sv = NULL, *mg = NULL;
        TL_ASSERT_OK(hv_solver_create(&host, &p, &o));
        hv_solve_info hi, di;
        TL_ASSERT_OK(hv_solver_solve(host, f, u_host, &hi));
        /* The CPU multigrid on the same problem: an independent answer. */
        float *u_mg = calloc(count, sizeof *u_mg);
        hv_solver_opts om = o;
        om.backend = HV_BACKEND_MG;
        TL_ASSERT_OK(hv_solver_create(&mg, &p, &om));
        TL_ASSERT_OK(hv_solver_solve(mg, f, u_mg, NULL));
        double dm = max_rel_diff(u_host, u_mg, count);
        ck_assert_msg(dm < 1e-5, "%s: host arrays on opencl differ from mg by %g", kind_name[kind],
                      dm);
        hv_solver_destroy(&mg);
        free(u_mg);
        TL_ASSERT_OK(hv_opencl_solver_create(&sv, &p, &o, ctx, dev, queue));
        cl_context c2 = NULL;
        cl_command_queue q2 = NULL;
        TL_ASSERT_OK(hv_opencl_solver_queue(sv, &c2, NULL, &q2));
        ck_assert(c2 == ctx && q2 == queue);
        cl_mem fd = buffer(count, f), ud = buffer(count, u_dev);
        /* Twice: the fields and the solver stay; the answer does not change. */
        for (int rep = 0; rep < 2; rep++) {
            TL_ASSERT_OK(hv_opencl_solve(sv, fd, ud, &di));
            ck_assert_int_eq(di.backend, HV_BACKEND_OPENCL);
            ck_assert_msg(di.reason == HV_STOP_CONVERGED && di.relres <= 1e-8, "relres %g",
                          di.relres);
            ck_assert_int_eq(clEnqueueReadBuffer(queue, ud, CL_TRUE, 0, count * sizeof(float),
                                                 u_dev, 0, NULL, NULL),
                             CL_SUCCESS);
            double d = max_rel_diff(u_dev, u_host, count);
            ck_assert_msg(d < 1e-5, "%s: device fields differ by %g (relative)", kind_name[kind],
                          d);
            if (solid)
                for (size_t c = 0; c < count; c++)
                    ck_assert(!solid[c] || u_dev[c] == 0.0f);
        }
        clReleaseMemObject(fd);
        clReleaseMemObject(ud);
        hv_solver_destroy(&sv);
        hv_solver_destroy(&host);
        free(solid);
        free(f);
        free(u_host);
        free(u_dev);
    }
}
END_TEST

/* A heat step with solid cells on fields on the device: f is zeroed on the
 * solid cells there, not by a round trip through the host's front end. The
 * profile of a queue of the caller's shows no write from the host in the
 * solve (the PCG reads back only its few sums). */
START_TEST(masked_heat_steps_should_stay_on_the_device)
{
    const int n = 24;
    const size_t count = (size_t)n * n * n;
    hv_problem p;
    uint8_t *solid;
    problem(&p, n, 2, &solid);
    cl_int e;
    cl_command_queue pq = clCreateCommandQueue(ctx, dev, CL_QUEUE_PROFILING_ENABLE, &e);
    ck_assert_int_eq(e, CL_SUCCESS);
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.backend = HV_BACKEND_OPENCL;
    hv_solver *sv = NULL;
    TL_ASSERT_OK(hv_opencl_solver_create(&sv, &p, &o, ctx, dev, pq));
    float *f = malloc(count * sizeof *f), *u = malloc(count * sizeof *u);
    tl_fill_random(f, count, 11);
    for (size_t c = 0; c < count; c++)
        u[c] = 1.0f; /* the solve overwrites every cell, solid ones with 0 */
    cl_mem fd = buffer(count, f), ud = buffer(count, u);
    hv_opencl_kernel_time t[256];
    hv_opencl_profile_take(t, 256); /* drops what the set-up moved */
    hv_solve_info info;
    TL_ASSERT_OK(hv_opencl_solve(sv, fd, ud, &info));
    ck_assert(info.reason == HV_STOP_CONVERGED);
    const int nt = hv_opencl_profile_take(t, 256);
    ck_assert_msg(nt > 0, "the profiling queue recorded nothing");
    /* A device without fp64 (or HEATVOX_OPENCL_FP64=0) solves through the host. */
    hv_opencl_device d;
    const char *no64 = getenv("HEATVOX_OPENCL_FP64");
    const int fp64 = hv_opencl_probe(&d) == HV_OK && d.fp64 && !(no64 && !strcmp(no64, "0"));
    for (int i = 0; fp64 && i < nt && i < 256; i++)
        ck_assert_msg(strcmp(t[i].name, "write") != 0,
                      "the solve wrote to the device from the host %ld times", (long)t[i].launches);
    ck_assert_int_eq(
        clEnqueueReadBuffer(pq, ud, CL_TRUE, 0, count * sizeof(float), u, 0, NULL, NULL),
        CL_SUCCESS);
    size_t nsolid = 0;
    for (size_t c = 0; c < count; c++)
        if (solid[c]) {
            nsolid++;
            ck_assert_msg(u[c] == 0.0f, "solid cell %zu holds %g", c, (double)u[c]);
        }
    ck_assert_uint_gt(nsolid, 0);
    clReleaseMemObject(fd);
    clReleaseMemObject(ud);
    hv_solver_destroy(&sv);
    clReleaseCommandQueue(pq);
    free(solid);
    free(f);
    free(u);
}
END_TEST

START_TEST(a_solver_of_hv_solver_create_should_take_buffers_on_its_own_context)
{
    const int n = 16;
    const size_t count = (size_t)n * n * n;
    hv_problem p;
    uint8_t *solid;
    problem(&p, n, 0, &solid);
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.backend = HV_BACKEND_OPENCL;
    hv_solver *sv = NULL;
    TL_ASSERT_OK(hv_solver_create(&sv, &p, &o));
    cl_context c = NULL;
    cl_command_queue q = NULL;
    TL_ASSERT_OK(hv_opencl_solver_queue(sv, &c, NULL, &q));
    float *f = malloc(count * sizeof *f), *u = calloc(count, sizeof *u);
    tl_fill_random(f, count, 3);
    cl_int e;
    cl_mem fd =
        clCreateBuffer(c, CL_MEM_READ_WRITE | CL_MEM_COPY_HOST_PTR, count * sizeof(float), f, &e);
    cl_mem ud = clCreateBuffer(c, CL_MEM_READ_WRITE, count * sizeof(float), NULL, &e);
    hv_solve_info info;
    TL_ASSERT_OK(hv_opencl_solve(sv, fd, ud, &info));
    ck_assert(info.reason == HV_STOP_CONVERGED);
    /* A buffer of another context is refused. */
    cl_mem other = buffer(count, NULL);
    ck_assert_int_eq(hv_opencl_solve(sv, other, ud, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "another context"));
    clReleaseMemObject(other);
    clReleaseMemObject(fd);
    clReleaseMemObject(ud);
    hv_solver_destroy(&sv);
    free(f);
    free(u);
}
END_TEST

START_TEST(wrong_queues_buffers_and_backends_should_be_refused)
{
    const int n = 16;
    const size_t count = (size_t)n * n * n;
    hv_problem p;
    uint8_t *solid;
    problem(&p, n, 0, &solid);
    hv_solver *sv = NULL;
    /* A queue of another context. */
    cl_int e;
    cl_context other = clCreateContext(NULL, 1, &dev, NULL, NULL, &e);
    ck_assert_int_eq(e, CL_SUCCESS);
    cl_command_queue oq = clCreateCommandQueue(other, dev, 0, &e);
    ck_assert_int_eq(e, CL_SUCCESS);
    ck_assert_int_eq(hv_opencl_solver_create(&sv, &p, NULL, ctx, dev, oq), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "another context"));
    ck_assert_ptr_null(sv);
    clReleaseCommandQueue(oq);
    clReleaseContext(other);
    /* An out-of-order queue, where the device offers one. */
    cl_command_queue ooo =
        clCreateCommandQueue(ctx, dev, CL_QUEUE_OUT_OF_ORDER_EXEC_MODE_ENABLE, &e);
    if (e == CL_SUCCESS) {
        ck_assert_int_eq(hv_opencl_solver_create(&sv, &p, NULL, ctx, dev, ooo), HV_ERR_INVALID_ARG);
        ck_assert_ptr_nonnull(strstr(hv_last_error(), "in-order"));
        clReleaseCommandQueue(ooo);
    }
    ck_assert_int_eq(hv_opencl_solver_create(&sv, &p, NULL, NULL, dev, queue), HV_ERR_INVALID_ARG);
    /* A buffer too small. */
    TL_ASSERT_OK(hv_opencl_solver_create(&sv, &p, NULL, ctx, dev, queue));
    cl_mem small = buffer(count - 1, NULL), ud = buffer(count, NULL);
    ck_assert_int_eq(hv_opencl_solve(sv, small, ud, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "bytes"));
    clReleaseMemObject(small);
    clReleaseMemObject(ud);
    hv_solver_destroy(&sv);
    /* A solver of another backend. */
    hv_solver_opts o;
    hv_solver_opts_default(&o);
    o.backend = HV_BACKEND_MG;
    TL_ASSERT_OK(hv_solver_create(&sv, &p, &o));
    cl_mem a = buffer(count, NULL), b = buffer(count, NULL);
    ck_assert_int_eq(hv_opencl_solve(sv, a, b, NULL), HV_ERR_UNSUPPORTED);
    ck_assert_int_eq(hv_opencl_solver_queue(sv, NULL, NULL, NULL), HV_ERR_UNSUPPORTED);
    clReleaseMemObject(a);
    clReleaseMemObject(b);
    hv_solver_destroy(&sv);
}
END_TEST

/* phi of a sphere (signed distance) and a vector field that varies, on n^3. */
static void sphere_case(int n, float *phi, float *v[3])
{
    const double h = 1.0 / n;
    for (int k = 0; k < n; k++)
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++) {
                const size_t c = i + (size_t)n * (j + (size_t)n * k);
                const double x = (i + 0.5) * h - 0.5, y = (j + 0.5) * h - 0.45,
                             z = (k + 0.5) * h - 0.55;
                phi[c] = (float)(sqrt(x * x + y * y + z * z) - 0.3);
                v[0][c] = (float)(1 + x);
                v[1][c] = (float)(y * z);
                v[2][c] = (float)(0.5 - x * y);
            }
}

START_TEST(an_extender_on_the_callers_context_should_extend_fields_on_the_device)
{
    const int n = 32, N[3] = {n, n, n};
    const size_t count = (size_t)n * n * n;
    float *phi = malloc(count * sizeof *phi), *v[3], *host[3], *dev_out = malloc(count * 4);
    for (int a = 0; a < 3; a++) {
        v[a] = malloc(count * sizeof(float));
        host[a] = malloc(count * sizeof(float));
    }
    sphere_case(n, phi, v);
    hv_extend_opts o;
    hv_extend_opts_default(&o);
    o.backend = HV_BACKEND_OPENCL;
    /* The host arrays on the device path: the reference. */
    hv_extender *he = NULL, *de = NULL;
    TL_ASSERT_OK(hv_extender_create(&he, 3, N, 1.0 / n, NULL, &o));
    hv_extend_field hf = {3, {v[0], v[1], v[2]}, {host[0], host[1], host[2]}};
    TL_ASSERT_OK(hv_extend_many(he, phi, 1, &hf, NULL));
    /* Fields on the device, on the test's context; twice, the second in place. */
    TL_ASSERT_OK(hv_opencl_extender_create(&de, 3, N, 1.0 / n, NULL, &o, ctx, dev, queue));
    cl_context c2 = NULL;
    TL_ASSERT_OK(hv_opencl_extender_queue(de, &c2, NULL, NULL));
    ck_assert(c2 == ctx);
    cl_mem pd = buffer(count, phi), in[3], out[3];
    for (int a = 0; a < 3; a++) {
        in[a] = buffer(count, v[a]);
        out[a] = buffer(count, NULL);
    }
    for (int rep = 0; rep < 2; rep++) {
        hv_opencl_field df = {3, {in[0], in[1], in[2]}, {out[0], out[1], out[2]}};
        if (rep == 1)
            memcpy(df.out, df.in, sizeof df.in);
        hv_extend_stats S;
        TL_ASSERT_OK(hv_opencl_extend(de, pd, 1, &df, &S));
        ck_assert_int_gt(S.solves, 0);
        for (int a = 0; a < 3; a++) {
            ck_assert_int_eq(clEnqueueReadBuffer(queue, df.out[a], CL_TRUE, 0, count * 4, dev_out,
                                                 0, NULL, NULL),
                             CL_SUCCESS);
            double d = max_rel_diff(dev_out, host[a], count);
            ck_assert_msg(d < 1e-5, "component %d (run %d): device differs by %g", a, rep, d);
        }
    }
    /* A buffer of another context, an extender on the CPU. */
    cl_int e;
    cl_context other = clCreateContext(NULL, 1, &dev, NULL, NULL, &e);
    cl_mem po = clCreateBuffer(other, CL_MEM_READ_WRITE, count * 4, NULL, &e);
    hv_opencl_field df = {3, {in[0], in[1], in[2]}, {out[0], out[1], out[2]}};
    ck_assert_int_eq(hv_opencl_extend(de, po, 1, &df, NULL), HV_ERR_INVALID_ARG);
    ck_assert_ptr_nonnull(strstr(hv_last_error(), "another context"));
    clReleaseMemObject(po);
    clReleaseContext(other);
    hv_extender *ce = NULL;
    o.backend = HV_BACKEND_MG;
    TL_ASSERT_OK(hv_extender_create(&ce, 3, N, 1.0 / n, NULL, &o));
    ck_assert_int_eq(hv_opencl_extend(ce, pd, 1, &df, NULL), HV_ERR_UNSUPPORTED);
    hv_extender_destroy(&ce);
    clReleaseMemObject(pd);
    for (int a = 0; a < 3; a++) {
        clReleaseMemObject(in[a]);
        clReleaseMemObject(out[a]);
        free(v[a]);
        free(host[a]);
    }
    hv_extender_destroy(&de);
    hv_extender_destroy(&he);
    free(phi);
    free(dev_out);
}
END_TEST

/* A number after "key": in a JSON line, or -1 when absent. */
static double json_num(const char *line, const char *key)
{
    char pat[64];
    snprintf(pat, sizeof pat, "\"%s\":", key);
    const char *p = strstr(line, pat);
    return p ? atof(p + strlen(pat)) : -1;
}

START_TEST(bench_solve_should_report_the_device_and_its_own_figures)
{
    const char *bin = tl_heatvox_bin();
    ck_assert_msg(bin != NULL, "build/heatvox not found (set HEATVOX_BIN)");
    char cmd[4200], line[8192] = "";
    /* With baffles (PCG, many iterations), so that the device solves the same problem. */
    snprintf(cmd, sizeof cmd,
             "'%s' bench solve --n 24 --poisson --obstacle baffles --backend opencl --repeat 1",
             bin);
    FILE *pp = popen(cmd, "r");
    ck_assert_ptr_nonnull(pp);
    ck_assert_ptr_nonnull(fgets(line, sizeof line, pp));
    ck_assert_int_eq(pclose(pp), 0);
    ck_assert_msg(strstr(line, "\"device\":\""), "%s", line);
    const char *keys[] = {"device_seconds", "device_event_seconds", "transfer_seconds",
                          "dev_copy_gbs",   "dev_solve_gbs",        "host_vs_device"};
    for (size_t k = 0; k < sizeof keys / sizeof keys[0]; k++)
        ck_assert_msg(json_num(line, keys[k]) > 0, "%s missing or not positive: %s", keys[k], line);
    ck_assert_msg(json_num(line, "device_relres") <= 1e-6, "%s", line);
    ck_assert_int_eq((int)json_num(line, "device_iterations"), (int)json_num(line, "iterations"));
    ck_assert_msg(json_num(line, "iterations") > 6, "baffles solved in too few iterations: %s",
                  line);
    /* the kernels' own time, from the benchmark's profiling queue: within the solve's */
    const double ks = json_num(line, "dev_kernel_seconds");
    ck_assert_msg(ks > 0 && ks <= json_num(line, "device_event_seconds") * 1.05, "%s", line);
    ck_assert_msg(json_num(line, "dev_launches") > 10 * json_num(line, "iterations"), "%s", line);
    ck_assert_msg(json_num(line, "dev_kernel_gbs") >= json_num(line, "dev_solve_gbs"), "%s", line);
}
END_TEST

/* The whole stdout of `env ENV heatvox ARGS` into out. */
static int run_out(const char *env, const char *args, char *out, size_t size)
{
    char cmd[4500];
    snprintf(cmd, sizeof cmd, "env %s '%s' %s", env, tl_heatvox_bin(), args);
    FILE *pp = popen(cmd, "r");
    ck_assert_ptr_nonnull(pp);
    size_t n = fread(out, 1, size - 1, pp);
    out[n] = 0;
    return pclose(pp);
}

/* HEATVOX_OPENCL_PROFILE=1: one kernel line per kernel and transfer after the
 * benchmark's line, the V-cycle's kernels among them, shares summing to 1. */
START_TEST(bench_profile_should_time_each_kernel_on_the_device)
{
    char out[16384];
    ck_assert_int_eq(run_out("HEATVOX_OPENCL_PROFILE=1",
                             "bench solve --n 24 --backend opencl "
                             "--repeat 1",
                             out, sizeof out),
                     0);
    int lines = 0, cheb = 0;
    double share = 0;
    for (char *l = strstr(out, "{\"bench\":\"kernel\""); l;
         l = strstr(l + 1, "{\"bench\":\"kernel\"")) {
        lines++;
        ck_assert_msg(strstr(l, "\"of\":\"solve\""), "%.200s", l);
        ck_assert_msg(json_num(l, "launches") > 0 && json_num(l, "seconds") >= 0, "%.200s", l);
        share += json_num(l, "share");
        cheb += !strncmp(strstr(l, "\"name\":"), "\"name\":\"mg_cheb\"", 16);
    }
    ck_assert_msg(lines >= 5 && cheb == 1, "%d kernel lines, mg_cheb %d:\n%s", lines, cheb, out);
    ck_assert_msg(fabs(share - 1) < 0.01, "shares sum to %g", share);
    ck_assert_int_eq(run_out("HEATVOX_OPENCL_PROFILE=",
                             "bench solve --n 24 --backend opencl "
                             "--repeat 1",
                             out, sizeof out),
                     0);
    ck_assert_msg(!strstr(out, "\"kernel\""), "%s", out);
}
END_TEST

START_TEST(devices_should_say_what_auto_takes_and_why)
{
    hv_opencl_device d;
    TL_ASSERT_OK(hv_opencl_probe(&d));
    char out[8192];
    ck_assert_int_eq(run_out("HEATVOX_AUTO_OPENCL=", "devices", out, sizeof out), 0);
    if (d.gpu)
        ck_assert_msg(strstr(out, "auto: opencl") && strstr(out, "is a GPU"), "%s", out);
    else
        ck_assert_msg(strstr(out, "auto: the CPU") && strstr(out, "is not a GPU"), "%s", out);
    ck_assert_int_eq(run_out("HEATVOX_AUTO_OPENCL=1", "devices", out, sizeof out), 0);
    ck_assert_msg(strstr(out, "auto: opencl") && strstr(out, "any size"), "%s", out);
    ck_assert_int_eq(run_out("HEATVOX_AUTO_OPENCL=0", "devices --json", out, sizeof out), 0);
    ck_assert_msg(strstr(out, "{\"auto\":\"cpu\"") && strstr(out, "HEATVOX_AUTO_OPENCL=0"), "%s",
                  out);
}
END_TEST

START_TEST(commands_on_the_device_should_name_it)
{
    hv_opencl_device d;
    TL_ASSERT_OK(hv_opencl_probe(&d));
    char dir[] = "/tmp/hv_check_opencl_device_XXXXXX", args[600], out[8192], want[200];
    ck_assert_ptr_nonnull(mkdtemp(dir));
    snprintf(args, sizeof args, "%s/src.txt", dir);
    FILE *f = fopen(args, "w");
    fputs("0 0 0\n", f);
    fclose(f);
    snprintf(want, sizeof want, "\"device\":\"%s\"", d.name);
    snprintf(
        args, sizeof args,
        "distance --sources %s/src.txt --obstacles none --res 16 --bbox -1 -1 -1 1 1 1 -o %s/d.vdb "
        "--backend opencl",
        dir, dir);
    ck_assert_int_eq(run_out("X=", args, out, sizeof out), 0);
    ck_assert_msg(strstr(out, want), "%s", out);
    ck_assert_int_eq(run_out("X=", "bench extend --n 16 --backend opencl", out, sizeof out), 0);
    ck_assert_msg(strstr(out, want), "%s", out);
    snprintf(
        args, sizeof args,
        "distance --sources %s/src.txt --obstacles none --res 16 --bbox -1 -1 -1 1 1 1 -o %s/d.vdb",
        dir, dir);
    ck_assert_int_eq(run_out("X=", args, out, sizeof out), 0);
    ck_assert_msg(!strstr(out, "\"device\""), "%s", out);
    tl_rm_rf(dir);
}
END_TEST

int main(int argc, char **argv)
{
    (void)argc;
    tl_pocl_cache(argv[0]);
    Suite *s = suite_create("opencl_device");
    TCase *tc = tcase_create("device");
    tcase_set_timeout(tc, 300);
    const int have = open_device();
    const char *why = "no OpenCL device";
    TL_ADD_IF(tc, device_fields_should_give_what_host_arrays_give, have, why);
    TL_ADD_IF(tc, masked_heat_steps_should_stay_on_the_device, have, why);
    TL_ADD_IF(tc, a_solver_of_hv_solver_create_should_take_buffers_on_its_own_context, have, why);
    TL_ADD_IF(tc, wrong_queues_buffers_and_backends_should_be_refused, have, why);
    TL_ADD_IF(tc, bench_solve_should_report_the_device_and_its_own_figures, have, why);
    TL_ADD_IF(tc, bench_profile_should_time_each_kernel_on_the_device, have, why);
    TL_ADD_IF(tc, devices_should_say_what_auto_takes_and_why, have, why);
    TL_ADD_IF(tc, commands_on_the_device_should_name_it, have, why);
    TL_ADD_IF(tc, an_extender_on_the_callers_context_should_extend_fields_on_the_device, have, why);
    suite_add_tcase(s, tc);
    int rc = tl_run(s);
    if (queue)
        clReleaseCommandQueue(queue);
    if (ctx)
        clReleaseContext(ctx);
    return rc;
}
