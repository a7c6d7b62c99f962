#include "heatvox/grid.h"
#include "error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

/* Blocks of this size or more are 2 MiB aligned and asked to live on huge
 * pages (Linux THP in madvise mode): stencils on big grids read rows whole
 * planes apart, and with 4 KiB pages every plane costs a TLB miss. */
#define HUGE_MIN ((size_t)8 << 20)
#define HUGE_ALIGN ((size_t)2 << 20)

void *hv_malloc(size_t bytes)
{
    void *p = NULL;
    size_t rounded = (bytes + 63u) & ~(size_t)63u;
    if (rounded < bytes)
        return NULL;
#ifdef MADV_HUGEPAGE
    if (rounded >= HUGE_MIN) {
        size_t whole = (rounded + HUGE_ALIGN - 1) & ~(HUGE_ALIGN - 1);
        if (whole < rounded || posix_memalign(&p, HUGE_ALIGN, whole) != 0)
            return NULL;
        (void)madvise(p, whole, MADV_HUGEPAGE); /* a hint: failure changes nothing */
        return p;
    }
#endif
    if (posix_memalign(&p, 64, rounded ? rounded : 64) != 0)
        return NULL;
    return p;
}

void *hv_calloc(size_t count, size_t size)
{
    if (size && count > SIZE_MAX / size)
        return NULL;
    void *p = hv_malloc(count * size);
    if (p)
        memset(p, 0, count * size);
    return p;
}

void hv_free(void *p) { free(p); }

hv_status hv_check_dims(int dim, const int n[3], double h, size_t bytes_per_cell)
{
    if (dim != 2 && dim != 3)
        return hv__error(HV_ERR_INVALID_ARG, "grid dimension must be 2 or 3, got %d", dim);
    if (!n)
        return hv__error(HV_ERR_INVALID_ARG, "grid size is NULL");
    for (int a = 0; a < dim; a++)
        if (n[a] <= 0)
            return hv__error(HV_ERR_INVALID_ARG, "grid size along %c must be positive, got %d",
                             "xyz"[a], n[a]);
    if (!(h > 0) || !isfinite(h))
        return hv__error(HV_ERR_INVALID_ARG, "voxel size must be positive and finite, got %g", h);
    double cells = (double)n[0] * n[1] * (dim == 3 ? n[2] : 1);
    double bytes = cells * (double)(bytes_per_cell ? bytes_per_cell : 1);
    if (bytes >= (double)SIZE_MAX / 2 || bytes > (double)hv__memory_limit(NULL)) {
        char lim[96];
        return hv__error(HV_ERR_NOMEM, "grid %d x %d x %d needs %.3g GB, more than %s", n[0], n[1],
                         dim == 3 ? n[2] : 1, bytes / 1e9, hv__memory_limit_text(lim, sizeof lim));
    }
    return HV_OK;
}

hv_status hv_grid_create(hv_grid **out, int dim, const int n[3], double h, const double origin[3])
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_grid_create: out is NULL");
    *out = NULL;
    hv_status st = hv_check_dims(dim, n, h, sizeof(float));
    if (st)
        return st;
    hv_grid *g = calloc(1, sizeof *g);
    if (!g)
        return hv__error(HV_ERR_NOMEM, "hv_grid_create: no memory for the grid header");
    g->dim = dim;
    g->n[0] = n[0];
    g->n[1] = n[1];
    g->n[2] = dim == 3 ? n[2] : 1;
    g->h = h;
    for (int a = 0; a < 3; a++)
        g->origin[a] = origin ? origin[a] : 0.0;
    g->v = hv_calloc(hv_grid_count(g), sizeof(float));
    if (!g->v) {
        size_t c = hv_grid_count(g);
        free(g);
        return hv__error(HV_ERR_NOMEM, "cannot allocate a grid of %zu cells (%.3g GB)", c,
                         c * 4.0 / 1e9);
    }
    *out = g;
    return HV_OK;
}

void hv_grid_destroy(hv_grid **g)
{
    if (!g || !*g)
        return;
    hv_free((*g)->v);
    hv_free((*g)->solid);
    free(*g);
    *g = NULL;
}

void hv_tiles_destroy(hv_tiles **t)
{
    if (!t || !*t)
        return;
    hv_free((*t)->ijk);
    hv_free((*t)->v);
    hv_free((*t)->on);
    free(*t);
    *t = NULL;
}

hv_status hv_tiles_create_like(hv_tiles **out, const hv_tiles *like, float value)
{
    if (!out || !like || (like->count && !like->ijk))
        return hv__error(HV_ERR_INVALID_ARG, "hv_tiles_create_like: out or like is NULL");
    *out = NULL;
    const size_t count = like->count, cells = (size_t)HV_TILE * HV_TILE * HV_TILE;
    if (count > SIZE_MAX / (cells * sizeof(float)))
        return hv__error(HV_ERR_NOMEM, "%zu tiles do not fit in memory", count);
    hv_tiles *t = calloc(1, sizeof *t);
    if (!t)
        return hv__error(HV_ERR_NOMEM, "cannot allocate %zu tiles", count);
    *t = *like;
    t->ijk = hv_malloc(3 * count * sizeof *t->ijk);
    t->v = hv_malloc(count * cells * sizeof *t->v);
    t->on = hv_calloc(HV_TILE * count, sizeof *t->on);
    t->active = 0;
    if (!t->ijk || !t->v || !t->on) {
        hv_tiles_destroy(&t);
        return hv__error(HV_ERR_NOMEM, "cannot allocate %zu tiles (%.3g GB)", count,
                         (double)count * cells * sizeof(float) / 1e9);
    }
    if (count)
        memcpy(t->ijk, like->ijk, 3 * count * sizeof *t->ijk);
    float *v = t->v;
#pragma omp parallel for schedule(static)
    for (size_t q = 0; q < count; q++)
        for (size_t c = 0; c < cells; c++)
            v[q * cells + c] = value;
    *out = t;
    return HV_OK;
}

hv_status hv_grid_add_mask(hv_grid *g)
{
    if (!g)
        return hv__error(HV_ERR_INVALID_ARG, "hv_grid_add_mask: grid is NULL");
    if (g->solid)
        return HV_OK;
    g->solid = hv_calloc(hv_grid_count(g), 1);
    if (!g->solid)
        return hv__error(HV_ERR_NOMEM, "cannot allocate a mask of %zu cells", hv_grid_count(g));
    return HV_OK;
}

size_t hv_grid_count(const hv_grid *g)
{
    return (size_t)g->n[0] * (size_t)g->n[1] * (size_t)g->n[2];
}

void hv_grid_cell_center(const hv_grid *g, int i, int j, int k, double x[3])
{
    x[0] = g->origin[0] + (i + 0.5) * g->h;
    x[1] = g->origin[1] + (j + 0.5) * g->h;
    x[2] = g->dim == 3 ? g->origin[2] + (k + 0.5) * g->h : g->origin[2];
}

hv_status hv_check_finite(const float *v, size_t count, const char *what)
{
    size_t bad = SIZE_MAX;
#pragma omp parallel for reduction(min : bad) schedule(static)
    for (size_t i = 0; i < count; i++)
        if (!isfinite(v[i]) && i < bad)
            bad = i;
    if (bad != SIZE_MAX)
        return hv__error(HV_ERR_NUMERIC, "%s holds a non-finite value (%g) at cell %zu", what,
                         (double)v[bad], bad);
    return HV_OK;
}

hv_status hv_check_finite_d(const double *v, size_t count, const char *what)
{
    size_t bad = SIZE_MAX;
#pragma omp parallel for reduction(min : bad) schedule(static)
    for (size_t i = 0; i < count; i++)
        if (!isfinite(v[i]) && i < bad)
            bad = i;
    if (bad != SIZE_MAX)
        return hv__error(HV_ERR_NUMERIC, "%s holds a non-finite value (%g) at cell %zu", what,
                         v[bad], bad);
    return HV_OK;
}
