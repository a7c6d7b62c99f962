/*
 * 2D curves: polylines read from a small text format or from SVG. Their
 * signed distance (the signed heat method on a 2D grid) is in sdf2d.h.
 *
 * Text format (.txt, .curves; one command per line, '#' starts a comment):
 *     M x y     start a new polyline at (x, y)
 *     L x y     line from the current point to (x, y)
 *     Z         close the current polyline (a segment back to its first point)
 *     x0 y0 x1 y1 ...   a whole open polyline on one line (at least two points)
 * Numbers are decimal (C syntax); commas may separate them. Coordinates are
 * world units with y up.
 *
 * SVG (.svg): every <path d="...">, <polygon points="..."> and
 * <polyline points="..."> element. Path commands M L H V Z in absolute and
 * relative forms (implicit repeats: pairs after M/m are line-tos), plus C S Q T
 * (cubic and quadratic Bezier, flattened into 16 segments each). Arcs (A) are
 * not supported (an error naming the byte offset). transform attributes,
 * <use> and CSS are ignored. SVG's y axis points down; the reader negates y so
 * the drawing keeps its look in heatvox's y-up grids.
 *
 * Orientation: a segment a -> b has its outward normal on its right,
 * (b - a) rotated by -90 degrees, so a counter-clockwise closed curve has
 * outward normals. Distances are negative inside.
 */
#ifndef HEATVOX_CURVES_H
#define HEATVOX_CURVES_H

#include "grid.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct hv_curves {
    size_t npoints;
    double *pts; /* 2 * npoints coordinates, owned */
    size_t nlines;
    size_t *start;   /* nlines + 1 offsets into the points: polyline k is points
                         start[k] .. start[k+1]-1, owned */
    uint8_t *closed; /* nlines flags: 1 = a segment joins the last point to the first */
} hv_curves;

/* Reads curves, choosing the format by extension (.svg, else the text format).
 * Errors name the file and the line (text) or byte offset (SVG). A file without
 * any segment is an error. Only regular files and pipes (up to 1 GiB) are read;
 * coordinates beyond +-1e100 give HV_ERR_NUMERIC. The caller owns *out
 * (hv_curves_destroy). */
HV_API hv_status hv_curves_read(const char *path, hv_curves **out);

/* Parses curves from memory; `name` is used in messages. svg selects the format. */
HV_API hv_status hv_curves_parse(const char *text, size_t len, int svg, const char *name,
                                 hv_curves **out);

/* Builds curves from arrays (copied): npoints points, nlines polylines. */
HV_API hv_status hv_curves_from_arrays(hv_curves **out, const double *pts, size_t npoints,
                                       const size_t *start, size_t nlines, const uint8_t *closed);

HV_API void hv_curves_destroy(hv_curves **c);

/* Number of segments (zero-length ones included). */
HV_API size_t hv_curves_segments(const hv_curves *c);

/* Bounds of the points; HV_ERR_INVALID_ARG when there are none. */
HV_API hv_status hv_curves_bounds(const hv_curves *c, double lo[2], double hi[2]);

#ifdef __cplusplus
}
#endif
#endif
