/*
 * The coarse levels by smoothed aggregation on a device, the twins of
 * src/solve/mg/agg_*.c: sparse rows (CSR: row starts rp, columns ci, values v)
 * for the coarse operators and the transfers between them, and the fine
 * level's transfers from its aggregates (agg, members mrp/mem) and the
 * stencil's apply (mg_apply). One work-item per row.
 */

/* Row r of a sparse matrix times x. */
static float csr_row(int r, __global const uint *rp, __global const int *ci,
                     __global const float *v, __global const float *x)
{
    float s = 0.0f;
    for (uint q = rp[r]; q < rp[r + 1]; q++)
        s += v[q] * x[ci[q]];
    return s;
}

/* y = M x over the n rows of M */
__kernel void agg_spmv(int n, __global const uint *rp, __global const int *ci,
                       __global const float *v, __global const float *x, __global float *y)
{
    const int r = get_global_id(0);
    if (r < n)
        y[r] = csr_row(r, rp, ci, v, x);
}

/* Row i of a coarse level's A times x: the template (nt entries at index
 * offsets toff, values tval) where plain[i] is set and nt > 0, else the row. */
static float agg_row(int i, __global const uint *rp, __global const int *ci,
                     __global const float *v, __global const uchar *plain, int nt,
                     __global const int *toff, __global const float *tval,
                     __global const float *x)
{
    if (!(nt > 0 && plain[i]))
        return csr_row(i, rp, ci, v, x);
    float s = 0.0f;
    for (int e = 0; e < nt; e++)
        s += tval[e] * x[i + toff[e]];
    return s;
}

/* r = f - A u on a coarse level */
__kernel void agg_residual(int n, __global const uint *rp, __global const int *ci,
                           __global const float *v, __global const uchar *plain, int nt,
                           __global const int *toff, __global const float *tval,
                           __global const float *u, __global const float *f, __global float *r)
{
    const int i = get_global_id(0);
    if (i < n)
        r[i] = f[i] - agg_row(i, rp, ci, v, plain, nt, toff, tval, u);
}

/* y = A x on a coarse level */
__kernel void agg_apply(int n, __global const uint *rp, __global const int *ci,
                        __global const float *v, __global const uchar *plain, int nt,
                        __global const int *toff, __global const float *tval,
                        __global const float *x, __global float *y)
{
    const int i = get_global_id(0);
    if (i < n)
        y[i] = agg_row(i, rp, ci, v, plain, nt, toff, tval, x);
}

/* A Chebyshev step: d = cd d + cr dinv r, u += d; with `zero` the step from
 * u = 0 (d and u are not read). */
__kernel void agg_cheb(int n, __global const float *dinv, __global const float *r,
                       __global float *d, __global float *u, float cd, float cr, int zero)
{
    const int i = get_global_id(0);
    if (i >= n)
        return;
    const float di = (zero ? 0.0f : cd * d[i]) + cr * dinv[i] * r[i];
    d[i] = di;
    u[i] = (zero ? 0.0f : u[i]) + di;
}

/* u += P uc over the n rows of P */
__kernel void agg_prolong(int n, __global const uint *rp, __global const int *ci,
                          __global const float *v, __global const float *uc, __global float *u)
{
    const int r = get_global_id(0);
    if (r < n)
        u[r] += csr_row(r, rp, ci, v, uc);
}

/* Fine level (and a coarse level without P and P^T): t = dinv r */
__kernel void agg_scale(int n, __global const float *dinv, __global const float *r,
                        __global float *t)
{
    const int i = get_global_id(0);
    if (i < n)
        t[i] = dinv[i] * r[i];
}

/* Fine level: fc = P^T r = P0^T (r - wp s), s = A D^-1 r, summed over the
 * members of each aggregate. */
__kernel void agg_restrict0(int nc, __global const uint *mrp, __global const int *mem,
                            __global const float *r, __global const float *s, float wp,
                            __global float *fc)
{
    const int I = get_global_id(0);
    if (I >= nc)
        return;
    float sum = 0.0f;
    for (uint q = mrp[I]; q < mrp[I + 1]; q++) {
        const int c = mem[q];
        sum += r[c] - wp * s[c];
    }
    fc[I] = sum;
}

/* Fine level: t = P0 uc (0 on cells in no aggregate) */
__kernel void agg_inject0(int n, __global const int *agg, __global const float *uc,
                          __global float *t)
{
    const int i = get_global_id(0);
    if (i < n)
        t[i] = agg[i] >= 0 ? uc[agg[i]] : 0.0f;
}

/* Fine level: u += P uc = t - wp D^-1 A t, with t = P0 uc and s = A t */
__kernel void agg_prolong0(int n, __global const float *t, __global const float *s,
                           __global const float *dinv, float wp, __global float *u)
{
    const int i = get_global_id(0);
    if (i < n)
        u[i] += t[i] - wp * dinv[i] * s[i];
}
