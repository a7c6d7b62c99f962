/* Pointwise steps of the heat methods on float arrays of n entries. */

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
