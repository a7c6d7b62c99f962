/*
 * Output files written safely: every writer creates a temporary file beside the
 * target and renames it into place only when complete, so a failed or
 * interrupted run never leaves a partial file under the requested name.
 */
#ifndef HEATVOX_IO_H
#define HEATVOX_IO_H

#include "grid.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Fills tmp (size tmpsize) with a unique temporary name in target's directory
 * ("<dir>/.<base>.tmp-<pid>-<n>"). The temporary is registered so that
 * hv_tmp_cleanup_all() (async-signal-safe, for a SIGINT handler) can unlink it. */
HV_API hv_status hv_tmp_name(const char *target, char *tmp, size_t tmpsize);

/* Renames tmp onto target and unregisters it; on failure unlinks tmp. */
HV_API hv_status hv_tmp_commit(const char *tmp, const char *target);

/* Unlinks tmp and unregisters it (for error paths). */
HV_API void hv_tmp_discard(const char *tmp);

/* Unlinks every registered temporary; async-signal-safe. */
HV_API void hv_tmp_cleanup_all(void);

/* Writes a dense float32 field as NumPy .npy, shape (nz, ny, nx) in 3D and
 * (ny, nx) in 2D, C order (x fastest). */
HV_API hv_status hv_write_npy(const char *path, const hv_grid *g);

/* Reads a .npy float32 (or float64, converted) array of 2 or 3 dimensions into a
 * new grid with h = 1 and origin 0; regular files only. The caller owns *out. */
HV_API hv_status hv_read_npy(const char *path, hv_grid **out);

#ifdef __cplusplus
}
#endif
#endif
