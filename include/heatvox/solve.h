/*
 * Linear solves (alpha*I - beta*Laplacian) u = f on a cell-centred grid with
 * Neumann walls and optional solid cells: the backward-Euler heat step
 * (alpha = 1, beta = t) and Neumann Poisson (alpha = 0).
 *
 * One interface, backends chosen at run time:
 *   HV_BACKEND_MG      matrix-free geometric multigrid on the CPU (any grid, masks)
 *   HV_BACKEND_FFTW    exact DCT-II solve (plain boxes only)
 *   HV_BACKEND_OPENCL  multigrid on an OpenCL device
 *   HV_BACKEND_PETSC   CG + hypre PFMG or BoomerAMG over MPI ranks (petsc.h;
 *                      builds with PETSc)
 *   HV_BACKEND_AUTO    FFTW for plain boxes, multigrid otherwise
 *
 * Lifecycle (PETSc-like): hv_solver_create (plans, hierarchies: expensive, once)
 * -> hv_solver_solve (repeatable, cheap) -> hv_solver_destroy(&s).
 * A solver object is not thread-safe; use one per thread.
 *
 * Poisson (alpha = 0): the right-hand side is projected onto the range
 * (mean-free in every connected fluid region) and the mean-free solution is
 * returned. Not converging is not an error: hv_solve_info says why it stopped.
 */
#ifndef HEATVOX_SOLVE_H
#define HEATVOX_SOLVE_H

#include "grid.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum hv_backend {
    HV_BACKEND_AUTO = 0,
    HV_BACKEND_MG,
    HV_BACKEND_FFTW,
    HV_BACKEND_OPENCL,
    HV_BACKEND_PETSC /* distributed over MPI ranks with PETSc (petsc.h; make mpi) */
} hv_backend;

typedef enum hv_smoother {
    HV_SMOOTH_RBGS = 0,  /* red-black Gauss-Seidel (CPU default) */
    HV_SMOOTH_JACOBI,    /* weighted Jacobi, omega 6/7 (3D) or 4/5 (2D) */
    HV_SMOOTH_CHEBYSHEV, /* Chebyshev on D^-1 A, degree 4 (GPU default) */
    HV_SMOOTH_AUTO       /* the backend's default: RBGS (mg), CHEBYSHEV (opencl) */
} hv_smoother;

typedef enum hv_coarse {
    HV_COARSE_AUTO = 0,   /* geometric; mg and opencl with solid cells change to aggregation
                              within a solve whose first 4 iterations show it would take more
                              than 16, for that solve and the ones that follow */
    HV_COARSE_GEOMETRIC,  /* halved grids with averaged coefficients (every backend) */
    HV_COARSE_AGGREGATION /* mg and opencl with solid cells: smoothed aggregation, Galerkin
                              coarse operators that keep every wall (docs/METHOD.md) */
} hv_coarse;

typedef enum hv_stop_reason {
    HV_STOP_NONE = 0,
    HV_STOP_CONVERGED, /* relative residual <= tol */
    HV_STOP_MAX_ITER,  /* max_iter reached above tol */
    HV_STOP_STAGNATED, /* residual stopped decreasing above tol */
    HV_STOP_EXACT      /* direct solve (FFTW) */
} hv_stop_reason;

HV_API const char *hv_backend_name(hv_backend b);
/* Parses "auto", "mg", "fftw", "opencl", "petsc"; HV_ERR_INVALID_ARG otherwise. */
HV_API hv_status hv_backend_parse(const char *s, hv_backend *out);
HV_API const char *hv_stop_reason_str(hv_stop_reason r);

/* Grids below this many cells keep AUTO on the CPU even with a GPU (kernel
 * launches and device set-up cost more than the solve there). */
#define HV_AUTO_DEVICE_MIN_CELLS ((size_t)1 << 20)

/* The backend that b stands for on a grid of `cells` cells (`solid`: it has
 * solid cells). Every backend but AUTO comes back unchanged. AUTO becomes
 * OPENCL when the device the opencl backend would use (opencl.h) is a GPU and
 * the grid has at least HV_AUTO_DEVICE_MIN_CELLS cells, else FFTW for a plain
 * box and MG with solid cells. A CPU OpenCL device (PoCL) is not taken: the
 * CPU multigrid is several times faster on the same cores. The devices are
 * probed once per process (no context is created); when no OpenCL platform
 * is installed that probe logs one warning (HV_LOG_WARN) and AUTO stays on
 * the CPU. HEATVOX_AUTO_OPENCL=0 keeps AUTO on the CPU; =1 lets it take any
 * OpenCL device, a CPU one too, whatever the size. */
HV_API hv_backend hv_backend_resolve(hv_backend b, size_t cells, int solid);

typedef struct hv_problem {
    int dim;              /* 2 or 3 */
    int n[3];             /* n[2] ignored in 2D */
    double h;             /* voxel size */
    const uint8_t *solid; /* NULL or one byte per cell; copied at create */
    double alpha;         /* >= 0 */
    double beta;          /* > 0 */
} hv_problem;

typedef struct hv_solver_opts {
    hv_backend backend;   /* default AUTO */
    hv_smoother smoother; /* default AUTO: RBGS (mg), CHEBYSHEV (opencl) */
    double tol;           /* relative residual ||f - A u|| / ||f||, default 1e-6; >= 1e-12 */
    int max_iter;         /* outer iterations (cycles), default 50 */
    int pre_smooth;       /* default 2 */
    int post_smooth;      /* default 2 */
    int nonzero_guess;    /* 1: u holds an initial guess on entry; default 0 */
    int fftw_double;      /* FFTW backend: 1 = double transforms, 0 = float; default 1 */
    const char
        *wisdom_file; /* FFTW wisdom loaded at create and saved after planning; NULL = none */
    int fftw_measure; /* 1: FFTW_MEASURE planning, 0: FFTW_ESTIMATE; default 0 */
    int cycles_per_iteration; /* mg, plain grid: V-cycles per double-precision correction;
                                 0 (default) = as many as the tolerance needs (1..3, RBGS),
                                 else that many (1..8) */
    hv_coarse coarse;         /* mg's coarse levels, default AUTO */
} hv_solver_opts;

#define HV_MAX_HISTORY 64

typedef struct hv_solve_info {
    hv_backend backend; /* the backend that ran */
    hv_stop_reason reason;
    int iterations;                 /* outer iterations: corrections or CG iterations */
    int cycles;                     /* V-cycles run (mg: >= iterations); 0 when not counted */
    double relres;                  /* final relative residual (double precision) */
    int nhistory;                   /* entries in history (capped at HV_MAX_HISTORY) */
    double history[HV_MAX_HISTORY]; /* relres after each iteration; history[0] = initial */
    double seconds;                 /* wall time of this solve */
    /* Timed V-cycles (mg on plain grids: every cycle but the FMG start): their
     * wall time and modelled memory traffic, so cycle_bytes / cycle_seconds is
     * the V-cycle's own effective bandwidth; 0 when not timed. */
    int cycles_timed;
    double cycle_seconds;
    double cycle_bytes;
} hv_solve_info;

typedef struct hv_solver hv_solver;

HV_API void hv_solver_opts_default(hv_solver_opts *o);

/* Builds the solver for problem p (copies p->solid). opts may be NULL (defaults).
 * AUTO picks FFTW when there is no mask and MG otherwise; an explicit FFTW with a
 * mask fails with HV_ERR_UNSUPPORTED. The caller owns *out. */
HV_API hv_status hv_solver_create(hv_solver **out, const hv_problem *p, const hv_solver_opts *opts);

/* Solves A u = f. f and u are arrays of the grid's cell count; values on solid
 * cells of f are ignored and u is 0 there. info may be NULL.
 * Fails with HV_ERR_NUMERIC if f holds NaN/Inf. */
HV_API hv_status hv_solver_solve(hv_solver *s, const float *f, float *u, hv_solve_info *info);
HV_API hv_status hv_solver_solve_d(hv_solver *s, const double *f, double *u, hv_solve_info *info);

/* Solves k right-hand sides that share the operator (same hierarchy / plans).
 * info is NULL or an array of k entries. */
HV_API hv_status hv_solver_solve_many(hv_solver *s, int k, const float *const *f, float *const *u,
                                      hv_solve_info *info);

#define HV_MAX_LEVELS 40

typedef struct hv_solver_stats {
    int levels;                 /* multigrid levels (1 for direct solvers) */
    int n[HV_MAX_LEVELS][3];    /* cells per axis on each level */
    int plain[HV_MAX_LEVELS];   /* 1 where a level needs no coefficient arrays */
    double bytes_per_iteration; /* modelled memory traffic of one outer iteration (one cycle) */
    double bytes_per_cycle;     /* of each further V-cycle in an iteration (0: not modelled) */
    size_t memory_bytes;        /* memory held by the backend's arrays */
    int aggregation_levels;     /* mg: levels of the aggregation hierarchy in use, 0 if none */
} hv_solver_stats;

/* Describes the backend's data structures (for benchmarks and tests). */
HV_API hv_status hv_solver_get_stats(const hv_solver *s, hv_solver_stats *st);

HV_API hv_backend hv_solver_backend(const hv_solver *s);
HV_API const hv_problem *hv_solver_problem(const hv_solver *s);

HV_API void hv_solver_destroy(hv_solver **s);

#ifdef __cplusplus
}
#endif
#endif
