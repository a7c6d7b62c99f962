/*
 * Sign from the nearest feature's angle-weighted pseudonormal (Baerentzen &
 * Aanaes, "Signed distance computation using the angle weighted
 * pseudonormal", IEEE TVCG 2005): exact for a closed, consistently oriented
 * manifold. The heat method's zero set is smooth at the scale sqrt(t) and
 * can miss plates a voxel or two thick; within a voxel of the surface the
 * pseudonormal decides instead, but only where the nearest feature is clean
 * (its edges manifold, consistently oriented, not on a boundary) and its
 * faces bound a solid by their winding number, so open sheets, faces buried
 * in other parts, non-manifold fans and leftover flips keep the heat sign.
 */
#include "exact.h"
#include "pseudonormal.h"
#include "core/error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct pedge {
    uint64_t key;
    uint32_t slot; /* 3 * face + local edge */
    uint32_t fwd;
} pedge;

static int cmp_pedge(const void *pa, const void *pb)
{
    const pedge *a = pa, *b = pb;
    if (a->key != b->key)
        return a->key < b->key ? -1 : 1;
    return a->slot < b->slot ? -1 : a->slot > b->slot;
}

void hv__pseudo_free(hv_pseudo *ps)
{
    free(ps->fn);
    free(ps->vn);
    free(ps->other);
    free(ps->vok);
    free(ps->ftrust);
    if (ps->have_W)
        hv__wn_free(&ps->W);
    memset(ps, 0, sizeof *ps);
}

hv_status hv__pseudo_build(const hv_mesh *m, hv_pseudo *ps)
{
    memset(ps, 0, sizeof *ps);
    size_t nt = m->ntris, nv = m->nverts;
    ps->fn = malloc(3 * nt * sizeof *ps->fn);
    ps->vn = calloc(3 * nv, sizeof *ps->vn);
    ps->other = malloc(3 * nt * sizeof *ps->other);
    ps->vok = malloc(nv);
    pedge *E = malloc(3 * nt * sizeof *E);
    if (!ps->fn || !ps->vn || !ps->other || !ps->vok || !E) {
        free(E);
        hv__pseudo_free(ps);
        return hv__error(HV_ERR_NOMEM, "pseudonormals: out of memory for %zu triangles", nt);
    }
    memset(ps->vok, 1, nv);
    for (size_t f = 0; f < nt; f++) {
        const uint32_t *t = m->tris + 3 * f;
        const double *P[3] = {m->verts + 3 * (size_t)t[0], m->verts + 3 * (size_t)t[1],
                              m->verts + 3 * (size_t)t[2]};
        double u[3], v[3], n[3];
        for (int d = 0; d < 3; d++)
            u[d] = P[1][d] - P[0][d], v[d] = P[2][d] - P[0][d];
        n[0] = u[1] * v[2] - u[2] * v[1];
        n[1] = u[2] * v[0] - u[0] * v[2];
        n[2] = u[0] * v[1] - u[1] * v[0];
        double l = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        for (int d = 0; d < 3; d++)
            ps->fn[3 * f + d] = l > 0 ? n[d] / l : 0.0;
        if (!(l > 0))
            for (int k = 0; k < 3; k++)
                ps->vok[t[k]] = 0;
        /* Angle-weighted vertex normals. */
        for (int k = 0; k < 3; k++) {
            const double *o = P[k], *x = P[(k + 1) % 3], *y = P[(k + 2) % 3];
            double e1[3], e2[3];
            for (int d = 0; d < 3; d++)
                e1[d] = x[d] - o[d], e2[d] = y[d] - o[d];
            double l1 = sqrt(e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]);
            double l2 = sqrt(e2[0] * e2[0] + e2[1] * e2[1] + e2[2] * e2[2]);
            if (!(l1 > 0 && l2 > 0 && l > 0))
                continue;
            double c = (e1[0] * e2[0] + e1[1] * e2[1] + e1[2] * e2[2]) / (l1 * l2);
            double ang = acos(c < -1 ? -1 : c > 1 ? 1 : c);
            for (int d = 0; d < 3; d++)
                ps->vn[3 * (size_t)t[k] + d] += ang * ps->fn[3 * f + d];
        }
        for (int e = 0; e < 3; e++) {
            uint32_t a = t[e], b = t[(e + 1) % 3];
            E[3 * f + e].key = a < b ? ((uint64_t)a << 32 | b) : ((uint64_t)b << 32 | a);
            E[3 * f + e].slot = (uint32_t)(3 * f + e);
            E[3 * f + e].fwd = a < b;
        }
    }
    qsort(E, 3 * nt, sizeof *E, cmp_pedge);
    for (size_t i = 0; i < 3 * nt; i++)
        ps->other[i] = UINT32_MAX;
    ps->balanced = 1;
    for (size_t r = 0; r < 3 * nt;) {
        size_t s = r;
        long sum = 0;
        while (r < 3 * nt && E[r].key == E[s].key)
            sum += E[r++].fwd ? 1 : -1;
        if (sum)
            ps->balanced = 0;
        int clean = r - s == 2 && E[s].fwd != E[s + 1].fwd;
        if (clean) {
            ps->other[E[s].slot] = E[s + 1].slot / 3;
            ps->other[E[s + 1].slot] = E[s].slot / 3;
        } else {
            ps->vok[E[s].key >> 32] = 0;
            ps->vok[(uint32_t)E[s].key] = 0;
        }
    }
    free(E);
    /* A face is trusted where the winding number's principal value on it is
     * near 1/2, as on the boundary of a solid: a single-sided sheet in free
     * space has about 0 there and a face buried inside another part (self-
     * intersections) about 3/2; neither separates inside from outside. The
     * test is made on demand (pseudo_trusted): only where a pseudonormal
     * would overturn the heat sign does it matter, a sixth of the faces or
     * fewer on the bunny at 256^3. */
    ps->ftrust = calloc(nt ? nt : 1, 1);
    uint32_t *all = malloc((nt ? nt : 1) * sizeof *all);
    if (!ps->ftrust || !all) {
        free(all);
        hv__pseudo_free(ps);
        return hv__error(HV_ERR_NOMEM, "pseudonormals: out of memory for %zu triangles", nt);
    }
    for (size_t f = 0; f < nt; f++)
        all[f] = (uint32_t)f;
    hv_status st = hv__wn_build(&ps->W, m->verts, m->tris, all, nt, NULL);
    free(all);
    if (st) {
        hv__pseudo_free(ps);
        return st;
    }
    ps->have_W = 1;
    return HV_OK;
}

/* Whether face f bounds a solid (see above), computed once per face; racing
 * threads store the same value. */
static int pseudo_trusted(hv_pseudo *ps, const hv_mesh *m, uint32_t f)
{
    uint8_t v = __atomic_load_n(&ps->ftrust[f], __ATOMIC_RELAXED);
    if (!v) {
        double c[3];
        for (int d = 0; d < 3; d++)
            c[d] = (m->verts[3 * (size_t)m->tris[3 * (size_t)f] + d] +
                    m->verts[3 * (size_t)m->tris[3 * (size_t)f + 1] + d] +
                    m->verts[3 * (size_t)m->tris[3 * (size_t)f + 2] + d]) /
                   3.0;
        /* Only |w - 1/2| < 1/4 is asked: a coarse far field (dipoles from
         * one cluster radius on, errors up to about 0.1) answers it for most
         * faces, whose w is near 1/2, 0 or 3/2; within 0.15 of the threshold
         * the dipoles start at 2 radii (errors of a few 0.01). */
        double w = hv__wn_eval_beta(&ps->W, c, f, 1.0);
        if (fabs(fabs(w - 0.5) - 0.25) < 0.15)
            w = hv__wn_eval_beta(&ps->W, c, f, 2.0);
        v = fabs(w - 0.5) < 0.25 ? 1 : 2;
        __atomic_store_n(&ps->ftrust[f], v, __ATOMIC_RELAXED);
    }
    return v == 1;
}

int hv__pseudo_sign(hv_pseudo *ps, const hv_mesh *m, uint32_t tri, const double p[3], int current)
{
    const uint32_t *t = m->tris + 3 * (size_t)tri;
    double diff[3];
    int region;
    hv__point_triangle_region(p, m->verts + 3 * (size_t)t[0], m->verts + 3 * (size_t)t[1],
                              m->verts + 3 * (size_t)t[2], diff, &region);
    double n[3];
    uint32_t o = UINT32_MAX;
    if (region == 0) {
        for (int d = 0; d < 3; d++)
            n[d] = ps->fn[3 * (size_t)tri + d];
    } else if (region <= 3) {
        uint32_t v = t[region - 1];
        if (!ps->vok[v])
            return 0;
        for (int d = 0; d < 3; d++)
            n[d] = ps->vn[3 * (size_t)v + d];
    } else {
        int e = region == 4 ? 0 : region == 5 ? 1 : 2;
        o = ps->other[3 * (size_t)tri + e];
        if (o == UINT32_MAX)
            return 0;
        for (int d = 0; d < 3; d++)
            n[d] = ps->fn[3 * (size_t)tri + d] + ps->fn[3 * (size_t)o + d];
    }
    double s = diff[0] * n[0] + diff[1] * n[1] + diff[2] * n[2];
    int sg = s > 0 ? 1 : s < 0 ? -1 : 0;
    /* Agreeing with the current sign, trust changes nothing. */
    if (!sg || sg == current)
        return sg;
    if (!pseudo_trusted(ps, m, tri) || (o != UINT32_MAX && !pseudo_trusted(ps, m, o)))
        return 0;
    return sg;
}
