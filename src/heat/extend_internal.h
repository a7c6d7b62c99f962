/* Private pieces of the extension off a level set shared by the host path
 * (extend_vhm.c) and the OpenCL path (extend_cl.c). */
#ifndef HV_HEAT_EXTEND_INTERNAL_H
#define HV_HEAT_EXTEND_INTERNAL_H

#include "heatvox/heat.h"

#define MAX_LEVELS 8
/* Fields per hv_extend_many call (each takes up to 4 right-hand sides). */
#define MAX_FIELDS_PER_CALL 64
#define LEVEL_FACTOR 16.0
/* A level's solve covers the cells it must answer for plus BOX_MARGIN sqrt(t)
 * on every side: Neumann walls there reflect e^{-2 BOX_MARGIN} (6e-6) of what
 * reaches them. */
#define BOX_MARGIN 6.0
/* Ratios are trusted where the diffused weight is RELIABLE times the solve's
 * pointwise error bound (relres * ||rhs||_2; the heat operator's inverse has
 * norm <= 1). */
#define RELIABLE 1e3
/* |grad phi| must lie in this range for phi to be taken as a distance. */
#define GRAD_MIN 0.5
#define GRAD_MAX 1.5

/* The box of level l as the level loop of hv_extend_many forms it: the box of
 * the cells with a weight (wlo..whi, inclusive) grown by 2 (the closest
 * points' stencils), joined with the box of the cells read at themselves
 * (rlo..rhi; lo > hi when empty), grown by BOX_MARGIN sqrt(t_l) voxels and
 * then to a size the solvers like, within the grid: corner lo, size bn. */
void hv_extend_level_box(const hv_extender *e, const int wlo[3], const int whi[3],
                         const int rlo[3], const int rhi[3], int l, int lo[3], int bn[3]);

/* The solver of diffusion level l (t_scale h^2 16^l) on the box [lo, lo + bn)
 * (Neumann walls at its faces), for `backend`: *sv is kept while the box keeps
 * its size and, with solid cells, its place (blo, bnk: the box it was made
 * for), and rebuilt otherwise. Shared by the host and device paths. */
hv_status hv_extend_level_solver(int dim, const int n[3], double h, const uint8_t *solid,
                                 const hv_extend_opts *o, hv_backend backend, int l,
                                 const int lo[3], const int bn[3], hv_solver **sv, int blo[3],
                                 int bnk[3]);

#endif
