/*
 * Definitions shared by every heatvox kernel file; the host prepends this file
 * to the others when it builds the program (src/cl/cl_core.c).
 *
 * Grids are cell-centred, x fastest: cell (i,j,k) has index i + nx*(j + ny*k).
 * Level geometry travels as int4 N = (nx, ny, nz, plain) and float4 (or
 * double4) C = (cx, cy, cz, alpha) with c_b = beta / h_b^2 (src/solve/mg/mg_level.h).
 * Stencil kernels run on a 2D range (x, row = j + ny*k); the host pads it to
 * whole work-groups, so every kernel checks its bounds.
 *
 * HV_FP64 is defined when the device has cl_khr_fp64: accumulations and the
 * fine-level defect correction are then in double.
 */
#ifdef HV_FP64
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double acc_t;
typedef double4 acc4_t;
#define HV_ACC(x) (x)
#else
typedef float acc_t;
typedef float4 acc4_t;
/* A literal in acc_t: a double constant is an error on a device without fp64. */
#define HV_ACC(x) (x##f)
#endif

/* Largest work-group the reduction kernels handle (local arrays). */
#define HV_WG_MAX 256

/* Reductions: work-item l of group g takes the elements
 *     g * HV_WG * HV_RED_BLOCK + q * HV_WG + l,   q < HV_RED_BLOCK,
 * coalesced on GPUs, and a fixed trip count that CPU compilers (PoCL) unroll
 * and vectorize across work-items; then one tree per group. The host passes
 * both numbers as build options (src/cl/cl_core.h). */
#ifndef HV_WG
#error "build with -DHV_WG=<work-group size> -DHV_RED_BLOCK=<elements per work-item>"
#endif

/*
 * Off-diagonal sum S = sum_faces c_b w_f u_nb and diagonal D of
 *     (A u)_i = alpha a_i u_i + sum_b c_b sum_faces w_f (u_i - u_nb)
 * at cell (i,j,k) = index c, in type T: the device twin of MG_STENCIL. Plain
 * levels (N.w != 0) have a = 1 and w = 1 inside, 0 on walls; weighted levels
 * read a, and face weights w0/w1/w2 laid out with n[b]+1 faces along b.
 */
#define HV_STENCIL(T, U, N, C, a, w0, w1, w2, i, j, k, c, S, D)                                  \
    do {                                                                                          \
        const size_t sy_ = (size_t)(N).x, sz_ = (size_t)(N).x * (size_t)(N).y;                    \
        if ((N).w) {                                                                              \
            const T cx_ = (T)(C).x, cy_ = (T)(C).y, cz_ = (T)(C).z;                               \
            D = (T)(C).w;                                                                         \
            S = (T)0;                                                                             \
            if ((i) > 0) { S += cx_ * U[(c) - 1]; D += cx_; }                                     \
            if ((i) < (N).x - 1) { S += cx_ * U[(c) + 1]; D += cx_; }                             \
            if ((j) > 0) { S += cy_ * U[(c) - sy_]; D += cy_; }                                   \
            if ((j) < (N).y - 1) { S += cy_ * U[(c) + sy_]; D += cy_; }                           \
            if ((k) > 0) { S += cz_ * U[(c) - sz_]; D += cz_; }                                   \
            if ((k) < (N).z - 1) { S += cz_ * U[(c) + sz_]; D += cz_; }                           \
        } else {                                                                                  \
            const size_t fx_ = (size_t)(i) + ((size_t)(N).x + 1) * ((size_t)(j) + (size_t)(N).y * (size_t)(k)); \
            const size_t fy_ = (size_t)(i) + sy_ * ((size_t)(j) + ((size_t)(N).y + 1) * (size_t)(k)); \
            T wl_ = (T)w0[fx_], wh_ = (T)w0[fx_ + 1];                                             \
            D = (T)(C).w * (T)a[c];                                                               \
            S = (T)0;                                                                             \
            if (wl_ != (T)0) S += (T)(C).x * wl_ * U[(c) - 1];                                    \
            if (wh_ != (T)0) S += (T)(C).x * wh_ * U[(c) + 1];                                    \
            D += (T)(C).x * (wl_ + wh_);                                                          \
            wl_ = (T)w1[fy_];                                                                     \
            wh_ = (T)w1[fy_ + sy_];                                                               \
            if (wl_ != (T)0) S += (T)(C).y * wl_ * U[(c) - sy_];                                  \
            if (wh_ != (T)0) S += (T)(C).y * wh_ * U[(c) + sy_];                                  \
            D += (T)(C).y * (wl_ + wh_);                                                          \
            if ((N).z > 1) {                                                                      \
                wl_ = (T)w2[c];                                                                   \
                wh_ = (T)w2[(c) + sz_];                                                           \
                if (wl_ != (T)0) S += (T)(C).z * wl_ * U[(c) - sz_];                              \
                if (wh_ != (T)0) S += (T)(C).z * wh_ * U[(c) + sz_];                              \
                D += (T)(C).z * (wl_ + wh_);                                                      \
            }                                                                                     \
        }                                                                                         \
    } while (0)

/* Sum of v over the work-group (any 1D or 2D shape whose size is a power of
 * two <= HV_WG_MAX); every work-item must call it. A program in which one
 * kernel alone calls a helper like this one, always with the same __local
 * array, must write the tree into that kernel instead: clang folds the
 * constant argument into the helper, and PoCL 3.1 then keeps the array as
 * one static array that every work-group shares (kernels/distance.cl,
 * dist_front_sums; docs/METHOD.md, "Testing notes"). */
static acc_t hv_group_sum(acc_t v, __local acc_t *red)
{
    const int lid = get_local_id(0) + get_local_size(0) * get_local_id(1);
    const int n = get_local_size(0) * get_local_size(1);
    red[lid] = v;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int s = n >> 1; s > 0; s >>= 1) {
        if (lid < s)
            red[lid] += red[lid + s];
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    acc_t t = red[0];
    barrier(CLK_LOCAL_MEM_FENCE);
    return t;
}

/* Linear id of the work-group in a 1D or 2D range (partial-sum slot). */
static size_t hv_group_index(void)
{
    return get_group_id(0) + get_num_groups(0) * get_group_id(1);
}
