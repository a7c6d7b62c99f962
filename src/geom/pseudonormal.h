/* Angle-weighted pseudonormals and the sign they give near a mesh (pseudonormal.c). */
#ifndef HV_HEAT_PSEUDONORMAL_H
#define HV_HEAT_PSEUDONORMAL_H

#include "heatvox/mesh.h"
#include "winding.h"

/* Angle-weighted pseudonormals of a mesh, with cleanliness of each feature. */
typedef struct hv_pseudo {
    double *fn;      /* 3 * ntris unit face normals */
    double *vn;      /* 3 * nverts angle-weighted vertex normals */
    uint32_t *other; /* 3 * ntris: face across each edge, UINT32_MAX if the edge is not clean */
    uint8_t *vok;    /* nverts: every edge at the vertex is clean */
    uint8_t *ftrust; /* ntris: 0 not yet known, 1 the face bounds a solid (winding number
                        about 1/2 on it), 2 not */
    hv_wn_tree W;    /* over all faces, for ftrust */
    int have_W;
    int balanced; /* every edge is used as often in one direction as in the other: the
                        mesh bounds, and its winding number changes only across it */
} hv_pseudo;

hv_status hv__pseudo_build(const hv_mesh *m, hv_pseudo *ps);
void hv__pseudo_free(hv_pseudo *ps);
/* Sign (+1 outside, -1 inside) from the pseudonormal of triangle tri's feature
 * nearest to p, where that feature is clean; 0 where it is not. Where that
 * sign differs from `current` it is only given when the feature's faces bound
 * a solid (tested on demand; thread-safe). */
int hv__pseudo_sign(hv_pseudo *ps, const hv_mesh *m, uint32_t tri, const double p[3], int current);

#endif
