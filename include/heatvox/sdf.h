/*
 * Signed (and unsigned) distance volumes from triangle meshes with the signed
 * heat method on grids (Feng & Crane, "A Heat Method for Generalized Signed
 * Distance", 2024), made robust to broken meshes: holes, flipped faces,
 * duplicated sheets, soups, self-intersections.
 *
 * Pipeline (hv_sdf_compute):
 *   1. repair     weld, drop degenerate and duplicate faces, make orientation
 *                 consistent across manifold edges, orient components outward
 *   2. splat      area-weighted normals (or areas, unsigned) onto cell centres
 *   3. diffuse    one backward-Euler heat step per component, (I - t Lap) Y = Y0
 *   4. normalize  X = Y/|Y| on cell faces (MAC), then div X
 *   5. poisson    Lap(phi) = div X, Neumann walls
 *   6. shift      phi -= area-weighted mean of phi at the surface samples
 *   7. redistance (HV_SDF_EXACT, the default) |phi| replaced by the exact
 *                 distance to the repaired triangles, keeping the heat sign
 * Values are negative inside. The grid is cell-centred (grid.h).
 */
#ifndef HEATVOX_SDF_H
#define HEATVOX_SDF_H

#include "grid.h"
#include "mesh.h"
#include "solve.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Mesh repair steps (bit flags, applied in this order). */
enum {
    HV_SDF_REPAIR_WELD = 1u << 0,        /* merge vertices at exactly the same position */
    HV_SDF_REPAIR_DEGENERATE = 1u << 1,  /* drop faces with a repeated vertex or zero area */
    HV_SDF_REPAIR_DUPLICATES = 1u << 2,  /* drop faces repeating an earlier face's vertex set */
    HV_SDF_REPAIR_ORIENT = 1u << 3,      /* one orientation per manifold-connected component */
    HV_SDF_REPAIR_OUTWARD = 1u << 4,     /* flip components whose signed volume is negative */
    HV_SDF_REPAIR_ALL = 0x1fu
};

/* How |phi| is obtained. */
typedef enum hv_sdf_magnitude {
    HV_SDF_EXACT = 0,  /* exact distance to the repaired triangles, heat-method sign (default) */
    HV_SDF_HEAT        /* the heat method's phi itself */
} hv_sdf_magnitude;

typedef struct hv_sdf_opts {
    /* Grid placement. Exactly one of res / voxel_size is used (voxel_size when > 0). */
    int res;              /* cells along the longest axis of the padded box; default 128 */
    double voxel_size;    /* h; default 0 (use res) */
    int pad;              /* cells between the mesh bounds and the block boundary; default 4 */
    int use_bbox;         /* 1: bbox below is the block's outer boundary (pad ignored) */
    double bbox[6];       /* x0 y0 z0 x1 y1 z1 */
    int round_to;         /* without bbox, round cell counts up to a multiple of this (extra
                             padding, centred) so multigrid coarsens well; default 8, 1 = off */

    /* Method. */
    int unsigned_distance;      /* 1: unsigned distance to the mesh; default 0 */
    hv_sdf_magnitude magnitude; /* default HV_SDF_EXACT */
    double t_scale;       /* diffusion time t = (t_scale * h)^2; default 1 */
    int far_levels;       /* extra diffusions with t multiplied by 16 each, used on faces where the
                             shorter ones have decayed below solver accuracy; -1 (default): as many
                             as needed to reach the whole grid (0 with HV_SDF_EXACT) */
    unsigned repair;      /* HV_SDF_REPAIR_* flags; default HV_SDF_REPAIR_ALL */

    /* Solves. */
    hv_backend backend;   /* default HV_BACKEND_AUTO */
    double diffuse_tol;   /* relative residual of the heat solves; default 1e-10 */
    double poisson_tol;   /* relative residual of the Poisson solve; default 1e-8 */
    int threads;          /* worker threads; 0 (default) leaves the current setting */
} hv_sdf_opts;

typedef struct hv_sdf_repair_report {
    size_t vertices_in, triangles_in;
    size_t vertices_welded;       /* vertices merged into an earlier one */
    size_t degenerate_removed;
    size_t duplicates_removed;    /* same vertex set as an earlier face, either orientation */
    size_t boundary_edges;        /* after repair */
    size_t nonmanifold_edges;     /* after repair */
    size_t inconsistent_before;   /* manifold edges traversed the same way by both faces */
    size_t inconsistent_after;
    size_t components;            /* components connected through manifold edges */
    size_t faces_flipped;         /* by orientation propagation and outward orientation */
    size_t components_flipped;    /* whole components turned outward */
    size_t vertices_out, triangles_out;
} hv_sdf_repair_report;

typedef struct hv_sdf_stats {
    int n[3];
    double h;
    double origin[3];
    double t;                    /* diffusion time of the finest level */
    int levels;                  /* diffusion levels used */
    hv_backend backend;          /* the solver backend that ran */
    size_t surface_samples;      /* quadrature points */
    /* Seconds per stage. */
    double t_repair, t_splat, t_diffuse, t_normalize, t_poisson, t_shift, t_redistance, t_total;
    int diffuse_iterations;      /* summed over components and levels */
    double diffuse_relres;       /* worst final relative residual */
    int poisson_iterations;
    double poisson_relres;
    double shift;                /* value subtracted from phi */
    size_t dead_faces;           /* faces where no level was above solver accuracy (X = 0) */
    size_t band_cells;           /* cells whose exact distance came from rasterization */
    hv_sdf_repair_report repair;
} hv_sdf_stats;

void hv_sdf_opts_default(hv_sdf_opts *o);

/* The grid hv_sdf_compute would use for mesh m: cell counts, voxel size and
 * block origin. Fails on empty meshes, NaN/Inf coordinates, inconsistent
 * options and grids too large for this machine. */
hv_status hv_sdf_grid_for_mesh(const hv_mesh *m, const hv_sdf_opts *o, int n[3], double *h,
                               double origin[3]);

/* Repairs a copy of `in` with the steps in `flags`; *out is a new mesh that the
 * caller frees with hv_mesh_destroy (its arrays come from malloc). report may be
 * NULL. Fails on NaN/Inf coordinates, out-of-range indices and empty meshes. */
hv_status hv_sdf_repair(const hv_mesh *in, unsigned flags, hv_mesh **out,
                        hv_sdf_repair_report *report);

/* Computes the distance volume of m. opts may be NULL (defaults); stats may be
 * NULL. The caller owns *out (hv_grid_destroy). Reports progress through
 * hv_set_progress between stages; a cancel returns HV_ERR_CANCELLED. */
hv_status hv_sdf_compute(const hv_mesh *m, const hv_sdf_opts *opts, hv_grid **out,
                         hv_sdf_stats *stats);

#ifdef __cplusplus
}
#endif
#endif
