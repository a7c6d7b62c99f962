/* libFuzzer target: hv_mesh_read on the formats read through assimp. The
 * first byte picks the extension, the rest is the file: one target and one
 * corpus for them all keep the fuzz stage's time. A mesh that loads also
 * goes through the report and the bounds. */
#include "fuzz_assimp.h"
#include "fuzz_common.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < 1)
        return 0;
    const char *path = fz_file(data + 1, size - 1, fz_assimp_ext(data[0]));
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
