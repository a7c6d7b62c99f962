/*
 * The extension off a narrow-band level set in tiles (extend_tiles.c) on an
 * OpenCL device: the same steps, each a kernel of kernels/bandext.cl, which
 * this file registers and builds (hv_cl_module, src/cl/cl_core.h).
 *
 *   1. the level set checked (finite; its background) and its tiles mapped
 *      in a dense map of the block's tiles
 *   2. classify: per tile, the weights, where each output cell is read, the
 *      cells a solve must answer for marked in bit masks of the block's tiles
 *   3. per diffusion level: the marks grown by BOX_MARGIN sqrt(t) cells along
 *      x, y and z (the cells the host's wave solves), laid out compactly in
 *      tile order; their neighbours, diagonals and right-hand sides; the
 *      Chebyshev sweeps (the wave's coefficients and per-cell arithmetic);
 *      the residual's norms
 *   4. per tile, the output cells read from the solutions at the marked
 *      cells; the cells left marked for the next level
 *
 * The masks and maps cover the block's tiles (268 bytes a tile, kept between
 * calls), the domain's kernels the box of its tiles; the solve's arrays
 * follow the domain's cells. On the way the host
 * reads the counters twice, then per level the domain's size, 3 R residual
 * sums and 4 counts; no field crosses. With the same cells, sweeps and reads
 * as the host, the values are the host's bit for bit (check_extend_tiles_cl).
 */
#include "extend_cl.h"
#include "core/error.h"
#include "cl/cl_core.h"
#include "cl/cl_ops.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

extern const char hv__kernel_bandext[]; /* kernels/bandext.cl, embedded by the Makefile */

static const char *const bx_sources[] = {hv__kernel_bandext, NULL};
enum {
    K_SCAN_PHI,
    K_MAP,
    K_UNMAP,
    K_CLASSIFY,
    K_COUNT,
    K_GROW_X,
    K_GROW_YZ,
    K_BUILD,
    K_FIRST,
    K_SWEEP,
    K_RESIDUAL,
    K_RESIDUAL_SUM,
    K_EVAL
};
static const char *const bx_kernels[] = {
    "bx_scan_phi", "bx_map",          "bx_unmap", "bx_classify", "bx_count",
    "bx_grow_x",   "bx_grow_yz",      "bx_build", "bx_first",    "bx_sweep",
    "bx_residual", "bx_residual_sum", "bx_eval",  NULL};
static const hv_cl_module bx_module = {"bandext", bx_sources, bx_kernels, 1, 0};

/* Counters (uint), as BX_* in kernels/bandext.cl. */
enum {
    BK_NSRC = 0,
    BK_NPEND = 1,
    BK_BADPHI = 2,
    BK_BG = 3,
    BK_BADF = 4,
    BK_BADTILE = 5,
    BK_DUP = 6,
    BK_LEFT = 8,
    BK_CP = 9,
    BK_RATIO = 10,
    BK_WEAK = 11,
    BK_BOX = 16, /* the marks' tiles: lowest x, y, z, then highest */
    BK_COUNT = 24
};
#define BK_NONE 0xffffffffu
#define T3 (HV_TILE * HV_TILE * HV_TILE)
/* Work-groups of the residual's first stage. */
#define RES_GROUPS 64

/* Kept by the extender between calls. */
struct hv_extend_tiles_cl {
    hv_cl *cl; /* the extender's device handle (extend_cl.c), not owned */
    int tn[3];
    size_t nt; /* tiles of the block */
    /* per tile of the block: map (tile + 1), masks (16 uint: marks, the
     * marks a level reads, two for growing), cells per tile and their
     * prefix sums (nt + 1) */
    cl_mem map, mark, need, g1, g2, cnt, base;
    cl_mem K, fnc, part, res;
    /* per call, grown: the level set (host calls), pending bytes, the
     * fields' sources, values and active words */
    cl_mem pijk, pv, pon, pend, src, fv, fon;
    size_t cap_pt, cap_pv, cap_pon, cap_pend, cap_src, cap_fv, cap_fon;
    /* per level, grown: neighbours, diagonals, right-hand sides, iterates */
    cl_mem nb, dg, f, A, B;
    size_t cap_cells, cap_rc;
};

void hv__extend_tiles_cl_destroy(struct hv_extend_tiles_cl **state)
{
    if (!state || !*state)
        return;
    struct hv_extend_tiles_cl *x = *state;
    cl_mem *m[] = {&x->map, &x->mark, &x->need, &x->g1,   &x->g2, &x->cnt, &x->base, &x->K,
                   &x->fnc, &x->part, &x->res,  &x->pijk, &x->pv, &x->pon, &x->pend, &x->src,
                   &x->fv,  &x->fon,  &x->nb,   &x->dg,   &x->f,  &x->A,   &x->B};
    for (size_t i = 0; i < sizeof m / sizeof m[0]; i++)
        hv__cl_free(m[i]);
    free(x);
    *state = NULL;
}

/* *m holds at least want bytes. */
static hv_status grow(hv_cl *cl, cl_mem *m, size_t *cap, size_t want)
{
    if (!want)
        want = 1;
    if (*m && *cap >= want)
        return HV_OK;
    hv__cl_free(m);
    *cap = 0;
    hv_status st = hv__cl_alloc(cl, want, NULL, m);
    if (!st)
        *cap = want;
    return st;
}

static hv_status state_create(struct hv_extend_tiles_cl **out, hv_extender *e)
{
    hv_status st;
    const hv_extend_grid g = {e,        e->dim, {e->n[0], e->n[1], e->n[2]}, e->h, e->count,
                              e->solid, &e->o};
    if ((st = hv__extend_cl_prepare(&e->cl, &g, NULL, NULL, NULL)))
        return st;
    hv_cl *cl = hv__extend_cl_handle(e->cl);
    if (!cl->fp64)
        return hv__error(HV_ERR_UNSUPPORTED,
                         "extend: tiles on the device need double precision (cl_khr_fp64)");
    cl_bool little = CL_FALSE;
    if (clGetDeviceInfo(cl->dev, CL_DEVICE_ENDIAN_LITTLE, sizeof little, &little, NULL) !=
            CL_SUCCESS ||
        !little)
        return hv__error(HV_ERR_UNSUPPORTED,
                         "extend: tiles on the device need a little-endian device");
    if ((st = hv__cl_module_open(cl, &bx_module)) || (st = hv__cl_ops_open(cl)))
        return st;
    struct hv_extend_tiles_cl *x = calloc(1, sizeof *x);
    if (!x)
        return hv__error(HV_ERR_NOMEM, "extend: out of memory");
    x->cl = cl;
    x->nt = 1;
    for (int a = 0; a < 3; a++) {
        x->tn[a] = (e->n[a] + HV_TILE - 1) / HV_TILE;
        x->nt *= (size_t)x->tn[a];
    }
    const size_t mb = 16 * sizeof(cl_uint) * x->nt, ub = (x->nt + 1) * sizeof(cl_uint);
    if (x->nt >= 0xffffffffu / 16) {
        const size_t nt = x->nt;
        free(x);
        return hv__error(HV_ERR_UNSUPPORTED,
                         "extend: a block of %zu tiles is past the device path's limit", nt);
    }
    if ((st = hv__cl_alloc(cl, x->nt * sizeof(cl_int), NULL, &x->map)) ||
        (st = hv__cl_alloc(cl, mb, NULL, &x->mark)) ||
        (st = hv__cl_alloc(cl, mb, NULL, &x->need)) || (st = hv__cl_alloc(cl, mb, NULL, &x->g1)) ||
        (st = hv__cl_alloc(cl, mb, NULL, &x->g2)) || (st = hv__cl_alloc(cl, ub, NULL, &x->cnt)) ||
        (st = hv__cl_alloc(cl, ub, NULL, &x->base)) ||
        (st = hv__cl_alloc(cl, BK_COUNT * sizeof(cl_uint), NULL, &x->K)) ||
        (st = hv__cl_alloc(cl, MAX_FIELDS_PER_CALL * sizeof(cl_int), NULL, &x->fnc)) ||
        (st = hv__cl_alloc(cl, 3 * RES_GROUPS * HV_EXTEND_TILES_CL_MAX_R * sizeof(double), NULL,
                           &x->part)) ||
        (st = hv__cl_alloc(cl, 3 * HV_EXTEND_TILES_CL_MAX_R * sizeof(double), NULL, &x->res))) {
        hv__extend_tiles_cl_destroy(&x);
        return st;
    }
    hv__cl_zero(cl, x->map, x->nt * sizeof(cl_int));
    hv__cl_zero(cl, x->cnt, ub);
    if ((st = hv__cl_check(cl))) {
        hv__extend_tiles_cl_destroy(&x);
        return st;
    }
    *out = x;
    return HV_OK;
}

hv_status hv__extend_tiles_cl_prepare(hv_extender *e)
{
    if (e->tcl)
        return HV_OK;
    return state_create(&e->tcl, e);
}

/* ---- one call -------------------------------------------------------------- */

typedef struct {
    struct hv_extend_tiles_cl *x;
    hv_extender *e;
    size_t count;        /* the level set's tiles */
    cl_mem ijk, pv, pon; /* the level set */
    int nfields, nfc, R;
    int fnc[MAX_FIELDS_PER_CALL];
    cl_int N[4], TN[4];
    int mlo[3], mhi[3]; /* the marked tiles' box (classify) */
    float bg;
    double bh, ob;
} bx_run;

static void groups(size_t n, size_t g[1], size_t l[1])
{
    l[0] = HV_CL_WG;
    g[0] = n * HV_CL_WG;
}

static void read_counters(bx_run *r, cl_uint K[BK_COUNT])
{
    hv__cl_read(r->x->cl, r->x->K, 0, BK_COUNT * sizeof(cl_uint), K);
}

/* Block cell of the level set's cell c (tile c / 512), read from its ijk. */
static void cell_at(bx_run *r, size_t c, int p[3])
{
    cl_int t[3] = {0, 0, 0};
    hv__cl_read(r->x->cl, r->ijk, 3 * (c / T3) * sizeof(cl_int), sizeof t, t);
    const int o = (int)(c % T3);
    p[0] = t[0] + (o & 7);
    p[1] = t[1] + ((o >> 3) & 7);
    p[2] = t[2] + (o >> 6);
}

/* 1. The level set checked and mapped. */
static hv_status check_and_map(bx_run *r)
{
    struct hv_extend_tiles_cl *x = r->x;
    hv_cl *cl = x->cl;
    cl_uint K[BK_COUNT];
    memset(K, 0, sizeof K);
    K[BK_BADPHI] = K[BK_BADF] = K[BK_BADTILE] = K[BK_DUP] = BK_NONE;
    K[BK_BOX] = K[BK_BOX + 1] = K[BK_BOX + 2] = BK_NONE;
    hv__cl_write(cl, x->K, 0, sizeof K, K);
    const size_t cells = r->count * T3;
    size_t g[1], l[1];
    hv__cl_range1(cells, g, l);
    hv__cl_args(cl, &bx_module, K_SCAN_PHI, "lmm", (size_t)cells, r->pv, x->K);
    if (cells)
        hv__cl_run(cl, &bx_module, K_SCAN_PHI, 1, g, l);
    hv__cl_range1(r->count, g, l);
    hv__cl_args(cl, &bx_module, K_MAP, "lIImmm", (size_t)r->count, r->N, r->TN, r->ijk, x->map,
                x->K);
    if (r->count)
        hv__cl_run(cl, &bx_module, K_MAP, 1, g, l);
    read_counters(r, K);
    hv_status st = hv__cl_check(cl);
    if (st)
        return st;
    if (K[BK_BADTILE] != BK_NONE)
        return hv__error(HV_ERR_INVALID_ARG,
                         "extend: tile %u of the level set is not on the block's 8^3 lattice",
                         K[BK_BADTILE]);
    if (K[BK_DUP] != BK_NONE)
        return hv__error(HV_ERR_INVALID_ARG, "extend: the level set lists a tile twice (tile %u)",
                         K[BK_DUP]);
    if (K[BK_BADPHI] != BK_NONE) {
        int p[3];
        float v = 0;
        cell_at(r, K[BK_BADPHI], p);
        hv__cl_read(cl, r->pv, K[BK_BADPHI] * sizeof v, sizeof v, &v);
        return hv__error(HV_ERR_NUMERIC,
                         "extend: the level set holds a non-finite value (%g) at cell (%d, %d, %d)",
                         (double)v, p[0], p[1], p[2]);
    }
    memcpy(&r->bg, &K[BK_BG], sizeof r->bg);
    return HV_OK;
}

/* 2. Weights, pending cells and level 0's marks; the outputs reset. */
static hv_status classify(bx_run *r, size_t *nsrc, size_t *npend)
{
    struct hv_extend_tiles_cl *x = r->x;
    hv_cl *cl = x->cl;
    const hv_extender *e = r->e;
    const size_t stride = r->count * T3;
    hv_status st;
    if ((st = grow(cl, &x->pend, &x->cap_pend, stride)))
        return st;
    hv__cl_zero(cl, x->mark, 16 * sizeof(cl_uint) * x->nt);
    size_t g[1], l[1];
    groups(r->count, g, l);
    hv__cl_args(cl, &bx_module, K_CLASSIFY, "IImmmmfaaaaiilmmmm", r->N, r->TN, x->map, r->ijk,
                r->pv, r->pon, (double)r->bg, r->bh, r->ob, e->h, e->o.band, e->o.closest_point,
                r->nfc, (size_t)stride, x->src, x->pend, x->mark, x->K);
    if (r->count)
        hv__cl_run(cl, &bx_module, K_CLASSIFY, 1, g, l);
    cl_uint K[BK_COUNT];
    read_counters(r, K);
    if ((st = hv__cl_check(cl)))
        return st;
    if (K[BK_BADF] != BK_NONE) {
        int p[3];
        cell_at(r, K[BK_BADF], p);
        for (int fi = 0, q0 = 0; fi < r->nfields; q0 += r->fnc[fi], fi++)
            for (int q = 0; q < r->fnc[fi]; q++) {
                float v = 0;
                hv__cl_read(cl, x->src, ((q0 + q) * stride + K[BK_BADF]) * sizeof v, sizeof v, &v);
                if (!isfinite(v))
                    return hv__error(HV_ERR_NUMERIC,
                                     "extend: field %d component %d is NaN/Inf at cell (%d, %d, "
                                     "%d), inside the source band",
                                     fi, q, p[0], p[1], p[2]);
            }
    }
    *nsrc = K[BK_NSRC];
    *npend = K[BK_NPEND];
    for (int a = 0; a < 3; a++) {
        r->mlo[a] = K[BK_BOX + a] == BK_NONE ? 0 : (int)K[BK_BOX + a];
        r->mhi[a] = (int)K[BK_BOX + 3 + a];
    }
    const float bgv = (float)e->o.background;
    hv__cl_fill(cl, x->fv, (size_t)r->nfc * stride * sizeof(float), &bgv, sizeof bgv);
    hv__cl_zero(cl, x->fon, (size_t)r->nfc * 16 * r->count * sizeof(cl_uint));
    return hv__cl_check(cl);
}

/* mask -> its cells per tile of the box B0, BN in x->cnt. */
static void count_cells(bx_run *r, cl_mem mask, const cl_int B0[4], const cl_int BN[4])
{
    hv_cl *cl = r->x->cl;
    size_t g[1], l[1];
    hv__cl_range1((size_t)BN[0] * BN[1] * BN[2], g, l);
    hv__cl_args(cl, &bx_module, K_COUNT, "IIImm", r->TN, B0, BN, mask, r->x->cnt);
    hv__cl_run(cl, &bx_module, K_COUNT, 1, g, l);
}

/* 3a. The domain of level l (marks grown by m) in g1, its cells per tile
 * in cnt and their prefix sums in base; *ncells its cells. The kernels run
 * on the box of the marked tiles grown by the reach and one tile (B0, BN),
 * which holds the domain and its neighbours; cnt is 0 outside it. */
static hv_status make_domain(bx_run *r, int m, size_t *ncells, cl_int B0[4], cl_int BN[4])
{
    struct hv_extend_tiles_cl *x = r->x;
    hv_cl *cl = x->cl;
    const size_t mb = 16 * sizeof(cl_uint) * x->nt;
    const int D = (m + HV_TILE - 1) / HV_TILE + 1;
    for (int a = 0; a < 3; a++) {
        B0[a] = r->mlo[a] - D < 0 ? 0 : r->mlo[a] - D;
        const int hi = r->mhi[a] + D >= x->tn[a] ? x->tn[a] - 1 : r->mhi[a] + D;
        BN[a] = hi - B0[a] + 1;
    }
    B0[3] = BN[3] = 0;
    size_t g[1], l[1];
    groups((size_t)BN[0] * BN[1] * BN[2], g, l);
    hv__cl_copy(cl, x->mark, x->need, mb);
    hv__cl_zero(cl, x->cnt, x->nt * sizeof(cl_uint));
    count_cells(r, x->need, B0, BN);
    hv__cl_args(cl, &bx_module, K_GROW_X, "IIIIimmm", r->N, r->TN, B0, BN, m, x->need, x->cnt,
                x->g1);
    hv__cl_run(cl, &bx_module, K_GROW_X, 1, g, l);
    count_cells(r, x->g1, B0, BN);
    hv__cl_args(cl, &bx_module, K_GROW_YZ, "IIIIiimmm", r->N, r->TN, B0, BN, m, 1, x->g1, x->cnt,
                x->g2);
    hv__cl_run(cl, &bx_module, K_GROW_YZ, 1, g, l);
    count_cells(r, x->g2, B0, BN);
    hv__cl_args(cl, &bx_module, K_GROW_YZ, "IIIIiimmm", r->N, r->TN, B0, BN, m, 2, x->g2, x->cnt,
                x->g1);
    hv__cl_run(cl, &bx_module, K_GROW_YZ, 1, g, l);
    count_cells(r, x->g1, B0, BN);
    hv_status st = hv__cl_scan_u32(cl, x->cnt, x->base, x->nt + 1);
    if (st)
        return st;
    cl_uint n = 0;
    hv__cl_read(cl, x->base, x->nt * sizeof n, sizeof n, &n);
    *ncells = n;
    return hv__cl_check(cl);
}

/* 3b. The band solve of level l (diffusion time s h^2) on the domain:
 * the solutions in the final iterate (*sol), *thr the trust bound. */
static hv_status solve(bx_run *r, double s, size_t ncells, const cl_int B0[4], const cl_int BN[4],
                       cl_mem *sol, double *thr, hv_extend_stats *S)
{
    struct hv_extend_tiles_cl *x = r->x;
    hv_cl *cl = x->cl;
    const int R = r->R;
    hv_status st;
    size_t cap = x->cap_cells;
    if (ncells > cap) {
        size_t c1 = 0, c2 = 0;
        if ((st = grow(cl, &x->nb, &c1, 6 * ncells * sizeof(cl_uint))) ||
            (st = grow(cl, &x->dg, &c2, ncells * sizeof(float))))
            return st;
        x->cap_cells = ncells;
    }
    if (ncells * R > x->cap_rc) {
        size_t c1 = 0, c2 = 0, c3 = 0;
        if ((st = grow(cl, &x->f, &c1, ncells * R * sizeof(float))) ||
            (st = grow(cl, &x->A, &c2, ncells * R * sizeof(float))) ||
            (st = grow(cl, &x->B, &c3, ncells * R * sizeof(float))))
            return st;
        x->cap_rc = ncells * R;
    }
    size_t g[1], l[1];
    groups((size_t)BN[0] * BN[1] * BN[2], g, l);
    hv__cl_args(cl, &bx_module, K_BUILD, "IIIIailimalmmmmmmmmm", r->N, r->TN, B0, BN, s, R, ncells,
                r->nfields, x->fnc, r->bh, (size_t)(r->count * T3), x->g1, x->base, x->cnt, x->map,
                r->pv, x->src, x->nb, x->dg, x->f);
    hv__cl_run(cl, &bx_module, K_BUILD, 1, g, l);
    hv__cl_range1(ncells, g, l);
    hv__cl_args(cl, &bx_module, K_FIRST, "limmmm", (size_t)ncells, R, x->dg, x->f, x->A, x->B);
    hv__cl_run(cl, &bx_module, K_FIRST, 1, g, l);
    /* The coefficients of the wave (extend_wave.c), sweep by sweep. */
    const int iters = hv__extend_band_iters(r->e, s);
    const double theta = 1, delta = 1 - 1 / (1 + 2 * r->e->dim * s), sigma = theta / delta;
    double rho = 1 / sigma;
    for (int t = 2; t <= iters; t++) {
        const double rn = 1 / (2 * sigma - rho);
        const float a = (float)(rn * rho), c = (float)(2 * rn / delta);
        rho = rn;
        cl_mem C = t & 1 ? x->B : x->A, O = t & 1 ? x->A : x->B;
        hv__cl_args(cl, &bx_module, K_SWEEP, "lifffmmmmm", (size_t)ncells, R, (double)(float)s,
                    (double)a, (double)c, x->nb, x->dg, x->f, C, O);
        hv__cl_run(cl, &bx_module, K_SWEEP, 1, g, l);
    }
    *sol = iters & 1 ? x->A : x->B;
    const size_t rg[2] = {RES_GROUPS * HV_CL_WG, (size_t)R}, rl[2] = {HV_CL_WG, 1};
    hv__cl_args(cl, &bx_module, K_RESIDUAL, "liammmmm", (size_t)ncells, R, s, x->nb, x->dg, x->f,
                *sol, x->part);
    hv__cl_run(cl, &bx_module, K_RESIDUAL, 2, rg, rl);
    hv__cl_range1((size_t)R, g, l);
    hv__cl_args(cl, &bx_module, K_RESIDUAL_SUM, "iimm", RES_GROUPS, R, x->part, x->res);
    hv__cl_run(cl, &bx_module, K_RESIDUAL_SUM, 1, g, l);
    double res[3 * HV_EXTEND_TILES_CL_MAX_R];
    hv__cl_read(cl, x->res, 0, 3 * (size_t)R * sizeof(double), res);
    if ((st = hv__cl_check(cl)))
        return st;
    double relmax = 0;
    for (int q = 0; q < R; q++)
        relmax = fmax(relmax, res[3 * q + 2] > 0 ? sqrt(res[3 * q]) / sqrt(res[3 * q + 2]) : 0);
    S->solves += R;
    S->relres = fmax(S->relres, relmax);
    *thr = fmax(RELIABLE * res[1], 1e-30);
    return HV_OK;
}

/* 4. The output cells read from the level's solutions; those left marked. */
static hv_status evaluate(bx_run *r, cl_mem sol, size_t ncells, int l, int last, double thr,
                          hv_extend_counts *n)
{
    struct hv_extend_tiles_cl *x = r->x;
    hv_cl *cl = x->cl;
    const hv_extender *e = r->e;
    const cl_uint zero[4] = {0, 0, 0, 0};
    hv__cl_write(cl, x->K, BK_LEFT * sizeof(cl_uint), sizeof zero, zero);
    hv__cl_zero(cl, x->mark, 16 * sizeof(cl_uint) * x->nt);
    size_t g[1], lc[1];
    groups(r->count, g, lc);
    hv__cl_args(cl, &bx_module, K_EVAL, "IImmmfaaiiiimlmmmmlaiifmmmmm", r->N, r->TN, x->map, r->ijk,
                r->pv, (double)r->bg, e->h, e->o.band, e->o.closest_point, r->R, r->nfields, r->nfc,
                x->fnc, (size_t)(r->count * T3), x->need, x->g1, x->base, sol, ncells, thr, l == 0,
                last, (double)(float)e->o.background, x->pend, x->mark, x->fv, x->fon, x->K);
    if (r->count)
        hv__cl_run(cl, &bx_module, K_EVAL, 1, g, lc);
    cl_uint K[4];
    hv__cl_read(cl, x->K, BK_LEFT * sizeof(cl_uint), sizeof K, K);
    n->left = K[0];
    n->cp = K[1];
    n->ratio = K[2];
    n->weak = K[3];
    return hv__cl_check(cl);
}

static hv_status run_level(bx_run *r, int l, int last, hv_extend_stats *S, hv_extend_counts *n)
{
    const double s = r->e->o.t_scale * pow(LEVEL_FACTOR, l);
    const int m = (int)lround(BOX_MARGIN * sqrt(s));
    double t0 = hv_now();
    size_t ncells = 0;
    cl_int B0[4], BN[4];
    hv_status st = make_domain(r, m, &ncells, B0, BN);
    if (st)
        return st;
    if (l == 0)
        S->solve_cells = ncells;
    if (ncells >= 0xffffffffu)
        return hv__error(HV_ERR_UNSUPPORTED,
                         "extend: a band of %zu cells is past the device path's limit", ncells);
    cl_mem sol = NULL;
    double thr = 0;
    if ((st = solve(r, s, ncells, B0, BN, &sol, &thr, S)))
        return st;
    const size_t work = ncells * (6 * sizeof(cl_uint) + sizeof(float) + 3 * r->R * sizeof(float));
    if (work > S->work_bytes)
        S->work_bytes = work;
    S->t_solve += hv_now() - t0;
    t0 = hv_now();
    st = evaluate(r, sol, ncells, l, last, thr, n);
    S->t_eval += hv_now() - t0;
    return st;
}

/* The call once the sources are in x->src: the levels, the outputs in
 * x->fv and x->fon. The map is cleared whatever happens. */
static hv_status run_loaded(bx_run *r, hv_extend_stats *S)
{
    struct hv_extend_tiles_cl *x = r->x;
    hv_cl *cl = x->cl;
    hv_extender *e = r->e;
    double t0 = hv_now();
    hv__cl_write(cl, x->fnc, 0, (size_t)(r->nfields ? r->nfields : 1) * sizeof(cl_int), r->fnc);
    hv_status st = check_and_map(r);
    size_t nsrc = 0, npend = 0;
    if (!st)
        st = classify(r, &nsrc, &npend);
    S->source_cells = nsrc;
    if (!st && !nsrc)
        st = hv__error(HV_ERR_INVALID_ARG,
                       "extend: no cell has |phi| < band * h = %g (the level set has no zero "
                       "crossing in the tiles, or the band is too thin)",
                       e->o.band * e->h);
    S->t_weights = hv_now() - t0;
    const double ob_vox = r->ob > 0 ? e->o.out_band : r->bg / e->h;
    const int last = hv__extend_last_level(e, ob_vox);
    for (int l = 0; !st && l <= last && npend > 0; l++) {
        if ((st = hv__progress(l ? 0.5 + 0.5 * l / (last + 1) : 0.1, "extend")))
            break;
        hv_extend_counts k = {0, 0, 0, 0};
        if ((st = run_level(r, l, l == last, S, &k)))
            break;
        S->levels = l + 1;
        S->cp_cells += k.cp;
        S->ratio_cells += k.ratio;
        S->weak_cells += k.weak;
        npend = k.left;
    }
    size_t g[1], l[1];
    hv__cl_range1(r->count, g, l);
    hv__cl_args(cl, &bx_module, K_UNMAP, "lIImm", (size_t)r->count, r->N, r->TN, r->ijk, x->map);
    if (r->count)
        hv__cl_run(cl, &bx_module, K_UNMAP, 1, g, l);
    hv_status fin = hv__cl_finish(cl);
    S->work_bytes += x->nt * (4 + 4 * 64 + 8) + r->count * T3 * (1 + 2 * sizeof(float) * r->nfc);
    return st ? st : fin;
}

/* The run's shape and the fields' buffers (sources, values, active words). */
static hv_status run_init(bx_run *r, hv_extender *e, size_t count, int nfields, const int *ncomp)
{
    hv_status st = hv__extend_tiles_cl_prepare(e);
    if (st)
        return st;
    memset(r, 0, sizeof *r);
    r->x = e->tcl;
    r->e = e;
    r->count = count;
    r->nfields = nfields;
    r->R = 1;
    for (int i = 0; i < nfields; i++) {
        r->fnc[i] = ncomp[i];
        r->nfc += ncomp[i];
        r->R += ncomp[i] == 1 ? 1 : ncomp[i] + 1;
    }
    if (r->R > HV_EXTEND_TILES_CL_MAX_R)
        return hv__error(HV_ERR_UNSUPPORTED,
                         "extend: %d right-hand sides on the device, at most %d (fewer fields "
                         "per call)",
                         r->R, HV_EXTEND_TILES_CL_MAX_R);
    if (count * T3 >= 0xffffffffu)
        return hv__error(HV_ERR_UNSUPPORTED, "extend: %zu tiles are past the device path's limit",
                         count);
    for (int a = 0; a < 3; a++) {
        r->N[a] = e->n[a];
        r->TN[a] = r->x->tn[a];
    }
    r->bh = e->o.band * e->h;
    r->ob = e->o.out_band > 0 ? e->o.out_band * e->h : 0;
    struct hv_extend_tiles_cl *x = r->x;
    const size_t cells = count * T3, nfc = (size_t)(r->nfc ? r->nfc : 1);
    if ((st = grow(x->cl, &x->src, &x->cap_src, nfc * cells * sizeof(float))) ||
        (st = grow(x->cl, &x->fv, &x->cap_fv, nfc * cells * sizeof(float))) ||
        (st = grow(x->cl, &x->fon, &x->cap_fon, nfc * 16 * count * sizeof(cl_uint))))
        return st;
    return HV_OK;
}

hv_status hv__extend_tiles_cl_run(hv_extender *e, const hv_tiles *phi, int nfields,
                                  hv_extend_tiles_field *f, hv_extend_stats *S)
{
    int ncomp[MAX_FIELDS_PER_CALL];
    for (int i = 0; i < nfields; i++)
        ncomp[i] = f[i].ncomp;
    bx_run r;
    hv_status st = run_init(&r, e, phi->count, nfields, ncomp);
    if (st)
        return st;
    struct hv_extend_tiles_cl *x = r.x;
    hv_cl *cl = x->cl;
    const size_t cells = phi->count * T3;
    if ((st = grow(cl, &x->pijk, &x->cap_pt, 3 * phi->count * sizeof(cl_int))))
        return st;
    if ((st = grow(cl, &x->pv, &x->cap_pv, cells * sizeof(float))) ||
        (st = grow(cl, &x->pon, &x->cap_pon, 8 * phi->count * sizeof(uint64_t))))
        return st;
    hv__cl_write(cl, x->pijk, 0, 3 * phi->count * sizeof(cl_int), phi->ijk);
    hv__cl_write(cl, x->pv, 0, cells * sizeof(float), phi->v);
    hv__cl_write(cl, x->pon, 0, 8 * phi->count * sizeof(uint64_t), phi->on);
    for (int i = 0, q0 = 0; i < nfields; q0 += f[i].ncomp, i++)
        for (int q = 0; q < f[i].ncomp; q++)
            hv__cl_write(cl, x->src, (q0 + q) * cells * sizeof(float), cells * sizeof(float),
                         f[i].v[q]->v);
    r.ijk = x->pijk;
    r.pv = x->pv;
    r.pon = x->pon;
    if ((st = run_loaded(&r, S)))
        return st;
    for (int i = 0, q0 = 0; i < nfields; q0 += f[i].ncomp, i++)
        for (int q = 0; q < f[i].ncomp; q++) {
            hv__cl_read(cl, x->fv, (q0 + q) * cells * sizeof(float), cells * sizeof(float),
                        f[i].v[q]->v);
            hv__cl_read(cl, x->fon, (q0 + q) * 8 * phi->count * sizeof(uint64_t),
                        8 * phi->count * sizeof(uint64_t), f[i].v[q]->on);
        }
    hv__cl_profile_flush(cl);
    return hv__cl_check(cl);
}

/* A buffer of x's context of at least `bytes`, or the reason not. */
static hv_status check_dev(hv_cl *cl, cl_mem m, size_t bytes, const char *what, int i, int q)
{
    char name[80];
    if (i < 0)
        snprintf(name, sizeof name, "%s", what);
    else
        snprintf(name, sizeof name, "%s (field %d component %d)", what, i, q);
    return hv__cl_check_floats(cl, m, (bytes + 3) / 4, "hv_opencl_extend_tiles", name);
}

hv_status hv__extend_tiles_cl_run_dev(hv_extender *e, const hv_opencl_tiles *phi, int nfields,
                                      const hv_opencl_tiles_field *f, hv_extend_stats *S)
{
    int ncomp[MAX_FIELDS_PER_CALL];
    for (int i = 0; i < nfields; i++)
        ncomp[i] = f[i].ncomp;
    bx_run r;
    hv_status st = run_init(&r, e, phi->count, nfields, ncomp);
    if (st)
        return st;
    struct hv_extend_tiles_cl *x = r.x;
    hv_cl *cl = x->cl;
    const size_t cells = phi->count * T3, ob = 8 * phi->count * sizeof(uint64_t);
    if (phi->count &&
        ((st = check_dev(cl, phi->ijk, 3 * phi->count * sizeof(cl_int), "ijk", -1, 0)) ||
         (st = check_dev(cl, phi->v, cells * sizeof(float), "v", -1, 0)) ||
         (st = check_dev(cl, phi->on, ob, "on", -1, 0))))
        return st;
    for (int i = 0; i < nfields && !st; i++)
        for (int q = 0; q < f[i].ncomp && !st; q++)
            if (!(st = check_dev(cl, f[i].v[q], cells * sizeof(float), "v", i, q)))
                st = check_dev(cl, f[i].on[q], ob, "on", i, q);
    if (st)
        return st;
    for (int i = 0, q0 = 0; i < nfields; q0 += f[i].ncomp, i++)
        for (int q = 0; q < f[i].ncomp; q++)
            hv__cl_copy_at(cl, f[i].v[q], 0, x->src, (q0 + q) * cells * sizeof(float),
                           cells * sizeof(float));
    r.ijk = phi->ijk;
    r.pv = phi->v;
    r.pon = phi->on;
    if ((st = run_loaded(&r, S)))
        return st;
    for (int i = 0, q0 = 0; i < nfields; q0 += f[i].ncomp, i++)
        for (int q = 0; q < f[i].ncomp; q++) {
            hv__cl_copy_at(cl, x->fv, (q0 + q) * cells * sizeof(float), f[i].v[q], 0,
                           cells * sizeof(float));
            hv__cl_copy_at(cl, x->fon, (q0 + q) * ob, f[i].on[q], 0, ob);
        }
    st = hv__cl_finish(cl);
    hv__cl_profile_flush(cl);
    return st;
}
