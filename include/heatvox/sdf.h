/*
 * Signed (and unsigned) distance volumes from triangle meshes with the signed
 * heat method on grids (Feng & Crane, "A Heat Method for Generalized Signed
 * Distance", 2024), made robust to broken meshes: holes, flipped faces,
 * duplicated sheets, soups, self-intersections, n-gons (fanned by the readers).
 *
 * Pipeline (hv_sdf_compute):
 *   1. repair     weld by position, drop degenerate faces and faces repeating a
 *                 vertex set (either orientation), propagate one orientation
 *                 across manifold edges, orient components outward by winding
 *                 number (cavities inward), close boundary loops with domed caps
 *   2. splat      area-weighted normals (areas, unsigned) onto cell centres,
 *                 triangles split until sub-edges are <= h, trilinear weights
 *   3. diffuse    one backward-Euler step per component, (I - t Lap) Y = Y0,
 *                 t = (t_scale h)^2, the three components sharing one solver
 *   4. normalize  X = Y/|Y| on cell faces (MAC: the two cells' mean, normalized
 *                 on the face); faces where Y is below the solver's error
 *                 bound get X = 0, where phi is then harmonic and keeps the
 *                 sign of its surroundings (maximum principle)
 *   5. poisson    Lap(phi) = div X, Neumann walls, the same solver interface
 *   6. shift      phi -= area-weighted mean of phi at the surface samples, then
 *                 the local residual extended by normalized heat convolution
 *   7. redistance (HV_SDF_EXACT, the default) |phi| := exact distance to the
 *                 repaired triangles (rasterized near them, propagated by
 *                 closest-triangle sweeps elsewhere); the sign is the heat
 *                 method's, except within a voxel of clean closed surface
 *                 where the angle-weighted pseudonormal decides. Where the
 *                 heat method's sign would depend on the block (the repaired
 *                 mesh stays open, or the block cuts it), the generalized
 *                 winding number of the repaired mesh signs instead and
 *                 stages 2-6 do not run (hv_sdf_sign)
 * Values are negative inside. The grid is cell-centred (grid.h).
 *
 * Why the exact magnitude: the heat method's own phi is right near the
 * surface but not far away (far-field error 0.3 voxel on a sphere, 5 voxels on
 * a torus at 128^3: diffused normals are not a gradient), while its sign is
 * robust. With HV_SDF_EXACT the error on a sphere or torus is the meshes'
 * faceting (< 0.01 voxel over the whole grid, tests/check_sdf.c).
 */
#ifndef HEATVOX_SDF_H
#define HEATVOX_SDF_H

#include "grid.h"
#include "mesh.h"
#include "solve.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Mesh repair steps (bit flags), applied in the order listed. */
enum {
    HV_SDF_REPAIR_WELD = 1u << 0,       /* merge vertices at exactly the same position */
    HV_SDF_REPAIR_DEGENERATE = 1u << 1, /* drop faces with a repeated vertex or zero area */
    HV_SDF_REPAIR_DUPLICATES = 1u << 2, /* drop faces repeating an earlier face's vertex set */
    HV_SDF_REPAIR_ORIENT = 1u << 3,     /* one orientation per manifold-connected component */
    HV_SDF_REPAIR_FILL_HOLES = 1u << 5, /* close boundary loops with planar caps (see max_hole) */
    HV_SDF_REPAIR_OUTWARD = 1u << 4,    /* orient components outward by winding number,
                                            cavities inward */
    HV_SDF_REPAIR_ALL = 0x3fu,
    HV_SDF_REPAIR_DOMED_CAPS = 1u << 6 /* with FILL_HOLES: caps that bulge like the wall
                                            around the hole instead of planar ones (not in ALL) */
};

/* Where the sign comes from (HV_SDF_EXACT, signed). */
typedef enum hv_sdf_sign {
    HV_SDF_SIGN_AUTO = 0, /* the winding number where the heat method's sign would depend on the
                             block: the repaired mesh is still open, or the block cuts the mesh;
                             the heat method otherwise (default) */
    HV_SDF_SIGN_HEAT,     /* the signed heat method on the block */
    HV_SDF_SIGN_WINDING   /* the generalized winding number of the repaired mesh above 1/2 */
} hv_sdf_sign;

/* How |phi| is obtained. */
typedef enum hv_sdf_magnitude {
    HV_SDF_EXACT = 0, /* exact distance to the repaired triangles, heat-method sign (default) */
    HV_SDF_HEAT       /* the heat method's phi itself */
} hv_sdf_magnitude;

/* A point cloud's normals: those given, recovered from the points alone
 * (hv_points_surface, step 0), or (AUTO) recovered when the cloud has none. */
typedef enum hv_points_orient {
    HV_ORIENT_AUTO = 0,
    HV_ORIENT_GIVEN,
    HV_ORIENT_RECOVER
} hv_points_orient;

typedef struct hv_sdf_opts {
    /* Grid placement. Exactly one of res / voxel_size is used (voxel_size when > 0). */
    int res;           /* cells along the longest axis of the padded box; default 128 */
    double voxel_size; /* h; default 0 (use res) */
    int pad;           /* cells between the mesh bounds and the block boundary; default 4 */
    int use_bbox;      /* 1: bbox below is the block's outer boundary (pad ignored) */
    double bbox[6];    /* x0 y0 z0 x1 y1 z1 */
    int round_to;      /* without bbox, round cell counts up to a multiple of this (extra
                             padding, centred) so multigrid coarsens well; default 8, 1 = off */

    /* Method. */
    int unsigned_distance;      /* 1: unsigned distance to the mesh; default 0 */
    hv_sdf_magnitude magnitude; /* default HV_SDF_EXACT */
    double t_scale;             /* diffusion time t = (t_scale * h)^2; default 1 */
    int far_levels;   /* extra diffusions with t multiplied by 16 each, used on faces where the
                             shorter ones have decayed below solver accuracy; -1 (default): as many
                             as needed to reach the whole grid (0 with HV_SDF_EXACT) */
    unsigned repair;  /* HV_SDF_REPAIR_* flags; default HV_SDF_REPAIR_ALL */
    double max_hole;  /* holes wider than this times their component's bounding-box diagonal
                             stay open (rims of bowls and sheets); default 0.5 */
    double near_sign; /* HV_SDF_EXACT, signed: within this many voxels of the mesh (and where
                             |phi| < 1.5 times it) the sign comes from the nearest feature's
                             angle-weighted pseudonormal when that feature is clean; 0 = off;
                             default 1 */
    int local_shift;  /* 1 (default): after the global shift, subtract the residual of phi
                             at the surface extended into the volume by normalized heat
                             convolution, so the zero set follows the mesh (signed only) */
    double band_only; /* HV_SDF_EXACT: > 0 computes the exact distance only within this many
                             voxels of the mesh, as a narrow-band level set needs; farther cells
                             get (band_only + 1) h with the heat method's sign. Bands up to 4
                             voxels are rasterized whole, wider ones dilated from a 2-voxel
                             raster; no pass over the whole grid.
                             0 (default): exact everywhere */

    /* Solves. */
    hv_backend backend; /* default HV_BACKEND_AUTO */
    double diffuse_tol; /* relative residual of the heat solves; 0 (default): 1e-6 where the heat
                             method only decides the sign (HV_SDF_EXACT, signed), else 1e-10 */
    double poisson_tol; /* relative residual of the Poisson solve; 0 (default): 1e-4 where the
                             heat method only decides the sign, else 1e-8 */
    int heat_coarsen;   /* HV_SDF_EXACT, signed: run the heat method (which then only decides
                             the sign) on a grid this many times coarser, 1..4; 0 (default):
                             2 on grids above 2^22 cells (about 160^3), else 1 */
    int threads;        /* > 0: calls hv_set_threads(threads) (process-wide) first;
                             0 (default) leaves the current setting */
    hv_sdf_sign sign;   /* HV_SDF_EXACT, signed: the sign's source; default HV_SDF_SIGN_AUTO.
                             The winding number needs the repair's orientation steps
                             (HV_SDF_REPAIR_ORIENT and HV_SDF_REPAIR_OUTWARD); AUTO uses the
                             heat method without them */

    /* Morphology of the signed result, in world units, applied in this order
     * (0 = off; signed distances only). The block is placed around the
     * mesh's bounds grown by what the shape may grow (offset > 0, close), and
     * bands grow by what they need. */
    double close;  /* grow by close, then shrink by it: fills gaps and cracks narrower
                      than 2 close (dense grids only) */
    double open;   /* shrink by open, then grow: removes parts thinner than 2 open
                      (dense grids only) */
    double offset; /* the surface moved out by offset (in when negative): phi - offset */
    double shell;  /* > 0: only a wall of this thickness inside the surface:
                      max(phi, -phi - shell) */

    /* Point clouds (hv_points_surface): where the normals come from. */
    hv_points_orient orient; /* default HV_ORIENT_AUTO */
} hv_sdf_opts;

typedef struct hv_sdf_repair_report {
    size_t vertices_in, triangles_in;
    size_t vertices_welded; /* vertices merged into an earlier one */
    size_t degenerate_removed;
    size_t duplicates_removed; /* same vertex set as an earlier face, either orientation */
    size_t holes_filled;       /* boundary loops closed with caps */
    size_t holes_left_open;    /* loops too wide, or not traceable (non-manifold rims) */
    size_t cap_triangles;
    size_t boundary_edges_closed; /* boundary edges on filled loops */
    size_t boundary_edges;        /* after repair */
    size_t nonmanifold_edges;     /* after repair */
    size_t inconsistent_before;   /* manifold edges traversed the same way by both faces */
    size_t inconsistent_after;
    size_t components;         /* components connected through manifold edges */
    size_t faces_flipped;      /* by orientation propagation and outward orientation */
    size_t components_flipped; /* whole components turned outward */
    size_t vertices_out, triangles_out;
} hv_sdf_repair_report;

typedef struct hv_sdf_stats {
    int n[3];
    double h;
    double origin[3];
    double t;               /* diffusion time of the finest level */
    int levels;             /* diffusion levels used */
    int heat_coarsen;       /* the heat method's grid was this many times coarser */
    hv_backend backend;     /* the solver backend that ran */
    size_t surface_samples; /* quadrature points */
    /* Seconds per stage. */
    double t_repair, t_splat, t_diffuse, t_normalize, t_poisson, t_shift, t_redistance, t_total;
    int diffuse_iterations; /* summed over components and levels */
    double diffuse_relres;  /* worst final relative residual */
    int poisson_iterations;
    double poisson_relres;
    double shift; /* value subtracted from phi (global shift) */
    double
        surface_rms_before; /* rms of phi at the surface samples, voxels, after the global shift */
    double surface_rms_after; /* the same after the local correction */
    size_t dead_faces;        /* faces where no level was above solver accuracy (X = 0) */
    size_t band_cells;        /* cells whose exact distance came from rasterization */
    size_t near_sign_cells;   /* cells signed by a pseudonormal (one that agreed with the heat
                                    sign counts even where its face's trust was not tested) */
    size_t near_sign_changed; /* of those, cells where it disagreed with the heat sign */
    hv_sdf_repair_report repair;
    hv_sdf_sign sign;     /* the sign's source that ran: HV_SDF_SIGN_HEAT or HV_SDF_SIGN_WINDING
                             (HV_SDF_SIGN_AUTO for unsigned distance and HV_SDF_HEAT) */
    size_t winding_evals; /* winding-number evaluations of the sign */
    double t_sign;        /* seconds of the winding-number sign (within t_redistance) */
    /* In tiles (hv_sdf_compute_tiles, hv_sdf_stream_tiles): */
    size_t tiles;           /* tiles with an active voxel */
    size_t active_voxels;   /* voxels within the band */
    size_t tiles_in_flight; /* what a batch's arrays hold (whole groups of 8, about 16384) */
    size_t tiles_bound;     /* the bound the sink was given */
} hv_sdf_stats;

HV_API void hv_sdf_opts_default(hv_sdf_opts *o);

/* The grid hv_sdf_compute would use for mesh m: cell counts, voxel size and
 * block origin. Fails on empty meshes, NaN/Inf coordinates, inconsistent
 * options and grids too large for this machine. */
HV_API hv_status hv_sdf_grid_for_mesh(const hv_mesh *m, const hv_sdf_opts *o, int n[3], double *h,
                                      double origin[3]);

/* Repairs a copy of `in` with the steps in `flags` (max_hole as in hv_sdf_opts);
 * *out is a new mesh that the caller frees with hv_mesh_destroy. report may be
 * NULL. Fails on NaN/Inf coordinates, out-of-range indices and empty meshes. */
HV_API hv_status hv_sdf_repair(const hv_mesh *in, unsigned flags, double max_hole, hv_mesh **out,
                               hv_sdf_repair_report *report);

/* Computes the distance volume of m. opts may be NULL (defaults); stats may be
 * NULL. The caller owns *out (hv_grid_destroy). Reports progress through
 * hv_set_progress between stages; a cancel returns HV_ERR_CANCELLED. */
HV_API hv_status hv_sdf_compute(const hv_mesh *m, const hv_sdf_opts *opts, hv_grid **out,
                                hv_sdf_stats *stats);

/* The narrow band of m's signed (or, with unsigned_distance, unsigned)
 * distance as 8^3 tiles, without the dense grid: memory and time follow the
 * surface, not the block. The block is hv_sdf_compute's (the same placement
 * options), band is the half width in voxels: a voxel is active where its
 * exact distance is below band * h, and holds the same value as the dense
 * result there. Other voxels of a tile hold +band * h; the sign of what is
 * not active is for a flood fill from the active voxels (as
 * hv_vdb_writer_add_levelset_tiles does). The sign is the winding number's
 * (HV_SDF_SIGN_AUTO and HV_SDF_SIGN_WINDING alike): the pseudonormal of the
 * nearest feature where it is clean and bounds a solid, else the generalized
 * winding number of the repaired mesh above 1/2, so that it does not depend on
 * the block. Fails for HV_SDF_HEAT and HV_SDF_SIGN_HEAT (they need the dense
 * grid), and when no band voxel lies in the block. The caller owns *out
 * (hv_tiles_destroy). stats: repair, grid, tiles, active_voxels, band_cells,
 * winding_evals, near_sign_cells, t_repair, t_redistance, t_sign, t_total. */
HV_API hv_status hv_sdf_compute_tiles(const hv_mesh *m, const hv_sdf_opts *opts, double band,
                                      hv_tiles **out, hv_sdf_stats *stats);

/* Whether a run with options o can compute its narrow band in tiles
 * (hv_sdf_compute_tiles, hv_sdf_stream_tiles) instead of on the dense
 * block: NULL when it can, else a sentence saying which option keeps it on
 * the dense grid. The rule of the library, the command and batch alike. With
 * levelset set, the run writes a level set from the tiles (a narrow-band
 * .vdb), which an unsigned distance is not: it needs a signed one. */
HV_API const char *hv_sdf_tiles_refusal(const hv_sdf_opts *o, int levelset);

/* hv_sdf_compute_tiles without ever holding the whole band: the same tiles,
 * in the same order, handed to sink in batches as they are finished (see
 * hv_tiles_sink; the batches' arrays are reused), so that a consumer such as
 * hv_vdb_writer_levelset_sink keeps what it needs and the producer holds one
 * batch (stats->tiles_in_flight tiles, about 2 kB each) beside its triangle
 * lists. sink->begin is told an upper bound on the tiles to come; sink->end
 * is called once, also when the run fails before begin. A status from the
 * sink stops the run and is returned; a cancel through the progress
 * callback stops it with HV_ERR_CANCELLED (once the sink has ended with ok,
 * the run stands). stats as hv_sdf_compute_tiles's (band_cells, winding_evals
 * and near_sign_cells over the tiles that can hold a band voxel). */
HV_API hv_status hv_sdf_stream_tiles(const hv_mesh *m, const hv_sdf_opts *opts, double band,
                                     const hv_tiles_sink *sink, hv_sdf_stats *stats);

/* Oriented point clouds to a closed surface: the signed heat method with
 * the points' normals as the source, then the zero set moved onto the
 * points.
 *   1. spacing   the area each point stands for, pi d^2 / k from the
 *                distance d to its k = 6th nearest neighbour, so that uneven
 *                density does not weigh the dense parts more
 *   2. heat      stages 2-6 of hv_sdf_compute on the block hv_sdf_compute
 *                would place around the points (res, voxel_size, pad, bbox,
 *                heat_coarsen as there), with these areas and normals as the
 *                vector areas, diffusion time (t_scale max(h, spacing))^2;
 *                normals flipped on part of the cloud are outvoted by their
 *                neighbours in the diffused field
 *   3. surface   phi's zero set as a closed mesh (hv_grid_to_mesh), each
 *                triangle split in four where the heat grid is the block's
 *                own (vertices half a voxel apart)
 *   4. project   each vertex moved along phi's gradient onto the local plane
 *                of the points within 2 sigma that face the same way
 *                (Gaussian weights of width sigma = max(the block's voxel,
 *                the spacing), corrected for the curvature by the points'
 *                normals, at most one heat voxel); on noisy points the
 *                kernel widens (to 1.5 sigma, while a fit weighs fewer
 *                than about 30 points) and each move is weighed
 *                against the heat method's surface by its uncertainty;
 *                where the cloud has a gap the heat method's surface stays
 * The result is closed and oriented outward; its signed distance
 * (hv_sdf_compute, hv_sdf_compute_tiles) is the cloud's. */
typedef struct hv_points_report {
    size_t points;
    double spacing_median, spacing_min, spacing_max; /* world units */
    size_t normals_against;      /* points whose normal points into the surface found */
    double normal_agreement;     /* fraction of the points' area whose normal points out of it */
    size_t vertices;             /* surface vertices */
    size_t vertices_unsupported; /* no point within reach: left where the heat method put them */
    double move_mean, move_max;  /* projection distances, voxels of the heat grid */
    double noise;                /* the points' scatter along the normal (world units; 0: clean) */
    double sigma;                /* the projection's kernel width (world units) */
    int n[3];                    /* the heat method's grid */
    double h;
    int coarsen;       /* it is this many times coarser than the block */
    hv_sdf_stats heat; /* its stages (t_splat .. t_shift, iterations, backend) */
    double t_spacing, t_heat, t_mesh, t_project, t_total; /* seconds */
    /* Step 0, the orientation recovered (recovered 0: the given normals). */
    int recovered;
    size_t orient_components; /* neighbour-graph components oriented outward each */
    size_t orient_components_flipped;
    int orient_rounds;          /* heat rounds that turned points to phi's outside */
    size_t orient_turned;       /* points the rounds turned, in all */
    size_t orient_disagree;     /* recovered normals against the given ones (where given) */
    double t_orient;            /* seconds: directions, propagation and the rounds' heat */
    double orient_spread;       /* median spread off the points' planes (0 clean, 1 no plane) */
    int orient_lines;           /* 1: the directions came from the diffused line field */
    int orient_line_iterations; /* of its six heat steps */
    size_t orient_thin_votes;   /* points of thin parts that the rays' sheet counts oriented */
    size_t orient_thin_turned;  /* points the thin parts' labelling turned */
} hv_points_report;

/* The closed surface of oriented points P (above); opts as for
 * hv_sdf_compute (NULL: defaults; only the placement, t_scale,
 * heat_coarsen, backend and threads are read). The caller owns *out
 * (hv_mesh_destroy). report may be NULL. Fails on an empty cloud, one with
 * no extent, and when the heat method finds no inside. */
HV_API hv_status hv_points_surface(const hv_points *P, const hv_sdf_opts *opts, hv_mesh **out,
                                   hv_points_report *report);

#ifdef __cplusplus
}
#endif
#endif
