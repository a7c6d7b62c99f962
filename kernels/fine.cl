/*
 * Fine-level double-precision kernels for the defect-correction loop and PCG
 * (float V-cycles reach 1e-6 and below only inside a double outer iteration:
 * docs/METHOD.md, "Multigrid"). Built only when the device has cl_khr_fp64;
 * otherwise the backend does this part on the host.
 */
#ifdef HV_FP64

/* r = f - A x on fluid cells (0 on solid ones) and rf = (float)r for the
 * V-cycle. (A reduction fused in here cost more on PoCL, one tree per 64
 * cells, than the separate red_dot_d pass, reduce.cl.) */
__kernel void fine_residual(int4 N, double4 C, __global const float *a,
                            __global const float *w0, __global const float *w1,
                            __global const float *w2, __global const double *x,
                            __global const double *f, __global double *r, __global float *rf)
{
    const int i = get_global_id(0), row = get_global_id(1);
    if (i >= N.x || row >= N.y * N.z)
        return;
    const int j = row % N.y, k = row / N.y;
    const size_t c = (size_t)i + (size_t)N.x * (size_t)row;
    double S, D;
    HV_STENCIL(double, x, N, C, a, w0, w1, w2, i, j, k, c, S, D);
    double v = f[c] - (D * x[c] - S);
    if (!N.w)
        v = a[c] != 0.0f ? v : 0.0;
    r[c] = v;
    rf[c] = (float)v;
}

/* q = A p */
__kernel void fine_apply(int4 N, double4 C, __global const float *a, __global const float *w0,
                         __global const float *w1, __global const float *w2,
                         __global const double *p, __global double *q)
{
    const int i = get_global_id(0), row = get_global_id(1);
    if (i >= N.x || row >= N.y * N.z)
        return;
    const int j = row % N.y, k = row / N.y;
    const size_t c = (size_t)i + (size_t)N.x * (size_t)row;
    double S, D;
    HV_STENCIL(double, p, N, C, a, w0, w1, w2, i, j, k, c, S, D);
    q[c] = D * p[c] - S;
}

/* x += u (the float coarse-grid correction of one cycle). */
__kernel void fine_add(__global double *x, __global const float *u, ulong n)
{
    const size_t c = get_global_id(0);
    if (c < n)
        x[c] += (double)u[c];
}

/* z = (double)u */
__kernel void fine_f2d(__global const float *u, __global double *z, ulong n)
{
    const size_t c = get_global_id(0);
    if (c < n)
        z[c] = (double)u[c];
}

/* u = (float)x */
__kernel void fine_d2f(__global const double *x, __global float *u, ulong n)
{
    const size_t c = get_global_id(0);
    if (c < n)
        u[c] = (float)x[c];
}

/* CG step with al = S[irz] / S[ipq] (0 when p.q <= 0, which the host then
 * reports): x += al p, r -= al q, rf = (float)r, partial sums of r*r. */
__kernel void fine_pcg_update(__global double *x, __global double *r, __global const double *p,
                              __global const double *q, __global const double *S, int irz,
                              int ipq, __global float *rf, ulong n, __global double *part)
{
    __local double red[HV_WG_MAX];
    const double pq = S[ipq], al = pq > 0 ? S[irz] / pq : 0.0;
    const size_t base = get_group_id(0) * (HV_WG * HV_RED_BLOCK) + get_local_id(0);
    double s = 0;
    for (int b = 0; b < HV_RED_BLOCK; b++) {
        const size_t c = base + b * HV_WG;
        if (c < n) {
            x[c] += al * p[c];
            const double v = r[c] - al * q[c];
            r[c] = v;
            rf[c] = (float)v;
            s += v * v;
        }
    }
    s = hv_group_sum(s, red);
    if (get_local_id(0) == 0)
        part[get_group_id(0)] = s;
}

/* p = z + (S[inew] / S[iold]) p */
__kernel void fine_xpay(__global double *p, __global const double *z, __global const double *S,
                        int inew, int iold, ulong n)
{
    const size_t c = get_global_id(0);
    const double old = S[iold], be = old != 0 ? S[inew] / old : 0.0;
    if (c < n)
        p[c] = z[c] + be * p[c];
}

/* v = 0 on solid cells (level-0 weight a == 0) */
__kernel void fine_mask(__global double *v, __global const float *a, ulong n)
{
    const size_t c = get_global_id(0);
    if (c < n && a[c] == 0.0f)
        v[c] = 0.0;
}

#endif
