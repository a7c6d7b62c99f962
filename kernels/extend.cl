/*
 * The extension off a level set (src/extend/extend_vhm.c) with its fields on a
 * device (src/extend/extend_cl.c): weights and the choice of where each output
 * cell is read, the right-hand sides on a level's box, and the evaluation of
 * the ratios at the closest points. Same rules and the same order of
 * operations as the host path, in acc_t (double on fp64 devices), so that
 * decisions taken at thresholds (|grad phi| in range, the trust bound) come
 * out as on the host. N = (nx, ny, nz, dim), nz = 1 in 2D; solutions and
 * fields are planes of count floats.
 *
 * Contraction off in this file (fused multiply-adds would round the closest
 * points differently from the host's), back on at its end for whatever
 * follows it in the program.
 */
#pragma OPENCL FP_CONTRACT OFF

/* Counters (int32), as EXT_K_* in src/extend/extend_cl.c. */
#define EXT_NSRC 0
#define EXT_NPEND 1
#define EXT_WBOX 2  /* lo xyz, hi xyz of the cells with a weight */
#define EXT_RBOX 8  /* lo xyz, hi xyz of the cells read at themselves (or still pending) */
#define EXT_LEFT 14
#define EXT_CP 15
#define EXT_RATIO 16
#define EXT_WEAK 17
#define EXT_BAD 18  /* per field component: first cell with a weight and a NaN/Inf value */
#define EXT_EMPTY (1 << 30)

/* Folds v of every work-item into dst with op (0 sum, 1 min, 2 max): a tree
 * in local memory, then one atomic per group and only when the group has
 * something to add. Every work-item must call it. */
static void ext_group_fold(__local int *red, int v, int op, __global int *dst)
{
    const int lid = get_local_id(0) + get_local_size(0) * get_local_id(1);
    const int n = get_local_size(0) * get_local_size(1);
    red[lid] = v;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int s = n >> 1; s > 0; s >>= 1) {
        if (lid < s) {
            const int a = red[lid], b = red[lid + s];
            red[lid] = op == 0 ? a + b : op == 1 ? min(a, b) : max(a, b);
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid == 0) {
        const int t = red[0];
        if (op == 0 && t)
            atomic_add(dst, t);
        else if (op == 1 && t < EXT_EMPTY)
            atomic_min(dst, t);
        else if (op == 2 && t > -EXT_EMPTY)
            atomic_max(dst, t);
    }
    barrier(CLK_LOCAL_MEM_FENCE);
}

/* The box of the cells with has set, folded into K[at..at+6). */
static void ext_group_box(__local int *red, int has, int i, int j, int k, __global int *K, int at)
{
    const int p[3] = {i, j, k};
    for (int a = 0; a < 3; a++) {
        ext_group_fold(red, has ? p[a] : EXT_EMPTY, 1, K + at + a);
        ext_group_fold(red, has ? p[a] : -EXT_EMPTY, 2, K + at + 3 + a);
    }
}

/* Trilinear (bilinear in 2D) stencil at index-space point p, clamped to the
 * grid: stencil() of extend_vhm.c. Returns the number of corners. */
static int ext_stencil(int4 N, const acc_t p[3], size_t idx[8], acc_t wt[8])
{
    const int n[3] = {N.x, N.y, N.z};
    int i0[3] = {0, 0, 0}, i1[3] = {0, 0, 0};
    acc_t fr[3] = {0, 0, 0};
    for (int a = 0; a < N.w; a++) {
        acc_t q = p[a];
        if (q < 0)
            q = 0;
        if (q > n[a] - 1)
            q = n[a] - 1;
        int f = (int)floor(q);
        if (f > n[a] - 2)
            f = n[a] - 2;
        if (f < 0)
            f = 0;
        i0[a] = f;
        i1[a] = n[a] > 1 ? f + 1 : f;
        fr[a] = n[a] > 1 ? q - f : 0;
    }
    const int m = N.w == 3 ? 8 : 4;
    for (int q = 0; q < m; q++) {
        const int ii = (q & 1) ? i1[0] : i0[0], jj = (q & 2) ? i1[1] : i0[1];
        const int kk = (q & 4) ? i1[2] : i0[2];
        idx[q] = (size_t)ii + (size_t)n[0] * ((size_t)jj + (size_t)n[1] * (size_t)kk);
        wt[q] = ((q & 1) ? fr[0] : 1 - fr[0]) * ((q & 2) ? fr[1] : 1 - fr[1]) *
                (N.w == 3 ? ((q & 4) ? fr[2] : 1 - fr[2]) : (acc_t)1);
    }
    return m;
}

static acc_t ext_sample(__global const float *v, const size_t idx[8], const acc_t wt[8], int m)
{
    acc_t s = 0;
    for (int q = 0; q < m; q++)
        s += wt[q] * (acc_t)v[idx[q]];
    return s;
}

/* evaluation_point() of extend_vhm.c: the closest point on the zero set when
 * phi is a distance at cell (i,j,k) (|grad phi| in [gmin, gmax], the point
 * inside the grid and, with validate, phi there within half the band of 0);
 * fills its stencil and returns 1, else leaves the cell's own and returns 0.
 * P = (band, h, gmin, gmax). */
static int ext_eval_point(int4 N, __global const float *phi, acc4_t P, int i, int j, int k,
                          int validate, size_t idx[8], acc_t wt[8], int *m)
{
    const size_t st[3] = {1, (size_t)N.x, (size_t)N.x * N.y};
    const size_t c = (size_t)i + st[1] * (size_t)j + st[2] * (size_t)k;
    const int ijk[3] = {i, j, k}, n[3] = {N.x, N.y, N.z};
    const acc_t h = P.y;
    idx[0] = c;
    wt[0] = 1;
    *m = 1;
    acc_t g[3] = {0, 0, 0}, gn = 0;
    /* Central differences, then (phi_diff2 of extend_internal.h) one-sided
     * ones towards the neighbour of smaller |phi|, on the axes where |phi|
     * grows across the cell, where those are out of range: next to a narrow
     * band's clamp. */
    for (int up = 0; up < 2; up++) {
        for (int a = 0; a < N.w; a++) {
            const int lo = ijk[a] > 0, hi = ijk[a] + 1 < n[a];
            g[a] = 0;
            if (!lo && !hi)
                continue;
            const acc_t pc = phi[c], vp = hi ? phi[c + st[a]] : pc, vm = lo ? phi[c - st[a]] : pc;
            if (up && lo && hi && fabs(vm) < fabs(pc) && fabs(pc) < fabs(vp))
                g[a] = (pc - vm) / h;
            else if (up && lo && hi && fabs(vp) < fabs(pc) && fabs(pc) < fabs(vm))
                g[a] = (vp - pc) / h;
            else
                g[a] = (vp - vm) / ((lo + hi) * h);
        }
        gn = 0;
        for (int a = 0; a < N.w; a++)
            gn += g[a] * g[a];
        gn = sqrt(gn);
        if (gn >= P.z && gn <= P.w)
            break;
    }
    if (!(gn >= P.z && gn <= P.w))
        return 0;
    const acc_t s = (acc_t)phi[c] / (gn * h);
    acc_t p[3] = {i, j, k};
    for (int a = 0; a < N.w; a++) {
        p[a] -= s * g[a];
        if (p[a] < -HV_ACC(0.5) || p[a] > n[a] - HV_ACC(0.5))
            return 0;
    }
    size_t ci[8];
    acc_t cw[8];
    const int cm = ext_stencil(N, p, ci, cw);
    if (validate && fabs(ext_sample(phi, ci, cw, cm)) > HV_ACC(0.5) * fmax(P.x, (acc_t)1) * h)
        return 0;
    for (int q = 0; q < cm; q++) {
        idx[q] = ci[q];
        wt[q] = cw[q];
    }
    *m = cm;
    return 1;
}

/* Per cell: the weight w (a bump of |phi| / (band h) on fluid cells), and
 * pending = 0 for cells outside the output (solid, or |phi| >= out_band h when
 * out_band > 0; their nout output planes get the background), 1 for cells read
 * at their closest point, 2 for cells read at themselves. Counts the source
 * and output cells and boxes the weights and the cells read at themselves.
 * Q = (band h, out_band h). */
__kernel void ext_setup(int4 N, acc4_t P, acc4_t Q, int closest_point,
                        __global const float *phi, __global const uchar *solid,
                        __global float *w, __global uchar *pending, __global float *out, int nout,
                        ulong count, float background, __global int *K)
{
    __local int red[HV_WG_MAX];
    const int i = get_global_id(0), row = get_global_id(1);
    const int inside = i < N.x && row < N.y * N.z;
    const int j = inside ? row % N.y : 0, k = inside ? row / N.y : 0;
    int src = 0, want = 0, self = 0, weighted = 0;
    if (inside) {
        const size_t c = (size_t)i + (size_t)N.x * (size_t)row;
        const int sol = solid && solid[c];
        const acc_t s = (acc_t)phi[c] / Q.x;
        acc_t v = 0;
        if (fabs(s) < 1 && !sol) {
            v = (1 - s * s) * (1 - s * s);
            src = 1;
        }
        const float wf = (float)v;
        w[c] = wf;
        want = !sol && (Q.y == 0 || fabs((acc_t)phi[c]) < Q.y);
        uchar pend = 0;
        if (want) {
            size_t idx[8];
            acc_t wt[8];
            int m;
            pend = closest_point && ext_eval_point(N, phi, P, i, j, k, 1, idx, wt, &m) ? 1 : 2;
            self = pend == 2;
        } else {
            for (int q = 0; q < nout; q++)
                out[(size_t)q * count + c] = background;
        }
        pending[c] = pend;
        weighted = wf > 0;
    }
    ext_group_box(red, weighted, i, j, k, K, EXT_WBOX);
    ext_group_fold(red, src, 0, K + EXT_NSRC);
    ext_group_fold(red, want, 0, K + EXT_NPEND);
    ext_group_box(red, self, i, j, k, K, EXT_RBOX);
}

/* K[EXT_BAD + slot] = min(itself, first cell with a weight where v is not finite). */
__kernel void ext_check(__global const float *w, __global const float *v, ulong off, ulong count,
                        __global int *K, int slot)
{
    const size_t c = get_global_id(0);
    if (c < count && w[c] > 0 && !isfinite(v[off + c]))
        atomic_min(K + EXT_BAD + slot, (int)c);
}

/* Right-hand side on the box of B cells at lo (rhs_value() of extend_vhm.c):
 * mode 0 the weights, 1 the weights times plane `off` of in, 2 the weights
 * times the length of the ncomp planes from `off`. */
__kernel void ext_rhs(int4 N, int4 B, int4 lo, __global const float *w, __global const float *in,
                      int mode, ulong off, int ncomp, ulong count, __global acc_t *out)
{
    const int bi = get_global_id(0), row = get_global_id(1);
    if (bi >= B.x || row >= B.y * B.z)
        return;
    const int bj = row % B.y, bk = row / B.y;
    const size_t c = (size_t)(lo.x + bi) + (size_t)N.x * ((size_t)(lo.y + bj) + (size_t)N.y * (lo.z + bk));
    const acc_t wc = w[c];
    acc_t v = 0;
    if (wc > 0) {
        if (mode == 0) {
            v = wc;
        } else if (mode == 1) {
            v = wc * (acc_t)in[off + c];
        } else {
            acc_t m = 0;
            for (int q = 0; q < ncomp; q++)
                m += (acc_t)in[off + q * count + c] * (acc_t)in[off + q * count + c];
            v = wc * sqrt(m);
        }
    }
    out[(size_t)bi + (size_t)B.x * (size_t)row] = v;
}

/* Plane `off` of sol on the box = (float) the box's solution u. */
__kernel void ext_scatter(int4 N, int4 B, int4 lo, __global const acc_t *u, __global float *sol,
                          ulong off)
{
    const int bi = get_global_id(0), row = get_global_id(1);
    if (bi >= B.x || row >= B.y * B.z)
        return;
    const int bj = row % B.y, bk = row / B.y;
    const size_t c = (size_t)(lo.x + bi) + (size_t)N.x * ((size_t)(lo.y + bj) + (size_t)N.y * (lo.z + bk));
    sol[off + c] = (float)u[(size_t)bi + (size_t)B.x * (size_t)row];
}

/* One level of the level loop of hv_extend_many for every pending cell: the
 * weight W sampled where the cell is read (its closest point; the cell itself
 * once the closest point has no trusted weight), then, when W > thr or on the
 * last level, the ratios of the nfields fields (ncomp[f] each; a vector's
 * magnitude ratio along the direction of its diffused components) from the
 * solution planes, or the background where W <= 0. Cells left for a later
 * level keep pending (2 from now on when their closest point failed) and are
 * boxed in K[EXT_RBOX..]; the stats' counts go to K. P as ext_eval_point. */
__kernel void ext_eval(int4 N, acc4_t P, __global const float *phi, __global uchar *pending,
                       __global const float *sol, ulong count, __global const int *ncomp,
                       int nfields, __global float *out, acc_t thr, int last, float background,
                       __global int *K)
{
    __local int red[HV_WG_MAX];
    const int i = get_global_id(0), row = get_global_id(1);
    const int inside = i < N.x && row < N.y * N.z;
    const int j = inside ? row % N.y : 0, k = inside ? row / N.y : 0;
    const size_t c = (size_t)i + (size_t)N.x * (size_t)row;
    int left = 0, cp = 0, ratio = 0, weak = 0;
    uchar p = inside ? pending[c] : 0;
    if (p) {
        size_t idx[8] = {c, 0, 0, 0, 0, 0, 0, 0};
        acc_t wt[8] = {1, 0, 0, 0, 0, 0, 0, 0};
        int m = 1, at_cp = 0;
        if (p == 1)
            at_cp = ext_eval_point(N, phi, P, i, j, k, 0, idx, wt, &m);
        acc_t W = ext_sample(sol, idx, wt, m);
        if (!(W > thr) && at_cp) {
            at_cp = 0;
            p = 2;
            idx[0] = c;
            wt[0] = 1;
            m = 1;
            W = ext_sample(sol, idx, wt, m);
        }
        if (!(W > thr) && !last) {
            left = 1;
            pending[c] = p;
        } else {
            if (!(W > 0)) {
                int nout = 0;
                for (int f = 0; f < nfields; f++)
                    nout += ncomp[f];
                for (int q = 0; q < nout; q++)
                    out[(size_t)q * count + c] = background;
            } else {
                size_t r = 1, o = 0;
                for (int f = 0; f < nfields; f++) {
                    const int nc = ncomp[f];
                    if (nc == 1) {
                        out[o * count + c] = (float)(ext_sample(sol + r * count, idx, wt, m) / W);
                        r++;
                        o++;
                        continue;
                    }
                    const acc_t mag = ext_sample(sol + r * count, idx, wt, m) / W;
                    acc_t v[3] = {0, 0, 0}, vn = 0;
                    for (int q = 0; q < nc; q++) {
                        v[q] = ext_sample(sol + (r + 1 + q) * count, idx, wt, m);
                        vn += v[q] * v[q];
                    }
                    vn = sqrt(vn);
                    for (int q = 0; q < nc; q++)
                        out[(o + q) * count + c] = vn > 0 ? (float)(mag * v[q] / vn) : 0.0f;
                    r += nc + 1;
                    o += nc;
                }
            }
            weak = !(W > thr);
            cp = at_cp;
            ratio = !at_cp;
            pending[c] = 0;
        }
    }
    ext_group_fold(red, left, 0, K + EXT_LEFT);
    ext_group_fold(red, cp, 0, K + EXT_CP);
    ext_group_fold(red, ratio, 0, K + EXT_RATIO);
    ext_group_fold(red, weak, 0, K + EXT_WEAK);
    ext_group_box(red, left, i, j, k, K, EXT_RBOX);
}

#pragma OPENCL FP_CONTRACT ON
