/*
 * The narrow band in tiles (sdf_tiles.c) on an OpenCL device: the same steps,
 * each a kernel of kernels/tiles.cl, which this file registers and builds
 * (hv_cl_module, src/cl/cl_core.h).
 *
 *   1. the mesh, its pseudonormals and its winding-number tree go to the
 *      device once; every face's trust (whether it bounds a solid) is
 *      evaluated there
 *   2. bin: (tile, triangle) pairs counted per tile key, the counts scanned
 *      into starts, the triangles filled into their tiles' lists (a counting
 *      sort by tile), the keys that hold a triangle listed in order
 *   3. per listed tile, one work-group: the near test, the raster, the
 *      signs, the band's values and active bits
 *   4. the tiles with an active voxel compacted in order, then read back in
 *      batches of the host path's size and handed to the sink
 *
 * On the way the host reads three counts and the stage's five sums, then
 * the kept tiles once; no field crosses before.
 */
#include "sdf_internal.h"
#include "core/error.h"
#include "cl/cl_core.h"
#include "cl/cl_ops.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

extern const char hv__kernel_tiles[]; /* kernels/tiles.cl, embedded by the Makefile */

static const char *const tiles_sources[] = {hv__kernel_tiles, NULL};
enum { K_TRUST, K_COUNT, K_FILL, K_FLAG, K_LIST, K_SIGN, K_COMPACT };
static const char *const tiles_kernels[] = {"tiles_trust",   "tiles_count", "tiles_fill",
                                            "tiles_flag",    "tiles_list",  "tiles_sign",
                                            "tiles_compact", NULL};
static const hv_cl_module tiles_module = {"tiles", tiles_sources, tiles_kernels, 1, 0};

#define T3 (HV_TILE * HV_TILE * HV_TILE)

/* The stage's sums (kernels/tiles.cl, tiles_sign). */
enum { C_BAND, C_ACTIVE, C_EVALS, C_USED, C_NEAR, C_COUNT };

/* What the device holds of one run. */
typedef struct {
    hv_cl *cl;
    cl_int N[4], NB[4];
    double O[4], R[4];
    size_t nkeys, npairs, ntiles, kept;
    int unsig, closed, nnodes;
    /* the mesh, its pseudonormals and its winding-number tree */
    cl_mem V, T, fn, vn, other, vok, ftrust, nd, ni, order, sign;
    /* the bins: counts, starts (nkeys + 1), pairs, listed keys */
    cl_mem cnt, start, pairs, flag, pos, list;
    /* the tiles, then the kept ones */
    cl_mem vt, on, ijk, keep, kpos, vo, ono, ijko, counts;
} tl_run;

static void run_free(tl_run *r)
{
    cl_mem *all[] = {&r->V,    &r->T,   &r->fn,    &r->vn,   &r->other, &r->vok,   &r->ftrust,
                     &r->nd,   &r->ni,  &r->order, &r->sign, &r->cnt,   &r->start, &r->pairs,
                     &r->flag, &r->pos, &r->list,  &r->vt,   &r->on,    &r->ijk,   &r->keep,
                     &r->kpos, &r->vo,  &r->ono,   &r->ijko, &r->counts};
    for (size_t i = 0; i < sizeof all / sizeof all[0]; i++)
        hv__cl_free(all[i]);
    hv__cl_close(&r->cl);
}

static void range_groups(size_t groups, size_t g[1], size_t l[1])
{
    l[0] = HV_CL_WG;
    g[0] = groups * HV_CL_WG;
}

/* One uint of m at index i (a host synchronization). */
static size_t read_u32(hv_cl *cl, cl_mem m, size_t i)
{
    cl_uint v = 0;
    hv__cl_read(cl, m, i * sizeof v, sizeof v, &v);
    return v;
}

/* 1. The mesh to the device. */
static hv_status put_mesh(tl_run *r, const hv_mesh *M)
{
    hv_status st;
    if ((st = hv__cl_alloc(r->cl, 3 * M->nverts * sizeof(double), M->verts, &r->V)) ||
        (st = hv__cl_alloc(r->cl, 3 * M->ntris * sizeof(uint32_t), M->tris, &r->T)))
        return st;
    return HV_OK;
}

/* The winding-number tree's nodes as the kernels read them: 8 doubles
 * (centre, vector area, radius, 0) and 4 ints (left, right, first, count). */
static hv_status put_tree(tl_run *r, const hv_wn_tree *W, size_t nfaces)
{
    const size_t nn = W->nnodes > 0 ? (size_t)W->nnodes : 1;
    double *nd = calloc(8 * nn, sizeof *nd);
    cl_int *ni = calloc(4 * nn, sizeof *ni);
    hv_status st = HV_OK;
    if (!nd || !ni) {
        st = hv__error(HV_ERR_NOMEM, "sdf: out of memory for the winding-number tree");
        goto out;
    }
    for (int k = 0; k < W->nnodes; k++) {
        const hv_wn_node *x = &W->nodes[k];
        for (int d = 0; d < 3; d++) {
            nd[8 * k + d] = x->c[d];
            nd[8 * k + 3 + d] = x->N[d];
        }
        nd[8 * k + 6] = x->r;
        ni[4 * k] = x->left;
        ni[4 * k + 1] = x->right;
        ni[4 * k + 2] = (cl_int)x->first;
        ni[4 * k + 3] = (cl_int)x->count;
    }
    r->nnodes = W->nnodes;
    if ((st = hv__cl_alloc(r->cl, 8 * nn * sizeof *nd, nd, &r->nd)) ||
        (st = hv__cl_alloc(r->cl, 4 * nn * sizeof *ni, ni, &r->ni)) ||
        (st = hv__cl_alloc(r->cl, nfaces * sizeof(uint32_t), W->order, &r->order)) ||
        (st = hv__cl_alloc(r->cl, nfaces, W->sign, &r->sign)))
        goto out;
out:
    free(nd);
    free(ni);
    return st;
}

/* 1. The pseudonormals, the tree and every face's trust, for the sign. */
static hv_status put_sign(tl_run *r, const hv_mesh *M)
{
    hv_pseudo ps;
    hv_status st = hv__pseudo_build(M, &ps);
    if (st)
        return st;
    const size_t nt = M->ntris, nv = M->nverts;
    r->closed = ps.balanced;
    if (!(st = hv__cl_alloc(r->cl, 3 * nt * sizeof(double), ps.fn, &r->fn)) &&
        !(st = hv__cl_alloc(r->cl, 3 * nv * sizeof(double), ps.vn, &r->vn)) &&
        !(st = hv__cl_alloc(r->cl, 3 * nt * sizeof(uint32_t), ps.other, &r->other)) &&
        !(st = hv__cl_alloc(r->cl, nv, ps.vok, &r->vok)) &&
        !(st = hv__cl_alloc(r->cl, nt, NULL, &r->ftrust)) && !(st = put_tree(r, &ps.W, nt))) {
        size_t g[1], l[1];
        hv__cl_range1(nt, g, l);
        hv__cl_args(r->cl, &tiles_module, K_TRUST, "immmmmmim", (int)nt, r->V, r->T, r->nd, r->ni,
                    r->order, r->sign, r->nnodes, r->ftrust);
        hv__cl_run(r->cl, &tiles_module, K_TRUST, 1, g, l);
        st = hv__cl_check(r->cl);
    }
    hv__pseudo_free(&ps);
    return st;
}

/* 2. The (tile, triangle) pairs sorted by tile and the keys listed. */
static hv_status bin(tl_run *r, size_t ntri)
{
    hv_cl *cl = r->cl;
    const size_t nk = r->nkeys;
    size_t g[1], l[1];
    hv_status st;
    if ((st = hv__cl_alloc(cl, (nk + 1) * sizeof(cl_uint), NULL, &r->cnt)) ||
        (st = hv__cl_alloc(cl, (nk + 1) * sizeof(cl_uint), NULL, &r->start)))
        return st;
    hv__cl_zero(cl, r->cnt, (nk + 1) * sizeof(cl_uint));
    hv__cl_range1(ntri, g, l);
    hv__cl_args(cl, &tiles_module, K_COUNT, "IIAaimmm", r->N, r->NB, r->O, r->R[0], (int)ntri, r->V,
                r->T, r->cnt);
    hv__cl_run(cl, &tiles_module, K_COUNT, 1, g, l);
    if ((st = hv__cl_scan_u32(cl, r->cnt, r->start, nk + 1)))
        return st;
    r->npairs = read_u32(cl, r->start, nk);
    if ((st = hv__cl_check(cl)))
        return st;
    if (r->npairs == 0)
        return hv__error(HV_ERR_INVALID_ARG, "sdf: no part of the mesh lies inside the grid block");
    if ((st = hv__cl_alloc(cl, r->npairs * sizeof(cl_uint), NULL, &r->pairs)))
        return st;
    hv__cl_zero(cl, r->cnt, (nk + 1) * sizeof(cl_uint));
    hv__cl_args(cl, &tiles_module, K_FILL, "IIAaimmmmm", r->N, r->NB, r->O, r->R[0], (int)ntri,
                r->V, r->T, r->cnt, r->start, r->pairs);
    hv__cl_run(cl, &tiles_module, K_FILL, 1, g, l);
    /* The counts' buffer takes the flags, then the keys' positions. */
    r->flag = r->cnt;
    r->cnt = NULL;
    if ((st = hv__cl_alloc(cl, (nk + 1) * sizeof(cl_uint), NULL, &r->pos)))
        return st;
    hv__cl_zero(cl, r->flag, (nk + 1) * sizeof(cl_uint));
    hv__cl_range1(nk, g, l);
    hv__cl_args(cl, &tiles_module, K_FLAG, "imm", (int)nk, r->start, r->flag);
    hv__cl_run(cl, &tiles_module, K_FLAG, 1, g, l);
    if ((st = hv__cl_scan_u32(cl, r->flag, r->pos, nk + 1)))
        return st;
    r->ntiles = read_u32(cl, r->pos, nk);
    if ((st = hv__cl_alloc(cl, (r->ntiles ? r->ntiles : 1) * sizeof(cl_uint), NULL, &r->list)))
        return st;
    hv__cl_args(cl, &tiles_module, K_LIST, "immm", (int)nk, r->start, r->pos, r->list);
    hv__cl_run(cl, &tiles_module, K_LIST, 1, g, l);
    hv__cl_free(&r->flag);
    hv__cl_free(&r->pos);
    return hv__cl_check(cl);
}

/* Whether the listed tiles' arrays (twice, before and after compaction)
 * fit in the device's memory with the lists. */
static hv_status device_fits(const tl_run *r)
{
    const double per = T3 * sizeof(float) + 8 * sizeof(uint64_t) + 3 * sizeof(int32_t) + 8;
    const double need = 2 * per * (double)r->ntiles + 4.0 * (double)(r->npairs + 2 * r->nkeys);
    const double have = (double)r->cl->info.global_mem;
    if (have > 0 && need > 0.8 * have)
        return hv__error(HV_ERR_NOMEM,
                         "sdf: the narrow band's %zu tiles need about %.3g GB on '%s', which has "
                         "%.3g GB",
                         r->ntiles, need / 1e9, r->cl->info.name, have / 1e9);
    return HV_OK;
}

/* 3. Every listed tile rasterized and signed; the sums into cnt. */
static hv_status sign_tiles(tl_run *r, cl_uint cnt[C_COUNT])
{
    hv_cl *cl = r->cl;
    const size_t nt = r->ntiles;
    hv_status st;
    if ((st = device_fits(r)) ||
        (st = hv__cl_alloc(cl, (size_t)T3 * nt * sizeof(float), NULL, &r->vt)) ||
        (st = hv__cl_alloc(cl, 8 * nt * sizeof(uint64_t), NULL, &r->on)) ||
        (st = hv__cl_alloc(cl, 3 * nt * sizeof(int32_t), NULL, &r->ijk)) ||
        (st = hv__cl_alloc(cl, (nt + 1) * sizeof(cl_uint), NULL, &r->keep)) ||
        (st = hv__cl_alloc(cl, C_COUNT * sizeof(cl_uint), NULL, &r->counts)))
        return st;
    hv__cl_zero(cl, r->keep, (nt + 1) * sizeof(cl_uint));
    hv__cl_zero(cl, r->counts, C_COUNT * sizeof(cl_uint));
    const cl_int F[4] = {r->unsig, r->closed, r->nnodes, 0};
    size_t g[1], l[1];
    range_groups(nt, g, l);
    hv__cl_args(cl, &tiles_module, K_SIGN, "IIAAImmmmmmmmmmmmmmmmmmm", r->N, r->NB, r->O, r->R, F,
                r->list, r->start, r->pairs, r->V, r->T, r->fn, r->vn, r->other, r->vok, r->ftrust,
                r->nd, r->ni, r->order, r->sign, r->vt, r->on, r->ijk, r->keep, r->counts);
    hv__cl_run(cl, &tiles_module, K_SIGN, 1, g, l);
    hv__cl_read(cl, r->counts, 0, C_COUNT * sizeof(cl_uint), cnt);
    return hv__cl_finish(cl);
}

/* 4. The kept tiles to the front, in order. */
static hv_status compact(tl_run *r)
{
    hv_cl *cl = r->cl;
    const size_t nt = r->ntiles;
    hv_status st;
    if ((st = hv__cl_alloc(cl, (nt + 1) * sizeof(cl_uint), NULL, &r->kpos)) ||
        (st = hv__cl_scan_u32(cl, r->keep, r->kpos, nt + 1)))
        return st;
    r->kept = read_u32(cl, r->kpos, nt);
    if ((st = hv__cl_check(cl)))
        return st;
    if (r->kept == 0)
        return hv__error(HV_ERR_INVALID_ARG,
                         "sdf: no part of the mesh's narrow band lies inside the grid block");
    const size_t k = r->kept;
    if ((st = hv__cl_alloc(cl, (size_t)T3 * k * sizeof(float), NULL, &r->vo)) ||
        (st = hv__cl_alloc(cl, 8 * k * sizeof(uint64_t), NULL, &r->ono)) ||
        (st = hv__cl_alloc(cl, 3 * k * sizeof(int32_t), NULL, &r->ijko)))
        return st;
    size_t g[1], l[1];
    range_groups(nt, g, l);
    hv__cl_args(cl, &tiles_module, K_COMPACT, "mmmmmmmm", r->keep, r->kpos, r->vt, r->on, r->ijk,
                r->vo, r->ono, r->ijko);
    hv__cl_run(cl, &tiles_module, K_COMPACT, 1, g, l);
    hv__cl_free(&r->vt);
    hv__cl_free(&r->on);
    hv__cl_free(&r->ijk);
    return hv__cl_finish(cl);
}

static size_t popcount64(uint64_t x)
{
    size_t c = 0;
    for (; x; x &= x - 1)
        c++;
    return c;
}

/* 4. The kept tiles read back batch by batch into the sink, once begun. */
static hv_status send(tl_run *r, const int n[3], double h, const double origin[3],
                      const hv_tiles_sink *sink)
{
    const size_t batch = hv__sdf_tile_batch();
    const size_t cap = batch < r->kept ? batch : r->kept;
    hv_tiles *B = hv__tiles_alloc(n, h, origin, cap);
    hv_status st = HV_OK;
    if (!B)
        return hv__error(HV_ERR_NOMEM, "sdf: out of memory for the narrow band's tiles");
    for (size_t t0 = 0; t0 < r->kept && !st; t0 += cap) {
        const size_t m = r->kept - t0 < cap ? r->kept - t0 : cap;
        hv__cl_read(r->cl, r->vo, (size_t)T3 * t0 * sizeof(float), (size_t)T3 * m * sizeof(float),
                    B->v);
        hv__cl_read(r->cl, r->ono, 8 * t0 * sizeof(uint64_t), 8 * m * sizeof(uint64_t), B->on);
        hv__cl_read(r->cl, r->ijko, 3 * t0 * sizeof(int32_t), 3 * m * sizeof(int32_t), B->ijk);
        if ((st = hv__cl_check(r->cl)))
            break;
        B->count = m;
        B->active = 0;
        for (size_t w = 0; w < 8 * m; w++)
            B->active += popcount64(B->on[w]);
        st = sink->put(sink->user, B);
    }
    hv_tiles_destroy(&B);
    return st;
}

/* The block's geometry and the run's constants (as hv__sdf_tiles's). */
static hv_status run_setup(tl_run *r, const hv_mesh *M, const int n[3], double h,
                           const double origin[3], double band, int unsig, double near_sign)
{
    const int nt[3] = {(n[0] + HV_TILE - 1) / HV_TILE, (n[1] + HV_TILE - 1) / HV_TILE,
                       (n[2] + HV_TILE - 1) / HV_TILE};
    const int nb[3] = {(nt[0] + 1) / 2, (nt[1] + 1) / 2, (nt[2] + 1) / 2};
    const double keys = 8.0 * nb[0] * nb[1] * nb[2];
    if (keys >= 4294967295.0 || M->ntris >= 2147483647u || M->nverts >= 2147483647u)
        return hv__error(HV_ERR_UNSUPPORTED,
                         "sdf: %d x %d x %d cells with %zu triangles are beyond the device "
                         "path's 32-bit lists",
                         n[0], n[1], n[2], M->ntris);
    hv_status st = hv__sdf_band_fits(M, n, h, 1);
    if (st)
        return st;
    for (int a = 0; a < 3; a++) {
        r->N[a] = n[a];
        r->NB[a] = nb[a];
        r->O[a] = origin[a];
    }
    r->N[3] = 0;
    r->NB[3] = nt[0];
    r->O[3] = h;
    r->nkeys = (size_t)keys;
    /* The raster's reach, the band, the pseudonormals' reaches: as the host
     * path's, the band and the reaches rounded to float there. */
    r->R[0] = fmax(band, 2.0) * h;
    r->R[1] = (float)(band * h);
    r->R[2] = (float)h;
    r->R[3] = (float)(near_sign * h);
    r->unsig = unsig;
    if ((st = hv__cl_open(&r->cl)))
        return st;
    if (!r->cl->fp64)
        return hv__error(HV_ERR_UNSUPPORTED,
                         "sdf: the narrow band on a device needs double precision, which '%s' "
                         "lacks",
                         r->cl->info.name);
    hv_status so = hv__cl_module_open(r->cl, &tiles_module);
    return so ? so : hv__cl_ops_open(r->cl);
}

static void run_stats(const tl_run *r, const cl_uint cnt[C_COUNT], double ts, hv_sdf_stats *S)
{
    S->tiles = r->kept;
    S->active_voxels = cnt[C_ACTIVE];
    S->band_cells = cnt[C_BAND];
    S->winding_evals = cnt[C_EVALS];
    S->near_sign_cells = cnt[C_USED];
    S->t_sign = ts;
    S->tiles_bound = r->kept;
    S->tiles_in_flight = hv__sdf_tile_batch() < r->kept ? hv__sdf_tile_batch() : r->kept;
    S->backend = HV_BACKEND_OPENCL;
}

hv_status hv__sdf_tiles_cl(const hv_mesh *M, const int n[3], double h, const double origin[3],
                           double band, int unsig, double near_sign, const hv_tiles_sink *sink,
                           hv_sdf_stats *S)
{
    tl_run r;
    memset(&r, 0, sizeof r);
    cl_uint cnt[C_COUNT] = {0};
    hv_status st;
    double ts = 0;
    if ((st = run_setup(&r, M, n, h, origin, band, unsig, near_sign)) || (st = put_mesh(&r, M)) ||
        (!unsig && (st = put_sign(&r, M))) || (st = bin(&r, M->ntris)) ||
        (st = hv__progress(0.3, "tiles")))
        goto out;
    ts = hv_now();
    if ((st = sign_tiles(&r, cnt)))
        goto out;
    ts = hv_now() - ts;
    if ((st = compact(&r)) || (st = hv__progress(0.9, "tiles")))
        goto out;
    const hv_tiles blk = {
        .n = {n[0], n[1], n[2]}, .h = h, .origin = {origin[0], origin[1], origin[2]}};
    /* From here the sink hears of the run's end. */
    st = sink->begin(sink->user, &blk, r.kept);
    if (!st)
        st = send(&r, n, h, origin, sink);
    run_stats(&r, cnt, ts, S);
    hv_status e = sink->end(sink->user, !st);
    st = st ? st : e;
out:
    run_free(&r);
    return st;
}
