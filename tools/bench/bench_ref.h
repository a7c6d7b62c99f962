/* OpenVDB's own algorithms that the benchmarks (heatvox bench sdf, bench
 * extend) and tests/check_vdb.c compare heatvox with, behind a C API
 * (tools/bench/bench_ref_vdb.cpp). Not part of heatvox's API: the library does not
 * contain them; the command and the tests that use them link that file.
 *
 * Grids follow include/heatvox/vdb.h: voxel (i,j,k) of an hv_grid is OpenVDB
 * index (i,j,k), at the cell centre origin + (i+1/2, j+1/2, k+1/2) * h. Errors
 * are returned as hv_status; the message is ref_vdb_last_error(), not
 * hv_last_error(). */
#ifndef HV_TOOLS_BENCH_REF_H
#define HV_TOOLS_BENCH_REF_H

#include "heatvox/grid.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Narrow-band signed distance of a closed triangle mesh by
 * openvdb::tools::meshToLevelSet (exact distance in the band, sign by flood
 * fill), sampled on out's voxels (out: dim 3, caller-created; its n, h and
 * origin define the samples). Voxels outside the band take -/+ band_voxels*h by
 * sign. verts: 3*nv world coordinates; tris: 3*nt indices < nv. seconds, if
 * not NULL, receives the time spent inside OpenVDB (without the dense copy). */
hv_status ref_vdb_mesh_to_levelset(const double *verts, size_t nv, const uint32_t *tris, size_t nt,
                                   double band_voxels, hv_grid *out, double *seconds);

/* The same as a whole job, as a user of OpenVDB runs it: meshToLevelSet on
 * the index lattice with voxel size h whose index (0,0,0) lies at
 * index0_world, written to path as grid "sdf" (32-bit floats, OpenVDB's
 * default compression). */
hv_status ref_vdb_mesh_to_vdb_file(const double *verts, size_t nv, const uint32_t *tris, size_t nt,
                                   double h, const double index0_world[3], double band_voxels,
                                   const char *path);
/* Extends a scalar field off the zero level set of phi by
 * openvdb::tools::sdfToExt (fast sweeping): on the surface the value is field
 * sampled trilinearly at the crossing points; elsewhere it is constant along
 * the characteristics (normals). phi, field and out must share n, h and origin.
 * band_voxels > 0 restricts the computation to |phi| < band_voxels*h (voxels
 * outside get `background`); band_voxels <= 0 computes on every voxel.
 * n_iter: fast-sweeping iterations (8 sweeps each; 0 means 1).
 * Note: OpenVDB 10.0.1 hands the boundary callback index-space coordinates
 * (upstream bug #1640); this function runs OpenVDB in index space so that the
 * result is right with either behaviour. */
hv_status ref_vdb_sdf_to_ext(const hv_grid *phi, const hv_grid *field, double band_voxels,
                             int n_iter, float background, hv_grid *out, double *seconds);

/* The same for a vector field (three components), extended as a Vec3s grid. */
hv_status ref_vdb_sdf_to_ext_vec3(const hv_grid *phi, const hv_grid *fx, const hv_grid *fy,
                                  const hv_grid *fz, double band_voxels, int n_iter,
                                  float background, hv_grid *ox, hv_grid *oy, hv_grid *oz,
                                  double *seconds);

/* The extension job as a user of OpenVDB runs it: opens in_path, reads the
 * level set ls_name and the field field_name (float or vec3s, on the level
 * set's index lattice), runs tools::sdfToExt over the level set's active band
 * (background 0, isovalue 0, one iteration; the boundary values sampled
 * trilinearly from the field with tools::BoxSampler) and writes out_path with
 * the level set and the extension, named like the field. */
hv_status ref_vdb_ext_file(const char *in_path, const char *ls_name, const char *field_name,
                           const char *out_path);

/* sdfToExt on a level set given as tiles (values in world units, active voxels
 * the band, the rest of the block signed by flood fill) and ncomp (1 or 3)
 * field tiles `in` like phi (read at their active voxels). The grids are built
 * from the tiles first; *seconds (if not NULL) is the time inside sdfToExt
 * alone. out: ncomp caller-made tiles like phi (hv_tiles_create_like) that
 * receive the extension on phi's active voxels, marked active. */
hv_status ref_vdb_sdf_to_ext_tiles(const hv_tiles *phi, int ncomp, const hv_tiles *const in[3],
                                   hv_tiles *const out[3], double *seconds);

/* Message of the last failed call above on this thread ("" when none). */
const char *ref_vdb_last_error(void);

/* cli_fail (tools/cli.h) for the calls above: prints "heatvox <cmd>: <what>:
 * <status>: <ref_vdb_last_error()>" on stderr and returns HV_EXIT_FAIL. */
int ref_vdb_fail(const char *cmd, const char *what, hv_status st);

/* Runs argv with this executable (/proc/self/exe) as a child process and waits:
 * wall seconds and peak RSS in MB (wait4). Returns -1 when it cannot start or
 * exits non-zero. The caller's own resident memory at the fork counts in the
 * child's peak (Linux keeps the high-water mark across exec): call it from a
 * small process. (tools/bench/bench_run.c) */
int bench_run_self(char **argv, double *seconds, double *rss_mb);
/* The same for the program exe, its stdout into the file out (NULL: this
 * process's): *code is its exit status (-1 when a signal ended it, 126
 * when out could not be opened, 127 when exe could not be run). Returns -1
 * only when no child could be started. */
int bench_run_exe(const char *exe, char **argv, const char *out, double *seconds, double *rss_mb,
                  int *code);

/* The smooth fields the extension benchmarks extend (bench extend, extend-band,
 * extend-loop), of coordinates scaled to about [-1,1]; neither comes near
 * zero there, so relative errors are well defined. (tools/bench/bench_run.c) */
void bench_field_at(const double p[3], double v[3]);
double bench_scalar_at(const double p[3]);

/* heatvox bench extend-band and extend-loop (tools/bench/cmd_bench_extend_band.c). */
int cmd_bench_extend_band(int argc, char **argv);
int cmd_bench_extend_loop(int argc, char **argv);

#ifdef __cplusplus
}
#endif
#endif
