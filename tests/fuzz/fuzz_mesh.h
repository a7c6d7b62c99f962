/* One mesh reader per target: the file gets the extension that selects the
 * reader; a mesh that loads also goes through the report and the bounds,
 * which meet whatever the reader let through (NaN, huge values, degenerate
 * faces). */
#include "fuzz_common.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const char *path = fz_file(data, size, FUZZ_EXT);
    if (!path)
        return 0;
    hv_mesh *m = NULL;
    if (hv_mesh_read(path, &m) == HV_OK) {
        hv_mesh_report r;
        double lo[3], hi[3];
        hv_mesh_report_compute(m, &r);
        hv_mesh_bounds(m, lo, hi);
    }
    hv_mesh_destroy(&m);
    fz_done(path);
    return 0;
}
