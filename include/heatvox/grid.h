/*
 * heatvox grids: regular, cell-centred, 2D or 3D, float storage.
 *
 * Sample (i,j,k) sits at origin + (i+1/2, j+1/2, k+1/2) * h, where origin is the
 * lower corner of the voxel block. x is fastest in memory:
 *     index = i + n[0] * (j + n[1] * k).
 * A 2D grid has dim = 2 and n[2] = 1. Walls are homogeneous Neumann.
 * An optional mask marks solid voxels (obstacles): solid[idx] != 0.
 */
#ifndef HEATVOX_GRID_H
#define HEATVOX_GRID_H

#include "core.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct hv_grid {
    int dim;          /* 2 or 3 */
    int n[3];         /* cells per axis; n[2] == 1 when dim == 2 */
    double h;         /* voxel size (world units) */
    double origin[3]; /* world position of the block's lower corner */
    float *v;         /* values, 64-byte aligned, owned by the grid */
    uint8_t *solid;   /* NULL, or one byte per cell (non-zero = solid), owned */
} hv_grid;

/* A sparse block: the 8^3 tiles of an hv_grid's block that hold data (a
 * narrow band), each at a multiple of HV_TILE cells, the rest of the block
 * implied (hv_sdf_compute_tiles). Each tile is listed once, in an order of
 * the producer's (hv_sdf_compute_tiles: by 2x2x2 groups). */
#define HV_TILE 8
typedef struct hv_tiles {
    int n[3];         /* the block, as an hv_grid's: cells per axis */
    double h;         /* voxel size */
    double origin[3]; /* world position of the block's lower corner */
    size_t count;     /* tiles */
    int32_t *ijk;     /* 3 * count: block index of each tile's first cell */
    float *v;         /* HV_TILE^3 * count: values, v[t * 512 + i + 8 j + 64 k] */
    uint64_t *on;     /* 8 * count: active voxels, bit i + 8 j of word k (cells beyond
                           the block are never active) */
    size_t active;    /* active voxels in all */
} hv_tiles;

/* A consumer of tiles handed over as they are finished (hv_sdf_stream_tiles),
 * so that a narrow band never has to be held whole by its producer:
 * - begin(user, block, max_tiles): block is the block (count 0, no arrays);
 *   at most max_tiles tiles will follow, in the producer's order.
 * - put(user, batch): the next tiles, each listed once across all batches;
 *   the batch's arrays are the producer's and reused after put returns.
 * - end(user, ok): called once per run, whatever begin and put returned and
 *   also when the run failed before begin; ok is 0 when the run failed (the
 *   sink drops what it took), 1 when every tile was put.
 * A non-zero status from begin or put stops the producer with that status. */
typedef struct hv_tiles_sink {
    void *user;
    hv_status (*begin)(void *user, const hv_tiles *block, size_t max_tiles);
    hv_status (*put)(void *user, const hv_tiles *batch);
    hv_status (*end)(void *user, int ok);
} hv_tiles_sink;

/* Frees the tiles and sets *t to NULL. Accepts NULL and *t == NULL. */
HV_API void hv_tiles_destroy(hv_tiles **t);

/* New tiles on like's block, with like's tiles in like's order, every value
 * `value` and no voxel active. HV_ERR_NOMEM when they do not fit. */
HV_API hv_status hv_tiles_create_like(hv_tiles **out, const hv_tiles *like, float value);

/* Allocates a zeroed grid. n[2] is ignored (taken as 1) when dim == 2.
 * origin may be NULL (zero). Fails with HV_ERR_INVALID_ARG for sizes <= 0 or
 * h <= 0, HV_ERR_NOMEM when the grid would not fit in memory.
 * The caller owns *out and frees it with hv_grid_destroy(). */
HV_API hv_status hv_grid_create(hv_grid **out, int dim, const int n[3], double h,
                                const double origin[3]);

/* Frees the grid and sets *g to NULL. Accepts NULL and *g == NULL. */
HV_API void hv_grid_destroy(hv_grid **g);

/* Allocates (zeroed) the solid mask if the grid has none. */
HV_API hv_status hv_grid_add_mask(hv_grid *g);

/* Number of cells n[0]*n[1]*n[2]. */
HV_API size_t hv_grid_count(const hv_grid *g);

/* World position of the centre of cell (i,j,k). */
HV_API void hv_grid_cell_center(const hv_grid *g, int i, int j, int k, double x[3]);

/* Checks sizes and voxel size; with bytes_per_cell, also that count*bytes
 * fits in memory and size_t. Used before any allocation sized by user input. */
HV_API hv_status hv_check_dims(int dim, const int n[3], double h, size_t bytes_per_cell);

/* HV_ERR_NUMERIC naming `what` and the first bad index if any value is NaN/Inf. */
HV_API hv_status hv_check_finite(const float *v, size_t count, const char *what);
HV_API hv_status hv_check_finite_d(const double *v, size_t count, const char *what);

/* Aligned allocation helpers (64 bytes); hv_free accepts NULL. */
HV_API void *hv_malloc(size_t bytes);
HV_API void *hv_calloc(size_t count, size_t size);
HV_API void hv_free(void *p);

#ifdef __cplusplus
}
#endif
#endif
