/* Generated meshes with known geometry, and defect makers that break them in
 * controlled ways, so that tests know the truth (docs/METHOD.md, "Measuring
 * accuracy"). */
#include "mesh_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static hv_mesh *mesh_new(double *v, size_t nv, uint32_t *t, size_t nt)
{
    hv_mesh *m = calloc(1, sizeof *m);
    if (!m)
        return NULL;
    m->verts = v;
    m->nverts = nv;
    m->tris = t;
    m->ntris = nt;
    return m;
}

/* Icosahedron with counter-clockwise faces seen from outside. */
static const double ico_v[12][3] = {
    {-1, 1.6180339887498949, 0},  {1, 1.6180339887498949, 0},   {-1, -1.6180339887498949, 0},
    {1, -1.6180339887498949, 0},  {0, -1, 1.6180339887498949},  {0, 1, 1.6180339887498949},
    {0, -1, -1.6180339887498949}, {0, 1, -1.6180339887498949},  {1.6180339887498949, 0, -1},
    {1.6180339887498949, 0, 1},   {-1.6180339887498949, 0, -1}, {-1.6180339887498949, 0, 1}};
static const uint32_t ico_t[20][3] = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                      {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                      {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                      {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};

static void unit(double *p)
{
    double n = sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
    p[0] /= n;
    p[1] /= n;
    p[2] /= n;
}

hv_status hv_mesh_make_sphere(hv_mesh **out, const double c[3], double r, int subdiv)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_mesh_make_sphere: out is NULL");
    *out = NULL;
    if (!c || !(r > 0) || !isfinite(r) || subdiv < 0 || subdiv > 9)
        return hv__error(HV_ERR_INVALID_ARG,
                         "hv_mesh_make_sphere: need a centre, radius > 0 (got %g) and subdiv in "
                         "0..9 (got %d)",
                         r, subdiv);
    size_t nt = 20;
    double *v = malloc(12 * 3 * sizeof *v);
    uint32_t *t = malloc(20 * 3 * sizeof *t);
    if (!v || !t)
        goto nomem;
    memcpy(v, ico_v, sizeof ico_v);
    memcpy(t, ico_t, sizeof ico_t);
    size_t nv = 12;
    for (size_t i = 0; i < nv; i++)
        unit(v + 3 * i);
    /* Each level splits every triangle in four. Midpoints are computed per
     * triangle, so shared edges produce the same doubles twice ((a+b)/2 is
     * symmetric); welding by exact position joins them. */
    for (int level = 0; level < subdiv; level++) {
        size_t nt2 = 4 * nt, nv2 = nv + 3 * nt;
        double *v2 = malloc(nv2 * 3 * sizeof *v2);
        uint32_t *t2 = malloc(nt2 * 3 * sizeof *t2);
        if (!v2 || !t2) {
            free(v2);
            free(t2);
            goto nomem;
        }
        memcpy(v2, v, nv * 3 * sizeof *v);
        size_t k = nv;
        for (size_t i = 0; i < nt; i++) {
            uint32_t a = t[3 * i], b = t[3 * i + 1], d = t[3 * i + 2];
            uint32_t ab = (uint32_t)k, bd = (uint32_t)k + 1, da = (uint32_t)k + 2;
            const uint32_t pairs[3][2] = {{a, b}, {b, d}, {d, a}};
            for (int e = 0; e < 3; e++) {
                double *p = v2 + 3 * k++;
                for (int x = 0; x < 3; x++)
                    p[x] = (v[3 * (size_t)pairs[e][0] + x] + v[3 * (size_t)pairs[e][1] + x]) / 2;
                unit(p);
            }
            const uint32_t sub[4][3] = {{a, ab, da}, {b, bd, ab}, {d, da, bd}, {ab, bd, da}};
            memcpy(t2 + 12 * i, sub, sizeof sub);
        }
        free(v);
        v = NULL;
        hv_status st = hv__mesh_weld(v2, nv2, t2, nt2, &v, &nv, NULL);
        free(v2);
        if (st) {
            free(t2);
            free(t);
            return st;
        }
        free(t);
        t = t2;
        nt = nt2;
    }
    for (size_t i = 0; i < nv; i++)
        for (int x = 0; x < 3; x++)
            v[3 * i + x] = c[x] + r * v[3 * i + x];
    if (!(*out = mesh_new(v, nv, t, nt)))
        goto nomem;
    return HV_OK;
nomem:
    free(v);
    free(t);
    return hv__error(HV_ERR_NOMEM, "hv_mesh_make_sphere: out of memory (subdiv %d)", subdiv);
}

hv_status hv_mesh_make_torus(hv_mesh **out, const double c[3], double R, double r, int nu, int nv)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_mesh_make_torus: out is NULL");
    *out = NULL;
    if (!c || !(r > 0) || !(R > r) || !isfinite(R) || nu < 3 || nv < 3 || nu > 65536 ||
        nv > 65536 || (size_t)nu * (size_t)nv > MESH_MAX_COUNT / 2)
        return hv__error(HV_ERR_INVALID_ARG,
                         "hv_mesh_make_torus: need 0 < r < R (got R=%g r=%g) and 3 <= nu, nv <= "
                         "65536 (got %d, %d)",
                         R, r, nu, nv);
    size_t n = (size_t)nu * (size_t)nv;
    double *v = malloc(n * 3 * sizeof *v);
    uint32_t *t = malloc(2 * n * 3 * sizeof *t);
    if (!v || !t) {
        free(v);
        free(t);
        return hv__error(HV_ERR_NOMEM, "hv_mesh_make_torus: out of memory");
    }
    const double two_pi = 6.283185307179586;
    for (int i = 0; i < nu; i++) {
        double u = two_pi * i / nu;
        for (int j = 0; j < nv; j++) {
            double w = two_pi * j / nv;
            double *p = v + 3 * ((size_t)i * nv + j);
            p[0] = c[0] + (R + r * cos(w)) * cos(u);
            p[1] = c[1] + (R + r * cos(w)) * sin(u);
            p[2] = c[2] + r * sin(w);
        }
    }
    /* dP/du x dP/dv = (R + r cos v) r (cos u cos v, sin u cos v, sin v) points
     * out of the tube, so (u, v) order is counter-clockwise from outside. */
    uint32_t *q = t;
    for (int i = 0; i < nu; i++)
        for (int j = 0; j < nv; j++) {
            uint32_t p00 = (uint32_t)(i * nv + j), p10 = (uint32_t)(((i + 1) % nu) * nv + j);
            uint32_t p11 = (uint32_t)(((i + 1) % nu) * nv + (j + 1) % nv);
            uint32_t p01 = (uint32_t)(i * nv + (j + 1) % nv);
            *q++ = p00, *q++ = p10, *q++ = p11;
            *q++ = p00, *q++ = p11, *q++ = p01;
        }
    if (!(*out = mesh_new(v, n, t, 2 * n))) {
        free(v);
        free(t);
        return hv__error(HV_ERR_NOMEM, "hv_mesh_make_torus: out of memory");
    }
    return HV_OK;
}

/* ---- defect makers ---- */

static hv_status check_mesh(const hv_mesh *m, const char *fn)
{
    if (!m || !m->verts || !m->tris || m->ntris == 0)
        return hv__error(HV_ERR_INVALID_ARG, "%s: empty or NULL mesh", fn);
    return HV_OK;
}

static double diagonal(const hv_mesh *m)
{
    double lo[3], hi[3];
    if (hv_mesh_bounds(m, lo, hi))
        return 0;
    return sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                (hi[2] - lo[2]) * (hi[2] - lo[2]));
}

/* Drops vertices no triangle uses, keeping the order of the others (no welding:
 * a soup stays a soup). */
static hv_status compact(hv_mesh *m)
{
    uint32_t *map = malloc((m->nverts ? m->nverts : 1) * sizeof *map);
    if (!map)
        return hv__error(HV_ERR_NOMEM, "out of memory compacting %zu vertices", m->nverts);
    for (size_t i = 0; i < m->nverts; i++)
        map[i] = UINT32_MAX;
    for (size_t i = 0; i < 3 * m->ntris; i++)
        map[m->tris[i]] = 0;
    size_t n = 0;
    for (size_t i = 0; i < m->nverts; i++)
        if (map[i] == 0) {
            memmove(m->verts + 3 * n, m->verts + 3 * i, 3 * sizeof *m->verts);
            map[i] = (uint32_t)n++;
        }
    for (size_t i = 0; i < 3 * m->ntris; i++)
        m->tris[i] = map[m->tris[i]];
    free(map);
    m->nverts = n;
    return HV_OK;
}

static void flip(uint32_t *t)
{
    uint32_t x = t[1];
    t[1] = t[2];
    t[2] = x;
}

/* Picks k distinct triangle indices (partial Fisher-Yates); caller frees. */
static uint32_t *pick(size_t nt, size_t k, uint64_t *rng)
{
    uint32_t *perm = malloc((nt ? nt : 1) * sizeof *perm);
    if (!perm)
        return NULL;
    for (size_t i = 0; i < nt; i++)
        perm[i] = (uint32_t)i;
    for (size_t i = 0; i < k; i++) {
        size_t j = i + (size_t)(mesh_rng_uniform(rng) * (double)(nt - i));
        if (j >= nt)
            j = nt - 1;
        uint32_t x = perm[i];
        perm[i] = perm[j];
        perm[j] = x;
    }
    return perm;
}

hv_status hv_mesh_defect_holes(hv_mesh *m, int nholes, double radius_frac, unsigned seed)
{
    hv_status st = check_mesh(m, "hv_mesh_defect_holes");
    if (st)
        return st;
    if (nholes < 0 || !(radius_frac >= 0) || !isfinite(radius_frac))
        return hv__error(HV_ERR_INVALID_ARG,
                         "hv_mesh_defect_holes: need nholes >= 0 (got %d) and radius_frac >= 0 "
                         "(got %g)",
                         nholes, radius_frac);
    double rad = radius_frac * diagonal(m), rad2 = rad * rad;
    uint64_t rng = seed;
    unsigned char *gone = calloc(m->ntris, 1);
    double *centres = malloc(((size_t)nholes + 1) * 3 * sizeof *centres);
    uint32_t *cid = malloc(((size_t)nholes + 1) * sizeof *cid);
    if (!gone || !centres || !cid) {
        free(gone);
        free(centres);
        free(cid);
        return hv__error(HV_ERR_NOMEM, "hv_mesh_defect_holes: out of memory");
    }
    for (int h = 0; h < nholes; h++) {
        /* a random corner of a random triangle: a vertex that is in use */
        size_t t = (size_t)(mesh_rng_uniform(&rng) * (double)m->ntris);
        cid[h] = m->tris[3 * (t < m->ntris ? t : m->ntris - 1) + (mesh_rng_next(&rng) % 3)];
        memcpy(centres + 3 * h, m->verts + 3 * (size_t)cid[h], 3 * sizeof *centres);
    }
    size_t kept = 0;
    for (size_t t = 0; t < m->ntris; t++) {
        const uint32_t *c = m->tris + 3 * t;
        for (int h = 0; h < nholes && !gone[t]; h++)
            for (int k = 0; k < 3; k++) {
                const double *p = m->verts + 3 * (size_t)c[k], *q = centres + 3 * h;
                double d2 = (p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]) +
                            (p[2] - q[2]) * (p[2] - q[2]);
                if (c[k] == cid[h] || d2 <= rad2) {
                    gone[t] = 1;
                    break;
                }
            }
        kept += !gone[t];
    }
    free(centres);
    free(cid);
    if (kept == 0) {
        free(gone);
        return hv__error(HV_ERR_INVALID_ARG,
                         "hv_mesh_defect_holes: %d holes of radius %g would remove every triangle",
                         nholes, radius_frac);
    }
    size_t n = 0;
    for (size_t t = 0; t < m->ntris; t++)
        if (!gone[t]) {
            memmove(m->tris + 3 * n, m->tris + 3 * t, 3 * sizeof *m->tris);
            n++;
        }
    free(gone);
    m->ntris = n;
    return compact(m);
}

hv_status hv_mesh_defect_flip(hv_mesh *m, double fraction, unsigned seed)
{
    hv_status st = check_mesh(m, "hv_mesh_defect_flip");
    if (st)
        return st;
    if (!(fraction >= 0 && fraction <= 1))
        return hv__error(HV_ERR_INVALID_ARG, "hv_mesh_defect_flip: fraction %g not in [0,1]",
                         fraction);
    uint64_t rng = seed;
    size_t k = (size_t)llround(fraction * (double)m->ntris);
    uint32_t *perm = pick(m->ntris, k, &rng);
    if (!perm)
        return hv__error(HV_ERR_NOMEM, "hv_mesh_defect_flip: out of memory");
    for (size_t i = 0; i < k; i++)
        flip(m->tris + 3 * (size_t)perm[i]);
    free(perm);
    return HV_OK;
}

hv_status hv_mesh_defect_flip_half(hv_mesh *m, int axis)
{
    hv_status st = check_mesh(m, "hv_mesh_defect_flip_half");
    if (st)
        return st;
    if (axis < 0 || axis > 2)
        return hv__error(HV_ERR_INVALID_ARG, "hv_mesh_defect_flip_half: axis %d not 0, 1 or 2",
                         axis);
    double mean = 0;
    for (size_t t = 0; t < m->ntris; t++) {
        const uint32_t *c = m->tris + 3 * t;
        mean += (m->verts[3 * (size_t)c[0] + axis] + m->verts[3 * (size_t)c[1] + axis] +
                 m->verts[3 * (size_t)c[2] + axis]) /
                3;
    }
    mean /= (double)m->ntris;
    for (size_t t = 0; t < m->ntris; t++) {
        uint32_t *c = m->tris + 3 * t;
        double x = (m->verts[3 * (size_t)c[0] + axis] + m->verts[3 * (size_t)c[1] + axis] +
                    m->verts[3 * (size_t)c[2] + axis]) /
                   3;
        if (x > mean)
            flip(c);
    }
    return HV_OK;
}

hv_status hv_mesh_defect_duplicate(hv_mesh *m, double fraction, unsigned seed)
{
    hv_status st = check_mesh(m, "hv_mesh_defect_duplicate");
    if (st)
        return st;
    if (!(fraction >= 0 && fraction <= 1))
        return hv__error(HV_ERR_INVALID_ARG, "hv_mesh_defect_duplicate: fraction %g not in [0,1]",
                         fraction);
    size_t k = (size_t)llround(fraction * (double)m->ntris);
    if (k > MESH_MAX_COUNT - m->ntris)
        return hv__error(HV_ERR_INVALID_ARG, "hv_mesh_defect_duplicate: too many triangles");
    uint64_t rng = seed;
    uint32_t *perm = pick(m->ntris, k, &rng);
    uint32_t *t = perm ? realloc(m->tris, (m->ntris + k) * 3 * sizeof *t) : NULL;
    if (!t) {
        free(perm);
        return hv__error(HV_ERR_NOMEM, "hv_mesh_defect_duplicate: out of memory");
    }
    m->tris = t;
    for (size_t i = 0; i < k; i++) {
        uint32_t *dst = t + 3 * (m->ntris + i);
        memcpy(dst, t + 3 * (size_t)perm[i], 3 * sizeof *t);
        if (i < k / 2)
            flip(dst);
    }
    m->ntris += k;
    free(perm);
    return HV_OK;
}

hv_status hv_mesh_defect_soup(hv_mesh *m, double jitter_rel, unsigned seed)
{
    hv_status st = check_mesh(m, "hv_mesh_defect_soup");
    if (st)
        return st;
    if (!(jitter_rel >= 0) || !isfinite(jitter_rel))
        return hv__error(HV_ERR_INVALID_ARG, "hv_mesh_defect_soup: jitter_rel %g must be >= 0",
                         jitter_rel);
    if (m->ntris > MESH_MAX_COUNT / 3)
        return hv__error(HV_ERR_INVALID_ARG, "hv_mesh_defect_soup: too many triangles");
    double amp = jitter_rel * diagonal(m);
    double *v = malloc(m->ntris * 9 * sizeof *v);
    if (!v)
        return hv__error(HV_ERR_NOMEM, "hv_mesh_defect_soup: out of memory");
    uint64_t rng = seed;
    for (size_t i = 0; i < 3 * m->ntris; i++) {
        for (int x = 0; x < 3; x++) {
            double d = amp > 0 ? amp * (2 * mesh_rng_uniform(&rng) - 1) : 0;
            v[3 * i + x] = m->verts[3 * (size_t)m->tris[i] + x] + d;
        }
        m->tris[i] = (uint32_t)i;
    }
    free(m->verts);
    m->verts = v;
    m->nverts = 3 * m->ntris;
    return HV_OK;
}
