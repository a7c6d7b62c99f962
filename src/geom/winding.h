/* Fast generalized winding numbers of triangle meshes (winding.c). */
#ifndef HV_HEAT_WINDING_H
#define HV_HEAT_WINDING_H

#include "heatvox/core.h"

#include <stddef.h>
#include <stdint.h>

/* Fast generalized winding number over a subset of a mesh's faces. */
typedef struct hv_wn_node {
    double c[3], N[3], r; /* area-weighted centre, summed vector area, radius */
    int left, right;      /* children or -1 */
    size_t first, count;  /* range in order[] */
} hv_wn_node;

typedef struct hv_wn_tree {
    const double *V;
    const uint32_t *T;
    uint32_t *order;
    signed char *sign; /* -1 for faces taken reversed */
    hv_wn_node *nodes;
    int nnodes;
} hv_wn_tree;

/* Builds the tree over faces[0..nfaces) of (V, T); flip (may be NULL) reverses faces. */
hv_status hv__wn_build(hv_wn_tree *W, const double *V, const uint32_t *T, const uint32_t *faces,
                       size_t nfaces, const uint8_t *flip);
/* Winding number at p, leaving out face `skip` (UINT32_MAX: none). */
double hv__wn_eval(const hv_wn_tree *W, const double p[3], uint32_t skip);
/* The same with clusters farther than beta times their radius taken as
 * dipoles (hv__wn_eval: 2.5; smaller is faster and coarser). */
double hv__wn_eval_beta(const hv_wn_tree *W, const double p[3], uint32_t skip, double beta);
void hv__wn_free(hv_wn_tree *W);

#endif
