/* Face-based operators on cell-centred grids (docs/METHOD.md, "Discretization"):
 * gradient on faces, divergence of face fluxes and the Laplacian as exactly
 * div(grad). */
#include "heatvox/ops.h"
#include "core/error.h"

#include <stdlib.h>
#include <string.h>

static size_t face_count(int dim, const int n[3], int a)
{
    if (a >= dim)
        return 0;
    size_t c = 1;
    for (int b = 0; b < 3; b++)
        c *= (size_t)(n[b] + (b == a));
    return c;
}

size_t hv_faces_count(const hv_faces *f, int axis) { return face_count(f->dim, f->n, axis); }

hv_status hv_faces_create(hv_faces **out, const hv_grid *g)
{
    if (!out || !g)
        return hv__error(HV_ERR_INVALID_ARG, "hv_faces_create: NULL argument");
    *out = NULL;
    hv_faces *f = calloc(1, sizeof *f);
    if (!f)
        return hv__error(HV_ERR_NOMEM, "hv_faces_create: out of memory");
    f->dim = g->dim;
    memcpy(f->n, g->n, sizeof f->n);
    for (int a = 0; a < g->dim; a++) {
        f->f[a] = hv_calloc(face_count(f->dim, f->n, a), sizeof(float));
        if (!f->f[a]) {
            hv_faces_destroy(&f);
            return hv__error(HV_ERR_NOMEM, "cannot allocate face arrays for a %d x %d x %d grid",
                             g->n[0], g->n[1], g->n[2]);
        }
    }
    *out = f;
    return HV_OK;
}

void hv_faces_destroy(hv_faces **f)
{
    if (!f || !*f)
        return;
    for (int a = 0; a < 3; a++)
        hv_free((*f)->f[a]);
    free(*f);
    *f = NULL;
}

/* Strides of cells and of axis-a faces. */
static void strides(const int n[3], int a, size_t cs[3], size_t fs[3])
{
    cs[0] = 1;
    cs[1] = (size_t)n[0];
    cs[2] = (size_t)n[0] * n[1];
    int m[3] = {n[0], n[1], n[2]};
    m[a] += 1;
    fs[0] = 1;
    fs[1] = (size_t)m[0];
    fs[2] = (size_t)m[0] * m[1];
}

hv_status hv_face_gradient(const hv_grid *u, hv_faces *g)
{
    if (!u || !g || g->dim != u->dim || memcmp(g->n, u->n, sizeof g->n))
        return hv__error(HV_ERR_INVALID_ARG, "hv_face_gradient: faces do not match the grid");
    const int *n = u->n;
    const float inv_h = (float)(1.0 / u->h);
    const uint8_t *s = u->solid;
    for (int a = 0; a < u->dim; a++) {
        size_t cs[3], fs[3];
        strides(n, a, cs, fs);
        float *F = g->f[a];
#pragma omp parallel for collapse(2) schedule(static)
        for (int k = 0; k < n[2] + (a == 2); k++)
            for (int j = 0; j < n[1] + (a == 1); j++)
                for (int i = 0; i < n[0] + (a == 0); i++) {
                    int idx[3] = {i, j, k};
                    size_t fi = i + fs[1] * j + fs[2] * k;
                    if (idx[a] == 0 || idx[a] == n[a]) {
                        F[fi] = 0.0f;
                        continue;
                    }
                    size_t hi = i + cs[1] * j + cs[2] * k, lo = hi - cs[a];
                    F[fi] = (s && (s[hi] || s[lo])) ? 0.0f : (u->v[hi] - u->v[lo]) * inv_h;
                }
    }
    return HV_OK;
}

hv_status hv_face_divergence(const hv_faces *F, hv_grid *out)
{
    if (!F || !out || F->dim != out->dim || memcmp(F->n, out->n, sizeof F->n))
        return hv__error(HV_ERR_INVALID_ARG, "hv_face_divergence: faces do not match the grid");
    const int *n = out->n;
    const double inv_h = 1.0 / out->h;
    const uint8_t *s = out->solid;
    size_t cs[3], fs[3][3];
    for (int a = 0; a < 3; a++)
        strides(n, a, cs, fs[a]);
#pragma omp parallel for collapse(2) schedule(static)
    for (int k = 0; k < n[2]; k++)
        for (int j = 0; j < n[1]; j++)
            for (int i = 0; i < n[0]; i++) {
                size_t c = i + cs[1] * j + cs[2] * k;
                if (s && s[c]) {
                    out->v[c] = 0.0f;
                    continue;
                }
                int idx[3] = {i, j, k};
                double d = 0.0;
                for (int a = 0; a < F->dim; a++) {
                    size_t lo = i + fs[a][1] * j + fs[a][2] * k, hi = lo + fs[a][a];
                    /* Walls and faces touching solid carry no flux. */
                    double flo = (idx[a] == 0 || (s && s[c - cs[a]])) ? 0.0 : F->f[a][lo];
                    double fhi = (idx[a] == n[a] - 1 || (s && s[c + cs[a]])) ? 0.0 : F->f[a][hi];
                    d += fhi - flo;
                }
                out->v[c] = (float)(d * inv_h);
            }
    return HV_OK;
}

hv_status hv_laplacian(const hv_grid *u, hv_grid *out)
{
    if (!u || !out || u->dim != out->dim || memcmp(u->n, out->n, sizeof u->n) || u->v == out->v)
        return hv__error(HV_ERR_INVALID_ARG,
                         "hv_laplacian: output must match the input grid and not alias it");
    const int *n = u->n;
    const double inv_h2 = 1.0 / (u->h * u->h);
    const uint8_t *s = u->solid;
    const size_t sy = (size_t)n[0], sz = (size_t)n[0] * n[1];
#pragma omp parallel for collapse(2) schedule(static)
    for (int k = 0; k < n[2]; k++)
        for (int j = 0; j < n[1]; j++)
            for (int i = 0; i < n[0]; i++) {
                size_t c = i + sy * j + sz * k;
                if (s && s[c]) {
                    out->v[c] = 0.0f;
                    continue;
                }
                double uc = u->v[c], acc = 0.0;
                /* Each open face adds (u_nb - u_c); walls and solid neighbours add nothing. */
#define HV_FACE(cond, off)                                                                         \
    if ((cond) && !(s && s[c + (off)]))                                                            \
        acc += u->v[c + (off)] - uc;
                HV_FACE(i > 0, -(ptrdiff_t)1)
                HV_FACE(i < n[0] - 1, (ptrdiff_t)1)
                HV_FACE(j > 0, -(ptrdiff_t)sy)
                HV_FACE(j < n[1] - 1, (ptrdiff_t)sy)
                if (u->dim == 3) {
                    HV_FACE(k > 0, -(ptrdiff_t)sz)
                    HV_FACE(k < n[2] - 1, (ptrdiff_t)sz)
                }
#undef HV_FACE
                out->v[c] = (float)(acc * inv_h2);
            }
    return HV_OK;
}
