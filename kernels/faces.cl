/*
 * Face operators on cell-centred grids, the device twins of src/ops/faces.c
 * (docs/METHOD.md, "Discretization"), and the face normalization of the heat
 * methods. Axis-a faces form an array with n[a]+1 entries along a; face i
 * along x lies between cells i-1 and i. Wall faces and faces touching a solid
 * cell carry nothing.
 * N = (nx, ny, nz, dim); solid is NULL or one byte per cell.
 */

/* Face (i,j,k) of axis a on a 2D range over the face array; returns when out
 * of range. lo/hi are the cells on either side; wall is set on boundary faces. */
#define HV_FACE_OR_RETURN(N, a, fi, lo, hi, wall)                                                 \
    const int mx_ = (N).x + ((a) == 0), my_ = (N).y + ((a) == 1), mz_ = (N).z + ((a) == 2);      \
    const int i = get_global_id(0), row_ = get_global_id(1);                                      \
    if (i >= mx_ || row_ >= my_ * mz_)                                                            \
        return;                                                                                   \
    const int j = row_ % my_, k = row_ / my_;                                                     \
    const size_t fi = (size_t)i + (size_t)mx_ * (size_t)row_;                                      \
    const int idx_ = (a) == 0 ? i : (a) == 1 ? j : k;                                             \
    const int wall = idx_ == 0 || idx_ == ((a) == 0 ? (N).x : (a) == 1 ? (N).y : (N).z);          \
    const size_t stride_ = (a) == 0 ? 1 : (a) == 1 ? (size_t)(N).x : (size_t)(N).x * (N).y;       \
    const size_t hi = (size_t)i + (size_t)(N).x * ((size_t)j + (size_t)(N).y * (size_t)k);        \
    const size_t lo = hi - stride_

/* g = (u[hi] - u[lo]) / h on axis-a faces. */
__kernel void face_gradient(int4 N, int axis, float inv_h, __global const uchar *solid,
                            __global const float *u, __global float *g)
{
    HV_FACE_OR_RETURN(N, axis, fi, lo, hi, wall);
    if (wall || (solid && (solid[hi] || solid[lo])))
        g[fi] = 0.0f;
    else
        g[fi] = (u[hi] - u[lo]) * inv_h;
}

/* out = sum_a (F_a[hi face] - F_a[lo face]) / h; fluxes through walls and
 * faces touching solid count as zero, and solid cells get 0. F2 is NULL in 2D. */
__kernel void face_divergence(int4 N, acc_t inv_h, __global const uchar *solid,
                              __global const float *F0, __global const float *F1,
                              __global const float *F2, __global float *out)
{
    const int i = get_global_id(0), row = get_global_id(1);
    if (i >= N.x || row >= N.y * N.z)
        return;
    const int j = row % N.y, k = row / N.y;
    const size_t c = (size_t)i + (size_t)N.x * (size_t)row;
    if (solid && solid[c]) {
        out[c] = 0.0f;
        return;
    }
    const size_t sy = N.x, sz = (size_t)N.x * N.y;
    acc_t d = 0;
    /* x faces: (nx+1) x ny x nz */
    size_t lo = (size_t)i + (size_t)(N.x + 1) * ((size_t)j + (size_t)N.y * k);
    d += ((i == N.x - 1 || (solid && solid[c + 1])) ? (acc_t)0 : (acc_t)F0[lo + 1]) -
         ((i == 0 || (solid && solid[c - 1])) ? (acc_t)0 : (acc_t)F0[lo]);
    lo = (size_t)i + sy * ((size_t)j + (size_t)(N.y + 1) * k);
    d += ((j == N.y - 1 || (solid && solid[c + sy])) ? (acc_t)0 : (acc_t)F1[lo + sy]) -
         ((j == 0 || (solid && solid[c - sy])) ? (acc_t)0 : (acc_t)F1[lo]);
    if (N.w == 3) {
        lo = c;
        d += ((k == N.z - 1 || (solid && solid[c + sz])) ? (acc_t)0 : (acc_t)F2[lo + sz]) -
             ((k == 0 || (solid && solid[c - sz])) ? (acc_t)0 : (acc_t)F2[lo]);
    }
    out[c] = (float)(d * inv_h);
}

/* Heat-method face field: the mean of the cell vectors (vx, vy, vz) of the two
 * cells at each axis-a face, normalized, and its axis-a component; 0 on walls,
 * on faces touching solid and where the mean's largest component is <= eps.
 * vz is NULL in 2D. Scaling by the largest component first keeps tiny heat
 * gradients (far from the source) from underflowing in float. */
__kernel void face_normalize(int4 N, int axis, __global const uchar *solid,
                             __global const float *vx, __global const float *vy,
                             __global const float *vz, __global float *out, float eps)
{
    HV_FACE_OR_RETURN(N, axis, fi, lo, hi, wall);
    if (wall || (solid && (solid[hi] || solid[lo]))) {
        out[fi] = 0.0f;
        return;
    }
    const float x = 0.5f * (vx[lo] + vx[hi]), y = 0.5f * (vy[lo] + vy[hi]);
    const float z = vz ? 0.5f * (vz[lo] + vz[hi]) : 0.0f;
    const float m = fmax(fabs(x), fmax(fabs(y), fabs(z)));
    if (!(m > eps)) {
        out[fi] = 0.0f;
        return;
    }
    const float xs = x / m, ys = y / m, zs = z / m;
    const float len = sqrt(xs * xs + ys * ys + zs * zs);
    out[fi] = (axis == 0 ? xs : axis == 1 ? ys : zs) / len;
}
