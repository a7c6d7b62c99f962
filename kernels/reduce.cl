/*
 * Reductions in two stages: each work-group writes a partial sum (acc_t,
 * double when the device has fp64), then red_finish adds the partials into a
 * slot of a small scalar buffer that later kernels read, so reductions need no
 * host round trip. Per-region sums (Neumann projections on masked grids, one
 * constant per connected fluid region) use chunks of a region-sorted cell list.
 * Work-items take fixed blocks (HV_RED_BLOCK, common.cl): PoCL vectorizes
 * across work-items, and a grid-stride loop inside a work-item kept it scalar.
 */

/* part[group] = sum of a*b (b NULL: of a) over the group's elements. */
__kernel void red_dot_f(__global const float *a, __global const float *b, ulong n,
                        __global acc_t *part)
{
    __local acc_t red[HV_WG_MAX];
    const size_t base = get_group_id(0) * (HV_WG * HV_RED_BLOCK) + get_local_id(0);
    acc_t s = 0;
    if (b) {
        for (int q = 0; q < HV_RED_BLOCK; q++) {
            const size_t c = base + q * HV_WG;
            if (c < n)
                s += (acc_t)a[c] * (acc_t)b[c];
        }
    } else {
        for (int q = 0; q < HV_RED_BLOCK; q++) {
            const size_t c = base + q * HV_WG;
            if (c < n)
                s += (acc_t)a[c];
        }
    }
    s = hv_group_sum(s, red);
    if (get_local_id(0) == 0)
        part[get_group_id(0)] = s;
}

/* S[slot] = sum of part[0..nparts), by one work-group. */
__kernel void red_finish(__global const acc_t *part, ulong nparts, __global acc_t *S, int slot)
{
    __local acc_t red[HV_WG_MAX];
    acc_t s = 0;
    for (size_t g0 = 0; g0 < nparts; g0 += get_local_size(0)) {
        const size_t g = g0 + get_local_id(0);
        if (g < nparts)
            s += part[g];
    }
    s = hv_group_sum(s, red);
    if (get_local_id(0) == 0)
        S[slot] = s;
}

/* Chunk g (one work-group) sums v over positions [cb[g], cb[g+1]) of the
 * region-sorted cell list perm (NULL: the cells in order); a chunk holds at
 * most HV_WG * HV_RED_BLOCK positions. Values T, sums ACC; fine.cl makes the
 * double twin. */
#define HV_RED_CHUNK(NAME, T, ACC)                                                                 \
    __kernel void NAME(__global const T *v, __global const uint *perm, __global const uint *cb,    \
                       __global ACC *part)                                                         \
    {                                                                                              \
        __local ACC red[HV_WG_MAX];                                                                \
        const size_t g = get_group_id(0);                                                          \
        const uint p0 = cb[g] + get_local_id(0), end = cb[g + 1];                                  \
        ACC s = 0;                                                                                 \
        if (perm) {                                                                                \
            for (int q = 0; q < HV_RED_BLOCK; q++) {                                               \
                const uint p = p0 + q * HV_WG;                                                     \
                if (p < end)                                                                       \
                    s += v[perm[p]];                                                               \
            }                                                                                      \
        } else {                                                                                   \
            for (int q = 0; q < HV_RED_BLOCK; q++) {                                               \
                const uint p = p0 + q * HV_WG;                                                     \
                if (p < end)                                                                       \
                    s += v[p];                                                                     \
            }                                                                                      \
        }                                                                                          \
        s = hv_group_sum(s, red);                                                                  \
        if (get_local_id(0) == 0)                                                                  \
            part[g] = s;                                                                           \
    }
HV_RED_CHUNK(red_chunk_f, float, acc_t)

/* out[r] = scale[r] * sum of the partials of region r's chunks
 * [rc[r], rc[r+1]), one work-group per region (scale NULL: the plain sum). */
__kernel void red_region(__global const acc_t *part, __global const uint *rc,
                         __global const acc_t *scale, __global acc_t *out)
{
    __local acc_t red[HV_WG_MAX];
    const int r = get_group_id(0);
    const uint end = rc[r + 1];
    acc_t s = 0;
    for (uint g0 = rc[r]; g0 < end; g0 += get_local_size(0)) {
        const uint g = g0 + get_local_id(0);
        if (g < end)
            s += part[g];
    }
    s = hv_group_sum(s, red);
    if (get_local_id(0) == 0)
        out[r] = scale ? s * scale[r] : s;
}

/* v -= mean of v's region; cells outside every region (solid) become 0.
 * region NULL: one region, the whole grid. */
#define HV_REGION_SUB(NAME, T, ACC)                                                                \
    __kernel void NAME(__global T *v, __global const int *region, __global const ACC *mean,        \
                       ulong n)                                                                    \
    {                                                                                              \
        const size_t c = get_global_id(0);                                                         \
        if (c >= n)                                                                                \
            return;                                                                                \
        if (region) {                                                                              \
            const int r = region[c];                                                               \
            v[c] = r >= 0 ? (T)((ACC)v[c] - mean[max(r, 0)]) : (T)0;                               \
        } else {                                                                                   \
            v[c] = (T)((ACC)v[c] - mean[0]);                                                       \
        }                                                                                          \
    }
HV_REGION_SUB(region_sub_f, float, acc_t)

#ifdef HV_FP64
/* Double twins of red_chunk_f and region_sub_f. */
HV_RED_CHUNK(red_chunk_d, double, double)
HV_REGION_SUB(region_sub_d, double, double)

/* part[group] = sum of a*b over the group's elements (blocks as red_dot_f). */
__kernel void red_dot_d(__global const double *a, __global const double *b, ulong n,
                        __global double *part)
{
    __local double red[HV_WG_MAX];
    const size_t base = get_group_id(0) * (HV_WG * HV_RED_BLOCK) + get_local_id(0);
    double s = 0;
    for (int q = 0; q < HV_RED_BLOCK; q++) {
        const size_t c = base + q * HV_WG;
        if (c < n)
            s += a[c] * b[c];
    }
    s = hv_group_sum(s, red);
    if (get_local_id(0) == 0)
        part[get_group_id(0)] = s;
}
#endif
