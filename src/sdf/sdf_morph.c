/*
 * Morphology on a signed distance (hv_sdf_opts: close, open, offset, shell):
 * what the signed heat method's paper calls generalized morphological
 * operations (Feng & Crane 2024), done on the exact distance. Moving the zero
 * set by d is phi - d, exact where the nearest point does not change (every
 * cell outside a grown surface, every cell inside a shrunk one). Closing and
 * opening move it twice, and the second move needs the exact distance to
 * the first's surface: that surface is taken from the grid as a closed mesh
 * (hv_grid_to_mesh) and its distance computed on the same block.
 */
#include "sdf_internal.h"
#include "core/error.h"
#include "heatvox/vdb.h"

#include <math.h>
#include <string.h>

static int finite_ge0(double x) { return isfinite(x) && x >= 0; }

hv_status hv__sdf_morph_check(const hv_sdf_opts *o)
{
    if (!finite_ge0(o->close) || !finite_ge0(o->open) || !finite_ge0(o->shell) ||
        !isfinite(o->offset))
        return hv__error(HV_ERR_INVALID_ARG,
                         "sdf: close, open and shell must be finite and >= 0, offset finite; got "
                         "%g, %g, %g and %g",
                         o->close, o->open, o->shell, o->offset);
    if (hv__sdf_morph_on(o) && o->unsigned_distance)
        return hv__error(HV_ERR_INVALID_ARG,
                         "sdf: close, open, offset and shell move a surface between an inside "
                         "and an outside; an unsigned distance has neither");
    return HV_OK;
}

int hv__sdf_morph_on(const hv_sdf_opts *o)
{
    return o->close > 0 || o->open > 0 || o->offset != 0 || o->shell > 0;
}

double hv__sdf_morph_growth(const hv_sdf_opts *o) { return o->close + fmax(o->offset, 0.0); }

double hv__sdf_morph_reach(const hv_sdf_opts *o)
{
    return o->close + o->open + fabs(o->offset) + o->shell;
}

static void shift_values(float *v, size_t n, double d)
{
#pragma omp parallel for schedule(static)
    for (size_t c = 0; c < n; c++)
        v[c] = (float)(v[c] - d);
}

/* max(phi, -phi - t): the surface and its inner offset by t. */
static void shell_values(float *v, size_t n, double t)
{
#pragma omp parallel for schedule(static)
    for (size_t c = 0; c < n; c++)
        v[c] = fmaxf(v[c], (float)(-v[c] - t));
}

/* g = the exact signed distance to g's zero set, plus d. The zero set as a
 * closed mesh; its distance with the winding number's sign on g's block.
 * Where the set is empty, every cell keeps its side. */
static hv_status redistance(hv_grid *g, const hv_sdf_opts *o, double d)
{
    hv_mesh *iso = NULL;
    hv_grid *r = NULL;
    hv_status st = hv_grid_to_mesh(g, 0.0, 0.0, &iso);
    if (st)
        return st;
    const size_t n = hv_grid_count(g);
    if (iso->ntris == 0) {
        const double far =
            (o->band_only > 0 ? o->band_only + 1 : g->n[0] + g->n[1] + g->n[2]) * g->h;
        for (size_t c = 0; c < n; c++)
            g->v[c] = (float)((g->v[c] < 0 ? -far : far) + d);
        hv_mesh_destroy(&iso);
        return HV_OK;
    }
    hv_sdf_opts ro = *o;
    ro.close = ro.open = ro.offset = ro.shell = 0;
    ro.use_bbox = 1;
    ro.voxel_size = g->h;
    ro.round_to = 1;
    ro.repair = HV_SDF_REPAIR_ALL;
    ro.sign = HV_SDF_SIGN_WINDING;
    for (int a = 0; a < 3; a++) {
        ro.bbox[a] = g->origin[a];
        ro.bbox[3 + a] = g->origin[a] + g->n[a] * g->h;
    }
    st = hv_sdf_compute(iso, &ro, &r, NULL);
    hv_mesh_destroy(&iso);
    if (!st && (r->n[0] != g->n[0] || r->n[1] != g->n[1] || r->n[2] != g->n[2]))
        st = hv__error(HV_ERR_INTERNAL,
                       "sdf: redistancing placed a %d x %d x %d block on %d x "
                       "%d x %d",
                       r->n[0], r->n[1], r->n[2], g->n[0], g->n[1], g->n[2]);
    if (!st) {
        memcpy(g->v, r->v, n * sizeof *g->v);
        shift_values(g->v, n, -d);
    }
    hv_grid_destroy(&r);
    return st;
}

hv_status hv__sdf_morph_grid(hv_grid *g, const hv_sdf_opts *o)
{
    const size_t n = hv_grid_count(g);
    hv_status st;
    if (o->close > 0) { /* grow, then the distance to the grown surface, shrunk */
        shift_values(g->v, n, o->close);
        if ((st = redistance(g, o, o->close)))
            return st;
    }
    if (o->open > 0) {
        shift_values(g->v, n, -o->open);
        if ((st = redistance(g, o, -o->open)))
            return st;
    }
    if (o->offset != 0)
        shift_values(g->v, n, o->offset);
    if (o->shell > 0)
        shell_values(g->v, n, o->shell);
    return HV_OK;
}

void hv__sdf_morph_tiles(hv_tiles *T, const hv_sdf_opts *o, double band)
{
    const size_t n = T->count * (size_t)(HV_TILE * HV_TILE * HV_TILE);
    if (o->offset != 0)
        shift_values(T->v, n, o->offset);
    if (o->shell > 0)
        shell_values(T->v, n, o->shell);
    /* Active: the voxels within the band of the moved surface. */
    const float bg = (float)(band * T->h);
    size_t active = 0;
#pragma omp parallel for schedule(static) reduction(+ : active)
    for (size_t q = 0; q < T->count; q++)
        for (int k = 0; k < HV_TILE; k++) {
            uint64_t on = T->on[8 * q + k];
            for (int b = 0; b < 64; b++)
                if ((on >> b & 1) && !(fabsf(T->v[q * 512 + (size_t)k * 64 + b]) < bg))
                    on &= ~((uint64_t)1 << b);
            T->on[8 * q + k] = on;
            active += (size_t)__builtin_popcountll(on);
        }
    T->active = active;
}
