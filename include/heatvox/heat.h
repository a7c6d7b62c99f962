/*
 * Heat-method distance around obstacles, and extension of fields off a level
 * set by diffusion (the vector heat method's scalar/vector split).
 *
 * Distance (Crane, Weischedel & Wardetzky, "The Heat Method for Distance
 * Computation", 2017) on a cell-centred grid whose solid cells are obstacles:
 *   1. diffuse    (I - t Lap) u = delta_sources for t and 4t (t = t_scale h^2),
 *                 double precision; solid faces carry no heat, so the heat, and
 *                 the distance, go around obstacles
 *   2. normalize  X = -grad psi / |grad psi| on cell faces (MAC: the face's own
 *                 difference, normalized with the mean of the open transverse
 *                 face differences around it), psi = ln u(t) - ln u(4t): the
 *                 logarithm keeps face and transverse differences consistent,
 *                 and the difference of two times cancels the amplitude that
 *                 tilts directions behind corners; only where both solves are
 *                 well above their error bound
 *   3. march      e^{-r/sqrt t} leaves the far field below that bound
 *                 (docs/METHOD.md, "Heat method"), and a larger t bends
 *                 directions near walls and corners. So the diffusion is
 *                 repeated from a front: a wavefront of the distance inside
 *                 the trusted zone (placed with the lattice's own decay rate
 *                 per direction, so fronts stay round), whose own heat flow
 *                 continues the directions outward (Huygens).
 *                 Stages repeat until every open face has a direction.
 *   4. poisson    Lap(phi) = div X with Neumann walls and solid faces closed
 *   5. shift      per connected fluid region, fitted on the cells 1.5-3 voxels
 *                 from the sources, where phi should equal the distance to them
 * Measured (mean |error| in voxels): wall with a gap 0.57 and L-shaped room 0.21
 * at 128^2, 0.36 / 0.24 in 3D at 48^3 / 64^3; roughly constant in voxels under
 * refinement (the error is mostly a jump of ~1.5 voxels at re-entrant corners).
 * Fluid cells connected to no source are "unreachable": they get
 * opts.unreachable (default +inf) and are counted in the stats.
 *
 * Extension (Sharp, Soliman & Crane, "The Vector Heat Method", 2019; in flat
 * space the connection Laplacian acts componentwise): weights w (a smooth bump
 * of |phi|/(band h)) mark the cells near the zero set; w*f and w are diffused
 * with one operator and f_ext = diffused(w f) / diffused(w) (a Nadaraya-Watson
 * average). Vectors: magnitude from the scalar ratio of w|v|, direction from
 * the componentwise diffused w v, normalized. Where phi is a distance
 * (|grad phi| near 1) the ratios are evaluated at the closest point
 * x - phi grad(phi)/|grad(phi)| (trilinear), which makes the result constant
 * along normals; elsewhere (clamped narrow-band level sets, medial axes) at x
 * itself, with larger diffusion times where the first one has decayed.
 */
#ifndef HEATVOX_HEAT_H
#define HEATVOX_HEAT_H

#include "grid.h"
#include "mesh.h"
#include "solve.h"
#include "opencl.h"

#ifdef __cplusplus
extern "C" {
#endif

/* ---- Distance ------------------------------------------------------------ */

/* Where the distance is zero. Any combination; all arrays are borrowed. */
typedef struct hv_distance_sources {
    const int *voxels; /* nvoxels triples i j k (k = 0 on 2D grids) */
    size_t nvoxels;
    const double *points; /* npoints world triples x y z (z ignored on 2D grids),
                              splatted trilinearly onto the fluid cells around them */
    size_t npoints;
    const hv_mesh *mesh; /* NULL, or a mesh whose surface is the source (3D grids):
                              sampled at spacing <= h/2 and splatted by area */
} hv_distance_sources;

typedef struct hv_distance_opts {
    double t_scale;     /* diffusion time t = t_scale * h^2; default 2 */
    int max_stages;     /* most diffusions (the source, then fronts); each reaches
                              about 20 sqrt(t) further; default 1000 */
    double diffuse_tol; /* relative residual of the heat solves; default 1e-11 */
    double poisson_tol; /* relative residual of the Poisson solve; default 1e-9 */
    hv_backend backend; /* default AUTO (FFTW without obstacles, multigrid with) */
    float unreachable;  /* value of fluid cells in regions without a source;
                              default +INFINITY */
    float solid_value;  /* value of solid cells; default +INFINITY */
    hv_coarse coarse;   /* the solves' coarse levels with obstacles (hv_solver_opts.coarse);
                           default AUTO: aggregation for the Poisson solve, AUTO for the
                           heat steps */
    int whole_stages;   /* 0 (default): each stage solves its heat steps on the tiles its
                           front reaches (8^3 cells, docs/METHOD.md "Stages on tiles"), by
                           Chebyshev sweeps on the host or, with opencl, on the device;
                           1: on the whole grid with the backend's solver, as the petsc
                           path always does */
} hv_distance_opts;

typedef struct hv_distance_stats {
    double t;                  /* diffusion time */
    int stages;                /* diffusions run */
    size_t faces_per_stage[8]; /* open faces whose direction came from stage l (first 8) */
    size_t dead_faces;         /* open faces of reachable regions no stage reached (X = 0) */
    size_t source_cells;       /* cells with a source weight */
    size_t sources_in_solid;   /* voxels/points/mesh samples with no fluid cell to land on */
    size_t regions;            /* connected fluid regions that hold a source */
    size_t unreachable_cells;  /* fluid cells in regions without a source */
    int diffuse_iterations;    /* summed over stages */
    double diffuse_relres;     /* worst final relative residual of the heat solves */
    int poisson_iterations;    /* summed over restarts */
    int poisson_restarts;      /* defect-correction restarts of the Poisson solve */
    double poisson_relres;     /* final relative residual */
    hv_backend backend;        /* backend of the solves */
    double t_splat, t_diffuse, t_normalize, t_poisson, t_total; /* seconds */
    size_t cells_solved;   /* cells the heat steps solved on, summed over stages */
    size_t stage_cells[8]; /* cells stage l solved on (first 8) */
    double t_setup;        /* seconds making the solvers an hv_distance keeps (0 when a
                              query reuses them) */
    double host_bytes;     /* the opencl path: bytes its stages moved between host and
                              device (the tiles' flags, lists and codes, residual sums) */
} hv_distance_stats;

HV_API void hv_distance_opts_default(hv_distance_opts *o);

/* Fills dist->v with the geodesic distance (world units) from the sources,
 * through the fluid cells of dist (dist->solid marks obstacles; NULL = none).
 * Values are >= 0 (the heat method's small negative values next to sources are
 * clamped); fluid cells in a region no source reaches get o->unreachable and
 * solid cells o->solid_value. opts and stats may be NULL.
 * Fails with HV_ERR_INVALID_ARG when no source lands on a fluid cell, a voxel
 * index is out of range or a mesh source is given for a 2D grid. Reports
 * progress through hv_set_progress before each stage ("diffuse") and the
 * Poisson solve ("poisson"), on every backend; a cancel returns
 * HV_ERR_CANCELLED. */
HV_API hv_status hv_distance_compute(hv_grid *dist, const hv_distance_sources *src,
                                     const hv_distance_opts *opts, hv_distance_stats *stats);

/* Distance queries on one set of obstacles: the object keeps what does not
 * depend on the sources (the obstacle mask, the Poisson solver and its coarse
 * levels; with whole_stages the heat steps' solvers too), so that every query
 * after the first pays no set-up. */
typedef struct hv_distance hv_distance;

/* Makes the object for grids of g's shape (dim, n, h, origin) and obstacles
 * (g->solid, copied; g->v is not read); opts may be NULL (defaults). The
 * first query's stats report the set-up time (t_setup); later ones 0. */
HV_API hv_status hv_distance_create(hv_distance **d, const hv_grid *g,
                                    const hv_distance_opts *opts);
/* Fills dist->v (a grid of the object's dim, n and h) with the distance from
 * src, as hv_distance_compute does (bit for bit); stats may be NULL. One
 * query at a time on an object (its solvers are shared). */
HV_API hv_status hv_distance_query(hv_distance *d, const hv_distance_sources *src, hv_grid *dist,
                                   hv_distance_stats *stats);
HV_API void hv_distance_destroy(hv_distance **d);

/* Marks as solid (adding a mask if needed) every cell of g whose closed box
 * meets a triangle of m: a watertight shell that blocks heat. Cells enclosed by
 * a closed mesh stay fluid and form their own region (unreachable unless a
 * source lies inside). g must be 3D. *nsolid (may be NULL) receives the number
 * of cells marked. */
HV_API hv_status hv_mask_from_mesh(hv_grid *g, const hv_mesh *m, size_t *nsolid);

/* ---- Extension ----------------------------------------------------------- */

typedef struct hv_extend_opts {
    double band;        /* source cells: |phi| < band * h, weight (1 - (phi/(band h))^2)^2;
                              default 1.5 */
    double t_scale;     /* diffusion time t = t_scale * h^2; default 0.25 (the ratio at a
                              closest point averages over ~sqrt(t): mean error 0.17% at 0.25,
                              0.24% at 0.5, 0.38% at 1, 0.65% at 2 on a 96^3 sphere; the
                              band solve is also cheaper at shorter times) */
    int closest_point;  /* 1 (default): evaluate at the closest point where phi is a
                              distance; 0: plain diffusion ratio at every cell */
    double out_band;    /* 0 (default): every cell; > 0: only cells with
                              |phi| < out_band * h, the others get `background` */
    float background;   /* default 0 */
    int max_levels;     /* diffusion times t * 16^l for cells the first has not
                              reached reliably (plain-ratio cells only); default 6; with
                              out_band > 0 they stop at the first whose reach sqrt(t_l)
                              covers out_band - band voxels */
    hv_backend backend; /* default AUTO */
    double tol;         /* relative residual of the iterative solves; default 1e-10 (the
                              band solve below runs in float to max(tol, 3e-5)) */
    int box_only;       /* 0 (default): with backend auto or mg, t_scale <= 8 and no
                              solid cells, the first diffusion time is solved only on the
                              cells near the weights and the cells read (grown by 6 sqrt(t)
                              voxels) when those are under half the box (always with
                              out_band > 0), by Chebyshev sweeps, and so are later times
                              up to 8 h^2 on the cells left; 1: always the box. Backends fftw and opencl always
                              solve on boxes (opencl: on the device, extend_cl.c) */
} hv_extend_opts;

typedef struct hv_extend_stats {
    size_t source_cells; /* cells with a weight */
    size_t cp_cells;     /* output cells evaluated at their closest point */
    size_t ratio_cells;  /* output cells evaluated at the cell itself */
    size_t weak_cells;   /* ratio cells whose weight no level brought above the error
                              bound (value taken from the last level anyway) */
    int levels;          /* diffusion times used in this call */
    size_t solve_cells;  /* cells of the first level's solve: the box around the weights
                              and the cells read at themselves, plus 6 sqrt(t), or the
                              band's cells */
    int solves;          /* right-hand sides solved */
    double relres;       /* worst relative residual */
    double t_weights, t_solve, t_eval, t_total; /* seconds: weights, input checks and the
                                                   choice of evaluation points; solves (with
                                                   the band's set-up); background and
                                                   evaluation */
    size_t tiles;                               /* hv_extend_tiles: the level set's tiles */
    size_t work_bytes;   /* hv_extend_tiles: the call's work memory at its largest (the
                          solves' arrays, the outputs not counted; on a device, its memory) */
    size_t remote_cells; /* hv_dmda_extend: this rank's output cells read at closest points
                            whose stencils lie on other ranks' cells past what the ghost
                            layer holds of the first level (their values fetched from
                            those ranks) */
    int on_device;       /* hv_extend_tiles: 1 when it ran on the OpenCL device */
} hv_extend_stats;

/* One field to extend: ncomp = 1 (scalar) or 2..3 (vector, per-component
 * arrays). in[c] and out[c] hold one value per cell; out may alias in. */
typedef struct hv_extend_field {
    int ncomp;
    const float *in[3];
    float *out[3];
} hv_extend_field;

typedef struct hv_extender hv_extender;

HV_API void hv_extend_opts_default(hv_extend_opts *o);

/* Creates an extender for grids of this shape (solid may be NULL; copied).
 * Solvers are built on first use and kept while the box they solve on keeps
 * its size (a box around the band plus 6 sqrt(t) on each side, grown to hold
 * the cells read at themselves), so repeated calls (a simulation's time steps)
 * mostly pay only for the solves. Not thread-safe. The caller owns *out. */
HV_API hv_status hv_extender_create(hv_extender **out, int dim, const int n[3], double h,
                                    const uint8_t *solid, const hv_extend_opts *opts);

HV_API void hv_extender_destroy(hv_extender **e);

/* Extends nfields fields off the zero set of phi (one value per cell, the
 * extender's shape). All right-hand sides (the weights, and per field its
 * components, plus the magnitude of vectors) are solved with the same solver.
 * Constant fields come back unchanged to float rounding. stats may be NULL.
 * Fails with HV_ERR_INVALID_ARG when no cell has |phi| < band*h. Reports
 * progress through hv_set_progress before each diffusion level ("extend"); a
 * cancel returns HV_ERR_CANCELLED with the outputs partly written (the
 * opencl path reports none). */
HV_API hv_status hv_extend_many(hv_extender *e, const float *phi, int nfields,
                                const hv_extend_field *fields, hv_extend_stats *stats);

/* Grid wrappers: phi, field(s) and out(s) must have the extender's shape and
 * voxel size, and share their origin. */
HV_API hv_status hv_extend_scalar(hv_extender *e, const hv_grid *phi, const hv_grid *field,
                                  hv_grid *out, hv_extend_stats *stats);
HV_API hv_status hv_extend_vec3(hv_extender *e, const hv_grid *phi, const hv_grid *const in[3],
                                hv_grid *const out[3], hv_extend_stats *stats);

/* ---- Extension on narrow bands (sparse) --------------------------------- */

/* One field on tiles, extended in place: ncomp = 1 (scalar) or 3 (vector),
 * v[c] on the level set's tiles (the same tiles in the same order, as
 * hv_vdb_read_tiles_like gives them). On entry: the field, read where the
 * weight is positive; on return: the extension on the output cells, which
 * become the tiles' active voxels, and `background` elsewhere. */
typedef struct hv_extend_tiles_field {
    int ncomp;
    hv_tiles *v[3];
} hv_extend_tiles_field;

/* hv_extend_many on a narrow-band level set given as tiles (hv_tiles, on the
 * extender's block and voxel size), without a dense grid: the output cells are
 * the level set's active voxels with |phi| < out_band h (every active voxel
 * when out_band is 0); cells of the block outside the tiles hold the level
 * set's background, with the sign of the neighbouring cells. Each diffusion
 * time is solved by Chebyshev sweeps on the cells near the weights and the
 * cells read, grown by 6 sqrt(t) voxels, as hv_extend_many's band solve does
 * (the values agree with it on the band to float rounding); the levels stop at
 * the first whose reach covers the output band. The extender keeps its maps
 * and work arrays between calls, so a level set that moves from call to call
 * costs no new set-up. With the opencl backend (or auto on a GPU) every
 * step runs on the device, which gives the same values bit for bit; it keeps
 * maps of the block's tiles there, 268 bytes a tile (2048^3: 4.5 GB), needs
 * double precision and takes at most 17 right-hand sides; auto keeps the CPU
 * where those maps would be more than 8 times the band and its fields (plus
 * 256 MB), and falls back to it where the device cannot run the call. An
 * extender with solid cells is refused (HV_ERR_INVALID_ARG). NaN/Inf in the
 * level set or in a field where it is read: HV_ERR_NUMERIC, the fields
 * unchanged (other failures, out of memory or a cancel, can leave them partly
 * extended). The fields' values at the cells read are copied compactly
 * first, so the extension needs no second copy of the tiles. stats: also
 * tiles, work_bytes and on_device. */
HV_API hv_status hv_extend_tiles(hv_extender *e, const hv_tiles *phi, int nfields,
                                 hv_extend_tiles_field *f, hv_extend_stats *stats);

/* An extender whose level set and fields are device buffers on the caller's
 * OpenCL context (hv_opencl_extender_create, hv_opencl_extend) is
 * declared in opencl.h, with the other entries that take OpenCL objects. */

#ifdef __cplusplus
}
#endif
#endif
