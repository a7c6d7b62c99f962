/*
 * The extension off a narrow-band level set in 8^3 tiles on a device
 * (src/extend/extend_tiles_cl.c; the host path is src/extend/extend_tiles.c
 * with the wave of extend_wave.c, whose rules and arithmetic these kernels
 * repeat, so that both give the same values bit for bit):
 *
 *   bx_scan_phi   every value of the level set finite; its background (the
 *                 largest |phi|)
 *   bx_map        the dense map of the block's tiles (tile + 1), the lattice
 *                 checked and a tile listed twice found; bx_unmap clears it
 *   bx_classify   one work-group per tile: the weights, where each output
 *                 cell is read (its closest point or itself), the cells a
 *                 solve must answer for marked in bit masks of the block's
 *                 tiles, the fields checked where they are read
 *   bx_count      per tile of a box of the block's tiles: the cells of a mask
 *   bx_grow_x/yz  a mask grown by m cells along one axis (box dilation)
 *   bx_build      per cell of the grown mask (the domain, compact in tile
 *                 order): its six neighbours' compact cells, its diagonal,
 *                 its right-hand sides
 *   bx_first, bx_sweep  the Chebyshev sweeps of the band solve
 *   bx_residual, bx_residual_sum  its residual norms
 *   bx_eval       one work-group per tile: the output cells read from the
 *                 solutions at the marked cells, the cells left marked for
 *                 the next level
 *
 * Masks: 16 uint per tile of the block, cell (i, j, k) of a tile at bit
 * 8 (j & 3) + i of word 2 k + (j >> 2), so that byte 8 k + j is its row
 * (j, k) (little-endian devices; the host checks). The level set's and the
 * fields' active words (uint64 on the host) read the same way. N = (nx, ny,
 * nz, 0), TN = tiles per axis. The domain's kernels run over the box of
 * tiles B0 .. B0 + BN - 1 that holds it (the marks' tiles grown by the
 * level's reach and one more); the host zeroes the counts outside it. Double precision, contraction off: fp64
 * devices only.
 */
#ifdef HV_FP64
#pragma OPENCL FP_CONTRACT OFF

#define BX_NONE 0xffffffffu
#define BX_GRAD_MIN 0.5
#define BX_GRAD_MAX 1.5
/* The most right-hand sides per call (src/extend/extend_tiles_cl.c). */
#define BX_MAX_R 17

/* Counters (uint), as BK_* in src/extend/extend_tiles_cl.c. */
#define BX_NSRC 0
#define BX_NPEND 1
#define BX_BADPHI 2  /* first cell with a non-finite phi (BX_NONE: none) */
#define BX_BG 3      /* the largest |phi|, as float bits */
#define BX_BADF 4    /* first cell read with a non-finite field value */
#define BX_BADTILE 5 /* first tile off the block's 8^3 lattice */
#define BX_DUP 6     /* a tile listed twice */
#define BX_LEFT 8
#define BX_CP 9
#define BX_RATIO 10
#define BX_WEAK 11
#define BX_BOX 16    /* the marks' tiles: lowest x, y, z, then highest x, y, z */

static uint bx_tile(int4 TN, int i, int j, int k)
{
    return (uint)(i >> 3) + (uint)TN.x * ((uint)(j >> 3) + (uint)TN.y * (uint)(k >> 3));
}

static int bx_off(int i, int j, int k) { return (i & 7) + 8 * (j & 7) + 64 * (k & 7); }

/* Tile q of the box B0 .. B0 + BN - 1, as its coordinates and index. */
static uint bx_box_tile(int4 TN, int4 B0, int4 BN, uint q, int *tx, int *ty, int *tz)
{
    *tx = B0.x + (int)(q % (uint)BN.x);
    *ty = B0.y + (int)(q / (uint)BN.x % (uint)BN.y);
    *tz = B0.z + (int)(q / ((uint)BN.x * (uint)BN.y));
    return (uint)*tx + (uint)TN.x * ((uint)*ty + (uint)TN.y * (uint)*tz);
}

/* phi at block cell (i, j, k); ref: the value of the cell that looks (its
 * sign for cells outside the tiles). */
static float bx_phi(__global const int *map, __global const float *pv, int4 TN, float bg, int i,
                    int j, int k, float ref)
{
    const int t = map[bx_tile(TN, i, j, k)];
    if (!t)
        return copysign(bg, ref);
    return pv[(size_t)(t - 1) * 512 + bx_off(i, j, k)];
}

static int bx_bit(__global const uint *M, int4 TN, int i, int j, int k)
{
    const int o = bx_off(i, j, k);
    return (M[16 * (size_t)bx_tile(TN, i, j, k) + (o >> 5)] >> (o & 31)) & 1;
}

static void bx_mark(__global uint *M, int4 TN, int i, int j, int k)
{
    const int o = bx_off(i, j, k);
    __global uint *w = &M[16 * (size_t)bx_tile(TN, i, j, k) + (o >> 5)];
    const uint bit = 1u << (o & 31);
    if (!(*w & bit))
        atomic_or(w, bit);
}

/* The compact cell of (i, j, k) in the domain dm (base: its tiles' first
 * compact cells), or BX_NONE outside it. */
static uint bx_cell(__global const uint *dm, __global const uint *base, int4 TN, int i, int j,
                    int k)
{
    const uint t = bx_tile(TN, i, j, k);
    const int o = bx_off(i, j, k), w = o >> 5;
    const uint word = dm[16 * (size_t)t + w];
    if (!((word >> (o & 31)) & 1))
        return BX_NONE;
    uint r = base[t];
    for (int q = 0; q < w; q++)
        r += popcount(dm[16 * (size_t)t + q]);
    return r + popcount(word & ((1u << (o & 31)) - 1u));
}

/* The weight of a cell of value v (extend_tiles.c, weight_of). */
static float bx_weight(float v, double bh)
{
    const double s = v / bh;
    return fabs(s) < 1 ? (float)((1 - s * s) * (1 - s * s)) : 0.0f;
}

/* Where a cell is read: itself (m = 1) or 8 trilinear corners from c[]
 * stepping d[] along each axis. */
typedef struct {
    int m, c[3], d[3];
    double wt[8];
} bx_stencil;

static void bx_self(bx_stencil *s, int i, int j, int k)
{
    s->m = 1;
    s->c[0] = i;
    s->c[1] = j;
    s->c[2] = k;
    s->d[0] = s->d[1] = s->d[2] = 0;
    s->wt[0] = 1;
}

static void bx_corner(const bx_stencil *s, int q, int p[3])
{
    p[0] = s->c[0] + ((q & 1) ? s->d[0] : 0);
    p[1] = s->c[1] + ((q & 2) ? s->d[1] : 0);
    p[2] = s->c[2] + ((q & 4) ? s->d[2] : 0);
}

/* phi_diff2 (src/extend/extend_internal.h). */
static double bx_diff2(double pc, double vm, double vp, int upwind)
{
    const double a = fabs(pc), am = fabs(vm), ap = fabs(vp);
    if (upwind && am < a && a < ap)
        return 2 * (pc - vm);
    if (upwind && ap < a && a < am)
        return 2 * (vp - pc);
    return vp - vm;
}

/* teval_point (extend_tiles.c) at an interior cell: hv__ext_closest_point
 * and hv__ext_trilinear. */
static int bx_point_inside(__global const int *map, __global const float *pv, int4 N, int4 TN,
                           float bg, double h, double band, int i, int j, int k, float pc,
                           int validate, bx_stencil *s)
{
    const double nb[6] = {bx_phi(map, pv, TN, bg, i - 1, j, k, pc),
                          bx_phi(map, pv, TN, bg, i + 1, j, k, pc),
                          bx_phi(map, pv, TN, bg, i, j - 1, k, pc),
                          bx_phi(map, pv, TN, bg, i, j + 1, k, pc),
                          bx_phi(map, pv, TN, bg, i, j, k - 1, pc),
                          bx_phi(map, pv, TN, bg, i, j, k + 1, pc)};
    const double p0 = pc;
    double gx = 0, gy = 0, gz = 0, gn = 0;
    for (int up = 0; up < 2; up++) {
        gx = bx_diff2(p0, nb[0], nb[1], up);
        gy = bx_diff2(p0, nb[2], nb[3], up);
        gz = bx_diff2(p0, nb[4], nb[5], up);
        gn = sqrt(gx * gx + gy * gy + gz * gz) * (0.5 / h);
        if (gn >= BX_GRAD_MIN && gn <= BX_GRAD_MAX)
            break;
    }
    if (!(gn >= BX_GRAD_MIN && gn <= BX_GRAD_MAX))
        return 0;
    const double sc = p0 * 0.5 / (gn * h * h);
    const double p[3] = {i - sc * gx, j - sc * gy, k - sc * gz};
    const int nn[3] = {N.x, N.y, N.z};
    bx_stencil t;
    t.m = 8;
    double fr[3];
    for (int a = 0; a < 3; a++) {
        if (p[a] < -0.5 || p[a] > nn[a] - 0.5)
            return 0;
        double q = p[a] < 0 ? 0 : p[a];
        if (q > nn[a] - 1)
            q = nn[a] - 1;
        int f = (int)q;
        if (f > nn[a] - 2)
            f = nn[a] - 2;
        fr[a] = q - f;
        t.c[a] = f;
        t.d[a] = 1;
    }
    const double wx[2] = {1 - fr[0], fr[0]}, wy[2] = {1 - fr[1], fr[1]}, wz[2] = {1 - fr[2], fr[2]};
    for (int q = 0; q < 8; q++)
        t.wt[q] = wx[q & 1] * wy[(q >> 1) & 1] * wz[q >> 2];
    double v = 0;
    for (int q = 0; q < 8; q++) {
        int c[3];
        bx_corner(&t, q, c);
        v += t.wt[q] * bx_phi(map, pv, TN, bg, c[0], c[1], c[2], pc);
    }
    if (validate && fabs(v) > 0.5 * fmax(band, 1.0) * h)
        return 0;
    *s = t;
    return 1;
}

/* teval_point at the block's walls: one-sided differences and a clamped
 * stencil (hv__ext_clamped). */
static int bx_point_wall(__global const int *map, __global const float *pv, int4 N, int4 TN,
                         float bg, double h, double band, int i, int j, int k, float pc,
                         int validate, bx_stencil *s)
{
    const int ijk[3] = {i, j, k}, nn[3] = {N.x, N.y, N.z};
    double g[3] = {0, 0, 0}, gn = 0;
    for (int up = 0; up < 2; up++) {
        for (int a = 0; a < 3; a++) {
            const int lo = ijk[a] > 0, hi = ijk[a] + 1 < nn[a];
            g[a] = 0;
            if (!lo && !hi)
                continue;
            int pp[3] = {i, j, k}, pm[3] = {i, j, k};
            pp[a] += 1;
            pm[a] -= 1;
            const double vp = hi ? bx_phi(map, pv, TN, bg, pp[0], pp[1], pp[2], pc) : pc,
                         vm = lo ? bx_phi(map, pv, TN, bg, pm[0], pm[1], pm[2], pc) : pc;
            g[a] = lo && hi ? bx_diff2(pc, vm, vp, up) / (2 * h) : (vp - vm) / h;
        }
        gn = 0;
        for (int a = 0; a < 3; a++)
            gn += g[a] * g[a];
        gn = sqrt(gn);
        if (gn >= BX_GRAD_MIN && gn <= BX_GRAD_MAX)
            break;
    }
    if (!(gn >= BX_GRAD_MIN && gn <= BX_GRAD_MAX))
        return 0;
    const double sv = pc / (gn * h);
    double p[3] = {i, j, k};
    for (int a = 0; a < 3; a++) {
        p[a] -= sv * g[a];
        if (p[a] < -0.5 || p[a] > nn[a] - 0.5)
            return 0;
    }
    bx_stencil t;
    t.m = 8;
    double fr[3];
    for (int a = 0; a < 3; a++) {
        double q = p[a];
        if (q < 0)
            q = 0;
        if (q > nn[a] - 1)
            q = nn[a] - 1;
        int fl = (int)floor(q);
        if (fl > nn[a] - 2)
            fl = nn[a] - 2;
        if (fl < 0)
            fl = 0;
        t.c[a] = fl;
        t.d[a] = nn[a] > 1;
        fr[a] = nn[a] > 1 ? q - fl : 0;
    }
    for (int q = 0; q < 8; q++)
        t.wt[q] = ((q & 1) ? fr[0] : 1 - fr[0]) * ((q & 2) ? fr[1] : 1 - fr[1]) *
                  ((q & 4) ? fr[2] : 1 - fr[2]);
    double v = 0;
    for (int q = 0; q < 8; q++) {
        int c[3];
        bx_corner(&t, q, c);
        v += t.wt[q] * bx_phi(map, pv, TN, bg, c[0], c[1], c[2], pc);
    }
    if (validate && fabs(v) > 0.5 * fmax(band, 1.0) * h)
        return 0;
    *s = t;
    return 1;
}

/* teval_point: 1 when the cell is read at its closest point (stencil s),
 * 0 when at itself. */
static int bx_point(__global const int *map, __global const float *pv, int4 N, int4 TN, float bg,
                    double h, double band, int cp_on, int i, int j, int k, float pc, int validate,
                    bx_stencil *s)
{
    bx_self(s, i, j, k);
    if (!cp_on)
        return 0;
    if (i > 0 && j > 0 && k > 0 && i + 1 < N.x && j + 1 < N.y && k + 1 < N.z)
        return bx_point_inside(map, pv, N, TN, bg, h, band, i, j, k, pc, validate, s);
    return bx_point_wall(map, pv, N, TN, bg, h, band, i, j, k, pc, validate, s);
}

/* ---- checks and maps ------------------------------------------------------- */

__kernel void bx_scan_phi(ulong cells, __global const float *pv, __global uint *K)
{
    __local uint bad[HV_WG], big[HV_WG];
    const int l = get_local_id(0);
    const size_t c = get_global_id(0);
    uint b = BX_NONE, m = 0;
    if (c < cells) {
        const float v = pv[c];
        if (!isfinite(v))
            b = (uint)c;
        else
            m = as_uint(fabs(v));
    }
    bad[l] = b;
    big[l] = m;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int s = HV_WG >> 1; s > 0; s >>= 1) {
        if (l < s) {
            bad[l] = min(bad[l], bad[l + s]);
            big[l] = max(big[l], big[l + s]);
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (l == 0) {
        if (bad[0] != BX_NONE)
            atomic_min(&K[BX_BADPHI], bad[0]);
        if (big[0])
            atomic_max(&K[BX_BG], big[0]);
    }
}

__kernel void bx_map(ulong count, int4 N, int4 TN, __global const int *ijk, __global int *map,
                     __global uint *K)
{
    const size_t t = get_global_id(0);
    if (t >= count)
        return;
    const int c[3] = {ijk[3 * t], ijk[3 * t + 1], ijk[3 * t + 2]}, n[3] = {N.x, N.y, N.z};
    for (int a = 0; a < 3; a++)
        if (c[a] < 0 || c[a] >= n[a] || (c[a] & 7)) {
            atomic_min(&K[BX_BADTILE], (uint)t);
            return;
        }
    if (atomic_cmpxchg(&map[bx_tile(TN, c[0], c[1], c[2])], 0, (int)t + 1) != 0)
        atomic_min(&K[BX_DUP], (uint)t);
}

__kernel void bx_unmap(ulong count, int4 N, int4 TN, __global const int *ijk, __global int *map)
{
    const size_t t = get_global_id(0);
    if (t >= count)
        return;
    const int c[3] = {ijk[3 * t], ijk[3 * t + 1], ijk[3 * t + 2]}, n[3] = {N.x, N.y, N.z};
    for (int a = 0; a < 3; a++)
        if (c[a] < 0 || c[a] >= n[a] || (c[a] & 7))
            return;
    map[bx_tile(TN, c[0], c[1], c[2])] = 0;
}

/* ---- classification: one work-group of 64 per tile, a row each ------------ */

/* src: the fields' nfc components, each a plane of `stride` floats laid out
 * as the tiles' values. */
__kernel void bx_classify(int4 N, int4 TN, __global const int *map, __global const int *ijk,
                          __global const float *pv, __global const uint *pon, float bg,
                          double bh, double ob, double h, double band, int cp_on, int nfc,
                          ulong stride, __global const float *src, __global uchar *pend,
                          __global uint *mark, __global uint *K)
{
    const size_t t = get_group_id(0);
    const int l = get_local_id(0), jj = l & 7, kk = l >> 3;
    const int i0 = ijk[3 * t], j = ijk[3 * t + 1] + jj, k = ijk[3 * t + 2] + kk;
    const uint onrow = (pon[16 * t + 2 * kk + (jj >> 2)] >> (8 * (jj & 3))) & 0xffu;
    __local int box[6][HV_WG];
    uint nsrc = 0, npend = 0, badf = BX_NONE;
    int lo[3] = {1 << 30, 1 << 30, 1 << 30}, hi[3] = {-1, -1, -1};
    for (int ii = 0; ii < 8; ii++) {
        const int i = i0 + ii, o = ii + 8 * jj + 64 * kk;
        const size_t tc = t * 512 + o;
        pend[tc] = 0;
        if (i >= N.x || j >= N.y || k >= N.z)
            continue;
        const float v = pv[tc];
        if (fabs(v / bh) < 1) {
            nsrc++;
            for (int q = 0; q < nfc; q++)
                if (!isfinite(src[q * stride + tc]) && (uint)tc < badf)
                    badf = (uint)tc;
            bx_mark(mark, TN, i, j, k);
            const int p[3] = {i, j, k};
            for (int a = 0; a < 3; a++) {
                lo[a] = min(lo[a], p[a] >> 3);
                hi[a] = max(hi[a], p[a] >> 3);
            }
        }
        if (!((onrow >> ii) & 1) || (ob > 0 && !(fabs(v) < ob)))
            continue;
        bx_stencil s;
        pend[tc] = bx_point(map, pv, N, TN, bg, h, band, cp_on, i, j, k, v, 1, &s) ? 1 : 2;
        npend++;
        for (int q = 0; q < s.m; q++) {
            int c[3];
            bx_corner(&s, q, c);
            bx_mark(mark, TN, c[0], c[1], c[2]);
            for (int a = 0; a < 3; a++) {
                lo[a] = min(lo[a], c[a] >> 3);
                hi[a] = max(hi[a], c[a] >> 3);
            }
        }
        /* the cell itself, which a later level may read */
        const int p[3] = {i, j, k};
        for (int a = 0; a < 3; a++) {
            lo[a] = min(lo[a], p[a] >> 3);
            hi[a] = max(hi[a], p[a] >> 3);
        }
    }
    /* the group's box of marked tiles, then one atomic per bound */
    for (int a = 0; a < 3; a++) {
        box[a][l] = lo[a];
        box[3 + a][l] = hi[a];
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int w = HV_WG >> 1; w > 0; w >>= 1) {
        if (l < w)
            for (int a = 0; a < 3; a++) {
                box[a][l] = min(box[a][l], box[a][l + w]);
                box[3 + a][l] = max(box[3 + a][l], box[3 + a][l + w]);
            }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (l == 0 && box[3][0] >= 0)
        for (int a = 0; a < 3; a++) {
            atomic_min(&K[BX_BOX + a], (uint)box[a][0]);
            atomic_max(&K[BX_BOX + 3 + a], (uint)box[3 + a][0]);
        }
    if (nsrc)
        atomic_add(&K[BX_NSRC], nsrc);
    if (npend)
        atomic_add(&K[BX_NPEND], npend);
    if (badf != BX_NONE)
        atomic_min(&K[BX_BADF], badf);
}

/* ---- the domain: the marks grown by m cells along x, y and z --------------- */

__kernel void bx_count(int4 TN, int4 B0, int4 BN, __global const uint *M, __global uint *cnt)
{
    const size_t q = get_global_id(0);
    if (q >= (size_t)BN.x * BN.y * BN.z)
        return;
    int tx, ty, tz;
    const uint t = bx_box_tile(TN, B0, BN, (uint)q, &tx, &ty, &tz);
    uint c = 0;
    for (int q = 0; q < 16; q++)
        c += popcount(M[16 * t + q]);
    cnt[t] = c;
}

/* One work-item per row (j, k) of a tile of the block; cnt: the input's
 * cells per tile (bx_count), so that empty tiles are skipped. */
__kernel void bx_grow_x(int4 N, int4 TN, int4 B0, int4 BN, int m, __global const uchar *in,
                        __global const uint *cnt, __global uchar *out)
{
    int tx, ty, tz;
    const uint t = bx_box_tile(TN, B0, BN, get_group_id(0), &tx, &ty, &tz);
    const int l = get_local_id(0), jj = l & 7, kk = l >> 3;
    const int D = (m + 7) / 8;
    uint o = 0;
    for (int dt = -D; dt <= D; dt++) {
        if (tx + dt < 0 || tx + dt >= TN.x || !cnt[t + dt])
            continue;
        const uint b = in[64 * (size_t)(t + dt) + 8 * kk + jj];
        for (int p = 0; p < 8 && b; p++) {
            if (!((b >> p) & 1))
                continue;
            const int lo = max(8 * dt + p - m, 0), hi = min(8 * dt + p + m, 7);
            if (lo <= hi)
                o |= ((2u << hi) - 1u) & ~((1u << lo) - 1u);
        }
    }
    const int xmax = N.x - 8 * tx;
    if (xmax < 8)
        o &= (1u << xmax) - 1u;
    out[64 * (size_t)t + 8 * kk + jj] = (uchar)o;
}

/* Along y (axis 1) or z (axis 2): row (j, k) takes the union of the rows
 * within m along the axis, in the block. */
__kernel void bx_grow_yz(int4 N, int4 TN, int4 B0, int4 BN, int m, int axis,
                         __global const uchar *in, __global const uint *cnt, __global uchar *out)
{
    int tx, ty, tz;
    const uint t = bx_box_tile(TN, B0, BN, get_group_id(0), &tx, &ty, &tz);
    const int l = get_local_id(0), jj = l & 7, kk = l >> 3;
    const int j = 8 * ty + jj, k = 8 * tz + kk;
    uint o = 0;
    if (j < N.y && k < N.z) {
        const int c = axis == 1 ? j : k, nc = axis == 1 ? N.y : N.z;
        const int lo = max(c - m, 0), hi = min(c + m, nc - 1);
        for (int s = lo >> 3; s <= hi >> 3; s++) {
            const uint st = axis == 1 ? (uint)tx + (uint)TN.x * ((uint)s + (uint)TN.y * (uint)tz)
                                      : (uint)tx + (uint)TN.x * ((uint)ty + (uint)TN.y * (uint)s);
            if (!cnt[st])
                continue;
            const int a = max(lo, 8 * s), b = min(hi, 8 * s + 7);
            for (int d = a; d <= b; d++)
                o |= in[64 * (size_t)st + (axis == 1 ? 8 * kk + (d - 8 * s) : 8 * (d - 8 * s) + jj)];
        }
    }
    out[64 * (size_t)t + 8 * kk + jj] = (uchar)o;
}

/* ---- the band solve on the domain --------------------------------------------- */

/* Per domain cell c of n: nb[a n + c] its neighbours' compact cells
 * (BX_NONE outside the domain) in the order the host's sweep adds them
 * (y - 1, y + 1, z - 1, z + 1, x - 1, x + 1), dg[c] the diagonal 1 + s
 * (neighbours in the block), f[r n + c] the right-hand sides (row_rhs): one
 * plane of n per right-hand side, as the iterates. fnc: each field's
 * components. One work-group per tile of the block, a row each. */
__kernel void bx_build(int4 N, int4 TN, int4 B0, int4 BN, double s, int R, ulong n, int nfields,
                       __global const int *fnc, double bh, ulong stride, __global const uint *dm,
                       __global const uint *base, __global const uint *cnt,
                       __global const int *map, __global const float *pv,
                       __global const float *src, __global uint *nb, __global float *dg,
                       __global float *f)
{
    int tx, ty, tz;
    const uint t = bx_box_tile(TN, B0, BN, get_group_id(0), &tx, &ty, &tz);
    if (!cnt[t])
        return;
    const int l = get_local_id(0), jj = l & 7, kk = l >> 3;
    const int j = 8 * ty + jj, k = 8 * tz + kk;
    const int tp = map[t];
    for (int ii = 0; ii < 8; ii++) {
        const int i = 8 * tx + ii, o = ii + 8 * jj + 64 * kk;
        const uint c = bx_cell(dm, base, TN, i, j, k);
        if (c == BX_NONE)
            continue;
        const int p[6][3] = {{i, j - 1, k}, {i, j + 1, k}, {i, j, k - 1},
                             {i, j, k + 1}, {i - 1, j, k}, {i + 1, j, k}};
        int in_block = 0;
        for (int a = 0; a < 6; a++) {
            uint v = BX_NONE;
            if (p[a][0] >= 0 && p[a][1] >= 0 && p[a][2] >= 0 && p[a][0] < N.x && p[a][1] < N.y &&
                p[a][2] < N.z) {
                in_block++;
                v = bx_cell(dm, base, TN, p[a][0], p[a][1], p[a][2]);
            }
            nb[a * n + c] = v;
        }
        dg[c] = (float)(1 + s * in_block);
        __global float *dst = f + c; /* right-hand side r at dst[r n] */
        const size_t tc = (size_t)(tp - 1) * 512 + o;
        const float wf = tp ? bx_weight(pv[tc], bh) : 0.0f;
        if (!(wf > 0)) {
            for (int r = 0; r < R; r++)
                dst[r * n] = 0;
            continue;
        }
        const double w = wf;
        int r = 0, q0 = 0;
        dst[n * r++] = (float)w;
        for (int fi = 0; fi < nfields; fi++) {
            const int nc = fnc[fi];
            if (nc == 1) {
                dst[n * r++] = (float)(w * src[q0 * stride + tc]);
                q0++;
                continue;
            }
            double mg = 0;
            for (int q = 0; q < nc; q++) {
                const float x = src[(q0 + q) * stride + tc];
                mg += (double)x * x;
            }
            dst[n * r++] = (float)(w * sqrt(mg));
            for (int q = 0; q < nc; q++)
                dst[n * r++] = (float)(w * src[(q0 + q) * stride + tc]);
            q0 += nc;
        }
    }
}

/* Iterate 1 = D^-1 f into A, iterate 0 = 0 into B. */
__kernel void bx_first(ulong n, int R, __global const float *dg, __global const float *f,
                       __global float *A, __global float *B)
{
    const size_t c = get_global_id(0);
    if (c >= n)
        return;
    const float cd = 1.0f / dg[c];
    for (int r = 0; r < R; r++) {
        A[r * n + c] = cd * f[r * n + c];
        B[r * n + c] = 0;
    }
}

/* One sweep: O = C + a (C - O) + c D^-1 (f - A C), as seg_update. */
__kernel void bx_sweep(ulong n, int R, float s, float a, float cc, __global const uint *nb,
                       __global const float *dg, __global const float *f,
                       __global const float *C, __global float *O)
{
    const size_t c = get_global_id(0);
    if (c >= n)
        return;
    const float d = dg[c], cd = cc / d;
    uint m[6];
    for (int q = 0; q < 6; q++)
        m[q] = nb[q * n + c];
    for (int r = 0; r < R; r++) {
        const size_t at = r * n;
        float v[6];
        for (int q = 0; q < 6; q++)
            v[q] = m[q] == BX_NONE ? 0.0f : C[at + m[q]];
        const float sum = v[0] + v[1] + v[2] + v[3] + v[4] + v[5];
        const float u = C[at + c], o = O[at + c];
        O[at + c] = u + a * (u - o) + cd * (f[at + c] - (d * u - s * sum));
    }
}

/* The residual f - A u of right-hand side r = group id 1, as
 * hv__band_run_residual: per group of the range (a contiguous block of the
 * cells, its work-items a cell apart) its squared sum, its largest
 * magnitude and the squared sum of f, into part[3 (g R + r) ..]. */
__kernel void bx_residual(ulong n, int R, double s, __global const uint *nb,
                          __global const float *dg, __global const float *f,
                          __global const float *U, __global double *part)
{
    __local double l2[HV_WG], lm[HV_WG], lf[HV_WG];
    const int l = get_local_id(0), r = get_group_id(1);
    double a2 = 0, am = 0, af = 0;
    const size_t G = get_num_groups(0), chunk = (n + G - 1) / G, c0 = get_group_id(0) * chunk;
    const size_t c1 = min(n, c0 + chunk);
    for (size_t c = c0 + l; c < c1; c += HV_WG) {
        float v[6];
        for (int q = 0; q < 6; q++) {
            const uint m = nb[q * n + c];
            v[q] = m == BX_NONE ? 0.0f : U[r * n + m];
        }
        const double sum = (double)v[0] + v[1] + v[2] + v[3] + v[4] + v[5];
        const double d = dg[c], fv = f[r * n + c];
        const double res = fv - (d * (double)U[r * n + c] - s * sum);
        a2 += res * res;
        if (fabs(res) > am)
            am = fabs(res);
        af += fv * fv;
    }
    l2[l] = a2;
    lm[l] = am;
    lf[l] = af;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int w = HV_WG >> 1; w > 0; w >>= 1) {
        if (l < w) {
            l2[l] += l2[l + w];
            lm[l] = fmax(lm[l], lm[l + w]);
            lf[l] += lf[l + w];
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (l == 0) {
        const size_t at = 3 * ((size_t)get_group_id(0) * R + r);
        part[at] = l2[0];
        part[at + 1] = lm[0];
        part[at + 2] = lf[0];
    }
}

/* The groups' parts summed per right-hand side into out[3 r ..]. */
__kernel void bx_residual_sum(int groups, int R, __global const double *part,
                              __global double *out)
{
    const int r = get_global_id(0);
    if (r >= R)
        return;
    double a2 = 0, am = 0, af = 0;
    for (int g = 0; g < groups; g++) {
        const size_t at = 3 * ((size_t)g * R + r);
        a2 += part[at];
        am = fmax(am, part[at + 1]);
        af += part[at + 2];
    }
    out[3 * r] = a2;
    out[3 * r + 1] = am;
    out[3 * r + 2] = af;
}

/* ---- evaluation: one work-group of 64 per tile, a row each ------------------- */

/* sample_all at stencil s from the solutions at the marked cells (need):
 * corners off need read 0. */
static void bx_sample(__global const uint *need, __global const uint *dm,
                      __global const uint *base, int4 TN, __global const float *sol, int R,
                      ulong n, const bx_stencil *s, double *out)
{
    for (int r = 0; r < R; r++)
        out[r] = 0;
    for (int q = 0; q < s->m; q++) {
        int c[3];
        bx_corner(s, q, c);
        if (!bx_bit(need, TN, c[0], c[1], c[2]))
            continue;
        const uint x = bx_cell(dm, base, TN, c[0], c[1], c[2]);
        if (x == BX_NONE)
            continue; /* cannot happen: the marks are in the domain */
        for (int r = 0; r < R; r++)
            out[r] += s->wt[q] * sol[r * n + x];
    }
}

/* write_cell into tile cell tc of the fields' planes. */
static void bx_write(int nfields, __global const int *fnc, ulong stride, size_t tc,
                     const double *val, __global float *fv)
{
    const double W = val[0];
    int r = 1, q0 = 0;
    for (int i = 0; i < nfields; i++) {
        const int nc = fnc[i];
        if (nc == 1) {
            fv[q0 * stride + tc] = (float)(val[r] / W);
            r++;
            q0++;
            continue;
        }
        double mag = val[r] / W, v[3] = {0, 0, 0}, vn = 0;
        for (int q = 0; q < nc; q++) {
            v[q] = val[r + 1 + q];
            vn += v[q] * v[q];
        }
        vn = sqrt(vn);
        for (int q = 0; q < nc; q++)
            fv[(q0 + q) * stride + tc] = vn > 0 ? (float)(mag * v[q] / vn) : 0.0f;
        r += nc + 1;
        q0 += nc;
    }
}

/* eval_level (extend_tiles.c): fv, fon the fields' values and active words
 * (nfc planes of stride floats, of 16 count uints). */
__kernel void bx_eval(int4 N, int4 TN, __global const int *map, __global const int *ijk,
                      __global const float *pv, float bg, double h, double band, int cp_on,
                      int R, int nfields, int nfc, __global const int *fnc, ulong stride,
                      __global const uint *need, __global const uint *dm,
                      __global const uint *base, __global const float *sol, ulong n, double thr,
                      int trusted, int last, float background, __global uchar *pend,
                      __global uint *mark, __global float *fv, __global uint *fon,
                      __global uint *K)
{
    const size_t t = get_group_id(0), count = get_num_groups(0);
    const int l = get_local_id(0), jj = l & 7, kk = l >> 3;
    const int i0 = ijk[3 * t], j = ijk[3 * t + 1] + jj, k = ijk[3 * t + 2] + kk;
    uint left = 0, cp = 0, ratio = 0, weak = 0;
    for (int ii = 0; ii < 8; ii++) {
        const int i = i0 + ii, o = ii + 8 * jj + 64 * kk;
        const size_t tc = t * 512 + o;
        int pd = pend[tc];
        if (!pd)
            continue;
        const float pc = pv[tc];
        bx_stencil s;
        bx_self(&s, i, j, k);
        int at_cp = 0;
        if (pd == 1)
            at_cp = bx_point(map, pv, N, TN, bg, h, band, cp_on, i, j, k, pc, 0, &s);
        double val[BX_MAX_R];
        bx_sample(need, dm, base, TN, sol, R, n, &s, val);
        double W = val[0];
        if (!(W > thr) && at_cp) {
            at_cp = 0;
            pd = 2;
            bx_self(&s, i, j, k);
            if (trusted && !bx_bit(need, TN, i, j, k)) {
                W = 0;
            } else {
                bx_sample(need, dm, base, TN, sol, R, n, &s, val);
                W = val[0];
            }
        }
        if (!(W > thr) && !last) {
            left++;
            bx_mark(mark, TN, i, j, k);
            pend[tc] = (uchar)pd;
            continue;
        }
        if (!(W > 0)) {
            for (int q = 0; q < nfc; q++)
                fv[q * stride + tc] = background;
        } else {
            bx_write(nfields, fnc, stride, tc, val, fv);
        }
        const size_t wi = 16 * t + (o >> 5);
        for (int q = 0; q < nfc; q++)
            atomic_or(&fon[q * 16 * count + wi], 1u << (o & 31));
        weak += !(W > thr);
        cp += at_cp;
        ratio += !at_cp;
        pend[tc] = 0;
    }
    if (left)
        atomic_add(&K[BX_LEFT], left);
    if (cp)
        atomic_add(&K[BX_CP], cp);
    if (ratio)
        atomic_add(&K[BX_RATIO], ratio);
    if (weak)
        atomic_add(&K[BX_WEAK], weak);
}

#pragma OPENCL FP_CONTRACT ON
#endif
