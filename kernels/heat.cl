/*
 * Device steps of the signed heat method (src/sdf/sdf.c, sdf_cl.c): the
 * trilinear splat of surface samples into the grid and the right-hand side
 * -div X of the Poisson step from the diffused fields. N = (nx, ny, nz, dim).
 */

/* Trilinear splat as a gather, so that no two work-items write one cell and
 * the sums do not depend on scheduling. The host sorts the samples by the
 * cell at the low corner of their stencil (the base cell of hv__trilinear):
 * samples of base cell b are [start[b], start[b+1]), with fractional
 * coordinates frac (0 along clamped axes, where hv__trilinear's step is 0) and
 * values val. Cell c gathers from the base cells c - q, q in {0,1}^3; the
 * weight is prod_a (q_a ? f_a : 1 - f_a), as hv__trilinear. */
__kernel void heat_splat(int4 N, __global const uint *start, __global const float4 *frac,
                         __global const float *val, __global float *out)
{
    const int i = get_global_id(0), row = get_global_id(1);
    if (i >= N.x || row >= N.y * N.z)
        return;
    const int j = row % N.y, k = row / N.y;
    const size_t sy = (size_t)N.x, sz = (size_t)N.x * N.y;
    const size_t c = (size_t)i + sy * (size_t)row;
    acc_t sum = 0;
    for (int q = 0; q < 8; q++) {
        const int qx = q & 1, qy = (q >> 1) & 1, qz = (q >> 2) & 1;
        if (i < qx || j < qy || k < qz)
            continue;
        const size_t b = c - (size_t)qx - qy * sy - qz * sz;
        const uint p1 = start[b + 1];
        for (uint p = start[b]; p < p1; p++) {
            const float4 f = frac[p];
            const acc_t wx = qx ? (acc_t)f.x : (acc_t)1 - (acc_t)f.x;
            const acc_t wy = qy ? (acc_t)f.y : (acc_t)1 - (acc_t)f.y;
            const acc_t wz = qz ? (acc_t)f.z : (acc_t)1 - (acc_t)f.z;
            sum += wx * wy * wz * (acc_t)val[p];
        }
    }
    out[c] = (float)sum;
}

/* Face vector at the axis-a face between cells lo = c - s_a and c (cell
 * coordinates i, j, k of c): the mean of the two cells' vectors (ncomp 3,
 * component b at Y + b * count), or for the unsigned field (ncomp 1) its
 * gradient, central differences across and one-sided (mirror) at walls, as
 * face_vec in src/sdf/sdf.c. */
static void heat_face_vec(int4 N, __global const float *Y, ulong count, int ncomp, acc_t inv_h,
                          int a, size_t c, int i, int j, int k, acc_t v[3])
{
    const size_t s[3] = {1, (size_t)N.x, (size_t)N.x * N.y};
    const size_t lo = c - s[a];
    if (ncomp == 3) {
        for (int b = 0; b < 3; b++)
            v[b] = HV_ACC(0.5) * ((acc_t)Y[b * count + c] + (acc_t)Y[b * count + lo]);
        return;
    }
    const int idx[3] = {i, j, k}, n[3] = {N.x, N.y, N.z};
    v[a] = ((acc_t)Y[c] - (acc_t)Y[lo]) * inv_h;
    for (int b = 0; b < 3; b++) {
        if (b == a)
            continue;
        acc_t g = 0;
        for (int side = 0; side < 2; side++) {
            const size_t cc = side ? c : lo;
            const size_t up = idx[b] < n[b] - 1 ? cc + s[b] : cc, dn = idx[b] > 0 ? cc - s[b] : cc;
            g += ((acc_t)Y[up] - (acc_t)Y[dn]) * (HV_ACC(0.5) * inv_h);
        }
        v[b] = HV_ACC(0.5) * g;
    }
}

/* Normalized flux through the face from the first level whose face vector is
 * longer than its noise bound tau[level]; 0 and *dead = 1 when none is. The
 * length is taken after scaling by the largest component, so that fields far
 * from the surface do not underflow in float. */
static acc_t heat_face_flux(int4 N, __global const float *Y, ulong count, int nlev, int ncomp,
                            __global const acc_t *tau, acc_t inv_h, int a, size_t c, int i, int j,
                            int k, int *dead)
{
    for (int l = 0; l < nlev; l++) {
        acc_t v[3] = {0, 0, 0};
        heat_face_vec(N, Y + (size_t)l * ncomp * count, count, ncomp, inv_h, a, c, i, j, k, v);
        const acc_t m = fmax(fabs(v[0]), fmax(fabs(v[1]), fabs(v[2])));
        if (!(m > 0))
            continue;
        const acc_t x = v[0] / m, y = v[1] / m, z = v[2] / m;
        const acc_t len = m * sqrt(x * x + y * y + z * z);
        if (len > tau[l]) {
            *dead = 0;
            return ncomp == 1 ? -v[a] / len : v[a] / len;
        }
    }
    *dead = 1;
    return 0;
}

/* rhs[c] = -(sum of the outward normalized fluxes of cell c) / h, the right-hand side of -Lap phi = -div X (build_rhs in src/sdf/sdf.c), from
 * nlev levels of ncomp diffused fields (level l, component b at
 * Y + (l * ncomp + b) * count). Counts the interior faces with no live level
 * in *dead (each face once, at its high cell). 3D grids only. */
__kernel void heat_sdf_rhs(int4 N, __global const float *Y, ulong count, int nlev, int ncomp,
                           __global const acc_t *tau, acc_t inv_h, __global float *rhs,
                           __global uint *dead)
{
    /* dead faces summed per work-group (a power of two, HV_CL_WG x 1), then
     * one atomic: a far field has millions of them */
    __local uint red[HV_WG_MAX];
    const int lid = get_local_id(0) + get_local_size(0) * get_local_id(1);
    const int lsize = get_local_size(0) * get_local_size(1);
    const int i = get_global_id(0), row = get_global_id(1);
    uint ndead = 0;
    if (i < N.x && row < N.y * N.z) {
        const int j = row % N.y, k = row / N.y;
        const size_t s[3] = {1, (size_t)N.x, (size_t)N.x * N.y};
        const size_t c = (size_t)i + s[1] * (size_t)row;
        const int idx[3] = {i, j, k}, n[3] = {N.x, N.y, N.z};
        acc_t div = 0;
        for (int a = 0; a < 3; a++) {
            int d;
            if (idx[a] > 0) {
                div -= heat_face_flux(N, Y, count, nlev, ncomp, tau, inv_h, a, c, i, j, k, &d);
                ndead += d;
            }
            if (idx[a] < n[a] - 1) {
                const int up[3] = {i + (a == 0), j + (a == 1), k + (a == 2)};
                div += heat_face_flux(N, Y, count, nlev, ncomp, tau, inv_h, a, c + s[a], up[0],
                                      up[1], up[2], &d);
            }
        }
        rhs[c] = (float)(-div * inv_h);
    }
    red[lid] = ndead;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int h = lsize / 2; h > 0; h >>= 1) {
        if (lid < h)
            red[lid] += red[lid + h];
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid == 0 && red[0])
        atomic_add(dead, red[0]);
}

/* out[p] = trilinear interpolation of v at binned sample p (base cell
 * base[p], fractions frac[p]): the transpose of heat_splat, as interp() in
 * src/sdf/sdf.c. Corners with zero weight are not read (clamped axes). */
__kernel void heat_sample(int4 N, __global const uint *base, __global const float4 *frac,
                          __global const float *v, __global float *out, ulong npts)
{
    const size_t p = get_global_id(0);
    if (p >= npts)
        return;
    const size_t sy = (size_t)N.x, sz = (size_t)N.x * N.y, b = base[p];
    const float4 f = frac[p];
    acc_t sum = 0;
    for (int q = 0; q < 8; q++) {
        const int qx = q & 1, qy = (q >> 1) & 1, qz = (q >> 2) & 1;
        const acc_t w = (qx ? (acc_t)f.x : (acc_t)1 - (acc_t)f.x) *
                        (qy ? (acc_t)f.y : (acc_t)1 - (acc_t)f.y) *
                        (qz ? (acc_t)f.z : (acc_t)1 - (acc_t)f.z);
        if (w != 0)
            sum += w * (acc_t)v[b + qx + qy * sy + qz * sz];
    }
    out[p] = (float)sum;
}

/* The zero-set correction of the signed heat method (local_shift in
 * src/sdf/sdf.c): phi -= shift, then phi -= taper(den) num / den where den is
 * above 100 tau, the taper rising linearly to 1 at 1000 tau. */
__kernel void heat_shift(__global float *phi, __global const float *num, __global const float *den,
                         float shift, acc_t tau, int local_shift, ulong n)
{
    const size_t c = get_global_id(0);
    if (c >= n)
        return;
    float p = phi[c] - shift;
    if (local_shift) {
        const acc_t d = den[c];
        if (d > 100 * tau) {
            const acc_t taper = d >= 1000 * tau ? (acc_t)1 : (d - 100 * tau) / (900 * tau);
            p -= (float)(taper * (acc_t)num[c] / d);
        }
    }
    phi[c] = p;
}
