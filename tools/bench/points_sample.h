/* Oriented points drawn on a triangle mesh, the input of the point-cloud
 * benchmark (heatvox bench points) and its tests: area-uniform samples with
 * the true face normals (outward where the mesh is closed and oriented either
 * way: a mesh with negative signed volume has its normals reversed), and on
 * request the defects of scanned data: uneven density, noise, flipped normals,
 * a missing patch. The same mesh, options and seed give the same points.
 * Public API alone. (tools/bench/points_sample.c) */
#ifndef HV_TOOLS_BENCH_POINTS_SAMPLE_H
#define HV_TOOLS_BENCH_POINTS_SAMPLE_H

#include <heatvox/mesh.h>

typedef struct points_sample_opts {
    size_t count;          /* points kept; default 100000 */
    uint64_t seed;         /* default 1 */
    double density_ratio;  /* >= 1: a point is kept with a probability falling linearly along x,
                              from 1 at the mesh's lowest x to 1/density_ratio at its highest;
                              1 (default): uniform */
    double noise;          /* standard deviation of Gaussian noise on the positions, world units;
                              default 0 */
    int noise_isotropic;   /* 0 (default): the noise along the point's normal; 1: in x, y, z */
    double flip_fraction;  /* this fraction of the normals (rounded) reversed, at random;
                              default 0 */
    double hole_radius;    /* > 0: no point within this distance of hole_center (before noise);
                              default 0 */
    double hole_center[3]; /* world units */
} points_sample_opts;

/* Points and their unit normals; free with points_set_free. */
typedef struct points_set {
    size_t count;
    double *xyz;    /* 3 * count, owned */
    double *normal; /* 3 * count, owned */
} points_set;

void points_sample_opts_default(points_sample_opts *o);

/* Draws o->count points on m's surface into *out. Returns 0, or -1 with a
 * message in err (the options keep no point anywhere, a mesh of zero area,
 * out of memory). */
int points_sample(const hv_mesh *m, const points_sample_opts *o, points_set *out, char *err,
                  size_t errsize);

/* An area-uniform random point of m's surface for seed (a place for
 * hole_center). Returns 0, or -1 when m has no area. */
int points_surface_point(const hv_mesh *m, uint64_t seed, double p[3]);

/* Writes "x y z nx ny nz" lines (after a '#' comment line) to path, under a
 * temporary name renamed into place when complete. Returns 0, or -1 with a
 * message naming the file in err. */
int points_write_xyz(const points_set *p, const char *path, char *err, size_t errsize);

void points_set_free(points_set *p);

#endif
