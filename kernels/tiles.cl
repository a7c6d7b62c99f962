/*
 * The narrow band of a signed distance volume in 8^3 tiles on a device
 * (src/sdf/tiles_cl.c; the host path is src/sdf/sdf_tiles.c, whose steps and
 * arithmetic these kernels repeat):
 *
 *   tiles_trust    per face: whether it bounds a solid (the winding number
 *                  of the other faces at its centroid near 1/2)
 *   tiles_count    per triangle: the tiles its box grown by the reach W
 *                  touches and its plane reaches, counted per tile key
 *   tiles_fill     the triangles into their tiles' lists at the counts'
 *                  prefix sums (src/cl/cl_ops.c): a counting sort of the
 *                  (tile, triangle) pairs by tile
 *   tiles_list     the tile keys that hold a triangle, in key order
 *   tiles_sign     one work-group per tile: the near test, the raster (the
 *                  least packed (distance bits, triangle) per cell), the
 *                  pseudonormal sign near clean surface, the flood of signs
 *                  on closed meshes, the winding number elsewhere, the
 *                  band's values and active bits
 *   tiles_compact  the tiles with an active voxel, in order
 *
 * Tile keys as sdf_tiles.c's tile_key: the 2x2x2 group of tiles numbered
 * along x, then y, then z, then the octant, so that the tiles come out in the
 * host path's order. Double precision throughout, contraction off (fused
 * multiply-adds would round the distances differently from the host's):
 * fp64 devices only. NB = (groups along x, y, z, tiles along x); O = (origin,
 * h); R = (W, band, h, near-sign reach), world units.
 */
#ifdef HV_FP64
#pragma OPENCL FP_CONTRACT OFF

#define TL_TILE 8
#define TL_T3 512
#define TL_WN_BETA 1.0
#define TL_WN_FLAT 0.25
#define TL_PI 3.14159265358979323846

#define TL_DOT(u, v) ((u)[0] * (v)[0] + (u)[1] * (v)[1] + (u)[2] * (v)[2])

/* hv_closest (src/geom/exact.h): the squared distance from p to triangle
 * abc, diff = p - closest point, region 0 face, 1..3 vertex, 4..6 edge. */
static double tl_closest(const double *p, const double *a, const double *b, const double *c,
                         double *q, int *region)
{
    double ab[3], ac[3], ap[3];
    for (int i = 0; i < 3; i++) {
        ab[i] = b[i] - a[i];
        ac[i] = c[i] - a[i];
        ap[i] = p[i] - a[i];
    }
    const double d1 = TL_DOT(ab, ap), d2 = TL_DOT(ac, ap);
    if (d1 <= 0 && d2 <= 0) {
        for (int i = 0; i < 3; i++)
            q[i] = ap[i];
        *region = 1;
        return TL_DOT(ap, ap);
    }
    double bp[3] = {p[0] - b[0], p[1] - b[1], p[2] - b[2]};
    const double d3 = TL_DOT(ab, bp), d4 = TL_DOT(ac, bp);
    if (d3 >= 0 && d4 <= d3) {
        for (int i = 0; i < 3; i++)
            q[i] = bp[i];
        *region = 2;
        return TL_DOT(bp, bp);
    }
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) {
        const double v = d1 / (d1 - d3);
        for (int i = 0; i < 3; i++)
            q[i] = ap[i] - v * ab[i];
        *region = 4;
        return TL_DOT(q, q);
    }
    double cp[3] = {p[0] - c[0], p[1] - c[1], p[2] - c[2]};
    const double d5 = TL_DOT(ab, cp), d6 = TL_DOT(ac, cp);
    if (d6 >= 0 && d5 <= d6) {
        for (int i = 0; i < 3; i++)
            q[i] = cp[i];
        *region = 3;
        return TL_DOT(cp, cp);
    }
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) {
        const double w = d2 / (d2 - d6);
        for (int i = 0; i < 3; i++)
            q[i] = ap[i] - w * ac[i];
        *region = 6;
        return TL_DOT(q, q);
    }
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
        const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        for (int i = 0; i < 3; i++)
            q[i] = bp[i] - w * (c[i] - b[i]);
        *region = 5;
        return TL_DOT(q, q);
    }
    const double denom = 1.0 / (va + vb + vc);
    const double v = vb * denom, w = vc * denom;
    for (int i = 0; i < 3; i++)
        q[i] = ap[i] - ab[i] * v - ac[i] * w;
    *region = 0;
    return TL_DOT(q, q);
}

/* Corner k of triangle t into x. */
static void tl_corner(__global const double *V, __global const uint *T, uint t, int k, double *x)
{
    const size_t v = 3 * (size_t)T[3 * (size_t)t + k];
    x[0] = V[v];
    x[1] = V[v + 1];
    x[2] = V[v + 2];
}

/* ---------- the winding number (src/geom/winding.c) ---------- */

/* Solid angle of abc seen from p (Van Oosterom & Strackee). */
static double tl_solid_angle(const double *p, const double *a, const double *b, const double *c)
{
    double A[3], B[3], C[3];
    for (int d = 0; d < 3; d++) {
        A[d] = a[d] - p[d];
        B[d] = b[d] - p[d];
        C[d] = c[d] - p[d];
    }
    const double la = sqrt(A[0] * A[0] + A[1] * A[1] + A[2] * A[2]);
    const double lb = sqrt(B[0] * B[0] + B[1] * B[1] + B[2] * B[2]);
    const double lc = sqrt(C[0] * C[0] + C[1] * C[1] + C[2] * C[2]);
    const double det = A[0] * (B[1] * C[2] - B[2] * C[1]) - A[1] * (B[0] * C[2] - B[2] * C[0]) +
                       A[2] * (B[0] * C[1] - B[1] * C[0]);
    const double den = la * lb * lc + (A[0] * B[0] + A[1] * B[1] + A[2] * B[2]) * lc +
                       (A[0] * C[0] + A[1] * C[1] + A[2] * C[2]) * lb +
                       (B[0] * C[0] + B[1] * C[1] + B[2] * C[2]) * la;
    return 2.0 * atan2(det, den);
}

/* hv__wn_eval_beta: nodes nd (8 doubles: centre, vector area, radius, 0)
 * and ni (left, right, first, count), faces order[] with their signs. */
static double tl_wn(__global const double *V, __global const uint *T, __global const double *nd,
                    __global const int *ni, __global const uint *order,
                    __global const char *sign, int nnodes, const double *p, uint skip,
                    double beta)
{
    if (!nnodes)
        return 0;
    int stack[128], top = 0;
    double w = 0;
    stack[top++] = 0;
    while (top) {
        const int k = stack[--top];
        __global const double *c = nd + 8 * (size_t)k;
        const double d[3] = {c[0] - p[0], c[1] - p[1], c[2] - p[2]};
        const double dist = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        if (dist > beta * c[6]) {
            w += (c[3] * d[0] + c[4] * d[1] + c[5] * d[2]) / (dist * dist * dist);
            continue;
        }
        const int left = ni[4 * k], right = ni[4 * k + 1];
        if (left < 0 || top > 120) {
            const int first = ni[4 * k + 2], count = ni[4 * k + 3];
            for (int q = first; q < first + count; q++) {
                const uint f = order[q];
                if (f == skip)
                    continue;
                double a[3], b[3], e[3];
                tl_corner(V, T, f, 0, a);
                tl_corner(V, T, f, 1, b);
                tl_corner(V, T, f, 2, e);
                w += sign[q] * tl_solid_angle(p, a, b, e);
            }
            continue;
        }
        stack[top++] = left;
        stack[top++] = right;
    }
    return w / (4 * TL_PI);
}

/* hv__wn_sure (src/sdf/sign_winding.c): dipoles from one radius, refined
 * where the value is near 1/2. *evals counts the evaluations. */
static double tl_wn_sure(__global const double *V, __global const uint *T,
                         __global const double *nd, __global const int *ni,
                         __global const uint *order, __global const char *sign, int nnodes,
                         const double *p, uint *evals)
{
    double beta = TL_WN_BETA, flat = TL_WN_FLAT;
    double w = tl_wn(V, T, nd, ni, order, sign, nnodes, p, 0xffffffffu, beta);
    ++*evals;
    while (fabs(w - 0.5) < flat && beta < 32) {
        beta *= 2;
        flat /= 4;
        w = tl_wn(V, T, nd, ni, order, sign, nnodes, p, 0xffffffffu, beta);
        ++*evals;
    }
    return w;
}

/* pseudo_trusted (src/geom/pseudonormal.c) for every face: 1 where the
 * winding number of the other faces at its centroid is within 1/4 of 1/2,
 * else 2. */
__kernel void tiles_trust(uint ntri, __global const double *V, __global const uint *T,
                          __global const double *nd, __global const int *ni,
                          __global const uint *order, __global const char *sign, int nnodes,
                          __global uchar *ftrust)
{
    const uint f = get_global_id(0);
    if (f >= ntri)
        return;
    double a[3], b[3], e[3], c[3];
    tl_corner(V, T, f, 0, a);
    tl_corner(V, T, f, 1, b);
    tl_corner(V, T, f, 2, e);
    for (int d = 0; d < 3; d++)
        c[d] = (a[d] + b[d] + e[d]) / 3.0;
    double w = tl_wn(V, T, nd, ni, order, sign, nnodes, c, f, 1.0);
    if (fabs(fabs(w - 0.5) - 0.25) < 0.15)
        w = tl_wn(V, T, nd, ni, order, sign, nnodes, c, f, 2.0);
    ftrust[f] = fabs(w - 0.5) < 0.25 ? 1 : 2;
}

/* ---------- binning ---------- */

/* tile_key (src/sdf/sdf_tiles.c). */
static uint tl_key(int4 NB, int x, int y, int z)
{
    return (((uint)(x >> 1) + (uint)NB.x * ((uint)(y >> 1) + (uint)NB.y * (uint)(z >> 1))) << 3) |
           (uint)((x & 1) | (y & 1) << 1 | (z & 1) << 2);
}

/* tri_tiles: the tile range [lo, hi] of triangle t's box grown by W; 0 when
 * it misses the block. */
static int tl_tri_tiles(int4 N, double4 O, double W, const double *a, const double *b,
                        const double *c, int *lo, int *hi)
{
    const int n[3] = {N.x, N.y, N.z};
    const double origin[3] = {O.x, O.y, O.z};
    const int nt[3] = {(N.x + TL_TILE - 1) / TL_TILE, (N.y + TL_TILE - 1) / TL_TILE,
                       (N.z + TL_TILE - 1) / TL_TILE};
    for (int ax = 0; ax < 3; ax++) {
        const double mn = fmin(a[ax], fmin(b[ax], c[ax])) - W;
        const double mx = fmax(a[ax], fmax(b[ax], c[ax])) + W;
        const double l = ceil((mn - origin[ax]) / O.w - 0.5), u = floor((mx - origin[ax]) / O.w - 0.5);
        if (u < 0 || l > n[ax] - 1)
            return 0;
        const int cl = l < 0 ? 0 : (int)l, cu = u > n[ax] - 1 ? n[ax] - 1 : (int)u;
        lo[ax] = cl / TL_TILE;
        hi[ax] = cu / TL_TILE;
        if (hi[ax] >= nt[ax])
            hi[ax] = nt[ax] - 1;
    }
    return 1;
}

/* plane_of: the unit normal pn and offset of t's plane, and its reach R
 * (0 normal: a degenerate triangle reaches every tile of its box). */
static double tl_plane(const double *a, const double *b, const double *c, double W, double h,
                       double *pn, double *R)
{
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    const double w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2],
                         u[0] * w[1] - u[1] * w[0]};
    const double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    *R = W + (0.5 * sqrt(3.0) * (TL_TILE - 1) + 1e-3) * h;
    pn[0] = pn[1] = pn[2] = 0;
    if (!(len > 0) || isinf(len))
        return 0;
    for (int k = 0; k < 3; k++)
        pn[k] = n[k] / len;
    return pn[0] * a[0] + pn[1] * a[1] + pn[2] * a[2];
}

/* The tiles triangle t reaches: counted into cnt (fill 0) or, with fill 1,
 * its index put into the lists at start[key] + cur[key]++. */
static void tl_bin(int4 N, int4 NB, double4 O, double W, __global const double *V,
                   __global const uint *T, uint t, __global uint *cnt,
                   __global const uint *start, __global uint *pairs, int fill)
{
    double a[3], b[3], c[3], pn[3], R;
    int lo[3], hi[3];
    tl_corner(V, T, t, 0, a);
    tl_corner(V, T, t, 1, b);
    tl_corner(V, T, t, 2, c);
    if (!tl_tri_tiles(N, O, W, a, b, c, lo, hi))
        return;
    const double d = tl_plane(a, b, c, W, O.w, pn, &R);
    for (int z = lo[2]; z <= hi[2]; z++)
        for (int y = lo[1]; y <= hi[1]; y++)
            for (int x = lo[0]; x <= hi[0]; x++) {
                const double q[3] = {O.x + (x + 0.5) * TL_TILE * O.w,
                                     O.y + (y + 0.5) * TL_TILE * O.w,
                                     O.z + (z + 0.5) * TL_TILE * O.w};
                if (!(fabs(pn[0] * q[0] + pn[1] * q[1] + pn[2] * q[2] - d) <= R))
                    continue;
                const uint key = tl_key(NB, x, y, z);
                const uint at = atomic_inc(&cnt[key]);
                if (fill)
                    pairs[start[key] + at] = t;
            }
}

__kernel void tiles_count(int4 N, int4 NB, double4 O, double W, uint ntri,
                          __global const double *V, __global const uint *T, __global uint *cnt)
{
    const uint t = get_global_id(0);
    if (t < ntri)
        tl_bin(N, NB, O, W, V, T, t, cnt, 0, 0, 0);
}

__kernel void tiles_fill(int4 N, int4 NB, double4 O, double W, uint ntri,
                         __global const double *V, __global const uint *T, __global uint *cur,
                         __global const uint *start, __global uint *pairs)
{
    const uint t = get_global_id(0);
    if (t < ntri)
        tl_bin(N, NB, O, W, V, T, t, cur, start, pairs, 1);
}

/* flag[k] = whether tile key k holds a triangle (start is its exclusive
 * prefix sum of nkeys + 1 entries). */
__kernel void tiles_flag(uint nkeys, __global const uint *start, __global uint *flag)
{
    const uint k = get_global_id(0);
    if (k < nkeys)
        flag[k] = start[k + 1] > start[k];
}

/* The keys with a triangle, in order: list[pos[k]] = k. */
__kernel void tiles_list(uint nkeys, __global const uint *start, __global const uint *pos,
                         __global uint *list)
{
    const uint k = get_global_id(0);
    if (k < nkeys && start[k + 1] > start[k])
        list[pos[k]] = k;
}

/* ---------- the tiles ---------- */

/* hv__pseudo_sign with no current sign: the sign of the pseudonormal of the
 * feature of triangle t nearest to p, where the feature is clean and its
 * faces bound a solid; 0 elsewhere. */
static int tl_pseudo_sign(__global const double *V, __global const uint *T,
                          __global const double *fn, __global const double *vn,
                          __global const uint *other, __global const uchar *vok,
                          __global const uchar *ftrust, uint t, const double *p)
{
    double a[3], b[3], c[3], diff[3], n[3];
    int region;
    tl_corner(V, T, t, 0, a);
    tl_corner(V, T, t, 1, b);
    tl_corner(V, T, t, 2, c);
    tl_closest(p, a, b, c, diff, &region);
    uint o = 0xffffffffu;
    if (region == 0) {
        for (int d = 0; d < 3; d++)
            n[d] = fn[3 * (size_t)t + d];
    } else if (region <= 3) {
        const uint v = T[3 * (size_t)t + region - 1];
        if (!vok[v])
            return 0;
        for (int d = 0; d < 3; d++)
            n[d] = vn[3 * (size_t)v + d];
    } else {
        const int e = region == 4 ? 0 : region == 5 ? 1 : 2;
        o = other[3 * (size_t)t + e];
        if (o == 0xffffffffu)
            return 0;
        for (int d = 0; d < 3; d++)
            n[d] = fn[3 * (size_t)t + d] + fn[3 * (size_t)o + d];
    }
    const double s = diff[0] * n[0] + diff[1] * n[1] + diff[2] * n[2];
    const int sg = s > 0 ? 1 : s < 0 ? -1 : 0;
    if (!sg)
        return 0;
    if (ftrust[t] != 1 || (o != 0xffffffffu && ftrust[o] != 1))
        return 0;
    return sg;
}

/* The tile's first cell and its extent within the block, from its key. */
static void tl_tile_of(int4 N, int4 NB, uint key, int *blo, int *ext)
{
    const uint gk = key >> 3, oc = key & 7;
    const int tc[3] = {2 * (int)(gk % (uint)NB.x) + (int)(oc & 1),
                       2 * (int)(gk / (uint)NB.x % (uint)NB.y) + (int)(oc >> 1 & 1),
                       2 * (int)(gk / (uint)NB.x / (uint)NB.y) + (int)(oc >> 2)};
    const int n[3] = {N.x, N.y, N.z};
    for (int a = 0; a < 3; a++) {
        blo[a] = tc[a] * TL_TILE;
        ext[a] = min(TL_TILE, n[a] - blo[a]);
    }
}

/* Whether triangle t comes within sqrt(r2) of p (tile_near's test). */
static int tl_near_one(__global const double *V, __global const uint *T, uint t, const double *p,
                       double r2)
{
    double a[3], b[3], c[3], q[3];
    int region;
    tl_corner(V, T, t, 0, a);
    tl_corner(V, T, t, 1, b);
    tl_corner(V, T, t, 2, c);
    return tl_closest(p, a, b, c, q, &region) <= r2;
}

/* Triangle x (corners, then its box's lower and upper corners: 15 doubles)
 * written into the column's cells 0..nk-1 at (px, py): best[k] keeps the
 * least (distance bits << 32 | t) within W. */
static void tl_raster_one(const double *x, uint t, double4 O, double W2, double px, double py,
                          double z0, int nk, ulong *best)
{
    const double ex = fmax(fmax(x[9] - px, px - x[12]), 0.0);
    const double ey = fmax(fmax(x[10] - py, py - x[13]), 0.0);
    if (ex * ex + ey * ey > W2)
        return;
    const double a[3] = {x[0], x[1], x[2]}, b[3] = {x[3], x[4], x[5]}, c[3] = {x[6], x[7], x[8]};
    for (int k = 0; k < nk; k++) {
        const double p[3] = {px, py, z0 + (k + 0.5) * O.w};
        const double ez = fmax(fmax(x[11] - p[2], p[2] - x[14]), 0.0);
        if (ex * ex + ey * ey + ez * ez > W2)
            continue;
        double q[3];
        int region;
        const double d2 = tl_closest(p, a, b, c, q, &region);
        if (!(d2 <= W2))
            continue;
        const ulong v = (ulong)as_uint((float)sqrt(d2)) << 32 | t;
        best[k] = v < best[k] ? v : best[k];
    }
}

/* Tile q = group id of the listed tiles: its values vt (512), active bits on
 * (8), first cell ijk (3), keep[q]; F = (unsigned, closed, nnodes, 0);
 * counts += (band cells, active voxels, winding evaluations, pseudonormal
 * signs, near tiles). Work-item l takes the column (i, j) = (l % 8, l / 8).
 * Every access to local memory is in this body, none in a helper (PoCL 3.1
 * makes a local array that a helper takes one array shared by every
 * work-group: kernels/common.cl, hv_group_sum). */
__kernel void tiles_sign(int4 N, int4 NB, double4 O, double4 R, int4 F,
                         __global const uint *list, __global const uint *start,
                         __global const uint *pairs, __global const double *V,
                         __global const uint *T, __global const double *fn,
                         __global const double *vn, __global const uint *other,
                         __global const uchar *vok, __global const uchar *ftrust,
                         __global const double *nd, __global const int *ni,
                         __global const uint *order, __global const char *sign,
                         __global float *vt, __global ulong *on, __global int *ijk,
                         __global uint *keep, __global uint *counts)
{
    __local double tv[15 * HV_WG];
    __local uint tid[HV_WG];
    __local float dl[TL_T3];
    __local char sg[TL_T3];
    __local int flag;
    __local uint onbits[2 * TL_TILE];
    __local uint red[4 * HV_WG];
    const uint q = get_group_id(0), l = get_local_id(0);
    const int i = (int)(l % TL_TILE), j = (int)(l / TL_TILE);
    const uint key = list[q], p0 = start[key], p1 = start[key + 1];
    const double W = R.x, W2 = W * W;
    const float bgf = (float)R.y, hff = (float)R.z, dlimf = (float)R.w;
    int blo[3], ext[3];
    tl_tile_of(N, NB, key, blo, ext);
    if (l < 3)
        ijk[3 * (size_t)q + l] = blo[l];

    /* The near test (tile_near): the tile's centre within the band plus the
     * half diagonal of one of its triangles. */
    const double pc[3] = {O.x + (blo[0] + 0.5 * TL_TILE) * O.w,
                          O.y + (blo[1] + 0.5 * TL_TILE) * O.w,
                          O.z + (blo[2] + 0.5 * TL_TILE) * O.w};
    const double rn = (double)bgf + (0.5 * sqrt(3.0) * (TL_TILE - 1) + 1e-3) * O.w;
    int mine = 0;
    for (uint s = p0 + l; s < p1 && !mine; s += HV_WG)
        mine = tl_near_one(V, T, pairs[s], pc, rn * rn);
    if (l == 0)
        flag = 0;
    barrier(CLK_LOCAL_MEM_FENCE);
    if (mine)
        flag = 1;
    barrier(CLK_LOCAL_MEM_FENCE);
    const int near = flag;
    if (l == 0)
        atomic_add(&counts[4], (uint)near);
    if (!near) {
        if (l == 0)
            keep[q] = 0;
        return;
    }

    /* The raster: the triangles through local memory HV_WG at a time. */
    ulong best[TL_TILE];
    for (int k = 0; k < TL_TILE; k++)
        best[k] = 0xffffffffffffffffUL;
    const double px = O.x + (blo[0] + i + 0.5) * O.w, py = O.y + (blo[1] + j + 0.5) * O.w;
    const double z0 = O.z + blo[2] * O.w;
    const int column = i < ext[0] && j < ext[1];
    for (uint c0 = p0; c0 < p1; c0 += HV_WG) {
        barrier(CLK_LOCAL_MEM_FENCE);
        if (c0 + l < p1) {
            const uint t = pairs[c0 + l];
            double a[3], b[3], c[3];
            tl_corner(V, T, t, 0, a);
            tl_corner(V, T, t, 1, b);
            tl_corner(V, T, t, 2, c);
            for (int d = 0; d < 3; d++) {
                tv[15 * l + d] = a[d];
                tv[15 * l + 3 + d] = b[d];
                tv[15 * l + 6 + d] = c[d];
                tv[15 * l + 9 + d] = fmin(a[d], fmin(b[d], c[d]));
                tv[15 * l + 12 + d] = fmax(a[d], fmax(b[d], c[d]));
            }
            tid[l] = t;
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        const uint m = min((uint)HV_WG, p1 - c0);
        for (uint s = 0; column && s < m; s++) {
            double x[15];
            for (int d = 0; d < 15; d++)
                x[d] = tv[15 * s + d];
            tl_raster_one(x, tid[s], O, W2, px, py, z0, ext[2], best);
        }
    }

    /* Within a voxel: the clean nearest feature's pseudonormal, else the
     * winding number (sign_near). */
    uint nband = 0, nact = 0, nevals = 0, nused = 0;
    if (l < 2 * TL_TILE)
        onbits[l] = 0;
    float d8[TL_TILE];
    char s8[TL_TILE];
    for (int k = 0; k < TL_TILE; k++) {
        d8[k] = INFINITY;
        s8[k] = 0;
        if (best[k] == 0xffffffffffffffffUL)
            continue;
        nband++;
        const float d = as_float((uint)(best[k] >> 32));
        d8[k] = d;
        if (F.x || !(d < hff))
            continue;
        const double p[3] = {px, py, z0 + (k + 0.5) * O.w};
        int sv = d < dlimf ? tl_pseudo_sign(V, T, fn, vn, other, vok, ftrust, (uint)best[k], p) : 0;
        if (sv)
            nused++;
        else
            sv = tl_wn_sure(V, T, nd, ni, order, sign, F.z, p, &nevals) > 0.5 ? -1 : 1;
        s8[k] = (char)sv;
    }
    for (int k = 0; k < TL_TILE; k++) {
        dl[i + TL_TILE * (j + TL_TILE * k)] = d8[k];
        sg[i + TL_TILE * (j + TL_TILE * k)] = s8[k];
    }
    barrier(CLK_LOCAL_MEM_FENCE);

    /* Closed meshes (sign_far): unsigned cells of the raster's reach take a
     * signed neighbour's sign until none does; then the first cell of the
     * band left (in the host's order) takes the winding number's, and the
     * flood goes on from it, until the band is signed. */
    for (int rounds = !F.x && F.y; rounds;) {
        for (int changed = 1; changed;) {
            if (l == 0)
                flag = 0;
            barrier(CLK_LOCAL_MEM_FENCE);
            for (int k = 0; k < TL_TILE; k++) {
                const int o = i + TL_TILE * (j + TL_TILE * k);
                if (sg[o] || !(dl[o] < INFINITY))
                    continue;
                int sv = i > 0 ? sg[o - 1] : 0;
                sv = !sv && i < TL_TILE - 1 ? sg[o + 1] : sv;
                sv = !sv && j > 0 ? sg[o - TL_TILE] : sv;
                sv = !sv && j < TL_TILE - 1 ? sg[o + TL_TILE] : sv;
                sv = !sv && k > 0 ? sg[o - TL_TILE * TL_TILE] : sv;
                sv = !sv && k < TL_TILE - 1 ? sg[o + TL_TILE * TL_TILE] : sv;
                if (sv) {
                    sg[o] = (char)sv;
                    flag = 1;
                }
            }
            barrier(CLK_LOCAL_MEM_FENCE);
            changed = flag;
            barrier(CLK_LOCAL_MEM_FENCE);
        }
        if (l == 0)
            flag = TL_T3;
        barrier(CLK_LOCAL_MEM_FENCE);
        for (int k = 0; k < TL_TILE; k++) {
            const int o = i + TL_TILE * (j + TL_TILE * k);
            if (!sg[o] && dl[o] < bgf)
                atomic_min(&flag, o);
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        const int first = flag;
        if (first < TL_T3 && (int)l == first % (TL_TILE * TL_TILE)) {
            const int k = first / (TL_TILE * TL_TILE);
            const double p[3] = {px, py, z0 + (k + 0.5) * O.w};
            sg[first] = tl_wn_sure(V, T, nd, ni, order, sign, F.z, p, &nevals) > 0.5 ? -1 : 1;
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        rounds = first < TL_T3;
    }

    /* The rest of the band by the winding number; the values and bits. */
    for (int k = 0; k < TL_TILE; k++) {
        const int o = i + TL_TILE * (j + TL_TILE * k);
        const float d = dl[o];
        int sv = sg[o];
        if (!F.x && !sv && d < bgf) {
            const double p[3] = {px, py, z0 + (k + 0.5) * O.w};
            sv = tl_wn_sure(V, T, nd, ni, order, sign, F.z, p, &nevals) > 0.5 ? -1 : 1;
        }
        const int act = d < bgf;
        vt[(size_t)TL_T3 * q + o] = act ? (sv < 0 ? -d : d) : bgf;
        if (act) {
            atomic_or(&onbits[2 * k + (l >= 32)], 1u << (l & 31));
            nact++;
        }
    }
    red[l] = nband;
    red[HV_WG + l] = nact;
    red[2 * HV_WG + l] = nevals;
    red[3 * HV_WG + l] = nused;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (uint h = HV_WG >> 1; h > 0; h >>= 1) {
        if (l < h)
            for (int c = 0; c < 4; c++)
                red[c * HV_WG + l] += red[c * HV_WG + l + h];
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (l < 4 && red[l * HV_WG])
        atomic_add(&counts[l], red[l * HV_WG]);
    if (l < TL_TILE)
        on[(size_t)TL_TILE * q + l] = (ulong)onbits[2 * l + 1] << 32 | onbits[2 * l];
    if (l == 0) {
        uint any = 0;
        for (int w = 0; w < 2 * TL_TILE; w++)
            any |= onbits[w];
        keep[q] = any != 0;
    }
}

/* The kept tiles to the front, in order: tile q to pos[q] where keep[q]
 * (one work-group per tile). */
__kernel void tiles_compact(__global const uint *keep, __global const uint *pos,
                            __global const float *vt, __global const ulong *on,
                            __global const int *ijk, __global float *vo, __global ulong *ono,
                            __global int *ijko)
{
    const uint q = get_group_id(0), l = get_local_id(0);
    if (!keep[q])
        return;
    const size_t to = pos[q];
    for (uint o = l; o < TL_T3; o += HV_WG)
        vo[TL_T3 * to + o] = vt[(size_t)TL_T3 * q + o];
    if (l < TL_TILE)
        ono[TL_TILE * to + l] = on[(size_t)TL_TILE * q + l];
    if (l < 3)
        ijko[3 * to + l] = ijk[3 * (size_t)q + l];
}
#endif
