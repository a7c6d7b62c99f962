/*
 * The narrow band of a signed distance volume as 8^3 tiles, without the dense
 * grid (docs/METHOD.md, "Sparse narrow bands"). Memory follows the surface:
 * the tiles a triangle's band can reach, and per thread one tile's work.
 *
 *   1. bin      each triangle into the tiles its box grown by the band
 *               touches: (tile, triangle) pairs sorted by tile (radix sort)
 *   2. raster   per tile, every binned triangle writes its distance into the
 *               tile's cells within the band (exact.c's raster, clipped to
 *               the tile), keeping the least with the nearest triangle: the
 *               same values, bit for bit, as the raster over the dense grid
 *   3. sign     per cell in the band: the pseudonormal of the nearest
 *               feature where it is clean and its faces bound a solid (exact
 *               for such a feature at any distance, Baerentzen & Aanaes
 *               2005), else the generalized winding number of the repaired
 *               mesh above 1/2, the convention of the dense path's winding
 *               sign (sign_winding.c). Thin features keep their inside: no
 *               coarse field is interpolated
 *   4. compact  tiles without an active voxel are dropped
 *
 * A cell is active where its distance is below band * h, as the level-set
 * writer makes active in a dense grid; other cells of a tile hold +band * h,
 * and the sign of everything not active is left to a flood fill from the
 * active cells (the .vdb writer runs OpenVDB's signedFloodFill).
 */
#include "sdf_internal.h"
#include "core/error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include <omp.h>
#include <stdatomic.h>

#define T3 (HV_TILE * HV_TILE * HV_TILE)

/* Sorts a[0..n) by their high 32 bits (stable, two 16-bit passes); tmp holds
 * n. Returns 0 when out of memory for the counts. */
static int sort_by_tile(uint64_t *a, uint64_t *tmp, size_t n)
{
    size_t *cnt = malloc(65536 * sizeof *cnt);
    if (!cnt)
        return 0;
    for (int pass = 0; pass < 2; pass++) {
        const int shift = 32 + 16 * pass;
        memset(cnt, 0, 65536 * sizeof *cnt);
        for (size_t i = 0; i < n; i++)
            cnt[(a[i] >> shift) & 0xffff]++;
        size_t at = 0;
        for (size_t b = 0; b < 65536; b++) {
            size_t c = cnt[b];
            cnt[b] = at;
            at += c;
        }
        for (size_t i = 0; i < n; i++)
            tmp[cnt[(a[i] >> shift) & 0xffff]++] = a[i];
        memcpy(a, tmp, n * sizeof *a);
    }
    free(cnt);
    return 1;
}

static int cmp_u32(const void *x, const void *y)
{
    uint32_t a = *(const uint32_t *)x, b = *(const uint32_t *)y;
    return a < b ? -1 : a > b;
}

static int cmp_hi32(const void *x, const void *y)
{
    uint64_t a = *(const uint64_t *)x >> 32, b = *(const uint64_t *)y >> 32;
    return a < b ? -1 : a > b;
}

/* The tile range [lo, hi] (inclusive) a triangle's box grown by W reaches;
 * 0 when it misses the block. */
static int tri_tiles(const hv_mesh *M, size_t t, const int n[3], double h, const double origin[3],
                     double W, const int nt[3], int lo[3], int hi[3])
{
    const uint32_t *v = M->tris + 3 * t;
    for (int a = 0; a < 3; a++) {
        double x0 = M->verts[3 * (size_t)v[0] + a], x1 = M->verts[3 * (size_t)v[1] + a],
               x2 = M->verts[3 * (size_t)v[2] + a];
        double mn = fmin(x0, fmin(x1, x2)) - W, mx = fmax(x0, fmax(x1, x2)) + W;
        double l = ceil((mn - origin[a]) / h - 0.5), u = floor((mx - origin[a]) / h - 0.5);
        if (u < 0 || l > n[a] - 1)
            return 0;
        int cl = l < 0 ? 0 : (int)l, cu = u > n[a] - 1 ? n[a] - 1 : (int)u;
        lo[a] = cl / HV_TILE;
        hi[a] = cu / HV_TILE;
        if (hi[a] >= nt[a])
            hi[a] = nt[a] - 1;
    }
    return 1;
}

/* A lower bound on the band's memory, checked before the binning (which
 * itself needs memory in proportion to the band): a plane cuts an 8^3 tile in
 * at most 64 sqrt(2) voxel^2, so the surface's area bounds the band's tiles
 * below. Blocks whose tiles cannot be numbered in 32 bits (past 2^41 cells)
 * are refused with the same figure. */
static hv_status band_fits(const hv_mesh *M, const int n[3], double h, int numbered)
{
    double area = 0;
    for (size_t t = 0; t < M->ntris; t++) {
        const double *a = M->verts + 3 * (size_t)M->tris[3 * t],
                     *b = M->verts + 3 * (size_t)M->tris[3 * t + 1],
                     *c = M->verts + 3 * (size_t)M->tris[3 * t + 2];
        double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
        double v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        double x = u[1] * v[2] - u[2] * v[1], y = u[2] * v[0] - u[0] * v[2],
               z = u[0] * v[1] - u[1] * v[0];
        area += 0.5 * sqrt(x * x + y * y + z * z);
    }
    double tiles = area / (h * h) / (64.0 * sqrt(2.0));
    double need = tiles * 2 * (T3 * sizeof(float) + 8 * sizeof(uint64_t) + 12);
    if (numbered && need <= (double)hv__physical_memory())
        return HV_OK;
    return hv__error(HV_ERR_NOMEM,
                     "sdf: a block of %d x %d x %d cells: its narrow band alone needs at least "
                     "%.3g GB, more than this machine's %.3g GB",
                     n[0], n[1], n[2], need / 1e9, hv__physical_memory() / 1e9);
}

hv_status hv__sdf_tiles(const hv_mesh *M, const int n[3], double h, const double origin[3],
                        double band, int unsig, double near_sign, hv_tiles **out, hv_sdf_stats *S)
{
    *out = NULL;
    const int nt[3] = {(n[0] + HV_TILE - 1) / HV_TILE, (n[1] + HV_TILE - 1) / HV_TILE,
                       (n[2] + HV_TILE - 1) / HV_TILE};
    /* Tiles are numbered by 2x2x2 group (16^3 cells, rasterized together),
     * then by octant within it. */
    const int nb[3] = {(nt[0] + 1) / 2, (nt[1] + 1) / 2, (nt[2] + 1) / 2};
#define TKEY(x, y, z)                                                                              \
    ((((uint64_t)((x) >> 1) +                                                                      \
       (uint64_t)nb[0] * ((uint64_t)((y) >> 1) + (uint64_t)nb[1] * (uint64_t)((z) >> 1)))          \
      << 3) |                                                                                      \
     (uint64_t)(((x)&1) | ((y)&1) << 1 | ((z)&1) << 2))
    hv_status st = band_fits(M, n, h, 8.0 * nb[0] * nb[1] * nb[2] < 4294967295.0);
    if (st)
        return st;
    /* The raster's reach: the band, and at least the 2 voxels the dense
     * path rasterizes, so that both keep the same nearest triangles. */
    const double bandw = band * h, W = fmax(band, 2.0) * h;
    const float bg = (float)bandw;
    const size_t ntri = M->ntris;
    size_t *first = hv_malloc((ntri + 1) * sizeof *first);
    uint64_t *pairs = NULL, *tmp = NULL;
    size_t *tstart = NULL, *gstart = NULL;
    hv_tiles *T = NULL;
    uint8_t *keep = NULL;
    hv_pseudo ps;
    int have_ps = 0;
    if (!first)
        goto nomem;

    /* 1. Bin: (tile << 32 | triangle), counted first, then filled. */
    first[0] = 0;
#pragma omp parallel for schedule(static)
    for (size_t t = 0; t < ntri; t++) {
        int lo[3], hi[3];
        first[t + 1] = tri_tiles(M, t, n, h, origin, W, nt, lo, hi)
                           ? (size_t)(hi[0] - lo[0] + 1) * (hi[1] - lo[1] + 1) * (hi[2] - lo[2] + 1)
                           : 0;
    }
    for (size_t t = 0; t < ntri; t++)
        first[t + 1] += first[t];
    const size_t npairs = first[ntri];
    if (npairs == 0) {
        st = hv__error(HV_ERR_INVALID_ARG, "sdf: no part of the mesh lies inside the grid block");
        goto out;
    }
    if (!(pairs = hv_malloc(npairs * sizeof *pairs)) || !(tmp = hv_malloc(npairs * sizeof *tmp)))
        goto nomem;
#pragma omp parallel for schedule(static)
    for (size_t t = 0; t < ntri; t++) {
        int lo[3], hi[3];
        if (!tri_tiles(M, t, n, h, origin, W, nt, lo, hi))
            continue;
        size_t at = first[t];
        for (int z = lo[2]; z <= hi[2]; z++)
            for (int y = lo[1]; y <= hi[1]; y++)
                for (int x = lo[0]; x <= hi[0]; x++) {
                    pairs[at++] = TKEY(x, y, z) << 32 | (uint64_t)t;
                }
    }
    hv_free(first);
    first = NULL;
    if (!sort_by_tile(pairs, tmp, npairs))
        qsort(pairs, npairs, sizeof *pairs, cmp_hi32);
    hv_free(tmp);
    tmp = NULL;
    size_t ntiles = 0;
    for (size_t i = 0; i < npairs; i++)
        ntiles += i == 0 || pairs[i] >> 32 != pairs[i - 1] >> 32;
    if ((st = hv__progress(0.3, "tiles")))
        goto out;

    /* Memory: the tiles, and the .vdb writer's copy of them. */
    {
        double need = (double)ntiles * 2 * (T3 * sizeof(float) + 8 * sizeof(uint64_t) + 12) +
                      (double)npairs * 8;
        int dims[3] = {(int)(need / 1048576.0) + 1, 1, 1};
        if (need > 1e18 || (st = hv_check_dims(3, dims, 1.0, 1048576))) {
            hv_clear_error();
            st = hv__error(HV_ERR_NOMEM,
                           "sdf: a block of %d x %d x %d cells: its narrow band needs about "
                           "%.3g GB, more than this machine's %.3g GB",
                           n[0], n[1], n[2], need / 1e9, hv__physical_memory() / 1e9);
            goto out;
        }
    }
    if (!(tstart = hv_malloc((ntiles + 1) * sizeof *tstart)) || !(T = calloc(1, sizeof *T)) ||
        !(T->ijk = hv_malloc(3 * ntiles * sizeof *T->ijk)) ||
        !(T->v = hv_malloc((size_t)T3 * ntiles * sizeof *T->v)) ||
        !(T->on = hv_calloc(8 * ntiles, sizeof *T->on)) || !(keep = hv_calloc(ntiles, 1)))
        goto nomem;
    for (size_t i = 0, k = 0; i < npairs; i++)
        if (i == 0 || pairs[i] >> 32 != pairs[i - 1] >> 32)
            tstart[k++] = i;
    tstart[ntiles] = npairs;
    for (int a = 0; a < 3; a++) {
        T->n[a] = n[a];
        T->origin[a] = origin[a];
    }
    T->h = h;
    if (!unsig) {
        if ((st = hv__pseudo_build(M, &ps)))
            goto out;
        have_ps = 1;
    }

    /* 2-3. Raster and sign, tile by tile. */
    const float hf = (float)h, dlim = (float)(near_sign * h);
    const int closed = !unsig && ps.balanced;
#define CENTRE(p, i, j, k)                                                                         \
    do {                                                                                           \
        (p)[0] = origin[0] + (blo[0] + (i) + 0.5) * h;                                             \
        (p)[1] = origin[1] + (blo[1] + (j) + 0.5) * h;                                             \
        (p)[2] = origin[2] + (blo[2] + (k) + 0.5) * h;                                             \
    } while (0)
    size_t band_cells = 0, active = 0, evals = 0, used = 0;
    double ts = 0;
    /* Groups: runs of tiles with one 16^3 group (tile key >> 3). */
    size_t ngroups = 0;
    for (size_t q = 0; q < ntiles; q++)
        ngroups += q == 0 || pairs[tstart[q]] >> 35 != pairs[tstart[q - 1]] >> 35;
    if (!(gstart = hv_malloc((ngroups + 1) * sizeof *gstart)))
        goto nomem;
    for (size_t q = 0, g = 0; q < ntiles; q++)
        if (q == 0 || pairs[tstart[q]] >> 35 != pairs[tstart[q - 1]] >> 35)
            gstart[g++] = q;
    gstart[ngroups] = ntiles;
    int failed = 0;
    /* Progress from the first thread alone, which also notes a cancel; the
     * groups after it are skipped. */
    _Atomic size_t groups_done = 0;
    _Atomic int cancelled = 0;
    hv__progress_span(0.3, 0.9);
#pragma omp parallel for schedule(dynamic, 1) reduction(+ : band_cells, active, evals, used, ts, failed)
    for (size_t gq = 0; gq < ngroups; gq++) {
        size_t done = atomic_fetch_add(&groups_done, 1);
        if (atomic_load(&cancelled))
            continue;
        if (omp_get_thread_num() == 0 && done % 64 == 0 &&
            hv__progress_part((double)done / ngroups, "tiles"))
            atomic_store(&cancelled, 1);
        /* The group's triangles, each once, rasterized into its 16^3 box:
         * fewer (box, triangle) pairs than tile by tile, the same minima. */
        const size_t p0 = tstart[gstart[gq]], p1 = tstart[gstart[gq + 1]];
        uint32_t *tl = malloc((p1 - p0) * sizeof *tl);
        uint64_t *big = malloc(8 * T3 * sizeof *big);
        if (!tl || !big) {
            free(tl);
            free(big);
            failed++;
            continue;
        }
        for (size_t i = p0; i < p1; i++)
            tl[i - p0] = (uint32_t)pairs[i];
        qsort(tl, p1 - p0, sizeof *tl, cmp_u32);
        size_t nu = 0;
        for (size_t i = 0; i < p1 - p0; i++)
            if (i == 0 || tl[i] != tl[i - 1])
                tl[nu++] = tl[i];
        const uint64_t gkey = pairs[p0] >> 35;
        const int gc[3] = {(int)(gkey % (uint64_t)nb[0]),
                           (int)(gkey / (uint64_t)nb[0] % (uint64_t)nb[1]),
                           (int)(gkey / (uint64_t)nb[0] / (uint64_t)nb[1])};
        int glo[3], ghi[3];
        for (int a = 0; a < 3; a++) {
            glo[a] = gc[a] * 2 * HV_TILE;
            ghi[a] = glo[a] + 2 * HV_TILE - 1 < n[a] - 1 ? glo[a] + 2 * HV_TILE - 1 : n[a] - 1;
        }
        const int gx = ghi[0] - glo[0] + 1, gy = ghi[1] - glo[1] + 1;
        memset(big, 0xff, 8 * T3 * sizeof *big);
        for (size_t i = 0; i < nu; i++)
            hv__exact_raster_tile(M, origin, h, glo, ghi, tl[i], W, big);
        free(tl);
        for (size_t q = gstart[gq]; q < gstart[gq + 1]; q++) {
            uint64_t best[T3];
            const uint64_t key = pairs[tstart[q]] >> 32;
            const int oc = (int)(key & 7);
            const int tc[3] = {2 * gc[0] + (oc & 1), 2 * gc[1] + (oc >> 1 & 1),
                               2 * gc[2] + (oc >> 2)};
            int blo[3], bhi[3];
            for (int a = 0; a < 3; a++) {
                blo[a] = tc[a] * HV_TILE;
                bhi[a] = blo[a] + HV_TILE - 1 < n[a] - 1 ? blo[a] + HV_TILE - 1 : n[a] - 1;
                T->ijk[3 * q + a] = blo[a];
            }
            const int ex = bhi[0] - blo[0] + 1, ey = bhi[1] - blo[1] + 1, ez = bhi[2] - blo[2] + 1;
            for (int k = 0; k < ez; k++)
                for (int j = 0; j < ey; j++)
                    for (int i = 0; i < ex; i++)
                        best[i + ex * (j + ey * k)] =
                            big[(blo[0] - glo[0] + i) +
                                (size_t)gx *
                                    ((blo[1] - glo[1] + j) + (size_t)gy * (blo[2] - glo[2] + k))];
            float *v = T->v + (size_t)T3 * q;
            uint64_t *on = T->on + 8 * q;
            double t0 = hv_now();
            int any = 0;
            float d[T3];
            int8_t sg[T3];
            int todo = 0;
            for (int k = 0; k < HV_TILE; k++)
                for (int j = 0; j < HV_TILE; j++)
                    for (int i = 0; i < HV_TILE; i++) {
                        const int o = i + HV_TILE * (j + HV_TILE * k);
                        v[o] = bg;
                        d[o] = INFINITY;
                        sg[o] = 0;
                        if (i >= ex || j >= ey || k >= ez)
                            continue;
                        const uint64_t b = best[i + ex * (j + ey * k)];
                        if (b == UINT64_MAX)
                            continue;
                        band_cells++;
                        uint32_t bits = (uint32_t)(b >> 32);
                        memcpy(&d[o], &bits, sizeof d[o]);
                        best[i + ex * (j + ey * k)] = (uint64_t)(uint32_t)b; /* the triangle */
                        if (unsig || !(d[o] < hf)) {
                            todo += !unsig && d[o] < bg;
                            continue;
                        }
                        /* Within a voxel: the clean nearest feature's pseudonormal
                     * (within near_sign voxels), else the winding number. */
                        double p[3];
                        CENTRE(p, i, j, k);
                        int s = d[o] < dlim ? hv__pseudo_sign(&ps, M, (uint32_t)b, p, 0) : 0;
                        if (s)
                            used++;
                        else
                            s = hv__wn_sure(&ps.W, p, &evals) > 0.5 ? -1 : 1;
                        sg[o] = (int8_t)s;
                    }
            /* Beyond a voxel. With a closed mesh the winding number only changes
         * across the surface, and no surface passes between two neighbours
         * of which one is a voxel or more from it: its sign floods in from
         * the neighbours, with one evaluation per part of the tile it does
         * not reach. An open mesh's winding number also crosses 1/2 in free
         * space (across openings): one evaluation per cell. */
            while (todo > 0) {
                int changed = 1;
                while (closed && changed) {
                    changed = 0;
                    for (int o = 0; o < T3; o++) {
                        if (sg[o] || !(d[o] < INFINITY))
                            continue;
                        const int i = o % HV_TILE, j = o / HV_TILE % HV_TILE,
                                  k = o / (HV_TILE * HV_TILE);
                        int s = i > 0 ? sg[o - 1] : 0;
                        s = !s && i < HV_TILE - 1 ? sg[o + 1] : s;
                        s = !s && j > 0 ? sg[o - HV_TILE] : s;
                        s = !s && j < HV_TILE - 1 ? sg[o + HV_TILE] : s;
                        s = !s && k > 0 ? sg[o - HV_TILE * HV_TILE] : s;
                        s = !s && k < HV_TILE - 1 ? sg[o + HV_TILE * HV_TILE] : s;
                        if (s) {
                            sg[o] = (int8_t)s;
                            changed = 1;
                            todo -= d[o] < bg;
                        }
                    }
                }
                for (int o = 0; o < T3 && todo > 0; o++) {
                    if (sg[o] || !(d[o] < bg))
                        continue;
                    double p[3];
                    CENTRE(p, o % HV_TILE, o / HV_TILE % HV_TILE, o / (HV_TILE * HV_TILE));
                    sg[o] = hv__wn_sure(&ps.W, p, &evals) > 0.5 ? -1 : 1;
                    todo--;
                    if (closed)
                        break;
                }
            }
            for (int o = 0; o < T3; o++) {
                if (!(d[o] < bg))
                    continue;
                v[o] = sg[o] < 0 ? -d[o] : d[o];
                on[o / (HV_TILE * HV_TILE)] |= (uint64_t)1 << (o % (HV_TILE * HV_TILE));
                active++;
                any = 1;
            }
            ts += hv_now() - t0;
            keep[q] = (uint8_t)any;
        }
        free(big);
    }
    if (failed)
        goto nomem;
    if ((st = hv__progress(0.9, "tiles")))
        goto out;
    /* A cancel inside the loop is the callback's answer again here. */

    /* 4. Compact in place, in tile order. */
    size_t kept = 0;
    for (size_t q = 0; q < ntiles; q++) {
        if (!keep[q])
            continue;
        if (kept != q) {
            memcpy(T->ijk + 3 * kept, T->ijk + 3 * q, 3 * sizeof *T->ijk);
            memcpy(T->v + (size_t)T3 * kept, T->v + (size_t)T3 * q, T3 * sizeof *T->v);
            memcpy(T->on + 8 * kept, T->on + 8 * q, 8 * sizeof *T->on);
        }
        kept++;
    }
    if (kept == 0) {
        st = hv__error(HV_ERR_INVALID_ARG,
                       "sdf: no part of the mesh's narrow band lies inside the grid block");
        goto out;
    }
    T->count = kept;
    T->active = active;
    S->tiles = kept;
    S->active_voxels = active;
    S->band_cells = band_cells;
    S->winding_evals = evals;
    S->near_sign_cells = used;
    S->t_sign = ts / (hv_get_threads() > 0 ? hv_get_threads() : 1);
    *out = T;
    T = NULL;
    goto out;
nomem:
    st = hv__error(HV_ERR_NOMEM, "sdf: out of memory for the narrow band's tiles");
out:
    if (have_ps)
        hv__pseudo_free(&ps);
    hv_free(first);
    hv_free(pairs);
    hv_free(tmp);
    hv_free(tstart);
    hv_free(gstart);
    hv_free(keep);
    hv_tiles_destroy(&T);
    return st;
#undef CENTRE
#undef TKEY
}
