/*
 * MPI and PETSc: the petsc solver backend (HV_BACKEND_PETSC, solve.h) in
 * builds with PETSc (`make mpi`, or `make` where Debian's petsc-dev is
 * installed), the distance and extension on a PETSc DMDA, and parallel HDF5.
 * Programs run SPMD under mpirun (without it, one rank): every rank
 * makes the same hv_solver calls with the same whole grid, the solve is
 * distributed over the ranks of PETSC_COMM_WORLD (a DMDA box per rank, CG with
 * hypre's PFMG or BoomerAMG), and every rank gets the whole solution. The first petsc
 * solver initializes PETSc (and MPI) when the program has not;
 * hv_petsc_finalize ends them before the program exits. In builds without
 * PETSc these functions exist, hv_petsc_available returns 0 and the backend's
 * solvers fail with HV_ERR_UNSUPPORTED.
 */
#ifndef HEATVOX_PETSC_H
#define HEATVOX_PETSC_H

#include "core.h"
#include "grid.h"

#ifdef __cplusplus
extern "C" {
#endif

/* The solver's and the features' options and results (solve.h, heat.h), by
 * pointer: petsc.h sits below them. */
typedef struct hv_solver_opts hv_solver_opts;
typedef struct hv_solve_info hv_solve_info;
typedef struct hv_distance_sources hv_distance_sources;
typedef struct hv_distance_opts hv_distance_opts;
typedef struct hv_distance_stats hv_distance_stats;
typedef struct hv_extend_opts hv_extend_opts;
typedef struct hv_extend_stats hv_extend_stats;
typedef struct hv_extend_field hv_extend_field;

/* 1 when this build has the petsc backend, 0 otherwise. */
HV_API int hv_petsc_available(void);

/* Starts PETSc (and MPI, when the program has not) if it is not up: programs
 * that want their rank before the first petsc solver call this first (the
 * heatvox command does for --backend petsc). HV_ERR_UNSUPPORTED without
 * PETSc. */
HV_API hv_status hv_petsc_init(void);

/* Sets a PETSc option (as -name value on PETSc's command line; value may be
 * NULL), starting PETSc if it is not up. heatvox's own option:
 *   -hv_petsc_pc auto|boomeramg|pfmg|gamg   the preconditioner of the
 *        petsc backend and of the solvers on a DMDA: auto (the default)
 *        takes hypre's structured PFMG on 3D grids, the fastest on thin
 *        walls, except for Poisson problems with more than one fluid region,
 *        where PFMG breaks down (the solve reports HV_STOP_STAGNATED), and on
 *        2D grids, which take hypre's BoomerAMG; or BoomerAMG, PFMG or
 *        PETSc's GAMG;
 * PETSc's own (-ksp_*, -pc_hypre_*, -pc_gamg_*) tune them further. Read when
 * a solver is created. PETSc's options are per process: set them alike on
 * every rank (ranks that chose different preconditioners would fail or
 * hang). HV_ERR_UNSUPPORTED without PETSc. */
HV_API hv_status hv_petsc_option(const char *name, const char *value);

/* Ends PETSc (and MPI, when PETSc started it) if a petsc solver started it
 * and it is still up; does nothing otherwise. Call once, at the end. */
HV_API void hv_petsc_finalize(void);

/* This process's rank in MPI_COMM_WORLD once MPI is up, else 0. */
HV_API int hv_mpi_rank(void);

/* The ranks in MPI_COMM_WORLD once MPI is up, else 1. */
HV_API int hv_mpi_size(void);

/* Writes nfields dense fields of one block (grids g[0..nfields-1], same
 * dimensions, voxel size and origin) as parallel HDF5, and an XDMF sidecar
 * that ParaView and VisIt open: path (".h5") gets one dataset per field,
 * "/<name>", float64, shape (nz, ny, nx) (2D: (ny, nx)), x fastest, each with
 * the attributes "spacing" (h along x, y, z) and "origin" (the world position
 * of the block's lower corner, x y z; the first cell's centre is origin +
 * h / 2); the sidecar is path with ".h5" replaced by ".xmf" (or ".xmf"
 * appended): a co-rectilinear grid of the cell corners with the fields
 * centred on the cells. Collective over PETSC_COMM_WORLD: rank 0's grids
 * are written (the other ranks pass the same nfields and names, and their g
 * is not read: NULL will do); they are scattered over the ranks, and each
 * writes its own box into the file (MPI-IO). Both files are written under temporary names and renamed
 * into place by rank 0; on error neither is left behind. Starts PETSc if it
 * is not up; HV_ERR_UNSUPPORTED without PETSc. */
HV_API hv_status hv_petsc_write_h5(const char *path, int nfields, const hv_grid *const *g,
                                   const char *const *names);

/* ---- on the caller's DMDA ------------------------------------------------
 *
 * For simulations that keep their fields in PETSc: the solves and the
 * extension on the caller's DMDA and Vecs, called every time step, with the
 * set-up made once. PETSc's own handles, declared as petscdmda.h declares
 * them (this header needs no PETSc headers). The DMDA: 2D or 3D, one degree
 * of freedom, no periodic boundaries, cell-centred cells of size h (the
 * cell (i, j, k) centred at origin + (i + 1/2) h); any ownership ranges and
 * stencil. Every call is collective over the DMDA's communicator. Builds
 * without PETSc have these functions; they fail with HV_ERR_UNSUPPORTED. */
typedef struct _p_DM *DM;
typedef struct _p_Vec *Vec;

/* (alpha I - beta Lap) u = f on the DMDA's cells: Neumann walls at the grid's
 * faces, and at solid cells (solid: NULL, or a global vector of the DMDA,
 * non-zero = solid; read once, at create), whose rows are the identity. For
 * alpha = 0 the null space is one constant per connected fluid region,
 * labelled across the ranks at create (the solution has zero mean on each).
 * Conjugate gradients preconditioned by hypre's PFMG or BoomerAMG
 * (-hv_petsc_pc, hv_petsc_option), to opts->tol (the
 * true residual relative to ||f||) within opts->max_iter iterations; the
 * other fields of opts are ignored; NULL = the defaults. The matrix, the
 * preconditioner and the work vectors are made here and reused by every
 * solve. */
typedef struct hv_dmda_solver hv_dmda_solver;
HV_API hv_status hv_dmda_solver_create(hv_dmda_solver **out, DM da, double h, double alpha,
                                       double beta, Vec solid, const hv_solver_opts *opts);

/* u = the solution for f (both global vectors of the DMDA; u holds the
 * initial guess when opts->nonzero_guess was set). info (may be NULL): the
 * iterations, the residual history and the reason, the same on every rank.
 * hv_dmda_solver_regions: the fluid regions found at create (alpha = 0),
 * else 0. */
HV_API hv_status hv_dmda_solver_solve(hv_dmda_solver *s, Vec f, Vec u, hv_solve_info *info);
HV_API int hv_dmda_solver_regions(const hv_dmda_solver *s);
HV_API void hv_dmda_solver_destroy(hv_dmda_solver **s);

/* The extension off a level set (hv_extend_many, heat.h) on the DMDA's
 * cells, without gathering the grid: each rank classifies and evaluates its
 * own box with a ghost layer as wide as the closest points reach; the first
 * diffusion level runs on each rank's box where the boxes are wide enough
 * for the ghost layer to hold all it depends on, and otherwise, like later
 * levels, over all ranks on the whole grid, its solutions exchanged into the
 * ghost layers. opts->out_band (0 to 64 voxels) gives the cells written:
 * |phi| < out_band h, or every cell with 0; there are no obstacles;
 * opts->backend is ignored. The ghost layer (hv_dmda_extender_ghost) is
 * ceil(1.5 W) + 2 cells (W = out_band, or the weights' band with out_band
 * 0), or the wider layer of the first level on each box (29 cells at
 * out_band 3, 26 with out_band 0); every rank's box must be at least that
 * wide. A cell whose closest point's stencil lies past what the ghost layer
 * holds of the first level (its whole width, or with the band solve on each
 * box ceil(1.5 W) cells of it; with out_band 0, cells far from the surface)
 * reads those cells from the ranks that own them: one exchange of the stencils' cells and their phi before
 * the first level and one of their solutions after it, in proportion to
 * the surface those cells see, not to the box. Cells read at themselves
 * (where phi is no distance: medial axes, clamped narrow bands) take the
 * first level whose weight passes its solve's trust bound; past the first
 * level the ranks' solves are converged to opts->tol, and such cells equal
 * those of hv_extend_many with box_only = 1 (its default solves level 1 on
 * a band with a looser bound, so they may settle a level apart). The
 * solvers of the levels are made on first use and kept. */
typedef struct hv_dmda_extender hv_dmda_extender;
typedef struct hv_dmda_field {
    int ncomp; /* 1 (scalar) to 3 (vector) */
    Vec v[3];  /* global vectors of the DMDA, extended in place */
} hv_dmda_field;
HV_API hv_status hv_dmda_extender_create(hv_dmda_extender **out, DM da, double h,
                                         const hv_extend_opts *opts);

/* Extends the fields in place off the zero set of phi (a global vector of
 * the DMDA, a signed distance near its zero set): cells with |phi| < out_band
 * h (phi rounded to float, as the extension reads it), or every cell with
 * out_band 0, get the values carried from the surface, the others keep
 * theirs. stats (may be NULL): the counts are this rank's box with its ghost
 * layer (remote_cells: this rank's own cells read past it); levels, solves
 * and relres are the same on every rank. HV_ERR_NUMERIC (on every
 * rank) for a non-finite phi, or a field where it is read, on any rank; the
 * fields are then unchanged. */
HV_API hv_status hv_dmda_extend(hv_dmda_extender *e, Vec phi, int nfields,
                                const hv_dmda_field *fields, hv_extend_stats *stats);
HV_API void hv_dmda_extender_destroy(hv_dmda_extender **e);

/* The extender's ghost layer in cells, and whether its level 0 takes the
 * band solve on each rank's box (*band0 = 1: no communication for it; the
 * layer is then wide enough for the band solve, which needs every rank's box
 * at least that wide) or is solved over all ranks (*band0 = 0). */
HV_API int hv_dmda_extender_ghost(const hv_dmda_extender *e, int *band0);

/* The extension of a whole block held by rank 0, distributed over the ranks
 * of PETSC_COMM_WORLD (heatvox extend --backend petsc under mpirun): the
 * block (dim, n, h, the options and the fields' component counts the same
 * on every rank) becomes a DMDA, rank 0's phi and fields are
 * scattered to the ranks' boxes, each rank extends its box (hv_dmda_extend),
 * and the results are gathered into rank 0's outputs: the extended values
 * where |phi| < opts->out_band h, opts->background elsewhere (out_band 0:
 * every cell).
 * Only rank 0 passes arrays (phi, f[i].in, f[i].out), and its n and h are
 * the block's; the other ranks pass NULL arrays. Rank 0 passing phi = NULL
 * (it could not read the block) makes every rank return an error. stats:
 * levels, solves and relres are the run's; the cell counts are rank 0's box
 * with its ghost layer. Collective; the same status on every rank. */
HV_API hv_status hv_petsc_extend_block(int dim, const int n[3], double h,
                                       const hv_extend_opts *opts, const float *phi, int nfields,
                                       const hv_extend_field *f, hv_extend_stats *stats);

/* The heat-method distance (hv_distance_compute, heat.h) on the DMDA's
 * cells, without gathering the grid: each rank splats the sources, assigns
 * the face directions and builds the fronts on its own box with a ghost
 * layer of 4 cells (every rank's box must be at least that wide where the
 * grid is split); the heat and Poisson solves run over all ranks (CG with
 * the preconditioner of -hv_petsc_pc), and the counts and the per-region
 * shift are summed over the ranks. The result is
 * the single process's up to the solves' tolerances. origin: the world
 * position of the grid's lower corner (for point and mesh sources; NULL =
 * 0); solid: NULL or a global vector of the DMDA (non-zero = solid), read
 * once, here, where its fluid regions are labelled across the ranks (kept
 * with the ghost exchange for every call); opts: as hv_distance_compute's
 * (backend ignored; NULL = the defaults). Each call makes its solvers (the
 * two heat steps, then Poisson once they are freed: no more than two
 * multigrid hierarchies at once, for about 3% of the call's time). With the
 * PETSc option -hv_distance_keep_solvers true (hv_petsc_option, read here),
 * the object makes all three once and keeps them for every call: the
 * memory of a third hierarchy for that time (docs/PERFORMANCE.md). */
typedef struct hv_dmda_distance hv_dmda_distance;
HV_API hv_status hv_dmda_distance_create(hv_dmda_distance **out, DM da, double h,
                                         const double origin[3], Vec solid,
                                         const hv_distance_opts *opts);

/* dist (a global vector of the DMDA) = the distance from src (the same
 * sources on every rank; world coordinates, voxel indices of the whole
 * grid). stats (may be NULL): as hv_distance_compute's, summed over the
 * ranks, the same on every rank; no progress is reported. Errors are those
 * of hv_distance_compute, on every rank. */
HV_API hv_status hv_dmda_distance_compute(hv_dmda_distance *d, const hv_distance_sources *src,
                                          Vec dist, hv_distance_stats *stats);
HV_API void hv_dmda_distance_destroy(hv_dmda_distance **d);

/* The distance of a whole grid held by rank 0, distributed over the ranks
 * of PETSC_COMM_WORLD (heatvox distance --backend petsc under mpirun): rank
 * 0 passes its grid (with its solid mask, if any) and the sources, the other
 * ranks NULL for both; the grid's shape, the mask, the sources and opts go
 * to every rank, each computes its box (hv_dmda_distance_compute), and the result
 * is gathered into rank 0's g->v. A NULL grid on rank 0 (it could not read
 * its input) makes every rank return an error. Collective; the same status
 * and stats on every rank. */
HV_API hv_status hv_petsc_distance_block(hv_grid *g, const hv_distance_sources *src,
                                         const hv_distance_opts *opts, hv_distance_stats *stats);

#ifdef __cplusplus
}
#endif

#endif
