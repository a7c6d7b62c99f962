/* The lattice and front rules of the heat-method distance's stages
 * (distance_internal.h), shared by the host path (distance_heat.c) and the
 * device path (distance_cl.c): the plane-wave decay rate of the discrete heat
 * operator, the trust bound on ln u and the distance to the next front
 * (docs/METHOD.md, "Heat method", step 4). */
#include "distance_internal.h"

#include <math.h>

double hv__dist_lattice_kappa(const double nu[3], int dim, double tau)
{
    double k = sqrt(tau);
    for (int it = 0; it < 8; it++) {
        double g = -tau, dg = 0;
        for (int b = 0; b < dim; b++) {
            g += 2 * (cosh(k * nu[b]) - 1);
            dg += 2 * nu[b] * sinh(k * nu[b]);
        }
        if (!(dg > 0))
            break;
        double step = g / dg;
        k -= step;
        if (fabs(step) < 1e-12 * k)
            break;
    }
    return k;
}

double hv__dist_trust_log(double relres, double wn, double t_scale)
{
    return log(RELIABLE * fmax(relres, 1e-14) * wn * sqrt(t_scale));
}

double hv__dist_axis_kappa(int dim, double tau)
{
    const double axis[3] = {1, 0, 0};
    return hv__dist_lattice_kappa(axis, dim, tau);
}

double hv__dist_front_step(double lu0, double lthr, int dim, double tau)
{
    return (lu0 - lthr - FRONT_MARGIN) / hv__dist_axis_kappa(dim, tau);
}

int hv__dist_next_reach(double voxels)
{
    /* a cell `voxels` from a front cell (chessboard) lies within
     * ceil((voxels + DIST_TILE - 1) / DIST_TILE) tiles of the front cell's tile */
    if (!(voxels > 0))
        return DIST_FIRST_REACH;
    double r = ceil((voxels + DIST_TILE - 1) / DIST_TILE);
    return r < 2 ? 2 : r > 16 ? 16 : (int)r;
}
