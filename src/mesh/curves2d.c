/* The 2D curve type (heatvox/curves.h): polylines built from arrays, their
 * segment count and bounds. The text and SVG readers are in src/io/curves.c. */
#include "heatvox/curves.h"
#include "core/error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

hv_status hv_curves_from_arrays(hv_curves **out, const double *pts, size_t npoints,
                                const size_t *start, size_t nlines, const uint8_t *closed)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_curves_from_arrays: out is NULL");
    *out = NULL;
    if (!pts || !start || nlines == 0 || npoints == 0)
        return hv__error(HV_ERR_INVALID_ARG, "hv_curves_from_arrays: no points or lines");
    if (start[0] != 0 || start[nlines] != npoints)
        return hv__error(HV_ERR_INVALID_ARG,
                         "hv_curves_from_arrays: offsets must run from 0 to npoints (%zu)",
                         npoints);
    for (size_t k = 0; k < nlines; k++)
        if (start[k + 1] < start[k] + 2)
            return hv__error(HV_ERR_INVALID_ARG,
                             "hv_curves_from_arrays: polyline %zu has fewer than 2 points", k);
    for (size_t i = 0; i < 2 * npoints; i++)
        if (!isfinite(pts[i]))
            return hv__error(HV_ERR_NUMERIC, "hv_curves_from_arrays: point %zu is not finite",
                             i / 2);
    hv_curves *c = calloc(1, sizeof *c);
    if (!c)
        return hv__error(HV_ERR_NOMEM, "hv_curves_from_arrays: out of memory");
    c->pts = malloc(2 * npoints * sizeof *c->pts);
    c->start = malloc((nlines + 1) * sizeof *c->start);
    c->closed = calloc(nlines, 1);
    if (!c->pts || !c->start || !c->closed) {
        hv_curves_destroy(&c);
        return hv__error(HV_ERR_NOMEM, "hv_curves_from_arrays: out of memory");
    }
    memcpy(c->pts, pts, 2 * npoints * sizeof *c->pts);
    memcpy(c->start, start, (nlines + 1) * sizeof *c->start);
    if (closed)
        memcpy(c->closed, closed, nlines);
    c->npoints = npoints;
    c->nlines = nlines;
    *out = c;
    return HV_OK;
}

void hv_curves_destroy(hv_curves **c)
{
    if (!c || !*c)
        return;
    free((*c)->pts);
    free((*c)->start);
    free((*c)->closed);
    free(*c);
    *c = NULL;
}

size_t hv_curves_segments(const hv_curves *c)
{
    size_t n = 0;
    for (size_t k = 0; c && k < c->nlines; k++) {
        size_t cnt = c->start[k + 1] - c->start[k];
        n += cnt - 1 + (c->closed[k] && cnt > 2);
    }
    return n;
}

hv_status hv_curves_bounds(const hv_curves *c, double lo[2], double hi[2])
{
    if (!c || c->npoints == 0)
        return hv__error(HV_ERR_INVALID_ARG, "curves: no points");
    lo[0] = lo[1] = INFINITY;
    hi[0] = hi[1] = -INFINITY;
    for (size_t i = 0; i < c->npoints; i++)
        for (int a = 0; a < 2; a++) {
            double v = c->pts[2 * i + a];
            lo[a] = v < lo[a] ? v : lo[a];
            hi[a] = v > hi[a] ? v : hi[a];
        }
    return HV_OK;
}
