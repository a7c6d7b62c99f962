/*
 * Device steps of the heat-method distance (src/distance/distance_heat.c,
 * distance_cl.c): the face-direction assignment from trusted log-ratios of the
 * two diffused fields, the next front's weights, the divergence of the face
 * field and the output with the per-region offsets. Double precision where
 * the host path uses it, so fp64 devices only (the host path runs otherwise).
 * N = (nx, ny, nz, dim); face arrays of axis a have n[a] + 1 faces along a,
 * index i + m0 * (j + m1 * k) with m0 = nx + (a == 0), m1 = ny + (a == 1).
 * Stencil kernels over cells or faces run on 2D ranges (x, row).
 */
#ifdef HV_FP64

/* Sum of a count over a power-of-two work-group, then one atomic. */
static void dist_count(uint v, __global uint *cnt, __local uint *red)
{
    const int lid = get_local_id(0) + get_local_size(0) * get_local_id(1);
    const int n = get_local_size(0) * get_local_size(1);
    red[lid] = v;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int h = n >> 1; h > 0; h >>= 1) {
        if (lid < h)
            red[lid] += red[lid + h];
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid == 0 && red[0])
        atomic_add(cnt, red[0]);
}

/* X = 0 on closed faces (walls, solid cells, regions without a source), NaN
 * (to be assigned) on the open ones, counted in cnt[0] (init_faces). */
__kernel void dist_faces(int4 N, int axis, __global const int *region, __global float *X,
                         __global uint *cnt)
{
    __local uint red[HV_WG_MAX];
    const int m0 = N.x + (axis == 0), m1 = N.y + (axis == 1), m2 = N.z + (axis == 2);
    const int i = get_global_id(0), row = get_global_id(1);
    uint open = 0;
    if (i < m0 && row < m1 * m2) {
        const int j = row % m1, k = row / m1;
        const int idx[3] = {i, j, k}, n[3] = {N.x, N.y, N.z};
        const size_t s[3] = {1, (size_t)N.x, (size_t)N.x * N.y};
        float v = 0.0f;
        if (idx[axis] > 0 && idx[axis] < n[axis]) {
            const size_t R = (size_t)i + (size_t)N.x * ((size_t)j + (size_t)N.y * k), L = R - s[axis];
            if (region[L] >= 0 && region[R] >= 0) {
                v = NAN;
                open = 1;
            }
        }
        X[(size_t)i + (size_t)m0 * (size_t)row] = v;
    }
    dist_count(open, cnt, red);
}

/* u = ln u(t), u2 = psi = ln u(t) - ln u(T_RATIO t) on trusted cells (-inf elsewhere),
 * ok = in a region with a source and both logs above their trust bounds. */
__kernel void dist_log(ulong n, __global const int *region, __global double *u,
                       __global double *u2, __global uchar *ok, double lthr, double lthr2)
{
    const size_t c = get_global_id(0);
    if (c >= n)
        return;
    const double a = u[c], b = u2[c];
    const double l1 = a > 0 ? log(a) : -INFINITY, l2 = b > 0 ? log(b) : -INFINITY;
    const int o = region[c] >= 0 && l1 > lthr && l2 > lthr2;
    ok[c] = o;
    u[c] = l1;
    u2[c] = o ? l1 - l2 : -INFINITY;
}

/* Differences of u on the axis-b faces on both sides of cell c (those open
 * and trusted) added to *sum; returns how many (transverse()). */
static int dist_transverse(__global const double *u, __global const uchar *ok, size_t c,
                           const int idx[3], const int n[3], const size_t s[3], int b, double *sum)
{
    int m = 0;
    if (idx[b] > 0) {
        const size_t o = c - s[b];
        if (ok[o]) {
            *sum += u[c] - u[o];
            m++;
        }
    }
    if (idx[b] + 1 < n[b]) {
        const size_t o = c + s[b];
        if (ok[o]) {
            *sum += u[o] - u[c];
            m++;
        }
    }
    return m;
}

/* assign_faces for one axis: every unassigned (NaN) face whose two cells are
 * trusted gets -grad psi / |grad psi| from its own difference and the mean of
 * the trusted transverse differences around it. cnt[0] += faces left,
 * cnt[1] += faces assigned. */
__kernel void dist_assign(int4 N, int axis, __global const double *psi, __global const uchar *ok,
                          __global float *X, __global uint *cnt)
{
    __local uint red[HV_WG_MAX];
    const int m0 = N.x + (axis == 0), m1 = N.y + (axis == 1), m2 = N.z + (axis == 2);
    const int i = get_global_id(0), row = get_global_id(1);
    uint left = 0, done = 0;
    if (i < m0 && row < m1 * m2) {
        const size_t f = (size_t)i + (size_t)m0 * (size_t)row;
        if (isnan(X[f])) {
            const int j = row % m1, k = row / m1, n[3] = {N.x, N.y, N.z};
            const size_t s[3] = {1, (size_t)N.x, (size_t)N.x * N.y};
            const size_t R = (size_t)i + (size_t)N.x * ((size_t)j + (size_t)N.y * k), L = R - s[axis];
            if (!(ok[L] && ok[R])) {
                left = 1;
            } else {
                double D[3] = {0, 0, 0};
                D[axis] = psi[L] - psi[R];
                const int iR[3] = {i, j, k};
                int iL[3] = {i, j, k};
                iL[axis]--;
                for (int b = 0; b < N.w; b++) {
                    if (b == axis)
                        continue;
                    double sum = 0;
                    const int m = dist_transverse(psi, ok, L, iL, n, s, b, &sum) +
                                  dist_transverse(psi, ok, R, iR, n, s, b, &sum);
                    if (m)
                        D[b] = -sum / m;
                }
                double dn = 0;
                for (int b = 0; b < N.w; b++)
                    dn += D[b] * D[b];
                X[f] = dn > 0 ? (float)(D[axis] / sqrt(dn)) : 0.0f;
                done = 1;
            }
        }
    }
    dist_count(left, cnt, red);
    dist_count(done, cnt + 1, red);
}

/* part[3g..3g+2] = group g's sums of w psi, w lu and w over the trusted cells
 * with w > 0 (blocks as red_dot_f). The tree is hv_group_sum's, written out
 * here: where this kernel is hv_group_sum's only caller (a program of
 * common.cl and this file), clang folds its constant argument red into the
 * helper, and PoCL then keeps red as one static array shared by every
 * work-group, not a __local per group, so concurrent groups race on it. */
__kernel void dist_front_sums(ulong n, __global const double *w, __global const double *psi,
                              __global const double *lu, __global const uchar *ok,
                              __global double *part)
{
    __local double red[3][HV_WG_MAX];
    const int lid = get_local_id(0);
    const size_t base = get_group_id(0) * (HV_WG * HV_RED_BLOCK) + lid;
    double s0 = 0, s1 = 0, sw = 0;
    for (int q = 0; q < HV_RED_BLOCK; q++) {
        const size_t c = base + q * HV_WG;
        if (c < n && w[c] > 0 && ok[c]) {
            s0 += w[c] * psi[c];
            s1 += w[c] * lu[c];
            sw += w[c];
        }
    }
    red[0][lid] = s0;
    red[1][lid] = s1;
    red[2][lid] = sw;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int h = (int)get_local_size(0) >> 1; h > 0; h >>= 1) {
        if (lid < h) {
            red[0][lid] += red[0][lid + h];
            red[1][lid] += red[1][lid + h];
            red[2][lid] += red[2][lid + h];
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid == 0) {
        const size_t g = get_group_id(0);
        part[3 * g] = red[0][0];
        part[3 * g + 1] = red[1][0];
        part[3 * g + 2] = red[2][0];
    }
}

/* kappa h of the lattice plane wave normal to nu (lattice_kappa). */
static double dist_kappa(const double nu[3], int dim, double tau)
{
    double k = sqrt(tau);
    for (int it = 0; it < 8; it++) {
        double g = -tau, dg = 0;
        for (int b = 0; b < dim; b++) {
            g += 2 * (cosh(k * nu[b]) - 1);
            dg += 2 * nu[b] * sinh(k * nu[b]);
        }
        if (!(dg > 0))
            break;
        const double step = g / dg;
        k -= step;
        if (fabs(step) < 1e-12 * k)
            break;
    }
    return k;
}

/* next_front's cell pass: the distance e travelled from the current front
 * (psi0) along the direction of -grad psi, the new front's weights w at
 * e = step (half width band), cells with e <= step inside; cnt[0] += front
 * cells. */
__kernel void dist_front(int4 N, __global const double *psi, __global const uchar *ok,
                         __global uchar *inside, __global double *w, double psi0, double step,
                         double tau0, double tau1, double band, __global uint *cnt)
{
    __local uint red[HV_WG_MAX];
    const int i = get_global_id(0), row = get_global_id(1);
    uint nf = 0;
    if (i < N.x && row < N.y * N.z) {
        const int j = row % N.y, k = row / N.y;
        const int idx[3] = {i, j, k}, n[3] = {N.x, N.y, N.z};
        const size_t s[3] = {1, (size_t)N.x, (size_t)N.x * N.y};
        const size_t c = (size_t)i + (size_t)N.x * (size_t)row;
        double v = 0;
        if (!inside[c] && ok[c]) {
            double nu[3] = {0, 0, 0}, nn = 0;
            for (int b = 0; b < N.w; b++) {
                double sum = 0;
                const int m = dist_transverse(psi, ok, c, idx, n, s, b, &sum);
                nu[b] = m ? -sum / m : 0;
                nn += nu[b] * nu[b];
            }
            if (nn > 0) {
                nn = sqrt(nn);
                for (int b = 0; b < N.w; b++)
                    nu[b] = fabs(nu[b]) / nn;
                const double dk = dist_kappa(nu, N.w, tau0) - dist_kappa(nu, N.w, tau1);
                const double e = (psi0 - psi[c]) / dk;
                const double sb = (e - step) / band;
                if (fabs(sb) < 1) {
                    v = (1 - sb * sb) * (1 - sb * sb);
                    nf = 1;
                }
                if (e <= step)
                    inside[c] = 1;
            }
        }
        w[c] = v;
    }
    dist_count(nf, cnt, red);
}

/* f = -div X / h on cells of regions with a source, 0 elsewhere; faces never
 * assigned (NaN) count 0 (divergence()). X2 unused in 2D. */
__kernel void dist_div(int4 N, __global const int *region, __global const float *X0,
                       __global const float *X1, __global const float *X2, double inv_h,
                       __global double *f)
{
    const int i = get_global_id(0), row = get_global_id(1);
    if (i >= N.x || row >= N.y * N.z)
        return;
    const int j = row % N.y, k = row / N.y;
    const size_t c = (size_t)i + (size_t)N.x * (size_t)row;
    double s = 0;
    if (region[c] >= 0) {
        const size_t fx = (size_t)i + (size_t)(N.x + 1) * (size_t)row;
        const size_t fy = (size_t)i + (size_t)N.x * ((size_t)j + (size_t)(N.y + 1) * k);
        float lo = X0[fx], hi = X0[fx + 1];
        s += (double)(isnan(hi) ? 0.0f : hi) - (double)(isnan(lo) ? 0.0f : lo);
        lo = X1[fy];
        hi = X1[fy + N.x];
        s += (double)(isnan(hi) ? 0.0f : hi) - (double)(isnan(lo) ? 0.0f : lo);
        if (N.w == 3) {
            lo = X2[c];
            hi = X2[c + (size_t)N.x * N.y];
            s += (double)(isnan(hi) ? 0.0f : hi) - (double)(isnan(lo) ? 0.0f : lo);
        }
    }
    f[c] = -s * inv_h;
}

/* out[q] = u[idx[q]] */
__kernel void dist_gather(__global const double *u, __global const uint *idx,
                          __global double *out, ulong m)
{
    const size_t q = get_global_id(0);
    if (q < m)
        out[q] = u[idx[q]];
}

/* The distance field: phi minus its region's offset, clamped at 0; the solid
 * and unreachable values elsewhere. */
__kernel void dist_output(ulong n, __global const int *region, __global const double *u,
                          __global const double *off, float solid_value, float unreachable,
                          __global float *out)
{
    const size_t c = get_global_id(0);
    if (c >= n)
        return;
    const int r = region[c];
    if (r >= 0) {
        const double v = u[c] - off[r];
        out[c] = (float)(v > 0 ? v : 0);
    } else {
        out[c] = r == -1 ? solid_value : unreachable;
    }
}

/* ---- Stages on tiles (src/distance/distance_band.c) ---------------------
 * The band's cells are stored tile after tile in list order: T = (tx, ty, tz,
 * cells of a tile), NT = (tiles along x, y, z, tiles); nbr holds six slots per
 * listed tile (-x +x -y +y -z +z, -1: no band tile there); code is 0 off the
 * unknowns, else 1 + the open faces (a closed face's neighbour holds 0). */

/* Per tile: whether a cell holds a front weight, and its open faces without
 * a direction (a face counts in the tile of its upper cell). */
__kernel void dist_tile_flags(int4 N, int4 T, int4 NT, __global const double *w,
                              __global const float *X0, __global const float *X1,
                              __global const float *X2, __global uchar *front, __global int *open)
{
    const size_t t = get_global_id(0);
    if (t >= (size_t)NT.w)
        return;
    const int i0 = (int)(t % NT.x) * T.x, j0 = (int)((t / NT.x) % NT.y) * T.y;
    const int k0 = (int)(t / ((size_t)NT.x * NT.y)) * T.z;
    int fr = 0, nopen = 0;
    for (int k = k0; k < k0 + T.z && k < N.z; k++)
        for (int j = j0; j < j0 + T.y && j < N.y; j++)
            for (int i = i0; i < i0 + T.x && i < N.x; i++) {
                const size_t c = (size_t)i + (size_t)N.x * ((size_t)j + (size_t)N.y * k);
                fr |= w[c] > 0;
                if (i > 0)
                    nopen += isnan(X0[(size_t)i + (size_t)(N.x + 1) * ((size_t)j + (size_t)N.y * k)]);
                if (j > 0)
                    nopen += isnan(X1[(size_t)i + (size_t)N.x * ((size_t)j + (size_t)(N.y + 1) * k)]);
                if (N.w == 3 && k > 0)
                    nopen += isnan(X2[c]);
            }
    front[t] = (uchar)fr;
    open[t] = nopen;
}

/* Band cell id's cell of the grid, or -1 past the grid's end. */
static long band_cell(int4 N, int4 T, int4 NT, __global const uint *list, size_t id)
{
    const size_t t = list[id / (size_t)T.w];
    const int l = (int)(id % (size_t)T.w);
    const int i = (int)(t % NT.x) * T.x + l % T.x;
    const int j = (int)((t / NT.x) % NT.y) * T.y + (l / T.x) % T.y;
    const int k = (int)(t / ((size_t)NT.x * NT.y)) * T.z + l / (T.x * T.y);
    if (i >= N.x || j >= N.y || k >= N.z)
        return -1;
    return (long)i + (long)N.x * ((long)j + (long)N.y * k);
}

/* f = the weights w on the band's n cells. */
__kernel void dist_band_gather(int4 N, int4 T, int4 NT, ulong n, __global const uint *list,
                               __global const double *w, __global double *f)
{
    const size_t id = get_global_id(0);
    if (id >= n)
        return;
    const long c = band_cell(N, T, NT, list, id);
    f[id] = c >= 0 ? w[c] : 0.0;
}

/* u = x on the core tiles' n cells. */
__kernel void dist_band_scatter(int4 N, int4 T, int4 NT, ulong n, __global const uint *list,
                                __global const double *x, __global double *u)
{
    const size_t id = get_global_id(0);
    if (id >= n)
        return;
    const long c = band_cell(N, T, NT, list, id);
    if (c >= 0)
        u[c] = x[id];
}

/* The sum of band cell id's six neighbours (0 where there is none), in the
 * host's order (-x +x -y +y -z +z). */
static double band_nb(int4 T, __global const int *nbr, __global const double *x, size_t id)
{
    const size_t q = id / (size_t)T.w;
    const int l = (int)(id % (size_t)T.w);
    const int lx = l % T.x, ly = (l / T.x) % T.y, lz = l / (T.x * T.y);
    const int sy = T.x, sz = T.x * T.y;
    __global const int *nb = nbr + 6 * q;
    double s = lx > 0 ? x[id - 1] : (nb[0] >= 0 ? x[(size_t)nb[0] * T.w + l + (T.x - 1)] : 0.0);
    s += lx + 1 < T.x ? x[id + 1] : (nb[1] >= 0 ? x[(size_t)nb[1] * T.w + l - (T.x - 1)] : 0.0);
    s += ly > 0 ? x[id - sy] : (nb[2] >= 0 ? x[(size_t)nb[2] * T.w + l + sy * (T.y - 1)] : 0.0);
    s += ly + 1 < T.y ? x[id + sy]
                      : (nb[3] >= 0 ? x[(size_t)nb[3] * T.w + l - sy * (T.y - 1)] : 0.0);
    if (T.z > 1) {
        s += lz > 0 ? x[id - sz] : (nb[4] >= 0 ? x[(size_t)nb[4] * T.w + l + sz * (T.z - 1)] : 0.0);
        s += lz + 1 < T.z ? x[id + sz]
                          : (nb[5] >= 0 ? x[(size_t)nb[5] * T.w + l - sz * (T.z - 1)] : 0.0);
    }
    return s;
}

/* One Chebyshev sweep of (I - s Lap) on the band: prev <- omega (cur + D^-1
 * (f - A cur) - prev) + prev on the unknowns, 0 elsewhere. */
__kernel void dist_band_sweep(int4 T, ulong n, __global const int *nbr, __global const uchar *code,
                              __global const double *f, __global const double *cur,
                              __global double *prev, double s, double omega)
{
    const size_t id = get_global_id(0);
    if (id >= n)
        return;
    const int c = code[id];
    if (!c) {
        prev[id] = 0.0;
        return;
    }
    const double x = cur[id], d = 1.0 + s * (c - 1), p = prev[id];
    const double v = omega * ((f[id] - (d * x - s * band_nb(T, nbr, cur, id))) / d + x - p) + p;
    prev[id] = v;
}

/* r = f - A x on the unknowns, 0 elsewhere. */
__kernel void dist_band_residual(int4 T, ulong n, __global const int *nbr,
                                 __global const uchar *code, __global const double *f,
                                 __global const double *x, __global double *r, double s)
{
    const size_t id = get_global_id(0);
    if (id >= n)
        return;
    const int c = code[id];
    r[id] = c ? f[id] - ((1.0 + s * (c - 1)) * x[id] - s * band_nb(T, nbr, x, id)) : 0.0;
}

#endif
