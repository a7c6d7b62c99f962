/* The signed distance pipeline's own pieces (sdf.c): the heat method's stages
 * (sdf_heat.c) and the winding-number sign (sign_winding.c), with the headers
 * of the parts they use. */
#ifndef HV_HEAT_SDF_INTERNAL_H
#define HV_HEAT_SDF_INTERNAL_H

#include "heatvox/sdf.h"
#include "geom/exact.h"
#include "geom/pseudonormal.h"
#include "geom/surface.h"

/* HV_ERR_NUMERIC for a vertex of m with a non-finite coordinate x: named by
 * the file's line (or its 1-based place among the file's vertices) when m
 * was read from a file, else by its 1-based index in m (repair.c). */
hv_status hv__nonfinite_vertex_error(const hv_mesh *m, const char *who, size_t v, double x);

/* Stages 2-6 of the signed heat method on gh (sdf_heat.c; on the device when
 * o->backend is HV_BACKEND_OPENCL): splat q, diffuse (nlev levels), normalize
 * on faces, Poisson, shift. phi in gh->v; times and counts into S. */
hv_status hv__sdf_heat(const hv_quad *q, hv_grid *gh, int nlev, int unsig, const hv_sdf_opts *o,
                       hv_sdf_stats *S);
/* The options' checks, the block for bounds lo, hi (cell counts, voxel
 * size, origin) and how many times coarser the heat method's grid is (sdf.c). */
hv_status hv__sdf_check_opts(const hv_sdf_opts *o);
hv_status hv__sdf_grid_place(const hv_sdf_opts *opts, const double lo[3], const double hi[3],
                             int n[3], double *h, double origin[3]);
int hv__sdf_heat_factor(const hv_sdf_opts *o, const int n[3]);

/* Morphology of the result (sdf_morph.c): whether o asks for any, its
 * checks, how far the shape may grow (world units; the block is placed
 * around the bounds grown by it) and how far bands must reach beyond the
 * output's band; the operations on a dense grid and on tiles (offset and
 * shell only; band: the output's band in voxels, whose voxels stay active). */
int hv__sdf_morph_on(const hv_sdf_opts *o);
hv_status hv__sdf_morph_check(const hv_sdf_opts *o);
double hv__sdf_morph_growth(const hv_sdf_opts *o);
double hv__sdf_morph_reach(const hv_sdf_opts *o);
hv_status hv__sdf_morph_grid(hv_grid *g, const hv_sdf_opts *o);
void hv__sdf_morph_tiles(hv_tiles *T, const hv_sdf_opts *o, double band);

/* Point clouds (points_bins.c). */
/* Points binned into cubic cells of side c, sorted by cell; a table with
 * open addressing maps a cell's key to its run of points. */
typedef struct pt_bins {
    double lo[3], c;
    uint32_t *order;       /* point indices, cell by cell */
    float *sx;             /* their coordinates in that order (x y z, float) */
    uint64_t *keys;        /* table: cell keys, UINT64_MAX where empty */
    uint32_t *start, *len; /* table: each cell's run in order */
    size_t mask;
} pt_bins;

/* The points of the cells at Chebyshev distance r from cell q, one by one:
 * hv__ring_first, then hv__ring_next until it returns 0. */
typedef struct ring_iter {
    long q[3], r, d[3];
    uint32_t s, len, m;
} ring_iter;

/* Bins the n points xyz into cells of side c from lo: a counting sort
 * through the table, so each cell's points stay in input order; the number
 * of cells with points into *cells. */
hv_status hv__bins_build(pt_bins *B, const double *xyz, size_t n, const double lo[3], double c,
                         size_t *cells);
void hv__bins_free(pt_bins *B);
/* The key of cell (i, j, k) (UINT64_MAX outside the keyed range), the cell
 * of x, the run of points in cell key (*len points from order + *start). */
uint64_t hv__cell_key(long i, long j, long k);
void hv__cell_of(const pt_bins *B, const double *x, long c[3]);
int hv__bins_find(const pt_bins *B, uint64_t key, uint32_t *start, uint32_t *len);
/* The cell of table slot t. */
void hv__slot_cell(const pt_bins *B, size_t t, long q[3]);
void hv__ring_first(ring_iter *it, const long q[3], long r);
int hv__ring_next(const pt_bins *B, ring_iter *it, uint32_t *j);

/* The orientation of a cloud without normals (sdf_orient.c): each point's
 * direction (sign unknown) into dir (by point), the axis of least spread of
 * the points of B within rho, and that spread over the least across it into
 * spread (0 on a clean plane, near 1 where no plane shows); then the directions turned along a minimum spanning tree
 * of the graph of each point's nearest in the 27 cells of `near` around it,
 * each component outward (area: the points' areas; counts into R). */
/* 1 when the points lie on a plane or a line (or are one point): no spread
 * across the least-spread axis of the whole cloud. */
int hv__points_flat(const hv_points *P);
hv_status hv__points_axes(const pt_bins *B, double rho, double *dir, float *spread);
/* Thin parts (orient_cut.c): the points whose spread (by point) is above
 * a threshold vote by rays of radius rc, off their own sheet by more than
 * `sheet`; T NULL: none. */
typedef struct pt_thin {
    const float *spread;
    double rc, sheet;
    unsigned char *held; /* by point: 1 on a thin part, its sign then kept (NULL: none) */
} pt_thin;
hv_status hv__points_propagate(const pt_bins *near, const hv_points *P, const double *area,
                               const pt_thin *T, double *dir, hv_points_report *R);
/* The neighbour graph of the tree: place u's neighbours (places in the
 * bins' order) from adj + off[u] to adj + off[u + 1], both ways. */
typedef struct or_graph {
    uint32_t *off, *adj;
} or_graph;
/* The votes of the thin parts' points, and the least-cost labelling of
 * the points near them (keep or turn their directions D, by place), which
 * turns D where it says so; counts into R. */
hv_status hv__points_cut(const pt_bins *near, const or_graph *G, const hv_points *P,
                         const pt_thin *T, double *D, hv_points_report *R);

/* The eigenvalues lam and eigenvectors (the columns of e) of the symmetric
 * 3 x 3 matrix m (xx yy zz xy xz yz), by Jacobi rotations (sdf_orient.c). */
void hv__sym3_axes(const double m[6], double lam[3], double e[3][3]);

/* The diffused line field of a cloud (points_lines.c): each point's
 * direction dir (sign unknown) splatted with its area as the tensor
 * a d d^T, six components, and one heat step (I - t Lap) per component on
 * g with the pipeline's solver (backend; opencl solves on the host, FFTW or
 * multigrid). T[0..5]: the fields, xx yy zz xy xz yz. */
typedef struct pt_lines {
    const hv_grid *g;
    float *T[6];
    int iterations; /* of the six heat steps, in all */
} pt_lines;
hv_status hv__lines_build(pt_lines *L, const hv_points *P, const double *area, const double *dir,
                          const hv_grid *g, double t, hv_backend backend);
void hv__lines_free(pt_lines *L);
/* The field's principal direction at x (world) into v, its sign along
 * `along` when that is not NULL; returns the anisotropy (l1 - l2) / l1
 * (0 where the field holds nothing), l1 >= l2 >= l3 the eigenvalues. At
 * cell c of L->g: hv__lines_cell. */
double hv__lines_at(const pt_lines *L, const double x[3], const double *along, double v[3]);
double hv__lines_cell(const pt_lines *L, size_t c, double v[3]);

/* Trilinear interpolation of v (on g's cells) at world point x (sdf_heat.c). */
double hv__sdf_interp(const hv_grid *g, const float *v, const double x[3]);
/* Adds ncomp values per point of q (vals[vstride * p + b], or its area when
 * vals is NULL) / h^3 trilinearly to out[b] (sdf_heat.c). */
void hv__sdf_splat(const hv_grid *g, const hv_quad *q, int ncomp, const double *vals, int vstride,
                   float *const *out);

/* out (on g) = trilinear interpolation of v (on gh) at g's cell centres. */
hv_status hv__sdf_upsample(const hv_grid *gh, const float *v, const hv_grid *g, float *out);

/* The sign of each cell of g from the generalized winding number of m (inside
 * above 1/2; ps->W), evaluated hierarchically (sign_winding.c): cubes far from
 * the surface (dist: the exact distance, INFINITY where not computed) whose
 * corners agree take one sign; cells within dlim of their nearest triangle
 * tri[c] (tri may be NULL) take its pseudonormal's sign where that feature
 * is clean and bounds a solid. out[c] = -1e-6 h inside, +1e-6 h outside.
 * evals counts winding-number evaluations, ps_used cells signed by
 * pseudonormals (either may be NULL). */
hv_status hv__winding_sign(const hv_mesh *m, const hv_grid *g, const float *dist,
                           const uint32_t *tri, hv_pseudo *ps, double dlim, float *out,
                           size_t *evals, size_t *ps_used);

/* The winding number of W at p, as precise as its distance from 1/2 needs
 * (dipoles refined near 1/2; sign_winding.c); ++*evals per evaluation. */
double hv__wn_sure(const hv_wn_tree *W, const double p[3], size_t *evals);

/* The sink hv_sdf_compute_tiles collects the batches with: one hv_tiles of
 * the bound begin is given, shrunk to the tiles that came; T is NULL until
 * begin and after a failed run. */
typedef struct {
    hv_tiles *T;
} hv__tiles_collect;
hv_tiles_sink hv__tiles_collector(hv__tiles_collect *c);

/* The narrow band of M (already repaired) on the block (n, h, origin) as
 * tiles (sdf_tiles.c): exact distance where it is below band * h, signed
 * within a voxel by the nearest clean feature's pseudonormal (within
 * near_sign voxels) or the winding number, and beyond by the winding number
 * (flooded from nearer cells where M is closed), handed to sink batch by
 * batch (sink->end is called once begin was). Counts into S (tiles,
 * active_voxels, band_cells, winding_evals, near_sign_cells, t_sign,
 * tiles_in_flight). */
hv_status hv__sdf_tiles(const hv_mesh *M, const int n[3], double h, const double origin[3],
                        double band, int unsig, double near_sign, const hv_tiles_sink *sink,
                        hv_sdf_stats *S);

/* sdf_tiles.c's helpers, which the device path (tiles_cl.c) shares: a lower
 * bound on the band's memory checked against the limit (numbered: the
 * block's tiles can be numbered in 32 bits); ntiles tiles on the block, no
 * voxel active (NULL when out of memory); the tiles a batch holds
 * (HEATVOX_TILE_BATCH, else 16384). */
hv_status hv__sdf_band_fits(const hv_mesh *M, const int n[3], double h, int numbered);
hv_tiles *hv__tiles_alloc(const int n[3], double h, const double origin[3], size_t ntiles);
size_t hv__sdf_tile_batch(void);

/* hv__sdf_tiles on an OpenCL device (tiles_cl.c, kernels/tiles.cl): the same
 * tiles in the same order, the same signs, distances as the host's to a few
 * ulps. Everything runs on the device; the tiles come back once. Before the
 * sink is begun a failure leaves it untouched (HV_ERR_UNSUPPORTED without a
 * device with fp64, HV_ERR_NOMEM when the device's memory does not hold the
 * band), so that the host path can take over; S->backend is set to
 * HV_BACKEND_OPENCL. */
hv_status hv__sdf_tiles_cl(const hv_mesh *M, const int n[3], double h, const double origin[3],
                           double band, int unsig, double near_sign, const hv_tiles_sink *sink,
                           hv_sdf_stats *S);

#endif
