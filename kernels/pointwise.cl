/* Pointwise steps of the heat methods on float arrays of n entries, and the
 * prefix sums of uint arrays (counts to offsets). */

/* out = b > eps ? a / b : 0 (e.g. a diffused quantity over diffused weights). */
__kernel void pw_ratio(__global const float *a, __global const float *b, __global float *out,
                       float eps, ulong n)
{
    const size_t c = get_global_id(0);
    if (c < n)
        out[c] = b[c] > eps ? a[c] / b[c] : 0.0f;
}

/* y += alpha x */
__kernel void pw_axpy(float alpha, __global const float *x, __global float *y, ulong n)
{
    const size_t c = get_global_id(0);
    if (c < n)
        y[c] += alpha * x[c];
}

/* Exclusive prefix sums of uint arrays: scan_block_u turns work-group g's
 * HV_WG * HV_RED_BLOCK elements of in (work-item l the HV_RED_BLOCK from
 * g * HV_WG * HV_RED_BLOCK + l * HV_RED_BLOCK on) into their exclusive sums
 * within the block in out and the block's total into sums[g]; scan_add_u
 * adds the blocks' scanned totals back (src/cl/cl_ops.c, hv__cl_scan_u32). */
__kernel void scan_block_u(ulong n, __global const uint *in, __global uint *out,
                           __global uint *sums)
{
    __local uint part[HV_WG];
    const uint l = get_local_id(0), g = get_group_id(0);
    const size_t base = (size_t)g * HV_WG * HV_RED_BLOCK + (size_t)l * HV_RED_BLOCK;
    uint s = 0;
    for (int q = 0; q < HV_RED_BLOCK; q++)
        s += base + q < n ? in[base + q] : 0;
    part[l] = s;
    barrier(CLK_LOCAL_MEM_FENCE);
    if (l == 0) {
        uint run = 0;
        for (int i = 0; i < HV_WG; i++) {
            const uint v = part[i];
            part[i] = run;
            run += v;
        }
        sums[g] = run;
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    uint run = part[l];
    for (int q = 0; q < HV_RED_BLOCK; q++)
        if (base + q < n) {
            const uint v = in[base + q];
            out[base + q] = run;
            run += v;
        }
}

__kernel void scan_add_u(ulong n, __global uint *out, __global const uint *sums)
{
    const size_t i = get_global_id(0);
    if (i < n)
        out[i] += sums[i / (HV_WG * HV_RED_BLOCK)];
}
