/* Private: pieces of the heat-method distance shared between its files: the
 * object and its entries (distance_heat.c), the stages (distance_march.c),
 * their tiles and local solves (distance_band.c), the sources
 * (distance_sources.c), the device path (distance_cl.c) and the lattice and
 * front rules (distance_front.c). */
#ifndef HV_HEAT_DISTANCE_INTERNAL_H
#define HV_HEAT_DISTANCE_INTERNAL_H

#include "heatvox/heat.h"

#include <stdint.h>

#define HV_DIST_REF_RADIUS 3.0

/* A cell is trusted in a stage when u (both times) is above RELIABLE * (solve
 * error bound) * sqrt(t)/h: the solve error is at most relres * ||f||_2
 * pointwise (the heat operator's inverse has norm <= 1), and a face difference
 * of u is about u h / sqrt(t). */
#define RELIABLE 1e3
/* The next front lies where ln u(t) is FRONT_MARGIN above the trust bound:
 * about FRONT_MARGIN sqrt(t) inside the trusted zone, so that the next
 * stage's directions are in place before this stage's give out. */
#define FRONT_MARGIN 8.0
/* Each stage diffuses for t and T_RATIO t: where the heat has bent around an
 * obstacle its amplitude A varies across the rays, and grad ln u = -grad d /
 * sqrt(t) + grad ln A tilts the direction (diffraction; a voxel or two of error
 * behind a corner). grad ln A hardly depends on t, so in ln u(t) - ln u(2t) =
 * -d (1/sqrt t - 1/sqrt 2t) it cancels. Measured at 128^2 (mean error in
 * voxels, one t -> two): a wall with a gap 1.36 -> 0.71, an L-shaped room
 * 0.68 -> 0.32. 2t rather than 4t: the second step's operator is better
 * conditioned (a fifth fewer sweeps) and bends less at the walls (smaller
 * errors against every exact distance measured; docs/METHOD.md, "Heat
 * method", step 3). */
#define T_RATIO 2.0
/* Half width of a front, in voxels (weights (1 - (s/FRONT_BAND)^2)^2). */
#define FRONT_BAND 1.5

/* kappa h of the lattice plane wave travelling normal to direction nu (unit):
 * sum_b 2 (cosh(kappa h nu_b) - 1) = tau (Newton from the continuum value). */
double hv__dist_lattice_kappa(const double nu[3], int dim, double tau);

/* The trust bound on ln u of a diffusion for t_scale h^2 (t_scale itself, or
 * times T_RATIO): ln(RELIABLE * relres * ||w||_2 * sqrt(t_scale)), relres
 * floored at 1e-14, for the solve's relative residual relres and the norm wn
 * of the front weights w. Callers pass the larger of the achieved residual
 * and the requested tolerance: the trusted faces then depend on what every
 * backend guarantees, not on how far below it one happened to stop, so the
 * backends (and the petsc backend on any number of ranks) trust the same
 * faces and give the same distances. */
double hv__dist_trust_log(double relres, double wn, double t_scale);

/* Voxels from the current front to the next: where ln u(t) (lu0 on the
 * current front) falls to FRONT_MARGIN above the trust bound lthr, at the
 * axis-aligned lattice decay rate for tau = h^2 / t. Below 2: no progress. */
double hv__dist_front_step(double lu0, double lthr, int dim, double tau);

/* kappa h of the axis-aligned lattice plane wave for tau = h^2 / t. */
double hv__dist_axis_kappa(int dim, double tau);
/* The core's reach in tiles for a trusted distance of `voxels` from the
 * front: every cell that far from a front cell lies on a core tile. */
int hv__dist_next_reach(double voxels);

/* The options' and the sources' checks of hv_distance_compute, and its error
 * when no source landed on a fluid cell (HV_OK when one did). */
hv_status hv__dist_check_opts(const hv_distance_opts *o, const hv_distance_sources *src);
/* A solver of (alpha - beta Lap) on the grid (dim, n, h, solid) for the
 * heat method's stages: tolerance tol, at most 200 iterations, on backend
 * with the given coarse levels (distance_solvers.c, as the next). */
hv_status hv__dist_solver(hv_solver **s, int dim, const int n[3], double h, const uint8_t *solid,
                          double alpha, double beta, double tol, hv_backend backend,
                          hv_coarse coarse);
hv_status hv__dist_no_source(const hv_distance_stats *S);
/* The Poisson solve's coarse levels: o->coarse, or with AUTO and obstacles
 * aggregation (one solve to a tight tolerance around walls, where the
 * geometric levels take tens to hundreds of iterations). */
hv_coarse hv__dist_poisson_coarse(const hv_distance_opts *o, const uint8_t *solid);

/* A window of the whole grid: g's cell (0, 0, 0) is the whole grid's cell
 * off; own_lo..own_hi-1 (whole-grid indices) are the cells whose sources
 * this rank counts. */
typedef struct hv_dist_window {
    const hv_grid *full; /* dim, n, h and origin of the whole grid */
    int off[3], own_lo[3], own_hi[3];
} hv_dist_window;

/* Adds the source weights of src onto w (one double per cell of g, zeroed by
 * the caller): voxels weigh 1, points 1 spread trilinearly over the fluid cells
 * among their 8 neighbours, mesh samples their area / h^2 the same way.
 * ref (one float per cell, +INFINITY on entry) receives, on the fluid cells
 * within HV_DIST_REF_RADIUS voxels of a source item (voxel centre, point, mesh
 * sample), the least distance from the cell centre to one: the distance those
 * cells should have (when no obstacle intervenes), used to place the zero.
 * *in_solid counts sources with no fluid cell to land on. win: NULL (g is
 * the whole grid), or g is a window of win->full (a rank's box and its ghost
 * layer, its solid mask with it): sources are checked against the whole grid,
 * those outside the window skipped, and *in_solid counts those whose nearest
 * cell is owned, so that the ranks' counts add up. Weights and ref are exact
 * on the window's cells at least HV_DIST_REF_RADIUS + 1 cells inside its
 * edges (or on the whole grid's). */
hv_status hv__dist_splat(const hv_grid *g, const hv_dist_window *win,
                         const hv_distance_sources *src, double *w, float *ref, size_t *in_solid);

/* What the stages need from where they run: the sums over ranks and the
 * solves. A single process (hv_distance_compute) sums nothing and solves on
 * its grid; on a DMDA (distance_dmda.c) the box is a rank's cells with a
 * ghost layer, sums run over the ranks and the solves over the whole grid,
 * their solutions exchanged into the ghost layer. */
typedef struct hv_dist_hooks {
    void *user;
    /* Sums v[0..n-1] over the ranks, in place. */
    void (*sum)(void *user, double *v, int n);
    /* u (the whole box) = the solution for f (read on the owned cells):
     * q = 0, 1: (I - t Lap) u = f with t = t_scale h^2, T_RATIO t_scale h^2;
     * q = 2: -Lap u = f to poisson_tol (after which q = 0 and 1 are not
     * asked for again). */
    hv_status (*solve)(void *user, int q, const double *f, double *u, hv_solve_info *info);
} hv_dist_hooks;

/* Tiles of the stages (distance_band.c): DIST_TILE cells a side (1 along z
 * on 2D grids). A stage solves on the core tiles, those within `reach` tiles
 * (chessboard) of a tile holding a front weight (behind the front, where every
 * face has its direction, only those next to one), and on a halo ring of tiles around
 * them; only the core's cells are trusted. */
#define DIST_TILE 8
/* The core reaches the next front's band and this many voxels beyond it (or
 * the whole trusted distance, when nearer): faces further out are assigned
 * by the next stage. At 4 the distances equal those of a core that covers
 * the trusted distance (about 26 voxels at t = 2 h^2), on 8% fewer cells (the
 * building at 128). */
#define DIST_CORE_MARGIN 4.0
/* The first stage's reach, in tiles: the sources' heat is trusted about 20
 * voxels out. */
#define DIST_FIRST_REACH 4
/* The band's heat steps are solved in double to this relative residual (or
 * diffuse_tol when tighter): the trust bound, and so each stage's step, moves
 * out by ln(diffuse_tol / DIST_BAND_TOL) / kappa voxels (6.7 at the default
 * 1e-11 and t = 2 h^2) for a few more sweeps. */
#ifndef DIST_BAND_TOL
#define DIST_BAND_TOL 1e-13
#endif

typedef struct hv_dist_tiles {
    int tn[3];           /* cells on a tile's side per axis */
    int nt[3];           /* tiles per axis */
    size_t count, cells; /* tiles; cells of a tile (tn[0] tn[1] tn[2]) */
    int band;            /* 1: stages on the band (hv__dist_band_*); 0: every tile is core
                           and the hooks solve on the whole box */
    uint32_t *list;      /* the stage's tiles, the core (ncore) first, then the halo */
    size_t ncore, nlist;
    int reach; /* the core's radius in tiles */
    /* band mode only (NULL otherwise): per tile */
    int32_t *slot;         /* its place in list, -1 outside the band */
    int32_t *nbr;          /* 6 per listed tile: the slots of its face neighbours (-1 none) */
    int32_t *fluid;        /* its cells in regions with a source */
    int32_t *open_faces;   /* open faces without a direction yet (a face counts in
                              the tile of its upper cell) */
    uint8_t *front;        /* it holds a weight of the current front */
    uint8_t *dist, *dist2; /* chessboard distance to a front tile (capped), scratch */
    /* per band cell (list order, `cells` per tile): 0 off the unknowns, else 1 +
     * its open faces; the right-hand side; the two solves' iterates */
    uint8_t *code;
    double *f, *x[4];
    size_t cap;
} hv_dist_tiles;

/* A box of cells the stages run on: the whole grid, or a rank's box with its
 * ghost layer, whose owned cells are lo..hi-1 (box indices). */
typedef struct hv_dist_box {
    int dim, n[3];
    size_t count, cs[3]; /* cells, cell strides */
    double h;
    const uint8_t *solid;
    int lo[3], hi[3]; /* the owned cells */
    int whole;        /* the box is the whole grid (progress is reported) */
    double tau[2];    /* h^2 / t of the two diffusion times */
    int32_t *region;  /* >= 0: region with a source; -1 solid; -2 fluid without source */
    float *X[3];      /* face directions; NaN = not assigned yet */
    size_t nface[3];
    const hv_dist_hooks *hk;
    hv_dist_tiles tl; /* set up by hv__dist_march */
    int band;         /* the stages solve on tiles near the front (hooks only for Poisson) */
} hv_dist_box;

/* Labels the connected fluid regions of b that hold a source weight of w
 * (b->region, allocated here). */
hv_status hv__dist_label_regions(hv_dist_box *b, const double *w, size_t *nregions,
                                 size_t *unreach);
/* The 2-norm of v over b's owned cells (and the ranks). */
double hv__dist_norm2(const hv_dist_box *b, const double *v);

/* Sets n, count, strides and the face counts of b from dim and n; the owned
 * cells default to all. */
void hv__dist_box_init(hv_dist_box *b, int dim, const int n[3], double h, const uint8_t *solid);

/* The stages, the Poisson solve and the shift (docs/METHOD.md, "Heat method")
 * on the box b: b->region labelled, S->regions set, b->X allocated; w (the
 * source weights, owned cells), ref (the reference distances near the
 * sources) as hv__dist_splat leaves them; u, u2 (doubles), inside (zeroed)
 * and ok (bytes) work arrays of b->count. Writes the distance of every box
 * cell into out (those of the owned cells and, where the ghost layer has
 * what they depend on, others). S's counts are sums over the ranks. */
hv_status hv__dist_march(hv_dist_box *b, const hv_distance_opts *o, double *w, double *u,
                         double *u2, uint8_t *inside, uint8_t *ok, float *ref, float *out,
                         hv_distance_stats *S);

/* Where the stages run: the host's box (distance_march.c) or a device
 * (distance_cl.c). hv__dist_stages is the one loop over either; each method
 * works on the current front and the fields its backend keeps. */
typedef struct hv_dist_stage_ops {
    void *self;
    /* Stage l's two heat steps from the front's weights: sets info (the
     * solves' iterations and residuals) and S's diffusion counts and backend. */
    hv_status (*diffuse)(void *self, int l, hv_solve_info info[2], hv_distance_stats *S);
    /* The trust bounds from info and the front's norm, the cells trusted and
     * the open faces they assign: *lthr the bound on ln u(t), *got the faces
     * assigned, *left the open faces still without a direction. */
    hv_status (*assign)(void *self, const hv_solve_info info[2], double *lthr, size_t *got,
                        size_t *left);
    /* The next front, a margin inside the trusted zone (lthr); *moved is 0
     * where none can be placed. */
    hv_status (*advance)(void *self, double lthr, int *moved, hv_distance_stats *S);
} hv_dist_stage_ops;

/* The stages (docs/METHOD.md, "Heat method", step 4) until every one of the
 * open faces has a direction, two stages pass without a new one or the front
 * stops; progress (whole grids): reports "diffuse" before each stage. Sets
 * S's stage counts and times; *left: the faces left open. */
hv_status hv__dist_stages(const hv_dist_stage_ops *ops, const hv_distance_opts *o, size_t open,
                          int progress, size_t *left, hv_distance_stats *S);

/* Tile t's first cell (box indices) and its cell counts per axis. */
static inline void hv__dist_tile_cells(const hv_dist_box *b, size_t t, int lo[3], int len[3])
{
    size_t r = t;
    for (int a = 0; a < 3; a++) {
        int ta = (int)(r % (size_t)b->tl.nt[a]);
        r /= (size_t)b->tl.nt[a];
        lo[a] = ta * b->tl.tn[a];
        len[a] = b->n[a] - lo[a] < b->tl.tn[a] ? b->n[a] - lo[a] : b->tl.tn[a];
    }
}

/* The tiles of box b (band: the stages' band mode); every tile listed as
 * core. Fails only out of memory. hv__dist_tiles_free releases them. */
hv_status hv__dist_tiles_init(hv_dist_box *b, int band);
void hv__dist_tiles_free(hv_dist_tiles *T);
/* Band mode: counts the tiles' reachable cells (b->region set). */
void hv__dist_tiles_fluid(hv_dist_box *b);
/* Band mode: hv__dist_tiles_fluid, the tiles' open faces without a direction
 * (b->X set up) and the tiles holding a weight of w as the front. */
void hv__dist_tiles_start(hv_dist_box *b, const double *w);
/* The largest step that keeps the next front (and its band) on the core
 * tiles; INFINITY without a band. */
double hv__dist_core_step(const hv_dist_tiles *T);
/* The next stage's reach, from this stage's full step (voxels) at tau. */
void hv__dist_core_next(hv_dist_tiles *T, double full, int dim, double tau);
/* Band mode: clears ok (when not NULL) on the previous core tiles' cells,
 * then chooses the stage's tiles around the front tiles and builds the band's
 * codes. */
hv_status hv__dist_band_select(hv_dist_box *b, uint8_t *ok);
/* Band mode: (I - t Lap) u = w and (I - T_RATIO t Lap) u2 = w on the band
 * (u = 0 beyond it), to the relative residual tol; writes u and u2 on the
 * core tiles' cells. info: sweeps and the measured relative residuals. */
hv_status hv__dist_band_solve(hv_dist_box *b, const double *w, double *u, double *u2, double tol,
                              hv_solve_info info[2]);
/* Chebyshev sweeps for the relative residual tol at s = t / h^2; the square
 * of the Jacobi-scaled spectral radius bound at s, and the weight of sweep
 * k + 1 from that of sweep k (the first is 1), for the host's and the
 * device's sweeps alike. */
int hv__dist_band_sweeps(int dim, double s, double tol);
double hv__dist_band_rho2(int dim, double s);
double hv__dist_band_omega(double omega, double rho2, int k);
/* The reachable cells of the stage's tiles (core and halo). */
size_t hv__dist_band_cells(const hv_dist_box *b);

#endif
