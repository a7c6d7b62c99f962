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

#ifdef __cplusplus
extern "C" {
#endif

/* 1 when this build has the petsc backend, 0 otherwise. */
HV_API int hv_petsc_available(void);

/* Ends PETSc (and MPI, when PETSc started it) if a petsc solver started it
 * and it is still up; does nothing otherwise. Call once, at the end. */
HV_API void hv_petsc_finalize(void);

/* This process's rank in MPI_COMM_WORLD once MPI is up, else 0. */
HV_API int hv_mpi_rank(void);

/* The ranks in MPI_COMM_WORLD once MPI is up, else 1. */
HV_API int hv_mpi_size(void);

#ifdef __cplusplus
}
#endif

#endif
