/*
 * Mesh-side repair before the signed heat method (NOTES §3): diffusing raw
 * normals survives ~30% random flips but not coherent flips or duplicated
 * sheets of opposite orientation, which cancel. Where connectivity exists we
 * can do better: weld, drop degenerate and duplicate faces, propagate one
 * orientation across manifold edges, then orient each component so that its
 * signed volume is positive (negative for shells nested inside an odd number
 * of other shells, e.g. the inner wall of a hollow ball).
 */
#include "sdf_internal.h"
#include "core/error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Components smaller than this share of the total area are not used as
 * enclosing shells in the nesting test, and at most this many are tested. */
#define NEST_MIN_AREA_SHARE 0.01
#define NEST_MAX_SHELLS 64

static const double *g_sort_v; /* qsort has no context argument in C11 */

static int cmp_vertex(const void *pa, const void *pb)
{
    const double *a = g_sort_v + 3 * (size_t) * (const uint32_t *)pa;
    const double *b = g_sort_v + 3 * (size_t) * (const uint32_t *)pb;
    for (int d = 0; d < 3; d++)
        if (a[d] != b[d])
            return a[d] < b[d] ? -1 : 1;
    uint32_t ia = *(const uint32_t *)pa, ib = *(const uint32_t *)pb;
    return ia < ib ? -1 : ia > ib;
}

typedef struct face_key {
    uint32_t v[3]; /* sorted vertex ids */
    uint32_t face;
} face_key;

static int cmp_face_key(const void *pa, const void *pb)
{
    const face_key *a = pa, *b = pb;
    for (int d = 0; d < 3; d++)
        if (a->v[d] != b->v[d])
            return a->v[d] < b->v[d] ? -1 : 1;
    return a->face < b->face ? -1 : a->face > b->face;
}

typedef struct edge_rec {
    uint64_t key;   /* lo << 32 | hi */
    uint32_t face;
    uint32_t fwd;   /* 1 if the face traverses lo -> hi */
} edge_rec;

static int cmp_edge(const void *pa, const void *pb)
{
    const edge_rec *a = pa, *b = pb;
    if (a->key != b->key)
        return a->key < b->key ? -1 : 1;
    return a->face < b->face ? -1 : a->face > b->face;
}

static void sort3(uint32_t v[3])
{
    uint32_t t;
    if (v[0] > v[1]) t = v[0], v[0] = v[1], v[1] = t;
    if (v[1] > v[2]) t = v[1], v[1] = v[2], v[2] = t;
    if (v[0] > v[1]) t = v[0], v[0] = v[1], v[1] = t;
}

static void cross_at(const double *V, const uint32_t *t, double n[3])
{
    const double *a = V + 3 * (size_t)t[0], *b = V + 3 * (size_t)t[1], *c = V + 3 * (size_t)t[2];
    double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    double w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    n[0] = u[1] * w[2] - u[2] * w[1];
    n[1] = u[2] * w[0] - u[0] * w[2];
    n[2] = u[0] * w[1] - u[1] * w[0];
}

/* Solid angle of triangle abc seen from p (Van Oosterom & Strackee), signed
 * so that a counter-clockwise triangle seen from behind its normal is positive. */
static double solid_angle(const double p[3], const double *a, const double *b, const double *c)
{
    double A[3], B[3], C[3];
    for (int d = 0; d < 3; d++) {
        A[d] = a[d] - p[d];
        B[d] = b[d] - p[d];
        C[d] = c[d] - p[d];
    }
    double la = sqrt(A[0] * A[0] + A[1] * A[1] + A[2] * A[2]);
    double lb = sqrt(B[0] * B[0] + B[1] * B[1] + B[2] * B[2]);
    double lc = sqrt(C[0] * C[0] + C[1] * C[1] + C[2] * C[2]);
    double det = A[0] * (B[1] * C[2] - B[2] * C[1]) - A[1] * (B[0] * C[2] - B[2] * C[0]) +
                 A[2] * (B[0] * C[1] - B[1] * C[0]);
    double den = la * lb * lc + (A[0] * B[0] + A[1] * B[1] + A[2] * B[2]) * lc +
                 (A[0] * C[0] + A[1] * C[1] + A[2] * C[2]) * lb +
                 (B[0] * C[0] + B[1] * C[1] + B[2] * C[2]) * la;
    return 2.0 * atan2(det, den);
}

/* Union-find-free component labelling and orientation propagation by BFS over
 * manifold edges. flip[f] is toggled so that both faces of every manifold edge
 * reached by the BFS traverse it in opposite directions. */
static hv_status orient_components(size_t nt, const edge_rec *E, size_t ne, const uint32_t *estart,
                                   uint8_t *flip, uint32_t *comp, size_t *ncomp, int propagate)
{
    /* Per face, up to three manifold neighbours and whether they agree. */
    uint32_t *nb = malloc(nt * 3 * sizeof *nb);
    uint8_t *same = malloc(nt * 3);
    uint32_t *queue = malloc(nt * sizeof *queue);
    if (!nb || !same || !queue) {
        free(nb), free(same), free(queue);
        return hv_error(HV_ERR_NOMEM, "mesh repair: out of memory for %zu faces", nt);
    }
    for (size_t i = 0; i < nt * 3; i++)
        nb[i] = UINT32_MAX;
    uint8_t *slot = calloc(nt, 1);
    if (!slot) {
        free(nb), free(same), free(queue);
        return hv_error(HV_ERR_NOMEM, "mesh repair: out of memory for %zu faces", nt);
    }
    for (size_t g = 0; g < ne; g++) {
        size_t s = estart[g], e = estart[g + 1];
        if (e - s != 2)
            continue;
        uint32_t f0 = E[s].face, f1 = E[s + 1].face;
        /* Same traversal direction means inconsistent orientation. */
        uint8_t agree = E[s].fwd == E[s + 1].fwd;
        if (slot[f0] < 3) nb[3 * f0 + slot[f0]] = f1, same[3 * f0 + slot[f0]++] = agree;
        if (slot[f1] < 3) nb[3 * f1 + slot[f1]] = f0, same[3 * f1 + slot[f1]++] = agree;
    }
    free(slot);
    for (size_t f = 0; f < nt; f++)
        comp[f] = UINT32_MAX;
    size_t nc = 0;
    for (size_t seed = 0; seed < nt; seed++) {
        if (comp[seed] != UINT32_MAX)
            continue;
        size_t head = 0, tail = 0;
        queue[tail++] = (uint32_t)seed;
        comp[seed] = (uint32_t)nc;
        while (head < tail) {
            uint32_t f = queue[head++];
            for (int q = 0; q < 3; q++) {
                uint32_t g = nb[3 * (size_t)f + q];
                if (g == UINT32_MAX || comp[g] != UINT32_MAX)
                    continue;
                comp[g] = (uint32_t)nc;
                if (propagate)
                    flip[g] = flip[f] ^ same[3 * (size_t)f + q];
                queue[tail++] = g;
            }
        }
        nc++;
    }
    free(nb), free(same), free(queue);
    *ncomp = nc;
    return HV_OK;
}

/* Counts boundary, non-manifold and inconsistent edges under the flips. */
static void count_edges(const edge_rec *E, const uint32_t *estart, size_t ne, const uint8_t *flip,
                        size_t *boundary, size_t *nonmanifold, size_t *inconsistent)
{
    size_t b = 0, nm = 0, inc = 0;
    for (size_t g = 0; g < ne; g++) {
        size_t s = estart[g], e = estart[g + 1];
        if (e - s == 1)
            b++;
        else if (e - s > 2)
            nm++;
        else if ((E[s].fwd ^ flip[E[s].face]) == (E[s + 1].fwd ^ flip[E[s + 1].face]))
            inc++;
    }
    *boundary = b, *nonmanifold = nm, *inconsistent = inc;
}

/* Decides the orientation of each component: positive signed volume unless
 * nested inside an odd number of other large shells. */
static void orient_outward(const double *V, const uint32_t *T, size_t nt, uint8_t *flip,
                           const uint32_t *comp, size_t nc, size_t *faces_flipped,
                           size_t *comps_flipped)
{
    double *acc = calloc(nc * 8, sizeof *acc); /* centroid*area (3), area, volume, best area, best face */
    if (!acc)
        return; /* best effort: leave orientation as propagated */
    for (size_t f = 0; f < nt; f++) {
        double n[3];
        cross_at(V, T + 3 * f, n);
        double a = 0.5 * sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        double *c = acc + 8 * comp[f];
        for (int d = 0; d < 3; d++)
            c[d] += a * (V[3 * (size_t)T[3 * f] + d] + V[3 * (size_t)T[3 * f + 1] + d] +
                         V[3 * (size_t)T[3 * f + 2] + d]) / 3.0;
        c[3] += a;
        if (a > c[5]) {
            c[5] = a;
            c[6] = (double)f;
        }
    }
    double total_area = 0;
    for (size_t k = 0; k < nc; k++) {
        double *c = acc + 8 * k;
        if (c[3] > 0)
            for (int d = 0; d < 3; d++)
                c[d] /= c[3];
        total_area += c[3];
    }
    /* Signed volume about the component's centroid, with the propagated flips. */
    for (size_t f = 0; f < nt; f++) {
        double *c = acc + 8 * comp[f];
        const double *a = V + 3 * (size_t)T[3 * f], *b = V + 3 * (size_t)T[3 * f + 1],
                     *e = V + 3 * (size_t)T[3 * f + 2];
        double A[3], B[3], C[3];
        for (int d = 0; d < 3; d++)
            A[d] = a[d] - c[d], B[d] = b[d] - c[d], C[d] = e[d] - c[d];
        double det = A[0] * (B[1] * C[2] - B[2] * C[1]) - A[1] * (B[0] * C[2] - B[2] * C[0]) +
                     A[2] * (B[0] * C[1] - B[1] * C[0]);
        c[4] += flip[f] ? -det / 6 : det / 6;
    }
    /* Large shells for the nesting test, largest first. */
    size_t nshell = 0;
    uint32_t shells[NEST_MAX_SHELLS];
    for (size_t k = 0; k < nc; k++) {
        if (acc[8 * k + 3] < NEST_MIN_AREA_SHARE * total_area || acc[8 * k + 4] == 0)
            continue;
        if (nshell < NEST_MAX_SHELLS)
            shells[nshell++] = (uint32_t)k;
    }
    int *depth = calloc(nc, sizeof *depth);
    if (nshell > 1 && depth) {
        uint8_t *is_shell = calloc(nc, 1);
        double *w = calloc(nshell * nshell, sizeof *w); /* w[i*ns+j]: winding of shell j at a point of i */
        if (is_shell && w) {
            for (size_t s = 0; s < nshell; s++)
                is_shell[shells[s]] = (uint8_t)(s + 1);
            for (size_t f = 0; f < nt; f++) {
                int js = is_shell[comp[f]];
                if (!js)
                    continue;
                double sign = ((acc[8 * comp[f] + 4] > 0) ^ flip[f]) ? 1.0 : -1.0;
                for (size_t i = 0; i < nshell; i++) {
                    if ((size_t)(js - 1) == i)
                        continue;
                    size_t bf = (size_t)acc[8 * shells[i] + 6];
                    const uint32_t *t = T + 3 * bf;
                    double p[3];
                    for (int d = 0; d < 3; d++)
                        p[d] = (V[3 * (size_t)t[0] + d] + V[3 * (size_t)t[1] + d] +
                                V[3 * (size_t)t[2] + d]) / 3.0;
                    const uint32_t *u = T + 3 * f;
                    w[i * nshell + (size_t)(js - 1)] +=
                        sign * solid_angle(p, V + 3 * (size_t)u[0], V + 3 * (size_t)u[1],
                                           V + 3 * (size_t)u[2]) / (4 * M_PI);
                }
            }
            for (size_t i = 0; i < nshell; i++)
                for (size_t j = 0; j < nshell; j++)
                    if (i != j && fabs(w[i * nshell + j]) > 0.5)
                        depth[shells[i]]++;
        }
        free(is_shell);
        free(w);
    }
    size_t ff = 0, cf = 0;
    for (size_t k = 0; k < nc; k++) {
        double vol = acc[8 * k + 4];
        int want_positive = !(depth && (depth[k] & 1));
        acc[8 * k + 7] = (vol != 0 && (vol > 0) != want_positive) ? 1 : 0;
        cf += acc[8 * k + 7] != 0;
    }
    for (size_t f = 0; f < nt; f++)
        if (acc[8 * comp[f] + 7] != 0) {
            flip[f] ^= 1;
            ff++;
        }
    free(depth);
    free(acc);
    *faces_flipped += ff;
    *comps_flipped += cf;
}

hv_status hv_sdf_repair(const hv_mesh *in, unsigned flags, hv_mesh **out,
                        hv_sdf_repair_report *report)
{
    if (!in || !out)
        return hv_error(HV_ERR_INVALID_ARG, "hv_sdf_repair: NULL argument");
    *out = NULL;
    hv_sdf_repair_report rep;
    memset(&rep, 0, sizeof rep);
    size_t nv = in->nverts, nt = in->ntris;
    rep.vertices_in = nv, rep.triangles_in = nt;
    if (nt == 0 || nv == 0 || !in->verts || !in->tris)
        return hv_error(HV_ERR_INVALID_ARG, "mesh repair: the mesh is empty (%zu vertices, %zu triangles)", nv, nt);
    if (nv >= UINT32_MAX || nt >= UINT32_MAX / 3)
        return hv_error(HV_ERR_INVALID_ARG, "mesh repair: too many vertices or triangles (%zu, %zu)", nv, nt);
    for (size_t i = 0; i < 3 * nv; i++)
        if (!isfinite(in->verts[i]))
            return hv_error(HV_ERR_NUMERIC, "mesh repair: vertex %zu has a non-finite coordinate (%g)",
                            i / 3, in->verts[i]);
    for (size_t i = 0; i < 3 * nt; i++)
        if (in->tris[i] >= nv)
            return hv_error(HV_ERR_INVALID_ARG, "mesh repair: triangle %zu uses vertex %u of %zu",
                            i / 3, in->tris[i], nv);

    hv_status st = HV_ERR_NOMEM;
    uint32_t *remap = malloc(nv * sizeof *remap);
    uint32_t *T = malloc(3 * nt * sizeof *T);
    double *V = malloc(3 * nv * sizeof *V);
    uint8_t *keep = malloc(nt);
    face_key *fk = NULL;
    edge_rec *E = NULL;
    uint32_t *estart = NULL, *comp = NULL;
    uint8_t *flip = NULL;
    hv_mesh *m = NULL;
    if (!remap || !T || !V || !keep)
        goto fail;

    /* 1. Weld by exact position: sort vertices, map each to its first twin. */
    size_t nvo = nv;
    if (flags & HV_SDF_REPAIR_WELD) {
        uint32_t *order = malloc(nv * sizeof *order);
        if (!order)
            goto fail;
        for (size_t i = 0; i < nv; i++)
            order[i] = (uint32_t)i;
        g_sort_v = in->verts;
        qsort(order, nv, sizeof *order, cmp_vertex);
        nvo = 0;
        for (size_t r = 0; r < nv; r++) {
            const double *b = in->verts + 3 * (size_t)order[r];
            const double *a = r ? in->verts + 3 * (size_t)order[r - 1] : NULL;
            if (!a || a[0] != b[0] || a[1] != b[1] || a[2] != b[2]) {
                memcpy(V + 3 * nvo, b, 3 * sizeof *V);
                nvo++;
            }
            remap[order[r]] = (uint32_t)(nvo - 1);
        }
        free(order);
        rep.vertices_welded = nv - nvo;
    } else {
        memcpy(V, in->verts, 3 * nv * sizeof *V);
        for (size_t i = 0; i < nv; i++)
            remap[i] = (uint32_t)i;
    }
    for (size_t i = 0; i < 3 * nt; i++)
        T[i] = remap[in->tris[i]];

    /* 2. Degenerate faces: a repeated vertex, or an area negligible against the
     * longest edge (collinear corners up to rounding). */
    for (size_t f = 0; f < nt; f++) {
        keep[f] = 1;
        if (!(flags & HV_SDF_REPAIR_DEGENERATE))
            continue;
        const uint32_t *t = T + 3 * f;
        if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) {
            keep[f] = 0;
            continue;
        }
        double n[3], L2 = 0;
        cross_at(V, t, n);
        for (int e = 0; e < 3; e++) {
            const double *a = V + 3 * (size_t)t[e], *b = V + 3 * (size_t)t[(e + 1) % 3];
            double l2 = (a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                        (a[2] - b[2]) * (a[2] - b[2]);
            L2 = l2 > L2 ? l2 : L2;
        }
        if (sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]) <= 1e-12 * L2)
            keep[f] = 0;
    }
    for (size_t f = 0; f < nt; f++)
        rep.degenerate_removed += !keep[f];

    /* 3. Duplicates: the same vertex set as an earlier face, either orientation. */
    if (flags & HV_SDF_REPAIR_DUPLICATES) {
        fk = malloc(nt * sizeof *fk);
        if (!fk)
            goto fail;
        size_t nk = 0;
        for (size_t f = 0; f < nt; f++) {
            if (!keep[f])
                continue;
            memcpy(fk[nk].v, T + 3 * f, sizeof fk[nk].v);
            sort3(fk[nk].v);
            fk[nk++].face = (uint32_t)f;
        }
        qsort(fk, nk, sizeof *fk, cmp_face_key);
        for (size_t r = 1; r < nk; r++)
            if (!memcmp(fk[r].v, fk[r - 1].v, sizeof fk[r].v)) {
                keep[fk[r].face] = 0;
                rep.duplicates_removed++;
            }
        free(fk);
        fk = NULL;
    }

    /* Compact the faces (unreferenced vertices are kept: they are harmless). */
    size_t ntk = 0;
    for (size_t f = 0; f < nt; f++)
        if (keep[f])
            memmove(T + 3 * ntk++, T + 3 * f, 3 * sizeof *T);
    if (ntk == 0) {
        st = hv_error(HV_ERR_INVALID_ARG, "mesh repair: all %zu triangles are degenerate", nt);
        goto fail;
    }
    /* 4. Edges, orientation propagation, components. */
    E = malloc(3 * ntk * sizeof *E);
    estart = malloc((3 * ntk + 1) * sizeof *estart);
    comp = malloc(ntk * sizeof *comp);
    flip = calloc(ntk, 1);
    if (!E || !estart || !comp || !flip)
        goto fail;
    for (size_t f = 0; f < ntk; f++)
        for (int e = 0; e < 3; e++) {
            uint32_t a = T[3 * f + e], b = T[3 * f + (e + 1) % 3];
            edge_rec *r = E + 3 * f + e;
            r->key = a < b ? ((uint64_t)a << 32 | b) : ((uint64_t)b << 32 | a);
            r->face = (uint32_t)f;
            r->fwd = a < b;
        }
    qsort(E, 3 * ntk, sizeof *E, cmp_edge);
    size_t ne = 0;
    for (size_t r = 0; r < 3 * ntk; r++)
        if (r == 0 || E[r].key != E[r - 1].key)
            estart[ne++] = (uint32_t)r;
    estart[ne] = (uint32_t)(3 * ntk);
    size_t bnd, nm;
    count_edges(E, estart, ne, flip, &bnd, &nm, &rep.inconsistent_before);
    size_t nc = 0;
    if ((st = orient_components(ntk, E, ne, estart, flip, comp, &nc,
                                (flags & HV_SDF_REPAIR_ORIENT) != 0)))
        goto fail;
    rep.components = nc;
    for (size_t f = 0; f < ntk; f++)
        rep.faces_flipped += flip[f];
    if (flags & HV_SDF_REPAIR_OUTWARD)
        orient_outward(V, T, ntk, flip, comp, nc, &rep.faces_flipped, &rep.components_flipped);
    count_edges(E, estart, ne, flip, &rep.boundary_edges, &rep.nonmanifold_edges,
                &rep.inconsistent_after);
    (void)bnd, (void)nm;

    /* Output mesh. */
    m = calloc(1, sizeof *m);
    if (!m)
        goto fail;
    m->nverts = nvo;
    m->ntris = ntk;
    m->verts = malloc(3 * nvo * sizeof *m->verts);
    m->tris = malloc(3 * ntk * sizeof *m->tris);
    if (!m->verts || !m->tris)
        goto fail;
    memcpy(m->verts, V, 3 * nvo * sizeof *V);
    for (size_t f = 0; f < ntk; f++) {
        m->tris[3 * f] = T[3 * f];
        m->tris[3 * f + 1] = flip[f] ? T[3 * f + 2] : T[3 * f + 1];
        m->tris[3 * f + 2] = flip[f] ? T[3 * f + 1] : T[3 * f + 2];
    }
    rep.vertices_out = nvo;
    rep.triangles_out = ntk;
    free(remap), free(T), free(V), free(keep), free(E), free(estart), free(comp), free(flip);
    if (report)
        *report = rep;
    *out = m;
    return HV_OK;
fail:
    if (st == HV_ERR_NOMEM)
        st = hv_error(HV_ERR_NOMEM, "mesh repair: out of memory for %zu vertices, %zu triangles", nv, nt);
    free(remap), free(T), free(V), free(keep), free(fk), free(E), free(estart), free(comp), free(flip);
    if (m) {
        free(m->verts);
        free(m->tris);
        free(m);
    }
    return st;
}
