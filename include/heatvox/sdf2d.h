/*
 * The signed distance of 2D curves (curves.h): the signed heat method on a 2D
 * cell-centred grid (the 5-point Laplacian), robust to broken input: gaps,
 * flipped segments, overlapping and duplicated pieces. Orientation and sign as
 * in curves.h: a counter-clockwise closed curve has outward normals, and
 * distances are negative inside.
 */
#ifndef HEATVOX_SDF2D_H
#define HEATVOX_SDF2D_H

#include "curves.h"
#include "grid.h"
#include "solve.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct hv_sdf2d_opts {
    int res;            /* cells along the longest axis of the padded box; default 256 */
    double voxel_size;  /* h; used when > 0 instead of res */
    int pad;            /* cells between the curves' bounds and the block; default 8 */
    int use_bbox;       /* 1: bbox below is the block (pad ignored) */
    double bbox[4];     /* x0 y0 x1 y1 */
    int heat_magnitude; /* 1: |phi| from the heat method; 0 (default): exact distance to the
                           segments with the heat method's sign */
    double t_scale;     /* diffusion time (t_scale h)^2; default 1 */
    int repair;         /* 1 (default): weld endpoints, drop duplicates, orient (below) */
    double weld_tol;    /* endpoints closer than weld_tol * h are one point; default 1e-3 */
    hv_backend backend; /* default AUTO */
    double tol;         /* solver relative residual; default 1e-10 */
    int sign;           /* where the sign comes from (exact magnitude): 0 auto (default: the
                           generalized winding number of the repaired curves where they stay
                           open or the block cuts them, the heat method otherwise), 1 the heat
                           method, 2 the winding number (needs repair); the values of
                           hv_sdf_sign in sdf.h */
} hv_sdf2d_opts;

/*
 * Repair (repair = 1):
 *  1. weld endpoints closer than weld_tol * h, drop zero-length segments, and
 *     split segments at points lying on them (within weld_tol * h), so that
 *     overlapping collinear pieces become duplicates;
 *  2. drop segments repeating the endpoints of an earlier one (either way);
 *  3. join segments into chains through points used by exactly two segments
 *     and make each chain's direction consistent, keeping the direction that
 *     the larger length of its segments had (a vote);
 *  4. open chains are turned to agree with each other: the coupling of two
 *     chains through their generalized winding numbers depends only on their
 *     end points (see sdf2d.c) and is positive when one continues the other
 *     or when they face each other as two sides of one shape;
 *  5. loops (closed chains, and groups of strongly coupled open chains) are
 *     oriented by nesting: counter-clockwise when inside an even number of
 *     other loops (|generalized winding number| > 1/2), clockwise when odd.
 * A lone straight chain has no inside: it keeps the direction it was drawn in.
 */
typedef struct hv_sdf2d_stats {
    int n[2];
    double h;
    double origin[2];
    int levels;
    size_t segments_in, segments_out;
    size_t points_welded, zero_length_removed, duplicates_removed;
    size_t segments_split;   /* segments cut at points lying on them (overlaps) */
    size_t segments_flipped; /* by the repair */
    size_t chains, cycles;
    size_t nesting_tests; /* windings of one loop evaluated at a point of another: only
                                loops whose bounding box holds the point are tried */
    size_t dead_faces;
    hv_backend backend;
    double t_repair, t_splat, t_diffuse, t_normalize, t_poisson, t_distance, t_total;
    int sign;             /* the sign that ran: 1 heat method, 2 winding number */
    size_t open_ends;     /* points at the end of an open chain after repair */
    size_t winding_evals; /* winding-number evaluations of the sign */
} hv_sdf2d_stats;

HV_API void hv_sdf2d_opts_default(hv_sdf2d_opts *o);

/* Signed distance of curves c on a new 2D grid (dim 2, origin[2] = 0). opts and
 * stats may be NULL. The caller owns *out. */
HV_API hv_status hv_curves_sdf(const hv_curves *c, const hv_sdf2d_opts *opts, hv_grid **out,
                               hv_sdf2d_stats *stats);

#ifdef __cplusplus
}
#endif
#endif
