/*
 * Multigrid level kernels (float storage), the device twins of the CPU code in
 * src/solve/mg/mg_rows.c and mg_transfer.c: operator apply and residual, red-black Gauss-Seidel by
 * colour, the Jacobi/Chebyshev update (fused with its residual), restriction
 * (mean of children, fused with the residual; or P^T for the symmetric cycle
 * of PCG), cell-centred linear
 * prolongation and a one-work-group CG for the bottom level.
 * Arguments a, w0, w1 and w2 are NULL on plain levels (N.w != 0). The diagonal
 * comes from the stencil itself (the CPU stores its inverse on weighted
 * levels): a select that loads from a NULL buffer on plain levels kept PoCL
 * from vectorizing, and the division costs nothing in these memory-bound loops.
 */

#define HV_LEVEL_ARGS                                                                             \
    int4 N, float4 C, __global const float *a, __global const float *w0,                          \
        __global const float *w1, __global const float *w2

/* Cell (i,j,k) and index c of a 2D range over (x, rows); work-items outside the
 * level return. */
#define HV_CELL_OR_RETURN(N, i, j, k, c)                                                          \
    const int i = get_global_id(0), row_ = get_global_id(1);                                      \
    if (i >= (N).x || row_ >= (N).y * (N).z)                                                      \
        return;                                                                                   \
    const int j = row_ % (N).y, k = row_ / (N).y;                                                 \
    const size_t c = (size_t)i + (size_t)(N).x * (size_t)row_

/* y = A u */
__kernel void mg_apply(HV_LEVEL_ARGS, __global const float *u, __global float *y)
{
    HV_CELL_OR_RETURN(N, i, j, k, c);
    float S, D;
    HV_STENCIL(float, u, N, C, a, w0, w1, w2, i, j, k, c, S, D);
    y[c] = D * u[c] - S;
}

/* r = f - A u */
__kernel void mg_residual(HV_LEVEL_ARGS, __global const float *u, __global const float *f,
                          __global float *r)
{
    HV_CELL_OR_RETURN(N, i, j, k, c);
    float S, D;
    HV_STENCIL(float, u, N, C, a, w0, w1, w2, i, j, k, c, S, D);
    r[c] = f[c] - (D * u[c] - S);
}

/* One colour of red-black Gauss-Seidel: cells with (i+j+k) % 2 == col. The
 * range's x extent is ceil(nx/2): work-item x handles i = 2x + parity. */
__kernel void mg_rbgs(HV_LEVEL_ARGS, __global float *u, __global const float *f, int col)
{
    const int row = get_global_id(1);
    if (row >= N.y * N.z)
        return;
    const int j = row % N.y, k = row / N.y;
    const int i = 2 * (int)get_global_id(0) + ((j + k + col) & 1);
    if (i >= N.x)
        return;
    const size_t c = (size_t)i + (size_t)N.x * (size_t)row;
    float S, D;
    HV_STENCIL(float, u, N, C, a, w0, w1, w2, i, j, k, c, S, D);
    u[c] = D > 0.0f ? (f[c] + S) / D : 0.0f;
}

/* One Jacobi/Chebyshev step on D^-1 A (docs/METHOD.md, "Multigrid"), reading
 * uin and writing uout (ping-pong buffers, so that the residual is fused in):
 *     d <- cd d + cr D^-1 (f - A uin),   uout = uin + d.
 * mg_jacobi is the step with cd = 0 (it does not read d): Jacobi sweeps and the
 * first Chebyshev step. (Reading d under a condition kept PoCL from vectorizing.) */
#define HV_CHEB_BODY(DN)                                                                          \
    HV_CELL_OR_RETURN(N, i, j, k, c);                                                             \
    float S, D;                                                                                   \
    HV_STENCIL(float, uin, N, C, a, w0, w1, w2, i, j, k, c, S, D);                                \
    const float r = f[c] - (D * uin[c] - S);                                                      \
    const float z = D > 0.0f ? r / D : 0.0f;                                                      \
    const float dn = (DN);                                                                        \
    d[c] = dn;                                                                                    \
    uout[c] = uin[c] + dn

__kernel void mg_cheb(HV_LEVEL_ARGS, __global const float *uin, __global float *uout,
                      __global const float *f, __global float *d, float cd, float cr)
{
    HV_CHEB_BODY(cd * d[c] + cr * z);
}

__kernel void mg_jacobi(HV_LEVEL_ARGS, __global const float *uin, __global float *uout,
                        __global const float *f, __global float *d, float cr)
{
    HV_CHEB_BODY(cr * z);
}

/* The step from u = 0, which reads neither u nor d: d = cr D^-1 f, uout = d
 * (the stencil runs on f for its diagonal alone). */
__kernel void mg_jacobi0(HV_LEVEL_ARGS, __global float *uout, __global const float *f,
                         __global float *d, float cr)
{
    HV_CELL_OR_RETURN(N, i, j, k, c);
    float S, D;
    HV_STENCIL(float, f, N, C, a, w0, w1, w2, i, j, k, c, S, D);
    const float r = f[c];
    const float dn = D > 0.0f ? cr * r / D : 0.0f;
    d[c] = dn;
    uout[c] = dn;
}

/* Children of coarse cell (I,J,K) along the coarsened axes co; children
 * beyond an odd edge are left out (they count as zero in the mean). */
#define HV_CHILDREN(NF, co, I, J, K, i0, i1, j0, j1, k0, k1)                                       \
    const int i0 = (co).x ? 2 * (I) : (I), j0 = (co).y ? 2 * (J) : (J), k0 = (co).z ? 2 * (K) : (K); \
    const int i1 = ((co).x && i0 + 1 < (NF).x) ? i0 + 1 : i0;                                      \
    const int j1 = ((co).y && j0 + 1 < (NF).y) ? j0 + 1 : j0;                                      \
    const int k1 = ((co).z && k0 + 1 < (NF).z) ? k0 + 1 : k0

/* fc = mean over the children of the fine residual f - A u (co.w = number of
 * children, 2^(coarsened axes)). */
__kernel void mg_restrict_residual(HV_LEVEL_ARGS, __global const float *u,
                                   __global const float *f, int4 NC, int4 co,
                                   __global float *fc)
{
    HV_CELL_OR_RETURN(NC, I, J, K, cc);
    HV_CHILDREN(N, co, I, J, K, i0, i1, j0, j1, k0, k1);
    float s = 0.0f;
    for (int k = k0; k <= k1; k++)
        for (int j = j0; j <= j1; j++)
            for (int i = i0; i <= i1; i++) {
                const size_t c = (size_t)i + (size_t)N.x * ((size_t)j + (size_t)N.y * (size_t)k);
                float S, D;
                HV_STENCIL(float, u, N, C, a, w0, w1, w2, i, j, k, c, S, D);
                s += f[c] - (D * u[c] - S);
            }
    fc[cc] = s * (1.0f / (float)co.w);
}

/* dst = mean over the children of src. */
__kernel void mg_restrict(int4 N, __global const float *src, int4 NC, int4 co,
                          __global float *dst)
{
    HV_CELL_OR_RETURN(NC, I, J, K, cc);
    HV_CHILDREN(N, co, I, J, K, i0, i1, j0, j1, k0, k1);
    float s = 0.0f;
    for (int k = k0; k <= k1; k++)
        for (int j = j0; j <= j1; j++)
            for (int i = i0; i <= i1; i++)
                s += src[(size_t)i + (size_t)N.x * ((size_t)j + (size_t)N.y * (size_t)k)];
    dst[cc] = s * (1.0f / (float)co.w);
}

/* Per-axis prolongation stencil: fine index i takes 3/4 of coarse I = i/2 and
 * 1/4 of the neighbour I1 on i's side, all weight on I at walls (w1 = 0). */
#define HV_PROLONG_AXIS(coarsen, nc, i, I0, I1, w1)                                                \
    int I0 = (i), I1 = (i);                                                                        \
    float w1 = 0.0f;                                                                               \
    if (coarsen) {                                                                                 \
        const int nb_ = ((i) & 1) ? ((i) >> 1) + 1 : ((i) >> 1) - 1;                               \
        I0 = I1 = (i) >> 1;                                                                        \
        if (nb_ >= 0 && nb_ < (nc)) {                                                              \
            I1 = nb_;                                                                              \
            w1 = 0.25f;                                                                            \
        }                                                                                          \
    }

/* Weight of coarse index I in the prolongation stencil of fine index i along
 * one axis (mg_transfer.c prolong_axis_weight). */
static float hv_prolong_axis_weight(int coarsen, int nc, int i, int I)
{
    HV_PROLONG_AXIS(coarsen, nc, i, I0, I1, w1);
    return (I0 == I ? 1.0f - w1 : 0.0f) + (I1 == I ? w1 : 0.0f);
}

/* fc = P^T (pn .* r) / co.w, the restriction of the symmetric cycle (PCG), as
 * mg_transfer.c's hv__mg_restrict_transpose: each coarse cell gathers the fine cells whose
 * interpolation stencil reaches it (2I-1 .. 2I+2 along coarsened axes), in the
 * CPU's order. ac is the coarse cell weights (NULL when the coarse level is
 * plain; empty coarse cells get 0), pn the fine renormalization (NULL = 1). */
__kernel void hv__mg_restrict_transpose(int4 N, __global const float *r, __global const float *pn,
                                    int4 NC, __global const float *ac, int4 co,
                                    __global float *fc)
{
    HV_CELL_OR_RETURN(NC, I, J, K, cc);
    if (ac) {
        if (ac[cc] == 0.0f) {
            fc[cc] = 0.0f;
            return;
        }
    }
    const int i0 = co.x ? max(2 * I - 1, 0) : I, i1 = co.x ? min(2 * I + 2, N.x - 1) : I;
    const int j0 = co.y ? max(2 * J - 1, 0) : J, j1 = co.y ? min(2 * J + 2, N.y - 1) : J;
    const int k0 = co.z ? max(2 * K - 1, 0) : K, k1 = co.z ? min(2 * K + 2, N.z - 1) : K;
    float s = 0.0f;
    for (int k = k0; k <= k1; k++) {
        const float wk = hv_prolong_axis_weight(co.z, NC.z, k, K);
        if (wk == 0.0f)
            continue;
        for (int j = j0; j <= j1; j++) {
            const float wj = hv_prolong_axis_weight(co.y, NC.y, j, J);
            if (wj == 0.0f)
                continue;
            const size_t row = (size_t)N.x * ((size_t)j + (size_t)N.y * (size_t)k);
            for (int i = i0; i <= i1; i++) {
                const float w = wk * wj * hv_prolong_axis_weight(co.x, NC.x, i, I);
                if (w == 0.0f)
                    continue;
                const size_t f = row + (size_t)i;
                s += w * (pn ? pn[f] : 1.0f) * r[f];
            }
        }
    }
    fc[cc] = s * (1.0f / (float)co.w);
}

/* One of the 8 coarse terms: weight W at coarse (I, J, K), left out where the
 * weighted coarse level is empty (the CPU also skips W == 0, which adds 0). */
#define HV_PROLONG_TERM(W, I, J, K)                                                                \
    do {                                                                                           \
        const size_t cc_ = (size_t)(I) + (size_t)NC.x * ((size_t)(J) + (size_t)NC.y * (size_t)(K)); \
        const float w_ = ac[cc_] == 0.0f ? 0.0f : (W);                                            \
        s += w_ * uc[cc_];                                                                         \
        ws += w_;                                                                                  \
    } while (0)

/* uf += P uc: cell-centred (bi/tri)linear interpolation from a weighted
 * coarse level (ac): empty coarse cells are left out and the weights
 * renormalized; solid cells of a weighted fine level (af != NULL) are skipped. */
__kernel void mg_prolong_w(int4 N, __global const float *af, int4 NC, __global const float *ac,
                           int4 co, __global const float *uc, __global float *uf)
{
    HV_CELL_OR_RETURN(N, i, j, k, fc);
    if (af) {
        if (af[fc] == 0.0f)
            return;
    }
    HV_PROLONG_AXIS(co.z, NC.z, k, K0, K1, wk1);
    HV_PROLONG_AXIS(co.y, NC.y, j, J0, J1, wj1);
    HV_PROLONG_AXIS(co.x, NC.x, i, I0, I1, wi1);
    const float wk0 = 1.0f - wk1, wj0 = 1.0f - wj1, wi0 = 1.0f - wi1;
    float s = 0.0f, ws = 0.0f;
    HV_PROLONG_TERM(wk0 * wj0 * wi0, I0, J0, K0);
    HV_PROLONG_TERM(wk0 * wj0 * wi1, I1, J0, K0);
    HV_PROLONG_TERM(wk0 * wj1 * wi0, I0, J1, K0);
    HV_PROLONG_TERM(wk0 * wj1 * wi1, I1, J1, K0);
    HV_PROLONG_TERM(wk1 * wj0 * wi0, I0, J0, K1);
    HV_PROLONG_TERM(wk1 * wj0 * wi1, I1, J0, K1);
    HV_PROLONG_TERM(wk1 * wj1 * wi0, I0, J1, K1);
    HV_PROLONG_TERM(wk1 * wj1 * wi1, I1, J1, K1);
    if (ws > 0.0f)
        uf[fc] += s / ws;
}

/* uf += P uc from a plain coarse level (the fine level may be weighted: af is
 * then not NULL and its solid cells are skipped). Work-item X of a row serves
 * the fine cells 2X and 2X+1 when x is coarsened (cell X otherwise), so that
 * coarse values are read as contiguous vectors: the coarse rows are first
 * interpolated in y and z at X-1, X, X+1, then in x. */
__kernel void mg_prolong(int4 N, __global const float *af, int4 NC, int4 co,
                         __global const float *uc, __global float *uf)
{
    const int X = get_global_id(0), row = get_global_id(1);
    if (X >= NC.x || row >= N.y * N.z)
        return;
    const int j = row % N.y, k = row / N.y;
    HV_PROLONG_AXIS(co.z, NC.z, k, K0, K1, wk1);
    HV_PROLONG_AXIS(co.y, NC.y, j, J0, J1, wj1);
    const float w00 = (1.0f - wk1) * (1.0f - wj1), w01 = (1.0f - wk1) * wj1;
    const float w10 = wk1 * (1.0f - wj1), w11 = wk1 * wj1;
    const size_t r00 = (size_t)NC.x * ((size_t)J0 + (size_t)NC.y * K0);
    const size_t r01 = (size_t)NC.x * ((size_t)J1 + (size_t)NC.y * K0);
    const size_t r10 = (size_t)NC.x * ((size_t)J0 + (size_t)NC.y * K1);
    const size_t r11 = (size_t)NC.x * ((size_t)J1 + (size_t)NC.y * K1);
#define HV_ROW_VALUE(I) (w00 * uc[r00 + (I)] + w01 * uc[r01 + (I)] + w10 * uc[r10 + (I)] + w11 * uc[r11 + (I)])
    const float v = HV_ROW_VALUE(X);
    const size_t frow = (size_t)N.x * (size_t)row;
    if (co.x) {
        /* at the walls the neighbour is the cell itself: all weight on X */
        const float vl = HV_ROW_VALUE(max(X - 1, 0)), vr = HV_ROW_VALUE(min(X + 1, NC.x - 1));
        const float f0 = 0.75f * v + 0.25f * vl, f1 = 0.75f * v + 0.25f * vr;
        const size_t i0 = frow + 2 * X, i1 = i0 + 1;
        const int has1 = 2 * X + 1 < N.x;
        if (af) {
            if (af[i0] != 0.0f)
                uf[i0] += f0;
            if (has1 && af[i1] != 0.0f)
                uf[i1] += f1;
        } else {
            uf[i0] += f0;
            if (has1)
                uf[i1] += f1;
        }
    } else {
        if (af) {
            if (af[frow + X] != 0.0f)
                uf[frow + X] += v;
        } else {
            uf[frow + X] += v;
        }
    }
#undef HV_ROW_VALUE
}

/* mg_prolong for the common case, plain fine and coarse levels with x
 * coarsened, without branches (1.8x faster on PoCL). */
__kernel void mg_prolong_x2(int4 N, int4 NC, int4 co, __global const float *uc,
                            __global float *uf)
{
    const int X = get_global_id(0), row = get_global_id(1);
    if (X >= NC.x || row >= N.y * N.z)
        return;
    const int j = row % N.y, k = row / N.y;
    HV_PROLONG_AXIS(co.z, NC.z, k, K0, K1, wk1);
    HV_PROLONG_AXIS(co.y, NC.y, j, J0, J1, wj1);
    const float w00 = (1.0f - wk1) * (1.0f - wj1), w01 = (1.0f - wk1) * wj1;
    const float w10 = wk1 * (1.0f - wj1), w11 = wk1 * wj1;
    __global const float *c00 = uc + (size_t)NC.x * ((size_t)J0 + (size_t)NC.y * K0);
    __global const float *c01 = uc + (size_t)NC.x * ((size_t)J1 + (size_t)NC.y * K0);
    __global const float *c10 = uc + (size_t)NC.x * ((size_t)J0 + (size_t)NC.y * K1);
    __global const float *c11 = uc + (size_t)NC.x * ((size_t)J1 + (size_t)NC.y * K1);
    const int Xl = max(X - 1, 0), Xr = min(X + 1, NC.x - 1);
    const float v = w00 * c00[X] + w01 * c01[X] + w10 * c10[X] + w11 * c11[X];
    const float vl = w00 * c00[Xl] + w01 * c01[Xl] + w10 * c10[Xl] + w11 * c11[Xl];
    const float vr = w00 * c00[Xr] + w01 * c01[Xr] + w10 * c10[Xr] + w11 * c11[Xr];
    __global float *o = uf + (size_t)N.x * (size_t)row + 2 * X;
    o[0] += 0.75f * v + 0.25f * vl;
    if (2 * X + 1 < N.x)
        o[1] += 0.75f * v + 0.25f * vr;
}

/* The bottom kernel's loops give every work-item the same trip count, guard
 * the body, and end on flags rather than break: with
 * for (c = lid; c < n; c += L), PoCL 3.1 stored past the end of a one-cell
 * level (valgrind), corrupting the heap. */
#define HV_GROUP_LOOP_BEGIN(c, n)                                                                  \
    for (size_t c##0_ = 0; c##0_ < (n); c##0_ += get_local_size(0)) {                             \
        const size_t c = c##0_ + get_local_id(0);                                                 \
        if (c < (n)) {
#define HV_GROUP_LOOP_END                                                                          \
    }                                                                                              \
    }

/* Subtracts the per-region mean (regions labelled in region, -1 = none;
 * rinv = 1/cells per region) from v, by work-item 0: the bottom is tiny. */
static void hv_bottom_project(__global acc_t *v, size_t n, __global const int *region,
                              __global const acc_t *rinv, int nregion, __global acc_t *sum)
{
    if (get_local_id(0) == 0) {
        for (int r = 0; r < nregion; r++)
            sum[r] = 0;
        for (size_t c = 0; c < n; c++)
            if (region[c] >= 0)
                sum[region[c]] += v[c];
        for (int r = 0; r < nregion; r++)
            sum[r] *= rinv[r];
    }
    barrier(CLK_GLOBAL_MEM_FENCE);
    HV_GROUP_LOOP_BEGIN(c, n) if (region[c] >= 0) v[c] -= sum[region[c]]; HV_GROUP_LOOP_END
    barrier(CLK_GLOBAL_MEM_FENCE);
}

/* Bottom solve: CG from zero on A u = f in acc_t, one work-group, to 1e-12
 * relative (as the CPU bottom solver; 1e-6 without fp64, where it also stops
 * when the residual stalls). With region != NULL (Poisson) f and u are
 * projected onto mean-free per region. scr holds 5n + nregion acc_t. */
__kernel void hv__mg_bottom_cg(int4 N, acc4_t C, __global const float *a, __global const float *w0,
                           __global const float *w1, __global const float *w2,
                           __global const float *f, __global float *u,
                           __global const int *region, __global const acc_t *rinv, int nregion,
                           __global acc_t *scr)
{
    __local acc_t red[HV_WG_MAX];
    const size_t n = (size_t)N.x * N.y * N.z;
    __global acc_t *x = scr, *b = x + n, *r = b + n, *p = r + n, *q = p + n, *sum = q + n;
#ifdef HV_FP64
    const acc_t tol = 1e-12;
#else
    const acc_t tol = 1e-6f;
#endif
    HV_GROUP_LOOP_BEGIN(c, n) x[c] = 0; b[c] = f[c]; HV_GROUP_LOOP_END
    barrier(CLK_GLOBAL_MEM_FENCE);
    if (region)
        hv_bottom_project(b, n, region, rinv, nregion, sum);
    acc_t t = 0;
    HV_GROUP_LOOP_BEGIN(c, n) r[c] = b[c]; p[c] = b[c]; t += b[c] * b[c]; HV_GROUP_LOOP_END
    acc_t rr = hv_group_sum(t, red), best = rr;
    const acc_t bn = sqrt(rr);
    int stall = 0, done = !(bn > 0);
    barrier(CLK_GLOBAL_MEM_FENCE);
    for (int it = 0; it < 4 * (int)n + 50 && !done; it++) {
        t = 0;
        HV_GROUP_LOOP_BEGIN(c, n)
            const int i = c % N.x, j = (c / N.x) % N.y, k = c / ((size_t)N.x * N.y);
            acc_t S, D;
            HV_STENCIL(acc_t, p, N, C, a, w0, w1, w2, i, j, k, c, S, D);
            q[c] = D * p[c] - S;
            t += p[c] * q[c]; HV_GROUP_LOOP_END
        const acc_t pq = hv_group_sum(t, red);
        /* p.q <= 0 ends the iteration with x unchanged, as the CPU's break */
        const acc_t al = pq > 0 ? rr / pq : 0;
        t = 0;
        HV_GROUP_LOOP_BEGIN(c, n) x[c] += al * p[c]; r[c] -= al * q[c]; t += r[c] * r[c]; HV_GROUP_LOOP_END
        const acc_t rr2 = hv_group_sum(t, red), be = rr2 / rr;
        rr = rr2;
        /* every work-item reads p's neighbours in the next apply */
        barrier(CLK_GLOBAL_MEM_FENCE);
        HV_GROUP_LOOP_BEGIN(c, n) p[c] = r[c] + be * p[c]; HV_GROUP_LOOP_END
        barrier(CLK_GLOBAL_MEM_FENCE);
        done = !(pq > 0) || !(sqrt(rr) > tol * bn);
#ifndef HV_FP64
        if (rr < 0.9f * best) {
            best = rr;
            stall = 0;
        } else if (++stall >= 20) {
            done = 1;
        }
#endif
    }
    (void)best;
    (void)stall;
    barrier(CLK_GLOBAL_MEM_FENCE);
    if (region && bn > 0)
        hv_bottom_project(x, n, region, rinv, nregion, sum);
    HV_GROUP_LOOP_BEGIN(c, n) u[c] = (float)x[c]; HV_GROUP_LOOP_END
}
