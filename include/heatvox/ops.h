/*
 * Finite-volume operators on cell-centred grids with homogeneous Neumann walls
 * and optional solid masks (docs/METHOD.md, "Discretization").
 *
 * Faces: axis-a faces form an array of (n[a]+1) cells along a and n[b] along the
 * other axes, x fastest; face i along x lies between cells i-1 and i. Wall faces
 * and faces touching a solid cell carry zero flux. With
 *     grad_a(u)[face] = (u[right] - u[left]) / h   and   div(F)[cell] = sum_a (F[a][hi] - F[a][lo]) / h
 * the Laplacian is exactly div(grad(u)).
 */
#ifndef HEATVOX_OPS_H
#define HEATVOX_OPS_H

#include "grid.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct hv_faces {
    int dim;
    int n[3];    /* the cell counts of the grid the faces belong to */
    float *f[3]; /* f[a]: faces normal to axis a; f[2] NULL in 2D; owned */
} hv_faces;

/* Zeroed face arrays matching grid g. Caller frees with hv_faces_destroy(). */
HV_API hv_status hv_faces_create(hv_faces **out, const hv_grid *g);
HV_API void hv_faces_destroy(hv_faces **f);
/* Number of faces normal to axis a. */
HV_API size_t hv_faces_count(const hv_faces *f, int axis);

/* out = Laplacian of u (5-point in 2D, 7-point in 3D); 0 on solid cells.
 * out uses u's geometry and mask; out->v must not alias u->v. */
HV_API hv_status hv_laplacian(const hv_grid *u, hv_grid *out);

/* Face gradient of u into g (created for u's geometry). */
HV_API hv_status hv_face_gradient(const hv_grid *u, hv_faces *g);

/* out = divergence of the face field F (face fluxes through walls and solid
 * faces are taken as zero whatever F holds there). */
HV_API hv_status hv_face_divergence(const hv_faces *F, hv_grid *out);

/* Applies A u = alpha*u - beta*Laplacian(u) in double precision (out may not alias u).
 * Solid cells give out = 0. This is the operator the solvers invert. */
HV_API hv_status hv_apply_helmholtz_d(int dim, const int n[3], double h, const uint8_t *solid,
                                      double alpha, double beta, const double *u, double *out);

#ifdef __cplusplus
}
#endif
#endif
