/*
 * Images of grids: OpenEXR files (float data, lossless) and PNG previews
 * (8-bit RGB, diverging colour map), plus 2D slices of 3D grids.
 *
 * Orientation. An image shows a 2D grid with its first axis to the right and
 * its second axis UP: image row 0 (the top row) holds j = n[1]-1 and the last
 * row holds j = 0. EXR and PNG writers use the same convention and the EXR
 * reader undoes it, so a round trip returns the grid as written.
 *
 * EXR layout (read by OpenEXR 2+/3 tools, Nuke, Blender, OpenImageIO):
 *  - a 2D grid is a single-part scanline image of n[0] x n[1] pixels with one
 *    FLOAT (32-bit) channel, named by the caller ("Y" by default, which viewers
 *    show as grey; "distance" is another common choice);
 *  - a 3D grid is a MULTI-PART file with one scanline part per z slice, in
 *    order, named "slice_0000", "slice_0001", ... (four digits, more when
 *    n[2] > 10000); every part is n[0] x n[1] pixels with the same one channel.
 *    Viewers list the parts as layers.
 *  - compression ZIP (16 lines per block); lossless, so values read back bit
 *    for bit, NaN included;
 *  - extra attributes on every part: "heatvox:voxelSize" (double),
 *    "heatvox:origin" (v3d, world position of the lower corner of the block),
 *    "heatvox:dims" (v3i, n[0] n[1] n[2]) and "heatvox:sliceIndex" (int, the
 *    z index; 0 in 2D). The reader uses them when present; files from other
 *    programs read with voxel size 1 and origin 0.
 *
 * Colour map of the PNG previews (for signed distances): a value v is mapped
 * through t = clamp(v / range, -1, 1); t < 0 blends white into blue
 * (HV_PNG_BLUE at t = -1), t > 0 white into red (HV_PNG_RED at t = +1), t = 0
 * is white. The zero contour is drawn black: a pixel is black when one of its
 * 4 neighbours has the other sign (v < 0 against v >= 0) and its |v| is not
 * larger than that neighbour's, which gives a line one pixel thick on the side
 * nearer to zero. NaN and Inf pixels are grey (HV_PNG_GREY).
 */
#ifndef HEATVOX_IMAGE_H
#define HEATVOX_IMAGE_H

#include "grid.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Colours of the preview map (R, G, B). */
#define HV_PNG_BLUE_R 33
#define HV_PNG_BLUE_G 102
#define HV_PNG_BLUE_B 172
#define HV_PNG_RED_R 178
#define HV_PNG_RED_G 24
#define HV_PNG_RED_B 43
#define HV_PNG_GREY 128
/* Width in pixels of the gap between slices in hv_png_write_slices (white). */
#define HV_PNG_GAP 4

/* ---- slices ---- */

/* Copies the 2D slice of a 3D grid at index `index` along `axis` (0 = x,
 * 1 = y, 2 = z) into a new 2D grid. The two remaining axes keep their order:
 * a z slice is (x, y), a y slice is (x, z), an x slice is (y, z). The slice
 * keeps the voxel size; its origin holds the world coordinates of the two
 * remaining axes' lower corner in [0], [1] and the slice plane (cell centre)
 * in [2]. A 2D input is accepted with axis 2 and index 0 (a copy). The solid
 * mask is sliced too. The caller owns *out. */
HV_API hv_status hv_grid_slice(const hv_grid *g, int axis, int index, hv_grid **out);

/* ---- OpenEXR ---- */

/* Writes g (2D or 3D, layout above) to path through a temporary file and a
 * rename. channel may be NULL ("Y"); it must be 1..31 characters. The file is
 * decoded in full before the rename: unless it gives back every value bit for
 * bit, it is removed and the call fails with HV_ERR_IO. */
HV_API hv_status hv_exr_write(const char *path, const hv_grid *g, const char *channel);

/* Reads an EXR file into a new grid, decoding every pixel (a truncated or
 * corrupt file fails with HV_ERR_PARSE naming it and the part and line).
 * A single-part file gives a 2D grid; a multi-part file whose parts all have the
 * same size and pixel layout gives a 3D grid with one z slice per part, in file
 * order. channel selects the channel by name; NULL takes the only channel, or
 * "Y" when there are several. HALF and UINT channels are converted to float.
 * Images must be scanline or tiled, not deep. The caller owns *out. */
HV_API hv_status hv_exr_read(const char *path, const char *channel, hv_grid **out);

/* ---- PNG previews ---- */

/* Fills rgb (3 * n[0] * n[1] bytes, rows top to bottom) with the colour map
 * above for a 2D grid. range <= 0 (or not finite) picks max |v| over the finite
 * values (1 if all are zero). */
HV_API hv_status hv_image_colormap(const hv_grid *g, double range, uint8_t *rgb);

/* Writes an 8-bit RGB PNG of a 2D grid through a temporary file and a rename.
 * range as in hv_image_colormap. */
HV_API hv_status hv_png_write(const char *path, const hv_grid *g, double range);

/* Writes `count` 2D grids side by side (bottom-aligned, HV_PNG_GAP white pixels
 * between them), sharing one symmetric range (range <= 0: max |v| over all). */
HV_API hv_status hv_png_write_slices(const char *path, const hv_grid *const *slices, int count,
                                     double range);

/* Writes the three middle slices of a 3D grid (x, then y, then z; see
 * hv_grid_slice) side by side, as hv_png_write_slices. */
HV_API hv_status hv_png_write_preview(const char *path, const hv_grid *g, double range);

/* Writes raw 8-bit RGB (rows top to bottom) as PNG, temporary file + rename. */
HV_API hv_status hv_png_write_rgb(const char *path, const uint8_t *rgb, int width, int height);

/* Reads a PNG of any colour type and bit depth as 8-bit RGB (alpha dropped,
 * grey expanded). *rgb is allocated with malloc; the caller frees it. */
HV_API hv_status hv_png_read_rgb(const char *path, uint8_t **rgb, int *width, int *height);

#ifdef __cplusplus
}
#endif
#endif
