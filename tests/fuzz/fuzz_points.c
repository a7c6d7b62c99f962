/* libFuzzer target: hv_points_read on point clouds, with normals or without. The file is
 * named .xyz; the reader takes PLY by its content ("ply" first), so one
 * target covers the text and the PLY readers. */
#include "fuzz_common.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const char *path = fz_file(data, size, ".xyz");
    if (!path)
        return 0;
    hv_points *P = NULL;
    if (hv_points_read(path, &P) == HV_OK && hv_points_file(path) != 1)
        __builtin_trap(); /* an .xyz file is always taken for points */
    hv_points_destroy(&P);
    fz_done(path);
    return 0;
}
