/* How close a reconstructed surface comes to the mesh its points were drawn
 * from (heatvox bench points): the inside-IoU on a grid and the distance of
 * the reconstruction to the true surface. (tools/bench/points_score.c) */
#ifndef HV_TOOLS_BENCH_POINTS_SCORE_H
#define HV_TOOLS_BENCH_POINTS_SCORE_H

#include "tri_buckets.h"

#include <heatvox/grid.h>
#include <heatvox/mesh.h>

typedef struct points_truth {
    const hv_mesh *m; /* the true surface; not owned */
    hv_grid *phi;     /* its exact signed distance, winding-number sign, on the block of
                         `heatvox sdf --res N` */
    tri_buckets b;    /* its triangles, for exact distances */
} points_truth;

typedef struct points_score {
    double iou;           /* |A and B| / |A or B| over the cells inside the truth (A) and
                             inside the reconstruction (B), on phi's grid */
    double mean_dist_vox; /* distance of the reconstructed surface to the true one, voxels,
                             mean over area-uniform samples of the reconstruction */
    double max_dist_vox;  /* the largest of those */
    size_t samples;
} points_score;

/* The truth of mesh m at res cells along the longest side (as heatvox sdf
 * --res places its block). Returns 0, or -1 with the message in err. */
int points_truth_init(points_truth *T, const hv_mesh *m, int res, char *err, size_t errsize);
void points_truth_free(points_truth *T);

/* Scores the reconstruction r against T. Returns 0, or -1 with the message
 * in err. */
int points_score_mesh(const points_truth *T, const hv_mesh *r, points_score *s, char *err,
                      size_t errsize);

#endif
