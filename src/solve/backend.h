/*
 * Private: the interface every solver backend implements. The front end
 * (solver.c) validates arguments, checks right-hand sides for NaN/Inf, labels
 * connected fluid regions, projects Poisson right-hand sides onto the range and
 * converts float arrays; a backend only solves. A distributed backend (MPI with
 * hypre or PETSc) implements this same table.
 */
#ifndef HV_SOLVE_BACKEND_H
#define HV_SOLVE_BACKEND_H

#include "heatvox/solve.h"

typedef struct hv_setup {
    hv_problem p;          /* p.solid points at the front end's copy (or NULL) */
    hv_solver_opts o;      /* defaults filled in */
    size_t count;          /* cells */
    int nregion;           /* connected fluid regions (1 without a mask) */
    const int32_t *region; /* NULL without a mask; else region id per cell, -1 on solid */
} hv_setup;

typedef struct hv_backend_ops {
    const char *name;
    /* Builds backend state for the setup (which outlives the state). */
    hv_status (*create)(void **state, const hv_setup *s);
    /* Solves A u = f in double precision. f is finite, zero on solid cells and,
     * for alpha == 0, mean-free in every region. u holds the initial guess when
     * s->o.nonzero_guess is set, else anything. On return u is zero on solid
     * cells and, for alpha == 0, mean-free per region. Fills info (never NULL)
     * except backend and seconds. */
    hv_status (*solve)(void *state, const double *f, double *u, hv_solve_info *info);
    /* Several right-hand sides at once; NULL means the front end loops. */
    hv_status (*solve_many)(void *state, int k, const double *const *f, double *const *u,
                            hv_solve_info *info);
    void (*destroy)(void *state);
    /* Fills levels, sizes, traffic model and memory; NULL: the front end reports one level. */
    void (*stats)(const void *state, hv_solver_stats *st);
    /* The float interface straight, where the backend keeps its own copies
     * (opencl: floats to the device and back, once each way): f as the
     * caller gave it (finite; not projected, not zeroed on solid cells), u
     * as solve's. HV_ERR_UNSUPPORTED, with no message, sends the front end
     * the double way; NULL always does. */
    hv_status (*solve_f)(void *state, const float *f, float *u, hv_solve_info *info);
} hv_backend_ops;

/* Every backend always builds and is referenced strongly: a weak undefined
 * symbol would not pull its object out of libheatvox.a. OpenCL links only the
 * ICD loader; without a platform its create fails with HV_ERR_UNSUPPORTED. */
extern const hv_backend_ops hv__backend_mg_ops;
extern const hv_backend_ops hv__backend_fftw_ops;
extern const hv_backend_ops hv__backend_opencl_ops;
extern const hv_backend_ops hv__backend_petsc_ops; /* petsc.c: fails without HV_HAVE_PETSC */

/* The OpenCL device that HV_BACKEND_AUTO may take (hv_backend_resolve): -1
 * none (no platform or device: logs one HV_LOG_WARN), 0 a CPU device, 1 a
 * GPU. Probes once per process, creating no context (cl/cl_backend.c). */
int hv__opencl_auto_device(void);

/* Records relres into info->history (capped) and bumps nhistory. */
static inline void hv_info_push(hv_solve_info *info, double relres)
{
    if (info->nhistory < HV_MAX_HISTORY)
        info->history[info->nhistory++] = relres;
    info->relres = relres;
}

/* The backend behind a solver and its state, for backend-specific entry
 * points (the OpenCL device-resident solve, cl_ops.h). */
const hv_backend_ops *hv__solver_ops(const hv_solver *sv);
void *hv__solver_state(hv_solver *sv);

/* Subtracts the per-region mean of u (regions as in s; whole grid without mask). */
void hv__project_mean(const hv_setup *s, double *u);
/* region[c]: the connected fluid region of cell c (faces shared with fluid
 * cells, n[2] = 1 in 2D), numbered from 0 in the order of the regions' first
 * cells; -1 on solid cells. Returns the number of regions, or -1 out of
 * memory. */
int hv__label_regions(const int n[3], const uint8_t *solid, int32_t *region);

/* ||v||_2 over fluid cells. */
double hv__norm2(const hv_setup *s, const double *v);

#endif
