/*
 * NumPy .npy files. Like every writer of heatvox this one writes a temporary
 * file beside the target and renames it into place when complete (core.h).
 */
#ifndef HEATVOX_IO_H
#define HEATVOX_IO_H

#include "grid.h"

#ifdef __cplusplus
extern "C" {
#endif

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
