/* libFuzzer target: the OpenVDB reader through the shim. Lists the grids, then
 * reads up to two of them by value type. The dense copy is asked for the
 * listed active box only when it is small: a valid file may well describe a
 * box of many GB, which is not a bug but would stop the fuzzer at its malloc
 * limit. Run with -rss_limit_mb and -malloc_limit_mb: corrupt headers can make
 * OpenVDB itself allocate without bound. */
#include "fuzz_common.h"

#define FZ_MAX_VOXELS ((int64_t)1 << 22)

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const char *path = fz_file(data, size, ".vdb");
    if (!path)
        return 0;
    hv_vdb_grid_info info[4];
    size_t count = 0;
    if (hv_vdb_list(path, info, 4, &count) == HV_OK) {
        for (size_t i = 0; i < count && i < 2; i++) {
            const hv_vdb_grid_info *d = &info[i];
            int64_t vox = 1;
            for (int a = 0; a < 3; a++) {
                int64_t e = (int64_t)d->bbox_hi[a] - d->bbox_lo[a] + 1;
                vox = e <= 0 || vox > FZ_MAX_VOXELS ? 0 : vox * e;
            }
            if (vox <= 0 || vox > FZ_MAX_VOXELS)
                continue;
            hv_vdb_read_opts o = {1,
                                  {d->bbox_lo[0], d->bbox_lo[1], d->bbox_lo[2]},
                                  {d->bbox_hi[0], d->bbox_hi[1], d->bbox_hi[2]}};
            hv_grid *g = NULL, *gy = NULL, *gz = NULL;
            int cls;
            if (!strcmp(d->value_type, "float") || !strcmp(d->value_type, "double"))
                hv_vdb_read_float(path, d->name, &o, &g, &cls);
            else if (!strncmp(d->value_type, "vec3", 4))
                hv_vdb_read_vec3(path, d->name, &o, &g, &gy, &gz);
            else
                hv_vdb_read_mask(path, d->name, &o, &g);
            hv_grid_destroy(&g);
            hv_grid_destroy(&gy);
            hv_grid_destroy(&gz);
        }
    }
    fz_done(path);
    return 0;
}
