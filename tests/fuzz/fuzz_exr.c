/* libFuzzer target: hv_exr_read (OpenEXRCore underneath, not instrumented:
 * coverage and checks are those of heatvox's own decoding code). */
#include "fuzz_common.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const char *path = fz_file(data, size, ".exr");
    if (!path)
        return 0;
    hv_grid *g = NULL;
    hv_exr_read(path, NULL, &g);
    hv_grid_destroy(&g);
    fz_done(path);
    return 0;
}
