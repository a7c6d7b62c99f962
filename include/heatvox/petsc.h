/*
 * MPI and PETSc: the petsc solver backend (HV_BACKEND_PETSC, solve.h) in
 * builds made with `make mpi`. Programs run SPMD under mpirun: every rank
 * makes the same hv_solver calls with the same whole grid, the solve is
 * distributed over the ranks of PETSC_COMM_WORLD (a DMDA box per rank, CG with
 * hypre's BoomerAMG), and every rank gets the whole solution. The first petsc
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

/* 1 when this build has the petsc backend, 0 otherwise. */
HV_API int hv_petsc_available(void);

/* Starts PETSc (and MPI, when the program has not) if it is not up: programs
 * that want their rank before the first petsc solver call this first (the
 * heatvox command does for --backend petsc). HV_ERR_UNSUPPORTED without
 * PETSc. */
HV_API hv_status hv_petsc_init(void);

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
 * centred on the cells. Collective over PETSC_COMM_WORLD: every rank passes
 * the same grids, and each writes its own box of the distributed grid into
 * the file (MPI-IO). Both files are written under temporary names and renamed
 * into place by rank 0; on error neither is left behind. Starts PETSc if it
 * is not up; HV_ERR_UNSUPPORTED without PETSc. */
HV_API hv_status hv_petsc_write_h5(const char *path, int nfields, const hv_grid *const *g,
                                   const char *const *names);

#ifdef __cplusplus
}
#endif

#endif
