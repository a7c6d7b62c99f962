/* Private: pieces of the heat-method distance shared between its files: the
 * pipeline (distance_heat.c), the sources (distance_sources.c), the device
 * path (distance_cl.c) and the lattice and front rules (distance_front.c). */
#ifndef HV_HEAT_DISTANCE_INTERNAL_H
#define HV_HEAT_DISTANCE_INTERNAL_H

#include "heatvox/heat.h"

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
 * behind a corner). grad ln A hardly depends on t, so in ln u(t) - ln u(4t) =
 * -d (1/sqrt t - 1/sqrt 4t) it cancels. Measured at 128^2 (mean error in
 * voxels, one t -> two): a wall with a gap 1.36 -> 0.71, an L-shaped room
 * 0.68 -> 0.32. */
#define T_RATIO 4.0
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

/* Adds the source weights of src onto w (one double per cell of g, zeroed by
 * the caller): voxels weigh 1, points 1 spread trilinearly over the fluid cells
 * among their 8 neighbours, mesh samples their area / h^2 the same way.
 * ref (one float per cell, +INFINITY on entry) receives, on the fluid cells
 * within HV_DIST_REF_RADIUS voxels of a source item (voxel centre, point, mesh
 * sample), the least distance from the cell centre to one: the distance those
 * cells should have (when no obstacle intervenes), used to place the zero.
 * *in_solid counts sources with no fluid cell to land on. */
hv_status hv__dist_splat(const hv_grid *g, const hv_distance_sources *src, double *w, float *ref,
                         size_t *in_solid);

#endif
