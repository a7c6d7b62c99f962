/* 2D slices of 3D grids (heatvox/image.h). */
#include "heatvox/image.h"
#include "core/error.h"

#include <string.h>

hv_status hv_grid_slice(const hv_grid *g, int axis, int index, hv_grid **out)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_grid_slice: out is NULL");
    *out = NULL;
    if (!g || !g->v)
        return hv__error(HV_ERR_INVALID_ARG, "hv_grid_slice: grid is NULL");
    if (axis < 0 || axis > 2)
        return hv__error(HV_ERR_INVALID_ARG, "slice axis must be 0, 1 or 2 (x, y, z), got %d",
                         axis);
    if (g->dim == 2 && axis != 2)
        return hv__error(HV_ERR_INVALID_ARG, "a 2D grid can only be sliced along z, not %c",
                         "xyz"[axis]);
    if (index < 0 || index >= g->n[axis])
        return hv__error(HV_ERR_INVALID_ARG, "slice index %d along %c is outside 0..%d", index,
                         "xyz"[axis], g -> n[axis] - 1);
    /* The remaining axes, in increasing order: u is the image's horizontal axis. */
    int u = axis == 0 ? 1 : 0, w = axis == 2 ? 1 : 2;
    int n2[3] = {g->n[u], g->n[w], 1};
    double org[3] = {g->origin[u], g->origin[w], g->origin[axis] + (index + 0.5) * g->h};
    if (g->dim == 2)
        org[2] = g->origin[2];
    hv_grid *s;
    hv_status st = hv_grid_create(&s, 2, n2, g->h, org);
    if (st)
        return st;
    if (g->solid && (st = hv_grid_add_mask(s)) != HV_OK) {
        hv_grid_destroy(&s);
        return st;
    }
    size_t stride[3] = {1, (size_t)g->n[0], (size_t)g->n[0] * (size_t)g->n[1]};
    size_t base = (size_t)index * stride[axis];
    for (int b = 0; b < n2[1]; b++)
        for (int a = 0; a < n2[0]; a++) {
            size_t src = base + (size_t)a * stride[u] + (size_t)b * stride[w];
            size_t dst = (size_t)a + (size_t)n2[0] * (size_t)b;
            s->v[dst] = g->v[src];
            if (g->solid)
                s->solid[dst] = g->solid[src];
        }
    *out = s;
    return HV_OK;
}
