/* libFuzzer target: hv_read_npy. */
#include "fuzz_common.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const char *path = fz_file(data, size, ".npy");
    if (!path)
        return 0;
    hv_grid *g = NULL;
    hv_read_npy(path, &g);
    hv_grid_destroy(&g);
    fz_done(path);
    return 0;
}
