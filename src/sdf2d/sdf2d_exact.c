/*
 * Exact distance from the cell centres of a 2D grid to a set of segments, the
 * magnitude hv_curves_sdf puts under the heat method's sign by default.
 */
#include "core/error.h"
#include "sdf2d_internal.h"

#include <math.h>
#include <stdlib.h>

/* Rasterization radius of the exact distance, in cells. */
#define SDF2_BAND 2.0

static double point_seg_d2(double x, double y, const double *p, const double *q)
{
    double dx = q[0] - p[0], dy = q[1] - p[1];
    double L2 = dx * dx + dy * dy;
    double t = L2 > 0 ? ((x - p[0]) * dx + (y - p[1]) * dy) / L2 : 0;
    t = t < 0 ? 0 : t > 1 ? 1 : t;
    double ex = p[0] + t * dx - x, ey = p[1] + t * dy - y;
    return ex * ex + ey * ey;
}

/* Exact distance to the segments: rasterized within SDF2_BAND cells of each
 * segment, then nearest-segment candidates passed on by sweeps in the four
 * diagonal directions (twice). */
hv_status hv__sdf2d_exact_distance(const double *P, const sdf2d_seg *S, size_t ns, const int n[2],
                                   double h, const double org[2], double *dist)
{
    size_t count = (size_t)n[0] * n[1];
    uint32_t *near = malloc(count * sizeof *near);
    if (!near)
        return hv__error(HV_ERR_NOMEM, "sdf2d: out of memory for the exact distance");
    for (size_t c = 0; c < count; c++) {
        dist[c] = INFINITY;
        near[c] = UINT32_MAX;
    }
    for (size_t k = 0; k < ns; k++) {
        const double *p = P + 2 * S[k].a, *q = P + 2 * S[k].b;
        int i0 = (int)floor((fmin(p[0], q[0]) - org[0]) / h - 0.5 - SDF2_BAND);
        int i1 = (int)ceil((fmax(p[0], q[0]) - org[0]) / h - 0.5 + SDF2_BAND);
        int j0 = (int)floor((fmin(p[1], q[1]) - org[1]) / h - 0.5 - SDF2_BAND);
        int j1 = (int)ceil((fmax(p[1], q[1]) - org[1]) / h - 0.5 + SDF2_BAND);
        i0 = i0 < 0 ? 0 : i0;
        j0 = j0 < 0 ? 0 : j0;
        i1 = i1 > n[0] - 1 ? n[0] - 1 : i1;
        j1 = j1 > n[1] - 1 ? n[1] - 1 : j1;
        for (int j = j0; j <= j1; j++)
            for (int i = i0; i <= i1; i++) {
                double x = org[0] + (i + 0.5) * h, y = org[1] + (j + 0.5) * h;
                double d2 = point_seg_d2(x, y, p, q);
                size_t c = (size_t)i + (size_t)n[0] * j;
                if (d2 < dist[c]) {
                    dist[c] = d2;
                    near[c] = (uint32_t)k;
                }
            }
    }
    for (int pass = 0; pass < 2; pass++)
        for (int dir = 0; dir < 4; dir++) {
            int di = dir & 1 ? -1 : 1, dj = dir & 2 ? -1 : 1;
            for (int jj = 0; jj < n[1]; jj++) {
                int j = dj > 0 ? jj : n[1] - 1 - jj;
                for (int ii = 0; ii < n[0]; ii++) {
                    int i = di > 0 ? ii : n[0] - 1 - ii;
                    size_t c = (size_t)i + (size_t)n[0] * j;
                    int nbi[3] = {i - di, i, i - di}, nbj[3] = {j, j - dj, j - dj};
                    for (int b = 0; b < 3; b++) {
                        if (nbi[b] < 0 || nbi[b] >= n[0] || nbj[b] < 0 || nbj[b] >= n[1])
                            continue;
                        uint32_t s = near[(size_t)nbi[b] + (size_t)n[0] * nbj[b]];
                        if (s == UINT32_MAX || s == near[c])
                            continue;
                        double x = org[0] + (i + 0.5) * h, y = org[1] + (j + 0.5) * h;
                        double d2 = point_seg_d2(x, y, P + 2 * S[s].a, P + 2 * S[s].b);
                        if (d2 < dist[c]) {
                            dist[c] = d2;
                            near[c] = s;
                        }
                    }
                }
            }
        }
    for (size_t c = 0; c < count; c++)
        dist[c] = sqrt(dist[c]);
    free(near);
    return HV_OK;
}
