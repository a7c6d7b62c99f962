/* advect_band_cl: a level-set simulation that keeps a narrow band in 8^3
 * tiles on an OpenCL device and extends its velocity off the interface every
 * time step with heatvox, without the fields leaving the device (opencl.h,
 * hv_opencl_extend_tiles).
 *
 *   make build/examples/advect_band_cl
 *   build/examples/advect_band_cl [--n N] [--steps S]
 *
 * A sphere of radius 0.2 in the unit box moves with the velocity (0.3, 0.1,
 * 0.05). Its level set lives on the tiles that the band crosses on its way
 * (the tiles are set up once; each step the active voxels follow |phi| <
 * 3 h), as device buffers on the program's own context and queue. As in a
 * two-phase flow solver the velocity is known only at the interface (|phi| <
 * 1.5 h); everywhere else the buffers hold a stale 0. Each step, on the
 * device:
 *   1. the interface cells get the flow's velocity, the others the stale 0;
 *   2. hv_opencl_extend_tiles carries it off the interface to the band's
 *      active voxels, in place (one extender, made before the loop, on the
 *      program's context);
 *   3. phi is advected semi-Lagrangian (each cell takes phi trilinearly at
 *      x - dt v, v the extended velocity at the cell), clamped to +-3 h off
 *      the band, and the active voxels renewed.
 * At the end the program reads phi and the velocity back once and prints the
 * sphere's centre (the centroid of phi < 0) and its volume (a smeared
 * Heaviside of phi) against the exact ones, the largest deviation of the
 * extended velocity from the flow's on the band, and what heatvox moved
 * between host and device per step (with HEATVOX_OPENCL_PROFILE=1: the
 * queue is made with profiling, and only the few counters heatvox reads per
 * level cross). It exits 1 when the centre is off by more than half a voxel,
 * the volume by more than 3% or the velocity by more than 1e-4 (relative).
 * --kernels prints the program's OpenCL C source (plain OpenCL C 1.2). */
#include <heatvox/heatvox.h>

#include <CL/cl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define T3 512
#define BAND 3.0     /* the level set's band: active where |phi| < BAND h */
#define SOURCE 1.5   /* the velocity is known where |phi| < SOURCE h */
#define RADIUS 0.2

static const double U[3] = {0.3, 0.1, 0.05};
static const double C0[3] = {0.32, 0.4, 0.42};

static const char *kernels =
    "/* Tiles: cell (i, j, k) of tile t at t * 512 + i + 8 j + 64 k; active\n"
    " * words: 16 uint per tile, bit 8 (j & 3) + i of word 2 k + (j >> 2). */\n"
    "__kernel void set_velocity(ulong cells, float known, float ux, float uy, float uz,\n"
    "                           __global const float *phi, __global float *vx,\n"
    "                           __global float *vy, __global float *vz)\n"
    "{\n"
    "    const size_t c = get_global_id(0);\n"
    "    if (c >= cells)\n"
    "        return;\n"
    "    const int in = fabs(phi[c]) < known;\n"
    "    vx[c] = in ? ux : 0.0f;\n"
    "    vy[c] = in ? uy : 0.0f;\n"
    "    vz[c] = in ? uz : 0.0f;\n"
    "}\n"
    "\n"
    "/* phi at cell (i, j, k), clamped to the block; outside the tiles the\n"
    " * background with the sign of ref. */\n"
    "static float phi_at(__global const int *map, __global const float *phi, int4 N, int4 TN,\n"
    "                    float bg, int i, int j, int k, float ref)\n"
    "{\n"
    "    i = clamp(i, 0, N.x - 1);\n"
    "    j = clamp(j, 0, N.y - 1);\n"
    "    k = clamp(k, 0, N.z - 1);\n"
    "    const int t = map[(i >> 3) + TN.x * ((j >> 3) + TN.y * (k >> 3))];\n"
    "    if (!t)\n"
    "        return copysign(bg, ref);\n"
    "    return phi[(size_t)(t - 1) * 512 + (i & 7) + 8 * (j & 7) + 64 * (k & 7)];\n"
    "}\n"
    "\n"
    "/* The tile cell of (i, j, k) with an extended velocity (active in von):\n"
    " * the cell itself, else its first such neighbour (a clamped cell next\n"
    " * to the band, which the band grows into); -1 none. */\n"
    "static long moving(__global const int *map, __global const uint *von, int4 N, int4 TN,\n"
    "                   int i, int j, int k)\n"
    "{\n"
    "    const int d[7][3] = {{0, 0, 0}, {-1, 0, 0}, {1, 0, 0}, {0, -1, 0},\n"
    "                         {0, 1, 0}, {0, 0, -1}, {0, 0, 1}};\n"
    "    for (int q = 0; q < 7; q++) {\n"
    "        const int a = i + d[q][0], b = j + d[q][1], c = k + d[q][2];\n"
    "        if (a < 0 || b < 0 || c < 0 || a >= N.x || b >= N.y || c >= N.z)\n"
    "            continue;\n"
    "        const int t = map[(a >> 3) + TN.x * ((b >> 3) + TN.y * (c >> 3))];\n"
    "        const int o = (a & 7) + 8 * (b & 7) + 64 * (c & 7);\n"
    "        if (t && (von[16 * (size_t)(t - 1) + (o >> 5)] >> (o & 31) & 1))\n"
    "            return (long)(t - 1) * 512 + o;\n"
    "    }\n"
    "    return -1;\n"
    "}\n"
    "\n"
    "/* One work-group of 64 per tile, a row of 8 cells each. */\n"
    "__kernel void advect(int4 N, int4 TN, float step, float bg, int mark,\n"
    "                     __global const int *ijk,\n"
    "                     __global const int *map, __global const float *phi,\n"
    "                     __global const float *vx, __global const float *vy,\n"
    "                     __global const float *vz, __global const uint *von,\n"
    "                     __global float *out, __global uint *on)\n"
    "{\n"
    "    const size_t t = get_group_id(0);\n"
    "    const int l = get_local_id(0), jj = l & 7, kk = l >> 3;\n"
    "    const int j = ijk[3 * t + 1] + jj, k = ijk[3 * t + 2] + kk;\n"
    "    uint bits = 0;\n"
    "    for (int ii = 0; ii < 8; ii++) {\n"
    "        const int i = ijk[3 * t] + ii;\n"
    "        const size_t c = t * 512 + ii + 8 * jj + 64 * kk;\n"
    "        const float p = phi[c];\n"
    "        const long m = moving(map, von, N, TN, i, j, k);\n"
    "        const float ux = m < 0 ? 0.0f : vx[m], uy = m < 0 ? 0.0f : vy[m],\n"
    "                    uz = m < 0 ? 0.0f : vz[m];\n"
    "        const float x = i - step * ux, y = j - step * uy, z = k - step * uz;\n"
    "        const int fx = (int)floor(x), fy = (int)floor(y), fz = (int)floor(z);\n"
    "        const float ax = x - fx, ay = y - fy, az = z - fz;\n"
    "        float v = 0;\n"
    "        for (int q = 0; q < 8; q++) {\n"
    "            const int dx = q & 1, dy = (q >> 1) & 1, dz = q >> 2;\n"
    "            const float w = (dx ? ax : 1 - ax) * (dy ? ay : 1 - ay) * (dz ? az : 1 - az);\n"
    "            v += w * phi_at(map, phi, N, TN, bg, fx + dx, fy + dy, fz + dz, p);\n"
    "        }\n"
    "        v = clamp(v, -bg, bg);\n"
    "        out[c] = v;\n"
    "        if (i < N.x && j < N.y && k < N.z && fabs(v) < bg)\n"
    "            bits |= 1u << (8 * (jj & 3) + ii);\n"
    "    }\n"
    "    /* four rows share a word: each ors its byte in */\n"
    "    __global uint *w = &on[16 * t + 2 * kk + (jj >> 2)];\n"
    "    if (mark && bits)\n"
    "        atomic_or(w, bits);\n"
    "}\n"
    "\n"
    "/* BFECC's corrected start: out = phi + (phi - back) / 2, in the band. */\n"
    "__kernel void correct(ulong cells, float bg, __global const float *phi,\n"
    "                      __global const float *back, __global float *out)\n"
    "{\n"
    "    const size_t c = get_global_id(0);\n"
    "    if (c < cells)\n"
    "        out[c] = clamp(phi[c] + 0.5f * (phi[c] - back[c]), -bg, bg);\n"
    "}\n";

typedef struct {
    cl_context ctx;
    cl_device_id dev;
    cl_command_queue q;
    cl_program prog;
    cl_kernel kv, ka, kc;
} device;

static int fail(const char *what, cl_int e)
{
    fprintf(stderr, "advect_band_cl: %s failed (OpenCL error %d)\n", what, e);
    return 1;
}

/* The device heatvox would take (HEATVOX_OPENCL_DEVICE), on a context and
 * in-order queue of the program's own. */
static int open_device(device *d)
{
    hv_opencl_device info;
    if (hv_opencl_probe(&info) != HV_OK) {
        fprintf(stderr, "advect_band_cl: no OpenCL device: %s\n", hv_last_error());
        return 1;
    }
    cl_platform_id ps[16];
    cl_device_id ds[16];
    cl_uint np = 0, nd = 0;
    cl_int e = clGetPlatformIDs(16, ps, &np);
    if (e != CL_SUCCESS || info.platform >= (int)np)
        return fail("clGetPlatformIDs", e);
    e = clGetDeviceIDs(ps[info.platform], CL_DEVICE_TYPE_ALL, 16, ds, &nd);
    if (e != CL_SUCCESS || info.device >= (int)nd)
        return fail("clGetDeviceIDs", e);
    d->dev = ds[info.device];
    d->ctx = clCreateContext(NULL, 1, &d->dev, NULL, NULL, &e);
    if (e != CL_SUCCESS)
        return fail("clCreateContext", e);
    const char *prof = getenv("HEATVOX_OPENCL_PROFILE");
    d->q = clCreateCommandQueue(d->ctx, d->dev,
                                prof && *prof == '1' ? CL_QUEUE_PROFILING_ENABLE : 0, &e);
    if (e != CL_SUCCESS)
        return fail("clCreateCommandQueue", e);
    d->prog = clCreateProgramWithSource(d->ctx, 1, &kernels, NULL, &e);
    if (e != CL_SUCCESS)
        return fail("clCreateProgramWithSource", e);
    if ((e = clBuildProgram(d->prog, 1, &d->dev, "-cl-std=CL1.2", NULL, NULL)) != CL_SUCCESS) {
        char log[4096] = "";
        clGetProgramBuildInfo(d->prog, d->dev, CL_PROGRAM_BUILD_LOG, sizeof log - 1, log, NULL);
        fprintf(stderr, "advect_band_cl: the kernels do not build:\n%s\n", log);
        return 1;
    }
    d->kv = clCreateKernel(d->prog, "set_velocity", &e);
    if (e == CL_SUCCESS)
        d->ka = clCreateKernel(d->prog, "advect", &e);
    if (e == CL_SUCCESS)
        d->kc = clCreateKernel(d->prog, "correct", &e);
    if (e != CL_SUCCESS)
        return fail("clCreateKernel", e);
    printf("advect_band_cl: %s (%s)\n", info.name, info.platform_name);
    return 0;
}

static void close_device(device *d)
{
    if (d->kv)
        clReleaseKernel(d->kv);
    if (d->ka)
        clReleaseKernel(d->ka);
    if (d->kc)
        clReleaseKernel(d->kc);
    if (d->prog)
        clReleaseProgram(d->prog);
    if (d->q)
        clReleaseCommandQueue(d->q);
    if (d->ctx)
        clReleaseContext(d->ctx);
}

/* The level set on the host before the loop: the tiles within reach of the
 * band along the sphere's path from C0 to c1, the sphere's distance clamped
 * to the band, active where |phi| < BAND h. */
typedef struct {
    int n;
    double h;
    size_t count;
    int32_t *ijk;
    float *phi;
    uint64_t *on;
    int32_t *map; /* per tile of the block: tile + 1, 0 none */
} band;

static double seg_dist(const double p[3], const double a[3], const double b[3])
{
    double ab[3], ap[3], l2 = 0, s = 0;
    for (int q = 0; q < 3; q++) {
        ab[q] = b[q] - a[q];
        ap[q] = p[q] - a[q];
        l2 += ab[q] * ab[q];
        s += ab[q] * ap[q];
    }
    s = l2 > 0 ? fmin(1, fmax(0, s / l2)) : 0;
    double d2 = 0;
    for (int q = 0; q < 3; q++)
        d2 += (ap[q] - s * ab[q]) * (ap[q] - s * ab[q]);
    return sqrt(d2);
}

static int make_band(band *b, int n, const double c1[3])
{
    memset(b, 0, sizeof *b);
    b->n = n;
    b->h = 1.0 / n;
    const int tn = (n + 7) / 8;
    const size_t nt = (size_t)tn * tn * tn;
    b->ijk = malloc(3 * nt * sizeof *b->ijk);
    b->map = calloc(nt, sizeof *b->map);
    if (!b->ijk || !b->map)
        return 1;
    const double reach = (BAND + 8 * sqrt(3.0)) * b->h;
    for (int k = 0; k < tn; k++)
        for (int j = 0; j < tn; j++)
            for (int i = 0; i < tn; i++) {
                const double p[3] = {(8 * i + 4) * b->h, (8 * j + 4) * b->h, (8 * k + 4) * b->h};
                if (seg_dist(p, C0, c1) - RADIUS > reach)
                    continue; /* the tiles the sphere never nears (its inside is kept) */
                b->ijk[3 * b->count] = 8 * i;
                b->ijk[3 * b->count + 1] = 8 * j;
                b->ijk[3 * b->count + 2] = 8 * k;
                b->map[i + tn * (j + (size_t)tn * k)] = (int32_t)++b->count;
            }
    b->phi = malloc(b->count * T3 * sizeof *b->phi);
    b->on = calloc(8 * b->count, sizeof *b->on);
    if (!b->phi || !b->on)
        return 1;
    const double bg = BAND * b->h;
    for (size_t t = 0; t < b->count; t++)
        for (int o = 0; o < T3; o++) {
            const int c[3] = {b->ijk[3 * t] + (o & 7), b->ijk[3 * t + 1] + (o >> 3 & 7),
                              b->ijk[3 * t + 2] + (o >> 6)};
            double r = 0;
            for (int q = 0; q < 3; q++)
                r += ((c[q] + 0.5) * b->h - C0[q]) * ((c[q] + 0.5) * b->h - C0[q]);
            const double p = fmax(-bg, fmin(bg, sqrt(r) - RADIUS));
            b->phi[t * T3 + o] = (float)p;
            if (c[0] < n && c[1] < n && c[2] < n && fabs(p) < bg)
                b->on[8 * t + (o >> 6)] |= 1ull << (o & 63);
        }
    return 0;
}

static void free_band(band *b)
{
    free(b->ijk);
    free(b->phi);
    free(b->on);
    free(b->map);
}

static cl_mem buffer(device *d, size_t bytes, const void *init, cl_int *e)
{
    return clCreateBuffer(d->ctx, CL_MEM_READ_WRITE | (init ? CL_MEM_COPY_HOST_PTR : 0), bytes,
                          (void *)init, e);
}

/* The buffers of the simulation, all on the device. */
typedef struct {
    cl_mem ijk, map, phi[2], tmp, on, v[3], von[3];
} fields;

static int make_fields(device *d, const band *b, fields *f)
{
    cl_int e = CL_SUCCESS, e2 = CL_SUCCESS;
    const size_t tn = (size_t)(b->n + 7) / 8, vb = b->count * T3 * sizeof(float),
                 ob = 8 * b->count * sizeof(uint64_t);
    memset(f, 0, sizeof *f);
    f->ijk = buffer(d, 3 * b->count * sizeof(int32_t), b->ijk, &e);
    if (e == CL_SUCCESS)
        f->map = buffer(d, tn * tn * tn * sizeof(int32_t), b->map, &e);
    if (e == CL_SUCCESS)
        f->phi[0] = buffer(d, vb, b->phi, &e);
    if (e == CL_SUCCESS)
        f->phi[1] = buffer(d, vb, NULL, &e);
    if (e == CL_SUCCESS)
        f->tmp = buffer(d, vb, NULL, &e);
    if (e == CL_SUCCESS)
        f->on = buffer(d, ob, b->on, &e);
    for (int q = 0; q < 3 && e == CL_SUCCESS && e2 == CL_SUCCESS; q++) {
        f->v[q] = buffer(d, vb, NULL, &e);
        f->von[q] = buffer(d, ob, NULL, &e2);
    }
    return e != CL_SUCCESS ? fail("clCreateBuffer", e) : e2 != CL_SUCCESS ? fail("clCreateBuffer", e2) : 0;
}

static void free_fields(fields *f)
{
    cl_mem all[] = {f->ijk, f->map, f->phi[0], f->phi[1], f->tmp, f->on,
                    f->v[0], f->v[1], f->v[2], f->von[0], f->von[1], f->von[2]};
    for (size_t i = 0; i < sizeof all / sizeof all[0]; i++)
        if (all[i])
            clReleaseMemObject(all[i]);
}

/* phi in advected semi-Lagrangian by dt into out (mark: its active voxels
 * into the level set's words). */
static cl_int advect(device *d, const band *b, fields *f, cl_mem in, cl_mem out, double dt,
                     int mark)
{
    const int tn = (b->n + 7) / 8;
    const cl_int N[4] = {b->n, b->n, b->n, 0}, TN[4] = {tn, tn, tn, 0}, mk = mark;
    const cl_float stepv = (cl_float)(dt / b->h), bg = (cl_float)(BAND * b->h);
    cl_int err = clSetKernelArg(d->ka, 0, sizeof N, N);
    err |= clSetKernelArg(d->ka, 1, sizeof TN, TN);
    err |= clSetKernelArg(d->ka, 2, sizeof stepv, &stepv);
    err |= clSetKernelArg(d->ka, 3, sizeof bg, &bg);
    err |= clSetKernelArg(d->ka, 4, sizeof mk, &mk);
    err |= clSetKernelArg(d->ka, 5, sizeof(cl_mem), &f->ijk);
    err |= clSetKernelArg(d->ka, 6, sizeof(cl_mem), &f->map);
    err |= clSetKernelArg(d->ka, 7, sizeof(cl_mem), &in);
    for (int q = 0; q < 3; q++)
        err |= clSetKernelArg(d->ka, 8 + q, sizeof(cl_mem), &f->v[q]);
    err |= clSetKernelArg(d->ka, 11, sizeof(cl_mem), &f->von[0]);
    err |= clSetKernelArg(d->ka, 12, sizeof(cl_mem), &out);
    err |= clSetKernelArg(d->ka, 13, sizeof(cl_mem), &f->on);
    const size_t g = b->count * 64, l = 64;
    if (err == CL_SUCCESS)
        err = clEnqueueNDRangeKernel(d->q, d->ka, 1, NULL, &g, &l, 0, NULL, NULL);
    return err;
}

/* One time step, all on the device: velocity at the interface, extended,
 * phi advected from phi[cur] into phi[1 - cur]. */
static int step(device *d, hv_extender *e, const band *b, fields *f, int cur, double dt,
                hv_extend_stats *S)
{
    const cl_ulong cells = b->count * T3;
    const cl_float known = (cl_float)(SOURCE * b->h), u[3] = {(cl_float)U[0], (cl_float)U[1],
                                                             (cl_float)U[2]};
    cl_int err = CL_SUCCESS;
    err |= clSetKernelArg(d->kv, 0, sizeof cells, &cells);
    err |= clSetKernelArg(d->kv, 1, sizeof known, &known);
    for (int q = 0; q < 3; q++)
        err |= clSetKernelArg(d->kv, 2 + q, sizeof u[q], &u[q]);
    err |= clSetKernelArg(d->kv, 5, sizeof(cl_mem), &f->phi[cur]);
    for (int q = 0; q < 3; q++)
        err |= clSetKernelArg(d->kv, 6 + q, sizeof(cl_mem), &f->v[q]);
    size_t g = (cells + 63) / 64 * 64, l = 64;
    if (err != CL_SUCCESS || (err = clEnqueueNDRangeKernel(d->q, d->kv, 1, NULL, &g, &l, 0, NULL,
                                                           NULL)) != CL_SUCCESS)
        return fail("set_velocity", err);
    /* 2. the velocity off the interface, in place, on the device */
    hv_opencl_tiles P = {b->count, f->ijk, f->phi[cur], f->on};
    hv_opencl_tiles_field V = {3, {f->v[0], f->v[1], f->v[2]}, {f->von[0], f->von[1], f->von[2]}};
    hv_status st = hv_opencl_extend_tiles(e, &P, 1, &V, S);
    if (st) {
        fprintf(stderr, "advect_band_cl: hv_opencl_extend_tiles: %s\n", hv_last_error());
        return 1;
    }
    /* 3. phi advected (BFECC: forward, back, the start corrected by half
     * the round trip's error, forward again), its active voxels renewed */
    if ((err = advect(d, b, f, f->phi[cur], f->phi[1 - cur], dt, 0)) ||
        (err = advect(d, b, f, f->phi[1 - cur], f->tmp, -dt, 0)))
        return fail("advect", err);
    const cl_float bg = (cl_float)(BAND * b->h);
    err = clSetKernelArg(d->kc, 0, sizeof cells, &cells);
    err |= clSetKernelArg(d->kc, 1, sizeof bg, &bg);
    err |= clSetKernelArg(d->kc, 2, sizeof(cl_mem), &f->phi[cur]);
    err |= clSetKernelArg(d->kc, 3, sizeof(cl_mem), &f->tmp);
    err |= clSetKernelArg(d->kc, 4, sizeof(cl_mem), &f->tmp);
    if (err != CL_SUCCESS || (err = clEnqueueNDRangeKernel(d->q, d->kc, 1, NULL, &g, &l, 0, NULL,
                                                           NULL)) != CL_SUCCESS)
        return fail("correct", err);
    const cl_uint zero = 0;
    err = clEnqueueFillBuffer(d->q, f->on, &zero, sizeof zero, 0, 8 * b->count * sizeof(uint64_t),
                              0, NULL, NULL);
    if (err != CL_SUCCESS || (err = advect(d, b, f, f->tmp, f->phi[1 - cur], dt, 1)))
        return fail("advect", err);
    return 0;
}

/* The bytes heatvox moved each way since the last call (profiling on). */
static void traffic(double *in, double *out)
{
    hv_opencl_kernel_time t[128];
    const int n = hv_opencl_profile_take(t, 128);
    *in = *out = 0;
    for (int i = 0; i < n && i < 128; i++) {
        if (!strcmp(t[i].name, "write"))
            *in += t[i].bytes;
        if (!strcmp(t[i].name, "read"))
            *out += t[i].bytes;
    }
}

/* The sphere's centre, volume and the velocity's deviation from U, from phi
 * and the extended velocity read back. */
static int report(device *d, const band *b, fields *f, int cur, const double c1[3])
{
    const size_t cells = b->count * T3;
    float *phi = malloc(cells * sizeof *phi), *v[3];
    uint64_t *on = malloc(8 * b->count * sizeof *on);
    cl_int e = phi && on ? CL_SUCCESS : CL_OUT_OF_HOST_MEMORY;
    if (e == CL_SUCCESS)
        e = clEnqueueReadBuffer(d->q, f->phi[cur], CL_TRUE, 0, cells * 4, phi, 0, NULL, NULL);
    if (e == CL_SUCCESS)
        e = clEnqueueReadBuffer(d->q, f->von[0], CL_TRUE, 0, 8 * b->count * 8, on, 0, NULL, NULL);
    for (int q = 0; q < 3; q++) {
        v[q] = malloc(cells * sizeof(float));
        if (e == CL_SUCCESS)
            e = v[q] ? clEnqueueReadBuffer(d->q, f->v[q], CL_TRUE, 0, cells * 4, v[q], 0, NULL,
                                           NULL)
                     : CL_OUT_OF_HOST_MEMORY;
    }
    int rc = e != CL_SUCCESS ? fail("reading the fields back", e) : 0;
    const double h = b->h, eps = 1.5 * h;
    double vol = 0, m = 0, cen[3] = {0, 0, 0}, dev = 0;
    size_t band_cells = 0;
    for (size_t t = 0; t < b->count && !rc; t++)
        for (int o = 0; o < T3; o++) {
            const int c[3] = {b->ijk[3 * t] + (o & 7), b->ijk[3 * t + 1] + (o >> 3 & 7),
                              b->ijk[3 * t + 2] + (o >> 6)};
            if (c[0] >= b->n || c[1] >= b->n || c[2] >= b->n)
                continue;
            const double p = phi[t * T3 + o];
            const double H = p < -eps ? 1 : p > eps ? 0 : 0.5 * (1 - p / eps - sin(M_PI * p / eps) / M_PI);
            vol += H * h * h * h;
            if (p < 0) {
                for (int q = 0; q < 3; q++)
                    cen[q] += (c[q] + 0.5) * h;
                m++;
            }
            if (!(on[8 * t + (o >> 6)] >> (o & 63) & 1))
                continue;
            double d2 = 0, u2 = 0;
            for (int q = 0; q < 3; q++) {
                d2 += (v[q][t * T3 + o] - U[q]) * (v[q][t * T3 + o] - U[q]);
                u2 += U[q] * U[q];
            }
            dev = fmax(dev, sqrt(d2 / u2));
            band_cells++;
        }
    if (!rc) {
        double off = 0;
        for (int q = 0; q < 3; q++) {
            cen[q] /= m;
            off += (cen[q] - c1[q]) * (cen[q] - c1[q]);
        }
        off = sqrt(off) / h;
        const double want = 4.0 / 3.0 * M_PI * RADIUS * RADIUS * RADIUS, dv = vol / want - 1;
        printf("advect_band_cl: centre (%.4f, %.4f, %.4f), exact (%.4f, %.4f, %.4f): %.3f voxels "
               "off; volume %.5f, exact %.5f (%+.2f%%); velocity on the band's %zu voxels within "
               "%.2e of the flow's\n",
               cen[0], cen[1], cen[2], c1[0], c1[1], c1[2], off, vol, want, 100 * dv, band_cells,
               dev);
        rc = off > 0.5 || fabs(dv) > 0.03 || dev > 1e-4 || band_cells == 0;
        if (rc)
            fprintf(stderr, "advect_band_cl: the sphere or its velocity is off (limits: 0.5 "
                            "voxel, 3%%, 1e-4)\n");
    }
    free(phi);
    free(on);
    for (int q = 0; q < 3; q++)
        free(v[q]);
    return rc;
}

int main(int argc, char **argv)
{
    int n = 64, steps = 24;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--kernels")) {
            fputs(kernels, stdout);
            return 0;
        } else if (!strcmp(argv[i], "--n") && i + 1 < argc) {
            n = atoi(argv[++i]);
        } else if (!strcmp(argv[i], "--steps") && i + 1 < argc) {
            steps = atoi(argv[++i]);
        } else {
            fprintf(stderr, "usage: advect_band_cl [--n N] [--steps S] [--kernels]\n");
            return 2;
        }
    }
    if (n < 24 || n > 1024 || steps < 1) {
        fprintf(stderr, "advect_band_cl: --n must be 24..1024 and --steps at least 1\n");
        return 2;
    }
    const double h = 1.0 / n, dt = 0.5 * h / sqrt(U[0] * U[0] + U[1] * U[1] + U[2] * U[2]);
    double c1[3];
    for (int q = 0; q < 3; q++)
        c1[q] = C0[q] + steps * dt * U[q];
    device d;
    memset(&d, 0, sizeof d);
    band b;
    memset(&b, 0, sizeof b);
    fields f;
    memset(&f, 0, sizeof f);
    hv_extender *e = NULL;
    int rc = open_device(&d);
    if (!rc && make_band(&b, n, c1)) {
        fprintf(stderr, "advect_band_cl: out of memory\n");
        rc = 1;
    }
    if (!rc)
        rc = make_fields(&d, &b, &f);
    if (!rc) {
        /* One extender for every step, on the program's context: out_band 0
         * (every active voxel of the level set). */
        hv_extend_opts o;
        hv_extend_opts_default(&o);
        const int ns[3] = {n, n, n};
        if (hv_opencl_extender_create(&e, 3, ns, h, NULL, &o, d.ctx, d.dev, d.q) != HV_OK) {
            fprintf(stderr, "advect_band_cl: %s\n", hv_last_error());
            rc = 1;
        }
    }
    printf("advect_band_cl: %d^3, %zu tiles of 8^3, %d steps of dt = %.4g\n", n, b.count, steps,
           dt);
    double t0 = hv_now(), in = 0, out = 0, tin = 0, tout = 0, text = 0;
    int cur = 0;
    for (int s = 0; s < steps && !rc; s++, cur = 1 - cur) {
        hv_extend_stats S;
        rc = step(&d, e, &b, &f, cur, dt, &S);
        text += S.t_total;
        traffic(&in, &out);
        tin += in;
        tout += out;
    }
    if (!rc)
        clFinish(d.q);
    const double wall = hv_now() - t0;
    if (!rc) {
        printf("advect_band_cl: %.2f ms a step (extension %.2f ms); heatvox moved %.0f bytes to "
               "the device and %.0f to the host a step\n",
               1e3 * wall / steps, 1e3 * text / steps, tin / steps, tout / steps);
        rc = report(&d, &b, &f, cur, c1);
    }
    hv_extender_destroy(&e);
    free_fields(&f);
    free_band(&b);
    close_device(&d);
    return rc;
}
