#include "heatvox/ops.h"
#include "core/error.h"

/*
 * A u = alpha*u - beta*Lap(u) with the cell-centred 5/7-point Laplacian
 * (docs/METHOD.md, "Discretization").
 * A Neumann wall is a mirror ghost u[-1] = u[0]: pointing the missing neighbour
 * row at the cell's own row makes its difference exactly zero, so the unmasked
 * path needs no per-cell tests and vectorizes along x.
 */

static inline double point(double v, double xm, double xp, double ym, double yp, double zm,
                           double zp, double alpha, double bc)
{
    return alpha * v - bc * ((xm - v) + (xp - v) + (ym - v) + (yp - v) + (zm - v) + (zp - v));
}

static void rows_plain(int dim, const int n[3], double c, double alpha, double beta,
                       const double *restrict u, double *restrict out)
{
    const ptrdiff_t nx = n[0], ny = n[1], nz = dim == 3 ? n[2] : 1;
    const ptrdiff_t sy = nx, sz = nx * ny;
    const double bc = beta * c;
#pragma omp parallel for collapse(2) schedule(static)
    for (ptrdiff_t k = 0; k < nz; k++)
        for (ptrdiff_t j = 0; j < ny; j++) {
            const double *restrict row = u + k * sz + j * sy;
            const double *restrict ym = j > 0 ? row - sy : row, *yp = j < ny - 1 ? row + sy : row;
            const double *restrict zm = k > 0 ? row - sz : row, *zp = k < nz - 1 ? row + sz : row;
            double *restrict o = out + k * sz + j * sy;
            if (nx == 1) {
                o[0] = point(row[0], row[0], row[0], ym[0], yp[0], zm[0], zp[0], alpha, bc);
                continue;
            }
            o[0] = point(row[0], row[0], row[1], ym[0], yp[0], zm[0], zp[0], alpha, bc);
            for (ptrdiff_t i = 1; i < nx - 1; i++)
                o[i] = point(row[i], row[i - 1], row[i + 1], ym[i], yp[i], zm[i], zp[i], alpha, bc);
            const ptrdiff_t e = nx - 1;
            o[e] = point(row[e], row[e - 1], row[e], ym[e], yp[e], zm[e], zp[e], alpha, bc);
        }
}

/* With a mask: a solid cell gives 0 and a face touching a solid cell carries no
 * flux, so the matrix has zero rows and columns on solid cells and stays
 * symmetric, with one constant per fluid component in its null space (alpha = 0). */
static void rows_masked(int dim, const int n[3], const uint8_t *solid, double c, double alpha,
                        double beta, const double *u, double *out)
{
    const ptrdiff_t nx = n[0], ny = n[1], nz = dim == 3 ? n[2] : 1;
    const ptrdiff_t sy = nx, sz = nx * ny;
#pragma omp parallel for collapse(2) schedule(static)
    for (ptrdiff_t k = 0; k < nz; k++)
        for (ptrdiff_t j = 0; j < ny; j++) {
            const ptrdiff_t base = k * sz + j * sy;
            for (ptrdiff_t i = 0; i < nx; i++) {
                const ptrdiff_t c0 = base + i;
                if (solid[c0]) {
                    out[c0] = 0.0;
                    continue;
                }
                const double v = u[c0];
                double lap = 0.0;
                if (i > 0 && !solid[c0 - 1])
                    lap += u[c0 - 1] - v;
                if (i < nx - 1 && !solid[c0 + 1])
                    lap += u[c0 + 1] - v;
                if (j > 0 && !solid[c0 - sy])
                    lap += u[c0 - sy] - v;
                if (j < ny - 1 && !solid[c0 + sy])
                    lap += u[c0 + sy] - v;
                if (k > 0 && !solid[c0 - sz])
                    lap += u[c0 - sz] - v;
                if (k < nz - 1 && !solid[c0 + sz])
                    lap += u[c0 + sz] - v;
                out[c0] = alpha * v - beta * c * lap;
            }
        }
}

hv_status hv_apply_helmholtz_d(int dim, const int n[3], double h, const uint8_t *solid,
                               double alpha, double beta, const double *u, double *out)
{
    hv_status st = hv_check_dims(dim, n, h, 0);
    if (st)
        return st;
    if (!u || !out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_apply_helmholtz_d: %s is NULL", u ? "out" : "u");
    if (u == out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_apply_helmholtz_d: out must not alias u");
    const double c = 1.0 / (h * h);
    if (solid)
        rows_masked(dim, n, solid, c, alpha, beta, u, out);
    else
        rows_plain(dim, n, c, alpha, beta, u, out);
    return HV_OK;
}
