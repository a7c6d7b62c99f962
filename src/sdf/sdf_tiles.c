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
 * Steps 2-4 run on batches of groups in order, and each batch's tiles go to
 * a sink (hv_tiles_sink) as soon as it is done: the producer holds the pairs
 * and one batch, never the whole band. Tiles that no triangle comes near
 * enough for a voxel of the band (the tile's centre farther than the band
 * plus its half diagonal from all of its triangles) are neither rasterized
 * nor counted in the bound the sink is given.
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
 * are refused with that figure, or as such where it fits. */
hv_status hv__sdf_band_fits(const hv_mesh *M, const int n[3], double h, int numbered)
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
    double need = tiles * (T3 * sizeof(float) + 8 * sizeof(uint64_t) + 12);
    if (numbered && need <= (double)hv__memory_limit(NULL))
        return HV_OK;
    if (need <= (double)hv__memory_limit(NULL))
        return hv__error(HV_ERR_NOMEM,
                         "sdf: a block of %d x %d x %d cells is more than a narrow band can "
                         "address (2.2e12 cells, about 13000^3)",
                         n[0], n[1], n[2]);
    char lim[96];
    return hv__error(HV_ERR_NOMEM,
                     "sdf: a block of %d x %d x %d cells: its narrow band alone needs at least "
                     "%.3g GB, more than %s",
                     n[0], n[1], n[2], need / 1e9, hv__memory_limit_text(lim, sizeof lim));
}

/* A tile's key: its 2x2x2 group of tiles (16^3 cells, rasterized together)
 * numbered along x, then y, then z, then its octant within the group. */
static uint64_t tile_key(const int nb[3], int x, int y, int z)
{
    return (((uint64_t)(x >> 1) +
             (uint64_t)nb[0] * ((uint64_t)(y >> 1) + (uint64_t)nb[1] * (uint64_t)(z >> 1)))
            << 3) |
           (uint64_t)((x & 1) | (y & 1) << 1 | (z & 1) << 2);
}

static hv_status tiles_nomem(void)
{
    return hv__error(HV_ERR_NOMEM, "sdf: out of memory for the narrow band's tiles");
}

/* A triangle's plane, to skip the tiles of its box that it cannot reach: a
 * tile whose centre is farther than R from the plane has no cell within W of
 * the triangle (R = W plus the half diagonal of the tile's cell centres), so
 * no raster of its group writes a cell for it. n = 0 (a degenerate
 * triangle) keeps every tile. */
typedef struct {
    double n[3], d, R;
} tri_plane;

static tri_plane plane_of(const hv_mesh *M, size_t t, double W, double h)
{
    const uint32_t *v = M->tris + 3 * t;
    const double *a = M->verts + 3 * (size_t)v[0], *b = M->verts + 3 * (size_t)v[1],
                 *c = M->verts + 3 * (size_t)v[2];
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]},
                 w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
    const double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    tri_plane p = {.R = W + (0.5 * sqrt(3.0) * (HV_TILE - 1) + 1e-3) * h};
    if (!(len > 0) || !isfinite(len))
        return p;
    for (int k = 0; k < 3; k++)
        p.n[k] = n[k] / len;
    p.d = p.n[0] * a[0] + p.n[1] * a[1] + p.n[2] * a[2];
    return p;
}

/* Whether tile (x, y, z) is within the plane's reach. */
static int plane_reaches(const tri_plane *p, const double origin[3], double h, int x, int y, int z)
{
    const double c[3] = {origin[0] + (x + 0.5) * HV_TILE * h, origin[1] + (y + 0.5) * HV_TILE * h,
                         origin[2] + (z + 0.5) * HV_TILE * h};
    return fabs(p->n[0] * c[0] + p->n[1] * c[1] + p->n[2] * c[2] - p->d) <= p->R;
}

/* The tiles of triangle t's box [lo, hi] that its plane reaches, into keys
 * (when not NULL); returns how many. */
static size_t tri_keys(const hv_mesh *M, size_t t, const double origin[3], double h, double W,
                       const int nb[3], const int lo[3], const int hi[3], uint64_t *keys)
{
    const tri_plane p = plane_of(M, t, W, h);
    size_t k = 0;
    for (int z = lo[2]; z <= hi[2]; z++)
        for (int y = lo[1]; y <= hi[1]; y++)
            for (int x = lo[0]; x <= hi[0]; x++) {
                if (!plane_reaches(&p, origin, h, x, y, z))
                    continue;
                if (keys)
                    keys[k] = tile_key(nb, x, y, z) << 32 | (uint64_t)t;
                k++;
            }
    return k;
}

/* 1. Bin: every (tile << 32 | triangle) pair, counted first, then filled,
 * sorted by tile. *pairs_out is new; NULL on failure. */
static hv_status bin_triangles(const hv_mesh *M, const int n[3], double h, const double origin[3],
                               double W, const int nt[3], const int nb[3], uint64_t **pairs_out,
                               size_t *npairs_out)
{
    const size_t ntri = M->ntris;
    size_t *first = hv_malloc((ntri + 1) * sizeof *first);
    uint64_t *pairs = NULL, *tmp = NULL;
    hv_status st = HV_OK;
    *pairs_out = NULL;
    if (!first)
        goto nomem;
    first[0] = 0;
#pragma omp parallel for schedule(static)
    for (size_t t = 0; t < ntri; t++) {
        int lo[3], hi[3];
        first[t + 1] = tri_tiles(M, t, n, h, origin, W, nt, lo, hi)
                           ? tri_keys(M, t, origin, h, W, nb, lo, hi, NULL)
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
        if (tri_tiles(M, t, n, h, origin, W, nt, lo, hi))
            tri_keys(M, t, origin, h, W, nb, lo, hi, pairs + first[t]);
    }
    /* The counts go before the sort, which holds the pairs twice. */
    hv_free(first);
    first = NULL;
    if (!sort_by_tile(pairs, tmp, npairs))
        qsort(pairs, npairs, sizeof *pairs, cmp_hi32);
    *pairs_out = pairs;
    *npairs_out = npairs;
    pairs = NULL;
    goto out;
nomem:
    st = tiles_nomem();
out:
    hv_free(first);
    hv_free(pairs);
    hv_free(tmp);
    return st;
}

/* The producer's own memory: the pairs (twice while sorted), the tiles'
 * starts and one batch of tiles. */
static hv_status band_memory(size_t ntiles, size_t npairs, size_t batch, const int n[3])
{
    double need = (double)npairs * 16 + (double)ntiles * (sizeof(size_t) + 1) +
                  (double)batch * (T3 * sizeof(float) + 8 * sizeof(uint64_t) + 13);
    char lim[96];
    if (need > 1e18 || need > (double)hv__memory_limit(NULL))
        return hv__error(HV_ERR_NOMEM,
                         "sdf: a block of %d x %d x %d cells: its narrow band's triangle lists "
                         "need about %.3g GB, more than %s",
                         n[0], n[1], n[2], need / 1e9, hv__memory_limit_text(lim, sizeof lim));
    return HV_OK;
}

/* The tiles of the sorted pairs: runs of one tile key (the high 32 bits).
 * Where start is not NULL, each run's first pair into it, and npairs after
 * the last. Returns how many. */
static size_t tile_runs(const uint64_t *pairs, size_t npairs, size_t *start)
{
    size_t k = 0;
    for (size_t i = 0; i < npairs; i++)
        if (i == 0 || pairs[i] >> 32 != pairs[i - 1] >> 32) {
            if (start)
                start[k] = i;
            k++;
        }
    if (start)
        start[k] = npairs;
    return k;
}

/* The groups: runs of tiles with one 16^3 group (tile key >> 3). *gstart
 * (each group's first tile, and ntiles after the last) is new; 0 when out of
 * memory. */
static int group_runs(const uint64_t *pairs, const size_t *tstart, size_t ntiles, size_t **gstart,
                      size_t *ngroups)
{
    size_t ng = 0;
    for (size_t q = 0; q < ntiles; q++)
        ng += q == 0 || pairs[tstart[q]] >> 35 != pairs[tstart[q - 1]] >> 35;
    size_t *gs = hv_malloc((ng + 1) * sizeof *gs);
    if (!gs)
        return 0;
    for (size_t q = 0, g = 0; q < ntiles; q++)
        if (q == 0 || pairs[tstart[q]] >> 35 != pairs[tstart[q - 1]] >> 35)
            gs[g++] = q;
    gs[ng] = ntiles;
    *gstart = gs;
    *ngroups = ng;
    return 1;
}

/* ntiles tiles on the block (n, h, origin), no voxel active; NULL when out
 * of memory. */
hv_tiles *hv__tiles_alloc(const int n[3], double h, const double origin[3], size_t ntiles)
{
    hv_tiles *T = calloc(1, sizeof *T);
    if (!T || !(T->ijk = hv_malloc(3 * ntiles * sizeof *T->ijk)) ||
        !(T->v = hv_malloc((size_t)T3 * ntiles * sizeof *T->v)) ||
        !(T->on = hv_calloc(8 * ntiles, sizeof *T->on))) {
        hv_tiles_destroy(&T);
        return NULL;
    }
    for (int a = 0; a < 3; a++) {
        T->n[a] = n[a];
        T->origin[a] = origin[a];
    }
    T->h = h;
    return T;
}

static hv_status collect_begin(void *user, const hv_tiles *block, size_t max_tiles)
{
    hv__tiles_collect *c = user;
    const double need = (double)max_tiles * (T3 * sizeof(float) + 8 * sizeof(uint64_t) + 12);
    char lim[96];
    if (need > (double)hv__memory_limit(NULL))
        return hv__error(HV_ERR_NOMEM,
                         "sdf: a block of %d x %d x %d cells: its narrow band of up to %zu tiles "
                         "needs about %.3g GB, more than %s",
                         block->n[0], block->n[1], block->n[2], max_tiles, need / 1e9,
                         hv__memory_limit_text(lim, sizeof lim));
    if (!(c->T = hv__tiles_alloc(block->n, block->h, block->origin, max_tiles ? max_tiles : 1)))
        return tiles_nomem();
    return HV_OK;
}

static hv_status collect_put(void *user, const hv_tiles *b)
{
    hv_tiles *T = ((hv__tiles_collect *)user)->T;
    memcpy(T->ijk + 3 * T->count, b->ijk, 3 * b->count * sizeof *b->ijk);
    memcpy(T->v + (size_t)T3 * T->count, b->v, (size_t)T3 * b->count * sizeof *b->v);
    memcpy(T->on + 8 * T->count, b->on, 8 * b->count * sizeof *b->on);
    T->count += b->count;
    T->active += b->active;
    return HV_OK;
}

/* The arrays keep the bound's length: what lies beyond the tiles that came
 * was never written, so it holds no memory but its address space (and the
 * active bits, 64 bytes a tile). */
static hv_status collect_end(void *user, int ok)
{
    hv__tiles_collect *c = user;
    if (!ok)
        hv_tiles_destroy(&c->T);
    return HV_OK;
}

hv_tiles_sink hv__tiles_collector(hv__tiles_collect *c)
{
    c->T = NULL;
    return (hv_tiles_sink){c, collect_begin, collect_put, collect_end};
}

/* What the threads read while they rasterize and sign the groups of tiles. */
typedef struct {
    const hv_mesh *M;
    hv_pseudo *ps; /* the pseudonormals and winding numbers; unset when unsig */
    const int *n, *nb;
    const double *origin;
    double h, W;                   /* voxel; the raster's reach */
    float hf, dlim, bg;            /* voxel; pseudonormals' reach; band, the value off it */
    int unsig, closed;             /* closed: the sign floods between neighbours */
    const uint64_t *pairs;         /* (tile << 32 | triangle), sorted */
    const size_t *tstart, *gstart; /* each tile's first pair, each group's first tile */
    const uint8_t *near;           /* per tile: whether a triangle comes near enough */
    hv_tiles *T;                   /* the batch: tile q is T's q - q0 */
    size_t q0;
    uint8_t *keep; /* per tile of the batch: whether it holds an active voxel */
} band_ctx;

/* A thread's sums over its tiles. */
typedef struct {
    size_t band_cells, active, evals, used;
    double ts;
} band_counts;

/* The world position of cell (i, j, k) of the tile whose first cell is blo. */
static void cell_centre(const band_ctx *c, const int blo[3], int i, int j, int k, double p[3])
{
    p[0] = c->origin[0] + (blo[0] + i + 0.5) * c->h;
    p[1] = c->origin[1] + (blo[1] + j + 0.5) * c->h;
    p[2] = c->origin[2] + (blo[2] + k + 0.5) * c->h;
}

/* The distinct triangles of a group's np pairs, sorted, into tl; returns how
 * many. */
static size_t group_triangles(const uint64_t *pairs, size_t np, uint32_t *tl)
{
    for (size_t i = 0; i < np; i++)
        tl[i] = (uint32_t)pairs[i];
    qsort(tl, np, sizeof *tl, cmp_u32);
    size_t nu = 0;
    for (size_t i = 0; i < np; i++)
        if (i == 0 || tl[i] != tl[i - 1])
            tl[nu++] = tl[i];
    return nu;
}

/* Tile q of group gc (rasterized into big over glo..ghi): its first cell blo
 * (also into T->ijk), its extent ext within the block, and its cells'
 * (distance << 32 | triangle) minima from big into best (ext[0] x ext[1] x
 * ext[2]). */
static void tile_nearest(const band_ctx *c, size_t q, const int gc[3], const int glo[3],
                         const int ghi[3], const uint64_t *big, int blo[3], int ext[3],
                         uint64_t *best)
{
    const uint64_t key = c->pairs[c->tstart[q]] >> 32;
    const int oc = (int)(key & 7);
    const int tc[3] = {2 * gc[0] + (oc & 1), 2 * gc[1] + (oc >> 1 & 1), 2 * gc[2] + (oc >> 2)};
    int bhi[3];
    for (int a = 0; a < 3; a++) {
        blo[a] = tc[a] * HV_TILE;
        bhi[a] = blo[a] + HV_TILE - 1 < c->n[a] - 1 ? blo[a] + HV_TILE - 1 : c->n[a] - 1;
        c->T->ijk[3 * (q - c->q0) + a] = blo[a];
    }
    const int ex = bhi[0] - blo[0] + 1, ey = bhi[1] - blo[1] + 1, ez = bhi[2] - blo[2] + 1;
    ext[0] = ex;
    ext[1] = ey;
    ext[2] = ez;
    const int gx = ghi[0] - glo[0] + 1, gy = ghi[1] - glo[1] + 1;
    for (int k = 0; k < ez; k++)
        for (int j = 0; j < ey; j++)
            for (int i = 0; i < ex; i++)
                best[i + ex * (j + ey * k)] =
                    big[(blo[0] - glo[0] + i) +
                        (size_t)gx * ((blo[1] - glo[1] + j) + (size_t)gy * (blo[2] - glo[2] + k))];
}

/* The tile's cells: v the band's edge, d the distance where the raster
 * reached (INFINITY elsewhere), and the sign sg of those within a voxel: the
 * clean nearest feature's pseudonormal (within near_sign voxels), else the
 * winding number (0: not yet signed). Returns the cells in the band left
 * unsigned. */
static int sign_near(const band_ctx *c, const int blo[3], const int ext[3], uint64_t *best,
                     float *v, float *d, int8_t *sg, band_counts *cnt)
{
    const int ex = ext[0], ey = ext[1], ez = ext[2];
    int todo = 0;
    for (int k = 0; k < HV_TILE; k++)
        for (int j = 0; j < HV_TILE; j++)
            for (int i = 0; i < HV_TILE; i++) {
                const int o = i + HV_TILE * (j + HV_TILE * k);
                v[o] = c->bg;
                d[o] = INFINITY;
                sg[o] = 0;
                if (i >= ex || j >= ey || k >= ez)
                    continue;
                const uint64_t b = best[i + ex * (j + ey * k)];
                if (b == UINT64_MAX)
                    continue;
                cnt->band_cells++;
                uint32_t bits = (uint32_t)(b >> 32);
                memcpy(&d[o], &bits, sizeof d[o]);
                best[i + ex * (j + ey * k)] = (uint64_t)(uint32_t)b; /* the triangle */
                if (c->unsig || !(d[o] < c->hf)) {
                    todo += !c->unsig && d[o] < c->bg;
                    continue;
                }
                double p[3];
                cell_centre(c, blo, i, j, k, p);
                int s = d[o] < c->dlim ? hv__pseudo_sign(c->ps, c->M, (uint32_t)b, p, 0) : 0;
                if (s)
                    cnt->used++;
                else
                    s = hv__wn_sure(&c->ps->W, p, &cnt->evals) > 0.5 ? -1 : 1;
                sg[o] = (int8_t)s;
            }
    return todo;
}

/* Unsigned cells of the raster's reach take a signed neighbour's sign, until
 * none does. Returns todo less the cells of the band so signed. */
static int flood_signs(const float *d, int8_t *sg, float bg, int todo)
{
    int changed = 1;
    while (changed) {
        changed = 0;
        for (int o = 0; o < T3; o++) {
            if (sg[o] || !(d[o] < INFINITY))
                continue;
            const int i = o % HV_TILE, j = o / HV_TILE % HV_TILE, k = o / (HV_TILE * HV_TILE);
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
    return todo;
}

/* Beyond a voxel. With a closed mesh the winding number only changes across
 * the surface, and no surface passes between two neighbours of which one is a
 * voxel or more from it: its sign floods in from the neighbours, with one
 * evaluation per part of the tile it does not reach. An open mesh's winding
 * number also crosses 1/2 in free space (across openings): one evaluation per
 * cell. */
static void sign_far(const band_ctx *c, const int blo[3], const float *d, int8_t *sg, int todo,
                     size_t *evals)
{
    while (todo > 0) {
        if (c->closed)
            todo = flood_signs(d, sg, c->bg, todo);
        for (int o = 0; o < T3 && todo > 0; o++) {
            if (sg[o] || !(d[o] < c->bg))
                continue;
            double p[3];
            cell_centre(c, blo, o % HV_TILE, o / HV_TILE % HV_TILE, o / (HV_TILE * HV_TILE), p);
            sg[o] = hv__wn_sure(&c->ps->W, p, evals) > 0.5 ? -1 : 1;
            todo--;
            if (c->closed)
                break;
        }
    }
}

/* The band's signed distances into v and their bits into on. Returns
 * whether the tile has any. */
static int write_band(float bg, const float *d, const int8_t *sg, float *v, uint64_t *on,
                      size_t *active)
{
    int any = 0;
    for (int o = 0; o < T3; o++) {
        if (!(d[o] < bg))
            continue;
        v[o] = sg[o] < 0 ? -d[o] : d[o];
        on[o / (HV_TILE * HV_TILE)] |= (uint64_t)1 << (o % (HV_TILE * HV_TILE));
        (*active)++;
        any = 1;
    }
    return any;
}

/* 2-3. Tile q of a group rasterized into big: its values, active voxels and
 * keep[q]. */
static void sign_tile(const band_ctx *c, size_t q, const int gc[3], const int glo[3],
                      const int ghi[3], const uint64_t *big, band_counts *cnt)
{
    uint64_t best[T3];
    int blo[3], ext[3];
    if (!c->near[q])
        return;
    tile_nearest(c, q, gc, glo, ghi, big, blo, ext, best);
    const size_t b = q - c->q0;
    float *v = c->T->v + (size_t)T3 * b;
    uint64_t *on = c->T->on + 8 * b;
    double t0 = hv_now();
    float d[T3];
    int8_t sg[T3];
    int todo = sign_near(c, blo, ext, best, v, d, sg, cnt);
    sign_far(c, blo, d, sg, todo, &cnt->evals);
    int any = write_band(c->bg, d, sg, v, on, &cnt->active);
    cnt->ts += hv_now() - t0;
    c->keep[b] = (uint8_t)any;
}

/* 2-3. Group gq: its triangles, each once, rasterized into its 16^3 box
 * (fewer (box, triangle) pairs than tile by tile, the same minima), then its
 * tiles signed. 0 when out of memory. */
static int sign_group(const band_ctx *c, size_t gq, band_counts *cnt)
{
    int any = 0;
    for (size_t q = c->gstart[gq]; q < c->gstart[gq + 1]; q++)
        any |= c->near[q];
    if (!any)
        return 1;
    const size_t p0 = c->tstart[c->gstart[gq]], p1 = c->tstart[c->gstart[gq + 1]];
    uint32_t *tl = malloc((p1 - p0) * sizeof *tl);
    uint64_t *big = malloc(8 * T3 * sizeof *big);
    if (!tl || !big) {
        free(tl);
        free(big);
        return 0;
    }
    const size_t nu = group_triangles(c->pairs + p0, p1 - p0, tl);
    const uint64_t gkey = c->pairs[p0] >> 35;
    const uint64_t nb0 = (uint64_t)c->nb[0], nb1 = (uint64_t)c->nb[1];
    const int gc[3] = {(int)(gkey % nb0), (int)(gkey / nb0 % nb1), (int)(gkey / nb0 / nb1)};
    int glo[3], ghi[3];
    for (int a = 0; a < 3; a++) {
        glo[a] = gc[a] * 2 * HV_TILE;
        ghi[a] = glo[a] + 2 * HV_TILE - 1 < c->n[a] - 1 ? glo[a] + 2 * HV_TILE - 1 : c->n[a] - 1;
    }
    memset(big, 0xff, 8 * T3 * sizeof *big);
    for (size_t i = 0; i < nu; i++)
        hv__exact_raster_tile(c->M, c->origin, c->h, glo, ghi, tl[i], c->W, big);
    free(tl);
    for (size_t q = c->gstart[gq]; q < c->gstart[gq + 1]; q++)
        sign_tile(c, q, gc, glo, ghi, big, cnt);
    free(big);
    return 1;
}

/* 2-3. Groups g0..g1 of ngroups, in parallel; the sums added to *sum.
 * Returns how many groups ran out of memory; *cancelled when the progress
 * callback asked to stop (the groups after it are skipped). */
static int sign_groups(const band_ctx *c, size_t g0, size_t g1, size_t ngroups, band_counts *sum,
                       int *cancelled)
{
    size_t band_cells = sum->band_cells, active = sum->active, evals = sum->evals, used = sum->used;
    double ts = sum->ts;
    int failed = 0;
    /* Progress from the first thread alone, which also notes a cancel. */
    _Atomic int stop = 0;
#pragma omp parallel for schedule(dynamic, 1) reduction(+ : band_cells, active, evals, used, ts, failed)
    for (size_t gq = g0; gq < g1; gq++) {
        if (atomic_load(&stop))
            continue;
        if (omp_get_thread_num() == 0 && gq % 64 == 0 &&
            hv__progress_part((double)gq / ngroups, "tiles"))
            atomic_store(&stop, 1);
        /* The thread's own sums go through cnt and back: they add up tile by
         * tile, as one running sum per thread. */
        band_counts cnt = {band_cells, active, evals, used, ts};
        failed += !sign_group(c, gq, &cnt);
        band_cells = cnt.band_cells;
        active = cnt.active;
        evals = cnt.evals;
        used = cnt.used;
        ts = cnt.ts;
    }
    *sum = (band_counts){band_cells, active, evals, used, ts};
    *cancelled = atomic_load(&stop);
    return failed;
}

/* 4. The tiles with an active voxel moved to the front, in tile order.
 * Returns how many. */
static size_t compact_tiles(hv_tiles *T, const uint8_t *keep, size_t ntiles)
{
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
    return kept;
}

static void band_stats(hv_sdf_stats *S, size_t kept, const band_counts *sum)
{
    S->tiles = kept;
    S->active_voxels = sum->active;
    S->band_cells = sum->band_cells;
    S->winding_evals = sum->evals;
    S->near_sign_cells = sum->used;
    S->t_sign = sum->ts / (hv_get_threads() > 0 ? hv_get_threads() : 1);
}

/* Whether a voxel of tile q can lie within the band: the distance from the
 * tile's centre to its nearest triangle at most the band plus the half
 * diagonal of the tile's cell centres (with a margin for rounding). */
static int tile_near(const band_ctx *c, size_t q)
{
    const uint64_t key = c->pairs[c->tstart[q]] >> 32;
    const uint64_t gk = key >> 3, nb0 = (uint64_t)c->nb[0], nb1 = (uint64_t)c->nb[1];
    const int oc = (int)(key & 7);
    const int tc[3] = {2 * (int)(gk % nb0) + (oc & 1), 2 * (int)(gk / nb0 % nb1) + (oc >> 1 & 1),
                       2 * (int)(gk / nb0 / nb1) + (oc >> 2)};
    double p[3];
    for (int a = 0; a < 3; a++)
        p[a] = c->origin[a] + (tc[a] * HV_TILE + 0.5 * HV_TILE) * c->h;
    const double r = c->bg + (0.5 * sqrt(3.0) * (HV_TILE - 1) + 1e-3) * c->h, r2 = r * r;
    for (size_t i = c->tstart[q]; i < c->tstart[q + 1]; i++) {
        const uint32_t *v = c->M->tris + 3 * (size_t)(uint32_t)c->pairs[i];
        double x[3];
        int region;
        if (hv_closest(p, c->M->verts + 3 * (size_t)v[0], c->M->verts + 3 * (size_t)v[1],
                       c->M->verts + 3 * (size_t)v[2], x, &region) <= r2)
            return 1;
    }
    return 0;
}

/* 1b. near[q] for every tile; returns how many are near. */
static size_t near_tiles(const band_ctx *c, size_t ntiles, uint8_t *near)
{
    size_t count = 0;
#pragma omp parallel for schedule(dynamic, 256) reduction(+ : count)
    for (size_t q = 0; q < ntiles; q++) {
        near[q] = (uint8_t)tile_near(c, q);
        count += near[q];
    }
    return count;
}

/* The tiles a batch holds: HEATVOX_TILE_BATCH where set (a test's way to
 * cut a small band into many batches), else 16384 (34 MB). */
size_t hv__sdf_tile_batch(void)
{
    const char *e = getenv("HEATVOX_TILE_BATCH");
    long b = e ? strtol(e, NULL, 10) : 0;
    return b >= 1 ? (size_t)b : 16384;
}

/* 2-4. The groups in batches of whole groups, about `batch` tiles each:
 * each signed in parallel, its tiles with an active voxel put into the sink.
 * *kept counts them. */
static hv_status stream_batches(band_ctx *c, size_t ngroups, size_t batch, hv_tiles *B,
                                const hv_tiles_sink *sink, band_counts *sum, size_t *kept)
{
    hv_status st = HV_OK;
    *kept = 0;
    hv__progress_span(0.3, 0.9);
    for (size_t g0 = 0, g1; g0 < ngroups && !st; g0 = g1) {
        for (g1 = g0 + 1; g1 < ngroups && c->gstart[g1 + 1] - c->gstart[g0] <= batch; g1++)
            ;
        const size_t nt = c->gstart[g1] - c->gstart[g0];
        c->q0 = c->gstart[g0];
        memset(c->keep, 0, nt);
        memset(B->on, 0, 8 * nt * sizeof *B->on);
        const size_t active0 = sum->active;
        int cancelled = 0;
        if (sign_groups(c, g0, g1, ngroups, sum, &cancelled))
            return tiles_nomem();
        /* The groups after a cancel were skipped: the band stops here. */
        if (cancelled)
            return hv__error(HV_ERR_CANCELLED, "cancelled during tiles");
        B->count = compact_tiles(B, c->keep, nt);
        B->active = sum->active - active0;
        *kept += B->count;
        if (B->count)
            st = sink->put(sink->user, B);
    }
    return st;
}

/* The tiles' block, count 0. */
static hv_tiles block_of(const int n[3], double h, const double origin[3])
{
    hv_tiles b = {.h = h};
    for (int a = 0; a < 3; a++) {
        b.n[a] = n[a];
        b.origin[a] = origin[a];
    }
    return b;
}

hv_status hv__sdf_tiles(const hv_mesh *M, const int n[3], double h, const double origin[3],
                        double band, int unsig, double near_sign, const hv_tiles_sink *sink,
                        hv_sdf_stats *S)
{
    const int nt[3] = {(n[0] + HV_TILE - 1) / HV_TILE, (n[1] + HV_TILE - 1) / HV_TILE,
                       (n[2] + HV_TILE - 1) / HV_TILE};
    const int nb[3] = {(nt[0] + 1) / 2, (nt[1] + 1) / 2, (nt[2] + 1) / 2};
    hv_status st = hv__sdf_band_fits(M, n, h, 8.0 * nb[0] * nb[1] * nb[2] < 4294967295.0);
    if (st)
        return st;
    /* The raster's reach: the band, and at least the 2 voxels the dense
     * path rasterizes, so that both keep the same nearest triangles. */
    const double bandw = band * h, W = fmax(band, 2.0) * h;
    uint64_t *pairs = NULL;
    size_t *tstart = NULL, *gstart = NULL;
    hv_tiles *B = NULL;
    uint8_t *keep = NULL, *near = NULL;
    hv_pseudo ps;
    int have_ps = 0, begun = 0;
    size_t npairs = 0, ngroups = 0, kept = 0;
    if ((st = bin_triangles(M, n, h, origin, W, nt, nb, &pairs, &npairs)))
        goto out;
    const size_t ntiles = tile_runs(pairs, npairs, NULL);
    const size_t batch = hv__sdf_tile_batch();
    const size_t cap = (batch < ntiles ? batch : ntiles) + 7; /* whole groups of up to 8 */
    if ((st = hv__progress(0.3, "tiles")) || (st = band_memory(ntiles, npairs, cap, n)))
        goto out;
    if (!(tstart = hv_malloc((ntiles + 1) * sizeof *tstart)) || !(near = hv_malloc(ntiles)) ||
        !(B = hv__tiles_alloc(n, h, origin, cap)) || !(keep = hv_calloc(cap, 1)))
        goto nomem;
    tile_runs(pairs, npairs, tstart);
    if (!unsig) {
        if ((st = hv__pseudo_build(M, &ps)))
            goto out;
        have_ps = 1;
    }
    if (!group_runs(pairs, tstart, ntiles, &gstart, &ngroups))
        goto nomem;
    band_ctx c = {.M = M,
                  .ps = &ps,
                  .n = n,
                  .nb = nb,
                  .origin = origin,
                  .h = h,
                  .W = W,
                  .hf = (float)h,
                  .dlim = (float)(near_sign * h),
                  .bg = (float)bandw,
                  .unsig = unsig,
                  .closed = !unsig && ps.balanced,
                  .pairs = pairs,
                  .tstart = tstart,
                  .gstart = gstart,
                  .near = near,
                  .T = B,
                  .keep = keep};
    const hv_tiles blk = block_of(n, h, origin);
    begun = 1;
    band_counts sum = {0};
    S->tiles_bound = near_tiles(&c, ntiles, near);
    if ((st = sink->begin(sink->user, &blk, S->tiles_bound)) ||
        (st = stream_batches(&c, ngroups, batch, B, sink, &sum, &kept)) ||
        (st = hv__progress(0.9, "tiles")))
        goto out;
    if (kept == 0) {
        st = hv__error(HV_ERR_INVALID_ARG,
                       "sdf: no part of the mesh's narrow band lies inside the grid block");
        goto out;
    }
    band_stats(S, kept, &sum);
    S->tiles_in_flight = cap;
    goto out;
nomem:
    st = tiles_nomem();
out:
    if (have_ps)
        hv__pseudo_free(&ps);
    hv_free(pairs);
    hv_free(tstart);
    hv_free(gstart);
    hv_free(keep);
    hv_free(near);
    hv_tiles_destroy(&B);
    if (begun) {
        hv_status e = sink->end(sink->user, !st);
        st = st ? st : e;
    }
    return st;
}
